"""Which section-2 tests a record holds, and where: from its signals, checked against its metadata.

A rig's CSV may carry no metadata, so every test is recognised from the signals first. The record
is cut into stretches of four shapes and each test's readers (:mod:`ema_sim.analysis.registry`) are
asked, most specific first, what each stretch is:

* **edges** of the held command: jumps between holds of ≥ 40 ms, a jump counting when it is larger
  than twice the band a hold may wander in (and three counts of a command logged in counts:
  :func:`command_counts`), the transition taking at most 20 ms; runs of them are a *staircase*
  (calibration), a *square* wave (timing), a square wave whose holds shrink (*regen*), or *steps*;
* **moves**: holds joined by longer monotone transitions that cruise at a constant speed or dwell
  (a drive's trapezoid demands): a *profile* (or a *staircase* of them);
* **moving** stretches of the command (neither held nor claimed above), by their turning points: a
  tone of steady period (a *sine* dwell or a *triangle*; growing amplitude: *static_threshold* below
  1 Hz, *dynamic_threshold* above), a period that shrinks steadily (*sweep*), a slow monotone *ramp*,
  or an irregular broadband signal (*schroeder* when it repeats, else *broadband*). A period that is
  piecewise constant (tones one after another, :attr:`MovingStretch.dwells`) is no sweep: each of
  its dwells is read on its own;
* **held command** for ≥ 5 s: with a varying hinge moment, a load staircase (*load_steps*:
  compliance), two opposite load levels (*load_reversal*: free play) or a sinusoidal load
  (*load_sine*: hysteresis); with a constant load, a *hold* (crosstalk, dither).

Repeated cycles of the command (:func:`ema_sim.analysis.records.periodic.find_periodic`) are then one test:
a periodic stretch that one segment of a matching kind covers keeps it, with the period and cycles
added to its parameters; one the readers cut into pieces, or read as something else, becomes one
segment named by its waveform (``square``, ``sine``, ``triangle``, else ``periodic``). Either way its
``cycles`` parameter has :mod:`ema_sim.analysis.section2.cycles` average it over its cycles.

The metadata's maneuver and load specs (``ema simulate``, the maneuver node's bags) then confirm each
segment or relabel it, adding the spec's parameters (sweep band, Schroeder period, tone frequency);
every segment says what it was recognised from.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from typing import TypeVar

import numpy as np
from numpy.typing import NDArray

from ema_sim.analysis.estimation.noise import COMMAND_COUNTS_SPANNED, detect_resolution
from ema_sim.analysis.records import series
from ema_sim.analysis.records.periodic import Periodicity, find_periodic
from ema_sim.analysis.records.series import Edge
from ema_sim.analysis.registry import EDGE_READERS, HELD_READERS, MOVE_READERS, MOVING_READERS
from ema_sim.analysis.section2.moves import find_moves
from ema_sim.analysis.section2.segments import (
    EdgeRun,
    HeldStretch,
    MoveRun,
    MovingStretch,
    Reading,
    Recognition,
    Segment,
)
from ema_sim.errors import EmaError
from ema_sim.io.measured import MeasuredData
from ema_sim.signals import Load, Maneuver, parse_load, parse_maneuver

FloatArray = NDArray[np.float64]
_S = TypeVar("_S")
"""A stretch of the record a reader reads (an edge run, a move run...)."""

EDGE_KINDS = ("steps", "square", "regen", "staircase")
MOVING_KINDS = ("sweep", "schroeder", "broadband", "sine", "triangle", "static_threshold", "dynamic_threshold", "ramp")
HELD_KINDS = ("hold", "load_steps", "load_reversal", "load_sine")
MIN_EDGE_HOLD_S = 0.04
LONG_HOLD_S = 0.3
MIN_MOVING_S = 1.0
HELD_TEST_S = 5.0
COUNTS_SPANNED_MOVING = 10.0
"""A command travelling ``COMMAND_COUNTS_SPANNED`` counts over at least this many is logged in counts."""
MAX_STEP_S = 0.02
"""A step's transition (a recorded command through a lag) takes at most this long; a move takes longer."""

MANEUVER_KINDS = {
    "step": "steps", "steps": "steps", "square": "square", "regen": "regen", "staircase": "staircase",
    "sweep": "sweep", "schroeder": "schroeder", "sine": "sine", "triangle": "triangle", "ramp": "ramp",
    "static_threshold": "static_threshold", "dynamic_threshold": "dynamic_threshold", "hold": "hold",
}
LOAD_KINDS = {"steps": "load_steps", "reversal": "load_reversal", "sine": "load_sine"}
PERIODIC_KINDS = {"square": ("square", "steps"), "profiled square": ("profile", "square"),
                  "trapezoid": ("profile", "square"), "triangle": ("triangle",), "sine": ("sine",),
                  "other": ("schroeder",)}
