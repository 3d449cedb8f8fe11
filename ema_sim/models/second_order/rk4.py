"""The identification simulator: figure 26 by fixed-step RK4 that never steps across an event.

Steps are at most ``h_max`` and never straddle an input breakpoint that changes its input (the delayed
command's or the hinge moment's; one that holds the value it had is no event), a sample, or a
switch of the rate limit or dead zone (located by bisection on :func:`figure26.servo`'s smooth
piece, the same classification the dynamics use); the free play is solved exactly
(:func:`figure29.free_play_exact`). Fast, accurate far below sensor noise and smooth in its
parameters, so identification can fit it.
"""

from __future__ import annotations

from collections.abc import Callable

import numba as nb
import numpy as np

from ema_sim.models.arrays import FloatArray
from ema_sim.models.compiling import borrowing
from ema_sim.models.second_order import stage_set
from ema_sim.models.second_order.figure26 import (
    derivatives,
    max_step_s,
    servo,
    servo_input,
    stages_on,
)
from ema_sim.models.second_order.figure29 import free_play_exact
from ema_sim.models.second_order.loac import at_stop
from ema_sim.models.second_order.params import P, X
from ema_sim.models.stages import TIME_EPS_S, compile_closure, held_change, limited_integrator

SWITCH_TOL_S = 1e-10
"""How closely a switch of the rate limit or dead zone is located inside an RK4 step."""


@borrowing
def smooth_piece(p: FloatArray, y: FloatArray, u: FloatArray, on: int = stage_set.ALL) -> int:
    """Which smooth piece of the right-hand side ``y`` is on (rate limit side × dead-zone side).

    Parameters
    ----------
    p : numpy.ndarray
        Kernel parameters.
    y : numpy.ndarray
        State.
    u : numpy.ndarray
        ``[command after stages 1–3, hinge moment]``.
    on : int
        The stages that may be on (:mod:`.stage_set`).

    Returns
    -------
    int
        The piece (see :func:`~ema_sim.models.second_order.figure26.servo`).
    """
    _, _, piece, _, _ = servo(p, servo_input(p, y, u[0]), y[X.position_deg], y[X.rate_dps], y, u[1], 0.0, on)
    return piece


@borrowing
def rk4_step(p: FloatArray, y: FloatArray, u: FloatArray, h: float, k1: FloatArray, k2: FloatArray, k3: FloatArray,
             k4: FloatArray, yt: FloatArray, out: FloatArray, on: int = stage_set.ALL) -> int:
    """One RK4 step of the actuator states from ``y`` into ``out``; free play solved exactly.

    Parameters
    ----------
    p : numpy.ndarray
        Kernel parameters.
    y : numpy.ndarray
        State at the start of the step.
    u : numpy.ndarray
        ``[command after stages 1–3, hinge moment]``, held.
    h : float
        The step (s).
    k1, k2, k3, k4, yt : numpy.ndarray
        Work arrays, one state long.
    out : numpy.ndarray
        The state at the end of the step.
    on : int
        The stages that may be on (:mod:`.stage_set`).

    Returns
    -------
    int
        The smooth piece ``y`` is on (:func:`smooth_piece`), from the step's first evaluation.
    """
    n = y.shape[0]
    piece = derivatives(p, y, u[0], u[1], k1, on)
    for a in range(n):
        yt[a] = y[a] + 0.5 * h * k1[a]
    derivatives(p, yt, u[0], u[1], k2, on)
    for a in range(n):
        yt[a] = y[a] + 0.5 * h * k2[a]
    derivatives(p, yt, u[0], u[1], k3, on)
    for a in range(n):
        yt[a] = y[a] + h * k3[a]
    derivatives(p, yt, u[0], u[1], k4, on)
    for a in range(n):
        out[a] = y[a] + h / 6.0 * (k1[a] + 2.0 * k2[a] + 2.0 * k3[a] + k4[a])
    out[X.free_play_deg] = y[X.free_play_deg]
    out[X.free_play_rate_dps] = y[X.free_play_rate_dps]
    free_play_exact(p, out, u[1], h)
    out[X.position_deg], out[X.rate_dps], _ = limited_integrator(out[X.position_deg], out[X.rate_dps],
                                                                 p[P.position_min_deg], p[P.position_max_deg])
    return piece


PARALLEL_SPAN_S = 0.05
"""A run takes the parallel kernel only over at least this much simulated time: a thread pool's start and join
cost more than a trim or a frame (under load, the other thread may not be scheduled for milliseconds). Over a
longer span it takes it for one instance too: Numba's parallel compilation of the same loop runs a little faster
even on one thread (measured, 15 s at 1 kHz with free play, a delay and compliance: one instance 7.5 against
7.9 ms; four, 29.4 against 30.8 ms with one thread and 24.4 against 30.9 ms with two). It ran 2.2× faster before
:func:`~ema_sim.models.compiling.borrowing` and :func:`~ema_sim.models.compiling.forward_array_copies` took away
the reference counting that made most of the difference. The outputs are the same bit for bit either way."""


