"""The vocabulary's loop: fit the declared model, then add the effects it lacks while they pay for themselves.

Each round screens every applicable effect by its signature in the residual
(:mod:`ema_sim.identify.screening`), fits the most promising few properly (all parameters together) and
accepts the best one only when the criteria of :mod:`ema_sim.identify.criteria` agree; the loop stops
when nothing passes or nothing is left above the noise floor.

Safeguards (the contract's rules for every report):

* the declared model is fitted from the better of its declared start and a coarse grid over ωn and
  ζ (one batched simulation), so a far-off configuration does not trap the baseline in a local
  minimum; no fit ends worse than the parameters it started from (the start is kept if it would);
* a record that cannot tell a held command from a sampled one (no step-like change from rest) is
  fitted both ways and the interpretation that fits clearly better (ΔBIC ≤ −10) is taken, and said;
* an accepted effect's rivals (another effect that explains the same residual: a gain error or a
  slow settling tail, a threshold or a stop) are fitted too and the better kept by BIC; when the
  record fits both about equally, the better is reported and the other named as its equivalent;
* after the loop each added effect is switched off in the final model: one whose removal no longer
  fails the acceptance criteria, or whose final value fails its physical check, has collapsed to
  "off" and is taken out again (the model refitted without it), with the reason;
* no accepted effect and no refit leaves an output worse than the baseline or the reference leave it.

One concept, the loop and its safeguards, in one module of about 750 lines: each safeguard is a step of the loop
and reads the loop's state.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from ema_sim.analysis.estimation import slew
from ema_sim.identify.criteria import DONE_EXCESS, MAX_DELTA_BIC, bic, blocks, excess, gain, judge
from ema_sim.identify.declared import not_determinable, run_declared
from ema_sim.identify.effects import BY_KEY, FREE, KEYS, Context, Effect, report_values
from ema_sim.identify.fit import TINY, Fit, evaluate, fit, residual_only, rms
from ema_sim.identify.grid_fit import finish, fit_model, no_worse
from ema_sim.identify.outcome import AsDeclared, Identification, Removal, Step, Verdict
from ema_sim.identify.parallel import SERIAL, Pool, TaskFuture, one_blas_thread, result
from ema_sim.identify.problem import Cancelled, Problem
from ema_sim.identify.quantization import step_candidates
from ema_sim.identify.record import Record
from ema_sim.identify.screening import Candidate, screen, within_range
from ema_sim.identify.stages import allow, worse
from ema_sim.models.second_order import SecondOrderParams
from ema_sim.parameters import metas

TOP_K = 3
NEXT_SCORE = 0.25
"""When none of a round's first fits is accepted, the next candidates that would remove at least this share of an
output's error above its noise are fitted too (up to :data:`TOP_K` more)."""
STOP_FACTOR = 2.0
"""A round stops once an accepted fit has removed this many times what the next candidate could, linearly."""
_ROUNDS = itertools.count()
"""Rounds submitted to workers, for their fits' cancellation tokens."""
MAX_EFFECTS = 8
START_WN_RAD_S = (8.0, 15.0, 30.0, 60.0, 120.0, 250.0, 480.0)
START_ZETA = (0.35, 0.7, 1.2, 2.0)
"""The coarse grid the baseline may start from (when it does better than the declared values)."""
MOVE_SHARE = 1e-3
"""A parameter whose Jacobian column is below this share of the largest one cannot be moved by the record."""
RIVALS: dict[str, tuple[str, ...]] = {
    "command_gain/command": ("servo_integral/feedback", "lag_filter/command"),
    "servo_integral/feedback": ("command_gain/command",),
    "static_threshold/feedback": ("command_bias/command", "command_gain/command"),
    "free_play/surface": ("hysteretic_damping/surface", "compliance/surface"),
    "lag_filter/command": ("time_delay/command",),
    "time_delay/command": ("lag_filter/command",),
}
"""Effects that can explain the same residual as another (a gain error or a slow settling tail, a threshold
or a bias): when one is the round's best, the others are fitted too and the better kept by BIC."""
AMBIGUOUS_BIC = 10.0
"""Two accepted explanations within this of each other's BIC fit the record about equally."""
SAME_RESIDUAL = 0.8
"""Two corrections that correlate at least this much explain the same part of the residual."""


