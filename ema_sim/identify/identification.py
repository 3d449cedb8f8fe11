"""``ema identify``'s chain: fit the declared model, add what it lacks, go beyond the vocabulary, never break.

The stages, in order, each guarded and each kept only when it pays on the whole record and trades no
output for another (:mod:`ema_sim.identify.stages`):

1. **record** — the sensors' and the logger's artefacts (isolated spikes, stale readings) are found
   from the record itself and taken out of the fit (:mod:`ema_sim.identify.artefacts`);
2. **baseline** — the declared model's own parameters fitted (:func:`ema_sim.identify.stepwise.choose_hold`);
   a fit that leaves an output worse than position = command is refitted with that output weighed more;
3. **effects** — the vocabulary's effects added while each pays (:func:`ema_sim.identify.stepwise.search`),
   those that collapse taken out again; when the declared model with its effects fits worse than the
   reference, the reference is the model;
4. **declared as is** — a high-order or linear declared model run as it is, when that fits better;
5. **physics** — a declared HOAD2/HOAD3's physical parameters, or the escalation to HOAD3's physics of a
   declared model that ran out of vocabulary on a record of LVDT and surface (section 4.2.5);
6. **discovery** — what is left regressed on terms built from the record, the loop closed with the terms
   that hold (:mod:`ema_sim.identify.discovery`); when the vocabulary's effects were added, the same is
   done on the baseline's residual, and the two explanations are compared by BIC.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ema_sim.identify import artefacts, changes, timing
from ema_sim.identify.criteria import MAX_DELTA_BIC, MIN_EXCESS_SHARE, simulator_error
from ema_sim.identify.declared import HIGH_ORDER, declared
from ema_sim.identify.discovery import STRUCTURED, Discovery, discover, named_stands
from ema_sim.identify.escalation import adopt_physical, escalation, keep_declared, within
from ema_sim.identify.fit import TINY, Fit, evaluate, rms
from ema_sim.identify.grid_fit import fit_model
from ema_sim.identify.outcome import REFERENCE, AsDeclared, Identification, Removal, Step
from ema_sim.identify.parallel import MIN_SAMPLES, SERIAL, Pool, one_blas_thread
from ema_sim.identify.physical import ESCALATE_TO, PHYSICAL_MODELS, PhysicalFit, fit_physical
from ema_sim.identify.problem import EQUIVALENT_EXCESS, Problem
from ema_sim.identify.record import Record
from ema_sim.identify.stages import Clock, Failure, Outcome, allow, ceiling, guarded, trade, worse
from ema_sim.identify.stepwise import MAX_EFFECTS, as_declared, choose_hold, prune, reference_fit, search
from ema_sim.models.second_order import SecondOrderParams

BALANCE_WEIGHTS = (4.0, 16.0, 64.0)
"""Weights tried on an output the baseline leaves worse than the reference, until it no longer does."""


class _Chain:
    """The stages' shared state: the result so far, the reference's rms, and the outcome of each stage."""

    def __init__(self, problem: Problem, result: Identification, say: Callable[[str], None], pool: Pool = SERIAL
                 ) -> None:
        self.problem = problem
        self.result = result
        self.say = say
        self.pool = pool
        self.reference = rms(problem, reference_fit(problem, result.baseline.params))

    @property
    def now(self) -> dict[str, float]:
        return rms(self.problem, self.result.final)

    def limit(self) -> dict[str, float]:
        """What a stage's model must not exceed on each output: the model before it, the baseline, the reference."""
        return self.ceiling(self.now)

    def ceiling(self, before: dict[str, float]) -> dict[str, float]:
        """The least of ``before`` and the baseline widened by the noise (:func:`allow`), and the reference."""
        return ceiling(allow(ceiling(before, rms(self.problem, self.result.baseline)), self.problem.sigma_deg),
                       self.reference)

    def run(self, stage: str, body: Callable[[], tuple[str, str]]) -> None:
        """Run ``body`` guarded; record its outcome (a failure leaves the model before it standing)."""
        clock = Clock()
        before = self.now
        saved = _snapshot(self.result)
        failures = self.result.failures
        n = len(failures)
        out = guarded(stage, failures, body)
        if out is None:
            _restore(self.result, saved)
            f = failures[n] if len(failures) > n else None
            why = f"{f.error} ({f.where})" if f is not None else "failed"
            self.result.warnings.append(f"stage '{stage}' failed and was skipped, the model before it stands: {why}")
            self.say(f"{stage}: failed: {why}")
            out = ("failed", why)
        status, reason = out
        after = self.now
        if status == "kept" and worse(after, self.ceiling(before)):
            why = trade(after, before, self.ceiling(before))
            _restore(self.result, saved)
            status, reason, after = "not kept", f"{reason}; {why}", self.now
            self.result.warnings.append(f"stage '{stage}': {why}")
        self.result.stages.append(Outcome(stage, status, reason, before, after, clock.elapsed_s))


