"""A corpus of rig-shaped bench records from a drive model that owes nothing to ``ema_sim.models``.

Issue 24: ``ema analyze`` run on other actuators' bench logs. Each record here is what a small
industrial electromechanical actuator's logger writes while a profile generator drives it through a
periodic demand:

* **the drive** (:class:`Drive`, :func:`run_drive`): a permanent-magnet DC motor behind a gear train and
  a lead screw or crank (``gear_deg_per_rad`` output degrees per motor radian), its current loop a
  first-order lag with a current (torque) limit, a PI velocity loop on the motor speed with a speed
  limit (the output's rate limit), and a proportional position loop on the output encoder, with
  viscous and Coulomb friction on the motor shaft; integrated with semi-implicit Euler at 0.25 ms;
* **the demand** (:func:`profiled_square`, :func:`trapezoid`, :func:`triangle`, :func:`sine`): the
  drive's own profile generator, periodic: a square wave whose edges go through a trapezoid velocity
  profile (speed and acceleration limits), a trapezoid (ramps and dwells), a triangle, a sine;
* **the logger** (:func:`log`): reads the running demand and the encoder at 70–100 Hz with a timer
  that jitters by a millisecond or two, writes integer-millisecond stamps, positions in counts of
  0.01 (the demand too), one channel, no hinge moment, no metadata about the X-43A;
* **the file** (:func:`write_rig_csv`): the data contract's ``time_s``, ``command_deg``,
  ``position_deg`` columns, values as the logger prints them.

Every record keeps its truth (:class:`RigRecord`: the drive's parameters, the demand's period,
amplitude and harmonics, the output's settled error) so tests can check what ``ema analyze`` states.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ema_sim.io.measured import MeasuredData

STEP_S = 0.00025
"""Integration step of the drive, s."""


@dataclass(frozen=True)
class Drive:
    """A DC-motor servo: gear/screw, current-limited torque, PI speed loop, P position loop."""

    gear_deg_per_rad: float = 0.5
    """Output degrees per motor radian (gear train and screw)."""
    inertia: float = 2.0e-5
    """Motor shaft inertia with the reflected load, kg·m²."""
    kt: float = 0.05
    """Torque constant, N·m/A."""
    viscous: float = 2.0e-5
    """Viscous friction on the motor shaft, N·m·s/rad."""
    coulomb: float = 0.004
    """Coulomb friction on the motor shaft, N·m."""
    current_tau_s: float = 0.001
    """Current loop's lag, s."""
    current_max_a: float = 4.0
    """Current limit, A."""
    kv: float = 0.02
    """Speed loop's proportional gain, A per rad/s."""
    ki: float = 0.4
    """Speed loop's integral gain, A per rad."""
    kp: float = 25.0
    """Position loop's gain, (output deg/s) per output degree of error."""
    speed_max_dps: float = 95.0
    """Speed limit, output deg/s (the rate limit the record shows)."""
    feedforward: float = 0.0
    """Share of the demand's own speed fed forward to the speed loop."""
    encoder_counts: float = 0.0
    """The position loop closes on the encoder's counts (0: on the true position)."""


def run_drive(t: np.ndarray, demand: np.ndarray, drive: Drive, start: float | None = None) -> np.ndarray:
    """The output position (deg) of the drive following ``demand`` on the fine grid ``t`` (from rest at ``start``).

    Parameters
    ----------
    t : numpy.ndarray
        Uniform time grid, s (step ``STEP_S``).
    demand : numpy.ndarray
        The profile generator's position demand, output deg.
    drive : Drive
        The drive.
    start : float, optional
        Where the output rests at first (default: the first demand).

    Returns
    -------
    numpy.ndarray
        Output position, deg.
    """
    g = drive.gear_deg_per_rad
    dt = float(t[1] - t[0])
    vd = np.gradient(demand, dt) * drive.feedforward
    pos = float(demand[0]) if start is None else float(start)
    omega = 0.0
    current = 0.0
    integ = 0.0
    out = np.empty(t.size)
    a_i = dt / (drive.current_tau_s + dt)
    wmax = drive.speed_max_dps / g
    q = drive.encoder_counts
    for k in range(t.size):
        out[k] = pos
        fb = round(pos / q) * q if q else pos
        speed_cmd = drive.kp * (demand[k] - fb) + vd[k]  # output deg/s
        w_cmd = min(max(speed_cmd / g, -wmax), wmax)
        err = w_cmd - omega
        i_cmd = drive.kv * err + integ
        if abs(i_cmd) < drive.current_max_a:
            integ += drive.ki * err * dt  # no wind-up while the current saturates
        i_cmd = min(max(i_cmd, -drive.current_max_a), drive.current_max_a)
        current += a_i * (i_cmd - current)
        torque = drive.kt * current - drive.viscous * omega
        if omega == 0.0 and abs(torque) <= drive.coulomb:
            continue  # static friction holds the shaft
        torque -= math.copysign(drive.coulomb, omega if omega != 0.0 else torque)
        new = omega + torque / drive.inertia * dt
        omega = 0.0 if omega != 0.0 and new * omega < 0.0 else new  # friction stops it, never reverses it
        pos += g * omega * dt
    return out