def offs(fields: tuple[str, ...] | list[str], base: SecondOrderParams) -> dict[str, float]:
    """Each parameter switched off (its declared off value; the declared model's value for one without).

    Parameters
    ----------
    fields : sequence of str
        The parameters.
    base : SecondOrderParams
        The declared model's values.

    Returns
    -------
    dict
        Parameter → its off value.
    """
    info = metas(SecondOrderParams)
    out = {}
    for f in fields:
        off = info[f].off
        out[f] = float(getattr(base, f)) if off is None else float(off)
    return out


def _quick(problem: Problem, base: SecondOrderParams, free: tuple[str, ...], flip: bool, cur: Fit) -> Fit:
    """A candidate's quick fit, or its full fit when the quick one ends worse than the current model.

    The quick fit is :func:`~ema_sim.identify.grid_fit.fit_model` without grids. An effect that moves the
    command's timing or scale can need Kb and offset moved with it: a lag filter on a trapezoid record behind
    LOADA's quantizer ended 1.49 times the current model's error with them held, and under it with them searched.
    """
    quick = fit_model(problem, base, free, flip=flip, grids=False)
    return quick if quick.rss <= cur.rss else fit_model(problem, base, free, flip=flip)


def _fit_candidate(problem: Problem, cur: Fit, cand: Candidate, ctx: Context) -> Fit:
    """Fit the current model plus the candidate; an alternative to an earlier effect is also tried without it."""
    new = _fit_added(problem, cur, cand, ctx)
    swap = [f for f in cand.effect.replaces if f in new.free]
    if not swap:
        return new
    base = new.params.replace(**offs(swap, ctx.declared))
    alt = _quick(problem, base, tuple(f for f in new.free if f not in swap), new.flip, cur)
    return alt if bic(problem, alt) < bic(problem, new) else new


def _companions(cur: Fit, effect: Effect, ctx: Context) -> list[Effect]:
    """The effect's companions the model lacks and the record can show."""
    out = []
    for key in effect.companions:
        companion = BY_KEY[key]
        if companion.applies(ctx) and not any(f in cur.free for f in companion.owned):
            out.append(companion)
    return out


def _fit_added(problem: Problem, cur: Fit, cand: Candidate, ctx: Context) -> Fit:
    """Fit the current model plus the candidate, every parameter together."""
    effect = cand.effect
    extra = _companions(cur, effect, ctx)
    if not effect.fields and not extra:
        return _quick(problem, effect.apply(cur.params, cand.value, ctx), cur.free, cand.flip, cur)
    base = effect.apply(cur.params, within_range(cand.value), ctx)
    if not effect.discrete:
        for companion in extra:
            base = base.replace(**companion.probes(ctx)[0])
        fields = [f for e in (effect, *extra) for f in e.fields]
        new = _quick(problem, base, tuple(dict.fromkeys((*cur.free, *fields))), cand.flip, cur)
        failed = [f for e in extra if e.check({g: getattr(new.params, g) for g in e.fields}, ctx) for f in e.fields]
        if failed:
            base = new.params.replace(**offs(failed, ctx.declared))
            new = _quick(problem, base, tuple(f for f in new.free if f not in failed), cand.flip, cur)
        return new
    # A quantizer's step: the linear search's (step, offset) candidates, each checked with the full
    # simulation on a fine local grid (one batch), then the continuous parameters refitted with it.
    grid = [
        effect.apply(cur.params, {"quantization_deg": q * (1.0 + d)}, ctx).replace(
            offset_deg=cur.params.offset_deg + shift)
        for q, shift in ctx.quantization_steps for d in np.linspace(-3e-4, 3e-4, 7)
    ]
    sims = problem.simulate(grid, [cand.flip] * len(grid))
    costs = [float(np.dot(r, r)) for r in (problem.weighted_residual(s) for s in sims)]
    first = grid[int(np.argmin(costs))]
    free = tuple(cur.free) if first.offset_deg == cur.params.offset_deg else (*cur.free, "offset_deg")
    free = tuple(dict.fromkeys(free))
    new = fit_model(problem, first, free, flip=cand.flip)
    # The step and the command map settle together: search the step again around the refit model.
    steps = new.params.quantization_deg * (1.0 + np.linspace(-2e-3, 2e-3, 41))
    sims = problem.simulate([new.params.replace(quantization_deg=g) for g in steps], [cand.flip] * steps.size)
    costs = [float(np.dot(r, r)) for r in (problem.weighted_residual(x) for x in sims)]
    best = new.params.replace(quantization_deg=float(steps[int(np.argmin(costs))]))
    return fit_model(problem, best, new.free, flip=cand.flip)


