"""The record's rests: where the command is still and the output should be, read before anything is called noise.

A residual at the noise floor means nothing is left to explain only if the floor is noise. This module
reads the floor where the output cannot move, and says what the rests show instead when they are not
quiet:

* **rests**: stretches where the logged command stays within its own noise of one value for at least
  :data:`REST_MIN_S`; the first :data:`SETTLE_SHARE` of each (at least :data:`SETTLE_MIN_S`) is left out,
  the output settling there;
* **a spectral line at rest**: the settled output, less a straight line, has one frequency above
  :data:`MIN_LINE_HZ` (and four cycles of the rest) whose periodogram peak stands :data:`LINE_OVER_MEDIAN`
  times over the median bin and holds :data:`LINE_SHARE` of the rest's variance, with a swing of at least
  one count. When the lines of at least half the rests agree within :data:`LINE_AGREE` of their median
  frequency, the output **hunts**: a **limit cycle** (a position loop through backlash or friction, a
  dead band and an integrator), reported with its frequency, amplitude (half the 2-98 % spread) and rms.
  The drive's current, when logged, must swing at the same frequency (its own periodogram peak there,
  :data:`LINE_OVER_MEDIAN` over its median): a line the current does not share is a vibration from outside
  the drive or the sensor's own, reported as a line at rest, not as hunting. With no current column the
  line is reported as a limit cycle the current could not confirm;
* **the floor**: the fourth-difference white noise (:func:`ema_sim.analysis.estimation.noise.noise_floor`)
  of the quiet rests (no line), each rest's differences taken within it;
* **a floor that grows with the excitation**: the moving part of the record cut into windows; in each,
  the output's fourth-difference floor less what the command's own shape leaks into it (the command's
  floor times the output's gain over the command there), against the excitation's frequency there
  (``rms(rate) / (2π·rms)`` of the command: a sine's frequency). A floor that rises with the frequency
  (rank correlation :data:`GROWTH_RANK` or more, the top third of the windows :data:`GROWTH_FACTOR` times
  the bottom third and :data:`GROWTH_OVER_REST` times the rests' floor) is motion's (a screw's rolling,
  friction, a rough track), not the sensor's noise.

:func:`ema_sim.analysis.estimation.noise.with_rests` turns this into the output's noise floor: the rests'
floor where the record's own estimate is above it by :data:`REST_EXCESS` (the rest of it is motion's), the
record's estimate as an upper bound where no rest is quiet (every rest hunts, or the output never rests).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import minimize_scalar

FloatArray = NDArray[np.float64]

MAD_TO_SIGMA = 1.4826
"""Median absolute deviation of Gaussian noise times this is its standard deviation."""
REST_MIN_S = 0.5
"""A rest: the command still for at least this long."""
SETTLE_SHARE = 0.4
"""Share of a rest left out at its start, the output settling there."""
SETTLE_MIN_S = 0.2
"""At least this much of a rest's start left out."""
MIN_REST_SAMPLES = 24
"""A settled rest shorter than this says nothing of lines or noise."""
MIN_LINE_HZ = 2.0
"""Lines below this are the output settling or creeping, not hunting."""
LINE_CYCLES = 4.0
"""A line the periodogram reads must complete this many cycles within the rest."""
EDGE_CYCLES = 2.5
"""A line below that, seen as the periodogram's skirt at the band's edge, is kept when its sine fit
completes this many cycles."""
LINE_OVER_MEDIAN = 20.0
"""A line's periodogram peak stands this many times over the median bin (white noise: one bin in e^20 or so)."""
LINE_SHARE = 0.4
"""Share of the rest's variance a line must hold (within three bins of it)."""
LINE_AGREE = 0.15
"""The rests' lines agree within this share of their median frequency."""
MIN_QUIET_DIFFS = 30
"""Fourth differences from quiet rests needed to take the floor there."""
REST_EXCESS = 1.5
"""The record's floor above the rests' by this factor: the difference is motion's, the rests' floor is taken."""
GROWTH_WINDOWS = 8
"""Windows the moving part of the record is cut into."""
GROWTH_MIN_SAMPLES = 64
"""Shortest window."""
GROWTH_SPAN = 3.0
"""The windows' excitation frequencies must span this factor for a trend with frequency to be seen."""
GROWTH_RANK = 0.8
"""Spearman rank correlation of the windows' floor with their frequency that makes a trend."""
GROWTH_FACTOR = 1.5
"""The top third of the windows (by frequency) over the bottom third."""
GROWTH_OVER_REST = 2.0
"""The top third of the windows over the rests' floor."""


