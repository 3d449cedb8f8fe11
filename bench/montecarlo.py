"""Speed and memory of Monte Carlo campaigns: LOADA by the ten thousand, HOAD3 batches, scaling, memory.

Every campaign here is a real ``ema montecarlo`` run on a local Dask cluster (cluster start included in
the wall time); the HOAD3 batch figure is one compiled call in this process. ``EMA_BENCH_MC_RUNS``
scales the memory benchmark's large campaign (default 100,000 runs).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import yaml

from ema_sim.benchmark import Benchmark, Result, jsbsim_realtime, timed
from ema_sim.models import create
from ema_sim.montecarlo import parse_campaign, run_campaign
from ema_sim.signals import parse_maneuver
from ema_sim.simulation import frame_inputs

LOADA = {
    "campaign": "loada-steps",
    "description": "LOADA at 800 Hz through 10 s of steps, ωn, ζ and delay over the figure-23 box",
    "model": "loada", "channel": "left_wing",
    "experiments": {"steps": {"maneuver": "steps:amps_deg=1/-1/0.5,lead_s=0.5,hold_s=1.5", "duration_s": 10.0,
                              "sample_hz": 200.0}},
    "dispersions": [{"parameter": p, "uniform": "report"} for p in ("wn_rad_s", "zeta", "delay_s")],
    "metrics": ["step", "error", "peak_rate", "final_error"],
    "batch": 1000,
}


def _campaign(runs: int, workers: int | None = None, **changes: object) -> dict[str, object]:
    c = parse_campaign({**LOADA, **changes}, "loada-steps")
    with tempfile.TemporaryDirectory() as tmp:
        return run_campaign(c, Path(tmp) / "mc", runs=runs, seed=1, workers=workers, plot=False)


def loada_10000() -> Result:
    """10,000 LOADA runs × 10 s at 800 Hz on a local cluster (one worker per core), rows and summary written."""
    t0 = time.perf_counter()
    doc = _campaign(10_000)
    wall = time.perf_counter() - t0
    ratio = 10_000 * 10.0 / wall / jsbsim_realtime(800.0)
    return Result(ratio, "× JSBSim", ratio >= 15.0,
                  f"{wall:.2f} s: {doc['runs']} runs; cluster and tasks {doc['wall_s']:.2f} s (tasks "
                  f"{doc['compute_s']:.2f} s, {doc['task_s']:.2f} s of worker time), {len(doc['workers'])} workers; "
                  "channel-seconds a second against JSBSim's real-time ratio at 800 Hz")


def scaling_2_vs_1() -> Result:
    """20,000 LOADA runs on one worker, then on two: the ratio of the task phases (cluster start left out)."""
    one = _campaign(20_000, workers=1)["compute_s"]
    two = _campaign(20_000, workers=2)["compute_s"]
    ratio = one / two
    return Result(ratio, "×", ratio >= 1.8, f"1 worker {one:.2f} s, 2 workers {two:.2f} s")


def _cli_memory(runs: int, out: Path) -> dict[str, float]:
    spec = out.with_suffix(".yaml")
    spec.write_text(yaml.safe_dump(LOADA), encoding="utf-8")
    cmd = [str(Path(sys.executable).parent / "ema"), "montecarlo", str(spec), "--runs", str(runs), "--seed", "1",
           "--out", str(out), "--no-plots"]
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    doc = json.loads((out / "summary.json").read_text(encoding="utf-8"))
    return {"client": doc["memory"]["client_peak_rss_mb"], "worker": doc["memory"]["worker_peak_rss_mb"],
            "wall": doc["wall_s"]}


def memory_flat() -> Result:
    """Peak memory of the ``ema montecarlo`` process and of its workers: 10,000 runs against 100,000."""
    big = int(os.environ.get("EMA_BENCH_MC_RUNS", "100000"))
    with tempfile.TemporaryDirectory() as tmp:
        small = _cli_memory(10_000, Path(tmp) / "small")
        large = _cli_memory(big, Path(tmp) / "large")
    growth = max(large["client"] / small["client"], large["worker"] / small["worker"])
    return Result(growth, "× peak RSS", growth <= 1.25,
                  f"client {small['client']:.0f} → {large['client']:.0f} MiB, worker {small['worker']:.0f} → "
                  f"{large['worker']:.0f} MiB for 10,000 → {big:,} runs ({small['wall']:.1f} s, {large['wall']:.1f} s)")


def hoad3_batch() -> Result:
    """64 HOAD3 instances (noise on, each its own stream) through a 10 s sweep at 10 kHz in one compiled call."""
    sweep = frame_inputs(parse_maneuver("sweep:f0_hz=0.2,f1_hz=18,amp_deg=1,sweep_s=10,lead_s=0"))
    n = 64
    model = create("hoad3", "left_wing", n=n, seed=list(range(n)))
    samples = np.arange(0, 10_000) / 1000.0

    def once() -> None:
        model.trim(0.0, 0.0)
        model.run(sweep.time_s, sweep.command_deg, sweep.hinge_moment_inlb, sample_times=samples, end_s=10.0)

    wall = timed(once)
    rate = n * 10.0 / wall
    theirs = jsbsim_realtime(10_000.0)
    return Result(rate / theirs, "× JSBSim", rate / theirs >= 40.0,
                  f"{n} × 10 s in {wall:.3f} s on one core ({wall / (n * 100_000) * 1e9:.1f} ns a step): "
                  f"{rate:,.0f} channel-s/s against JSBSim's {theirs:.1f}× real time at 10 kHz")


BENCHMARKS = [
    Benchmark("montecarlo_loada_10000x10s", "≥ 15× JSBSim's channel-seconds", loada_10000),
    Benchmark("montecarlo_scaling_2_vs_1_workers", "≥ 1.8×", scaling_2_vs_1),
    Benchmark("montecarlo_memory_flat_100000", "≤ 1.25× peak RSS", memory_flat),
    Benchmark("hoad3_batch_channel_seconds", "≥ 40× JSBSim's channel-seconds per core", hoad3_batch),
]
