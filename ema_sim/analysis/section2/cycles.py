"""A periodic test averaged over its cycles: every figure with the cycle-to-cycle spread as its uncertainty.

:mod:`ema_sim.analysis.records.periodic` recognises repeated cycles of the command; this test reads them as
one test measured ``n`` times:

* **response at the waveform's harmonics**, **bandwidth** and, for a sine or triangle, the **lag**
  at the fundamental (:mod:`ema_sim.analysis.estimation.harmonics`): only at the harmonics the waveform carries,
  never ``ok`` where the coherence is under the threshold, ``saturated`` when the output's moves are
  rate-limited (:func:`rate_limited`);
* **transitions** (square, profiled square, trapezoid): every change of the command's level in every
  cycle read against the commanded level and against the output's own last value
  (:mod:`ema_sim.analysis.estimation.settling`), per direction; a direction whose changes do not settle to the
  command before the next one is *unsettled*, with the error left;
* **repeatability**: the rms of each output cycle about the mean output cycle;
* **slope**: :func:`ema_sim.analysis.estimation.slew.measure` on the stretch, the same measurement ``ema identify``
  restarts its rate limit from;
* **change over the test**: the second order fitted on each cycle, its bandwidth and delay tested for a
  trend (:mod:`ema_sim.analysis.estimation.cycle_changes`): an actuator that changed while it was recorded
  is said to, with the values per cycle.

Each figure is a :class:`~ema_sim.analysis.estimation.quality.Measurement`: a value with its uncertainty, or
"not measured: why".
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray
from typing_extensions import override

from ema_sim.analysis.estimation import settling, slew
from ema_sim.analysis.estimation.cycle_changes import CycleChanges, cycle_changes
from ema_sim.analysis.estimation.frf import COHERENCE_GOOD
from ema_sim.analysis.estimation.grid import decimal_grid
from ema_sim.analysis.estimation.harmonics import (
    Harmonic,
    bandwidth,
    cycle_phases,
    harmonic_response,
    lag_at_fundamental,
)
from ema_sim.analysis.estimation.quality import Measurement, Quality
from ema_sim.analysis.estimation.settling import Transitions
from ema_sim.analysis.formatting import figure
from ema_sim.analysis.formatting.markdown import bullets, image, num, quality, table
from ema_sim.analysis.records.periodic import Periodicity, dwell_runs
from ema_sim.analysis.section2.base import RecordAnalysis, Section2Test
from ema_sim.analysis.section2.segments import Segment
from ema_sim.jsontypes import JsonObject

FloatArray = NDArray[np.float64]

TRANSITION_SHAPES = ("square", "profiled square", "trapezoid")
MIN_LIMITED = 2
MAJORITY = 0.5
"""A stretch is rate-limited when this share of its moves (and at least MIN_LIMITED) are."""
TRACKING_SHAPES = ("sine", "triangle")


@dataclass(frozen=True)
class CycleResult:
    """One periodic test averaged over its cycles.

    Parameters
    ----------
    kind : str
        The segment's kind.
    output : str
        The output read.
    start_s : float
        Start of the first whole cycle, s.
    end_s : float
        End of the last whole cycle, s.
    periodicity : Periodicity
        The command's cycles and waveform.
    harmonics : list
        The response at each harmonic the waveform carries.
    bandwidth : Measurement
        The −3 dB frequency, or why not.
    transitions : list
        Each direction's changes (square, profiled square, trapezoid).
    lag : Measurement
        The lag at the fundamental (sine, triangle), or why not.
    repeatability : float
        Rms of the output's cycles about their mean.
    output_span : float
        Peak to peak of the mean output cycle.
    slope : slew.Slew
        The slope of the stretch's rate-limited moves.
    mean_command : numpy.ndarray
        The mean command cycle (phase points).
    mean_output : numpy.ndarray
        The mean output cycle.
    spread_output : numpy.ndarray
        The output cycles' standard deviation at each phase point.
    unit : str
        The positions' unit as the report writes it (``°``, `` mm``).
    notes : list
        Notes.
    changes : CycleChanges
        The second order fitted on each cycle, and whether its bandwidth and delay changed over the test.
    """

    kind: str
    output: str
    start_s: float
    end_s: float
    periodicity: Periodicity
    harmonics: list[Harmonic]
    bandwidth: Measurement
    transitions: list[Transitions]
    lag: Measurement
    repeatability: float
    output_span: float
    slope: slew.Slew
    mean_command: FloatArray
    mean_output: FloatArray
    spread_output: FloatArray
    unit: str = "°"
    notes: list[str] = field(default_factory=list)
    changes: CycleChanges = field(default_factory=CycleChanges)

    @property
    def saturated(self) -> bool:
        """Most of the output's moves are rate-limited (the command outran them)."""
        return rate_limited(self.slope)

    @property
    def quality(self) -> Quality:
        """``saturated`` when rate-limited; ``not_determined`` when no harmonic is determined; else ``ok``."""
        if self.saturated:
            return "saturated"
        return "ok" if any(h.quality == "ok" for h in self.harmonics) else "not_determined"

    @property
    def quality_note(self) -> str:
        """Why the quality is what it is."""
        if self.saturated:
            return (f"{self.slope.moves} of {self.slope.seen} moves rate-limited at {self.slope.rate:.4g}"
                    f"{self.unit.strip()}/s: the "
                    "harmonics are the rate limit's describing function, not the small-signal response")
        if self.quality != "ok":
            return f"coherence under {COHERENCE_GOOD} at every harmonic"
        return ""

    def as_dict(self) -> JsonObject:
        """Plain values for JSON.

        Returns
        -------
        dict
            The waveform, its harmonics and the response at them, the bandwidth, the transitions, the
            lag, the repeatability, the slope, quality and notes.
        """
        p = self.periodicity
        return {
            "test": self.kind, "output": self.output, "start_s": self.start_s, "end_s": self.end_s,
            "period_s": p.period_s, "freq_hz": p.freq_hz,
            "cycles": p.cycles, "shape": p.shape, "amplitude": p.amplitude, "centre": p.centre,
            "cycle_mismatch": p.mismatch, "harmonics_in_command": list(p.harmonics), "odd_harmonics_only": p.odd_only,
            "harmonic_statement": p.harmonic_statement,
            "response": [h.as_dict() for h in self.harmonics], "bandwidth_3db_hz": self.bandwidth.as_dict(),
            "transitions": [tr.as_dict() for tr in self.transitions], "lag_s": self.lag.as_dict(),
            "repeatability_rms": self.repeatability, "output_peak_to_peak": self.output_span,
            "slope": self.slope.as_dict(), "quality": self.quality, "quality_note": self.quality_note,
            "notes": [*self.notes], "changes": self.changes.as_dict(),
        }