# ---------------------------------------------------------------------------------------------- demands
def _profile(targets: np.ndarray, t: np.ndarray, speed: float, accel: float) -> np.ndarray:
    """A profile generator's output: moves towards each sample's target at most ``speed``, ``accel``."""
    dt = float(t[1] - t[0])
    out = np.empty(t.size)
    p, v = float(targets[0]), 0.0
    for k in range(t.size):
        out[k] = p
        d = float(targets[k]) - p
        stop = v * v / (2.0 * accel)  # distance needed to stop
        want = math.copysign(speed, d) if abs(d) > stop + 1e-9 else 0.0
        if abs(d) <= stop and v * d > 0.0:
            want = 0.0
        dv = min(max(want - v, -accel * dt), accel * dt)
        v += dv
        step = v * dt
        if abs(step) >= abs(d) and abs(v) <= accel * dt * 2.0:
            p, v = float(targets[k]), 0.0
        else:
            p += step
    return out


def _grid(lead_s: float, period_s: float, cycles: int, tail_s: float) -> tuple[np.ndarray, np.ndarray]:
    t = np.arange(0.0, lead_s + cycles * period_s + tail_s, STEP_S)
    phase = (t - lead_s) / period_s
    return t, phase


def profiled_square(amp: float, period_s: float, cycles: int, *, speed: float, accel: float,
                    lead_s: float = 0.6, tail_s: float = 0.6) -> tuple[np.ndarray, np.ndarray]:
    """A square wave ±``amp`` whose edges go through the profile generator (trapezoid speed moves)."""
    t, ph = _grid(lead_s, period_s, cycles, tail_s)
    target = np.where((ph >= 0) & (ph < cycles), np.where(ph % 1.0 < 0.5, amp, -amp), 0.0)
    return t, _profile(target, t, speed, accel)


def trapezoid(amp: float, period_s: float, cycles: int, *, ramp_share: float = 0.25, lead_s: float = 0.6,
              tail_s: float = 0.6) -> tuple[np.ndarray, np.ndarray]:
    """A trapezoid ±``amp``: ramps taking ``ramp_share`` of the period each, dwells between."""
    t, ph = _grid(lead_s, period_s, cycles, tail_s)
    x = ph % 1.0
    r = ramp_share
    d = 0.5 - r  # dwell share at each level
    up = np.clip(x / r, 0.0, 1.0)  # 0→1 over the first ramp
    down = np.clip((x - r - d) / r, 0.0, 1.0)
    wave = amp * (-1.0 + 2.0 * up - 2.0 * down)
    # start at −amp: lead in from 0 by a ramp of the same speed
    inside = (ph >= 0) & (ph < cycles)
    lead = np.clip((t - (lead_s - r * period_s / 2)) / (r * period_s / 2), 0.0, 1.0) * -amp
    return t, np.where(inside, wave, np.where(ph < 0, lead, -amp))


def triangle(amp: float, period_s: float, cycles: int, *, lead_s: float = 0.6,
             tail_s: float = 0.6) -> tuple[np.ndarray, np.ndarray]:
    """A triangle ±``amp`` starting from 0 upward."""
    t, ph = _grid(lead_s, period_s, cycles, tail_s)
    x = (ph + 0.25) % 1.0
    wave = amp * (4.0 * np.abs(x - 0.5) - 1.0) * -1.0
    return t, np.where((ph >= 0) & (ph < cycles), wave, 0.0)


def sine(amp: float, period_s: float, cycles: int, *, lead_s: float = 0.6,
         tail_s: float = 0.6) -> tuple[np.ndarray, np.ndarray]:
    """A sine ±``amp`` from 0."""
    t, ph = _grid(lead_s, period_s, cycles, tail_s)
    return t, np.where((ph >= 0) & (ph < cycles), amp * np.sin(2 * np.pi * ph), 0.0)


# ---------------------------------------------------------------------------------------------- the logger
@dataclass(frozen=True)
class RigRecord:
    """A logged record and its truth."""

    name: str
    family: str
    """``square``, ``trapezoid``, ``triangle`` or ``sine``."""
    data: MeasuredData
    period_s: float
    amp: float
    cycles: int
    rate_hz: float
    drive: Drive
    fine_t: np.ndarray = field(repr=False)
    fine_demand: np.ndarray = field(repr=False)
    fine_output: np.ndarray = field(repr=False)


