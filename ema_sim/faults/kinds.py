"""Faults you can inject on a schedule, as ``kind:at_s=...,ramp_s=...,size=...`` spec strings.

Each fault acts on one named parameter or stage of the models' pipelines, from ``at_s`` on, reaching its
full ``size`` after ``ramp_s`` (0: a step). Parameter faults (friction, jam, backlash, motor and driver,
loop delay, linkage) are schedules of kernel parameters applied frame by frame through
:meth:`~ema_sim.models.base.ActuatorModel.retune`; sensor faults (LVDT bias, drift, scale) act on the
position reading the record reports; the hinge-moment sign error acts on the load the host applies. The
models stay pure: a fault is data here, applied by :mod:`ema_sim.faults.schedule`. ``docs/faults.md``
gives each one's physics and its place in the report's block diagrams.

``size`` is a relative change (``0.5``: +50 %) for the kinds whose :attr:`Fault.relative` is true, and an
absolute amount in the unit :attr:`Fault.unit` names for the others.
"""

from __future__ import annotations

import math
from abc import ABC
from dataclasses import dataclass
from typing import ClassVar

import numpy as np
from numpy.typing import NDArray

from ema_sim.errors import SpecError
from ema_sim.signals.spec import Spec, describe, param, parse

FloatArray = NDArray[np.float64]
SECOND_ORDER = "second-order"
HIGH_ORDER = "high-order"
JAM_FORCE_LBF = 1e7
"""Friction of a jammed screw: beyond any force the motor can make, so the rod stops and the current limits."""
JAM_GAP_DEG = 1e-6
"""Half the gap a jammed second-order model's travel limits leave around the held position."""


@dataclass(frozen=True)
class Change:
    """How a fault moves one kernel parameter.

    ``scale`` by ``(1 + level)**power``, ``add`` level, ``set`` it to :attr:`value`, or ``hold`` it at the
    position the actuator had at the onset (a travel stop closing in).
    """

    parameter: str
    how: str
    power: float = 1.0
    value: float = 0.0
    """The value a ``set`` change goes to at full level (``hold``: the offset from the held position)."""

    def apply(self, nominal: float, level: float, ramp: float, held_deg: float = 0.0) -> float:
        """The parameter at ``level``: the fault's size times its ramp (``ramp``, 0..1).

        ``held_deg`` is the position at the onset, for ``hold``.
        """
        if self.how == "hold":
            return held_deg + self.value if ramp > 0.0 else nominal
        if self.how == "scale":
            return float(nominal * (1.0 + level) ** self.power)
        if self.how == "add":
            return nominal + level
        return nominal + (self.value - nominal) * ramp if math.isfinite(nominal) else self.value


@dataclass(frozen=True)
class Fault(Spec, ABC):
    """A fault of one actuator channel, injected on a schedule."""

    family: ClassVar[str] = "fault"
    stage: ClassVar[str] = "parameter"
    """``parameter`` (a kernel parameter), ``output`` (the reported LVDT reading) or ``input`` (the load)."""
    relative: ClassVar[bool] = True
    unit: ClassVar[str] = "-"
    changes: ClassVar[dict[str, tuple[Change, ...]]] = {}
    """Family (``second-order``, ``high-order``) → the parameter changes it makes there."""
    at_s: float = param(1.0, low=0.0, doc="onset time (s)")
    ramp_s: float = param(0.0, low=0.0, doc="time to full size (s); 0 is a step")

    @property
    def magnitude(self) -> float:
        """The fault's full size in its unit (1 for a jam)."""
        return float(getattr(self, "size", 1.0))

    def ramp(self, time_s: FloatArray) -> FloatArray:
        """How much of the fault is in at each instant: 0 before ``at_s``, 1 after the ramp."""
        t = np.asarray(time_s, dtype=float)
        if self.ramp_s <= 0.0:
            return (t >= self.at_s).astype(float)
        return np.clip((t - self.at_s) / self.ramp_s, 0.0, 1.0)

    def level(self, time_s: FloatArray) -> FloatArray:
        """The fault's size in at each instant (the truth recorded beside the run)."""
        return self.magnitude * self.ramp(time_s)

    def parameter(self, family: str) -> str:
        """The model parameter the fault implicates in ``family`` (its first change), or its stage."""
        changes = self.changes.get(family, ())
        return changes[0].parameter if changes else f"{self.stage}:{self.kind}"


