"""HOAD2 and HOAD3: figure 30 discretized at 10,000 Hz with the flight/test elements (table 5, 4.2.5).

Stages 1–3 (command delay, 5 mV quantization through the command calibration, command noise) and
16–17 (feedback delay, noise and quantization through the feedback calibration) around the figure-30
chain of :mod:`.figure30`. Mechanics are symplectic Euler (stable for the stiff gear train), the
motor current and the bus voltage exact over each step with the bridge voltage held, as the EMAC's
sampled loops would be.
"""

from __future__ import annotations

import math

import numba as nb

from ema_sim.calibration import cubic, cubic_inverse, cubic_slope
from ema_sim.models import noise as nz
from ema_sim.models.arrays import FloatArray, UIntArray
from ema_sim.models.base import O_BUS, O_CUR, O_FLAGS, O_POS, O_RATE, O_SURF
from ema_sim.models.compiling import borrowing
from ema_sim.models.high_order.figure30 import (
    bus_current,
    bus_voltage_step,
    drive_flags,
    friction_step,
    gear_train,
    integrating,
    motor_current_step,
    servo_drive,
)
from ema_sim.models.high_order.params import P, X
from ema_sim.models.stages import (
    FLAG_BRAKE,
    FLAG_FREE_PLAY,
    FLAG_POSITION,
    TIME_EPS_S,
    TWO_PI,
    quantize,
    zoh_index,
)


@borrowing(nogil=True)
def command_in(params: FloatArray, c0: float, c1: float, c2: float, c3: float, bp_u: FloatArray, x_out: FloatArray,
               slope_out: FloatArray) -> None:
    """Stage 2 on every breakpoint of every instance: degrees → volts (command curve) → 5 mV → degrees → in.

    ``slope_out`` gets the inches per volt at the quantized command (for the command noise); with
    neither quantization nor command noise the command passes straight through and the slope is 0.
    The curve, its inverse and its slope are :mod:`ema_sim.calibration`'s compiled functions, the
    ones :class:`~ema_sim.calibration.Cubic` evaluates, so the result is the same to the last bit.

    Parameters
    ----------
    params : numpy.ndarray
        Kernel parameters, one row per instance (:data:`~ema_sim.models.high_order.params.P`).
    c0, c1, c2, c3 : float
        The channel's command calibration (degrees → volts).
    bp_u : numpy.ndarray
        Command at each breakpoint, one row per instance (deg).
    x_out : numpy.ndarray
        Filled with the command in screw inches.
    slope_out : numpy.ndarray
        Filled with the inches per volt there.
    """
    quant_any = False
    noise_any = False
    for i in range(params.shape[0]):
        quant_any = quant_any or params[i, P.quantization_v] > 0.0
        noise_any = noise_any or params[i, P.command_noise_v] > 0.0
    for i in range(params.shape[0]):
        dpi = params[i, P.deg_per_in]
        quant = params[i, P.quantization_v]
        for j in range(bp_u.shape[1]):
            u = bp_u[i, j]
            if not quant_any and not noise_any:
                x_out[i, j] = u / dpi
                slope_out[i, j] = 0.0
                continue
            deg = u
            if quant > 0.0:
                deg = cubic_inverse(c0, c1, c2, c3, quantize(cubic(c0, c1, c2, c3, u), quant))
            x_out[i, j] = deg / dpi
            slope_out[i, j] = 1.0 / (cubic_slope(c0, c1, c2, c3, deg) * dpi)


FEEDBACK_TOL = 1e-15
"""Relative Newton step at which stage 17's inverse calibration stops (every sample; the command path runs
its steps to the end)."""


