"""The effects vocabulary of ``../shared/data-contract.md`` as model stages the fits can switch on.

Each :class:`Effect` names the second-order stage that carries it, the parameter in the contract's
vocabulary, its physical range, the probe values that draw its signature in a residual, and the
check that says whether a fitted value means something physical. An effect is only a candidate
where the record can show it (free play needs a reversing load and a surface sensor, ...).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from ema_sim.identify.problem import Problem
from ema_sim.models.second_order import SecondOrderParams
from ema_sim.parameters import metas


@dataclass(frozen=True)
class Free:
    """A fitted model parameter: bounds and whether it is fitted on a log scale."""

    field: str
    low: float
    high: float
    log: bool = False
    scale: float = 1.0
    """Typical size, so every fitted coordinate is of order one."""

    def to_x(self, value: float) -> float:
        """Model value → optimiser coordinate."""
        value = min(max(value, self.low), self.high)
        return math.log(value / self.scale) if self.log else value / self.scale

    def from_x(self, x: float) -> float:
        """Optimiser coordinate → model value."""
        return self.scale * math.exp(x) if self.log else self.scale * x

    def x_bounds(self) -> tuple[float, float]:
        """Bounds in optimiser coordinates."""
        return self.to_x(self.low), self.to_x(self.high)

    def derivative(self, value: float) -> float:
        """d(value)/dx, to carry covariances from x to physical units."""
        return value if self.log else self.scale


def _free(name: str, *, log: bool = False, scale: float = 1.0) -> Free:
    """A fitted parameter whose bounds are its declared range (:mod:`ema_sim.models.second_order.params`)."""
    m = metas(SecondOrderParams)[name]
    return Free(name, m.min, m.max, log=log, scale=scale)


# Every continuously fitted parameter of the second-order family; bounds from the parameter metadata.
FREE: dict[str, Free] = {
    f.field: f
    for f in (
        _free("wn_rad_s", log=True, scale=60.0),
        _free("zeta", log=True, scale=0.7),
        _free("delay_s", scale=0.01),
        _free("command_lag_hz", log=True, scale=20.0),
        _free("feedback_lag_hz", log=True, scale=20.0),
        _free("kb", scale=0.01),
        _free("offset_deg", scale=0.05),
        _free("rate_limit_dps", log=True, scale=100.0),
        _free("threshold_deg", scale=0.05),
        _free("free_play_deg", scale=0.1),
        _free("compliance_deg_per_kinlb", scale=0.2),
        _free("lvdt_compliance_deg_per_kinlb", scale=0.1),
        _free("hysteresis_h_lb_per_in", log=True, scale=3000.0),
    )
}

HM_FIELDS = ("compliance_deg_per_kinlb", "lvdt_compliance_deg_per_kinlb", "free_play_deg",
             "hysteresis_h_lb_per_in", "kcp_per_kinlb")
"""Model parameters through which the hinge moment acts (what hinge_moment_sign can be seen in)."""


OFF = 1e-9
"""A parameter this close to zero is off (a fit pinned on a zero bound lands a hair above it)."""


def hinge_moment_active(p: SecondOrderParams) -> bool:
    """True when the model's outputs depend on the sign of the hinge moment."""
    loads = any(abs(getattr(p, f)) > OFF for f in HM_FIELDS)
    return loads or (p.k2_dps_per_lb > 0.0 and math.isfinite(p.rate_limit_dps))


@dataclass(frozen=True)
class Context:
    """What the current model does on the record (for probe values and checks)."""

    problem: Problem
    params: SecondOrderParams
    max_rate_dps: float
    declared: SecondOrderParams
    """The declared model's starting values (a restart point for effects that distort a fit)."""
    quantization_steps: list[tuple[float, float]] = field(default_factory=list)
    """(step, offset correction) pairs whose quantization error best explains the residual, best first."""