def white_floor(d4: FloatArray) -> float:
    """White-noise standard deviation from fourth differences (MAD, ``Var Δ⁴ = 70σ²``); 0 for too few.

    Parameters
    ----------
    d4 : numpy.ndarray
        The fourth differences (of one stretch, or several pooled).

    Returns
    -------
    float
        The standard deviation.
    """
    if d4.size < 6:
        return 0.0
    return float(MAD_TO_SIGMA * np.median(np.abs(d4 - np.median(d4))) / math.sqrt(70.0))


@dataclass(frozen=True)
class Rest:
    """One settled rest of the output.

    Parameters
    ----------
    start, stop : int
        The settled part, sample indices (stop exclusive).
    white : float
        Its fourth-difference white noise.
    rms : float
        The output's standard deviation about a straight line through it.
    amplitude : float
        Half its 2-98 % spread about that line.
    line_hz : float or None
        The frequency of its spectral line (None: none).
    current_line : bool or None
        Whether the current swings at that line (None: no line, or no current logged).
    current_rms : float or None
        The current's standard deviation there (None: not logged).
    """

    start: int
    stop: int
    white: float
    rms: float
    amplitude: float
    line_hz: float | None
    current_line: bool | None
    current_rms: float | None


@dataclass(frozen=True)
class LimitCycle:
    """A spectral line the rests share: hunting when the current swings with it (or was not logged).

    Parameters
    ----------
    freq_hz : float
        Median frequency over the rests with the line.
    amplitude : float
        Median half 2-98 % spread (the ``±``).
    rms : float
        Median rms.
    rests : int
        Rests with the line.
    of : int
        Rests examined.
    current : str
        ``swings`` (the current shares the line), ``quiet`` (it does not: no hunting) or ``not logged``.
    current_rms : float or None
        Median current standard deviation at those rests, A.
    """

    freq_hz: float
    amplitude: float
    rms: float
    rests: int
    of: int
    current: str
    current_rms: float | None

    @property
    def hunting(self) -> bool:
        """The drive's own oscillation (the current swings with it, or could not be checked)."""
        return self.current != "quiet"

    def statement(self, output: str, unit: str) -> str:
        """The finding in one sentence.

        Parameters
        ----------
        output : str
            The output's name as the report shows it.
        unit : str
            The record's unit (deg, mm, in).

        Returns
        -------
        str
            The sentence.
        """
        u = "°" if unit == "deg" else f" {unit}"
        fig = (f"{self.freq_hz:.3g} Hz, ±{self.amplitude:.2g}{u} (rms {self.rms:.2g}{u}) in {self.rests} of "
               f"{self.of} rests")
        if self.current == "swings":
            return (f"{output} hunts in a limit cycle at rest: {fig}, the drive's current swinging "
                    f"{self.current_rms:.2g} A rms at the same frequency: the servo's behaviour, not noise")
        if self.current == "not logged":
            return (f"{output} holds a spectral line at rest, a limit cycle (hunting) by its look: {fig}; the drive's "
                    "current was not logged, so it cannot confirm the drive drives it: behaviour, not noise")
        return (f"{output} holds a spectral line at rest: {fig}, the drive's current quiet at that frequency: a "
                "vibration from outside the drive or the sensor's own, not hunting and not white noise")

    def as_dict(self) -> dict[str, float | int | str | bool | None]:
        """Plain values for JSON."""
        return {"freq_hz": self.freq_hz, "amplitude": self.amplitude, "rms": self.rms, "rests": self.rests,
                "of": self.of, "current": self.current, "current_rms_a": self.current_rms, "hunting": self.hunting}


