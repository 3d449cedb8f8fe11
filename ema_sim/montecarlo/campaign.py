"""A campaign: the model and channel, the experiments every run performs, the dispersions and the metrics.

Campaigns are YAML files (or the built-in ones of :mod:`.builtin`, written the same way)::

    campaign: loada-steps              # name
    description: what it shows
    model: loada                       # registry name (ema models)
    channel: left_wing
    options: {rate_hz: 800}            # model keywords: rate_hz, bound, noise, hysteresis
    set: {quantization_deg: 0.0}       # fixed parameter values (the model's own names)
    experiments:
      step:     {maneuver: "step:amp_deg=1", load: "const:inlb=0", duration_s: 3, sample_hz: 1000}
      response: {multisine: "schroeder:f0_hz=0.1,f1_hz=20,amp_deg=0.5,period_s=10", frame_hz: 1000}
      dwells:   {dwell: {min_hz: 0.5, max_hz: 20, points: 24}, amp_deg: 1, load_inlb: 0}
    dispersions:
      - {parameter: wn_rad_s, uniform: [45, 75]}        # or uniform: report | analysis
      - {parameters: [kb, offset_deg], corners: [[-0.0032, 0.0032], [-0.018, 0.018]]}
      - {parameter: step.load.inlb, normal: {mean: 0, std: 100}}
    metrics: [step, error, {metric: gain_phase, experiment: response, at_hz: [1, 5, 10]}]
    batch: 500                         # runs per task (default: the model's)

An aircraft-in-the-loop campaign (``kind: ail``) runs :func:`ema_sim.ail.loop.run_ail` for every run
(``profile``, ``model``, ``duration_s``) and disperses the test environment (``command.delay_s``,
``environment.lag_hz``: both paths...), the wing bungee (``setup.bungee_inlb``) and the model's
parameters; its metric is ``dither``.

Experiments: ``record`` (a maneuver and a load; the outputs sampled at ``sample_hz``), ``multisine`` (a
``schroeder`` maneuver whose last period is read at its harmonics: a frequency response) and ``dwell``
(one sine dwell per frequency, all in one batch run: :func:`ema_sim.analysis.section2.sine_dwell.sine_dwell`).
Dispersible names: the model's parameters, ``bound`` (HOAD3), and per experiment
``<experiment>.maneuver.<field>``, ``<experiment>.load.<field>`` and a dwell's ``<experiment>.load_inlb``.
Anything unknown or malformed is one :class:`~ema_sim.errors.ConfigError` line.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, fields
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from ema_sim.ail.params import load_ail_config
from ema_sim.config import CHANNELS
from ema_sim.environment import PathSpec, load_profile
from ema_sim.errors import ConfigError, EmaError, UnknownNameError
from ema_sim.jsontypes import JsonObject, JsonValue
from ema_sim.models import model_class, model_names, model_parameters
from ema_sim.montecarlo.dispersions import Dispersion, Target, parse_dispersion
from ema_sim.montecarlo.metrics import MetricSpec, parse_metric
from ema_sim.parameters import metas
from ema_sim.signals import parse_load, parse_maneuver
from ema_sim.signals.maneuvers import Schroeder
from ema_sim.signals.spec import Spec

KINDS = ("model", "ail")
EXPERIMENT_KINDS = ("record", "multisine", "dwell")
OPTIONS = ("rate_hz", "bound", "noise", "hysteresis")
"""Model keywords a campaign may fix (``seed`` is every run's own)."""
OUTPUTS = ("position_deg", "surface_deg")
BOUND = Target("bound", "-", -1.0, 1.0, 0.0, None,
               "HOAD3's compliance bound (figure 35): −1 lower (stiffest), 0 mean, +1 upper (most compliant)")
ENVIRONMENT_BOTH = ("lag_hz", "quantization_v", "noise_rms_v")
"""Test-environment elements an AIL campaign disperses on both paths at once (the same FMU software, converter
cards and harness: one value, fully correlated)."""
DEFAULT_BATCH = {"hoad2": 8, "hoad3": 8, "hoac1": 1, "loac": 20, "second_order": 100}
"""Runs per task when the campaign does not say (a task of about a second of work); others: 1,000."""


@dataclass(frozen=True)
class Experiment:
    """What every run does once: a record, a multisine response or sine dwells.

    Parameters
    ----------
    name : str
        Its name in the campaign.
    kind : str
        ``record``, ``multisine`` or ``dwell``.
    maneuver : str
        The maneuver spec (record, multisine).
    load : str
        The load spec (record, multisine).
    duration_s : float or None
        Record length (default: the maneuver's).
    frame_hz : float
        The input grid (the FMU frame, 200 Hz by default).
    sample_hz : float
        Output samples (record; a multisine is read at its frames).
    output : str
        ``position_deg`` (LVDT) or ``surface_deg``.
    freq_hz : tuple of float
        Dwell frequencies.
    amp_deg : float
        Dwell amplitude.
    load_inlb : float
        Dwell hinge moment.
    """

    name: str
    kind: str
    maneuver: str = ""
    load: str = "none"
    duration_s: float | None = None
    frame_hz: float = 200.0
    sample_hz: float = 1000.0
    output: str = "position_deg"
    freq_hz: tuple[float, ...] = ()
    amp_deg: float = 1.0
    load_inlb: float = 0.0

    @property
    def gives(self) -> str:
        """What its metrics read: ``record`` or ``response``."""
        return "record" if self.kind == "record" else "response"

    def as_dict(self) -> JsonObject:
        """Plain values (the YAML form)."""
        if self.kind == "dwell":
            return {"dwell": [*self.freq_hz], "amp_deg": self.amp_deg, "load_inlb": self.load_inlb,
                    "output": self.output}
        out: JsonObject = {self.kind if self.kind == "multisine" else "maneuver": self.maneuver,
                           "load": self.load, "frame_hz": self.frame_hz, "output": self.output}
        if self.kind == "record":
            out["sample_hz"] = self.sample_hz
        if self.duration_s is not None:
            out["duration_s"] = self.duration_s
        return out


@dataclass(frozen=True)
class Campaign:
    """A whole campaign (see the module docstring); built by :func:`parse_campaign`.

    Parameters
    ----------
    name : str
        Its name.
    description : str
        What it shows.
    kind : str
        ``model`` or ``ail``.
    model : str
        Registry name.
    channel : str
        The channel (model campaigns).
    options : dict
        Fixed model keywords.
    fixed : dict
        Fixed parameter values (``set``).
    experiments : tuple of Experiment
        What every run does.
    dispersions : tuple of Dispersion
        What varies, resolved against the metadata.
    metrics : tuple of MetricSpec
        What every run measures.
    batch : int
        Runs per task.
    profile : str
        The test environment (AIL campaigns).
    duration_s : float
        Run length (AIL campaigns).
    raw : dict
        The mapping it was parsed from, with every ``report``/``analysis`` bound resolved into numbers.
    """

    name: str
    description: str
    kind: str
    model: str
    channel: str
    options: Mapping[str, JsonValue]
    fixed: Mapping[str, float]
    experiments: tuple[Experiment, ...]
    dispersions: tuple[Dispersion, ...]
    metrics: tuple[MetricSpec, ...]
    batch: int
    profile: str = "ail"
    duration_s: float = 24.0
    raw: Mapping[str, JsonValue] = field(default_factory=dict)

    @cached_property
    def parameters(self) -> tuple[str, ...]:
        """The dispersed parameters, in order."""
        return tuple(n for d in self.dispersions for n in d.names)

    def experiment(self, name: str) -> Experiment:
        """An experiment by name.

        Parameters
        ----------
        name : str
            Its name.

        Returns
        -------
        Experiment
            The experiment.
        """
        for e in self.experiments:
            if e.name == name:
                return e
        raise UnknownNameError("experiment", name, [e.name for e in self.experiments])

    def to_json(self) -> str:
        """The campaign as canonical JSON (what tasks rebuild it from, what ``--resume`` compares)."""
        return json.dumps(self.raw, sort_keys=True)


# ----------------------------------------------------------------------------------------------- targets
def _spec_targets(prefix: str, spec: Spec) -> dict[str, Target]:
    """The numeric fields of a maneuver or load spec, with the spec's declared bounds."""
    out = {}
    for f in fields(spec):
        value = getattr(spec, f.name)
        if isinstance(value, bool) or not isinstance(value, int | float):
            continue
        low, high = f.metadata.get("low"), f.metadata.get("high")
        lo = -math.inf if low is None else float(low)
        hi = math.inf if high is None else float(high)
        out[f"{prefix}.{f.name}"] = Target(f"{prefix}.{f.name}", "", lo, hi, float(value), None,
                                           f"{spec.family} {spec.kind!r} field {f.name}")
    return out


def model_targets(model: str, channel: str, fixed: Mapping[str, float]) -> dict[str, Target]:
    """Every model parameter a campaign may disperse, from :func:`ema_sim.models.model_parameters`.

    Parameters
    ----------
    model : str
        Registry name.
    channel : str
        The channel whose values are the nominal ones.
    fixed : mapping
        The campaign's fixed values (they are the nominal ones where given).

    Returns
    -------
    dict
        Name → :class:`Target` (numbers only; curves are dispersed through ``bound``).
    """
    out = {}
    for p in model_parameters(model, channel):
        if p.size != 1 or not isinstance(p.default, int | float):
            continue
        low = p.min if p.off is None else min(p.min, p.off)
        high = p.max if p.off is None else max(p.max, p.off)
        nominal = float(fixed.get(p.name, p.default))
        where = f"{model} parameter {p.path} ({p.description})"
        if p.uncertainty_source:
            where += f"; uncertainty: {p.uncertainty_source}"
        out[p.name] = Target(p.name, p.unit, low, high, nominal, p.uncertainty, where)
    if getattr(model_class(model), "figure33", False):
        out["bound"] = BOUND
    return out


def ail_targets(profile: str) -> dict[str, Target]:
    """The test-environment elements and the bungee an AIL campaign may disperse.

    Parameters
    ----------
    profile : str
        The test environment whose values are the nominal ones.

    Returns
    -------
    dict
        ``command.<field>``, ``feedback.<field>``, ``environment.<field>`` (both paths) and
        ``setup.bungee_inlb``.
    """
    prof = load_profile(profile)
    out: dict[str, Target] = {}
    for name, m in metas(PathSpec).items():
        for path in ("command", "feedback"):
            value = float(getattr(getattr(prof, path), name))
            out[f"{path}.{name}"] = Target(f"{path}.{name}", m.unit, m.min, m.max, value, m.uncertainty,
                                           f"test environment {path} path: {m.description}")
        if name in ENVIRONMENT_BOTH:
            value = float(getattr(prof.command, name))
            out[f"environment.{name}"] = Target(f"environment.{name}", m.unit, m.min, m.max, value, m.uncertainty,
                                                f"test environment, both paths: {m.description}")
    bungee = load_ail_config().setup(profile).bungee_inlb
    out["setup.bungee_inlb"] = Target("setup.bungee_inlb", "in·lb", -1e4, 1e4, bungee, None,
                                      "the wings' bungee load on the ground (section 4.3: 50-100 in·lb)")
    return out


# ----------------------------------------------------------------------------------------------- parsing
# The parsers below take a campaign file's values as YAML gave them, each checked
# where it is read (a wrong one is one ConfigError naming its place).
def _number(values: Mapping[str, Any], key: str, where: str, default: float | None = None,
            positive: bool = True) -> float:
    if key not in values:
        if default is None:
            raise ConfigError(f"{where}: missing {key}")
        return default
    try:
        v = float(values[key])
    except (TypeError, ValueError):
        raise ConfigError(f"{where}: {key} must be a number, got {values[key]!r}") from None
    if not math.isfinite(v) or (positive and v <= 0.0):
        raise ConfigError(f"{where}: {key} must be a {'positive' if positive else 'finite'} number, got {v:g}")
    return v


def _frequencies(value: object, where: str) -> tuple[float, ...]:
    if isinstance(value, Mapping):
        lo = _number(value, "min_hz", where)
        hi = _number(value, "max_hz", where)
        points = int(_number(value, "points", where))
        if hi <= lo or points < 2:
            raise ConfigError(f"{where}: dwell needs min_hz < max_hz and at least 2 points")
        return tuple(float(f) for f in np.geomspace(lo, hi, points))
    freqs = np.atleast_1d(np.asarray(value, dtype=float))
    if freqs.size == 0 or not np.all(np.isfinite(freqs) & (freqs > 0)) or np.any(np.diff(freqs) <= 0):
        raise ConfigError(f"{where}: dwell frequencies must be positive and ascending")
    return tuple(float(f) for f in freqs)


def parse_experiment(name: str, values: object, where: str) -> Experiment:
    """One ``experiments`` entry.

    Parameters
    ----------
    name : str
        Its name.
    values : mapping
        ``{maneuver: SPEC | multisine: SPEC | dwell: FREQUENCIES, ...}``.
    where : str
        Its place, for messages.

    Returns
    -------
    Experiment
        The checked experiment.
    """
    if not isinstance(values, Mapping):
        raise ConfigError(f"{where}: expected a mapping, got {values!r}")
    keys = set(values)
    kinds = [k for k in ("maneuver", "multisine", "dwell") if k in keys]
    if len(kinds) != 1:
        raise ConfigError(f"{where}: give exactly one of maneuver, multisine, dwell")
    kind = {"maneuver": "record", "multisine": "multisine", "dwell": "dwell"}[kinds[0]]
    allowed = {"dwell": {"dwell", "amp_deg", "load_inlb", "output"},
               "record": {"maneuver", "load", "duration_s", "frame_hz", "sample_hz", "output"},
               "multisine": {"multisine", "load", "frame_hz", "output"}}[kind]
    unknown = sorted(keys - allowed)
    if unknown:
        raise ConfigError(f"{where}: unknown key {unknown[0]!r} for a {kind} experiment "
                          f"(known: {', '.join(sorted(allowed))})")
    output = str(values.get("output", "position_deg"))
    if output not in OUTPUTS:
        raise UnknownNameError("output", output, OUTPUTS)
    if kind == "dwell":
        return Experiment(name, kind, freq_hz=_frequencies(values["dwell"], where),
                          amp_deg=_number(values, "amp_deg", where, 1.0),
                          load_inlb=_number(values, "load_inlb", where, 0.0, positive=False), output=output)
    man = parse_maneuver(str(values[kinds[0]]))
    load = parse_load(str(values.get("load", "none")))
    if kind == "multisine" and not isinstance(man, Schroeder):
        raise ConfigError(f"{where}: multisine needs a schroeder maneuver, got {man.kind!r}")
    duration = _number(values, "duration_s", where, man.duration_s) if kind == "record" else None
    return Experiment(name, kind, maneuver=man.spec(), load=load.spec(),
                      duration_s=duration if "duration_s" in values else None,
                      frame_hz=_number(values, "frame_hz", where, 200.0),
                      sample_hz=_number(values, "sample_hz", where, 1000.0), output=output)


def experiment_targets(exp: Experiment) -> dict[str, Target]:
    """The dispersible fields of one experiment: its maneuver's and load's numbers, or a dwell's load.

    Parameters
    ----------
    exp : Experiment
        The experiment.

    Returns
    -------
    dict
        Name (``<experiment>.maneuver.<field>``...) → :class:`Target`.
    """
    if exp.kind == "dwell":
        return {f"{exp.name}.load_inlb": Target(f"{exp.name}.load_inlb", "in·lb", -1e5, 1e5, exp.load_inlb, None,
                                                "hinge moment the dwells run under")}
    return {**_spec_targets(f"{exp.name}.maneuver", parse_maneuver(exp.maneuver)),
            **_spec_targets(f"{exp.name}.load", parse_load(exp.load))}


CAMPAIGN_KEYS = ("campaign", "description", "kind", "model", "channel", "options", "set", "experiments",
                 "dispersions", "metrics", "batch", "profile", "duration_s")
"""The keys of a campaign YAML."""


def _head(values: object, origin: str) -> tuple[str, str, str, dict[str, JsonValue], dict[str, float]]:
    """Kind, model, channel, options and fixed values of a campaign mapping, checked."""
    if not isinstance(values, Mapping):
        raise ConfigError(f"{origin}: a campaign is a YAML mapping")
    unknown = sorted(set(values) - set(CAMPAIGN_KEYS))
    if unknown:
        raise ConfigError(f"{origin}: unknown key {unknown[0]!r} (known: {', '.join(CAMPAIGN_KEYS)})")
    kind = str(values.get("kind", "model"))
    if kind not in KINDS:
        raise UnknownNameError("campaign kind", kind, KINDS)
    model = str(values.get("model", "hoad3" if kind == "ail" else ""))
    if model not in model_names():
        raise UnknownNameError("model", model, model_names())
    channel = str(values.get("channel", "left_wing"))
    if channel not in CHANNELS:
        raise UnknownNameError("channel", channel, CHANNELS)
    options = dict(values.get("options") or {})
    for key in options:
        if key not in OPTIONS:
            raise UnknownNameError("model option", key, OPTIONS)
    try:
        fixed = {str(k): float(v) for k, v in dict(values.get("set") or {}).items()}
    except (TypeError, ValueError):
        raise ConfigError(f"{origin}: set: every value must be a number") from None
    return kind, model, channel, options, fixed


def _dispersions(raw: object, targets: Mapping[str, Target], fixed: Mapping[str, float], origin: str,
                 analysis: Mapping[str, tuple[float, float]] | None) -> tuple[Dispersion, ...]:
    """The ``dispersions`` list, each parameter dispersed once and never also set."""
    if not isinstance(raw, Sequence) or isinstance(raw, str):
        raise ConfigError(f"{origin}: dispersions must be a list")
    out = tuple(parse_dispersion(d, targets, f"{origin}: dispersions[{i}]", analysis) for i, d in enumerate(raw))
    seen: set[str] = set()
    for d in out:
        for n in d.names:
            if n in seen or n in fixed:
                raise ConfigError(f"{origin}: {n} is dispersed twice (or also set)")
            seen.add(n)
    return out


def parse_campaign(values: Mapping[str, Any], origin: str = "<campaign>",
                   analysis: Mapping[str, tuple[float, float]] | None = None) -> Campaign:
    """A campaign from its YAML mapping (see the module docstring), checked against the metadata.

    Parameters
    ----------
    values : mapping
        The YAML document.
    origin : str
        Where it comes from, for messages.
    analysis : mapping, optional
        Parameter → (low, high) from ``ema analyze`` JSON (for ``uniform: analysis``).

    Returns
    -------
    Campaign
        The campaign.
    """
    kind, model, channel, options, fixed = _head(values, origin)
    targets = model_targets(model, channel, fixed)
    for key, value in fixed.items():
        if key not in targets:
            raise UnknownNameError(f"{model} parameter", key, targets)
        targets[key].check(np.array([value]), f"{origin}: set")
    experiments: list[Experiment] = []
    profile, duration = "ail", 24.0
    if kind == "ail":
        profile = str(values.get("profile", "ail"))
        duration = _number(values, "duration_s", origin, 24.0)
        targets.update(ail_targets(profile))
        kinds = {"ail": "ail"}
    else:
        raw_exps = values.get("experiments")
        if not isinstance(raw_exps, Mapping) or not raw_exps:
            raise ConfigError(f"{origin}: experiments: give at least one (name: {{maneuver | multisine | dwell ...}})")
        for name, ev in raw_exps.items():
            exp = parse_experiment(str(name), ev, f"{origin}: experiments.{name}")
            experiments.append(exp)
            targets.update(experiment_targets(exp))
        kinds = {e.name: e.gives for e in experiments}
    raw_disp = values.get("dispersions") or []
    dispersions = _dispersions(raw_disp, targets, fixed, origin, analysis)
    metrics = tuple(parse_metric(m, kinds, f"{origin}: metrics[{i}]")
                    for i, m in enumerate(values.get("metrics") or []))
    if not metrics:
        raise ConfigError(f"{origin}: metrics: give at least one")
    if len({(m.name, m.experiment) for m in metrics}) != len(metrics):
        raise ConfigError(f"{origin}: a metric is listed twice for one experiment")
    batch = int(_number(values, "batch", origin, float(DEFAULT_BATCH.get(model, 1000))))
    resolved = dict(values)
    resolved["dispersions"] = [_resolved(d, raw) for d, raw in zip(dispersions, raw_disp, strict=True)]
    resolved.update(kind=kind, model=model, channel=channel, batch=batch)
    return Campaign(str(values.get("campaign", Path(origin).stem)), str(values.get("description", "")), kind, model,
                    channel, options, fixed, tuple(experiments), dispersions, metrics, batch, profile, duration,
                    resolved)


def _resolved(d: Dispersion, raw: Mapping[str, JsonValue]) -> JsonObject:
    """A dispersion entry with ``report``/``analysis`` bounds replaced by the numbers they stood for."""
    out = dict(raw)
    if d.kind in ("uniform", "corners") and isinstance(raw.get(d.kind), str):
        out[d.kind] = [[float(a), float(b)] for a, b in zip(d.low, d.high, strict=True)]
    return out


def read_campaign(path: str | Path, analysis: Mapping[str, tuple[float, float]] | None = None) -> Campaign:
    """A campaign YAML file.

    Parameters
    ----------
    path : str or pathlib.Path
        The file.
    analysis : mapping, optional
        Parameter → (low, high) from ``ema analyze`` JSON.

    Returns
    -------
    Campaign
        The campaign.
    """
    p = Path(path)
    try:
        doc = yaml.safe_load(p.read_text(encoding="utf-8"))
    except OSError as exc:
        raise ConfigError(f"{p}: cannot read ({exc.strerror})") from None
    except yaml.YAMLError as exc:
        line = getattr(getattr(exc, "problem_mark", None), "line", None)
        raise ConfigError(f"{p}: not valid YAML{'' if line is None else f' (line {line + 1})'}") from None
    return parse_campaign(doc, str(p), analysis)


def analysis_spread(paths: Sequence[str | Path]) -> dict[str, tuple[float, float]]:
    """Dispersion bounds from ``ema analyze`` JSON files: figure 23's spread and the four-corner magnitudes.

    ``wn_rad_s``, ``zeta`` and ``delay_s`` range over the determined second-order fits of every file
    (``second_order_spread``, position output first); ``kb`` and ``offset_deg`` over ±the largest
    |Kb| and |offset| of the pooled calibrations (``command_error_bounds``, section 3.1.2.2).

    Parameters
    ----------
    paths : sequence of path
        ``ema analyze --json`` outputs.

    Returns
    -------
    dict
        Parameter → (low, high).
    """
    lows: dict[str, float] = {}
    highs: dict[str, float] = {}
    for path in paths:
        try:
            doc = json.loads(Path(path).read_text(encoding="utf-8"))
        except (OSError, ValueError) as exc:
            raise EmaError(f"{path}: not an ema analyze JSON file ({exc})") from None
        if not isinstance(doc, dict) or doc.get("tool") != "ema analyze":
            raise EmaError(f"{path}: not an ema analyze JSON file")
        spread = doc.get("second_order_spread") or {}
        for output in sorted(spread, key=lambda o: o != "position_deg"):
            for key in ("wn_rad_s", "zeta", "delay_s"):
                stats = spread[output].get(key)
                if stats:
                    lows[key] = min(lows.get(key, math.inf), float(stats["min"]))
                    highs[key] = max(highs.get(key, -math.inf), float(stats["max"]))
            break
        bounds = doc.get("command_error_bounds")
        if bounds:
            for key, field_ in (("kb", "kb_max_abs"), ("offset_deg", "offset_max_abs_deg")):
                mag = abs(float(bounds[field_]))
                lows[key] = min(lows.get(key, math.inf), -mag)
                highs[key] = max(highs.get(key, -math.inf), mag)
    return {k: (lows[k], highs[k]) for k in lows}


def nominal_values(c: Campaign) -> dict[str, float]:
    """Every dispersed parameter's nominal value (the campaign's fixed value, or the declared default).

    Parameters
    ----------
    c : Campaign
        The campaign.

    Returns
    -------
    dict
        Parameter → nominal value.
    """
    return {t.name: t.nominal for d in c.dispersions for t in d.targets}
