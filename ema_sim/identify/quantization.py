"""Finding a command quantizer's step, whose simulated cost is a thicket of narrow local minima.

A step q turns the command v into q·round(v/q): the error it adds, e_q(v) = q·round(v/q) − v, is a
sawtooth in the command level whose phase at a level v drifts by v·Δq/q² when q is off by Δq. With
commands of tens of degrees the cost therefore has basins only ~10⁻⁴ wide in q. The search scores a
fine grid of steps with the *linear* part of the current model (the residual should be G·e_q, a
low-order filter run over the record in a compiled loop), first on the small commands (wide basins),
then on all of them around the best few; the full nonlinear simulation makes the final choice.
"""

from __future__ import annotations

import numba as nb
import numpy as np
from numpy.typing import NDArray
from scipy.signal import cont2discrete

from ema_sim.identify.problem import OUTPUT_COLUMN, Problem
from ema_sim.models.second_order import SecondOrderParams

FloatArray = NDArray[np.float64]
SMALL_COMMAND_DEG = 2.5


def _linear_response(p: SecondOrderParams, dt: float, output: str) -> tuple[FloatArray, FloatArray]:
    """Discrete (b, a) of the model's linear command dynamics to ``output`` (lags included)."""
    wn, z = p.wn_rad_s, p.zeta
    num = np.array([wn * wn])
    den = np.array([1.0, 2.0 * z * wn, wn * wn])
    lags = [p.command_lag_hz]
    if output == "position_deg":
        lags.append(p.feedback_lag_hz)
    for corner in lags:
        if corner > 0.0:
            wc = 2.0 * np.pi * corner
            num = np.polymul(num, [wc])
            den = np.polymul(den, [1.0, wc])
    b, a, _ = cont2discrete((num, den), dt, method="zoh")
    b = np.asarray(b, dtype=float).ravel()
    a = np.asarray(a, dtype=float).ravel()
    return b / a[0], a / a[0]


def _pre_quantizer(problem: Problem, p: SecondOrderParams) -> FloatArray:
    """The model's command just before its quantizer, at every sample (delay rounded to a sample)."""
    u = problem.data.command_deg
    shift = round(p.delay_s * problem.sample_hz)
    if shift > 0:
        u = np.concatenate([np.full(shift, u[0]), u[:-shift]])
    return (1.0 + p.kb) * u + p.offset_deg


FILTER_TAPS = 5
"""Most coefficients of G's numerator and denominator: a second order and two first-order lags."""


@nb.njit(cache=True, parallel=True)
def _costs(residual: NDArray[np.float64], v: NDArray[np.float64], shift: float, steps: NDArray[np.float64],
           b: NDArray[np.float64], a: NDArray[np.float64], weight: NDArray[np.float64], starts: NDArray[np.int64],
           ends: NDArray[np.int64], warm: int) -> NDArray[np.float64]:
    """Σ weight·(residual − G·(q·round((v + shift)/q) − v))² for every step q, over the windows given.

    The model the residual was taken against saw ``v`` unquantized; the candidate quantizes it with
    its offset moved by ``shift``. G is a direct-form IIR filter (a[0] = 1, at most :data:`FILTER_TAPS`
    coefficients each), started ``warm`` samples before each window so its transient has died out where
    the cost is counted. Its taps are zero-padded scalars, not arrays shifted each sample: half the time,
    the same sums term for term.
    """
    out = np.empty(steps.size)
    bb = np.zeros(FILTER_TAPS)
    aa = np.zeros(FILTER_TAPS)
    bb[:b.size] = b
    aa[:a.size] = a
    b0, b1, b2, b3, b4 = bb[0], bb[1], bb[2], bb[3], bb[4]
    a1, a2, a3, a4 = aa[1], aa[2], aa[3], aa[4]
    for k in nb.prange(steps.size):
        q = steps[k]
        acc = 0.0
        for w in range(starts.size):
            x0 = x1 = x2 = x3 = x4 = 0.0
            y0 = y1 = y2 = y3 = 0.0
            for i in range(max(starts[w] - warm, 0), ends[w]):
                x4, x3, x2, x1 = x3, x2, x1, x0
                x0 = q * np.floor((v[i] + shift) / q + 0.5) - v[i]
                y = 0.0
                y += b0 * x0
                y += b1 * x1
                y += b2 * x2
                y += b3 * x3
                y += b4 * x4
                y -= a1 * y0
                y -= a2 * y1
                y -= a3 * y2
                y -= a4 * y3
                y3, y2, y1, y0 = y2, y1, y0, y
                if i >= starts[w]:
                    d = residual[i] - y
                    acc += weight[i] * d * d
        out[k] = acc
    return out


