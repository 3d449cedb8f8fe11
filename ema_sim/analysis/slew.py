"""The slope of the output's constant-rate moves, measured as a person would with a ruler.

A rate-limited move is a straight line between two rests that the command outran: the output crosses
the middle of its travel (20 % to 80 %) at one rate while the command moved faster. Each move of the
output is found from its own motion (a run of samples moving one way faster than a tenth of the
record's peak rate), a line is fitted to its middle on the record's own time stamps, and the move
counts as rate-limited when no sample of that middle departs from the line by more than
:data:`STRAIGHT` of the move's travel (and the noise allows) and the command moved at least
:data:`OUTRUN` times faster in the same stretch (a step, or a profile faster than the actuator; a
triangle the actuator follows is straight too, but is the command's own slope). The slew rate is the
median slope of those moves, per direction and overall, with the moves' spread as its uncertainty.
``ema identify`` restarts a runaway rate-limit fit from it and says when its fitted limit disagrees.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
MOVING = 0.1
"""A sample moves when its rate exceeds this share of the record's peak rate (99th percentile)."""
STRAIGHT = 0.03
"""The middle of a constant-rate move stays within this share of its travel of a straight line."""
MIN_SAMPLES = 4
"""Fewest samples in a move's middle for its slope to be read."""
OUTRUN = 1.05
"""The command's fastest rate in a move's stretch over the output's slope, for the move to be rate-limited."""
LEAD_S = 0.05
"""How far before the output moves its command is looked at (the delay between a step and the motion)."""
AGREE = 0.1
"""A rate limit within this share of the measured slope agrees with it."""


@dataclass(frozen=True)
class Slew:
    """The slope of the rate-limited moves.

    Parameters
    ----------
    rate : float or None
        Median slope of every rate-limited move (None: no move is).
    up, down : float or None
        The same over positive and negative moves (magnitudes).
    sigma : float or None
        Spread of the moves' slopes over √moves (None with fewer than two moves).
    moves : int
        Rate-limited moves found.
    seen : int
        Moves examined.
    """

    rate: float | None
    up: float | None
    down: float | None
    sigma: float | None
    moves: int
    seen: int

    def as_dict(self) -> dict[str, float | int | None]:
        """Plain values for JSON.

        Returns
        -------
        dict
            The slopes, their spread and the counts.
        """
        return {"rate": self.rate, "positive": self.up, "negative": self.down, "sigma": self.sigma,
                "rate_limited_moves": self.moves, "moves": self.seen}


def _runs(moving: NDArray[np.bool_], sign: FloatArray) -> list[tuple[int, int]]:
    """Index ranges [a, b) where the output moves one way without a stop."""
    out = []
    n = moving.size
    i = 0
    while i < n:
        if not moving[i]:
            i += 1
            continue
        j = i
        while j < n and moving[j] and sign[j] == sign[i]:
            j += 1
        out.append((i, j))
        i = j
    return out


def measure(time_s: FloatArray, command: FloatArray, y: FloatArray, noise: float = 0.0) -> Slew:
    """The slew rate of ``y`` from its rate-limited moves (module docstring).

    Parameters
    ----------
    time_s : numpy.ndarray
        Sample times (uniform or not), s.
    command : numpy.ndarray
        The command (what the output was asked to follow).
    y : numpy.ndarray
        The output.
    noise : float
        Its noise floor (a move's straightness is judged beyond it).

    Returns
    -------
    Slew
        Median slopes, spread and counts.
    """
    t = np.asarray(time_s, dtype=float)
    u = np.asarray(command, dtype=float)
    y = np.asarray(y, dtype=float)
    if t.size < 3 * MIN_SAMPLES:
        return Slew(None, None, None, None, 0, 0)
    rate = np.gradient(y, t)
    peak = float(np.percentile(np.abs(rate), 99))
    if peak <= 0.0:
        return Slew(None, None, None, None, 0, 0)
    moving = np.abs(rate) > MOVING * peak
    slopes: list[float] = []
    seen = 0
    for a, b in _runs(moving, np.sign(rate)):
        # the move from the rest before it to the rest after it
        a0, b0 = max(a - 1, 0), min(b, y.size - 1)
        travel = float(y[b0] - y[a0])
        if abs(travel) < max(20.0 * noise, 1e-9):
            continue
        seen += 1
        frac = (y[a0:b0 + 1] - y[a0]) / travel
        mid = np.flatnonzero((frac >= 0.2) & (frac <= 0.8)) + a0
        if mid.size < MIN_SAMPLES:
            continue
        tm, ym = t[mid], y[mid]
        slope, icpt = np.polyfit(tm, ym, 1)
        dev = float(np.max(np.abs(ym - (slope * tm + icpt))))
        if dev > STRAIGHT * abs(travel) + 3.0 * noise or np.sign(slope) != np.sign(travel):
            continue
        lead = int(np.searchsorted(t, t[a0] - LEAD_S))
        stretch = slice(lead, b0 + 1)
        asked = float(np.max(np.abs(np.diff(u[stretch]) / np.diff(t[stretch])), initial=0.0))
        if asked >= OUTRUN * abs(slope):
            slopes.append(float(slope))
    if not slopes:
        return Slew(None, None, None, None, 0, seen)
    mags = np.abs(np.array(slopes))
    ups = [abs(s) for s in slopes if s > 0]
    downs = [abs(s) for s in slopes if s < 0]
    sigma = float(np.std(mags, ddof=1) / math.sqrt(mags.size)) if mags.size > 1 else None
    return Slew(float(np.median(mags)), float(np.median(ups)) if ups else None,
                float(np.median(downs)) if downs else None, sigma, len(slopes), seen)
