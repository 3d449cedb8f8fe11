"""The effects vocabulary of ``../shared/data-contract.md`` (and ``docs/effects.md``) as model stages.

Each :class:`Effect` names the stages of the second-order model that carry it (one or more model
parameters), the keys the report gives them, where it acts (``command``, ``feedback`` — inside the
servo loop —, ``surface`` — outside it —, or ``load`` for the hinge-moment column itself), the
probe points that draw its signature in a residual, and the check that says whether a fitted value
means something physical. An effect is only a candidate where the record can show it (free play
needs a reversing load and a surface sensor, a linkage mode a surface sensor...).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from ema_sim.identify.problem import Problem
from ema_sim.models.second_order import SecondOrderParams
from ema_sim.parameters import metas

Values = dict[str, float]
"""Model parameter → value."""


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
        """Model value → optimiser coordinate.

        Parameters
        ----------
        value : float
            The model's value (clipped into the bounds).

        Returns
        -------
        float
            The coordinate.
        """
        value = min(max(value, self.low), self.high)
        return math.log(value / self.scale) if self.log else value / self.scale

    def from_x(self, x: float) -> float:
        """Optimiser coordinate → model value.

        Parameters
        ----------
        x : float
            The coordinate.

        Returns
        -------
        float
            The model's value.
        """
        return self.scale * math.exp(x) if self.log else self.scale * x

    def capped(self, high: float | None) -> Free:
        """The same parameter with its upper bound lowered to ``high`` (never below its lower bound).

        Parameters
        ----------
        high : float or None
            The record's own bound on it (None: the physical range as it is).
        """
        if high is None or high >= self.high:
            return self
        return replace(self, high=max(high, self.low))

    def x_bounds(self) -> tuple[float, float]:
        """Bounds in optimiser coordinates.

        Returns
        -------
        tuple of float
            (low, high).
        """
        return self.to_x(self.low), self.to_x(self.high)

    def derivative(self, value: float) -> float:
        """d(value)/dx, to carry covariances from x to physical units.

        Parameters
        ----------
        value : float
            The model's value.

        Returns
        -------
        float
            The derivative.
        """
        return value if self.log else self.scale


def _free(name: str, *, log: bool = False, scale: float = 1.0) -> Free:
    """A fitted parameter whose bounds are its declared range (:mod:`ema_sim.models.second_order.params`)."""
    m = metas(SecondOrderParams)[name]
    return Free(name, m.min, m.max, log=log, scale=scale)


# Every continuously fitted parameter of the second-order family; bounds from the parameter metadata.
FREE: dict[str, Free] = {f.field: f for f in (
        _free("wn_rad_s", log=True, scale=60.0),
        _free("zeta", log=True, scale=0.7),
        _free("delay_s", scale=0.01),
        _free("command_lag_hz", log=True, scale=20.0),
        _free("feedback_lag_hz", log=True, scale=20.0),
        _free("kb", scale=0.01),
        _free("offset_deg", scale=0.05),
        _free("rate_limit_dps", log=True, scale=100.0),
        _free("k2_dps_per_lb", scale=0.01),
        _free("threshold_deg", scale=0.05),
        _free("free_play_deg", scale=0.1),
        _free("compliance_deg_per_kinlb", scale=0.2),
        _free("lvdt_compliance_deg_per_kinlb", scale=0.1),
        _free("hysteresis_h_lb_per_in", log=True, scale=3000.0),
        _free("feedback_delay_s", scale=0.002),
        _free("integral_hz", log=True, scale=0.1),
        _free("servo_compliance_deg_per_kinlb", scale=0.1),
        _free("accel_limit_dps2", log=True, scale=1e4),
        _free("velocity_loop_hz", log=True, scale=300.0),
        _free("linkage_freq_hz", log=True, scale=30.0),
        _free("linkage_zeta", log=True, scale=0.1),
        _free("compliance_knee_inlb", log=True, scale=500.0),
        _free("compliance_stiff_deg_per_kinlb", scale=0.2),
        _free("lvdt_compliance_knee_inlb", log=True, scale=500.0),
        _free("lvdt_compliance_stiff_deg_per_kinlb", scale=0.1),
)}


class ArmParams(Protocol):
    """Model parameters with the moment arm a per-force rate is turned into a per-moment one with."""

    @property
    def moment_arm_in(self) -> float: ...  # noqa: D102


def _same_unit(_p: object) -> float:
    """The report's unit is the model's: factor 1."""
    return 1.0


@dataclass(frozen=True)
class Key:
    """How the report names a model parameter, and the factor from the model's unit to the report's."""

    name: str
    factor: Callable[[ArmParams], float] = _same_unit


def _per_kinlb_from_per_lb(p: ArmParams) -> float:
    """K2 (°/s per lbf at the moment arm) → °/s per 1000 in·lb of hinge moment."""
    return 1000.0 / float(p.moment_arm_in)


KEYS: dict[str, Key] = {
    "delay_s": Key("delay_s"),
    "feedback_delay_s": Key("feedback_delay_s"),
    "command_lag_hz": Key("corner_hz"),
    "feedback_lag_hz": Key("feedback_corner_hz"),
    "kb": Key("kb"),
    "offset_deg": Key("offset_deg"),
    "quantization_deg": Key("step_deg"),
    "rate_limit_dps": Key("rate_dps"),
    "k2_dps_per_lb": Key("dps_per_kinlb", _per_kinlb_from_per_lb),
    "threshold_deg": Key("threshold_deg"),
    "free_play_deg": Key("width_deg"),
    "compliance_deg_per_kinlb": Key("deg_per_kinlb"),
    "compliance_knee_inlb": Key("knee_inlb"),
    "compliance_stiff_deg_per_kinlb": Key("stiff_deg_per_kinlb"),
    "lvdt_compliance_deg_per_kinlb": Key("lvdt_deg_per_kinlb"),
    "lvdt_compliance_knee_inlb": Key("lvdt_knee_inlb"),
    "lvdt_compliance_stiff_deg_per_kinlb": Key("lvdt_stiff_deg_per_kinlb"),
    "hysteresis_h_lb_per_in": Key("h_lb_per_in"),
    "integral_hz": Key("integral_hz"),
    "servo_compliance_deg_per_kinlb": Key("servo_deg_per_kinlb"),
    "accel_limit_dps2": Key("accel_dps2"),
    "velocity_loop_hz": Key("velocity_loop_hz"),
    "linkage_freq_hz": Key("freq_hz"),
    "linkage_zeta": Key("linkage_zeta"),
}
"""Model parameter → the report's key: one key per quantity in every report (an LVDT compliance is
``lvdt_deg_per_kinlb``, never the surface's ``deg_per_kinlb``; the linkage's damping ratio is
``linkage_zeta`` because ``zeta`` is the servo's)."""

