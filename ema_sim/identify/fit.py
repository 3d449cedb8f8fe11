"""Output-error least squares on a :class:`~ema_sim.identify.problem.Problem`.

The model is simulated with the measured inputs and its parameters are moved until the weighted
output error is least (trust-region reflective, bounds in scaled coordinates). The Jacobian is
finite differences computed as one batched simulation, so a fit of p parameters costs one compiled
call per iteration. Parameter covariance is corrected for coloured residuals the way Morelli and
Klein do it: (JᵀJ)⁻¹·JᵀRJ·(JᵀJ)⁻¹ with R the residual autocovariance.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import least_squares
from scipy.signal import fftconvolve

from ema_sim.analysis.estimation.noise import autocovariance
from ema_sim.identify.effects import FREE, Free
from ema_sim.identify.problem import Problem
from ema_sim.models.second_order import SecondOrderParams

FloatArray = NDArray[np.float64]
FD_STEP = 1e-4
"""Finite-difference step in scaled coordinates (the simulator is smooth to ~1e-7°)."""
FTOL = 1e-6
"""A fit stops once a step removes less than this share of its weighted error. A millionth of the error moves a
BIC by n·1e-6 (0.06 on 30 s of two outputs at 1 kHz, 0.36 on 180 s), far below any decision the search takes on
one (10), and below the 5 % of the noise variance a stage counts as a change; the fits of the 30 s HOAD3 record
spent about half their runs on the last 1e-6 of their error before (measured, 32 fits)."""
DIVERGED = 1e6
"""What a non-finite weighted residual entry counts as: a run that diverged is a bad step for the optimiser
(it backs off), not a crash."""


TINY = 1e-300
"""Floor on a residual sum of squares in a ratio (a noise-free record can be matched exactly)."""


def finite(residual: FloatArray) -> FloatArray:
    """``residual`` with every non-finite entry replaced by :data:`DIVERGED`.

    Parameters
    ----------
    residual : numpy.ndarray
        A weighted residual.

    Returns
    -------
    numpy.ndarray
        The same, finite.
    """
    if np.all(np.isfinite(residual)):
        return residual
    return np.where(np.isfinite(residual), residual, DIVERGED)
COVARIANCE_LAGS = 200
BATCHES = 4
"""Stretches of the record the batch-means uncertainty compares (:func:`batch_sigma`)."""


@dataclass(frozen=True)
class Fit:
    """A fitted parameter set and what it leaves."""

    params: SecondOrderParams
    flip: bool
    free: tuple[str, ...]
    sim: FloatArray
    """The model's outputs on the record ``(samples, 3)``."""
    residual: FloatArray
    """Weighted residual at the optimum."""
    jacobian: FloatArray
    """d(model)/dx, weighted, in scaled coordinates (columns follow ``free``)."""
    sigma: dict[str, float]
    """One-sigma uncertainty of each free parameter, coloured-residual corrected."""
    jac_free: tuple[str, ...] = ()
    """The parameters the Jacobian's columns belong to (``free`` unless some were grid-searched)."""

    @property
    def rss(self) -> float:
        """Weighted residual sum of squares."""
        return float(np.dot(self.residual, self.residual))


class _Objective:
    """Residual and batched Jacobian of one fit, sharing simulations between the two."""

    def __init__(self, problem: Problem, base: SecondOrderParams, free: Sequence[Free], flip: bool) -> None:
        self.problem = problem
        self.base = base
        self.free = list(free)
        self.flip = flip
        self._cache: tuple[bytes, FloatArray] | None = None
        self._jac: tuple[bytes, FloatArray] | None = None
        """The last simulation and the last Jacobian, each with the point it was made at: the optimiser's
        final point has both already, so the fit's summary reuses them instead of simulating again."""

    def params(self, x: FloatArray) -> SecondOrderParams:
        return self.base.replace(**{f.field: f.from_x(float(v)) for f, v in zip(self.free, x, strict=True)})

    def _simulate(self, xs: Sequence[FloatArray]) -> FloatArray:
        return self.problem.simulate([self.params(x) for x in xs], [self.flip] * len(xs))

    def sim(self, x: FloatArray) -> FloatArray:
        key = x.tobytes()
        if self._cache is None or self._cache[0] != key:
            self._cache = (key, self._simulate([x])[0])
        return self._cache[1]

    def residual(self, x: FloatArray) -> FloatArray:
        return finite(self.problem.weighted_residual(self.sim(x)))

    def jacobian(self, x: FloatArray) -> FloatArray:
        key = x.tobytes()
        if self._jac is None or self._jac[0] != key:
            self._jac = (key, self._jacobian(x))
        return self._jac[1]

    def _jacobian(self, x: FloatArray) -> FloatArray:
        _, hi = zip(*(f.x_bounds() for f in self.free), strict=True)
        points, steps = difference_points(x, np.asarray(hi, dtype=float))
        sims = self._simulate(points)
        r0 = self.residual(x)
        cols = [(finite(self.problem.weighted_residual(s)) - r0) / h for s, h in zip(sims, steps, strict=True)]
        # residual = measured − model, so d(model)/dx = −d(residual)/dx
        return -np.column_stack(cols) if cols else np.zeros((r0.size, 0))


