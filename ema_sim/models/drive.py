"""The electromechanical drive of the high-order models (figure 30) as numba stages.

From the EMAC channel to the ball screw: position-loop controller electronics, current loop, PWM with
its dead band, the three-phase brushless DC motor as its DC equivalent with a current limit, the
150 V bus with regeneration, Coulomb friction, stiction and the power-off brake. Mechanical
quantities are in ball-screw coordinates (in, in/s, lbf); the motor's rotation maps to them through
the gear ratio and screw lead (``G = lead / (2π·N)`` in/rad).

Each switching element exists in two forms: ``*_segment`` classifies its input into a numbered
region, and the element itself takes that region as an argument. A fixed-step kernel classifies then
evaluates; the continuous model holds the region fixed between located events (every branch is a
smooth function extended past its boundary), so Dormand–Prince never steps across a corner.
"""

from __future__ import annotations

import math

from ema_sim.models.stages import jit

INLB_PER_NM = 8.850745793490558
"""in·lbf per N·m: the motor's torque constant in in·lbf/A is its back-EMF constant (V·s/rad) times this."""


# ------------------------------------------------------------------------- switching elements
@jit
def saturation_segment(x: float, limit: float) -> int:
    """−1 below −limit, 0 inside, +1 above."""
    if x > limit:
        return 1
    if x < -limit:
        return -1
    return 0


@jit
def saturate(x: float, limit: float, segment: int) -> float:
    """A saturation held on ``segment`` (see :func:`saturation_segment`)."""
    if segment > 0:
        return limit
    if segment < 0:
        return -limit
    return x


@jit
def pwm_segment(v_demand: float, dead_band_v: float, v_max: float) -> int:
    """Region of the PWM stage: ±2 saturated, ±1 linear, 0 inside the dead band."""
    if v_demand > dead_band_v:
        return 2 if v_demand - dead_band_v > v_max else 1
    if v_demand < -dead_band_v:
        return -2 if v_demand + dead_band_v < -v_max else -1
    return 0


# ------------------------------------------------------------------------- figure 30 stages
@jit
def position_loop(x_command_in: float, x_feedback_in: float, kp_per_s: float, integral_in_s: float) -> float:
    """Position-loop controller electronics: the velocity demand ``Kp·(command − LVDT) + ∫Ki·e`` (in/s).

    Saturated at the slew limit with :func:`saturate`; the tachometer closes the velocity loop next.
    The integral (:func:`integrating`) gives the loaded servo its static stiffness (section 2.8).
    """
    return kp_per_s * (x_command_in - x_feedback_in) + integral_in_s


@jit
def integrating(rate_segment: int, current_segment: int, pwm_segment_: int) -> bool:
    """Conditional integration: only while the PWM drives linearly and nothing saturates.

    Frozen inside the PWM dead band, an unloaded actuator at rest keeps its dead zone (no hunting on
    stiction), while a loaded one, driven outside the band, integrates its error away.
    """
    return rate_segment == 0 and current_segment == 0 and pwm_segment_ in (1, -1)


@jit
def velocity_loop(v_command_in_s: float, v_tach_in_s: float, kv_a_per_in_s: float) -> float:
    """Velocity (tachometer) loop: the current demand ``Kv·(v_command − v_motor)`` (A), before the limit."""
    return kv_a_per_in_s * (v_command_in_s - v_tach_in_s)


@jit
def current_loop(i_command_a: float, i_a: float, v_tach_in_s: float, kc_v_per_a: float, r_ohm: float,
                 ke_v_per_in_s: float) -> float:
    """Current loop: proportional on the current error plus resistive and back-EMF feed-forward (V).

    With the feed-forward the motor current settles on the demand exactly outside the PWM dead band;
    there is no integrator, so nothing winds up inside it (an integrator would hunt on stiction).
    """
    return kc_v_per_a * (i_command_a - i_a) + r_ohm * i_command_a + ke_v_per_in_s * v_tach_in_s


