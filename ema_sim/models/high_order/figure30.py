"""Figure 30: the EMAC channel, motor, bus and mechanics of the high-order models, each stage written once.

flight/test environment (HOAD2, HOAD3; section 4.2.5; :mod:`.hoad`)
    1. command delay         command to first motion (HOAD3: 4 ms, section 2.3)
    2. command quantization  5 mV through the channel's command calibration, degrees → volts → degrees
    3. command noise         band-limited, seeded, measured rms in volts
EMAC channel and motor (this module)
    4. position-loop controller electronics  Kp·(command − filtered LVDT) plus an integral that runs
                             only while the PWM drives; limited at the slew rate
    5. velocity loop         tachometer feedback, current demand limited at the current limit
    6. current loop          proportional, resistive and back-EMF feed-forward
    7. PWM with dead band    no drive for small demands, duty limit on the bus voltage
    8. brushless DC motor    DC equivalent: 0.88 Ω stator (table A2), inductance, Kt = Ke
    9. 150 V bus             supply, source resistance and bus capacitance; regeneration raises it
   10. rotor and screw inertia, ball screw and gear ratio
   11. Coulomb friction and stiction; brake engaged while unpowered (> 4,000 lbf, table 1)
gear train and surface
   12. gear train            figure 32 (HOAC1, HOAD2): backlash dead zone, gear and backup stiffness;
                             figure 33 (HOAD3): three-segment total and actuator compliance;
                             figure 36 (option): hysteretic damping h/ω scaled by stiffness
                             (elements in :mod:`.gear_train`; :func:`gear_train` here picks the figure)
   13. servo crank arm       force ↔ hinge moment, screw travel ↔ surface angle
   14. surface inertia       with the hinge-moment input and spindle (hinge) friction
   15. LVDT with its filter  fed back to stage 4 (inside the servo loop)
flight/test environment, feedback side (:mod:`.hoad`)
   16. feedback delay        motion to feedback (HOAD3: 2 ms, section 2.3)
   17. feedback noise and 5 mV quantization through the feedback calibration

Mechanical quantities are in ball-screw coordinates (in, in/s, lbf); the motor's rotation maps to
them through the gear ratio and screw lead (``G = lead / (2π·N)`` in/rad).

Each switching element exists in three forms written side by side: a classification of its input
into a numbered segment, the element evaluated on a given segment, and the distances to the held
segment's boundaries (the continuous model's event guards). :func:`servo_drive` chains stages 4–7
once: a fixed-step kernel lets it classify every segment, the continuous model (:mod:`.hoac1`) holds
them between located events (every branch is a smooth function extended past its boundary), so
Dormand–Prince never steps across a corner. One diagram in one module of about 720 lines: its stages
are read in the figure's order, each with its segments and guards beside it.
"""

from __future__ import annotations

import math

from ema_sim.models.arrays import FloatArray
from ema_sim.models.compiling import unlikely
from ema_sim.models.high_order import gear_train as gt
from ema_sim.models.high_order.params import P
from ema_sim.models.stages import FLAG_CURRENT, FLAG_PWM_DEAD_BAND, FLAG_RATE, FLAG_STALL, band_side, jit

INF = math.inf
MOTOR_STOP_LOW, MOTOR_SLIP_NEG, MOTOR_STUCK, MOTOR_SLIP_POS, MOTOR_STOP_HIGH = -2, -1, 0, 1, 2
"""Stages 10–11's regimes of the motor: on a stop, slipping either way, or stuck by stiction."""

saturation_segment = band_side
"""A saturation's segment: −1 below −limit, 0 inside, +1 above (the one band classification)."""


# ------------------------------------------------------------------------- switching elements
@jit
def saturate(x: float, limit: float, segment: int) -> float:
    """A saturation held on ``segment`` (see :data:`saturation_segment`).

    Parameters
    ----------
    x : float
        The input.
    limit : float
        The limit's magnitude.
    segment : int
        −1, 0 or +1.

    Returns
    -------
    float
        ``−limit``, ``x`` or ``+limit``.
    """
    if segment > 0:
        return limit
    if segment < 0:
        return -limit
    return x


