"""A parameter's uncertainty on one window of a record, for the test of whether the record changed.

The coloured-residual σ a fit gives (:func:`ema_sim.identify.fit.covariance`) counts what the model leaves
as noise independent of the parameters, which averages out over the samples. A model that misses structure
leaves a misfit instead, and a misfit pulls a parameter by what the record excites there: a dead band fitted
as a threshold pulls the delay one way on small steps and another on large ones. Two windows of an
unchanged actuator then give two equivalents, not one value twice. What the misfit does is measured on the
window itself: the scatter of the fit's score over :data:`STRETCHES` stretches of it
(:func:`ema_sim.identify.fit.stretch_covariance`), and the share of its error above the noise floor:

* **windows of one excitation** (a repeating command cut at its period): the misfit pulls each window
  alike, so their difference keeps only what differs inside a window: σ is the larger of the coloured
  σ and the stretch σ (the σ of the window's estimate from its stretches' scatter);
* **windows of unlike excitation** (any other record): one window can differ from another by what the
  misfit pulls one stretch from another, S·σ_stretch² (a stretch's own estimate scatters that much), of
  which the share m = 1 − 1/r² of the window's mean square weighted error r² is misfit, not noise. The
  actuator and the model are one over the record when nothing changed, so what the misfit does is one
  too: the largest m·S·σ_stretch² of the windows (a window whose stretches happen to be excited alike
  shows less of it than it suffers) is added to every window's coloured variance. A model at its noise
  floor (r ≈ 1) keeps the coloured σ, so a change of a well-fitted actuator is found as sharply as before.

A parameter found by a grid search (Kb and the offset behind a quantizer,
:func:`ema_sim.identify.stepwise.fit_model`) has no σ at all: its ± is the grid's finest spacing, a
resolution; :func:`grid_searched` says which, and the change test leaves them untested.
"""

from __future__ import annotations

import math

import numpy as np

from ema_sim.identify.effects import FREE
from ema_sim.identify.fit import Fit, stretch_covariance
from ema_sim.identify.grid_fit import PRE_QUANTIZER
from ema_sim.identify.problem import Problem
from ema_sim.models.second_order import SecondOrderParams

STRETCHES = 8
"""Stretches of a window whose scores' scatter measures what the model's misfit does to an estimate."""


def grid_searched(params: SecondOrderParams, name: str) -> bool:
    """Whether ``name`` is found by a grid search (behind a quantizer): its ± the grid's spacing, no σ.

    Parameters
    ----------
    params : SecondOrderParams
        The fitted parameters.
    name : str
        The model parameter.
    """
    return params.quantization_deg > 0.0 and name in PRE_QUANTIZER


def window_sigmas(subs: list[Problem], fits: list[Fit], name: str, alike: bool) -> list[float]:
    """Each window's σ of ``name``, one that covers the model's misfit as well as the noise (module docstring).

    Parameters
    ----------
    subs : list of Problem
        The windows.
    fits : list of Fit
        Their fits.
    name : str
        The model parameter.
    alike : bool
        The windows carry the same excitation (periods of a repeating command).

    Returns
    -------
    list of float
        One sigma per window; inf where the window cannot move it; the grid's spacing for a grid-searched one
        (untested).
    """
    coloured = [float(f.sigma.get(name, math.inf)) for f in fits]
    if any(grid_searched(f.params, name) or name not in f.jac_free for f in fits):
        return coloured
    stretch, misfit = [], []
    for sub, f in zip(subs, fits, strict=True):
        k, i = len(sub.outputs), f.jac_free.index(name)
        var = float(stretch_covariance(f.residual, f.jacobian, f.residual.size // k, k, STRETCHES)[i, i])
        stretch.append(math.sqrt(max(var, 0.0)) * abs(FREE[name].derivative(float(getattr(f.params, name)))))
        misfit.append(max(0.0, 1.0 - 1.0 / max(float(np.mean(f.residual**2)), 1e-300)) * STRETCHES * stretch[-1] ** 2)
    if alike:
        return [max(c, s) for c, s in zip(coloured, stretch, strict=True)]
    seen = [m for m in misfit if math.isfinite(m)]  # a window that cannot move it says nothing of the misfit
    return [math.sqrt(c**2 + max(seen, default=0.0)) for c in coloured]
