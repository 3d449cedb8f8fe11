"""The gear train of the high-order models: figures 32, 33 and 36 as numba stages.

Everything here is in actuator (ball-screw) coordinates: deflection in inches, force in lbf, the
hinge moment already divided by the servo crank arm (section 3.2.1: "torque was converted to force by
using the geometry of the servo crank arm"). ``d = x_motor − x_surface`` is the gear-train
deformation and ``F`` the force the train passes to the surface (positive pushes it positive).

* **Figure 32** (HOAC1, HOAD2): the deformation passes a dead zone (the actuator's backlash) and the
  gear-train stiffness; the same force deflects the backup structure, which the report adds to the
  surface position. Solved for the force, gear and backup springs act in series beyond the dead zone,
  and the LVDT (nut relative to the actuator housing) reads ``x_surface + F/K_backup``.
* **Figure 33** (HOAD3): the gear train and linkages follow the *total* compliance curve and the
  actuator (inside the servo loop) the *LVDT* compliance curve of figure 16, each as the three-segment
  piecewise-linear model of section 3.2.1 (first segment: the steep free-play region; second: moderate
  load; third: high load). Pure free play is gone: it lives in the first segment. The LVDT reads
  ``x_motor − g_actuator(F)``.
* **Figure 36**: hysteretic damping as the viscous equivalent ``c = h/ω``, scaled by the current over
  the average stiffness because the coupling is nonlinear (section 3.2.2). ``h`` is in lb/in at the
  actuator: rw13's loop is force at the actuator (hinge moment / crank arm, lbf) against deflection at
  the actuator (surface angle × crank arm, in), so its area is lbf·in (the report's "in·lb") and
  ``A/(π·Pk²)`` is lbf/in, the units of this module (see :mod:`ema_sim.analysis.section2.hysteresis`).
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from ema_sim.models.stages import band_side, jit

# ------------------------------------------------------------------------------------ figure 32
dead_zone_segment = band_side
"""Which side of the figure-32 dead zone a deflection is on: −1, 0 (free play) or +1 (in contact)."""


@jit
def gear_train_fig32(d: float, v_rel: float, half_backlash_in: float, k_series_lbf_per_in: float,
                     damping_lbf_s_per_in: float, segment: int) -> tuple[float, float]:
    """Figure 32: dead zone (backlash) → gear stiffness in series with backup-structure stiffness.

    ``segment`` picks the branch (−1, 0, +1; see :func:`dead_zone_segment`), so a continuous
    integrator can hold it fixed between located events. The damper acts only in contact.

    Parameters
    ----------
    d : float
        Gear-train deformation ``x_motor − x_surface`` (in).
    v_rel : float
        Its rate (in/s).
    half_backlash_in : float
        Half the backlash (in).
    k_series_lbf_per_in : float
        Gear and backup stiffness in series (lbf/in).
    damping_lbf_s_per_in : float
        Damping in contact (lbf·s/in).
    segment : int
        The branch held.

    Returns
    -------
    spring : float
        Spring force (lbf).
    total : float
        Spring plus damper force (lbf).
    """
    if segment > 0:
        spring = k_series_lbf_per_in * (d - half_backlash_in)
    elif segment < 0:
        spring = k_series_lbf_per_in * (d + half_backlash_in)
    else:
        return 0.0, 0.0
    return spring, spring + damping_lbf_s_per_in * v_rel


@jit
def series_stiffness(k_gear_lbf_per_in: float, k_backup_lbf_per_in: float) -> float:
    """Gear train and backup structure in series: the figure-32 loop solved for the force.

    Parameters
    ----------
    k_gear_lbf_per_in : float
        Gear-train stiffness.
    k_backup_lbf_per_in : float
        Backup-structure stiffness.

    Returns
    -------
    float
        The series stiffness (lbf/in).
    """
    return k_gear_lbf_per_in * k_backup_lbf_per_in / (k_gear_lbf_per_in + k_backup_lbf_per_in)


@jit
def lvdt_fig32(x_surface_in: float, spring_force_lbf: float, k_backup_lbf_per_in: float) -> float:
    """What the LVDT reads in figure 32: the nut relative to a housing the backup structure lets move.

    Parameters
    ----------
    x_surface_in : float
        Surface position at the screw (in).
    spring_force_lbf : float
        Gear-train force (lbf).
    k_backup_lbf_per_in : float
        Backup-structure stiffness.

    Returns
    -------
    float
        The LVDT reading (in).
    """
    return x_surface_in + spring_force_lbf / k_backup_lbf_per_in


# ------------------------------------------------------------------------------------ figure 33
def three_segment_breakpoints(f1: float, f2: float, k1: float, k2: float, k3: float) -> tuple[float, ...]:
    """Section 3.2.1's three-segment curve in kernel form, divisions done once.

    Parameters
    ----------
    f1, f2 : float
        Breakpoint forces, ``f1 < f2`` (lbf).
    k1, k2, k3 : float
        Segment stiffnesses (lbf/in).

    Returns
    -------
    tuple of float
        ``(f1, f2, d1, d2, k1, k2, k3, c1, c2, c3)``: the deflections ``d1, d2`` at the breakpoints
        and the segment compliances ``c = 1/k``.
    """
    d1 = f1 / k1
    d2 = d1 + (f2 - f1) / k2
    return f1, f2, d1, d2, k1, k2, k3, 1.0 / k1, 1.0 / k2, 1.0 / k3


@jit
def three_segment_force(d: float, f1: float, f2: float, d1: float, d2: float, k1: float, k2: float,
                        k3: float) -> tuple[float, float, int]:
    """Force from deflection on the odd-symmetric three-segment curve.

    Parameters
    ----------
    d : float
        Deflection (in).
    f1, f2 : float
        Breakpoint forces, ``f1 < f2`` (lbf).
    d1, d2 : float
        Deflections at the breakpoints (in).
    k1, k2, k3 : float
        Segment stiffnesses (lbf/in).

    Returns
    -------
    force : float
        lbf.
    stiffness : float
        Tangent stiffness (lbf/in).
    segment : int
        1, 2 or 3.
    """
    a = abs(d)
    if a <= d1:
        return math.copysign(k1 * a, d), k1, 1
    if a <= d2:
        return math.copysign(f1 + k2 * (a - d1), d), k2, 2
    return math.copysign(f2 + k3 * (a - d2), d), k3, 3


@jit
def three_segment_deflection(force: float, f1: float, f2: float, d1: float, d2: float, c1: float, c2: float,
                             c3: float) -> float:
    """The inverse of :func:`three_segment_force`: deflection from force.

    Parameters
    ----------
    force : float
        lbf.
    f1, f2 : float
        Breakpoint forces, ``f1 < f2`` (lbf).
    d1, d2 : float
        Deflections at the breakpoints (in).
    c1, c2, c3 : float
        Segment compliances (in/lbf).

    Returns
    -------
    float
        Deflection (in).
    """
    a = abs(force)
    if a <= f1:
        return math.copysign(a * c1, force)
    if a <= f2:
        return math.copysign(d1 + (a - f1) * c2, force)
    return math.copysign(d2 + (a - f2) * c3, force)


@jit
def lvdt_fig33(x_motor_in: float, spring_force_lbf: float, f1: float, f2: float, g1: float, g2: float,
               c1: float, c2: float, c3: float) -> float:
    """What the LVDT reads in figure 33: motor-side position less the actuator's own compliance.

    Parameters
    ----------
    x_motor_in : float
        Motor-side screw position (in).
    spring_force_lbf : float
        Gear-train force (lbf).
    f1, f2 : float
        The actuator curve's breakpoint forces (lbf).
    g1, g2 : float
        Its deflections at the breakpoints (in).
    c1, c2, c3 : float
        Its segment compliances (in/lbf).

    Returns
    -------
    float
        The LVDT reading (in).
    """
    return x_motor_in - three_segment_deflection(spring_force_lbf, f1, f2, g1, g2, c1, c2, c3)


# ------------------------------------------------------------------------------------ figure 36
@jit
def hysteretic_damping(coefficient: float, k_tangent: float) -> float:
    """Figure 36: viscous equivalent of hysteretic damping, ``(h/ω)·(k/k_avg)`` in lbf·s/in.

    ``coefficient = h/(ω·k_avg)`` (0 when off), so the kernel multiplies by the current stiffness only.

    Parameters
    ----------
    coefficient : float
        :func:`hysteresis_coefficient` (s).
    k_tangent : float
        The current tangent stiffness (lbf/in).

    Returns
    -------
    float
        Damping coefficient (lbf·s/in).
    """
    return coefficient * k_tangent


def hysteresis_coefficient(h_lbf_per_in: float, omega_rad_s: float, k_average: float) -> float:
    """``h/(ω·k_avg)`` for :func:`hysteretic_damping` (s); 0 when ``h`` or ``ω`` is 0.

    Parameters
    ----------
    h_lbf_per_in : float
        Hysteretic damping h.
    omega_rad_s : float
        The frequency ω of h/ω.
    k_average : float
        :func:`hysteresis_average_stiffness` (lbf/in).

    Returns
    -------
    float
        The coefficient (s).
    """
    if h_lbf_per_in <= 0.0 or omega_rad_s <= 0.0:
        return 0.0
    return h_lbf_per_in / (omega_rad_s * k_average)


def hysteresis_average_stiffness(peak_force_lbf: float, curve: tuple[float, ...], points: int = 20_001) -> float:
    """The average stiffness of figure 36's stiffness ratio over the anticipated motion.

    Over one quasi-static cycle of a sinusoidal force of amplitude ``peak_force_lbf`` the scaled
    damper dissipates ``(h/k_avg)·P²·∫cos²θ / k(θ) dθ``. This ``k_avg`` is the average that makes it
    ``π·h·X²`` (X the deflection amplitude), the energy of the hysteresis loop ``h`` was estimated
    from (``h = A/(π·X²)``, section 3.2.2); for a linear spring it is that spring's stiffness. It weighs
    the stiffness by where the coupling moves fastest, through the soft free-play segment.
    Parameters
    ----------
    peak_force_lbf : float
        Force amplitude of the anticipated motion (lbf).
    curve : tuple of float
        :func:`three_segment_breakpoints`' tuple.
    points : int
        Quadrature points over the cycle.

    Returns
    -------
    float
        ``k_avg`` (lbf/in).
    """
    f1, f2, d1, d2, _, _, _, c1, c2, c3 = curve
    theta = np.linspace(0.0, 2.0 * np.pi, points)
    force = np.abs(peak_force_lbf * np.sin(theta))
    compliance = np.where(force <= f1, c1, np.where(force <= f2, c2, c3))
    x_peak = three_segment_deflection(peak_force_lbf, f1, f2, d1, d2, c1, c2, c3)
    integral = np.trapezoid(np.cos(theta) ** 2 * compliance, theta)
    return float(peak_force_lbf**2 * integral / (np.pi * x_peak**2))


@nb.njit(cache=True)
def three_segment_curve(force: np.ndarray, f1: float, f2: float, d1: float, d2: float, c1: float, c2: float,
                        c3: float) -> np.ndarray:
    """:func:`three_segment_deflection` for an array of forces (for plots, tests and the table in docs/models.md).

    Parameters
    ----------
    force : numpy.ndarray
        Forces (lbf).
    f1, f2 : float
        Breakpoint forces, ``f1 < f2`` (lbf).
    d1, d2 : float
        Deflections at the breakpoints (in).
    c1, c2, c3 : float
        Segment compliances (in/lbf).

    Returns
    -------
    numpy.ndarray
        Deflections (in).
    """
    out = np.empty_like(force)
    for j in range(force.shape[0]):
        out[j] = three_segment_deflection(force[j], f1, f2, d1, d2, c1, c2, c3)
    return out
