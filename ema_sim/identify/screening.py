"""Screening: every applicable effect's signature in the residual, ranked before any is fitted.

Each effect is probed at a starting value; the change it makes to the model's outputs is its signature.
The partial correlation of the residual with that signature, after the current model's own parameter
sensitivities are projected out (as stepwise regression does), says how much of the error the effect
would remove if it entered linearly. The most promising few are then fitted properly
(:mod:`ema_sim.identify.stepwise`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ema_sim.identify.criteria import blocks, excess, on_bound
from ema_sim.identify.effects import EFFECTS, FREE, Context, Effect, Values
from ema_sim.identify.fit import Fit
from ema_sim.identify.problem import Problem

SIGNED = ("kb", "offset_deg", "delay_s", "feedback_delay_s")
"""Parameters a probe moves from where they are, either way (their screening step is signed)."""


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


def within_range(values: Values) -> Values:
    """Each :data:`~ema_sim.identify.effects.FREE` parameter's value clipped to its range, for a probe or a fit's start.

    A value read off the record beyond the range (a rate at a glitch's slope) starts at the bound instead of
    failing the model's validation.

    Parameters
    ----------
    values : dict
        Model parameter → value.

    Returns
    -------
    dict
        The same, each fitted parameter's value within its bounds.
    """
    return {f: min(max(v, FREE[f].low), FREE[f].high) if f in FREE else v for f, v in values.items()}


def screen(problem: Problem, cur: Fit, ctx: Context) -> list[Candidate]:
    """Every applicable effect's best probe, ranked by what it would remove if it entered linearly.

    The rank is the share of one output's error above its noise floor: an effect seen on one output
    only (an LVDT filter) must not be drowned by a larger error on the other.

    Parameters
    ----------
    problem : Problem
        The record as fitted.
    cur : Fit
        The current model.
    ctx : Context
        What the current model does on the record.

    Returns
    -------
    list of Candidate
        The best probe of each effect, most promising first.
    """
    effects = [e for e in EFFECTS if e.applies(ctx) and not any(f in cur.free for f in e.owned)]
    probes: list[tuple[Effect, Values]] = [(e, v) for e in effects for v in e.probes(ctx)]
    if not probes:
        return []
    params = [e.apply(cur.params, within_range(v), ctx) for e, v in probes]
    flips = [cur.flip != (e.name == "hinge_moment_sign") for e, _ in probes]
    sims = problem.simulate(params, flips)
    r = cur.residual
    # Project out what the model's own parameters can still explain; one pinned on a bound cannot
    # move that way (a compliance held at zero by a reversed load), so its column stays in.
    movable = [j for j, name in enumerate(cur.jac_free) if not on_bound(getattr(cur.params, name), FREE[name])]
    jac = cur.jacobian[:, movable]
    q = np.linalg.qr(jac, mode="reduced")[0] if jac.shape[1] else np.zeros((r.size, 0))
    r_perp = r - q @ (q.T @ r)
    r_norm = float(np.linalg.norm(r_perp))
    room = excess(problem, r)
    best: dict[str, Candidate] = {}
    for (effect, value), sim in zip(probes, sims, strict=True):
        s = r - problem.weighted_residual(sim)  # the change the effect makes to the model
        s_perp = s - q @ (q.T @ s)
        ss = float(np.dot(s_perp, s_perp))
        rs = float(np.dot(r_perp, s_perp))
        if not (math.isfinite(ss) and math.isfinite(rs)) or ss <= 1e-12 or r_norm == 0.0:
            continue  # a probe whose run diverged (or changes nothing) says nothing of where to start
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
        elif len(value) == 1 and not effect.measured:  # a single stage switched on: scaled to what the residual asks
            start = {f: v * min(max(beta, 0.3), 3.0) for f, v in value.items()}
        step = beta * s_perp
        shares = [float(2.0 * np.dot(rb, sb) - np.dot(sb, sb)) / e
                  for rb, sb, e in zip(blocks(problem, r_perp), blocks(problem, step), room, strict=True)]
        cand = Candidate(effect, start, flip, rs * rs / ss, rs / (r_norm * math.sqrt(ss)), max(shares))
        if effect.key not in best or cand.score > best[effect.key].score:
            best[effect.key] = cand
    return sorted(best.values(), key=lambda c: -c.score)

