"""A discrete high-order model's physical parameters fitted to a record: the report's own loop (4.2.5).

Section 4.2.5 matched installed data by changing the high-order model's physical elements (the
figure-33 compliance curves, the delays), not by bolting equivalents onto a second-order model. This
fits those elements of HOAD2/HOAD3 (figure 30's drive with figure 32's or 33's gear train) to a record:

* **Delays** are scanned first, each on a wide grid (:data:`DELAY_STEP_S`) with the rest as declared,
  then fitted with everything else: the models blend the two whole steps a delay falls between
  (:func:`ema_sim.models.high_order.hoad.split_delay`), so the output moves smoothly with it.
* **The rest** (gains, limits, friction, PWM dead band, filter corner, damping, inertia, and one scale
  on each figure-33 curve family) are fitted in log coordinates by least squares with central
  differences of :data:`DIFF_STEP` (a friction or a dead band has no derivative of its own, only its
  effect on a 5 % wider or narrower element), the fit restarted while a restart pays.
* **Two more fits** start :data:`START_SHIFT` away under other noise seeds; the best of the three is
  kept and their spread joins each uncertainty (with the coloured-residual and the batch-means sigma).
* **What the record cannot move** (a column of the Jacobian below :data:`MOVE_SHARE` of the largest,
  or a relative uncertainty above one) is held at its declared value and named.
* **An escalation that cannot pay stops early.** When the physics must beat a model already fitted (a
  declared model escalated to HOAD3's physics, :mod:`ema_sim.identify.escalation`), it is screened twice
  against the error it must get under: after the delay scan, by the Gauss-Newton prediction of what the
  fit can remove from there (the Jacobian the held elements are read from, no run more), taken
  :data:`SCREEN_OPTIMISM` times over (a rough objective may do better than its linearisation); and after
  the first fit, by where it ended (the shifted starts only move the end by the optimizer's own spread).
  The first fit itself runs in short rounds and stops once even that many times its last round's progress,
  in every round left, could not get it there. Either way the fit stops, says why and how long it ran, and the
  shifted starts and the uncertainty are not run.
* **Screened on a coarse copy first.** Given the current model's residual, an escalation takes those steps on
  the record's coarse copy (:mod:`ema_sim.identify.coarse`: the outputs decimated to 250 Hz, the model at
  5 kHz), against the same share of that model's error above the floor there; the fine model is run once
  at the coarse fit's end before the verdict. Only a physics that gets under goes on to the whole record,
  from the coarse end (fewer fine runs), then to its shifted starts and uncertainty there as above.

The declared model's noise levels and quantization are not fitted; its command noise is run (4.3: noise
inside the loop dithers the drive's dead band and friction, which a noise-free model would absorb into
smaller ones), with fixed seeds so that the objective is deterministic, and its LVDT noise is not (the
record carries its own).
"""

from __future__ import annotations

import math
import os
import threading
import time
from collections import OrderedDict
from collections.abc import Callable, Mapping
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares

from ema_sim.errors import DataError
from ema_sim.identify.coarse import COARSE_RATE_HZ, coarse_problem, decimation, on_coarse
from ema_sim.identify.declared import run_declared
from ema_sim.identify.fit import batch_sigma, block_covariance, correlation, finite
from ema_sim.identify.parallel import SERIAL, Pool, one_blas_thread, result
from ema_sim.identify.problem import Problem
from ema_sim.models import model_parameters
from ema_sim.models.arrays import FloatArray

