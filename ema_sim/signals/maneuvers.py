"""Command signals of the report's section 2 tests, in surface degrees.

Every maneuver is a frozen dataclass with a ``kind``, typed fields carrying their units, a
``duration_s`` and a vectorised ``command_deg(t)``. Parse one from a spec string with
:func:`parse_maneuver`, e.g. ``step:amp_deg=1`` or ``sweep:f0_hz=0.2,f1_hz=18,amp_deg=1``.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from dataclasses import dataclass
from functools import cached_property
from typing import ClassVar

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ema_sim.errors import SpecError
from ema_sim.signals.spec import Spec, describe, param, parse

FloatArray = NDArray[np.float64]
FULL_SCALE_DEG = 43.0
"""±10 V full scale in surface degrees (config: ±1.3 in of stroke at 33.09 °/in)."""


@dataclass(frozen=True)
class Maneuver(Spec, ABC):
    """A command signal: ``command_deg(t)`` for ``0 ≤ t``; holds its last value after ``duration_s``."""

    family: ClassVar[str] = "maneuver"

    @property
    @abstractmethod
    def duration_s(self) -> float:
        """Natural length of the signal."""

    def command_deg(self, t: ArrayLike) -> FloatArray:
        """The command at times ``t``.

        Parameters
        ----------
        t : array_like
            Seconds from the start of the maneuver.

        Returns
        -------
        numpy.ndarray
            Command (deg), held at its last value after :attr:`duration_s`.
        """
        t = np.asarray(t, dtype=float)
        return self._signal(np.clip(t, 0.0, self.duration_s))

    @abstractmethod
    def _signal(self, t: FloatArray) -> FloatArray:
        """The signal on ``0 ≤ t ≤ duration_s``."""


def _after(t: FloatArray, lead_s: float) -> FloatArray:
    return np.maximum(t - lead_s, 0.0)


@dataclass(frozen=True)
class Step(Maneuver):
    """A step of amp_deg from start_deg after a quiet lead-in, held, then back (section 2.7)."""

    kind: ClassVar[str] = "step"
    amp_deg: float = param(1.0)
    start_deg: float = param(0.0)
    lead_s: float = param(0.5, low=0.0)
    hold_s: float = param(1.5, low=0.0, strict=True)
    back: bool = param(True)

    @property
    def duration_s(self) -> float:  # noqa: D102
        return self.lead_s + self.hold_s * (2 if self.back else 1)

    def _signal(self, t: FloatArray) -> FloatArray:
        up = (t >= self.lead_s) & ((t < self.lead_s + self.hold_s) | (not self.back))
        return np.asarray(self.start_deg + self.amp_deg * up, dtype=float)


@dataclass(frozen=True)
class StepSet(Maneuver):
    """Steps of each amplitude in amps_deg (slash-separated), each up, held and back (section 2.7)."""

    kind: ClassVar[str] = "steps"
    amps_deg: str = param("0.5/1/20")
    lead_s: float = param(0.5, low=0.0)
    hold_s: float = param(1.5, low=0.0, strict=True)

    @cached_property
    def amplitudes(self) -> tuple[float, ...]:
        """The step amplitudes, degrees."""
        try:
            values = tuple(float(a) for a in self.amps_deg.split("/") if a.strip())
        except ValueError:
            raise SpecError(
                f"maneuver 'steps': field 'amps_deg' must be numbers separated by '/', got {self.amps_deg!r}"
            ) from None
        if not values or not all(math.isfinite(v) for v in values):
            raise SpecError("maneuver 'steps': field 'amps_deg' needs at least one finite amplitude")
        return values

    def validate(self) -> None:  # noqa: D102
        _ = self.amplitudes

    @property
    def duration_s(self) -> float:  # noqa: D102
        return self.lead_s + 2.0 * self.hold_s * len(self.amplitudes)

    def _signal(self, t: FloatArray) -> FloatArray:
        k = np.floor(_after(t, self.lead_s) / self.hold_s).astype(int)
        amps = np.array(self.amplitudes)
        idx = np.clip(k // 2, 0, len(amps) - 1)
        on = (t >= self.lead_s) & (k % 2 == 0) & (k < 2 * len(amps))
        return np.where(on, amps[idx], 0.0)


@dataclass(frozen=True)
class Sine(Maneuver):
    """A sine of freq_hz and amp_deg about bias_deg for a whole number of cycles (sine dwell)."""

    kind: ClassVar[str] = "sine"
    freq_hz: float = param(5.0, low=0.0, strict=True)
    amp_deg: float = param(0.4)
    bias_deg: float = param(0.0)
    cycles: int = param(20, low=1)
    lead_s: float = param(0.2, low=0.0)

    @property
    def duration_s(self) -> float:  # noqa: D102
        return self.lead_s + self.cycles / self.freq_hz

    def _signal(self, t: FloatArray) -> FloatArray:
        tt = _after(t, self.lead_s)
        return self.bias_deg + self.amp_deg * np.sin(2.0 * np.pi * self.freq_hz * tt)


@dataclass(frozen=True)
class Sweep(Maneuver):
    """A sine sweep from f0_hz to f1_hz over duration_s (log or linear), section 2.7: 0.2–18 Hz."""

    kind: ClassVar[str] = "sweep"
    f0_hz: float = param(0.2, low=0.0, strict=True)
    f1_hz: float = param(18.0, low=0.0, strict=True)
    amp_deg: float = param(1.0)
    bias_deg: float = param(0.0)
    sweep_s: float = param(60.0, low=0.0, strict=True)
    log: bool = param(True)
    lead_s: float = param(1.0, low=0.0)

    def validate(self) -> None:  # noqa: D102
        if self.f1_hz <= self.f0_hz:
            raise SpecError(f"maneuver 'sweep': f1_hz ({self.f1_hz}) must be above f0_hz ({self.f0_hz})")

    @property
    def duration_s(self) -> float:  # noqa: D102
        return self.lead_s + self.sweep_s

    def phase_rad(self, t: FloatArray) -> FloatArray:
        """Instantaneous phase of the sweep after the lead-in.

        Parameters
        ----------
        t : numpy.ndarray
            Times (s).

        Returns
        -------
        numpy.ndarray
            Phase (rad).
        """
        tt = np.clip(_after(t, self.lead_s), 0.0, self.sweep_s)
        if self.log:
            k = math.log(self.f1_hz / self.f0_hz) / self.sweep_s
            return 2.0 * np.pi * self.f0_hz * np.expm1(k * tt) / k
        rate = (self.f1_hz - self.f0_hz) / self.sweep_s
        return 2.0 * np.pi * (self.f0_hz * tt + 0.5 * rate * tt * tt)

    def frequency_hz(self, t: ArrayLike) -> FloatArray:
        """Instantaneous frequency at times ``t``.

        Parameters
        ----------
        t : array_like
            Times (s).

        Returns
        -------
        numpy.ndarray
            Frequency (Hz).
        """
        tt = np.clip(_after(np.asarray(t, float), self.lead_s), 0.0, self.sweep_s)
        if self.log:
            return self.f0_hz * (self.f1_hz / self.f0_hz) ** (tt / self.sweep_s)
        return self.f0_hz + (self.f1_hz - self.f0_hz) * tt / self.sweep_s

    def _signal(self, t: FloatArray) -> FloatArray:
        on = (t >= self.lead_s) & (t <= self.lead_s + self.sweep_s)
        return self.bias_deg + np.where(on, self.amp_deg * np.sin(self.phase_rad(t)), 0.0)


@dataclass(frozen=True)
class Schroeder(Maneuver):
    """A Schroeder-phased multisine (ref. 3): harmonics of 1/period_s in [f0_hz, f1_hz], peak amp_deg."""

    kind: ClassVar[str] = "schroeder"
    f0_hz: float = param(0.2, low=0.0, strict=True)
    f1_hz: float = param(18.0, low=0.0, strict=True)
    amp_deg: float = param(1.0)
    bias_deg: float = param(0.0)
    period_s: float = param(20.0, low=0.0, strict=True)
    periods: int = param(2, low=1)
    lead_s: float = param(1.0, low=0.0)

    def validate(self) -> None:  # noqa: D102
        if self.f1_hz <= self.f0_hz:
            raise SpecError(f"maneuver 'schroeder': f1_hz ({self.f1_hz}) must be above f0_hz ({self.f0_hz})")
        if self.harmonics.size == 0:
            raise SpecError("maneuver 'schroeder': no harmonic of 1/period_s falls in [f0_hz, f1_hz]")

    @cached_property
    def harmonics(self) -> NDArray[np.int64]:
        """Harmonic numbers k, frequencies k/period_s."""
        k0 = math.ceil(self.f0_hz * self.period_s - 1e-9)
        k1 = math.floor(self.f1_hz * self.period_s + 1e-9)
        return np.arange(max(k0, 1), k1 + 1)

    @cached_property
    def _phases_and_scale(self) -> tuple[FloatArray, float]:
        m = self.harmonics.size
        j = np.arange(1, m + 1)
        phases = -np.pi * j * (j - 1) / m  # Schroeder's low-peak-factor phases
        grid = np.linspace(0.0, self.period_s, 20 * int(self.harmonics[-1]) + 1)
        peak = np.max(np.abs(self._sum(grid, phases)))
        return phases, 1.0 / peak

    def _sum(self, t: FloatArray, phases: FloatArray) -> FloatArray:
        w = 2.0 * np.pi * self.harmonics / self.period_s
        out = np.zeros_like(t)
        for wk, ph in zip(w, phases, strict=True):
            out += np.cos(wk * t + ph)
        return out

    @property
    def frequencies_hz(self) -> FloatArray:
        """Frequencies of the components."""
        return self.harmonics / self.period_s

    @property
    def duration_s(self) -> float:  # noqa: D102
        return self.lead_s + self.period_s * self.periods

    def _signal(self, t: FloatArray) -> FloatArray:
        phases, scale = self._phases_and_scale
        tt = _after(t, self.lead_s)
        on = t >= self.lead_s
        return self.bias_deg + np.where(on, self.amp_deg * scale * self._sum(tt, phases), 0.0)


@dataclass(frozen=True)
class Ramp(Maneuver):
    """A slow triangle start_deg → peak_deg → start_deg at rate_dps (section 2.7: 0.01 and 0.005 °/s)."""

    kind: ClassVar[str] = "ramp"
    rate_dps: float = param(0.01, low=0.0, strict=True)
    peak_deg: float = param(2.0)
    start_deg: float = param(0.0)
    lead_s: float = param(1.0, low=0.0)

    def validate(self) -> None:  # noqa: D102
        if self.peak_deg == self.start_deg:
            raise SpecError("maneuver 'ramp': peak_deg must differ from start_deg")

    @property
    def duration_s(self) -> float:  # noqa: D102
        return self.lead_s + 2.0 * abs(self.peak_deg - self.start_deg) / self.rate_dps

    def _signal(self, t: FloatArray) -> FloatArray:
        span = self.peak_deg - self.start_deg
        half = abs(span) / self.rate_dps
        tt = _after(t, self.lead_s)
        frac = np.where(tt <= half, tt / half, 2.0 - tt / half)
        return self.start_deg + span * np.clip(frac, 0.0, 1.0)


def _triangle_wave(phase_cycles: FloatArray) -> FloatArray:
    """Unit triangle starting at 0 and rising: 0 → 1 → −1 → 0 per cycle."""
    p = np.mod(phase_cycles, 1.0)
    return np.where(p < 0.25, 4 * p, np.where(p < 0.75, 2 - 4 * p, 4 * p - 4))


@dataclass(frozen=True)
class Triangle(Maneuver):
    """A triangle wave of freq_hz and amp_deg about bias_deg (dynamic crosstalk: 0.5 Hz, 10 % FS)."""

    kind: ClassVar[str] = "triangle"
    freq_hz: float = param(0.5, low=0.0, strict=True)
    amp_deg: float = param(2.15)
    bias_deg: float = param(0.0)
    cycles: int = param(5, low=1)
    lead_s: float = param(0.2, low=0.0)

    @property
    def duration_s(self) -> float:  # noqa: D102
        return self.lead_s + self.cycles / self.freq_hz

    def _signal(self, t: FloatArray) -> FloatArray:
        tt = _after(t, self.lead_s)
        return self.bias_deg + self.amp_deg * _triangle_wave(self.freq_hz * tt)


@dataclass(frozen=True)
class Square(Maneuver):
    """A square wave of freq_hz and amp_deg about bias_deg (timing test: 1 Hz, 10 % of travel)."""

    kind: ClassVar[str] = "square"
    freq_hz: float = param(1.0, low=0.0, strict=True)
    amp_deg: float = param(4.3)
    bias_deg: float = param(0.0)
    cycles: int = param(5, low=1)
    lead_s: float = param(0.5, low=0.0)

    @property
    def duration_s(self) -> float:  # noqa: D102
        return self.lead_s + self.cycles / self.freq_hz

    def _signal(self, t: FloatArray) -> FloatArray:
        tt = _after(t, self.lead_s)
        sq = np.where(np.mod(self.freq_hz * tt, 1.0) < 0.5, 1.0, -1.0)
        return self.bias_deg + np.where(t >= self.lead_s, self.amp_deg * sq, 0.0)


@dataclass(frozen=True)
class Hold(Maneuver):
    """A constant command (the observed channel of a crosstalk test; a surface held under load)."""

    kind: ClassVar[str] = "hold"
    value_deg: float = param(0.0)
    hold_s: float = param(10.0, low=0.0, strict=True)

    @property
    def duration_s(self) -> float:  # noqa: D102
        return self.hold_s

    def _signal(self, t: FloatArray) -> FloatArray:
        return np.full_like(t, self.value_deg)


@dataclass(frozen=True)
class StaticThreshold(Maneuver):
    """Static threshold (2.1.1): 0.1 Hz triangles whose amplitude rises slowly from 0 to amp_max_deg."""

    kind: ClassVar[str] = "static_threshold"
    freq_hz: float = param(0.1, low=0.0, strict=True)
    amp_max_deg: float = param(0.3, low=0.0, strict=True)
    cycles: int = param(6, low=1)
    bias_deg: float = param(0.0)
    lead_s: float = param(1.0, low=0.0)

    @property
    def duration_s(self) -> float:  # noqa: D102
        return self.lead_s + self.cycles / self.freq_hz

    def amplitude_deg(self, t: ArrayLike) -> FloatArray:
        """The envelope at times ``t``.

        Parameters
        ----------
        t : array_like
            Times (s).

        Returns
        -------
        numpy.ndarray
            Amplitude (deg).
        """
        tt = _after(np.asarray(t, float), self.lead_s)
        return self.amp_max_deg * np.clip(tt * self.freq_hz / self.cycles, 0.0, 1.0)

    def _signal(self, t: FloatArray) -> FloatArray:
        tt = _after(t, self.lead_s)
        return self.bias_deg + self.amplitude_deg(t) * _triangle_wave(self.freq_hz * tt)


@dataclass(frozen=True)
class DynamicThreshold(Maneuver):
    """Dynamic threshold (2.1.2): a 5 Hz sine whose amplitude rises from 1 % FS (0.1 Vpp) upward."""

    kind: ClassVar[str] = "dynamic_threshold"
    freq_hz: float = param(5.0, low=0.0, strict=True)
    amp0_deg: float = param(0.2125, low=0.0)
    amp1_deg: float = param(1.0, low=0.0, strict=True)
    ramp_s: float = param(30.0, low=0.0, strict=True)
    bias_deg: float = param(0.0)
    lead_s: float = param(0.5, low=0.0)

    @property
    def duration_s(self) -> float:  # noqa: D102
        return self.lead_s + self.ramp_s

    def amplitude_deg(self, t: ArrayLike) -> FloatArray:
        """The envelope at times ``t``.

        Parameters
        ----------
        t : array_like
            Times (s).

        Returns
        -------
        numpy.ndarray
            Amplitude (deg).
        """
        tt = _after(np.asarray(t, float), self.lead_s)
        return self.amp0_deg + (self.amp1_deg - self.amp0_deg) * np.clip(tt / self.ramp_s, 0.0, 1.0)

    def _signal(self, t: FloatArray) -> FloatArray:
        tt = _after(t, self.lead_s)
        on = t >= self.lead_s
        return self.bias_deg + np.where(on, self.amplitude_deg(t) * np.sin(2 * np.pi * self.freq_hz * tt), 0.0)


@dataclass(frozen=True)
class Regeneration(Maneuver):
    """Voltage regeneration (2.5): a 5 % FS square wave swept 0.1–5 Hz (log)."""

    kind: ClassVar[str] = "regen"
    amp_deg: float = param(0.05 * FULL_SCALE_DEG)
    f0_hz: float = param(0.1, low=0.0, strict=True)
    f1_hz: float = param(5.0, low=0.0, strict=True)
    sweep_s: float = param(60.0, low=0.0, strict=True)
    lead_s: float = param(0.5, low=0.0)

    def validate(self) -> None:  # noqa: D102
        if self.f1_hz <= self.f0_hz:
            raise SpecError("maneuver 'regen': f1_hz must be above f0_hz")

    @property
    def duration_s(self) -> float:  # noqa: D102
        return self.lead_s + self.sweep_s

    def _signal(self, t: FloatArray) -> FloatArray:
        sweep = Sweep(f0_hz=self.f0_hz, f1_hz=self.f1_hz, amp_deg=1.0, sweep_s=self.sweep_s, lead_s=self.lead_s)
        on = t >= self.lead_s
        return np.where(on, self.amp_deg * np.where(np.sin(sweep.phase_rad(t)) >= 0.0, 1.0, -1.0), 0.0)


@dataclass(frozen=True)
class Staircase(Maneuver):
    """Calibration staircase (2.6): 0 → +max_deg → −max_deg → 0 in steps of step_deg, each held."""

    kind: ClassVar[str] = "staircase"
    step_deg: float = param(5.0, low=0.0, strict=True)
    max_deg: float = param(40.0, low=0.0, strict=True)
    hold_s: float = param(3.0, low=0.0, strict=True)

    @cached_property
    def levels_deg(self) -> FloatArray:
        """The held levels, in order."""
        n = math.floor(self.max_deg / self.step_deg + 1e-9)
        up = self.step_deg * np.arange(0, n + 1)
        return np.concatenate([up, up[::-1][1:], -up[1:], -up[::-1][1:]])

    @property
    def duration_s(self) -> float:  # noqa: D102
        return self.hold_s * self.levels_deg.size

    def _signal(self, t: FloatArray) -> FloatArray:
        idx = np.clip((t / self.hold_s).astype(int), 0, self.levels_deg.size - 1)
        return np.asarray(self.levels_deg[idx], dtype=float)


@dataclass(frozen=True)
class ParameterId(Maneuver):
    """The PID sequence of figure 20: a doublet, a sine sweep and a Schroeder sweep, with quiet gaps."""

    kind: ClassVar[str] = "pid"
    amp_deg: float = param(1.0)
    doublet_s: float = param(1.0, low=0.0, strict=True)
    f0_hz: float = param(0.5, low=0.0, strict=True)
    f1_hz: float = param(10.0, low=0.0, strict=True)
    sweep_s: float = param(20.0, low=0.0, strict=True)
    gap_s: float = param(2.0, low=0.0)

    @cached_property
    def _parts(self) -> tuple[tuple[float, Maneuver], ...]:
        doublet = Square(freq_hz=0.5 / self.doublet_s, amp_deg=self.amp_deg, cycles=1, lead_s=0.0)
        sweep = Sweep(f0_hz=self.f0_hz, f1_hz=self.f1_hz, amp_deg=self.amp_deg, sweep_s=self.sweep_s, lead_s=0.0)
        schroeder = Schroeder(f0_hz=self.f0_hz, f1_hz=self.f1_hz, amp_deg=self.amp_deg,
                              period_s=self.sweep_s / 2.0, periods=2, lead_s=0.0)
        parts: list[tuple[float, Maneuver]] = []
        t0 = self.gap_s
        for man in (doublet, sweep, schroeder):
            parts.append((t0, man))
            t0 += man.duration_s + self.gap_s
        return tuple(parts)

    def validate(self) -> None:  # noqa: D102
        if self.f1_hz <= self.f0_hz:
            raise SpecError("maneuver 'pid': f1_hz must be above f0_hz")

    @property
    def duration_s(self) -> float:  # noqa: D102
        t0, last = self._parts[-1]
        return t0 + last.duration_s + self.gap_s

    def _signal(self, t: FloatArray) -> FloatArray:
        out = np.zeros_like(t)
        for t0, man in self._parts:
            inside = (t >= t0) & (t < t0 + man.duration_s)
            out = np.where(inside, man.command_deg(t - t0), out)
        return out


MANEUVERS: dict[str, type[Maneuver]] = {
    cls.kind: cls
    for cls in (
        Step, StepSet, Sine, Sweep, Schroeder, Ramp, Triangle, Square, Hold, StaticThreshold,
        DynamicThreshold, Regeneration, Staircase, ParameterId,
    )
}


def parse_maneuver(text: str) -> Maneuver:
    """A maneuver from its spec string, e.g. ``sine:freq_hz=5,amp_deg=0.4``.

    Parameters
    ----------
    text : str
        ``kind:field=value,...`` (``ema maneuvers`` lists them).

    Returns
    -------
    Maneuver
        The checked maneuver.
    """
    return parse(text, MANEUVERS, "maneuver")


def maneuver_help() -> str:
    """Every maneuver kind with its fields and defaults."""
    return "\n".join(describe(MANEUVERS))  # type: ignore[arg-type]
