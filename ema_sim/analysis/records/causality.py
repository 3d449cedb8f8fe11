"""The output's lag behind its command, under each way the command may have been logged: a servo never leads.

For a move of the command from one rest to the next, normalise the command and the output by their own
change (``p_u`` and ``p_y`` each run from 0 to 1); the **lag** is ``∫(p_u − p_y) dt``, the distance between
the centroids of the two transitions. For a servo of unity static gain it is its equivalent delay
``−G'(0)/G(0)`` (``2ζ/ωn`` plus any transport delay for a second order), and a rate, current or
acceleration limit only adds to it. It is never negative: a servo does not lead its command.

How much of the command's integral there is depends on how the command was logged:

* **held** (the data contract): the actuator saw ``u[k]`` from ``t[k]`` to ``t[k+1]``, a left Riemann sum;
* **sampled** from a running demand: the demand between samples is best taken as the straight line
  between them, a trapezoid.

On the record's own stamps the two differ by half a sample interval times the move (exactly, jitter
included), so a record yields both lags at once. A lag that is negative under one assumption beyond its
uncertainty refutes that assumption; negative under both, the logged command is not what the actuator
followed (the demand logged is itself a filtered target, the log was resampled, or the command's column
is stamped late against the output's).

Records without rest-to-rest moves (a sine or a sweep) are cut into windows and the lag is the pure
delay that best aligns the output with the linearly interpolated command (offset free, the gain positive:
a servo follows its command, never its opposite), its held counterpart half a sample less: the equivalent
delay at the frequencies the record excites. The search reaches :data:`MAX_LAG_S` either way, beyond a
servo's equivalent delay (a transport delay and its loop's lag). A window whose command is nearly one
frequency aligns about as well a whole period earlier or later: its lag is known only modulo that period,
so it decides nothing (:data:`AMBIGUOUS_SHARE`), and a sine dwell whose lag exceeds half its period is
never taken for a lead.

The uncertainty is the moves' (or windows') spread over √n: it holds the noise, the stamps' jitter and
any dependence on amplitude or direction. Fewer than :data:`MIN_MOVES` moves (or windows) decide nothing.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ema_sim.analysis.records.series import hold_tolerance, holds
from ema_sim.jsontypes import JsonObject

FloatArray = NDArray[np.float64]

REST_S = 0.05
"""A rest of the command lasts at least this long (and 3 samples)."""
MIN_MOVES = 3
"""Fewest moves (or windows) whose lags decide anything."""
MOVE_BANDS = 10.0
"""A move's change is at least this many of the output's detection bands (so its lag is read beyond the noise)."""
SETTLE_SHARE = 0.25
"""The output must have settled over the last share of the rest that ends a move (its level read there)."""
SIGNIFICANCE_SIGMAS = 3.0
"""A lag below zero by more than this many standard errors is a lead."""
MATERIAL_SHARE = 0.1
"""...and by more than this share of a sample interval: a lead smaller than that is no evidence of a hold."""
WINDOW_S = 2.0
"""Windows of a record without rests, for the delay fit (at least :data:`MIN_MOVES` of them)."""
MAX_LAG_S = 0.25
"""The delay fit's search: up to this lag either way, s (a few times a servo's equivalent delay)."""
COARSE_STEPS = 25
"""The delay fit's coarse search: this many steps each way before each minimum is refined to a sample."""
AMBIGUOUS_SHARE = 0.01
"""A window is ambiguous when another alignment leaves less than twice the best's unexplained share of the
output's variance plus this share: a sine dwell's alignments a period apart leave the same."""


