"""HOAC1: figure 30 in continuous time, every regime change located as an event (table 5).

The manufacturer's HOAC1 is proprietary, so this one is built from physics and the published
specifications. Adaptive Dormand–Prince (:mod:`ema_sim.models.hybrid`) integrates the figure-30
chain with every switching element held on a regime: the slew and current limits and the PWM
(:func:`figure30.servo_drive` with its segments held), the figure-32 backlash, the motor stuck by
stiction, slipping or on a stop, the surface held by hinge friction or sliding. The guards are each
element's own boundary distances; a crossing is located, its transition applied and every regime
settled from the state again.
"""

from __future__ import annotations

import numba as nb

from ema_sim.models.arrays import FloatArray
from ema_sim.models.base import O_BUS, O_CUR, O_FLAGS, O_POS, O_RATE, O_SURF
from ema_sim.models.compiling import borrowing
from ema_sim.models.high_order import gear_train as gt
from ema_sim.models.high_order.figure30 import (
    INF,
    MOTOR_SLIP_NEG,
    MOTOR_SLIP_POS,
    MOTOR_STOP_HIGH,
    MOTOR_STOP_LOW,
    MOTOR_STUCK,
    bus_current,
    bus_voltage_rate,
    drive_flags,
    integrating,
    motor_current_rate,
    pwm_guards,
    pwm_segment,
    saturation_guards,
    saturation_segment,
    servo_drive,
)
from ema_sim.models.high_order.params import P, X
from ema_sim.models.hybrid import make_hybrid
from ema_sim.models.stages import FLAG_BRAKE, FLAG_FREE_PLAY, FLAG_POSITION, TIME_EPS_S, jit, zoh_index
from ema_sim.parameters import slots

U = slots("Hoac1Inputs", ("command_in", "hinge_moment_inlb", "power", "rate_segment", "current_segment",
                          "pwm_region", "motor_regime", "gear_segment", "surface_regime"))
"""The continuous model's inputs and held regimes (its ``u`` vector)."""
N_U = len(U)
N_GUARDS = 11


@jit
def _servo_drive(p: FloatArray, y: FloatArray, u: FloatArray, classify: bool) -> tuple[float, float, float, float, int,
                                                                                        int, int]:
    """Figure 30's stages 4–7 on the continuous state, regimes held or classified."""
    return servo_drive(
        p[P.position_gain_per_s], p[P.rate_limit_in_s], p[P.velocity_gain_a_per_in_s], p[P.current_limit_a],
        p[P.current_gain_v_per_a], p[P.stator_resistance_ohm], p[P.back_emf_v_per_in_s], p[P.pwm_dead_band_v],
        p[P.pwm_max_duty_ratio], u[U.command_in], y[X.lvdt_filtered_in], y[X.integral_in_s], y[X.v_motor_in_s],
        y[X.current_a], y[X.bus_v], int(u[U.rate_segment]), int(u[U.current_segment]), int(u[U.pwm_region]),
        classify)


@borrowing
def drive(p: FloatArray, y: FloatArray, u: FloatArray) -> tuple[float, float, float, float]:
    """Stages 4–7 with the held regimes.

    Parameters
    ----------
    p : numpy.ndarray
        Kernel parameters.
    y : numpy.ndarray
        Continuous state.
    u : numpy.ndarray
        Inputs and held regimes (:data:`U`).

    Returns
    -------
    velocity_demand, current_demand, voltage_demand, voltage : float
        The raw demands of stages 4–6 and the bridge voltage.
    """
    vc_raw, ic_raw, vd, v, _, _, _ = _servo_drive(p, y, u, False)
    return vc_raw, ic_raw, vd, v


@borrowing
def forces(p: FloatArray, y: FloatArray, u: FloatArray) -> tuple[float, float, float]:
    """Spring force, gear force and the force applied to the motor (all but friction).

    Parameters
    ----------
    p : numpy.ndarray
        Kernel parameters.
    y : numpy.ndarray
        Continuous state.
    u : numpy.ndarray
        Inputs and held regimes.

    Returns
    -------
    spring, gear, motor : float
        Forces (lbf).
    """
    fk, f = gt.gear_train_fig32(y[X.x_motor_in] - y[X.x_surface_in], y[X.v_motor_in_s] - y[X.v_surface_in_s],
                                p[P.half_backlash_in], p[P.series_stiffness_lbf_per_in],
                                p[P.gear_damping_lbf_s_per_in], int(u[U.gear_segment]))
    return fk, f, p[P.force_per_amp_lbf_per_a] * y[X.current_a] - f


