"""What ``ema identify`` says: the contract's JSON, a Markdown report, residual plots and a residuals CSV.

The JSON is strict (RFC 8259): a value that does not exist is ``null`` and an unbounded one is said in
words (:func:`strict`), so no reader meets a bare ``NaN`` or ``Infinity``. Beside the contract's keys
it carries the ``reference`` (position = command), the ``warnings`` (:mod:`ema_sim.identify.trust`,
:mod:`ema_sim.identify.diagnosis`), the noise floors with their resolution, how the command was
taken, the travel, the unit, the effects ``removed`` again, identifiability and the residual
diagnosis.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any, cast, overload

import numpy as np

from ema_sim.analysis.estimation import slew
from ema_sim.analysis.estimation.noise import input_independence, whiteness
from ema_sim.analysis.formatting.units import texts_in_unit
from ema_sim.config import GENERIC
from ema_sim.identify.contract import Baseline, DiscoveredTerm, Final, IdentifyReport, Num, identify_schema
from ema_sim.identify.diagnosis import diagnose
from ema_sim.identify.effects import FREE, KEYS
from ema_sim.identify.fit import Fit
from ema_sim.identify.outcome import AS_DECLARED, Identification, model_name
from ema_sim.identify.problem import OUTPUT_COLUMN, Problem
from ema_sim.identify.stages import guarded
from ema_sim.identify.trust import assess, reference
from ema_sim.io.contract import check
from ema_sim.io.csv import FloatArray, write_csv
from ema_sim.jsontypes import JsonObject, JsonValue
from ema_sim.models import create

DIVERGED_DEG = 1.0e3
"""An implementation error beyond this (or not finite) is a diverging discretization, not an error figure."""


def _round(x: float, digits: int = 6) -> float:
    if not math.isfinite(x):
        return x
    return float(f"{x:.{digits}g}")


def _names(result: Identification, fit: Fit) -> dict[str, str]:
    """Model parameter → reported name: the declared model's own names, the vocabulary's for added effects."""
    own = set(result.baseline.free)
    return {f: f if f in own or f not in KEYS else KEYS[f].name for f in fit.free}


def _factor(result: Identification, fit: Fit, f: str) -> float:
    """The factor from a parameter's model unit to the unit its reported name carries."""
    return 1.0 if f in result.baseline.free or f not in KEYS else KEYS[f].factor(fit.params)


def _params(result: Identification, fit: Fit) -> dict[str, float]:
    names = _names(result, fit)
    out = {names[f]: _round(float(getattr(fit.params, f)) * _factor(result, fit, f)) for f in fit.free}
    if fit.params.hysteresis_h_lb_per_in > 0.0 and "hysteresis_h_lb_per_in" in fit.free:
        out["load_freq_hz"] = _round(fit.params.hysteresis_freq_hz)
    return out


def _lower_bounds(result: Identification, fit: Fit, unit: str) -> dict[str, str]:
    """Parameters held at the record's own bound (:attr:`Problem.caps`): figures the record shows only as "at least"."""
    p, names = result.problem, _names(result, fit)
    settled = p.settled
    if settled is None:
        return {}
    return {names[f]: settled.held(lambda v: format(v, ".4g"), unit) for f, cap in p.caps.items()
            if f in fit.free and float(getattr(fit.params, f)) >= cap * (1.0 - 1e-6)}


def _physical_final(result: Identification) -> dict[str, object]:
    """The final block of a high-order model whose physical parameters were fitted (model names and units)."""
    pf = result.physical
    assert pf is not None
    p = result.problem
    return {
        "model": model_name(result),
        "params": {k: _round(v) for k, v in pf.scalars().items()},
        "curves": {k: [_round(float(q)) for q in v] for k, v in pf.params.items() if isinstance(v, tuple)},
        "declared": {k: ([_round(float(q)) for q in v] if isinstance(v, tuple) else _round(float(v)))
                     for k, v in pf.declared.items()},
        "fields": {k: k for k in pf.fitted},
        "uncertainty": _determined({k: _round(v, 3) for k, v in pf.sigma.items()}),
        "correlation": {a: {b: _round(r, 4) for b, r in row.items()} for a, row in pf.correlation.items()},
        "not_determined": list(pf.held),
        "grid_searched": [],
        "hinge_moment_reversed": False,
        "simulations": pf.simulations,
        **_stats(p, result.final),
    }


