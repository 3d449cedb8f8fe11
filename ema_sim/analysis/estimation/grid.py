"""The count grid of a logged signal: every value a whole number of counts ``q`` (plus an offset).

A position read from an encoder, or from an A/D converter through a linear calibration, can only
take the values ``offset + k·q``. :func:`ema_sim.analysis.estimation.noise.detect_resolution` finds ``q`` from
the signal's *changes* (the smallest ones are one count); it needs changes of one count, and a drive
that moves two counts at a time, or a still output that never toggles, has none. This module reads
the grid from the *values* themselves, as a person would who sees ``3.00, 3.01, 3.07`` in the file:

* the **decimal grid**: the fewest decimals that write every value (within float tolerance,
  :data:`FLOAT_TOLERANCE` of the last digit): ``3.00, 3.01, 3.07`` are hundredths;
* the **spacing grid**: the smallest gap between two distinct values, when every value lies on
  multiples of it about a common offset (within :data:`FLOAT_TOLERANCE` of it): counts that are no
  decimal (0.02125° from a calibration), or a grid coarser than the printing;
* the spacing grid is the count when it is no decimal grid's multiple, or when the values populate
  enough of it that landing on its multiples by chance is unlikely (``k^(levels − 1)`` ≥
  :data:`CHANCE` for a spacing of ``k`` decimal steps: three levels four hundredths apart say the
  count is a hundredth used sparsely, not 0.04); else the decimal grid is;
* the **coarse grid** (:func:`coarse_grid`): a count coarser than the printing and no multiple of its
  last digit, such as an encoder of 6600 counts a turn (0.0545°) logged to 0.01°, whose values step
  0.05 or 0.06 apart. No value is a whole number of counts once printed, but every one lies within
  half a digit of ``offset + k·q``: ``q`` is fitted to the distinct values by least squares on their
  count numbers ``k``, and is the count when every value lies within :data:`COARSE_SLACK` of a digit of
  it and the values populate it beyond chance (a value lands that close to a grid of ``q`` with odds
  ``2·COARSE_SLACK·digit/q``; ``(levels − 2)`` of them, the fit's two parameters aside, must reach
  :data:`CHANCE`);
* at least :data:`MIN_LEVELS` distinct values (an output toggling between two says nothing of its
  count), a count no finer than :data:`MIN_RELATIVE` of the values' scale (finer is the printing's),
  and a grid only matters when the signal sits on it: at least :data:`MIN_REPEATS` of the
  consecutive samples repeat a value exactly, or the distinct values are at most half the samples (a
  continuous signal printed to six decimals lies on a grid of 1e-6 too, but never repeats a value).

The count's quantization error is uniform over a count, ``q/√12`` standard deviation: no noise floor
stated for such a signal is below that (:func:`ema_sim.analysis.estimation.noise.output_noise`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

FLOAT_TOLERANCE = 1e-3
"""A value within this share of a count of a whole number of counts is on the grid."""
MIN_REPEATS = 0.05
"""Share of consecutive samples that must repeat a value exactly for a grid to matter."""
MIN_VALUES = 20
"""Fewer samples tell nothing of a grid."""
MIN_LEVELS = 3
"""Fewer distinct values tell nothing of a count (two levels of a toggling output are one gap apart, whatever
the count is)."""
MAX_DECIMALS = 12
CHANCE = 1000.0
"""A spacing of k decimal steps is the count when k^(levels − 1) reaches this (the odds against chance)."""
MIN_RELATIVE = 1e-6
"""A grid finer than this share of the signal's scale is the printing's, no sensor's count."""
COARSE_MIN_STEPS = 1.5
"""A coarse grid's smallest gap between values spans at least this many digits (one digit apart: the printing's)."""
COARSE_SLACK = 0.6
"""A value within this share of a digit of a coarse grid's count lies on it (the printing rounds by half a digit;
the fitted offset and count add a little)."""


@dataclass(frozen=True)
class Grid:
    """A signal's count grid.

    Parameters
    ----------
    q : float
        The count, in the signal's unit.
    offset : float
        The grid's offset (the values are ``offset + k·q``), within ``[0, q)``.
    levels : int
        Distinct values the signal takes.
    repeats : float
        Share of consecutive samples that repeat a value.
    statement : str
        How it was found, in one sentence.
    """

    q: float
    offset: float
    levels: int
    repeats: float
    statement: str

    @property
    def quantization(self) -> float:
        """Standard deviation of the rounding to whole counts, ``q/√12``."""
        return self.q / float(np.sqrt(12.0))


def _on_grid(values: FloatArray, q: float) -> tuple[bool, float]:
    """Whether every value is ``offset + k·q`` within FLOAT_TOLERANCE of a count, and the offset."""
    phase = np.mod(values / q, 1.0)
    d = np.abs(phase - float(phase[0]))
    d = np.minimum(d, 1.0 - d)
    offset = float(np.mod(float(phase[0]) * q, q))
    if min(offset, q - offset) <= FLOAT_TOLERANCE * q:
        offset = 0.0
    return bool(np.all(d <= FLOAT_TOLERANCE)), offset


