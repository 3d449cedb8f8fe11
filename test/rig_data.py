"""Records shaped like a small industrial EMA's bench logs, generated with a known truth.

What such logs look like (issue 14): 70–100 Hz with jittery time stamps in whole milliseconds, the
position logged in counts of 0.01, profiled trapezoid demands from the drive's profile generator,
rotary ±80° travel (or millimetres for linear ones), no hinge moment, and a demand that the logger
*samples* (the drive follows its own demand between log samples, so the position may move at the
very sample where the logged demand changes) rather than holds.

The truth is a second-order actuator with a rate limit (``loada`` at 2 kHz, every element of the
figure-26 pipeline but ωn, ζ, rate limit and delay switched off), driven by the demand on a 1 ms grid.
The logger reads demand and position at its own jittery instants and writes the integer-millisecond
stamp of each read.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ema_sim.io.measured import MeasuredData
from ema_sim.models import create

FINE_S = 0.001
"""The drive's own demand and the truth run on this grid."""


@dataclass(frozen=True)
class Actuator:
    """The truth: a rate-limited second order behind a delay, with a wide travel."""

    wn_rad_s: float = 40.0
    zeta: float = 0.7
    rate_dps: float = 100.0
    delay_s: float = 0.002
    travel_deg: float = 90.0


def trapezoid_moves(targets_deg: list[float], *, speed_dps: float, accel_dps2: float, dwell_s: float,
                    start_deg: float = 0.0, lead_s: float = 0.5) -> tuple[np.ndarray, np.ndarray]:
    """A profile generator's demand on the fine grid: trapezoid velocity moves to each target, dwelling between."""
    segments = [np.full(round(lead_s / FINE_S), start_deg)]
    pos = start_deg
    for target in targets_deg:
        dist = abs(target - pos)
        sign = np.sign(target - pos)
        v = min(speed_dps, np.sqrt(dist * accel_dps2))
        t_acc = v / accel_dps2
        t_move = dist / v + t_acc if v > 0 else 0.0
        tt = np.arange(0.0, t_move, FINE_S)
        s = np.where(tt < t_acc, 0.5 * accel_dps2 * tt**2,
                     np.where(tt < t_move - t_acc, 0.5 * accel_dps2 * t_acc**2 + v * (tt - t_acc),
                              dist - 0.5 * accel_dps2 * np.clip(t_move - tt, 0, None) ** 2))
        segments += [pos + sign * s, np.full(round(dwell_s / FINE_S), target)]
        pos = target
    u = np.concatenate(segments)
    return np.arange(u.size) * FINE_S, u


def square_wave(amp_deg: float, freq_hz: float, cycles: int, *, lead_s: float = 0.5,
                phase_s: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """A square wave of ``amp_deg`` about zero, its edges on the fine grid (``phase_s`` shifts them)."""
    t = np.arange(0.0, lead_s + cycles / freq_hz + 0.5, FINE_S)
    ph = (t - lead_s - phase_s) * freq_hz
    u = np.where((ph >= 0) & (ph < cycles), amp_deg * np.where(ph % 1.0 < 0.5, 1.0, -1.0), 0.0)
    return t, u


def sine_sweep(amp_deg: float, f0_hz: float, f1_hz: float, sweep_s: float, *, lead_s: float = 1.0
               ) -> tuple[np.ndarray, np.ndarray]:
    """A logarithmic sine sweep on the fine grid."""
    t = np.arange(0.0, lead_s + sweep_s + 1.0, FINE_S)
    tau = np.clip(t - lead_s, 0.0, sweep_s)
    k = np.log(f1_hz / f0_hz) / sweep_s
    phase = 2 * np.pi * f0_hz * (np.exp(k * tau) - 1.0) / k
    return t, np.where((t >= lead_s) & (t <= lead_s + sweep_s), amp_deg * np.sin(phase), 0.0)


def truth(t: np.ndarray, u: np.ndarray, act: Actuator) -> np.ndarray:
    """The actuator's position on the fine grid, from rest at the first demand."""
    model = create("loada", "left_wing", rate_hz=2000.0, wn_rad_s=act.wn_rad_s, zeta=act.zeta,
                   rate_limit_dps=act.rate_dps, delay_s=act.delay_s, position_min_deg=-act.travel_deg,
                   position_max_deg=act.travel_deg, kb=0.0, offset_deg=0.0, quantization_deg=0.0,
                   free_play_deg=0.0, kcp_per_kinlb=0.0, k2_dps_per_lb=0.0)
    model.trim(float(u[0]), 0.0)
    rec = model.run(t, u, np.zeros_like(t), sample_times=t, end_s=float(t[-1]))
    return rec.position_deg[0]


def log_instants(duration_s: float, rate_hz: float, jitter_s: float, rng: np.random.Generator, *,
                 drift: bool = False) -> np.ndarray:
    """When a jittery logger loop reads its inputs.

    A timer-driven loop reads at its nominal instants plus Gaussian jitter (within a third of a
    period); a free-running one (``drift``) waits a jittery period after each read, so its instants
    wander off the grid.
    """
    n = int(duration_s * rate_hz)
    period = 1.0 / rate_hz
    if drift:
        inst = 0.013 + np.cumsum(np.clip(period + rng.normal(0.0, jitter_s, n), 0.3 * period, None))
    else:
        inst = 0.013 + period * np.arange(n) + np.clip(rng.normal(0.0, jitter_s, n), -period / 3, period / 3)
    return inst[inst < duration_s - 0.01]


def rig_record(t: np.ndarray, u: np.ndarray, *, act: Actuator | None = None, rate_hz: float = 80.0,
               jitter_s: float = 0.0015, counts: float = 0.01, noise_deg: float = 0.0, sampled: bool = True,
               seed: int = 0, source: str = "rig.csv", drift: bool = False) -> MeasuredData:
    """The bench log of the demand ``u`` (fine grid ``t``): see the module docstring.

    ``sampled``: the logger reads the drive's running demand (it may change between log samples).
    Otherwise the log is the drive's input: the truth is driven by the logged demand, held.
    """
    act = act or Actuator()
    rng = np.random.default_rng(seed)
    inst = log_instants(float(t[-1]), rate_hz, jitter_s, rng, drift=drift)
    idx = np.clip(np.searchsorted(t, inst, side="right") - 1, 0, t.size - 1)
    logged_u = u[idx]
    if sampled:
        y_fine = truth(t, u, act)
    else:
        held = logged_u[np.clip(np.searchsorted(inst, t, side="right") - 1, 0, inst.size - 1)]
        y_fine = truth(t, np.where(t < inst[0], logged_u[0], held), act)
    y = y_fine[idx] + rng.normal(0.0, noise_deg, inst.size) if noise_deg else y_fine[idx]
    if counts:
        y = np.round(y / counts) * counts
        logged_u = np.round(logged_u / counts) * counts
    stamps = np.floor(inst * 1000.0) / 1000.0
    return MeasuredData(time_s=stamps - stamps[0], command_deg=logged_u, position_deg=y, metadata={},
                        source=source)