HM_FIELDS = ("compliance_deg_per_kinlb", "lvdt_compliance_deg_per_kinlb", "free_play_deg",
             "hysteresis_h_lb_per_in", "kcp_per_kinlb", "servo_compliance_deg_per_kinlb")
"""Model parameters through which the hinge moment acts (what hinge_moment_sign can be seen in)."""


OFF = 1e-9
"""A parameter this close to zero is off (a fit pinned on a zero bound lands a hair above it)."""


def hinge_moment_active(p: SecondOrderParams) -> bool:
    """True when the model's outputs depend on the sign of the hinge moment.

    Parameters
    ----------
    p : SecondOrderParams
        The model.

    Returns
    -------
    bool
        Whether a load stage is on.
    """
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
    max_accel_dps2: float = 0.0
    """Largest acceleration the current model reaches on the record."""
    ringing_hz: float = 0.0
    """Where the surface residual's spectrum peaks above 3 Hz (0: no surface, or nothing there)."""


Probe = Callable[[Context], list[Values]]
Check = Callable[[Values, Context], "str | None"]


def _no_check(_v: Values, _ctx: Context) -> str | None:
    """Every fitted value is physical."""
    return None


@dataclass(frozen=True)
class Effect:
    """One vocabulary effect realised as stages of the second-order model."""

    name: str
    """Vocabulary name (data contract, docs/effects.md)."""
    where: str
    """Where it acts: command, feedback (inside the servo loop), surface (outside it), load (the column)."""
    fields: tuple[str, ...]
    """The model parameters it fits and reports (none for a structural switch)."""
    signature: str
    """What it looks like in a residual (for the evidence line)."""
    probes: Probe
    """Points that draw its signature: model parameter → value (the first one of a single-field effect is scaled)."""
    applies: Callable[[Context], bool]
    check: Check = _no_check
    switch: Mapping[str, float] = field(default_factory=dict)
    """Model parameters it sets and does not fit (a structural switch, the in-loop filter)."""
    discrete: bool = False
    """Fitted by a one-dimensional search rather than by gradients (quantization)."""
    load_effect: bool = False
    """Acts through the hinge moment (a negative fit points at a reversed load sign)."""
    restart: bool = False
    """Start its fit from the declared ωn and ζ: without it the fit bent them to mimic the effect."""
    replaces: tuple[str, ...] = ()
    """Parameters of another effect this one is an alternative to: its fit is also tried with them switched
    off (the in-loop feedback filter against the lag on the LVDT reading), and the better one kept."""
    companions: tuple[str, ...] = ()
    """Effects (``name/where``) fitted together with this one when the model lacks them: a structure the
    current fit has bent its own parameters to mimic (the in-loop filter re-times the whole loop, so
    the delays it hid are freed with it); each one whose value fails its check is dropped again."""
    contract: Mapping[str, str] = field(default_factory=dict)
    """The data contract's key for a parameter in this effect's own ``params`` where it differs from the key the
    final model's parameters carry (the linkage's damping ratio is ``zeta`` in its effect, ``linkage_zeta`` beside
    the servo's own ``zeta`` in the final model)."""
    own: tuple[str, ...] | None = None
    """The parameters that are this effect's alone (its fields when None): once they are fitted, it is in.
    A nonlinear compliance also fits (and reports) the compliance below its knee, which a linear
    compliance found earlier may already have."""
    ramp_clause: str = ""
    """The part of :attr:`signature` that only a command that ramps can show (left out of the evidence otherwise)."""
    measured: bool = False
    """Its probes are read off the record (a rate limit at the output's speed plateau): its fit starts from
    them as they are, not scaled by what the residual would ask of them linearly."""

    @property
    def owned(self) -> tuple[str, ...]:
        """The parameters whose presence in a fit means the effect is in."""
        return self.fields if self.own is None else self.own

    @property
    def key(self) -> str:
        """Unique name of the variant (effect/where)."""
        return f"{self.name}/{self.where}"

    @property
    def field(self) -> str | None:
        """The first (main) model parameter, None for a switch."""
        return self.fields[0] if self.fields else None

    def apply(self, p: SecondOrderParams, values: Values, ctx: Context) -> SecondOrderParams:
        """The model with this effect set to ``values``.

        Parameters
        ----------
        p : SecondOrderParams
            The current model.
        values : dict
            Model parameter → value.
        ctx : Context
            The record and the declared model.

        Returns
        -------
        SecondOrderParams
            The changed model.
        """
        if self.name == "hinge_moment_sign":  # restore load stages a wrong-signed fit drove to zero
            restore = {f: getattr(ctx.declared, f) for f in HM_FIELDS
                       if abs(getattr(p, f)) <= OFF and abs(getattr(ctx.declared, f)) > OFF}
            return p.replace(**restore) if restore else p
        changes = {**self.switch, **values}
        if self.restart:
            changes |= {"wn_rad_s": ctx.declared.wn_rad_s, "zeta": ctx.declared.zeta}
        if "hysteresis_h_lb_per_in" in changes:
            changes["hysteresis_freq_hz"] = ctx.problem.load_freq_hz
        return p.replace(**changes)

    def evidence(self, command: NDArray[np.float64]) -> str:
        """Its signature in words that fit the record: a clause about ramps only where the command ramps.

        Parameters
        ----------
        command : numpy.ndarray
            The record's command as logged.
        """
        if self.ramp_clause and self.ramp_clause in self.signature and not ramps(command):
            return " ".join(self.signature.replace(self.ramp_clause, "").split())
        return self.signature