def difference_points(x: FloatArray, hi: FloatArray) -> tuple[list[FloatArray], list[float]]:
    """The points of a forward-difference Jacobian at ``x``, and the step taken on each coordinate.

    Each coordinate is stepped by :data:`FD_STEP`, backwards where the step would cross its upper bound.

    Parameters
    ----------
    x : numpy.ndarray
        The optimiser's coordinates.
    hi : numpy.ndarray
        Their upper bounds.

    Returns
    -------
    tuple
        One point per coordinate, and the step taken on it.
    """
    points, steps = [], []
    for j in range(x.size):
        h = FD_STEP if x[j] + FD_STEP <= hi[j] else -FD_STEP
        xp = x.copy()
        xp[j] += h
        points.append(xp)
        steps.append(h)
    return points, steps


def fit(
    problem: Problem,
    base: SecondOrderParams,
    free_fields: Sequence[str],
    *,
    flip: bool = False,
    max_nfev: int = 40,
    capped: bool = True,
    ftol: float = FTOL,
) -> Fit:
    """Fit ``free_fields`` of ``base`` to the record; everything else stays as in ``base``.

    Parameters
    ----------
    problem : Problem
        The record as fitted.
    base : SecondOrderParams
        The starting parameters (everything not fitted stays as here).
    free_fields : sequence of str
        The model parameters fitted.
    flip : bool
        Run with the hinge moment reversed (the hinge_moment_sign effect).
    max_nfev : int
        Most residual evaluations of the optimiser.
    capped : bool
        Keep the record's own bounds (:attr:`Problem.caps`); False asks how far the fit would go without them.
    ftol : float
        The relative drop in cost at which the optimiser stops.
    """
    free = [FREE[f].capped(problem.caps.get(f) if capped else None) for f in free_fields]
    obj = _Objective(problem, base, free, flip)
    x0 = np.array([f.to_x(getattr(base, f.field)) for f in free], dtype=float)
    if free:
        lo, hi = (np.array(b, dtype=float) for b in zip(*(f.x_bounds() for f in free), strict=True))
        x0 = np.clip(x0, lo + 1e-9 * (hi - lo), hi - 1e-9 * (hi - lo))
        res = least_squares(
            obj.residual, x0, jac=lambda x: -obj.jacobian(x), bounds=(lo, hi), method="trf",
            x_scale=1.0, max_nfev=max_nfev, xtol=1e-8, ftol=ftol, gtol=1e-10,
        )
        x = res.x
    else:
        x = x0
    return _at(obj, x, tuple(free_fields))


def evaluate(problem: Problem, params: SecondOrderParams, free_fields: Sequence[str], *, flip: bool = False) -> Fit:
    """The :class:`Fit` of ``params`` as they are (residual, Jacobian, uncertainty), without moving them.

    Parameters
    ----------
    problem : Problem
        The record as fitted.
    params : SecondOrderParams
        The parameters, as they are.
    free_fields : sequence of str
        The model parameters fitted.
    flip : bool
        Run with the hinge moment reversed (the hinge_moment_sign effect).
    """
    obj, x = _objective_at(problem, params, free_fields, flip)
    return _at(obj, x, tuple(free_fields))


def _objective_at(problem: Problem, params: SecondOrderParams, free_fields: Sequence[str],
                  flip: bool) -> tuple[_Objective, FloatArray]:
    """The objective of ``free_fields`` about ``params``, and the point ``params`` are at in its coordinates."""
    free = [FREE[f] for f in free_fields]
    return _Objective(problem, params, free, flip), np.array([f.to_x(getattr(params, f.field)) for f in free],
                                                             dtype=float)


def residual_only(problem: Problem, params: SecondOrderParams, free_fields: Sequence[str], *, flip: bool = False
                  ) -> Fit:
    """:func:`evaluate` without the Jacobian and the uncertainty: the model's own run, no more.

    For a caller that reads only what the model leaves (its residual), such as a test of whether an effect still pays.

    Parameters
    ----------
    problem : Problem
        The record as fitted.
    params : SecondOrderParams
        The parameters, as they are.
    free_fields : sequence of str
        The model parameters fitted.
    flip : bool
        Run with the hinge moment reversed (the hinge_moment_sign effect).
    """
    obj, x = _objective_at(problem, params, free_fields, flip)
    sim = obj.sim(x)
    residual = problem.weighted_residual(sim)
    return Fit(obj.params(x), flip, tuple(free_fields), sim, residual, np.zeros((residual.size, 0)), {}, ())


