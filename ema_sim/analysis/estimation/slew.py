"""The slope of the output's constant-rate moves, measured as a person would with a ruler.

A rate-limited move is a straight line between two rests that the command outran: the output crosses
its travel at one rate while the command moved faster. Each move of the output is found from its own
motion (a run of samples moving one way faster than :data:`MOVING` of the record's peak rate) and
read on the record's own time stamps. It counts as rate-limited when

* it is **long enough** for its straightness to be judged beyond the noise (:data:`STRAIGHT` of its
  travel at least six noise floors: a third of a degree is too short to tell a rate limit from a
  linear response at the 0.003° of an inclinometer);
* it is **straight well beyond its middle**, from 10 % to 90 % of its travel: no sample there departs
  from a line through them by more than :data:`STRAIGHT` of the travel (and the noise allows). A
  linear second order's step is nearly straight through its middle, 1-3 % off a line for ζ
  0.4-0.7, but 2.6-6 % off from 10 % to 90 %, where a rate-limited move of ten times its corners'
  travel stays within 2 %;
* it holds **one rate**: the slopes over the three thirds of that stretch agree within :data:`EVEN`
  (three samples a third at least). A linear step slows through it, by 20-130 % from its first third
  to its last for ζ 0.6-1, and a lightly damped one speeds up; a sine's swing, straight to within a
  few per cent from 10 % to 90 % and even between its halves, is 22 % faster in its middle third
  than in its outer ones;
* it runs **from rest to rest**: just before and just after it the output moves at most
  :data:`REST` of its slope (a slow swing's middle, fast enough to count against the record's peak
  rate, is no move of its own);
* the **command outran it**: its fastest mean rate over the time the output takes through the
  middle (20-80 %) of its move reaches :data:`OUTRUN` times the output's slope there (a step, or a
  profile faster than the actuator; a triangle the actuator follows is straight too, but is the
  command's own slope). Averaged over that time, neither a jittery stamp nor a command held in
  frames makes a command look faster than it is.

The slope is read on the middle 20-80 % of each such move. The slew rate is the median slope of those
moves, per direction and overall, with the moves' spread as its uncertainty. ``ema analyze`` reports
it for the record (and a periodic test's stretch, and as the steps' large-amplitude slew rate);
``ema identify`` restarts a runaway rate-limit fit from it and says when its fitted limit disagrees.

A record whose moves fail those tests (a sweep with no rest between its swings, a demand only slightly
faster than the actuator, jittery stamps bending the straight stretch) can still show a **speed plateau**
(:func:`plateau`): every run of the output's motion one way (a move, a swing of a sine) is read on its
own speed. A run's speed has a flat top when it stays within a tolerance of its top speed (5 %, widened to
three times the speed's own scatter, at most :data:`MAX_TOL`) over most of its 10-90 % travel: a linear
second order's step stays within 5 % of its peak speed for at most 50 % of that time and within 10 % for
68 % (over every ζ from 0.2 to 2.5), a sine's swing for 34 % and 49 %; a move on a rate limit stays there
almost throughout. When at least two runs have flat tops at one speed (within :data:`AGREE`), that speed is
the plateau: the ceiling the output cannot pass whatever its command asks, the evidence of a rate (or
current) limit that makes the response depend on amplitude. A flat top counts only where the command asked
for more: its fastest mean rate over the flat stretch's duration (from :data:`LEAD_S` before the run) beats
the flat slope by :data:`PLATEAU_OUTRUN` (a step, a swing past the limit, a profile faster than the actuator);
an actuator following a profile's constant speed has a flat top at the profile's own speed, which is no
limit. The slew rate is then the plateau's.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from ema_sim.jsontypes import JsonObject

FloatArray = NDArray[np.float64]
MOVING = 0.1
"""A sample moves when its rate exceeds this share of the record's peak rate (99th percentile)."""
STRAIGHT = 0.02
"""A constant-rate move stays within this share of its travel of a straight line from 10 % to 90 % of it."""
WIDE = (0.1, 0.9)
"""The share of a move's travel that must be straight."""
MIDDLE = (0.2, 0.8)
"""The share of a move's travel its slope is read on."""
EVEN = 0.1
"""The thirds of a constant-rate move's straight stretch have slopes within this share of each other."""
THIRDS = 3
"""The straight stretch is cut into this many parts whose slopes must agree."""
REST = 0.3
"""Just before and just after a move (a fifth of its length), the output moves at most this share of its slope."""
MIN_SAMPLES = 4
"""Fewest samples in a move's middle for its slope to be read."""
OUTRUN = 1.15
"""The command's fastest mean rate in a move's stretch over the output's slope, for the move to be rate-limited."""
LEAD_S = 0.05
"""How far before the output moves its command is looked at (the delay between a step and the motion)."""
AGREE = 0.1
"""A rate limit within this share of the measured slope agrees with it."""
MIN_NOISE = 1e-3
"""The least noise floor a move's straightness is judged with (``ema identify``'s least weight, so both tools
measure the same slope on the same record)."""


