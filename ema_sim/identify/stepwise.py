"""Close the loop: fit the declared model, then add the effects it lacks while they pay for themselves.

Each round screens every applicable effect by its signature in the residual — the partial
correlation of the residual with the change the effect makes, after the current model's own
parameter sensitivities are projected out, as stepwise regression does — then fits the most
promising few properly (all parameters together) and accepts the best one only when

* the information criteria agree (ΔBIC ≤ −10 and partial F ≥ 20), *and*
* it removes at least a fifth of the error variance left above the noise floor, *and* at least
  5 % of the noise variance (with 10⁵ samples the criteria alone would take sub-sample timing shifts
  and integration error for effects), *and* far more than the simulator's own error, *and*
* its fitted value means something physical (a delay of at least one sample, a rate limit that
  binds, a positive compliance...).

The loop stops when nothing passes or nothing is left above the noise floor.

Safeguards (the contract's rules for every report):

* the declared model is fitted from the better of its declared start and a coarse grid over ωn and
  ζ (one batched simulation), so a far-off configuration does not trap the baseline in a local
  minimum; no fit ends worse than the parameters it started from (the start is kept if it would);
* a record that cannot tell a held command from a sampled one (no step-like change from rest) is
  fitted both ways and the interpretation that fits clearly better (ΔBIC ≤ −10) is taken, and said;
* after the loop each added effect is switched off in the final model: one whose removal no longer
  fails the acceptance criteria, or whose final value fails its physical check, has collapsed to
  "off" and is taken out again (the model refitted without it), with the reason;
* the trivial model position = command (surface = command) is always available: when the declared
  model with every effect added still fits worse (weighted, all outputs), the final model *is* the
  trivial one, and the fitted model stays in the report as the baseline with the reason.

Beyond the vocabulary (section 4.2.5's loop, :mod:`ema_sim.identify.physical`): a declared HOAD2/HOAD3
has its physical parameters fitted, and the effect search is skipped when they leave at most
:data:`EQUIVALENT_EXCESS` times the noise; any other declared model that ends above that on a record of
LVDT and surface is escalated to HOAD3's physics, kept when it pays, the declared model with its effects
reported beside it as the equivalent.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from ema_sim.analysis.command_hold import HoldMode
from ema_sim.config import ChannelConfig
from ema_sim.identify.declared import HIGH_ORDER, declared, not_determinable, run_declared
from ema_sim.identify.effects import BY_KEY, EFFECTS, FREE, KEYS, Context, Effect, Free, Values, report_values
from ema_sim.identify.fit import Fit, evaluate, fit
from ema_sim.identify.physical import ESCALATE_TO, PHYSICAL_MODELS, PhysicalFit, fit_physical
from ema_sim.identify.problem import EQUIVALENT_EXCESS, IN_LOOP_SHARE, Problem, in_loop_share
from ema_sim.identify.quantization import step_candidates
from ema_sim.identify.record import Record, prepare
from ema_sim.io.csv import MeasuredData
from ema_sim.models.second_order import SecondOrderParams
from ema_sim.parameters import metas

TOP_K = 3
MAX_EFFECTS = 8
MIN_EXCESS_SHARE = 0.1
MIN_NOISE_SHARE = 0.05
MAX_DELTA_BIC = -10.0
MIN_PARTIAL_F = 20.0
DONE_EXCESS = 0.02
"""Stop when the weighted error variance is within 2 % of the noise floor."""
NOT_DETERMINED = 0.25
"""An effect whose own parameter's one-sigma uncertainty exceeds this share of its value is not accepted."""
TINY = 1e-300
"""Floor on a residual sum of squares in a ratio (a noise-free record can be matched exactly)."""
REFERENCE = "position = command"
"""The trivial model every report compares with (and falls back on)."""
START_WN_RAD_S = (8.0, 15.0, 30.0, 60.0, 120.0, 250.0, 480.0)
START_ZETA = (0.35, 0.7, 1.2, 2.0)
"""The coarse grid the baseline may start from (when it does better than the declared values)."""
AS_DECLARED = " (as declared)"
"""How a model name reads when the declared model, run as it is, is the final model (no parameters fitted)."""