def make_rk4(parallel: bool) -> Callable[..., None]:
    """The RK4 kernel compiled with its instances in parallel threads or in one.

    Parameters
    ----------
    parallel : bool
        Run the instances on Numba's thread pool.

    Returns
    -------
    callable
        The kernel (see :func:`run_rk4` for its arguments).
    """

    def kernel(params: FloatArray, states: FloatArray, history: FloatArray, bp_t: FloatArray, bp_u: FloatArray,
               bp_h: FloatArray, t0: float, t_end: float, h_max: float, sample_t: FloatArray, out: FloatArray) -> None:
        for i in nb.prange(params.shape[0]):
            p = params[i]
            y = states[i]
            hist = history[i]
            on = stages_on(p)
            n = y.shape[0]
            u = np.empty(2)
            k1 = np.empty(n)
            k2 = np.empty(n)
            k3 = np.empty(n)
            k4 = np.empty(n)
            yt = np.empty(n)
            y1 = np.empty(n)
            t = t0
            u_i = bp_u[i]
            h_i = bp_h[i]
            jd, jd_next = held_change(bp_t, u_i, t - p[P.delay_s], 0, 0)  # a breakpoint that holds a value: no stop
            jh, jh_next = held_change(bp_t, h_i, t, 0, 0)
            js = 0
            jf = 0
            while True:
                js, jf, t_next = at_stop(p, y, hist, t, t_end, bp_t, u_i, h_i, jd, jh, jd_next, jh_next, js, jf,
                                         sample_t, out[i], u)
                if t >= t_end - TIME_EPS_S:
                    break
                while t_next - t > TIME_EPS_S:
                    h = min(h_max, max_step_s(p), t_next - t)
                    s0 = rk4_step(p, y, u, h, k1, k2, k3, k4, yt, y1, on)  # the piece the step starts on
                    s1 = smooth_piece(p, y1, u, on)
                    if s1 != s0 and h > SWITCH_TOL_S:
                        lo = 0.0  # the step to the switch: last length still on s0's piece
                        hi = h
                        while hi - lo > SWITCH_TOL_S:
                            mid = 0.5 * (lo + hi)
                            rk4_step(p, y, u, mid, k1, k2, k3, k4, yt, y1, on)
                            if smooth_piece(p, y1, u, on) == s0:
                                lo = mid
                            else:
                                hi = mid
                        h = hi
                        rk4_step(p, y, u, h, k1, k2, k3, k4, yt, y1, on)
                    for a in range(n):
                        y[a] = y1[a]
                    t += h
                t = t_next
                jd, jd_next = held_change(bp_t, u_i, t - p[P.delay_s], jd, jd_next)
                jh, jh_next = held_change(bp_t, h_i, t, jh, jh_next)

    compiled: Callable[..., None] = compile_closure(kernel, "parallel" if parallel else "serial", parallel=parallel,
                                                    forward_copies=not parallel)
    return compiled


_SERIAL = make_rk4(False)
_PARALLEL = make_rk4(True)


def run_rk4(params: FloatArray, states: FloatArray, history: FloatArray, bp_t: FloatArray, bp_u: FloatArray,
            bp_h: FloatArray, t0: float, t_end: float, h_max: float, sample_t: FloatArray, out: FloatArray) -> None:
    """Second-order kernel for identification; over a long span, the parallel kernel (:data:`PARALLEL_SPAN_S`).

    Parameters
    ----------
    params : numpy.ndarray
        Kernel parameters, one row per instance.
    states : numpy.ndarray
        States, one row per instance, advanced in place.
    history : numpy.ndarray
        Each instance's feedback-delay ring (stage 14), advanced in place.
    bp_t : numpy.ndarray
        Input breakpoint times (s).
    bp_u : numpy.ndarray
        Command at each breakpoint, one row per instance (deg).
    bp_h : numpy.ndarray
        Hinge moment at each breakpoint, one row per instance (in·lb).
    t0 : float
        Start (s).
    t_end : float
        End (s).
    h_max : float
        Longest RK4 step (s); each instance also keeps under its own fastest stage's (:func:`max_step_s`).
    sample_t : numpy.ndarray
        Sample instants (s).
    out : numpy.ndarray
        Output block ``(instances, samples, outputs)``, filled.
    """
    kernel = _PARALLEL if t_end - t0 >= PARALLEL_SPAN_S else _SERIAL
    kernel(params, states, history, bp_t, bp_u, bp_h, t0, t_end, h_max, sample_t, out)