def _at(obj: _Objective, x: FloatArray, free_fields: tuple[str, ...]) -> Fit:
    problem, free = obj.problem, obj.free
    params = obj.params(x)
    sim = obj.sim(x)
    residual = problem.weighted_residual(sim)
    jac = obj.jacobian(x) if free else np.zeros((residual.size, 0))
    cov = covariance(problem, residual, jac)
    sigma = {}
    for i, f in enumerate(free):
        d = f.derivative(getattr(params, f.field))
        sigma[f.field] = float(math.sqrt(max(cov[i, i], 0.0)) * abs(d)) if np.isfinite(cov[i, i]) else math.inf
    return Fit(params, obj.flip, free_fields, sim, residual, jac, sigma, free_fields)


def covariance(problem: Problem, residual: FloatArray, jac: FloatArray) -> FloatArray:
    """Parameter covariance in the fit's scaled coordinates, corrected for coloured residuals per output block.

    Morelli and Klein: (JᵀJ)⁻¹·JᵀRJ·(JᵀJ)⁻¹ with R each output's residual autocovariance (Toeplitz,
    so R·J is a convolution). A singular JᵀJ (a parameter the record cannot move) gives infinities.

    Parameters
    ----------
    problem : Problem
        The record as fitted.
    residual : numpy.ndarray
        The stacked weighted residual (outputs one after the other).
    jac : numpy.ndarray
        Its Jacobian (one column per fitted parameter).
    """
    block = int(problem.mask.sum())
    blocks = range(len(problem.outputs))
    return block_covariance([residual[b * block:(b + 1) * block] for b in blocks],
                            [jac[b * block:(b + 1) * block] for b in blocks])


def block_covariance(residuals: Sequence[FloatArray], jacobians: Sequence[FloatArray]) -> FloatArray:
    """:func:`covariance` over given blocks (each output's residual and Jacobian rows, contiguous in time).

    Parameters
    ----------
    residuals : sequence of numpy.ndarray
        Each output block's residual, contiguous in time.
    jacobians : sequence of numpy.ndarray
        Each output block's Jacobian rows.
    """
    p = jacobians[0].shape[1]
    if p == 0:
        return np.zeros((0, 0))
    out = np.full((p, p), math.inf)
    norms = np.sqrt(sum((np.sum(j * j, axis=0) for j in jacobians), np.zeros(p)))
    moved = np.flatnonzero(norms > 1e-12 * max(float(norms.max()), 1e-300))
    if moved.size == 0:
        return out
    # a parameter the record cannot move at all (a zero column) is infinitely uncertain on its own:
    # the others keep the finite covariance of a fit without it
    jacobians = [j[:, moved] for j in jacobians]
    jtj = sum((j.T @ j for j in jacobians), np.zeros((moved.size, moved.size)))
    try:
        inv = np.linalg.inv(jtj)
    except np.linalg.LinAlgError:
        return out
    middle = np.zeros_like(jtj)
    for r, j in zip(residuals, jacobians, strict=True):
        acov = autocovariance(r, COVARIANCE_LAGS)
        kernel = np.concatenate([acov[:0:-1], acov])  # R is Toeplitz: R·J is a convolution
        rj = np.column_stack([fftconvolve(j[:, c], kernel, mode="same") for c in range(j.shape[1])])
        middle += j.T @ rj
    out[np.ix_(moved, moved)] = inv @ _nearest_psd(middle) @ inv
    return out


def batch_sigma(residual: FloatArray, jac: FloatArray, block: int, outputs: int) -> FloatArray:
    """Batch-means one-sigma: the spread of the Gauss-Newton steps on :data:`BATCHES` stretches, over √BATCHES.

    Each step starts from the optimum and sees one contiguous stretch of the record.

    The residual's covariance covers the noise the sensors add; a friction, a dead band or an integral
    also answer to the noise inside the loop (where the actuator happens to stick), which leaves the
    residual white yet moves the estimate from one stretch of the record to the next. The spread
    between stretches measures that; the larger of the two is the uncertainty.

    Parameters
    ----------
    residual : numpy.ndarray
        The stacked weighted residual at the optimum (outputs one after the other).
    jac : numpy.ndarray
        Its Jacobian (one column per fitted coordinate).
    block : int
        Rows per output.
    outputs : int
        Outputs stacked.
    """
    p = jac.shape[1]
    steps = []
    for rows in _stretch_rows(block, outputs, BATCHES):
        j, r = jac[rows], residual[rows]
        try:
            steps.append(np.linalg.lstsq(j, r, rcond=None)[0])
        except np.linalg.LinAlgError:
            return np.full(p, math.inf)
    return np.asarray(np.std(np.array(steps), axis=0, ddof=1) / math.sqrt(BATCHES), dtype=float)


