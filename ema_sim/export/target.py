"""What an export carries: the model, its parameter values, its rate and method, and where they come from.

An :class:`ExportTarget` is resolved from a registry model (``loada``, ``loadf``; ``loac`` and
``second_order`` discretised as LOADA; the linear ``loes``, ``hoalm`` and ``sloac`` as their own
zero-order-hold state space, :mod:`ema_sim.export.lti`; the high-order ``hoad2`` and ``hoad3`` as
their own 10 kHz kernel, :mod:`ema_sim.export.hoad_c`) or from an identification report (the JSON ``ema identify
--json`` writes): its final model's fitted parameters on the declared model's others. It names the
*truth*, the ema_sim model the artefact is verified against, and travels with the artefact as a
manifest (:meth:`ExportTarget.manifest`), so ``ema verify`` rebuilds the same truth from the artefact
alone. What cannot be exported is said in :data:`NOT_EXPORTABLE`.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from ema_sim import __version__
from ema_sim.config import GENERIC, STAND_IN, load_channel
from ema_sim.errors import EmaError
from ema_sim.export.csource import ModelValues
from ema_sim.jsontypes import JsonObject, JsonValue
from ema_sim.models import ActuatorModel, create
from ema_sim.models.arrays import FloatArray
from ema_sim.models.high_order.params import OPTIONS as HIGH_ORDER_OPTIONS
from ema_sim.models.high_order.params import HighOrderParams
from ema_sim.models.second_order.params import SecondOrderParams

DISCRETE: dict[str, tuple[float, bool]] = {"loada": (800.0, False), "loadf": (200.0, True)}
"""The exported kernels: registry name → (default rate, backward Euler)."""
CONTINUOUS = ("loac", "second_order")
"""Second-order models exported through LOADA's kernel at a fixed rate (their discretisation error is measured)."""
LINEAR = ("loes", "hoalm", "sloac")
"""Linear models exported as their own zero-order-hold state space and delay lines (:mod:`ema_sim.export.lti`)."""
LINEAR_NO_JSBSIM = ("a linear model has no JSBSim system: JSBSim has no discrete state-space component (its filters "
                    "are Tustin first and second orders, its integrators rectangular, trapezoidal or Adams-Bashforth, "
                    "none the zero-order hold), and a transcription into one summer and one-frame delay per state is "
                    "not written; export it as an FMU or C (exact)")
"""Why ``ema export --jsbsim`` refuses ``loes``, ``hoalm`` and ``sloac``."""
HIGH_ORDER = ("hoad2", "hoad3")
"""The high-order discrete models, exported as their own 10 kHz kernel (:mod:`ema_sim.export.hoad_c`)."""
HIGH_ORDER_FRAME_HZ = 1_000.0
"""The frame a high-order export is driven at by ``ema verify`` (10 of its 10 kHz steps; any whole number works)."""
HIGH_ORDER_DEFAULTS: dict[str, float] = {"bound": 0.0, "hysteresis": 0.0, "noise": 1.0, "seed": 0.0}
"""The high-order models' options (figure 35's compliance bound, figure 36's damping, the noise and its seed)."""
HIGH_ORDER_NO_JSBSIM = ("the high-order model has no JSBSim system: its motor, current loop, PWM, bus, friction and "
                        "three-segment gear train at 10 kHz have no JSBSim components; export it as an FMU or C "
                        "(exact)")
"""Why ``ema export --jsbsim`` refuses ``hoad2`` and ``hoad3``."""
NOT_EXPORTABLE: dict[str, str] = {
    "hoac1": "the continuous high-order model is integrated by an adaptive Dormand-Prince that locates every regime "
             "change (stick, slip, stops, backlash, PWM and limit corners) to a tolerance: its steps depend on the "
             "record and the tolerance, and a C port would match it only to that tolerance, not bit for bit; export "
             "hoad3 (its 10 kHz discretisation, exact in C; its error against hoac1 is in docs/export.md)",
}
"""Registry models ``ema export`` refuses, and why."""


class ExportError(EmaError):
    """A model or report that cannot be exported, or an artefact that cannot be read."""


