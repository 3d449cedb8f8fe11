"""The record's time stamps: how much they jitter about a uniform grid, and the error floor that sets.

A bench logger's stamps are often integer milliseconds from a software clock: they scatter about the
uniform grid the logger samples on (or the instants scatter and the stamps follow them). Either way a
model run on the stamps is read ``δt`` away from where the output was sampled whenever the stamps are
wrong, and the output then differs from the model by ``rate × δt``: white, but only while the output
moves, and as large as the rate makes it (±2 ms on a 100 °/s move is ±0.2°, far above a good sensor's
noise). No effect of the actuator explains that; a fit that weighs it as noise-floor error takes it for
one (a rate limit that clips the fastest moves, where the error is largest).

:func:`measure` reads the stamps alone: their nominal interval (the least-squares line through them),
their scatter about it (rms and peak), and the stamps' own step (integer ms: the rounding's share,
``step/√12``, is part of the scatter). :meth:`Stamps.floor` is the error floor the scatter sets on an
output moving at the given rates: ``rms(rate) × scatter`` over the record, ``max|rate| × peak`` at the
fastest moves. Whether the stamps or the instants are the ones that are off, only the residual of a
model can tell (the error appears when the stamps are wrong, not when they follow the instants):
:func:`timing_error` estimates it from a residual and the rate.

A *gap* is not jitter: an interval longer than :data:`GAP_INTERVALS` nominal intervals is a pause of the
logger (:func:`find_gaps`), said as such and left out of the scatter, which is read within each stretch
between gaps (:func:`stretches`). Within a stretch the scatter is the stamps' rms about the straight line
through them when they keep to one; when the instants wander (a logger whose every interval jitters, so
its instants drift as a random walk, a sample now and then skipped), that line says how far they wandered,
not how far a stamp is from its neighbours: the scatter is then each stamp's distance from the line
through its two neighbours (at their slots on the nominal grid), scaled to a stamp's own (``/√1.5`` for
neighbours one slot away), which is what a model run on the stamps feels.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from itertools import pairwise

import numpy as np
from numpy.typing import NDArray
from scipy.signal import savgol_filter

FloatArray = NDArray[np.float64]
STEP_MATCH = 1e-6
"""Stamps within this share of a step of a multiple of it are logged in that step (integer ms)."""
STEPS_S = (1e-3, 1e-4)
"""The stamp steps looked for: integer milliseconds, tenths of a millisecond."""
RATE_WINDOW_S = 0.015
"""The smoothing window of the output's rate (savgol, quadratic): long enough to average the counts."""
GAP_INTERVALS = 4.0
"""An interval longer than this many median intervals is a gap in the record, not jitter."""
SKIP = 0.25
"""An interval counts one slot per nominal interval, a skipped sample from 1.75 of them (3 ms among 2 ms is one)."""
WANDER = 1.5
"""Stamps whose rms about their straight line exceeds this many times their local scatter wander."""


@dataclass(frozen=True)
class Gap:
    """A pause in the stamps: no sample from ``start_s`` for ``duration_s``; the next is sample ``index``."""

    index: int
    start_s: float
    duration_s: float

    def as_dict(self) -> dict[str, float]:
        """Plain values for JSON."""
        return {"index": self.index, "start_s": self.start_s, "duration_s": self.duration_s}


def find_gaps(time_s: FloatArray) -> tuple[Gap, ...]:
    """The intervals longer than :data:`GAP_INTERVALS` median intervals (module docstring).

    Parameters
    ----------
    time_s : numpy.ndarray
        The logged stamps, s (increasing).

    Returns
    -------
    tuple of Gap
        One per such interval, in time order (empty: none).
    """
    t = np.asarray(time_s, dtype=float)
    if t.size < 3:
        return ()
    dt = np.diff(t)
    med = float(np.median(dt))
    return tuple(Gap(int(i) + 1, float(t[i]), float(dt[i])) for i in np.flatnonzero(dt > GAP_INTERVALS * med))


def stretches(n: int, gaps: tuple[Gap, ...]) -> list[tuple[int, int]]:
    """The samples ``[start, stop)`` of each contiguous stretch between a record's gaps.

    Parameters
    ----------
    n : int
        The record's samples.
    gaps : tuple of Gap
        Its gaps (:func:`find_gaps`).

    Returns
    -------
    list of tuple
        ``(start, stop)`` of each stretch, in order.
    """
    cuts = [0, *(g.index for g in gaps), n]
    return [(a, b) for a, b in pairwise(cuts) if b > a]