@jit
def saturation_guards(x: float, limit: float, segment: int) -> tuple[float, float]:
    """Distances of ``x`` to the lower and upper boundaries of a saturation held on ``segment``.

    Parameters
    ----------
    x : float
        The saturation's input.
    limit : float
        The limit's magnitude.
    segment : int
        The held segment.

    Returns
    -------
    lower : float
        Positive while ``x`` has not left the segment downwards (inf: no boundary).
    upper : float
        Positive while ``x`` has not left the segment upwards.
    """
    if segment > 0:
        return x - limit, INF
    if segment < 0:
        return INF, -limit - x
    return x + limit, limit - x


@jit
def pwm_segment(v_demand: float, dead_band_v: float, v_max: float) -> int:
    """Region of the PWM stage: ±2 saturated, ±1 linear, 0 inside the dead band.

    Parameters
    ----------
    v_demand : float
        The voltage demand (V).
    dead_band_v : float
        Half width of the dead band (V).
    v_max : float
        Duty limit on the bus voltage (V).

    Returns
    -------
    int
        −2 … +2.
    """
    if v_demand > dead_band_v:
        return 2 if v_demand - dead_band_v > v_max else 1
    if v_demand < -dead_band_v:
        return -2 if v_demand + dead_band_v < -v_max else -1
    return 0


@jit
def pwm(v_demand: float, dead_band_v: float, v_max: float, segment: int) -> float:
    """Stage 7, PWM with its dead band: no output inside ±dead band, then linear, then the duty limit.

    The dead band is a dead zone (the output is continuous): an unloaded actuator at rest draws no
    current until its error needs more than the band (section 4.3's dither mechanism).

    Parameters
    ----------
    v_demand : float
        The voltage demand (V).
    dead_band_v : float
        Half width of the dead band (V).
    v_max : float
        Duty limit on the bus voltage (V).
    segment : int
        The region (:func:`pwm_segment`).

    Returns
    -------
    float
        The bridge voltage (V).
    """
    if segment == 0:
        return 0.0
    if segment == 1:
        return v_demand - dead_band_v
    if segment == -1:
        return v_demand + dead_band_v
    if segment == 2:
        return v_max
    return -v_max


@jit
def pwm_guards(v_demand: float, dead_band_v: float, v_max: float, segment: int) -> tuple[float, float]:
    """Distances of the demand to the lower and upper boundaries of the held PWM region.

    Parameters
    ----------
    v_demand : float
        The voltage demand (V).
    dead_band_v : float
        Half width of the dead band (V).
    v_max : float
        Duty limit on the bus voltage (V).
    segment : int
        The held region.

    Returns
    -------
    lower : float
        Positive while the demand has not left the region downwards (inf: no boundary).
    upper : float
        Positive while it has not left upwards.
    """
    b0, b1, b2, b3 = -dead_band_v - v_max, -dead_band_v, dead_band_v, dead_band_v + v_max
    if segment == -2:
        return INF, b0 - v_demand
    if segment == -1:
        return v_demand - b0, b1 - v_demand
    if segment == 0:
        return v_demand - b1, b2 - v_demand
    if segment == 1:
        return v_demand - b2, b3 - v_demand
    return v_demand - b3, INF


# ------------------------------------------------------------------------- stages 4-8
@jit
def position_loop(x_command_in: float, x_feedback_in: float, kp_per_s: float, integral_in_s: float) -> float:
    """Stage 4, position-loop controller electronics: the velocity demand ``Kp·(command − LVDT) + ∫Ki·e``.

    Saturated at the slew limit with :func:`saturate`; the tachometer closes the velocity loop next.
    The integral (:func:`integrating`) gives the loaded servo its static stiffness (section 2.8).

    Parameters
    ----------
    x_command_in : float
        The command (in).
    x_feedback_in : float
        The filtered LVDT (in).
    kp_per_s : float
        Position gain (1/s).
    integral_in_s : float
        The integral's state (in/s).

    Returns
    -------
    float
        The velocity demand before the slew limit (in/s).
    """
    return kp_per_s * (x_command_in - x_feedback_in) + integral_in_s