@dataclass(frozen=True)
class ExportTarget:
    """One model to export: the kernel, its values, and the truth it is verified against.

    Parameters
    ----------
    model : str
        The exported kernel: ``loada``, ``loadf``, or a linear model (``loes``, ``hoalm``, ``sloac``).
    truth : str
        The registry model that is the truth (``loada``, ``loadf``, ``loac``, ``second_order``, a linear one).
    channel : str
        The channel.
    params : SecondOrderParams
        Every parameter's value (a linear model's: the channel's second-order values, unused).
    rate_hz : float
        The model's rate (its fixed step is ``1/rate_hz``).
    backward : bool
        LOADF's backward Euler with the look-ahead feedback.
    source : str
        Where the values come from (``registry``, or the report's path).
    notes : list of str
        What a user must know (a reversed hinge moment, a discretised continuous model).
    options : dict
        A linear model's parameter overrides (its truth is built with them; ``params`` is then unused), or a
        high-order model's options (bound, hysteresis, noise, seed).
    high_order_params : HighOrderParams, optional
        A high-order model's values (``params`` is then the channel's second-order values, unused).
    """

    model: str
    truth: str
    channel: str
    params: SecondOrderParams
    rate_hz: float
    backward: bool
    source: str = "registry"
    notes: list[str] = field(default_factory=list)
    options: dict[str, float] = field(default_factory=dict)
    high_order_params: HighOrderParams | None = None

    @property
    def linear(self) -> bool:
        """A linear model (its zero-order-hold state space), not figure 26's kernel."""
        return self.model in LINEAR

    @property
    def high_order(self) -> bool:
        """A high-order discrete model (figure 30's 10 kHz kernel), not figure 26's."""
        return self.high_order_params is not None

    @property
    def frame_hz(self) -> float:
        """The rate a host drives the export at, one input per frame: the model's own, a high-order model's 1 kHz."""
        if self.high_order and self.rate_hz > HIGH_ORDER_FRAME_HZ:
            return self.rate_hz / self.steps_per_frame
        return self.rate_hz

    @property
    def steps_per_frame(self) -> int:
        """The model's steps in one frame of :attr:`frame_hz`."""
        if self.high_order and self.rate_hz > HIGH_ORDER_FRAME_HZ:
            return max(round(self.rate_hz / HIGH_ORDER_FRAME_HZ), 1)
        return 1

    def kernel_vector(self) -> FloatArray:
        """The exported kernel's parameter vector (what the C model's defaults hold).

        Returns
        -------
        numpy.ndarray
            Figure 26's slots, or figure 30's for a high-order model (its options applied).
        """
        if self.high_order:
            p: FloatArray = self.truth_model()._P[0].copy()  # type: ignore[attr-defined]
            return p
        return self.params.kernel_vector()

    def with_values(self, **changes: float) -> ExportTarget:
        """The same target with some parameter values changed (a fault planted in the truth).

        Parameters
        ----------
        **changes : float
            Parameter name → value.

        Returns
        -------
        ExportTarget
            The copy.
        """
        if self.high_order_params is not None:
            return replace(self, high_order_params=self.high_order_params.replace(**changes))
        return replace(self, params=self.params.replace(**changes))

    def delay_params(self) -> dict[str, float]:
        """The truth's delays that are on (a host may have left one out).

        Returns
        -------
        dict
            Parameter name → delay (s).
        """
        names = ("command_delay_s", "feedback_delay_s") if self.high_order else ("delay_s", "feedback_delay_s")
        source: HighOrderParams | SecondOrderParams = (self.high_order_params if self.high_order_params is not None
                                                       else self.params)
        values = {n: float(getattr(source, n)) for n in names} if not self.linear else {}
        return {n: v for n, v in values.items() if v > 0.0}

    @property
    def description(self) -> str:
        """One line: the model, channel, rate and source."""
        if self.high_order:
            noise = "noise on (ema_sim's generator, seed " + f"{self.options.get('seed', 0.0):g})" if self.options.get(
                "noise", 1.0) else "noise off"
            return (f"X-43A EMA {self.model} ({self.channel}) at {self.rate_hz:g} Hz, NASA/TM-2008-214637 figures 30, "
                    f"{'33' if self.model == 'hoad3' else '32'}, section 4.2.5; {noise}; values from {self.source}; "
                    f"exported by ema_sim {__version__}")
        if self.linear:
            return (f"X-43A EMA {self.model} ({self.channel}) at {self.rate_hz:g} Hz, zero-order-hold state space "
                    f"with delay lines, NASA/TM-2008-214637 sections 3.4, 4.2.7; values from {self.source}; "
                    f"exported by ema_sim {__version__}")
        method = "backward Euler, feedback one frame ahead (LOADF)" if self.backward else "forward Euler (LOADA)"
        truth = "" if self.truth == self.model else f"; truth {self.truth}"
        return (f"X-43A EMA {self.model} ({self.channel}) at {self.rate_hz:g} Hz, {method}, NASA/TM-2008-214637 "
                f"figure 26; values from {self.source}{truth}; exported by ema_sim {__version__}")

    def values(self) -> ModelValues:
        """What the C sources hold.

        Returns
        -------
        ModelValues
            Name, description, parameters, rate, method.
        """
        return ModelValues(self.model, self.description, self.params, self.rate_hz, self.backward)

    def truth_model(self) -> ActuatorModel:
        """The ema_sim model the artefact is verified against, with the same values.

        Returns
        -------
        ActuatorModel
            One instance.
        """
        if self.truth in LINEAR:
            return create(self.truth, self.channel, rate_hz=self.rate_hz, **self.options)
        if self.high_order_params is not None:
            return create(self.truth, self.channel, params=self.high_order_params, rate_hz=self.rate_hz,
                          **self.options)
        if self.truth in CONTINUOUS:
            return create(self.truth, self.channel, params=self.params)
        return create(self.truth, self.channel, params=self.params, rate_hz=self.rate_hz)

    def manifest(self, artefact: str, extra: Mapping[str, JsonValue] | None = None) -> JsonObject:
        """The provenance an artefact carries (what ``ema verify`` reads back).

        Parameters
        ----------
        artefact : str
            ``fmu``, ``c`` or ``jsbsim``.
        extra : dict, optional
            More keys (the stages a JSBSim system leaves out...).

        Returns
        -------
        dict
            JSON-ready (infinite values as strings).
        """
        high: JsonObject = {}
        if self.high_order_params is not None:
            high = {"high_order_params": {k: [_json_float(x) for x in v] if isinstance(v, tuple) else _json_float(v)
                                          for k, v in self.high_order_params.as_dict().items()}}
        return {
            "artefact": artefact, "model": self.model, "truth": self.truth, "channel": self.channel,
            "rate_hz": self.rate_hz, "backward": self.backward, "source": self.source, "notes": [*self.notes],
            **high,
            "params": {k: _json_float(v) for k, v in self.params.as_dict().items()},
            "options": {k: _json_float(v) for k, v in self.options.items()},
            "ema_sim": __version__, **(extra or {}),
        }


