"""LOADA and HOAD3 beside JSBSim on the same machine in the same minute (issue 27).

JSBSim 1.3.3 runs figure 21's servo written as flight-control components (``bench/jsbsim/aircraft/
ema_actuator``: summers, gains, a clipped rate command, two integrators) on a bare airframe, stepped from
Python one frame at a time as a host simulation would, the command changed every 5 ms frame. The
figures are ratios measured in one process, so they hold whatever else the machine runs.
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import jsbsim
import numpy as np

from ema_sim.benchmark import Benchmark, Result, timed
from ema_sim.models import create
from ema_sim.signals import parse_maneuver
from ema_sim.simulation import frame_inputs

ROOT = Path(__file__).resolve().with_name("jsbsim")
DURATION_S = 10.0


def jsbsim_ratio(rate_hz: float, duration_s: float = DURATION_S) -> float:
    """JSBSim's real-time ratio on the servo at ``rate_hz`` (best of 3)."""
    jsbsim.FGJSBBase().debug_lvl = 0  # no start-up banner
    fdm = jsbsim.FGFDMExec(str(ROOT), None)
    fdm.set_debug_level(0)
    if not fdm.load_model("ema_actuator"):
        raise RuntimeError(f"JSBSim could not load {ROOT}/aircraft/ema_actuator")
    fdm.set_dt(1.0 / rate_hz)
    fdm.run_ic()
    steps = round(duration_s * rate_hz)
    per_frame = max(round(rate_hz * 0.005), 1)
    best = math.inf
    for _ in range(3):
        t0 = time.perf_counter()
        for k in range(steps):
            if k % per_frame == 0:
                fdm["fcs/ema-cmd-deg"] = math.sin(2.0 * math.pi * k / rate_hz)
            fdm.run()
        best = min(best, time.perf_counter() - t0)
    return duration_s / best


def ema_ratio(name: str, duration_s: float = DURATION_S) -> float:
    """ema_sim's real-time ratio for ``name`` on a sweep sampled at 1 kHz (best of 3)."""
    sweep = frame_inputs(parse_maneuver(f"sweep:f0_hz=0.2,f1_hz=18,amp_deg=1,sweep_s={duration_s},lead_s=0"))
    model = create(name, "left_wing")
    samples = np.arange(0, round(duration_s * 1000)) / 1000.0

    def once() -> None:
        model.trim(0.0, 0.0)
        model.run(sweep.time_s, sweep.command_deg, sweep.hinge_moment_inlb, sample_times=samples, end_s=duration_s)

    return duration_s / timed(once)


def side_by_side(name: str, rate_hz: float, target: float) -> Result:
    """``name`` against JSBSim at the model's own rate: how many times faster, in the same sitting."""
    ours = ema_ratio(name)
    theirs = jsbsim_ratio(rate_hz)
    ratio = ours / theirs
    return Result(ratio, "× JSBSim", ratio >= target,
                  f"{name} {ours:,.0f}× real time, JSBSim {jsbsim.__version__} {theirs:,.1f}× at {rate_hz:g} Hz")


BENCHMARKS = [
    Benchmark("loada_vs_jsbsim_800hz", "≥ 50× JSBSim", lambda: side_by_side("loada", 800.0, 50.0)),
    Benchmark("hoad3_vs_jsbsim_10khz", "≥ 25× JSBSim", lambda: side_by_side("hoad3", 10_000.0, 25.0)),
]