"""Kinds of a single segment that may cover a periodic stretch of each waveform (it keeps its kind)."""
PERIODIC_COVER = 0.9
"""Share of a periodic stretch one segment must cover to stand for it."""
COMPATIBLE = {("broadband", "schroeder"), ("broadband", "sweep"), ("sine", "triangle"), ("triangle", "sine"),
              ("steps", "square"), ("square", "steps"), ("steps", "regen"), ("square", "regen"),
              ("load_reversal", "load_steps"), ("load_steps", "load_reversal")}
"""(signal reading, metadata kind) pairs a signal can mistake for each other."""


def _read(readers: tuple[Callable[[_S], Reading | None], ...], stretch: _S) -> Reading:
    """The first reader's answer (the last reader of a tuple always answers)."""
    for reader in readers:
        reading = reader(stretch)
        if reading is not None:
            return reading
    raise AssertionError("the last reader answers every stretch")


def _group_edges(edges: list[Edge]) -> list[list[Edge]]:
    groups: list[list[Edge]] = []
    for e in edges:
        if groups and groups[-1][-1].after.start == e.before.start:
            groups[-1].append(e)
        else:
            groups.append([e])
    return groups


def edge_threshold(u: FloatArray) -> tuple[float, float]:
    """How far the command may wander in a hold, and the smallest jump between two holds that is an edge.

    A hold stays within ``HOLD_BAND`` tolerances of its level, so two holds whose levels differ by
    twice that cannot be one hold; a command logged in counts also needs three counts (a slow ramp
    through its counts is a staircase of one-count jumps, no steps).

    Parameters
    ----------
    u : numpy.ndarray
        The command.

    Returns
    -------
    tuple of float
        The hold tolerance and the edge threshold, deg.
    """
    tol = series.hold_tolerance(u)
    counts = command_counts(u)
    scale = max(1.0, float(np.max(np.abs(u)))) if u.size else 1.0
    return tol, max(2.0 * series.HOLD_BAND * tol, 3.0 * counts, 1e-6 * scale)


def command_counts(u: FloatArray) -> float:
    """The count a command is logged in (0 when it is continuous), judged against the command's motion.

    A command's count is a fine grid, not a designed step: the command spans at least
    ``COMMAND_COUNTS_SPANNED`` counts, or (a small-amplitude test, a threshold test at the D/A's
    limit) it travels that many counts in all, one change of a count or a few at a time, over at least
    ``COUNTS_SPANNED_MOVING`` levels. A waveform between a few levels (a square wave, a regeneration
    test) spans too few; a step set or staircase changes too seldom (each of its jumps is one test
    level, and a test has tens of them, not hundreds).

    Parameters
    ----------
    u : numpy.ndarray
        The command.

    Returns
    -------
    float
        The count, deg (0: none).
    """
    spanned = detect_resolution(u, COMMAND_COUNTS_SPANNED)
    if spanned is not None:
        return spanned
    q = detect_resolution(u)
    if q is None or u.size < 2 or float(np.ptp(u)) < COUNTS_SPANNED_MOVING * q:
        return 0.0
    travel = float(np.sum(np.abs(np.diff(u)))) / q
    return q if travel >= COMMAND_COUNTS_SPANNED else 0.0


def _maneuver(data: MeasuredData) -> tuple[Maneuver | None, str | None]:
    text = data.metadata.get("maneuver")
    if not text:
        return None, None
    try:
        return parse_maneuver(text), None
    except EmaError as exc:
        return None, f"metadata maneuver {text!r} not understood ({exc})"


def _load(data: MeasuredData) -> tuple[Load | None, str | None]:
    text = data.metadata.get("load")
    if not text:
        return None, None
    try:
        return parse_load(text), None
    except EmaError as exc:
        return None, f"metadata load {text!r} not understood ({exc})"


def _runs(mask: NDArray[np.bool_]) -> list[tuple[int, int]]:
    padded = np.concatenate([[False], mask, [False]])
    d = np.flatnonzero(np.diff(padded.astype(np.int8)))
    return list(zip(d[::2].tolist(), d[1::2].tolist(), strict=True))