@jit
def integrating(rate_segment: int, current_segment: int, pwm_segment_: int) -> bool:
    """Conditional integration: only while the PWM drives linearly and nothing saturates.

    Frozen inside the PWM dead band, an unloaded actuator at rest keeps its dead zone (no hunting on
    stiction), while a loaded one, driven outside the band, integrates its error away.

    Parameters
    ----------
    rate_segment : int
        The slew limit's segment.
    current_segment : int
        The current limit's segment.
    pwm_segment_ : int
        The PWM region.

    Returns
    -------
    bool
        True while the integral runs.
    """
    return rate_segment == 0 and current_segment == 0 and pwm_segment_ in (1, -1)


@jit
def velocity_loop(v_command_in_s: float, v_tach_in_s: float, kv_a_per_in_s: float) -> float:
    """Stage 5, the tachometer loop: the current demand ``Kv·(v_command − v_motor)``, before the limit.

    Parameters
    ----------
    v_command_in_s : float
        The (limited) velocity demand (in/s).
    v_tach_in_s : float
        The motor-side screw rate (in/s).
    kv_a_per_in_s : float
        Velocity gain (A per in/s).

    Returns
    -------
    float
        The current demand (A).
    """
    return kv_a_per_in_s * (v_command_in_s - v_tach_in_s)


@jit
def current_loop(i_command_a: float, i_a: float, v_tach_in_s: float, kc_v_per_a: float, r_ohm: float,
                 ke_v_per_in_s: float) -> float:
    """Stage 6, the current loop: proportional on the error plus resistive and back-EMF feed-forward.

    With the feed-forward the motor current settles on the demand exactly outside the PWM dead band;
    there is no integrator, so nothing winds up inside it (an integrator would hunt on stiction).

    Parameters
    ----------
    i_command_a : float
        The (limited) current demand (A).
    i_a : float
        The motor current (A).
    v_tach_in_s : float
        The motor-side screw rate (in/s).
    kc_v_per_a : float
        Current gain (V/A).
    r_ohm : float
        Stator resistance (Ω).
    ke_v_per_in_s : float
        Back-EMF per screw rate (V per in/s).

    Returns
    -------
    float
        The voltage demand (V).
    """
    return kc_v_per_a * (i_command_a - i_a) + r_ohm * i_command_a + ke_v_per_in_s * v_tach_in_s


@jit
def servo_drive(kp: float, vmax: float, kv: float, imax: float, kc: float, r: float, ke: float, vdb: float,
                duty: float, x_command_in: float, lvdt_in: float, integral_in_s: float, v_motor_in_s: float,
                current_a: float, bus_v: float, rate_segment: int, current_segment: int, pwm_region: int,
                classify: bool) -> tuple[float, float, float, float, int, int, int]:
    """Stages 4–7 in order: the position loop, the velocity loop, the current loop and the PWM.

    With ``classify`` every switching element's segment is found from its input (a fixed-step
    kernel, or the continuous model settling its regimes); without, the given segments are held
    (the continuous model between events).

    Parameters
    ----------
    kp : float
        Position gain (1/s).
    vmax : float
        Slew limit on the velocity demand (in/s).
    kv : float
        Velocity gain (A per in/s).
    imax : float
        Current limit (A).
    kc : float
        Current gain (V/A).
    r : float
        Stator resistance (Ω).
    ke : float
        Back-EMF per screw rate (V per in/s).
    vdb : float
        PWM dead band (V).
    duty : float
        PWM duty limit.
    x_command_in : float
        The command after stages 1–3 (in).
    lvdt_in : float
        The filtered LVDT (in).
    integral_in_s : float
        The position integral (in/s).
    v_motor_in_s : float
        The motor-side screw rate (in/s).
    current_a : float
        The motor current (A).
    bus_v : float
        The bus voltage (V).
    rate_segment, current_segment, pwm_region : int
        The held segments of the slew limit, the current limit and the PWM (ignored with ``classify``).
    classify : bool
        Classify the segments rather than hold them.

    Returns
    -------
    velocity_demand : float
        Stage 4's output before the slew limit (in/s).
    current_demand : float
        Stage 5's output before the current limit (A).
    voltage_demand : float
        Stage 6's output (V).
    voltage : float
        The bridge voltage, stage 7's output (V).
    rate_segment, current_segment, pwm_region : int
        The segments used.
    """
    vc_raw = position_loop(x_command_in, lvdt_in, kp, integral_in_s)
    if classify:
        rate_segment = saturation_segment(vc_raw, vmax)
    ic_raw = velocity_loop(saturate(vc_raw, vmax, rate_segment), v_motor_in_s, kv)
    if classify:
        current_segment = saturation_segment(ic_raw, imax)
    vd = current_loop(saturate(ic_raw, imax, current_segment), current_a, v_motor_in_s, kc, r, ke)
    vlim = duty * bus_v
    if classify:
        pwm_region = pwm_segment(vd, vdb, vlim)
    return vc_raw, ic_raw, vd, pwm(vd, vdb, vlim, pwm_region), rate_segment, current_segment, pwm_region