@dataclass(frozen=True)
class Causality:
    """The output's lag behind the command under each assumption, and what that says of the logging.

    Parameters
    ----------
    lag_held_s : float or None
        Mean lag of the output behind the command taken as held (None: not measured).
    lag_sampled_s : float or None
        Mean lag behind the command taken as sampled and interpolated linearly.
    sigma_s : float or None
        Standard error of either lag (the moves' spread over √n).
    count : int
        Moves (or windows) measured.
    method : str
        ``moves`` (rest-to-rest moves) or ``windows`` (the delay fit on windows), or ``none``.
    sample_s : float
        The record's median sample interval, s.
    """

    lag_held_s: float | None
    lag_sampled_s: float | None
    sigma_s: float | None
    count: int
    method: str
    sample_s: float

    @property
    def measured(self) -> bool:
        """Whether enough moves (or windows) were measured to judge."""
        return self.lag_held_s is not None and self.sigma_s is not None and self.count >= MIN_MOVES

    def _leads(self, lag: float | None) -> bool:
        if not self.measured or lag is None or self.sigma_s is None:
            return False
        return lag < -max(SIGNIFICANCE_SIGMAS * self.sigma_s, MATERIAL_SHARE * self.sample_s)

    @property
    def held_leads(self) -> bool:
        """The output would lead a held command beyond its uncertainty: held is refuted."""
        return self._leads(self.lag_held_s)

    @property
    def sampled_leads(self) -> bool:
        """The output leads even the command taken as sampled: the logged command is not what it followed."""
        return self._leads(self.lag_sampled_s)

    @property
    def statement(self) -> str:
        """The lags in one sentence."""
        if not self.measured or self.lag_held_s is None or self.lag_sampled_s is None:
            return f"the output's lag behind the command not measured ({self.count} move(s) from rest to rest)"
        what = "rest-to-rest moves" if self.method == "moves" else f"windows of {WINDOW_S:g} s (delay fit)"
        se = 1e3 * (self.sigma_s or 0.0)
        return (f"the output lags the command by {1e3 * self.lag_held_s:+.2f} ± {se:.2g} ms taken as held, "
                f"{1e3 * self.lag_sampled_s:+.2f} ± {se:.2g} ms taken as sampled ({self.count} {what})")

    def as_dict(self) -> JsonObject:
        """Plain values for JSON.

        Returns
        -------
        dict
            The two lags, their standard error, the count, the method and the verdicts.
        """
        return {"lag_held_s": self.lag_held_s, "lag_sampled_s": self.lag_sampled_s, "sigma_s": self.sigma_s,
                "count": self.count, "method": self.method, "held_leads": self.held_leads,
                "sampled_leads": self.sampled_leads}


def _trapezoid(t: FloatArray, x: FloatArray) -> float:
    return float(np.sum(0.5 * (x[1:] + x[:-1]) * np.diff(t)))


def _left(t: FloatArray, x: FloatArray) -> float:
    return float(np.sum(x[:-1] * np.diff(t)))


def move_lags(time_s: FloatArray, command: FloatArray, output: FloatArray, band: float
              ) -> tuple[FloatArray, FloatArray]:
    """The lag of every rest-to-rest move under each assumption (module docstring).

    Parameters
    ----------
    time_s : numpy.ndarray
        The record's own stamps, s.
    command : numpy.ndarray
        The logged command.
    output : numpy.ndarray
        The output (the LVDT position when there is one).
    band : float
        The output's detection band (a few noise floors, or counts).

    Returns
    -------
    tuple of numpy.ndarray
        The moves' lags taken as held and as sampled, s.
    """
    t = np.asarray(time_s, dtype=float)
    u = np.asarray(command, dtype=float)
    y = np.asarray(output, dtype=float)
    dt = float(np.median(np.diff(t)))
    rests = holds(u, max(3, round(REST_S / dt)), hold_tolerance(u))
    held: list[float] = []
    sampled: list[float] = []
    for a, b in itertools.pairwise(rests):
        du = b.value - a.value
        if abs(du) < MOVE_BANDS * band:
            continue
        start = a.start + a.length // 2
        tail = max(2, round(SETTLE_SHARE * b.length))
        y0 = float(np.mean(y[start:a.stop]))
        y1 = float(np.mean(y[b.stop - tail:b.stop]))
        dy = y1 - y0
        if dy * du <= 0.0 or abs(dy) < 0.5 * abs(du):
            continue  # the output did not follow this move (a stop, a dead band): no lag to read
        before = y[start:a.stop]
        after = y[b.stop - tail:b.stop]
        if np.ptp(before) > 2.0 * band + 0.02 * abs(dy) or np.ptp(after) > 2.0 * band + 0.02 * abs(dy):
            continue  # not at rest at either end
        sl = slice(start, b.stop)
        ts, pu, py = t[sl], (u[sl] - a.value) / du, (y[sl] - y0) / dy
        ty = _trapezoid(ts, py)
        held.append(_left(ts, pu) - ty)
        sampled.append(_trapezoid(ts, pu) - ty)
    return np.asarray(held), np.asarray(sampled)


