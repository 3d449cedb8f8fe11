"""LOADA and HOAD3 beside JSBSim on the same machine in the same minute.

JSBSim runs figure 21's servo written as flight-control components (``bench/jsbsim/aircraft/ema_actuator``:
summers, gains, a clipped rate command, two integrators) on a bare airframe, stepped from Python one frame
at a time as a host simulation would, the command changed every 5 ms frame
(:func:`ema_sim.benchmark.jsbsim_realtime`, the run's yardstick). The figures are ratios measured in one
process, so they hold whatever else the machine runs: LOADA ≥ 60× JSBSim at 800 Hz, HOAD3 ≥ 100× at 10 kHz.
"""

from __future__ import annotations

import numpy as np

from ema_sim.benchmark import Benchmark, Result, jsbsim_realtime, jsbsim_version, timed
from ema_sim.models import create
from ema_sim.signals import parse_maneuver
from ema_sim.simulation import frame_inputs

DURATION_S = 10.0


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
    theirs = jsbsim_realtime(rate_hz)
    ratio = ours / theirs
    return Result(ratio, "× JSBSim", ratio >= target,
                  f"{name} {ours:,.0f}× real time, JSBSim {jsbsim_version()} {theirs:,.1f}× at {rate_hz:g} Hz")


BENCHMARKS = [
    Benchmark("loada_vs_jsbsim_800hz", "≥ 60× JSBSim", lambda: side_by_side("loada", 800.0, 60.0)),
    Benchmark("hoad3_vs_jsbsim_10khz", "≥ 100× JSBSim", lambda: side_by_side("hoad3", 10_000.0, 100.0)),
]
