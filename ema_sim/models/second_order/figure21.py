"""Figure 21: the basic second-order model, with Lallman's rate limit on its velocity command (3.1.2.1).

``ẍ = 2ζωn·(sat(ωn/(2ζ)·(u − x)) − ẋ)``: unsaturated it is ωn²(u − x) − 2ζωn·ẋ; saturated the steady
rate is the limit ``rl + K2·hm/marm`` in the direction of motion. The velocity command and which side
of its limits it is on are written once here, so the dynamics and the RK4 integrator's switch
detection can never disagree.
"""

from __future__ import annotations

from ema_sim.models.stages import jit


@jit
def load_rate_limits(rl_dps: float, k2_dps_per_lb: float, hinge_moment_inlb: float,
                     marm_in: float) -> tuple[float, float]:
    """Rate limits with load (section 3.1.2.1): ``rl ± K2·hm/marm``, never below 0.

    A hinge moment aiding positive motion raises the positive limit and lowers the negative one.

    Parameters
    ----------
    rl_dps : float
        Unloaded rate limit (°/s).
    k2_dps_per_lb : float
        Slope of the limit with the load (°/s per lbf).
    hinge_moment_inlb : float
        Hinge moment (in·lb, positive aids positive deflection).
    marm_in : float
        Moment arm (in).

    Returns
    -------
    up : float
        Positive-direction limit (°/s).
    down : float
        Negative-direction magnitude (°/s).
    """
    f_lb = hinge_moment_inlb / marm_in
    up = rl_dps + k2_dps_per_lb * f_lb
    down = rl_dps - k2_dps_per_lb * f_lb
    return max(up, 0.0), max(down, 0.0)


@jit
def velocity_command(u: float, x: float, wn: float, zeta: float, up: float, down: float) -> tuple[float, int]:
    """The rate-limited velocity command ``sat(ωn/(2ζ)·(u − x))`` and the side of its limits.

    Parameters
    ----------
    u : float
        The position the loop drives to (deg).
    x : float
        The position (deg).
    wn : float
        Natural frequency (rad/s).
    zeta : float
        Damping ratio.
    up : float
        Positive rate limit (°/s).
    down : float
        Negative rate limit's magnitude (°/s).

    Returns
    -------
    command : float
        The velocity command (°/s).
    side : int
        +1 on the positive limit, −1 on the negative one, 0 between.
    """
    vc = wn / (2.0 * zeta) * (u - x)
    if vc > up:
        return up, 1
    if vc < -down:
        return -down, -1
    return vc, 0


@jit
def rate_loop(v_drive: float, v: float, wn: float, zeta: float) -> float:
    """Figure 21's rate loop: the acceleration ``2ζωn·(v_drive − v)`` that brings the rate to the demand.

    Parameters
    ----------
    v_drive : float
        The rate the drive delivers (the limited velocity command, with any load droop) (°/s).
    v : float
        The rate (°/s).
    wn : float
        Natural frequency (rad/s).
    zeta : float
        Damping ratio.

    Returns
    -------
    float
        The acceleration (°/s²).
    """
    return 2.0 * zeta * wn * (v_drive - v)


@jit
def second_order(u: float, x: float, v: float, wn: float, zeta: float, up: float,
                 down: float) -> tuple[float, int]:
    """Figure 21 with the rate limit on the velocity command: the acceleration and the limit's side.

    Parameters
    ----------
    u : float
        The position the loop drives to (deg).
    x : float
        The position (deg).
    v : float
        The rate (°/s).
    wn : float
        Natural frequency (rad/s).
    zeta : float
        Damping ratio.
    up : float
        Positive rate limit (°/s).
    down : float
        Negative rate limit's magnitude (°/s).

    Returns
    -------
    acceleration : float
        ``2ζωn·(command − v)`` (°/s²).
    side : int
        The velocity command's side of its limits (0: not limited).
    """
    vc, side = velocity_command(u, x, wn, zeta, up, down)
    return rate_loop(vc, v, wn, zeta), side