@dataclass(frozen=True)
class _Saved:
    """What a stage may change in the result, as it stood before the stage (restored when the stage fails)."""

    final: Fit
    final_model: str
    steps: list[Step]
    removed: list[Removal]
    physical: PhysicalFit | None
    equivalent: Fit | None
    equivalent_model: str
    discovery: Discovery | None
    discovered: str


def _snapshot(r: Identification) -> _Saved:
    return _Saved(r.final, r.final_model, list(r.steps), list(r.removed), r.physical, r.equivalent,
                  r.equivalent_model, r.discovery, r.discovered)


def _restore(r: Identification, saved: _Saved) -> None:
    r.final, r.final_model, r.steps, r.removed = saved.final, saved.final_model, saved.steps, saved.removed
    r.physical, r.equivalent, r.equivalent_model = saved.physical, saved.equivalent, saved.equivalent_model
    r.discovery, r.discovered = saved.discovery, saved.discovered


@dataclass(frozen=True)
class Search:
    """How far identification searches, and where its fits run.

    Parameters
    ----------
    max_effects : int
        Most effects to add.
    escalate : bool
        Whether a declared model that runs out of vocabulary may be replaced by :data:`ESCALATE_TO` with
        its physical parameters fitted (never with ``max_effects`` 0).
    discover_terms : bool
        Whether what is left is regressed on the library and the loop closed with it (never with
        ``max_effects`` 0).
    workers : int
        Fit a round's candidates and the physics' extra starts at once on a local Dask cluster of this many
        threads (0 or 1: one after another here); the same result either way (:mod:`.parallel`).
    scheduler : str, optional
        A running Dask scheduler's address to send those fits to instead of a local cluster.
    """

    max_effects: int = MAX_EFFECTS
    escalate: bool = True
    discover_terms: bool = True
    workers: int = 0
    scheduler: str | None = None


def identify(record: Record, model: str = "second_order", overrides: dict[str, float] | None = None, *,
             search: Search | None = None, log: Callable[[str], None] | None = None) -> Identification:
    """Fit ``model`` to a prepared record, add the effects it lacks, discover what no effect names (module docstring).

    Parameters
    ----------
    record : Record
        The record prepared once (:func:`ema_sim.identify.record.prepare`): its data, channel, noise floors,
        command timing, stamps and units, which every stage reads from it.
    model : str
        The declared model (:data:`ema_sim.identify.declared.DECLARED`).
    overrides : dict, optional
        Stages declared on top (model parameter → value).
    search : Search, optional
        How far to search and where the fits run (the defaults: every stage, in this process).
    log : callable, optional
        Called with each progress line.

    Returns
    -------
    Identification
        The outcome: baseline, effects, final model, every stage and verdict.
    """
    t0 = time.perf_counter()
    search = search or Search()
    say = log or (lambda _msg: None)
    problem = Problem(record.data, record.channel, command_sampled=record.command_sampled,
                      output_range=record.sensor_range, prepared=record.prepared)
    workers, scheduler = search.workers, search.scheduler
    pool = Pool(scheduler, workers) if scheduler or (workers >= 2 and problem.n_fit >= MIN_SAMPLES) else SERIAL
    pool.start()  # the cluster starts while the baseline is fitted
    if scheduler:
        pool.client()  # a scheduler that cannot be reached is the user's error, said before any fit
    try:
        with one_blas_thread():
            result = _identify(problem, record, model, overrides, t0=t0, say=say, pool=pool,
                               max_effects=search.max_effects, escalate=search.escalate,
                               discover_terms=search.discover_terms)
        if pool.failed:
            result.warnings.append(pool.failed)
        return result
    finally:
        pool.close()