@dataclass(frozen=True)
class CoulombFriction(Fault):
    """Coulomb friction and stiction of motor and screw grow by ``size`` (relative; figure 30's stage 11)."""

    kind: ClassVar[str] = "coulomb_friction"
    changes: ClassVar[dict[str, tuple[Change, ...]]] = {
        HIGH_ORDER: (Change("coulomb_friction_lbf", "scale"), Change("stiction_lbf", "scale")),
    }
    size: float = param(0.5, low=-1.0, strict=True, doc="relative growth")


@dataclass(frozen=True)
class ViscousFriction(Fault):
    """Viscous friction grows: the loop's damping ratio rises by ``size`` (relative; figure 21's ζ)."""

    kind: ClassVar[str] = "viscous_friction"
    changes: ClassVar[dict[str, tuple[Change, ...]]] = {SECOND_ORDER: (Change("zeta", "scale"),)}
    size: float = param(0.5, low=-1.0, strict=True, doc="relative growth")


@dataclass(frozen=True)
class Jam(Fault):
    """The rod stops where it is: the screw seizes.

    High order: a friction beyond stall, the current climbs to its limit. Second order: both travel limits
    close in on the position at the onset.
    """

    kind: ClassVar[str] = "jam"
    relative: ClassVar[bool] = False
    changes: ClassVar[dict[str, tuple[Change, ...]]] = {
        HIGH_ORDER: (Change("stiction_lbf", "set", value=JAM_FORCE_LBF),
                     Change("coulomb_friction_lbf", "set", value=JAM_FORCE_LBF)),
        SECOND_ORDER: (Change("position_min_deg", "hold", value=-JAM_GAP_DEG),
                       Change("position_max_deg", "hold", value=JAM_GAP_DEG)),
    }


@dataclass(frozen=True)
class Backlash(Fault):
    """Backlash (free play) grows by ``size`` (relative; figure 29's free play, figure 32's gear backlash)."""

    kind: ClassVar[str] = "backlash"
    changes: ClassVar[dict[str, tuple[Change, ...]]] = {
        SECOND_ORDER: (Change("free_play_deg", "scale"),),
        HIGH_ORDER: (Change("gear_backlash_in", "scale"),),
    }
    size: float = param(1.0, low=-1.0, doc="relative growth")


@dataclass(frozen=True)
class TorqueConstant(Fault):
    """The motor's torque constant changes by ``size`` (relative; demagnetized rotor, shorted turns)."""

    kind: ClassVar[str] = "torque_constant"
    changes: ClassVar[dict[str, tuple[Change, ...]]] = {HIGH_ORDER: (Change("back_emf_v_s_per_rad", "scale"),)}
    size: float = param(-0.3, low=-1.0, strict=True, doc="relative change")


@dataclass(frozen=True)
class CurrentLimit(Fault):
    """The driver's current limit changes by ``size`` (relative; a degraded bridge or its protection)."""

    kind: ClassVar[str] = "current_limit"
    changes: ClassVar[dict[str, tuple[Change, ...]]] = {
        HIGH_ORDER: (Change("current_limit_a", "scale"),),
        SECOND_ORDER: (Change("accel_limit_dps2", "scale"),),
    }
    size: float = param(-0.3, low=-1.0, strict=True, doc="relative change")


@dataclass(frozen=True)
class Delay(Fault):
    """The loop's command delay grows by ``size`` seconds (section 2.3's time delay)."""

    kind: ClassVar[str] = "delay"
    relative: ClassVar[bool] = False
    unit: ClassVar[str] = "s"
    changes: ClassVar[dict[str, tuple[Change, ...]]] = {
        SECOND_ORDER: (Change("delay_s", "add"),),
        HIGH_ORDER: (Change("command_delay_s", "add"),),
    }
    size: float = param(0.005, low=0.0, high=0.1, doc="added delay (s)")


