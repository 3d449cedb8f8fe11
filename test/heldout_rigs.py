"""Held-out "stranger-shaped" bench records of electromechanical actuators that are not the X-43A's.

A plant of its own, written from physics and from nothing in ``ema_sim`` (numpy only), so that
``ema analyze`` and ``ema identify`` can be judged on records nobody tunes them against:

- a brushless motor whose field-oriented current loop is a first-order lag (time constant ``tau_i``)
  behind a current limit ``i_max``;
- a speed loop, P or PI (``kv``, ``ti_v``) with anti-windup, behind a speed limit ``v_max`` (output units/s);
- a position loop, P with optional integral (``kp``, ``ki``) and velocity feedforward (``vff``), closed on the
  drive's own encoder (counts ``enc``);
- rotor + screw (or gearbox) inertia and the load's inertia, rigid, or as two masses through a backlash
  (``gap``) with a contact stiffness; Coulomb + Stribeck + viscous friction (Karnopp stick-slip);
- an optional load torque (a spring, a hinge-moment-like ``k_spring``) and a rolling-noise torque;
- a transport delay on the demand that may wander, and a loop gain that may decay over the record.

The linear part of each mass (current lag, inertia, viscous friction) is integrated exactly over each
drive tick (zero-order-hold discretisation by matrix exponential); friction, contact and load torques and the
current demand are held over the tick, as a digital drive holds them. The tick is 0.1-0.25 ms.

A logger then samples the drive at 70-250 Hz: its own jittering instants, integer-millisecond stamps, the
demand as the drive had it at that instant (``sampled``) or the host's command held by its D/A (``held``),
the position in the encoder's counts printed to the logger's digits.

Cases (issue 37's points) and the truth each carries beside the logger's (command logging, stamps, count,
rest noise, measured travel, the current limit's effect against a twin without it):

- ``profiled_square_mm``, ``profiled_square_rotary`` (1): a 0.5 Hz square through the drive's profile generator
  (trapezoid, jerk-limited), logged sampled at 70/80/100 Hz; the rotary one geared, on a spring load with its
  hinge moment logged. Truth: ``lag_ms`` (the servo lags), ``harmonics`` (gain, phase, delay at 0.5/1.5/2.5 Hz).
- ``rate_limit_squares_mm``, ``small_steps_mm``, ``rate_limit_sweep_mm`` (2): one speed-limited actuator; 10 mm
  squares and a ±5 mm sweep plateau at ``speed_limit`` (measured on the fine step), 1 mm steps never reach it
  (``small_signal`` wn, zeta).
- ``settle_exact_mm`` (3): PI position loop, 1 mm squares logged in 0.01 mm: settles on the command, no
  threshold, dead band or free play.
- ``limit_cycle_mm`` (4): backlash inside a P position loop closed on the load's scale: ``limit_cycle``
  (frequency 35-40 Hz, amplitude ±0.03-0.045 mm, current rms). ``noise_grows_sweep_mm`` (4): rolling noise
  that grows with speed in a sweep, quiet rests (``sensor_noise_rms``, ``motion_noise_rms``).
- ``coarse_encoder_rotary``, ``counts_001_mm`` (5): an output encoder of 0.05-0.06° logged to 0.01°; a 0.01 mm
  scale. Truth: ``count`` / ``resolution``.
- ``mm_hygiene`` (6): a ±30 mm stroke in mm, no X-43A channel (every record has none).
- ``bandwidth_drift``, ``wandering_delay``, ``jitter_only`` (7): 92 s with the loop gain falling 25 %
  (``bandwidth_hz`` start/end, ``trend``); a transport delay wandering 2-12 ms (``delay_ms``); a clean linear
  servo whose stamps jitter ±2 ms (``effects``: none, ``stamp_error_ms``).

Every case is a function ``case(seed) -> Record`` (``CASES``); a :class:`Record` writes a contract CSV (the
``*_mm`` names of a linear rig need ``--columns``: ``Record.columns_arg``) and a truth JSON computed from
the fine-step simulation. Seeds 0-2 (``DEV_SEEDS``) may be used in unit tests; seeds 100+
(``HELDOUT_SEEDS``) are for ``bench/truthful.py`` only.

    python test/heldout_rigs.py OUTDIR [--set dev|heldout] [--cases a,b]
"""

from __future__ import annotations

import argparse
import json
import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

DEV_SEEDS = (0, 1, 2)
HELDOUT_SEEDS = (100, 101, 102)
TWO_PI = 2.0 * math.pi
INLB_PER_NM = 1.0 / 0.112984829


# ------------------------------------------------------------------------------------------ the plant
@dataclass(frozen=True)
class Drive:
    """A servo drive and its mechanism; positions in the output unit (mm of a ball screw, or degrees of a gearbox)."""

    unit: str = "mm"
    scale: float = 5.0 / TWO_PI
    """Output units per motor radian (ball screw lead 5 mm/rev; a gearbox: degrees(1)/ratio)."""
    kt: float = 0.12
    """Torque constant, N·m/A."""
    jm: float = 3.0e-5
    """Rotor + screw (or input gear) inertia, kg·m²."""
    jl: float = 1.3e-5
    """Load inertia reflected to the motor, kg·m²."""
    b: float = 2.0e-5
    """Viscous friction at the motor, N·m·s/rad."""
    tau_i: float = 2.0e-4
    """Current loop time constant, s."""
    i_max: float = 10.0
    """Current limit, A."""
    kv: float = 0.2
    """Speed loop proportional gain, A per rad/s."""
    ti_v: float = 0.0
    """Speed loop integral time, s (0: P only)."""
    v_max: float = 1.0e9
    """Speed limit on the position loop's output, output units/s."""
    kp: float = 40.0
    """Position loop gain, 1/s."""
    ki: float = 0.0
    """Position loop integral gain, 1/s²."""
    vff: float = 0.0
    """Velocity feedforward of the demand's derivative, fraction."""
    tc: float = 0.0
    """Coulomb friction at the motor, N·m."""
    ts: float = 0.0
    """Breakaway (static) friction at the motor, N·m (>= tc)."""
    ws: float = 5.0
    """Stribeck speed, rad/s."""
    enc: float = 0.0
    """The drive's encoder count, output units (0: ideal)."""
    gap: float = 0.0
    """Backlash between motor and load, total, output units (0: rigid)."""
    k_c: float = 0.0
    """Contact stiffness of the backlash, N·m/rad at the motor."""
    c_c: float = 0.0
    """Contact damping, N·m·s/rad."""
    tl_c: float = 0.0
    """Coulomb friction on the load side (two-mass), N·m at the motor."""
    k_spring: float = 0.0
    """Load spring, N·m at the motor per output unit (positive opposes deflection)."""
    dt: float = 2.5e-4
    """Drive tick, s."""


@dataclass
class Sim:
    """Fine-step truth: time, the demand the loop used, the output, the motor side, current and speed."""

    t: np.ndarray
    demand: np.ndarray
    x: np.ndarray
    xm: np.ndarray
    iq: np.ndarray
    v: np.ndarray
    load_nm: np.ndarray
    drive: Drive | None = None
    used: np.ndarray | None = None
    """The demand the loop used (after a transport delay); ``demand`` is the one sent."""
    kwargs: dict[str, Any] = field(default_factory=dict)


def _expm(m: np.ndarray) -> np.ndarray:
    """Matrix exponential (scaling and squaring of a Taylor series)."""
    norm = float(np.max(np.sum(np.abs(m), axis=1)))
    s = max(0, math.ceil(math.log2(norm / 0.25))) if norm > 0.25 else 0
    a = m / 2.0 ** s
    out = np.eye(len(m))
    term = np.eye(len(m))
    for k in range(1, 20):
        term = term @ a / k
        out = out + term
    for _ in range(s):
        out = out @ out
    return out


