"""The model fitted to a record, the quantizer's Kb and offset included: smooth least squares and grids.

A quantizer makes the cost piecewise flat in the parameters before it (the command gain error Kb and the
offset), so gradients cannot move them: :func:`fit_model` fits the smooth parameters with them held, searches
them on coordinate grids (widened while the best point is at an edge), and fits the smooth ones again. A round
of the effect search fits its candidates without the grids and to a looser tolerance (they start from a model
whose grids ran); :func:`finish` makes the accepted one a full fit. Every fit here ends no worse than where it
started (:func:`no_worse`).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ema_sim.identify.effects import FREE
from ema_sim.identify.fit import FTOL, Fit, evaluate, fit
from ema_sim.identify.problem import Problem
from ema_sim.models.arrays import FloatArray
from ema_sim.models.second_order import SecondOrderParams

CANDIDATE_FTOL = 1e-4
"""Where a round's candidate fits stop (the relative drop in cost): far finer than what decides between them (a
BIC of ten is a share ten over the fitted samples), and the accepted one is converged fully (:func:`finish`)."""
PRE_QUANTIZER = ("kb", "offset_deg")
"""Parameters acting before the quantizer: the cost is piecewise flat in them once a step is on."""
WIDEN = 3.0
MAX_WIDEN = 6
"""A pre-quantizer grid whose best point is at its edge is moved there and widened this many times, at most so often
(:func:`_grids`)."""
MAX_CYCLES = 3
"""Most rounds of grids and smooth fit after a grid widened (:func:`_grid_search`)."""


def fit_model(problem: Problem, base: SecondOrderParams, free: tuple[str, ...] | list[str], *, flip: bool,
              grids: bool = True) -> Fit:
    """:func:`fit`, except that with a quantizer on, Kb and offset are found by batched grid searches.

    The quantizer makes the cost piecewise flat in the parameters before it, so gradients cannot
    move them: the smooth parameters are fitted with them held, then a coordinate search (a grid of
    11 over ±half a step, then one five times finer, for each) picks them, then the smooth
    parameters are fitted again (unless the grids found nothing that changes the outputs: the smooth fit
    then stands where it converged). Without ``grids`` (a round's candidate fits, which start from a model
    whose grids ran) they stay held where ``base`` has them and the fit stops at :data:`CANDIDATE_FTOL`; the
    accepted candidate's grids and full convergence are :func:`finish`'s.

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
    grids : bool
        A full fit: Kb and offset searched on their grids, converged to :data:`~ema_sim.identify.fit.FTOL`
        (else Kb and offset held, with the grid's resolution as their ±, and converged to
        :data:`CANDIDATE_FTOL`).
    """
    q = base.quantization_deg
    held = [f for f in free if f in PRE_QUANTIZER]
    if q <= 0.0 or not held:
        return fit(problem, base, free, flip=flip)
    ftol = FTOL if grids else CANDIDATE_FTOL
    smooth = fit(problem, base, [f for f in free if f not in PRE_QUANTIZER], flip=flip, ftol=ftol)
    new = _grid_search(problem, smooth, free, held) if grids else _held(problem, smooth, free, held)
    return no_worse(problem, base, free, new)


def finish(problem: Problem, new: Fit) -> Fit:
    """An accepted candidate's fit (:func:`fit_model` without grids) made a full one, never worse.

    Its smooth parameters converged to :data:`~ema_sim.identify.fit.FTOL` from where the candidate's fit
    stopped, and with a quantizer on, Kb and offset searched on their grids and the smooth fit redone.

    Parameters
    ----------
    problem : Problem
        The record as fitted.
    new : Fit
        The candidate's fit.

    Returns
    -------
    Fit
        The full fit.
    """
    held = [f for f in new.free if f in PRE_QUANTIZER] if new.params.quantization_deg > 0.0 else []
    smooth = fit(problem, new.params, [f for f in new.free if f not in held], flip=new.flip)
    done = _grid_search(problem, smooth, new.free, held) if held else smooth
    return done if done.rss <= new.rss else new


def _half_steps(problem: Problem, q: float) -> dict[str, float]:
    """Half a quantizer step in offset and in Kb (at the record's largest command): each grid's span."""
    u_max = max(float(np.max(np.abs(problem.data.command_deg))), 1e-6)
    return {"offset_deg": 0.5 * q, "kb": 0.5 * q / u_max}


def _held(problem: Problem, smooth: Fit, free: tuple[str, ...] | list[str], held: list[str]) -> Fit:
    """The smooth fit as a fit of every parameter in ``free``, those before the quantizer held at their start."""
    half = _half_steps(problem, smooth.params.quantization_deg)
    sigma = dict(smooth.sigma)
    for name in held:
        sigma[name] = half[name] * 0.2 / 10.0  # the finest grid spacing: the resolution the search has
    return Fit(smooth.params, smooth.flip, tuple(free), smooth.sim, smooth.residual, smooth.jacobian, sigma,
               smooth.jac_free)


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


def _grid_search(problem: Problem, first: Fit, free: tuple[str, ...] | list[str], held: list[str]) -> Fit:
    """Coordinate grids on ``held`` from a smooth fit, then the smooth parameters fitted again.

    When the grids had to widen (a large move), the smooth parameters were fitted far from where Kb and offset
    ended: grids and smooth fit alternate again, up to :data:`MAX_CYCLES` times, until the grids stay put.
    """
    smooth = [f for f in free if f not in PRE_QUANTIZER]
    cur = first
    for _ in range(MAX_CYCLES):
        params, outputs, widened = _grids(problem, cur, held)
        # A grid that found no other outputs leaves the smooth fit where it converged: fitting again would restart
        # it there.
        if np.array_equal(outputs, cur.sim):  # the grid's point, which runs the same as the smooth fit's
            return _held(problem, replace(cur, params=params), free, held)
        cur = fit(problem, params, smooth, flip=cur.flip)
        if not widened:
            break
    return _held(problem, cur, free, held)


def _grids(problem: Problem, first: Fit, held: list[str]) -> tuple[SecondOrderParams, FloatArray, bool]:
    """The coordinate grids on ``held`` from ``first``: where they end, its outputs, and whether one widened.

    Each parameter's grid of 11 spans ±half a step; while its best point is at an edge, and better there than
    anywhere inside, the grid is moved there and widened :data:`WIDEN` times (at most :data:`MAX_WIDEN` times:
    a gain error of a few per cent is many half steps away), the parameters in turn until none widened; then each
    grid is narrowed fivefold until it is five times finer than half a step.
    """
    flip = first.flip
    half = _half_steps(problem, first.params.quantization_deg)
    params, outputs = first.params, first.sim
    span = dict(half)

    def search(name: str) -> bool:
        """One grid on ``name`` about its value; whether its best point is at an edge and better than inside."""
        nonlocal params, outputs
        centre = getattr(params, name)
        low, high = FREE[name].low, FREE[name].high
        grid = [params.replace(**{name: min(max(centre + d, low), high)})
                for d in np.linspace(-1.0, 1.0, 11) * span[name]]
        sims = problem.simulate(grid, [flip] * len(grid))
        costs = [float(np.dot(r, r)) for r in (problem.weighted_residual(x) for x in sims)]
        best = int(np.argmin(costs))
        params, outputs = grid[best], sims[best]
        return best in (0, len(grid) - 1) and costs[best] < min(costs[1:-1])

    moved = False
    for _ in range(MAX_WIDEN):  # passes over the parameters while one of them widened
        widened = False
        for name in held:
            for _ in range(MAX_WIDEN):
                if not search(name):
                    break
                span[name] *= WIDEN
                widened = moved = True
        if not widened:
            break
    for name in held:  # the finer grids (when nothing widened: one, a fifth as wide)
        while span[name] > 0.2 * half[name] * (1.0 + 1e-9):
            span[name] = max(0.2 * span[name], 0.2 * half[name])
            search(name)
    return params, outputs, moved
