"""Figure 26: the modified second-order model with its nonlinear elements, each stage written once.

command path (FMU side, held between frames)
    1. time delay            command to first motion (section 2.3)
    2. command error         (1 + Kb)·u + offset (3.1.2.2)
    3. quantization          D/A resolution, 0.020° (3.1.2.2)
actuator (integrated at the model's own rate)
    4. command lag           optional first-order lag on the command
    5. compliance correction K_CP, a gain that varies with load (3.1.2.4)
    6. threshold             optional dead zone on the servo error
    7. rate limit            on the velocity command, rl + K2·hm/marm (3.1.2.1; :mod:`.figure21`)
    8. second order          ωn, ζ (figure 21)
    9. position limits       on the states, so nothing winds up
   10. LVDT compliance       optional deflection with load that the servo loop does not remove
   11. feedback lag          optional first-order lag on the LVDT feedback
surface (outside the servo loop)
   12. free play             hm / Is double-integrated in a limited integrator, ±width/2 (:mod:`.figure29`)
   13. compliance            optional deflection linear in hinge moment, with optional hysteretic
                             damping (figure 36): viscous equivalent h/ω on the linkage

The integrators (:mod:`.loada`, :mod:`.loac`, :mod:`.rk4`) call these functions: :func:`command_path`
for stages 2–3, :func:`servo` for stages 5–8, :func:`derivatives` for the whole chain in continuous
time, :func:`sample` and :func:`write_outputs` for what the outside sees.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from ema_sim.models.arrays import FloatArray
from ema_sim.models.base import O_BUS, O_CUR, O_FLAGS, O_POS, O_RATE, O_SURF
from ema_sim.models.second_order.figure21 import load_rate_limits, second_order
from ema_sim.models.second_order.figure29 import free_play_accel
from ema_sim.models.second_order.params import P, X
from ema_sim.models.stages import (
    DEG2RAD,
    FLAG_FREE_PLAY,
    FLAG_POSITION,
    FLAG_RATE,
    FLAG_THRESHOLD,
    TWO_PI,
    dead_zone,
    jit,
    quantize,
)


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
def compliance_deflection(hinge_moment_inlb: float, deg_per_kinlb: float) -> float:
    """Stages 10 and 13: deflection linear in hinge moment (deg).

    Parameters
    ----------
    hinge_moment_inlb : float
        Hinge moment (in·lb).
    deg_per_kinlb : float
        Compliance (deg per 1000 in·lb).

    Returns
    -------
    float
        The deflection (deg).
    """
    return deg_per_kinlb * hinge_moment_inlb * 1e-3


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
def servo(p: FloatArray, u_in: float, x: float, v: float, hinge_moment_inlb: float) -> tuple[float, int, int]:
    """Stages 5–8: the actuator's acceleration, its limit flags and which smooth piece it is on.

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
    hinge_moment_inlb : float
        Hinge moment (in·lb).

    Returns
    -------
    acceleration : float
        °/s².
    flags : int
        Rate-limit and threshold flags.
    piece : int
        ``3·(rate limit side) + (dead zone side)``: the right-hand side is smooth while it holds.
    """
    u_eff = compliance_correction(u_in, hinge_moment_inlb, p[P.kcp_per_kinlb])
    e_dz, dz = dead_zone(u_eff - x, p[P.threshold_deg])
    up, down = load_rate_limits(p[P.rate_limit_dps], p[P.k2_dps_per_lb], hinge_moment_inlb, p[P.moment_arm_in])
    a, side = second_order(x + e_dz, x, v, p[P.wn_rad_s], p[P.zeta], up, down)
    flags = FLAG_RATE if side != 0 else 0
    if p[P.threshold_deg] > 0.0 and e_dz == 0.0:
        flags |= FLAG_THRESHOLD
    if p[P.threshold_deg] <= 0.0:
        dz = 0
    return a, flags, 3 * side + dz


@jit
def lvdt(p: FloatArray, x_pos: float, hinge_moment_inlb: float) -> float:
    """Stage 10: what the LVDT reads, the servo position plus the compliance the loop does not remove.

    Parameters
    ----------
    p : numpy.ndarray
        Kernel parameters.
    x_pos : float
        Servo position (deg).
    hinge_moment_inlb : float
        Hinge moment (in·lb).

    Returns
    -------
    float
        The LVDT reading (deg).
    """
    return x_pos + compliance_deflection(hinge_moment_inlb, p[P.lvdt_compliance_deg_per_kinlb])


@jit
def compliance_time_constant_s(p: FloatArray) -> float:
    """Stage 13: linkage stiffness k and hysteretic damping h/ω make the compliance a first-order lag.

    The linkage deflects x = δ·marm (in) under F = hm/marm (lb), so k = F/x = 1000/(C·marm²) lb/in
    with C in rad per 1000 in·lb; the damper c = h/ω gives τ = c/k. Zero when either is off.

    Parameters
    ----------
    p : numpy.ndarray
        Kernel parameters.

    Returns
    -------
    float
        τ (s); 0 for a compliance without damping.
    """
    c = p[P.compliance_deg_per_kinlb]
    if c <= 0.0 or p[P.hysteresis_h_lb_per_in] <= 0.0:
        return 0.0
    k_lb_per_in = 1000.0 / (c * DEG2RAD * p[P.moment_arm_in] * p[P.moment_arm_in])
    return float(p[P.hysteresis_h_lb_per_in] / (TWO_PI * p[P.hysteresis_freq_hz]) / k_lb_per_in)


@jit
def derivatives(p: FloatArray, y: FloatArray, u: float, hinge_moment_inlb: float, dydt: FloatArray) -> None:
    """Stages 4–13 in continuous time: the state's derivatives into ``dydt`` (position limits are the integrator's).

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
    """
    if p[P.command_lag_hz] > 0.0:
        dydt[X.command_lag_deg] = TWO_PI * p[P.command_lag_hz] * (u - y[X.command_lag_deg])
    else:
        dydt[X.command_lag_deg] = 0.0
    a, _, _ = servo(p, servo_input(p, y, u), y[X.position_deg], y[X.rate_dps], hinge_moment_inlb)
    dydt[X.position_deg] = y[X.rate_dps]
    dydt[X.rate_dps] = a
    dydt[X.free_play_deg] = y[X.free_play_rate_dps]
    dydt[X.free_play_rate_dps] = free_play_accel(hinge_moment_inlb, p[P.surface_inertia_inlbs2])
    if p[P.feedback_lag_hz] > 0.0:
        target = lvdt(p, y[X.position_deg], hinge_moment_inlb)
        dydt[X.feedback_lag_deg] = TWO_PI * p[P.feedback_lag_hz] * (target - y[X.feedback_lag_deg])
    else:
        dydt[X.feedback_lag_deg] = 0.0
    tau_c = compliance_time_constant_s(p)
    if tau_c > 0.0:
        target = compliance_deflection(hinge_moment_inlb, p[P.compliance_deg_per_kinlb])
        dydt[X.compliance_deg] = (target - y[X.compliance_deg]) / tau_c
    else:
        dydt[X.compliance_deg] = 0.0


@jit
def write_outputs(p: FloatArray, x: FloatArray, position_fb: float, hinge_moment_inlb: float, flags: int,
                  row: FloatArray) -> None:
    """Stages 10–13 seen from outside: LVDT position, surface angle, rate and flags into one output row.

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
    """
    row[O_POS] = position_fb
    damped = compliance_time_constant_s(p) > 0.0
    compliance = x[X.compliance_deg] if damped else compliance_deflection(hinge_moment_inlb,
                                                                            p[P.compliance_deg_per_kinlb])
    row[O_SURF] = lvdt(p, x[X.position_deg], hinge_moment_inlb) + x[X.free_play_deg] + compliance
    row[O_RATE] = x[X.rate_dps]
    row[O_CUR] = np.nan
    row[O_BUS] = np.nan
    half = 0.5 * p[P.free_play_deg]
    if x[X.position_deg] >= p[P.position_max_deg] or x[X.position_deg] <= p[P.position_min_deg]:
        flags |= FLAG_POSITION
    if half > 0.0 and abs(x[X.free_play_deg]) >= half:
        flags |= FLAG_FREE_PLAY
    row[O_FLAGS] = flags


@jit
def sample(p: FloatArray, y: FloatArray, u: float, hinge_moment_inlb: float, row: FloatArray) -> None:
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
    row : numpy.ndarray
        The output row.
    """
    _, flags, _ = servo(p, servo_input(p, y, u), y[X.position_deg], y[X.rate_dps], hinge_moment_inlb)
    lagged = p[P.feedback_lag_hz] > 0.0
    position_fb = y[X.feedback_lag_deg] if lagged else lvdt(p, y[X.position_deg], hinge_moment_inlb)
    write_outputs(p, y, position_fb, hinge_moment_inlb, flags, row)