def _zoh(a: np.ndarray, b: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    n, m = b.shape
    big = np.zeros((n + m, n + m))
    big[:n, :n] = a
    big[:n, n:] = b
    e = _expm(big * dt)
    return e[:n, :n], e[:n, n:]


def simulate(  # noqa: PLR0912, PLR0915 - one loop on locals, for speed
        d: Drive, demand: np.ndarray, *, ff_v: np.ndarray | None = None, gain: np.ndarray | None = None,
        torque: np.ndarray | None = None) -> Sim:
    """Run the drive on a demand given on its tick grid.

    Parameters
    ----------
    d : Drive
        The drive and mechanism.
    demand : numpy.ndarray
        The position demand at each tick (after any transport delay), output units.
    ff_v : numpy.ndarray, optional
        The demand's speed for the feedforward (default: its differences).
    gain : numpy.ndarray, optional
        A factor on kp, kv and 1/ti_v at each tick (a loop gain that changes).
    torque : numpy.ndarray, optional
        An external torque at the motor at each tick, N·m (a load, a rolling noise).
    """
    n = demand.size
    dt = d.dt
    if ff_v is None:
        ff_v = np.gradient(demand, dt)
    two = d.gap > 0.0
    jmot = d.jm if two else d.jm + d.jl
    a = np.array([[-1.0 / d.tau_i, 0.0, 0.0], [d.kt / jmot, -d.b / jmot, 0.0], [0.0, 1.0, 0.0]])
    bm = np.array([[1.0 / d.tau_i, 0.0], [0.0, 1.0 / jmot], [0.0, 0.0]])
    ad, bd = _zoh(a, bm, dt)
    a11, a21, a22, a31, a32 = (float(ad[0, 0]), float(ad[1, 0]), float(ad[1, 1]), float(ad[2, 0]), float(ad[2, 1]))
    b11, b21, b22, b31, b32 = (float(bd[0, 0]), float(bd[1, 0]), float(bd[1, 1]), float(bd[2, 0]), float(bd[2, 1]))
    scale = d.scale
    kt = d.kt
    kp0, ki, kv0, vff, vmax, imax = d.kp, d.ki, d.kv, d.vff, d.v_max, d.i_max
    kiv0 = d.kv / d.ti_v if d.ti_v > 0 else 0.0
    tc, ts, ws = d.tc, max(d.ts, d.tc), d.ws
    enc = d.enc
    ksp = d.k_spring
    dem = demand.tolist()
    ffl = ff_v.tolist()
    gl = gain.tolist() if gain is not None else None
    tq = torque.tolist() if torque is not None else None
    out_x = np.empty(n)
    out_xm = np.empty(n)
    out_i = np.empty(n)
    out_v = np.empty(n)
    out_t = np.empty(n)
    iq = w = th = 0.0
    th0 = demand[0] / scale
    th = th0
    thl = th0
    wl = 0.0
    iv = 0.0
    ip = 0.0
    exp = math.exp
    floor = math.floor
    # two-mass constants
    jl = d.jl
    gr = 0.5 * d.gap / scale
    kc, cc, tlc = d.k_c, d.c_c, d.tl_c
    for k in range(n):
        g = gl[k] if gl is not None else 1.0
        xl = (thl if two else th) * scale
        xf = floor(xl / enc + 0.5) * enc if enc > 0 else xl
        e = dem[k] - xf
        vr = kp0 * g * e + ip + vff * ffl[k]
        sat = False
        if vr > vmax:
            vr, sat = vmax, True
        elif vr < -vmax:
            vr, sat = -vmax, True
        if ki > 0.0 and not sat:
            ip += ki * g * g * e * dt
        ew = vr / scale - w
        ic = kv0 * g * ew + iv
        if ic > imax:
            ic = imax
        elif ic < -imax:
            ic = -imax
        elif kiv0 > 0.0:
            iv += kiv0 * g * g * ew * dt
        text = tq[k] if tq is not None else 0.0
        if two:
            dd = th - thl
            if dd > gr:
                tcon = kc * (dd - gr) + cc * (w - wl)
                tcon = tcon if tcon > 0.0 else 0.0
            elif dd < -gr:
                tcon = kc * (dd + gr) + cc * (w - wl)
                tcon = tcon if tcon < 0.0 else 0.0
            else:
                tcon = 0.0
            tx = -tcon
        else:
            tcon = 0.0
            tx = text - ksp * th * scale
        # motor friction (Karnopp)
        tn = kt * iq + tx
        stuck = False
        if w == 0.0:
            if abs(tn) <= ts:
                tf, stuck = -tn, True
            else:
                tf = -ts if tn > 0 else ts
        else:
            mag = tc + (ts - tc) * exp(-(w / ws) ** 2) if ts > tc else tc
            tf = -mag if w > 0 else mag
        u = tx + tf
        iq_n = a11 * iq + b11 * ic
        w_n = a21 * iq + a22 * w + b21 * ic + b22 * u
        th_n = th + a31 * iq + a32 * w + b31 * ic + b32 * u
        if stuck:
            w_n, th_n = 0.0, th
        elif (tc > 0.0 or ts > 0.0) and w * w_n < 0.0:
            w_n = 0.0
        if two:
            tl = tcon + text - ksp * thl * scale
            sl = wl if wl != 0.0 else tl
            fl = -tl if wl == 0.0 and abs(tl) <= tlc else (-tlc if sl > 0 else tlc)
            acc = (tl + fl) / jl
            wl_n = wl + acc * dt
            thl = thl + (wl + 0.5 * acc * dt) * dt
            if (wl == 0.0 and abs(tl) <= tlc) or (tlc > 0.0 and wl * wl_n < 0.0):
                wl_n = 0.0
            wl = wl_n
        iq, w, th = iq_n, w_n, th_n
        out_t[k] = k * dt
        out_x[k] = (thl if two else th) * scale
        out_xm[k] = th * scale
        out_i[k] = iq
        out_v[k] = (wl if two else w) * scale
    load = (np.asarray(tq) if tq is not None else np.zeros(n)) - ksp * out_x
    return Sim(out_t, demand.copy(), out_x, out_xm, out_i, out_v, load, d, demand,
               {"ff_v": ff_v, "gain": gain, "torque": torque})


def current_limit_effect(sim: Sim) -> dict[str, float]:
    """How far the output is from the same drive with no current limit (rms, max; output units)."""
    assert sim.drive is not None
    assert sim.used is not None
    if float(np.max(np.abs(sim.iq))) < 0.95 * sim.drive.i_max:
        return {"rms": 0.0, "max": 0.0}
    twin = simulate(replace(sim.drive, i_max=1.0e4), sim.used, **sim.kwargs)
    dx = sim.x - twin.x
    return {"rms": float(np.std(dx)), "max": float(np.max(np.abs(dx)))}


# ----------------------------------------------------------------------------------- demand profiles
def trapezoid_move(tau: np.ndarray, dist: float, vmax: float, amax: float) -> np.ndarray:
    """Displacement at ``tau`` after the start of a rest-to-rest move of ``dist``, limited in speed and acceleration."""
    D = abs(dist)
    out = np.zeros_like(tau)
    if D == 0.0:
        return out
    ta = vmax / amax
    if vmax * ta > D:
        ta = math.sqrt(D / amax)
        vp, tcr = amax * ta, 0.0
    else:
        vp, tcr = vmax, (D - vmax * ta) / vmax
    total = 2 * ta + tcr
    t = np.clip(tau, 0.0, total)
    out = np.where(t < ta, 0.5 * amax * t ** 2,
                   np.where(t < ta + tcr, 0.5 * amax * ta ** 2 + vp * (t - ta), D - 0.5 * amax * (total - t) ** 2))
    return math.copysign(1.0, dist) * out


def moves(t: np.ndarray, times: list[float], levels: list[float], start: float, vmax: float, amax: float,
          jerk_s: float = 0.0) -> np.ndarray:
    """A profile generator's demand: trapezoid moves to each level at each time; jerk-limited by a moving average."""
    x = np.full_like(t, start)
    prev = start
    for tk, lv in zip(times, levels, strict=True):
        x += trapezoid_move(t - tk, lv - prev, vmax, amax) * (t >= tk)
        prev = lv
    if jerk_s > 0.0:
        dt = t[1] - t[0]
        m = max(1, round(jerk_s / dt))
        pad = np.concatenate([np.full(m, x[0]), x])
        c = np.cumsum(pad)
        x = (c[m:] - c[:-m]) / m
    return x


def square_levels(t0: float, t1: float, period: float, lo: float, hi: float) -> tuple[list[float], list[float]]:
    """Switch times and levels of a square wave between lo and hi (first to hi at t0)."""
    times, levels = [], []
    k = 0
    tk = t0
    while tk < t1:
        times.append(tk)
        levels.append(hi if k % 2 == 0 else lo)
        k += 1
        tk = t0 + k * period / 2.0
    return times, levels


def square(x: np.ndarray, t0: float, half: float, first: float, second: float) -> np.ndarray:
    """A square wave from t0 (zero before), ``first`` for ``half`` seconds, then ``second``, and so on."""
    return np.where(((x - t0) // half) % 2 == 0, first, second) * (x >= t0)


def held(t: np.ndarray, t_samples: np.ndarray, values: np.ndarray) -> np.ndarray:
    """The host's command held by its D/A from each sample instant to the next, on the tick grid."""
    idx = np.searchsorted(t_samples, t, side="right") - 1
    return values[np.clip(idx, 0, values.size - 1)] * (idx >= 0) + values[0] * (idx < 0)


def chirp(t: np.ndarray, t0: float, t1: float, f0: float, f1: float, amp: float, log: bool = True) -> np.ndarray:
    """A sine sweep from f0 to f1 between t0 and t1 (zero outside), faded in and out over 0.5 s."""
    tau = np.clip(t - t0, 0.0, t1 - t0)
    span = t1 - t0
    if log:
        k = math.log(f1 / f0) / span
        phase = TWO_PI * f0 * (np.exp(k * tau) - 1.0) / k
    else:
        phase = TWO_PI * (f0 * tau + 0.5 * (f1 - f0) / span * tau ** 2)
    ramp = np.clip(np.minimum(tau, span - tau) / min(0.5, span / 4), 0.0, 1.0)
    y = amp * np.sin(phase) * 0.5 * (1.0 - np.cos(np.pi * ramp))  # half-cosine fade in and out: no jump
    return np.where((t >= t0) & (t <= t1), y, 0.0)


# ------------------------------------------------------------------------------------------- logger
@dataclass(frozen=True)
class Logger:
    """A DAU: its rate, its instants' jitter, its stamps and digits."""

    rate_hz: float = 100.0
    jitter_ms: float = 0.0
    """Peak lateness of the instants (uniform 0..jitter) around the nominal grid."""
    stamp_err_ms: float = 0.0
    """Peak error of the stamps (uniform ±) around the true instants (a software clock)."""
    stamp_res_s: float = 1e-3
    pos_count: float = 0.001
    """The position's count (encoder), output units."""
    pos_digits: int = 3
    cmd_digits: int = 3
    noise: float = 0.0
    """Analog noise on the position (rms) before the counts."""
    cur_noise: float = 0.02
    cur_digits: int = 2


def sample_instants(t_end: float, lg: Logger, rng: np.random.Generator,
                    t_start: float = 0.05) -> tuple[np.ndarray, np.ndarray]:
    """True sample instants and their stamps."""
    n = int((t_end - t_start) * lg.rate_hz)
    nominal = t_start + np.arange(n) / lg.rate_hz
    true = nominal + rng.uniform(0.0, lg.jitter_ms * 1e-3, n) if lg.jitter_ms > 0 else nominal.copy()
    stamp = true + (rng.uniform(-lg.stamp_err_ms, lg.stamp_err_ms, n) * 1e-3 if lg.stamp_err_ms > 0 else 0.0)
    stamp = np.round(stamp / lg.stamp_res_s) * lg.stamp_res_s
    keep = np.concatenate([[True], np.diff(stamp) > 0])
    return true[keep], stamp[keep]


def counts(x: np.ndarray, q: float) -> np.ndarray:
    return np.floor(x / q + 0.5) * q if q > 0 else x


# ------------------------------------------------------------------------------------------- record
@dataclass
class Record:
    """One bench record: its columns as the logger printed them, metadata, and the truth."""

    name: str
    seed: int
    unit: str
    columns: dict[str, np.ndarray]
    digits: dict[str, int]
    metadata: dict[str, str]
    truth: dict[str, Any]
    sim: Sim | None = field(default=None, repr=False)

    @property
    def columns_arg(self) -> str | None:
        """The ``--columns`` mapping the tools need (None for a degrees record with the contract's names)."""
        if self.unit == "deg":
            return None
        return ",".join(f"{c}={c}" for c in self.columns if c.endswith(f"_{self.unit}"))

    def csv_text(self) -> str:
        lines = [f"# {k}: {v}" for k, v in self.metadata.items()]
        names = list(self.columns)
        lines.append(",".join(names))
        cols = [self.columns[c] for c in names]
        digits = [self.digits[c] for c in names]
        for row in zip(*cols, strict=True):
            lines.append(",".join(f"{round(float(v), dg) + 0.0:.{dg}f}" for dg, v in zip(digits, row, strict=True)))
        return "\n".join(lines) + "\n"

    def write(self, folder: str | Path) -> tuple[Path, Path]:
        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        stem = f"{self.name}_s{self.seed}"
        csv_path = folder / f"{stem}.csv"
        csv_path.write_text(self.csv_text(), encoding="utf-8")
        truth = {"case": self.name, "seed": self.seed, "unit": self.unit, "columns_arg": self.columns_arg,
                 "csv": csv_path.name, **self.truth}
        json_path = folder / f"{stem}.truth.json"
        json_path.write_text(json.dumps(_plain(truth), indent=1, allow_nan=False) + "\n", encoding="utf-8")
        return csv_path, json_path


def _plain(v: Any) -> Any:
    if isinstance(v, dict):
        return {str(k): _plain(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_plain(x) for x in v]
    if isinstance(v, (np.floating, float)):
        f = float(v)
        return round(f, 6) if math.isfinite(f) else None
    if isinstance(v, np.integer):
        return int(v)
    if isinstance(v, np.bool_):
        return bool(v)
    return v


def make_record(name: str, seed: int, d: Drive, sim: Sim, lg: Logger, rng: np.random.Generator, *,
                command: str, host_cmd: tuple[np.ndarray, np.ndarray] | None = None, current: bool = True,
                hinge: bool = False, truth: dict[str, Any], metadata: dict[str, str] | None = None) -> Record:
    """Sample the fine-step truth as the logger does and print it.

    ``command``: ``sampled`` (the drive's demand at each instant) or ``held`` (``host_cmd`` = the host's
    instants and values, the same clock as the logger's).
    """
    if host_cmd is not None:
        t_true, stamps = host_cmd[2], host_cmd[3]  # type: ignore[misc]
    else:
        t_true, stamps = sample_instants(sim.t[-1] - 0.01, lg, rng)
    if command == "sampled":
        cmd = np.interp(t_true, sim.t, sim.demand)
    else:
        assert host_cmd is not None
        cmd = host_cmd[1]
    pos = np.interp(t_true, sim.t, sim.x)
    if lg.noise > 0:
        pos = pos + rng.normal(0.0, lg.noise, pos.size)
    pos = counts(pos, lg.pos_count)
    u = d.unit
    cols: dict[str, np.ndarray] = {"time_s": stamps, f"command_{u}": np.round(cmd, lg.cmd_digits),
                                   f"position_{u}": np.round(pos, lg.pos_digits)}
    digits = {"time_s": 3 if lg.stamp_res_s >= 1e-3 else 4, f"command_{u}": lg.cmd_digits,
              f"position_{u}": lg.pos_digits}
    if current:
        cur = np.interp(t_true, sim.t, sim.iq) + rng.normal(0.0, lg.cur_noise, t_true.size)
        cols["current_a"] = cur
        digits["current_a"] = lg.cur_digits
    if hinge:
        hm = np.interp(t_true, sim.t, sim.load_nm) * truth.get("inlb_per_motor_nm", 1.0)
        cols["hinge_moment_inlb"] = hm + rng.normal(0.0, 0.3, hm.size)
        digits["hinge_moment_inlb"] = 1
    kind = "linear ball-screw" if u == "mm" else "rotary geared"
    meta = {"rig": "held-out bench (ema_sim test/heldout_rigs.py)", "actuator": f"generic {kind} EMA"}
    meta.update(metadata or {})
    dts = np.diff(stamps)
    base = {"command_logging": command, "sample_hz_nominal": lg.rate_hz, "stamp_jitter_ms_peak": lg.jitter_ms,
            "stamp_error_ms_peak": lg.stamp_err_ms, "stamp_interval_ms": {"median": float(np.median(dts) * 1e3),
                                                                          "min": float(dts.min() * 1e3),
                                                                          "max": float(dts.max() * 1e3)},
            "position_count": lg.pos_count, "position_digits": lg.pos_digits,
            "resolution": (lg.pos_count if lg.noise < 0.3 * lg.pos_count and lg.pos_count >= 10 ** -lg.pos_digits
                           else None),
            "rest_noise_rms": math.sqrt(lg.noise ** 2 + lg.pos_count ** 2 / 12.0),
            "travel_measured": [float(pos.min()), float(pos.max())], "x43a_channel": None,
            "drive": {k: v for k, v in d.__dict__.items() if isinstance(v, (int, float, str)) and v not in (1e9,)},
            "current_limit_effect": current_limit_effect(sim)}
    base.update(truth)
    return Record(name, seed, u, cols, digits, meta, base, sim)


def host_schedule(t_end: float, lg: Logger, rng: np.random.Generator, fn: Callable[[np.ndarray], np.ndarray],
                  grid: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A host command computed at the logger's instants and held by its D/A on the drive's tick grid.

    Returns (the held demand on the grid, the logged values, the true instants, the stamps)."""
    t_true, stamps = sample_instants(t_end - 0.01, lg, rng)
    vals = np.round(fn(t_true), lg.cmd_digits)
    return held(grid, t_true, vals), vals, t_true, stamps


# ------------------------------------------------------------------------------------------ truths
def lag_truth(sim: Sim, mask: np.ndarray | None = None, max_s: float = 0.05) -> float:
    """The pure delay that best maps the demand onto the output (fine grid, sub-tick by parabola), s."""
    dt = sim.t[1] - sim.t[0]
    m = mask if mask is not None else np.ones_like(sim.t, bool)
    lags = np.arange(-int(0.01 / dt), int(max_s / dt) + 1)
    err = []
    for L in lags:
        shifted = np.roll(sim.demand, L)
        err.append(float(np.mean((sim.x[m] - shifted[m]) ** 2)))
    err = np.asarray(err)
    i = int(np.argmin(err))
    if 0 < i < len(err) - 1:
        den = err[i - 1] - 2 * err[i] + err[i + 1]
        frac = 0.5 * (err[i - 1] - err[i + 1]) / den if den > 0 else 0.0
    else:
        frac = 0.0
    return float((lags[i] + frac) * dt)


def harmonic_phase(sim: Sim, f0: float, t0: float, t1: float, harmonics: tuple[int, ...] = (1, 3, 5)) -> dict[str, Any]:
    """Gain and phase (deg) of the output against the demand at harmonics of f0, over whole periods in [t0, t1]."""
    period = 1.0 / f0
    n_per = int((t1 - t0) / period + 1e-9)
    m = (sim.t >= t0) & (sim.t < t0 + n_per * period)
    t = sim.t[m]
    out = {}
    for h in harmonics:
        e = np.exp(-1j * TWO_PI * h * f0 * t)
        x = np.sum(sim.x[m] * e)
        r = np.sum(sim.demand[m] * e)
        hxr = x / r
        out[f"{h * f0:g}"] = {"gain": float(abs(hxr)), "phase_deg": float(np.degrees(np.angle(hxr))),
                              "delay_ms": float(-np.angle(hxr) / (TWO_PI * h * f0) * 1e3)}
    return out


def closed_loop(d: Drive, f: np.ndarray, gain: float = 1.0, delay_s: float = 0.0) -> np.ndarray:
    """The linear (no friction, no limits) closed-loop response position/demand of the rigid drive."""
    s = 1j * TWO_PI * f
    j = d.jm + d.jl
    gi = 1.0 / (d.tau_i * s + 1.0)
    p = d.kt / (j * s + d.b)
    cv = d.kv * gain * (1.0 + (gain / (d.ti_v * s) if d.ti_v > 0 else 0.0))
    tw = cv * gi * p / (1.0 + cv * gi * p)
    cp = d.kp * gain + (d.ki * gain ** 2 / s if d.ki > 0 else 0.0)
    h = (tw * cp / s + d.vff * tw) / (1.0 + tw * cp / s)
    return h * np.exp(-s * delay_s)


def bandwidth_hz(d: Drive, gain: float = 1.0) -> float:
    """The -3 dB frequency of the linear closed loop."""
    f = np.logspace(-1, 3, 4000)
    h = np.abs(closed_loop(d, f, gain))
    below = np.nonzero(h < 1.0 / math.sqrt(2.0))[0]
    return float(f[below[0]]) if below.size else float("nan")


def _unit_step(t: np.ndarray, wn: float, z: np.ndarray) -> np.ndarray:
    """Unit step responses of second orders (one row per damping ratio in ``z``) at times ``t``."""
    out = np.empty((z.size, t.size))
    for i, zz in enumerate(z.tolist()):
        if zz < 0.999:
            wd = wn * math.sqrt(1 - zz * zz)
            out[i] = 1 - np.exp(-zz * wn * t) * (np.cos(wd * t) + zz / math.sqrt(1 - zz * zz) * np.sin(wd * t))
        elif zz <= 1.001:
            out[i] = 1 - np.exp(-wn * t) * (1 + wn * t)
        else:
            s1 = -wn * (zz - math.sqrt(zz * zz - 1))
            s2 = -wn * (zz + math.sqrt(zz * zz - 1))
            out[i] = 1 + (s2 * np.exp(s1 * t) - s1 * np.exp(s2 * t)) / (s1 - s2)
    return out


def fit_second_order(t: np.ndarray, y: np.ndarray, step: float) -> tuple[float, float]:
    """Least-squares wn, zeta of a second-order step response to y (a step of size ``step`` at t=0), by grid."""
    k = max(1, t.size // 300)
    t, yn = t[::k], y[::k] / step
    best = (math.inf, 0.0, 0.0)
    zs = np.linspace(0.2, 2.0, 46)
    for wn in np.arange(5.0, 400.0, 4.0):
        e = np.sum((_unit_step(t, float(wn), zs) - yn) ** 2, axis=1)
        i = int(np.argmin(e))
        if e[i] < best[0]:
            best = (float(e[i]), float(wn), float(zs[i]))
    wn0, z0 = best[1], best[2]
    zs = np.linspace(max(0.1, z0 - 0.05), z0 + 0.05, 21)
    for wn in np.arange(max(1.0, wn0 - 4.0), wn0 + 4.0, 0.25):
        e = np.sum((_unit_step(t, float(wn), zs) - yn) ** 2, axis=1)
        i = int(np.argmin(e))
        if e[i] < best[0]:
            best = (float(e[i]), float(wn), float(zs[i]))
    return best[1], best[2]


def small_signal(d: Drive, step: float) -> dict[str, float]:
    """wn and zeta of a second-order fitted to the drive's own small step (fine-step, noise-free)."""
    t = np.arange(0.0, 0.6, d.dt)
    dem = np.where(t >= 0.05, step, 0.0)
    s = simulate(replace(d, enc=0.0), dem)
    m = t >= 0.05
    wn, z = fit_second_order(t[m] - 0.05, s.x[m], step)
    peak_v = float(np.max(np.abs(np.gradient(s.x, d.dt))))
    return {"wn_rad_s": wn, "zeta": z, "step": step, "peak_speed": peak_v}


def rest_segments(demand: np.ndarray, t: np.ndarray, settle_s: float, min_s: float) -> list[tuple[int, int]]:
    """Index ranges where the demand has been still for ``settle_s`` and stays still for at least ``min_s``."""
    still = np.abs(np.gradient(demand)) < 1e-12
    out = []
    i = 0
    n = demand.size
    dt = t[1] - t[0]
    while i < n:
        if still[i]:
            j = i
            while j < n and still[j]:
                j += 1
            a = i + int(settle_s / dt)
            if (j - a) * dt >= min_s:
                out.append((a, j))
            i = j
        else:
            i += 1
    return out


def plateau_speed(sim: Sim, frac: float = 0.9) -> dict[str, Any]:
    """The flat top of |speed| on the large moves of the fine-step truth."""
    v = np.abs(sim.v)
    top = float(np.percentile(v, 99.5))
    flat = v > frac * top
    return {"peak": float(v.max()), "median_near_top": float(np.median(v[flat])) if flat.any() else None,
            "share_of_time_at_plateau": float(np.mean(flat))}


# ------------------------------------------------------------------------------------------ drives
def linear_drive(rng: np.random.Generator, **kw: Any) -> Drive:
    """A ball-screw actuator: 5 mm lead, 20-35 kg."""
    mass = rng.uniform(20.0, 35.0)
    lead = 5.0e-3
    jl = mass * (lead / TWO_PI) ** 2
    base = {"unit": "mm", "scale": 5.0 / TWO_PI, "jm": rng.uniform(2.5e-5, 3.5e-5), "jl": jl,
            "kt": rng.uniform(0.10, 0.14), "b": 3e-5, "tau_i": rng.uniform(1.5e-4, 3e-4), "i_max": 8.0,
            "tc": rng.uniform(0.008, 0.015), "enc": 0.001}
    base["ts"] = base["tc"] * rng.uniform(1.1, 1.4)
    base.update(kw)
    return Drive(**base)


def tune(d: Drive, wv: float, kp: float, ti_factor: float = 4.0) -> Drive:
    """Speed loop bandwidth wv (rad/s) by pole placement on the rigid inertia, and position gain kp."""
    j = d.jm + d.jl
    kv = j * wv / d.kt
    return replace(d, kv=kv, ti_v=ti_factor / wv if ti_factor > 0 else 0.0, kp=kp)


def rotary_drive(rng: np.random.Generator, ratio: float, **kw: Any) -> Drive:
    """A geared rotary actuator: output in degrees."""
    jload = rng.uniform(0.05, 0.12)  # kg m² at the output
    base = {"unit": "deg", "scale": math.degrees(1.0) / ratio, "jm": rng.uniform(1.5e-5, 2.5e-5),
            "jl": jload / ratio ** 2, "kt": rng.uniform(0.08, 0.11), "b": 2e-5, "tau_i": rng.uniform(1.5e-4, 3e-4),
            "i_max": 8.0, "tc": rng.uniform(0.005, 0.01), "enc": 0.001}
    base["ts"] = base["tc"] * rng.uniform(1.1, 1.4)
    base.update(kw)
    return Drive(**base)


def _rng(name: str, seed: int) -> np.random.Generator:
    return np.random.default_rng([seed, sum(map(ord, name))])


# --------------------------------------------------------------------------------------------- cases
def profiled_square_mm(seed: int) -> Record:
    """Point 1: a 0.5 Hz square through the drive's profile generator, logged sampled at 70-100 Hz, ms stamps."""
    name = "profiled_square_mm"
    rng = _rng(name, seed)
    d = tune(linear_drive(rng), wv=rng.uniform(450, 650), kp=rng.uniform(35, 50), ti_factor=5.0)
    d = replace(d, vff=rng.uniform(0.82, 0.9))
    t_end = 24.0
    t = np.arange(0.0, t_end, d.dt)
    amp = rng.uniform(2.0, 5.0)
    times, levels = square_levels(1.0, t_end - 1.0, 2.0, -amp, amp)
    dem = moves(t, times, levels, 0.0, vmax=rng.uniform(60, 120), amax=rng.uniform(800, 2000),
                jerk_s=rng.uniform(0.01, 0.02))
    sim = simulate(d, dem)
    lg = Logger(rate_hz=float(rng.choice([70.0, 80.0, 100.0])), jitter_ms=rng.uniform(1.0, 2.0), pos_count=0.001,
                pos_digits=3, cmd_digits=3)
    m = sim.t > 2.0
    truth = {"point": 1, "what": "sampled profiled square 0.5 Hz; the position lags the demand",
             "lag_ms": lag_truth(sim, m) * 1e3, "phase_sign": "lag",
             "harmonics": harmonic_phase(sim, 0.5, 2.0, times[-1]),
             "square": {"f_hz": 0.5, "amplitude": amp}, "speed_limit": None}
    return make_record(name, seed, d, sim, lg, rng, command="sampled", truth=truth)


def profiled_square_rotary(seed: int) -> Record:
    """Point 1, loaded rotary: a geared actuator on a spring load, profiled 0.5 Hz square, hinge moment logged."""
    name = "profiled_square_rotary"
    rng = _rng(name, seed)
    ratio = rng.uniform(60, 100)
    d = rotary_drive(rng, ratio)
    k_inlb_per_deg = rng.uniform(15.0, 40.0)  # spring at the output
    k_nm_motor = k_inlb_per_deg / INLB_PER_NM / ratio  # N m at the motor per output degree
    d = replace(tune(d, wv=rng.uniform(400, 600), kp=rng.uniform(35, 50), ti_factor=5.0), k_spring=k_nm_motor,
                vff=rng.uniform(0.82, 0.9), enc=360.0 / 2 ** 18)
    t_end = 24.0
    t = np.arange(0.0, t_end, d.dt)
    amp = rng.uniform(4.0, 8.0)
    times, levels = square_levels(1.0, t_end - 1.0, 2.0, -amp, amp)
    dem = moves(t, times, levels, 0.0, vmax=rng.uniform(80, 150), amax=rng.uniform(1000, 3000),
                jerk_s=rng.uniform(0.01, 0.02))
    sim = simulate(d, dem)
    lg = Logger(rate_hz=float(rng.choice([70.0, 80.0, 100.0])), jitter_ms=rng.uniform(1.0, 2.0), pos_count=0.001,
                pos_digits=3, cmd_digits=3)
    m = sim.t > 2.0
    truth = {"point": 1, "what": "sampled profiled square 0.5 Hz on a geared rotary actuator with a spring load",
             "lag_ms": lag_truth(sim, m) * 1e3, "phase_sign": "lag",
             "harmonics": harmonic_phase(sim, 0.5, 2.0, times[-1]),
             "square": {"f_hz": 0.5, "amplitude": amp}, "speed_limit": None,
             "inlb_per_motor_nm": INLB_PER_NM * ratio, "spring_inlb_per_deg": k_inlb_per_deg}
    return make_record(name, seed, d, sim, lg, rng, command="sampled", hinge=True, truth=truth)


def _limited_drive(rng: np.random.Generator) -> Drive:
    """Point 2's actuator: soft cascade (small-signal wn ~ 50-70 rad/s) behind a speed limit of 80-110 mm/s."""
    d = linear_drive(rng, i_max=6.0)
    wv = rng.uniform(80.0, 100.0)
    d = tune(d, wv=wv, kp=rng.uniform(38.0, 46.0), ti_factor=0.0)
    return replace(d, v_max=rng.uniform(80.0, 110.0))


def rate_limit_squares_mm(seed: int) -> Record:
    """Point 2: 10 mm squares (host steps, 100 Hz) on a speed-limited drive: the speed plateaus at v_max."""
    name = "rate_limit_squares_mm"
    rng = _rng("limited_actuator", seed)
    d = _limited_drive(rng)
    rng = _rng(name, seed)
    t_end = 24.0
    grid = np.arange(0.0, t_end, d.dt)
    lg = Logger(rate_hz=100.0, jitter_ms=rng.uniform(0.5, 1.5), pos_count=0.001, pos_digits=3, cmd_digits=3)
    period = float(rng.choice([2.0, 3.0, 4.0]))
    dem, vals, tt, st = host_schedule(t_end, lg, rng, lambda x: square(x, 1.0, period / 2, 5.0, -5.0), grid)
    sim = simulate(d, dem)
    pl = plateau_speed(sim)
    truth = {"point": 2, "what": "10 mm squares on a speed-limited drive", "speed_limit": pl["median_near_top"],
             "drive_speed_limit_setting": d.v_max, "plateau": pl, "small_signal": small_signal(d, 1.0),
             "phase_sign": "lag"}
    return make_record(name, seed, d, sim, lg, rng, command="held", host_cmd=(dem, vals, tt, st), truth=truth)


def small_steps_mm(seed: int) -> Record:
    """Point 2: 1 mm steps on the same actuator as rate_limit_squares_mm: linear, small-signal wn."""
    name = "small_steps_mm"
    rng = _rng("limited_actuator", seed)
    d = _limited_drive(rng)
    rng = _rng(name, seed)
    t_end = 24.0
    grid = np.arange(0.0, t_end, d.dt)
    lg = Logger(rate_hz=100.0, jitter_ms=rng.uniform(0.5, 1.5), pos_count=0.001, pos_digits=3, cmd_digits=3)
    base = rng.uniform(-3, 3)
    dem, vals, tt, st = host_schedule(t_end, lg, rng, lambda x: base + square(x, 1.0, 1.0, 0.5, -0.5), grid)
    sim = simulate(d, dem)
    ss = small_signal(d, 1.0)
    truth = {"point": 2, "what": "1 mm steps on the speed-limited actuator: the limit never binds",
             "speed_limit": None, "actuator_speed_limit": d.v_max, "small_signal": ss,
             "plateau": plateau_speed(sim), "phase_sign": "lag"}
    return make_record(name, seed, d, sim, lg, rng, command="held", host_cmd=(dem, vals, tt, st), truth=truth)


def rate_limit_sweep_mm(seed: int) -> Record:
    """Point 2: a ±5 mm sine sweep (the drive's own generator, logged sampled) that saturates in speed."""
    name = "rate_limit_sweep_mm"
    rng = _rng("limited_actuator", seed)
    d = _limited_drive(rng)
    rng = _rng(name, seed)
    t_end = 32.0
    t = np.arange(0.0, t_end, d.dt)
    dem = chirp(t, 1.0, t_end - 1.0, 0.2, float(rng.uniform(5.0, 6.0)), 5.0)
    sim = simulate(d, dem)
    lg = Logger(rate_hz=100.0, jitter_ms=rng.uniform(0.5, 1.5), pos_count=0.001, pos_digits=3, cmd_digits=3)
    pl = plateau_speed(sim)
    truth = {"point": 2, "what": "±5 mm sweep past the speed limit", "speed_limit": pl["median_near_top"],
             "drive_speed_limit_setting": d.v_max, "plateau": pl, "small_signal": small_signal(d, 1.0),
             "phase_sign": "lag",
             "binds_above_hz": d.v_max / (TWO_PI * 5.0)}
    return make_record(name, seed, d, sim, lg, rng, command="sampled", truth=truth)


def settle_exact_mm(seed: int) -> Record:
    """Point 3: 1 mm squares; a PI position loop settles exactly on the command (no threshold, dead band, free play)."""
    name = "settle_exact_mm"
    rng = _rng(name, seed)
    d = linear_drive(rng)
    d = replace(tune(d, wv=rng.uniform(300, 400), kp=rng.uniform(30, 40), ti_factor=5.0), ki=rng.uniform(150, 250),
                ts=d.tc * 1.05, enc=0.001)
    t_end = 24.0
    grid = np.arange(0.0, t_end, d.dt)
    lg = Logger(rate_hz=float(rng.choice([80.0, 100.0])), jitter_ms=rng.uniform(0.5, 1.5), pos_count=0.01,
                pos_digits=2, cmd_digits=2)
    base = round(float(rng.uniform(-5, 5)), 1)
    dem, vals, tt, st = host_schedule(t_end, lg, rng, lambda x: base + square(x, 1.0, 1.0, 0.5, -0.5), grid)
    sim = simulate(d, dem)
    rests = rest_segments(sim.demand, sim.t, 0.6, 0.2)
    errs = [float(np.median(sim.x[a:b] - sim.demand[a:b])) for a, b in rests]
    truth = {"point": 3, "what": "1 mm squares, PI position loop: settles on the command",
             "threshold": 0.0, "dead_band": 0.0, "free_play": 0.0,
             "settled_error_fine": {"median_abs": float(np.median(np.abs(errs))),
                                    "max_abs": float(np.max(np.abs(errs)))},
             "speed_limit": None, "phase_sign": "lag"}
    return make_record(name, seed, d, sim, lg, rng, command="held", host_cmd=(dem, vals, tt, st), truth=truth)


def _lc_truth(sim: Sim, rests: list[tuple[int, int]]) -> dict[str, Any]:
    freqs, amps, rmss, cur = [], [], [], []
    dt = sim.t[1] - sim.t[0]
    for a, b in rests:
        x = sim.x[a:b] - np.mean(sim.x[a:b])
        n = x.size
        spec = np.abs(np.fft.rfft(x * np.hanning(n), 8 * n))
        f = np.fft.rfftfreq(8 * n, dt)
        k = int(np.argmax(spec * (f > 2.0)))
        freqs.append(float(f[k]))
        amps.append(float(0.5 * (np.percentile(x, 99) - np.percentile(x, 1))))
        rmss.append(float(np.std(x)))
        cur.append(float(np.std(sim.iq[a:b])))
    return {"freq_hz": float(np.median(freqs)), "amplitude": float(np.median(amps)), "rms": float(np.median(rmss)),
            "current_rms_a": float(np.median(cur)), "per_rest_freq_hz": freqs}


def limit_cycle_mm(seed: int) -> Record:
    """Point 4: P position loop closed on the load's scale, backlash in the nut: hunts at every rest (20-50 Hz)."""
    name = "limit_cycle_mm"
    rng = _rng(name, seed)
    d = linear_drive(rng, dt=1.0e-4, i_max=80.0)
    scale = d.scale
    gap = rng.uniform(0.04, 0.055)
    k_ax = rng.uniform(1.0e7, 3.0e7)  # N/m, nut and mounting
    k_c = k_ax * (5e-3 / TWO_PI) ** 2
    jr = d.jm * d.jl / (d.jm + d.jl)
    d = replace(tune(d, wv=rng.uniform(260, 320), kp=rng.uniform(140, 170), ti_factor=3.0), gap=gap, k_c=k_c,
                c_c=2 * 0.15 * math.sqrt(k_c * jr), tl_c=rng.uniform(0.001, 0.003), tc=0.004, ts=0.005, enc=0.001)
    del scale
    t_end = 20.0
    grid = np.arange(0.0, t_end, d.dt)
    rate = float(rng.choice([100.0, 100.0, 250.0]))
    lg = Logger(rate_hz=rate, jitter_ms=rng.uniform(0.5, 1.5), pos_count=0.001, pos_digits=3, cmd_digits=3)
    period = 5.0
    dem, vals, tt, st = host_schedule(t_end, lg, rng, lambda x: square(x, 1.0, period / 2, 1.0, -1.0), grid)
    sim = simulate(d, dem)
    rests = rest_segments(sim.demand, sim.t, 0.8, 1.0)
    lc = _lc_truth(sim, rests)
    truth = {"point": 4, "what": "limit cycle at rest (backlash inside a P position loop on the load scale)",
             "limit_cycle": lc, "speed_limit": None, "phase_sign": "lag", "backlash": gap}
    return make_record(name, seed, d, sim, lg, rng, command="held", host_cmd=(dem, vals, tt, st), truth=truth)


def noise_grows_sweep_mm(seed: int) -> Record:
    """Point 4: a sweep whose 'noise' grows with frequency (the screw's rolling noise grows with speed); rests quiet."""
    name = "noise_grows_sweep_mm"
    rng = _rng(name, seed)
    d = tune(linear_drive(rng), wv=rng.uniform(300, 400), kp=rng.uniform(35, 45), ti_factor=5.0)
    t_end = 34.0
    t = np.arange(0.0, t_end, d.dt)
    dem = chirp(t, 3.0, t_end - 3.0, 0.3, float(rng.uniform(5.0, 6.0)), 2.0)
    # rolling noise: white torque, band-limited to ~300 Hz, scaled by the demand's speed (mm/s)
    white = rng.normal(0.0, 1.0, t.size)
    a = math.exp(-TWO_PI * 300.0 * d.dt)
    col = np.empty_like(white)
    acc = 0.0
    for i, wv in enumerate(white.tolist()):
        acc = a * acc + (1 - a) * wv
        col[i] = acc
    col /= np.std(col)
    speed = np.abs(np.gradient(dem, d.dt))
    k_noise = rng.uniform(2.0e-2, 3.0e-2)  # N m per (mm/s)^0.5
    torque = k_noise * np.sqrt(speed) * col
    sim = simulate(d, dem, torque=torque)
    quiet = simulate(d, dem)
    diff = sim.x - quiet.x
    lg = Logger(rate_hz=100.0, jitter_ms=rng.uniform(0.5, 1.5), pos_count=0.001, pos_digits=3, cmd_digits=3,
                noise=0.002)
    n = t.size
    early = (t > 4.0) & (t < 10.0)
    late = (t > t_end - 9.0) & (t < t_end - 3.5)
    truth = {"point": 4, "what": "rolling noise that grows with speed in a sweep; quiet at rest",
             "sensor_noise_rms": 0.002, "motion_noise_rms": {"early_sweep": float(np.std(diff[early])),
                                                             "late_sweep": float(np.std(diff[late]))},
             "speed_limit": None, "phase_sign": "lag", "samples_fine": n}
    return make_record(name, seed, d, sim, lg, rng, command="sampled", truth=truth)


def coarse_encoder_rotary(seed: int) -> Record:
    """Point 5: an output encoder of 6000-7200 counts/rev (0.05-0.06°) logged to 0.01°."""
    name = "coarse_encoder_rotary"
    rng = _rng(name, seed)
    cpr = int(rng.integers(6000, 7200))
    q = 360.0 / cpr
    ratio = rng.uniform(60, 100)
    d = replace(tune(rotary_drive(rng, ratio, i_max=40.0), wv=rng.uniform(300, 450), kp=rng.uniform(30, 45),
                     ti_factor=5.0), enc=360.0 / 2 ** 18)  # the drive: a fine motor encoder; the logger: the coarse one
    t_end = 30.0
    grid = np.arange(0.0, t_end, d.dt)
    lg = Logger(rate_hz=float(rng.choice([80.0, 100.0])), jitter_ms=rng.uniform(0.5, 1.5), pos_count=q,
                pos_digits=2, cmd_digits=2)

    def fn(x: np.ndarray) -> np.ndarray:
        steps = np.where(((x - 1.0) // 1.5) % 2 == 0, 2.0, -2.0) * ((x >= 1.0) & (x < 13.0))
        sweep = chirp(x, 14.0, t_end - 1.0, 0.3, 4.0, 4.0)
        return steps + sweep

    dem, vals, tt, st = host_schedule(t_end, lg, rng, fn, grid)
    sim = simulate(d, dem)
    truth = {"point": 5, "what": "coarse output encoder logged to 0.01°", "count": q, "counts_per_rev": cpr,
             "speed_limit": None, "phase_sign": "lag"}
    rec = make_record(name, seed, d, sim, lg, rng, command="held", host_cmd=(dem, vals, tt, st), truth=truth)
    rec.truth["resolution"] = q
    return rec


def counts_001_mm(seed: int) -> Record:
    """Point 5: a linear scale of 0.01 mm counts, logged in 0.01 mm."""
    name = "counts_001_mm"
    rng = _rng(name, seed)
    d = replace(tune(linear_drive(rng, i_max=40.0), wv=rng.uniform(300, 450), kp=rng.uniform(30, 45), ti_factor=5.0),
                enc=0.001)
    t_end = 30.0
    grid = np.arange(0.0, t_end, d.dt)
    lg = Logger(rate_hz=float(rng.choice([80.0, 100.0])), jitter_ms=rng.uniform(0.5, 1.5), pos_count=0.01,
                pos_digits=2, cmd_digits=2)

    def fn(x: np.ndarray) -> np.ndarray:
        steps = np.where(((x - 1.0) // 1.5) % 2 == 0, 1.0, -1.0) * ((x >= 1.0) & (x < 13.0))
        return steps + chirp(x, 14.0, t_end - 1.0, 0.3, 4.0, 1.5)

    dem, vals, tt, st = host_schedule(t_end, lg, rng, fn, grid)
    sim = simulate(d, dem)
    truth = {"point": 5, "what": "position in 0.01 mm counts", "count": 0.01, "speed_limit": None, "phase_sign": "lag"}
    return make_record(name, seed, d, sim, lg, rng, command="held", host_cmd=(dem, vals, tt, st), truth=truth)


def mm_hygiene(seed: int) -> Record:
    """Point 6: a long-stroke linear actuator (±30 mm) in mm, no X-43A channel; profiled moves and sines."""
    name = "mm_hygiene"
    rng = _rng(name, seed)
    d = replace(tune(linear_drive(rng, i_max=40.0), wv=rng.uniform(350, 500), kp=rng.uniform(35, 50), ti_factor=5.0),
                vff=rng.uniform(0.5, 0.8), v_max=400.0)
    t_end = 30.0
    t = np.arange(0.0, t_end, d.dt)
    levels = [float(x) for x in rng.uniform(-30, 30, 8)]
    times = [1.0 + 1.5 * k for k in range(8)]
    dem = (moves(t, [*times, 13.0], [*levels, 0.0], 0.0, vmax=150.0, amax=1500.0, jerk_s=0.015)
           + chirp(t, 14.0, t_end - 1.0, 0.2, 3.0, 8.0))
    sim = simulate(d, dem)
    lg = Logger(rate_hz=float(rng.choice([70.0, 100.0])), jitter_ms=rng.uniform(1.0, 2.0), pos_count=0.001,
                pos_digits=3, cmd_digits=3)
    truth = {"point": 6, "what": "mm record, long stroke, no X-43A channel",
             "lag_ms": lag_truth(sim, sim.t > 1.0) * 1e3,
             "speed_limit": None, "phase_sign": "lag"}
    return make_record(name, seed, d, sim, lg, rng, command="sampled", truth=truth,
                       metadata={"actuator": "ball-screw linear EMA, 5 mm lead, ±40 mm stroke", "units": "mm"})


def _block(x: np.ndarray, amp: float, rng_block: np.ndarray) -> np.ndarray:
    """A repeating 11.5 s excitation: four steps and a 0.5-6 Hz chirp; each part of the record can be fitted alone."""
    tb = np.mod(x, 11.5)
    steps = np.select([tb < 1.2, tb < 2.4, tb < 3.6, tb < 4.8], [amp, -amp, 0.5 * amp, -0.5 * amp], 0.0)
    return steps + chirp(tb, 5.0, 11.0, 0.5, 6.0, 0.6 * amp) + 0.0 * rng_block[0]


def bandwidth_drift(seed: int) -> Record:
    """Point 7: 92 s, the drive's loop gain decays (winding heating): bandwidth falls 25 %."""
    name = "bandwidth_drift"
    rng = _rng(name, seed)
    ratio = rng.uniform(60, 100)
    d = tune(rotary_drive(rng, ratio, tc=0.0, ts=0.0, i_max=40.0), wv=rng.uniform(70, 90), kp=rng.uniform(35, 45),
             ti_factor=0.0)
    t_end = 92.5
    grid = np.arange(0.0, t_end, d.dt)
    lg = Logger(rate_hz=float(rng.choice([100.0, 200.0, 250.0])), jitter_ms=0.0, pos_count=0.001, pos_digits=3,
                cmd_digits=3)
    amp = rng.uniform(2.0, 4.0)
    dem, vals, tt, st = host_schedule(t_end, lg, rng, lambda x: _block(x, amp, np.zeros(1)), grid)
    gain = 1.0 - 0.25 * np.clip(grid / 92.0, 0, 1)
    sim = simulate(d, dem, gain=gain)
    ss0 = fit_second_order(*_step_of(d, 1.0, 1.0))
    ss1 = fit_second_order(*_step_of(d, 1.0, 0.75))
    truth = {"point": 7, "what": "bandwidth falls 25 % over 92 s (loop gain decays linearly)", "trend": "falling",
             "bandwidth_hz": {"start": bandwidth_hz(d, 1.0), "end": bandwidth_hz(d, 0.75)},
             "wn_rad_s": {"start": ss0[0], "end": ss1[0]}, "zeta": {"start": ss0[1], "end": ss1[1]},
             "speed_limit": None, "phase_sign": "lag"}
    return make_record(name, seed, d, sim, lg, rng, command="held", host_cmd=(dem, vals, tt, st), truth=truth)


def _step_of(d: Drive, step: float, gain: float) -> tuple[np.ndarray, np.ndarray, float]:
    t = np.arange(0.0, 0.6, d.dt)
    dem = np.where(t >= 0.05, step, 0.0)
    s = simulate(d, dem, gain=np.full(t.size, gain))
    m = t >= 0.05
    return t[m] - 0.05, s.x[m], step


def wandering_delay(seed: int) -> Record:
    """Point 7: 92 s, a transport delay on the demand (a fieldbus) that wanders between 2 and 12 ms."""
    name = "wandering_delay"
    rng = _rng(name, seed)
    ratio = rng.uniform(60, 100)
    d = tune(rotary_drive(rng, ratio, tc=0.0, ts=0.0, i_max=40.0), wv=rng.uniform(70, 90), kp=rng.uniform(35, 45),
             ti_factor=0.0)
    t_end = 92.5
    grid = np.arange(0.0, t_end, d.dt)
    lg = Logger(rate_hz=float(rng.choice([100.0, 200.0, 250.0])), jitter_ms=0.0, pos_count=0.001, pos_digits=3,
                cmd_digits=3)
    amp = rng.uniform(2.0, 4.0)
    dem, vals, tt, st = host_schedule(t_end, lg, rng, lambda x: _block(x, amp, np.zeros(1)), grid)
    ph = rng.uniform(0, TWO_PI)
    period = rng.uniform(40.0, 70.0)
    tau = 7e-3 + 5e-3 * np.sin(TWO_PI * grid / period + ph)
    idx = np.clip(np.round((grid - tau) / d.dt).astype(int), 0, grid.size - 1)
    delayed = dem[idx]
    sim = simulate(d, delayed)
    sim.demand = dem.copy()  # the truth's demand is the one sent (the logger's)
    win = [(float(a), float(1e3 * np.mean(tau[(grid >= a) & (grid < a + 11.5)]))) for a in np.arange(0.0, 92.0, 11.5)]
    truth = {"point": 7, "what": "transport delay wandering 2-12 ms", "trend": "wandering",
             "delay_ms": {"min": float(tau.min() * 1e3), "max": float(tau.max() * 1e3), "period_s": period,
                          "per_block": win},
             "speed_limit": None, "phase_sign": "lag"}
    return make_record(name, seed, d, sim, lg, rng, command="held", host_cmd=(dem, vals, tt, st), truth=truth)


def jitter_only(seed: int) -> Record:
    """Point 7: a clean linear servo (no friction, no limit, no delay) at 100 Hz whose stamps jitter ±2 ms."""
    name = "jitter_only"
    rng = _rng(name, seed)
    ratio = rng.uniform(60, 100)
    d = tune(rotary_drive(rng, ratio, tc=0.0, ts=0.0, tau_i=5e-5, enc=0.0, i_max=40.0), wv=rng.uniform(70, 100),
             kp=rng.uniform(35, 50), ti_factor=0.0)
    t_end = 30.0
    grid = np.arange(0.0, t_end, d.dt)
    lg = Logger(rate_hz=100.0, jitter_ms=0.0, stamp_err_ms=2.0, pos_count=0.0001, pos_digits=4, cmd_digits=4,
                noise=0.002)
    amp = rng.uniform(2.0, 4.0)
    dem, vals, tt, st = host_schedule(t_end, lg, rng, lambda x: _block(x, amp, np.zeros(1)), grid)
    sim = simulate(d, dem)
    jit = st - tt
    ss = fit_second_order(*_step_of(d, 1.0, 1.0))
    truth = {"point": 7, "what": "clean linear servo, stamps jitter ±2 ms: nothing but jitter", "effects": [],
             "stamp_error_ms": {"rms": float(np.std(jit) * 1e3), "peak": float(np.max(np.abs(jit)) * 1e3)},
             "wn_rad_s": ss[0], "zeta": ss[1], "lag_ms": lag_truth(sim) * 1e3, "speed_limit": None,
             "phase_sign": "lag", "rest_noise_rms": 0.002}
    rec = make_record(name, seed, d, sim, lg, rng, command="held", host_cmd=(dem, vals, tt, st), truth=truth)
    rec.truth["resolution"] = None
    rec.truth["rest_noise_rms"] = math.sqrt(0.002 ** 2 + 0.0001 ** 2 / 12)
    return rec


CASES: dict[str, Callable[[int], Record]] = {
    "profiled_square_mm": profiled_square_mm,
    "profiled_square_rotary": profiled_square_rotary,
    "rate_limit_squares_mm": rate_limit_squares_mm,
    "small_steps_mm": small_steps_mm,
    "rate_limit_sweep_mm": rate_limit_sweep_mm,
    "settle_exact_mm": settle_exact_mm,
    "limit_cycle_mm": limit_cycle_mm,
    "noise_grows_sweep_mm": noise_grows_sweep_mm,
    "coarse_encoder_rotary": coarse_encoder_rotary,
    "counts_001_mm": counts_001_mm,
    "mm_hygiene": mm_hygiene,
    "bandwidth_drift": bandwidth_drift,
    "wandering_delay": wandering_delay,
    "jitter_only": jitter_only,
}


def generate(name: str, seed: int, folder: str | Path) -> tuple[Record, Path, Path]:
    """Make one case's record and write its CSV and truth JSON into ``folder``."""
    rec = CASES[name](seed)
    csv_path, truth_path = rec.write(folder)
    return rec, csv_path, truth_path


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("out")
    ap.add_argument("--set", choices=("dev", "heldout"), default="dev")
    ap.add_argument("--cases", default=None)
    args = ap.parse_args()
    seeds = DEV_SEEDS if args.set == "dev" else HELDOUT_SEEDS
    names = args.cases.split(",") if args.cases else list(CASES)
    for name in names:
        for seed in seeds:
            _, p, _ = generate(name, seed, args.out)
            print(p)


if __name__ == "__main__":
    main()
