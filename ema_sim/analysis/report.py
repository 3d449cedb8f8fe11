"""``ema analyze``'s outputs: the JSON document and the Markdown report around the PNG plots.

Both are loops over :data:`ema_sim.analysis.registry.TESTS`: each record's header (channel, rate,
span, outputs, their noise floor and resolution, whether the command is held or sampled), then every
test's section as the test writes it, then what was not computed and why. Schema in the README's
"Offline analysis".
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import cast, overload

import numpy as np

from ema_sim import __version__
from ema_sim.analysis.contract import AnalyzeReport, analyze_schema
from ema_sim.analysis.estimation.second_order_fit import UNCERTAINTY_METHOD, SecondOrderFit
from ema_sim.analysis.formatting.markdown import bullets, image, quality, table
from ema_sim.analysis.formatting.units import in_unit, texts_in_unit
from ema_sim.analysis.pipeline import spread
from ema_sim.analysis.plots import plot_key
from ema_sim.analysis.registry import TESTS
from ema_sim.analysis.section2.base import RecordAnalysis
from ema_sim.analysis.section2.calibration_fit import TEST as CALIBRATION
from ema_sim.analysis.section2.calibration_fit import pooled_bounds
from ema_sim.analysis.section2.hysteresis import RW13_AREA_INLB, RW13_PEAK_IN, hysteretic_damping_constant
from ema_sim.io.contract import check
from ema_sim.jsontypes import JsonObject, JsonValue

__all__ = ["RW13_AREA_INLB", "RW13_PEAK_IN", "record_json", "slope_json", "slope_statement", "to_json", "to_markdown"]


@overload
def _clean(value: dict[str, object]) -> JsonObject: ...
@overload
def _clean(value: object) -> JsonValue: ...
def _clean(value: object) -> JsonValue:  # noqa: PLR0911 - one return per type
    """JSON-safe: numpy scalars to Python, non-finite floats to None (anything else: json.dumps' own TypeError)."""
    if isinstance(value, dict):
        return {str(k): _clean(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_clean(v) for v in value]
    if isinstance(value, np.ndarray):
        items: object = value.tolist()  # nested lists of Python scalars (numpy leaves it untyped)
        return _clean(items)
    if isinstance(value, np.bool_ | bool):
        return bool(value)
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, float | np.floating):
        v = float(value)
        return v if np.isfinite(v) else None
    if value is None or isinstance(value, int | str):
        return value
    raise TypeError(f"Object of type {type(value).__name__} is not JSON serializable")


def record_json(ra: RecordAnalysis) -> JsonObject:
    """One record's figures.

    Parameters
    ----------
    ra : RecordAnalysis
        The record.

    Returns
    -------
    dict
        Its header, every test's keys, ``second_order_fits``, ``not_computed`` and ``notes``.
    """
    d = ra.data
    t = d.time_s
    doc: dict[str, object] = {
        "data": d.source, "channel": ra.channel_name, "samples": len(d) if ra.logged is None else ra.logged,
        **({} if ra.logged is None else {"samples_resampled": len(d)}), "sample_hz": d.sample_hz,
        "duration_s": float(t[-1] - t[0]), "outputs": d.outputs, "unit": d.unit, "metadata": d.metadata,
        "noise_deg": ra.noise_deg, "resolution_deg": ra.resolution_deg,
        "noise": {k: v.as_dict() for k, v in ra.noise.items()},
        "command": {**ra.command.as_dict(), "each_assumption": ra.other_timing or None},
        "tests": [s.as_dict(t) for s in ra.recognition.segments],
        "slew": slope_json(ra),
    }
    for test in TESTS:
        doc.update(test.as_json(ra.of(test), ra))
    doc["second_order_fits"] = [f.as_dict() for f in ra.fits]
    doc["not_computed"] = ra.not_computed
    doc["notes"] = ra.notes
    return dict(texts_in_unit(_clean(doc), d.unit))


SLOPE_METHOD = ("slope of the straight middle (20-80 %) of every move of the output that its command outran, "
                "median over the moves, on the record's own stamps (ema_sim.analysis.estimation.slew.measure): "
                "the measurement ema identify restarts its rate limit from and compares it with, so both reports "
                "give one slope")


def slope_statement(ra: RecordAnalysis) -> str:
    """The record's slope of rate-limited moves in one sentence (or why there is none).

    Parameters
    ----------
    ra : RecordAnalysis
        The record.

    Returns
    -------
    str
        The slope with its spread and the moves it comes from.
    """
    s = ra.slew
    unit = f"{ra.unit.strip()}/s"
    if s is None or s.rate is None:
        seen = s.seen if s is not None else 0
        return f"not measured: no rate-limited move ({seen} move(s) of the output examined, none outrun and straight)"
    sigma = f" ± {s.sigma:.2g}" if s.sigma is not None else ""
    return f"{s.rate:.4g}{sigma} {unit} ({s.moves} of {s.seen} moves rate-limited)"


def slope_json(ra: RecordAnalysis) -> JsonObject:
    """The record's slope of rate-limited moves, its statement and method.

    Parameters
    ----------
    ra : RecordAnalysis
        The record.

    Returns
    -------
    dict
        :meth:`~ema_sim.analysis.estimation.slew.Slew.as_dict`, ``statement`` and ``method``.
    """
    base = ra.slew.as_dict() if ra.slew is not None else {}
    return {**base, "statement": slope_statement(ra), "method": SLOPE_METHOD}


def to_json(records: Sequence[RecordAnalysis]) -> AnalyzeReport:
    """The whole ``--json`` document, checked against its published schema (:mod:`ema_sim.analysis.contract`).

    Parameters
    ----------
    records : sequence of RecordAnalysis
        The records.

    Returns
    -------
    dict
        Tool, version, the records, the spread across tests, the pooled command-error bounds, the
        uncertainty method and the rw13 check.
    """
    fits = [f for r in records for f in r.fits]
    cals = [c for r in records for c in r.of(CALIBRATION)]
    bounds = None
    if cals:
        lo = min(min(c.nominal_levels) for c in cals)
        hi = max(max(c.nominal_levels) for c in cals)
        bounds = pooled_bounds([c.error for c in cals], lo, hi)
    doc = dict(_clean({
        "tool": "ema analyze", "version": __version__,
        "records": [record_json(r) for r in records],
        "second_order_spread": texts_in_unit(_clean(spread(fits)), _one_unit(records)) if fits else None,
        "command_error_bounds": bounds,
        "uncertainty_method": UNCERTAINTY_METHOD,
        "rw13_check": {"area_inlb": RW13_AREA_INLB, "peak_in": RW13_PEAK_IN,
                       "h_lb_per_in": hysteretic_damping_constant(RW13_AREA_INLB, RW13_PEAK_IN)},
    }))
    check(doc, analyze_schema(), "ema analyze")
    return cast(AnalyzeReport, doc)  # the schema check above is the narrowing


def _one_unit(records: Sequence[RecordAnalysis]) -> str:
    """The records' unit when they share one (texts across them are then in it), else ``deg`` (as written)."""
    units = {r.data.unit for r in records}
    return units.pop() if len(units) == 1 else "deg"


# ---------------------------------------------------------------------------------------------- Markdown
def _pm(value: float, sigma: float, fmt: str = ".4g") -> str:
    return f"{value:{fmt}} ± {sigma:.2g}"


def _fit_rows(fits: list[SecondOrderFit]) -> list[list[str]]:
    rows = []
    for f in fits:
        hand = f"{f.hand.wn_rad_s:.4g} / {f.hand.zeta:.3g}" if f.hand else "—"
        rows.append([f.test, f.method.split(" (")[0], f.output, _pm(f.wn_rad_s.value, f.wn_rad_s.sigma),
                     f"{f.wn_rad_s.sigma_white:.2g}", _pm(f.zeta.value, f.zeta.sigma, ".4f"),
                     _pm(1e3 * f.delay_s.value, 1e3 * f.delay_s.sigma, ".3f"), hand,
                     f"{f.rms:.3g} {'dB' if f.rms_unit == 'db' else '°'}",
                     "yes" if f.residual_whiteness.white else "no", quality(f.quality, f.quality_note)])
    return rows


def _header(i: int, ra: RecordAnalysis, plots: dict[str, str]) -> list[str]:
    d = ra.data
    t = d.time_s
    lines = [f"## Record {i + 1}: `{d.source}`", ""]
    res = ", ".join(f"{k} {v:g}{ra.unit}" if v else f"{k} continuous" for k, v in ra.resolution_deg.items())
    lines += table(["channel", "samples", "rate", "span", "outputs", "noise floor", "resolution", "command"], [[
        ra.channel_name, f"{len(d):,}" if ra.logged is None else f"{ra.logged:,} logged, resampled onto {len(d):,}",
        f"{d.sample_hz:.6g} Hz", f"{t[-1] - t[0]:.4g} s", ", ".join(d.outputs),
        ", ".join(f"{k} {v:.2g}{ra.unit}" for k, v in ra.noise_deg.items()), res,
        "sampled" if ra.command.assumed_sampled else "held"]])
    lines += [f"Command: {ra.command.statement}.", ""]
    if ra.command.leads:
        lines += [f"**Causality:** {ra.command.leads}.", ""]
    lines += _each_assumption(ra)
    lines += [f"Slope of the rate-limited moves: {slope_statement(ra)}; {SLOPE_METHOD}.", ""]
    lines += [f"Noise and resolution: {'; '.join(f'{k}: {v.statement}' for k, v in ra.noise.items())}.", ""]
    if d.unit != "deg":
        lines += [f"Positions are in {d.unit} as logged (a linear actuator, not converted through a crank arm): "
                  f"every figure below is in {d.unit} and {d.unit}/s where a degree would be.", ""]
    meta = ", ".join(f"{k}: `{v}`" for k, v in d.metadata.items() if k in ("maneuver", "load", "model", "profile",
                                                                          "test", "channel"))
    if meta:
        lines += [f"Metadata: {meta}", ""]
    lines += image(plots.get(f"r{i}_overview"), "time history")
    lines += ["### Tests recognised", ""]
    lines += table(["kind", "from", "to", "evidence"],
                   [[s.kind, f"{t[s.start]:.3f} s", f"{t[s.stop - 1]:.3f} s", s.evidence]
                    for s in ra.recognition.segments]) if ra.recognition.segments else ["None.", ""]
    return lines


def _each_assumption(ra: RecordAnalysis) -> list[str]:
    """What the held and the sampled command give, side by side, for a record that cannot tell them apart."""
    if not ra.other_timing:
        return []
    rows = []
    for f in ra.other_timing:
        if f["quantity"] == "delay_s":
            rows.append([f["figure"], "delay, ms", f"{1e3 * f['held']:+.2f}", f"{1e3 * f['sampled']:+.2f}"])
        else:
            rows.append([f["figure"], "phase, °", f"{f['held']:+.2f}", f"{f['sampled']:+.2f}"])
    return ["The record cannot tell how its command was logged; each timing figure under both assumptions (the "
            "report's tables assume held):", "", *table(["figure", "quantity", "held", "sampled"], rows)]


def _record_md(i: int, ra: RecordAnalysis, plots: dict[str, str]) -> list[str]:
    """One record's section, in the record's unit (:func:`~ema_sim.analysis.formatting.units.in_unit`)."""
    return [in_unit(line, ra.data.unit) for line in _record_lines(i, ra, plots)]


def _record_lines(i: int, ra: RecordAnalysis, plots: dict[str, str]) -> list[str]:
    lines = _header(i, ra, plots)
    for test in TESTS:
        results = ra.of(test)
        if not results:
            continue
        images = [plots.get(plot_key(i, test.key, j)) for j in range(len(results))]
        lines += [f"### {test.title}", ""]
        lines += test.markdown(ra, results, images)
    if ra.fits:
        lines += ["### Second-order fits (section 3.1.1)", "",
                  f"± is one standard error corrected for coloured residuals ({UNCERTAINTY_METHOD}); the white-noise "
                  "standard error of ωn is beside it. Hand calculation: ωn / ζ from rise and settling time. A fit on "
                  "a bound of its range or with a standard error over a quarter of its value is not a measurement "
                  "(quality).", ""]
        lines += table(["test", "method", "output", "ωn, rad/s", "σ white", "ζ", "delay, ms", "hand ωn / ζ", "RMS",
                        "white residual", "quality"], _fit_rows(ra.fits))
    if ra.not_computed:
        absent = [k for k, v in ra.not_computed.items() if "recognised" in v and not v.startswith("no hinge")]
        limited = {k: v for k, v in ra.not_computed.items() if k not in absent}
        lines += ["### Not computed", ""]
        lines += [f"- **{k}**: {v}" for k, v in limited.items()]
        if absent:
            lines.append(f"- not in this record (no such test recognised): {', '.join(absent)}")
        lines.append("")
    if ra.notes:
        lines += ["### Notes", "", *bullets(ra.notes)]
    return lines


def to_markdown(records: Sequence[RecordAnalysis], plots: dict[str, str]) -> str:
    """The Markdown report.

    Parameters
    ----------
    records : sequence of RecordAnalysis
        The records.
    plots : dict
        Plot key → file name (:func:`ema_sim.analysis.plots.write_plots`).

    Returns
    -------
    str
        The report.
    """
    lines = ["# ema analyze report", "",
             f"ema_sim {__version__}; {len(records)} record(s). Methods: composite-window H1 spectra (Hann, 80 % "
             "overlap) or periodic chirp-z DFT; second-order fits by least squares with uncertainty corrected for "
             "coloured residuals (Morelli & Klein); everything cited to NASA/TM-2008-214637. Every result carries a "
             "quality: ok, on a bound, not determined, saturated, or leads its command (not causal: a servo never "
             "does, so the figure says how the record was logged).", ""]
    for i, ra in enumerate(records):
        lines += _record_md(i, ra, plots)
    across = len(lines)
    fits = [f for r in records for f in r.fits]
    if len(fits) > 1:
        lines += ["## Spread across tests (figure 23)", ""]
        for output, entry in spread(fits).items():
            w, z, d = entry["wn_rad_s"], entry["zeta"], entry["delay_s"]
            left = f" ({entry['left_out']} fit(s) not determined or on a bound left out)" if entry["left_out"] else ""
            if w is None:
                lines += [f"**{output}**: no determined estimate{left}.", ""]
                continue
            lines += [f"**{output}** over {w['count']} estimates{left}: ωn {w['min']:.4g}-{w['max']:.4g} rad/s (mean "
                      f"{w['mean']:.4g}), ζ {z['min']:.4f}-{z['max']:.4f} (mean {z['mean']:.4f}), delay "
                      f"{1e3 * d['min']:.3f}-{1e3 * d['max']:.3f} ms; model bounds uniform between the extremes.", ""]
        lines += image(plots.get("spread"), "spread of estimates")
    cals = [c for r in records for c in r.of(CALIBRATION)]
    if len(cals) > 1:
        lines += ["## Command-error bounds over all calibrations (figure 27)", "",
                  f"{len(cals)} calibrations: |Kb| ≤ {max(abs(c.error.kb) for c in cals):.5f}, |offset| ≤ "
                  f"{max(abs(c.error.offset_deg) for c in cals):.4f}°.", ""]
    unit = _one_unit(records)
    lines[across:] = [in_unit(line, unit) for line in lines[across:]]
    return "\n".join(lines) + "\n"