def gap_statement(gaps: tuple[Gap, ...], interval_s: float) -> str:
    """The gaps in one clause (empty: none).

    Parameters
    ----------
    gaps : tuple of Gap
        The record's gaps.
    interval_s : float
        The nominal sample interval.

    Returns
    -------
    str
        How many, where and how long.
    """
    if not gaps:
        return ""
    each = ", ".join(f"{g.duration_s:.4g} s at {g.start_s:.4g} s ({g.duration_s / interval_s:.0f} intervals)"
                     for g in gaps[:5])
    more = f" and {len(gaps) - 5} more" if len(gaps) > 5 else ""
    return (f"{len(gaps)} gap(s) in the time stamps (an interval over {GAP_INTERVALS:g}× the nominal "
            f"{1e3 * interval_s:.4g} ms): {each}{more}")


@dataclass(frozen=True)
class Stamps:
    """The stamps' regularity (module docstring)."""

    interval_s: float
    """Nominal sample interval: the stretches' span over their slots on the grid (no gap counted)."""
    scatter_s: float
    """Rms of the stamps about their grid, within the stretches between gaps (0: uniform)."""
    peak_s: float
    """Largest distance of a stamp from that grid."""
    step_s: float | None
    """The stamps' own step (1 ms for integer-millisecond stamps), None when they have none."""
    samples: int
    gaps: tuple[Gap, ...] = ()
    """The pauses of the logger, left out of the scatter."""

    @property
    def jitters(self) -> bool:
        """The stamps scatter about a uniform grid by more than a millionth of a sample."""
        return self.scatter_s > 1e-6 * self.interval_s

    @property
    def rounding_s(self) -> float:
        """The share of the scatter the stamps' own step accounts for (``step/√12``)."""
        return 0.0 if self.step_s is None else self.step_s / math.sqrt(12.0)

    def floor(self, rate: FloatArray) -> tuple[float, float]:
        """The error floor the scatter sets on an output moving at ``rate``: rms over the record, and peak.

        Parameters
        ----------
        rate : numpy.ndarray
            The output's rate at each sample (unit/s).

        Returns
        -------
        tuple of float
            ``rms(rate) × scatter`` and ``max|rate| × peak`` (output units).
        """
        r = np.asarray(rate, dtype=float)
        if r.size == 0:
            return 0.0, 0.0
        return float(np.sqrt(np.mean(r * r))) * self.scatter_s, float(np.max(np.abs(r))) * self.peak_s

    def statement(self, rate: FloatArray | None = None, unit: str = "deg") -> str:
        """The stamps in one sentence, with the floor they set on an output moving at ``rate`` when given.

        Parameters
        ----------
        rate : numpy.ndarray, optional
            The output's rate at each sample.
        unit : str
            The output's unit (``deg`` is printed °).

        Returns
        -------
        str
            One clause (empty for uniform stamps).
        """
        if not self.jitters:
            return ""
        step = (f", logged in steps of {1e3 * self.step_s:.3g} ms ({1e3 * self.rounding_s:.2g} ms rms of it)"
                if self.step_s is not None else "")
        text = (f"time stamps jitter {1e3 * self.scatter_s:.2g} ms rms (±{1e3 * self.peak_s:.2g} ms peak) about a "
                f"uniform {1e3 * self.interval_s:.4g} ms grid{step}")
        if rate is not None:
            rms, peak = self.floor(rate)
            u = "°" if unit == "deg" else f" {unit}"
            text += (f"; where the stamps are off the instants the output was sampled at, the error floor that sets is "
                     f"rate × jitter: {rms:.3g}{u} rms over the record, up to {peak:.3g}{u} on the fastest moves")
        return text

    def as_dict(self) -> dict[str, float | bool | list[dict[str, float]] | None]:
        """Plain values for JSON (ms; the gaps in s)."""
        return {"interval_ms": 1e3 * self.interval_s, "jitter_rms_ms": 1e3 * self.scatter_s,
                "jitter_peak_ms": 1e3 * self.peak_s, "step_ms": None if self.step_s is None else 1e3 * self.step_s,
                "jitters": self.jitters, "gaps": [g.as_dict() for g in self.gaps]}