@borrowing(error_model="numpy")
def feedback_deg(p: FloatArray, lvdt_in: float, noise_v: float) -> float:
    """Stages 16–17 at a sample instant: LVDT degrees → volts (+ noise) → 5 mV → degrees.

    The noise is the step's (:func:`run_discrete` draws it once a step, like the command's), so the
    outputs do not depend on when or how often the model is sampled: an FMU sampled at its
    communication points gives the same bits as a run sampled at its record's instants. Compiled
    without fast-math, like the whole kernel, so a C transcription (:mod:`ema_sim.export.hoad_stages`)
    returns the same bits.

    Parameters
    ----------
    p : numpy.ndarray
        Kernel parameters.
    lvdt_in : float
        The delayed filtered LVDT (in).
    noise_v : float
        The feedback noise now (V).

    Returns
    -------
    float
        The position feedback the FMU reads (deg).
    """
    deg = float(lvdt_in * p[P.deg_per_in])
    if p[P.quantization_v] <= 0.0 and p[P.feedback_noise_v] <= 0.0:
        return deg
    c0, c1 = p[P.feedback_cal_c0_deg], p[P.feedback_cal_c1_deg_per_v]
    c2, c3 = p[P.feedback_cal_c2_deg_per_v2], p[P.feedback_cal_c3_deg_per_v3]
    volts = cubic_inverse(c0, c1, c2, c3, deg, FEEDBACK_TOL)
    if p[P.feedback_noise_v] > 0.0:
        volts += noise_v
    return cubic(c0, c1, c2, c3, quantize(volts, p[P.quantization_v]))


DELAY_STEP_EPS = 1e-9
"""A delay within this share of a step of a whole number of steps is that whole number."""


@nb.njit(cache=True)
def split_delay(delay_s: float, dt: float) -> tuple[int, float]:
    """A delay as whole steps and the share of one more: ``(m, w)`` with ``delay_s = (m + w)·dt``.

    A delay between two steps is the mean over the step of what the delayed input does: ``(1 − w)`` of it as
    ``m`` steps delayed and ``w`` of it as ``m + 1`` (the LVDT reading blended; the drive's voltage and the
    integral's error over the step in which the delayed command changes). The outputs then move smoothly
    with the delay (identification fits it by least squares); a whole number of steps is the plain delay,
    bit for bit.

    Parameters
    ----------
    delay_s : float
        The delay (s).
    dt : float
        The step (s).

    Returns
    -------
    tuple of (int, float)
        Whole steps and the share of the next.
    """
    steps = delay_s / dt
    m = math.floor(steps + DELAY_STEP_EPS)
    w = steps - m
    return m, (w if w > DELAY_STEP_EPS else 0.0)


