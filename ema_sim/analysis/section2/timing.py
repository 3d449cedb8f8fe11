"""Command-to-surface timing (section 2.3): command to first motion, and motion to feedback.

The report measured 4 ms from the FMU command to the first motion of the surface (a servo
inclinometer on it) and 2 ms more until the LVDT feedback reached the FMU, on a 1 Hz square wave of
10 % of travel. Here each edge of a square wave or step set is timed:

* first motion (:func:`first_motion`): the response from rest starts as a parabola, so the early
  rise ``z = (y − y₀)/A`` (up to 30 % of the step or 0.5°, whichever is less) is fitted with
  ``c·s²·(1 − d·s + e·s²)``, ``s = t − t₀``, for t > t₀ and 0 before; t₀ is the first-motion
  instant, to a fraction of a sample, and the cubic and quartic terms absorb the curvature a plain
  threshold crossing or parabola would turn into bias. The quartic term is dropped (e = 0) for steps
  under 500 noise standard deviations, where its variance costs more than the bias it removes
  (LOAC, 0.003° noise, 30 seeds: 0.5° steps σ 0.42 ms without it, 0.72 ms with it; 20° steps bias
  −0.3 ms without it, −0.03 ms with it).
* command → first motion: t₀ of the surface angle (external sensor) minus the edge time; without
  a surface column, of the LVDT position. First motion is only defined from rest: an output that
  is already moving before the edge (its drift over the last 0.1 s exceeds ``STILL_NOISE`` times
  its noise: a surface deflected by a varying hinge moment through compliance and free play, or still
  ringing) is not timed when a still one is there: the edge is timed on the LVDT instead (and its
  motion to feedback is not measured). When no output is still, the edge is timed on the surface all the
  same and marked: a first motion before such an edge says nothing about the data's stamps. A surface
  whose start leads the edge by more than one edge's scatter while the LVDT's does not (an aiding load
  takes it through its free play or compliance ahead of the actuator: no parabola) is not timed either;
  the LVDT times that edge.
* motion → feedback: t₀ of the LVDT position minus t₀ of the surface, per edge.
* FMU command → first motion: when the record also carries the flight computer's side of the test
  environment (a suite bag's ``/ema/fmu/command``), the same first motion against the FMU's edge:
  the report's own figure, environment delay and lags included.

An edge's time is the first sample at which the command has left its old level (for a command that
reaches the actuator through a lag, the start of its transition, not the first sample at the new
level). With a held command a first motion before the edge is impossible and is flagged. With a
command sampled from a running demand (:mod:`ema_sim.analysis.records.command_hold`) the demand changed up to
one sample before the logged edge: the first motion is then known only to within that sample
(between the figure and the figure plus one sample; best estimate half a sample later), and the
result says so (quality ``not_determined``).

The test runs on step and square-wave segments; a square wave is recognised by :func:`read_square`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import least_squares
from typing_extensions import override

from ema_sim.analysis.estimation.quality import Quality
from ema_sim.analysis.formatting import figure
from ema_sim.analysis.formatting.markdown import bullets, image, ms, quality, table
from ema_sim.analysis.records.series import Edge, settled
from ema_sim.analysis.section2.base import RecordAnalysis, Section2Test
from ema_sim.analysis.section2.segments import EdgeRun, Reading
from ema_sim.jsontypes import JsonObject

FloatArray = NDArray[np.float64]

FIT_TOP = 0.3
"""Fraction of the step fitted for first motion..."""
QUARTIC_SNR = 500.0
"""Steps larger than this many noise standard deviations get the quartic term."""
FIT_TOP_DEG = 0.5
"""...but no more than this many degrees: a large step soon runs into its rate limit and stops being a parabola."""
PRE_EDGE_S = 0.1
"""The output's level before an edge is its mean over this long (within the edge's hold)."""
FIT_SCATTER_SAMPLES = 0.5
"""One edge's first motion scatters by up to this share of a sample (LOADA steps of 0.5–15°, 0.003° noise,
1 kHz, 20 seeds: σ 0.13–0.5 ms): the floor of the standard error of a few edges, whose spread tells little."""
STILL_NOISE = 5.0
"""An output whose drift over the pre-edge window exceeds this many noise standard deviations is moving..."""
DETECT_SHARE = 0.01
"""...and this share of the edge's jump: the least departure from the level :func:`first_motion` detects (a
drift under it moves the level the first motion is measured from by less than that)."""


def first_motion(t: FloatArray, y: FloatArray, edge: int, y0: float, amplitude: float, noise: float,
                 stop: int | None = None) -> float | None:
    """Instant the response to the edge at sample ``edge`` leaves ``y0`` (None when it never clearly does).

    Parameters
    ----------
    t : numpy.ndarray
        Sample times, s.
    y : numpy.ndarray
        The output, deg.
    edge : int
        Sample of the command edge.
    y0 : float
        Level before the edge.
    amplitude : float
        Step of the output (settled minus initial).
    noise : float
        The output's noise floor, deg.
    stop : int or None
        One past the last sample of the edge's hold (default: the end).

    Returns
    -------
    float or None
        The instant, s, or None when the output never clearly leaves its level.
    """
    stop = y.size if stop is None else stop
    if amplitude == 0.0:
        return None
    z = (y[edge:stop] - y0) / amplitude
    tt = t[edge:stop]
    zs = np.convolve(z, np.ones(3) / 3.0, mode="same")
    top = np.flatnonzero(zs >= min(FIT_TOP, max(FIT_TOP_DEG / abs(amplitude), 10.0 * noise / abs(amplitude))))
    if top.size == 0:
        return None
    i_hi = int(top[0])
    detect = max(4.0 * noise / abs(amplitude), DETECT_SHARE)
    above = np.flatnonzero(zs[: i_hi + 1] >= detect)
    if above.size == 0 or i_hi < 2:
        return None
    i_lo = int(above[0])
    t1, z1 = tt[i_lo], max(zs[i_lo], 1e-6)
    t2, z2 = tt[i_hi], zs[i_hi]
    k = np.sqrt(z2 / z1)
    t0_init = float((t2 - k * t1) / (1.0 - k)) if k != 1.0 else float(t1)
    t0_init = min(max(t0_init, tt[0] - 0.002), t1)
    span = max(t2 - t0_init, 1e-4)
    c_init = z2 / span**2
    fit_t, fit_z = tt[: i_hi + 1], z[: i_hi + 1]

    def model(p: FloatArray) -> FloatArray:
        t0, c, d, e = p
        s = np.maximum(fit_t - t0, 0.0)
        return np.asarray(c * s * s * (1.0 - d * s + e * s * s), dtype=float)

    def resid(p: FloatArray) -> FloatArray:
        return model(p) - fit_z

    quartic = 1.0 / span**2 if abs(amplitude) > QUARTIC_SNR * noise else 1e-12 / span**2
    lo = [tt[0] - 0.01, 0.0, -1.0 / span, -quartic]
    hi = [t2, np.inf, 2.0 / span, quartic]
    x0 = np.clip([t0_init, c_init, 0.0, 0.0], np.array(lo) + 1e-12, np.array(hi) - 1e-12)
    sol = least_squares(resid, x0, bounds=(lo, hi), x_scale=[span, c_init, 1.0 / span, 1.0 / span**2])
    return float(sol.x[0])


@dataclass(frozen=True)
class EdgeTiming:
    """Timing of one command edge.

    Parameters
    ----------
    time_s : float
        Time of the edge, s.
    jump_deg : float
        The command's jump, deg.
    command_to_motion_s : float or None
        Command edge to first motion, s.
    motion_to_feedback_s : float or None
        First motion to the LVDT's, s.
    fmu_to_motion_s : float or None
        FMU command edge to first motion, s.
    motion_signal : str
        The output this edge's first motion is taken from.
    moving_before : bool
        That output was already moving before the edge (no output was still): the first motion is
        measured against motion under way.
    """

    time_s: float
    jump_deg: float
    command_to_motion_s: float | None
    motion_to_feedback_s: float | None
    fmu_to_motion_s: float | None = None
    motion_signal: str = ""
    moving_before: bool = False

    def as_dict(self) -> JsonObject:
        """Plain values for JSON.

        Returns
        -------
        dict
            Edge time, jump, and the three intervals (None where not measured).
        """
        return {"time_s": self.time_s, "jump_deg": self.jump_deg, "command_to_motion_s": self.command_to_motion_s,
                "motion_to_feedback_s": self.motion_to_feedback_s, "fmu_command_to_motion_s": self.fmu_to_motion_s,
                "motion_signal": self.motion_signal, "moving_before": self.moving_before}


@dataclass(frozen=True)
class TimingResult:
    """Median timing over the edges of a square wave or step set (section 2.3).

    Parameters
    ----------
    motion_signal : str
        The output first motion is taken from.
    command_to_motion_s : float or None
        Median command to first motion, s.
    motion_to_feedback_s : float or None
        Median motion to feedback, s.
    edges : list
        The command edges.
    notes : list
        What could not be measured.
    sampled : bool
        The command was sampled from a running demand, not held.
    sample_s : float
        The record's sample interval, s.
    fmu_to_motion_s : float or None
        FMU command to first motion (a suite bag's flight-computer side), median over the edges.
    """

    motion_signal: str
    command_to_motion_s: float | None
    motion_to_feedback_s: float | None
    edges: list[EdgeTiming] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    sampled: bool = False
    """The command was sampled from a running demand, not held."""
    sample_s: float = 0.0
    fmu_to_motion_s: float | None = None
    """FMU command to first motion (a suite bag's flight-computer side), median over the edges."""

    @property
    def bounds_s(self) -> tuple[float, float] | None:
        """Where the actuator's first motion lies after the demand changed, given how the command was logged."""
        c = self.command_to_motion_s
        if c is None:
            return None
        return (max(c, 0.0), c + self.sample_s) if self.sampled else (c, c)

    @property
    def from_rest(self) -> list[float]:
        """Command to first motion of the edges whose output was still before them, s."""
        return [e.command_to_motion_s for e in self.edges
                if e.command_to_motion_s is not None and not e.moving_before]

    @property
    def early(self) -> bool:
        """First motion from rest clearly before a held command's edge (more than a quarter sample and two s.e.).

        An output already moving before its edge proves nothing about the stamps. The standard error of
        the median is taken from the edges' spread, but never below one edge's own scatter
        (``FIT_SCATTER_SAMPLES`` of a sample) over the root of their number: a single edge has no spread
        to measure.
        """
        spread = self.from_rest
        if not spread or self.sampled:
            return False
        c = float(np.median(spread))
        se = 1.2533 * float(np.std(spread)) / np.sqrt(len(spread)) if len(spread) > 1 else 0.0
        se = max(se, FIT_SCATTER_SAMPLES * self.sample_s / np.sqrt(len(spread)))
        return bool(c < -max(0.25 * self.sample_s, 2.0 * se))

    @property
    def quality(self) -> Quality:
        """``not_determined``: a sampled command, a first motion before a held edge, or no output still before one."""
        c = self.command_to_motion_s
        if c is None or self.sampled or self.early or not self.from_rest:
            return "not_determined"
        return "ok"

    @property
    def quality_note(self) -> str:
        """Why the quality is what it is."""
        c = self.command_to_motion_s
        if c is None:
            return "no edge with a clear first motion"
        if self.sampled:
            lo, hi = self.bounds_s or (c, c)
            return (f"the command is sampled, not held: the demand changed up to one sample ({1e3 * self.sample_s:.3g}"
                    f" ms) before the logged edge, so the actuator's first motion lies {1e3 * lo:.3g}-{1e3 * hi:.3g} "
                    "ms after the demand changed")
        if self.early:
            return ("first motion before the command edge: impossible for a held command; the command is sampled "
                    "rather than held, or the stamps of command and output are misaligned")
        if not self.from_rest:
            return ("every output was already moving before the edges (a varying hinge moment?): the first motion "
                    "is measured against motion under way, not from rest")
        return ""

    @property
    def total_s(self) -> float | None:
        """Command to feedback: the actuator's loop time."""
        if self.command_to_motion_s is None or self.motion_to_feedback_s is None:
            return None
        return self.command_to_motion_s + self.motion_to_feedback_s

    def as_dict(self) -> JsonObject:
        """Plain values for JSON.

        Returns
        -------
        dict
            The medians, their bounds, quality, every edge and notes.
        """
        spread = [e.command_to_motion_s for e in self.edges if e.command_to_motion_s is not None]
        return {
            "quality": self.quality, "quality_note": self.quality_note, "command_sampled": self.sampled,
            "command_to_motion_bounds_s": list(self.bounds_s) if self.bounds_s else None,
            "fmu_command_to_motion_s": self.fmu_to_motion_s,
            "motion_signal": self.motion_signal, "command_to_motion_s": self.command_to_motion_s,
            "command_to_motion_spread_s": float(np.std(spread)) if len(spread) > 1 else None,
            "motion_to_feedback_s": self.motion_to_feedback_s, "command_to_feedback_s": self.total_s,
            "edges": [e.as_dict() for e in self.edges], "notes": [*self.notes],
        }


def _pre_edge(t: FloatArray, e: Edge) -> int:
    """First sample of the window the output's level before the edge is read over."""
    return max(e.before.start, e.index - max(5, int(PRE_EDGE_S / (t[1] - t[0]))))


def moving_before(t: FloatArray, y: FloatArray, e: Edge, noise: float) -> bool:
    """Whether an output is already moving before a command edge (its fitted drift over the pre-edge window).

    Parameters
    ----------
    t : numpy.ndarray
        Time, s (uniform).
    y : numpy.ndarray
        The output, deg.
    e : Edge
        The command edge.
    noise : float
        The output's noise floor, deg.

    Returns
    -------
    bool
        True when the output drifts over the window (up to ``PRE_EDGE_S`` before the edge, within its
        hold) by more than ``STILL_NOISE`` times the noise and ``DETECT_SHARE`` of the edge's jump: twice
        the difference of the medians of its two halves (a drift's change over the whole window; an
        isolated spike moves neither median).
    """
    pre = _pre_edge(t, e)
    if e.index - pre < 4:
        return False
    yy = y[pre:e.index]
    half = yy.size // 2
    drift = 2.0 * abs(float(np.median(yy[-half:])) - float(np.median(yy[:half])))
    return drift > max(STILL_NOISE * noise, DETECT_SHARE * abs(e.jump))


def _edge_motion(t: FloatArray, y: FloatArray, e: Edge, noise: float) -> float | None:
    pre = _pre_edge(t, e)
    y0 = float(np.mean(y[pre:e.index])) if e.index > pre else float(y[e.index])
    y1, _ = settled(y, e.index, e.after.stop, 0.3)
    return first_motion(t, y, e.index, y0, y1 - y0, noise, e.after.stop)


def _time_edge(t: FloatArray, e: Edge, motion_name: str, motion: FloatArray, position: FloatArray | None,
               noise: dict[str, float]) -> tuple[str, float | None, float | None, bool, bool]:
    """One edge's first motion: the output read, the instant, motion → feedback, moving before, surface led.

    The surface's start leads the edge by more than one edge's scatter (``FIT_SCATTER_SAMPLES`` of a sample)
    while the LVDT's does not: the surface was taken through its free play or compliance by its load, and
    the LVDT's first motion is taken.
    """
    name, y = motion_name, motion
    moving = moving_before(t, y, e, noise.get(name, 0.0))
    if moving and name == "surface_deg" and position is not None \
            and not moving_before(t, position, e, noise.get("position_deg", 0.0)):
        name, y, moving = "position_deg", position, False  # the surface moves under its load: time the LVDT
    tm = _edge_motion(t, y, e, noise.get(name, 0.0))
    if name != "surface_deg" or position is None or tm is None:
        return name, tm, None, moving, False
    tp = _edge_motion(t, position, e, noise.get("position_deg", 0.0))
    if tp is not None and tm < float(t[e.index]) - FIT_SCATTER_SAMPLES * float(t[1] - t[0]) <= tp:
        return "position_deg", tp, None, moving, True
    return name, tm, None if tp is None else tp - tm, moving, False


def edge_timing(t: FloatArray, edges: list[Edge], position: FloatArray | None, surface: FloatArray | None,
                noise: dict[str, float], *, sampled: bool = False,
                fmu_command: FloatArray | None = None) -> TimingResult:
    """Time every edge; medians over the edges (see the module docstring).

    Parameters
    ----------
    t : numpy.ndarray
        Time, s (uniform).
    edges : list of Edge
        The command edges.
    position : numpy.ndarray or None
        LVDT position.
    surface : numpy.ndarray or None
        External surface angle.
    noise : dict
        Each output's noise floor.
    sampled : bool
        The command was sampled from a running demand, not held.
    fmu_command : numpy.ndarray, optional
        The flight computer's command (a suite bag), for FMU command → first motion.

    Returns
    -------
    TimingResult
        Per edge and median timing.
    """
    notes: list[str] = []
    motion = surface if surface is not None else position
    motion_name = "surface_deg" if surface is not None else "position_deg"
    if surface is None:
        notes.append("no external surface angle: first motion taken from the LVDT position, "
                     "so motion to feedback is not measured")
    elif position is None:
        notes.append("no LVDT position: motion to feedback not measured")
    assert motion is not None
    fmu_changes = np.flatnonzero(np.diff(fmu_command) != 0.0) + 1 if fmu_command is not None else None
    rows = []
    dt = float(np.median(np.diff(t)))
    leading = 0
    for e in edges:
        t_edge = float(t[e.index])
        name, tm, m2f, moving, led = _time_edge(t, e, motion_name, motion, position, noise)
        leading += led
        c2m = None if tm is None else tm - t_edge
        f2m = None
        if fmu_changes is not None and fmu_changes.size and tm is not None:
            before = fmu_changes[fmu_changes <= e.index]
            if before.size:
                f2m = tm - float(t[before[-1]])
        rows.append(EdgeTiming(t_edge, e.jump, c2m, m2f, f2m, name, moving))
    c2m_all = [r.command_to_motion_s for r in rows if r.command_to_motion_s is not None]
    m2f_all = [r.motion_to_feedback_s for r in rows if r.motion_to_feedback_s is not None]
    f2m_all = [r.fmu_to_motion_s for r in rows if r.fmu_to_motion_s is not None]
    if len(c2m_all) < len(rows):
        notes.append(f"{len(rows) - len(c2m_all)} edge(s) without a clear first motion")
    on_lvdt = sum(1 for r in rows if r.motion_signal != motion_name)
    if on_lvdt:
        notes.append(f"{on_lvdt} of {len(rows)} edge(s) timed on the LVDT position: the surface was already moving "
                     "before them, or started before them, while the LVDT was still; their motion to feedback is not "
                     "measured")
        if on_lvdt == len(rows):
            motion_name = "position_deg"
    if leading:
        notes.append(f"of those, {leading} because the surface's start came before the edge while the LVDT's did not: "
                     "a surface taken through its free play or compliance by its load leads the actuator, and its "
                     "start is no first motion (the stamps are not to blame)")
    if any(r.moving_before for r in rows):
        notes.append(f"{sum(r.moving_before for r in rows)} edge(s) with every output already moving before them: "
                     "their first motion is measured against motion under way")
    return TimingResult(
        motion_name,
        float(np.median(c2m_all)) if c2m_all else None,
        float(np.median(m2f_all)) if m2f_all else None,
        rows, notes, sampled, dt, float(np.median(f2m_all)) if f2m_all else None,
    )


def read_square(run: EdgeRun) -> Reading | None:
    """Alternating equal jumps at a steady rate (holds within 15 %): a square wave.

    Parameters
    ----------
    run : EdgeRun
        Consecutive command edges.

    Returns
    -------
    Reading or None
        ``square`` with its frequency and amplitude, or None.
    """
    inner = run.inner_holds_s
    if not run.alternating_equal or float(np.std(inner) / np.mean(inner)) >= 0.15:
        return None
    freq = 0.5 / float(np.median(inner))
    amp = run.amplitude_deg
    return Reading("square", f"square wave {freq:.3g} Hz, ±{amp:.3g}°, {run.n} edges",
                   {"freq_hz": freq, "amp_deg": amp})


class Timing(Section2Test[TimingResult]):
    """Command-to-surface timing over every edge of the step and square-wave segments."""

    key = "timing"
    title = "Command-to-surface timing (section 2.3)"
    kinds = ("steps", "square")
    absent = "no step or square-wave command edges to time"

    @override
    def run(self, ra: RecordAnalysis) -> list[TimingResult]:
        edges = [e for s in ra.segments(*self.kinds) for e in s.edges]
        if not edges:
            return []
        d = ra.data
        return [edge_timing(d.time_s, edges, d.position_deg, d.surface_deg, ra.noise_deg,
                            sampled=ra.command.assumed_sampled, fmu_command=d.extra.get("fmu_command_deg"))]


    @override
    def as_json(self, results: list[TimingResult], ra: RecordAnalysis) -> JsonObject:
        return {self.key: results[0].as_dict() if results else None}

    @override
    def markdown(self, ra: RecordAnalysis, results: list[TimingResult],
                 images: list[str | None]) -> list[str]:
        lines: list[str] = []
        for tm, img in zip(results, images, strict=True):
            head = ["command → first motion", "motion → feedback", "command → feedback", "edges", "motion from"]
            row = [f"{ms(tm.command_to_motion_s)} ms", f"{ms(tm.motion_to_feedback_s)} ms", f"{ms(tm.total_s)} ms",
                   str(len(tm.edges)), tm.motion_signal]
            if tm.fmu_to_motion_s is not None:
                head.insert(0, "FMU command → first motion")
                row.insert(0, f"{ms(tm.fmu_to_motion_s)} ms")
            lines += table(head, [row])
            lines += [f"Quality: {quality(tm.quality, tm.quality_note)}.", ""]
            if tm.fmu_to_motion_s is not None:
                lines += ["The FMU column is the report's figure (section 2.3): from the flight computer's command, "
                          "through the test environment, to the first motion; the others start at the command the "
                          "actuator received.", ""]
            lines += bullets(tm.notes)
            lines += image(img, "timing")
        return lines

    @override
    def summary(self, ra: RecordAnalysis, r: TimingResult) -> list[str]:
        if r.command_to_motion_s is None:
            return ["timing: no edge with a clear first motion"]
        m2f = r.motion_to_feedback_s
        line = (f"timing: command → first motion {1e3 * r.command_to_motion_s:.2f} ms, motion → feedback "
                f"{'—' if m2f is None else f'{1e3 * m2f:.2f} ms'}")
        if r.fmu_to_motion_s is not None:
            line += f", FMU command → first motion {1e3 * r.fmu_to_motion_s:.2f} ms"
        return [line + ("" if r.quality == "ok" else f" ({r.quality_note})")]

    @override
    def plot(self, ra: RecordAnalysis, r: TimingResult, path: Path) -> bool:
        if not r.edges:
            return False
        d = ra.data
        e = next((x for x in r.edges if x.command_to_motion_s is not None), r.edges[0])
        dt = ra.sample_s()
        sl = (d.time_s >= e.time_s - max(0.005, 3 * dt)) & (d.time_s <= e.time_s + max(0.03, 8 * dt))
        tt = 1e3 * (d.time_s[sl] - e.time_s)
        fig, ax = figure.pyplot().subplots(figsize=(8, 4))
        ax.step(tt, d.command_deg[sl], where="post", color=figure.COLORS["command"], label="command")
        if "fmu_command_deg" in d.extra:
            ax.step(tt, d.extra["fmu_command_deg"][sl], where="post", color="0.7", ls="--", label="FMU command")
        for name in d.outputs:
            ax.plot(tt, getattr(d, name)[sl], ".-", ms=3, lw=0.8, color=figure.COLORS[name], label=name)
        if e.command_to_motion_s is not None:
            ax.axvline(1e3 * e.command_to_motion_s, color=figure.COLORS[e.motion_signal or r.motion_signal], ls="--",
                       label=f"first motion {1e3 * e.command_to_motion_s:.2f} ms")
            if r.sampled:
                ax.axvspan(1e3 * e.command_to_motion_s, 1e3 * (e.command_to_motion_s + r.sample_s), color="0.9",
                           label="first motion after the demand changed (sampled command)")
            if e.motion_to_feedback_s is not None:
                ax.axvline(1e3 * (e.command_to_motion_s + e.motion_to_feedback_s), color=figure.COLORS["position_deg"],
                           ls=":", label=f"feedback moves +{1e3 * e.motion_to_feedback_s:.2f} ms")
        ax.set_xlabel("ms from the command edge")
        ax.set_ylabel("deg")
        ax.legend(fontsize=8)
        ax.grid(lw=0.3)
        c2m = r.command_to_motion_s
        ax.set_title(f"command-to-surface timing, median over {len(r.edges)} edges: "
                     f"{'—' if c2m is None else f'{1e3 * c2m:.2f} ms'} to first motion", fontsize=9)
        figure.save(fig, path)
        return True


TEST = Timing()