def _identify(problem: Problem, record: Record, model: str, overrides: dict[str, float] | None, *, t0: float,
              say: Callable[[str], None], pool: Pool, max_effects: int, escalate: bool, discover_terms: bool
              ) -> Identification:
    """:func:`identify` on the problem set up (its fits of a round on ``pool``)."""
    found = artefacts.find(problem)
    artefacts.exclude(problem, found)
    peak = float(np.percentile(np.abs(problem.hinge_moment), 98))
    base, free = declared(model, record.channel, overrides or {}, peak)
    notes: list[str] = [a.statement() for a in found]
    key = model.strip().lower()
    decl = as_declared(problem, key, base, free, notes) if key in HIGH_ORDER else None
    if decl is not None:
        free = list(decl.free)
    failures: list[Failure] = []
    fitted = guarded("baseline", failures, lambda: choose_hold(problem, base, free, record, notes))
    if fitted is None:
        trivial = reference_fit(problem, base)
        fitted = (trivial, trivial)
    cur, start = fitted
    weighed, said = timing.weigh(problem, record.stamps, cur, record.unit) if record.stamps else (False, "")
    if weighed:  # the weights changed: the baseline refitted under them, its start re-evaluated
        cur = fit_model(problem, cur.params, cur.free, flip=cur.flip)
        start = evaluate(problem, start.params, start.free, flip=start.flip)
    result = Identification(problem, model, cur, cur, record=record, start=start, notes=notes)
    result.timing = said
    result.failures += failures
    result.artefacts = [a.as_dict() for a in found]
    result.as_declared = decl
    chain = _Chain(problem, result, say, pool)
    if failures:
        result.final_model = REFERENCE
        why = f"{failures[0].error} ({failures[0].where})"
        result.warnings.append(f"the declared {model} could not be fitted, the reference stands: {why}")
        result.stages.append(Outcome("baseline", "failed", why, chain.reference, chain.reference, 0.0))
    else:
        _balance(chain, free)
    say(f"baseline {model}: rms {rms(problem, result.baseline)}")
    result.simulator_error_deg = guarded("baseline", result.failures,
                                         lambda: simulator_error(problem, cur.params, cur.flip)) or {}
    _stages(chain, key, base, decl, failed=bool(failures), max_effects=max_effects, escalate=escalate,
            discover_terms=discover_terms)
    result.elapsed_s = time.perf_counter() - t0
    return result


def _stages(chain: _Chain, key: str, base: SecondOrderParams, decl: AsDeclared | None, *, failed: bool,
            max_effects: int, escalate: bool, discover_terms: bool) -> None:
    """The stages after the baseline, in order: effects, the declared model as is, physics, discovery."""
    problem, result, say, notes = chain.problem, chain.result, chain.say, chain.result.notes
    record = result.record
    assert record is not None
    physical: PhysicalFit | None = None
    if key in PHYSICAL_MODELS and record.unit != "deg":
        notes.append(f"{key}'s physical parameters not fitted: the record is in {record.unit}, and the model's "
                     "outputs are surface degrees through its crank arm (give --crank-arm-in to convert)")
    elif key in PHYSICAL_MODELS and not failed:
        physical = guarded("physics", result.failures, lambda: fit_physical(problem, key, say, chain.pool))
    searched = max_effects if not failed else 0
    if physical is not None and within(problem, physical.rms_deg):
        searched = 0
        notes.append(f"{key} with its physical parameters fitted leaves at most {EQUIVALENT_EXCESS:g}× the noise "
                     "floor on every output: its second-order-family equivalent is fitted as the baseline only, "
                     "no effect of the vocabulary searched")
    if searched:
        chain.run("effects", lambda: _effects(chain, base, searched))
    if decl is not None and not failed:
        chain.run("declared as is", lambda: keep_declared(problem, result, decl, chain.limit()))
    if physical is not None:
        chain.run("physics", lambda: adopt_physical(problem, result, physical, chain.limit()))
    elif escalate and max_effects > 0 and not failed:
        result.escalated = escalation(problem, result)
        if result.escalated:
            chain.run("physics", lambda: _escalate(chain))
    if max_effects > 0 and not failed:
        _changes(chain, base)
    if discover_terms and max_effects > 0:
        if result.changes is not None and result.changes.changed:
            result.stages.append(Outcome("discovery", "skipped", "the record changed over its length: terms regressed "
                                         "on the whole of it would stand in for the change", chain.now, chain.now, 0.0))
        else:
            chain.run("discovery", lambda: _discovery(chain))