def _fs(ctx: Context) -> float:
    return ctx.problem.sample_hz


def _has(output: str) -> Callable[[Context], bool]:
    return lambda ctx: output in ctx.problem.outputs


def _loaded(ctx: Context) -> bool:
    return ctx.problem.load_span_inlb > 20.0


def _off(ctx: Context, name: str) -> bool:
    """The model has this stage switched off."""
    return bool(getattr(ctx.params, name) == metas(SecondOrderParams)[name].off)


def _min(name: str, value: float, what: str) -> Check:
    return lambda v, _ctx: None if v[name] >= value else f"{what} {v[name]:.4g} is below {value:g}"


def _dead_band(name: str, value: float, what: str, half: float = 1.0) -> Check:
    """:func:`_min`, and no dead band (its half width: ``half`` × the value) wider than the settled error.

    An output that settles on its command leaves nothing for a threshold or a free play to explain
    (:mod:`ema_sim.identify.settled`): a wider one stands in for something else, and is not added.
    """
    floor = _min(name, value, what)

    def check(v: Values, ctx: Context) -> str | None:
        low = floor(v, ctx)
        if low is not None:
            return low
        p = ctx.problem
        settled = p.settled
        if settled is None or half * v[name] <= settled.bound * (1.0 + 1e-9):
            return None
        unit = p.data.unit
        return (f"{what} {v[name]:.4g} {unit} is larger than any error the output settles to at the end of the "
                f"command's holds (median {settled.median_abs:.3g}, largest {settled.max_abs:.3g} {unit} over "
                f"{settled.holds} holds; + half a count: {settled.bound:.3g}): it explains no settled error, it stands "
                "in for something else")
    return check


