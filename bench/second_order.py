"""Speed of the second-order family: one LOADA channel and a Monte Carlo batch.

Targets sit near what the code does (issue 27): 17,100–18,000× in four sittings on the idle two-core machine
(35,900× in one) and 0.112–0.126 s, once the kernels stopped counting references
(:mod:`ema_sim.models.compiling`), so a lost fifth shows as a FAIL (instruction counts: ``make bench-check``).
A batch this long runs its instances on numba's threads (:data:`ema_sim.models.second_order.loada.PARALLEL_STEPS`),
the same outputs bit for bit.
"""

from __future__ import annotations

import numpy as np

from ema_sim.benchmark import Benchmark, Result, timed
from ema_sim.models import create
from ema_sim.models.second_order import Loada, SecondOrderParams
from ema_sim.signals import parse_maneuver
from ema_sim.simulation import frame_inputs


def loada_realtime() -> Result:
    """One left-wing LOADA at 800 Hz through a 60 s sweep and a step set, sampled at 1 kHz."""
    sweep = frame_inputs(parse_maneuver("sweep:f0_hz=0.2,f1_hz=18,amp_deg=1,sweep_s=60,lead_s=0"))
    model = create("loada", "left_wing", rate_hz=800.0)
    samples = np.arange(0, 60_000) / 1000.0

    def once() -> None:
        model.trim(0.0, 0.0)
        model.run(sweep.time_s, sweep.command_deg, sweep.hinge_moment_inlb, sample_times=samples, end_s=60.0)

    wall = timed(once)
    ratio = 60.0 / wall
    return Result(ratio, "× real time", ratio >= 15000.0, f"60 s simulated in {wall * 1e3:.2f} ms")


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
    return Result(wall, "s", wall <= 0.15, "1,000 instances × 10 s at 800 Hz")


BENCHMARKS = [
    Benchmark("loada_800hz_one_channel", "≥ 15,000× real time", loada_realtime),
    Benchmark("loada_batch_1000x10s", "≤ 0.15 s", loada_batch),
]