def _fmt(value: float) -> str:
    return f"{value:.4g}"


def _entries(problem: Problem, cur: Fit, new: Fit, cand: Candidate) -> list[Step]:
    """The report lines for an accepted candidate (a reversed load sign is a line of its own)."""
    before, after = rms(problem, cur), rms(problem, new)
    effect = cand.effect
    steps: list[Step] = []
    shares = {
        o: 100.0 * (float(np.dot(b, b)) - float(np.dot(a, a))) / e
        for o, b, a, e in zip(problem.outputs, blocks(problem, cur.residual), blocks(problem, new.residual),
                              excess(problem, cur.residual), strict=True)
    }
    cut = ", ".join(f"{o.split('_')[0]} −{v:.0f} %" for o, v in shares.items() if v >= 1.0) or "small"
    if new.flip != cur.flip:
        if effect.name == "hinge_moment_sign":
            evidence = (f"{effect.signature} (partial ρ = {cand.rho:.2f}); reversing it cut the error above the "
                        f"noise floor: {cut}")
            return [Step("hinge_moment_sign", "load", {}, {}, before, after, evidence)]
        evidence = (f"{effect.name.replace('_', ' ')} fits only with the hinge moment reversed "
                    f"(partial ρ = {-abs(cand.rho):.2f} with the declared sign): the load was applied backwards")
        steps.append(Step("hinge_moment_sign", "load", {}, {}, before, before, evidence))
    vocab = report_values(new.params, effect.fields)
    sigma = {KEYS[f].name: new.sigma[f] * KEYS[f].factor(new.params) for f in effect.fields if f in new.sigma}
    vocab = {effect.contract.get(k, k): v for k, v in vocab.items()}
    sigma = {effect.contract.get(k, k): v for k, v in sigma.items()}
    if "hysteresis_h_lb_per_in" in effect.fields:
        vocab["load_freq_hz"] = problem.load_freq_hz
    where = f" on the {effect.where}" if effect.where in ("feedback", "surface") else ""
    fitted = ", ".join(f"{k} = {_fmt(v)}" for k, v in vocab.items())
    if effect.name == "feedback_filter":
        fitted = f"corner 2ζωn = {new.params.zeta * new.params.wn_rad_s / math.pi:.3g} Hz"
    removed = tuple(KEYS[f].name if f in KEYS else f for f in cur.free if f not in new.free)
    instead = f"; replaces {', '.join(removed)}" if removed else ""
    held = [f for f in effect.fields if f in problem.caps
            and float(getattr(new.params, f)) >= problem.caps[f] * (1.0 - 1e-6)]
    asked = fit(problem, new.params, new.free, flip=new.flip, capped=False) if held else None
    at_cap = (f"; {problem.settled.held(_fmt, problem.data.unit, float(getattr(asked.params, held[0])))}"
              if asked is not None and problem.settled is not None else "")
    evidence = (f"{effect.evidence(problem.data.command_deg)} (partial ρ = {abs(cand.rho):.2f}); fitted {fitted}"
                f"{where}{instead}{at_cap}; error above the noise floor: {cut}")
    steps.append(Step(effect.name, effect.where, vocab, sigma, before, after, evidence, removed))
    for companion in effect.companions:
        extra = BY_KEY[companion]
        if extra.fields and all(f in new.free and f not in cur.free for f in extra.fields):
            values = report_values(new.params, extra.fields)
            spread = {KEYS[f].name: new.sigma[f] * KEYS[f].factor(new.params) for f in extra.fields if f in new.sigma}
            text = ", ".join(f"{k} = {_fmt(v)}" for k, v in values.items())
            steps.append(Step(extra.name, extra.where, values, spread, before, after,
                              f"{extra.signature}: fitted with {effect.name} ({text}), which it had hidden"))
    return steps


