"""LOADA and LOADF: figure 26 stepped by Euler at a fixed rate (table 5, section 4.2.4).

* LOADA, the auto-coded model: forward Euler at ``rate_hz`` (800 Hz).
* LOADF, flight 1's hand-coded FORTRAN, with the faults section 4.2.4 names: backward-Euler
  integrators, the position feedback taken one frame ahead of where it belongs, and 200 Hz. It
  responds to a step sooner than LOAC does, the lead that over-predicted flight 1's margins.

Each step runs the stages in diagram order, each lag by its exact zero-order-hold gain. The stages
identification adds to figure 26 are stepped so the fixed rate cannot destabilise them: stage 9's
velocity loop by its exact step (:func:`~.figure26.drive_step`; Euler on a 300 Hz loop
diverges at 800 Hz), the linkage mode by its exact step on each segment of its spring
(:func:`~.figure26.linkage_step`); figure 26's own stages are Euler's, as the report's LOADA is.
"""

from __future__ import annotations

import functools
from collections.abc import Callable

import numba as nb
import numpy as np

from ema_sim.models.arrays import FloatArray
from ema_sim.models.compiling import row_values
from ema_sim.models.second_order import stage_set
from ema_sim.models.second_order.figure26 import (
    command_path,
    compliance_gain,
    compliance_time_constant_s,
    drive_on,
    free_play_subsystem,
    history_read,
    history_write,
    linkage_step,
    linkage_steps,
    lvdt,
    servo,
    surface_compliance,
    write_outputs,
)
from ema_sim.models.second_order.figure29 import free_play_accel, free_play_euler
from ema_sim.models.second_order.params import N_PARAMS, P, X
from ema_sim.models.stages import (
    TIME_EPS_S,
    compile_closure,
    euler_pair,
    first_order_lag,
    lag_gain,
    limited_integrator,
    transport_delay,
    zoh_index,
)

METHOD_FORWARD_EULER = 0
"""LOADA."""
METHOD_LOADF = 1
"""LOADF: backward Euler, the loop closed on the position one frame ahead."""


Kernel = Callable[[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, float, float, int,
                   FloatArray, FloatArray, int, int], None]
"""``kernel(params, states, history, bp_t, bp_u, bp_h, t0, dt, n_steps, sample_t, out, first, stop)``: instances
``first`` to ``stop - 1``."""