@jit
def pwm(v_demand: float, dead_band_v: float, v_max: float, segment: int) -> float:
    """PWM with its dead band: no output for demands inside ±dead band, then linear, then the duty limit.

    The dead band is a dead zone (the output is continuous): an unloaded actuator at rest draws no
    current until its error needs more than the band (section 4.3's dither mechanism).
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
def motor_current_rate(v_applied: float, i_a: float, v_motor_in_s: float, r_ohm: float, l_h: float,
                       ke_v_per_in_s: float) -> float:
    """DC-equivalent brushless motor: ``L·di/dt = V − R·i − Ke·ω`` (A/s)."""
    return (v_applied - r_ohm * i_a - ke_v_per_in_s * v_motor_in_s) / l_h


@jit
def motor_current_step(v_applied: float, i_a: float, v_motor_in_s: float, conductance: float, ke_v_per_in_s: float,
                       decay: float) -> float:
    """The motor current after one step with voltage and speed held: exact RL response.

    ``conductance = 1/R`` (S), ``decay = exp(−R·dt/L)``; exact whatever the step, where forward Euler
    on an electrical time constant well under a step would not be.
    """
    i_inf = (v_applied - ke_v_per_in_s * v_motor_in_s) * conductance
    return i_inf + (i_a - i_inf) * decay


@jit
def bus_current(v_applied: float, i_a: float, v_bus: float) -> float:
    """H-bridge input current (A): ``duty·i``; negative while the motor regenerates into the bus."""
    return v_applied * i_a / v_bus


@jit
def bus_voltage_rate(v_bus: float, i_bus_a: float, v_supply: float, r_source_ohm: float, c_bus_f: float) -> float:
    """150 V bus: supply behind its source resistance feeding the bus capacitance (V/s).

    Regenerated current (``i_bus < 0``) charges the capacitance and raises the bus above the supply
    (section 2.5; the allowable peak is 185 V).
    """
    return ((v_supply - v_bus) / r_source_ohm - i_bus_a) / c_bus_f


@jit
def bus_voltage_step(v_bus: float, i_bus_a: float, v_supply: float, r_source_ohm: float, decay: float) -> float:
    """The bus voltage after one step with the bridge current held (exact; ``decay = exp(−dt/(R·C))``)."""
    v_inf = v_supply - r_source_ohm * i_bus_a
    return v_inf + (v_bus - v_inf) * decay


@jit
def steady_bus_voltage(v_supply: float, r_source_ohm: float, power_w: float) -> float:
    """Bus voltage when the bridge draws ``power_w`` steadily: ``V = Vs − Rs·P/V`` solved for V."""
    disc = v_supply * v_supply - 4.0 * r_source_ohm * power_w
    return 0.5 * (v_supply + math.sqrt(max(disc, 0.0)))


@jit
def friction_step(v: float, f_applied: float, coulomb_lbf: float, stiction_lbf: float, dt_per_mass: float,
                  damping_dt_per_mass: float) -> float:
    """Coulomb friction and stiction on a mass over one step, with its own viscous damping implicit.

    ``f_applied`` is every force but friction and the damper's ``−c·v`` on this mass, whose step
    factor ``c·dt/m`` is ``damping_dt_per_mass``: taken implicitly, so the stiff hysteretic damper
    (``h/ω`` at low ω) stays stable. At rest the mass stays put until the applied force exceeds
    stiction; moving, kinetic friction opposes the motion, and a velocity that would change sign
    within the step sticks at zero instead (the discrete form of the stick event the continuous
    model locates). Returns the new velocity.
    """
    if v == 0.0:
        if abs(f_applied) <= stiction_lbf:
            return 0.0
        return dt_per_mass * (f_applied - math.copysign(coulomb_lbf, f_applied)) / (1.0 + damping_dt_per_mass)
    v_new = (v + dt_per_mass * (f_applied - math.copysign(coulomb_lbf, v))) / (1.0 + damping_dt_per_mass)
    if v_new * v <= 0.0 and abs(f_applied) <= stiction_lbf:
        return 0.0
    return v_new