@borrowing
def friction_levels(p: FloatArray, u: FloatArray) -> tuple[float, float]:
    """Coulomb friction and stiction on the motor, the brake's added while unpowered.

    Parameters
    ----------
    p : numpy.ndarray
        Kernel parameters.
    u : numpy.ndarray
        Inputs and held regimes.

    Returns
    -------
    coulomb, stiction : float
        lbf.
    """
    brake = 0.0 if u[U.power] > 0.5 else p[P.brake_holding_lbf]
    return p[P.coulomb_friction_lbf] + brake, p[P.stiction_lbf] + brake


@borrowing
def rhs(t: float, y: FloatArray, p: FloatArray, u: FloatArray, dydt: FloatArray) -> None:  # noqa: ARG001 - the integrator's signature
    """HOAC1 right-hand side with every regime held (see :mod:`ema_sim.models.hybrid`).

    Parameters
    ----------
    t : float
        Time (s; the model is time-invariant).
    y : numpy.ndarray
        Continuous state.
    p : numpy.ndarray
        Kernel parameters.
    u : numpy.ndarray
        Inputs and held regimes.
    dydt : numpy.ndarray
        Filled with the derivatives.
    """
    fk, f, fapp = forces(p, y, u)
    lvdt = gt.lvdt_fig32(y[X.x_surface_in], fk, p[P.backup_stiffness_lbf_per_in])
    dydt[X.lvdt_filtered_in] = p[P.lvdt_filter_rad_s] * (lvdt - y[X.lvdt_filtered_in])
    dydt[X.integral_in_s] = 0.0
    if u[U.power] > 0.5:
        _, _, _, v = drive(p, y, u)
        dydt[X.current_a] = motor_current_rate(v, y[X.current_a], y[X.v_motor_in_s], p[P.stator_resistance_ohm],
                                               p[P.inductance_h], p[P.back_emf_v_per_in_s])
        if integrating(int(u[U.rate_segment]), int(u[U.current_segment]), int(u[U.pwm_region])):
            dydt[X.integral_in_s] = p[P.position_integral_per_s2] * (u[U.command_in] - y[X.lvdt_filtered_in])
    else:
        v = 0.0
        dydt[X.current_a] = 0.0
    motor = int(u[U.motor_regime])
    if motor in (MOTOR_SLIP_POS, MOTOR_SLIP_NEG):
        fc, _ = friction_levels(p, u)
        dydt[X.x_motor_in] = y[X.v_motor_in_s]
        dydt[X.v_motor_in_s] = (fapp - motor * fc) / p[P.motor_mass_lbs2_per_in]
    else:
        dydt[X.x_motor_in] = 0.0
        dydt[X.v_motor_in_s] = 0.0
    surface = int(u[U.surface_regime])
    if surface != 0:
        dydt[X.x_surface_in] = y[X.v_surface_in_s]
        net = f + u[U.hinge_moment_inlb] / p[P.crank_arm_in] - surface * p[P.hinge_friction_lbf]
        dydt[X.v_surface_in_s] = net / p[P.surface_mass_lbs2_per_in]
    else:
        dydt[X.x_surface_in] = 0.0
        dydt[X.v_surface_in_s] = 0.0
    dydt[X.bus_v] = bus_voltage_rate(y[X.bus_v], bus_current(v, y[X.current_a], y[X.bus_v]), p[P.bus_supply_v],
                                     p[P.bus_source_resistance_ohm], p[P.bus_capacitance_f])


