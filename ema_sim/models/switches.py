"""Elements switched off by name, for studies that remove one effect at a time (section 4.3's dither).

The names are the test environment's (``delay``, ``lag``, ``quantization``, ``noise``, or one path's,
``command.delay``...) and the actuator's own ``dead_band`` (the PWM dead band of the high-order models).
A bare ``quantization`` or ``noise`` also switches off the model's own stage that stands for the same
converters and harness: HOAD2/HOAD3's 5 mV quantization and measured noise, LOADA's 0.020° D/A stage.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

from ema_sim.environment import ELEMENTS as ENV_ELEMENTS
from ema_sim.environment.profile import PATHS
from ema_sim.errors import EmaError, UnknownNameError
from ema_sim.models.registry import model_class

MODEL_ELEMENTS: tuple[str, ...] = ("dead_band",)
"""Elements only the actuator model has."""
ELEMENTS: tuple[str, ...] = (*ENV_ELEMENTS, *MODEL_ELEMENTS)
"""Every bare element name."""


def element_names(items: Iterable[str]) -> tuple[str, ...]:
    """Validated element names from ``--disable`` items (comma-separated allowed); one error lists the known."""
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
    """The names the test environment switches off (the model-only ones left out)."""
    return tuple(n for n in names if n not in MODEL_ELEMENTS)


def model_overrides(model: str, names: Iterable[str]) -> dict[str, Any]:
    """Keyword arguments of :func:`ema_sim.models.create` that switch the model's own elements off.

    ``dead_band`` on a model without one is an error (the study would silently remove nothing).
    """
    from ema_sim.models.high_order import HighOrderModel  # noqa: PLC0415
    from ema_sim.models.second_order import SecondOrderModel  # noqa: PLC0415

    chosen = set(names)
    cls = model_class(model)
    high = issubclass(cls, HighOrderModel)
    discrete_high = high and not cls.continuous
    out: dict[str, Any] = {}
    if "dead_band" in chosen:
        if not high:
            raise EmaError(f"{model} has no PWM dead band (only the high-order models have one)")
        out["pwm_dead_band_v"] = 0.0
    if "quantization" in chosen:
        if discrete_high:
            out["quantization_v"] = 0.0
        elif issubclass(cls, SecondOrderModel):
            out["quantization_deg"] = 0.0
    if "noise" in chosen and discrete_high:
        out["noise"] = False
    return out