@dataclass(frozen=True)
class Effect:
    """One vocabulary effect realised as a stage of the second-order model."""

    name: str
    """Vocabulary name (data contract)."""
    where: str
    """Where it acts: command, feedback, surface, position, load."""
    field: str | None
    """The model parameter it sets (None for hinge_moment_sign)."""
    vocab: str | None
    """The contract's parameter name for it."""
    signature: str
    """What it looks like in a residual (for the evidence line)."""
    probes: Callable[[Context], list[float]]
    applies: Callable[[Context], bool]
    check: Callable[[float, Context], str | None] = field(default=lambda v, c: None)  # noqa: ARG005
    discrete: bool = False
    """Fitted by a one-dimensional search rather than by gradients (quantization)."""
    load_effect: bool = False
    """Acts through the hinge moment (a negative fit points at a reversed load sign)."""
    restart: bool = False
    """Start its fit from the declared ωn and ζ: without it the fit bent them to mimic the effect."""

    @property
    def key(self) -> str:
        """Unique name of the variant (effect/where)."""
        return f"{self.name}/{self.where}"

    def apply(self, p: SecondOrderParams, value: float, ctx: Context) -> SecondOrderParams:
        """The model with this effect set to ``value``."""
        if self.field is None:  # hinge_moment_sign: restore load stages a wrong-signed fit drove to zero
            restore = {f: getattr(ctx.declared, f) for f in HM_FIELDS
                       if abs(getattr(p, f)) <= OFF and abs(getattr(ctx.declared, f)) > OFF}
            return p.replace(**restore) if restore else p
        changes = {self.field: value}
        if self.restart:
            changes |= {"wn_rad_s": ctx.declared.wn_rad_s, "zeta": ctx.declared.zeta}
        if self.field == "hysteresis_h_lb_per_in":
            changes["hysteresis_freq_hz"] = ctx.problem.load_freq_hz
        return p.replace(**changes)


def _fs(ctx: Context) -> float:
    return ctx.problem.sample_hz


def _has(output: str) -> Callable[[Context], bool]:
    return lambda ctx: output in ctx.problem.outputs


def _loaded(ctx: Context) -> bool:
    return ctx.problem.load_span_inlb > 20.0


def _min(value: float, what: str) -> Callable[[float, Context], str | None]:
    return lambda v, ctx: None if v >= value else f"{what} {v:.4g} is below {value:g}"  # noqa: ARG005


def _delay_check(v: float, ctx: Context) -> str | None:
    floor = max(1.0 / _fs(ctx), 5e-4)
    if v < floor:
        return f"delay {v * 1e3:.3f} ms is below one sample ({1e3 / _fs(ctx):.3f} ms): a sampling shift, not an effect"
    return None


def _lag_check(v: float, ctx: Context) -> str | None:
    ceiling = _fs(ctx) / (2.0 * math.pi)
    if v > ceiling:
        return f"corner {v:.1f} Hz is faster than one sample's time constant ({ceiling:.0f} Hz)"
    return None


def _rate_check(v: float, ctx: Context) -> str | None:
    unlimited = ctx.problem.max_rate_dps(ctx.problem.simulate([ctx.params.replace(rate_limit_dps=math.inf)])[0])
    if v > 0.95 * unlimited:
        return f"rate limit {v:.1f} °/s never binds (unlimited, the model peaks at {unlimited:.1f} °/s)"
    return None


def _quant_check(v: float, ctx: Context) -> str | None:
    span = float(np.ptp(ctx.problem.data.command_deg))
    if v < 1e-3:
        return f"step {v:.5f}° is below 0.001°"
    if v > 0.05 * span:
        return f"step {v:.3f}° is too coarse for a command spanning {span:.2f}°"
    return None