def log(name: str, family: str, t: np.ndarray, demand: np.ndarray, drive: Drive, *, period_s: float, amp: float,
        cycles: int, rate_hz: float = 80.0, jitter_s: float = 0.0012, counts: float = 0.01, seed: int = 0,
        unit: str = "deg", start: float | None = None, vibration: tuple[float, float] = (0.0, 0.0)) -> RigRecord:
    """The bench log of the drive following ``demand``: jittery timer, integer-ms stamps, counts of 0.01.

    ``vibration`` (amplitude, Hz): the rig's own vibration, seen by the encoder on top of the output.
    """
    rng = np.random.default_rng(seed)
    y = run_drive(t, demand, drive, start) + vibration[0] * np.sin(2.0 * np.pi * vibration[1] * t)
    period = 1.0 / rate_hz
    n = int((t[-1] - 0.02) * rate_hz)
    inst = 0.007 + period * np.arange(n) + np.clip(rng.normal(0.0, jitter_s, n), -period / 3, period / 3)
    inst = inst[inst < t[-1] - 0.005]
    idx = np.clip(np.searchsorted(t, inst, side="right") - 1, 0, t.size - 1)
    stamps = np.floor(inst * 1000.0) / 1000.0
    u = np.round(demand[idx] / counts) * counts
    pos = np.round(y[idx] / counts) * counts
    data = MeasuredData(time_s=stamps - stamps[0], command_deg=u, position_deg=pos, metadata={}, source=f"{name}.csv",
                        unit=unit)
    return RigRecord(name, family, data, period_s, amp, cycles, rate_hz, drive, t, demand, y)


def write_rig_csv(rec: RigRecord, folder: Path) -> Path:
    """The record as the data contract's CSV, printed as the logger prints: ms stamps, two decimals."""
    path = folder / f"{rec.name}.csv"
    d = rec.data
    rows = [f"{a:.3f},{b:.2f},{c:.2f}" for a, b, c in zip(d.time_s, d.command_deg, d.position_deg, strict=True)]
    path.write_text("# rig: bench 3, drive A\ntime_s,command_deg,position_deg\n" + "\n".join(rows) + "\n",
                    encoding="utf-8")
    return path


# ---------------------------------------------------------------------------------------------- the corpus
STALLING = Drive(kp=12.0, ki=0.0, coulomb=0.006)
"""A drive without integral action: Coulomb friction stops it short of the command (by ≈ 3 °/s / kp)."""


def _held(t: np.ndarray, u: np.ndarray, extra_s: float) -> tuple[np.ndarray, np.ndarray]:
    n = int(extra_s / STEP_S)
    return np.concatenate([t, t[-1] + STEP_S * np.arange(1, n + 1)]), np.concatenate([u, np.full(n, u[-1])])


def corpus() -> dict[str, RigRecord]:
    """One record per waveform family, a stalling servo and a held drive on a vibrating rig.

    Returns
    -------
    dict
        Name → record: ``square`` (a profiled square wave the drive cannot follow at its speed),
        ``trapezoid``, ``triangle``, ``sine``, ``stall`` (a square wave at 1 Hz whose drive stops short of
        every command) and ``hold`` (a held command, the encoder toggling one count at the rig's 6 Hz).
    """
    out = {}
    t, u = profiled_square(10.0, 2.0, 5, speed=150.0, accel=2000.0)
    out["square"] = log("square", "square", t, u, Drive(), period_s=2.0, amp=10.0, cycles=5, rate_hz=80.0, seed=1)
    t, u = trapezoid(8.0, 2.5, 4, ramp_share=0.2)
    out["trapezoid"] = log("trapezoid", "trapezoid", t, u, Drive(), period_s=2.5, amp=8.0, cycles=4, rate_hz=90.0,
                           seed=2)
    t, u = triangle(6.0, 1.6, 6)
    out["triangle"] = log("triangle", "triangle", t, u, Drive(), period_s=1.6, amp=6.0, cycles=6, rate_hz=100.0,
                          seed=3)
    t, u = sine(5.0, 1.0, 8)
    out["sine"] = log("sine", "sine", t, u, Drive(), period_s=1.0, amp=5.0, cycles=8, rate_hz=70.0, seed=4)
    t, u = profiled_square(2.0, 1.0, 6, speed=400.0, accel=20000.0)
    out["stall"] = log("stall", "square", t, u, STALLING, period_s=1.0, amp=2.0, cycles=6, rate_hz=100.0, seed=5)
    t = np.arange(0.0, 12.0, STEP_S)
    u = np.full(t.size, 3.005)
    out["hold"] = log("hold", "hold", t, u, Drive(), period_s=0.0, amp=0.0, cycles=0, rate_hz=80.0, seed=6,
                      vibration=(0.004, 6.0))
    return out
