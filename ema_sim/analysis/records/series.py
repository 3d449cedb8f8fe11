"""Time-series helpers shared by the analyses: uniform grids, held levels, step edges, smoothing.

The data contract allows non-uniform time; spectral and filter-based analyses need a uniform grid, so
:func:`uniform_record` resamples onto one (the command by zero-order hold, as the contract defines
it, the measured columns linearly). A gap in the stamps
(:func:`ema_sim.analysis.records.stamps.find_gaps`) is never bridged: :func:`split_at_gaps` cuts the
record into its contiguous stretches first. A *hold* is a run of samples over which a signal keeps its value
(the digital command of a step or staircase, a static load level); an *edge* is a jump between two
holds.
"""

from __future__ import annotations

from dataclasses import dataclass, fields, replace
from itertools import pairwise

import numpy as np
from numpy.typing import NDArray

from ema_sim.analysis.records.stamps import find_gaps, gap_statement, stretches
from ema_sim.errors import DataError
from ema_sim.io.measured import MeasuredData

FloatArray = NDArray[np.float64]

UNIFORM_TOLERANCE = 0.01
"""Sample intervals within 1 % of the median count as uniform."""
MEASURED = ("position_deg", "surface_deg", "hinge_moment_inlb", "current_a", "position_v", "bus_v", "rate_dps")
HELD = ("command_deg", "command_v")


def is_uniform(time_s: FloatArray) -> bool:
    """True when every sample interval is within 1 % of the median interval.

    Parameters
    ----------
    time_s : numpy.ndarray
        Sample times, s.

    Returns
    -------
    bool
        Whether the intervals are uniform.
    """
    dt = np.diff(time_s)
    med = float(np.median(dt))
    return bool(np.all(np.abs(dt - med) <= UNIFORM_TOLERANCE * med))


JITTER_LIMIT = 0.5
"""Stamps within half a sample of the least-squares line through them: regular sampling, no sample missing."""


def uniform_record(data: MeasuredData, *, command_sampled: bool = False) -> MeasuredData:
    """The record on a uniform grid (unchanged when it already is uniform); cut it at its gaps first.

    Time stamps that only jitter belong to regular sampling: when every stamp lies within half a
    sample of the least-squares line through them (a missing sample or a burst shifts the later
    stamps by a whole sample), they are replaced by that line and the samples are kept as they are
    (resampling would delay the held command by up to a sample against the outputs, and blur an
    output logged in counts). Records with gaps or mixed rates are resampled at the median rate:
    held columns (the command) by zero-order hold, as the contract defines the command, measured
    columns by linear interpolation. A held column takes, at each grid point, the level the logged
    staircase has half a grid step later: the new staircase then changes level at the grid point nearest
    the logged change (within half a step either way, no bias), where taking the level at the grid point
    itself would make every change up to a whole step late, half a step on average, which a frequency
    response would read as the output leading its command.

    Parameters
    ----------
    data : MeasuredData
        A record as read.
    command_sampled : bool
        The command was sampled from a running demand rather than held: a resampled command is then
        interpolated like the outputs, not held.

    Returns
    -------
    MeasuredData
        The record on a uniform grid; ``metadata["resampled"]`` says what was done.
    """
    t = data.time_s
    if is_uniform(t):
        return data
    dt_all = np.diff(t)
    med = float(np.median(dt_all))
    meta = dict(data.metadata)
    k = np.arange(t.size, dtype=float)
    slope, icpt = np.polyfit(k, t, 1)
    jitter = float(np.max(np.abs(t - (icpt + slope * k))))
    if jitter < JITTER_LIMIT * slope:
        meta["resampled"] = (f"time stamps jitter by up to {1e3 * jitter:.3g} ms: samples taken as uniform at "
                             f"{1.0 / slope:.6g} Hz (least-squares line through the stamps), not resampled")
        return replace(data, time_s=icpt + slope * k, metadata=meta)
    dt = med
    held = () if command_sampled else (*HELD, "fmu_command_deg")
    n = int(np.floor((t[-1] - t[0]) / dt + 1e-9)) + 1
    grid = t[0] + dt * np.arange(n)
    idx = np.clip(np.searchsorted(t, grid + 0.5 * dt + 1e-12, side="right") - 1, 0, t.size - 1)
    changes: dict[str, object] = {"time_s": grid}
    for f in fields(data):
        value = getattr(data, f.name)
        if not isinstance(value, np.ndarray) or f.name == "time_s":
            continue
        changes[f.name] = value[idx] if f.name in held else np.interp(grid, t, value)
    changes["extra"] = {k: v[idx] if k in held else np.interp(grid, t, v) for k, v in data.extra.items()}
    meta["resampled"] = (f"time stamps not uniform (intervals {1e3 * dt_all.min():.3g}-{1e3 * dt_all.max():.3g} ms): "
                         f"resampled at {1.0 / dt:.6g} Hz, command "
                         f"{'interpolated (sampled)' if command_sampled else 'held'}, outputs interpolated: {n} "
                         f"samples on the grid from the {t.size} logged")
    gaps = find_gaps(t)
    if gaps:
        meta["resampled"] += (f", across {gap_statement(gaps, dt)} too: what was in them is made up "
                              "(ema analyze cuts a record at its gaps instead)")
    changes["metadata"] = meta
    return replace(data, **changes)  # type: ignore[arg-type]