def make_euler(backward: bool, on: int) -> Kernel:  # noqa: PLR0915 - one compiled loop
    """The fixed-step kernel of one method and stage set, both compiled in as constants.

    Neither is tested per step: the stages outside ``on`` are not in the machine code at all.

    Parameters
    ----------
    backward : bool
        LOADF's backward Euler with the look-ahead feedback, rather than LOADA's forward Euler.
    on : int
        The stages that may be on (:mod:`.stage_set`).

    Returns
    -------
    callable
        The compiled kernel (see :func:`run_discrete` for its arguments).
    """

    def kernel(  # noqa: PLR0912, PLR0915 - the stages in diagram order, one step
        params: FloatArray, states: FloatArray, history: FloatArray, bp_t: FloatArray, bp_u: FloatArray,
        bp_h: FloatArray, t0: float, dt: float, n_steps: int, sample_t: FloatArray, out: FloatArray, first: int,
        stop: int,
    ) -> None:
        k_samples = sample_t.shape[0]
        k0 = int(t0 / dt + 0.5)  # t0 is on the model's step grid: time from the step count, as one run has it
        # what every instance reads at each step, found once for them all: the load's breakpoint, and the samples
        # due before the next step (a sample reads the state of the last step at or before it)
        held = np.empty(n_steps, dtype=np.int64)
        due = np.empty(n_steps + 1, dtype=np.int64)
        jh = 0
        js = 0
        for k in range(n_steps + 1):
            t = (k0 + k) * dt
            while js < k_samples and (k == n_steps or sample_t[js] < t + dt - TIME_EPS_S):
                js += 1
            due[k] = js
            if k < n_steps:
                jh = zoh_index(bp_t, t, jh)
                held[k] = jh
        for i in range(first, stop):
            p = row_values(params[i], N_PARAMS)  # values, not memory: what they derive is computed once
            x = states[i]
            hist = history[i]
            u_i = bp_u[i if bp_u.shape[0] > 1 else 0]  # one row: the instances share their inputs
            h_i = bp_h[i if bp_h.shape[0] > 1 else 0]
            jd = 0
            js = 0
            g_cmd = lag_gain(p[P.command_lag_hz], dt)
            g_fb = lag_gain(p[P.feedback_lag_hz], dt)
            g_c = compliance_gain(p, dt)
            free_play = bool(on & stage_set.FREE_PLAY) and free_play_subsystem(p)
            half = 0.5 * p[P.free_play_deg] if free_play else 0.0
            fp_acc_per_inlb = free_play_accel(1.0, p[P.surface_inertia_inlbs2])
            linkage = bool(on & stage_set.LINKAGE) and p[P.linkage_freq_hz] > 0.0
            link_steps = linkage_steps(p, dt) if linkage else np.empty((3, 6))
            in_loop = bool(on & stage_set.IN_LOOP_FILTER) and p[P.feedback_filter_in_loop] > 0.5
            fb_delay = p[P.feedback_delay_s] if on & stage_set.FEEDBACK_DELAY else 0.0
            integral = bool(on & stage_set.INTEGRAL) and p[P.integral_hz] > 0.0
            drive = bool(on & stage_set.DRIVE) and drive_on(p)
            damped = bool(on & stage_set.COMPLIANCE_LAG) and compliance_time_constant_s(p) > 0.0
            # figure 26's own states in locals (registers) over the steps, back in ``x`` for what reads it there
            cmd_lag, pos, rate = x[X.command_lag_deg], x[X.position_deg], x[X.rate_dps]
            fp, fp_rate = x[X.free_play_deg], x[X.free_play_rate_dps]
            fb_lag, compliance = x[X.feedback_lag_deg], x[X.compliance_deg]
            hm = h_i[zoh_index(bp_t, t0, 0)]
            _, flags, _, _, _ = servo(p, cmd_lag, pos, rate, x, hm, dt, on)
            fb_prev = fb_lag
            jq = -1  # the breakpoint the held command ``uq`` was computed from
            uq = 0.0
            for k in range(n_steps + 1):
                t = (k0 + k) * dt
                fb = fb_lag
                # (a call that continues a run finds its first entry written by the one before, rate and all)
                if fb_delay > 0.0 and (k > 0 or t > x[X.history_last_s] + TIME_EPS_S):
                    history_write(p, x, hist, t, fb, (fb - fb_prev) / dt, False)
                fb_prev = fb
                until = due[k]
                if js < until:  # the states write_outputs reads
                    x[X.position_deg], x[X.rate_dps] = pos, rate
                    x[X.free_play_deg], x[X.compliance_deg] = fp, compliance
                    while js < until:
                        if fb_delay > 0.0:
                            fb = history_read(x, hist, sample_t[js] - fb_delay)
                        write_outputs(p, x, fb, hm, flags, out[i, js], on)
                        js += 1
                if k == n_steps:
                    break
                # stages 1-4: delayed command, command error, quantizer (on a new breakpoint), command lag
                u_del, jd = transport_delay(bp_t, u_i, t, p[P.delay_s], jd)
                if jd != jq:
                    uq = command_path(p, u_del)
                    jq = jd
                hm = h_i[held[k]]
                cmd_lag = first_order_lag(cmd_lag, uq, g_cmd)
                # stages 5-11: the servo on the position (LOADF: one frame ahead), drive, limited integrators
                a, flags, _, integrand, drive_accel = servo(p, cmd_lag, pos + dt * rate if backward else pos, rate,
                                                            x, hm, dt, on)
                pos, rate = euler_pair(pos, rate, a, dt, backward)
                pos, rate, _ = limited_integrator(pos, rate, p[P.position_min_deg], p[P.position_max_deg])
                if integral:
                    x[X.integral_deg_s] += dt * integrand
                if drive:
                    x[X.drive_rate_dps] += dt * drive_accel
                # stage 15: free play; 17: the linkage mode (its exact step on the spring's segment)
                if free_play:
                    fp, fp_rate = free_play_euler(fp, fp_rate, hm * fp_acc_per_inlb, dt, half, backward)
                if linkage:
                    x[X.linkage_deg], x[X.linkage_rate_dps] = linkage_step(p, x, hm, drive_accel if in_loop else a,
                                                                           link_steps)
                # stages 12-13: LVDT and its feedback lag (gain 1 when off); 16: compliance
                fb_pos = pos + dt * rate if backward else pos
                fb_lag = first_order_lag(fb_lag, lvdt(p, fb_pos, hm, on), g_fb)
                if damped:  # read only when damped (an undamped compliance is its static deflection)
                    compliance = first_order_lag(compliance, surface_compliance(p, hm, on), g_c)
            x[X.command_lag_deg], x[X.position_deg], x[X.rate_dps] = cmd_lag, pos, rate
            x[X.free_play_deg], x[X.free_play_rate_dps] = fp, fp_rate
            x[X.feedback_lag_deg], x[X.compliance_deg] = fb_lag, compliance

    compiled: Kernel = compile_closure(kernel, f"{'backward' if backward else 'forward'}_{on}", forward_copies=True)
    return compiled


