"""``ema analyze``'s engine: recognise a record's tests and run every analysis that applies.

:func:`analyze_record` takes one :class:`~ema_sim.io.csv.MeasuredData` (a rig's CSV or a bag read
through the node suite's reader), puts it on a uniform grid, recognises its segments
(:mod:`ema_sim.analysis.recognize`) and runs, per segment kind:

====================  ===============================================================================
segment               analyses
====================  ===============================================================================
sweep, broadband      frequency response (composite windows), second-order fit, bandwidth, phase
schroeder             frequency response (periodic, chirp-z), second-order fit, bandwidth, phase
sine                  gain and phase at the dwell frequency
steps, square         step metrics and fits, slew rates; command-to-surface timing
staircase             calibration curves, command error Kb/offset, four-corner bounds
static/dynamic thr.   thresholds
hold, triangle        crosstalk noise against the threshold; dither (holds)
load_steps            LVDT and total compliance, share outside the loop, three-segment fits
load_reversal         free play
load_sine             hysteretic damping h = A/(π·Pk²)
(bus_v column)        regeneration peak against 185 V
====================  ===============================================================================

Every analysis that finds nothing to work on says why in ``not_computed``.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ema_sim.analysis import frequency_response as frm
from ema_sim.analysis import series
from ema_sim.analysis.calibration_fit import Calibration, fit_calibration
from ema_sim.analysis.compliance import ComplianceResult, analyze_compliance
from ema_sim.analysis.crosstalk import CrosstalkResult, crosstalk_noise
from ema_sim.analysis.dither import DitherResult, detect_dither
from ema_sim.analysis.free_play import FreePlayResult, reversal_free_play
from ema_sim.analysis.hysteresis import HysteresisResult, analyze_hysteresis
from ema_sim.analysis.noise import noise_floor
from ema_sim.analysis.recognize import Recognition, Segment, recognize
from ema_sim.analysis.regeneration import RegenerationResult, bus_peak
from ema_sim.analysis.second_order_fit import SecondOrderFit, fit_frequency_response
from ema_sim.analysis.sine_fit import sine_at
from ema_sim.analysis.steps import SlewRates, StepResponse, analyze_steps, slew_rates
from ema_sim.analysis.threshold import DynamicThreshold, StaticThreshold, dynamic_threshold, static_threshold
from ema_sim.analysis.timing import TimingResult, edge_timing
from ema_sim.config import CHANNELS, ChannelConfig, load_channel
from ema_sim.io.csv import MeasuredData

FloatArray = NDArray[np.float64]

DEFAULT_AT_HZ: tuple[float, ...] = (1.0, 2.0, 5.0, 7.5, 10.0)
SPEC_THRESHOLD_IN = 0.0075
"""Threshold with inertial load, table A2 (inches of actuator travel)."""
FIT_BAND_TRIM = 0.05
"""Share of a sweep's band (in log frequency) left out of the fit at each end (see FrequencyResult)."""


@dataclass(frozen=True)
class Options:
    """What ``ema analyze`` was asked for."""

    at_hz: tuple[float, ...] = DEFAULT_AT_HZ
    model: str | None = None
    """A registered model simulated on the measured command and overlaid on the Bode plots."""
    threshold_deg: float | None = None
    """Threshold the crosstalk noise is compared with (default: measured, else table A2)."""
    compliance_deg_per_kinlb: float | None = None
    """Compliance taken out of the free-play jumps (default: measured in the same run, else none)."""
    channel: str | None = None