MIN_STRETCH = 100
"""A stretch between gaps with fewer samples is not analysed (the data contract's shortest record)."""
SAID = ("truncated", "dropouts", "gaps", "resampled")
"""The metadata a record's reading, cuts and resampling leave, said with every analysis of it."""


def part(data: MeasuredData, a: int, b: int) -> MeasuredData:
    """Samples ``[a, b)`` of a record, every column cut alike.

    Parameters
    ----------
    data : MeasuredData
        The record.
    a, b : int
        The first sample and the one after the last.

    Returns
    -------
    MeasuredData
        The part.
    """
    changes: dict[str, object] = {f.name: getattr(data, f.name)[a:b] for f in fields(data)
                                  if isinstance(getattr(data, f.name), np.ndarray)}
    changes["extra"] = {k: v[a:b] for k, v in data.extra.items()}
    return replace(data, **changes)  # type: ignore[arg-type]


def split_at_gaps(data: MeasuredData) -> list[MeasuredData]:
    """The record's contiguous stretches between gaps in its stamps, each a record of its own.

    A gap (an interval of several sample intervals) is a pause of the logger: what the actuator did in
    it is unknown, so no analysis may bridge it, and resampling would invent the samples. Each stretch
    of at least :data:`MIN_STRETCH` samples comes back as a record named by its span, its metadata's
    ``gaps`` saying where the gaps are and which stretch it is; shorter ones are left out and said.

    Parameters
    ----------
    data : MeasuredData
        A record as read.

    Returns
    -------
    list of MeasuredData
        ``[data]`` unchanged when it has no gap, else its stretches long enough to analyse.

    Raises
    ------
    DataError
        No stretch between the gaps is long enough.
    """
    gaps = find_gaps(data.time_s)
    if not gaps:
        return [data]
    t = data.time_s
    head = gap_statement(gaps, float(np.median(np.diff(t))))
    return cut(data, stretches(t.size, gaps), "gaps", head,
               ": analysed stretch by stretch, never across a gap (nothing interpolated in it)")


def cut(data: MeasuredData, parts: list[tuple[int, int]], key: str, head: str, how: str = "") -> list[MeasuredData]:
    """The record's ``parts`` of :data:`MIN_STRETCH` samples or more, each a record named by its span.

    Each part's metadata ``key`` says why the record was cut (``head``, then ``how``), what was left out and which
    part it is; shorter parts are left out and said.

    Parameters
    ----------
    data : MeasuredData
        The record.
    parts : list of tuple
        ``(start, stop)`` samples of each part, in order.
    key : str
        The metadata entry that says the cut.
    head : str
        What the record was cut at.
    how : str
        How it is analysed, after ``head``.

    Returns
    -------
    list of MeasuredData
        The parts long enough to analyse.

    Raises
    ------
    DataError
        No part is long enough.
    """
    t = data.time_s
    kept = [(a, b) for a, b in parts if b - a >= MIN_STRETCH]
    if not kept:
        raise DataError(f"{data.source}: {head}; no stretch between them has {MIN_STRETCH} samples to analyse")
    short = len(parts) - len(kept)
    dropped = f"; {short} stretch(es) under {MIN_STRETCH} samples not analysed" if short else ""
    out = []
    for i, (a, b) in enumerate(kept):
        meta = dict(data.metadata)
        span = f"{t[a]:.4g}-{t[b - 1]:.4g} s"
        meta[key] = f"{head}{how}{dropped}; this is stretch {i + 1} of {len(kept)}: {span}, {b - a} samples"
        out.append(replace(part(data, a, b), metadata=meta, source=f"{data.source} [{span}]"))
    return out


def sample_period(data: MeasuredData) -> float:
    """Median sample interval, s.

    Parameters
    ----------
    data : MeasuredData
        The record.

    Returns
    -------
    float
        The interval, s.
    """
    return float(np.median(np.diff(data.time_s)))


