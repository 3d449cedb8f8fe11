"""Which section-2 tests a record holds, and where: from its signals, checked against its metadata.

A rig's CSV may carry no metadata, so every test is recognised from the signals first:

* **edges** of the held digital command (jumps of ≥ 0.05° between holds of ≥ 40 ms) grouped into
  runs: a *staircase* (≥ 6 edges, ≥ 5 levels, holds ≥ 0.8 s, mostly one direction: calibration), a
  *square* wave (alternating equal jumps at a steady rate: timing), a square wave whose holds shrink
  (*regen*, the regeneration sweep), or *steps*;
* **moving** stretches of the command (not held, not edges), by their turning points: one tone of
  steady period (a *sine* dwell or a *triangle*; growing amplitude: *static_threshold* below 1 Hz,
  *dynamic_threshold* above), a period that shrinks steadily (*sweep*), a slow monotone *ramp*, or an
  irregular broadband signal (*schroeder* when it repeats, else *broadband*);
* **held command** for ≥ 5 s: with a varying hinge moment, a load staircase (*load_steps*:
  compliance), two opposite load levels (*load_reversal*: free play) or a sinusoidal load
  (*load_sine*: hysteresis); with a constant load, a *hold* (crosstalk, dither).

The metadata's maneuver and load specs (``ema simulate``, the maneuver node's bags) then confirm each
segment or relabel it, adding the spec's parameters (sweep band, Schroeder period, tone frequency);
every segment says what it was recognised from.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from itertools import pairwise
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ema_sim.analysis import series
from ema_sim.analysis.noise import autocorrelation
from ema_sim.analysis.series import Edge, Hold
from ema_sim.analysis.sine_fit import fit_sine
from ema_sim.errors import EmaError
from ema_sim.io.csv import MeasuredData
from ema_sim.signals import Load, Maneuver, parse_load, parse_maneuver

FloatArray = NDArray[np.float64]

EDGE_KINDS = ("steps", "square", "regen", "staircase")
MOVING_KINDS = ("sweep", "schroeder", "broadband", "sine", "triangle", "static_threshold", "dynamic_threshold", "ramp")
HELD_KINDS = ("hold", "load_steps", "load_reversal", "load_sine")
MIN_EDGE_HOLD_S = 0.04
LONG_HOLD_S = 0.3
MIN_MOVING_S = 1.0
HELD_TEST_S = 5.0
MIN_LOAD_SWING_INLB = 20.0

MANEUVER_KINDS = {
    "step": "steps", "steps": "steps", "square": "square", "regen": "regen", "staircase": "staircase",
    "sweep": "sweep", "schroeder": "schroeder", "sine": "sine", "triangle": "triangle", "ramp": "ramp",
    "static_threshold": "static_threshold", "dynamic_threshold": "dynamic_threshold", "hold": "hold",
}
LOAD_KINDS = {"steps": "load_steps", "reversal": "load_reversal", "sine": "load_sine"}
COMPATIBLE = {("broadband", "schroeder"), ("broadband", "sweep"), ("sine", "triangle"), ("triangle", "sine"),
              ("steps", "square"), ("square", "steps"), ("steps", "regen"), ("square", "regen"),
              ("load_reversal", "load_steps"), ("load_steps", "load_reversal")}
"""(signal reading, metadata kind) pairs a signal can mistake for each other."""


@dataclass(frozen=True)
class Segment:
    """Samples ``[start, stop)`` of one test of kind ``kind``."""

    kind: str
    start: int
    stop: int
    evidence: str
    params: dict[str, float] = field(default_factory=dict)
    edges: tuple[Edge, ...] = ()
    holds: tuple[Hold, ...] = ()

    def as_dict(self, t: FloatArray) -> dict[str, Any]:
        """Plain values for JSON."""
        return {"kind": self.kind, "start_s": float(t[self.start]), "end_s": float(t[self.stop - 1]),
                "evidence": self.evidence, "params": self.params}


@dataclass(frozen=True)
class Recognition:
    """The segments of a record, in time order, and what the metadata said."""

    segments: list[Segment]
    maneuver: Maneuver | None
    load: Load | None
    notes: list[str] = field(default_factory=list)

    def of(self, *kinds: str) -> list[Segment]:
        """Segments of the given kinds."""
        return [s for s in self.segments if s.kind in kinds]


# ---------------------------------------------------------------------------------------------- edges
def _group_edges(edges: list[Edge]) -> list[list[Edge]]:
    groups: list[list[Edge]] = []
    for e in edges:
        if groups and groups[-1][-1].after.start == e.before.start:
            groups[-1].append(e)
        else:
            groups.append([e])
    return groups


def _classify_edges(group: list[Edge], dt: float) -> tuple[str, str, dict[str, float]]:
    jumps = np.array([e.jump for e in group])
    levels = [group[0].before.value] + [e.after.value for e in group]
    distinct = np.unique(np.round(levels, 6)).size
    holds_s = np.array([e.after.length * dt for e in group])
    n = len(group)
    same_dir = float(np.mean(np.sign(jumps[1:]) == np.sign(jumps[:-1]))) if n > 1 else 0.0
    if n >= 6 and distinct >= 5 and np.median(holds_s) >= 0.8 and same_dir >= 0.6:
        return "staircase", f"{n} edges over {distinct} held levels, mostly one way (calibration staircase)", {}
    mags = np.abs(jumps[1:]) if n > 3 else np.abs(jumps)
    alternating = n >= 3 and bool(np.all(np.sign(jumps[1:]) != np.sign(jumps[:-1])))
    if alternating and np.ptp(mags) <= 0.1 * np.median(mags) and distinct <= 3:
        inner = holds_s[:-1] if n > 2 else holds_s
        cv = float(np.std(inner) / np.mean(inner))
        amp = float(np.median(mags) / 2.0)
        if cv < 0.15:
            freq = 0.5 / float(np.median(inner))
            return "square", f"square wave {freq:.3g} Hz, ±{amp:.3g}°, {n} edges", {"freq_hz": freq, "amp_deg": amp}
        if inner[-1] < 0.5 * inner[0]:
            f0, f1 = 0.5 / float(inner[0]), 0.5 / float(inner[-1])
            return "regen", f"square wave swept {f0:.3g}-{f1:.3g} Hz, ±{amp:.3g}°", {"f0_hz": f0, "f1_hz": f1}
    return "steps", f"{n} step edge(s) of {', '.join(f'{j:+.3g}°' for j in jumps[:6])}{'...' if n > 6 else ''}", {}


# ---------------------------------------------------------------------------------------------- moving
def _spearman(x: FloatArray) -> float:
    r = np.argsort(np.argsort(x)).astype(float)
    i = np.arange(x.size, dtype=float)
    return float(np.corrcoef(i, r)[0, 1]) if x.size > 2 else 0.0


def _period_by_autocorrelation(u: FloatArray, dt: float) -> tuple[float, float] | None:
    """Lag (≥ 1 s, ≤ 60 % of the record) of the highest unbiased autocorrelation, refined parabolically."""
    n = u.size
    lo = round(1.0 / dt)
    hi = int(0.6 * n)
    if hi < lo + 2:
        return None
    rho = autocorrelation(u, hi)
    # The biased estimator shrinks by (1 − k/N); undo it so a repeat late in the record counts fully.
    k = np.arange(rho.size)
    rho = rho / (1.0 - k / n)
    i = lo + int(np.argmax(rho[lo:hi]))
    lag = float(i)
    if lo < i < hi - 1:
        den = rho[i - 1] - 2 * rho[i] + rho[i + 1]
        if den < 0:
            lag += 0.5 * (rho[i - 1] - rho[i + 1]) / den
    return float(lag * dt), float(rho[i])


def _classify_moving(t: FloatArray, u: FloatArray) -> tuple[str, str, dict[str, float]]:  # noqa: PLR0911 - per kind
    dt = float(np.median(np.diff(t)))
    turns = series.extrema(u)
    span = float(t[-1] - t[0])
    if turns.size <= 3:
        rate = np.abs(np.diff(u)) / dt
        fast = float(np.percentile(rate, 99)) if rate.size else 0.0
        if fast < 1.0:
            return "ramp", f"slow monotone command (≤ {fast:.3g} °/s, {turns.size} turning point(s))", {}
        return "broadband", "moving command with few turning points", {}
    half = np.diff(t[turns])
    swing = np.abs(np.diff(u[turns]))
    cv = float(np.std(half) / np.mean(half))
    if turns.size >= 6 and cv < 0.15:
        freq = 0.5 / float(np.median(half))
        k = min(3, swing.size // 3)
        growth = float(np.median(swing[-k:]) / max(np.median(swing[:k]), 1e-12))
        if growth > 1.5:
            kind = "static_threshold" if freq < 1.0 else "dynamic_threshold"
            return kind, f"{freq:.3g} Hz tone whose amplitude grows {growth:.2g}×", {"freq_hz": freq}
        tone = fit_sine(t, u, freq)
        r2 = tone.r2 if tone else 0.0
        freq = tone.freq_hz if tone else freq
        kind = "sine" if r2 > 0.99 else "triangle"
        return kind, f"steady {freq:.4g} Hz {'sine' if kind == 'sine' else 'triangle'} (sine R² {r2:.3f})", \
            {"freq_hz": freq, "amp_deg": float(np.median(swing) / 2)}
    if turns.size >= 12:
        rho = _spearman(half)
        f0, f1 = 0.5 / float(np.median(half[:3])), 0.5 / float(np.median(half[-3:]))
        if rho < -0.9 and f1 / f0 > 3.0:
            return "sweep", f"sine sweep {f0:.3g}-{f1:.3g} Hz (period shrinks steadily)", {"f0_hz": f0, "f1_hz": f1}
    per = _period_by_autocorrelation(u, dt)
    if per is not None and per[1] > 0.9 and span >= 1.9 * per[0]:
        return "schroeder", f"broadband command repeating every {per[0]:.4g} s (autocorrelation {per[1]:.3f})", \
            {"period_s": per[0]}
    return "broadband", f"broadband command ({turns.size} irregular turning points)", {}


# ---------------------------------------------------------------------------------------------- held
def _classify_held(t: FloatArray, hm: FloatArray | None, start: int, stop: int) -> tuple[str, str, tuple[Hold, ...]]:
    if hm is None:
        return "hold", "command held, no hinge moment recorded", ()
    seg = hm[start:stop]
    swing = float(np.ptp(seg))
    if swing < MIN_LOAD_SWING_INLB:
        return "hold", f"command held, load constant ({swing:.3g} in·lb swing)", ()
    dt = float(np.median(np.diff(t)))
    hs = [Hold(h.start + start, h.stop + start, h.value)
          for h in series.holds(seg, round(LONG_HOLD_S / dt), max(series.hold_tolerance(seg), 1e-3 * swing))]
    covered = sum(h.length for h in hs) / max(stop - start, 1)
    levels = np.unique(np.round([h.value / (0.01 * swing) for h in hs]))
    signs = [np.sign(h.value) if abs(h.value) > 0.05 * swing else 0.0 for h in hs]
    reversals = sum(1 for a, b in pairwise(signs) if a * b < 0)
    if covered >= 0.7 and reversals >= 2 and levels.size <= 3:
        nonzero = [h.value for h in hs if abs(h.value) > 0.05 * swing]
        return "load_reversal", f"command held; load reversing {reversals} times between {min(nonzero):.3g} " \
                                f"and {max(nonzero):.3g} in·lb", tuple(hs)
    if covered >= 0.7 and levels.size >= 3:
        return "load_steps", f"command held; load staircase over {levels.size} levels ({swing:.4g} in·lb swing)", \
            tuple(hs)
    return "load_sine", f"command held; load moving continuously ({swing:.4g} in·lb swing)", ()


# ---------------------------------------------------------------------------------------------- main
def _spec(data: MeasuredData, key: str) -> tuple[Maneuver | Load | None, str | None]:
    text = data.metadata.get(key)
    if not text:
        return None, None
    try:
        return (parse_maneuver(text) if key == "maneuver" else parse_load(text)), None
    except EmaError as exc:
        return None, f"metadata {key} {text!r} not understood ({exc})"


def _runs(mask: NDArray[np.bool_]) -> list[tuple[int, int]]:
    padded = np.concatenate([[False], mask, [False]])
    d = np.flatnonzero(np.diff(padded.astype(np.int8)))
    return list(zip(d[::2].tolist(), d[1::2].tolist(), strict=True))


def recognize(data: MeasuredData) -> Recognition:
    """Segments of ``data`` (uniformly sampled) with the evidence for each; see the module docstring."""
    t, u = data.time_s, data.command_deg
    dt = float(np.median(np.diff(t)))
    notes: list[str] = []
    maneuver, note_m = _spec(data, "maneuver")
    load, note_l = _spec(data, "load")
    notes += [n for n in (note_m, note_l) if n]
    tol = series.hold_tolerance(u)
    edges = series.edges(u, dt, min_hold_s=MIN_EDGE_HOLD_S, min_jump=max(0.05, 20.0 * tol), tol=tol)
    segments: list[Segment] = []
    stepped = np.zeros(u.size, dtype=bool)
    for group in _group_edges(edges):
        kind, why, params = _classify_edges(group, dt)
        start, stop = group[0].before.start, group[-1].after.stop
        stepped[start:stop] = True
        holds = tuple([group[0].before] + [e.after for e in group])
        segments.append(Segment(kind, start, stop, f"signal: {why}", params, tuple(group), holds))
    long_holds = series.holds(u, round(LONG_HOLD_S / dt), tol)
    held = np.zeros(u.size, dtype=bool)
    for h in long_holds:
        held[h.start:h.stop] = True
    moving = ~held & ~stepped
    spans = _runs(moving)
    # Merge moving stretches split by short pauses (a quantized command sits still near its peaks).
    merged: list[tuple[int, int]] = []
    for a, b in spans:
        if merged and a - merged[-1][1] < round(1.0 / dt) and not stepped[merged[-1][1]:a].any():
            merged[-1] = (merged[-1][0], b)
        else:
            merged.append((a, b))
    for lo, hi in merged:
        # Leading and trailing samples where the command sits still belong to no test.
        a, b = lo, hi
        before = max(lo - 1, 0)
        changes = np.flatnonzero(np.abs(np.diff(u[before:hi])) > tol)
        if changes.size:
            a, b = before + int(changes[0]) + 1, before + int(changes[-1]) + 2
        if (b - a) * dt < MIN_MOVING_S:
            continue
        kind, why, params = _classify_moving(t[a:b], u[a:b])
        segments.append(Segment(kind, a, b, f"signal: {why}", params))
    for h in long_holds:
        if (h.stop - h.start) * dt >= HELD_TEST_S:
            kind, why, hs = _classify_held(t, data.hinge_moment_inlb, h.start, h.stop)
            segments.append(Segment(kind, h.start, h.stop, f"signal: {why}", {"command_deg": h.value}, holds=hs))
    segments.sort(key=lambda s: s.start)
    segments = _metadata_window(segments, t, maneuver)
    segments = _reconcile(segments, maneuver, load, notes)
    if not segments:
        notes.append("no section-2 test recognised in the signals")
    return Recognition(segments, maneuver, load, notes)


def _metadata_window(segments: list[Segment], t: FloatArray, maneuver: Maneuver | None) -> list[Segment]:
    """Widen a moving test the signals cut short to the window its spec gives (lead-in, length).

    The signals alone can cut a slow sweep short (its first cycles sit almost still between samples
    under a noisy, quantized command). When the signal found the spec's kind (or a compatible one)
    inside the spec's window but short of it, the segment takes the whole window.
    A contradicted reading is left alone for the reconciliation to report.
    """
    if maneuver is None or not hasattr(maneuver, "lead_s"):
        return segments
    kind = MANEUVER_KINDS.get(maneuver.kind, maneuver.kind)
    if kind not in MOVING_KINDS:
        return segments
    start_s, stop_s = float(maneuver.lead_s), float(maneuver.duration_s)  # type: ignore[attr-defined]
    a = int(np.searchsorted(t, t[0] + start_s, side="left"))
    b = min(int(np.searchsorted(t, t[0] + stop_s, side="right")), t.size)
    if b - a < 2 or t[b - 1] - t[a] < MIN_MOVING_S:
        return segments
    inside = [seg for seg in segments if seg.kind in MOVING_KINDS and seg.start < b and seg.stop > a]
    agreeing = [seg for seg in inside if seg.kind == kind or (seg.kind, kind) in COMPATIBLE]
    covered = sum(min(seg.stop, b) - max(seg.start, a) for seg in agreeing)
    if not agreeing or len(agreeing) < len(inside) or covered >= 0.99 * (b - a):
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
        parts = [m for _, m in maneuver._parts]
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
        out.append(Segment(kind, s.start, s.stop, ev, params, s.edges, s.holds))
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