@dataclass(frozen=True)
class FrequencyResult:
    """One measured frequency response with its figures and fits.

    The fit leaves out the first and last 5 % of a sweep's band in log frequency: the sweep starts
    and ends there, so every window that sees those frequencies also sees the record's start or end
    (on a noise-free SLOAC sweep 0.2-18 Hz the estimate is 0.5° off at 0.2 Hz and 6° at 18 Hz, under
    0.4° in between).
    """

    kind: str
    response: frm.FrequencyResponse
    bandwidth_hz: float | None
    bandwidth_note: str
    at: list[dict[str, Any]]
    low_coherence_above_hz: float | None
    coherence_note: str
    phase_90_hz: float | None
    fit: SecondOrderFit | None
    fit_band_hz: tuple[float, float]
    overlay: frm.FrequencyResponse | None = None
    overlay_model: str | None = None

    def as_dict(self) -> dict[str, Any]:
        """Plain values for JSON."""
        r = self.response
        out: dict[str, Any] = {
            "test": self.kind, "output": r.output, "method": r.method, "start_s": r.start_s, "end_s": r.end_s,
            "freq_hz": r.freq_hz.tolist(), "gain_db": r.gain_db.tolist(), "phase_deg": r.phase_deg.tolist(),
            "coherence": r.coherence.tolist(), "random_error": r.random_error.tolist(),
            "bandwidth_3db_hz": self.bandwidth_hz, "bandwidth_note": self.bandwidth_note,
            "phase_minus_90_hz": self.phase_90_hz, "at": self.at,
            "low_coherence_above_hz": self.low_coherence_above_hz, "coherence_note": self.coherence_note,
            "fit_band_hz": list(self.fit_band_hz), "second_order_fit": self.fit.as_dict() if self.fit else None,
        }
        if self.overlay is not None:
            out["model_overlay"] = {"model": self.overlay_model, "at": frm.at_frequencies(self.overlay, [
                a["freq_hz"] for a in self.at]), "bandwidth_3db_hz": frm.bandwidth_3db(self.overlay)[0]}
        return out


@dataclass
class RecordAnalysis:
    """Everything ``ema analyze`` found in one record."""

    data: MeasuredData
    channel: ChannelConfig
    recognition: Recognition
    noise_deg: dict[str, float]
    frequency: list[FrequencyResult] = field(default_factory=list)
    sine_dwell: list[dict[str, Any]] = field(default_factory=list)
    steps: list[StepResponse] = field(default_factory=list)
    slew: SlewRates | None = None
    timing: TimingResult | None = None
    calibration: list[Calibration] = field(default_factory=list)
    compliance: list[ComplianceResult] = field(default_factory=list)
    hysteresis: list[HysteresisResult] = field(default_factory=list)
    free_play: list[FreePlayResult] = field(default_factory=list)
    static_threshold: list[StaticThreshold] = field(default_factory=list)
    dynamic_threshold: list[DynamicThreshold] = field(default_factory=list)
    crosstalk: list[CrosstalkResult] = field(default_factory=list)
    regeneration: RegenerationResult | None = None
    dither: list[DitherResult] = field(default_factory=list)
    not_computed: dict[str, str] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)

    @property
    def fits(self) -> list[SecondOrderFit]:
        """Every second-order fit of the record (steps and frequency responses)."""
        out = [s.fit for s in self.steps if s.fit is not None]
        out += [f.fit for f in self.frequency if f.fit is not None]
        return out


def resolve_channel(data: MeasuredData, requested: str | None) -> tuple[ChannelConfig, str | None]:
    """The channel configuration to use (crank arm, calibration slopes) and a note on how it was chosen."""
    meta = data.metadata.get("channel")
    if requested:
        return load_channel(requested), None
    if meta in CHANNELS:
        return load_channel(meta), None
    why = f"metadata channel {meta!r} is not one of ours" if meta else "no channel in the metadata"
    return load_channel("left_wing"), f"{why}: left_wing's configuration used (crank arm, calibration slopes)"


def _primary(data: MeasuredData, prefer: tuple[str, ...]) -> tuple[str, FloatArray]:
    for name in prefer:
        value = getattr(data, name)
        if value is not None:
            return name, value
    raise AssertionError("the data contract guarantees an output column")


def _outputs(data: MeasuredData, sl: slice) -> dict[str, FloatArray]:
    return {name: getattr(data, name)[sl] for name in data.outputs}