@borrowing
def guards(t: float, y: FloatArray, p: FloatArray, u: FloatArray, g: FloatArray) -> None:  # noqa: ARG001
    """Distance of every held regime to its boundary (positive inside), each element's own guards.

    Parameters
    ----------
    t : float
        Time (s).
    y : numpy.ndarray
        Continuous state.
    p : numpy.ndarray
        Kernel parameters.
    u : numpy.ndarray
        Inputs and held regimes.
    g : numpy.ndarray
        Filled with the :data:`N_GUARDS` distances.
    """
    for j in range(N_GUARDS):
        g[j] = INF
    if u[U.power] > 0.5:
        vc_raw, ic_raw, vd, _ = drive(p, y, u)
        g[0], g[1] = saturation_guards(vc_raw, p[P.rate_limit_in_s], int(u[U.rate_segment]))
        g[2], g[3] = saturation_guards(ic_raw, p[P.current_limit_a], int(u[U.current_segment]))
        g[4], g[5] = pwm_guards(vd, p[P.pwm_dead_band_v], p[P.pwm_max_duty_ratio] * y[X.bus_v],
                                int(u[U.pwm_region]))
    d = y[X.x_motor_in] - y[X.x_surface_in]
    g[6], g[7] = saturation_guards(d, p[P.half_backlash_in], int(u[U.gear_segment]))
    _, _, fapp = forces(p, y, u)
    _, fs = friction_levels(p, u)
    motor = int(u[U.motor_regime])
    if motor == MOTOR_STUCK:
        g[8] = fs - abs(fapp)
    elif motor == MOTOR_SLIP_POS:
        g[8] = y[X.v_motor_in_s]
        g[9] = p[P.position_max_in] - y[X.x_motor_in]
    elif motor == MOTOR_SLIP_NEG:
        g[8] = -y[X.v_motor_in_s]
        g[9] = y[X.x_motor_in] - p[P.position_min_in]
    elif motor == MOTOR_STOP_HIGH:
        g[8] = fapp + fs
    else:
        g[8] = fs - fapp
    surface = int(u[U.surface_regime])
    if surface == 0:
        _, f, _ = forces(p, y, u)
        g[10] = p[P.hinge_friction_lbf] - abs(f + u[U.hinge_moment_inlb] / p[P.crank_arm_in])
    else:
        g[10] = surface * y[X.v_surface_in_s]


@borrowing
def surface_stops_or_reverses(p: FloatArray, y: FloatArray, u: FloatArray) -> None:
    """The surface at zero speed: held by hinge friction or slipping the way the net force pushes.

    Parameters
    ----------
    p : numpy.ndarray
        Kernel parameters.
    y : numpy.ndarray
        Continuous state (its surface rate is zeroed).
    u : numpy.ndarray
        Inputs and held regimes (the surface regime is set).
    """
    y[X.v_surface_in_s] = 0.0
    _, f, _ = forces(p, y, u)
    net = f + u[U.hinge_moment_inlb] / p[P.crank_arm_in]
    if abs(net) <= p[P.hinge_friction_lbf]:
        u[U.surface_regime] = 0.0
    else:
        u[U.surface_regime] = 1.0 if net > 0.0 else -1.0


@borrowing
def motor_stops_or_reverses(p: FloatArray, y: FloatArray, u: FloatArray) -> None:
    """The motor at zero speed: stuck when stiction holds, otherwise slipping the way the force pushes.

    Parameters
    ----------
    p : numpy.ndarray
        Kernel parameters.
    y : numpy.ndarray
        Continuous state (its motor rate is zeroed).
    u : numpy.ndarray
        Inputs and held regimes (the motor regime is set).
    """
    y[X.v_motor_in_s] = 0.0
    _, _, fapp = forces(p, y, u)
    _, fs = friction_levels(p, u)
    if abs(fapp) <= fs:
        u[U.motor_regime] = MOTOR_STUCK
    else:
        u[U.motor_regime] = MOTOR_SLIP_POS if fapp > 0.0 else MOTOR_SLIP_NEG


@borrowing
def transition(k: int, t: float, y: FloatArray, p: FloatArray, u: FloatArray) -> None:  # noqa: ARG001
    """What crossing guard ``k`` does to the regimes.

    Parameters
    ----------
    k : int
        The guard crossed.
    t : float
        Time (s).
    y : numpy.ndarray
        Continuous state (a stop resets positions and rates).
    p : numpy.ndarray
        Kernel parameters.
    u : numpy.ndarray
        Inputs and held regimes, updated.
    """
    if k < 8:
        slot = (U.rate_segment, U.rate_segment, U.current_segment, U.current_segment, U.pwm_region, U.pwm_region,
                U.gear_segment, U.gear_segment)[k]
        u[slot] += -1.0 if k % 2 == 0 else 1.0
        return
    if k == 10:  # hinge friction
        if int(u[U.surface_regime]) == 0:
            _, f, _ = forces(p, y, u)
            u[U.surface_regime] = 1.0 if f + u[U.hinge_moment_inlb] / p[P.crank_arm_in] > 0.0 else -1.0
        else:
            surface_stops_or_reverses(p, y, u)
        return
    motor = int(u[U.motor_regime])
    if k == 9:  # a mechanical stop
        if motor == MOTOR_SLIP_POS:
            y[X.x_motor_in] = p[P.position_max_in]
            u[U.motor_regime] = MOTOR_STOP_HIGH
        else:
            y[X.x_motor_in] = p[P.position_min_in]
            u[U.motor_regime] = MOTOR_STOP_LOW
        y[X.v_motor_in_s] = 0.0
        return
    if motor == MOTOR_STUCK:
        _, _, fapp = forces(p, y, u)
        u[U.motor_regime] = MOTOR_SLIP_POS if fapp > 0.0 else MOTOR_SLIP_NEG
    elif motor in (MOTOR_SLIP_POS, MOTOR_SLIP_NEG):
        motor_stops_or_reverses(p, y, u)
    elif motor == MOTOR_STOP_HIGH:
        u[U.motor_regime] = MOTOR_SLIP_NEG
    else:
        u[U.motor_regime] = MOTOR_SLIP_POS


