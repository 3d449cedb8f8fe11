"""Measured-like data for identification tests: one model, undeclared effects, sensor noise.

The truth is LOAC (the adaptive continuous reference, not the RK4 simulator identification fits
with) driven by a realistic test sequence: steps (one large enough to rate-limit), a frequency sweep,
a slow ramp, and a hinge moment that varies slowly and reverses. Outputs are sampled like a DAU and
get white sensor noise; the measured hinge moment gets load-cell noise.
"""

from __future__ import annotations

import numpy as np

from ema_sim.config import load_channel
from ema_sim.io.measured import MeasuredData
from ema_sim.models.second_order import Loac, SecondOrderParams

EFFECT_FIELDS = {  # vocabulary effect -> the model field its parameter lands in
    "time_delay": "delay_s",
    "lag_filter": "command_lag_hz",
    "lag_filter/feedback": "feedback_lag_hz",
    "command_gain": "kb",
    "command_bias": "offset_deg",
    "quantization": "quantization_deg",
    "rate_limit": "rate_limit_dps",
    "static_threshold": "threshold_deg",
    "free_play": "free_play_deg",
    "compliance": "compliance_deg_per_kinlb",
    "hysteretic_damping": "hysteresis_h_lb_per_in",
    "time_delay/feedback": "feedback_delay_s",
    "compliance/feedback": "lvdt_compliance_deg_per_kinlb",
    "servo_integral": "integral_hz",
    "servo_compliance": "servo_compliance_deg_per_kinlb",
    "load_rate_limit": "k2_dps_per_lb",
}
"""Single-parameter effects: vocabulary effect (/where) → the model field its parameter lands in. The
multi-parameter ones (linkage_mode, nonlinear_compliance, current_limit, feedback_filter) are given as
a dict of model fields."""
FRAME_S = 0.005


def command_sequence(t: np.ndarray, duration_s: float = 60.0) -> np.ndarray:
    """Steps (±1°, 5°, 20°, 0.5°), a 0.5–12 Hz sweep at ±1°, a 0→2→0° ramp; fitted into ``duration_s``.

    At 60 s: steps over 0–13 s, the sweep over 14–34 s, the ramp (0.2 °/s) over 36–56 s.
    """
    k = duration_s / 60.0
    cmd = np.zeros_like(t)
    steps = [(1.0, 1.0), (2.0, -1.0), (3.0, 0.0), (4.0, 5.0), (5.5, 0.0), (7.0, 20.0), (9.0, 0.0), (11.0, 0.5),
             (12.0, 0.0)]
    for start, value in steps:
        cmd = np.where(t >= start * k, value, cmd)
    t0, span = 14.0 * k, 20.0 * k
    sweep = (t >= t0) & (t < t0 + span)
    ts = np.clip(t - t0, 0.0, span)
    rate = np.log(12.0 / 0.5) / span
    cmd = np.where(sweep, np.sin(2 * np.pi * 0.5 * np.expm1(rate * ts) / rate), cmd)
    r0, half = 36.0 * k, 10.0 * k
    tr = t - r0
    ramp = (tr >= 0.0) & (tr < 2 * half)
    cmd = np.where(ramp, np.where(tr < half, 2.0 * tr / half, 2.0 - 2.0 * (tr - half) / half), cmd)
    return np.where(t >= r0 + 2 * half, 0.0, cmd)


def load_sequence(t: np.ndarray, amp_inlb: float = 600.0) -> np.ndarray:
    """A slow ±amp sinusoid (0.1 Hz) with ±25 % square reversals at 0.37 Hz on top."""
    return amp_inlb * (np.sin(2 * np.pi * 0.1 * t) + 0.25 * np.sign(np.sin(2 * np.pi * 0.37 * t + 0.4)))


def truth_params(effects: dict[str, float | dict[str, float]], *, channel: str = "left_wing", wn_rad_s: float = 56.5,
                 zeta: float = 0.65, **extra: float) -> SecondOrderParams:
    """The basic second order plus the named effects (vocabulary names → model parameters)."""
    values: dict[str, float] = {}
    for name, v in effects.items():
        values.update(v if isinstance(v, dict) else {EFFECT_FIELDS[name]: v})
    if "hysteretic_damping" in effects:
        values["hysteresis_freq_hz"] = 0.1
    return SecondOrderParams.basic(load_channel(channel), wn_rad_s=wn_rad_s, zeta=zeta, **values, **extra)


