"""Speed of the offline analysis: a 60 s sweep sampled at 1 kHz, against JSBSim simulating it.

The time is in JSBSim runs (:func:`ema_sim.benchmark.jsbsim_seconds`): the analysis's wall time over what JSBSim's
actuator chain takes to simulate the same 60 s at 800 Hz in the same run: at most four.
"""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np

from ema_sim.analysis.pipeline import analyze_record
from ema_sim.benchmark import Benchmark, Result, jsbsim_seconds, timed
from ema_sim.io.measured import MeasuredData
from ema_sim.signals import parse_maneuver
from ema_sim.simulation import csv_columns, simulate


def _sweep_record() -> MeasuredData:
    """LOADA, left wing, 0.2-18 Hz ±1° over 60 s (no lead-in), DAU at 1 kHz, 0.003° sensor noise on both outputs."""
    model, rec, meta = simulate("loada", parse_maneuver("sweep:f0_hz=0.2,f1_hz=18,amp_deg=1,sweep_s=60,lead_s=0"))
    data = MeasuredData(metadata=meta, source="bench sweep", **csv_columns(model, rec))
    rng = np.random.default_rng(0)
    return replace(data, position_deg=data.position_deg + rng.normal(0, 0.003, len(data)),
                   surface_deg=data.surface_deg + rng.normal(0, 0.003, len(data)))


def sweep_analysis() -> Result:
    """Recognition, composite-window frequency response and second-order fit of both outputs."""
    data = _sweep_record()
    wall = timed(lambda: analyze_record(data))
    t0 = time.perf_counter()
    ra = analyze_record(data)
    once = time.perf_counter() - t0
    responses = ra.results["frequency_response"]
    fit = responses[0].fit
    runs = wall / jsbsim_seconds(60.0, 800.0)
    detail = (f"{len(data):,} samples, {len(responses)} responses; best {wall * 1e3:.0f} ms, last "
              f"{once * 1e3:.0f} ms; fit ωn {fit.wn_rad_s.value:.2f} rad/s, ζ {fit.zeta.value:.3f}")
    return Result(runs, "JSBSim 60 s runs", runs <= 4.0, detail)


BENCHMARKS = [
    Benchmark("analyze_60s_sweep_1khz", "≤ 4 JSBSim runs of the record at 800 Hz", sweep_analysis),
]