def _overlay(options: Options, ch: ChannelConfig, data: MeasuredData, sl: slice) -> FloatArray | None:
    """The named model's LVDT position on the segment, simulated on the measured command and load.

    The model runs from the record's first sample (trimmed there), so a discrete model's internal
    step grid keeps the alignment with the command frames it had when the record was made.
    """
    if not options.model:
        return None
    from ema_sim.models import create  # noqa: PLC0415

    model = create(options.model, ch.channel)
    stop = sl.stop
    t = data.time_s[:stop] - data.time_s[0]
    u = data.command_deg[:stop]
    hm = data.hinge_moment[:stop]
    model.trim(u[0], hm[0])
    rec = model.run(t, u, hm, sample_times=t, end_s=float(t[-1]))
    return rec.position_deg[0][sl.start:stop]


def _frequency(ra: RecordAnalysis, seg: Segment, options: Options) -> None:
    data = ra.data
    fs = data.sample_hz
    stop = seg.stop
    if seg.kind == "schroeder" and "period_s" in seg.params:
        # Whole periods from the start of the sweep (the command holds its value after the last change).
        n_per = seg.params["period_s"] * fs
        periods = int(np.floor((seg.stop - seg.start) / n_per + 0.02))
        stop = max(stop, min(len(data), seg.start + round(periods * n_per)))
    sl = slice(seg.start, stop)
    u = data.command_deg[sl]
    outs = _outputs(data, sl)
    t0 = float(data.time_s[seg.start])
    if "f0_hz" in seg.params and "f1_hz" in seg.params:
        band = (seg.params["f0_hz"], seg.params["f1_hz"])
    else:
        band = frm.excitation_band(u, fs)
    model_y = _overlay(options, ra.channel, data, sl)
    if seg.kind == "schroeder" and "period_s" in seg.params:
        period = seg.params["period_s"]
        responses = frm.from_periodic(u, outs, fs, period, band, start_s=t0)
        overlays = frm.from_periodic(u, {"model": model_y}, fs, period, band, start_s=t0) if model_y is not None else []
        fit_band = (band[0], band[1])
    else:
        responses = frm.from_sweep(u, outs, fs, band, start_s=t0)
        overlays = frm.from_sweep(u, {"model": model_y}, fs, band, start_s=t0) if model_y is not None else []
        trim = (band[1] / band[0]) ** FIT_BAND_TRIM if band[1] > band[0] else 1.0
        fit_band = (band[0] * trim, band[1] / trim)
    if not responses:
        ra.notes.append(f"{seg.kind} at {t0:.2f} s: band {band[0]:.3g}-{band[1]:.3g} Hz too narrow for a response")
        return
    for r in responses:
        bw, bw_note = frm.bandwidth_3db(r)
        above, coh_note = frm.coherence_statement(r)
        in_band = (r.freq_hz >= fit_band[0] * (1 - 1e-9)) & (r.freq_hz <= fit_band[1] * (1 + 1e-9))
        sub = frm.FrequencyResponse(r.output, r.method, r.freq_hz[in_band], r.h[in_band], r.coherence[in_band],
                                    r.random_error[in_band], r.start_s, r.end_s)
        label = f"{seg.kind} {band[0]:.3g}-{band[1]:.3g} Hz at {t0:.2f} s"
        fit = fit_frequency_response(sub, test=label)
        ra.frequency.append(FrequencyResult(
            seg.kind, r, bw, bw_note, frm.at_frequencies(r, list(options.at_hz)), above, coh_note,
            frm.phase_crossing_hz(r), fit, fit_band, overlays[0] if overlays else None, options.model))


def _sine_dwell(ra: RecordAnalysis, seg: Segment) -> None:
    data = ra.data
    sl = slice(seg.start, seg.stop)
    t, u = data.time_s[sl], data.command_deg[sl]
    f = seg.params.get("freq_hz")
    if not f:
        return
    # Whole cycles after the first, so the start-up transient stays out.
    per = 1.0 / f
    keep = (t >= t[0] + per) & (t <= t[0] + per * np.floor((t[-1] - t[0]) / per))
    if keep.sum() < 20:
        return
    su = sine_at(t[keep], u[keep], f)
    for name, y in _outputs(data, sl).items():
        sy = sine_at(t[keep], y[keep], f)
        h = (sy.amplitude / su.amplitude) * np.exp(1j * (sy.phase_rad - su.phase_rad)) / frm.zoh_factor(
            np.array([f]), data.sample_hz)[0]
        ra.sine_dwell.append({"output": name, "freq_hz": f, "command_amplitude_deg": su.amplitude,
                              "gain_db": float(20 * np.log10(abs(h))), "phase_deg": float(np.degrees(np.angle(h))),
                              "output_r2": sy.r2, "start_s": float(t[0]), "end_s": float(t[-1])})