@dataclass(frozen=True)
class Growth:
    """A floor that grows with the excitation's frequency over the record's moving windows.

    Parameters
    ----------
    freq_hz : tuple of float
        Each window's excitation frequency.
    floor : tuple of float
        Each window's floor, less the command's leak.
    rank : float
        Spearman correlation of the two.
    low, high : float
        Median floor of the bottom and top third of the windows by frequency.
    low_hz, high_hz : float
        Their median frequencies.
    """

    freq_hz: tuple[float, ...]
    floor: tuple[float, ...]
    rank: float
    low: float
    high: float
    low_hz: float
    high_hz: float

    def statement(self, output: str, unit: str, rest_floor: float | None) -> str:
        """The finding in one sentence.

        Parameters
        ----------
        output : str
            The output's name as the report shows it.
        unit : str
            The record's unit (deg, mm, in).
        rest_floor : float or None
            The quiet rests' floor, said beside the growth.

        Returns
        -------
        str
            The sentence.
        """
        u = "°" if unit == "deg" else f" {unit}"
        rest = f"; at rest it is {rest_floor:.2g}{u}" if rest_floor is not None else ""
        return (f"{output}'s floor grows with the excitation's frequency, from {self.low:.2g}{u} at "
                f"{self.low_hz:.2g} Hz to {self.high:.2g}{u} at {self.high_hz:.2g} Hz{rest}: not noise but a "
                "disturbance that grows with motion (a screw's rolling, friction, a rough track)")

    def as_dict(self) -> dict[str, object]:
        """Plain values for JSON."""
        return {"freq_hz": list(self.freq_hz), "floor": list(self.floor), "rank_correlation": self.rank,
                "low": self.low, "high": self.high, "low_hz": self.low_hz, "high_hz": self.high_hz}


@dataclass(frozen=True)
class Rests:
    """What the rests of one output show.

    Parameters
    ----------
    rests : tuple of Rest
        The settled rests.
    quiet_floor : float or None
        White noise of the quiet rests (None: no quiet rest long enough).
    line : LimitCycle or None
        A line the rests share (hunting or not).
    growth : Growth or None
        A floor that grows with the excitation's frequency.
    current_logged : bool
        Whether the record has the drive's current.
    """

    rests: tuple[Rest, ...]
    quiet_floor: float | None
    line: LimitCycle | None
    growth: Growth | None
    current_logged: bool

    @property
    def limit_cycle(self) -> LimitCycle | None:
        """The line when it is the drive hunting (or could not be told from it)."""
        return self.line if self.line is not None and self.line.hunting else None

    @property
    def why_no_quiet_rest(self) -> str:
        """Why the floor could not be taken where the output cannot move (empty when it was)."""
        if self.quiet_floor is not None:
            return ""
        if not self.rests:
            return "the output never rests (no command still for 0.5 s)"
        if self.line is not None:
            return "every rest holds the line at rest"
        return "the quiet rests are too short"

    def as_dict(self) -> dict[str, object]:
        """Plain values for JSON."""
        return {"rests": len(self.rests), "quiet_floor": self.quiet_floor,
                "line_at_rest": self.line.as_dict() if self.line else None,
                "floor_grows": self.growth.as_dict() if self.growth else None, "current_logged": self.current_logged}