def _changes(chain: _Chain, base: SecondOrderParams) -> None:
    """The final model refitted on windows of the record (:mod:`.changes`), said as a stage of its own.

    An effect that stood in for a change is taken out although the whole record's error rises: that error was the
    change's, not the effect's to explain.
    """
    clock = Clock()
    before = chain.now
    saved = _snapshot(chain.result)
    found = guarded("changes", chain.result.failures,
                    lambda: changes.analyse(chain.problem, chain.result, base, chain.say, chain.pool))
    if found is None:
        _restore(chain.result, saved)
        status, reason = "failed", "the windowed refit failed: no change over the record is reported"
    else:
        chain.result.changes = found
        status = "kept" if found.proxies else "nothing to add"
        reason = "; ".join(found.proxies) or found.skipped or "; ".join(found.statements)
    chain.result.stages.append(Outcome("changes", status, reason, before, chain.now, clock.elapsed_s))


def _balance(chain: _Chain, free: list[str]) -> None:
    """Refit a baseline that leaves an output worse than the reference with that output weighed more."""
    p, r = chain.problem, chain.result
    bad = worse(rms(p, r.baseline), chain.reference)
    if not bad or not r.baseline.free:
        return
    before = rms(p, r.baseline)
    for w in BALANCE_WEIGHTS:
        p.weights = dict.fromkeys(bad, w)
        try:
            new = guarded("baseline", r.failures, lambda: fit_model(p, r.baseline.params, free, flip=r.baseline.flip))
        finally:
            p.weights = {}
        if new is None:
            return
        fit = evaluate(p, new.params, tuple(new.free), flip=new.flip)
        if not worse(rms(p, fit), chain.reference):
            r.notes.append(f"the declared model's fit left {', '.join(bad)} worse than {REFERENCE} "
                           f"({', '.join(f'{o} {before[o]:.4g}' for o in bad)}): refitted with it weighed {w:g}×, "
                           f"so that no output is worse than the reference")
            r.baseline = r.final = fit
            return
    r.warnings.append(f"the declared model fits {', '.join(bad)} worse than {REFERENCE} whatever the weights: "
                      f"{trade(before, chain.reference, chain.reference)}")


def _effects(chain: _Chain, base: SecondOrderParams, searched: int) -> tuple[str, str]:
    p, r = chain.problem, chain.result
    limit = chain.limit()
    cur = search(p, r, r.final, base, searched, chain.say, limit, chain.pool)
    final = prune(p, r, cur, base, limit)
    trivial = reference_fit(p, final.params)
    if trivial.rss <= final.rss and not worse(chain.reference, limit):
        why = (f"the model it was added to fits worse than {REFERENCE} "
               f"(weighted error ×{final.rss / max(trivial.rss, TINY):.3g})")
        r.removed += [Removal(s.effect, s.where, dict(s.params), why) for s in r.steps]
        r.steps.clear()
        r.final, r.final_model = trivial, REFERENCE
        return "kept", why
    r.final = final
    if not r.steps:
        return "nothing to add", f"no effect of the vocabulary pays for itself ({r.search_ended})"
    return "kept", f"added {', '.join(s.effect for s in r.steps)} ({r.search_ended})"