def _volts_per_deg(ch: ChannelConfig) -> float:
    """Command volts per degree at the centre of the channel's command curve."""
    return abs(float(ch.command_cal.slope(0.0)))


def analyze_record(data: MeasuredData, options: Options | None = None) -> RecordAnalysis:
    """Recognise and analyse one record (see the module docstring)."""
    options = options or Options()
    data = series.uniform_record(data)
    ch, ch_note = resolve_channel(data, options.channel)
    noise = {name: noise_floor(getattr(data, name)) for name in data.outputs}
    rec = recognize(data)
    ra = RecordAnalysis(data, ch, rec, noise)
    if ch_note:
        ra.notes.append(ch_note)
    if "resampled" in data.metadata:
        ra.notes.append(data.metadata["resampled"])
    ra.notes += rec.notes
    for seg in rec.of("sweep", "schroeder", "broadband"):
        _frequency(ra, seg, options)
    for seg in rec.of("sine"):
        _sine_dwell(ra, seg)
    if not ra.frequency and not ra.sine_dwell:
        ra.not_computed["frequency_response"] = "no sweep, Schroeder sweep or sine dwell recognised"
    _steps_and_timing(ra)
    for seg in rec.of("staircase"):
        ra.calibration.append(fit_calibration(data, list(seg.holds)))
    if not ra.calibration:
        ra.not_computed["command_error"] = "no calibration staircase recognised"
    _thresholds(ra)
    _crosstalk_and_dither(ra, options)
    for seg in rec.of("ramp"):
        t = data.time_s
        ra.notes.append(f"slow ramp at {t[seg.start]:.1f}-{t[seg.stop - 1]:.1f} s: tracking is in the time-history "
                        "plot; no figure of this tool applies to it")
    _loaded(ra, rec, data.hinge_moment_inlb, options)
    if data.bus_v is not None:
        ra.regeneration = bus_peak(data.time_s, data.bus_v)
        if not rec.of("regen"):
            ra.notes.append("bus voltage assessed on a record that is not the regeneration square sweep")
    else:
        ra.not_computed["regeneration"] = "no bus voltage column (bus_v): regeneration not assessed"
    return ra


def _steps_and_timing(ra: RecordAnalysis) -> None:
    """Step metrics and fits of every command edge of the step and square-wave segments; their timing."""
    data, t = ra.data, ra.data.time_s
    edges = [e for s in ra.recognition.of("steps", "square") for e in s.edges]
    if not edges:
        ra.not_computed["steps"] = "no step or square-wave command recognised"
        ra.not_computed["timing"] = "no step or square-wave command edges to time"
        return
    name, y = _primary(data, ("position_deg", "surface_deg"))
    ra.steps = analyze_steps(t, data.command_deg, y, edges, output=name, noise_floor=ra.noise_deg[name],
                             rated_slew_dps=ra.channel.slew_rate_dps)
    ra.slew = slew_rates(ra.steps)
    ra.timing = edge_timing(t, edges, data.position_deg, data.surface_deg, ra.noise_deg)


def _thresholds(ra: RecordAnalysis) -> None:
    """Static and dynamic thresholds on the external sensor (the LVDT when there is none)."""
    data, t = ra.data, ra.data.time_s
    vpd = _volts_per_deg(ra.channel)
    name, y = _primary(data, ("surface_deg", "position_deg"))
    for seg in ra.recognition.of("static_threshold"):
        sl = slice(seg.start, seg.stop)
        r = static_threshold(t[sl], data.command_deg[sl], y[sl], ra.noise_deg[name], output=name, volts_per_deg=vpd)
        if r:
            ra.static_threshold.append(r)
    for seg in ra.recognition.of("dynamic_threshold"):
        sl = slice(seg.start, seg.stop)
        f = seg.params.get("freq_hz")
        if f:
            r2 = dynamic_threshold(t[sl], data.command_deg[sl], y[sl], f, ra.noise_deg[name], output=name,
                                   volts_per_deg=vpd)
            if r2:
                ra.dynamic_threshold.append(r2)
    if not ra.static_threshold:
        ra.not_computed["static_threshold"] = "no slow triangles of growing amplitude recognised"
    if not ra.dynamic_threshold:
        ra.not_computed["dynamic_threshold"] = "no tone of growing amplitude recognised"


