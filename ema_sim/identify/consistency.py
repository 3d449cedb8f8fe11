"""Consistency of one actuator identified from several maneuvers: whether its parameters agree.

"Consistency": the same actuator identified from different records must give parameters
that agree within their stated uncertainties, or the report must say the record cannot determine
them. :func:`compare` reads two or more ``ema identify`` reports (:func:`parse_report`) and, for every
model parameter fitted in at least two of them, gives the inverse-variance weighted mean and its
sigma, the chi-square of the values about it (n − 1 degrees of freedom) and its p-value, the largest
pairwise ``|Δ| / √(σa² + σb²)`` with the pair named, and a verdict:

``agree``
    every pair within ``sigma`` combined standard deviations;
``disagree``
    some pair beyond it (the pairs and their distance in sigma are listed);
``undetermined``
    at least one report gives no finite, positive uncertainty for it, lists it as not determined by its
    record, or found it on a grid (``final.grid_searched``: a parameter before the quantizer, whose ± is
    the grid's spacing); those reports are named, the others are still compared among themselves;
``single``
    fitted in one report only: listed, not compared.

Parameters are matched by model field (``final.fields``: report key → model field), so a key renamed
from one report to the next still matches, and values are taken to the field's declared unit (a
load rate limit reported per 1000 in·lb is taken back to °/s per lbf). Effects added in some reports
and not in others are listed. A report whose final error on an output is above
:data:`STRUCTURE_FACTOR` times its noise floor gets a note: its parameters are the equivalents of a
model that leaves structure in the residual, so disagreement with another maneuver says the model
lacks structure, not that the actuator changed.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from functools import cache
from itertools import combinations
from pathlib import Path

from scipy.stats import chi2

from ema_sim.config import GENERIC, STAND_IN, load_channel
from ema_sim.errors import DataError, SpecError
from ema_sim.identify.effects import KEYS
from ema_sim.identify.physical import ESCALATE_TO
from ema_sim.identify.problem import EQUIVALENT_EXCESS
from ema_sim.jsontypes import JsonObject
from ema_sim.models import model_parameters
from ema_sim.models.second_order import SecondOrderParams
from ema_sim.parameters import metas

STRUCTURE_FACTOR = EQUIVALENT_EXCESS
"""A final rms above this many times an output's noise floor: the model leaves structure, and the report itself
already calls its parameters equivalents (the diagnosis's one threshold)."""

VERDICTS = ("agree", "disagree", "undetermined", "single")
"""Every verdict :func:`compare` gives, in the order the summary counts them."""

_REPORT_NAME = {key.name: field for field, key in KEYS.items()}
"""Report key → model field, for a report written before ``final.fields`` existed."""


@dataclass(frozen=True)
class IdentifyReport:
    """The parts of one ``ema identify`` report a consistency check reads.

    Parameters
    ----------
    name : str
        How tables and verdicts name the report (its file name, the path when names repeat).
    path : str
        Where it was read from.
    data : str
        The record it identified (the report's ``data``).
    channel : str
        The report's channel.
    unit : str
        The record's unit (``deg``, or a rig's linear unit kept as logged).
    model : str
        The final model (``final.model``).
    keys : dict
        Model field → the report's key for it.
    values : dict
        Model field → fitted value in the field's declared unit (NaN when the report gives no number).
    sigmas : dict
        Model field → one-sigma uncertainty in the same unit (inf when the report gives none).
    not_determined : tuple of str
        Model fields the report says its record does not determine.
    effects : tuple of tuple of str
        ``(effect, where)`` of every effect added, in order.
    grid_searched : tuple of str
        Model fields found by a grid search before the quantizer: their ± is the grid's spacing, no statistic.
    rms_over_noise : dict
        Output → final rms over the noise floor (inf when the rms is unbounded).
    """

    name: str
    path: str
    data: str
    channel: str
    unit: str
    model: str
    keys: dict[str, str]
    values: dict[str, float]
    sigmas: dict[str, float]
    not_determined: tuple[str, ...]
    effects: tuple[tuple[str, str], ...]
    rms_over_noise: dict[str, float]
    grid_searched: tuple[str, ...] = ()

    @property
    def structured(self) -> dict[str, float]:
        """Outputs whose final rms is above :data:`STRUCTURE_FACTOR` times their noise floor → that ratio."""
        return {o: r for o, r in self.rms_over_noise.items() if not r <= STRUCTURE_FACTOR}


@dataclass(frozen=True)
class Pair:
    """Two reports' values of one parameter and their distance in combined standard deviations.

    Parameters
    ----------
    a, b : str
        The reports' names.
    z : float
        ``|value_a − value_b| / √(σa² + σb²)``.
    """

    a: str
    b: str
    z: float


@dataclass(frozen=True)
class Entry:
    """One report's value of one parameter.

    Parameters
    ----------
    report : str
        The report's name.
    key : str
        The report's key for it.
    value : float
        Value in the field's declared unit (NaN: the report gives no number).
    sigma : float
        One-sigma uncertainty in that unit (inf: the report gives none).
    determined : bool
        True when the value and a positive uncertainty are finite and the report does not list it as
        not determined by its record.
    """

    report: str
    key: str
    value: float
    sigma: float
    determined: bool


@dataclass(frozen=True)
class FieldConsistency:
    """One model parameter across the reports that fitted it.

    Parameters
    ----------
    field : str
        The model field (its declared name).
    unit : str
        Its declared unit ('' when the parameter metadata has none).
    entries : tuple of Entry
        One per report that fitted it, in the reports' order.
    mean, mean_sigma : float
        Inverse-variance weighted mean of the determined values and its one-sigma (NaN with fewer than two).
    chi_square : float
        ``Σ (value − mean)² / σ²`` over the determined values (NaN with fewer than two).
    dof : int
        Degrees of freedom: determined values − 1 (0 with fewer than two).
    p_value : float
        Probability of a chi-square this large or larger if the values agree (NaN with fewer than two).
    worst : Pair or None
        The pair of determined values furthest apart (None with fewer than two).
    beyond : tuple of Pair
        Every pair beyond the limit, furthest first.
    verdict : str
        One of :data:`VERDICTS`.
    reason : str
        The verdict in words.
    """

    field: str
    unit: str
    entries: tuple[Entry, ...]
    mean: float
    mean_sigma: float
    chi_square: float
    dof: int
    p_value: float
    worst: Pair | None
    beyond: tuple[Pair, ...]
    verdict: str
    reason: str

    def as_dict(self) -> JsonObject:
        """The comparison as plain data (non-finite numbers left for :func:`~ema_sim.identify.report.strict`).

        Returns
        -------
        dict
            Field, unit, per-report values, statistics, verdict and reason.
        """
        return {
            "field": self.field,
            "unit": self.unit,
            "values": {e.report: {"key": e.key, "value": _number(e.value), "sigma": _number(e.sigma),
                                  "determined": e.determined} for e in self.entries},
            "weighted_mean": _number(self.mean),
            "weighted_sigma": _number(self.mean_sigma),
            "chi_square": _number(self.chi_square),
            "dof": self.dof,
            "p_value": _number(self.p_value),
            "max_z": None if self.worst is None else self.worst.z,
            "max_pair": None if self.worst is None else [self.worst.a, self.worst.b],
            "beyond": [{"reports": [p.a, p.b], "z": p.z} for p in self.beyond],
            "undetermined_in": [e.report for e in self.entries if not e.determined],
            "verdict": self.verdict,
            "reason": self.reason,
        }


@dataclass(frozen=True)
class EffectPresence:
    """An effect added in some reports and not in others.

    Parameters
    ----------
    effect : str
        The vocabulary's name.
    where : str
        Where it acts (the report's ``where``).
    added_in, not_in : tuple of str
        The reports that added it and those that did not.
    """

    effect: str
    where: str
    added_in: tuple[str, ...]
    not_in: tuple[str, ...]


@dataclass(frozen=True)
class Consistency:
    """The parameters of several identifications of one actuator, compared.

    Parameters
    ----------
    reports : tuple of IdentifyReport
        The reports, in the order given.
    sigma : float
        The limit: a pair further apart than this many combined standard deviations disagrees.
    fields : tuple of FieldConsistency
        Every model field fitted in at least one report, in order of first appearance.
    effects : tuple of EffectPresence
        Effects added in some reports and not in others.
    common_effects : tuple of tuple of str
        ``(effect, where)`` added in every report.
    notes : tuple of str
        What a reader must know to read the verdicts (a report whose model leaves structure).
    """

    reports: tuple[IdentifyReport, ...]
    sigma: float
    fields: tuple[FieldConsistency, ...]
    effects: tuple[EffectPresence, ...]
    common_effects: tuple[tuple[str, str], ...]
    notes: tuple[str, ...]

    def counts(self) -> dict[str, int]:
        """How many parameters got each verdict.

        Returns
        -------
        dict
            Verdict → count, every verdict of :data:`VERDICTS` present.
        """
        return {v: sum(f.verdict == v for f in self.fields) for v in VERDICTS}

    def as_dict(self) -> JsonObject:
        """The whole comparison as plain data; write it with :func:`~ema_sim.identify.report.write_json`.

        Returns
        -------
        dict
            Reports, limit, per-field comparisons, effects, notes and the verdicts counted.
        """
        return {
            "channel": self.reports[0].channel,
            "unit": self.reports[0].unit,
            "sigma": self.sigma,
            "reports": [{"name": r.name, "path": r.path, "data": r.data, "model": r.model,
                         "rms_over_noise": {**r.rms_over_noise}, "structured_residual": bool(r.structured)}
                        for r in self.reports],
            "fields": [f.as_dict() for f in self.fields],
            "effects_in_some": [{"effect": e.effect, "where": e.where, "added_in": list(e.added_in),
                                 "not_in": list(e.not_in)} for e in self.effects],
            "effects_in_all": [{"effect": e, "where": w} for e, w in self.common_effects],
            "notes": list(self.notes),
            "verdicts": {**self.counts()},
        }


def _number(x: float) -> float | None:
    """NaN → None (no value); an infinity stays (``strict`` says it in words)."""
    return None if math.isnan(x) else x


def _float(x: object) -> float:
    """A report's number as float: a word (``"unbounded"``) or null is no finite number."""
    if isinstance(x, bool) or not isinstance(x, (int, float)):
        return math.inf if isinstance(x, str) and x.startswith("unbounded") else math.nan
    return float(x)


def _mapping(doc: Mapping[str, object], key: str, where: str, source: str) -> Mapping[str, object]:
    value = doc.get(key)
    if not isinstance(value, Mapping):
        raise DataError(f"{source}: not an `ema identify` report (no {where}{key} object)")
    return value


@cache
def _channel_params(channel: str) -> SecondOrderParams:
    """The channel's configured second-order parameters (what a report key's unit factor reads)."""
    return SecondOrderParams.from_channel(load_channel(STAND_IN if channel == GENERIC else channel))


def _factor(field: str, key: str, channel: str) -> float:
    """From the unit of a report's ``key`` to the declared unit of ``field`` (1 unless the key was renamed)."""
    if key == field or field not in KEYS or KEYS[field].name != key:
        return 1.0
    return float(KEYS[field].factor(_channel_params(channel)))


def parse_report(doc: object, source: str, name: str | None = None) -> IdentifyReport:
    """One ``ema identify`` report (:func:`~ema_sim.identify.report.to_json`'s dict) as a consistency check reads it.

    Parameters
    ----------
    doc : object
        The parsed JSON.
    source : str
        Where it came from (named in errors).
    name : str, optional
        How verdicts name it (default: ``source``).

    Returns
    -------
    IdentifyReport
        The report's parameters keyed by model field, in each field's declared unit.

    Raises
    ------
    DataError
        When ``doc`` is not an identify report.
    """
    if not isinstance(doc, Mapping):
        raise DataError(f"{source}: not an `ema identify` report (a JSON {type(doc).__name__}, not an object)")
    final = _mapping(doc, "final", "", source)
    params = _mapping(final, "params", "final.", source)
    channel = doc.get("channel")
    if not isinstance(channel, str):
        raise DataError(f"{source}: not an `ema identify` report (no channel)")
    fields_doc = final.get("fields")
    if fields_doc is None:
        fields = {k: _REPORT_NAME.get(k, k) for k in params}
    elif isinstance(fields_doc, Mapping) and all(isinstance(v, str) for v in fields_doc.values()):
        fields = {str(k): str(v) for k, v in fields_doc.items() if k in params}
    else:
        raise DataError(f"{source}: not an `ema identify` report (final.fields is not key → field names)")
    sigma_doc = final.get("uncertainty") or {}
    if not isinstance(sigma_doc, Mapping):
        raise DataError(f"{source}: not an `ema identify` report (final.uncertainty is not an object)")
    keys: dict[str, str] = {}
    values: dict[str, float] = {}
    sigmas: dict[str, float] = {}
    for key, field in fields.items():
        factor = _factor(field, key, channel)
        s = _float(sigma_doc.get(key))
        keys[field] = key
        values[field] = _float(params[key]) / factor
        sigmas[field] = math.inf if math.isnan(s) else abs(s / factor)
    nd = final.get("not_determined") or []
    not_determined = tuple(fields.get(str(k), str(k)) for k in nd) if isinstance(nd, list) else ()
    gs = final.get("grid_searched") or []
    grid_searched = tuple(fields.get(str(k), str(k)) for k in gs) if isinstance(gs, list) else ()
    added = doc.get("added") or []
    effects = tuple((str(a.get("effect", "?")), str(a.get("where", "")))
                    for a in added if isinstance(a, Mapping)) if isinstance(added, list) else ()
    return IdentifyReport(
        name=name or source, path=source, data=str(doc.get("data", "")), channel=channel,
        unit=str(doc.get("unit", "deg")), model=str(final.get("model", "")), keys=keys, values=values,
        sigmas=sigmas, not_determined=not_determined, effects=effects,
        rms_over_noise=_rms_over_noise(doc, final), grid_searched=grid_searched,
    )


def _rms_over_noise(doc: Mapping[str, object], final: Mapping[str, object]) -> dict[str, float]:
    """Output → final rms / noise floor, for the outputs the report gives both of."""
    rms, noise = final.get("rms_deg"), doc.get("noise_deg")
    if not isinstance(rms, Mapping) or not isinstance(noise, Mapping):
        return {}
    out = {}
    for o, r in rms.items():
        n = _float(noise.get(o))
        if math.isfinite(n) and n > 0.0:
            x = _float(r)
            out[str(o)] = math.inf if math.isnan(x) else x / n
    return out


def read_report(path: str | Path, name: str | None = None) -> IdentifyReport:
    """Read one ``ema identify --json`` file.

    A bare ``NaN`` or ``Infinity`` (reports written before the JSON was strict) is read as no finite
    number, the same as the strict report's ``null`` and ``"unbounded"``.

    Parameters
    ----------
    path : str or pathlib.Path
        The JSON file.
    name : str, optional
        How verdicts name it (default: the path as given).

    Returns
    -------
    IdentifyReport
        The report (:func:`parse_report`).

    Raises
    ------
    DataError
        A missing or unreadable file, malformed JSON, or JSON that is not an identify report.
    """
    source = str(path)
    try:
        text = Path(path).read_text(encoding="utf-8")
    except FileNotFoundError:
        raise DataError(f"{source}: no such file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise DataError(f"{source}: cannot read it ({getattr(exc, 'strerror', None) or exc})") from None
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as exc:
        raise DataError(f"{source}: malformed JSON: {exc.msg} (line {exc.lineno}, column {exc.colno})") from None
    return parse_report(doc, source, name)


def read_reports(paths: Sequence[str | Path]) -> list[IdentifyReport]:
    """Read several reports, each named by its file name (by its path when two names are the same).

    Parameters
    ----------
    paths : sequence of str or pathlib.Path
        The JSON files.

    Returns
    -------
    list of IdentifyReport
        In the order given.
    """
    names = [Path(p).name for p in paths]
    if len(set(names)) < len(names):
        names = [str(p) for p in paths]
    names = [n if names.count(n) == 1 else f"{n} ({i + 1})" for i, n in enumerate(names)]
    return [read_report(p, n) for p, n in zip(paths, names, strict=True)]


def _entry(r: IdentifyReport, field: str) -> Entry:
    v, s = r.values[field], r.sigmas[field]
    ok = (math.isfinite(v) and math.isfinite(s) and s > 0.0 and field not in r.not_determined
          and field not in r.grid_searched)
    return Entry(r.name, r.keys[field], v, s, ok)


def _undetermined_why(entries: Sequence[Entry], reports: Mapping[str, IdentifyReport], field: str) -> str:
    parts = []
    for e in entries:
        if e.determined:
            continue
        if field in reports[e.report].not_determined:
            parts.append(f"{e.report} says its record does not determine it")
        elif field in reports[e.report].grid_searched:
            parts.append(f"{e.report} found it on a grid before the quantizer (its ± is the grid's spacing, not a "
                         "statistical uncertainty)")
        elif not math.isfinite(e.value):
            parts.append(f"{e.report} gives no finite value")
        else:
            parts.append(f"{e.report} gives no finite uncertainty")
    return "; ".join(parts)


def compare_field(field: str, entries: Sequence[Entry], sigma: float, unit: str = "",
                  why_undetermined: str = "") -> FieldConsistency:
    """One parameter's values across reports: weighted mean, chi-square, worst pair, verdict.

    Parameters
    ----------
    field : str
        The model field.
    entries : sequence of Entry
        Its value in every report that fitted it.
    sigma : float
        The limit in combined standard deviations.
    unit : str
        Its declared unit.
    why_undetermined : str
        What the undetermined entries lack, in words (used in the reason).

    Returns
    -------
    FieldConsistency
        The comparison.
    """
    good = [e for e in entries if e.determined]
    mean = mean_sigma = chi_square = p_value = math.nan
    dof = 0
    worst: Pair | None = None
    beyond: list[Pair] = []
    if len(good) >= 2:
        weights = [1.0 / e.sigma**2 for e in good]
        total = math.fsum(weights)
        mean = math.fsum(w * e.value for w, e in zip(weights, good, strict=True)) / total
        mean_sigma = 1.0 / math.sqrt(total)
        chi_square = math.fsum(w * (e.value - mean) ** 2 for w, e in zip(weights, good, strict=True))
        dof = len(good) - 1
        p_value = float(chi2.sf(chi_square, dof))
        pairs = [Pair(a.report, b.report, abs(a.value - b.value) / math.hypot(a.sigma, b.sigma))
                 for a, b in combinations(good, 2)]
        worst = max(pairs, key=lambda p: p.z)
        beyond = sorted((p for p in pairs if p.z > sigma), key=lambda p: -p.z)
    pairs_text = ", ".join(f"{p.a} and {p.b} by {p.z:.1f}σ" for p in beyond)
    if len(entries) == 1:
        verdict, reason = "single", f"fitted in {entries[0].report} only"
    elif len(good) < len(entries):
        verdict = "undetermined"
        reason = why_undetermined or "some report gives no finite uncertainty"
        if worst is not None:
            reason += (f"; the others differ by up to {worst.z:.1f}σ ({worst.a} and {worst.b})"
                       + (f", beyond {sigma:g}σ" if beyond else ""))
    elif beyond:
        verdict, reason = "disagree", f"beyond {sigma:g}σ: {pairs_text}"
    else:
        assert worst is not None
        verdict = "agree"
        reason = f"every pair within {sigma:g}σ (largest {worst.z:.1f}σ, {worst.a} and {worst.b})"
    return FieldConsistency(field, unit, tuple(entries), mean, mean_sigma, chi_square, dof, p_value, worst,
                            tuple(beyond), verdict, reason)


def compare(reports: Sequence[IdentifyReport], sigma: float = 3.0) -> Consistency:
    """Compare the parameters of several identifications of one actuator (module docstring).

    Parameters
    ----------
    reports : sequence of IdentifyReport
        Two or more reports of one channel, in one unit (:func:`parse_report`).
    sigma : float
        A pair further apart than this many combined standard deviations disagrees.

    Returns
    -------
    Consistency
        Per-field verdicts, effects added in some reports only, notes.

    Raises
    ------
    SpecError
        Fewer than two reports, or a limit that is not a positive number.
    DataError
        Reports of different channels or units.
    """
    if len(reports) < 2:
        raise SpecError(f"a consistency check needs two reports or more, got {len(reports)}")
    if not (math.isfinite(sigma) and sigma > 0.0):
        raise SpecError(f"--sigma must be a positive number, got {sigma:g}")
    for attr, what in (("channel", "channels"), ("unit", "units")):
        if len({getattr(r, attr) for r in reports}) > 1:
            listed = ", ".join(f"{r.name} {getattr(r, attr)}" for r in reports)
            raise DataError(f"reports of different {what} cannot be compared: {listed}")
    by_name = {r.name: r for r in reports}
    units = {m.name: m.unit for m in model_parameters(ESCALATE_TO)} | {k: m.unit for k, m in
                                                                     metas(SecondOrderParams).items()}
    order: list[str] = []
    for r in reports:
        order += [f for f in r.keys if f not in order]
    fields = []
    for f in order:
        entries = [_entry(r, f) for r in reports if f in r.keys]
        unit = units.get(f, "")
        fields.append(compare_field(f, entries, sigma, unit, _undetermined_why(entries, by_name, f)))
    seen: list[tuple[str, str]] = []
    for r in reports:
        seen += [e for e in dict.fromkeys(r.effects) if e not in seen]
    some = tuple(EffectPresence(e, w, tuple(r.name for r in reports if (e, w) in r.effects),
                                tuple(r.name for r in reports if (e, w) not in r.effects))
                 for e, w in seen if not all((e, w) in r.effects for r in reports))
    common = tuple(e for e in seen if all(e in r.effects for r in reports))
    return Consistency(tuple(reports), sigma, tuple(fields), some, common, tuple(_notes(reports)))


def _notes(reports: Sequence[IdentifyReport]) -> list[str]:
    notes = []
    for r in reports:
        if r.structured:
            over = ", ".join(f"{o} {x:.3g}×" if math.isfinite(x) else f"{o} unbounded" for o, x in r.structured.items())
            notes.append(f"{r.name}: final rms above {STRUCTURE_FACTOR:g}× its noise floor ({over}): its parameters "
                         "are the equivalents of a model that leaves structure in the residual, so disagreement with "
                         "another maneuver is expected and says the model lacks structure, not that the actuator "
                         "changed")
    return notes


def _value(e: Entry) -> str:
    v = f"{e.value:.4g}" if math.isfinite(e.value) else "—"
    s = f"{e.sigma:.2g}" if math.isfinite(e.sigma) else "?"
    return f"{v} ± {s}" + ("" if e.determined or not math.isfinite(e.sigma) else " (nd)")


def format_table(result: Consistency) -> str:
    """The comparison for the terminal: a Markdown table, then verdicts, effects and notes in words.

    Parameters
    ----------
    result : Consistency
        What :func:`compare` found.

    Returns
    -------
    str
        Lines of text.
    """
    names = [r.name for r in result.reports]
    lines = [f"{len(names)} reports, channel {result.reports[0].channel}; limit {result.sigma:g}σ"]
    lines += [f"  {r.name}: {r.model} ({r.data})" for r in result.reports]
    lines += ["", "| field | unit | " + " | ".join(names) + " | weighted mean | χ² p | max z | verdict |",
              "| --- | --- |" + " --- |" * len(names) + " --- | --- | --- | --- |"]
    for f in result.fields:
        by = {e.report: e for e in f.entries}
        cells = [_value(by[n]) if n in by else "" for n in names]
        mean = f"{f.mean:.4g} ± {f.mean_sigma:.2g}" if math.isfinite(f.mean) else ""
        p = f"{f.p_value:.2g}" if math.isfinite(f.p_value) else ""
        z = f"{f.worst.z:.1f}" if f.worst is not None else ""
        lines.append(f"| {f.field} | {f.unit} | " + " | ".join(cells) + f" | {mean} | {p} | {z} | {f.verdict} |")
    counts = result.counts()
    lines += ["", "verdicts: " + ", ".join(f"{counts[v]} {v}" for v in VERDICTS)]
    lines += [f"{f.verdict}: {f.field}: {f.reason}" for f in result.fields if f.verdict in ("disagree", "undetermined")]
    for e in result.effects:
        lines.append(f"effect {e.effect} ({e.where}) added in {', '.join(e.added_in)}, not in {', '.join(e.not_in)}")
    lines += [f"note: {n}" for n in result.notes]
    return "\n".join(lines)


__all__ = ["STRUCTURE_FACTOR", "VERDICTS", "Consistency", "EffectPresence", "Entry", "FieldConsistency",
           "IdentifyReport", "Pair", "compare", "compare_field", "format_table", "parse_report", "read_report",
           "read_reports"]
