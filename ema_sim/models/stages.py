"""The elements of the report's block diagrams as small numba functions, one per named stage.

Every model family composes these in its own fixed pipeline (figure 26 for the second-order family,
figures 30, 32, 33 and 36 for the high-order family), the way JSBSim's actuator runs one fixed chain
of stages driven by configuration. A stage whose parameter is zero is the identity, so a family's
pipeline never changes shape with its configuration.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

RAD2DEG = 180.0 / math.pi
DEG2RAD = math.pi / 180.0
TWO_PI = 2.0 * math.pi
TIME_EPS_S = 1e-9
"""Times closer than this are the same instant (breakpoints, samples and steps meet on it)."""

# Limit flags every model reports with each sample (bit values; see ema_sim.models.base.Flags).
FLAG_RATE = 1
FLAG_POSITION = 2
FLAG_FREE_PLAY = 4
FLAG_THRESHOLD = 8
FLAG_CURRENT = 16
FLAG_PWM_DEAD_BAND = 32
FLAG_BRAKE = 64
FLAG_STALL = 128

jit = nb.njit(cache=True, inline="always")


@jit
def zoh_index(times: np.ndarray, t: float, j: int) -> int:
    """Index of the latest breakpoint at or before ``t``, searching forward from ``j``."""
    n = times.shape[0]
    while j + 1 < n and times[j + 1] <= t + TIME_EPS_S:
        j += 1
    return j


@jit
def transport_delay(times: np.ndarray, values: np.ndarray, t: float, delay_s: float, j: int) -> tuple:
    """Time delay: the zero-order-held input as it was ``delay_s`` ago; returns (value, index)."""
    j = zoh_index(times, t - delay_s, j)
    return values[j], j


@jit
def command_error(u: float, kb: float, offset_deg: float) -> float:
    """Command error of section 3.1.2.2: ``(1 + Kb)·u + offset``."""
    return (1.0 + kb) * u + offset_deg


@jit
def quantize(u: float, step: float) -> float:
    """Mid-tread quantizer (D/A resolution); identity when ``step`` is 0."""
    if step <= 0.0:
        return u
    return step * math.floor(u / step + 0.5)


@jit
def lag_gain(corner_hz: float, dt: float) -> float:
    """Exact zero-order-hold gain of a first-order lag over ``dt``; 1 (pass-through) when off."""
    if corner_hz <= 0.0:
        return 1.0
    return 1.0 - math.exp(-TWO_PI * corner_hz * dt)


@jit
def first_order_lag(y: float, u: float, gain: float) -> float:
    """One step of a first-order lag ``y ← y + gain·(u − y)`` (see :func:`lag_gain`)."""
    return y + gain * (u - y)


@jit
def compliance_correction(u: float, hinge_moment_inlb: float, kcp_per_kinlb: float) -> float:
    """Compliance correction gain K_CP of section 3.1.2.4 on the command.

    ``K_CP = 1 + kcp·(aiding load)/1000``: a hinge moment that aids the commanded direction raises
    the gain, an opposing one lowers it.
    """
    if kcp_per_kinlb == 0.0 or u == 0.0:
        return u
    aiding = hinge_moment_inlb if u > 0.0 else -hinge_moment_inlb
    return u * (1.0 + kcp_per_kinlb * aiding * 1e-3)


@jit
def dead_zone(e: float, half_width: float) -> float:
    """Dead zone: zero inside ±half_width, shifted identity outside."""
    if e > half_width:
        return e - half_width
    if e < -half_width:
        return e + half_width
    return 0.0


@jit
def load_rate_limits(rl_dps: float, k2_dps_per_lb: float, hinge_moment_inlb: float, marm_in: float) -> tuple:
    """Rate limits with load (section 3.1.2.1): ``rl + K2·hm/marm`` in each direction, never below 0.

    A hinge moment aiding positive motion raises the positive limit and lowers the negative one.
    Returns (positive limit, negative-direction magnitude).
    """
    f_lb = hinge_moment_inlb / marm_in
    up = rl_dps + k2_dps_per_lb * f_lb
    down = rl_dps - k2_dps_per_lb * f_lb
    return max(up, 0.0), max(down, 0.0)


@jit
def rate_limited_second_order(
    u: float, x: float, v: float, wn: float, zeta: float, up: float, down: float
) -> tuple:
    """Basic second order (figure 21) with the rate limit on the velocity command (Lallman form).

    ``ẍ = 2ζωn·(sat(ωn/(2ζ)·(u − x)) − ẋ)``: unsaturated it is ωn²(u − x) − 2ζωn·ẋ; saturated the
    steady rate is the limit. Returns (acceleration, rate-limited flag).
    """
    vc = wn / (2.0 * zeta) * (u - x)
    limited = 0
    if vc > up:
        vc = up
        limited = 1
    elif vc < -down:
        vc = -down
        limited = 1
    return 2.0 * zeta * wn * (vc - v), limited


@jit
def limited_integrator(x: float, v: float, lo: float, hi: float) -> tuple:
    """Clamp a position state to [lo, hi] and stop its velocity at the stop (no wind-up).

    Returns (x, v, at-stop flag).
    """
    if x >= hi:
        return hi, min(v, 0.0), 1
    if x <= lo:
        return lo, max(v, 0.0), 1
    return x, v, 0


@jit
def free_play_accel(hinge_moment_inlb: float, inertia_inlbs2: float) -> float:
    """Free play subsystem input (figure 29): hinge moment over surface inertia, in deg/s²."""
    return hinge_moment_inlb / inertia_inlbs2 * RAD2DEG


@jit
def compliance_deflection(hinge_moment_inlb: float, deg_per_kinlb: float) -> float:
    """Surface deflection outside the servo loop, linear in hinge moment (deg)."""
    return deg_per_kinlb * hinge_moment_inlb * 1e-3
