"""Adaptive Dormand–Prince 5(4) integration for the continuous models (LOAC, HOAC1).

The continuous models are the references the discrete ones are judged against (table 6, figure 40),
so they integrate at a tight tolerance and *locate* the instants where a limited integrator reaches
its stop instead of stepping over them. Inputs are piecewise constant: callers integrate from one
input breakpoint to the next, which keeps the right-hand side smooth inside every call.

A limited state ``s`` with velocity state ``w`` (or ``w = -1`` for a first-order state) is described
by a row ``[s, w, lo, hi]`` of ``limits``; ``mode`` holds 0 (free), +1 (on the upper stop), −1 (on
the lower stop) or 2 (fixed, ``lo == hi``). On a stop both derivatives are held at zero until the
free acceleration points back inside.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from ema_sim.models.arrays import FloatArray, IntArray
from ema_sim.models.stages import compile_closure

Rhs = Callable[[float, FloatArray, FloatArray, FloatArray, FloatArray], None]
"""A right-hand side ``rhs(t, y, p, u, dydt)``: fills ``dydt`` for state ``y``, parameters ``p``, inputs ``u``."""
Stepper = Callable[[FloatArray, FloatArray, FloatArray, float, float, float, float, float, float, FloatArray,
                    IntArray], tuple[float, int]]
"""``dopri5(p, u, y, t, t_end, h, rtol, atol, h_max, limits, mode) -> (next h, steps)``."""

# Dormand–Prince 5(4) tableau.
C2, C3, C4, C5 = 1.0 / 5.0, 3.0 / 10.0, 4.0 / 5.0, 8.0 / 9.0
A21 = 1.0 / 5.0
A31, A32 = 3.0 / 40.0, 9.0 / 40.0
A41, A42, A43 = 44.0 / 45.0, -56.0 / 15.0, 32.0 / 9.0
A51, A52, A53, A54 = 19372.0 / 6561.0, -25360.0 / 2187.0, 64448.0 / 6561.0, -212.0 / 729.0
A61, A62, A63, A64, A65 = 9017.0 / 3168.0, -355.0 / 33.0, 46732.0 / 5247.0, 49.0 / 176.0, -5103.0 / 18656.0
B1, B3, B4, B5, B6 = 35.0 / 384.0, 500.0 / 1113.0, 125.0 / 192.0, -2187.0 / 6784.0, 11.0 / 84.0
E1, E3, E4, E5, E6, E7 = (
    71.0 / 57600.0, -71.0 / 16695.0, 71.0 / 1920.0, -17253.0 / 339200.0, 22.0 / 525.0, -1.0 / 40.0
)

EVENT_TOL = 1e-10
"""How far past a stop (state units) a located event may land before it is clamped onto it."""
MAX_EVENT_ITERATIONS = 12


def make_dopri5(rhs: Rhs) -> Stepper:  # noqa: PLR0915
    """A compiled Dormand–Prince stepper for one right-hand side ``rhs(t, y, p, u, dydt)``.

    The stepper is a closure over ``rhs`` rather than taking it as an argument, so numba can cache
    it (a function passed as a value is a run-time pointer and defeats the cache).

    Parameters
    ----------
    rhs : callable
        The compiled right-hand side ``rhs(t, y, p, u, dydt)``.

    Returns
    -------
    callable
        ``dopri5(p, u, y, t, t_end, h, rtol, atol, h_max, limits, mode) -> (next h, steps)``.
    """

    def _masked(t: float, y: FloatArray, p: FloatArray, u: FloatArray, limits: FloatArray, mode: IntArray,
                dydt: FloatArray) -> None:
        rhs(t, y, p, u, dydt)
        for k in range(limits.shape[0]):
            if mode[k] != 0:
                dydt[int(limits[k, 0])] = 0.0
                w = int(limits[k, 1])
                if w >= 0:
                    dydt[w] = 0.0

    def release_stops(t: float, y: FloatArray, p: FloatArray, u: FloatArray, limits: FloatArray, mode: IntArray,
                      dydt: FloatArray) -> None:
        """Free every limited state whose free acceleration points back inside its range."""
        any_stop = False
        for k in range(limits.shape[0]):
            if mode[k] == 1 or mode[k] == -1:
                any_stop = True
        if not any_stop:
            return
        rhs(t, y, p, u, dydt)
        for k in range(limits.shape[0]):
            if mode[k] == 1 or mode[k] == -1:
                w = int(limits[k, 1])
                d = dydt[w] if w >= 0 else dydt[int(limits[k, 0])]
                if d * mode[k] < 0.0:
                    mode[k] = 0

    def dopri5(p: FloatArray, u: FloatArray, y: FloatArray, t: float, t_end: float, h: float, rtol: float,  # noqa: PLR0912, PLR0915
               atol: float, h_max: float, limits: FloatArray, mode: IntArray) -> tuple[float, int]:
        """Integrate ``y`` from ``t`` to ``t_end`` with inputs ``u`` held; returns (next h, steps taken).

        ``h`` is the step to try first (carried between calls); the returned step is the controller's
        proposal for the next call, not shortened by ``t_end``.
        """
        n = y.shape[0]
        k1 = np.empty(n)
        k2 = np.empty(n)
        k3 = np.empty(n)
        k4 = np.empty(n)
        k5 = np.empty(n)
        k6 = np.empty(n)
        k7 = np.empty(n)
        yt = np.empty(n)
        y5 = np.empty(n)
        steps = 0
        h_prop = min(h, h_max)
        while t_end - t > 1e-15 * max(1.0, abs(t_end)):
            release(t, y, p, u, limits, mode, k1)
            masked(t, y, p, u, limits, mode, k1)
            h_try = h_prop
            clipped = h_try > t_end - t
            if clipped:
                h_try = t_end - t
            events = 0
            while True:
                hh = h_try
                for i in range(n):
                    yt[i] = y[i] + hh * A21 * k1[i]
                masked(t + C2 * hh, yt, p, u, limits, mode, k2)
                for i in range(n):
                    yt[i] = y[i] + hh * (A31 * k1[i] + A32 * k2[i])
                masked(t + C3 * hh, yt, p, u, limits, mode, k3)
                for i in range(n):
                    yt[i] = y[i] + hh * (A41 * k1[i] + A42 * k2[i] + A43 * k3[i])
                masked(t + C4 * hh, yt, p, u, limits, mode, k4)
                for i in range(n):
                    yt[i] = y[i] + hh * (A51 * k1[i] + A52 * k2[i] + A53 * k3[i] + A54 * k4[i])
                masked(t + C5 * hh, yt, p, u, limits, mode, k5)
                for i in range(n):
                    yt[i] = y[i] + hh * (A61 * k1[i] + A62 * k2[i] + A63 * k3[i] + A64 * k4[i] + A65 * k5[i])
                masked(t + hh, yt, p, u, limits, mode, k6)
                for i in range(n):
                    y5[i] = y[i] + hh * (B1 * k1[i] + B3 * k3[i] + B4 * k4[i] + B5 * k5[i] + B6 * k6[i])
                masked(t + hh, y5, p, u, limits, mode, k7)
                err = 0.0
                for i in range(n):
                    e = hh * (E1 * k1[i] + E3 * k3[i] + E4 * k4[i] + E5 * k5[i] + E6 * k6[i] + E7 * k7[i])
                    sc = atol + rtol * max(abs(y[i]), abs(y5[i]))
                    err += (e / sc) ** 2
                err = (err / n) ** 0.5
                if err > 1.0:
                    h_try = hh * max(0.2, 0.9 * err ** -0.2)
                    h_prop = h_try
                    clipped = False
                    continue
                # Accepted by the error test: does a free limited state pass its stop inside the step?
                theta = 2.0
                hit = -1
                for k in range(limits.shape[0]):
                    if mode[k] != 0:
                        continue
                    s = int(limits[k, 0])
                    lo = limits[k, 2]
                    hi = limits[k, 3]
                    if y5[s] > hi and y[s] <= hi:
                        th = (hi - y[s]) / (y5[s] - y[s])
                    elif y5[s] < lo and y[s] >= lo:
                        th = (lo - y[s]) / (y5[s] - y[s])
                    else:
                        continue
                    over = max(y5[s] - hi, lo - y5[s])
                    if over <= EVENT_TOL or events >= MAX_EVENT_ITERATIONS:
                        th = 1.0  # landed on the stop: clamp below
                    if th < theta:
                        theta = th
                        hit = k
                if hit >= 0 and theta < 1.0:
                    events += 1
                    h_try = hh * max(theta * (1.0 + 1e-7), 1e-12)
                    continue
                break
            for i in range(n):
                y[i] = y5[i]
            t += hh
            steps += 1
            for k in range(limits.shape[0]):
                s = int(limits[k, 0])
                w = int(limits[k, 1])
                if mode[k] == 0 and y[s] >= limits[k, 3]:
                    y[s] = limits[k, 3]
                    mode[k] = 1
                    if w >= 0 and y[w] > 0.0:
                        y[w] = 0.0
                elif mode[k] == 0 and y[s] <= limits[k, 2]:
                    y[s] = limits[k, 2]
                    mode[k] = -1
                    if w >= 0 and y[w] < 0.0:
                        y[w] = 0.0
            if not clipped and events == 0:
                h_prop = min(h_max, hh * min(5.0, max(0.2, 0.9 * max(err, 1e-10) ** -0.2)))
        return h_prop, steps

    masked = compile_closure(_masked, rhs, borrow=True)
    release = compile_closure(release_stops, rhs, borrow=True)
    stepper: Stepper = compile_closure(dopri5, rhs, forward_copies=True)
    return stepper