def _edge_segments(t: FloatArray, u: FloatArray, tol: float, min_jump: float, claimed: NDArray[np.bool_]
                   ) -> list[Segment]:
    """Runs of command edges, each read by the edge readers."""
    dt = float(np.median(np.diff(t)))
    out = []
    edges = series.edges(u, dt, min_hold_s=MIN_EDGE_HOLD_S, min_jump=min_jump, max_gap_s=MAX_STEP_S, tol=tol)
    for group in _group_edges(edges):
        r = _read(EDGE_READERS, EdgeRun(tuple(group), dt))
        start, stop = group[0].before.start, group[-1].after.stop
        claimed[start:stop] = True
        holds = tuple([group[0].before] + [e.after for e in group])
        out.append(Segment(r.kind, start, stop, f"signal: {r.evidence}", r.params, tuple(group), holds))
    return out


def _move_segments(t: FloatArray, u: FloatArray, tol: float, min_jump: float, claimed: NDArray[np.bool_]
                   ) -> list[Segment]:
    """Runs of profiled moves (not already claimed as edges), each read by the move readers."""
    dt = float(np.median(np.diff(t)))
    out = []
    short_holds = series.holds(u, max(2, round(MIN_EDGE_HOLD_S / dt)), tol)
    for run in find_moves(t, u, short_holds, min_jump=min_jump, max_gap=round(MAX_STEP_S / dt) + 1,
                          counts=command_counts(u), tol=tol):
        start, stop = run[0].before.start, run[-1].after.stop
        if claimed[start:stop].any():
            continue
        r = _read(MOVE_READERS, MoveRun(tuple(run), dt))
        claimed[start:stop] = True
        holds = tuple([run[0].before] + [m.after for m in run])
        out.append(Segment(r.kind, start, stop, f"signal: {r.evidence}", r.params, holds=holds, moves=tuple(run)))
    return out


def _moving_segments(t: FloatArray, u: FloatArray, tol: float, held: NDArray[np.bool_],
                     claimed: NDArray[np.bool_]) -> list[Segment]:
    """Stretches where the command keeps moving, each read by the moving readers."""
    dt = float(np.median(np.diff(t)))
    spans = _runs(~held & ~claimed)
    # Merge moving stretches split by short pauses (a quantized command sits still near its peaks).
    merged: list[tuple[int, int]] = []
    for a, b in spans:
        if merged and a - merged[-1][1] < round(1.0 / dt) and not claimed[merged[-1][1]:a].any():
            merged[-1] = (merged[-1][0], b)
        else:
            merged.append((a, b))
    out = []
    for lo, hi in merged:
        # Leading and trailing samples where the command has not yet left (or has come back to) the level it
        # starts (ends) at belong to no test; a slow start that creeps away a count at a time is moving.
        a, b = lo, hi
        before = max(lo - 1, 0)
        left = np.flatnonzero(np.abs(u[before:hi] - u[before]) > tol)
        back = np.flatnonzero(np.abs(u[before:hi] - u[hi - 1]) > tol)
        if left.size and back.size:
            a, b = before + max(int(left[0]) - 1, 0) + 1, before + int(back[-1]) + 2
        if (b - a) * dt < MIN_MOVING_S:
            continue
        stretch = MovingStretch(t[a:b], u[a:b])
        dwells = stretch.dwells
        if not dwells:
            r = _read(MOVING_READERS, stretch)
            out.append(Segment(r.kind, a, b, f"signal: {r.evidence}", r.params))
            continue
        for k, (i, j) in enumerate(dwells):  # a stepped sine: each dwell is read on its own
            r = _read(MOVING_READERS, MovingStretch(t[a + i:a + j], u[a + i:a + j]))
            out.append(Segment(r.kind, a + i, a + j, f"signal: {r.evidence}, dwell {k + 1} of {len(dwells)} of a "
                               "stepped tone (its period is piecewise constant)", r.params))
    return out


