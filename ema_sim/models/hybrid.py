"""Event-located integration of a switched (hybrid) continuous model on :func:`make_dopri5`.

A high-fidelity actuator switches between smooth regimes: a PWM inside or outside its dead band, a
motor stuck by stiction or slipping, gear teeth in contact or in their backlash, a saturated or a
linear velocity loop. The model's right-hand side takes the regime of every switching element from
its input vector ``u`` and is smooth as long as those regimes are held; *guards* ``g_k(y) ≥ 0`` say
that the state is still inside them. This driver lets the existing adaptive Dormand–Prince stepper
(:func:`ema_sim.models.integrate.make_dopri5`) take each step, checks the guards at its end, and when
one has changed sign re-integrates from the step's start to find the crossing by Illinois regula falsi
to ``EVENT_TIME_TOL``, lands just past it, applies the model's transition and carries on. Corners and
jumps are never stepped over, so the continuous reference converges with its tolerance.

The model supplies four numba functions:

* ``rhs(t, y, p, u, dydt)``   the regime-held right-hand side;
* ``guards(t, y, p, u, g)``   fills ``g`` (positive inside every held regime; ``inf`` for none);
* ``transition(k, t, y, p, u)`` what crossing guard ``k`` does (updates regimes in ``u``, may reset ``y``);
* ``settle(t, y, p, u)``      makes every regime consistent with the state (after inputs change).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from ema_sim.models.arrays import FloatArray
from ema_sim.models.integrate import Rhs, make_dopri5
from ema_sim.models.stages import compile_closure

Guards = Callable[[float, FloatArray, FloatArray, FloatArray, FloatArray], None]
Transition = Callable[[int, float, FloatArray, FloatArray, FloatArray], None]
Settle = Callable[[float, FloatArray, FloatArray, FloatArray], None]
Advance = Callable[[FloatArray, FloatArray, FloatArray, float, float, float, float, float, float], tuple[float, int]]
"""``advance(p, u, y, t, t_end, h, rtol, atol, h_max) -> (next h, events)``."""

EVENT_TIME_TOL = 1e-12
"""Seconds: how closely an event time is bracketed before the integrator lands just past it."""
MAX_LOCATE_ITERATIONS = 80
MAX_STALLED_EVENTS = 200
"""Events in a row that make no progress in time before the driver steps on regardless (chatter guard)."""


def make_hybrid(  # noqa: PLR0915 - one compiled loop
    rhs: Rhs,
    guards: Guards,
    transition: Transition,
    settle: Settle,
    n_guards: int,
) -> Advance:
    """A compiled ``advance(p, u, y, t, t_end, h, rtol, atol, h_max) -> (next h, events)`` for one model.

    Parameters
    ----------
    rhs : callable
        The regime-held right-hand side ``rhs(t, y, p, u, dydt)``.
    guards : callable
        ``guards(t, y, p, u, g)``: fills ``g`` with the distance of every held regime to its boundary.
    transition : callable
        ``transition(k, t, y, p, u)``: what crossing guard ``k`` does.
    settle : callable
        ``settle(t, y, p, u)``: makes every regime consistent with the state.
    n_guards : int
        Length of ``g``.

    Returns
    -------
    callable
        The compiled driver.
    """
    dopri5 = make_dopri5(rhs)

    def advance(p: FloatArray, u: FloatArray, y: FloatArray, t: float, t_end: float, h: float, rtol: float,  # noqa: PLR0912, PLR0915
                atol: float, h_max: float) -> tuple[float, int]:
        n = y.shape[0]
        y0 = np.empty(n)
        yt = np.empty(n)
        g0 = np.empty(n_guards)
        g1 = np.empty(n_guards)
        gt = np.empty(n_guards)
        no_limits = np.empty((0, 4))
        no_modes = np.zeros(0, dtype=np.int64)
        events = 0
        stalled = 0
        settle(t, y, p, u)
        h = min(h, h_max)
        while t_end - t > 1e-15 * max(1.0, abs(t_end)):
            te = t_end if h >= t_end - t else t + h
            step = te - t
            for i in range(n):
                y0[i] = y[i]
            guards(t, y0, p, u, g0)
            h_next, _ = dopri5(p, u, y, t, te, step, rtol, atol, h_max, no_limits, no_modes)
            guards(te, y, p, u, g1)
            k = -1
            best = 2.0
            for j in range(n_guards):
                if g0[j] >= 0.0 and g1[j] < 0.0:
                    frac = g0[j] / (g0[j] - g1[j])
                    if frac < best:
                        best = frac
                        k = j
            if k < 0:
                t = te
                h = h_next
                stalled = 0
                continue
            # Locate the first crossing in (0, step]: Illinois regula falsi on the guard that crosses
            # first, switching guard whenever another one turns out to cross earlier.
            lo = 0.0
            hi = step
            glo = g0[k]
            ghi = g1[k]
            side = 0
            for _ in range(MAX_LOCATE_ITERATIONS):
                if hi - lo <= EVENT_TIME_TOL:
                    break
                tau = (lo * ghi - hi * glo) / (ghi - glo)
                if not (lo < tau < hi):
                    tau = 0.5 * (lo + hi)
                for i in range(n):
                    yt[i] = y0[i]
                dopri5(p, u, yt, t, t + tau, tau, rtol, atol, h_max, no_limits, no_modes)
                guards(t + tau, yt, p, u, gt)
                earlier = -1
                best = 2.0
                for j in range(n_guards):
                    if j != k and g0[j] >= 0.0 and gt[j] < 0.0:
                        frac = g0[j] / (g0[j] - gt[j])
                        if frac < best:
                            best = frac
                            earlier = j
                if earlier >= 0:
                    k = earlier
                    hi = tau
                    ghi = gt[k]
                    lo = 0.0
                    glo = g0[k]
                    side = 0
                elif gt[k] < 0.0:
                    hi = tau
                    ghi = gt[k]
                    if side == -1:
                        glo *= 0.5
                    side = -1
                else:
                    lo = tau
                    glo = gt[k]
                    if side == 1:
                        ghi *= 0.5
                    side = 1
            for i in range(n):
                y[i] = y0[i]
            dopri5(p, u, y, t, t + hi, hi, rtol, atol, h_max, no_limits, no_modes)
            t = t + hi
            transition(k, t, y, p, u)
            settle(t, y, p, u)
            events += 1
            stalled = stalled + 1 if hi <= 10.0 * EVENT_TIME_TOL else 0
            if stalled > MAX_STALLED_EVENTS:
                # A regime boundary the model keeps re-entering (a sliding mode): step over it once.
                te = min(t_end, t + 1e-9)
                dopri5(p, u, y, t, te, te - t, rtol, atol, h_max, no_limits, no_modes)
                t = te
                settle(t, y, p, u)
                stalled = 0
            h = max(min(h_next, h_max), 1e-12)
        return h, events

    compiled: Advance = compile_closure(advance, rhs, forward_copies=True)
    return compiled
