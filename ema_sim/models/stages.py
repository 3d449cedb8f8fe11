"""The block-diagram elements every family shares, as small numba functions, one per named element.

Each family composes these in its own fixed pipeline (figure 26 in :mod:`ema_sim.models.second_order`,
figure 30 in :mod:`ema_sim.models.high_order`), the way JSBSim's actuator runs one fixed chain of
stages driven by configuration; the test environment (:mod:`ema_sim.environment`) steps the same
quantizer and lag. A stage whose parameter is zero is the identity, so a pipeline never changes
shape with its configuration. Every element here is written once and used everywhere it occurs.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import TypeVar

import numba as nb
import numpy as np
import numpy.typing as npt

from ema_sim.models.arrays import FloatArray
from ema_sim.models.compiling import ForwardCopiesCompiler, borrowing

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

_F = TypeVar("_F", bound=Callable[..., object])

jit = nb.njit(cache=True, inline="always")
"""Compile an element for inlining into the kernels (it takes the caller's floating-point flags)."""

def compile_closure(fn: _F, of: Callable[..., object] | str, *, parallel: bool = False, forward_copies: bool = False,
                    borrow: bool = False) -> _F:
    """Compile a kernel a factory made, cached under a name of its own (``qualname_of``).

    Numba names a cache file after the function's qualified name, which every closure of one factory
    shares: two processes compiling two of them at once (two nodes' first runs, two test workers)
    would write one index and one data file between them and load each other's machine code.

    Parameters
    ----------
    fn : callable
        The closure, as its factory defined it.
    of : callable or str
        What tells it from its siblings: the compiled function it closes over, or a name.
    parallel : bool
        Compile its ``prange`` loops as parallel threads.
    forward_copies : bool
        Compile it with :class:`~ema_sim.models.compiling.ForwardCopiesCompiler`: no reference counting of the
        array arguments it passes to inlined elements (:func:`~ema_sim.models.compiling.forward_array_copies`).
    borrow : bool
        Compile it without Numba's runtime (:func:`~ema_sim.models.compiling.borrowing`): a called element that
        only works in its caller's arrays.

    Returns
    -------
    numba dispatcher
        ``fn`` compiled and cached.
    """
    func: Callable[..., object] | str = getattr(of, "py_func", of)
    tag = f"{func.__module__.rsplit('.', 1)[-1]}_{func.__name__}" if callable(func) else str(of)
    fn.__qualname__ = f"{fn.__qualname__}_{tag}"
    if borrow:
        return borrowing(fn)
    if forward_copies:
        return nb.njit(cache=True, parallel=parallel, pipeline_class=ForwardCopiesCompiler)(fn)
    return nb.njit(cache=True, parallel=parallel)(fn)


@jit
def zoh_index(times: FloatArray, t: float, j: int) -> int:
    """Index of the latest breakpoint at or before ``t``, searching forward from ``j``.

    Parameters
    ----------
    times : numpy.ndarray
        Breakpoint times, increasing (s).
    t : float
        The time asked for (s).
    j : int
        Where to start searching (a breakpoint at or before ``t``).

    Returns
    -------
    int
        The breakpoint index.
    """
    n = times.shape[0]
    while j + 1 < n and times[j + 1] <= t + TIME_EPS_S:
        j += 1
    return j


@jit
def next_change(values: FloatArray, j: int) -> int:
    """Index of the first breakpoint after ``j`` whose value differs from breakpoint ``j``'s (the count if none).

    An integrator need not stop where a held input keeps its value.

    Parameters
    ----------
    values : numpy.ndarray
        The input at each breakpoint.
    j : int
        The breakpoint held now.

    Returns
    -------
    int
        The breakpoint index.
    """
    n = values.shape[0]
    k = j + 1
    while k < n and values[k] == values[j]:
        k += 1
    return k


@jit
def held_change(times: FloatArray, values: FloatArray, t: float, j: int, j_next: int) -> tuple[int, int]:
    """The breakpoint held at ``t`` (:func:`zoh_index` from ``j``) and the next that changes its value.

    Parameters
    ----------
    times : numpy.ndarray
        Breakpoint times, increasing (s).
    values : numpy.ndarray
        The input at each breakpoint.
    t : float
        Now (s).
    j : int
        The breakpoint held before (at or before ``t``).
    j_next : int
        The change ahead of ``j`` (:func:`next_change`; 0 when not known yet).

    Returns
    -------
    tuple of (int, int)
        The breakpoint held and the next change.
    """
    j = zoh_index(times, t, j)
    if j >= j_next:
        j_next = next_change(values, j)
    return j, j_next


@nb.njit(cache=True)
def held_indices(times: FloatArray, at: FloatArray) -> npt.NDArray[np.int64]:
    """The breakpoint each instant reads under a zero-order hold (:func:`zoh_index` for ascending instants).

    One merge over both arrays: a record's samples cost a few instructions each, not a binary search.

    Parameters
    ----------
    times : numpy.ndarray
        Breakpoint times, increasing (s).
    at : numpy.ndarray
        The instants, ascending (s).

    Returns
    -------
    numpy.ndarray
        Index of the latest breakpoint at or before each instant (0 before the first).
    """
    held = np.empty(at.shape[0], dtype=np.int64)
    j = 0
    for k in range(at.shape[0]):
        j = zoh_index(times, at[k], j)
        held[k] = j
    return held


@jit
def transport_delay(times: FloatArray, values: FloatArray, t: float, delay_s: float, j: int) -> tuple[float, int]:
    """Time delay: the zero-order-held input as it was ``delay_s`` ago.

    Parameters
    ----------
    times : numpy.ndarray
        Breakpoint times (s).
    values : numpy.ndarray
        The input at each breakpoint.
    t : float
        Now (s).
    delay_s : float
        The delay (s).
    j : int
        Where to start searching.

    Returns
    -------
    value : float
        The delayed input.
    index : int
        Its breakpoint (the next search's start).
    """
    j = zoh_index(times, t - delay_s, j)
    return values[j], j


@jit
def band_side(x: float, half_width: float) -> int:
    """Which side of the band ±half_width ``x`` is on: −1 below, 0 inside, +1 above.

    The one classification behind every symmetric switching element: a saturation's segment, a
    dead zone's side, a backlash's contact.

    Parameters
    ----------
    x : float
        The input.
    half_width : float
        Half width of the band (≥ 0).

    Returns
    -------
    int
        −1, 0 or +1.
    """
    if x > half_width:
        return 1
    if x < -half_width:
        return -1
    return 0


@jit
def quantize(u: float, step: float) -> float:
    """Mid-tread quantizer (D/A and A/D resolution); identity when ``step`` is 0.

    Parameters
    ----------
    u : float
        The input (a non-finite input passes through).
    step : float
        The resolution (0: off).

    Returns
    -------
    float
        ``step·floor(u/step + ½)``.
    """
    if step <= 0.0:
        return u
    return step * float(np.floor(u / step + 0.5))


@nb.njit(cache=True)
def quantize_array(u: FloatArray, step: float) -> FloatArray:
    """:func:`quantize` on every element of an array (the test environment's vector path).

    Parameters
    ----------
    u : numpy.ndarray
        The inputs (C-contiguous).
    step : float
        The resolution (0: off).

    Returns
    -------
    numpy.ndarray
        The quantized values, same shape.
    """
    out = np.empty_like(u)
    flat_in = u.ravel()
    flat_out = out.ravel()
    for j in range(flat_in.shape[0]):
        flat_out[j] = quantize(flat_in[j], step)
    return out


@jit
def lag_gain(corner_hz: float, dt: float) -> float:
    """Exact zero-order-hold gain of a first-order lag over ``dt``; 1 (pass-through) when off.

    Parameters
    ----------
    corner_hz : float
        Corner frequency (0: off).
    dt : float
        The step (s).

    Returns
    -------
    float
        ``1 − exp(−2π·f·dt)``.
    """
    if corner_hz <= 0.0:
        return 1.0
    return 1.0 - math.exp(-TWO_PI * corner_hz * dt)


@jit
def oscillator_step(stiffness: float, damping: float, dt: float) -> tuple[float, float, float, float, float]:
    """Exact zero-order-hold step of ``ë = −k·e − c·ė + f`` over ``dt`` with f held (k ≥ 0, c ≥ 0).

    ``e ← φ00·e + φ01·ė + γ0·f`` and ``ė ← φ10·e + φ11·ė + φ01·f``: the matrix exponential in closed
    form, stable at any step (an explicit Euler step of the same element diverges once ω·dt or c·dt
    nears 2).

    Parameters
    ----------
    stiffness : float
        k (1/s²).
    damping : float
        c (1/s).
    dt : float
        The step (s).

    Returns
    -------
    tuple of float
        ``(φ00, φ01, φ10, φ11, γ0)``.
    """
    mu = -0.5 * damping
    d2 = mu * mu - stiffness
    x2 = abs(d2) * dt * dt
    if x2 < 1e-6:  # (nearly) critical: the series of cosh/cos and sinh/sin about 0
        sign = 1.0 if d2 >= 0.0 else -1.0
        em = math.exp(mu * dt)
        c_t = em * (1.0 + sign * x2 / 2.0 + x2 * x2 / 24.0)
        s_t = em * dt * (1.0 + sign * x2 / 6.0 + x2 * x2 / 120.0)
    elif d2 > 0.0:  # real roots μ ± d ≤ 0: from their exponentials, so a heavy damper cannot overflow
        d = math.sqrt(d2)
        e1 = math.exp((mu + d) * dt)
        e2 = math.exp((mu - d) * dt)
        c_t = 0.5 * (e1 + e2)
        s_t = 0.5 * (e1 - e2) / d
    else:
        d = math.sqrt(-d2)
        em = math.exp(mu * dt)
        c_t = em * math.cos(d * dt)
        s_t = em * math.sin(d * dt) / d
    phi11 = c_t + mu * s_t
    if stiffness > 0.0:
        gamma0 = (1.0 - phi11 - damping * s_t) / stiffness
    elif damping > 0.0:
        gamma0 = (dt - s_t) / damping
    else:
        gamma0 = 0.5 * dt * dt
    return c_t - mu * s_t, s_t, -stiffness * s_t, phi11, gamma0


@jit
def first_order_lag(y: float, u: float, gain: float) -> float:
    """One step of a first-order lag ``y ← y + gain·(u − y)`` (see :func:`lag_gain`).

    Parameters
    ----------
    y : float
        The lag's output so far.
    u : float
        Its input over the step.
    gain : float
        :func:`lag_gain` of the step.

    Returns
    -------
    float
        The new output.
    """
    return y + gain * (u - y)


@jit
def dead_zone(e: float, half_width: float) -> tuple[float, int]:
    """Dead zone: zero inside ±half_width, shifted identity outside.

    Parameters
    ----------
    e : float
        The input.
    half_width : float
        Half width of the zone (≥ 0).

    Returns
    -------
    output : float
        The dead-zone output.
    side : int
        Which side of the zone the input is on (:func:`band_side`).
    """
    side = band_side(e, half_width)
    if side > 0:
        return e - half_width, side
    if side < 0:
        return e + half_width, side
    return 0.0, 0


@jit
def limited_integrator(x: float, v: float, lo: float, hi: float) -> tuple[float, float, int]:
    """Clamp a position state to [lo, hi] and stop its velocity at the stop (no wind-up).

    Parameters
    ----------
    x : float
        The position state.
    v : float
        Its velocity.
    lo, hi : float
        The stops.

    Returns
    -------
    x : float
        The clamped position.
    v : float
        The velocity, stopped at a stop.
    at_stop : int
        1 on a stop, else 0.
    """
    if x >= hi:
        return hi, min(v, 0.0), 1
    if x <= lo:
        return lo, max(v, 0.0), 1
    return x, v, 0


@jit
def euler_pair(x: float, v: float, a: float, dt: float, backward: bool) -> tuple[float, float]:
    """One Euler step of a double integrator ``ẋ = v, v̇ = a``.

    Forward: both take the values at the start of the step. Backward (flight 1's FORTRAN): the
    velocity first, then the position from the new velocity.

    Parameters
    ----------
    x : float
        Position.
    v : float
        Velocity.
    a : float
        Acceleration over the step.
    dt : float
        The step (s).
    backward : bool
        Backward rather than forward Euler.

    Returns
    -------
    x : float
        The new position.
    v : float
        The new velocity.
    """
    if backward:
        v += dt * a
        x += dt * v
        return x, v
    x += dt * v
    v += dt * a
    return x, v


__all__ = [
    "DEG2RAD", "FLAG_BRAKE", "FLAG_CURRENT", "FLAG_FREE_PLAY", "FLAG_POSITION", "FLAG_PWM_DEAD_BAND", "FLAG_RATE",
    "FLAG_STALL", "FLAG_THRESHOLD", "RAD2DEG", "TIME_EPS_S", "TWO_PI", "band_side", "dead_zone",
    "euler_pair", "first_order_lag", "held_change", "jit", "lag_gain", "limited_integrator", "next_change", "quantize",
    "quantize_array", "transport_delay", "zoh_index",
]