def recognize(data: MeasuredData) -> Recognition:
    """Segments of a uniformly sampled record, with the evidence for each; see the module docstring.

    Parameters
    ----------
    data : MeasuredData
        The record on a uniform grid.

    Returns
    -------
    Recognition
        The segments in time order, the metadata's maneuver and load, and notes.
    """
    t, u = data.time_s, data.command_deg
    dt = float(np.median(np.diff(t)))
    notes: list[str] = []
    maneuver, note_m = _maneuver(data)
    load, note_l = _load(data)
    notes += [n for n in (note_m, note_l) if n]
    tol, min_jump = edge_threshold(u)
    claimed = np.zeros(u.size, dtype=bool)
    segments = _edge_segments(t, u, tol, min_jump, claimed)
    segments += _move_segments(t, u, tol, min_jump, claimed)
    long_holds = series.holds(u, round(LONG_HOLD_S / dt), tol)
    held = np.zeros(u.size, dtype=bool)
    for h in long_holds:
        held[h.start:h.stop] = True
    segments += _moving_segments(t, u, tol, held, claimed)
    for h in long_holds:
        if (h.stop - h.start) * dt >= HELD_TEST_S and not claimed[h.start:h.stop].all():
            stretch = HeldStretch(t, data.hinge_moment_inlb, h.start, h.stop, h.value)
            r = _read(HELD_READERS, stretch)
            segments.append(Segment(r.kind, h.start, h.stop, f"signal: {r.evidence}", {"command_deg": h.value},
                                    holds=stretch.load_holds if r.kind != "hold" else ()))
    segments.sort(key=lambda s: s.start)
    periodic = find_periodic(t, u, tol)
    segments = _periodic(segments, periodic, u, dt, tol, min_jump)
    segments = _metadata_window(segments, t, maneuver)
    segments = _reconcile(segments, maneuver, load, notes)
    if not segments:
        notes.append("no section-2 test recognised in the signals")
    return Recognition(segments, maneuver, load, notes, tol, min_jump, periodic)


def _periodic(segments: list[Segment], periodic: list[Periodicity], u: FloatArray, dt: float, tol: float,
              min_jump: float) -> list[Segment]:
    """Each periodic stretch of the command as one test (see the module docstring)."""
    for p in periodic:
        inside = [s for s in segments if s.start < p.stop and s.stop > p.start and s.kind not in HELD_KINDS]
        span = p.stop - p.start
        if len(inside) == 1 and inside[0].kind in PERIODIC_KINDS[p.shape]:
            s = inside[0]
            if min(s.stop, p.stop) - max(s.start, p.start) >= PERIODIC_COVER * span:
                if p.shape == "other":
                    continue  # a repeating broadband command: its own reader's periodic analysis stands
                kept = Segment(s.kind, s.start, s.stop, f"{s.evidence}; {p.evidence}", {**p.params(), **s.params},
                               s.edges, s.holds, s.moves)
                segments = sorted([x for x in segments if x is not s] + [kept], key=lambda x: x.start)
                continue
        # the lead-in and lead-out (the first swing from rest, the last back to it) are part of the same test
        reach = round(p.period_samples)
        ends = [s for s in segments if s not in inside and s.kind not in HELD_KINDS
                and (p.stop <= s.start <= p.stop + reach or p.start - reach <= s.stop <= p.start)]
        seg = _periodic_segment(p, u, dt, tol, min_jump)
        if ends:
            spans = ", ".join(f"samples {s.start}-{s.stop} (read alone as {s.kind})" for s in ends)
            seg = replace(seg, evidence=f"{seg.evidence}; its lead-in/lead-out {spans} belong to it")
        segments = sorted([x for x in segments if x not in inside and x not in ends] + [seg], key=lambda x: x.start)
    return segments


def _periodic_segment(p: Periodicity, u: FloatArray, dt: float, tol: float, min_jump: float) -> Segment:
    """One segment for a periodic stretch the readers cut up or misread."""
    kind = {"square": "square", "sine": "sine", "triangle": "triangle"}.get(p.shape, "periodic")
    edges: tuple[Edge, ...] = ()
    if kind == "square":
        found = series.edges(u[p.start:p.stop], dt, min_hold_s=MIN_EDGE_HOLD_S, min_jump=min_jump,
                             max_gap_s=MAX_STEP_S, tol=tol)
        edges = tuple(_shifted(e, p.start) for e in found)
        if not edges:
            kind = "periodic"
    holds = tuple([edges[0].before] + [e.after for e in edges]) if edges else ()
    return Segment(kind, p.start, p.stop, f"signal: {p.evidence} (one test, not its pieces)", p.params(), edges,
                   holds)


def _shifted(e: Edge, by: int) -> Edge:
    """An edge found on a slice, in record indices."""
    def hold(h: series.Hold) -> series.Hold:
        return series.Hold(h.start + by, h.stop + by, h.value)

    return Edge(e.index + by, hold(e.before), hold(e.after))


