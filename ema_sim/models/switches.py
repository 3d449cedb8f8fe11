"""The models' own elements switched off by name, for studies that remove one effect at a time (4.3's dither).

Each model's parameters declare which of their stages an element name switches off (field metadata
``element``, :mod:`ema_sim.parameters`): the high-order models' PWM ``dead_band``, HOAD2/HOAD3's 5 mV
``quantization`` and measured ``noise``, the second-order models' 0.020° D/A ``quantization``. The
linear models have none (linearization removed them). Combining these with the test environment's
elements is :mod:`ema_sim.switches`' job, one layer up.
"""

from __future__ import annotations

from collections.abc import Iterable

from ema_sim.models.registry import model_class, model_names
from ema_sim.parameters import metas


def model_elements() -> tuple[str, ...]:
    """Every element name some model switches off, in registry order.

    Returns
    -------
    tuple of str
        Each name once.
    """
    return tuple(dict.fromkeys(e for name in model_names() for e in model_class(name).elements()))


def has_element(model: str, element: str) -> bool:
    """True when ``model`` has a stage the element name switches off.

    Parameters
    ----------
    model : str
        Registry name.
    element : str
        Element name.

    Returns
    -------
    bool
        Whether the model declares it.
    """
    return element in model_class(model).elements()


def element_overrides(model: str, names: Iterable[str]) -> dict[str, float]:
    """The parameter overrides that switch the named elements off in ``model`` (those it has).

    Parameters
    ----------
    model : str
        Registry name.
    names : iterable of str
        Element names.

    Returns
    -------
    dict
        Parameter name → switch-off value (keyword arguments of :func:`ema_sim.models.create`).
    """
    return model_class(model).element_overrides(names)


def element_models(element: str) -> tuple[str, ...]:
    """The models that have a stage the element name switches off.

    Parameters
    ----------
    element : str
        Element name.

    Returns
    -------
    tuple of str
        Registry names.
    """
    return tuple(name for name in model_names() if has_element(name, element))


def element_description(element: str) -> str:
    """What the element is, from the first parameter declaring it (``PWM dead band``).

    Parameters
    ----------
    element : str
        Element name.

    Returns
    -------
    str
        The declaring parameter's description up to its first parenthesis; the name when none declares it.
    """
    for name in model_names():
        for m in metas(model_class(name).params_class).values():
            if m.element == element:
                return m.description.split(" (")[0]
    return element