@dataclass(frozen=True)
class Candidate:
    """An effect at a starting value, with what screening saw of it."""

    effect: Effect
    value: Values
    """Where its fit starts: model parameter → value."""
    flip: bool
    predicted_drop: float
    """Weighted error it would remove if it entered linearly (all outputs)."""
    rho: float
    score: float = 0.0
    """The largest share of one output's error above its noise floor it would remove (ranking)."""


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
    """Why the physical fit of :data:`ESCALATE_TO` was tried for the declared model (empty: it was not)."""


def _rms(problem: Problem, f: Fit) -> dict[str, float]:
    return {o: float(np.sqrt(np.mean(e**2))) for o, e in problem.errors_deg(f.sim).items()}


def simulator_error(problem: Problem, params: SecondOrderParams, flip: bool) -> dict[str, float]:
    """RMS change of each output when the simulator's step is halved: its own accuracy on this record.

    Parameters
    ----------
    problem : Problem
        The record as fitted.
    params : SecondOrderParams
        The model.
    flip : bool
        Run with the hinge moment reversed (the hinge_moment_sign effect).
    """
    coarse = problem.simulate([params], [flip])[0]
    step = problem.step_s
    problem.step_s = step / 2.0
    try:
        fine = problem.simulate([params], [flip])[0]
    finally:
        problem.step_s = step
    out = {}
    for o in problem.outputs:
        col = 0 if o == "position_deg" else 1
        out[o] = float(np.sqrt(np.mean((coarse[problem.mask, col] - fine[problem.mask, col]) ** 2)))
    return out


def _on_bound(value: float, free: Free) -> bool:
    span = free.high - free.low
    return value <= free.low + 1e-6 * span or value >= free.high - 1e-6 * span


def _blocks(problem: Problem, vector: np.ndarray) -> list[np.ndarray]:
    """A stacked residual split back into its outputs."""
    n = int(problem.mask.sum())
    return [vector[k * n:(k + 1) * n] for k in range(len(problem.outputs))]


def _excess(problem: Problem, residual: np.ndarray) -> list[float]:
    """Each output's weighted error above its noise floor (at least 5 % of the noise, so never zero)."""
    return [max(float(np.dot(b, b)) - b.size, MIN_NOISE_SHARE * b.size) for b in _blocks(problem, residual)]


def _screen(problem: Problem, cur: Fit, ctx: Context) -> list[Candidate]:
    """Every applicable effect's best probe, ranked by what it would remove if it entered linearly.

    The rank is the share of one output's error above its noise floor: an effect seen on one output
    only (an LVDT filter) must not be drowned by a larger error on the other.
    """
    effects = [e for e in EFFECTS if e.applies(ctx) and not any(f in cur.free for f in e.owned)]
    probes: list[tuple[Effect, Values]] = [(e, v) for e in effects for v in e.probes(ctx)]
    if not probes:
        return []
    params = [e.apply(cur.params, v, ctx) for e, v in probes]
    flips = [cur.flip != (e.name == "hinge_moment_sign") for e, _ in probes]
    sims = problem.simulate(params, flips)
    r = cur.residual
    # Project out what the model's own parameters can still explain; one pinned on a bound cannot
    # move that way (a compliance held at zero by a reversed load), so its column stays in.
    movable = [j for j, name in enumerate(cur.jac_free) if not _on_bound(getattr(cur.params, name), FREE[name])]
    jac = cur.jacobian[:, movable]
    q = np.linalg.qr(jac, mode="reduced")[0] if jac.shape[1] else np.zeros((r.size, 0))
    r_perp = r - q @ (q.T @ r)
    r_norm = float(np.linalg.norm(r_perp))
    excess = _excess(problem, r)
    best: dict[str, Candidate] = {}
    for (effect, value), sim in zip(probes, sims, strict=True):
        s = r - problem.weighted_residual(sim)  # the change the effect makes to the model
        s_perp = s - q @ (q.T @ s)
        ss = float(np.dot(s_perp, s_perp))
        if ss <= 1e-12 or r_norm == 0.0:
            continue
        rs = float(np.dot(r_perp, s_perp))
        beta = rs / ss
        flip = cur.flip
        start = dict(value)
        if effect.name == "hinge_moment_sign":
            flip = not cur.flip
            if beta <= 0.0:
                continue
        elif effect.load_effect and beta < 0.0 and len(value) == 1:
            flip = not cur.flip  # the load would have to act backwards: try it with the sign reversed
            start = {f: abs(beta) * v for f, v in value.items()}
        elif effect.field in SIGNED:
            start = {f: getattr(cur.params, f) + beta * (v - getattr(cur.params, f)) for f, v in value.items()}
        elif beta <= 0.0:
            continue
        elif len(value) == 1:  # a single stage switched on: scale its probe by what the residual asks for
            start = {f: v * min(max(beta, 0.3), 3.0) for f, v in value.items()}
        step = beta * s_perp
        shares = [float(2.0 * np.dot(rb, sb) - np.dot(sb, sb)) / e
                  for rb, sb, e in zip(_blocks(problem, r_perp), _blocks(problem, step), excess, strict=True)]
        cand = Candidate(effect, start, flip, rs * rs / ss, rs / (r_norm * math.sqrt(ss)), max(shares))
        if effect.key not in best or cand.score > best[effect.key].score:
            best[effect.key] = cand
    return sorted(best.values(), key=lambda c: -c.score)


