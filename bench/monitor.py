"""The monitor's figures: false alarms in an hour of clean flight-like running, and its CPU per channel.

Clean hour: five channels in lockstep run LOADA for an hour through a flight-like Schroeder multisine (0.05-2 Hz,
3° peak) under a spring-like hinge moment, behind the AIL test environment (config/ail.yaml): the command path's
26 ms delay, 50 Hz lag, 5 mV quantum and 3 mV noise between the recorded FMU command and the actuator, and the
feedback's 3 mV noise and 5 mV quantum on the LVDT reading. ``ema monitor`` watches each channel against the
reference it learns on the first 30 s (:func:`ema_sim.monitor.learn`: the fitted second order learns the
environment's delay and lag with the actuator) at its default 0.1 false alarms per hour; the figure is the
alarms counted over the five channel-hours.

CPU: :class:`~ema_sim.monitor.online.OnlineMonitor` (the node's per-frame path) stepped frame by frame at 200 Hz
on 120 s of one channel with an LVDT bias detected, isolated and re-estimated in it; the figure is its process
time over the simulated time, the share of one core one channel takes in real time.

Run: ``python bench/monitor.py`` (about five minutes on one core).
"""

from __future__ import annotations

import time

import numpy as np

from ema_sim.benchmark import Benchmark, Result
from ema_sim.config import load_channel
from ema_sim.faults import parse_fault
from ema_sim.io.measured import MeasuredData
from ema_sim.models import create
from ema_sim.monitor import Options, from_name, learn, watch
from ema_sim.monitor.online import OnlineMonitor
from ema_sim.montecarlo.faults import ail_command
from ema_sim.signals import parse_maneuver
from ema_sim.simulation import Inputs, frame_inputs, run_maneuver, simulate

CHANNELS = ("left_wing", "right_wing", "left_rudder", "right_rudder", "cowl_door")
FLIGHT = "schroeder:f0_hz=0.05,f1_hz=2,amp_deg=3,period_s=60,periods=60,lead_s=1"
HOUR_S = 3600.0
FRAME_HZ = 200.0
SPRING_INLB_PER_DEG = 150.0
"""A hinge moment opposing deflection, like an aerodynamic load on a surface (illustrative)."""


def _feedback(deg: np.ndarray, ch_name: str, rng: np.random.Generator) -> np.ndarray:
    ch = load_channel(ch_name)
    v = np.asarray(ch.position_deg_to_v(deg)) + rng.normal(0.0, 0.003, deg.size)
    return np.asarray(ch.feedback_cal(np.round(v / 0.005) * 0.005), dtype=float)


def clean_channel(ch_name: str, seed: int, duration_s: float = HOUR_S) -> tuple[int, float]:
    """Alarms on one channel's clean hour, and the watched seconds."""
    rng = np.random.default_rng(seed)
    fmu = frame_inputs(parse_maneuver(FLIGHT), None, duration_s=duration_s, frame_hz=FRAME_HZ)
    cmd = fmu.command_deg
    hm = -SPRING_INLB_PER_DEG * cmd
    seen = ail_command(cmd, ch_name, rng, FRAME_HZ)
    model = create("loada", ch_name)
    rec = run_maneuver(model, Inputs(fmu.time_s, seen, hm, duration_s), sample_hz=FRAME_HZ)
    held = np.minimum(np.searchsorted(fmu.time_s, rec.time_s, side="right") - 1, fmu.time_s.size - 1)
    data = MeasuredData(rec.time_s, cmd[held], _feedback(rec.position_deg[0], ch_name, rng), None, hm[held],
                        source=f"{ch_name} clean hour")
    ch = load_channel(ch_name)
    v = watch(data, learn(data, ch, 30.0), Options(healthy_s=30.0))
    return len(v.detections), v.watched_s


def clean_hour() -> Result:
    """Alarms over five channels' clean hours (each channel latches its first alarm)."""
    alarms, watched = 0, 0.0
    for k, ch in enumerate(CHANNELS):
        n, s = clean_channel(ch, 10 + k)
        alarms += n
        watched += s
    return Result(float(alarms), "alarms", alarms == 0,
                  f"{alarms} alarms in {watched / 3600.0:.2f} channel-hours (5 channels, AIL noise and delays)")


def cpu_share() -> Result:
    """The online monitor's process time per simulated second at 200 Hz, one channel."""
    _, rec, _ = simulate("loada", parse_maneuver("sine:amp_deg=3,freq_hz=0.5,cycles=60"), None, duration_s=120.0,
                         sample_hz=FRAME_HZ, faults=[parse_fault("lvdt_bias:at_s=90,size=0.1")])
    rng = np.random.default_rng(0)
    mon = OnlineMonitor(from_name("loada", load_channel("left_wing")), Options(healthy_s=30.0), 1.0 / FRAME_HZ)
    pos = rec.position_deg[0] + rng.normal(0.0, 0.01, rec.time_s.size)
    t0 = time.process_time()
    for k in range(1, rec.time_s.size):
        mon.step(float(rec.command_deg[0, k - 1]), float(rec.hinge_moment_inlb[0, k - 1]), float(pos[k]))
    share = (time.process_time() - t0) / 120.0
    found = mon.detection.kind if mon.detection else "nothing"
    return Result(100.0 * share, "% of a core", share <= 0.10, f"one channel at 200 Hz, 120 s, detected {found}")


BENCHMARKS = [
    Benchmark("monitor_clean_hour_alarms", "0 false alarms in five clean channel-hours (AIL noise and delays)",
              clean_hour),
    Benchmark("monitor_cpu_share_per_channel", "≤ 10 % of one core per channel at 200 Hz", cpu_share),
]


if __name__ == "__main__":
    for b in BENCHMARKS:
        r = b.run()
        print(f"{b.name}: {r.value:.4g} {r.unit} ({'pass' if r.passed else 'FAIL'}) {r.detail}", flush=True)