def still_runs(time_s: FloatArray, command: FloatArray, min_s: float = REST_MIN_S) -> list[tuple[int, int]]:
    """Index ranges (stop exclusive) where the command stays within its own noise of one value for ``min_s``.

    Parameters
    ----------
    time_s : numpy.ndarray
        Stamps, s.
    command : numpy.ndarray
        The command as logged.
    min_s : float
        Shortest run, s.

    Returns
    -------
    list of tuple
        The runs, in time order.
    """
    u = np.asarray(command, dtype=float)
    if u.size < 2:
        return []
    scale = max(1.0, float(np.max(np.abs(u))))
    tol = max(1e-9 * scale, 4.0 * white_floor(np.diff(u, 4)))
    values, stamps = u.tolist(), np.asarray(time_s, dtype=float).tolist()  # plain floats: a loop over samples
    out, i, n = [], 0, u.size
    while i < n:
        j = i + 1
        while j < n and abs(values[j] - values[i]) <= tol:
            j += 1
        if stamps[j - 1] - stamps[i] >= min_s:
            out.append((i, j))
        i = j
    return out


def _periodogram(x: FloatArray, dt: float) -> tuple[FloatArray, FloatArray]:
    """Hann-windowed periodogram, padded eight-fold (frequencies, power)."""
    n = x.size
    spec = np.abs(np.fft.rfft(x * np.hanning(n), 8 * n)) ** 2
    freqs: FloatArray = np.fft.rfftfreq(8 * n, dt).astype(float)
    return freqs, np.asarray(spec, dtype=float)


def _detrended(x: FloatArray) -> FloatArray:
    k = np.arange(x.size, dtype=float)
    return x - np.polyval(np.polyfit(k, x, 1), k)


def _line(x: FloatArray, dt: float, count: float) -> float | None:
    """The frequency of one spectral line in a settled rest (module docstring), or None."""
    n = x.size
    f, p = _periodogram(x, dt)
    band = (f >= max(MIN_LINE_HZ, LINE_CYCLES / (n * dt))) & (f <= 0.49 / dt)
    if not np.any(band) or float(np.ptp(x)) < 2.0 * count:
        return None
    k = int(np.flatnonzero(band)[np.argmax(p[band])])
    med = float(np.median(p[band]))
    near = np.abs(f - f[k]) <= 3.0 / (n * dt)
    if p[k] < LINE_OVER_MEDIAN * med or float(np.sum(p[near])) < LINE_SHARE * float(np.sum(p[f > 0])):
        return None
    span = n * dt
    if k == int(np.flatnonzero(band)[0]):  # the skirt of a line below the band: where is it, and is it a line?
        low = max(MIN_LINE_HZ, EDGE_CYCLES / span)
        hz = _refined(x, dt, float(f[k]), low)
        return hz if low * 1.001 < hz < float(f[k]) else None  # a fit on its bound found no line, only a slope
    return _refined(x, dt, float(f[k]), float(f[k]) - 1.0 / span)


def _refined(x: FloatArray, dt: float, hz: float, low_hz: float) -> float:
    """The line's frequency by a sine fit (with a straight line) from ``low_hz`` to a bin above ``hz``.

    A rest holds a few cycles: the windowed periodogram's peak is then off by a good share of a bin, and a line
    under :data:`LINE_CYCLES` cycles shows only as the skirt at the band's lower edge (a 3 Hz hunt in 1.2 s rests
    was read at 3.33 Hz, the edge); the least-squares sine is not fooled by either.
    """
    t = np.arange(x.size, dtype=float) * dt
    width = 1.0 / (x.size * dt)

    def residual(f: float) -> float:
        w = 2.0 * np.pi * f * t
        a = np.column_stack([np.sin(w), np.cos(w), np.ones_like(t), t])
        coef, *_ = np.linalg.lstsq(a, x, rcond=None)
        r = x - a @ coef
        return float(np.dot(r, r))

    best = minimize_scalar(residual, bounds=(max(low_hz, 0.5 * hz), hz + width), method="bounded",
                           options={"xatol": 1e-4 * hz})
    return float(best.x) if best.success and residual(float(best.x)) <= residual(hz) else hz