def _delay_fit(t: FloatArray, u: FloatArray, y: FloatArray, dt: float) -> float | None:
    """The pure delay (s) that best aligns ``y`` with ``u`` interpolated linearly (module docstring).

    A coarse search (:data:`COARSE_STEPS` steps each way), each of its minima refined sample by sample. None when
    the command does not move, the best alignment is at the search's edge, or another alignment leaves nearly as
    little unexplained (:data:`AMBIGUOUS_SHARE`).
    """
    if np.ptp(u) <= 0.0:
        return None
    reach = max(1, round(MAX_LAG_S / dt))
    inner = (t >= t[0] + reach * dt) & (t <= t[-1] - reach * dt)
    if inner.sum() < 10:
        return None
    ti, yc = t[inner], y[inner] - float(np.mean(y[inner]))
    total = float(np.dot(yc, yc))
    if total <= 0.0:
        return None

    def unexplained(k: int) -> float:
        """The share of the output's variance a delay of ``k`` samples leaves (a positive gain only)."""
        x = np.interp(ti - k * dt, t, u)
        x -= float(np.mean(x))
        cov, var = float(np.dot(x, yc)), float(np.dot(x, x))
        return 1.0 - cov * cov / var / total if cov > 0.0 and var > 0.0 else 1.0

    step = max(1, reach // COARSE_STEPS)
    grid = np.arange(-reach, reach + 1, step)
    coarse = np.array([unexplained(int(k)) for k in grid])
    inside = (coarse[1:-1] < coarse[:-2]) & (coarse[1:-1] <= coarse[2:])
    minima = [*(np.flatnonzero(inside) + 1).tolist(), 0, grid.size - 1]  # an edge may hide a minimum beyond it

    def refined(m: int) -> tuple[int, float]:
        ks = range(max(-reach, int(grid[m]) - step), min(reach, int(grid[m]) + step) + 1)
        return min(((k, unexplained(k)) for k in ks), key=lambda kc: kc[1])

    ends = [refined(m) for m in minima]
    best_k, best = min(ends, key=lambda kc: kc[1])
    if abs(best_k) >= reach or best >= 1.0:
        return None  # no minimum inside the search
    if any(abs(k - best_k) > step and c < 2.0 * best + AMBIGUOUS_SHARE for k, c in ends):
        return None  # as good a whole period away: the lag is known only modulo it
    c0, c2 = unexplained(best_k - 1), unexplained(best_k + 1)
    den = c0 - 2.0 * best + c2
    shift = 0.5 * (c0 - c2) / den if den > 0.0 else 0.0
    return float((best_k + shift) * dt)


def window_lags(time_s: FloatArray, command: FloatArray, output: FloatArray) -> FloatArray:
    """The delay (s) aligning the output with the linearly interpolated command, window by window.

    Parameters
    ----------
    time_s : numpy.ndarray
        The record's own stamps, s.
    command : numpy.ndarray
        The logged command.
    output : numpy.ndarray
        The output.

    Returns
    -------
    numpy.ndarray
        One delay per window in which the command moves and a minimum is found (taken as sampled).
    """
    t = np.asarray(time_s, dtype=float)
    u = np.asarray(command, dtype=float)
    y = np.asarray(output, dtype=float)
    dt = float(np.median(np.diff(t)))
    span = float(t[-1] - t[0])
    n = max(MIN_MOVES, int(span // WINDOW_S))
    out = []
    for idx in np.array_split(np.arange(t.size), n):
        if idx.size * dt < 4.0 * MAX_LAG_S:
            continue
        d = _delay_fit(t[idx], u[idx], y[idx], dt)
        if d is not None:
            out.append(d)
    return np.asarray(out)


def measure(time_s: FloatArray, command: FloatArray, output: FloatArray, band: float) -> Causality:
    """The output's lag behind the command under both assumptions (module docstring).

    Parameters
    ----------
    time_s : numpy.ndarray
        The record's own stamps, s.
    command : numpy.ndarray
        The logged command.
    output : numpy.ndarray
        The output.
    band : float
        The output's detection band.

    Returns
    -------
    Causality
        The lags, from the rest-to-rest moves when there are enough, else from windows.
    """
    t = np.asarray(time_s, dtype=float)
    dt = float(np.median(np.diff(t)))
    held, sampled = move_lags(t, command, output, band)
    method = "moves"
    if held.size < MIN_MOVES:
        sampled = window_lags(t, command, output)
        method = "windows"
        # the held command is the interpolated one delayed by half a sample on average
        held = sampled - 0.5 * dt
    if sampled.size < MIN_MOVES:
        return Causality(None, None, None, int(sampled.size), "none", dt)
    sigma = float(np.std(sampled, ddof=1) / math.sqrt(sampled.size))
    sigma_h = float(np.std(held, ddof=1) / math.sqrt(held.size))
    return Causality(float(np.mean(held)), float(np.mean(sampled)), max(sigma, sigma_h), int(sampled.size), method,
                     dt)