def _escalate(chain: _Chain) -> tuple[str, str]:
    cur = chain.result.final
    excess = max(cur.rss - chain.problem.n_fit, TINY)
    pf = fit_physical(chain.problem, ESCALATE_TO, chain.say, chain.pool, beat=cur.rss - MIN_EXCESS_SHARE * excess,
                      current=cur.residual)
    return adopt_physical(chain.problem, chain.result, pf, chain.limit())


def _refitter(result: Identification) -> Callable[[Problem], Fit] | None:
    """How discovery refits the final model's own parameters (None: it cannot, the model stays as it is)."""
    final = result.final
    if result.final_model or not final.free:
        return None
    return lambda p: fit_model(p, final.params, final.free, flip=final.flip)


def _discovery(chain: _Chain) -> tuple[str, str]:
    p, r = chain.problem, chain.result
    disc = discover(p, r.final, chain.limit(), _refitter(r), chain.say)
    r.discovery = disc
    kept = disc.kept
    rival = _rival(chain, disc) if r.steps and not r.final_model else None
    if rival is not None:
        return rival
    if kept is None or kept.fit is None:
        if not any(f.structured for f in disc.found.values()):
            return "nothing to add", "no output's residual is structured (white, or within 1.5× its floor)"
        if not any(f.regression.selected for f in disc.found.values()):
            return "nothing to add", "; ".join(disc.statements) or "no term of the library holds up"
        return "not kept", "; ".join(f"{c.where}: {c.reason}" for c in disc.closures)
    label = disc.label()
    r.final = kept.fit
    r.discovered = label
    return "kept", f"{label}: {kept.reason}"


def _rival(chain: _Chain, disc: Discovery) -> tuple[str, str] | None:
    """The baseline with discovered terms instead of the vocabulary's effects, when it explains the record better.

    Two explanations of one residual (free play or a drift, a gain error or a slow tail) are compared by BIC;
    within :data:`MAX_DELTA_BIC` of each other both are said to fit and the named one is kept.
    """
    p, r = chain.problem, chain.result
    other = discover(p, r.baseline, chain.limit(), lambda q: fit_model(q, r.baseline.params, r.baseline.free,
                                                                         flip=r.baseline.flip))
    alt = other.kept
    if alt is None or alt.fit is None:
        return None
    named = disc.kept.fit if disc.kept is not None and disc.kept.fit is not None else r.final
    n_named = len(named.free) + _extra(disc)
    n_alt = len(alt.fit.free) + _extra(other)
    d = (p.n_fit * np.log(max(alt.fit.rss, TINY)) + n_alt * np.log(p.n_fit)) - (
        p.n_fit * np.log(max(named.rss, TINY)) + n_named * np.log(p.n_fit))
    effects = ", ".join(s.effect for s in r.steps)
    if d > -MAX_DELTA_BIC:
        return None
    same = other.equivalents([s.effect for s in r.steps])
    if same or named_stands(rms(p, named), p.sigma_deg):
        pairs = "; ".join(f"the discovered {t} is {e}'s equivalent" for e, t in same)
        why = (f"{pairs}: the named physical effect stands" if same else
               f"the named effects already explain it to within {STRUCTURED:g}× the noise floor: they stand")
        r.notes.append(f"the discovered {other.label()} fit the record better than {effects} "
                       f"(ΔBIC {d:+.1f}), but {why}")
        return None
    if d > MAX_DELTA_BIC:
        r.ambiguities.append(f"the vocabulary's {effects} and the discovered {other.label()} explain the record about "
                             f"equally (ΔBIC {d:+.1f}): the discovered terms are the named effects' equivalent "
                             "on this record; the named effects are kept")
        return None
    if worse(rms(p, alt.fit), chain.limit()):
        return None
    why = f"the discovered {other.label()} explain the record better than {effects} (ΔBIC {d:+.1f})"
    r.removed += [Removal(s.effect, s.where, dict(s.params), why) for s in r.steps]
    r.steps.clear()
    r.discovery = other
    r.final = alt.fit
    r.discovered = other.label()
    return "kept", why


def _extra(disc: Discovery) -> int:
    c = disc.kept
    return 0 if c is None else sum(len(v) for ts in c.terms.values() for _, v, _, _ in ts)