def start_point(problem: Problem, base: SecondOrderParams, free: list[str], flip: bool) -> SecondOrderParams:
    """The declared start, or the best point of a coarse ωn × ζ grid when it fits better (one batched run).

    Parameters
    ----------
    problem : Problem
        The record as fitted.
    base : SecondOrderParams
        The starting parameters (everything not fitted stays as here).
    free : sequence of str
        The model parameters fitted.
    flip : bool
        Run with the hinge moment reversed (the hinge_moment_sign effect).
    """
    if not {"wn_rad_s", "zeta"} <= set(free):
        return base
    wn, zeta = FREE["wn_rad_s"], FREE["zeta"]
    grid = [base] + [base.replace(wn_rad_s=w, zeta=z) for w in START_WN_RAD_S for z in START_ZETA
                     if wn.low <= w <= wn.high and zeta.low <= z <= zeta.high]
    sims = problem.simulate(grid, [flip] * len(grid))
    costs = [float(np.dot(r, r)) for r in (problem.weighted_residual(x) for x in sims)]
    return grid[int(np.argmin(costs))]


def _baseline(problem: Problem, base: SecondOrderParams, free: list[str]) -> tuple[Fit, Fit]:
    """The declared model's fit from its best start, and the model at that start."""
    start = start_point(problem, base, free, False)
    return no_worse(problem, start, free, fit_model(problem, start, free, flip=False)), evaluate(
        problem, start, tuple(free), flip=False)


def choose_hold(problem: Problem, base: SecondOrderParams, free: list[str], record: Record,
                 notes: list[str]) -> tuple[Fit, Fit]:
    """Fit the baseline with the command as the record says it was logged, or both ways when it cannot tell.

    Parameters
    ----------
    problem : Problem
        The record as fitted (its command hold is set to the one kept).
    base : SecondOrderParams
        The declared model's starting values.
    free : list of str
        The parameters fitted.
    record : Record
        The prepared record (how its command was logged).
    notes : list of str
        Where the choice is said.

    Returns
    -------
    tuple of Fit
        The baseline and the start it was fitted from.
    """
    held = _baseline(problem, base, free)
    if record.hold.sampled is not None or record.hold.source != "detected":
        return held
    problem.set_command_sampled(True)
    sampled = _baseline(problem, base, free)
    delta_bic = problem.n_fit * math.log(max(sampled[0].rss, TINY) / max(held[0].rss, TINY))
    each = (f"taken as held: {_hold_summary(problem, held[0])}; taken as sampled: "
            f"{_hold_summary(problem, sampled[0])}")
    if delta_bic <= MAX_DELTA_BIC:
        notes.append(f"command taken as sampled from a running demand for the fit: the record's timing is "
                     f"undecided, and the declared model fits it clearly better so (ΔBIC {delta_bic:.0f}); {each}")
        return sampled
    problem.set_command_sampled(False)
    notes.append(f"command taken as held (the data contract) for the fit: the record's timing is undecided, and a "
                 f"sampled command fits no better (ΔBIC {delta_bic:+.0f}); {each}")
    return held


def _hold_summary(problem: Problem, fit: Fit) -> str:
    """A baseline's fitted parameters and error, in a few words (what one timing assumption gives)."""
    p = fit.params
    parts = [f"{name} {getattr(p, name):.4g}" for name in fit.free]
    err = ", ".join(f"{o.removesuffix('_deg')} {v:.3g}" for o, v in rms(problem, fit).items())
    return f"{', '.join(parts)}; rms {err}"


def reference_fit(problem: Problem, params: SecondOrderParams) -> Fit:
    """The trivial model position = command (surface = command) as a :class:`Fit` with no free parameter.

    ``params`` are carried along unused (a :class:`Fit` has some); its outputs are the logged command.

    Parameters
    ----------
    problem : Problem
        The record as fitted.
    params : SecondOrderParams
        Carried along unused (a fit has some).
    """
    u = problem.data.command_deg
    sim = np.column_stack([u, u, np.gradient(u, problem.time_s)])
    residual = problem.weighted_residual(sim)
    return Fit(params, False, (), sim, residual, np.zeros((residual.size, 0)), {}, ())