SIGNED = ("kb", "offset_deg", "delay_s", "feedback_delay_s")
"""Parameters a probe moves from where they are, either way (their screening step is signed)."""
PRE_QUANTIZER = ("kb", "offset_deg")
"""Parameters acting before the quantizer: the cost is piecewise flat in them once a step is on."""


def fit_model(problem: Problem, base: SecondOrderParams, free: tuple[str, ...] | list[str], *, flip: bool) -> Fit:
    """:func:`fit`, except that with a quantizer on, Kb and offset are found by batched grid searches.

    The quantizer makes the cost piecewise flat in the parameters before it, so gradients cannot
    move them: the smooth parameters are fitted with them held, then a coordinate search (a grid of
    11 over ±half a step, then one five times finer, for each) picks them, then the smooth
    parameters are fitted again.

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
    q = base.quantization_deg
    held = [f for f in free if f in PRE_QUANTIZER]
    if q <= 0.0 or not held:
        return fit(problem, base, free, flip=flip)
    return no_worse(problem, base, free, _fit_quantized(problem, base, free, held, flip=flip))


def no_worse(problem: Problem, start: SecondOrderParams, free: tuple[str, ...] | list[str], new: Fit) -> Fit:
    """``new``, unless it ends worse than the parameters it started from: then the start, as a fit.

    Parameters
    ----------
    problem : Problem
        The record as fitted.
    start : SecondOrderParams
        The parameters the fit started from.
    free : sequence of str
        The model parameters fitted.
    new : Fit
        The fit.
    """
    at_start = problem.weighted_residual(problem.simulate([start], [new.flip])[0])
    if new.rss <= float(np.dot(at_start, at_start)):
        return new
    return evaluate(problem, start, tuple(free), flip=new.flip)


def _fit_quantized(problem: Problem, base: SecondOrderParams, free: tuple[str, ...] | list[str], held: list[str],
                   *, flip: bool) -> Fit:
    """:func:`fit_model` with a quantizer on: smooth fit, coordinate grids on ``held``, smooth fit again."""
    q = base.quantization_deg
    smooth = [f for f in free if f not in PRE_QUANTIZER]
    first = fit(problem, base, smooth, flip=flip)
    u_max = max(float(np.max(np.abs(problem.data.command_deg))), 1e-6)
    half = {"offset_deg": 0.5 * q, "kb": 0.5 * q / u_max}
    params = first.params
    for scale in (1.0, 0.2):
        for name in held:
            centre = getattr(params, name)
            grid = [params.replace(**{name: centre + d}) for d in np.linspace(-1.0, 1.0, 11) * half[name] * scale]
            sims = problem.simulate(grid, [flip] * len(grid))
            costs = [float(np.dot(r, r)) for r in (problem.weighted_residual(x) for x in sims)]
            params = grid[int(np.argmin(costs))]
    final = fit(problem, params, smooth, flip=flip)
    sigma = dict(final.sigma)
    for name in held:
        sigma[name] = half[name] * 0.2 / 10.0  # the finest grid spacing: the resolution the search has
    return Fit(final.params, flip, tuple(free), final.sim, final.residual, final.jacobian, sigma, final.jac_free)


def _offs(fields: tuple[str, ...] | list[str], base: SecondOrderParams) -> dict[str, float]:
    """Each parameter switched off (its declared off value; the declared model's value for one without)."""
    info = metas(SecondOrderParams)
    out = {}
    for f in fields:
        off = info[f].off
        out[f] = float(getattr(base, f)) if off is None else float(off)
    return out


def _bic(problem: Problem, f: Fit) -> float:
    return problem.n_fit * math.log(f.rss) + len(f.free) * math.log(problem.n_fit)


def _fit_candidate(problem: Problem, cur: Fit, cand: Candidate, ctx: Context) -> Fit:
    """Fit the current model plus the candidate; an alternative to an earlier effect is also tried without it."""
    new = _fit_added(problem, cur, cand, ctx)
    swap = [f for f in cand.effect.replaces if f in new.free]
    if not swap:
        return new
    base = new.params.replace(**_offs(swap, ctx.declared))
    alt = fit_model(problem, base, tuple(f for f in new.free if f not in swap), flip=new.flip)
    return alt if _bic(problem, alt) < _bic(problem, new) else new


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
        return fit_model(problem, effect.apply(cur.params, cand.value, ctx), cur.free, flip=cand.flip)
    start = {f: min(max(v, FREE[f].low), FREE[f].high) if f in FREE else v for f, v in cand.value.items()}
    base = effect.apply(cur.params, start, ctx)
    if not effect.discrete:
        for companion in extra:
            base = base.replace(**companion.probes(ctx)[0])
        fields = [f for e in (effect, *extra) for f in e.fields]
        new = fit_model(problem, base, tuple(dict.fromkeys((*cur.free, *fields))), flip=cand.flip)
        failed = [f for e in extra if e.check({g: getattr(new.params, g) for g in e.fields}, ctx) for f in e.fields]
        if failed:
            base = new.params.replace(**_offs(failed, ctx.declared))
            new = fit_model(problem, base, tuple(f for f in new.free if f not in failed), flip=cand.flip)
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


def _gain(problem: Problem, cur: Fit, new: Fit, q: int, sim_err: dict[str, float]
          ) -> tuple[str, float, float, float, float]:
    """Whether going from ``cur`` to ``new`` (``q`` more parameters) pays.

    Returns the reason it does not ("" when it does), ΔBIC, partial F, the largest share of one output's
    error above its floor removed, and the share of the noise variance removed.
    """
    n = problem.n_fit
    rss0, rss1 = cur.rss, new.rss
    p1 = len(new.free)
    delta_bic = n * math.log(max(rss1, TINY) / max(rss0, TINY)) + q * math.log(n)
    partial_f = ((rss0 - rss1) / max(q, 1)) / (max(rss1, TINY) / max(n - p1, 1))
    # The margin is judged per output: an effect that removes a clear share of one output's error
    # above its noise floor counts even when the other output's error is larger.
    before = _blocks(problem, cur.residual)
    after = _blocks(problem, new.residual)
    drops = [(float(np.dot(b, b)) - float(np.dot(a, a))) / b.size for b, a in zip(before, after, strict=True)]
    excess_share = max(d * b.size / e for d, b, e in zip(drops, before, _excess(problem, cur.residual), strict=True))
    drop = max(drops)
    sim_floor = max((sim_err[o] / problem.sigma_deg[o]) ** 2 for o in problem.outputs)
    reason = ""
    if rss1 > rss0:
        reason = f"its fit ends worse than the model it started from (weighted error ×{rss1 / max(rss0, TINY):.3g})"
    elif delta_bic > MAX_DELTA_BIC or partial_f < MIN_PARTIAL_F:
        reason = f"does not pay for itself (ΔBIC {delta_bic:.1f}, partial F {partial_f:.1f})"
    elif excess_share < MIN_EXCESS_SHARE:
        reason = f"removes only {100 * excess_share:.1f} % of the error above the noise floor"
    elif drop < MIN_NOISE_SHARE:
        reason = f"changes the error by {100 * drop:.2f} % of the noise variance, below what sampling can tell"
    elif drop < 100.0 * sim_floor:
        reason = "within a hundred times the simulator's own error"
    return reason, delta_bic, partial_f, excess_share, drop


def _judge(problem: Problem, cur: Fit, new: Fit, cand: Candidate, ctx: Context,
           sim_err: dict[str, float]) -> Verdict:
    effect = cand.effect
    q = len(new.free) - len(cur.free) + sum(1 for f in effect.fields if f not in new.free)  # a swap counts less
    reason, delta_bic, partial_f, excess_share, drop = _gain(problem, cur, new, q, sim_err)
    values = {f: float(getattr(new.params, f)) for f in effect.fields}
    value = values[effect.fields[0]] if values else None
    if not reason and values:
        reason = effect.check(values, replace(ctx, params=new.params)) or ""
        for f, v in values.items():
            bound = FREE.get(f)
            if not reason and bound is not None and (v >= bound.high * (1 - 1e-3)
                                                     or (bound.low > 0 and v <= bound.low * 1.001)):
                reason = f"fitted {KEYS[f].name if f in KEYS else f} {v:.4g} sits on the bound of its physical range"
        for f, v in values.items():
            spread = new.sigma.get(f, 0.0) / abs(v) if v else math.inf
            if not reason and f in effect.owned and spread > NOT_DETERMINED:
                reason = (f"the record does not determine its {KEYS[f].name if f in KEYS else f} "
                          f"(±1σ {100 * spread:.0f} % of {v:.4g}): a stand-in, not a finding")
    return Verdict(effect.name, effect.where, value, not reason, reason or "accepted", delta_bic, partial_f,
                   excess_share, drop)


def _fmt(value: float) -> str:
    return f"{value:.4g}"


def _entries(problem: Problem, cur: Fit, new: Fit, cand: Candidate) -> list[Step]:
    """The report lines for an accepted candidate (a reversed load sign is a line of its own)."""
    before, after = _rms(problem, cur), _rms(problem, new)
    effect = cand.effect
    steps: list[Step] = []
    shares = {
        o: 100.0 * (float(np.dot(b, b)) - float(np.dot(a, a))) / e
        for o, b, a, e in zip(problem.outputs, _blocks(problem, cur.residual), _blocks(problem, new.residual),
                              _excess(problem, cur.residual), strict=True)
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
    if "hysteresis_h_lb_per_in" in effect.fields:
        vocab["load_freq_hz"] = problem.load_freq_hz
    where = f" on the {effect.where}" if effect.where in ("feedback", "surface") else ""
    fitted = ", ".join(f"{k} = {_fmt(v)}" for k, v in vocab.items())
    if effect.name == "feedback_filter":
        fitted = f"corner 2ζωn = {new.params.zeta * new.params.wn_rad_s / math.pi:.3g} Hz"
    removed = tuple(KEYS[f].name if f in KEYS else f for f in cur.free if f not in new.free)
    instead = f"; replaces {', '.join(removed)}" if removed else ""
    evidence = (f"{effect.signature} (partial ρ = {abs(cand.rho):.2f}); fitted {fitted}"
                f"{where}{instead}; error above the noise floor: {cut}")
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


def _choose_hold(problem: Problem, base: SecondOrderParams, free: list[str], record: Record,
                 notes: list[str]) -> tuple[Fit, Fit]:
    """Fit the baseline with the command as the record says it was logged, or both ways when it cannot tell."""
    held = _baseline(problem, base, free)
    if record.hold.sampled is not None or record.hold.source != "detected":
        return held
    problem.set_command_sampled(True)
    sampled = _baseline(problem, base, free)
    delta_bic = problem.n_fit * math.log(max(sampled[0].rss, TINY) / max(held[0].rss, TINY))
    if delta_bic <= MAX_DELTA_BIC:
        notes.append(f"command taken as sampled from a running demand, not held: the record has no step-like "
                     f"change from rest to tell, and the declared model fits it clearly better so "
                     f"(ΔBIC {delta_bic:.0f})")
        return sampled
    problem.set_command_sampled(False)
    notes.append(f"command taken as held (the data contract): the record cannot tell, and a sampled command "
                 f"fits no better (ΔBIC {delta_bic:+.0f})")
    return held


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


def _prune(problem: Problem, result: Identification, cur: Fit, base: SecondOrderParams) -> Fit:
    """Take out again every added effect that collapsed to "off" in the final fit (module docstring)."""
    for step in reversed(list(result.steps)):
        effect = _effect_of(step)
        if effect is None or not all(f in cur.free for f in effect.owned):
            continue
        values = {f: float(getattr(cur.params, f)) for f in effect.fields}
        off = _offs(effect.owned, base)
        ctx = Context(problem, cur.params, problem.max_rate_dps(cur.sim), base,
                      max_accel_dps2=problem.max_accel_dps2(cur.sim))
        reason = effect.check(values, ctx)
        free = tuple(f for f in cur.free if f not in off)
        if reason is None:
            without = evaluate(problem, cur.params.replace(**off), free, flip=cur.flip)
            why = _gain(problem, without, cur, len(off), result.simulator_error_deg)[0]
            if not why:
                continue
            reason = f"switched off in the final model, it no longer pays: {why}"
        refit = fit_model(problem, cur.params.replace(**off), free, flip=cur.flip)
        if refit.rss > result.baseline.rss:
            continue  # never end worse than the declared model's own fit
        result.steps.remove(step)
        result.removed.append(Removal(step.effect, step.where, dict(step.params), reason))
        cur = refit
    return cur


MOVE_SHARE = 1e-3
"""A parameter whose Jacobian column is below this share of the largest one cannot be moved by the record."""


def _as_declared(problem: Problem, model: str, base: SecondOrderParams, free: list[str], notes: list[str]
                 ) -> AsDeclared:
    """A high-order declared model: its own error on the record, and which of its equivalent's stages to fit.

    The stages whose Jacobian column at the start is negligible (a current limit the record never
    reaches, a delay under a sample) cannot be moved by the record: they are held at their declared
    values and said, not fitted (a singular fit would make every uncertainty infinite).
    """
    d = problem.data
    sim = run_declared(model, problem.channel, problem.time_s, d.command_deg, d.hinge_moment)
    rms = {o: float(np.sqrt(np.mean(e**2))) for o, e in problem.errors_deg(sim).items()}
    at = evaluate(problem, base, tuple(free), flip=False)
    size = np.linalg.norm(at.jacobian, axis=0)
    still = [f for f, s in zip(at.jac_free, size, strict=True)
             if f not in ("wn_rad_s", "zeta") and s <= MOVE_SHARE * float(np.max(size, initial=0.0))]
    fitted = [f for f in free if f not in still]
    text = ", ".join(f"{o} {v:.4g}°" for o, v in rms.items())
    notes.append(f"{model} as declared (its own simulation on the record): rms {text}; fitted through its "
                 f"second-order-family stages ({', '.join(fitted)})")
    if still:
        notes.append(f"{model}'s {', '.join(still)} cannot be moved by this record (the output does not change "
                     "with them): held at the declared values, not fitted")
    return AsDeclared(rms, {f: float(getattr(base, f)) for f in free}, tuple(fitted), tuple(still),
                      tuple(not_determinable(model, problem.channel)), sim[:, :3])


def identify(
    data: MeasuredData,
    channel: ChannelConfig,
    model: str = "second_order",
    overrides: dict[str, float] | None = None,
    *,
    max_effects: int = MAX_EFFECTS,
    log: Callable[[str], None] | None = None,
    record: Record | None = None,
    command: HoldMode = "detect",
    escalate: bool = True,
) -> Identification:
    """Fit ``model`` to ``data``, then add the vocabulary effects it lacks while they pay for themselves.

    ``record`` is ``data`` already prepared (:func:`ema_sim.identify.record.prepare`, with the
    channel's stand-in note); without it the record is prepared here with ``channel`` as declared
    and ``command`` (detect, held or sampled) for how its command was logged.

    Parameters
    ----------
    data : MeasuredData
        The measured record.
    channel : ChannelConfig
        The channel (travel, moment arm, configured values).
    model : str
        The declared model (:data:`ema_sim.identify.declared.DECLARED`).
    overrides : dict, optional
        Stages declared on top (model parameter → value).
    max_effects : int
        Most effects to add.
    log : callable, optional
        Called with each progress line.
    record : Record, optional
        ``data`` already prepared (:func:`ema_sim.identify.record.prepare`).
    command : str
        How the command was logged: ``detect``, ``held`` or ``sampled``.
    escalate : bool
        Whether a declared model that runs out of vocabulary (:func:`_escalation`) may be replaced by
        :data:`ESCALATE_TO` with its physical parameters fitted (never with ``max_effects`` 0).
    """
    t0 = time.perf_counter()
    say = log or (lambda _msg: None)
    record = record or prepare(data, channel, command=command)
    problem = Problem(record.data, record.channel, noise=record.noise, command_sampled=record.command_sampled)
    peak = float(np.percentile(np.abs(problem.hinge_moment), 98))
    base, free = declared(model, record.channel, overrides or {}, peak)
    notes: list[str] = []
    key = model.strip().lower()
    as_declared = _as_declared(problem, key, base, free, notes) if key in HIGH_ORDER else None
    if as_declared is not None:
        free = list(as_declared.free)
    cur, start = _choose_hold(problem, base, free, record, notes)
    baseline = cur
    say(f"baseline {model}: rms {_rms(problem, cur)}")
    result = Identification(problem, model, baseline, cur, record=record, start=start, notes=notes)
    result.as_declared = as_declared
    result.simulator_error_deg = simulator_error(problem, cur.params, cur.flip)
    physical = None
    if key in PHYSICAL_MODELS and record.unit != "deg":
        notes.append(f"{key}'s physical parameters not fitted: the record is in {record.unit}, and the model's "
                     "outputs are surface degrees through its crank arm (give --crank-arm-in to convert)")
    elif key in PHYSICAL_MODELS:
        physical = fit_physical(problem, key, say)
    searched = max_effects
    if physical is not None and _within(problem, physical.rms_deg):
        searched = 0
        notes.append(f"{key} with its physical parameters fitted leaves at most {EQUIVALENT_EXCESS:g}× the noise "
                     "floor on every output: its second-order-family equivalent is fitted as the baseline only, "
                     "no effect of the vocabulary searched")
    cur = _search(problem, result, cur, base, searched, say)
    result.final = _prune(problem, result, cur, base)
    trivial = reference_fit(problem, result.final.params)
    if trivial.rss <= result.final.rss:
        why = (f"the model it was added to fits worse than {REFERENCE} "
               f"(weighted error ×{result.final.rss / max(trivial.rss, TINY):.3g})")
        result.removed += [Removal(s.effect, s.where, dict(s.params), why) for s in result.steps]
        result.steps.clear()
        result.final, result.final_model = trivial, REFERENCE
    if as_declared is not None:
        _keep_declared(problem, result, as_declared)
    if physical is not None:
        _adopt_physical(problem, result, physical)
    elif escalate and max_effects > 0:
        result.escalated = _escalation(problem, result)
        if result.escalated:
            _adopt_physical(problem, result, fit_physical(problem, ESCALATE_TO, say))
    result.elapsed_s = time.perf_counter() - t0
    return result


def _search(problem: Problem, result: Identification, cur: Fit, base: SecondOrderParams, max_effects: int,
            say: Callable[[str], None]) -> Fit:
    """Add the vocabulary's effects to ``cur`` one at a time while each pays for itself (module docstring)."""
    for _ in range(max_effects):
        if cur.rss / problem.n_fit - 1.0 <= DONE_EXCESS:
            break
        steps = (step_candidates(problem, cur.params, cur.sim)
                 if cur.params.quantization_deg == 0.0 and "quantization_deg" not in cur.free else [])
        ctx = Context(problem, cur.params, problem.max_rate_dps(cur.sim), base, steps,
                      problem.max_accel_dps2(cur.sim), problem.ringing_hz(cur.sim))
        ranked = _screen(problem, cur, ctx)
        say("  screened: " + ", ".join(f"{c.effect.key} {c.score:.2f}" for c in ranked))
        best: tuple[Fit, Candidate] | None = None
        for k, cand in enumerate(ranked[:TOP_K]):
            new = _fit_candidate(problem, cur, cand, ctx)
            verdict = _judge(problem, cur, new, cand, ctx, result.simulator_error_deg)
            result.verdicts.append(verdict)
            say(f"  {cand.effect.key}: {verdict.reason}")
            if verdict.accepted and (best is None or new.rss < best[0].rss):
                best = (new, cand)
            # Stop fitting when the best so far already removed more than the rest could, even linearly.
            rest = ranked[k + 1].predicted_drop if k + 1 < len(ranked) else 0.0
            if best is not None and cur.rss - best[0].rss > 2.0 * rest:
                break
        if best is None:
            break
        new, cand = best
        result.steps.extend(_entries(problem, cur, new, cand))
        cur = new
    return cur


def _within(problem: Problem, rms_deg: dict[str, float]) -> bool:
    """Every output within :data:`EQUIVALENT_EXCESS` times its noise floor."""
    return all(v <= EQUIVALENT_EXCESS * problem.sigma_deg[o] for o, v in rms_deg.items())


def _escalation(problem: Problem, result: Identification) -> str:
    """Why the servo's own structure must be fitted (empty: it need not be).

    A declared model (the second-order family, HOAC1, HOALM, LOES) whose final fit, every effect that paid
    included, leaves more than :data:`EQUIVALENT_EXCESS` times the noise on a record of both the LVDT and
    the surface (an installed actuator's record, as HOAD3 describes one) has run out of vocabulary: its
    effects are equivalents. Where the error is (the share of the surface's the position's carries) is
    said, not required: HOAD3 carries the drive inside the loop and the linkage outside it.
    """
    if "surface_deg" not in problem.outputs or "position_deg" not in problem.outputs:
        return ""
    if result.record is not None and result.record.unit != "deg":
        return ""
    errors = problem.errors_deg(result.final.sim)
    ratio = {o: float(np.sqrt(np.mean(e**2))) / problem.sigma_deg[o] for o, e in errors.items()}
    worst = max(ratio, key=lambda o: ratio[o])
    if ratio[worst] <= EQUIVALENT_EXCESS:
        return ""
    share = in_loop_share(errors["surface_deg"], errors["position_deg"], problem.sigma_deg["surface_deg"],
                          problem.sigma_deg["position_deg"])
    if share is None:
        where = ""
    elif share >= IN_LOOP_SHARE:
        where = f", {100 * share:.0f} % of the surface's error the position's own (the servo's motion, inside the loop)"
    else:
        where = (f", {100 * (1.0 - share):.0f} % of the surface's error its own (outside the loop: the linkage, "
                 "the compliance)")
    return f"{result.model} with its effects leaves {ratio[worst]:.3g}× the noise on {worst}{where}"


def _adopt_physical(problem: Problem, result: Identification, pf: PhysicalFit) -> None:
    """The fitted physical parameters become the final model when they fit better (escalated: when they pay)."""
    cur = result.final
    excess = max(cur.rss - problem.n_fit, TINY)
    gain = (cur.rss - pf.rss) / excess
    text = ", ".join(f"{o} {v:.4g}°" for o, v in pf.rms_deg.items())
    share = f"{100 * min(gain, 1.0):.1f} %" if gain >= 0.0 else "none"
    if pf.rss >= cur.rss or (result.escalated and gain < MIN_EXCESS_SHARE):
        result.notes.append(f"{pf.model} with its physical parameters fitted ({pf.simulations} runs): rms {text}; "
                            f"not kept: it removes {share} of the error above the noise floor that {_label(result)} "
                            "left")
        return
    held = f"; held at declared values (the record cannot move them): {', '.join(pf.held)}" if pf.held else ""
    result.notes.append(f"{pf.model} with its physical parameters fitted ({pf.simulations} runs, {pf.elapsed_s:.1f} "
                        f"s): rms {text}; it removes {share} of the error above the noise floor that "
                        f"{_label(result)} left{held}")
    result.physical = pf
    result.equivalent, result.equivalent_model = cur, _label(result)
    result.final = Fit(cur.params, False, (), np.asarray(pf.sim, dtype=float), pf.residual,
                       np.zeros((pf.residual.size, 0)), {}, ())
    result.final_model = f"{pf.model} (physical parameters fitted)"


def _label(result: Identification) -> str:
    """The final model so far, in words (the one a physical fit would replace)."""
    return result.final_model or " + ".join([result.model, *(s.effect for s in result.steps)])


def _keep_declared(problem: Problem, result: Identification, as_declared: AsDeclared) -> None:
    """A declared model that fits better as it is than anything fitted through its equivalent is the final model."""
    r = problem.weighted_residual(as_declared.sim)
    if float(np.dot(r, r)) > result.final.rss:
        return
    why = (f"the declared {result.model} as it is fits better than its fitted second-order-family equivalent "
           f"(weighted error ×{result.final.rss / max(float(np.dot(r, r)), TINY):.3g})")
    result.removed += [Removal(s.effect, s.where, dict(s.params), why) for s in result.steps]
    result.steps.clear()
    result.final = Fit(result.final.params, False, (), as_declared.sim, r, np.zeros((r.size, 0)), {}, ())
    result.final_model = f"{result.model}{AS_DECLARED}"