MAX_TOL = 0.10
"""A run whose speed scatters more than this share of its top (three standard deviations) is not judged flat."""
FLAT_SHARE = ((0.05, 0.6), (0.10, 0.78))
"""The share of a run's 10-90 % travel time its speed must stay within the tolerance of its top to be flat, at
5 % and 10 % tolerance (linear between): above a linear second order's 50 % and 68 % with room for the rounded
ends of a rate-limited move."""
MIN_FLAT = 3
"""Fewest samples on a flat top."""
PLATEAU_OUTRUN = 1.05
"""The command's fastest mean rate over a flat top, over the flat slope, for the top to be a limit."""


@dataclass(frozen=True)
class Plateau:
    """A speed plateau: the ceiling the output's runs flatten against (:func:`plateau`).

    Parameters
    ----------
    rate : float or None
        The plateau's speed, the median of the flat runs' slopes (None: no plateau).
    up, down : float or None
        The same over positive and negative runs.
    sigma : float or None
        The flat runs' spread over √runs.
    runs : int
        Runs with a flat top at the plateau.
    seen : int
        Runs examined.
    below : int
        Runs that stayed below the plateau without a flat top (the smaller moves: the amplitude dependence).
    """

    rate: float | None
    up: float | None
    down: float | None
    sigma: float | None
    runs: int
    seen: int
    below: int

    def as_dict(self) -> dict[str, float | int | None]:
        """Plain values for JSON.

        Returns
        -------
        dict
            The plateau's speed, per direction, its spread and the counts.
        """
        return {"rate": self.rate, "positive": self.up, "negative": self.down, "sigma": self.sigma,
                "flat_runs": self.runs, "runs": self.seen, "runs_below": self.below}


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
    plateau: Plateau | None = None
    """The output's speed plateau (:func:`plateau`), read whether or not moves were found."""
    source: str = "moves"
    """``moves`` (straight rest-to-rest moves the command outran) or ``plateau`` (the speed plateau alone)."""

    def as_dict(self) -> JsonObject:
        """Plain values for JSON.

        Returns
        -------
        dict
            The slopes, their spread, the counts, where the rate comes from and the speed plateau.
        """
        return {"rate": self.rate, "positive": self.up, "negative": self.down, "sigma": self.sigma,
                "rate_limited_moves": self.moves, "moves": self.seen, "source": self.source,
                "plateau": None if self.plateau is None else {**self.plateau.as_dict()}}


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


