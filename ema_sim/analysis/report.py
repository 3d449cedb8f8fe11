"""``ema analyze``'s outputs: the JSON document and the Markdown report around the PNG plots.

:func:`to_json` assembles every figure of every record (schema in the README's "Offline analysis");
:func:`to_markdown` writes the report a person reads, with the plots of :mod:`ema_sim.analysis.plots`.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from ema_sim import __version__
from ema_sim.analysis.calibration_fit import pooled_bounds
from ema_sim.analysis.hysteresis import hysteretic_damping_constant
from ema_sim.analysis.pipeline import RecordAnalysis, spread
from ema_sim.analysis.second_order_fit import UNCERTAINTY_METHOD, SecondOrderFit

RW13_AREA_INLB = 4.88
RW13_PEAK_IN = 0.02155
"""The report's rw13 hysteresis case (section 3.2.2): 4.88 in·lb and 0.02155 in give 3,344.84 lb/in."""


def _clean(value: Any) -> Any:  # noqa: PLR0911 - one return per type
    """JSON-safe: numpy scalars to Python, non-finite floats to None."""
    if isinstance(value, dict):
        return {str(k): _clean(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_clean(v) for v in value]
    if isinstance(value, np.ndarray):
        return _clean(value.tolist())
    if isinstance(value, np.bool_ | bool):
        return bool(value)
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, float | np.floating):
        v = float(value)
        return v if np.isfinite(v) else None
    return value


def record_json(ra: RecordAnalysis) -> dict[str, Any]:
    """One record's figures."""
    d = ra.data
    t = d.time_s
    return _clean({
        "data": d.source, "channel": ra.channel.channel, "samples": len(d), "sample_hz": d.sample_hz,
        "duration_s": float(t[-1] - t[0]), "outputs": d.outputs, "metadata": d.metadata, "noise_deg": ra.noise_deg,
        "tests": [s.as_dict(t) for s in ra.recognition.segments],
        "frequency_response": [f.as_dict() for f in ra.frequency],
        "sine_dwell": ra.sine_dwell,
        "steps": [s.as_dict() for s in ra.steps],
        "slew_rates": ra.slew.as_dict() if ra.slew else None,
        "second_order_fits": [f.as_dict() for f in ra.fits],
        "timing": ra.timing.as_dict() if ra.timing else None,
        "command_error": [c.as_dict() for c in ra.calibration],
        "static_threshold": [s.as_dict() for s in ra.static_threshold],
        "dynamic_threshold": [s.as_dict() for s in ra.dynamic_threshold],
        "crosstalk": [c.as_dict() for c in ra.crosstalk],
        "dither": [x.as_dict() for x in ra.dither],
        "compliance": [c.as_dict() for c in ra.compliance],
        "hysteresis": [h.as_dict() for h in ra.hysteresis],
        "free_play": [f.as_dict() for f in ra.free_play],
        "regeneration": ra.regeneration.as_dict() if ra.regeneration else None,
        "not_computed": ra.not_computed,
        "notes": ra.notes,
    })


def to_json(records: Sequence[RecordAnalysis]) -> dict[str, Any]:
    """The whole ``--json`` document."""
    fits = [f for r in records for f in r.fits]
    errors = [c.error for r in records for c in r.calibration]
    bounds = None
    if errors:
        lo = min(min(c.nominal_levels) for r in records for c in r.calibration)
        hi = max(max(c.nominal_levels) for r in records for c in r.calibration)
        bounds = pooled_bounds(errors, lo, hi)
    return _clean({
        "tool": "ema analyze", "version": __version__,
        "records": [record_json(r) for r in records],
        "second_order_spread": spread(fits) if fits else None,
        "command_error_bounds": bounds,
        "uncertainty_method": UNCERTAINTY_METHOD,
        "rw13_check": {"area_inlb": RW13_AREA_INLB, "peak_in": RW13_PEAK_IN,
                       "h_lb_per_in": hysteretic_damping_constant(RW13_AREA_INLB, RW13_PEAK_IN)},
    })


# ---------------------------------------------------------------------------------------------- Markdown
def _f(value: float | None, fmt: str = ".4g", unit: str = "") -> str:
    if value is None or not np.isfinite(value):
        return "—"
    return f"{value:{fmt}}{unit}"


def _times(value: float | None, factor: float) -> float | None:
    return None if value is None else value * factor