def _crosstalk_and_dither(ra: RecordAnalysis, options: Options) -> None:
    """Crosstalk noise on held or slow-triangle observed channels (LVDT feedback); dither on the held ones."""
    data, t, ch = ra.data, ra.data.time_s, ra.channel
    threshold, source = _threshold_reference(ra, options, ch)
    name, y = _primary(data, ("position_deg", "surface_deg"))
    for seg in ra.recognition.of("hold", "triangle"):
        sl = slice(seg.start, seg.stop)
        ra.crosstalk.append(crosstalk_noise(t[sl], data.command_deg[sl], y[sl], ra.noise_deg[name], output=name,
                                            threshold_deg=threshold, threshold_source=source,
                                            volts_per_deg=abs(1.0 / float(ch.feedback_cal.slope(0.0)))))
        if seg.kind == "hold":
            d = detect_dither(t[sl], y[sl], output=name)
            if d:
                ra.dither.append(d)
    if not ra.crosstalk:
        ra.not_computed["crosstalk"] = "no held or slow-triangle observed channel recognised"
    if not ra.dither:
        ra.not_computed["dither"] = "no command held for ≥ 5 s with a constant load"


def _loaded(ra: RecordAnalysis, rec: Recognition, hm: FloatArray | None, options: Options) -> None:
    data, ch, t = ra.data, ra.channel, ra.data.time_s
    no_hm = "no hinge moment: {} not computed"
    if hm is None:
        ra.not_computed["compliance"] = no_hm.format("compliance")
        ra.not_computed["hysteresis"] = no_hm.format("hysteretic damping")
        ra.not_computed["free_play"] = no_hm.format("free play")
        return
    for seg in rec.of("load_steps"):
        holds = list(seg.holds)
        if len(holds) < 3:
            continue
        ra.compliance.append(analyze_compliance(data.position_deg, data.surface_deg, hm, holds,
                                                seg.params.get("command_deg", float(data.command_deg[seg.start])),
                                                ch.crank_arm_in))
    for seg in rec.of("load_sine"):
        sl = slice(seg.start, seg.stop)
        name, y = _primary(data, ("surface_deg", "position_deg"))
        h = analyze_hysteresis(t[sl], hm[sl], y[sl], output=name, crank_arm_in=ch.crank_arm_in,
                               freq_hz=seg.params.get("freq_hz"))
        if h:
            ra.hysteresis.append(h)
    _free_play(ra, rec, hm, options)
    if not ra.compliance:
        ra.not_computed["compliance"] = "no load staircase with the command held recognised"
    if not ra.hysteresis:
        ra.not_computed["hysteresis"] = "no sinusoidal load with the command held recognised"
    if not ra.free_play and "free_play" not in ra.not_computed:
        gaps = [c for c in ra.compliance if c.total and c.total.gap_deg is not None]
        reason = "no load reversal recognised"
        if gaps:
            reason += "; see compliance.free_play_deg (gap between the load lines at zero load)"
        ra.not_computed["free_play"] = reason


