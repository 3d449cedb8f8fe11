"""Speed of the second-order family in a Monte Carlo batch, against JSBSim's channel-seconds in the same run.

One LOADA channel beside JSBSim is ``bench/jsbsim_side.py``'s. A batch this long runs its instances on numba's
threads (:data:`ema_sim.models.second_order.loada.PARALLEL_STEPS`), the same outputs bit for bit. Its speed is
channel-seconds simulated per wall second over JSBSim's real-time ratio on the servo at the same 800 Hz
(:func:`ema_sim.benchmark.jsbsim_realtime`): ≥ 300× (instruction counts: ``make bench-check``).
"""

from __future__ import annotations

import numpy as np

from ema_sim.benchmark import Benchmark, Result, jsbsim_realtime, timed
from ema_sim.models import create
from ema_sim.models.second_order import Loada, SecondOrderParams
from ema_sim.signals import parse_maneuver
from ema_sim.simulation import frame_inputs


def loada_batch() -> Result:
    """1,000 LOADA instances (ωn, ζ spread ±10 %) for 10 simulated seconds of a 1° step set."""
    rng = np.random.default_rng(1)
    base = SecondOrderParams.from_channel(create("loada").channel)
    params = [
        base.replace(wn_rad_s=base.wn_rad_s * rng.uniform(0.9, 1.1), zeta=base.zeta * rng.uniform(0.9, 1.1))
        for _ in range(1000)
    ]
    model = Loada("left_wing", n=1000, params=params)
    inputs = frame_inputs(parse_maneuver("steps:amps_deg=1/-1/0.5,lead_s=0.5,hold_s=1.5"), duration_s=10.0)

    def once() -> None:
        model.trim(0.0, 0.0)
        model.run(inputs.time_s, inputs.command_deg, inputs.hinge_moment_inlb, end_s=10.0)

    wall = timed(once)
    rate = 1000 * 10.0 / wall
    theirs = jsbsim_realtime(800.0)
    ratio = rate / theirs
    return Result(ratio, "× JSBSim", ratio >= 300.0,
                  f"1,000 instances × 10 s at 800 Hz in {wall:.3f} s: {rate:,.0f} channel-s/s against JSBSim's "
                  f"{theirs:,.0f}× real time")


BENCHMARKS = [
    Benchmark("loada_batch_1000x10s", "≥ 300× JSBSim's channel-seconds", loada_batch),
]