def _pm(value: float, sigma: float, fmt: str = ".4g") -> str:
    return f"{value:{fmt}} ± {sigma:.2g}"


def _table(head: list[str], rows: list[list[str]]) -> list[str]:
    out = ["| " + " | ".join(head) + " |", "| " + " | ".join("---" for _ in head) + " |"]
    out += ["| " + " | ".join(r) + " |" for r in rows]
    return [*out, ""]


def _notes(notes: list[str]) -> list[str]:
    """A result's notes as a bullet list and a blank line (nothing when there are none)."""
    return [*(f"- {n}" for n in notes), ""] if notes else []


def _img(plots: dict[str, str], key: str, alt: str) -> list[str]:
    return [f"![{alt}]({plots[key]})", ""] if key in plots else []


def _fit_rows(fits: list[SecondOrderFit]) -> list[list[str]]:
    rows = []
    for f in fits:
        hand = f"{f.hand.wn_rad_s:.4g} / {f.hand.zeta:.3g}" if f.hand else "—"
        rows.append([f.test, f.method.split(" (")[0], f.output, _pm(f.wn_rad_s.value, f.wn_rad_s.sigma),
                     f"{f.wn_rad_s.sigma_white:.2g}", _pm(f.zeta.value, f.zeta.sigma, ".4f"),
                     _pm(1e3 * f.delay_s.value, 1e3 * f.delay_s.sigma, ".3f"), hand,
                     f"{f.rms:.3g} {'dB' if f.rms_unit == 'db' else '°'}",
                     "yes" if f.residual_whiteness.white else "no"])
    return rows


