"""Figure 26's surface, outside the servo loop: stages 15–17, each written once.

15. free play             figure 29's limited integrator (:mod:`.figure29`), or the dead zone of stage 17's spring
16. compliance            deflection with hinge moment, linear or stiffening at a knee (figures 16, 33), with
                          hysteretic damping (figure 36) as a first-order lag
17. linkage mode          the surface's inertia on the linkage spring (stages 15–16 as its force–deflection
                          curve), excited by the actuator's acceleration and the hinge moment (figures 32, 33)

Stage 12 (the LVDT's compliance) reads the same curve as stage 16 (:func:`compliance_deflection`).
:mod:`.figure26` names these stages in the diagram's order; the integrators call them from there.
"""

from __future__ import annotations

import math

import numpy as np

from ema_sim.models.arrays import FloatArray
from ema_sim.models.second_order import stage_set
from ema_sim.models.second_order.params import P, X
from ema_sim.models.stages import DEG2RAD, TWO_PI, dead_zone, jit, oscillator_step


@jit
def compliance_deflection(hinge_moment_inlb: float, deg_per_kinlb: float, knee_inlb: float = math.inf,
                          stiff_deg_per_kinlb: float = 0.0) -> float:
    """Stages 12 and 16: deflection with hinge moment (deg), linear up to the knee, stiffer beyond it.

    ``c·|hm|`` up to the knee, then ``c·knee + c_stiff·(|hm| − knee)``, with the sign of hm (the data
    contract's ``nonlinear_compliance``); an infinite knee is the linear compliance.

    Parameters
    ----------
    hinge_moment_inlb : float
        Hinge moment (in·lb).
    deg_per_kinlb : float
        Compliance below the knee (deg per 1000 in·lb).
    knee_inlb : float
        Hinge moment where it stiffens (in·lb; inf: linear).
    stiff_deg_per_kinlb : float
        Compliance above the knee (deg per 1000 in·lb).

    Returns
    -------
    float
        The deflection (deg).
    """
    a = abs(hinge_moment_inlb)
    d = deg_per_kinlb * a if a <= knee_inlb else deg_per_kinlb * knee_inlb + stiff_deg_per_kinlb * (a - knee_inlb)
    return math.copysign(d * 1e-3, hinge_moment_inlb) if d != 0.0 else 0.0


@jit
def surface_compliance(p: FloatArray, hinge_moment_inlb: float, on: int = stage_set.ALL) -> float:
    """Stage 16's static deflection (deg).

    Parameters
    ----------
    p : numpy.ndarray
        Kernel parameters.
    hinge_moment_inlb : float
        Hinge moment (in·lb).
    on : int
        The stages that may be on (:mod:`.stage_set`).

    Returns
    -------
    float
        The deflection outside the servo loop (deg).
    """
    if not on & stage_set.COMPLIANCE:
        return 0.0
    return compliance_deflection(hinge_moment_inlb, p[P.compliance_deg_per_kinlb], p[P.compliance_knee_inlb],
                                 p[P.compliance_stiff_deg_per_kinlb])


