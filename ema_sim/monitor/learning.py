"""A reference learned on a first window the user states is healthy: the fidelity that reproduces it best.

Candidates: the channel's second-order pipeline (figure 26) with ωn, ζ, delay and command bias fitted by
identification's output-error least squares (:func:`ema_sim.identify.fit.fit`), and each high-order physics
(HOAD2, HOAD3) with the parameters the monitor's fault candidates act on (friction, backlash, torque constant,
current limit, command delay, linkage stiffness) fitted on the window one at a time, by the isolation's own fit
(:func:`ema_sim.monitor.isolate.fit_candidate`), each kept when it pays two per parameter (Akaike). The one
whose residual varies least on the window's position and surface is kept (its centre does not count: the
monitor centres the residual on the healthy window).

A second order cannot reproduce a high-order actuator's step transients, and a CUSUM calibrated on its
residual's spread takes those recurring transients for a fault; a high-order model at the channel's values
cannot reproduce an actuator whose friction or delay differ from them, nor one behind another command path,
which the fitted second order learns.
"""

from __future__ import annotations

import numpy as np

from ema_sim.config import ChannelConfig
from ema_sim.errors import DataError
from ema_sim.identify.fit import fit
from ema_sim.identify.problem import Problem
from ema_sim.io.measured import MeasuredData
from ema_sim.models.second_order import SecondOrderParams
from ema_sim.monitor.isolate import OUTPUT_KINDS, Window, candidates, fit_candidate
from ema_sim.monitor.reference import LEARNED_FIELDS, Reference, held_inputs, predict, window

PHYSICS = ("hoad2", "hoad3")
"""The high-order models a learned reference may be."""
ROUNDS = 2
"""Passes over the physics' parameters (a parameter fitted first may move once the others have)."""
MIN_SPREAD = 1e-3
"""Floor on an output's residual spread in the fits' weights (deg, A)."""


def learn(data: MeasuredData, channel: ChannelConfig, healthy_s: float,
          physics: tuple[str, ...] = PHYSICS) -> Reference:
    """The model that best reproduces the first ``healthy_s`` seconds (module docstring).

    Parameters
    ----------
    data : MeasuredData
        The record.
    channel : ChannelConfig
        The channel.
    healthy_s : float
        The first seconds, stated healthy.
    physics : tuple of str
        The high-order candidates (none: the second order only).

    Returns
    -------
    Reference
        The kept candidate, its origin saying what was fitted.

    Raises
    ------
    DataError
        The record is shorter than 1.5 times the healthy window (too little would be left to watch).
    """
    t = data.time_s - data.time_s[0]
    if t[-1] < 1.5 * healthy_s:
        raise DataError(f"{data.source or 'data'}: {t[-1]:.1f} s of data leaves too little to watch after a "
                        f"{healthy_s:g} s healthy window (give --model, or a shorter --healthy-s)")
    first = window(data, 0.0, healthy_s)
    base = SecondOrderParams.from_channel(channel)
    result = fit(Problem(first, channel), base, LEARNED_FIELDS, max_nfev=60)
    values = {k: float(v) for k, v in result.params.as_dict().items()}
    text = ", ".join(f"{k}={values[k]:.4g}" for k in LEARNED_FIELDS)
    learned = Reference("second_order", channel, values,
                        f"the channel's second order with {text} learned on the first {healthy_s:g} s")
    scored = [(spread_on(first, learned), learned)]
    for name in physics:
        ref = refine(first, Reference(name, channel, {}, name))
        fitted = ", ".join(f"{k}={v:.4g}" for k, v in ref.overrides.items()) or "none moved from the channel's"
        ref = Reference(ref.model, channel, ref.overrides,
                        f"{name} with {fitted} learned on the first {healthy_s:g} s")
        scored.append((spread_on(first, ref), ref))
    return min(scored, key=lambda sr: sr[0])[1]


def spread_on(data: MeasuredData, reference: Reference) -> float:
    """The variance of the reference's residual on a record, summed over position and surface (deg²)."""
    pred = predict(reference.build(), data)
    cols = [(data.position_deg, 0), (data.surface_deg, 1)]
    return float(sum(np.var(c - pred[:, j]) for c, j in cols if c is not None))


def refine(data: MeasuredData, reference: Reference, rounds: int = ROUNDS) -> Reference:
    """A high-order reference with its fault candidates' parameters fitted on ``data`` one at a time.

    Each parameter the isolation would re-estimate after a fault is fitted from the whole record by the
    isolation's own fit, the others held, and kept when it lowers the weighted residual by more than two
    (Akaike); ``rounds`` passes. The weights are each output's residual spread at the start.

    Parameters
    ----------
    data : MeasuredData
        The healthy window.
    reference : Reference
        The starting reference (a high-order model).
    rounds : int
        Passes over the parameters.

    Returns
    -------
    Reference
        The reference with the kept values among its overrides.
    """
    present = (data.position_deg is not None, data.surface_deg is not None, data.current_a is not None)
    pred = predict(reference.build(), data)
    meas = [data.position_deg, data.surface_deg, data.current_a]
    sigma = tuple(max(float(np.std(m - pred[:, j])), MIN_SPREAD) if m is not None else 1.0
                  for j, m in enumerate(meas))
    end = float(data.time_s[-1] - data.time_s[0]) + 1e-9
    _, bp_u, bp_h = held_inputs(data)
    values = dict(reference.overrides)
    for _ in range(rounds):
        moved = False
        current = Reference(reference.model, reference.channel, values)
        model = current.build()
        model.trim(bp_u[0], bp_h[0])
        nominal = predict(current.build(), data)
        win = Window(data, model, 0.0, 0.0, end, nominal, sigma,
                     (present[0], present[1], present[2] and model.has_current))
        r0 = win.residual(nominal)
        cost = float(r0 @ r0)
        for cand in candidates(model, data):
            if cand.kind in OUTPUT_KINDS or not cand.free:
                continue
            e = fit_candidate(win, cand)
            if e.cost < cost - 2.0:
                values.update(cand.values(e.estimate))
                current = Reference(reference.model, reference.channel, values)
                model = current.build()
                model.trim(bp_u[0], bp_h[0])
                nominal = predict(current.build(), data)
                win = Window(data, model, 0.0, 0.0, end, nominal, sigma, win.outputs)
                cost = e.cost
                moved = True
        if not moved:
            break
    return Reference(reference.model, reference.channel, values, reference.origin)