def make_record(
    effects: dict[str, float | dict[str, float]],
    *,
    seed: int = 0,
    noise_deg: tuple[float, float] = (0.003, 0.002),
    hm_noise_inlb: float = 0.1,
    load_amp_inlb: float = 600.0,
    duration_s: float = 60.0,
    sample_hz: float = 1000.0,
    outputs: tuple[str, ...] = ("position_deg", "surface_deg"),
    reverse_load_column: bool = False,
    channel: str = "left_wing",
    resolution_deg: float = 0.0,
    **truth: float,
) -> MeasuredData:
    """A record of the truth model with ``effects`` and sensor noise (seeded); outputs logged in counts of
    ``resolution_deg`` when it is not 0 (a coarse sensor)."""
    rng = np.random.default_rng(seed)
    frames = np.arange(round(duration_s / FRAME_S)) * FRAME_S
    cmd = command_sequence(frames, duration_s)
    hm = load_sequence(frames, load_amp_inlb)
    model = Loac(channel, params=truth_params(effects, channel=channel, **truth))
    model.trim(cmd[0], hm[0])
    t = np.arange(round(duration_s * sample_hz)) / sample_hz
    rec = model.run(frames, cmd, hm, sample_times=t, end_s=float(t[-1]))
    held = np.searchsorted(frames, t + 1e-9, side="right") - 1
    measured_hm = hm[held] + rng.normal(0.0, hm_noise_inlb, t.size)
    cols: dict[str, np.ndarray | None] = {"position_deg": None, "surface_deg": None}
    for name, sigma in zip(("position_deg", "surface_deg"), noise_deg, strict=True):
        if name in outputs:
            clean = rec.position_deg[0] if name == "position_deg" else rec.surface_deg[0]
            cols[name] = clean + rng.normal(0.0, sigma, t.size)
            if resolution_deg > 0.0:
                cols[name] = np.round(cols[name] / resolution_deg) * resolution_deg
    return MeasuredData(
        time_s=t,
        command_deg=cmd[held],
        hinge_moment_inlb=-measured_hm if reverse_load_column else measured_hm,
        metadata={"channel": channel, "generator": "test/identgen.py", "effects": repr(effects)},
        source=f"identgen(seed={seed})",
        **cols,
    )


def hoad3_record(*, seed: int = 0, duration_s: float = 30.0, surface_noise_deg: float = 0.002,
                 load_amp_inlb: float = 600.0, channel: str = "left_wing", **overrides: float) -> MeasuredData:
    """The same test sequence run on HOAD3 (its own LVDT noise and 5 mV quantization), with an external
    surface sensor's noise added: the 'real actuator' a second-order model is identified against.
    ``overrides`` are HOAD3 parameters other than its channel's (an actuator off its declared values)."""
    from ema_sim.models import create  # noqa: PLC0415 - only this generator needs the high-order family

    rng = np.random.default_rng(seed)
    frames = np.arange(round(duration_s / FRAME_S)) * FRAME_S
    cmd = command_sequence(frames, duration_s)
    hm = load_sequence(frames, load_amp_inlb)
    model = create("hoad3", channel, seed=seed, **overrides)
    model.trim(cmd[0], hm[0])
    t = np.arange(round(duration_s * 1000.0)) / 1000.0
    rec = model.run(frames, cmd, hm, sample_times=t, end_s=float(t[-1]))
    held = np.searchsorted(frames, t + 1e-9, side="right") - 1
    return MeasuredData(
        time_s=t,
        command_deg=cmd[held],
        position_deg=rec.position_deg[0],
        surface_deg=rec.surface_deg[0] + rng.normal(0.0, surface_noise_deg, t.size),
        hinge_moment_inlb=hm[held] + rng.normal(0.0, 0.1, t.size),
        metadata={"channel": channel, "model": "hoad3", "generator": "test/identgen.py"},
        source=f"hoad3(seed={seed})",
    )
