"""Figure 26: the modified second-order model with its nonlinear elements, each stage written once.

command path (FMU side, held between frames)
    1. time delay            command to first motion (section 2.3)
    2. command error         (1 + Kb)·u + offset (3.1.2.2)
    3. quantization          D/A resolution, 0.020° (3.1.2.2)
actuator (integrated at the model's own rate)
    4. command lag           optional first-order lag on the command
    5. compliance correction K_CP, a gain that varies with load (3.1.2.4)
    6. threshold             optional dead zone on the servo error
    7. velocity demand       ωn/(2ζ)·(error + ωi·∫error): optional integral action (figure 30's stage 4),
                             integrating while nothing limits; rate limit rl + K2·hm/marm (3.1.2.1; :mod:`.figure21`)
    8. servo compliance      optional: an aiding hinge moment adds (ωn/2ζ)·droop·hm to the rate (2.8)
    9. current-limited drive optional velocity loop whose acceleration saturates (figure 30's stage 5)
   10. second order          ωn, ζ (figure 21)
   11. position limits       on the states, so nothing winds up
feedback
   12. LVDT compliance       optional deflection with load the LVDT reads, linear or stiffening at a knee
   13. feedback lag          optional first-order lag on the LVDT reading (outside the loop)
   14. feedback delay        optional delay from motion to the reading (HOAD3's 2 ms)
       in-loop filter        optional reading of figure 21: the loop closes on a first-order filtered LVDT
                             whose corner is 2ζωn, so the actuator leads the position by ẋ/(2ζωn)
surface (outside the servo loop)
   15. free play             hm / Is double-integrated in a limited integrator, ±width/2 (:mod:`.figure29`)
   16. compliance            optional deflection with hinge moment, linear or stiffening at a knee
                             (figures 16, 33), with optional hysteretic damping (figure 36): h/ω on the linkage
   17. linkage mode          optional: the surface's inertia on the linkage spring (stages 15–16 as its
                             force–deflection curve, free play its dead zone), excited by the actuator's
                             acceleration and the hinge moment (figures 32, 33)

The integrators (:mod:`.loada`, :mod:`.loac`, :mod:`.rk4`) call these functions: :func:`command_path`
for stages 2–3, :func:`servo` for stages 5–10, :func:`derivatives` for the whole chain in continuous
time, :func:`sample` and :func:`write_outputs` for what the outside sees, :func:`history_write` and
:func:`history_read` for stage 14 (:mod:`.feedback_delay`); stages 15–17, the surface outside the loop, are in
:mod:`.surface`. One concept, the servo loop and its whole chain in continuous time, kept in one module of about
700 lines: its stages are read in the diagram's order, and each is short.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from ema_sim.models.arrays import FloatArray
from ema_sim.models.base import O_BUS, O_CUR, O_FLAGS, O_POS, O_RATE, O_SURF
from ema_sim.models.second_order import stage_set
from ema_sim.models.second_order.feedback_delay import (
    HISTORY_SIZE,
    NEVER_S,
    history_read,
    history_spacing_s,
    history_write,
)
from ema_sim.models.second_order.figure21 import load_rate_limits, rate_loop, velocity_command
from ema_sim.models.second_order.figure29 import free_play_accel
from ema_sim.models.second_order.params import P, X
from ema_sim.models.second_order.surface import (
    compliance_deflection,
    compliance_time_constant_s,
    free_play_subsystem,
    linkage_accel,
    linkage_damping,
    linkage_rest,
    linkage_slope,
    linkage_spring,
    linkage_step,
    linkage_steps,
    surface_compliance,
)
from ema_sim.models.stages import (
    FLAG_CURRENT,
    FLAG_FREE_PLAY,
    FLAG_POSITION,
    FLAG_RATE,
    FLAG_THRESHOLD,
    TWO_PI,
    dead_zone,
    jit,
    quantize,
)

# The diagram's stages are all named here, those of stages 14-17 from their own modules, so a reader (and the
# integrators, the C export) finds every stage of figure 26 in one namespace.
__all__ = [
    "HISTORY_SIZE", "NEVER_S", "actuator_position", "command_error", "command_path", "compliance_correction",
    "compliance_deflection", "compliance_gain", "compliance_time_constant_s", "current_limited_drive",
    "derivatives", "drive_on", "drive_step", "feedback_value", "free_play_subsystem", "history_read",
    "history_spacing_s", "history_write", "linkage_accel", "linkage_damping", "linkage_rest", "linkage_slope",
    "linkage_spring", "linkage_step", "linkage_steps", "lvdt", "max_step_s", "sample", "servo", "servo_input",
    "stages_on", "stages_on_any", "surface_compliance", "trim", "velocity_demand", "write_outputs",
]

@jit
def command_error(u: float, kb: float, offset_deg: float) -> float:
    """Stage 2, the command error of section 3.1.2.2: ``(1 + Kb)·u + offset``.

    Parameters
    ----------
    u : float
        Command (deg).
    kb : float
        Slope error.
    offset_deg : float
        Bias (deg).

    Returns
    -------
    float
        The command the actuator sees (deg).
    """
    return (1.0 + kb) * u + offset_deg


@jit
def command_path(p: FloatArray, u: float) -> float:
    """Stages 2–3 on the (already delayed) command.

    Parameters
    ----------
    p : numpy.ndarray
        Kernel parameters (:data:`~ema_sim.models.second_order.params.P`).
    u : float
        The delayed command (deg).

    Returns
    -------
    float
        The command after the command error and the quantizer (deg).
    """
    return quantize(command_error(u, p[P.kb], p[P.offset_deg]), p[P.quantization_deg])


@jit
def compliance_correction(u: float, hinge_moment_inlb: float, kcp_per_kinlb: float) -> float:
    """Stage 5, the compliance correction gain of section 3.1.2.4 on the command.

    ``K_CP = 1 + kcp·(aiding load)/1000``: a hinge moment that aids the commanded direction raises
    the gain, an opposing one lowers it.

    Parameters
    ----------
    u : float
        Command (deg).
    hinge_moment_inlb : float
        Hinge moment (in·lb).
    kcp_per_kinlb : float
        Gain change per 1000 in·lb of aiding load (0: off).

    Returns
    -------
    float
        The corrected command (deg).
    """
    if kcp_per_kinlb == 0.0 or u == 0.0:
        return u
    aiding = hinge_moment_inlb if u > 0.0 else -hinge_moment_inlb
    return u * (1.0 + kcp_per_kinlb * aiding * 1e-3)


@jit
def servo_input(p: FloatArray, y: FloatArray, u: float) -> float:
    """Stage 4 seen by stage 5 in continuous time: the command lag's state, or the command when it is off.

    Parameters
    ----------
    p : numpy.ndarray
        Kernel parameters.
    y : numpy.ndarray
        State (:data:`~ema_sim.models.second_order.params.X`).
    u : float
        The command after stages 1–3 (deg).

    Returns
    -------
    float
        The servo's input (deg).
    """
    return y[X.command_lag_deg] if p[P.command_lag_hz] > 0.0 else u


@jit
def drive_on(p: FloatArray) -> bool:
    """Stage 9 runs: a current limit, or an in-loop filter whose actuator acceleration moves a linkage mode.

    Parameters
    ----------
    p : numpy.ndarray
        Kernel parameters.

    Returns
    -------
    bool
        True when the drive's velocity is a state.
    """
    return bool(p[P.accel_limit_dps2] < math.inf or (p[P.feedback_filter_in_loop] > 0.5 and p[P.linkage_freq_hz] > 0.0))


@jit
def stages_on(p: FloatArray) -> int:
    """The optional stages this parameter set runs (:mod:`.stage_set`): each bit where its parameter is not off.

    Parameters
    ----------
    p : numpy.ndarray
        Kernel parameters.

    Returns
    -------
    int
        The set, as bits.
    """
    on = 0
    if p[P.kcp_per_kinlb] != 0.0:
        on |= stage_set.KCP
    if p[P.threshold_deg] > 0.0:
        on |= stage_set.THRESHOLD
    if p[P.integral_hz] > 0.0:
        on |= stage_set.INTEGRAL
    if p[P.servo_compliance_deg_per_kinlb] != 0.0:
        on |= stage_set.SERVO_COMPLIANCE
    if drive_on(p):
        on |= stage_set.DRIVE
    if p[P.lvdt_compliance_deg_per_kinlb] != 0.0 or p[P.lvdt_compliance_stiff_deg_per_kinlb] != 0.0:
        on |= stage_set.LVDT_COMPLIANCE
    if p[P.feedback_delay_s] > 0.0:
        on |= stage_set.FEEDBACK_DELAY
    if p[P.feedback_filter_in_loop] > 0.5:
        on |= stage_set.IN_LOOP_FILTER
    if p[P.free_play_deg] > 0.0:
        on |= stage_set.FREE_PLAY
    if p[P.compliance_deg_per_kinlb] != 0.0 or p[P.compliance_stiff_deg_per_kinlb] != 0.0:
        on |= stage_set.COMPLIANCE
    if compliance_time_constant_s(p) > 0.0:
        on |= stage_set.COMPLIANCE_LAG
    if p[P.linkage_freq_hz] > 0.0:
        on |= stage_set.LINKAGE
    return on


@nb.njit(cache=True)
def stages_on_any(params: FloatArray) -> int:
    """The optional stages any instance of a batch runs: the union of :func:`stages_on` over its rows.

    Parameters
    ----------
    params : numpy.ndarray
        Kernel parameters, one row per instance.

    Returns
    -------
    int
        The set, as bits.
    """
    on = 0
    for i in range(params.shape[0]):
        on |= stages_on(params[i])
    return on


@jit
def velocity_demand(p: FloatArray, u_in: float, x: float, integral_deg_s: float,
                    hinge_moment_inlb: float, on: int = stage_set.ALL) -> tuple[float, float, int, int, float]:
    """Stages 5–8: the limited velocity command, the load's droop rate, flags, smooth piece, integrand.

    Parameters
    ----------
    p : numpy.ndarray
        Kernel parameters.
    u_in : float
        The servo's input (deg).
    x : float
        The position the loop closes on (deg).
    integral_deg_s : float
        The integral of the servo error (deg·s).
    hinge_moment_inlb : float
        Hinge moment (in·lb).
    on : int
        The stages that may be on (:mod:`.stage_set`).

    Returns
    -------
    command : float
        The rate-limited velocity command (°/s).
    droop : float
        The rate an aiding hinge moment adds through the servo's compliance (°/s).
    flags : int
        Rate-limit and threshold flags.
    piece : int
        ``3·(rate limit side) + (dead zone side)``.
    integrand : float
        The servo error while the integral runs (outside the threshold, rate unlimited), else 0.
    """
    wn, zeta = p[P.wn_rad_s], p[P.zeta]
    u_eff = compliance_correction(u_in, hinge_moment_inlb, p[P.kcp_per_kinlb]) if on & stage_set.KCP else u_in
    e = u_eff - x
    thresholded = bool(on & stage_set.THRESHOLD) and p[P.threshold_deg] > 0.0
    if thresholded:
        e_dz, dz = dead_zone(e, p[P.threshold_deg])
    else:  # the zero-width dead zone, e − 0
        e_dz, dz = e, 0
    up, down = load_rate_limits(p[P.rate_limit_dps], p[P.k2_dps_per_lb], hinge_moment_inlb, p[P.moment_arm_in])
    wi = TWO_PI * p[P.integral_hz] if on & stage_set.INTEGRAL else 0.0
    target = x + e_dz + wi * integral_deg_s if wi > 0.0 else x + e_dz
    vc, side = velocity_command(target, x, wn, zeta, up, down)
    droop = 0.0
    if on & stage_set.SERVO_COMPLIANCE:
        droop = wn / (2.0 * zeta) * p[P.servo_compliance_deg_per_kinlb] * hinge_moment_inlb * 1e-3
    flags = FLAG_RATE if side != 0 else 0
    if thresholded and e_dz == 0.0:
        flags |= FLAG_THRESHOLD
    integrand = e if (wi > 0.0 and side == 0 and (not thresholded or dz != 0)) else 0.0
    return vc, droop, flags, 3 * side + dz, integrand


@jit
def drive_step(p: FloatArray, dt: float) -> tuple[float, float]:
    """Stage 9's velocity loop over a fixed step: its gain and how far its mean rate leads its start.

    In continuous time the gain is ωv and there is no step. Over a step ``dt`` with the command c
    held, ``dv/dt = ωv·(c − v)`` moves v by ``g·(c − v)``, ``g = 1 − e^(−ωv·dt)``, and averages
    ``v + (dt/g − 1/ωv)·Δv/dt`` over the step: the gain ``g/dt`` is that exact step's (Euler with ωv
    itself diverges once ωv·dt > 2: a 300 Hz loop beyond 254 Hz of it at 800 Hz), and the rate loop
    it drives integrates the mean (exact below the current limit), not the rate a step late.

    Parameters
    ----------
    p : numpy.ndarray
        Kernel parameters.
    dt : float
        The fixed step (s); 0 in continuous time.

    Returns
    -------
    gain : float
        rad/s.
    lead : float
        s: the mean rate over the step is the rate at its start plus ``lead·dv/dt``.
    """
    wv = TWO_PI * p[P.velocity_loop_hz]
    if dt <= 0.0:
        return wv, 0.0
    g = -math.expm1(-wv * dt)
    return g / dt, dt / g - 1.0 / wv


@jit
def current_limited_drive(p: FloatArray, command_dps: float, droop_dps: float, v_drive: float,
                          wv: float) -> tuple[float, int]:
    """Stage 9: the drive's velocity loop, its acceleration saturated at the current limit.

    ``dv/dt = sat(ωv·(command − v)) + ωv·droop``: a held load shifts the rate it settles at by the
    droop; at the limit it still adds its own acceleration.

    Parameters
    ----------
    p : numpy.ndarray
        Kernel parameters.
    command_dps : float
        The limited velocity command (°/s).
    droop_dps : float
        The load's droop rate (°/s).
    v_drive : float
        The drive's rate (°/s).
    wv : float
        The velocity loop's gain (rad/s; :func:`drive_step`).

    Returns
    -------
    acceleration : float
        dv/dt (°/s²).
    side : int
        +1/−1 on the current limit, 0 below it.
    """
    acc = wv * (command_dps - v_drive)
    limit = p[P.accel_limit_dps2]
    side = 0
    if acc > limit:
        acc = limit
        side = 1
    elif acc < -limit:
        acc = -limit
        side = -1
    return acc + wv * droop_dps, side


@jit
def servo(p: FloatArray, u_in: float, x: float, v: float, y: FloatArray, hinge_moment_inlb: float,
          dt: float = 0.0, on: int = stage_set.ALL) -> tuple[float, int, int, float, float]:
    """Stages 5–10: the actuator's acceleration, its limit flags, its smooth piece and two state rates.

    Parameters
    ----------
    p : numpy.ndarray
        Kernel parameters.
    u_in : float
        The servo's input (deg).
    x : float
        The position the loop closes on (deg).
    v : float
        The rate (°/s).
    y : numpy.ndarray
        State (the integral and the drive's rate).
    hinge_moment_inlb : float
        Hinge moment (in·lb).
    dt : float
        The fixed step (s) stage 9 is discretised for; 0 in continuous time.
    on : int
        The stages that may be on (:mod:`.stage_set`).

    Returns
    -------
    acceleration : float
        °/s².
    flags : int
        Rate-limit, current-limit and threshold flags.
    piece : int
        ``9·(current limit side) + 3·(rate limit side) + (dead zone side)``: smooth while it holds.
    integral_rate : float
        d/dt of the integral state (deg).
    drive_accel : float
        d/dt of the drive's rate (°/s²; 0 when stage 9 is off).
    """
    vc, droop, flags, piece, integrand = velocity_demand(p, u_in, x, y[X.integral_deg_s], hinge_moment_inlb, on)
    if on & stage_set.DRIVE and drive_on(p):
        wv, lead = drive_step(p, dt)
        drive_accel, cside = current_limited_drive(p, vc, droop, y[X.drive_rate_dps], wv)
        v_drive = y[X.drive_rate_dps]
        if lead > 0.0:
            v_drive += lead * drive_accel
        if cside != 0:
            flags |= FLAG_CURRENT
            integrand = 0.0
        piece += 9 * cside
    else:
        drive_accel = 0.0
        v_drive = vc + droop
    return rate_loop(v_drive, v, p[P.wn_rad_s], p[P.zeta]), flags, piece, integrand, drive_accel


@jit
def lvdt(p: FloatArray, x_pos: float, hinge_moment_inlb: float, on: int = stage_set.ALL) -> float:
    """Stage 12: what the LVDT reads, the servo position plus the compliance the loop does not remove.

    Parameters
    ----------
    p : numpy.ndarray
        Kernel parameters.
    x_pos : float
        Servo position (deg).
    hinge_moment_inlb : float
        Hinge moment (in·lb).
    on : int
        The stages that may be on (:mod:`.stage_set`).

    Returns
    -------
    float
        The LVDT reading (deg).
    """
    if not on & stage_set.LVDT_COMPLIANCE:
        return x_pos
    return x_pos + compliance_deflection(hinge_moment_inlb, p[P.lvdt_compliance_deg_per_kinlb],
                                         p[P.lvdt_compliance_knee_inlb], p[P.lvdt_compliance_stiff_deg_per_kinlb])


@jit
def actuator_position(p: FloatArray, x: float, v: float, on: int = stage_set.ALL) -> float:
    """Where the actuator is: the position, or ahead of it by ẋ/(2ζωn) when the loop closes on a filtered LVDT.

    Parameters
    ----------
    p : numpy.ndarray
        Kernel parameters.
    x : float
        The position state (deg).
    v : float
        Its rate (°/s).
    on : int
        The stages that may be on (:mod:`.stage_set`).

    Returns
    -------
    float
        The actuator's position (deg).
    """
    if on & stage_set.IN_LOOP_FILTER and p[P.feedback_filter_in_loop] > 0.5:
        return float(x + v / (2.0 * p[P.zeta] * p[P.wn_rad_s]))
    return x


@jit
def derivatives(p: FloatArray, y: FloatArray, u: float, hinge_moment_inlb: float, dydt: FloatArray,
                on: int = stage_set.ALL) -> int:
    """Stages 4–17 in continuous time: the state's derivatives into ``dydt`` (position limits are the integrator's).

    Parameters
    ----------
    p : numpy.ndarray
        Kernel parameters.
    y : numpy.ndarray
        State (:data:`~ema_sim.models.second_order.params.X`).
    u : float
        The command after stages 1–3 (deg).
    hinge_moment_inlb : float
        Hinge moment (in·lb).
    dydt : numpy.ndarray
        Filled with the derivatives.
    on : int
        The stages that may be on (:mod:`.stage_set`).

    Returns
    -------
    int
        The smooth piece the state is on (:func:`servo`), for an integrator that must not step across a switch.
    """
    if p[P.command_lag_hz] > 0.0:
        dydt[X.command_lag_deg] = TWO_PI * p[P.command_lag_hz] * (u - y[X.command_lag_deg])
    else:
        dydt[X.command_lag_deg] = 0.0
    a, _, piece, integrand, drive_accel = servo(p, servo_input(p, y, u), y[X.position_deg], y[X.rate_dps], y,
                                                hinge_moment_inlb, 0.0, on)
    dydt[X.position_deg] = y[X.rate_dps]
    dydt[X.rate_dps] = a
    dydt[X.integral_deg_s] = integrand
    dydt[X.drive_rate_dps] = drive_accel
    dydt[X.free_play_deg] = y[X.free_play_rate_dps]
    dydt[X.free_play_rate_dps] = free_play_accel(hinge_moment_inlb, p[P.surface_inertia_inlbs2])
    if p[P.feedback_lag_hz] > 0.0:
        target = lvdt(p, y[X.position_deg], hinge_moment_inlb, on)
        dydt[X.feedback_lag_deg] = TWO_PI * p[P.feedback_lag_hz] * (target - y[X.feedback_lag_deg])
    else:
        dydt[X.feedback_lag_deg] = 0.0
    tau_c = compliance_time_constant_s(p) if on & stage_set.COMPLIANCE_LAG else 0.0
    if tau_c > 0.0 and p[P.linkage_freq_hz] <= 0.0:
        dydt[X.compliance_deg] = (surface_compliance(p, hinge_moment_inlb, on) - y[X.compliance_deg]) / tau_c
    else:
        dydt[X.compliance_deg] = 0.0
    if on & stage_set.LINKAGE and p[P.linkage_freq_hz] > 0.0:
        actuator_accel = drive_accel if p[P.feedback_filter_in_loop] > 0.5 else a
        dydt[X.linkage_deg] = y[X.linkage_rate_dps]
        dydt[X.linkage_rate_dps] = linkage_accel(p, y, hinge_moment_inlb, actuator_accel)
    else:
        dydt[X.linkage_deg] = 0.0
        dydt[X.linkage_rate_dps] = 0.0
    dydt[X.history_head] = 0.0
    dydt[X.history_last_s] = 0.0
    return piece


@jit
def feedback_value(p: FloatArray, y: FloatArray, hinge_moment_inlb: float) -> tuple[float, float]:
    """Stages 12–13: the LVDT reading before the delay, and its rate (stage 14 records both).

    Parameters
    ----------
    p : numpy.ndarray
        Kernel parameters.
    y : numpy.ndarray
        State.
    hinge_moment_inlb : float
        Hinge moment (in·lb).

    Returns
    -------
    value : float
        The reading (deg).
    rate : float
        Its rate between input changes (°/s).
    """
    reading = lvdt(p, y[X.position_deg], hinge_moment_inlb)
    if p[P.feedback_lag_hz] > 0.0:
        return y[X.feedback_lag_deg], TWO_PI * p[P.feedback_lag_hz] * (reading - y[X.feedback_lag_deg])
    return reading, y[X.rate_dps]


@jit
def write_outputs(p: FloatArray, x: FloatArray, position_fb: float, hinge_moment_inlb: float, flags: int,
                  row: FloatArray, on: int = stage_set.ALL) -> None:
    """Stages 12–17 seen from outside: LVDT position, surface angle, rate and flags into one output row.

    Parameters
    ----------
    p : numpy.ndarray
        Kernel parameters.
    x : numpy.ndarray
        State.
    position_fb : float
        The position feedback (deg).
    hinge_moment_inlb : float
        Hinge moment (in·lb).
    flags : int
        The servo's flags (position and free-play flags are added here).
    row : numpy.ndarray
        The output row (:data:`~ema_sim.models.base.OUTPUT_FIELDS`).
    on : int
        The stages that may be on (:mod:`.stage_set`).
    """
    row[O_POS] = position_fb
    actuator = lvdt(p, actuator_position(p, x[X.position_deg], x[X.rate_dps], on), hinge_moment_inlb, on)
    half = 0.5 * p[P.free_play_deg] if on & stage_set.FREE_PLAY else 0.0
    if on & stage_set.LINKAGE and p[P.linkage_freq_hz] > 0.0:
        row[O_SURF] = actuator + x[X.linkage_deg]
        in_free_play = half > 0.0 and abs(x[X.linkage_deg]) <= half
    else:
        damped = bool(on & stage_set.COMPLIANCE_LAG) and compliance_time_constant_s(p) > 0.0
        compliance = x[X.compliance_deg] if damped else surface_compliance(p, hinge_moment_inlb, on)
        row[O_SURF] = actuator + x[X.free_play_deg] + compliance
        in_free_play = half > 0.0 and abs(x[X.free_play_deg]) < half
    row[O_RATE] = x[X.rate_dps]
    row[O_CUR] = np.nan
    row[O_BUS] = np.nan
    if x[X.position_deg] >= p[P.position_max_deg] or x[X.position_deg] <= p[P.position_min_deg]:
        flags |= FLAG_POSITION
    if half > 0.0 and not in_free_play:
        flags |= FLAG_FREE_PLAY
    row[O_FLAGS] = flags


@jit
def sample(p: FloatArray, y: FloatArray, u: float, hinge_moment_inlb: float, hist: FloatArray, t: float,
           row: FloatArray) -> None:
    """The continuous models' outputs at a sample instant, from the state and the held inputs.

    Parameters
    ----------
    p : numpy.ndarray
        Kernel parameters.
    y : numpy.ndarray
        State.
    u : float
        The command after stages 1–3 (deg).
    hinge_moment_inlb : float
        Hinge moment (in·lb).
    hist : numpy.ndarray
        Stage 14's ring.
    t : float
        The sample instant (s).
    row : numpy.ndarray
        The output row.
    """
    _, flags, _, _, _ = servo(p, servo_input(p, y, u), y[X.position_deg], y[X.rate_dps], y, hinge_moment_inlb)
    position_fb, _ = feedback_value(p, y, hinge_moment_inlb)
    if p[P.feedback_delay_s] > 0.0:
        position_fb = history_read(y, hist, t - p[P.feedback_delay_s])
    write_outputs(p, y, position_fb, hinge_moment_inlb, flags, row)


@jit
def compliance_gain(p: FloatArray, dt: float) -> float:
    """Stage 16's exact step gain over ``dt`` (1 when the compliance is undamped).

    Parameters
    ----------
    p : numpy.ndarray
        Kernel parameters.
    dt : float
        The step (s).

    Returns
    -------
    float
        ``1 − exp(−dt/τ)``.
    """
    tau_c = compliance_time_constant_s(p)
    return 1.0 - math.exp(-dt / tau_c) if tau_c > 0.0 else 1.0


@jit
def max_step_s(p: FloatArray) -> float:
    """The longest step a fixed-order integrator may take: a quarter of the fastest stage's time constant.

    Parameters
    ----------
    p : numpy.ndarray
        Kernel parameters.

    Returns
    -------
    float
        Seconds.
    """
    fastest = p[P.wn_rad_s]
    if p[P.linkage_freq_hz] > 0.0:
        fastest = max(fastest, TWO_PI * p[P.linkage_freq_hz])
    if drive_on(p):  # a first-order loop: RK4 at h·λ = 1 is accurate to 2 % of its (fast) transient
        fastest = max(fastest, 0.25 * TWO_PI * p[P.velocity_loop_hz])
    return float(1.0 / (4.0 * fastest))


@nb.njit(cache=True)
def trim(params: FloatArray, command_deg: FloatArray, hinge_moment_inlb: FloatArray, states: FloatArray,
         history: FloatArray) -> None:
    """Every instance's state at rest under a held command and load (no start-up transient).

    The servo sits where stages 2–5 put the command (inside the position limits), moved by the servo
    compliance's droop unless an integral holds it (which then stores the droop), the free play on
    the side the load pushes it, the lags at their inputs, stage 14's history holding the reading.

    Parameters
    ----------
    params : numpy.ndarray
        Kernel parameters, one row per instance.
    command_deg : numpy.ndarray
        The held command of each instance (deg).
    hinge_moment_inlb : numpy.ndarray
        The held load of each instance (in·lb).
    states : numpy.ndarray
        Filled with each instance's state.
    history : numpy.ndarray
        Each instance's stage-14 ring, filled with the held reading.
    """
    for i in range(params.shape[0]):
        p = params[i]
        x = states[i]
        hm = hinge_moment_inlb[i]
        uq = command_path(p, command_deg[i])
        droop = p[P.servo_compliance_deg_per_kinlb] * hm * 1e-3
        target = compliance_correction(uq, hm, p[P.kcp_per_kinlb])
        x[:] = 0.0
        if p[P.integral_hz] > 0.0:
            x[X.integral_deg_s] = -droop / (TWO_PI * p[P.integral_hz])
        else:
            target += droop
        pos = min(max(target, p[P.position_min_deg]), p[P.position_max_deg])
        x[X.position_deg] = pos
        x[X.free_play_deg] = 0.5 * p[P.free_play_deg] * np.sign(hm) if free_play_subsystem(p) else 0.0
        x[X.command_lag_deg] = uq
        x[X.feedback_lag_deg] = lvdt(p, pos, hm)
        x[X.compliance_deg] = surface_compliance(p, hm)
        if p[P.linkage_freq_hz] > 0.0:
            x[X.linkage_deg] = linkage_rest(p, hm)
        x[X.history_last_s] = NEVER_S
        reading, _ = feedback_value(p, x, hm)
        for j in range(history.shape[1]):
            history[i, j, 0] = NEVER_S
            history[i, j, 1] = reading
            history[i, j, 2] = 0.0