# ---------------------------------------------------------------------------------------------- computation
def rate_limited(slope: slew.Slew) -> bool:
    """Whether most of a stretch's moves are rate-limited (a stray straight move among many is not a rate limit).

    Parameters
    ----------
    slope : Slew
        :func:`ema_sim.analysis.estimation.slew.measure` on the stretch.

    Returns
    -------
    bool
        At least two moves, and at least half of those seen, rate-limited.
    """
    return slope.rate is not None and slope.moves >= max(MIN_LIMITED, MAJORITY * slope.seen)


def _level(u: FloatArray, a: int, b: int) -> float:
    return float(np.median(u[max(a, 0):max(b, a + 1)]))


def transitions(t: FloatArray, u: FloatArray, y: FloatArray, p: Periodicity, tol: float, noise: float,
                counts: float | None) -> list[Transitions]:
    """Every change of the command's level in every cycle, read against the command and the output's last value.

    Parameters
    ----------
    t : numpy.ndarray
        Time, s.
    u : numpy.ndarray
        The record's command.
    y : numpy.ndarray
        The record's output.
    p : Periodicity
        The cycles (a waveform with two dwell levels).
    tol : float
        How far the command may wander and still count as held.
    noise : float
        The output's noise floor.
    counts : float or None
        The output's count.

    Returns
    -------
    list of Transitions
        Rising, then falling (only the directions with a complete change).
    """
    top, bottom = dwell_runs(p.template, tol)
    if len(top) != 1 or len(bottom) != 1:
        return []
    m = p.template.size
    scale = p.period_samples / m
    out = []
    for name, (a, b), (oa, ob) in (("rising", top[0], bottom[0]), ("falling", bottom[0], top[0])):
        readings = []
        back = m if ob > a else 0  # the other level's dwell before this one (in the cycle before when it is later)
        for base in p.cycle_starts():
            arrive, end = round(base + a * scale), round(base + b * scale)
            other_start, other_end = round(base + (oa - back) * scale), round(base + (ob - back) * scale)
            if arrive < p.start or end > p.stop or end - arrive < 3 or other_start < 0:
                continue  # a dwell that wraps past the last whole cycle
            before = _level(u, other_start, other_end)
            after = _level(u, arrive, end)
            readings.append(settling.read(t, y, arrive, end, commanded=after, change=after - before, noise=noise,
                                          counts=counts))
        if readings:
            out.append(Transitions(name, readings))
    return out