RAMP_SAMPLES = 5
"""A command that moves the same way in at least this many consecutive small steps ramps (a jump is one step)."""


def ramps(command: NDArray[np.float64]) -> bool:
    """Whether a command ramps: :data:`RAMP_SAMPLES` consecutive changes of one sign (a square wave only jumps).

    Parameters
    ----------
    command : numpy.ndarray
        The command as logged.
    """
    d = np.sign(np.diff(np.asarray(command, dtype=float)))
    same = (d[1:] == d[:-1]) & (d[1:] != 0.0)
    if same.size < RAMP_SAMPLES - 1:
        return False
    window = np.convolve(same.astype(float), np.ones(RAMP_SAMPLES - 1), mode="valid")
    return bool(np.any(window >= RAMP_SAMPLES - 1))


SUB_SAMPLE_FLOOR = 0.1
"""A fitted delay under this share of a sample is a sampling shift, not an effect. Between it and one sample a
delay is kept (a 4 ms transport delay at 200 Hz is real) and the report says the record cannot tell it from a
skew between the logging of the command and of the feedback."""


def _delay_check(name: str) -> Check:
    def check(v: Values, ctx: Context) -> str | None:
        floor = max(SUB_SAMPLE_FLOOR / _fs(ctx), 1e-4)
        if v[name] < floor:
            return (f"delay {v[name] * 1e3:.3f} ms is below the {floor * 1e3:.3f} ms a record sampled every "
                    f"{1e3 / _fs(ctx):.3f} ms tells from a sampling shift: not an effect")
        return None
    return check


def _lag_check(name: str) -> Check:
    def check(v: Values, ctx: Context) -> str | None:
        ceiling = _fs(ctx) / (2.0 * math.pi)
        if v[name] > ceiling:
            return f"corner {v[name]:.1f} Hz is faster than one sample's time constant ({ceiling:.0f} Hz)"
        return None
    return check