ParamValue = float | tuple[float, ...]
"""A model parameter's value: a number, or a curve's segment values."""
PHYSICAL_MODELS = ("hoad2", "hoad3")
"""The declared models whose physical parameters are fitted (discrete, so hundreds of runs are seconds;
HOAC1's continuous solver is ~40 times slower per run and is left as declared)."""
ESCALATE_TO = "hoad3"
"""The installed actuator's model (4.2.5) whose physics a declared model out of vocabulary is escalated to."""
DELAYS = ("command_delay_s", "feedback_delay_s")
CANDIDATES = (
    "position_gain_per_s", "velocity_gain_a_per_in_s", "current_limit_a", "rate_limit_in_s", "pwm_dead_band_v",
    "coulomb_friction_lbf", "lvdt_filter_hz", "position_integral_per_s2", "hinge_friction_inlb",
    "linkage_damping_lbf_s_per_in", "gear_damping_lbf_s_per_in", "gear_stiffness_lbf_per_in",
    "total_mean_stiffness_lbf_per_in", "actuator_mean_stiffness_lbf_per_in", "surface_inertia_inlbs2",
)
"""The physical elements a position/surface record can move, in the model's own names and units."""
TIED = {
    "coulomb_friction_lbf": ("stiction_lbf",),
    "total_mean_stiffness_lbf_per_in": ("total_upper_stiffness_lbf_per_in", "total_lower_stiffness_lbf_per_in"),
    "actuator_mean_stiffness_lbf_per_in": ("actuator_upper_stiffness_lbf_per_in",
                                           "actuator_lower_stiffness_lbf_per_in"),
}
"""Parameters scaled with another: stiction keeps its ratio to Coulomb friction (one record cannot split
them), and figure 33's upper and lower curves keep theirs to its mean curve (the fit scales the family)."""
DELAY_STEP_S = 5e-4
"""The wide scan's grid, and how far the shifted starts move each delay."""
DELAY_SPAN_S = 0.012
DELAY_DIFF_S = 2.5e-4
"""Difference step of a delay: 2.5 of the model's 0.1 ms steps (between two, the model blends them)."""
DELAY_SCALE_S = 1e-3
"""A delay's scale beside the log coordinates (1 ms weighs as a factor e) in the trust region."""
DELAY_RESOLUTION_S = 1e-4
"""HOAD2/HOAD3's step: a delay's uncertainty is never below half of it."""
DIFF_STEP = 0.05
"""Difference step in log coordinates: 5 % of each element. A friction, a dead band or the noise inside
the loop make the objective rough at small scales; a difference over 5 % follows its trend."""
MOVE_SHARE = 1e-3
MAX_NFEV = 40
POLISH_ROUNDS = 4
POLISH_SHARE = 5e-3
"""The fit is restarted (its trust region reset) while a restart removes this share of the error above
the noise floor: on a rough objective the trust region shrinks to nothing before the optimum."""
START_SHIFT = 0.1
"""Two more fits start this far (in log, ~10 %) from the first's end, each coordinate shifted alternately up
and down (and the other way for the second): the spread of where they end is the optimizer's own
reproducibility on this record, part of each uncertainty."""
FTOL = 1e-8
"""A fit's round stops once a step removes less than this share of its weighted error (least squares' default)."""
START_FTOL = 1e-6
"""The same for the fits from shifted starts: a millionth of the error (0.07 of 71,000 on the 30 s HOAD3 record)
moves neither which end is best (their mean costs differ by units) nor their spread (the ends' costs differ by
hundreds); there they spent a third of their runs below it, and their restarts after converging gained 0.004."""
KEPT_RUNS_BYTES = 48 * 2**20
"""Most memory a fit's kept runs may take: 69 runs of 30 s at 1 kHz, so a Jacobian's 28 runs at a fit's end are
still kept when the uncertainty asks for them at the same point."""
TINY = 1e-300
LOG_LIMIT = math.log(100.0)
"""No element moves beyond a hundredfold of its declared value either way (past that the model is not HOAD3's
actuator any more, and exp() would overflow or an inertia collapse to zero)."""
MAX_DELAY_S = 0.05
SCREEN_NFEV = 10
"""An escalation's first fit runs in rounds of this many evaluations, its progress judged after each."""
SCREEN_OPTIMISM = 3.0
"""The screen after the delay scan stops the fit when even this many times the Gauss-Newton prediction of what
the fit can remove leaves it above the error it must beat."""
SEEDS = (7, 8, 9)
"""The model's own noise is run with these seeds: the first for the fit, the others for the two fits from
shifted starts, so their spread carries the noise inside the loop as well."""
WORKERS = max(1, min(int(os.environ.get("NUMBA_NUM_THREADS") or len(os.sched_getaffinity(0))), 8))
"""Threads for a Jacobian's columns (the discrete kernels release the GIL); ``NUMBA_NUM_THREADS`` bounds them
as it bounds numba's own, so one setting keeps a process to its share of the cores."""


@dataclass
class PhysicalFit:
    """The fitted physical parameters of a high-order model and what they leave."""

    model: str
    params: dict[str, ParamValue]
    """Fitted and held values, in the model's names and units (a curve is its tuple of segment values)."""
    declared: dict[str, ParamValue]
    sigma: dict[str, float]
    """One-sigma uncertainty (a curve's is that of its first segment; a delay's never below half a model step)."""
    fitted: tuple[str, ...]
    held: tuple[str, ...]
    """Parameters the record cannot move: held at their declared values."""
    sim: FloatArray
    residual: FloatArray
    rms_deg: dict[str, float]
    simulations: int = 0
    elapsed_s: float = 0.0
    correlation: dict[str, dict[str, float]] = field(default_factory=dict)
    starts: int = 1
    """Fits from different starts whose ends the uncertainty includes."""
    stopped: str = ""
    """Why the fit stopped before its end (empty: it ran to the end): it could not beat the model it must."""
    screen: str = ""
    """How an escalation was screened on the record's coarse copy, and how long that took (empty: it was not)."""

    @property
    def rss(self) -> float:
        """Weighted residual sum of squares."""
        return float(np.dot(self.residual, self.residual))

    def scalars(self) -> dict[str, float]:
        """Every fitted or held value as one number (a curve by its first segment), for reports."""
        return {k: float(v[0] if isinstance(v, tuple) else v) for k, v in self.params.items()}


