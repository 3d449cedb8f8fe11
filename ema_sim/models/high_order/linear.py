"""HOAD3 linearized about a load for HOALM (section 4.2.7), its nonlinear elements removed.

The figure-30 chain with the PWM dead band, stiction and Coulomb friction, the current, rate and
voltage limits and the switching taken out; figure 33's piecewise-linear compliance curves replaced by
their slopes at the operating force; quantization and noise dropped; the command and feedback delays
kept (exactly, as delays). :class:`ema_sim.models.linear.Hoalm` steps and evaluates the result.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ema_sim.models.arrays import FloatArray
from ema_sim.models.high_order.figure30 import total_deflection, total_force
from ema_sim.models.high_order.params import HighOrderParams, P
from ema_sim.parameters import slots

STATES = ("x_motor_in", "v_motor_in_s", "x_surface_in", "v_surface_in_s", "current_a", "lvdt_filtered_in",
          "integral_in_s")
"""The linear model's states, in order."""
L = slots("LinearState", STATES)


@dataclass(frozen=True)
class LinearizedActuator:
    """HOAD3 linearized about a load, for HOALM (section 4.2.7): matrices of ``ẋ = A·x + B·u``, ``y = C·x``.

    States: :data:`STATES`. Inputs: command (deg), hinge moment (in·lb). Outputs: position and
    surface (deg).

    Parameters
    ----------
    a, b, c : numpy.ndarray
        The state-space matrices.
    command_delay_s : float
        Command delay (s).
    feedback_delay_s : float
        Delay on the position output (s).
    total_stiffness_lbf_per_in : float
        The gear train's slope at the operating force.
    actuator_compliance_in_per_lbf : float
        The in-loop (LVDT) compliance at the operating force.
    states : tuple of str
        The state names.
    """

    a: FloatArray
    b: FloatArray
    c: FloatArray
    command_delay_s: float
    feedback_delay_s: float
    total_stiffness_lbf_per_in: float
    actuator_compliance_in_per_lbf: float
    states: tuple[str, ...] = STATES


def linearize(params: HighOrderParams, hinge_moment_inlb: float = 0.0, *, bound: float = 0.0,
              figure33: bool = True) -> LinearizedActuator:
    """The figure-30 pipeline about the equilibrium under ``hinge_moment_inlb``, nonlinear elements removed.

    The position integral is linear and stays (it integrates whenever the PWM is out of its dead band,
    which without a dead band is always). Hysteretic damping is frequency dependent and is left out.

    Parameters
    ----------
    params : HighOrderParams
        The parameters (HOAD3's).
    hinge_moment_inlb : float
        The load it is linearized at (in·lb).
    bound : float
        Figure 35's compliance bound (−1 … +1).
    figure33 : bool
        Figure 33's gear train (else figure 32's, beyond its backlash).

    Returns
    -------
    LinearizedActuator
        The matrices and delays.
    """
    v = params.kernel_vector(figure33=figure33, bound=bound, hysteresis=False, noise=False)
    force = -hinge_moment_inlb / v[P.crank_arm_in]
    if figure33:
        _, kt, _ = total_force(v, total_deflection(v, force))
        seg_c = (v[P.actuator_c1_in_per_lbf], v[P.actuator_c2_in_per_lbf], v[P.actuator_c3_in_per_lbf])
        f1, f2 = v[P.actuator_f1_lbf], v[P.actuator_f2_lbf]
        ca = seg_c[0] if abs(force) < f1 else (seg_c[1] if abs(force) < f2 else seg_c[2])
        damping = v[P.linkage_damping_lbf_s_per_in]
    else:
        kt = v[P.series_stiffness_lbf_per_in]
        # figure 32: LVDT = x_surface + F/K_backup, beyond the backlash
        ca = 1.0 / v[P.series_stiffness_lbf_per_in] - 1.0 / v[P.backup_stiffness_lbf_per_in]
        damping = v[P.gear_damping_lbf_s_per_in]
    kp, kv, kc = v[P.position_gain_per_s], v[P.velocity_gain_a_per_in_s], v[P.current_gain_v_per_a]
    r, ll, kf = v[P.stator_resistance_ohm], v[P.inductance_h], v[P.force_per_amp_lbf_per_a]
    mm, ms, wf, dpi = v[P.motor_mass_lbs2_per_in], v[P.surface_mass_lbs2_per_in], v[P.lvdt_filter_rad_s], \
        v[P.deg_per_in]
    a = np.zeros((7, 7))
    b = np.zeros((7, 2))
    xm, vm, xs, vs, cur, lf, xi = (L.x_motor_in, L.v_motor_in_s, L.x_surface_in, L.v_surface_in_s, L.current_a,
                                   L.lvdt_filtered_in, L.integral_in_s)
    # current loop without the dead band: L·di/dt = (Kc + R)·(i_c − i), i_c = Kv·(Kp·(x_c − lf) + ∫ − v_m)
    g = (kc + r) / ll
    a[cur, cur] = -g
    a[cur, vm] = -g * kv
    a[cur, lf] = -g * kv * kp
    a[cur, xi] = g * kv
    b[cur, 0] = g * kv * kp / dpi
    a[xi, lf] = -v[P.position_integral_per_s2]
    b[xi, 0] = v[P.position_integral_per_s2] / dpi
    # motor and surface through the linearized gear train
    a[xm, vm] = 1.0
    a[vm, cur] = kf / mm
    a[vm, xm] = -kt / mm
    a[vm, xs] = kt / mm
    a[vm, vm] = -damping / mm
    a[vm, vs] = damping / mm
    a[xs, vs] = 1.0
    a[vs, xm] = kt / ms
    a[vs, xs] = -kt / ms
    a[vs, vm] = damping / ms
    a[vs, vs] = -damping / ms
    b[vs, 1] = 1.0 / (v[P.crank_arm_in] * ms)
    # LVDT (motor-side position less the in-loop compliance) and its filter
    a[lf, xm] = wf * (1.0 - ca * kt)
    a[lf, xs] = wf * ca * kt
    a[lf, lf] = -wf
    c = np.zeros((2, 7))
    c[0, lf] = dpi
    c[1, xs] = dpi
    return LinearizedActuator(a, b, c, params.command_delay_s, params.feedback_delay_s, float(kt), float(ca))
