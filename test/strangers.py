"""Held-out records for ``ema identify``: another plant, another logger, kept out of development.

:mod:`fuzzgen` is the corpus the identification is developed against; this one is only evaluated.
Its plant shares nothing with either: a voltage-driven DC motor on a lead screw under a PID position
loop with integrator windup and a PWM dead band, a screw whose friction depends on whether the load
aids or opposes the motion, a potentiometer that bows and warms, logged in millimetres or degrees by
a rig that stamps integer milliseconds and profiles its demands. Servos are tuned anywhere from sluggish
to ringing, so some never settle within a hold.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

PLANT_S = 2e-4


@dataclass
class Rig:
    """One draw: the servo, the screw, the pot, the logger and the demand, its oddities listed."""

    seed: int
    kp: float
    ki: float
    kd: float
    volts: float
    dead_v: float
    motor_tau_s: float
    speed_per_v: float
    aid_friction: float
    oppose_friction: float
    spring: float
    bow: float
    warm_per_s: float
    counts: float
    noise: float
    rate_hz: float
    ms_stamps: bool
    duration_s: float
    demand: str
    unit: str
    oddities: list[str] = field(default_factory=list)


def recipe(seed: int, *, short: bool = True) -> Rig:
    """Draw one rig (its oddities named in plain words, for the evaluation table)."""
    rng = np.random.default_rng(7_000_000 + seed)
    odd: list[str] = []
    kp = float(rng.uniform(2.0, 30.0))
    ki = float(rng.choice([0.0, rng.uniform(5.0, 120.0)]))
    kd = float(rng.uniform(0.0, 0.4))
    if ki > 60.0 or kd < 0.05:
        odd.append("ringing or slow-settling servo")
    dead = float(rng.choice([0.0, rng.uniform(0.2, 1.5)]))
    if dead:
        odd.append("PWM dead band")
    aid, opp = float(rng.uniform(0.0, 2.0)), float(rng.uniform(0.0, 6.0))
    if abs(aid - opp) > 1.5:
        odd.append("load-direction friction")
    spring = float(rng.choice([0.0, rng.uniform(0.5, 6.0)]))
    if spring:
        odd.append("return spring")
    bow = float(rng.choice([0.0, rng.uniform(-0.01, 0.01)]))
    if bow:
        odd.append("bowed potentiometer")
    warm = float(rng.choice([0.0, 0.0, rng.uniform(-0.01, 0.01)]))
    if warm:
        odd.append("warming potentiometer")
    rate = float(rng.choice([50.0, 70.0, 100.0, 200.0, 500.0]))
    ms = bool(rng.uniform() < 0.6)
    if ms:
        odd.append("integer-ms stamps")
    counts = float(rng.choice([0.0, 0.01, 0.02]))
    if counts:
        odd.append("counts")
    return Rig(seed, kp, ki, kd, float(rng.uniform(12.0, 28.0)), dead, float(rng.uniform(0.005, 0.05)),
               float(rng.uniform(2.0, 12.0)), aid, opp, spring, bow, warm, counts,
               float(rng.choice([0.0, 0.003, 0.02])), rate, ms,
               float(rng.uniform(3.0, 8.0)) if short else float(rng.uniform(15.0, 60.0)),
               str(rng.choice(["profiled squares", "prbs", "staircase", "chirp", "multisine"])),
               str(rng.choice(["mm", "deg"])), odd)


def _demand(r: Rig, t: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    amp = float(rng.uniform(1.0, 8.0))
    if r.demand == "profiled squares":
        period, ramp = float(rng.uniform(0.6, 2.0)), float(rng.uniform(0.05, 0.2))
        phase = np.mod(t, period) / period
        edge = np.clip(phase * period / ramp, 0, 1) - np.clip((phase - 0.5) * period / ramp, 0, 1)
        return amp * (2 * edge - 1)
    if r.demand == "prbs":
        bits = rng.integers(0, 2, int(t[-1] / 0.1) + 2)
        return amp * (2.0 * bits[(t / 0.1).astype(int)] - 1.0)
    if r.demand == "staircase":
        levels = np.round(rng.uniform(-amp, amp, int(t[-1] / 0.5) + 2), 1)
        return levels[(t / 0.5).astype(int)]
    if r.demand == "chirp":
        f0, f1 = 0.2, float(rng.uniform(4.0, 15.0))
        return amp * 0.5 * np.sin(2 * np.pi * (f0 * t + (f1 - f0) * t**2 / (2 * t[-1])))
    freqs = rng.uniform(0.2, 6.0, 4)
    return amp * 0.3 * np.sum([np.sin(2 * np.pi * f * t + rng.uniform(0, 6.3)) for f in freqs], axis=0)


def _simulate(r: Rig, t: np.ndarray, u: np.ndarray, load: np.ndarray) -> np.ndarray:
    """Motor speed follows the PWM volts through a lag; friction opposes it harder when the load opposes."""
    x = w = integ = 0.0
    prev_e = 0.0
    out = np.empty_like(t)
    for i in range(t.size):
        e = u[i] - x
        integ = float(np.clip(integ + e * PLANT_S, -r.volts / max(r.ki, 1e-9), r.volts / max(r.ki, 1e-9)))
        v = r.kp * e + r.ki * integ + r.kd * (e - prev_e) / PLANT_S
        prev_e = e
        v = float(np.clip(v, -r.volts, r.volts))
        v = math.copysign(max(abs(v) - r.dead_v, 0.0), v)
        drive = r.speed_per_v * v - r.spring * x + load[i]
        fric = r.aid_friction if load[i] * w > 0 else r.oppose_friction
        target = drive - math.copysign(min(fric, abs(drive)), drive) if w == 0.0 else drive - fric * math.copysign(1, w)
        w += (target - w) * PLANT_S / r.motor_tau_s
        if abs(w) < 1e-3 and abs(drive) <= fric:
            w = 0.0
        x += w * PLANT_S
        out[i] = x
    return out


def record(seed: int, *, short: bool = True) -> tuple[Rig, dict[str, np.ndarray]]:
    """One record: the rig and its logged columns (contract names, in its unit)."""
    r = recipe(seed, short=short)
    rng = np.random.default_rng(8_000_000 + seed)
    t = np.arange(0.0, r.duration_s, PLANT_S)
    u = _demand(r, t, rng)
    load = float(rng.uniform(0.0, 4.0)) * np.sin(2 * np.pi * float(rng.uniform(0.05, 0.5)) * t)
    x = _simulate(r, t, u, load)
    inst = np.arange(0.01, r.duration_s - 0.01, 1.0 / r.rate_hz)
    inst = inst + rng.uniform(0.0, 0.3 / r.rate_hz, inst.size)
    idx = np.clip(np.round(inst / PLANT_S).astype(int), 0, t.size - 1)
    pos = x[idx] * (1.0 + r.bow * x[idx]) + r.warm_per_s * inst + rng.normal(0.0, r.noise or 1e-12, inst.size)
    if r.counts:
        pos = np.round(pos / r.counts) * r.counts
    unit = r.unit
    if r.ms_stamps:
        stamps = np.round(inst * 1e3)
        keep = np.concatenate([[True], np.diff(stamps) > 0])
        return r, {"time_ms": stamps[keep] - stamps[0], f"command_{unit}": u[idx][keep],
                   f"position_{unit}": pos[keep]}
    return r, {"time_s": inst - inst[0], f"command_{unit}": u[idx], f"position_{unit}": pos}


def write(cols: dict[str, np.ndarray], path: Path) -> Path:
    """The columns as a CSV the contract reads."""
    names = list(cols)
    lines = [",".join(names)]
    lines += [",".join(f"{v:.9g}" for v in row) for row in zip(*(cols[n] for n in names), strict=True)]
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path
