"""Elements switched off by name (``--disable``): the test environment's and the actuator model's, combined.

The names are the test environment's (``delay``, ``lag``, ``quantization``, ``noise``, or one path's,
``command.delay``...; :mod:`ema_sim.environment`) and the models' own (:mod:`ema_sim.models.switches`,
e.g. ``dead_band``, the PWM dead band of the high-order models). A bare ``quantization`` or ``noise``
also switches off the model's own stage that stands for the same converters and harness: HOAD2/HOAD3's
5 mV quantization and measured noise, LOADA's 0.020° D/A stage. This module sits above both and is the
one place that validates the names and splits them between the two.
"""

from __future__ import annotations

from collections.abc import Iterable

from ema_sim.environment import ELEMENTS as ENV_ELEMENTS
from ema_sim.environment import PATHS
from ema_sim.errors import EmaError, UnknownNameError
from ema_sim.models.switches import (
    element_description,
    element_models,
    element_overrides,
    has_element,
    model_elements,
)

MODEL_ELEMENTS: tuple[str, ...] = tuple(e for e in model_elements() if e not in ENV_ELEMENTS)
"""Elements only the actuator model has."""
ELEMENTS: tuple[str, ...] = (*ENV_ELEMENTS, *MODEL_ELEMENTS)
"""Every bare element name."""


def element_names(items: Iterable[str]) -> tuple[str, ...]:
    """Validated element names from ``--disable`` items (comma-separated allowed); one error lists the known.

    Parameters
    ----------
    items : iterable of str
        ``--disable`` values.

    Returns
    -------
    tuple of str
        The names, in order.
    """
    known = [*ELEMENTS, *(f"{p}.{e}" for p in PATHS for e in ENV_ELEMENTS)]
    out: list[str] = []
    for item in items:
        for name in (s.strip() for s in item.split(",")):
            if not name:
                continue
            if name not in known:
                raise UnknownNameError("element", name, known)
            out.append(name)
    return tuple(out)


def environment_elements(names: Iterable[str]) -> tuple[str, ...]:
    """The names the test environment switches off (the model-only ones left out).

    Parameters
    ----------
    names : iterable of str
        Validated element names.

    Returns
    -------
    tuple of str
        Those for the environment.
    """
    return tuple(n for n in names if n not in MODEL_ELEMENTS)


def model_overrides(model: str, names: Iterable[str]) -> dict[str, float]:
    """Keyword arguments of :func:`ema_sim.models.create` that switch the model's own elements off.

    A model-only name (``dead_band``) on a model without that stage is an error (the study would
    silently remove nothing); a shared name the model lacks only switches the environment's off.

    Parameters
    ----------
    model : str
        Registry name.
    names : iterable of str
        Validated element names.

    Returns
    -------
    dict
        Parameter name → switch-off value.
    """
    chosen = tuple(names)
    for name in chosen:
        if name in MODEL_ELEMENTS and not has_element(model, name):
            owners = ", ".join(element_models(name))
            raise EmaError(f"{model} has no {element_description(name)} (models with one: {owners})")
    return element_overrides(model, chosen)