@borrowing
def settle(t: float, y: FloatArray, p: FloatArray, u: FloatArray) -> None:  # noqa: ARG001
    """Classify every regime from the state (after an input change, or several events at once).

    Parameters
    ----------
    t : float
        Time (s).
    y : numpy.ndarray
        Continuous state (a stop or a stick resets rates).
    p : numpy.ndarray
        Kernel parameters.
    u : numpy.ndarray
        Inputs and held regimes, updated.
    """
    if u[U.power] > 0.5:
        _, _, _, _, sv, si, sp = _servo_drive(p, y, u, True)
        u[U.rate_segment] = sv
        u[U.current_segment] = si
        u[U.pwm_region] = sp
    u[U.gear_segment] = gt.dead_zone_segment(y[X.x_motor_in] - y[X.x_surface_in], p[P.half_backlash_in])
    motor = int(u[U.motor_regime])
    _, _, fapp = forces(p, y, u)
    fc, fs = friction_levels(p, u)
    v_motor = y[X.v_motor_in_s]
    if motor == MOTOR_STUCK:
        if abs(fapp) > fs:
            u[U.motor_regime] = MOTOR_SLIP_POS if fapp > 0.0 else MOTOR_SLIP_NEG
    elif motor in (MOTOR_SLIP_POS, MOTOR_SLIP_NEG):
        if motor * v_motor < 0.0 or (v_motor == 0.0 and motor * (fapp - motor * fc) < 0.0):
            motor_stops_or_reverses(p, y, u)
        elif motor == MOTOR_SLIP_POS and y[X.x_motor_in] >= p[P.position_max_in]:
            y[X.x_motor_in] = p[P.position_max_in]
            y[X.v_motor_in_s] = 0.0
            u[U.motor_regime] = MOTOR_STOP_HIGH
        elif motor == MOTOR_SLIP_NEG and y[X.x_motor_in] <= p[P.position_min_in]:
            y[X.x_motor_in] = p[P.position_min_in]
            y[X.v_motor_in_s] = 0.0
            u[U.motor_regime] = MOTOR_STOP_LOW
    elif motor == MOTOR_STOP_HIGH and fapp < -fs:
        u[U.motor_regime] = MOTOR_SLIP_NEG
    elif motor == MOTOR_STOP_LOW and fapp > fs:
        u[U.motor_regime] = MOTOR_SLIP_POS
    surface = int(u[U.surface_regime])
    _, f, _ = forces(p, y, u)
    net = f + u[U.hinge_moment_inlb] / p[P.crank_arm_in]
    fh = p[P.hinge_friction_lbf]
    v_surface = y[X.v_surface_in_s]
    if surface == 0:
        if abs(net) > fh:
            u[U.surface_regime] = 1.0 if net > 0.0 else -1.0
    elif surface * v_surface < 0.0 or (v_surface == 0.0 and surface * (net - surface * fh) < 0.0):
        surface_stops_or_reverses(p, y, u)


advance = make_hybrid(rhs, guards, transition, settle, N_GUARDS)
"""HOAC1's compiled ``advance(p, u, y, t, t_end, h, rtol, atol, h_max) -> (next h, events)``."""


