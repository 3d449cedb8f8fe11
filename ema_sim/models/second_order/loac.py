"""LOAC: figure 26 in continuous time, adaptive Dormand–Prince with the stops located (table 5).

The reference the discrete models are judged against (table 6): :func:`figure26.derivatives` under
:func:`ema_sim.models.integrate.make_dopri5` at a tight tolerance, the position and free-play stops
located exactly, the integration broken at every input change.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from ema_sim.models.arrays import FloatArray, IntArray
from ema_sim.models.compiling import borrowing
from ema_sim.models.integrate import make_dopri5
from ema_sim.models.second_order.figure26 import (
    command_path,
    derivatives,
    feedback_value,
    free_play_subsystem,
    history_write,
    max_step_s,
    sample,
)
from ema_sim.models.second_order.params import P, X
from ema_sim.models.stages import TIME_EPS_S, zoh_index


@borrowing
def rhs(t: float, y: FloatArray, p: FloatArray, u: FloatArray, dydt: FloatArray) -> None:  # noqa: ARG001 - the integrator's signature
    """Figure 26's right-hand side in the integrators' signature.

    Parameters
    ----------
    t : float
        Time (s; the model is time-invariant).
    y : numpy.ndarray
        State (:data:`~ema_sim.models.second_order.params.X`).
    p : numpy.ndarray
        Kernel parameters.
    u : numpy.ndarray
        ``[command after stages 1–3 (deg), hinge moment (in·lb)]``.
    dydt : numpy.ndarray
        Filled with the derivatives.
    """
    derivatives(p, y, u[0], u[1], dydt)


_loac_dopri5 = make_dopri5(rhs)


@borrowing
def next_event(t_end: float, bp_t: FloatArray, m: int, jd_next: int, delay_s: float, jh_next: int,
               sample_t: FloatArray, js: int, k_samples: int, feedback_delay_s: float, jf: int) -> float:
    """Where an integration step must stop: the next delayed command, hinge moment or sample instant.

    Also the instant a delayed position sample reads (stage 14), so its entry is exact.

    Parameters
    ----------
    t_end : float
        End of the run (s).
    bp_t : numpy.ndarray
        Input breakpoint times (s).
    m : int
        Number of breakpoints.
    jd_next : int
        The delayed command's next breakpoint (the next that changes it, or simply the next).
    delay_s : float
        The command delay (s).
    jh_next : int
        The hinge moment's next breakpoint (likewise).
    sample_t : numpy.ndarray
        Sample instants (s).
    js : int
        The next sample.
    k_samples : int
        Number of samples.
    feedback_delay_s : float
        The feedback delay (s; 0: none).
    jf : int
        The next sample whose delayed position is not recorded yet.

    Returns
    -------
    float
        The time to stop at (s).
    """
    t_next = t_end
    if jd_next < m:
        t_next = min(t_next, bp_t[jd_next] + delay_s)
    if jh_next < m:
        t_next = min(t_next, bp_t[jh_next])
    if js < k_samples:
        t_next = min(t_next, sample_t[js])
    if feedback_delay_s > 0.0 and jf < k_samples:
        t_next = min(t_next, sample_t[jf] - feedback_delay_s)
    return t_next


@borrowing
def record_feedback(p: FloatArray, y: FloatArray, hist: FloatArray, t: float, hinge_moment_inlb: float,
                    sample_t: FloatArray, jf: int) -> int:
    """Stage 14 at a stop of a continuous integrator: record the reading, exactly at a delayed sample's instant.

    Parameters
    ----------
    p : numpy.ndarray
        Kernel parameters.
    y : numpy.ndarray
        State.
    hist : numpy.ndarray
        The instance's ring.
    t : float
        Now (s).
    hinge_moment_inlb : float
        Hinge moment (in·lb).
    sample_t : numpy.ndarray
        Sample instants (s).
    jf : int
        The next sample whose delayed instant was not reached.

    Returns
    -------
    int
        The next sample whose delayed instant is still ahead.
    """
    delay = p[P.feedback_delay_s]
    if delay <= 0.0:
        return jf
    while jf < sample_t.shape[0] and sample_t[jf] - delay <= t + TIME_EPS_S:
        jf += 1
    value, rate = feedback_value(p, y, hinge_moment_inlb)
    history_write(p, y, hist, t, value, rate, jf > 0 and abs(sample_t[jf - 1] - delay - t) < 1e-9)
    return jf




@borrowing
def at_stop(p: FloatArray, y: FloatArray, hist: FloatArray, t: float, t_end: float, bp_t: FloatArray,
            bp_u: FloatArray, bp_h: FloatArray, jd: int, jh: int, jd_next: int, jh_next: int, js: int, jf: int,
            sample_t: FloatArray, out: FloatArray, u: FloatArray) -> tuple[int, int, float]:
    """What a continuous integrator does at each stop: stage 14's reading, the samples due, the next stop.

    LOAC (Dormand–Prince) and RK4 share it; only how they cross to the next stop differs.

    Parameters
    ----------
    p : numpy.ndarray
        Kernel parameters.
    y : numpy.ndarray
        State.
    hist : numpy.ndarray
        The instance's feedback-delay ring.
    t : float
        Now (s).
    t_end : float
        End (s).
    bp_t : numpy.ndarray
        Input breakpoint times (s).
    bp_u : numpy.ndarray
        The instance's command at each breakpoint (deg).
    bp_h : numpy.ndarray
        The instance's hinge moment at each breakpoint (in·lb).
    jd : int
        Breakpoint of the delayed command.
    jh : int
        Breakpoint of the hinge moment.
    jd_next, jh_next : int
        The next breakpoint at which each must stop (``jd + 1``, ``jh + 1``, or the next that changes the input).
    js : int
        Next sample to take.
    jf : int
        Next sample whose delayed feedback instant is ahead.
    sample_t : numpy.ndarray
        Sample instants (s).
    out : numpy.ndarray
        The instance's output block ``(samples, outputs)``, filled as samples fall due.
    u : numpy.ndarray
        Set to the inputs of the piece that starts here.

    Returns
    -------
    tuple
        ``js``, ``jf`` and the next stop (s); the next stop is ``t`` itself once ``t_end`` is reached.
    """
    k_samples = sample_t.shape[0]
    jf = record_feedback(p, y, hist, t, bp_h[jh], sample_t, jf)
    while js < k_samples and sample_t[js] <= t + TIME_EPS_S:
        sample(p, y, command_path(p, bp_u[jd]), bp_h[jh], hist, sample_t[js], out[js])
        js += 1
    if t >= t_end - TIME_EPS_S:
        return js, jf, t
    t_next = next_event(t_end, bp_t, bp_t.shape[0], jd_next, p[P.delay_s], jh_next, sample_t, js, k_samples,
                        p[P.feedback_delay_s], jf)
    u[0] = command_path(p, bp_u[jd])
    u[1] = bp_h[jh]
    return js, jf, t_next

@nb.njit(cache=True)
def run_continuous(params: FloatArray, states: FloatArray, history: FloatArray, modes: IntArray, steps: FloatArray,
                   bp_t: FloatArray, bp_u: FloatArray, bp_h: FloatArray, t0: float, t_end: float, sample_t: FloatArray,
                   rtol: float, atol: float, out: FloatArray) -> None:
    """LOAC kernel: integrate every instance from ``t0`` to ``t_end``, breaking at each input change.

    Parameters
    ----------
    params : numpy.ndarray
        Kernel parameters, one row per instance.
    states : numpy.ndarray
        States, one row per instance, advanced in place.
    history : numpy.ndarray
        Each instance's feedback-delay ring (stage 14), advanced in place.
    modes : numpy.ndarray
        Each instance's stop modes (position, free play), updated in place.
    steps : numpy.ndarray
        Each instance's step size, updated in place (s).
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
    sample_t : numpy.ndarray
        Sample instants (s).
    rtol : float
        Relative tolerance.
    atol : float
        Absolute tolerance.
    out : numpy.ndarray
        Output block ``(instances, samples, outputs)``, filled.
    """
    limits = np.empty((2, 4))
    u = np.empty(2)
    for i in range(params.shape[0]):
        p = params[i]
        y = states[i]
        hist = history[i]
        mode = modes[i]
        half = 0.5 * p[P.free_play_deg]
        limits[0, 0] = X.position_deg
        limits[0, 1] = X.rate_dps
        limits[0, 2] = p[P.position_min_deg]
        limits[0, 3] = p[P.position_max_deg]
        limits[1, 0] = X.free_play_deg
        limits[1, 1] = X.free_play_rate_dps
        limits[1, 2] = -half
        limits[1, 3] = half
        if not free_play_subsystem(p):
            mode[1] = 2
            y[X.free_play_deg] = 0.0
            y[X.free_play_rate_dps] = 0.0
        h_max = max_step_s(p)
        t = t0
        jd = zoh_index(bp_t, t - p[P.delay_s], 0)
        jh = zoh_index(bp_t, t, 0)
        js = 0
        jf = 0
        while True:
            js, jf, t_next = at_stop(p, y, hist, t, t_end, bp_t, bp_u[i], bp_h[i], jd, jh, jd + 1, jh + 1, js, jf,
                                     sample_t, out[i], u)
            if t >= t_end - TIME_EPS_S:
                break
            if t_next > t + TIME_EPS_S:
                steps[i], _ = _loac_dopri5(p, u, y, t, t_next, steps[i], rtol, atol, h_max, limits, mode)
            t = t_next
            jd = zoh_index(bp_t, t - p[P.delay_s], jd)
            jh = zoh_index(bp_t, t, jh)