def _rms_of(problem: Problem, fit: Fit) -> dict[str, float]:
    return {o: float(np.sqrt(np.mean(e**2))) for o, e in problem.errors_deg(fit.sim).items()}


def _stats(problem: Problem, fit: Fit) -> dict[str, object]:
    errors = problem.errors_deg(fit.sim)
    rms = {o: float(np.sqrt(np.mean(e**2))) for o, e in errors.items()}
    return {
        "rms_deg": {o: _round(v) for o, v in rms.items()},
        "max_abs_deg": {o: _round(float(np.max(np.abs(e)))) for o, e in errors.items()},
        "nrmse": {o: _round(rms[o] / float(np.std(problem.observed[o][problem.mask]))) for o in errors},
        "rms_over_noise": {o: _round(rms[o] / problem.sigma_deg[o], 4) for o in errors},
        "whiteness": {o: whiteness(e, lags=50).as_dict() for o, e in errors.items()},
        "independence": {  # the hinge moment only when the record logged one (a zero column tests nothing)
            o: {"command_deg": input_independence(e, problem.data.command_deg[problem.mask]).as_dict(),
                **({"hinge_moment_inlb": input_independence(e, problem.hinge_moment[problem.mask]).as_dict()}
                   if problem.data.hinge_moment_inlb is not None else {})}
            for o, e in errors.items()
        },
    }


def implementation_error(result: Identification) -> dict[str, float] | None:
    """How far the declared discrete implementation (LOADA at 800 Hz...) strays from its own equations.

    Identification fits the equations with an accurate simulator; this is the extra error the user's
    own implementation adds on the same record, reported apart so it is never mistaken for an effect.

    Parameters
    ----------
    result : Identification
        The identification.
    """
    if result.model not in ("loada", "loadf") or (result.final_model and result.equivalent is None):
        return None
    problem = result.problem
    final = result.equivalent or result.final  # the declared model with its effects, even when escalated
    model = create(result.model, problem.channel.channel, params=final.params)
    sign = -1.0 if final.flip else 1.0
    d = problem.data
    model.trim(d.command_deg[0], sign * d.hinge_moment[0])
    with np.errstate(all="ignore"):  # a discretization the fitted stages make unstable diverges: said, not warned
        out = model.run_outputs(problem.time_s, d.command_deg, sign * d.hinge_moment, sample_times=problem.time_s,
                                end_s=float(problem.time_s[-1]))[0]
    errors = {}
    for i, o in ((0, "position_deg"), (1, "surface_deg")):
        if o in problem.outputs:
            e = out[problem.mask, OUTPUT_COLUMN[o]] - final.sim[problem.mask, i]
            diverged = not np.all(np.isfinite(e)) or float(np.max(np.abs(e))) > DIVERGED_DEG
            errors[o] = math.inf if diverged else _round(float(np.sqrt(np.mean(e**2))))
    return errors


def implementation_warning(result: Identification, errors: Mapping[str, float]) -> str | None:
    """The warning a diverging declared implementation earns (its rms error unbounded), else None.

    Parameters
    ----------
    result : Identification
        The identification.
    errors : mapping
        :func:`implementation_error`'s figures.
    """
    bad = [o for o, v in errors.items() if not math.isfinite(v)]
    if not bad:
        return None
    rate = create(result.model, result.problem.channel.channel, params=result.final.params).rate_hz
    added = ", ".join(s.effect for s in result.steps) or "none"
    return (f"{result.model} at {rate:g} Hz, the declared discrete implementation, diverges on this record with the "
            f"fitted parameters ({', '.join(bad)}; effects added: {added}): its fixed step cannot carry them; this "
            f"report's figures are those of the same equations simulated accurately")