@nb.njit(cache=True, nogil=True, error_model="numpy")
def run_discrete(params: FloatArray, states: FloatArray, rngs: UIntArray, buffers: FloatArray, power: FloatArray,  # noqa: PLR0912, PLR0915 - one compiled loop
                 bp_t: FloatArray, cmd_in: FloatArray, cmd_slope: FloatArray, bp_h: FloatArray, t0: float, dt: float,
                 n_steps: int, sample_t: FloatArray, out: FloatArray) -> None:
    """HOAD2/HOAD3 fixed-step kernel: every instance through ``n_steps`` steps from ``t0``.

    A sample at time s reads the state of the last step at or before s.

    Parameters
    ----------
    params : numpy.ndarray
        Kernel parameters, one row per instance.
    states : numpy.ndarray
        States (:data:`~ema_sim.models.high_order.params.X`), one row per instance, advanced in place.
    rngs : numpy.ndarray
        Each instance's noise generator state.
    buffers : numpy.ndarray
        Each instance's feedback-delay ring of filtered LVDT values.
    power : numpy.ndarray
        Each instance's motor power (1 on, 0 off).
    bp_t : numpy.ndarray
        Input breakpoint times (s).
    cmd_in : numpy.ndarray
        The command after stage 2 at each breakpoint (in), one row per instance.
    cmd_slope : numpy.ndarray
        Its inches per volt, for the command noise.
    bp_h : numpy.ndarray
        Hinge moment at each breakpoint (in·lb), one row per instance.
    t0 : float
        Time of the first step (s).
    dt : float
        The step (s).
    n_steps : int
        Steps to take.
    sample_t : numpy.ndarray
        Sample instants (s).
    out : numpy.ndarray
        Output block ``(instances, samples, outputs)``, filled.
    """
    k_samples = sample_t.shape[0]
    for i in range(params.shape[0]):
        p = params[i]
        x = states[i]
        rng = rngs[i]
        buf = buffers[i]
        nbuf = buf.shape[0]
        kp, vmax, kv = p[P.position_gain_per_s], p[P.rate_limit_in_s], p[P.velocity_gain_a_per_in_s]
        imax, kc = p[P.current_limit_a], p[P.current_gain_v_per_a]
        vdb, duty = p[P.pwm_dead_band_v], p[P.pwm_max_duty_ratio]
        ki_dt = p[P.position_integral_per_s2] * dt
        r = p[P.stator_resistance_ohm]
        ke = p[P.back_emf_v_per_in_s]
        kf = p[P.force_per_amp_lbf_per_a]
        arm = p[P.crank_arm_in]
        vsup = p[P.bus_supply_v]
        rsrc = p[P.bus_source_resistance_ohm]
        xmin = p[P.position_min_in]
        xmax = p[P.position_max_in]
        delay = p[P.command_delay_s]
        dt_m = dt / p[P.motor_mass_lbs2_per_in]
        dt_s = dt / p[P.surface_mass_lbs2_per_in]
        inv_arm = 1.0 / arm
        inv_r = 1.0 / r
        decay_i = math.exp(-r * dt / p[P.inductance_h])
        g_lf = 1.0 - math.exp(-p[P.lvdt_filter_rad_s] * dt)
        decay_bus = math.exp(-dt / (rsrc * p[P.bus_capacitance_f]))
        a_cmd = math.exp(-TWO_PI * p[P.noise_bandwidth_hz] * dt) if p[P.noise_bandwidth_hz] > 0.0 else 0.0
        w_cmd = p[P.command_noise_v] * math.sqrt(1.0 - a_cmd * a_cmd)
        w_fbn = p[P.feedback_noise_v] * math.sqrt(1.0 - a_cmd * a_cmd)
        n_delay, w_fb = split_delay(p[P.feedback_delay_s], dt)
        n_delay = min(n_delay, nbuf - 2)
        _, w_cmd_delay = split_delay(delay, dt)
        delay_lo = delay - w_cmd_delay * dt  # whole steps (the delay itself when it is whole)
        delay_hi = delay_lo + dt
        on = power[i] > 0.5
        brake = 0.0 if on else p[P.brake_holding_lbf]
        fc = p[P.coulomb_friction_lbf] + brake
        fs = p[P.stiction_lbf] + brake
        fh = p[P.hinge_friction_lbf]
        xm = x[X.x_motor_in]
        vm = x[X.v_motor_in_s]
        xs = x[X.x_surface_in]
        vs = x[X.v_surface_in_s]
        cur = x[X.current_a]
        lf = x[X.lvdt_filtered_in]
        vbus = x[X.bus_v]
        ncmd = x[X.command_noise_v]
        nfb = x[X.feedback_noise_v]
        xi = x[X.integral_in_s]
        flags = int(x[X.flags])
        head = int(x[X.delay_head])
        rng_state = rng[0]  # held in a register through the run, stored once at the end
        jd = zoh_index(bp_t, t0 - delay_lo, 0)
        jd_hi = zoh_index(bp_t, t0 - delay_hi, 0)
        jh = zoh_index(bp_t, t0, 0)
        js = 0
        for k in range(n_steps + 1):
            t = t0 + k * dt
            while js < k_samples and (k == n_steps or sample_t[js] < t + dt - TIME_EPS_S):
                row = out[i, js]
                lagged = buf[head - n_delay if head >= n_delay else head - n_delay + nbuf]
                if w_fb > 0.0:
                    older = buf[head - n_delay - 1 if head > n_delay else head - n_delay - 1 + nbuf]
                    lagged += w_fb * (older - lagged)
                row[O_POS] = feedback_deg(p, lagged, nfb)
                row[O_SURF] = xs * p[P.deg_per_in]
                row[O_RATE] = vm * p[P.deg_per_in]
                row[O_CUR] = cur
                row[O_BUS] = vbus if on else 0.0
                row[O_FLAGS] = flags
                js += 1
            if k == n_steps:
                break
            jd = zoh_index(bp_t, t - delay_lo, jd)
            jh = zoh_index(bp_t, t, jh)
            hm = bp_h[i, jh]
            flags = 0
            # stages 1–3: delayed, quantized command with noise (volts → inches at its calibration slope)
            ncmd, rng_state = nz.band_limited_held(ncmd, a_cmd, w_cmd, rng_state)
            nfb, rng_state = nz.band_limited_held(nfb, a_cmd, w_fbn, rng_state)  # stage 17's, drawn with the step's
            xc = cmd_in[i, jd] + ncmd * cmd_slope[i, jd]
            xc_hi = xc  # the command one step older, when the delay falls between two steps and it differs
            if w_cmd_delay > 0.0:
                jd_hi = zoh_index(bp_t, t - delay_hi, jd_hi)
                if jd_hi != jd:
                    xc_hi = min(max(cmd_in[i, jd_hi] + ncmd * cmd_slope[i, jd_hi], xmin), xmax)
            if xc > xmax:
                xc = xmax
                flags |= FLAG_POSITION
            elif xc < xmin:
                xc = xmin
                flags |= FLAG_POSITION
            # stages 12, 15: gear train, LVDT and its filter
            fk, c, lvdt, free = gear_train(p, xm, xs)
            if free:
                flags |= FLAG_FREE_PLAY
            lf += g_lf * (lvdt - lf)
            head += 1
            if head == nbuf:
                head = 0
            buf[head] = lf
            # stages 4–8: controller electronics, current loop, PWM, motor
            if on:
                err = xc - lf
                _, _, _, v, sv, si, sp = servo_drive(kp, vmax, kv, imax, kc, r, ke, vdb, duty, xc, lf, xi, vm, cur,
                                                     vbus, 0, 0, 0, True)
                if xc_hi != xc:  # the delayed command changed within the step: the drive's mean over it
                    v_hi = servo_drive(kp, vmax, kv, imax, kc, r, ke, vdb, duty, xc_hi, lf, xi, vm, cur, vbus,
                                       0, 0, 0, True)[3]
                    v += w_cmd_delay * (v_hi - v)
                    err += w_cmd_delay * (xc_hi - xc)
                cur = motor_current_step(v, cur, vm, inv_r, ke, decay_i)
                if integrating(sv, si, sp):
                    xi += ki_dt * err
            else:
                v = 0.0
                cur = 0.0
                sv = si = 0
                sp = 1
                flags |= FLAG_BRAKE
            # stages 10–11, 13–14: motor and screw with friction (symplectic Euler), surface
            vm = friction_step(vm, kf * cur - fk + c * vs, fc, fs, dt_m, c * dt_m)
            xm += vm * dt
            if xm >= xmax:
                xm = xmax
                vm = min(vm, 0.0)
                flags |= FLAG_POSITION
            elif xm <= xmin:
                xm = xmin
                vm = max(vm, 0.0)
                flags |= FLAG_POSITION
            flags |= drive_flags(sv, si, sp, vm)
            vs = friction_step(vs, fk + c * vm + hm * inv_arm, fh, fh, dt_s, c * dt_s)
            xs += vs * dt
            # stage 9: the bus
            vbus = bus_voltage_step(vbus, bus_current(v, cur, vbus), vsup, rsrc, decay_bus)
        x[X.x_motor_in] = xm
        x[X.v_motor_in_s] = vm
        x[X.x_surface_in] = xs
        x[X.v_surface_in_s] = vs
        x[X.current_a] = cur
        x[X.lvdt_filtered_in] = lf
        x[X.bus_v] = vbus
        x[X.command_noise_v] = ncmd
        x[X.feedback_noise_v] = nfb
        x[X.integral_in_s] = xi
        x[X.flags] = flags
        x[X.delay_head] = head
        rng[0] = rng_state
