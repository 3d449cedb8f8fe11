"""Beyond the vocabulary's equivalents: the declared model as it is, and the servo's physics (section 4.2.5).

A declared HOAD2/HOAD3 has its physical parameters fitted (:mod:`ema_sim.identify.physical`); any other
declared model whose final fit leaves more than :data:`EQUIVALENT_EXCESS` times the noise on a record of
LVDT and surface is escalated to :data:`ESCALATE_TO`'s physics, and the physics is kept when it pays and
trades no output for another (:mod:`ema_sim.identify.stages`): the declared model with its effects then
stays in the report beside it as the equivalent. A high-order or linear declared model that fits better
as it is than its fitted equivalent is the final model as declared.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from ema_sim.identify.criteria import MIN_EXCESS_SHARE
from ema_sim.identify.fit import TINY, Fit, rms
from ema_sim.identify.outcome import AS_DECLARED, AsDeclared, Identification, Removal
from ema_sim.identify.physical import ESCALATE_TO, PhysicalFit
from ema_sim.identify.problem import EQUIVALENT_EXCESS, IN_LOOP_SHARE, Problem, in_loop_share
from ema_sim.identify.stages import trade, worse

__all__ = ["ESCALATE_TO", "adopt_physical", "escalation", "keep_declared", "label", "within"]


def within(problem: Problem, rms_deg: Mapping[str, float]) -> bool:
    """Every output within :data:`EQUIVALENT_EXCESS` times its noise floor.

    Parameters
    ----------
    problem : Problem
        The record as fitted.
    rms_deg : mapping
        Output → rms.

    Returns
    -------
    bool
        Within on every output.
    """
    return all(v <= EQUIVALENT_EXCESS * problem.sigma_deg[o] for o, v in rms_deg.items())


def escalation(problem: Problem, result: Identification) -> str:
    """Why the servo's own structure must be fitted (empty: it need not be).

    A declared model (the second-order family, HOAC1, HOALM, LOES) whose final fit, every effect that paid
    included, leaves more than :data:`EQUIVALENT_EXCESS` times the noise on a record of both the LVDT and
    the surface (an installed actuator's record, as HOAD3 describes one) has run out of vocabulary: its
    effects are equivalents. Where the error is (the share of the surface's the position's carries) is
    said, not required: HOAD3 carries the drive inside the loop and the linkage outside it.

    Parameters
    ----------
    problem : Problem
        The record as fitted.
    result : Identification
        The identification so far.

    Returns
    -------
    str
        Why to escalate (empty: not).
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


def adopt_physical(problem: Problem, result: Identification, pf: PhysicalFit, limit: Mapping[str, float]
                   ) -> tuple[str, str]:
    """The fitted physical parameters become the final model when they fit better (escalated: when they pay).

    They are never kept when they leave an output worse than ``limit`` (a trade of the LVDT for the surface).

    Parameters
    ----------
    problem : Problem
        The record as fitted.
    result : Identification
        The identification so far (its final model is replaced when the physics is kept).
    pf : PhysicalFit
        The physical fit.
    limit : mapping
        Per output, the rms no model may exceed.

    Returns
    -------
    tuple of str
        The stage's status (``kept`` or ``not kept``) and why.
    """
    cur = result.final
    excess = max(cur.rss - problem.n_fit, TINY)
    gain = (cur.rss - pf.rss) / excess
    text = ", ".join(f"{o} {v:.4g}°" for o, v in pf.rms_deg.items())
    share = f"{100 * min(gain, 1.0):.1f} %" if gain >= 0.0 else "none"
    head = f"{pf.model} with its physical parameters fitted ({pf.simulations} runs, {pf.elapsed_s:.1f} s): rms {text}"
    if pf.screen and not pf.stopped:
        head += f" ({pf.screen})"
    if pf.stopped:
        why = f"{head}; not kept, stopped early: {pf.stopped}"
        result.notes.append(why)
        return "not kept", why
    if pf.rss >= cur.rss or (result.escalated and gain < MIN_EXCESS_SHARE):
        why = f"{head}; not kept: it removes {share} of the error above the noise floor that {label(result)} left"
        result.notes.append(why)
        return "not kept", why
    if worse(pf.rms_deg, limit):
        why = f"{head}; {trade(pf.rms_deg, rms(problem, cur), limit)}"
        result.notes.append(why)
        result.warnings.append(why)
        return "not kept", why
    held = f"; held at declared values (the record cannot move them): {', '.join(pf.held)}" if pf.held else ""
    why = f"{head}; it removes {share} of the error above the noise floor that {label(result)} left{held}"
    result.notes.append(why)
    result.physical = pf
    result.equivalent, result.equivalent_model = cur, label(result)
    result.final = Fit(cur.params, False, (), np.asarray(pf.sim, dtype=float), pf.residual,
                       np.zeros((pf.residual.size, 0)), {}, ())
    result.final_model = f"{pf.model} (physical parameters fitted)"
    return "kept", why


def label(result: Identification) -> str:
    """The final model so far, in words (the one a physical fit would replace).

    Parameters
    ----------
    result : Identification
        The identification so far.

    Returns
    -------
    str
        ``loada + compliance + …``, or the final model's own name.
    """
    return result.final_model or " + ".join([result.model, *(s.effect for s in result.steps)])


def keep_declared(problem: Problem, result: Identification, as_declared: AsDeclared, limit: Mapping[str, float]
                  ) -> tuple[str, str]:
    """A declared model that fits better as it is than anything fitted through its equivalent is the final model.

    Parameters
    ----------
    problem : Problem
        The record as fitted.
    result : Identification
        The identification so far (its final model is replaced when the declared one is kept).
    as_declared : AsDeclared
        The declared model's own run on the record.
    limit : mapping
        Per output, the rms no model may exceed.

    Returns
    -------
    tuple of str
        The stage's status and why.
    """
    r = problem.weighted_residual(as_declared.sim)
    rss = float(np.dot(r, r))
    if rss > result.final.rss:
        return "not kept", (f"the declared {result.model} as it is fits worse than its fitted equivalent (weighted "
                            f"error ×{rss / max(result.final.rss, TINY):.3g})")
    if worse(as_declared.rms_deg, limit):
        traded = trade(as_declared.rms_deg, rms(problem, result.final), limit)
        return "not kept", f"the declared {result.model} as it is: {traded}"
    why = (f"the declared {result.model} as it is fits better than its fitted second-order-family equivalent "
           f"(weighted error ×{result.final.rss / max(rss, TINY):.3g})")
    result.removed += [Removal(s.effect, s.where, dict(s.params), why) for s in result.steps]
    result.steps.clear()
    result.final = Fit(result.final.params, False, (), as_declared.sim, r, np.zeros((r.size, 0)), {}, ())
    result.final_model = f"{result.model}{AS_DECLARED}"
    return "kept", why