@overload
def strict(value: Mapping[str, object]) -> JsonObject: ...
@overload
def strict(value: object) -> JsonValue: ...
def strict(value: object) -> JsonValue:
    """``value`` with every non-finite number made strict JSON: NaN → null, ±inf → "unbounded" in words.

    Parameters
    ----------
    value : object
        Nested dicts, lists, tuples and scalars (numpy's included).

    Returns
    -------
    JSON value
        The same structure with plain Python scalars only.

    Raises
    ------
    TypeError
        A value JSON cannot hold (json.dumps' own error).
    """
    if isinstance(value, Mapping):
        return {str(k): strict(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [strict(v) for v in value]
    if isinstance(value, (bool, np.bool_, int, np.integer)):
        return value.item() if isinstance(value, np.generic) else value
    if isinstance(value, (float, np.floating)):
        x = float(value)
        return x if math.isfinite(x) else None if math.isnan(x) else "unbounded" if x > 0 else "unbounded below"
    if value is None or isinstance(value, str):
        return value
    raise TypeError(f"Object of type {type(value).__name__} is not JSON serializable")


def _slew(result: Identification) -> tuple[JsonObject, str | None]:
    """The slope measured on the record's rate-limited moves, and a warning when the model's rate limit disagrees."""
    measured = result.problem.measured_slew
    final = result.final
    if measured.rate is None or "rate_limit_dps" not in final.free:
        return measured.as_dict(), None
    fitted = float(final.params.rate_limit_dps)
    tol = max(slew.AGREE * measured.rate, 2.0 * (measured.sigma or 0.0))
    if abs(fitted - measured.rate) <= tol:
        return measured.as_dict(), None
    return measured.as_dict(), (
        f"the fitted rate limit {fitted:.4g} and the slope measured on the record's {measured.moves} rate-limited "
        f"moves, {measured.rate:.4g} (the straight middle of each move), disagree by "
        f"{100 * (fitted / measured.rate - 1):+.0f} %: the model's limit is not the slope the data show")


def to_json(result: Identification, data_name: str) -> IdentifyReport:
    """The report of ``../shared/data-contract.md`` (and more: uncertainty, diagnostics, verdicts, warnings).

    Parameters
    ----------
    result : Identification
        The identification.
    data_name : str
        How the report names the data (its path).
    """
    p = result.problem
    base = result.baseline
    final = result.final
    names = _names(result, final)
    record = result.record
    failures = result.failures
    assessed = guarded("trust", failures, lambda: assess(result))
    warnings, ident, exc = assessed if assessed is not None else ([], None, None)
    diagnosis = guarded("diagnosis", failures, lambda: diagnose(result))
    warnings += diagnosis.warnings if diagnosis is not None else []
    warnings += result.warnings + result.ambiguities + _sub_sample_delays(result)
    warnings += result.changes.warnings if result.changes is not None else []
    slope = guarded("slew", failures, lambda: _slew(result))
    if slope is not None and slope[1]:
        warnings.append(slope[1])
    warnings += [f"stage '{f.stage}' failed ({f.error}); what it would have said is missing" for f in failures
                 if f.stage in ("trust", "diagnosis")]
    ref = reference(p)
    unit = record.unit if record else "deg"
    report: dict[str, object] = {
        "data": data_name,
        "outputs": p.outputs,
        "unit": unit,
        "noise_deg": {o: _round(v) for o, v in p.sigma_deg.items()},
        "resolution_deg": {o: _resolution(p, o) for o in p.outputs},
        "reference": {"model": f"{'/'.join(o.split('_')[0] for o in p.outputs)} = command",
                      **{k: {o: _round(v) for o, v in m.items()} for k, m in ref.items()}},
        "baseline": {"model": result.model, "params": _params(result, base), **_stats(p, base),
                     "start": ({"params": _params(result, result.start),
                                "rms_deg": {o: _round(v) for o, v in _rms_of(p, result.start).items()}}
                               if result.start is not None else None)},
        **({"declared": {
            "model": result.model,
            "rms_deg": {o: _round(v) for o, v in result.as_declared.rms_deg.items()},
            "equivalent": {k: _round(v) for k, v in result.as_declared.equivalent.items()},
            "fitted": list(result.as_declared.free),
            "held_fixed": list(result.as_declared.held_fixed),
            "not_determinable": list(result.as_declared.not_determinable),
        }} if result.as_declared is not None else {}),
        "added": [
            {
                "effect": s.effect,
                "params": {k: _round(v) for k, v in s.params.items()},
                "uncertainty": _determined({k: _round(v, 3) for k, v in s.sigma.items()}),
                "rms_deg_before": {k: _round(v) for k, v in s.rms_deg_before.items()},
                "rms_deg_after": {k: _round(v) for k, v in s.rms_deg_after.items()},
                "evidence": s.evidence,
                "where": s.where,
                **({"replaces": list(s.replaces)} if s.replaces else {}),
            }
            for s in result.steps
        ],
        "removed": [{"effect": r.effect, "where": r.where, "params": {k: _round(v) for k, v in r.params.items()},
                     "reason": r.reason} for r in result.removed],
        "final": _physical_final(result) if result.physical is not None else {
            "model": model_name(result),
            "params": _params(result, final),
            "fields": {names[f]: f for f in final.free},
            "uncertainty": _determined({names[f]: _round(v * _factor(result, final, f), 3)
                                        for f, v in final.sigma.items()}),
            "relative_uncertainty": ({names[f]: _round(v, 3) for f, v in ident.relative_sigma.items()}
                                     if ident is not None else {}),
            "correlation": ({names[a]: {names[b]: _round(r, 4) for b, r in row.items()}
                             for a, row in ident.correlation.items()} if ident is not None else {}),
            "not_determined": list(dict.fromkeys(
                ([names[f] for f in ident.not_determined] if ident is not None else [])
                + [names[f] for f, v in final.sigma.items() if v == 0.0])),
            "not_determined_reason": {names[f]: ZERO_SIGMA for f, v in final.sigma.items() if v == 0.0},
            **({"lower_bound": bounds} if (bounds := _lower_bounds(result, final, unit)) else {}),
            "grid_searched": [names[f] for f in final.free if final.jac_free and f not in final.jac_free],
            "hinge_moment_reversed": final.flip,
            **_stats(p, final),
        },
        **({"equivalent": {
            "model": result.equivalent_model,
            # a declared model as it is has no fitted parameters of its own (its run is the declared one)
            "params": ({} if result.equivalent_model.endswith(AS_DECLARED)
                       else _params(result, result.equivalent)),
            "rms_deg": {o: _round(v) for o, v in _rms_of(p, result.equivalent).items()},
            "rms_over_noise": {o: _round(v / p.sigma_deg[o], 4) for o, v in _rms_of(p, result.equivalent).items()},
            "escalated_because": result.escalated or None,
        }} if result.equivalent is not None else {}),
        "slew_dps": slope[0] if slope is not None else None,
        "stages": [o.as_dict() for o in result.stages],
        "failures": [{"stage": f.stage, "error": f.error, "where": f.where} for f in failures],
        "discovered": result.discovery.as_dict() if result.discovery is not None else None,
        "discovered_terms": _discovered_terms(result),
        "artefacts": result.artefacts,
        "ambiguities": result.ambiguities,
        "warnings": warnings,
        "diagnosis": diagnosis.as_dict() if diagnosis is not None else None,
        "notes": (record.notes if record else []) + result.notes + ([p.unfitted_start] if p.unfitted_start else [])
        + ([result.timing] if result.timing else []),
        "changes": result.changes.as_dict() if result.changes is not None else None,
        "stamps": ({**record.stamps.as_dict(), "weighed_timing_ms": 1e3 * p.timing_s, "statement": result.timing}
                   if record is not None and record.stamps is not None else None),
        "command": {**(record.hold.as_dict() if record else {}),
                    "fitted_as": "sampled" if p.command_sampled else "held"},
        "travel_deg": ({"declared": list(record.travel.declared), "used": list(record.travel.limits),
                        "source": record.travel.source, "statement": record.travel.statement} if record else None),
        "excitation": ({"duration_s": _round(exc.duration_s), "level_changes": exc.changes,
                        "span_deg": _round(exc.span), "content_hz": _round(exc.bandwidth_hz)}
                       if exc is not None else None),
        "rejected": [
            {"effect": v.effect, "where": v.where, "value": None if v.value is None else _round(v.value),
             "reason": v.reason}
            for v in result.verdicts if not v.accepted
        ],
        "channel": GENERIC if record is not None and record.generic else p.channel.channel,
        "samples": int(p.time_s.size),
        "sample_hz": _round(p.sample_hz),
        "simulator_error_deg": {o: _round(v, 3) for o, v in result.simulator_error_deg.items()},
        "simulations": p.simulations,
        "simulations_reused": p.reused,
        "elapsed_s": round(result.elapsed_s, 2),
    }
    impl = guarded("implementation error", failures, lambda: implementation_error(result))
    if impl is not None:
        report["declared_implementation_error_deg"] = impl
        text = implementation_warning(result, impl)
        if text:
            warnings.append(text)
    # every text in the record's unit (a stage's words in degrees said in mm on a linear rig)
    out = texts_in_unit(strict(report), unit)
    check(out, identify_schema(), "ema identify")
    return cast(IdentifyReport, out)  # the schema check above is the narrowing


ZERO_SIGMA = ("not determined: its one-sigma came out exactly 0 (the fit cannot move it, or it sits on a bound), "
              "which is no measured uncertainty")
"""Why an uncertainty of exactly 0 is reported as null."""


def _determined(sigma: Mapping[str, float]) -> dict[str, float | None]:
    """One-sigma values with an exact 0 (no uncertainty measured, never a perfect one) made null."""
    return {k: (None if v == 0.0 else v) for k, v in sigma.items()}


def _discovered_terms(result: Identification) -> list[JsonObject]:
    """The discovered terms the final model carries: each with where it acts, its coefficients and one-sigma."""
    disc = result.discovery
    kept = disc.kept if disc is not None and result.discovered else None
    if kept is None:
        return []
    return [{"term": n, "on": o.split("_")[0], "placement": kept.where, "coefficient": [_round(c) for c in v],
             "uncertainty": [None if x == 0.0 else _round(x, 3) for x in sg], "unit": u}
            for o, ts in kept.terms.items() for n, v, sg, u in ts]


def _sub_sample_delays(result: Identification) -> list[str]:
    """A fitted delay under one sample: what the record cannot tell it from."""
    sample_s = 1.0 / result.problem.sample_hz
    out = []
    for field_name, label in (("delay_s", "time delay"), ("feedback_delay_s", "delay on the feedback")):
        value = float(getattr(result.final.params, field_name, 0.0))
        if field_name in result.final.free and 0.0 < value < sample_s:
            out.append(f"the {label}, {value * 1e3:.2f} ms, is under one sample ({sample_s * 1e3:.2f} ms): a transport "
                       "delay and a skew between the logging of the command and of the output look the same here")
    return out


def _resolution(p: Problem, output: str) -> float | None:
    """An output's count size, None when it has none."""
    q = None if p.noise is None else p.noise[output].resolution
    return None if q is None else _round(q)


def write_json(report: IdentifyReport | JsonObject, path: str | Path) -> None:
    """Write the report as indented strict JSON (no NaN or Infinity tokens: :func:`strict`).

    Parameters
    ----------
    report : dict
        The report (:func:`to_json`).
    path : path-like
        Where to write it.
    """
    text = json.dumps(strict(report), indent=2, ensure_ascii=False, allow_nan=False)
    Path(path).write_text(text + "\n", encoding="utf-8")


def write_residuals(result: Identification, path: str | Path) -> Path:
    """Time, and per output the measured, baseline and final model outputs and both residuals, as CSV.

    Every sample of the record is written; ``fitted`` is 1 on the samples the fits were judged on
    (0 on the first settling ones). Values are in the record's unit (``deg`` unless a linear unit was kept).

    Parameters
    ----------
    result : Identification
        The identification.
    path : path-like
        Where to write it.
    """
    p = result.problem
    cols: dict[str, FloatArray] = {"time_s": p.time_s, "fitted": p.mask.astype(float),
                                   "command_deg": p.data.command_deg}
    for o in p.outputs:
        meas = p.observed[o]
        col = OUTPUT_COLUMN[o]
        cols[f"{o}_measured"] = meas
        cols[f"{o}_baseline"] = result.baseline.sim[:, col]
        cols[f"{o}_final"] = result.final.sim[:, col]
        cols[f"{o}_residual_baseline"] = meas - result.baseline.sim[:, col]
        cols[f"{o}_residual_final"] = meas - result.final.sim[:, col]
    meta = {"model": result.model, "unit": result.record.unit if result.record else "deg",
            "command_fitted_as": "sampled" if p.command_sampled else "held"}
    write_csv(path, cols, meta)
    return Path(path)


def summary(report: IdentifyReport) -> str:
    """A few lines for the terminal.

    Parameters
    ----------
    report : dict
        The report (:func:`to_json`).
    """
    unit = report.get("unit", "deg")
    u = "°" if unit == "deg" else f" {unit}"
    lines = [f"{report['data']}: {report['samples']} samples at {report['sample_hz']:g} Hz, "
             f"noise {', '.join(f'{o} {v:.4g}{u}' for o, v in report['noise_deg'].items())}"]
    if "reference" in report:
        lines.append(f"reference {report['reference']['model']}: rms {_fmt_rms(report['reference']['rms_deg'], unit)}")
    if "declared" in report:
        d = report["declared"]
        lines.append(f"declared {d['model']} as it is: rms {_fmt_rms(d['rms_deg'], unit)}; not determinable by the "
                     f"record: {', '.join(d['not_determinable']) or 'none'}")
    b = report["baseline"]
    lines.append(f"baseline {b['model']}: {_fmt_params(b['params'])}; rms {_fmt_rms(b['rms_deg'], unit)}")
    for a in report["added"]:
        lines.append(f"  + {a['effect']} {_fmt_params(a['params'])}: rms {_fmt_rms(a['rms_deg_before'], unit)} → "
                     f"{_fmt_rms(a['rms_deg_after'], unit)}")
        lines.append(f"      {a['evidence']}")
    terms = report.get("discovered_terms") or []
    for t in terms:
        lines.append(f"  + discovered {_fmt_term(t)}")
    if not report["added"] and not terms:
        lines.append("  nothing added: no effect paid for itself")
    for r in report.get("removed", []):
        lines.append(f"  − {r['effect']} taken out again: {r['reason']}")
    f = report["final"]
    lines.append(f"final model: {f['model']}")
    lines.append(f"final: {_fmt_params(f['params'])}; rms {_fmt_rms(f['rms_deg'], unit)} "
                 f"({', '.join(f'{v:.2f}× noise' for v in f['rms_over_noise'].values())})")
    changes = report.get("changes") or {}
    if changes.get("changed"):
        lines.append("the record changed: the final values are the whole record's equivalents; per window:")
        lines += [f"  {s}" for s in _texts(changes.get("statements"))]
    lines += [f"warning: {w}" for w in report.get("warnings", [])]
    return "\n".join(lines)


def _num(v: object, spec: str = ".4g") -> str:
    """A number in ``spec``, or a word (``unbounded``) or null as it stands."""
    return format(v, spec) if isinstance(v, (int, float)) and not isinstance(v, bool) else str(v)


def _fmt_params(params: Mapping[str, object]) -> str:
    return ", ".join(f"{k} {_num(v)}" for k, v in params.items()) or "(none)"


def _fmt_sigma(sigma: Mapping[str, object]) -> str:
    """One-sigma values, a null one (an exact 0: :data:`ZERO_SIGMA`) said as not determined."""
    return ", ".join(f"{k} {'not determined' if v is None else _num(v)}" for k, v in sigma.items()) or "(none)"


def _fmt_term(t: DiscoveredTerm) -> str:
    """A discovered term: its name, where it acts, its coefficients ± one-sigma and unit."""
    coef = ", ".join(f"{_num(c)} ± {'not determined' if s is None else _num(s, '.2g')}"
                     for c, s in zip(t["coefficient"], t["uncertainty"], strict=False))
    return f"{t['term']} ({t['on']}, {t['placement']}): {coef} {t['unit']}".rstrip()


def _texts(value: object) -> list[str]:
    """An open block's list of sentences (none when it has none)."""
    return [str(s) for s in value] if isinstance(value, list) else []


def _fmt_rms(rms: Mapping[str, Num], unit: str = "deg") -> str:
    u = "°" if unit == "deg" else f" {unit}"
    return ", ".join(f"{k.split('_')[0]} {v:.4g}{u}" for k, v in rms.items())


def write_report(result: Identification, report: IdentifyReport, directory: str | Path) -> Path:
    """Markdown report with plots of the residual before and after, under ``directory``.

    Parameters
    ----------
    result : Identification
        The identification.
    report : dict
        The report (:func:`to_json`).
    directory : path-like
        The report's directory (created).
    """
    out = Path(directory)
    out.mkdir(parents=True, exist_ok=True)
    _plots(result, report, out)
    return _markdown(result, report, out)


def _plots(result: Identification, report: IdentifyReport, out: Path) -> None:
    """``residual.png`` (before and after, with the noise floor) and ``fit.png`` (measured and model)."""
    import matplotlib as mpl  # noqa: PLC0415 - plotting only when asked

    mpl.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415 - the same (0.4 s of import)

    p = result.problem
    t = p.time_s[p.mask]
    rows = 2 * len(p.outputs) + 1
    fig, axes = plt.subplots(rows, 1, figsize=(11, 2.4 * rows), sharex=True)
    for k, o in enumerate(p.outputs):
        col = OUTPUT_COLUMN[o]
        meas = p.observed[o][p.mask]
        s = p.sigma_deg[o]
        for ax, fit, label in ((axes[2 * k], result.baseline, f"before ({report['baseline']['model']})"),
                               (axes[2 * k + 1], result.final, "after")):
            ax.plot(t, meas - fit.sim[p.mask, col], lw=0.5, color="tab:blue" if fit is result.baseline else "tab:green",
                    label=label)
            ax.axhspan(-2 * s, 2 * s, color="0.85", zorder=0, label="±2σ noise floor (counts included)")
            ax.set_ylabel(f"{o.split('_')[0]} residual, {report.get('unit', 'deg')}")
            ax.legend(loc="upper right", fontsize=8)
            ax.grid(alpha=0.3)
    unit = report.get("unit", "deg")
    axes[-1].plot(t, p.data.command_deg[p.mask], lw=0.7, label="command_deg")
    if p.load_span_inlb > 0.0:  # no empty load axis on a record without a hinge moment
        ax2 = axes[-1].twinx()
        ax2.plot(t, p.hinge_moment[p.mask], lw=0.5, color="tab:red", label="hinge moment")
        ax2.set_ylabel("hinge moment, in·lb")
    axes[-1].set_ylabel(f"command, {unit}")
    axes[-1].set_xlabel("time, s")
    fig.suptitle("Residual (measured − model) before and after identification")
    fig.tight_layout()
    fig.savefig(out / "residual.png", dpi=110)
    plt.close(fig)

    fig, axes = plt.subplots(len(p.outputs), 1, figsize=(11, 3.2 * len(p.outputs)), sharex=True, squeeze=False)
    for ax, o in zip(axes[:, 0], p.outputs, strict=True):
        col = OUTPUT_COLUMN[o]
        ax.plot(p.time_s, p.observed[o], lw=0.6, label="measured")
        ax.plot(p.time_s, result.final.sim[:, col], lw=0.6, ls="--", label="identified model")
        ax.set_ylabel(f"{o}")
        ax.legend(loc="upper right", fontsize=8)
        ax.grid(alpha=0.3)
    axes[-1, 0].set_xlabel("time, s")
    fig.tight_layout()
    fig.savefig(out / "fit.png", dpi=110)
    plt.close(fig)



def _md_terms(report: IdentifyReport) -> list[str]:
    """The discovered terms of the final model as a table (none: nothing)."""
    terms = report.get("discovered_terms") or []
    if not terms:
        return []
    rows = ["Discovered terms (beyond the vocabulary) the final model carries:", "",
            "| term | acts on | placement | coefficient | ±1σ | unit |", "| --- | --- | --- | --- | --- | --- |"]
    for t in terms:
        sig = ", ".join("not determined" if x is None else _num(x, ".3g") for x in t["uncertainty"])
        coef = ", ".join(_num(c, ".6g") for c in t["coefficient"])
        rows.append(f"| {t['term']} | {t['on']} | {t['placement']} | {coef} | {sig} | {t['unit'].strip()} |")
    return [*rows, ""]


def _markdown(result: Identification, report: IdentifyReport, out: Path) -> Path:
    """``report.md``: the summary, the record, the warnings, the errors, the effects, the diagnosis."""
    p = result.problem
    unit = report.get("unit", "deg")
    md = ["# Identification report", "", "```", summary(report), "```", "", "## The record", ""]
    md += [f"- {n}" for n in report.get("notes", [])]
    md += ["", "## Warnings", ""]
    md += [f"- {w}" for w in report.get("warnings", [])] or ["None."]
    md += ["", "## Error before and after", "",
           f"| | output | rms, {unit} | max abs, {unit} | NRMSE | rms / noise | white |",
           "| --- | --- | --- | --- | --- | --- | --- |"]
    ref = report["reference"]
    for o in p.outputs:
        md.append(f"| reference ({ref['model']}) | {o} | {ref['rms_deg'][o]:.4g} | {ref['max_abs_deg'][o]:.4g} | | "
                  f"{cast(float, ref['rms_deg'][o]) / cast(float, report['noise_deg'][o]):.3g} | |")
    blocks: tuple[tuple[str, Baseline | Final], ...] = (("baseline", report["baseline"]), ("final", report["final"]))
    for label, block in blocks:
        for o in p.outputs:
            md.append(f"| {label} | {o} | {block['rms_deg'][o]:.4g} | {block['max_abs_deg'][o]:.4g} | "
                      f"{block['nrmse'][o]:.4g} | {block['rms_over_noise'][o]:.3g} | "
                      f"{'yes' if block['whiteness'][o]['white'] else 'no'} |")
    md += ["", "## Effects added", ""]
    if report["added"]:
        md += ["| effect | parameters | ±1σ | evidence |", "| --- | --- | --- | --- |"]
        for a in report["added"]:
            md.append(f"| {a['effect']} | {_fmt_params(a['params'])} | {_fmt_sigma(a['uncertainty'])} | "
                      f"{a['evidence']} |")
    elif report.get("discovered_terms"):
        md.append("No effect of the vocabulary: the final model carries the discovered terms below instead.")
    else:
        md.append("None: no candidate paid for itself.")
    md += ["", "## Final model", "", f"`{report['final']['model']}`", ""]
    md += _md_terms(report)
    md += ["## Final parameters", "", "| parameter | value | ±1σ |", "| --- | --- | --- |"]
    unc, bounds = report["final"]["uncertainty"], report["final"].get("lower_bound", {})
    for k, v in report["final"]["params"].items():
        sg = unc.get(k, "—")
        bound = "; a lower bound (≥, below)" if k in bounds else ""
        md.append(f"| {k} | {_num(v, '.6g')} | {'not determined' if sg is None else _num(sg, '.3g')}{bound} |")
    md += ["", *(f"- {k}: {why}" for k, why in bounds.items())] if bounds else []
    if report.get("removed"):
        md += ["", "## Effects taken out again", "", "| effect | where | parameters | why |",
               "| --- | --- | --- | --- |"]
        md += [f"| {r['effect']} | {r['where']} | {_fmt_params(r['params'])} | {r['reason']} |"
               for r in report["removed"]]
    md += _changes_md(report.get("changes"))
    md += ["", "## What the final model leaves (residual diagnosis)", ""]
    md += [f"- {line}" for line in _texts((report["diagnosis"] or {}).get("text"))]
    md += [f"- discovery: {line}" for line in _texts((report["discovered"] or {}).get("text"))]
    if report["rejected"]:
        md += ["", "## Candidates fitted and rejected", "", "| effect | where | value | why |",
               "| --- | --- | --- | --- |"]
        md += [f"| {r['effect']} | {r['where']} | {r['value']} | {r['reason']} |" for r in report["rejected"]]
    md += ["", "![residual](residual.png)", "", "![fit](fit.png)", ""]
    (out / "report.md").write_text("\n".join(md), encoding="utf-8")
    return out / "report.md"


def _changes_md(changes: dict[str, Any] | None) -> list[str]:
    """The section on the parameters fitted per window of the record (empty when they were not)."""
    if not changes or not changes.get("parameters"):
        return []
    md = ["", "## Over the record: the parameters per window", "", f"Windows: {changes['how']}.", ""]
    windows = changes["windows_s"]
    head = " | ".join(f"{a:.4g}-{b:.4g} s" for a, b in windows)
    md += [f"| parameter | trend | {head} |", "| --- | --- | " + " | ".join("---" for _ in windows) + " |"]
    for t in changes["parameters"]:
        cells = " | ".join(f"{_num(v, '.4g')} ± {_num(s, '.2g')}" for v, s in zip(t["values"], t["sigma"], strict=True))
        md.append(f"| {t['parameter']} | {t['trend']} | {cells} |")
    if changes.get("bandwidth_hz"):
        md.append("| bandwidth, Hz | | " + " | ".join(_num(b, ".3g") for b in changes["bandwidth_hz"]) + " |")
    md.append("")
    md += [f"- {s}" for s in changes.get("statements", [])]
    md += [f"- {s}" for s in changes.get("proxies_removed", [])]
    return md


__all__ = ["FREE", "strict", "summary", "to_json", "write_json", "write_report", "write_residuals"]
