"""The ``ema identify --json`` report as a typed contract: the TypedDicts its JSON Schema is generated from.

Per-output figures are maps from an output column (``position_deg``, ``surface_deg``, or a rig's own name) to a
number: ``null`` where it is not a number, ``"unbounded"`` (or ``"unbounded below"``) where it is infinite, as an
uncertainty the record cannot bound is. Blocks other modules own and describe (the command's timing, the
slope, the discovery and the diagnosis, the excitation's stages) are open objects here; the keys this module
names are closed: a key added to the report is added here first, or the suite's schema check fails.
:func:`identify_schema` is the schema published as ``docs/schema/identify.schema.json``.
"""

from __future__ import annotations

from functools import cache
from typing import Literal, NotRequired, TypedDict

from ema_sim.io.contract import schema_of

__all__ = ["IdentifyReport", "identify_schema"]

Num = float | Literal["unbounded", "unbounded below"] | None
PerOutput = dict[str, Num]
Params = dict[str, Num]


class Whiteness(TypedDict):
    """A residual's whiteness (Ljung-Box over ``lags``)."""

    lags: int
    q_statistic: Num
    p_value: Num
    fraction_outside_95: Num
    white: bool


class Independence(TypedDict):
    """A residual's cross-correlation with an input, against the 99 % bound over every lag."""

    max_lag: int
    peak_correlation: Num
    peak_lag: int
    bound_99_all_lags: Num
    independent: bool


class Start(TypedDict):
    """Where the fit started, when it did not start at the declared model."""

    params: Params
    rms_deg: PerOutput


class Baseline(TypedDict):
    """The declared model fitted as it is, and its errors."""

    model: str
    params: Params
    rms_deg: PerOutput
    max_abs_deg: PerOutput
    nrmse: PerOutput
    rms_over_noise: PerOutput
    whiteness: dict[str, Whiteness]
    independence: dict[str, dict[str, Independence]]
    start: Start | None


class Reference(TypedDict):
    """Output = command: the error every model must beat."""

    model: str
    rms_deg: PerOutput
    max_abs_deg: PerOutput


class Declared(TypedDict):
    """The declared model with its own elements fitted, before any effect is added."""

    model: str
    rms_deg: PerOutput
    equivalent: Params
    fitted: list[str]
    held_fixed: list[str]
    not_determinable: list[str]


class Added(TypedDict):
    """One effect the search added: its parameters, what it removed, why."""

    effect: str
    params: Params
    uncertainty: Params
    rms_deg_before: PerOutput
    rms_deg_after: PerOutput
    evidence: str
    where: str
    replaces: NotRequired[list[str]]


class Removed(TypedDict):
    """An effect taken out again, and why."""

    effect: str
    where: str
    params: Params
    reason: str


class Rejected(TypedDict):
    """A candidate effect that did not pay for itself."""

    effect: str
    where: str
    value: Num
    reason: str


class Final(TypedDict):
    """The final model: every parameter with its uncertainty, correlations and errors."""

    model: str
    params: Params
    fields: dict[str, str]
    uncertainty: Params
    relative_uncertainty: NotRequired[Params]
    correlation: dict[str, Params]
    not_determined: list[str]
    not_determined_reason: NotRequired[dict[str, str]]
    lower_bound: NotRequired[dict[str, str]]
    """Parameters the record shows only as "at least" their figure (a dead band held at its holds' bound), and why."""
    grid_searched: list[str]
    hinge_moment_reversed: bool
    curves: NotRequired[dict[str, list[Num]]]
    declared: NotRequired[dict[str, object]]
    simulations: NotRequired[int]
    rms_deg: PerOutput
    max_abs_deg: PerOutput
    nrmse: PerOutput
    rms_over_noise: PerOutput
    whiteness: dict[str, Whiteness]
    independence: dict[str, dict[str, Independence]]


class Equivalent(TypedDict):
    """The declared fidelity's equivalent of a final model it cannot hold (after an escalation)."""

    model: str
    params: Params
    rms_deg: PerOutput
    rms_over_noise: PerOutput
    escalated_because: str | None


class Failure(TypedDict):
    """A stage that failed: the report says what it would have said is missing."""

    stage: str
    error: str
    where: str


class Travel(TypedDict):
    """The travel limits declared and used, and where they came from."""

    declared: list[Num]
    used: list[Num]
    source: str
    statement: str


class Excitation(TypedDict):
    """What the record excites: its span, level changes and frequency content."""

    duration_s: Num
    level_changes: int
    span_deg: Num
    content_hz: Num


class DiscoveredTerm(TypedDict):
    """A discovered term the final model carries: where it acts, its coefficients and their one-sigma."""

    term: str
    on: str
    placement: str
    coefficient: list[Num]
    uncertainty: list[Num]
    unit: str


class IdentifyReport(TypedDict):
    """``ema identify``'s report: the record, the declared model, what was added and why, and the final model."""

    data: str
    outputs: list[str]
    unit: str
    noise_deg: PerOutput
    resolution_deg: PerOutput
    reference: Reference
    baseline: Baseline
    declared: NotRequired[Declared]
    added: list[Added]
    removed: list[Removed]
    final: Final
    equivalent: NotRequired[Equivalent]
    slew_dps: dict[str, object] | None
    stages: list[dict[str, object]]
    failures: list[Failure]
    discovered: dict[str, object] | None
    discovered_terms: list[DiscoveredTerm]
    changes: dict[str, object] | None
    stamps: dict[str, object] | None
    artefacts: list[dict[str, object]]
    ambiguities: list[str]
    warnings: list[str]
    diagnosis: dict[str, object] | None
    notes: list[str]
    command: dict[str, object]
    travel_deg: Travel | None
    excitation: Excitation | None
    rejected: list[Rejected]
    channel: str
    samples: int
    sample_hz: Num
    simulator_error_deg: PerOutput
    simulations: int
    simulations_reused: int
    elapsed_s: Num
    declared_implementation_error_deg: NotRequired[PerOutput]


@cache
def identify_schema() -> dict[str, object]:
    """The JSON Schema of :class:`IdentifyReport` (published as ``docs/schema/identify.schema.json``)."""
    return schema_of(IdentifyReport, "ema identify report")