def make_parallel(serial: Kernel, name: str) -> Kernel:
    """The instances of ``serial`` spread over Numba's thread pool, one call of it per :data:`PARALLEL_CHUNK`.

    The per-instance arithmetic is ``serial``'s own machine code, so the outputs are the same bit for bit, and
    this thin loop compiles in seconds where a ``prange`` over the whole step loop took minutes.

    Parameters
    ----------
    serial : callable
        The compiled serial kernel (:func:`make_euler`).
    name : str
        Its cache name.

    Returns
    -------
    callable
        The compiled parallel kernel, with ``serial``'s arguments.
    """

    def kernel(
        params: FloatArray, states: FloatArray, history: FloatArray, bp_t: FloatArray, bp_u: FloatArray,
        bp_h: FloatArray, t0: float, dt: float, n_steps: int, sample_t: FloatArray, out: FloatArray, first: int,
        stop: int,
    ) -> None:
        for c in nb.prange((stop - first + PARALLEL_CHUNK - 1) // PARALLEL_CHUNK):
            lo = first + c * PARALLEL_CHUNK
            serial(params, states, history, bp_t, bp_u, bp_h, t0, dt, n_steps, sample_t, out, lo,
                   min(lo + PARALLEL_CHUNK, stop))

    compiled: Kernel = compile_closure(kernel, f"{name}_parallel", parallel=True)
    return compiled


PARALLEL_STEPS = 20_000
"""A batch runs its instances on parallel threads only when it takes at least this many instance-steps in all
and Numba has more than one thread: a thread pool's start and join cost more than a frame of a few
instances, and the outputs are the same bit for bit either way."""


PARALLEL_CHUNK = 8
"""Instances a thread takes at a time from a parallel batch, one call of the serial kernel (which finds what they
share once per call): a thread that another process slows takes fewer of them, where halves fixed in advance
would wait for it."""


@functools.cache
def kernel(method: int, on: int, parallel: bool = False) -> Kernel:
    """The compiled kernel of a method and a stage set (compiled on first use, then cached on disk).

    Parameters
    ----------
    method : int
        :data:`METHOD_FORWARD_EULER` (LOADA) or :data:`METHOD_LOADF`.
    on : int
        The stages that may be on (:func:`~.stage_set.kernel_set`).
    parallel : bool
        The instances on Numba's thread pool.

    Returns
    -------
    callable
        The kernel (see :func:`run_discrete` for its arguments).
    """
    serial = _serial(method, on)
    return make_parallel(serial, f"{'backward' if method == METHOD_LOADF else 'forward'}_{on}") if parallel else serial


@functools.cache
def _serial(method: int, on: int) -> Kernel:
    return make_euler(method == METHOD_LOADF, on)


def run_discrete(params: FloatArray, states: FloatArray, history: FloatArray, bp_t: FloatArray, bp_u: FloatArray,
                 bp_h: FloatArray, t0: float, dt: float, n_steps: int, sample_t: FloatArray, method: int,
                 out: FloatArray, on: int = stage_set.ALL) -> None:
    """Fixed-step LOADA/LOADF kernel: every instance through ``n_steps`` steps from ``t0``.

    A sample at time s reads the state of the last step at or before s (a DAU sampling a
    zero-order-held discrete output).

    Parameters
    ----------
    params : numpy.ndarray
        Kernel parameters, one row per instance (:data:`~ema_sim.models.second_order.params.P`).
    states : numpy.ndarray
        States, one row per instance, advanced in place.
    history : numpy.ndarray
        Each instance's feedback-delay ring (stage 14), advanced in place.
    bp_t : numpy.ndarray
        Input breakpoint times (s).
    bp_u : numpy.ndarray
        Command at each breakpoint, one row per instance or one for all (deg).
    bp_h : numpy.ndarray
        Hinge moment at each breakpoint, one row per instance or one for all (in·lb).
    t0 : float
        Time of the first step (s).
    dt : float
        The step (s).
    n_steps : int
        Steps to take.
    sample_t : numpy.ndarray
        Sample instants (s).
    method : int
        :data:`METHOD_FORWARD_EULER` (LOADA) or :data:`METHOD_LOADF`.
    out : numpy.ndarray
        Output block ``(instances, samples, outputs)``, filled.
    on : int
        The stages that may be on (:func:`~.stage_set.kernel_set`; :data:`~.stage_set.ALL` decides each
        by its parameter).
    """
    n = params.shape[0]
    parallel = n > 1 and n * n_steps >= PARALLEL_STEPS and nb.get_num_threads() > 1
    args = (params, states, history, bp_t, bp_u, bp_h, t0, dt, n_steps, sample_t, out, 0, n)
    if not parallel:
        kernel(method, on)(*args)
        return
    with nb.parallel_chunksize(1):  # type: ignore[attr-defined] # threads take chunks as they finish them
        kernel(method, on, parallel)(*args)
