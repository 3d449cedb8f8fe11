"""Hinge-moment profiles (in·lb) of the loaded tests: free play, compliance, hysteresis, aero loads.

Positive hinge moment aids positive deflection. A load may depend on the command (``gradient``,
an aerodynamic hinge moment proportional to deflection), so profiles take both time and command.
Parse one with :func:`parse_load`, e.g. ``const:inlb=500`` or ``sine:amp_inlb=1780,freq_hz=0.0125``.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from dataclasses import dataclass
from functools import cached_property
from typing import ClassVar

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ema_sim.signals.spec import Spec, describe, param, parse

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class Load(Spec, ABC):
    """A hinge moment ``hinge_moment_inlb(t, command_deg)``; ``duration_s`` is 0 when it has none."""

    family: ClassVar[str] = "load"

    @property
    def duration_s(self) -> float:
        """Natural length of the profile (0: as long as the maneuver)."""
        return 0.0

    def hinge_moment_inlb(self, t: ArrayLike, command_deg: ArrayLike) -> FloatArray:
        """The load at times ``t`` while the command is ``command_deg``.

        Parameters
        ----------
        t : array_like
            Times from the start of the load (s).
        command_deg : array_like
            The command at those times (deg; loads that oppose or follow the motion read it).

        Returns
        -------
        numpy.ndarray
            Hinge moment (in·lb, positive aids positive deflection).
        """
        t = np.asarray(t, dtype=float)
        return np.broadcast_to(self._load(t, np.asarray(command_deg, dtype=float)), t.shape).astype(float)

    @abstractmethod
    def _load(self, t: FloatArray, command_deg: FloatArray) -> FloatArray:
        """The profile."""


@dataclass(frozen=True)
class NoLoad(Load):
    """No hinge moment (the unloaded tests of section 2)."""

    kind: ClassVar[str] = "none"

    def _load(self, t: FloatArray, command_deg: FloatArray) -> FloatArray:  # noqa: ARG002
        return np.zeros_like(t)


@dataclass(frozen=True)
class ConstantLoad(Load):
    """A constant hinge moment (static weights; a bungee; the stall test)."""

    kind: ClassVar[str] = "const"
    inlb: float = param(0.0)

    def _load(self, t: FloatArray, command_deg: FloatArray) -> FloatArray:  # noqa: ARG002
        return np.full_like(t, self.inlb)


@dataclass(frozen=True)
class SineLoad(Load):
    """A sinusoidal hinge moment (hysteresis tests 2.9: ±100…±1780 in·lb, three cycles at 0.025 Hz)."""

    kind: ClassVar[str] = "sine"
    amp_inlb: float = param(1780.0)
    freq_hz: float = param(0.0125, low=0.0, strict=True)
    bias_inlb: float = param(0.0)
    cycles: int = param(0, low=0)
    lead_s: float = param(0.0, low=0.0)

    @property
    def duration_s(self) -> float:  # noqa: D102
        return 0.0 if self.cycles == 0 else self.lead_s + self.cycles / self.freq_hz

    def _load(self, t: FloatArray, command_deg: FloatArray) -> FloatArray:  # noqa: ARG002
        tt = np.maximum(t - self.lead_s, 0.0)
        if self.cycles:
            tt = np.minimum(tt, self.cycles / self.freq_hz)
        return self.bias_inlb + self.amp_inlb * np.sin(2.0 * np.pi * self.freq_hz * tt)


@dataclass(frozen=True)
class LoadSteps(Load):
    """Compliance staircase (2.8.2): 0 → +max → −max → 0 in steps of step_inlb, each held hold_s."""

    kind: ClassVar[str] = "steps"
    step_inlb: float = param(222.5, low=0.0, strict=True)
    max_inlb: float = param(1780.0, low=0.0, strict=True)
    hold_s: float = param(2.0, low=0.0, strict=True)
    lead_s: float = param(1.0, low=0.0)

    @cached_property
    def levels_inlb(self) -> FloatArray:
        """The held load levels, in order."""
        n = math.floor(self.max_inlb / self.step_inlb + 1e-9)
        up = self.step_inlb * np.arange(0, n + 1)
        return np.concatenate([up, up[::-1][1:], -up[1:], -up[::-1][1:]])

    @property
    def duration_s(self) -> float:  # noqa: D102
        return self.lead_s + self.hold_s * self.levels_inlb.size

    def _load(self, t: FloatArray, command_deg: FloatArray) -> FloatArray:  # noqa: ARG002
        idx = np.clip(((t - self.lead_s) / self.hold_s).astype(int), 0, self.levels_inlb.size - 1)
        return np.where(t >= self.lead_s, self.levels_inlb[idx], 0.0)


@dataclass(frozen=True)
class Reversal(Load):
    """Free play test (2.4): a small load applied one way, then reversed, period_s per reversal."""

    kind: ClassVar[str] = "reversal"
    inlb: float = param(50.0, low=0.0, strict=True)
    period_s: float = param(2.0, low=0.0, strict=True)
    reversals: int = param(4, low=1)
    lead_s: float = param(0.5, low=0.0)

    @property
    def duration_s(self) -> float:  # noqa: D102
        return self.lead_s + self.period_s * (self.reversals + 1)

    def _load(self, t: FloatArray, command_deg: FloatArray) -> FloatArray:  # noqa: ARG002
        k = np.floor(np.maximum(t - self.lead_s, 0.0) / self.period_s)
        sign = np.where(np.mod(k, 2) == 0, -1.0, 1.0)
        return np.where(t >= self.lead_s, sign * self.inlb, 0.0)


@dataclass(frozen=True)
class Gradient(Load):
    """An aerodynamic hinge moment proportional to the command: ``bias + inlb_per_deg·command``.

    Negative ``inlb_per_deg`` opposes deflection (a statically stable surface), positive aids it.
    """

    kind: ClassVar[str] = "gradient"
    inlb_per_deg: float = param(-50.0)
    bias_inlb: float = param(0.0)

    def _load(self, t: FloatArray, command_deg: FloatArray) -> FloatArray:  # noqa: ARG002
        return self.bias_inlb + self.inlb_per_deg * command_deg


LOADS: dict[str, type[Load]] = {
    cls.kind: cls for cls in (NoLoad, ConstantLoad, SineLoad, LoadSteps, Reversal, Gradient)
}


def parse_load(text: str) -> Load:
    """A load from its spec string, e.g. ``steps:step_inlb=222.5,max_inlb=1780``.

    Parameters
    ----------
    text : str
        ``kind:field=value,...`` (``ema maneuvers`` lists them).

    Returns
    -------
    Load
        The checked load.
    """
    return parse(text, LOADS, "load")


def load_help() -> str:
    """Every load kind with its fields and defaults."""
    return "\n".join(describe(LOADS))  # type: ignore[arg-type]