def _effect_of(step: Step) -> Effect | None:
    effect = BY_KEY.get(f"{step.effect}/{step.where}")
    return effect if effect is not None and effect.fields else None


def prune(problem: Problem, result: Identification, cur: Fit, base: SecondOrderParams, limit: Mapping[str, float]
          ) -> Fit:
    """Take out again every added effect that collapsed to "off" in the final fit (module docstring).

    Parameters
    ----------
    problem : Problem
        The record as fitted.
    result : Identification
        Its steps (an effect taken out leaves them for ``removed``).
    cur : Fit
        The model with every effect added.
    base : SecondOrderParams
        The declared model's starting values (the off value of a stage that has none).
    limit : mapping
        Per output, the rms no refit may exceed.

    Returns
    -------
    Fit
        The model without the effects that collapsed.
    """
    for step in reversed(list(result.steps)):
        effect = _effect_of(step)
        if effect is None or not all(f in cur.free for f in effect.owned):
            continue
        values = {f: float(getattr(cur.params, f)) for f in effect.fields}
        off = offs(effect.owned, base)
        ctx = Context(problem, cur.params, problem.max_rate_dps(cur.sim), base,
                      max_accel_dps2=problem.max_accel_dps2(cur.sim))
        reason = effect.check(values, ctx)
        free = tuple(f for f in cur.free if f not in off)
        if reason is None:
            without = residual_only(problem, cur.params.replace(**off), free, flip=cur.flip)
            why = gain(problem, without, cur, len(off), result.simulator_error_deg)[0]
            if not why:
                continue
            reason = f"switched off in the final model, it no longer pays: {why}"
        refit = fit_model(problem, cur.params.replace(**off), free, flip=cur.flip)
        if refit.rss > result.baseline.rss or worse(rms(problem, refit), limit):
            continue  # never end worse than the declared model's own fit, nor trade an output
        result.steps.remove(step)
        result.removed.append(Removal(step.effect, step.where, dict(step.params), reason))
        cur = refit
    return cur




def as_declared(problem: Problem, model: str, base: SecondOrderParams, free: list[str], notes: list[str]
                 ) -> AsDeclared:
    """A high-order declared model: its own error on the record, and which of its equivalent's stages to fit.

    The stages whose Jacobian column at the start is negligible (a current limit the record never
    reaches, a delay under a sample) cannot be moved by the record: they are held at their declared
    values and said, not fitted (a singular fit would make every uncertainty infinite).

    Parameters
    ----------
    problem : Problem
        The record as fitted.
    model : str
        The declared high-order model.
    base : SecondOrderParams
        Its second-order-family equivalent's values.
    free : list of str
        The equivalent's parameters that could be fitted.
    notes : list of str
        Where its own error and the held stages are said.

    Returns
    -------
    AsDeclared
        Its own error per output, the parameters fitted and those held.
    """
    d = problem.data
    sim = problem.saturate(run_declared(model, problem.channel, problem.time_s, d.command_deg, d.hinge_moment))
    own = {o: float(np.sqrt(np.mean(e**2))) for o, e in problem.errors_deg(sim).items()}
    at = evaluate(problem, base, tuple(free), flip=False)
    size = np.linalg.norm(at.jacobian, axis=0)
    still = [f for f, s in zip(at.jac_free, size, strict=True)
             if f not in ("wn_rad_s", "zeta") and s <= MOVE_SHARE * float(np.max(size, initial=0.0))]
    fitted = [f for f in free if f not in still]
    text = ", ".join(f"{o} {v:.4g}°" for o, v in own.items())
    notes.append(f"{model} as declared (its own simulation on the record): rms {text}; fitted through its "
                 f"second-order-family stages ({', '.join(fitted)})")
    if still:
        notes.append(f"{model}'s {', '.join(still)} cannot be moved by this record (the output does not change "
                     "with them): held at the declared values, not fitted")
    return AsDeclared(own, {f: float(getattr(base, f)) for f in free}, tuple(fitted), tuple(still),
                      tuple(not_determinable(model, problem.channel)), sim[:, :3])