@jit
def drive_flags(rate_segment: int, current_segment: int, pwm_region: int, v_motor_in_s: float) -> int:
    """The limit flags of stages 4–7: slew limit, current limit (a stall when the motor stands), dead band.

    Parameters
    ----------
    rate_segment : int
        The slew limit's segment.
    current_segment : int
        The current limit's segment.
    pwm_region : int
        The PWM region.
    v_motor_in_s : float
        The motor-side screw rate (in/s).

    Returns
    -------
    int
        Bits of :class:`~ema_sim.models.base.Flags`.
    """
    flags = 0
    if rate_segment != 0:
        flags |= FLAG_RATE
    if current_segment != 0:
        flags |= FLAG_CURRENT
        if v_motor_in_s == 0.0:
            flags |= FLAG_STALL
    if pwm_region == 0:
        flags |= FLAG_PWM_DEAD_BAND
    return flags


@jit
def motor_current_rate(v_applied: float, i_a: float, v_motor_in_s: float, r_ohm: float, l_h: float,
                       ke_v_per_in_s: float) -> float:
    """Stage 8, the DC-equivalent brushless motor: ``L·di/dt = V − R·i − Ke·ω`` (A/s).

    Parameters
    ----------
    v_applied : float
        Bridge voltage (V).
    i_a : float
        Motor current (A).
    v_motor_in_s : float
        Motor-side screw rate (in/s).
    r_ohm : float
        Stator resistance (Ω).
    l_h : float
        Inductance (H).
    ke_v_per_in_s : float
        Back-EMF per screw rate (V per in/s).

    Returns
    -------
    float
        di/dt (A/s).
    """
    return (v_applied - r_ohm * i_a - ke_v_per_in_s * v_motor_in_s) / l_h


@jit
def motor_current_step(v_applied: float, i_a: float, v_motor_in_s: float, conductance: float, ke_v_per_in_s: float,
                       decay: float) -> float:
    """Stage 8 over one step with voltage and speed held: the exact RL response.

    Exact whatever the step, where forward Euler on an electrical time constant well under a step
    would not be.

    Parameters
    ----------
    v_applied : float
        Bridge voltage (V).
    i_a : float
        Motor current at the start of the step (A).
    v_motor_in_s : float
        Motor-side screw rate (in/s).
    conductance : float
        ``1/R`` (S).
    ke_v_per_in_s : float
        Back-EMF per screw rate (V per in/s).
    decay : float
        ``exp(−R·dt/L)``.

    Returns
    -------
    float
        The current at the end of the step (A).
    """
    i_inf = (v_applied - ke_v_per_in_s * v_motor_in_s) * conductance
    return i_inf + (i_a - i_inf) * decay


# ------------------------------------------------------------------------- stage 9: the bus
@jit
def bus_current(v_applied: float, i_a: float, v_bus: float) -> float:
    """H-bridge input current ``duty·i`` (A); negative while the motor regenerates into the bus.

    Parameters
    ----------
    v_applied : float
        Bridge voltage (V).
    i_a : float
        Motor current (A).
    v_bus : float
        Bus voltage (V).

    Returns
    -------
    float
        The bridge's input current (A).
    """
    return v_applied * i_a / v_bus