def _json_float(x: float) -> float | str:
    return x if math.isfinite(x) else ("inf" if x > 0 else "-inf")


def _from_json_float(x: float | str) -> float:
    return float(x)


def from_manifest(doc: Mapping[str, Any]) -> ExportTarget:
    """The target an artefact's manifest describes.

    Parameters
    ----------
    doc : dict
        :meth:`ExportTarget.manifest`'s dict.

    Returns
    -------
    ExportTarget
        The same target.
    """
    try:
        params = SecondOrderParams(**{k: _from_json_float(v) for k, v in doc["params"].items()})
        params.validate()
        high = None
        if "high_order_params" in doc:
            values: dict[str, Any] = {k: tuple(_from_json_float(x) for x in v) if isinstance(v, list)
                                      else _from_json_float(v) for k, v in doc["high_order_params"].items()}
            high = HighOrderParams(**values)
            high.validate()
        return ExportTarget(model=str(doc["model"]), truth=str(doc["truth"]), channel=str(doc["channel"]),
                            params=params, rate_hz=float(doc["rate_hz"]), backward=bool(doc["backward"]),
                            source=str(doc.get("source", "registry")), notes=list(doc.get("notes", [])),
                            options={str(k): _from_json_float(v) for k, v in doc.get("options", {}).items()},
                            high_order_params=high)
    except (KeyError, TypeError, ValueError, EmaError) as exc:
        raise ExportError(f"the artefact's ema_sim manifest is incomplete or malformed ({exc})") from None