def decimal_grid(values: FloatArray) -> float | None:
    """The finest power of ten that every value is a whole multiple of (the printing's last digit).

    Parameters
    ----------
    values : numpy.ndarray
        The values.

    Returns
    -------
    float or None
        ``10^-n`` for the fewest decimals ``n`` (up to 12) that write every value, or None.
    """
    for n in range(MAX_DECIMALS + 1):
        scaled = values * 10.0**n
        if np.all(np.abs(scaled - np.round(scaled)) <= FLOAT_TOLERANCE):
            return float(10.0**-n)
    return None


def coarse_grid(levels: FloatArray, digit: float) -> tuple[float, float] | None:
    """A count coarser than the printing's last digit and no multiple of it (module docstring), or None.

    Parameters
    ----------
    levels : numpy.ndarray
        The distinct values, sorted.
    digit : float
        The printing's last digit (:func:`decimal_grid`).

    Returns
    -------
    tuple or None
        The count ``q`` and the offset (within ``[0, q)``) of the grid every value lies on within
        :data:`COARSE_SLACK` of a digit, or None.
    """
    gaps = np.diff(levels)
    if levels.size < MIN_LEVELS or float(np.min(gaps)) < COARSE_MIN_STEPS * digit:
        return None
    smallest = gaps[gaps <= float(np.min(gaps)) + digit * (1.0 + FLOAT_TOLERANCE)]
    q = float(np.mean(smallest))  # one count, printed as the digits either side of it
    x = levels - levels[0]
    k = np.round(x / q)
    for _ in range(4):  # refit: the count numbers from the count, the count from the count numbers
        a, q = np.linalg.lstsq(np.column_stack([np.ones_like(k), k]), x, rcond=None)[0]
        k_new = np.round((x - a) / q)
        if np.array_equal(k_new, k):
            break
        k = k_new
    resid = x - (a + q * k)
    if (q < COARSE_MIN_STEPS * digit or np.any(np.diff(k) < 1) or float(np.max(np.abs(resid))) > COARSE_SLACK * digit
            or (levels.size - 2) * float(np.log(q / (2.0 * COARSE_SLACK * digit))) < float(np.log(CHANCE))):
        return None
    offset = float(np.mod(levels[0] + a, q))
    return float(q), (0.0 if min(offset, q - offset) <= COARSE_SLACK * digit else offset)


def value_grid(y: FloatArray) -> Grid | None:
    """The count grid the values of ``y`` sit on (module docstring), or None.

    Parameters
    ----------
    y : numpy.ndarray
        The signal as logged.

    Returns
    -------
    Grid or None
        The grid; None for a continuous signal, one too short or too still to tell, or one that never
        repeats a value.
    """
    y = np.asarray(y, dtype=float)
    if y.size < MIN_VALUES or not np.all(np.isfinite(y)):
        return None
    levels = np.unique(y)
    if levels.size < MIN_LEVELS:
        return None
    repeats = float(np.mean(np.diff(y) == 0.0))
    if repeats < MIN_REPEATS and levels.size > y.size // 2:
        return None
    base = decimal_grid(levels)
    gaps = np.diff(levels)
    spacing = float(np.min(gaps[gaps > (base or 0.0) * FLOAT_TOLERANCE])) if np.any(gaps > 0) else None
    q, offset, how, within = None, 0.0, "", "within float tolerance"
    if spacing is not None:
        ok, off = _on_grid(levels, spacing)
        k = spacing / base if base else float("inf")
        whole = base is not None and abs(k - round(k)) <= FLOAT_TOLERANCE * k
        if ok and (not whole or round(k) == 1 or (levels.size - 1) * float(np.log(round(k))) >= np.log(CHANCE)):
            q, offset, how = spacing, off, "on multiples of the smallest gap between values"
    if q is None and base is not None:
        coarse = coarse_grid(levels, base)
        if coarse is not None:
            q, offset = coarse
            how = f"a count coarser than the printing's {base:g}, fitted to the values"
            within = f"within {COARSE_SLACK:g} of a printed digit"
        else:
            q, how = base, "written with the same last decimal"
    scale = max(float(np.max(np.abs(levels))), float(np.ptp(levels)))
    if q is None or q < MIN_RELATIVE * scale:
        return None
    q = float(f"{q:.10g}")
    offset = float(f"{offset:.10g}")
    where = f" + {offset:g}" if offset else ""
    return Grid(q, offset, int(levels.size), repeats,
                f"every value lies on multiples of {q:g}{where} ({how}, {within}); {levels.size} "
                f"distinct values, {100 * repeats:.0f} % of the samples repeat the one before")