@jit
def compliance_gain(p: FloatArray, dt: float) -> float:
    """Stage 13's exact step gain over ``dt`` (1 when the compliance is undamped).

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


@nb.njit(cache=True)
def trim(params: FloatArray, command_deg: FloatArray, hinge_moment_inlb: FloatArray, states: FloatArray) -> None:
    """Every instance's state at rest under a held command and load (no start-up transient).

    The servo sits where stages 2–5 put the command (inside the position limits), the free play on
    the side the load pushes it, the lags at their inputs.

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
    """
    for i in range(params.shape[0]):
        p = params[i]
        x = states[i]
        hm = hinge_moment_inlb[i]
        uq = command_path(p, command_deg[i])
        pos = min(max(compliance_correction(uq, hm, p[P.kcp_per_kinlb]), p[P.position_min_deg]),
                  p[P.position_max_deg])
        x[:] = 0.0
        x[X.position_deg] = pos
        x[X.free_play_deg] = 0.5 * p[P.free_play_deg] * np.sign(hm)
        x[X.command_lag_deg] = uq
        x[X.feedback_lag_deg] = pos + compliance_deflection(hm, p[P.lvdt_compliance_deg_per_kinlb])
        x[X.compliance_deg] = compliance_deflection(hm, p[P.compliance_deg_per_kinlb])