def stretch_covariance(residual: FloatArray, jac: FloatArray, block: int, outputs: int, stretches: int = BATCHES
                       ) -> FloatArray:
    """Covariance in scaled coordinates from the scatter of the fit's score over contiguous stretches of the record.

    (JᵀJ)⁻¹·S·(JᵀJ)⁻¹ with S = k/(k−1)·Σ sₖsₖᵀ, sₖ = Jₖᵀrₖ the score of stretch k (they sum to nought at the
    optimum): the sandwich of :func:`covariance` with the residual's correlation taken over whole stretches
    instead of :data:`COVARIANCE_LAGS` samples. A misfit that pulls the estimate one way where the record
    excites one thing and another way elsewhere (the model lacks structure) scatters the scores, and shows
    here as the uncertainty it is; noise alone gives about :func:`covariance`. Unlike :func:`batch_sigma`
    it needs no stretch to determine every parameter on its own.

    Parameters
    ----------
    residual : numpy.ndarray
        The stacked weighted residual at the optimum (outputs one after the other).
    jac : numpy.ndarray
        Its Jacobian (one column per fitted coordinate).
    block : int
        Rows per output.
    outputs : int
        Outputs stacked.
    stretches : int
        Stretches the record is cut into (at least 2).
    """
    p = jac.shape[1]
    out = np.full((p, p), math.inf)
    norms = np.sqrt(np.sum(jac * jac, axis=0))
    moved = np.flatnonzero(norms > 1e-12 * max(float(norms.max(initial=0.0)), 1e-300))
    if moved.size == 0:  # as in block_covariance: a column the record cannot move is infinitely uncertain
        return out
    j = jac[:, moved]
    try:
        inv = np.linalg.inv(j.T @ j)
    except np.linalg.LinAlgError:
        return out
    scores = []
    for rows in _stretch_rows(block, outputs, stretches):
        scores.append(j[rows].T @ residual[rows])
    s = np.array(scores)
    out[np.ix_(moved, moved)] = inv @ (stretches / (stretches - 1) * (s.T @ s)) @ inv
    return out


def _stretch_rows(block: int, outputs: int, stretches: int) -> list[NDArray[np.int64]]:
    """The stacked residual's rows of each of ``stretches`` contiguous stretches of the record, every output's."""
    edges = np.linspace(0, block, stretches + 1).round().astype(int)
    return [np.concatenate([np.arange(o * block + a, o * block + b) for o in range(outputs)])
            for a, b in itertools.pairwise(edges)]


def _nearest_psd(m: FloatArray) -> FloatArray:
    """The symmetric positive semi-definite matrix nearest ``m`` (its negative eigenvalues set to zero).

    The coloured-residual middle term sums a truncated autocovariance, which need not be positive
    semi-definite: left as it is, a covariance built on it can give correlations beyond ±1.
    """
    sym = 0.5 * (m + m.T)
    if not np.all(np.isfinite(sym)):
        return sym
    w, v = np.linalg.eigh(sym)
    return np.asarray((v * np.clip(w, 0.0, None)) @ v.T, dtype=float)


def correlation(cov: FloatArray) -> FloatArray:
    """Correlations of a covariance matrix, within ±1 (NaN where a variance is zero or not finite).

    Parameters
    ----------
    cov : numpy.ndarray
        A covariance matrix (from :func:`covariance` or :func:`block_covariance`).

    Returns
    -------
    numpy.ndarray
        The correlation matrix, clipped to [-1, 1] against rounding.
    """
    d = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.outer(d, d)
    bad = ~np.isfinite(corr) | (np.outer(d, d) <= 0.0)
    return np.where(bad, np.nan, np.clip(corr, -1.0, 1.0))


def rms(problem: Problem, f: Fit) -> dict[str, float]:
    """Each output's rms error of a fit, over the fitted samples.

    Parameters
    ----------
    problem : Problem
        The record as fitted.
    f : Fit
        The fit.

    Returns
    -------
    dict
        Output → rms (deg).
    """
    return {o: float(np.sqrt(np.mean(e**2))) for o, e in problem.errors_deg(f.sim).items()}