@dataclass(frozen=True)
class LvdtBias(Fault):
    """The reported LVDT position reads ``size`` degrees high (demodulator offset)."""

    kind: ClassVar[str] = "lvdt_bias"
    stage: ClassVar[str] = "output"
    relative: ClassVar[bool] = False
    unit: ClassVar[str] = "deg"
    size: float = param(0.1, doc="bias (deg)")


@dataclass(frozen=True)
class LvdtDrift(Fault):
    """The reported LVDT position drifts at ``size`` degrees per second from the onset."""

    kind: ClassVar[str] = "lvdt_drift"
    stage: ClassVar[str] = "output"
    relative: ClassVar[bool] = False
    unit: ClassVar[str] = "deg/s"
    size: float = param(0.01, doc="drift rate (deg/s)")

    def level(self, time_s: FloatArray) -> FloatArray:
        """The drift accumulated at each instant (deg)."""
        return self.size * np.maximum(np.asarray(time_s, dtype=float) - self.at_s, 0.0)


@dataclass(frozen=True)
class LvdtScale(Fault):
    """The reported LVDT position's scale changes by ``size`` (relative; excitation or gain drift)."""

    kind: ClassVar[str] = "lvdt_scale"
    stage: ClassVar[str] = "output"
    size: float = param(0.02, low=-0.5, high=0.5, doc="relative scale error")


@dataclass(frozen=True)
class Linkage(Fault):
    """A loosened linkage: the surface mode's frequency changes by ``size`` (relative, negative: it falls)."""

    kind: ClassVar[str] = "linkage"
    changes: ClassVar[dict[str, tuple[Change, ...]]] = {
        SECOND_ORDER: (Change("linkage_freq_hz", "scale"),),
        HIGH_ORDER: (Change("gear_stiffness_lbf_per_in", "scale", power=2.0),),
    }
    size: float = param(-0.3, low=-0.9, high=1.0, doc="relative frequency change")


@dataclass(frozen=True)
class HingeMomentSign(Fault):
    """The host applies the hinge moment with the wrong sign (section 4.4.1); ``size`` 1 reverses it fully."""

    kind: ClassVar[str] = "hm_sign"
    stage: ClassVar[str] = "input"
    relative: ClassVar[bool] = False
    size: float = param(1.0, low=0.0, high=1.0, doc="fraction of the load reversed (1: sign error)")


FAULTS: dict[str, type[Fault]] = {c.kind: c for c in (
    CoulombFriction, ViscousFriction, Jam, Backlash, TorqueConstant, CurrentLimit, Delay, LvdtBias, LvdtDrift,
    LvdtScale, Linkage, HingeMomentSign)}


def parse_fault(text: str) -> Fault:
    """A fault from its spec string, e.g. ``coulomb_friction:at_s=5,ramp_s=2,size=0.5``.

    Parameters
    ----------
    text : str
        The spec.

    Returns
    -------
    Fault
        The fault.
    """
    fault = parse(text, FAULTS, "fault")
    if not isinstance(fault, Fault):  # pragma: no cover - the registry holds faults only
        raise SpecError(f"not a fault: {text!r}")
    return fault


def parse_faults(text: str) -> list[Fault]:
    """Faults from ``;``-separated specs (an EMAC node parameter); an empty string or ``none`` is no fault.

    Parameters
    ----------
    text : str
        The specs.

    Returns
    -------
    list of Fault
        The faults.
    """
    parts = [p.strip() for p in text.split(";") if p.strip()]
    return [] if parts in ([], ["none"]) else [parse_fault(p) for p in parts]


def fault_help() -> str:
    """Every fault kind with its fields and defaults."""
    return "\n".join(describe(FAULTS))  # type: ignore[arg-type]