def _windows(mask: NDArray[np.bool_], limit: int) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """The longest runs of ``mask``, up to ``limit`` samples in all (start, end indices)."""
    edges = np.flatnonzero(np.diff(np.concatenate([[0], mask.astype(np.int8), [0]])))
    runs = sorted(zip(edges[::2], edges[1::2], strict=True), key=lambda r: r[0] - r[1])
    starts, ends, total = [], [], 0
    for a0, run_end in runs:
        if total >= limit:
            break
        a1 = min(run_end, a0 + limit - total)
        starts.append(a0)
        ends.append(a1)
        total += a1 - a0
    order = np.argsort(starts)
    return np.asarray(starts, dtype=np.int64)[order], np.asarray(ends, dtype=np.int64)[order]


def step_candidates(problem: Problem, p: SecondOrderParams, current_sim: FloatArray, keep: int = 2,
                    low: float = 0.002, high: float = 0.2) -> list[tuple[float, float]]:
    """Steps whose quantization error best explains the current residual, best first.

    Each comes with the correction to the command offset it wants: a wrong offset moves every
    rounding threshold, so step and offset are refined together around each coarse pick.

    Parameters
    ----------
    problem : Problem
        The record as fitted.
    p : SecondOrderParams
        The model.
    current_sim : numpy.ndarray
        The current model's outputs on the record.
    keep : int
        How many candidates to return.
    low : float
        Smallest step tried (deg).
    high : float
        Largest step tried (deg).
    """
    output = "position_deg" if "position_deg" in problem.outputs else "surface_deg"
    residual = problem.observed[output] - current_sim[:, OUTPUT_COLUMN[output]]
    v = _pre_quantizer(problem, p)
    b, a = _linear_response(p, 1.0 / problem.sample_hz, output)
    weight = problem.mask.astype(float)
    warm = round(0.3 * problem.sample_hz)
    small = problem.mask & (np.abs(v) <= SMALL_COMMAND_DEG)
    if small.sum() < 0.5 * problem.sample_hz:
        small = problem.mask
    # The coarse pass runs on at most 15 s of small commands: the basins there are wide.
    s0, s1 = _windows(small, int(15.0 * problem.sample_hz))
    every = (np.array([0]), np.array([v.size]))
    coarse = np.geomspace(low, high, 5000)  # relative spacing 9e-4: finer than the small-command basins
    c = _costs(residual, v, 0.0, coarse, b, a, weight, s0, s1, warm)
    picks: list[float] = []
    for k in np.argsort(c):
        q = float(coarse[k])
        if all(abs(q / other - 1.0) > 0.01 for other in picks):
            picks.append(q)
        if len(picks) == keep:
            break
    refined = []
    for pick in picks:
        # Step and offset together on the small commands, then the step alone on the whole record.
        best = (np.inf, pick, 0.0)
        fine = pick * (1.0 + np.linspace(-2e-3, 2e-3, 81))
        for shift in np.linspace(-0.5 * pick, 0.5 * pick, 11):
            cf = _costs(residual, v, shift, fine, b, a, weight, s0, s1, warm)
            k = int(np.argmin(cf))
            if cf[k] < best[0]:
                best = (float(cf[k]), float(fine[k]), float(shift))
        _, q, shift = best
        fine = q * (1.0 + np.linspace(-5e-4, 5e-4, 41))
        cf = _costs(residual, v, shift, fine, b, a, weight, *every, 0)
        k = int(np.argmin(cf))
        refined.append((float(cf[k]), float(fine[k]), shift))
    refined.sort()
    return [(q, shift) for _, q, shift in refined]