EFFECTS: tuple[Effect, ...] = (
    Effect("time_delay", "command", "delay_s", "delay_s", "a lag at every frequency, residual ∝ −ẏ",
           probes=lambda ctx: [ctx.params.delay_s + 0.002], applies=lambda _ctx: True, check=_delay_check),
    Effect("lag_filter", "command", "command_lag_hz", "corner_hz",
           "a lag growing with frequency, with attenuation, on both outputs",
           probes=lambda _ctx: [30.0], applies=lambda ctx: ctx.params.command_lag_hz == 0.0, check=_lag_check),
    Effect("lag_filter", "feedback", "feedback_lag_hz", "corner_hz",
           "a lag growing with frequency on the LVDT feedback only",
           probes=lambda _ctx: [30.0],
           applies=lambda ctx: _has("position_deg")(ctx) and ctx.params.feedback_lag_hz == 0.0, check=_lag_check),
    Effect("command_gain", "command", "kb", "kb", "residual proportional to the command",
           probes=lambda ctx: [ctx.params.kb + 0.01], applies=lambda _ctx: True),
    Effect("command_bias", "command", "offset_deg", "offset_deg", "a constant residual",
           probes=lambda ctx: [ctx.params.offset_deg + 0.05], applies=lambda _ctx: True),
    Effect("quantization", "command", "quantization_deg", "step_deg",
           "a sawtooth locked to the command level", probes=lambda ctx: [q for q, _ in ctx.quantization_steps[:1]],
           applies=lambda ctx: ctx.params.quantization_deg == 0.0, check=_quant_check, discrete=True),
    Effect("rate_limit", "command", "rate_limit_dps", "rate_dps", "saturated slopes on the large steps",
           probes=lambda ctx: [ctx.problem.measured_rate_dps],
           applies=lambda ctx: not math.isfinite(ctx.params.rate_limit_dps) and ctx.problem.measured_rate_dps > 5.0,
           check=_rate_check, restart=True),
    Effect("static_threshold", "command", "threshold_deg", "threshold_deg",
           "the surface lags slow ramps and ignores small command changes", probes=lambda _ctx: [0.01, 0.05],
           applies=lambda ctx: ctx.params.threshold_deg == 0.0, check=_min(1e-3, "threshold")),
    Effect("free_play", "surface", "free_play_deg", "width_deg",
           "a square wave in the sign of the hinge moment on the surface", probes=lambda _ctx: [0.1, 0.3],
           applies=lambda ctx: _has("surface_deg")(ctx) and ctx.problem.load_reverses
           and ctx.params.free_play_deg == 0.0,
           check=_min(5e-3, "free play"), load_effect=True),
    Effect("compliance", "surface", "compliance_deg_per_kinlb", "deg_per_kinlb",
           "surface residual proportional to the hinge moment", probes=lambda _ctx: [0.2],
           applies=lambda ctx: _has("surface_deg")(ctx) and _loaded(ctx)
           and ctx.params.compliance_deg_per_kinlb == 0.0,
           check=_min(1e-3, "compliance"), load_effect=True),
    Effect("compliance", "position", "lvdt_compliance_deg_per_kinlb", "deg_per_kinlb",
           "LVDT residual proportional to the hinge moment (compliance inside the servo loop)",
           probes=lambda _ctx: [0.1],
           applies=lambda ctx: _has("position_deg")(ctx) and _loaded(ctx)
           and ctx.params.lvdt_compliance_deg_per_kinlb == 0.0,
           check=_min(1e-3, "LVDT compliance"), load_effect=True),
    Effect("hysteretic_damping", "surface", "hysteresis_h_lb_per_in", "h_lb_per_in",
           "surface residual in quadrature with the oscillating hinge moment", probes=lambda _ctx: [2000.0],
           applies=lambda ctx: ctx.params.compliance_deg_per_kinlb > 1e-3 and ctx.params.hysteresis_h_lb_per_in == 0.0
           and _loaded(ctx),
           check=_min(10.0, "h")),
    Effect("hinge_moment_sign", "load", None, None,
           "the load-dependent stages fit the residual only with the hinge moment reversed",
           probes=lambda _ctx: [0.0],
           applies=lambda ctx: (hinge_moment_active(ctx.params) or hinge_moment_active(ctx.declared)) and _loaded(ctx)),
)

VOCABULARY = tuple(dict.fromkeys(e.name for e in EFFECTS))
"""The effect names identification can report."""