@dataclass(frozen=True)
class Hold:
    """Samples ``[start, stop)`` over which a signal keeps ``value``.

    Parameters
    ----------
    start : int
        First sample.
    stop : int
        One past the last sample.
    value : float
        The held level (median).
    """

    start: int
    stop: int
    value: float

    @property
    def length(self) -> int:
        """Number of samples."""
        return self.stop - self.start


def _d2_noise(x: FloatArray) -> float:
    """Standard deviation of white noise on ``x`` from the MAD of its second differences."""
    d2 = np.abs(np.diff(x, 2))
    return 1.4826 * float(np.median(d2)) / np.sqrt(6.0) if d2.size else 0.0


def hold_tolerance(x: FloatArray) -> float:
    """How much a held signal may wander and still count as held.

    A digital command is exact (a rounding allowance of 1e-6 of its scale); a recorded analog signal
    gets five times its noise while it is held. The noise is first estimated robustly from the second
    differences of the whole signal, then again from the samples that sit still within that first
    tolerance only: a demand that spends most of its time on ramps sampled at jittery instants must
    not lend its ramps' scatter to its holds.

    Parameters
    ----------
    x : numpy.ndarray
        The signal.

    Returns
    -------
    float
        The tolerance, in the signal's unit.
    """
    scale = max(1.0, float(np.max(np.abs(x))) if x.size else 1.0)
    floor = 1e-6 * scale
    first = max(floor, 5.0 * _d2_noise(x))
    if x.size < 4:
        return first
    still = np.abs(np.diff(x)) <= first
    both = still[:-1] & still[1:]  # second differences whose two steps are both still
    if both.sum() < 10:
        return first
    d2 = np.abs(np.diff(x, 2))[both]
    return float(max(floor, 5.0 * 1.4826 * float(np.median(d2)) / np.sqrt(6.0)))


HOLD_BAND = 3.0
"""A hold's spread stays within this many hold tolerances (noise alone spans about 1.2)."""


def _spread(x: FloatArray) -> float:
    """1st to 99th percentile: the range of a stretch, blind to an isolated spike."""
    lo, hi = np.percentile(x, [1.0, 99.0])
    return float(hi - lo)


def holds(x: FloatArray, min_samples: int, tol: float | None = None) -> list[Hold]:
    """Runs of at least ``min_samples`` samples whose consecutive changes are within ``tol``.

    Parameters
    ----------
    x : numpy.ndarray
        The signal.
    min_samples : int
        Shortest hold, samples.
    tol : float or None
        Hold tolerance (default: the signal's own).

    Returns
    -------
    list
        The holds, in time order.
    """
    if x.size < 2:
        return []
    tol = hold_tolerance(x) if tol is None else tol
    moving = np.abs(np.diff(x)) > tol
    # Boundaries of runs of "not moving" steps: a run of k quiet steps spans k + 1 samples.
    padded = np.concatenate([[True], moving, [True]])
    change = np.flatnonzero(np.diff(padded.astype(np.int8)))
    starts, stops = change[::2], change[1::2]
    # A noise spike breaks a run; runs that meet again at the same level are one hold.
    ends = stops  # last sample of each run
    merge = np.zeros(starts.size, dtype=bool)
    if starts.size > 1:
        merge[1:] = (starts[1:] - ends[:-1] <= 2) & (np.abs(x[starts[1:]] - x[ends[:-1]]) <= 3 * tol)
    group = np.cumsum(~merge) - 1
    first = starts[~merge]
    last = np.zeros(first.size, dtype=int)
    np.maximum.at(last, group, ends)
    out = []
    for s, e in zip(first.tolist(), last.tolist(), strict=True):
        stop = e + 1
        # Small steps can still add up: a slow sine sampled fast moves less than the tolerance per
        # sample. A hold stays inside a band of a few tolerances around its level.
        if stop - s >= min_samples and _spread(x[s:stop]) <= HOLD_BAND * tol:
            out.append(Hold(int(s), int(stop), float(np.median(x[s:stop]))))
    return out


@dataclass(frozen=True)
class Edge:
    """A jump of a held signal: from hold ``before`` to hold ``after``.

    Parameters
    ----------
    index : int
        First sample that left the old level (for a command through a lag, the start of its transition).
    before : Hold
        The hold before.
    after : Hold
        The hold after.
    """

    index: int
    """First sample that left the old level (for a command through a lag, the start of its transition)."""
    before: Hold
    after: Hold

    @property
    def jump(self) -> float:
        """New level minus old level."""
        return self.after.value - self.before.value


