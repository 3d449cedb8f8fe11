"""Bench logs of small industrial EMAs, from a plant that is *not* any model identification fits.

The plant is a servo drive as industry builds it, integrated at 10 kHz:

* a profile generator (trapezoid velocity moves to each target, dwelling between), updated at the
  drive's own control rate;
* a cascade controller at the control rate (zero-order held): position P with velocity feed-forward,
  speed limit, velocity PI with anti-windup on a current (torque) limit, a first-order current loop;
* a motor inertia with viscous and Coulomb friction (Karnopp stick-slip: it sticks while the net
  torque stays below the breakaway level), a compliant shaft to a load inertia (the resonance), an
  optional unmeasured spring load (a return spring or gravity arm);
* the position feedback on the motor side or the load side.

The logger reads the drive's *running* demand and the logged position at its own jittery instants
(70–100 Hz, timer-driven) and writes integer-millisecond stamps; the position is written in counts
(0.01° or 0.01 mm). There is no hinge-moment column: the log has what such rigs log.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numba as nb
import numpy as np

from ema_sim.io.measured import MeasuredData

SIM_S = 1e-4


@dataclass(frozen=True)
class Drive:
    """One actuator and its drive (output-side units: deg or mm, inertias normalised)."""

    resonance_hz: float = 35.0
    resonance_zeta: float = 0.05
    load_share: float = 0.4
    """Load inertia / total inertia."""
    position_bw_hz: float = 5.0
    velocity_bw_hz: float = 25.0
    accel_limit: float = 1500.0
    """Current limit as an acceleration of the whole inertia, unit/s²."""
    speed_limit: float = 150.0
    coulomb_share: float = 0.03
    """Coulomb friction as a share of the current limit (breakaway 1.3× that)."""
    viscous: float = 0.4
    """Viscous friction, 1/s (acceleration per unit of speed)."""
    current_tau_s: float = 5e-4
    control_hz: float = 2000.0
    feedforward: float = 0.8
    load_side_feedback: bool = True
    log_load: bool = False
    """Log the load-side position (an output sensor outside the loop) whatever the loop closes on."""
    spring: float = 0.0
    """Unmeasured spring load, acceleration per unit of position (1/s²)."""


@nb.njit(cache=True)
def _simulate(ref, ref_rate, n_sub, j_m, j_l, k_s, c_s, kp, kff, vmax, kv, ki, imax, tau_i, tc, b,
              spring, load_fb, log_load, dt):
    """Integrate the plant; ``ref`` is the demand at each control tick (held ``n_sub`` steps)."""
    n = ref.size * n_sub
    out = np.empty(n)
    th_m = ref[0]
    th_l = ref[0]
    w_m = 0.0
    w_l = 0.0
    cur = 0.0
    integ = 0.0
    i_ref = 0.0
    for k in range(ref.size):
        fb = th_l if load_fb else th_m
        w_fb = w_m  # the speed loop closes on the motor's own encoder (collocated)
        v_ref = kp * (ref[k] - fb) + kff * ref_rate[k]
        v_ref = min(max(v_ref, -vmax), vmax)
        ev = v_ref - w_fb
        raw = kv * ev + integ
        i_ref = min(max(raw, -imax), imax)
        if raw == i_ref or raw * ev < 0.0:  # anti-windup: integrate only when not pushing into the limit
            integ += ki * ev * n_sub * dt
        for s in range(n_sub):
            cur += (i_ref - cur) * dt / tau_i
            shaft = k_s * (th_m - th_l) + c_s * (w_m - w_l)
            drive = cur - shaft - b * w_m * (j_m + j_l)
            if w_m == 0.0 and abs(drive) <= 1.3 * tc:
                acc_m = 0.0
            else:
                sgn = np.sign(w_m) if w_m != 0.0 else np.sign(drive)
                acc_m = (drive - tc * sgn) / j_m
                if w_m != 0.0 and np.sign(w_m + acc_m * dt) != np.sign(w_m):
                    acc_m = -w_m / dt  # stops within the step: sticks
            acc_l = (shaft - spring * th_l * (j_m + j_l)) / j_l
            w_m += acc_m * dt
            w_l += acc_l * dt
            th_m += w_m * dt
            th_l += w_l * dt
            out[k * n_sub + s] = th_l if load_fb or log_load else th_m
    return out


def profile(targets: list[float], *, speed: float, accel: float, dwell_s: float, start: float = 0.0,
            lead_s: float = 0.6, tick_s: float = 5e-4) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A profile generator's demand and demand rate at each control tick: trapezoid moves to each target."""
    pos, segs, rates = start, [np.full(round(lead_s / tick_s), start)], [np.zeros(round(lead_s / tick_s))]
    for target in targets:
        dist = abs(target - pos)
        sign = np.sign(target - pos)
        v = min(speed, np.sqrt(dist * accel))
        t_acc = v / accel if v > 0 else 0.0
        t_move = dist / v + t_acc if v > 0 else 0.0
        tt = np.arange(0.0, t_move, tick_s)
        s = np.where(tt < t_acc, 0.5 * accel * tt**2,
                     np.where(tt < t_move - t_acc, 0.5 * accel * t_acc**2 + v * (tt - t_acc),
                              dist - 0.5 * accel * np.clip(t_move - tt, 0, None) ** 2))
        r = np.where(tt < t_acc, accel * tt, np.where(tt < t_move - t_acc, v, accel * np.clip(t_move - tt, 0, None)))
        segs += [pos + sign * s, np.full(round(dwell_s / tick_s), target)]
        rates += [sign * r, np.zeros(round(dwell_s / tick_s))]
        pos = target
    u = np.concatenate(segs)
    return np.arange(u.size) * tick_s, u, np.concatenate(rates)