def _free_play(ra: RecordAnalysis, rec: Recognition, hm: FloatArray, options: Options) -> None:
    """Free play of every load-reversal segment, less the compliance when one is known."""
    data, t = ra.data, ra.data.time_s
    compliance = options.compliance_deg_per_kinlb
    source = "given (--compliance)" if compliance is not None else None
    if compliance is None:
        measured = [c.total.slope_deg_per_kinlb for c in ra.compliance if c.total and c.total.slope_deg_per_kinlb]
        compliance = measured[0] if measured else None
        source = "total compliance measured in this record" if measured else None
    for seg in rec.of("load_reversal"):
        if data.surface_deg is None:
            ra.not_computed["free_play"] = ("no external surface angle: free play lies outside the servo loop, "
                                            "the LVDT cannot see it")
            continue
        sl = slice(seg.start, seg.stop)
        swing = float(np.ptp(hm[sl]))
        dt = float(np.median(np.diff(t)))
        hedges = [series.Edge(e.index + seg.start, series.Hold(e.before.start + seg.start, e.before.stop + seg.start,
                                                               e.before.value),
                              series.Hold(e.after.start + seg.start, e.after.stop + seg.start, e.after.value))
                  for e in series.edges(hm[sl], dt, min_hold_s=0.2, min_jump=0.3 * swing,
                                        tol=max(series.hold_tolerance(hm[sl]), 1e-3 * swing))]
        fp = reversal_free_play(t, hedges, hm, data.surface_deg, data.position_deg, compliance, source)
        if fp:
            ra.free_play.append(fp)


def _threshold_reference(ra: RecordAnalysis, options: Options, ch: ChannelConfig) -> tuple[float, str]:
    if options.threshold_deg is not None:
        return options.threshold_deg, "given (--threshold-deg)"
    measured = [s.onset_deg for s in ra.static_threshold if s.onset_deg is not None]
    if measured:
        return float(measured[0]), "static threshold measured in this record"
    return SPEC_THRESHOLD_IN * ch.deg_per_in, f"table A2: {SPEC_THRESHOLD_IN} in × {ch.deg_per_in:.2f} °/in"


def analyze_records(records: list[MeasuredData], options: Options | None = None) -> list[RecordAnalysis]:
    """Analyse several records, then let each use what another of the same channel measured.

    A crosstalk record judged against table A2's threshold is judged again against a static threshold
    measured on the same channel; free-play jumps with no compliance taken out get the total compliance
    measured on a load staircase of the same channel.
    """
    options = options or Options()
    done = [analyze_record(d, options) for d in records]
    for ra in done:
        ch = ra.channel.channel
        same = [o for o in done if o.channel.channel == ch and o is not ra]
        onsets = [(s.onset_deg, o.data.source) for o in same for s in o.static_threshold if s.onset_deg is not None]
        if options.threshold_deg is None and onsets and not ra.static_threshold:
            value, src = onsets[0]
            ra.crosstalk = [replace(c, threshold_deg=value, threshold_source=f"static threshold measured in {src}")
                            for c in ra.crosstalk]
        slopes = [(c.total.slope_deg_per_kinlb, o.data.source) for o in same for c in o.compliance
                  if c.total and c.total.slope_deg_per_kinlb]
        if slopes:
            value, src = slopes[0]
            ra.free_play = [f.with_compliance(value, f"total compliance measured in {src}")
                            if f.compliance_deg_per_kinlb is None else f for f in ra.free_play]
    return done


# ---------------------------------------------------------------------------------------------- across tests
def spread(fits: list[SecondOrderFit]) -> dict[str, Any]:
    """Figure 23: the estimates of every test, and their range, per output."""
    out: dict[str, Any] = {}
    for output in sorted({f.output for f in fits}):
        rows = [f for f in fits if f.output == output]
        entry: dict[str, Any] = {"tests": [{"test": f.test, "method": f.method, "wn_rad_s": f.wn_rad_s.value,
                                            "wn_sigma": f.wn_rad_s.sigma, "zeta": f.zeta.value,
                                            "zeta_sigma": f.zeta.sigma, "delay_s": f.delay_s.value,
                                            "delay_sigma_s": f.delay_s.sigma} for f in rows]}
        for key in ("wn_rad_s", "zeta", "delay_s"):
            vals = np.array([getattr(f, key).value for f in rows])
            entry[key] = {"min": float(vals.min()), "max": float(vals.max()), "mean": float(vals.mean()),
                          "std": float(vals.std(ddof=1)) if vals.size > 1 else None, "count": int(vals.size)}
        entry["bounds"] = ("uniform between the minimum and maximum over the tests, as section 3.1.1 "
                           "defines the model's uncertainty")
        out[output] = entry
    return out