@borrowing
def flags_at(p: FloatArray, y: FloatArray, u: FloatArray) -> int:
    """The limit flags at a sample instant: each raw demand against its element's limits, stops, free play.

    Parameters
    ----------
    p : numpy.ndarray
        Kernel parameters.
    y : numpy.ndarray
        Continuous state.
    u : numpy.ndarray
        Inputs and held regimes.

    Returns
    -------
    int
        Bits of :class:`~ema_sim.models.base.Flags`.
    """
    flags = 0
    if u[U.power] > 0.5:
        vc_raw, ic_raw, vd, _ = drive(p, y, u)
        flags |= drive_flags(saturation_segment(vc_raw, p[P.rate_limit_in_s]),
                             saturation_segment(ic_raw, p[P.current_limit_a]),
                             pwm_segment(vd, p[P.pwm_dead_band_v], p[P.pwm_max_duty_ratio] * y[X.bus_v]),
                             y[X.v_motor_in_s])
        if u[U.command_in] >= p[P.position_max_in] or u[U.command_in] <= p[P.position_min_in]:
            flags |= FLAG_POSITION
    else:
        flags |= FLAG_BRAKE
    if abs(u[U.motor_regime]) == 2.0:
        flags |= FLAG_POSITION
    if gt.dead_zone_segment(y[X.x_motor_in] - y[X.x_surface_in], p[P.half_backlash_in]) == 0:
        flags |= FLAG_FREE_PLAY
    return flags


@nb.njit(cache=True)
def run_continuous(params: FloatArray, states: FloatArray, inputs: FloatArray, steps: FloatArray, power: FloatArray,
                   bp_t: FloatArray, cmd_in: FloatArray, bp_h: FloatArray, t0: float, t_end: float,
                   sample_t: FloatArray, rtol: float, atol: float, out: FloatArray) -> int:
    """HOAC1 kernel: integrate every instance from ``t0`` to ``t_end``, breaking at each input change.

    Parameters
    ----------
    params : numpy.ndarray
        Kernel parameters, one row per instance.
    states : numpy.ndarray
        Continuous states, one row per instance, advanced in place.
    inputs : numpy.ndarray
        Inputs and held regimes (:data:`U`), one row per instance, updated.
    steps : numpy.ndarray
        Each instance's step size (s), updated.
    power : numpy.ndarray
        Each instance's motor power (1 on, 0 off).
    bp_t : numpy.ndarray
        Input breakpoint times (s).
    cmd_in : numpy.ndarray
        The command in screw inches at each breakpoint, one row per instance.
    bp_h : numpy.ndarray
        Hinge moment at each breakpoint (in·lb), one row per instance.
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

    Returns
    -------
    int
        Regime changes located.
    """
    k_samples = sample_t.shape[0]
    m = bp_t.shape[0]
    events = 0
    for i in range(params.shape[0]):
        p = params[i]
        y = states[i]
        u = inputs[i]
        u[U.power] = power[i]
        h_max = 0.05 / p[P.lvdt_filter_rad_s]
        t = t0
        jh = zoh_index(bp_t, t, 0)
        js = 0
        while True:
            u[U.command_in] = min(max(cmd_in[i, jh], p[P.position_min_in]), p[P.position_max_in])
            u[U.hinge_moment_inlb] = bp_h[i, jh]
            settle(t, y, p, u)
            while js < k_samples and sample_t[js] <= t + TIME_EPS_S:
                row = out[i, js]
                row[O_POS] = y[X.lvdt_filtered_in] * p[P.deg_per_in]
                row[O_SURF] = y[X.x_surface_in] * p[P.deg_per_in]
                row[O_RATE] = y[X.v_motor_in_s] * p[P.deg_per_in]
                row[O_CUR] = y[X.current_a]
                row[O_BUS] = y[X.bus_v] if u[U.power] > 0.5 else 0.0
                flags = flags_at(p, y, u)
                if cmd_in[i, jh] > p[P.position_max_in] or cmd_in[i, jh] < p[P.position_min_in]:
                    flags |= FLAG_POSITION
                row[O_FLAGS] = flags
                js += 1
            if t >= t_end - TIME_EPS_S:
                break
            t_next = t_end
            if jh + 1 < m:
                t_next = min(t_next, bp_t[jh + 1])
            if js < k_samples:
                t_next = min(t_next, sample_t[js])
            if t_next > t + TIME_EPS_S:
                steps[i], ev = advance(p, u, y, t, t_next, steps[i], rtol, atol, h_max)
                events += ev
            t = t_next
            jh = zoh_index(bp_t, t, jh)
    return events