def _repeatability(tb: FloatArray, t: FloatArray, y: FloatArray, p: Periodicity
                   ) -> tuple[float, FloatArray, FloatArray, FloatArray]:
    """Rms of the output cycles about their mean, the mean cycle, its spread, and the mean command cycle."""
    m = p.template.size
    grid = np.arange(m) / m
    margin = 2.0 / p.period_samples
    cyc = np.array([np.interp(grid, tau, y[idx]) for idx, tau in cycle_phases(tb, t, p, margin)])
    mean = np.mean(cyc, axis=0)
    return float(np.sqrt(np.mean((cyc - mean) ** 2))), mean, np.std(cyc, axis=0), p.template


def analyze_cycles(ra: RecordAnalysis, seg: Segment, p: Periodicity) -> CycleResult:
    """The periodic test of one segment (module docstring).

    Parameters
    ----------
    ra : RecordAnalysis
        The record.
    seg : Segment
        The segment.
    p : Periodicity
        Its cycles.

    Returns
    -------
    CycleResult
        Every figure.
    """
    d = ra.data
    name, y = ra.primary(("position_deg", "surface_deg"))
    t, u = d.time_s, d.command_deg
    sl = slice(p.start, p.stop)
    tb = ra.stamps if ra.stamps is not None else t
    slope = slew.measure(tb[sl], u[sl], y[sl], max(ra.noise_deg[name], slew.MIN_NOISE))
    unit = ra.unit.strip()
    saturated = (f"the output's moves are rate-limited at {slope.rate:.4g} {unit}/s ({slope.moves} of {slope.seen}): "
                 "the ratio here is the rate limit's describing function at this amplitude, not the small-signal "
                 "response") if rate_limited(slope) else ""
    harmonics = harmonic_response(tb, t, u, y, p, d.sample_hz, held=not ra.command.assumed_sampled,
                                  saturated=saturated)
    notes = [f"command: {p.harmonic_statement}"]
    if not ra.command.assumed_sampled:
        notes.append(f"the command is taken as held between samples ({ra.command.statement}): the hold's half "
                     f"sample, {0.5e3 / d.sample_hz:.3g} ms of lag, is divided out of every harmonic; a rig that logs "
                     "a running demand is read with --command sampled")
    if p.odd_only:
        notes.append("the command has no even harmonics: nothing is read at them (an output's even harmonics there "
                     "are its own asymmetry, not a response)")
    trans = (transitions(tb, u, y, p, ra.recognition.command_tolerance_deg, ra.noise_deg[name],
                         ra.resolution_deg.get(name)) if p.shape in TRANSITION_SHAPES else [])
    stamp_s = (decimal_grid(ra.stamps) or 0.0) if ra.stamps is not None else 0.0
    lag = (lag_at_fundamental(harmonics, stamp_s) if p.shape in TRACKING_SHAPES else
           Measurement(None, None, "not_determined",
                       f"not measured: a {p.shape} dwells; its transitions are read instead"))
    rep, mean_y, spread_y, mean_u = _repeatability(tb, t, y, p)
    changes = (CycleChanges(skipped=f"not read: {saturated}") if saturated else
               cycle_changes(tb, t, u, y, p, d.sample_hz, harmonics=harmonics, held=not ra.command.assumed_sampled,
                             output=name))
    return CycleResult(seg.kind, name, float(t[p.start]), float(t[p.stop - 1]), p, harmonics,
                       bandwidth(harmonics, saturated), trans, lag, rep, float(np.ptp(mean_y)), slope, mean_u, mean_y,
                       spread_y, ra.unit, notes, changes)