def _record_md(i: int, ra: RecordAnalysis, plots: dict[str, str]) -> list[str]:  # noqa: PLR0912, PLR0915
    d = ra.data
    t = d.time_s
    lines = [f"## Record {i + 1}: `{d.source}`", ""]
    meta = ", ".join(f"{k}: `{v}`" for k, v in d.metadata.items() if k in ("maneuver", "load", "model", "profile",
                                                                          "test", "channel"))
    lines += _table(["channel", "samples", "rate", "span", "outputs", "noise floor"], [[
        ra.channel.channel, f"{len(d):,}", f"{d.sample_hz:.6g} Hz", f"{t[-1] - t[0]:.4g} s", ", ".join(d.outputs),
        ", ".join(f"{k} {v:.2g}°" for k, v in ra.noise_deg.items())]])
    if meta:
        lines += [f"Metadata: {meta}", ""]
    lines += _img(plots, f"r{i}_overview", "time history")
    lines += ["### Tests recognised", ""]
    lines += _table(["kind", "from", "to", "evidence"],
                    [[s.kind, f"{t[s.start]:.3f} s", f"{t[s.stop - 1]:.3f} s", s.evidence]
                     for s in ra.recognition.segments]) if ra.recognition.segments else ["None.", ""]

    if ra.frequency or ra.sine_dwell:
        lines += ["### Frequency response", ""]
        for j, fr in enumerate(ra.frequency):
            r = fr.response
            lines += [f"**{fr.kind}, {r.output}** ({r.start_s:.2f}-{r.end_s:.2f} s): {r.method}.", ""]
            lines += [f"- −3 dB bandwidth: {_f(fr.bandwidth_hz, '.3f', ' Hz')} ({fr.bandwidth_note}); phase −90° at "
                      f"{_f(fr.phase_90_hz, '.3f', ' Hz')}", f"- {fr.coherence_note}"]
            if fr.fit:
                ft = fr.fit
                lines.append(f"- second order fitted over {fr.fit_band_hz[0]:.3g}-{fr.fit_band_hz[1]:.3g} Hz: "
                             f"ωn {_pm(ft.wn_rad_s.value, ft.wn_rad_s.sigma)} rad/s "
                             f"({ft.wn_rad_s.value / 2 / np.pi:.3f} Hz), ζ {_pm(ft.zeta.value, ft.zeta.sigma, '.4f')}, "
                             f"delay {_pm(1e3 * ft.delay_s.value, 1e3 * ft.delay_s.sigma, '.3f')} ms, gain "
                             f"{ft.gain.value:.4f}, fit RMS {ft.rms:.3g} dB")
            lines.append("")
            rows = [[f"{a['freq_hz']:g}", _f(a["gain_db"], "+.2f"), _f(a["phase_deg"], ".1f"),
                     _f(a["coherence"], ".3f"),
                     a.get("note", "")] for a in fr.at]
            if fr.overlay is not None:
                from ema_sim.analysis.frequency_response import at_frequencies  # noqa: PLC0415

                ov = at_frequencies(fr.overlay, [a["freq_hz"] for a in fr.at])
                for row, o in zip(rows, ov, strict=True):
                    row.insert(3, f"{_f(o['gain_db'], '+.2f')} / {_f(o['phase_deg'], '.1f')}")
                lines += _table(["f, Hz", "gain, dB", "phase, °", f"{fr.overlay_model}: gain / phase", "coherence",
                                 "note"], rows)
            else:
                lines += _table(["f, Hz", "gain, dB", "phase, °", "coherence", "note"], rows)
            lines += _img(plots, f"r{i}_bode{j}", "Bode plot")
        if ra.sine_dwell:
            lines += _table(["output", "f, Hz", "command amplitude, °", "gain, dB", "phase, °"],
                            [[s["output"], f"{s['freq_hz']:g}", f"{s['command_amplitude_deg']:.3g}",
                              f"{s['gain_db']:+.2f}", f"{s['phase_deg']:.1f}"] for s in ra.sine_dwell])

    if ra.steps:
        lines += ["### Steps", ""]
        lines += _table(["step", "first motion, ms", "rise 10-90 %, ms", "settling, ms", "overshoot, %",
                         "peak rate, °/s", "rate-limited"],
                        [[s.label, _f(None if s.delay_s is None else 1e3 * s.delay_s, ".2f"),
                          _f(None if s.rise_s is None else 1e3 * s.rise_s, ".1f"),
                          _f(None if s.settling_s is None else 1e3 * s.settling_s, ".0f"),
                          _f(s.overshoot_pct, ".1f"), f"{s.peak_rate_dps:.1f}",
                          ("yes: " + s.rate_reason) if s.rate_limited else "no"] for s in ra.steps])
        if ra.slew:
            lines += [f"Slew rate: small amplitude {_f(ra.slew.small_dps, '.1f', ' °/s')} (steps "
                      f"{', '.join(f'{a:g}°' for a in ra.slew.small_steps_deg) or '—'}), large amplitude "
                      f"{_f(ra.slew.large_dps, '.1f', ' °/s')} (steps "
                      f"{', '.join(f'{a:g}°' for a in ra.slew.large_steps_deg) or '—'}; table 1: 115.8 °/s).", ""]
        lines += _img(plots, f"r{i}_steps", "step responses")

    if ra.fits:
        lines += ["### Second-order fits (section 3.1.1)", "",
                  f"± is one standard error corrected for coloured residuals ({UNCERTAINTY_METHOD}); the white-noise "
                  "standard error of ωn is beside it. Hand calculation: ωn / ζ from rise and settling time.", ""]
        lines += _table(["test", "method", "output", "ωn, rad/s", "σ white", "ζ", "delay, ms", "hand ωn / ζ", "RMS",
                         "white residual"], _fit_rows(ra.fits))

    if ra.timing:
        tm = ra.timing
        lines += ["### Command-to-surface timing (section 2.3)", ""]
        lines += _table(["command → first motion", "motion → feedback", "command → feedback", "edges", "motion from"],
                        [[_f(None if tm.command_to_motion_s is None else 1e3 * tm.command_to_motion_s, ".2f", " ms"),
                          _f(None if tm.motion_to_feedback_s is None else 1e3 * tm.motion_to_feedback_s, ".2f", " ms"),
                          _f(None if tm.total_s is None else 1e3 * tm.total_s, ".2f", " ms"), str(len(tm.edges)),
                          tm.motion_signal]])
        lines += _notes(tm.notes)
        lines += _img(plots, f"r{i}_timing", "timing")

    for c in ra.calibration:
        lines += ["### Command error (section 3.1.2.2)", ""]
        rows = []
        if c.curve_error:
            rows.append(["calibration curves", f"{c.curve_error.kb:+.5f}", f"{c.curve_error.offset_deg:+.4f}",
                         f"command curve RMS {_f(c.command_curve_rms_v, '.2g')} V, feedback curve RMS "
                         f"{_f(c.feedback_curve_rms_deg, '.2g')}° (against {c.feedback_reference})"])
        rows.append(["direct (settled − command)", f"{c.direct.kb:+.5f} ± {c.direct_sigma[0]:.1g}",
                      f"{c.direct.offset_deg:+.4f} ± {c.direct_sigma[1]:.1g}", f"against {c.direct_reference}"])
        lines += _table(["method", "Kb", "offset, °", "fit"], rows)
        if c.command_curve and c.feedback_curve:
            lines += [f"Command curve (deg → V): {', '.join(f'{x:.6g}' for x in c.command_curve.coefficients())}; "
                      f"feedback curve (V → deg): {', '.join(f'{x:.6g}' for x in c.feedback_curve.coefficients())}.",
                      ""]
        lines += [f"Four-corner bounds at ±{max(abs(c.nominal_deg)):.0f}°: {c.bounds_deg[0][-1]:+.4f}° to "
                  f"{c.bounds_deg[1][-1]:+.4f}°.", ""]
        lines += _notes(c.notes)
        lines += _img(plots, f"r{i}_command_error", "command error")

    for s in ra.static_threshold:
        lines += ["### Static threshold (section 2.1.1)", "",
                  f"Motion onset {_f(s.onset_deg, '.4f', '°')} "
                  f"({_f(_times(s.onset_deg, s.volts_per_deg), '.4f', ' V')}); "
                  f"follows from {_f(s.follow_deg, '.4f', '°')} amplitude; gain above threshold {_f(s.gain, '.3f')} "
                  f"(on {s.output}).", ""]
        lines += _notes(s.notes)
        lines += _img(plots, f"r{i}_static_threshold", "static threshold")
    for s in ra.dynamic_threshold:
        lines += [f"### Dynamic threshold (section 2.1.2), {s.freq_hz:g} Hz", "",
                  f"Motion onset {_f(s.onset_deg, '.4f', '°')} amplitude; follows from "
                  f"{_f(s.follow_deg, '.4f', '°')} (on {s.output}).", ""]
        lines += _notes(s.notes)
        lines += _img(plots, f"r{i}_dynamic_threshold", "dynamic threshold")

    for c in ra.crosstalk:
        verdict = "below" if c.below_threshold else "ABOVE"
        lines += ["### Crosstalk noise (section 2.2)", "",
                  f"{c.kind}: {c.peak_to_peak_deg:.4f}° peak to peak ({c.peak_to_peak_deg * c.volts_per_deg:.4f} V), "
                  f"RMS {c.rms_deg:.4f}° ({c.excess_rms_deg:.4f}° above the {c.sensor_noise_deg:.4f}° sensor noise), "
                  f"dominant {_f(c.dominant_hz, '.3g', ' Hz')}; **{verdict}** the threshold {c.threshold_deg:.4f}° "
                  f"({c.threshold_source}).", ""]
        lines += _img(plots, f"r{i}_crosstalk", "crosstalk")
    for x in ra.dither:
        lines += ["### Dither (sections 2.10, 4.3)", "", f"{x.output}, {x.start_s:.1f}-{x.end_s:.1f} s: {x.statement}.",
                  ""]
        lines += _img(plots, f"r{i}_dither", "dither")

    for c in ra.compliance:
        lines += [f"### Compliance (sections 2.8, 3.2.1), command {c.command_deg:g}°", ""]
        rows = []
        for cur in (c.lvdt, c.total):
            if cur is None:
                continue
            m = cur.mean
            seg = ("—" if m is None else
                   f"knots {m.knots_lb[0]:.0f} / {m.knots_lb[1]:.0f} lb; slopes "
                   + " / ".join(f"{1e3 * s:.3g}" for s in m.slopes_deg_per_lb) + " °/klb")
            rows.append(["LVDT (inside the loop)" if cur.name == "lvdt" else "total (surface)",
                         _f(cur.slope_deg_per_kinlb, ".4f"), _f(cur.span_deg, ".4f"), _f(cur.gap_deg, ".4f"), seg])
        lines += _table(["curve", "compliance, °/kin·lb", "span, °", "gap at zero load, °", "three-segment (mean)"],
                        rows)
        lines += [f"Share of the compliance outside the servo loop: {_f(_times(c.share_outside, 100), '.1f', ' %')} "
                  f"(slopes), {_f(_times(c.share_outside_span, 100), '.1f', ' %')} "
                  "(span, free play included); the report: > 81 % (wings, vehicle 2), 77 % (vehicle 3).", ""]
        lines += _notes(c.notes)
        lines += _img(plots, f"r{i}_compliance", "compliance")
    for h in ra.hysteresis:
        lines += ["### Hysteretic damping (section 3.2.2)", "",
                  f"{len(h.cycles)} load cycle(s) at {h.freq_hz:.4g} Hz ({2 * np.pi * h.freq_hz:.4g} rad/s), "
                  f"±{h.load_amplitude_inlb:.4g} in·lb (±{h.load_amplitude_inlb / h.crank_arm_in:.4g} lb at the "
                  f"{h.crank_arm_in:g} in crank arm), on {h.output}: A = {h.area_inlb:.4g} in·lb, Pk = "
                  f"{h.peak_in:.5f} in, **h = A/(π·Pk²) = {h.h_lb_per_in:,.2f} lb/in**. The report's rw13: "
                  f"{RW13_AREA_INLB} in·lb and {RW13_PEAK_IN} in give "
                  f"{hysteretic_damping_constant(RW13_AREA_INLB, RW13_PEAK_IN):,.2f} lb/in.", ""]
        lines += _notes(h.notes)
        lines += _img(plots, f"r{i}_hysteresis", "hysteresis loop")
    for fp in ra.free_play:
        lines += ["### Free play (section 2.4)", "",
                  f"{fp.width_deg:.4f}° ± {fp.spread_deg:.2g}° over {len(fp.reversals)} reversal(s) ({fp.method}); "
                  "the report: 0.171-0.179° (vehicle 1), ≈ 0.200° (vehicles 2, 3).", ""]
        lines += _notes(fp.notes)
        lines += _img(plots, f"r{i}_free_play", "free play")
    if ra.regeneration:
        g = ra.regeneration
        lines += ["### Voltage regeneration (section 2.5)", "",
                  f"Bus nominal {g.nominal_v:.1f} V, peak {g.peak_v:.1f} V at {g.peak_time_s:.2f} s "
                  f"(+{g.rise_v:.1f} V): {'within' if g.peak_v <= g.limit_v else 'OVER'} the {g.limit_v:g} V limit, "
                  f"margin {g.margin_v:.1f} V.", ""]
        lines += _img(plots, f"r{i}_regeneration", "bus voltage")

    if ra.not_computed:
        absent = [k for k, v in ra.not_computed.items() if "recognised" in v and not v.startswith("no hinge")]
        limited = {k: v for k, v in ra.not_computed.items() if k not in absent}
        lines += ["### Not computed", ""]
        lines += [f"- **{k}**: {v}" for k, v in limited.items()]
        if absent:
            lines.append(f"- not in this record (no such test recognised): {', '.join(absent)}")
        lines.append("")
    if ra.notes:
        lines += ["### Notes", ""] + [f"- {n}" for n in ra.notes] + [""]
    return lines


