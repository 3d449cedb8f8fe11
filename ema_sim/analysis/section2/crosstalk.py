"""Crosstalk noise on an observed channel (section 2.2) against its threshold.

Static crosstalk: the observed channel is held while the others move; its feedback should not move.
Dynamic crosstalk: it follows a slow 0.5 Hz triangle while the others move; noise would ride on the
ramp. The noise is what is left after removing what the command explains:

* held command: the output minus its mean and linear trend;
* moving command: the output minus a second order with delay, gain and bias fitted to it on the same
  command (:func:`ema_sim.analysis.estimation.second_order_fit.fit_step`), which takes out the tracking and the
  actuator's own transients at the triangle's corners.

Peak-to-peak and RMS of that residual, the RMS in excess of the white sensor noise floor, the same in
volts through the feedback curve's slope, and the verdict against the threshold: the report's right
wing saw 0.02 V (≈ 0.086°) of noise, "below the threshold command level".

Crosstalk is what the command does *not* explain, so on a moving command the observed channel must
follow its command: an output whose rate on the triangle's ramps falls 5 % short of the command's
(a rate limit) lags ever further behind, and the residual must be independent of the command
(:func:`ema_sim.analysis.estimation.noise.input_independence`, lags up to 0.1 s). Otherwise what the fit leaves
is tracking error, not crosstalk, and it is not judged against the threshold (quality
``not_determined``).

No verdict without its measurement:

* crosstalk is the noise *another* channel's motion puts on this one, so a verdict needs a second
  channel that moves (:func:`crosstalk_sources`): a suite bag's plan naming the other channels'
  maneuvers, the metadata's ``static_crosstalk``/``dynamic_crosstalk`` test (three other surfaces
  square, tables 2 and 3), or a ``moving_channels`` metadata line. A single-channel record gets the
  figures of its held (or tracking) output only, quality ``not_determined``, no verdict;
* the threshold is the channel's own: given (``--threshold-deg``), measured in this record (or
  another of the same channel), else table A2's, which belongs to the X-43A and applies only to a
  channel named by ``--channel`` or by the record. A stand-in channel has no threshold: figures only.

The test is recognised from a held command with a constant load (:func:`read_hold`) or a steady
tone that is no sine (:func:`read_triangle`); dither runs on the same holds.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from numpy.typing import NDArray
from typing_extensions import override

from ema_sim.analysis.estimation.noise import IndependenceTest, input_independence
from ema_sim.analysis.estimation.second_order_fit import fit_step, simulate
from ema_sim.analysis.estimation.sine_fit import dominant_frequency
from ema_sim.analysis.formatting import figure
from ema_sim.analysis.formatting.markdown import bullets, image, quality
from ema_sim.analysis.section2.base import Quality, RecordAnalysis, Section2Test
from ema_sim.analysis.section2.hysteresis import MIN_LOAD_SWING_INLB
from ema_sim.analysis.section2.segments import SINE_R2, HeldStretch, MovingStretch, Reading
from ema_sim.analysis.section2.threshold import STATIC
from ema_sim.config import ChannelConfig
from ema_sim.jsontypes import JsonObject

FloatArray = NDArray[np.float64]

SPEC_THRESHOLD_IN = 0.0075
"""Threshold with inertial load, table A2 (inches of actuator travel)."""
INDEPENDENCE_LAG_S = 0.1
KEEP_UP = 0.95
"""The output's rate on the ramps must reach this share of the command's."""

@dataclass(frozen=True)
class CrosstalkResult:
    """Noise on the observed channel and how it compares with the threshold.

    Parameters
    ----------
    output : str
        Name of the output.
    kind : str
        ``static (command held)`` or ``dynamic (command moving)``.
    peak_to_peak_deg : float
        Peak to peak of the residual, deg.
    rms_deg : float
        Its RMS, deg.
    excess_rms_deg : float
        RMS above the sensor noise, deg.
    sensor_noise_deg : float
        The output's noise floor, deg.
    dominant_hz : float or None
        Frequency of the residual's largest spectral peak, Hz.
    volts_per_deg : float
        Feedback volts per degree.
    threshold_deg : float or None
        The threshold it is judged against, deg (None: no threshold applies).
    threshold_source : str
        Where the threshold comes from, or why there is none.
    residual : numpy.ndarray
        What the command does not explain, deg.
    notes : list
        How the tracking was taken out.
    independence : IndependenceTest or None
        The residual against the command (moving command only).
    rates_dps : tuple[float, float] or None
        Command's and output's median rate on the ramps (moving command only).
    start : int
        First sample of the segment.
    stop : int
        One past the last sample.
    sources : tuple
        The other channels that move while this one is observed (none: no crosstalk to judge).
    sources_note : str
        Where they come from, or why there are none.
    """

    output: str
    kind: str
    peak_to_peak_deg: float
    rms_deg: float
    excess_rms_deg: float
    sensor_noise_deg: float
    dominant_hz: float | None
    volts_per_deg: float
    threshold_deg: float | None
    threshold_source: str
    residual: FloatArray
    notes: list[str] = field(default_factory=list)
    independence: IndependenceTest | None = None
    """The residual against the command (moving command only)."""
    rates_dps: tuple[float, float] | None = None
    """Command's and output's median rate on the ramps (moving command only)."""
    start: int = 0
    stop: int = 0
    sources: tuple[str, ...] = ()
    sources_note: str = ""

    @property
    def below_threshold(self) -> bool | None:
        """Peak-to-peak noise below the threshold amplitude (None: no threshold applies)."""
        return None if self.threshold_deg is None else self.peak_to_peak_deg < self.threshold_deg

    @property
    def lags_behind(self) -> bool:
        """The output's rate on the ramps falls 5 % short of the command's."""
        return self.rates_dps is not None and self.rates_dps[1] < KEEP_UP * self.rates_dps[0]

    @property
    def tracking_error(self) -> bool:
        """The output does not follow its command: what the fit leaves is tracking error."""
        dependent = self.independence is not None and not self.independence.independent
        return dependent or self.lags_behind

    @property
    def quality(self) -> Quality:
        """``not_determined`` without a second channel that moves, or when the output does not follow its command."""
        return "not_determined" if self.tracking_error or not self.sources else "ok"

    @property
    def quality_note(self) -> str:
        """Why the quality is what it is."""
        notes = []
        if self.tracking_error and self.independence is not None:
            if self.lags_behind and self.rates_dps is not None:
                rc, ro = self.rates_dps
                notes.append(f"the output moves at {ro:.3g} °/s on the ramps against the command's {rc:.3g} °/s: it "
                             "lags ever further behind, so the residual is tracking error, not crosstalk noise")
            else:
                ind = self.independence
                notes.append(f"the residual follows the command's rate (correlation {ind.peak_correlation:+.2f} at lag "
                             f"{ind.peak_lag}, band ±{ind.bound:.2g}): tracking error, not crosstalk noise")
        if not self.sources:
            notes.append(f"no second channel moves ({self.sources_note}): the figures are this output's own noise, "
                         "not crosstalk")
        return "; ".join(notes)

    @property
    def verdict(self) -> str:
        """``below``, ``ABOVE``, or ``not judged`` (not crosstalk, or no threshold for this channel)."""
        if self.quality != "ok" or self.below_threshold is None:
            return "not judged"
        return "below" if self.below_threshold else "ABOVE"

    def as_dict(self) -> JsonObject:
        """Plain values for JSON.

        Returns
        -------
        dict
            Peak to peak and RMS in degrees and volts, the threshold and the verdict, quality and notes.
        """
        v = self.volts_per_deg
        return {
            "quality": self.quality, "quality_note": self.quality_note, "verdict": self.verdict,
            "input_independence": {**self.independence.as_dict()} if self.independence else None,
            "output": self.output, "test": self.kind, "peak_to_peak_deg": self.peak_to_peak_deg,
            "peak_to_peak_v": self.peak_to_peak_deg * v, "rms_deg": self.rms_deg, "rms_v": self.rms_deg * v,
            "excess_rms_over_sensor_noise_deg": self.excess_rms_deg, "sensor_noise_deg": self.sensor_noise_deg,
            "dominant_hz": self.dominant_hz, "threshold_deg": self.threshold_deg,
            "threshold_source": self.threshold_source, "below_threshold": self.below_threshold, "notes": [*self.notes],
            "moving_channels": list(self.sources), "moving_channels_source": self.sources_note,
        }


def _tracking_residual(t: FloatArray, u: FloatArray, y: FloatArray) -> tuple[FloatArray, str]:
    """The output less a second order with delay fitted to it on the same command (time domain)."""
    fit = fit_step(t, u, y, test="tracking", output_name="", wn0=50.0, zeta0=0.7, delay0=0.005)
    dt = float(np.median(np.diff(t)))
    model = fit.gain.value * simulate(u, dt, fit.wn_rad_s.value, fit.zeta.value, fit.delay_s.value)
    model += fit.bias_deg.value if fit.bias_deg else 0.0
    how = (f"tracking removed by a fitted second order (ωn {fit.wn_rad_s.value:.1f} rad/s, ζ {fit.zeta.value:.2f}, "
           f"delay {1e3 * fit.delay_s.value:.1f} ms)")
    return y - model, how


def crosstalk_noise(t: FloatArray, u: FloatArray, y: FloatArray, sensor_noise: float, *, output: str,
                    threshold_deg: float | None, threshold_source: str, volts_per_deg: float) -> CrosstalkResult:
    """Residual noise of the observed channel (see the module docstring).

    Parameters
    ----------
    t : numpy.ndarray
        Time, s.
    u : numpy.ndarray
        Command, deg.
    y : numpy.ndarray
        The observed channel's output, deg.
    sensor_noise : float
        Its noise floor, deg.
    output : str
        Its name.
    threshold_deg : float or None
        The threshold the noise is judged against (None: none applies).
    threshold_source : str
        Where the threshold comes from.
    volts_per_deg : float
        Feedback volts per degree.

    Returns
    -------
    CrosstalkResult
        The residual and its figures.
    """
    notes: list[str] = []
    held = np.ptp(u) <= 1e-9 * max(1.0, float(np.max(np.abs(u))))
    independence = None
    rates = (0.0, 0.0)
    if held:
        coef = np.polyfit(t - t[0], y, 1)
        resid = y - np.polyval(coef, t - t[0])
        kind = "static (command held)"
    else:
        resid, how = _tracking_residual(t, u, y)
        kind = "dynamic (command moving)"
        notes.append(how)
        dt = float(np.median(np.diff(t)))
        independence = input_independence(resid, u, max(2, round(INDEPENDENCE_LAG_S / dt)))
        du, dy = np.gradient(u, t), np.gradient(y, t)
        ramp = np.abs(du) >= 0.5 * float(np.max(np.abs(du)))
        rates = (float(np.median(np.abs(du[ramp]))), float(np.median(np.abs(dy[ramp]))))
    rms = float(np.sqrt(np.mean(resid**2)))
    excess = float(np.sqrt(max(rms * rms - sensor_noise * sensor_noise, 0.0)))
    dom = dominant_frequency(t, resid, f_min=0.2)
    return CrosstalkResult(output, kind, float(np.ptp(resid)), rms, excess, sensor_noise, dom, volts_per_deg,
                           threshold_deg, threshold_source, resid, notes, independence,
                           None if held else rates)


def read_hold(h: HeldStretch) -> Reading | None:
    """A held command with no hinge moment or a constant one: a crosstalk (and dither) hold.

    Parameters
    ----------
    h : HeldStretch
        A held stretch of the command.

    Returns
    -------
    Reading or None
        ``hold``, or None when the load moves.
    """
    if h.load is None:
        return Reading("hold", "command held, no hinge moment recorded")
    if h.swing < MIN_LOAD_SWING_INLB:
        return Reading("hold", f"command held, load constant ({h.swing:.3g} in·lb swing)")
    return None


def read_triangle(m: MovingStretch) -> Reading | None:
    """A steady tone a sine does not explain (R² < 0.99): a triangle (dynamic crosstalk, section 2.2.2).

    Parameters
    ----------
    m : MovingStretch
        A moving stretch of the command.

    Returns
    -------
    Reading or None
        ``triangle`` with its frequency and amplitude, or None.
    """
    if not m.steady:
        return None
    r2 = m.sine.r2 if m.sine else 0.0
    if r2 > SINE_R2:
        return None
    freq = m.sine.freq_hz if m.sine else m.tone_hz
    return Reading("triangle", f"steady {freq:.4g} Hz triangle (sine R² {r2:.3f})",
                   {"freq_hz": freq, "amp_deg": float(np.median(m.swings) / 2)})


def crosstalk_sources(ra: RecordAnalysis) -> tuple[tuple[str, ...], str]:
    """The other channels that move while this one is observed, from what the record says (module docstring).

    Parameters
    ----------
    ra : RecordAnalysis
        The record.

    Returns
    -------
    tuple
        The moving channels (empty: none known), and where they come from or why there are none.
    """
    meta = ra.data.metadata
    own = ra.channel.channel if ra.channel_named else meta.get("channel")
    if meta.get("moving_channels"):
        names = tuple(n.strip() for n in meta["moving_channels"].split(",") if n.strip() and n.strip() != own)
        if names:
            return names, "the metadata's moving_channels"
    plan = meta.get("plan")
    if plan:
        try:
            doc = json.loads(plan)
        except ValueError:
            doc = {}
        moving = tuple(ch for ch, spec in doc.items() if ch != own and isinstance(spec, dict)
                       and not str(spec.get("maneuver", "hold")).startswith("hold"))
        if moving:
            return moving, "the record's test plan (the other channels' maneuvers)"
    if meta.get("test") in ("static_crosstalk", "dynamic_crosstalk"):
        return ("the three other surfaces",), (f"the metadata's {meta['test']} test (tables 2 and 3: three others "
                                               "square)")
    return (), "a single channel: no other channel's motion in the record, its plan or its metadata"


def threshold_reference(ra: RecordAnalysis) -> tuple[float | None, str]:
    """The threshold crosstalk is judged against: given, measured in the record, else table A2 for an X-43A channel.

    Parameters
    ----------
    ra : RecordAnalysis
        The record (its static thresholds already run).

    Returns
    -------
    tuple
        The threshold, deg (None when none applies), and where it comes from or why there is none.
    """
    if ra.options.threshold_deg is not None:
        return ra.options.threshold_deg, "given (--threshold-deg)"
    measured = [s.onset_deg for s in ra.of(STATIC) if s.onset_deg is not None]
    if measured:
        return float(measured[0]), "static threshold measured in this record"
    if not ra.channel_named:
        return None, ("no threshold: table A2's belongs to the X-43A and the record names no channel of it (give "
                      "--channel, or --threshold-deg for this actuator's own): figures only")
    ch: ChannelConfig = ra.channel
    return SPEC_THRESHOLD_IN * ch.deg_per_in, f"table A2: {SPEC_THRESHOLD_IN} in × {ch.deg_per_in:.2f} °/in"


class Crosstalk(Section2Test[CrosstalkResult]):
    """Crosstalk noise on every held or slow-triangle observed channel (the LVDT feedback)."""

    key = "crosstalk"
    title = "Crosstalk noise (section 2.2)"
    kinds = ("hold", "triangle")
    absent = "no held or slow-triangle observed channel recognised"

    @override
    def run(self, ra: RecordAnalysis) -> list[CrosstalkResult]:
        data, t = ra.data, ra.data.time_s
        threshold, source = threshold_reference(ra)
        sources, sources_note = crosstalk_sources(ra)
        name, y = ra.primary(("position_deg", "surface_deg"))
        vpd = abs(1.0 / float(ra.channel.feedback_cal.slope(0.0)))
        out = []
        for seg in ra.segments(*self.kinds):
            sl = slice(seg.start, seg.stop)
            c = crosstalk_noise(t[sl], data.command_deg[sl], y[sl], ra.noise_deg[name], output=name,
                                threshold_deg=threshold, threshold_source=source, volts_per_deg=vpd)
            out.append(replace(c, start=seg.start, stop=seg.stop, sources=sources, sources_note=sources_note))
        return out

    @override
    def share(self, ra: RecordAnalysis, others: list[RecordAnalysis]) -> None:
        onsets = [(s.onset_deg, o.data.source) for o in others for s in o.of(STATIC) if s.onset_deg is not None]
        if ra.options.threshold_deg is None and onsets and not ra.of(STATIC):
            value, src = onsets[0]
            ra.results[self.key] = [replace(c, threshold_deg=value, threshold_source=f"static threshold measured in "
                                            f"{src}") for c in ra.of(self)]


    @override
    def markdown(self, ra: RecordAnalysis, results: list[CrosstalkResult],
                 images: list[str | None]) -> list[str]:
        lines: list[str] = []
        for c, img in zip(results, images, strict=True):
            dom = "—" if c.dominant_hz is None else f"{c.dominant_hz:.3g} Hz"
            pp_v = c.peak_to_peak_deg * c.volts_per_deg
            judged = (f"**{c.verdict}** the threshold {c.threshold_deg:.4f}° ({c.threshold_source})"
                      if c.threshold_deg is not None else f"**not judged**: {c.threshold_source}")
            moving = (f"other channels moving: {', '.join(c.sources)} ({c.sources_note})" if c.sources
                      else "no other channel moves")
            lines += [f"{c.kind}: {c.peak_to_peak_deg:.4f}° peak to peak ({pp_v:.4f} V),"
                      f" RMS {c.rms_deg:.4f}° ({c.excess_rms_deg:.4f}° above the {c.sensor_noise_deg:.4f}° sensor "
                      f"noise), dominant {dom}; {moving}; {judged}. Quality: {quality(c.quality, c.quality_note)}.",
                      ""]
            lines += bullets(c.notes)
            lines += image(img, "crosstalk")
        return lines

    @override
    def summary(self, ra: RecordAnalysis, r: CrosstalkResult) -> list[str]:
        against = f" threshold {r.threshold_deg:.4f}°" if r.threshold_deg is not None else " (no threshold)"
        return [f"crosstalk: {r.peak_to_peak_deg:.4f}° p-p, {r.verdict}{against}"
                + ("" if r.quality == "ok" else f" ({r.quality_note})")]

    @override
    def plot(self, ra: RecordAnalysis, r: CrosstalkResult, path: Path) -> bool:
        d = ra.data
        t = d.time_s[r.start:r.stop]
        moving = r.kind.startswith("dynamic")
        fig, axes = figure.pyplot().subplots(2 if moving else 1, 1, figsize=(9, 5.5 if moving else 3.5),
                                             squeeze=False)
        ax = axes[0][0]
        ax.plot(t, r.residual, lw=0.6, label=f"{r.output} residual ({r.kind})")
        if r.threshold_deg is not None:
            for v in (-r.threshold_deg / 2, r.threshold_deg / 2):
                ax.axhline(v, color="r", ls="--", lw=0.8)
        ax.set_ylabel("deg")
        against = (f" vs threshold {r.threshold_deg:.4f}° (dashed: ±half)" if r.threshold_deg is not None
                   else " (no threshold for this channel)")
        ax.set_title(f"crosstalk: {r.peak_to_peak_deg:.4f}° p-p{against}"
                     + ("" if r.quality == "ok" else f"; not judged: {r.quality_note[:60]}"), fontsize=9)
        ax.legend(fontsize=8)
        ax.grid(lw=0.3)
        if moving:
            lower = axes[1][0]
            lower.plot(t, d.command_deg[r.start:r.stop], color=figure.COLORS["command"], lw=0.8, label="command")
            lower.plot(t, getattr(d, r.output)[r.start:r.stop], color=figure.COLORS.get(r.output, "tab:blue"),
                       lw=0.7, label=r.output)
            lower.set_ylabel("deg")
            lower.legend(fontsize=8)
            lower.grid(lw=0.3)
        axes[-1][0].set_xlabel("time, s")
        figure.save(fig, path)
        return True


TEST = Crosstalk()
