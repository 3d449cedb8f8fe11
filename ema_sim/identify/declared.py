"""The declared starting model: which second-order stages it has and which of its parameters are fitted.

Every fidelity can be declared. The second-order family (``second_order``, ``loac``, ``loada``,
``loadf``, ``sloac``) is fitted as it is. A high-order or linear model (``hoac1``, ``hoad2``,
``hoad3``, ``hoalm``, ``loes``) is translated into the second-order family's installed-actuator stages
(figure 26: delays, the in-loop LVDT filter, rate and current limits, servo integral, free play,
linear or figure-33 compliance) from its own parameters; those stages are what a position and
surface record can determine and what is fitted. The model's other parameters (motor, bus, PWM,
friction, gains: everything the servo's ωn and ζ lump together) are listed as not determinable by the
record (:func:`not_determinable`), and the declared model itself is run on the record
(:func:`run_declared`) so the report gives the error as declared, before anything is fitted.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from ema_sim.config import ChannelConfig
from ema_sim.errors import UnknownNameError
from ema_sim.identify.effects import FREE
from ema_sim.models import create, model_parameters
from ema_sim.models.arrays import FloatArray
from ema_sim.models.high_order.figure30 import total_deflection
from ema_sim.models.high_order.linear import linearize
from ema_sim.models.high_order.params import HighOrderParams, P
from ema_sim.models.second_order import SecondOrderParams
from ema_sim.parameters import metas

if TYPE_CHECKING:  # a type only: ema_sim.models.linear imports python-control (1.2 s)
    from ema_sim.models.linear import LoesParams

SECOND_ORDER = ("second_order", "loac", "loada", "loadf", "sloac")
"""The second-order family, fitted with its accurate simulator."""
HIGH_ORDER = ("hoac1", "hoad2", "hoad3", "hoalm", "loes")
"""Models declared through their second-order-family equivalent (module docstring)."""
DECLARED = (*SECOND_ORDER, *HIGH_ORDER)
"""Models identification can start from."""

COMPANION = {
    "velocity_loop_hz": "accel_limit_dps2",
    "linkage_zeta": "linkage_freq_hz",
    "compliance_stiff_deg_per_kinlb": "compliance_knee_inlb",
    "lvdt_compliance_stiff_deg_per_kinlb": "lvdt_compliance_knee_inlb",
}
"""A parameter that means something only with another stage on: the stage that switches it."""

CARRIED = {
    "hoac1": ("lvdt_filter_hz", "rate_limit_in_s", "current_limit_a", "position_integral_per_s2", "gear_backlash_in",
              "gear_stiffness_lbf_per_in", "backup_stiffness_lbf_per_in", "crank_arm_in", "position_min_deg",
              "position_max_deg", "command_delay_s", "feedback_delay_s"),
    "figure33": ("total_breakpoints_lbf", "total_mean_stiffness_lbf_per_in", "actuator_breakpoints_lbf",
                 "actuator_mean_stiffness_lbf_per_in"),
    "loes": ("wn_rad_s", "zeta", "delay_s", "dc_gain_ratio"),
}
"""The declared model's parameters its second-order-family equivalent carries (the rest: ωn and ζ lump
them, or the record cannot tell them)."""


def declared(model: str, channel: ChannelConfig, overrides: dict[str, float],
             peak_load_inlb: float = 1000.0) -> tuple[SecondOrderParams, list[str]]:
    """Starting parameters and the names of the model's own fitted parameters.

    ``second_order`` is the basic model of figure 21 (ωn, ζ); overrides switch more stages on and
    make them the model's own. ``loac``/``loada``/``loadf`` start from the channel's configuration
    and fit ωn, ζ and every continuous element it has on; quantization and the load terms stay as
    configured. ``sloac`` is the second order with its delay. A high-order or linear model starts
    from its equivalent (:func:`equivalent`, figure 33's curve read up to ``peak_load_inlb``). The
    discrete models' integrators are not part of the physics: they are simulated accurately (their
    own discretization error is reported separately).

    Parameters
    ----------
    model : str
        One of :data:`DECLARED`.
    channel : ChannelConfig
        The channel.
    overrides : dict
        Stages declared on top (model parameter → value).
    peak_load_inlb : float
        The record's largest hinge moment (where a figure-33 curve's stiffening is read).

    Returns
    -------
    tuple
        The parameters and the fitted parameters' names.
    """
    key = model.strip().lower()
    if key not in DECLARED:
        raise UnknownNameError("declared model for identification", model, DECLARED)
    if key == "second_order":
        params = SecondOrderParams.basic(channel, **overrides)
    elif key == "sloac":
        cfg = SecondOrderParams.from_channel(channel)
        params = SecondOrderParams.basic(channel, delay_s=cfg.delay_s, **overrides)
    elif key in HIGH_ORDER:
        params = SecondOrderParams.basic(channel, **{**equivalent(key, channel, peak_load_inlb), **overrides})
    else:
        params = SecondOrderParams.from_channel(channel, **overrides)
    free = ["wn_rad_s", "zeta"]
    info = metas(SecondOrderParams)
    for name in FREE:
        switch = COMPANION.get(name, name)
        if name not in free and getattr(params, switch) != info[switch].off:
            free.append(name)
    return params, free


def _two_slopes(deflection_deg: FloatArray, load_inlb: FloatArray) -> dict[str, float]:
    """A stiffening curve as the nonlinear compliance's (c below the knee, stiff above, knee where they meet)."""
    c = float(deflection_deg[1] / load_inlb[1]) * 1e3
    stiff = float((deflection_deg[-1] - deflection_deg[-2]) / (load_inlb[-1] - load_inlb[-2])) * 1e3
    if c <= 0.0 or abs(stiff - c) < 0.1 * c:
        return {"compliance_deg_per_kinlb": max(float(deflection_deg[-1] / load_inlb[-1]) * 1e3, 0.0)}
    knee = (float(deflection_deg[-1]) * 1e3 - stiff * float(load_inlb[-1])) / (c - stiff)
    return {"compliance_deg_per_kinlb": c, "compliance_knee_inlb": float(np.clip(knee, 1.0, 1e5)),
            "compliance_stiff_deg_per_kinlb": max(stiff, 0.0)}