def _rate_check(v: Values, ctx: Context) -> str | None:
    """A limit binds when it moves the model's outputs by more than the noise somewhere on the record.

    The limit acts on the velocity command inside the loop (section 3.1.2.1), so it can bind while the surface
    itself never reaches it (a motor lag between them): the peak output rate alone cannot tell.
    """
    p = ctx.problem
    limited, unlimited = p.simulate([ctx.params, ctx.params.replace(rate_limit_dps=math.inf)])
    with_limit, without = p.errors_deg(limited), p.errors_deg(unlimited)
    moved = {o: float(np.max(np.abs(with_limit[o] - without[o]), initial=0.0)) for o in p.outputs}
    if all(moved[o] <= p.sigma_deg[o] for o in p.outputs):
        rate, peak = v["rate_limit_dps"], p.max_rate_dps(unlimited)
        return (f"rate limit {rate:.1f} °/s never binds: the model with and without it differs by at most "
                f"{max(moved.values()):.4f}°, within the noise (the model peaks at {peak:.1f} °/s)")
    return None


def _load_rate_check(v: Values, ctx: Context) -> str | None:
    why = _rate_check(v, ctx) if "rate_limit_dps" in v else None
    if why:
        return why
    shift = v["k2_dps_per_lb"] * ctx.problem.load_span_inlb / 2.0 / ctx.params.moment_arm_in
    rate = v.get("rate_limit_dps", ctx.params.rate_limit_dps)
    if shift < 0.005 * rate:
        return f"the load moves the rate limit by {shift:.2f} °/s, under 0.5 % of {rate:.1f} °/s"
    return None


def _accel_check(v: Values, ctx: Context) -> str | None:
    free = ctx.params.replace(accel_limit_dps2=math.inf)
    unlimited = ctx.problem.max_accel_dps2(ctx.problem.simulate([free])[0])
    accel = v["accel_limit_dps2"]
    if unlimited > 0.0 and accel > 0.95 * unlimited:
        return f"acceleration limit {accel:.0f} °/s² never binds (the model peaks at {unlimited:.0f} °/s²)"
    loop = v.get("velocity_loop_hz", ctx.params.velocity_loop_hz)
    if loop > _fs(ctx):
        return f"the drive's velocity loop ({loop:.0f} Hz) is faster than the sample rate: it cannot be told"
    return None


def _quant_check(v: Values, ctx: Context) -> str | None:
    span = float(np.ptp(ctx.problem.data.command_deg))
    q = v["quantization_deg"]
    if q < 1e-3:
        return f"step {q:.5f}° is below 0.001°"
    if q > 0.05 * span:
        return f"step {q:.3f}° is too coarse for a command spanning {span:.2f}°"
    return None


def _integral_check(v: Values, ctx: Context) -> str | None:
    corner = v["integral_hz"]
    length_s = float(ctx.problem.time_s[-1])
    if corner < 0.5 / length_s:
        return f"integral corner {corner:.3g} Hz is slower than the record ({length_s:.1f} s) can show"
    if corner > 0.2 * ctx.params.wn_rad_s / (2.0 * math.pi):
        return f"integral corner {corner:.3g} Hz is not slow against the servo's ωn: it reshapes the loop instead"
    return None


def _linkage_check(v: Values, ctx: Context) -> str | None:
    freq = v["linkage_freq_hz"]
    if freq > 0.4 * _fs(ctx):
        return f"linkage mode {freq:.1f} Hz is at or above 0.4× the sample rate ({_fs(ctx):.0f} Hz)"
    zeta = v.get("linkage_zeta", ctx.params.linkage_zeta)
    if zeta > 1.0:
        return f"linkage damping ratio {zeta:.2f} is overdamped: no mode rings"
    return None


def _knee_check(prefix: str) -> Check:
    def check(v: Values, ctx: Context) -> str | None:
        knee = v[f"{prefix}_knee_inlb"]
        hm = np.abs(ctx.problem.hinge_moment)
        low, high = float(np.percentile(hm, 5)), float(np.percentile(hm, 98))
        if not low < knee < high:
            return f"knee {knee:.0f} in·lb is outside the record's load ({low:.0f}–{high:.0f} in·lb)"
        c = v.get(f"{prefix}_deg_per_kinlb", getattr(ctx.params, f"{prefix}_deg_per_kinlb"))
        stiff = v[f"{prefix}_stiff_deg_per_kinlb"]
        if abs(stiff - c) < 0.1 * c:
            return f"compliance above the knee ({stiff:.3g}) is within 10 % of below it ({c:.3g}): linear"
        return None
    return check