def resolve(spec: str, channel: str | None = None, *, rate_hz: float | None = None,
            overrides: dict[str, float] | None = None) -> ExportTarget:
    """The target of ``ema export MODEL_OR_REPORT``: a registry name, or the path of an identification report.

    Parameters
    ----------
    spec : str
        ``loada``, ``loadf``, ``loac``, ``second_order``, ``loes``, ``hoalm``, ``sloac``, or a ``.json`` report.
    channel : str, optional
        The channel (a report's own by default; ``left_wing`` for a registry model).
    rate_hz : float, optional
        The rate (the model's own by default; 800 Hz for a continuous model).
    overrides : dict, optional
        Parameter values that replace the model's.

    Returns
    -------
    ExportTarget
        The target.
    """
    path = Path(spec)
    if spec.lower().endswith(".json") or path.is_file():
        target = from_report(path, channel, rate_hz=rate_hz)
    else:
        target = from_registry(spec, channel or "left_wing", rate_hz=rate_hz)
    if overrides and target.linear:
        target = ExportTarget(target.model, target.truth, target.channel, target.params, target.rate_hz,
                              target.backward, target.source,
                              [*target.notes, "overrides: " + ", ".join(f"{k}={v:g}" for k, v in overrides.items())],
                              {**target.options, **overrides})
        try:
            target.truth_model()
        except (EmaError, TypeError) as exc:
            raise ExportError(f"{target.model}: {exc}") from None
    elif overrides and target.high_order_params is not None:
        options = {k: float(v) for k, v in overrides.items() if k in HIGH_ORDER_OPTIONS}
        values = {k: v for k, v in overrides.items() if k not in HIGH_ORDER_OPTIONS}
        unknown = set(values) - set(target.high_order_params.as_dict())
        if unknown:
            raise ExportError(f"unknown high-order parameter(s) or option(s): {', '.join(sorted(unknown))} (options: "
                              f"{', '.join(HIGH_ORDER_OPTIONS)})")
        try:
            high = target.high_order_params.replace(**values)
        except EmaError as exc:
            raise ExportError(f"{target.model}: {exc}") from None
        target = replace(target, high_order_params=high, options={**target.options, **options},
                         notes=[*target.notes, "overrides: " + ", ".join(f"{k}={v:g}" for k, v in overrides.items())])
        try:
            target.truth_model()
        except (EmaError, TypeError) as exc:
            raise ExportError(f"{target.model}: {exc}") from None
    elif overrides:
        unknown = set(overrides) - set(target.params.as_dict())
        if unknown:
            raise ExportError(f"unknown second-order parameter(s): {', '.join(sorted(unknown))}")
        target = ExportTarget(target.model, target.truth, target.channel, target.params.replace(**overrides),
                              target.rate_hz, target.backward, target.source,
                              [*target.notes, "overrides: " + ", ".join(f"{k}={v:g}" for k, v in overrides.items())])
    return target


def _kernel_for(truth: str, rate_hz: float | None) -> tuple[str, float, bool]:
    if truth in DISCRETE:
        rate, backward = DISCRETE[truth]
        return truth, rate if rate_hz is None else float(rate_hz), backward
    return "loada", 800.0 if rate_hz is None else float(rate_hz), False


def _check_model(name: str) -> None:
    if name in NOT_EXPORTABLE:
        raise ExportError(f"{name} is not exportable: {NOT_EXPORTABLE[name]}")
    if name not in (*DISCRETE, *CONTINUOUS, *LINEAR, *HIGH_ORDER):
        known = ", ".join((*DISCRETE, *CONTINUOUS, *LINEAR, *HIGH_ORDER))
        raise ExportError(f"unknown model {name!r}; exportable: {known} (or an `ema identify --json` report)")


def from_registry(name: str, channel: str, *, rate_hz: float | None = None) -> ExportTarget:
    """A registry model with its channel's values.

    Parameters
    ----------
    name : str
        Registry name.
    channel : str
        The channel.
    rate_hz : float, optional
        The rate (the model's own by default).

    Returns
    -------
    ExportTarget
        The target.
    """
    key = name.strip().lower()
    _check_model(key)
    if rate_hz is not None and not (math.isfinite(rate_hz) and rate_hz > 0.0):
        raise ExportError(f"the rate must be a positive number of Hz, got {rate_hz!r}")
    if key in LINEAR:
        model = create(key, channel, **({} if rate_hz is None else {"rate_hz": rate_hz}))
        return ExportTarget(key, key, model.channel.channel, SecondOrderParams.from_channel(model.channel),
                            model.rate_hz, False, "registry",
                            [f"{key} is linear: exported as its zero-order-hold state space at {model.rate_hz:g} Hz "
                             "with its delays as delay lines (the matrices computed by ema_sim, fixed)"])
    if key in HIGH_ORDER:
        model = create(key, channel, **({} if rate_hz is None else {"rate_hz": rate_hz}))
        high: HighOrderParams = model.params[0]  # type: ignore[attr-defined]
        return ExportTarget(key, key, model.channel.channel, SecondOrderParams.from_channel(model.channel),
                            model.rate_hz, False, "registry",
                            [f"{key} steps its own fixed {model.rate_hz:g} Hz kernel: a host's frame (an FMU's "
                             "communication step) must be a whole number of its steps",
                             "its noise is drawn from ema_sim's own generator (xorshift64* seeded by splitmix64, "
                             "ziggurat normals), so the export is the model bit for bit with the noise on; --set "
                             "noise=0 turns it off, --set seed=N picks the stream"],
                            dict(HIGH_ORDER_DEFAULTS), high)
    kernel, rate, backward = _kernel_for(key, rate_hz)
    model = create(key, channel)
    params = model.params[0]  # type: ignore[attr-defined]
    notes = []
    if key in CONTINUOUS:
        notes.append(f"{key} is continuous: exported as LOADA's forward Euler at {rate:g} Hz; `ema verify` measures "
                     f"that discretisation against {key}")
    return ExportTarget(kernel, key, model.channel.channel, params, rate, backward, "registry", notes)