def _pick(problem: Problem, cur: Fit, fitted: list[tuple[Fit, Candidate]]
          ) -> tuple[tuple[Fit, Candidate] | None, list[str]]:
    """The accepted fit with the lowest BIC, and each accepted rival that explains the same residual about as well."""
    said: list[str] = []
    if not fitted:
        return None, said
    ranked = sorted(fitted, key=lambda fc: bic(problem, fc[0]))
    best = ranked[0]
    change = best[0].residual - cur.residual
    for other in ranked[1:]:
        d = bic(problem, other[0]) - bic(problem, best[0])
        if d > AMBIGUOUS_BIC:
            break
        alt = other[0].residual - cur.residual
        denom = float(np.linalg.norm(change) * np.linalg.norm(alt))
        if denom > 0.0 and float(np.dot(change, alt)) / denom >= SAME_RESIDUAL:
            said.append(
                f"{best[1].effect.name} ({best[1].effect.where}) and {other[1].effect.name} ({other[1].effect.where}) "
                f"explain the same residual about equally (ΔBIC {d:.1f}, their corrections correlate "
                f"{float(np.dot(change, alt)) / denom:.2f}): on this record they are equivalent, one effect with "
                f"two names; {best[1].effect.name} is reported, {other[1].effect.name} is its equivalent")
    return best, said


STEP_RISE = 0.1
"""A candidate may raise an output's rms by this share of the current model's (besides the noise allowance)."""


@dataclass
class _Round:
    """One round of the search: candidates fitted against the same current model, and what became of them."""

    problem: Problem
    cur: Fit
    ctx: Context
    result: Identification
    limit: Mapping[str, float]
    say: Callable[[str], None]
    tried: dict[str, tuple[Fit, Verdict]]
    accepted: list[tuple[Fit, Candidate]]

    @property
    def step_limit(self) -> dict[str, float]:
        """What a candidate must not exceed on each output: the stage's limit and the current model's error.

        The current model's is widened by the noise as the stages widen theirs
        (:func:`~ema_sim.identify.stages.allow`) and by :data:`STEP_RISE` of itself: an effect that clears one
        output by spoiling another the model before had right is a trade, never a step, but one that moves an
        output still far above its noise by a few per cent while it clears the other is no trade (a record of
        the report's compliance staircase: the LVDT's compliance cut its error threefold and moved the
        surface's, at 12 times its noise, by 0.4 %).
        """
        cur = rms(self.problem, self.cur)
        now = allow(cur, self.problem.sigma_deg)
        return {o: min(v, max(now.get(o, v), (1.0 + STEP_RISE) * cur.get(o, v))) for o, v in self.limit.items()}

    def attempt(self, cand: Candidate, pending: object = None) -> None:
        """Fit ``cand`` (or take its fit from ``pending``, a fit already submitted to the pool) and judge it."""
        if pending is None:
            new = _fit_candidate(self.problem, self.cur, cand, self.ctx)
        else:
            new, simulations, reused = result(pending)
            self.problem.simulations += simulations
            self.problem.reused += reused
        verdict = judge(self.problem, self.cur, new, cand.effect, self.ctx, self.result.simulator_error_deg,
                        self.step_limit)
        self.result.verdicts.append(verdict)
        self.tried[cand.effect.key] = (new, verdict)
        self.say(f"  {cand.effect.key}: {verdict.reason}")
        if verdict.accepted:
            self.accepted.append((new, cand))


def remote_candidate(problem: Problem, cur: Fit, key: str, value: dict[str, float], flip: bool,
                     ctx: dict[str, Any], token: str = "") -> tuple[Fit, int, int] | None:
    """:func:`_fit_candidate` of the effect ``key`` from ``value`` on a worker, and the simulations it asked for.

    The effect is named by its key (its probes and checks are functions of the vocabulary, not pickled);
    the context is given without its problem, which comes on its own (scattered once to the workers).

    Parameters
    ----------
    problem : Problem
        The record as fitted.
    cur : Fit
        The current model.
    key : str
        The effect's key (:data:`ema_sim.identify.effects.BY_KEY`).
    value : dict
        Where its fit starts.
    flip : bool
        Run with the hinge moment reversed.
    ctx : dict
        The :class:`Context`'s fields other than its problem.
    token : str
        What the search cancels the fit by (:meth:`Problem.cancel`): a fit in a thread of the search's own
        process stops at its next simulation.

    Returns
    -------
    tuple or None
        The fit, the simulations it asked for, and how many of them were kept from before; they count once
        the search takes the fit (a fit it stopped before needing does not count, wherever it ran). None: the
        search cancelled it.
    """
    cand = Candidate(BY_KEY[key], value, flip, 0.0, 0.0)
    try:
        with one_blas_thread(), problem.tally(token) as counts:
            new = _fit_candidate(problem, cur, cand, Context(problem, **ctx))
    except Cancelled:
        return None
    return new, counts.simulations, counts.reused


