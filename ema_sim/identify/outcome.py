"""What an identification found: the fits, the effects added and removed, every verdict, every stage.

These are the results the stages of :func:`ema_sim.identify.identification.identify` fill in and the
report (:mod:`ema_sim.identify.report`) reads; they hold no logic beyond naming what they carry.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Protocol

import numpy as np

from ema_sim.identify.fit import Fit
from ema_sim.identify.physical import PhysicalFit
from ema_sim.identify.problem import Problem
from ema_sim.identify.record import Record
from ema_sim.identify.stages import Failure, Outcome
from ema_sim.jsontypes import JsonObject

if TYPE_CHECKING:
    from ema_sim.identify.discovery import Discovery

REFERENCE = "position = command"
"""The trivial model every report compares with (and falls back on)."""
AS_DECLARED = " (as declared)"
"""How a model name reads when the declared model, run as it is, is the final model (no parameters fitted)."""

class Changes(Protocol):
    """What the windowed refits found (:class:`ema_sim.identify.changes.Changes`), as the outcome holds it.

    A protocol, so this module, which the refits' own module imports, needs nothing from it.
    """

    @property
    def changed(self) -> bool:
        """Whether a parameter changes over the record beyond its uncertainty."""

    @property
    def warnings(self) -> list[str]:
        """What the report warns of."""

    def as_dict(self) -> JsonObject:
        """Plain values for JSON."""

@dataclass(frozen=True)
class Step:
    """One accepted effect and the error before and after it."""

    effect: str
    where: str
    params: dict[str, float]
    sigma: dict[str, float]
    rms_deg_before: dict[str, float]
    rms_deg_after: dict[str, float]
    evidence: str
    replaces: tuple[str, ...] = ()
    """Report keys of an earlier effect's parameters this one switched off (an alternative that fits better)."""


@dataclass(frozen=True)
class Verdict:
    """A candidate that was fitted, and whether (and why not) it was accepted."""

    effect: str
    where: str
    value: float | None
    accepted: bool
    reason: str
    delta_bic: float
    partial_f: float
    excess_share: float
    noise_share: float


@dataclass(frozen=True)
class Removal:
    """An added effect taken out again because it collapsed to "off" in the final fit."""

    effect: str
    where: str
    params: dict[str, float]
    reason: str


@dataclass(frozen=True)
class AsDeclared:
    """A high-order or linear declared model on the record, and the second-order-family equivalent fitted for it."""

    rms_deg: dict[str, float]
    """The model run as it is (its own simulation): the error before anything is fitted."""
    equivalent: dict[str, float]
    """The equivalent's stages (model parameter → declared starting value)."""
    free: tuple[str, ...]
    """The stages fitted."""
    held_fixed: tuple[str, ...]
    """Stages the record cannot move (kept at their declared values, not fitted)."""
    not_determinable: tuple[str, ...]
    """The declared model's parameters the equivalent does not carry (lumped into ωn and ζ, or not seen)."""
    sim: np.ndarray = field(repr=False, default_factory=lambda: np.zeros((0, 3)))
    """Its outputs on the record (position, surface, rate columns)."""


@dataclass
class Identification:
    """The outcome: the declared fit, the effects added, the final fit, and every verdict on the way."""

    problem: Problem
    model: str
    baseline: Fit
    final: Fit
    steps: list[Step] = field(default_factory=list)
    verdicts: list[Verdict] = field(default_factory=list)
    simulator_error_deg: dict[str, float] = field(default_factory=dict)
    elapsed_s: float = 0.0
    record: Record | None = None
    """The prepared record: noise floors, command hold, travel, unit, and what was found on the way."""
    start: Fit | None = None
    """The declared model at the parameters its fit started from."""
    removed: list[Removal] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    """What the fit decided about the record (command interpretation, start), one line each."""
    final_model: str = ""
    """:data:`REFERENCE` when the trivial model fits better than anything fitted; else empty (the declared one)."""
    as_declared: AsDeclared | None = None
    """A high-order or linear declared model: its own error and the equivalent it was fitted through."""
    physical: PhysicalFit | None = None
    """A high-order model's physical parameters fitted to the record, when they are the final model."""
    equivalent: Fit | None = None
    """The declared model with its effects, when :attr:`physical` replaced it as the final model."""
    equivalent_model: str = ""
    """:attr:`equivalent` in words (``loada + compliance + …``, ``hoad3 (as declared)``)."""
    escalated: str = ""
    """Why the physical fit of :data:`ema_sim.identify.physical.ESCALATE_TO` was tried (empty: it was not)."""
    search_ended: str = ""
    """Why the effects search ended (:func:`ema_sim.identify.stepwise.search`; empty: it did not run)."""
    stages: list[Outcome] = field(default_factory=list)
    """Every stage in order: what it did and the error before and after it."""
    failures: list[Failure] = field(default_factory=list)
    """Stages that raised: they ended, the model before them stands."""
    discovery: Discovery | None = None
    """What the residual was regressed on beyond the vocabulary, and the loop closed with it."""
    discovered: str = ""
    """The discovered terms the final model carries, in words (empty: none kept)."""
    artefacts: list[dict[str, object]] = field(default_factory=list)
    """Samples the record's sensors or logger corrupted, taken out of the fit (spikes, stale readings)."""
    ambiguities: list[str] = field(default_factory=list)
    """Explanations the record cannot choose between, one line each."""
    warnings: list[str] = field(default_factory=list)
    """What the stages flag (a trade not kept, a stage that failed), one line each, for the report's warnings."""
    changes: Changes | None = None
    """The final model refitted on windows of the record: what changes over it (:mod:`ema_sim.identify.changes`)."""
    timing: str = ""
    """What the stamps' jitter sets and whether the fit weighs it (:mod:`ema_sim.identify.timing`); empty: uniform."""


def model_name(result: Identification) -> str:
    """The final model in words: declared model and effects (or what replaced it), and discovered terms.

    Parameters
    ----------
    result : Identification
        The identification.

    Returns
    -------
    str
        ``second_order + rate_limit + discovered: sign(rate) (position) inside the loop``.
    """
    name = result.final_model or " + ".join([result.model, *(s.effect for s in result.steps)])
    return f"{name} + {result.discovered}" if result.discovered else name