def from_report(path: Path, channel: str | None = None, *, rate_hz: float | None = None) -> ExportTarget:
    """An identification report's final model: its fitted parameters on the declared model's others.

    Parameters
    ----------
    path : pathlib.Path
        The JSON ``ema identify --json`` wrote.
    channel : str, optional
        Must be the report's channel when given.
    rate_hz : float, optional
        The rate (the declared model's own; 800 Hz for a continuous one).

    Returns
    -------
    ExportTarget
        The target.
    """
    from ema_sim.identify.effects import KEYS  # noqa: PLC0415 - the identify package only for reports

    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
        final = doc["final"]
        declared = str(doc["baseline"]["model"])
        report_channel = str(doc["channel"])
        fitted = {str(k): float(v) for k, v in final["params"].items()}
        fields = {str(k): str(v) for k, v in final.get("fields", {}).items()}
    except FileNotFoundError:
        raise ExportError(f"{path}: no such report") from None
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise ExportError(f"{path}: not an `ema identify --json` report ({exc})") from None
    if channel is not None and channel != report_channel:
        raise ExportError(f"{path} identifies channel {report_channel}, not {channel}")
    name = str(final.get("model", declared))
    if "curves" in final or "physical" in name:
        raise ExportError(f"{path}: the final model {name!r} is the high-order model's physics fitted to a record; "
                          "its fitted curves are not carried into an export yet: export hoad3 from the registry with "
                          "--set NAME=VALUE")
    if "discovered" in name:
        raise ExportError(f"{path}: the final model {name!r} has a term discovery found beyond the vocabulary; it has "
                          "no stage in the exported C model")
    _check_model(declared)
    if declared in HIGH_ORDER:
        raise ExportError(f"{path}: the declared model {declared} is high-order; export it from the registry "
                          f"(`ema export {declared} --set NAME=VALUE`)")
    if declared in LINEAR:
        raise ExportError(f"{path}: the declared model {declared} is linear; export it from the registry "
                          f"(`ema export {declared} --set NAME=VALUE`)")
    # a generic actuator's fits started from the stand-in's nominal values: its parameters are read against them
    config = load_channel(STAND_IN if report_channel == GENERIC else report_channel)
    base: SecondOrderParams = create(declared, config).params[0]  # type: ignore[attr-defined]
    values: dict[str, float] = {}
    for reported, value in fitted.items():
        key = fields.get(reported, "hysteresis_freq_hz" if reported == "load_freq_hz" else reported)
        if key not in base.as_dict():
            raise ExportError(f"{path}: the final model's parameter {reported!r} is not a second-order parameter")
        factor = KEYS[key].factor(base) if key in KEYS and reported != key else 1.0
        values[key] = value / factor
    try:
        params = base.replace(**values)
    except EmaError as exc:
        raise ExportError(f"{path}: {exc}") from None
    kernel, rate, backward = _kernel_for(declared, rate_hz)
    notes = [f"identified: {name}"]
    if final.get("hinge_moment_reversed"):
        notes.append("the report found the record's hinge moment reversed: the export takes ema_sim's convention "
                     "(positive aids positive deflection); feed it the hinge moment with that sign")
    if declared in CONTINUOUS:
        notes.append(f"declared model {declared} is continuous: exported as LOADA's forward Euler at {rate:g} Hz; "
                     f"`ema verify` measures that discretisation against {declared}")
    return ExportTarget(kernel, declared, config.channel, params, rate, backward, str(path), notes)
