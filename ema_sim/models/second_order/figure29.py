"""Figure 29: the free-play subsystem, hinge moment over surface inertia double-integrated in a limited integrator.

Pure free play (3.1.2.3): the surface floats ±width/2 about the actuator, driven by ``hm/Is``. The
discrete models step it by Euler (forward for LOADA, backward for LOADF), the identification
simulator solves it exactly, LOAC integrates :func:`free_play_accel` with its stops located.
"""

from __future__ import annotations

from ema_sim.models.arrays import FloatArray
from ema_sim.models.second_order.params import P, X
from ema_sim.models.stages import RAD2DEG, euler_pair, jit, limited_integrator


@jit
def free_play_accel(hinge_moment_inlb: float, inertia_inlbs2: float) -> float:
    """The subsystem's input: hinge moment over surface inertia, in °/s².

    Parameters
    ----------
    hinge_moment_inlb : float
        Hinge moment (in·lb).
    inertia_inlbs2 : float
        Surface inertia (in·lb·s²).

    Returns
    -------
    float
        Angular acceleration (°/s²).
    """
    return hinge_moment_inlb / inertia_inlbs2 * RAD2DEG


@jit
def free_play_euler(fp: float, v: float, accel: float, dt: float, half: float,
                    backward: bool) -> tuple[float, float]:
    """One Euler step of the limited double integrator (see :func:`ema_sim.models.stages.euler_pair`).

    Parameters
    ----------
    fp : float
        Free-play position (deg).
    v : float
        Its rate (°/s).
    accel : float
        :func:`free_play_accel` over the step.
    dt : float
        The step (s).
    half : float
        Half the free-play width (deg).
    backward : bool
        Backward Euler (LOADF) rather than forward (LOADA).

    Returns
    -------
    fp : float
        The new position, inside ±half.
    v : float
        The new rate, stopped at a limit.
    """
    fp, v = euler_pair(fp, v, accel, dt, backward)
    fp, v, _ = limited_integrator(fp, v, -half, half)
    return fp, v


@jit
def free_play_exact(p: FloatArray, y: FloatArray, hinge_moment_inlb: float, h: float) -> None:
    """The subsystem solved exactly over ``h`` with the hinge moment held, in place on ``y``.

    Exact except for an impact and rebound inside one step, which a held load cannot produce.

    Parameters
    ----------
    p : numpy.ndarray
        Kernel parameters (:data:`~ema_sim.models.second_order.params.P`).
    y : numpy.ndarray
        State (:data:`~ema_sim.models.second_order.params.X`); its free-play columns are advanced.
    hinge_moment_inlb : float
        Hinge moment over the step (in·lb).
    h : float
        The step (s).
    """
    half = 0.5 * p[P.free_play_deg]
    if half <= 0.0 or p[P.linkage_freq_hz] > 0.0:  # none, or the dead zone of a linkage mode's spring
        y[X.free_play_deg] = 0.0
        y[X.free_play_rate_dps] = 0.0
        return
    a = free_play_accel(hinge_moment_inlb, p[P.surface_inertia_inlbs2])
    fp = y[X.free_play_deg]
    v = y[X.free_play_rate_dps]
    if (fp >= half and a >= 0.0 and v >= 0.0) or (fp <= -half and a <= 0.0 and v <= 0.0):
        y[X.free_play_deg] = half if fp > 0.0 else -half
        y[X.free_play_rate_dps] = 0.0
        return
    fp += h * (v + 0.5 * a * h)
    v += a * h
    if fp >= half:
        fp = half
        v = 0.0
    elif fp <= -half:
        fp = -half
        v = 0.0
    y[X.free_play_deg] = fp
    y[X.free_play_rate_dps] = v