def _metadata_window(segments: list[Segment], t: FloatArray, maneuver: Maneuver | None) -> list[Segment]:
    """Widen a moving test the signals cut short to the window its spec gives (lead-in, length).

    The signals alone can cut a slow sweep short (its first cycles sit almost still between samples
    under a noisy, quantized command). When the signal found the spec's kind (or a compatible one)
    inside the spec's window but short of it, the segment takes the whole window.
    A contradicted reading is left alone for the reconciliation to report.
    """
    lead = getattr(maneuver, "lead_s", None)
    if maneuver is None or lead is None:
        return segments
    kind = MANEUVER_KINDS.get(maneuver.kind, maneuver.kind)
    if kind not in MOVING_KINDS:
        return segments
    start_s, stop_s = float(lead), float(maneuver.duration_s)
    a = int(np.searchsorted(t, t[0] + start_s, side="left"))
    b = min(int(np.searchsorted(t, t[0] + stop_s, side="right")), t.size)
    if b - a < 2 or t[b - 1] - t[a] < MIN_MOVING_S:
        return segments
    inside = [seg for seg in segments if seg.kind in MOVING_KINDS and seg.start < b and seg.stop > a]
    agreeing = [seg for seg in inside if seg.kind == kind or (seg.kind, kind) in COMPATIBLE]
    covered = sum(min(seg.stop, b) - max(seg.start, a) for seg in agreeing)
    if not agreeing or len(agreeing) < len(inside) or covered >= (b - a) - 1:
        return segments
    seen = ", ".join(f"{seg.kind} {t[seg.start]:.3g}–{t[seg.stop - 1]:.3g} s" for seg in agreeing)
    window = Segment(agreeing[0].kind, a, b, f"signal: {seen}; widened to the metadata's {maneuver.kind} window "
                     f"{start_s:g}–{stop_s:g} s", agreeing[0].params)
    return sorted([seg for seg in segments if seg not in inside] + [window], key=lambda seg: seg.start)


def _expected(maneuver: Maneuver | None) -> list[str]:
    if maneuver is None:
        return []
    if maneuver.kind == "pid":
        return ["steps", "sweep", "schroeder"]
    return [MANEUVER_KINDS.get(maneuver.kind, maneuver.kind)]


def _spec_params(maneuver: Maneuver, kind: str) -> dict[str, float]:
    parts: list[Maneuver] = [maneuver]
    if maneuver.kind == "pid":
        parts = [m for _, m in getattr(maneuver, "_parts", ())]
    out: dict[str, float] = {}
    for m in parts:
        mk = MANEUVER_KINDS.get(m.kind, m.kind)
        if mk != kind:
            continue
        d = m.as_dict()
        for key in ("f0_hz", "f1_hz", "period_s", "freq_hz", "amp_deg"):
            if isinstance(d.get(key), int | float):
                out[key] = float(d[key])
    return out


def _reconcile(segments: list[Segment], maneuver: Maneuver | None, load: Load | None,
               notes: list[str]) -> list[Segment]:
    """Confirm or relabel segments with the metadata's maneuver and load."""
    expected = _expected(maneuver)
    out = []
    moving_expected = [k for k in expected if k in MOVING_KINDS]
    edge_expected = [k for k in expected if k in EDGE_KINDS]
    for s in segments:
        kind, ev = s.kind, s.evidence
        if s.kind in MOVING_KINDS and moving_expected:
            want = moving_expected.pop(0) if len(moving_expected) > 1 else moving_expected[0]
            kind, ev = _agree(s, want, ev)
        elif s.kind in EDGE_KINDS and edge_expected:
            kind, ev = _agree(s, edge_expected[0], ev)
        elif s.kind in HELD_KINDS and load is not None and load.kind in LOAD_KINDS and s.kind != "hold":
            kind, ev = _agree(s, LOAD_KINDS[load.kind], ev)
        elif s.kind == "hold" and maneuver is not None and maneuver.kind == "hold":
            ev += "; metadata maneuver agrees (hold)"
        params = dict(s.params)
        if maneuver is not None and kind in MOVING_KINDS + EDGE_KINDS:
            params.update(_spec_params(maneuver, kind))
        if load is not None and kind in ("load_sine",) and isinstance(getattr(load, "freq_hz", None), float):
            params["freq_hz"] = float(load.freq_hz)  # type: ignore[attr-defined]
        out.append(Segment(kind, s.start, s.stop, ev, params, s.edges, s.holds, s.moves))
    satisfied = {k: {k} for k in expected}
    satisfied["hold"] = set(HELD_KINDS)
    if maneuver is not None and not any(seg.kind in satisfied[k] for k in expected for seg in out):
        notes.append(f"metadata maneuver {maneuver.kind!r} but no such test found in the signals")
    return out


def _agree(s: Segment, want: str, evidence: str) -> tuple[str, str]:
    if s.kind == want:
        return want, f"{evidence}; metadata agrees ({want})"
    if (s.kind, want) in COMPATIBLE:
        return want, f"{evidence}; metadata says {want}"
    return s.kind, f"{evidence}; metadata says {want}, the signal disagrees, kept {s.kind}"