def _at_rest(t: FloatArray, y: FloatArray, a0: int, b0: int, slope: float, noise: float) -> bool:
    """Whether the output is still (under REST of the move's slope) just before and just after the move."""
    n = max(2, (b0 - a0) // 5)
    for lo, hi in ((max(a0 - n, 0), a0), (b0, min(b0 + n, y.size - 1))):
        if hi - lo < 1:
            continue
        dt = float(t[hi] - t[lo])
        if abs(float(y[hi] - y[lo])) / dt > REST * abs(slope) + 3.0 * math.sqrt(2.0) * noise / dt:
            return False
    return True


def _asked(t: FloatArray, u: FloatArray, span_s: float) -> float:
    """The command's fastest mean rate over any window of ``span_s``.

    A staircase's frames and a jittery stamp average out over the time the output takes through the
    middle of its move.
    """
    if t.size < 2:
        return 0.0
    span_s = max(span_s, float(np.median(np.diff(t))))
    j = np.minimum(np.searchsorted(t, t + span_s), t.size - 1)
    ok = j > np.arange(t.size)
    if not ok.any():
        return 0.0
    i = np.flatnonzero(ok)
    return float(np.max(np.abs(u[j[i]] - u[i]) / (t[j[i]] - t[i])))


def _even(t: FloatArray, y: FloatArray) -> bool:
    """Whether the slopes over the three thirds of a stretch agree within EVEN."""
    parts = np.array_split(np.arange(t.size), THIRDS)
    slopes = [abs(float(np.polyfit(t[p[0]:p[-1] + 2], y[p[0]:p[-1] + 2], 1)[0])) for p in parts]
    return max(slopes) - min(slopes) <= EVEN * max(slopes)


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
        if abs(travel) < max(6.0 * noise / STRAIGHT, 1e-9):
            continue
        seen += 1
        frac = (y[a0:b0 + 1] - y[a0]) / travel
        mid = np.flatnonzero((frac >= MIDDLE[0]) & (frac <= MIDDLE[1])) + a0
        wide = np.flatnonzero((frac >= WIDE[0]) & (frac <= WIDE[1])) + a0
        if mid.size < MIN_SAMPLES:
            continue
        tm, ym = t[mid], y[mid]
        slope = float(np.polyfit(tm, ym, 1)[0])
        tw, yw = t[wide], y[wide]
        line = np.polyfit(tw, yw, 1)
        dev = float(np.max(np.abs(yw - np.polyval(line, tw))))
        if dev > STRAIGHT * abs(travel) + 3.0 * noise or np.sign(slope) != np.sign(travel):
            continue
        if wide.size < 3 * THIRDS or not _even(tw, yw) or not _at_rest(t, y, a0, b0, slope, noise):
            continue
        lead = int(np.searchsorted(t, t[a0] - LEAD_S))
        if _asked(t[lead:b0 + 1], u[lead:b0 + 1], float(tm[-1] - tm[0])) >= OUTRUN * abs(slope):
            slopes.append(float(slope))
    flat = plateau(t, u, y, noise)
    if not slopes:
        if flat.rate is not None:
            return Slew(flat.rate, flat.up, flat.down, flat.sigma, flat.runs, max(seen, flat.seen), flat, "plateau")
        return Slew(None, None, None, None, 0, seen, flat)
    return replace(_median_slopes(slopes, seen), plateau=flat)


def _median_slopes(slopes: list[float], seen: int) -> Slew:
    """The median slope overall and per direction, with the spread over √n."""
    mags = np.abs(np.array(slopes))
    ups = [abs(s) for s in slopes if s > 0]
    downs = [abs(s) for s in slopes if s < 0]
    sigma = float(np.std(mags, ddof=1) / math.sqrt(mags.size)) if mags.size > 1 else None
    return Slew(float(np.median(mags)), float(np.median(ups)) if ups else None,
                float(np.median(downs)) if downs else None, sigma, len(slopes), seen)


def _speed(t: FloatArray, y: FloatArray) -> FloatArray:
    """The output's speed on its own stamps: the slope of a line through each sample and its two neighbours."""
    v = np.gradient(y, t)
    if t.size < 5:
        return v
    tm = (t[:-2] + t[1:-1] + t[2:]) / 3.0
    ym = (y[:-2] + y[1:-1] + y[2:]) / 3.0
    num = (t[:-2] - tm) * (y[:-2] - ym) + (t[1:-1] - tm) * (y[1:-1] - ym) + (t[2:] - tm) * (y[2:] - ym)
    den = (t[:-2] - tm) ** 2 + (t[1:-1] - tm) ** 2 + (t[2:] - tm) ** 2
    v[1:-1] = num / np.maximum(den, 1e-300)
    return v


def _flat_share(tol: float) -> float:
    """The share of a run's 10-90 % travel its speed must stay within ``tol`` of its top to be flat."""
    (t0, s0), (t1, s1) = FLAT_SHARE
    return s0 + (s1 - s0) * min(max((tol - t0) / (t1 - t0), 0.0), 1.0)


def _flat_slope(t: FloatArray, y: FloatArray, v: FloatArray, noise: float
                ) -> tuple[float | None, float, FloatArray]:
    """A run's flat-top slope (None: no flat top over most of its 10-90 % travel), top speed and flat samples' times."""
    travel = float(y[-1] - y[0])
    frac = (y - y[0]) / travel
    wide = np.flatnonzero((frac >= WIDE[0]) & (frac <= WIDE[1]))
    speed = np.abs(v)
    top = float(np.percentile(speed[wide], 90)) if wide.size else float(np.max(speed))
    empty = np.zeros(0)
    if wide.size < 2 * MIN_FLAT or top <= 0.0:
        return None, top, empty
    d2 = np.diff(v[wide], 2)
    scatter = 1.4826 * float(np.median(np.abs(d2))) / math.sqrt(6.0) if d2.size else 0.0
    scatter = max(scatter, math.sqrt(2.0) * noise / float(np.median(np.diff(t))))
    tol = max(0.05, 3.0 * scatter / top)
    if tol > MAX_TOL:
        return None, top, empty
    near = wide[speed[wide] >= (1.0 - tol) * top]
    if near.size < MIN_FLAT or near.size < _flat_share(tol) * wide.size:
        return None, top, empty
    return abs(float(np.polyfit(t[near], y[near], 1)[0])), top, t[near]


def plateau(time_s: FloatArray, command: FloatArray, y: FloatArray, noise: float = 0.0) -> Plateau:
    """The output's speed plateau (module docstring).

    Parameters
    ----------
    time_s : numpy.ndarray
        Sample times (uniform or not), s.
    command : numpy.ndarray
        The command (a flat top counts where it asked for more).
    y : numpy.ndarray
        The output.
    noise : float
        Its noise floor.

    Returns
    -------
    Plateau
        The plateau's speed and counts (``rate`` None when fewer than two runs agree on one).
    """
    t = np.asarray(time_s, dtype=float)
    u = np.asarray(command, dtype=float)
    y = np.asarray(y, dtype=float)
    none = Plateau(None, None, None, None, 0, 0, 0)
    if t.size < 3 * MIN_SAMPLES:
        return none
    v = _speed(t, y)
    peak = float(np.percentile(np.abs(v), 99))
    if peak <= 0.0:
        return none
    flats: list[float] = []
    tops: list[float] = []
    seen = 0
    for a, b in _runs(np.abs(v) > MOVING * peak, np.sign(v)):
        a0, b0 = max(a - 1, 0), min(b, y.size - 1)
        if abs(float(y[b0] - y[a0])) < max(6.0 * noise / STRAIGHT, 1e-9) or b0 - a0 < 2 * MIN_FLAT:
            continue
        seen += 1
        slope, top, flat_t = _flat_slope(t[a0:b0 + 1], y[a0:b0 + 1], v[a0:b0 + 1], noise)
        tops.append(top)
        if slope is None:
            continue
        lead = int(np.searchsorted(t, t[a0] - LEAD_S))
        if _asked(t[lead:b0 + 1], u[lead:b0 + 1], float(flat_t[-1] - flat_t[0])) >= PLATEAU_OUTRUN * slope:
            flats.append(slope * float(np.sign(y[b0] - y[a0])))
    mags = np.abs(np.array(flats))
    if mags.size < 2:
        return Plateau(None, None, None, None, int(mags.size), seen, 0)
    level = float(np.median(mags))
    agree = [f for f in flats if abs(abs(f) - level) <= AGREE * level]
    if len(agree) < 2:
        return Plateau(None, None, None, None, len(agree), seen, 0)
    ceiling = _median_slopes(agree, seen)
    assert ceiling.rate is not None
    below = sum(1 for top in tops if top < (1.0 - AGREE) * ceiling.rate)
    return Plateau(ceiling.rate, ceiling.up, ceiling.down, ceiling.sigma, len(agree), seen, below)
