"""The error a record's output settles to at the end of each hold of its command: what a dead band may explain.

A static threshold (a dead band on the servo's error) or a free play stops the output short of its
command by up to its width. A record whose output settles on the command leaves no room for one: a
threshold larger than the settled error it would explain is a proxy for something else (a friction,
a slow tail), and identification does not add it (:mod:`ema_sim.identify.effects`).

The settled error of one hold is the median of output − command over the last :data:`TAIL` of it.
A dead band stops driving the output once the error enters it; the output coasts inward from the edge,
so every settled error lies within the band's half width and the largest of them is the closest look
at it the record has. The holds therefore show the band *at least* that wide, and no wider: an edge
beyond every hold (where the drive stopped before the coast) is a figure no hold shows. The point
figure a threshold may take (:attr:`Settled.bound`) is the largest settled error plus half the
output's count (an output in counts cannot settle closer than that). That largest figure is a median
of n samples, so its own uncertainty is the tail's scatter × √(π/2)/√n (:attr:`Settled.max_se`), not
a multiple of one sample's noise: it is said beside the bound ("at least … ± …"), never added to it. A threshold the
record pays for is fitted within the bound (:attr:`ema_sim.identify.problem.Problem.caps`); when the
fit asks for more it is held there and reported as a lower bound ("at least"), with its evidence.
"""

from __future__ import annotations

from collections.abc import Callable
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
MAD_TO_SIGMA = 1.4826
"""A normal scatter's standard deviation over its median absolute deviation."""
MEDIAN_EFFICIENCY = 1.2533
"""A median's standard error over the mean's, for Gaussian noise (√(π/2))."""


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
    max_se: float = 0.0
    """Standard error of the largest one: its hold's tail scatter × √(π/2) / √(its samples)."""

    @property
    def bound(self) -> float:
        """The widest dead band (half width) the holds show: the largest settled error + half a count."""
        return self.max_abs + 0.5 * self.count

    def held(self, fmt: Callable[[float], str], unit: str, asked: float | None = None) -> str:
        """The evidence of a dead band the fit wanted wider, held at :attr:`bound`: a lower bound, with what shows it.

        Parameters
        ----------
        fmt : callable
            How a figure is written.
        unit : str
            The record's unit.
        asked : float, optional
            The half width the fit reaches without the bound (the edge where the drive stops, in the model).
        """
        se = f" ± {fmt(self.max_se)}" if self.max_se > 0.0 else ""
        wider = f"{fmt(asked)} {unit}" if asked is not None and asked > self.bound else "a wider one"
        return (f"at least {fmt(self.bound)}{se} {unit}, held there: the largest error the output settles to at the "
                f"end of the command's holds ({fmt(self.max_abs)} {unit}, + half a count) shows the band that wide; "
                f"the fit asked for {wider}, which no hold shows (an output that coasts into its band stops "
                "inside it)")


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
        The settled error, its largest value's standard error and how many holds it was read on.
    """
    spans = _holds(np.asarray(time_s, dtype=float), np.asarray(command, dtype=float))
    if len(spans) < MIN_HOLDS:
        return None
    errs, ses = [], []
    for a, b in spans:
        k = a + int((1.0 - TAIL) * (b - a))
        e = output[k:b] - command[k:b]
        mid = float(np.median(e))
        errs.append(abs(mid))
        ses.append(MEDIAN_EFFICIENCY * MAD_TO_SIGMA * float(np.median(np.abs(e - mid))) / np.sqrt(e.size))
    top = int(np.argmax(errs))
    return Settled(float(np.median(errs)), errs[top], len(errs), float(count or 0.0), float(ses[top]))
