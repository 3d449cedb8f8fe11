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
"""

from __future__ import annotations

import math
from dataclasses import dataclass

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


@dataclass(frozen=True)
class Stamps:
    """The stamps' regularity (module docstring)."""

    interval_s: float
    """Nominal sample interval: the slope of the least-squares line through the stamps."""
    scatter_s: float
    """Rms of the stamps about that line (0: uniform)."""
    peak_s: float
    """Largest distance of a stamp from that line."""
    step_s: float | None
    """The stamps' own step (1 ms for integer-millisecond stamps), None when they have none."""
    samples: int

    @property
    def jitters(self) -> bool:
        """The stamps scatter about a uniform grid by more than a millionth of a sample."""
        return self.scatter_s > 1e-6 * self.interval_s

    @property
    def rounding_s(self) -> float:
        """The share of the scatter the stamps' own step accounts for (``step/√12``)."""
        return 0.0 if self.step_s is None else self.step_s / math.sqrt(12.0)

    def grid(self) -> FloatArray:
        """The uniform grid the stamps scatter about (the least-squares line), s from the first stamp."""
        return self.interval_s * np.arange(self.samples, dtype=float)

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

    def as_dict(self) -> dict[str, float | bool | None]:
        """Plain values for JSON (ms)."""
        return {"interval_ms": 1e3 * self.interval_s, "jitter_rms_ms": 1e3 * self.scatter_s,
                "jitter_peak_ms": 1e3 * self.peak_s, "step_ms": None if self.step_s is None else 1e3 * self.step_s,
                "jitters": self.jitters}


def measure(time_s: FloatArray) -> Stamps:
    """The stamps' nominal interval, their scatter about it and their own step (module docstring).

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
    k = np.arange(n, dtype=float)
    slope, icpt = np.polyfit(k, t, 1)
    dev = t - (icpt + slope * k)
    scatter = float(np.sqrt(np.mean(dev * dev)))
    peak = float(np.max(np.abs(dev)))
    tol = STEP_MATCH * max(float(np.max(np.abs(t))), 1.0)
    if scatter <= 1e-6 * slope:
        scatter = peak = 0.0
    step = next((s for s in STEPS_S if s < slope and np.all(np.abs(t / s - np.round(t / s)) * s <= max(tol, 1e-9))),
                None)
    return Stamps(float(slope), scatter, peak, step, n)


def output_rate(stamps: Stamps, y: FloatArray) -> FloatArray:
    """An output's rate on the uniform grid (smoothed over :data:`RATE_WINDOW_S`, at least 5 samples), unit/s.

    The derivative is taken on the grid, not the stamps: a jittery stamp would put its own error into it.

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
    if y.size <= window:
        return np.gradient(y, stamps.interval_s) if y.size > 1 else np.zeros_like(y)
    out: FloatArray = savgol_filter(y, window, 2, deriv=1, delta=stamps.interval_s)
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