def measure(time_s: FloatArray) -> Stamps:
    """The stamps' nominal interval, their scatter about it, their own step and their gaps (module docstring).

    Parameters
    ----------
    time_s : numpy.ndarray
        The logged stamps, s (increasing).

    Returns
    -------
    Stamps
        What they show.
    """
    t = np.asarray(time_s, dtype=float)
    n = t.size
    if n < 3:
        return Stamps(float(t[-1] - t[0]) if n == 2 else 0.0, 0.0, 0.0, None, n)
    gaps = find_gaps(t)
    parts = [(a, b) for a, b in stretches(n, gaps) if b - a >= 3]
    if not parts:
        return Stamps(float(np.median(np.diff(t))), 0.0, 0.0, None, n, gaps)
    med = float(np.median(np.diff(t)))
    line_dev, local_dev, slots, spans = [], [], 0.0, 0.0
    for a, b in parts:
        seg = t[a:b]
        k = np.concatenate([[0.0], np.cumsum(np.maximum(np.floor(np.diff(seg) / med + SKIP), 1.0))])
        slope, icpt = np.polyfit(k, seg, 1)
        line_dev.append(seg - (icpt + slope * k))
        slots, spans = slots + k[-1], spans + float(seg[-1] - seg[0])
        w = (k[1:-1] - k[:-2]) / (k[2:] - k[:-2])
        local_dev.append((seg[1:-1] - (seg[:-2] + w * (seg[2:] - seg[:-2]))) / np.sqrt(1.0 + w * w + (1.0 - w) ** 2))
    slope = spans / slots
    dev, local = np.concatenate(line_dev), np.concatenate(local_dev)
    scatter = float(np.sqrt(np.mean(dev * dev)))
    near = float(np.sqrt(np.mean(local * local)))
    if scatter > WANDER * near:
        dev, scatter = local, near
    peak = float(np.max(np.abs(dev)))
    tol = STEP_MATCH * max(float(np.max(np.abs(t))), 1.0)
    if scatter <= 1e-6 * slope:
        scatter = peak = 0.0
    step = next((s for s in STEPS_S if s < slope and np.all(np.abs(t / s - np.round(t / s)) * s <= max(tol, 1e-9))),
                None)
    return Stamps(float(slope), scatter, peak, step, n, gaps)


def output_rate(stamps: Stamps, y: FloatArray) -> FloatArray:
    """An output's rate on the uniform grid (smoothed over :data:`RATE_WINDOW_S`, at least 5 samples), unit/s.

    The derivative is taken on the grid, not the stamps: a jittery stamp would put its own error into it;
    each stretch between gaps on its own (none across a gap).

    Parameters
    ----------
    stamps : Stamps
        The record's stamps.
    y : numpy.ndarray
        The output, one value per stamp.

    Returns
    -------
    numpy.ndarray
        Its rate at each sample.
    """
    y = np.asarray(y, dtype=float)
    window = max(round(RATE_WINDOW_S / max(stamps.interval_s, 1e-9)) | 1, 5)
    out: FloatArray = np.zeros_like(y)
    for a, b in stretches(y.size, stamps.gaps):
        if b - a > window:
            out[a:b] = savgol_filter(y[a:b], window, 2, deriv=1, delta=stamps.interval_s)
        elif b - a > 1:
            out[a:b] = np.gradient(y[a:b], stamps.interval_s)
    return out


def timing_error(residual: FloatArray, sigma: float, rate: FloatArray) -> float:
    """The rms timing error that, with the noise floor ``sigma``, explains a residual's variance (0: none).

    The residual's square is regressed on ``rate²`` through ``sigma²``: ``e² ≈ σ² + σ_t²·rate²``.

    Parameters
    ----------
    residual : numpy.ndarray
        A model's residual, output units.
    sigma : float
        The output's noise floor.
    rate : numpy.ndarray
        The output's rate at the same samples.

    Returns
    -------
    float
        ``σ_t``, s (0 when the residual shows none).
    """
    x = np.asarray(rate, dtype=float) ** 2
    if not np.any(x):
        return 0.0
    e2 = np.asarray(residual, dtype=float) ** 2
    var_t = float(np.dot(x, e2 - sigma * sigma) / np.dot(x, x))
    return math.sqrt(var_t) if var_t > 0.0 else 0.0
