"""The stamps' jitter in the fit: the floor it sets, weighed as the logger's error, absorbed by no effect.

The record is fitted on its own stamps (:mod:`ema_sim.identify.record`). When the stamps jitter about a
uniform grid (:mod:`ema_sim.analysis.records.stamps`) either the stamps are off the instants the outputs
were sampled at, and every model leaves ``rate × δt`` on the output, or the instants jittered and the
stamps follow them, and no model does. The declared model's residual tells which: regressed on the
output's rate squared (``e² ≈ σ² + σ_t²·rate²``), it shows a timing error ``σ_t``. When that error is the
stamps' own scatter (within a factor :data:`AGREE` of it) and explains the residual's level (the residual
divided by ``√(σ² + (rate·scatter)²)`` has an rms of at most :data:`EXPLAINED`), the stamps are what is off:
each sample is weighed by its floor with the stamps' scatter in it
(:meth:`~ema_sim.identify.problem.Problem.set_timing`), so no effect of the vocabulary pays for absorbing
the logger's timing (a rate limit that clips the fastest moves, where that error is largest). The floor
is said either way, with what the residual showed.
"""

from __future__ import annotations

import math

import numpy as np

from ema_sim.analysis.records.stamps import Stamps, output_rate, timing_error
from ema_sim.identify.fit import Fit
from ema_sim.identify.problem import Problem

AGREE = 2.0
"""The residual's timing error and the stamps' scatter agree within this factor either way."""
EXPLAINED = 1.5
"""The residual over its floor with the stamps' scatter in it: at most this rms when the scatter explains it."""
NEGLIGIBLE = 0.5
"""A jitter floor (rms over the record) under this share of the noise floor is not weighed."""


def weigh(problem: Problem, stamps: Stamps, fit: Fit, unit: str = "deg") -> tuple[bool, str]:
    """Whether the stamps' jitter is the residual's (then every sample is weighed with it), and the sentence.

    Parameters
    ----------
    problem : Problem
        The record as fitted (its weights set when the jitter is the residual's).
    stamps : Stamps
        The record's stamps.
    fit : Fit
        The declared model's fit (the baseline).
    unit : str
        The output's unit.

    Returns
    -------
    tuple
        True when the weights were set, and the statement for the report ("" for uniform stamps).
    """
    if not stamps.jitters:
        return False, ""
    rates = {o: output_rate(stamps, problem.observed[o]) for o in problem.outputs}
    o = problem.outputs[0]
    sigma = problem.sigma_deg[o]
    rate = rates[o][problem.mask]
    head = stamps.statement(rate, unit)
    floor_rms, _ = stamps.floor(rate)
    if floor_rms < NEGLIGIBLE * sigma:
        return False, f"{head}; under {NEGLIGIBLE:g}× the noise floor ({sigma:.3g}), it is not weighed"
    e = problem.errors_deg(fit.sim)[o]
    sigma_t = timing_error(e, sigma, rate)
    level = float(np.sqrt(np.mean(e**2 / (sigma**2 + (stamps.scatter_s * rate) ** 2))))
    agree = sigma_t > 0.0 and 1.0 / AGREE <= sigma_t / stamps.scatter_s <= AGREE
    if not agree or level > EXPLAINED or not math.isfinite(level):
        shown = f"{1e3 * sigma_t:.2g} ms" if sigma_t > 0.0 else "none"
        return False, (f"{head}; the declared model's residual shows a timing error of {shown} (its error against "
                       f"rate²), {'not the stamps’ scatter' if not agree else f'and {level:.2g}× its floor with it'}: "
                       "the stamps are taken to follow the instants, the samples weighed by the noise floor alone")
    problem.set_timing(stamps.scatter_s, rates)
    return True, (f"{head}; the declared model's residual shows it (a timing error of {1e3 * sigma_t:.2g} ms against "
                  f"the stamps' {1e3 * stamps.scatter_s:.2g} ms; {level:.2g}× the floor with it): the stamps are off "
                  "the instants, so each sample is weighed by its floor with rate × jitter in it and no effect is "
                  "added to absorb the logger's timing")