def steps(levels: list[float], *, dwell_s: float, lead_s: float = 0.6,
          tick_s: float = 5e-4) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A demand that jumps between levels (no profile), dwelling ``dwell_s`` on each."""
    u = np.concatenate([np.zeros(round(lead_s / tick_s))] + [np.full(round(dwell_s / tick_s), v) for v in levels])
    return np.arange(u.size) * tick_s, u, np.zeros_like(u)


def run_drive(drive: Drive, tick_t: np.ndarray, ref: np.ndarray, ref_rate: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The feedback position at every 0.1 ms, driven by the demand at each control tick."""
    tick = 1.0 / drive.control_hz
    n_sub = round(tick / SIM_S)
    j = 1.0
    j_l = drive.load_share * j
    j_m = j - j_l
    j_eq = j_m * j_l / j
    w_r = 2 * np.pi * drive.resonance_hz
    k_s = w_r**2 * j_eq
    c_s = 2 * drive.resonance_zeta * w_r * j_eq
    w_v = 2 * np.pi * drive.velocity_bw_hz
    kv = w_v * j
    ki = kv * w_v / 4.0
    kp = 2 * np.pi * drive.position_bw_hz
    imax = drive.accel_limit * j
    tc = drive.coulomb_share * imax
    y = _simulate(ref.astype(float), ref_rate.astype(float), n_sub, j_m, j_l, k_s, c_s, kp, drive.feedforward,
                  drive.speed_limit, kv, ki, imax, drive.current_tau_s, tc, drive.viscous, drive.spring,
                  drive.load_side_feedback, drive.log_load, SIM_S)
    t = tick_t[0] + SIM_S * np.arange(y.size)
    return t, y


def bench_log(drive: Drive, tick_t: np.ndarray, ref: np.ndarray, ref_rate: np.ndarray, *, rate_hz: float = 80.0,
              jitter_s: float = 0.0012, counts: float = 0.01, noise: float = 0.0, seed: int = 0,
              unit: str = "deg", held: bool = False, source: str = "bench.tsv") -> MeasuredData:
    """The logger's record of the drive following ``ref`` (see the module docstring).

    ``held``: the drive's demand is the logged one, held between log samples (a host sending set
    points at the log rate), instead of a running profile that the logger samples.
    """
    rng = np.random.default_rng(seed)
    end = float(tick_t[-1])
    period = 1.0 / rate_hz
    n = int(end * rate_hz) - 1
    inst = 0.011 + period * np.arange(n) + np.clip(rng.normal(0.0, jitter_s, n), -period / 3, period / 3)
    inst = inst[inst < end - 0.02]
    idx = np.clip(np.searchsorted(tick_t, inst, side="right") - 1, 0, tick_t.size - 1)
    logged = ref[idx]
    if held:
        hold = np.clip(np.searchsorted(inst, tick_t, side="right") - 1, 0, inst.size - 1)
        ref = np.where(tick_t < inst[0], logged[0], logged[hold])
        ref_rate = np.zeros_like(ref)
    t, y = run_drive(drive, tick_t, ref, ref_rate)
    pos = np.interp(inst, t, y)
    if noise:
        pos = pos + rng.normal(0.0, noise, pos.size)
    pos = np.round(pos / counts) * counts
    logged = np.round(logged / counts) * counts
    stamps = np.floor(inst * 1000.0) / 1000.0
    return MeasuredData(time_s=stamps - stamps[0], command_deg=logged, position_deg=pos, source=source, unit=unit)


def write_tab(data: MeasuredData, path) -> None:
    """The log as the rig writes it: tab separated, time in integer ms, positions to the count."""
    rows = [f"{round(1e3 * a)}\t{b:.2f}\t{c:.2f}" for a, b, c in zip(data.time_s, data.command_deg,
                                                                     data.position_deg, strict=True)]
    path.write_text("time\tdemand\tactual\n" + "\n".join(rows) + "\n", encoding="utf-8")


__all__ = ["Drive", "bench_log", "profile", "replace", "run_drive", "steps", "write_tab"]