def periodicity_of(ra: RecordAnalysis, seg: Segment) -> Periodicity | None:
    """The :class:`~ema_sim.analysis.records.periodic.Periodicity` the recogniser found for a segment.

    Parameters
    ----------
    ra : RecordAnalysis
        The record.
    seg : Segment
        A segment with a ``cycles`` parameter.

    Returns
    -------
    Periodicity or None
        The one overlapping the segment most.
    """
    best, overlap = None, 0
    for p in ra.recognition.periodic:
        o = min(p.stop, seg.stop) - max(p.start, seg.start)
        if o > overlap:
            best, overlap = p, o
    return best


class Cycles(Section2Test[CycleResult]):
    """Every periodic test averaged over its cycles."""

    key = "periodic"
    title = "Periodic tests, averaged over their cycles"
    kinds = ("periodic",)
    absent = "no periodic command (at least 3 matching cycles) recognised"

    @override
    def run(self, ra: RecordAnalysis) -> list[CycleResult]:
        out = []
        for seg in ra.recognition.segments:
            if seg.kind not in self.kinds and "cycles" not in seg.params:
                continue
            p = periodicity_of(ra, seg)
            if p is not None:
                out.append(analyze_cycles(ra, seg, p))
        return out


    @override
    def markdown(self, ra: RecordAnalysis, results: list[CycleResult], images: list[str | None]) -> list[str]:
        u = ra.unit
        lines: list[str] = []
        for r, img in zip(results, images, strict=True):
            p = r.periodicity
            t = ra.data.time_s
            lines += [f"**{r.kind}: {p.cycles} cycles of a {p.shape}, period {p.period_s:.4g} s, "
                      f"±{p.amplitude:.4g}{u}** ({t[p.start]:.2f}-{t[p.stop - 1]:.2f} s, {r.output}): every figure is "
                      "the mean over the cycles, ± its standard error from the cycle-to-cycle spread. Quality "
                      f"{quality(r.quality, r.quality_note)}.", ""]
            lines += table(["harmonic", "f, Hz", f"command amplitude, {u.strip()}", "gain, dB", "phase, °",
                            "coherence", "quality"],
                           [[str(h.k), f"{h.freq_hz:.4g}", f"{h.command_amplitude:.3g}",
                             f"{h.gain_db:+.2f} ± {h.gain_sigma_db:.2g}",
                             f"{h.phase_deg:.1f} ± {h.phase_sigma_deg:.2g}", f"{h.coherence:.3f}",
                             quality(h.quality, h.note)] for h in r.harmonics])
            lines.append(f"- bandwidth: {r.bandwidth.statement}")
            if p.shape in TRACKING_SHAPES:
                lines.append(f"- tracking: {r.lag.statement}")
            for tr in r.transitions:
                oc, oc_se = tr.overshoot_command
                of, of_se = tr.overshoot_final
                lines.append(f"- {tr.direction} changes ({len(tr.readings)}, {tr.change:+.4g}{u}): "
                             f"{tr.settling_command.statement}; overshoot past the command {oc:.1f} %"
                             f"{_pm(oc_se)}, past its own last value {of:.1f} %{_pm(of_se)}")
            sl = r.slope
            lines.append(f"- slope of the rate-limited moves: {num(sl.rate, '.4g', f' {u.strip()}/s')}"
                         + (f" ± {sl.sigma:.2g}" if sl.sigma else "") + f" ({sl.moves} of {sl.seen} moves)")
            lines.append(f"- repeatability: the output's cycles lie {r.repeatability:.3g}{u} rms about their mean "
                         f"({100 * r.repeatability / max(r.output_span, 1e-12):.2g} % of its peak to peak)")
            ch = r.changes
            lines.append("- change over the test: " + ("; ".join(ch.statements) if ch.statements else
                                                      f"not read: {ch.skipped}"))
            lines.append("")
            lines += bullets(r.notes)
            lines += image(img, "periodic test")
        return lines

    @override
    def summary(self, ra: RecordAnalysis, r: CycleResult) -> list[str]:
        p = r.periodicity
        head = f"periodic {p.shape}: {p.cycles} cycles of {p.period_s:.4g} s; bandwidth {r.bandwidth.statement}"
        lines = [head + ("" if r.quality == "ok" else f" [{r.quality}]")]
        lines += [f"  {tr.direction}: {tr.settling_command.statement}" for tr in r.transitions]
        if p.shape in TRACKING_SHAPES:
            lines.append(f"  tracking: {r.lag.statement}")
        lines += [f"  {text}" for text, tr in zip(r.changes.statements, (r.changes.bandwidth, r.changes.delay),
                                                   strict=False) if tr is not None and tr.changed]
        return lines

    @override
    def plot(self, ra: RecordAnalysis, r: CycleResult, path: Path) -> bool:
        p = r.periodicity
        fig, ax = figure.pyplot().subplots(1, 2, figsize=(11, 4))
        ph = np.arange(r.mean_output.size) / r.mean_output.size * p.period_s
        ax[0].plot(ph, r.mean_command, color=figure.COLORS["command"], lw=0.9, label="command (median cycle)")
        ax[0].plot(ph, r.mean_output, color=figure.COLORS.get(r.output, "tab:blue"), lw=1.0,
                   label=f"{r.output} (mean of {p.cycles} cycles)")
        ax[0].fill_between(ph, r.mean_output - 2 * r.spread_output, r.mean_output + 2 * r.spread_output,
                           color=figure.COLORS.get(r.output, "tab:blue"), alpha=0.25, label="±2σ over the cycles")
        ax[0].set_xlabel("time in the cycle, s")
        ax[0].legend(fontsize=7)
        ax[0].set_title(f"{p.cycles} cycles of a {p.shape}, {p.period_s:.4g} s", fontsize=9)
        if r.harmonics:
            f = [h.freq_hz for h in r.harmonics]
            ok = [h.quality == "ok" for h in r.harmonics]
            ax[1].errorbar(f, [h.gain_db for h in r.harmonics], yerr=[2 * h.gain_sigma_db for h in r.harmonics],
                           fmt="o", ms=4, label="gain, dB (±2σ over the cycles)")
            ax[1].scatter([x for x, k in zip(f, ok, strict=True) if not k],
                          [h.gain_db for h, k in zip(r.harmonics, ok, strict=True) if not k], marker="x", color="r",
                          zorder=3, label="not ok (coherence or saturation)")
            ax[1].set_xscale("log")
            ax[1].set_xlabel("harmonic frequency, Hz")
            ax[1].set_ylabel("gain, dB")
            ax[1].legend(fontsize=7)
            ax[1].set_title(r.bandwidth.statement[:90], fontsize=8)
        for a in ax:
            a.grid(lw=0.3, which="both")
        figure.save(fig, path)
        return True


TEST = Cycles()


def _pm(sigma: float | None) -> str:
    """`` ± σ``, or that the spread is not determined (None: one reading, or identical ones, a spread of 0)."""
    return f" ± {sigma:.2g}" if sigma is not None else " (its spread not determined)"