def _knee_probe(prefix: str, start: float) -> Probe:
    def probe(ctx: Context) -> list[Values]:
        c = getattr(ctx.params, f"{prefix}_deg_per_kinlb")
        base = {} if c > 1e-3 else {f"{prefix}_deg_per_kinlb": start}
        c = c if c > 1e-3 else start
        peak = float(np.percentile(np.abs(ctx.problem.hinge_moment), 98))
        return [{**base, f"{prefix}_knee_inlb": k * peak, f"{prefix}_stiff_deg_per_kinlb": 0.5 * c} for k in (0.3, 0.6)]
    return probe


def _nonlinear_applies(prefix: str, output: str) -> Callable[[Context], bool]:
    def applies(ctx: Context) -> bool:
        # A refinement of a compliance already in the model: as a rival to the linear one, its three
        # parameters took a hysteresis loop's quadrature residual for a bend.
        return (output in ctx.problem.outputs and _loaded(ctx) and _off(ctx, f"{prefix}_knee_inlb")
                and getattr(ctx.params, f"{prefix}_deg_per_kinlb") > 1e-3)
    return applies


def _rate_probes(ctx: Context) -> list[Values]:
    """A rate limit at the slope the record's rate-limited moves or speed plateau show, and at its peak speed.

    The plateau is the record's own evidence of the limit (:func:`ema_sim.analysis.estimation.slew.measure`); the
    peak speed is where a limit could start to bind when no move shows one.
    """
    slope = ctx.problem.measured_slew.rate
    peak = ctx.problem.measured_rate_dps
    rates = [slope] if slope is not None and slope > 5.0 else []
    if not rates or abs(peak - rates[0]) > 0.1 * rates[0]:
        rates.append(peak)
    return [{"rate_limit_dps": r} for r in rates]


def _load_rate_probe(ctx: Context) -> list[Values]:
    rate = ctx.params.rate_limit_dps if not _off(ctx, "rate_limit_dps") else ctx.problem.measured_rate_dps
    k2 = 0.1 * rate * ctx.params.moment_arm_in / max(ctx.problem.load_span_inlb / 2.0, 1.0)
    return [{"rate_limit_dps": rate, "k2_dps_per_lb": k2}]


def _linkage_probe(ctx: Context) -> list[Values]:
    freqs = [ctx.ringing_hz] if ctx.ringing_hz > 0.0 else []
    freqs += [f for f in (15.0, 30.0) if f < 0.4 * _fs(ctx) and all(abs(f - g) > 0.3 * g for g in freqs)]
    return [{"linkage_freq_hz": f, "linkage_zeta": 0.15} for f in freqs]


