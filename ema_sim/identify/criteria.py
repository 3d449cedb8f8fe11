"""When an effect pays for itself: the information criteria, the margins, the physical checks, no trade.

A candidate's fit is accepted only when

* the information criteria agree (ΔBIC ≤ :data:`MAX_DELTA_BIC` and partial F ≥ :data:`MIN_PARTIAL_F`), *and*
* it removes at least :data:`MIN_EXCESS_SHARE` of the error variance left above the noise floor on some
  output, *and* at least :data:`MIN_NOISE_SHARE` of the noise variance (with 10⁵ samples the criteria alone
  would take sub-sample timing shifts and integration error for effects), *and* far more than the
  simulator's own error, *and*
* no output ends worse than the baseline or the reference leave it (:mod:`ema_sim.identify.stages`), *and*
* its fitted value means something physical (a delay of at least one sample, a rate limit that binds, a
  positive compliance...), sits inside its range and is determined by the record.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import replace

import numpy as np

from ema_sim.identify.effects import FREE, KEYS, Context, Effect, Free
from ema_sim.identify.fit import TINY, Fit, rms
from ema_sim.identify.outcome import Verdict
from ema_sim.identify.problem import Problem
from ema_sim.identify.stages import trade, worse
from ema_sim.models.second_order import SecondOrderParams

MIN_EXCESS_SHARE = 0.1
MIN_NOISE_SHARE = 0.05
MAX_DELTA_BIC = -10.0
MIN_PARTIAL_F = 20.0
DONE_EXCESS = 0.02
"""Stop when the weighted error variance is within 2 % of the noise floor."""
NOT_DETERMINED = 0.25
"""An effect whose own parameter's one-sigma uncertainty exceeds this share of its value is not accepted."""


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


def on_bound(value: float, free: Free) -> bool:
    """Whether a fitted value sits on a bound of its range.

    Parameters
    ----------
    value : float
        The value.
    free : Free
        The parameter's range.

    Returns
    -------
    bool
        On a bound (within a millionth of the range).
    """
    span = free.high - free.low
    return value <= free.low + 1e-6 * span or value >= free.high - 1e-6 * span


def blocks(problem: Problem, vector: np.ndarray) -> list[np.ndarray]:
    """A stacked residual split back into its outputs.

    Parameters
    ----------
    problem : Problem
        The record as fitted.
    vector : numpy.ndarray
        The stacked residual (outputs one after the other).

    Returns
    -------
    list of numpy.ndarray
        One block per output.
    """
    n = int(problem.mask.sum())
    return [vector[k * n:(k + 1) * n] for k in range(len(problem.outputs))]


def excess(problem: Problem, residual: np.ndarray) -> list[float]:
    """Each output's weighted error above its noise floor (at least 5 % of the noise, so never zero).

    Parameters
    ----------
    problem : Problem
        The record as fitted.
    residual : numpy.ndarray
        The stacked weighted residual.

    Returns
    -------
    list of float
        One sum of squares per output.
    """
    return [max(float(np.dot(b, b)) - b.size, MIN_NOISE_SHARE * b.size) for b in blocks(problem, residual)]


def bic(problem: Problem, f: Fit) -> float:
    """The fit's Bayesian information criterion on the record (its free parameters counted).

    Parameters
    ----------
    problem : Problem
        The record as fitted.
    f : Fit
        The fit.

    Returns
    -------
    float
        n·log(RSS) + p·log(n).
    """
    return problem.n_fit * math.log(max(f.rss, TINY)) + len(f.free) * math.log(problem.n_fit)


def gain(problem: Problem, cur: Fit, new: Fit, q: int, sim_err: dict[str, float]
         ) -> tuple[str, float, float, float, float]:
    """Whether going from ``cur`` to ``new`` (``q`` more parameters) pays.

    Parameters
    ----------
    problem : Problem
        The record as fitted.
    cur : Fit
        The model before.
    new : Fit
        The model after.
    q : int
        Parameters added.
    sim_err : dict
        The simulator's own error per output.

    Returns
    -------
    tuple
        The reason it does not ("" when it does), ΔBIC, partial F, the largest share of one output's error
        above its floor removed, and the share of the noise variance removed.
    """
    n = problem.n_fit
    rss0, rss1 = cur.rss, new.rss
    p1 = len(new.free)
    delta_bic = n * math.log(max(rss1, TINY) / max(rss0, TINY)) + q * math.log(n)
    partial_f = ((rss0 - rss1) / max(q, 1)) / (max(rss1, TINY) / max(n - p1, 1))
    # The margin is judged per output: an effect that removes a clear share of one output's error
    # above its noise floor counts even when the other output's error is larger.
    before = blocks(problem, cur.residual)
    after = blocks(problem, new.residual)
    drops = [(float(np.dot(b, b)) - float(np.dot(a, a))) / b.size for b, a in zip(before, after, strict=True)]
    excess_share = max(d * b.size / e for d, b, e in zip(drops, before, excess(problem, cur.residual), strict=True))
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


def judge(problem: Problem, cur: Fit, new: Fit, effect: Effect, ctx: Context, sim_err: dict[str, float],
          limit: Mapping[str, float]) -> Verdict:
    """Whether ``new`` (``cur`` with ``effect`` added) is accepted, and why not (module docstring).

    Parameters
    ----------
    problem : Problem
        The record as fitted.
    cur : Fit
        The model before.
    new : Fit
        The model with the effect.
    effect : Effect
        The effect.
    ctx : Context
        What the current model does on the record.
    sim_err : dict
        The simulator's own error per output.
    limit : mapping
        Per output, the rms no model may exceed (the baseline's and the reference's,
        :func:`ema_sim.identify.stages.ceiling`).

    Returns
    -------
    Verdict
        Accepted, or the reason it is not.
    """
    q = len(new.free) - len(cur.free) + sum(1 for f in effect.fields if f not in new.free)  # a swap counts less
    reason, delta_bic, partial_f, excess_share, drop = gain(problem, cur, new, q, sim_err)
    values = {f: float(getattr(new.params, f)) for f in effect.fields}
    value = values[effect.fields[0]] if values else None
    after = rms(problem, new)
    if not reason and worse(after, limit):
        reason = trade(after, rms(problem, cur), limit)
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