def to_markdown(records: Sequence[RecordAnalysis], plots: dict[str, str]) -> str:
    """The Markdown report."""
    lines = ["# ema analyze report", "",
             f"ema_sim {__version__}; {len(records)} record(s). Methods: composite-window H1 spectra (Hann, 80 % "
             "overlap) or periodic chirp-z DFT; second-order fits by least squares with uncertainty corrected for "
             "coloured residuals (Morelli & Klein); everything cited to NASA/TM-2008-214637.", ""]
    for i, ra in enumerate(records):
        lines += _record_md(i, ra, plots)
    fits = [f for r in records for f in r.fits]
    if len(fits) > 1:
        lines += ["## Spread across tests (figure 23)", ""]
        for output, entry in spread(fits).items():
            w, z, d = entry["wn_rad_s"], entry["zeta"], entry["delay_s"]
            lines += [f"**{output}** over {w['count']} estimates: ωn {w['min']:.4g}-{w['max']:.4g} rad/s (mean "
                      f"{w['mean']:.4g}), ζ {z['min']:.4f}-{z['max']:.4f} (mean {z['mean']:.4f}), delay "
                      f"{1e3 * d['min']:.3f}-{1e3 * d['max']:.3f} ms; model bounds uniform between the extremes.", ""]
        lines += _img(plots, "spread", "spread of estimates")
    errors = [c for r in records for c in r.calibration]
    if len(errors) > 1:
        lines += ["## Command-error bounds over all calibrations (figure 27)", "",
                  f"{len(errors)} calibrations: |Kb| ≤ {max(abs(c.error.kb) for c in errors):.5f}, |offset| ≤ "
                  f"{max(abs(c.error.offset_deg) for c in errors):.4f}°.", ""]
    return "\n".join(lines) + "\n"