@jit
def bus_voltage_rate(v_bus: float, i_bus_a: float, v_supply: float, r_source_ohm: float, c_bus_f: float) -> float:
    """Stage 9: the supply behind its source resistance feeding the bus capacitance (V/s).

    Regenerated current (``i_bus < 0``) charges the capacitance and raises the bus above the supply
    (section 2.5; the allowable peak is 185 V).

    Parameters
    ----------
    v_bus : float
        Bus voltage (V).
    i_bus_a : float
        The bridge's input current (A).
    v_supply : float
        Supply voltage (V).
    r_source_ohm : float
        Source resistance (Ω).
    c_bus_f : float
        Bus capacitance (F).

    Returns
    -------
    float
        dV/dt (V/s).
    """
    return ((v_supply - v_bus) / r_source_ohm - i_bus_a) / c_bus_f


@jit
def bus_voltage_step(v_bus: float, i_bus_a: float, v_supply: float, r_source_ohm: float, decay: float) -> float:
    """Stage 9 over one step with the bridge current held (exact).

    Parameters
    ----------
    v_bus : float
        Bus voltage at the start of the step (V).
    i_bus_a : float
        The bridge's input current (A).
    v_supply : float
        Supply voltage (V).
    r_source_ohm : float
        Source resistance (Ω).
    decay : float
        ``exp(−dt/(R·C))``.

    Returns
    -------
    float
        The bus voltage at the end of the step (V).
    """
    v_inf = v_supply - r_source_ohm * i_bus_a
    return v_inf + (v_bus - v_inf) * decay


@jit
def steady_bus_voltage(v_supply: float, r_source_ohm: float, power_w: float) -> float:
    """Bus voltage when the bridge draws ``power_w`` steadily: ``V = Vs − Rs·P/V`` solved for V.

    Parameters
    ----------
    v_supply : float
        Supply voltage (V).
    r_source_ohm : float
        Source resistance (Ω).
    power_w : float
        Power drawn (W).

    Returns
    -------
    float
        The bus voltage (V).
    """
    disc = v_supply * v_supply - 4.0 * r_source_ohm * power_w
    return 0.5 * (v_supply + math.sqrt(max(disc, 0.0)))


# ------------------------------------------------------------------------- stages 10-11, 14
@jit
def friction_step(v: float, f_applied: float, coulomb_lbf: float, stiction_lbf: float, dt_per_mass: float,
                  damping_dt_per_mass: float) -> float:
    """Stage 11 (and 14's hinge friction) on a mass over one step, with its own viscous damping implicit.

    ``f_applied`` is every force but friction and the damper's ``−c·v`` on this mass, whose step
    factor ``c·dt/m`` is ``damping_dt_per_mass``: taken implicitly, so the stiff hysteretic damper
    (``h/ω`` at low ω) stays stable. At rest the mass stays put until the applied force exceeds
    stiction; moving, kinetic friction opposes the motion, and a velocity that would change sign
    within the step sticks at zero instead (the discrete form of the stick event the continuous
    model locates).

    Parameters
    ----------
    v : float
        Velocity at the start of the step (in/s).
    f_applied : float
        Applied force (lbf).
    coulomb_lbf : float
        Kinetic friction (lbf).
    stiction_lbf : float
        Static friction (lbf).
    dt_per_mass : float
        ``dt/m`` (in/(lbf·s)).
    damping_dt_per_mass : float
        ``c·dt/m``.

    Returns
    -------
    float
        The velocity at the end of the step (in/s).
    """
    implicit = 1.0 / (1.0 + damping_dt_per_mass)  # known at the step's start: off the velocity's critical path
    if v == 0.0:
        if abs(f_applied) <= stiction_lbf:
            return 0.0
        return dt_per_mass * (f_applied - math.copysign(coulomb_lbf, f_applied)) * implicit
    v_new = (v + dt_per_mass * (f_applied - math.copysign(coulomb_lbf, v))) * implicit
    if unlikely(v_new * v <= 0.0 and abs(f_applied) <= stiction_lbf):  # a branch, not a select on the new velocity
        return 0.0
    return v_new


