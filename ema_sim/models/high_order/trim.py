"""Trim of the high-order models: the state in which a held command and load leave every stage at rest.

Used by every implementation to start in equilibrium (no start-up transient) and to find the command
that holds a wanted LVDT reading under a load.
"""

from __future__ import annotations

import math
from typing import Literal, TypedDict

from ema_sim.models.arrays import FloatArray
from ema_sim.models.high_order import gear_train as gt
from ema_sim.models.high_order.figure30 import (
    MOTOR_STOP_HIGH,
    MOTOR_STOP_LOW,
    MOTOR_STUCK,
    actuator_deflection,
    steady_bus_voltage,
    total_deflection,
)
from ema_sim.models.high_order.params import P
from ema_sim.models.stages import FLAG_BRAKE, FLAG_FREE_PLAY, FLAG_POSITION, FLAG_PWM_DEAD_BAND

TrimKey = Literal["xm", "xs", "cur", "lf", "vbus", "xi"]
"""The trimmed states of :class:`Equilibrium` (the models write them into their state columns by these names)."""


class Equilibrium(TypedDict):
    """The trim :func:`equilibrium` finds: positions (in), current (A), LVDT (in), bus (V), integral (in/s)."""

    xm: float
    xs: float
    cur: float
    lf: float
    vbus: float
    xi: float
    motor: int
    """The motor's regime (``MOTOR_*`` of :mod:`~ema_sim.models.high_order.figure30`)."""
    flags: int
    """The limit flags the trim holds (``FLAG_*`` of :mod:`~ema_sim.models.stages`)."""


def equilibrium(p: FloatArray, x_command_in: float, hinge_moment_inlb: float, powered: bool) -> Equilibrium:
    """The state in which a held command and load leave every stage at rest (trim).

    The gear train carries the load (``F = −hm/r``) and the motor current holds it with friction
    carrying nothing. The current demand is what the current loop and the PWM dead band need for that
    current; the position integral supplies it with no servo error (without the integral, a servo
    error does). Unloaded, the PWM rests in its dead band with the integral at zero. A load the motor
    cannot hold (beyond stall plus stiction) leaves the motor on the stop the load pushes it to, with
    the current demand limited.

    Parameters
    ----------
    p : numpy.ndarray
        Kernel parameters (:data:`~ema_sim.models.high_order.params.P`).
    x_command_in : float
        The held command after stage 2 (in).
    hinge_moment_inlb : float
        The held load (in·lb).
    powered : bool
        Motor power on (off: the brake holds).

    Returns
    -------
    Equilibrium
        ``xm``, ``xs`` (in), ``cur`` (A), ``lf`` (in), ``vbus`` (V), ``xi`` (in/s), ``motor`` (regime)
        and ``flags``.
    """
    xc = min(max(x_command_in, p[P.position_min_in]), p[P.position_max_in])
    force = -hinge_moment_inlb / p[P.crank_arm_in]
    kf, kp, kv = p[P.force_per_amp_lbf_per_a], p[P.position_gain_per_s], p[P.velocity_gain_a_per_in_s]
    kc, r, vdb = p[P.current_gain_v_per_a], p[P.stator_resistance_ohm], p[P.pwm_dead_band_v]
    i_db = vdb / (kc + r)
    motor = MOTOR_STUCK
    cur = 0.0
    lf = xc
    xi = 0.0
    if powered:
        cur = force / kf
        if abs(cur) > p[P.current_limit_a] - i_db + p[P.stiction_lbf] / kf:
            motor = MOTOR_STOP_HIGH if hinge_moment_inlb > 0.0 else MOTOR_STOP_LOW
            cur = 0.0
        elif cur != 0.0:
            ic = cur + math.copysign(i_db, cur)
            if p[P.position_integral_per_s2] > 0.0:
                xi = ic / kv
            else:
                lf = xc - ic / (kv * kp)
    if motor == MOTOR_STUCK:
        xm, xs = positions_from_lvdt(p, lf, force)
    else:
        xm = p[P.position_max_in] if motor == MOTOR_STOP_HIGH else p[P.position_min_in]
        lf, xs, cur = at_stop(p, xm, xc, force)
    volts = r * cur
    power = volts * cur
    vbus = steady_bus_voltage(p[P.bus_supply_v], p[P.bus_source_resistance_ohm], power) if powered else \
        p[P.bus_supply_v]
    flags = 0 if powered else FLAG_BRAKE
    if powered and cur == 0.0:
        flags |= FLAG_PWM_DEAD_BAND
    if motor != MOTOR_STUCK or x_command_in != xc:
        flags |= FLAG_POSITION
    if p[P.figure33] > 0.5:
        free = abs(force) <= p[P.total_f1_lbf]
    else:
        free = gt.dead_zone_segment(xm - xs, p[P.half_backlash_in]) == 0
    if free:
        flags |= FLAG_FREE_PLAY
    return {"xm": xm, "xs": xs, "cur": cur, "lf": lf, "vbus": vbus, "xi": xi, "motor": motor, "flags": flags}


def positions_from_lvdt(p: FloatArray, lvdt: float, force: float) -> tuple[float, float]:
    """Motor-side and surface positions whose LVDT reading is ``lvdt`` under gear force ``force``.

    Parameters
    ----------
    p : numpy.ndarray
        Kernel parameters.
    lvdt : float
        The LVDT reading (in).
    force : float
        The gear force (lbf).

    Returns
    -------
    xm, xs : float
        Motor-side and surface positions (in).
    """
    if p[P.figure33] > 0.5:
        xm = lvdt + actuator_deflection(p, force)
        d = total_deflection(p, force)
        return xm, xm - d
    xs = lvdt - force / p[P.backup_stiffness_lbf_per_in]
    d = 0.0 if force == 0.0 else force / p[P.series_stiffness_lbf_per_in] + math.copysign(p[P.half_backlash_in],
                                                                                        force)
    return xs + d, xs


def at_stop(p: FloatArray, xm: float, xc: float, force: float) -> tuple[float, float, float]:
    """LVDT, surface position and current of a motor held on a stop (the stop takes the difference).

    Parameters
    ----------
    p : numpy.ndarray
        Kernel parameters.
    xm : float
        The stop (in).
    xc : float
        The command (in).
    force : float
        The gear force (lbf).

    Returns
    -------
    lvdt, xs : float
        LVDT reading and surface position (in).
    current : float
        The limited current pushing towards the command (A).
    """
    if p[P.figure33] > 0.5:
        lvdt = xm - actuator_deflection(p, force)
        xs = xm - total_deflection(p, force)
    else:
        d = 0.0 if force == 0.0 else force / p[P.series_stiffness_lbf_per_in] + math.copysign(p[P.half_backlash_in],
                                                                                            force)
        xs = xm - d
        lvdt = xs + force / p[P.backup_stiffness_lbf_per_in]
    toward = math.copysign(1.0, xc - lvdt) if xc != lvdt else 0.0
    i_db = p[P.pwm_dead_band_v] / (p[P.current_gain_v_per_a] + p[P.stator_resistance_ohm])
    cur = toward * (p[P.current_limit_a] - i_db)
    return lvdt, xs, cur