def likely_needed(cands: list[Candidate]) -> list[Candidate]:
    """The round's candidates the search will probably fit: up to the first the early stop would skip, linearly.

    The search stops once an accepted fit has removed more than :data:`STOP_FACTOR` times the next candidate's
    predicted drop; taking each fit's drop as predicted, a candidate after one whose predicted drop is that much
    larger is not needed. Fitting it at once on the second core would only slow the fits the search waits for.

    Parameters
    ----------
    cands : list of Candidate
        The round's candidates, in the search's order.

    Returns
    -------
    list of Candidate
        Their first few.
    """
    out: list[Candidate] = []
    for cand in cands:
        if out and max(c.predicted_drop for c in out) > STOP_FACTOR * cand.predicted_drop:
            break
        out.append(cand)
    return out


def _submit(pool: Pool, problem: Problem, cur: Fit, cands: list[Candidate], ctx: Context
            ) -> dict[str, tuple[TaskFuture, str]]:
    """The round's candidate fits the search will likely need, submitted to the pool's workers at once.

    Returns each one's future and cancellation token by effect (empty: every fit is made here in turn; one not
    submitted is fitted here when the search reaches it).
    """
    cands = likely_needed(cands)
    client = pool.client() if len(cands) > 1 else None
    if client is None:
        return {}
    shared, model = client.scatter([problem, cur], broadcast=True)
    fields = {k: v for k, v in vars(ctx).items() if k != "problem"}
    round_id = next(_ROUNDS)
    out = {}
    for c in cands:
        token = f"{round_id}/{c.effect.key}"
        out[c.effect.key] = (client.submit(remote_candidate, shared, model, c.effect.key, dict(c.value), c.flip,
                                           fields, token, pure=False), token)
    return out


def _restart_rate(problem: Problem, cur: Fit, ranked: list[Candidate], tried: dict[str, tuple[Fit, Verdict]],
                  ctx: Context, result: Identification, limit: Mapping[str, float], say: Callable[[str], None]
                  ) -> tuple[Fit, Candidate] | None:
    """A rate-limit fit that ran away, restarted from the slope the record's rate-limited moves show."""
    key = "rate_limit/feedback"
    slope = problem.measured_slew.rate
    if key not in tried or slope is None:
        return None
    new, verdict = tried[key]
    if verdict.accepted:
        return None
    fitted = float(new.params.rate_limit_dps)
    if abs(fitted - slope) <= slew.AGREE * slope:
        return None
    base = next((c for c in ranked if c.effect.key == key), None)
    if base is None:
        return None
    cand = Candidate(base.effect, {"rate_limit_dps": slope}, base.flip, base.predicted_drop, base.rho, base.score)
    again = _fit_candidate(problem, cur, cand, ctx)
    v2 = judge(problem, cur, again, cand.effect, ctx, result.simulator_error_deg, limit)
    result.verdicts.append(v2)
    say(f"  {key} restarted from the measured slope {slope:.4g}: {v2.reason}")
    end = f"accepted at {float(again.params.rate_limit_dps):.4g}" if v2.accepted else v2.reason
    result.notes.append(f"the rate-limit fit ended at {fitted:.4g} ({verdict.reason}); restarted from the slope of the "
                        f"record's rate-limited moves, {slope:.4g}: {end}")
    return (again, cand) if v2.accepted else None


def _next(round_: _Round, ranked: list[Candidate]) -> None:
    """The most promising fits failed: the next candidates the residual still points at, until one is accepted."""
    for cand in [c for c in ranked if c.effect.key not in round_.tried and c.score >= NEXT_SCORE][:TOP_K]:
        round_.attempt(cand)
        if round_.accepted:
            return