def run_model(problem: Problem, model: str, values: Mapping[str, object], seed: int) -> FloatArray:
    """``model`` at ``values`` on the problem's inputs, its command noise from ``seed``: ``(samples, 3)``.

    The command noise (stage 3) is inside the loop: it dithers the drive's dead band and friction, which a
    noise-free model would absorb into smaller ones. The LVDT's noise (stage 17) is not run: it is
    measurement noise only, which the record already carries and the residual's weights already count.

    Parameters
    ----------
    problem : Problem
        The record (its inputs, held or interpolated as the problem drives its models).
    model : str
        One of :data:`PHYSICAL_MODELS`.
    values : dict
        Model parameters other than declared.
    seed : int
        The noise seed.
    """
    bp_t, bp_u, bp_h = problem.breakpoints
    return problem.saturate(run_declared(model, problem.channel, bp_t, bp_u, bp_h, sample_times=problem.time_s,
                                         overrides={**values, "noise": True, "seed": seed,
                                                    "feedback_noise_v": 0.0})[:, :3].copy())


class _Runs:
    """The model on the record at a parameter vector: delays absolute, the rest log-scaled from declared."""

    def __init__(self, problem: Problem, model: str, names: list[str], declared: dict[str, ParamValue],
                 options: dict[str, object] | None = None) -> None:
        self.problem = problem
        self.options = options or {}
        """Model options every run takes beside the parameters (a coarse copy's integration rate)."""
        self.model = model
        self.names = names
        self.declared = declared
        self.count = 0
        self._lock = threading.Lock()
        self._kept: OrderedDict[tuple[bytes, int], FloatArray] = OrderedDict()
        """The latest runs by point and seed (the model is deterministic): a round's start and end, the Jacobian
        the fit ended on, are asked for again."""
        self.delay = np.array([n in DELAYS for n in names])
        self.step = np.where(self.delay, DELAY_DIFF_S, DIFF_STEP)
        self.scale = np.where(self.delay, DELAY_SCALE_S, 1.0)

    def values(self, x: FloatArray) -> dict[str, ParamValue]:
        """Model overrides at ``x``."""
        out: dict[str, ParamValue] = {}
        for n, v in zip(self.names, x, strict=True):
            if n in DELAYS:
                out[n] = max(float(v), 0.0)
                continue
            for m in (n, *TIED.get(n, ())):
                if m in self.declared:
                    out[m] = _scaled(self.declared[m], float(v))
        return out

    def sim(self, x: FloatArray, seed: int = SEEDS[0]) -> FloatArray:
        """The model's outputs at ``x`` with its noise from ``seed`` (a point just run is not run again)."""
        key = (np.asarray(x, dtype=float).tobytes(), seed)
        with self._lock:
            self.count += 1
            kept = self._kept.get(key)
            if kept is not None:
                self._kept.move_to_end(key)
                return kept.copy()
        out = run_model(self.problem, self.model, {**self.values(x), **self.options}, seed)
        with self._lock:
            self._kept[key] = out
            while len(self._kept) > max(1, KEPT_RUNS_BYTES // out.nbytes):
                self._kept.popitem(last=False)
        return out.copy()

    def residual(self, x: FloatArray, seed: int = SEEDS[0]) -> FloatArray:
        """Weighted residual at ``x`` (a run that diverged counts as a very bad one, not an error)."""
        return finite(self.problem.weighted_residual(self.sim(x, seed)))

    def cost(self, x: FloatArray, seed: int = SEEDS[0]) -> float:
        """Weighted residual sum of squares at ``x``."""
        r = self.residual(x, seed)
        return float(np.dot(r, r))

    def costs(self, points: list[FloatArray], seeds: list[int] | None = None) -> list[float]:
        """:meth:`cost` at each point (under the seed ``seeds`` gives it; the first without), on every core."""
        with ThreadPoolExecutor(WORKERS) as pool:
            return list(pool.map(self.cost, points, seeds or [SEEDS[0]] * len(points)))

    def jacobian(self, x: FloatArray, cols: list[int], r0: FloatArray, seed: int = SEEDS[0]) -> FloatArray:
        """Central differences of the weighted residual in the ``cols`` coordinates, on every core.

        Forward differences (one run a column) stall the fit in the narrow valley the dead band, the
        velocity gain and the integral make together; central ones follow it (measured: an HOAD3 with 12
        parameters off their declared values ended 30 % above the truth's error with 5 % forward
        differences, and below it with central ones). A delay too small to step back is differenced forward.
        """

        def column(i: int) -> FloatArray:
            h = float(self.step[i])
            up = x.copy()
            up[i] += h
            down = x.copy()
            down[i] -= h
            if self.delay[i] and down[i] < 0.0:
                return (self.residual(up, seed) - r0) / h
            return (self.residual(up, seed) - self.residual(down, seed)) / (2.0 * h)

        with ThreadPoolExecutor(WORKERS) as pool:
            return np.column_stack(list(pool.map(column, cols))) if cols else np.zeros((r0.size, 0))


def _param_value(name: str, value: object) -> ParamValue:
    """A declared parameter's value as a number or a curve's tuple (one clear error for anything else)."""
    if isinstance(value, float) or (isinstance(value, tuple) and all(isinstance(q, float) for q in value)):
        return value
    if isinstance(value, int) or (isinstance(value, tuple) and all(isinstance(q, int | float) for q in value)):
        return float(value) if isinstance(value, int) else tuple(float(q) for q in value)
    raise DataError(f"{name}: declared value {value!r} is neither a number nor a curve")


def _scaled(value: ParamValue, log_scale: float) -> ParamValue:
    """A declared value (or each segment of a curve) times ``exp(log_scale)``, the scale within :data:`LOG_LIMIT`."""
    k = math.exp(min(max(log_scale, -LOG_LIMIT), LOG_LIMIT))
    return tuple(float(q) * k for q in value) if isinstance(value, tuple) else float(value) * k


def _fit(runs: _Runs, x: FloatArray, free: list[int], nfev: int, seed: int = SEEDS[0],
         end: dict[str, FloatArray] | None = None, ftol: float = FTOL) -> FloatArray:
    """Least squares over the ``free`` coordinates of ``x`` (the others held).

    ``end`` takes the residual (``fun``), the free coordinates' Jacobian (``jac``) where it ended and least
    squares' ``status`` (above 0: a tolerance ended it).
    """
    if not free:
        return x
    last: dict[str, FloatArray] = {}

    def put(z: FloatArray) -> FloatArray:
        y = x.copy()
        y[free] = z
        return y

    def res(z: FloatArray) -> FloatArray:
        r = runs.residual(put(z), seed)
        last["z"], last["r"] = z.copy(), r
        return r

    def jac(z: FloatArray) -> FloatArray:
        r0 = last["r"] if "z" in last and np.array_equal(last["z"], z) else runs.residual(put(z), seed)
        return runs.jacobian(put(z), free, r0, seed)

    lower = np.where(runs.delay[free], 0.0, -LOG_LIMIT)
    upper = np.where(runs.delay[free], MAX_DELAY_S, LOG_LIMIT)
    start = np.clip(x[free], lower + 1e-9, upper - 1e-9)
    out = least_squares(res, start, jac=jac, bounds=(lower, upper), x_scale=runs.scale[free], method="trf",
                        max_nfev=nfev, ftol=ftol)
    if end is not None:
        end["fun"], end["jac"] = np.asarray(out.fun, dtype=float), np.asarray(out.jac, dtype=float)
        end["status"] = np.array([out.status], dtype=float)
    return put(np.asarray(out.x, dtype=float))


def _scan(runs: _Runs, x: FloatArray, i: int, grid: FloatArray) -> FloatArray:
    """Coordinate ``i`` on ``grid`` (the others held), the best kept."""
    points = [x.copy() for _ in grid]
    for y, g in zip(points, grid, strict=True):
        y[i] = max(float(g), 0.0)
    return points[int(np.argmin(runs.costs(points)))]


def _fit_restarted(runs: _Runs, x: FloatArray, free: list[int], seed: int = SEEDS[0], beat: float | None = None,
                   why: list[str] | None = None, shifted: bool = False) -> FloatArray:
    """Restart the fit from where it ended while a restart pays (:data:`POLISH_SHARE`).

    A fit from a shifted start (``shifted``) stops at :data:`START_FTOL`, and once a tolerance ends a round.

    With ``beat`` (an escalation's error to get under), the fit runs in rounds of :data:`SCREEN_NFEV`
    evaluations and stops once even :data:`SCREEN_OPTIMISM` times the last round's drop, in every round
    left, could not bring it under ``beat``, or once the Gauss-Newton prediction from where the round ended
    (its own Jacobian there, no run more), taken that many times over, could not (:func:`_screen`); ``why``
    takes the reason.
    """
    cost = runs.cost(x, seed)
    nfev, rounds = (MAX_NFEV, POLISH_ROUNDS) if beat is None else (SCREEN_NFEV, POLISH_ROUNDS * MAX_NFEV // SCREEN_NFEV)
    for k in range(rounds):
        end: dict[str, FloatArray] = {}
        y = _fit(runs, x, free, nfev, seed, end, START_FTOL if shifted else FTOL)
        c = runs.cost(y, seed)
        if c >= cost:
            break
        gain = (cost - c) / max(cost - runs.problem.n_fit, TINY)
        drop = cost - c
        x, cost = y, c
        if gain < POLISH_SHARE or (shifted and end.get("status", np.zeros(1))[0] > 0):
            break
        if beat is None:
            continue
        if cost - SCREEN_OPTIMISM * drop * (rounds - k - 1) >= beat:
            if why is not None:
                why.append(f"after round {k + 1} of the first fit ({nfev} evaluations each) at weighted error "
                           f"{cost:.6g}: {SCREEN_OPTIMISM:g} times its last drop ({drop:.6g}) in each of the "
                           f"{rounds - k - 1} rounds left still leaves it above the {beat:.6g} it must get under")
            break
        predicted = _screen(end["fun"], end["jac"], beat) if "jac" in end and end["jac"].shape[1] else ""
        if predicted:
            if why is not None:
                why.append(f"after round {k + 1} of the first fit: " + predicted.removeprefix(
                    "screened after the delay scan: "))
            break
    return x


def _shifted(runs: _Runs, x: FloatArray, free: list[int], sign: float) -> FloatArray:
    """``x`` with each free coordinate moved alternately up and down (``sign`` first).

    A log coordinate moves by :data:`START_SHIFT`, a delay by :data:`DELAY_STEP_S` (never below zero).
    """
    y = x.copy()
    for k, i in enumerate(free):
        y[i] += sign * (DELAY_STEP_S if runs.delay[i] else START_SHIFT) * (1.0 if k % 2 == 0 else -1.0)
        y[i] = min(max(y[i], 0.0), MAX_DELAY_S) if runs.delay[i] else min(max(y[i], -LOG_LIMIT), LOG_LIMIT)
    return y


def remote_start(problem: Problem, model: str, names: list[str], declared: dict[str, ParamValue], x: FloatArray,
                 free: list[int], seed: int, options: dict[str, object] | None = None) -> tuple[FloatArray, int]:
    """:func:`_fit_restarted` from ``x`` under the noise ``seed`` on a worker, and the runs it took.

    Parameters
    ----------
    problem : Problem
        The record and its noise floors.
    model : str
        One of :data:`PHYSICAL_MODELS`.
    names : list of str
        The coordinates' parameters.
    declared : dict
        The declared values the log coordinates scale.
    x : numpy.ndarray
        The start.
    free : list of int
        The coordinates fitted.
    seed : int
        The model's noise seed.
    options : dict, optional
        Model options every run takes (a coarse copy's integration rate).

    Returns
    -------
    tuple
        Where the fit ended, and the model runs it took.
    """
    runs = _Runs(problem, model, names, declared, options)
    with one_blas_thread():
        return _fit_restarted(runs, x, free, seed, shifted=True), runs.count


def fit_physical(problem: Problem, model: str, log: Callable[[str], None] | None = None, pool: Pool = SERIAL,
                 beat: float | None = None, current: FloatArray | None = None) -> PhysicalFit:
    """Fit ``model``'s physical parameters (module docstring) to the problem's record.

    Parameters
    ----------
    problem : Problem
        The record and its noise floors.
    model : str
        One of :data:`PHYSICAL_MODELS`.
    log : callable, optional
        Called with each progress line.
    pool : Pool
        Where the two shifted starts' fits run (:mod:`ema_sim.identify.parallel`): at once on its workers,
        the same ends as one after the other.
    beat : float, optional
        The weighted error the physics must get under to be kept (an escalation's): the fit stops as soon as
        it cannot (module docstring). None: fitted to its end (a declared HOAD2/HOAD3).
    current : numpy.ndarray, optional
        With ``beat``, the weighted residual of the model the physics must beat: the fit is then screened and
        started on the record's coarse copy (:func:`_screened`).

    Returns
    -------
    PhysicalFit
        Fitted and held values, uncertainties and the residual.
    """
    t0 = time.perf_counter()
    say = log or (lambda _msg: None)
    info = {p.name: p for p in model_parameters(model, problem.channel)}
    tied = [m for n in CANDIDATES for m in TIED.get(n, ())]
    declared = {n: _param_value(n, info[n].default) for n in (*DELAYS, *CANDIDATES, *tied) if n in info}
    names = [n for n in (*DELAYS, *CANDIDATES) if n in info
             and (n in DELAYS or _positive(info[n].default))]
    runs = _Runs(problem, model, names, declared)
    x = np.array([(d[0] if isinstance(d := declared[n], tuple) else d) if n in DELAYS else 0.0 for n in names])
    coarse = coarse_problem(problem) if beat is not None and current is not None else None
    screen = ""
    if coarse is not None and beat is not None and current is not None:
        screened = _screened(runs, coarse, x, current, beat, t0, say)
        if isinstance(screened, PhysicalFit):
            return screened
        x, held, free, screen = _from_coarse(runs, screened, beat)
    else:
        x, held, free, r_start, jac = _start(runs, x)
        if beat is not None:
            why = _screen(r_start, jac, beat)
            if why:
                return _stopped(runs, x, held, why, t0, say)
        x = _fit_restarted(runs, x, free, beat=beat)
    say(f"  {model}: delays scanned, {len(free)} parameters fitted: weighted error {runs.cost(x):.6g}")
    if beat is not None and runs.cost(x) >= beat:
        why = (f"the first fit ended at weighted error {runs.cost(x):.6g}, above the {beat:.6g} it must get under "
               "to pay: the shifted starts and the uncertainty were not run")
        return _stopped(runs, x, held, why, t0, say, screen)
    ends = [x, *_other_starts(runs, x, free, pool)]
    each = runs.costs([e for e in ends for _ in SEEDS], [s for _ in ends for s in SEEDS])
    mean_cost = [float(np.mean(each[k:k + len(SEEDS)])) for k in range(0, len(each), len(SEEDS))]
    x = ends[int(np.argmin(mean_cost))]
    start_sigma = np.std(np.array(ends)[:, free], axis=0, ddof=1) if free else np.zeros(0)
    say(f"{model} physical fit: {runs.count} runs; mean cost over the noise seeds from {len(ends)} starts: "
        + ", ".join(f"{c:.6g}" for c in mean_cost))
    residual = runs.residual(x)
    sim = runs.sim(x)
    sigma, corr, vague = _uncertainty(runs, x, free, residual, start_sigma)
    values = runs.values(x)
    held += vague
    for n in vague:
        for m in (n, *TIED.get(n, ())):
            if m in declared:
                values[m] = declared[m]
    out_sigma = {names[i]: s for i, s in sigma.items() if names[i] not in vague}
    if vague:  # the held values moved the residual: recompute it there
        sim = run_model(problem, model, values, SEEDS[0])
        residual = problem.weighted_residual(sim)
    rms = {o: float(np.sqrt(np.mean(e**2))) for o, e in problem.errors_deg(sim).items()}
    fitted = tuple(n for n in names if n not in held)
    return PhysicalFit(model, values, {n: declared[n] for n in names}, out_sigma, fitted, tuple(held), sim,
                       residual, rms, runs.count, time.perf_counter() - t0,
                       {names[a]: {names[b]: v for b, v in row.items()} for a, row in corr.items()}, len(ends),
                       screen=screen)


def _start(runs: _Runs, x: FloatArray) -> tuple[FloatArray, list[str], list[int], FloatArray, FloatArray]:
    """The delays scanned from ``x``, and what the record cannot move, from the Jacobian at the scanned start.

    Returns
    -------
    tuple
        The scanned start, the held parameters, the free coordinates, the residual there and the Jacobian of
        the free coordinates other than the delays there.
    """
    names = runs.names
    wide = np.arange(0.0, DELAY_SPAN_S + 0.5 * DELAY_STEP_S, DELAY_STEP_S)
    for i in [names.index(n) for n in DELAYS if n in names]:
        x = _scan(runs, x, i, wide)
    held, free, r_start, jac = _movable(runs, x)
    return x, held, free, r_start, jac


def _movable(runs: _Runs, x: FloatArray) -> tuple[list[str], list[int], FloatArray, FloatArray]:
    """What the record cannot move at ``x`` (a Jacobian column below :data:`MOVE_SHARE` of the largest).

    Returns
    -------
    tuple
        The held parameters, the free coordinates, the residual at ``x`` and the Jacobian of the free
        coordinates other than the delays there.
    """
    names = runs.names
    delays = [names.index(n) for n in DELAYS if n in names]
    rest = [i for i in range(len(names)) if i not in delays]
    r = runs.residual(x)
    jac = runs.jacobian(x, rest, r)
    size = np.linalg.norm(jac, axis=0)
    top = float(np.max(size, initial=0.0))
    held = [names[i] for i, s in zip(rest, size, strict=True) if s <= MOVE_SHARE * top]
    free = delays + [i for i in rest if names[i] not in held]
    return held, free, r, jac[:, [k for k, i in enumerate(rest) if names[i] not in held]]


def _from_coarse(runs: _Runs, screened: tuple[FloatArray, str], beat: float
                 ) -> tuple[FloatArray, list[str], list[int], str]:
    """The fine fit on the whole record from the coarse end (:func:`_screened`'s), with what the record moves there.

    An element the whole record cannot move at the coarse end is held at its declared value, as the full fit
    holds what it cannot move at its start.
    """
    x, screen = screened
    held, free, _, _ = _movable(runs, x)
    x = x.copy()
    x[[runs.names.index(n) for n in held]] = 0.0  # log coordinate 0: the declared value
    return _fit_restarted(runs, x, free, beat=beat), held, free, screen


def _screened(runs: _Runs, coarse: Problem, x: FloatArray, current: FloatArray, beat: float, t0: float,
              say: Callable[[str], None]) -> PhysicalFit | tuple[FloatArray, str]:
    """An escalation screened and fitted first on the record's coarse copy (:mod:`ema_sim.identify.coarse`).

    On the copy the physics must get under the same share of the current model's error above the noise floor
    as on the record (``beat``). It is screened as the record was (:func:`_screen` after the delay scan, then
    the first fit in rounds, :func:`_fit_restarted`) and stops as soon as it cannot get there; at the coarse
    fit's end the fine model is run once on the copy's samples, and the fit stops when neither it nor the
    coarse one got under. Otherwise the fine fit on the whole record starts from the coarse end.

    Returns
    -------
    PhysicalFit or tuple
        The fit stopped (with why), or the coarse end and what the screen did.
    """
    problem = runs.problem
    cruns = _Runs(coarse, runs.model, runs.names, runs.declared, {"rate_hz": COARSE_RATE_HZ})
    fine = _Runs(coarse, runs.model, runs.names, runs.declared)
    cur_rss = float(np.dot(current, current))
    share = (cur_rss - beat) / max(cur_rss - problem.n_fit, TINY)
    own = on_coarse(problem, coarse, current)
    cur_c = float(np.dot(own, own))
    beat_c = cur_c - share * max(cur_c - coarse.n_fit, TINY)
    every = decimation(problem)
    copy = f"the coarse copy (every {every} samples, the model at {COARSE_RATE_HZ / 1000:g} kHz)"
    say(f"  {runs.model}: screened on {copy}: must get under {beat_c:.6g} (the current model leaves {cur_c:.6g})")

    def stop(why: str) -> PhysicalFit:
        text = f"screened on {copy}: {why} ({cruns.count + fine.count} coarse runs, {time.perf_counter() - t0:.1f} s)"
        runs.count += cruns.count + fine.count
        return _stopped(runs, x, held, text, t0, say, text)

    x, held, free, r_start, jac = _start(cruns, x)
    why = _screen(r_start, jac, beat_c)
    if why:
        return stop(why)
    bound: list[str] = []
    x = _fit_restarted(cruns, x, free, beat=beat_c, why=bound)
    c, f = cruns.cost(x), fine.cost(x)
    say(f"  {runs.model}: delays scanned, {len(free)} parameters fitted on {copy}: weighted error {c:.6g} "
        f"({f:.6g} with the model at its own rate)")
    if min(c, f) >= beat_c:
        early = f"{bound[0]}; " if bound else ""
        return stop(f"{early}the first fit ended at weighted error {c:.6g} ({f:.6g} with the model at its own rate), "
                    f"above the {beat_c:.6g} it must get under to pay: the whole record and the uncertainty were "
                    "not run")
    runs.count += cruns.count + fine.count
    return x, (f"screened on {copy}: it got under the {beat_c:.6g} it must ({c:.6g}; {cruns.count + fine.count} "
                     f"coarse runs, {time.perf_counter() - t0:.1f} s), then fitted on the whole record from there")


def _other_starts(runs: _Runs, x: FloatArray, free: list[int], pool: Pool) -> list[FloatArray]:
    """The fits from the two shifted starts under the other noise seeds (on the pool's workers when it has some)."""
    client = pool.client()
    starts = [(_shifted(runs, x, free, sign), seed) for seed, sign in zip(SEEDS[1:], (1.0, -1.0), strict=True)]
    if client is None:
        return [_fit_restarted(runs, start, free, seed, shifted=True) for start, seed in starts]
    shared = client.scatter(runs.problem, broadcast=True)
    futures = [client.submit(remote_start, shared, runs.model, runs.names, runs.declared, start, free, seed,
                             runs.options, pure=False) for start, seed in starts]
    ends = []
    for future in futures:
        end, count = result(future)
        ends.append(end)
        runs.count += count
    return ends


def _screen(r: FloatArray, jac: FloatArray, beat: float) -> str:
    """Why the fit cannot pay, from its Gauss-Newton prediction at the start (empty: it may)."""
    cost = float(np.dot(r, r))
    if cost < beat or jac.shape[1] == 0:
        return ""
    good = np.all(np.isfinite(jac), axis=0)
    q = np.linalg.qr(jac[:, good], mode="reduced")[0] if good.any() else np.zeros((r.size, 0))
    drop = float(np.sum((q.T @ r) ** 2))
    if cost - SCREEN_OPTIMISM * drop < beat:
        return ""
    return (f"screened after the delay scan: weighted error {cost:.6g}, of which a linearised fit removes {drop:.6g}; "
            f"{SCREEN_OPTIMISM:g} times that still leaves it above the {beat:.6g} it must get under to pay")


def _stopped(runs: _Runs, x: FloatArray, held: list[str], why: str, t0: float, say: Callable[[str], None],
             screen: str = "") -> PhysicalFit:
    """The physics where it stopped, on the whole record, with why (no uncertainty: it was not worth computing)."""
    say(f"{runs.model} physical fit stopped after {runs.count} runs: {why}")
    sim = runs.sim(x)
    residual = runs.residual(x)
    rms = {o: float(np.sqrt(np.mean(e**2))) for o, e in runs.problem.errors_deg(sim).items()}
    return PhysicalFit(runs.model, runs.values(x), {n: runs.declared[n] for n in runs.names}, {},
                       tuple(n for n in runs.names if n not in held), tuple(held), sim, residual, rms, runs.count,
                       time.perf_counter() - t0, stopped=why, screen=screen)


def _positive(v: object) -> bool:
    """A declared value a log coordinate can scale (every segment of a curve above zero)."""
    vals = v if isinstance(v, tuple) else (v,)
    return all(float(q) > 0.0 for q in vals)


def _uncertainty(runs: _Runs, x: FloatArray, free: list[int], residual: FloatArray, start_sigma: FloatArray
                 ) -> tuple[dict[int, float], dict[int, dict[int, float]], list[str]]:
    """One-sigma of each free parameter, correlations, and those the record leaves vague.

    The larger of the coloured-residual and the batch-means sigma (:func:`~ema_sim.identify.fit.batch_sigma`),
    combined with the spread of the fits from shifted starts under other noise seeds (:data:`START_SHIFT`,
    :data:`SEEDS`): the noise inside the loop decides where a dead band or a friction lets the actuator
    stop, the record's own realization of it is unknown, and on a rough objective where the optimizer
    ends depends on where it starts.
    """
    if not free:
        return {}, {}, []
    jac = runs.jacobian(x, free, residual)
    p = runs.problem
    block = int(p.mask.sum())
    k = len(p.outputs)
    cov = block_covariance([residual[b * block:(b + 1) * block] for b in range(k)],
                           [jac[b * block:(b + 1) * block] for b in range(k)])
    sx = np.hypot(np.maximum(np.sqrt(np.clip(np.diag(cov), 0.0, None)), batch_sigma(residual, jac, block, k)),
                  start_sigma)
    sigma: dict[int, float] = {}
    vague: list[str] = []
    values = runs.values(x)
    for j, i in enumerate(free):
        name = runs.names[i]
        v = values[name]
        if runs.delay[i]:  # absolute, never finer than the model's own step
            sigma[i] = max(float(sx[j]), 0.5 * DELAY_RESOLUTION_S) if math.isfinite(sx[j]) else math.inf
            if sigma[i] > max(v[0] if isinstance(v, tuple) else v, DELAY_RESOLUTION_S):
                vague.append(name)
            continue
        scale = float(v[0] if isinstance(v, tuple) else v)
        # d(value) = value · d(log value)
        sigma[i] = abs(scale) * float(sx[j]) if math.isfinite(sx[j]) else math.inf
        if not math.isfinite(sx[j]) or sx[j] > 1.0:
            vague.append(name)
    corr_m = correlation(cov)
    corr = {free[a]: {free[b]: float(corr_m[a, b]) for b in range(len(free)) if b != a and np.isfinite(corr_m[a, b])}
            for a in range(len(free))}
    return sigma, corr, vague