def _shares_line(c: FloatArray, dt: float, hz: float) -> bool:
    """Whether the current swings at ``hz`` (its own periodogram peak there over its median)."""
    f, p = _periodogram(_detrended(c), dt)
    near = np.abs(f - hz) <= 3.0 / (c.size * dt)
    band = f >= MIN_LINE_HZ
    return bool(np.any(near)) and float(np.max(p[near])) >= LINE_OVER_MEDIAN * float(np.median(p[band]))


def settled_rests(time_s: FloatArray, command: FloatArray, y: FloatArray, current: FloatArray | None = None,
                  count: float = 0.0, runs: list[tuple[int, int]] | None = None) -> list[Rest]:
    """Each rest's settled part, its noise, spread and line (module docstring).

    Parameters
    ----------
    time_s : numpy.ndarray
        Stamps, s.
    command : numpy.ndarray
        The command.
    y : numpy.ndarray
        The output.
    current : numpy.ndarray, optional
        The drive's current, A.
    count : float
        The output's count (0: continuous): a line must swing at least one.
    runs : list of tuple, optional
        The command's still runs (:func:`still_runs`), when already found.

    Returns
    -------
    list of Rest
        The rests whose settled part has at least :data:`MIN_REST_SAMPLES` samples.
    """
    out = []
    for a, b in still_runs(time_s, command) if runs is None else runs:
        skip = max(SETTLE_MIN_S, SETTLE_SHARE * float(time_s[b - 1] - time_s[a]))
        s = int(np.searchsorted(time_s, time_s[a] + skip))
        if b - s < MIN_REST_SAMPLES:
            continue
        x = _detrended(np.asarray(y[s:b], dtype=float))
        dt = float(np.median(np.diff(time_s[s:b])))
        hz = _line(x, dt, count)
        cur = None if current is None else np.asarray(current[s:b], dtype=float)
        shares = None if hz is None or cur is None else _shares_line(cur, dt, hz)
        lo, hi = np.percentile(x, [2.0, 98.0])
        out.append(Rest(s, b, white_floor(np.diff(y[s:b], 4)), float(np.std(x)), float(0.5 * (hi - lo)), hz,
                        shares, None if cur is None else float(np.std(_detrended(cur)))))
    return out


def shared_line(rests: list[Rest], current_logged: bool) -> LimitCycle | None:
    """The line at least half the rests agree on (module docstring), or None.

    Parameters
    ----------
    rests : list of Rest
        The settled rests (:func:`settled_rests`).
    current_logged : bool
        Whether the record has the drive's current.

    Returns
    -------
    LimitCycle or None
        The shared line, hunting or not.
    """
    lined = [r for r in rests if r.line_hz is not None]
    if not lined or 2 * len(lined) < len(rests):
        return None
    med = float(np.median([r.line_hz for r in lined]))
    agree = [r for r in lined if abs(float(r.line_hz or 0.0) - med) <= LINE_AGREE * med]
    if 2 * len(agree) < len(rests):
        return None
    if not current_logged:
        current = "not logged"
    else:
        current = "swings" if 2 * sum(bool(r.current_line) for r in agree) >= len(agree) else "quiet"
    cur = [r.current_rms for r in agree if r.current_rms is not None]
    return LimitCycle(float(np.median([r.line_hz for r in agree])), float(np.median([r.amplitude for r in agree])),
                      float(np.median([r.rms for r in agree])), len(agree), len(rests), current,
                      float(np.median(cur)) if cur else None)


def _rank(a: FloatArray, b: FloatArray) -> float:
    ra, rb = np.argsort(np.argsort(a)).astype(float), np.argsort(np.argsort(b)).astype(float)
    ra -= ra.mean()
    rb -= rb.mean()
    den = float(np.sqrt(np.sum(ra * ra) * np.sum(rb * rb)))
    return float(np.sum(ra * rb) / den) if den > 0 else 0.0