def _round_candidates(problem: Problem, ranked: list[Candidate]) -> list[Candidate]:
    """The round's first fits: the best screened, and an effect the record measured wherever screening ranked it.

    The measured effect is a rate limit at the speed plateau the record's moves show.
    """
    first = ranked[:TOP_K]
    if problem.measured_slew.rate is not None:
        first += [c for c in ranked[TOP_K:] if c.effect.measured]
    return first


def search(problem: Problem, result: Identification, cur: Fit, base: SecondOrderParams, max_effects: int,
           say: Callable[[str], None], limit: Mapping[str, float], pool: Pool = SERIAL) -> Fit:
    """Add the vocabulary's effects to ``cur`` one at a time while each pays for itself (module docstring).

    Parameters
    ----------
    problem : Problem
        The record as fitted.
    result : Identification
        Where the steps, verdicts, notes and ambiguities go.
    cur : Fit
        The baseline.
    base : SecondOrderParams
        The declared model's starting values.
    max_effects : int
        Most effects to add.
    say : callable
        Progress lines.
    limit : mapping
        Per output, the rms no accepted model may exceed (the baseline's and the reference's).
    pool : Pool
        Where a round's candidate fits run (:mod:`ema_sim.identify.parallel`): all at once on its workers,
        taken in the search's own order (the same result as fitted one after another).

    Returns
    -------
    Fit
        The model with every effect that paid.
    """
    result.search_ended = f"it added the most effects asked for ({max_effects})"
    for round_no in range(1, max_effects + 1):
        if cur.rss / problem.n_fit - 1.0 <= DONE_EXCESS:
            result.search_ended = (f"it stopped before round {round_no}: the error left is within "
                                   f"{100 * DONE_EXCESS:g} % of the noise floor")
            break
        steps = (step_candidates(problem, cur.params, cur.sim)
                 if cur.params.quantization_deg == 0.0 and "quantization_deg" not in cur.free else [])
        ctx = Context(problem, cur.params, problem.max_rate_dps(cur.sim), base, steps,
                      problem.max_accel_dps2(cur.sim), problem.ringing_hz(cur.sim))
        ranked = screen(problem, cur, ctx)
        say("  screened: " + ", ".join(f"{c.effect.key} {c.score:.2f}" for c in ranked))
        accepted: list[tuple[Fit, Candidate]] = []
        tried: dict[str, tuple[Fit, Verdict]] = {}
        round_ = _Round(problem, cur, ctx, result, limit, say, tried, accepted)
        first = _round_candidates(problem, ranked)
        pending = _submit(pool, problem, cur, first, ctx)
        for k, cand in enumerate(first):
            round_.attempt(cand, pending.pop(cand.effect.key, (None, ""))[0])
            # Stop fitting when the best so far already removed more than the rest could, even linearly.
            rest = first[k + 1].predicted_drop if k + 1 < len(first) else 0.0
            if accepted and cur.rss - min(f.rss for f, _ in accepted) > STOP_FACTOR * rest:
                break
        for future, token in pending.values():  # fits the search stopped before needing
            future.cancel()
            problem.cancel(token)
        if not accepted:
            _next(round_, ranked)
        restarted = _restart_rate(problem, cur, ranked, tried, ctx, result, limit, say)
        if restarted is not None:
            accepted.append(restarted)
        leader, _ = _pick(problem, cur, accepted)
        if leader is not None:  # its rivals, when screening did not put them in the round
            for key in RIVALS.get(leader[1].effect.key, ()):
                rival = next((c for c in ranked if c.effect.key == key), None)
                if rival is not None and key not in tried:
                    round_.attempt(rival)
        best, said = _pick(problem, cur, accepted)
        result.ambiguities += said
        if best is None:
            result.search_ended = (f"it stopped after round {round_no}: none of its {len(tried)} candidate fit"
                                   f"{'s' if len(tried) != 1 else ''} paid for itself")
            break
        new, cand = best
        new = finish(problem, new)
        result.steps.extend(_entries(problem, cur, new, cand))
        cur = new
    return cur
