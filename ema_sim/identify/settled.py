"""The error a record's output settles to at the end of each hold of its command: what a dead band may explain.

A static threshold (a dead band on the servo's error) or a free play stops the output short of its
command by up to its width. A record whose output settles on the command leaves no room for one: a
threshold larger than the settled error it would explain is a proxy for something else (a friction,
a slow tail), and identification does not add it (:mod:`ema_sim.identify.effects`).

The settled error of one hold is the median of output − command over the last :data:`TAIL` of it.
A static threshold (a dead band on the servo's error) stops driving the output once the error enters
its band; the output coasts inward from the edge, so every settled error lies within the band's half
width and the largest of them is the closest look at it. A band may be as wide as the largest settled
error, plus half the output's count (an output in counts cannot settle closer than that) and
:data:`NOISE_MARGIN` times the noise floor beyond the count's own share (q/√12, which the half count
already covers). A threshold the record pays for is fitted within this bound
(:attr:`ema_sim.identify.problem.Problem.caps`) and said to be held there when the fit asked for more.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
MIN_HOLD_S = 0.4
"""A hold shorter than this is no rest (the output may still be moving)."""
TAIL = 0.3
"""The share of each hold, at its end, the settled error is read on."""
MIN_HOLDS = 3
"""Fewer holds than this say nothing about where the output settles."""
NOISE_MARGIN = 3.0
"""Noise floors (beyond the count's share) a settled error may be read short by."""


@dataclass(frozen=True)
class Settled:
    """Where the output settles at the end of the command's holds."""

    median_abs: float
    """Median over holds of |median(output − command)| on each hold's tail, in the record's unit."""
    max_abs: float
    """The largest of them."""
    holds: int
    """How many holds it was read on."""
    count: float
    """The output's count (0: continuous), in the record's unit."""

    def limit(self, noise: float) -> float:
        """The widest dead band (half width) the settled errors can explain (module docstring).

        Parameters
        ----------
        noise : float
            The output's noise floor, in the record's unit.
        """
        beyond_count = math.sqrt(max(noise * noise - self.count * self.count / 12.0, 0.0))
        return self.max_abs + 0.5 * self.count + NOISE_MARGIN * beyond_count


def _holds(time_s: FloatArray, command: FloatArray) -> list[tuple[int, int]]:
    """Index ranges (start, stop) where the command stays at one value for at least :data:`MIN_HOLD_S`."""
    change = np.flatnonzero(np.diff(command) != 0.0) + 1
    starts = np.concatenate([[0], change])
    stops = np.concatenate([change, [command.size]])
    return [(int(a), int(b)) for a, b in zip(starts, stops, strict=True)
            if b - a >= 2 and time_s[b - 1] - time_s[a] >= MIN_HOLD_S]


def settled_error(time_s: FloatArray, command: FloatArray, output: FloatArray, count: float | None = None
                  ) -> Settled | None:
    """The record's settled error (module docstring), None when it has fewer than :data:`MIN_HOLDS` holds.

    Parameters
    ----------
    time_s : numpy.ndarray
        Sample times, s.
    command : numpy.ndarray
        The command as logged.
    output : numpy.ndarray
        The output, in the command's unit.
    count : float, optional
        The output's count (resolution); None or 0 for a continuous output.

    Returns
    -------
    Settled or None
        The settled error and how many holds it was read on.
    """
    spans = _holds(np.asarray(time_s, dtype=float), np.asarray(command, dtype=float))
    if len(spans) < MIN_HOLDS:
        return None
    errs = []
    for a, b in spans:
        k = a + int((1.0 - TAIL) * (b - a))
        errs.append(abs(float(np.median(output[k:b] - command[k:b]))))
    return Settled(float(np.median(errs)), float(np.max(errs)), len(errs), float(count or 0.0))