def floor_growth(time_s: FloatArray, command: FloatArray, y: FloatArray, runs: list[tuple[int, int]],
                 rest_floor: float | None) -> Growth | None:
    """A floor that grows with the excitation's frequency over the moving windows (module docstring), or None.

    Parameters
    ----------
    time_s : numpy.ndarray
        Stamps, s.
    command : numpy.ndarray
        The command.
    y : numpy.ndarray
        The output.
    runs : list of tuple
        The command's still runs (:func:`still_runs`), left out.
    rest_floor : float or None
        The quiet rests' floor, when there is one: the top windows must stand over it too.

    Returns
    -------
    Growth or None
        The trend, when there is one.
    """
    moving = np.ones(y.size, dtype=bool)
    for a, b in runs:
        moving[a:b] = False
    idx = np.flatnonzero(moving)
    if idx.size < GROWTH_WINDOWS * GROWTH_MIN_SAMPLES // 2:
        return None
    size = max(GROWTH_MIN_SAMPLES, idx.size // GROWTH_WINDOWS)
    freqs, floors = [], []
    for w in range(idx.size // size):
        sel = idx[w * size:(w + 1) * size]
        if sel[-1] - sel[0] != sel.size - 1:  # a window across a rest: its differences would span the gap
            continue
        t, u, x = time_s[sel], command[sel], y[sel]
        du = np.diff(u) / np.diff(t)
        su = float(np.std(u))
        if su <= 0.0:
            continue
        gain = float(np.std(x)) / su
        leak = gain * white_floor(np.diff(u, 4))
        own = white_floor(np.diff(x, 4))
        freqs.append(float(np.sqrt(np.mean(du * du))) / (2.0 * math.pi * su))
        floors.append(math.sqrt(max(own * own - leak * leak, 0.0)))
    if len(freqs) < 4:
        return None
    fa, fl = np.asarray(freqs), np.asarray(floors)
    if float(fa.max()) < GROWTH_SPAN * float(fa.min()) or float(fl.max()) <= 0.0:
        return None
    order = np.argsort(fa)
    third = max(1, len(order) // 3)
    low, high = order[:third], order[-third:]
    lo, hi = float(np.median(fl[low])), float(np.median(fl[high]))
    rank = _rank(fa, fl)
    if rank < GROWTH_RANK or hi < GROWTH_FACTOR * lo or (rest_floor is not None and hi < GROWTH_OVER_REST * rest_floor):
        return None
    return Growth(tuple(freqs), tuple(floors), rank, lo, hi, float(np.median(fa[low])), float(np.median(fa[high])))


def read_rests(time_s: FloatArray, command: FloatArray, y: FloatArray, current: FloatArray | None = None,
               count: float = 0.0) -> Rests:
    """What one output's rests show (module docstring).

    Parameters
    ----------
    time_s : numpy.ndarray
        Stamps, s.
    command : numpy.ndarray
        The command.
    y : numpy.ndarray
        The output.
    current : numpy.ndarray, optional
        The drive's current, A (None: not logged).
    count : float
        The output's count (0: continuous).

    Returns
    -------
    Rests
        The rests, the quiet floor, a line at rest and a floor that grows with the excitation.
    """
    t = np.asarray(time_s, dtype=float)
    u = np.asarray(command, dtype=float)
    x = np.asarray(y, dtype=float)
    runs = still_runs(t, u)
    rests = settled_rests(t, u, x, current, count, runs)
    line = shared_line(rests, current is not None)
    quiet = [r for r in rests if r.line_hz is None]
    d4 = [np.diff(x[r.start:r.stop], 4) for r in quiet]
    pooled = np.concatenate(d4) if d4 else np.zeros(0)
    quiet_floor = white_floor(pooled) if pooled.size >= MIN_QUIET_DIFFS else None
    growth = floor_growth(t, u, x, runs, quiet_floor)
    return Rests(tuple(rests), quiet_floor, line, growth, current is not None)