def equivalent(model: str, channel: ChannelConfig, peak_load_inlb: float = 1000.0) -> dict[str, float]:
    """The second-order-family stages (model parameter → value) of a high-order or linear model.

    From the model's own parameters: its command and feedback delays, the LVDT filter closed inside
    the loop, the slew limit and the current limit (as the acceleration the limited current gives the
    actuator and surface masses), the position loop's integral corner Ki/Kp, the gear backlash as free
    play, and the linkage's compliance: figure 32's series stiffness (HOAC1, HOAD2), figure 33's total
    curve as a knee and two slopes up to ``peak_load_inlb`` (HOAD3), its slope at zero load (HOALM).
    LOES is its own second order, delay and gain. ωn and ζ start at the channel's second-order values.

    Parameters
    ----------
    model : str
        One of :data:`HIGH_ORDER`.
    channel : ChannelConfig
        The channel.
    peak_load_inlb : float
        Where figure 33's curve is read up to (in·lb).

    Returns
    -------
    dict
        Model parameter → value.
    """
    if model == "loes":
        loes: LoesParams = getattr(create("loes", channel.channel), "params")  # noqa: B009 - Loes has them
        return {"wn_rad_s": loes.wn_rad_s, "zeta": loes.zeta, "delay_s": loes.delay_s, "kb": loes.dc_gain_ratio - 1.0}
    h = HighOrderParams.from_channel(channel, "hoad3" if model == "hoalm" else model)
    cfg = SecondOrderParams.from_channel(channel)
    dpi, arm = h.deg_per_in, h.crank_arm_in
    out: dict[str, float] = {
        "wn_rad_s": cfg.wn_rad_s, "zeta": cfg.zeta, "feedback_filter_in_loop": 1.0,
        "delay_s": h.command_delay_s, "feedback_delay_s": h.feedback_delay_s,
    }
    corner = h.position_integral_per_s2 / h.position_gain_per_s / (2.0 * math.pi)
    if corner > 0.0:
        out["integral_hz"] = corner
    per_kinlb = 1000.0 / arm * dpi  # deg per 1000 in·lb for 1 in/lbf
    if model == "hoalm":
        lin = linearize(h, 0.0)
        return {**out, "compliance_deg_per_kinlb": per_kinlb / lin.total_stiffness_lbf_per_in}
    out["rate_limit_dps"] = h.rate_limit_in_s * dpi
    out["accel_limit_dps2"] = h.force_per_amp_lbf * h.current_limit_a / (
        h.motor_mass_lbs2_per_in + h.surface_mass_lbs2_per_in) * dpi
    if h.gear_backlash_in > 0.0:
        out["free_play_deg"] = h.gear_backlash_in * dpi
    if model == "hoad3":
        v = h.kernel_vector(figure33=True, bound=0.0, hysteresis=False, noise=False)
        load = np.linspace(0.0, max(peak_load_inlb, 100.0), 41)
        deflection = np.array([total_deflection(v, m / v[P.crank_arm_in]) for m in load]) * dpi
        return {**out, **_two_slopes(deflection, load)}
    lin = linearize(h, 0.0, figure33=False)
    return {**out, "compliance_deg_per_kinlb": per_kinlb / lin.total_stiffness_lbf_per_in}