EFFECTS: tuple[Effect, ...] = (
    Effect("time_delay", "command", ("delay_s",), "a lag at every frequency, residual ∝ −ẏ",
           probes=lambda ctx: [{"delay_s": ctx.params.delay_s + 0.002}], applies=lambda _ctx: True,
           check=_delay_check("delay_s")),
    Effect("time_delay", "feedback", ("feedback_delay_s",),
           "the LVDT reading lags the motion at every frequency, the surface does not",
           probes=lambda ctx: [{"feedback_delay_s": ctx.params.feedback_delay_s + 0.002}],
           applies=lambda ctx: _has("position_deg")(ctx) and _has("surface_deg")(ctx),
           check=_delay_check("feedback_delay_s")),
    Effect("lag_filter", "command", ("command_lag_hz",),
           "a lag growing with frequency, with attenuation, on both outputs",
           probes=lambda _ctx: [{"command_lag_hz": 30.0}], applies=lambda ctx: _off(ctx, "command_lag_hz"),
           check=_lag_check("command_lag_hz")),
    Effect("lag_filter", "feedback", ("feedback_lag_hz",), "a lag growing with frequency on the LVDT feedback only",
           probes=lambda _ctx: [{"feedback_lag_hz": 30.0}],
           applies=lambda ctx: _has("position_deg")(ctx) and _off(ctx, "feedback_lag_hz"),
           check=_lag_check("feedback_lag_hz")),
    Effect("feedback_filter", "feedback", (),
           "the surface leads the LVDT reading by the servo's own lag: the loop closes on a filtered LVDT",
           probes=lambda _ctx: [{}], switch={"feedback_filter_in_loop": 1.0}, restart=True,
           replaces=("feedback_lag_hz",), companions=("time_delay/command", "time_delay/feedback"),
           applies=lambda ctx: _has("surface_deg")(ctx) and ctx.params.feedback_filter_in_loop < 0.5),
    Effect("command_gain", "command", ("kb",), "residual proportional to the command",
           probes=lambda ctx: [{"kb": ctx.params.kb + 0.01}], applies=lambda _ctx: True),
    Effect("command_bias", "command", ("offset_deg",), "a constant residual",
           probes=lambda ctx: [{"offset_deg": ctx.params.offset_deg + 0.05}], applies=lambda _ctx: True),
    Effect("quantization", "command", ("quantization_deg",), "a sawtooth locked to the command level",
           probes=lambda ctx: [{"quantization_deg": q} for q, _ in ctx.quantization_steps[:1]],
           applies=lambda ctx: ctx.params.quantization_deg == 0.0, check=_quant_check, discrete=True),
    Effect("rate_limit", "feedback", ("rate_limit_dps",), "the output's speed flat at one ceiling on its large moves",
           probes=_rate_probes,
           applies=lambda ctx: _off(ctx, "rate_limit_dps") and ctx.problem.measured_rate_dps > 5.0,
           check=_rate_check, restart=True, measured=True),
    Effect("load_rate_limit", "feedback", ("rate_limit_dps", "k2_dps_per_lb"),
           "saturated slopes steeper with an aiding load, shallower against an opposing one",
           probes=_load_rate_probe,
           applies=lambda ctx: ctx.problem.measured_rate_dps > 5.0 and _loaded(ctx) and ctx.params.k2_dps_per_lb == 0.0,
           check=_load_rate_check, own=("k2_dps_per_lb",)),
    Effect("static_threshold", "feedback", ("threshold_deg",),
           "the output lags slow ramps and ignores small command changes", ramp_clause="lags slow ramps and",
           probes=lambda _ctx: [{"threshold_deg": 0.01}, {"threshold_deg": 0.05}],
           applies=lambda ctx: ctx.params.threshold_deg == 0.0, check=_dead_band("threshold_deg", 1e-3, "threshold")),
    Effect("servo_integral", "feedback", ("integral_hz",),
           "slow creep after steps and a load droop that washes out: the loop integrates its error",
           probes=lambda _ctx: [{"integral_hz": 0.1}], applies=lambda ctx: _off(ctx, "integral_hz"),
           check=_integral_check),
    Effect("servo_compliance", "feedback", ("servo_compliance_deg_per_kinlb",),
           "both outputs droop with the hinge moment through the servo's own response",
           probes=lambda _ctx: [{"servo_compliance_deg_per_kinlb": 0.1}],
           applies=lambda ctx: _loaded(ctx) and _off(ctx, "servo_compliance_deg_per_kinlb"),
           check=_min("servo_compliance_deg_per_kinlb", 1e-3, "servo compliance"), load_effect=True),
    Effect("current_limit", "feedback", ("accel_limit_dps2", "velocity_loop_hz"),
           "the start of each large step is slower than the servo asks: the drive's acceleration saturates",
           probes=lambda _ctx: [{"accel_limit_dps2": a, "velocity_loop_hz": 300.0} for a in (1e3, 4e3, 1.6e4)],
           applies=lambda ctx: _off(ctx, "accel_limit_dps2"),
           check=_accel_check),
    Effect("free_play", "surface", ("free_play_deg",), "a square wave in the sign of the hinge moment on the surface",
           probes=lambda _ctx: [{"free_play_deg": 0.1}, {"free_play_deg": 0.3}],
           applies=lambda ctx: _has("surface_deg")(ctx) and ctx.problem.load_reverses
           and ctx.params.free_play_deg == 0.0,
           check=_min("free_play_deg", 5e-3, "free play"), load_effect=True),
    Effect("compliance", "surface", ("compliance_deg_per_kinlb",), "surface residual proportional to the hinge moment",
           probes=lambda _ctx: [{"compliance_deg_per_kinlb": 0.2}],
           applies=lambda ctx: _has("surface_deg")(ctx) and _loaded(ctx) and ctx.params.compliance_deg_per_kinlb == 0.0,
           check=_min("compliance_deg_per_kinlb", 1e-3, "compliance"), load_effect=True),
    Effect("compliance", "feedback", ("lvdt_compliance_deg_per_kinlb",),
           "LVDT residual proportional to the hinge moment (compliance inside the servo loop)",
           probes=lambda _ctx: [{"lvdt_compliance_deg_per_kinlb": 0.1}],
           applies=lambda ctx: _has("position_deg")(ctx) and _loaded(ctx)
           and ctx.params.lvdt_compliance_deg_per_kinlb == 0.0,
           check=_min("lvdt_compliance_deg_per_kinlb", 1e-3, "LVDT compliance"), load_effect=True),
    Effect("nonlinear_compliance", "surface",
           ("compliance_deg_per_kinlb", "compliance_knee_inlb", "compliance_stiff_deg_per_kinlb"),
           "the surface's compliance residual bends with the load: the linkage stiffens (figures 16, 33)",
           probes=_knee_probe("compliance", 0.3), applies=_nonlinear_applies("compliance", "surface_deg"),
           check=_knee_check("compliance"), own=("compliance_knee_inlb", "compliance_stiff_deg_per_kinlb")),
    Effect("nonlinear_compliance", "feedback",
           ("lvdt_compliance_deg_per_kinlb", "lvdt_compliance_knee_inlb", "lvdt_compliance_stiff_deg_per_kinlb"),
           "the LVDT's compliance residual bends with the load (figure 16's LVDT curve)",
           probes=_knee_probe("lvdt_compliance", 0.1), applies=_nonlinear_applies("lvdt_compliance", "position_deg"),
           check=_knee_check("lvdt_compliance"),
           own=("lvdt_compliance_knee_inlb", "lvdt_compliance_stiff_deg_per_kinlb")),
    Effect("hysteretic_damping", "surface", ("hysteresis_h_lb_per_in",),
           "surface residual in quadrature with the oscillating hinge moment",
           probes=lambda _ctx: [{"hysteresis_h_lb_per_in": 2000.0}],
           applies=lambda ctx: ctx.params.compliance_deg_per_kinlb > 1e-3 and ctx.params.hysteresis_h_lb_per_in == 0.0
           and _loaded(ctx),
           check=_min("hysteresis_h_lb_per_in", 10.0, "h")),
    Effect("linkage_mode", "surface", ("linkage_freq_hz", "linkage_zeta"),
           "the surface rings after steps (an LVDT, inside the servo loop, would not): its own mode outside the loop",
           probes=_linkage_probe, applies=lambda ctx: _has("surface_deg")(ctx) and _off(ctx, "linkage_freq_hz"),
           check=_linkage_check, contract={"linkage_zeta": "zeta"}),
    Effect("hinge_moment_sign", "load", (), "the load-dependent stages fit the residual only with the hinge moment "
           "reversed", probes=lambda _ctx: [{}],
           applies=lambda ctx: (hinge_moment_active(ctx.params) or hinge_moment_active(ctx.declared)) and _loaded(ctx)),
)

BY_KEY: dict[str, Effect] = {e.key: e for e in EFFECTS}
"""Each effect variant by its ``name/where``."""

VOCABULARY = tuple(dict.fromkeys(e.name for e in EFFECTS))
"""The effect names identification can report."""


def report_values(p: ArmParams, fields: tuple[str, ...] | list[str]) -> dict[str, float]:
    """The report's key → value of some model parameters (each in the report's unit).

    Parameters
    ----------
    p : SecondOrderParams
        The model.
    fields : sequence of str
        Model parameters.

    Returns
    -------
    dict
        Key → value.
    """
    out = {}
    for f in fields:
        key = KEYS.get(f, Key(f))
        out[key.name] = float(getattr(p, f)) * key.factor(p)
    return out