def edges(x: FloatArray, dt: float, *, min_hold_s: float = 0.04, min_jump: float = 0.05,
          max_gap_s: float = 0.02, tol: float | None = None) -> list[Edge]:
    """Jumps of at least ``min_jump`` between two holds of at least ``min_hold_s`` each.

    ``max_gap_s`` allows a recorded (analog) command a short transition between the two levels;
    the edge is then at the transition's first sample.

    Parameters
    ----------
    x : numpy.ndarray
        The held signal.
    dt : float
        Sample interval, s.
    min_hold_s : float
        Shortest hold on either side, s.
    min_jump : float
        Smallest jump between the two holds.
    max_gap_s : float
        Longest transition between the holds, s.
    tol : float, optional
        Hold tolerance (default: :func:`hold_tolerance`).

    Returns
    -------
    list of Edge
        In time order.
    """
    hs = holds(x, max(2, round(min_hold_s / dt)), tol)
    out = []
    max_gap = round(max_gap_s / dt) + 1
    for a, b in pairwise(hs):
        if b.start - a.stop <= max_gap and abs(b.value - a.value) >= min_jump:
            out.append(Edge(a.stop, a, b))
    return out


def settled(y: FloatArray, start: int, stop: int, fraction: float = 0.5) -> tuple[float, float]:
    """Mean and standard deviation of ``y`` over the last ``fraction`` of ``[start, stop)``.

    Parameters
    ----------
    y : numpy.ndarray
        The signal.
    start : int
        First sample.
    stop : int
        One past the last sample.
    fraction : float
        Share of the stretch at its end to average.

    Returns
    -------
    tuple
        Mean and standard deviation.
    """
    first = stop - max(1, int((stop - start) * fraction))
    seg = y[first:stop]
    return float(np.mean(seg)), float(np.std(seg))


def moving_average(y: FloatArray, n: int) -> FloatArray:
    """Centred moving average over ``n`` samples (edges use the samples available).

    Parameters
    ----------
    y : numpy.ndarray
        The signal.
    n : int
        Window length, samples.

    Returns
    -------
    numpy.ndarray
        The averaged signal.
    """
    n = max(1, int(n))
    if n == 1:
        return y.astype(float, copy=True)
    c = np.concatenate([[0.0], np.cumsum(y, dtype=float)])
    half = n // 2
    idx = np.arange(y.size)
    lo = np.clip(idx - half, 0, y.size)
    hi = np.clip(idx - half + n, 0, y.size)
    return np.asarray((c[hi] - c[lo]) / (hi - lo), dtype=float)


def derivative(y: FloatArray, dt: float, window_s: float = 0.011) -> FloatArray:
    """Smoothed derivative (Savitzky-Golay, quadratic, over ``window_s``).

    Parameters
    ----------
    y : numpy.ndarray
        The signal.
    dt : float
        Sample interval, s.
    window_s : float
        Window length, s.

    Returns
    -------
    numpy.ndarray
        The derivative.
    """
    from scipy.signal import savgol_filter  # noqa: PLC0415 - scipy.signal loads in ~0.5 s; only the smoothed derivative needs it

    n = max(3, round(window_s / dt) | 1)
    if y.size < n:
        return np.asarray(np.gradient(y, dt), dtype=float)
    return np.asarray(savgol_filter(y, n, 2, deriv=1, delta=dt), dtype=float)


def extrema(x: FloatArray) -> NDArray[np.int64]:
    """Indices of the turning points of ``x`` (plateaus count once, at their middle).

    Parameters
    ----------
    x : numpy.ndarray
        The signal.

    Returns
    -------
    numpy.ndarray
        Indices of the turning points.
    """
    d = np.diff(x)
    nz = np.flatnonzero(d != 0.0)
    if nz.size < 2:
        return np.zeros(0, dtype=np.int64)
    s = np.sign(d[nz])
    turn = np.flatnonzero(s[1:] != s[:-1])
    # A turn lies between the last change of one sign (nz[turn]) and the first of the other.
    left = nz[turn] + 1
    right = nz[turn + 1]
    return ((left + right) // 2).astype(np.int64)


def require_length(data: MeasuredData, seconds: float, what: str) -> None:
    """Raise a DataError when the record is shorter than ``seconds``.

    Parameters
    ----------
    data : MeasuredData
        The record.
    seconds : float
        The shortest record, s.
    what : str
        What needs it.
    """
    span = float(data.time_s[-1] - data.time_s[0])
    if span < seconds:
        raise DataError(f"{data.source or 'data'}: {what} needs at least {seconds:g} s of data, got {span:g} s")