def not_determinable(model: str, channel: ChannelConfig) -> list[str]:
    """The declared model's parameters its equivalent does not carry: lumped into ωn and ζ, or not seen.

    Parameters
    ----------
    model : str
        One of :data:`HIGH_ORDER`.
    channel : ChannelConfig
        The channel.

    Returns
    -------
    list of str
        Parameter names, in the model's declaration order.
    """
    key = model.strip().lower()
    carried = set(CARRIED["loes"] if key == "loes" else CARRIED["hoac1"])
    if key in ("hoad3", "hoalm"):
        carried |= set(CARRIED["figure33"])
    if key == "loes":
        carried |= {"fit_min_hz", "fit_max_hz", "dwell_amp_deg"}  # the fit's settings, not the model
    return [p.name for p in model_parameters(key, channel) if p.name not in carried]


def run_declared(model: str, channel: ChannelConfig, time_s: FloatArray, command_deg: FloatArray,
                 hinge_moment_inlb: FloatArray, overrides: dict[str, object] | None = None,
                 sample_times: FloatArray | None = None) -> FloatArray:
    """The declared model itself (noise off) on the record's inputs: ``(samples, outputs)``, position then surface.

    Parameters
    ----------
    model : str
        A registry model name.
    channel : ChannelConfig
        The channel (its travel as the record set it).
    time_s, command_deg, hinge_moment_inlb : numpy.ndarray
        The inputs' breakpoints (s, from 0), command and hinge moment, held between breakpoints.
    overrides : dict, optional
        Model parameters other than declared (name → value in the model's units).
    sample_times : numpy.ndarray, optional
        Where the outputs are read (s; default: ``time_s``).

    Returns
    -------
    numpy.ndarray
        The outputs at the record's samples.
    """
    options: dict[str, object] = {"noise": False} if model in ("hoad2", "hoad3") else {}
    m = create(model, channel, **{**options, **(overrides or {})})
    m.trim(float(command_deg[0]), float(hinge_moment_inlb[0]))
    samples = time_s if sample_times is None else sample_times
    return np.asarray(m.run_outputs(time_s, command_deg, hinge_moment_inlb, sample_times=samples,
                                    end_s=float(samples[-1]))[0], dtype=float)