@jit
def compliance_time_constant_s(p: FloatArray) -> float:
    """Stage 16: linkage stiffness k and hysteretic damping h/ω make the compliance a first-order lag.

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
def free_play_subsystem(p: FloatArray) -> bool:
    """Stage 15 runs as figure 29's own subsystem (not as the dead zone of a linkage mode's spring).

    Parameters
    ----------
    p : numpy.ndarray
        Kernel parameters.

    Returns
    -------
    bool
        True with free play and no linkage mode.
    """
    return bool(p[P.free_play_deg] > 0.0 and p[P.linkage_freq_hz] <= 0.0)


@jit
def linkage_spring(p: FloatArray, e: float) -> tuple[float, int]:
    """Stage 17's spring, as the static deflection its force balances: stage 16's curve inverted.

    Inside the free play (stage 15) it carries nothing; beyond it, the deflection up to the knee's,
    then the stiffer segment scaled back to the compliance below the knee (so the linkage frequency
    is the one below the knee and rises by √(c/c_stiff) above it).

    Parameters
    ----------
    p : numpy.ndarray
        Kernel parameters.
    e : float
        The surface's deflection from the actuator (deg).

    Returns
    -------
    deflection : float
        The static deflection the spring's force would hold (deg).
    piece : int
        The curve's segment: 0 in the free play, 1 below the knee, 2 above it (:func:`linkage_slope`).
    """
    e_dz, side = dead_zone(e, 0.5 * p[P.free_play_deg])
    if side == 0 and p[P.free_play_deg] > 0.0:
        return e_dz, 0
    c = p[P.compliance_deg_per_kinlb]
    knee = p[P.compliance_knee_inlb]
    if c <= 0.0 or knee == math.inf:
        return e_dz, 1
    a = abs(e_dz)
    ck = c * knee * 1e-3
    if a <= ck:
        return e_dz, 1
    return math.copysign(ck + c * (a - ck) / max(p[P.compliance_stiff_deg_per_kinlb], 1e-6), e_dz), 2


@jit
def linkage_slope(p: FloatArray, piece: int) -> float:
    """The slope of :func:`linkage_spring` on one of its segments.

    Parameters
    ----------
    p : numpy.ndarray
        Kernel parameters.
    piece : int
        0 (free play), 1 (below the knee) or 2 (above it).

    Returns
    -------
    float
        d(deflection)/de.
    """
    if piece == 0:
        return 0.0
    if piece == 1:
        return 1.0
    return float(p[P.compliance_deg_per_kinlb] / max(p[P.compliance_stiff_deg_per_kinlb], 1e-6))


@jit
def linkage_damping(p: FloatArray) -> float:
    """Stage 17's damping ``2ζω + ω²τh`` (1/s): the damper and any hysteretic damping's viscous equivalent.

    Parameters
    ----------
    p : numpy.ndarray
        Kernel parameters.

    Returns
    -------
    float
        1/s.
    """
    w0 = TWO_PI * p[P.linkage_freq_hz]
    return float(2.0 * p[P.linkage_zeta] * w0 + w0 * w0 * compliance_time_constant_s(p))


@jit
def linkage_accel(p: FloatArray, y: FloatArray, hinge_moment_inlb: float, actuator_accel: float) -> float:
    """Stage 17: the surface's acceleration relative to the actuator (°/s²).

    ``ë = ω²·(curve(hm) − spring(e)) − (2ζω + ω²τh)·ė − a_actuator``: the hinge moment loads the
    spring, the actuator's acceleration shakes the surface, the damper (and any hysteretic damping's
    viscous equivalent) damps the relative motion.

    Parameters
    ----------
    p : numpy.ndarray
        Kernel parameters.
    y : numpy.ndarray
        State.
    hinge_moment_inlb : float
        Hinge moment (in·lb).
    actuator_accel : float
        The actuator's acceleration (°/s²).

    Returns
    -------
    float
        d/dt of the linkage rate (°/s²).
    """
    w0 = TWO_PI * p[P.linkage_freq_hz]
    target = surface_compliance(p, hinge_moment_inlb)
    spring, _ = linkage_spring(p, y[X.linkage_deg])
    return float(w0 * w0 * (target - spring) - linkage_damping(p) * y[X.linkage_rate_dps] - actuator_accel)


@jit
def linkage_steps(p: FloatArray, dt: float) -> FloatArray:
    """Stage 17's exact steps over ``dt``, one row per spring segment: ``(φ00, φ01, φ10, φ11, γ0, k)``.

    On each segment of :func:`linkage_spring` the mode is linear, ``ë = −k·e − c·ė + f`` with
    ``k = ω²·slope``, so its zero-order-hold step (:func:`~ema_sim.models.stages.oscillator_step`) is
    exact for the inputs held over the step and stable at any rate; computed once per run.

    Parameters
    ----------
    p : numpy.ndarray
        Kernel parameters.
    dt : float
        The fixed step (s).

    Returns
    -------
    numpy.ndarray
        ``(3, 6)``.
    """
    w0 = TWO_PI * p[P.linkage_freq_hz]
    damping = linkage_damping(p)
    steps = np.empty((3, 6))
    for piece in range(3):
        k = w0 * w0 * linkage_slope(p, piece)
        steps[piece, 0], steps[piece, 1], steps[piece, 2], steps[piece, 3], steps[piece, 4] = oscillator_step(
            k, damping, dt)
        steps[piece, 5] = k
    return steps


@jit
def linkage_step(p: FloatArray, y: FloatArray, hinge_moment_inlb: float, actuator_accel: float,
                 steps: FloatArray) -> tuple[float, float]:
    """Stage 17 over one fixed step: the deflection and its rate after it (deg, °/s).

    The segment the deflection starts on holds for the step, the hinge moment and the actuator's
    acceleration are held: its affine forcing ``f = ë + k·e + c·ė`` goes through the exact step.

    Parameters
    ----------
    p : numpy.ndarray
        Kernel parameters.
    y : numpy.ndarray
        State.
    hinge_moment_inlb : float
        Hinge moment (in·lb).
    actuator_accel : float
        The actuator's acceleration over the step (°/s²).
    steps : numpy.ndarray
        :func:`linkage_steps`.

    Returns
    -------
    deflection : float
        deg.
    rate : float
        °/s.
    """
    e, v = y[X.linkage_deg], y[X.linkage_rate_dps]
    _, piece = linkage_spring(p, e)
    s = steps[piece]
    f = linkage_accel(p, y, hinge_moment_inlb, actuator_accel) + s[5] * e + linkage_damping(p) * v
    return s[0] * e + s[1] * v + s[4] * f, s[2] * e + s[3] * v + s[1] * f


@jit
def linkage_rest(p: FloatArray, hinge_moment_inlb: float) -> float:
    """Stage 17 at rest under a held load: the deflection whose spring balances the compliance's.

    Parameters
    ----------
    p : numpy.ndarray
        Kernel parameters.
    hinge_moment_inlb : float
        Hinge moment (in·lb).

    Returns
    -------
    float
        The deflection (deg), pushed across the free play by the load.
    """
    return float(surface_compliance(p, hinge_moment_inlb) + 0.5 * p[P.free_play_deg] * np.sign(hinge_moment_inlb))