# ------------------------------------------------------------------------- stages 12 and 15
@jit
def total_force(p: FloatArray, d: float) -> tuple[float, float, int]:
    """Figure 33's total gear-train and linkage curve at deflection ``d``.

    Parameters
    ----------
    p : numpy.ndarray
        Kernel parameters.
    d : float
        Deflection (in).

    Returns
    -------
    force : float
        lbf.
    stiffness : float
        Tangent stiffness (lbf/in).
    segment : int
        1, 2 or 3.
    """
    return gt.three_segment_force(d, p[P.total_f1_lbf], p[P.total_f2_lbf], p[P.total_d1_in], p[P.total_d2_in],
                                  p[P.total_k1_lbf_per_in], p[P.total_k2_lbf_per_in], p[P.total_k3_lbf_per_in])


@jit
def total_deflection(p: FloatArray, force: float) -> float:
    """Deflection of figure 33's total curve under ``force`` (in).

    Parameters
    ----------
    p : numpy.ndarray
        Kernel parameters.
    force : float
        lbf.

    Returns
    -------
    float
        in.
    """
    return gt.three_segment_deflection(force, p[P.total_f1_lbf], p[P.total_f2_lbf], p[P.total_d1_in],
                                       p[P.total_d2_in], 1.0 / p[P.total_k1_lbf_per_in],
                                       1.0 / p[P.total_k2_lbf_per_in], 1.0 / p[P.total_k3_lbf_per_in])


@jit
def actuator_deflection(p: FloatArray, force: float) -> float:
    """Figure 33's actuator (in-loop, LVDT) compliance: deflection under ``force`` (in).

    Parameters
    ----------
    p : numpy.ndarray
        Kernel parameters.
    force : float
        lbf.

    Returns
    -------
    float
        in.
    """
    return gt.three_segment_deflection(force, p[P.actuator_f1_lbf], p[P.actuator_f2_lbf], p[P.actuator_d1_in],
                                       p[P.actuator_d2_in], p[P.actuator_c1_in_per_lbf],
                                       p[P.actuator_c2_in_per_lbf], p[P.actuator_c3_in_per_lbf])


@jit
def gear_train(p: FloatArray, xm: float, xs: float) -> tuple[float, float, float, bool]:
    """Stage 12 (figure 32, or 33 with 36) and stage 15's LVDT reading, segments classified.

    The damper's force ``c·(v_motor − v_surface)`` is left to the integrator, which takes it
    implicitly on each mass.

    Parameters
    ----------
    p : numpy.ndarray
        Kernel parameters.
    xm : float
        Motor-side screw position (in).
    xs : float
        Surface position at the screw (in).

    Returns
    -------
    force : float
        Spring force (lbf).
    damping : float
        Damping coefficient (lbf·s/in).
    lvdt : float
        What the LVDT reads (in).
    free : bool
        In the free play (figure 32's dead zone, figure 33's first segment).
    """
    d = xm - xs
    if p[P.figure33] > 0.5:
        fk, ktan, seg = total_force(p, d)
        c = p[P.linkage_damping_lbf_s_per_in] + gt.hysteretic_damping(p[P.hysteresis_coefficient_s], ktan)
        lvdt = gt.lvdt_fig33(xm, fk, p[P.actuator_f1_lbf], p[P.actuator_f2_lbf], p[P.actuator_d1_in],
                             p[P.actuator_d2_in], p[P.actuator_c1_in_per_lbf], p[P.actuator_c2_in_per_lbf],
                             p[P.actuator_c3_in_per_lbf])
        return fk, c, lvdt, seg == 1
    seg = gt.dead_zone_segment(d, p[P.half_backlash_in])
    fk, _ = gt.gear_train_fig32(d, 0.0, p[P.half_backlash_in], p[P.series_stiffness_lbf_per_in],
                                p[P.gear_damping_lbf_s_per_in], seg)
    c = p[P.gear_damping_lbf_s_per_in] if seg != 0 else 0.0
    return fk, c, gt.lvdt_fig32(xs, fk, p[P.backup_stiffness_lbf_per_in]), seg == 0
