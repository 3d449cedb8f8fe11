"""Speed of identification (issue 13): a 90 s record at 1 kHz, ``second_order`` and ``hoad3`` declared.

≤ 60 s with ``second_order`` declared, ≤ 5 min with ``hoad3`` (HOAD3 data: the declared model's own run,
its second-order-family equivalent as the baseline, then HOAD3's physical parameters fitted).
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

from ema_sim.benchmark import Benchmark, Result
from ema_sim.config import load_channel
from ema_sim.identify.identification import identify

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "test"))
from identgen import hoad3_record, make_record


def identify_90s() -> Result:
    """Delay, compliance and free play hidden in 90 s of position and surface at 1 kHz."""
    effects = {"time_delay": 0.008, "compliance": 0.3, "free_play": 0.2}
    data = make_record(effects, seed=7, duration_s=90.0)
    identify(make_record({}, seed=1, duration_s=5.0), load_channel("left_wing"))  # compile outside the clock
    t0 = time.perf_counter()
    result = identify(data, load_channel("left_wing"))
    wall = time.perf_counter() - t0
    found = sorted(s.effect for s in result.steps)
    ok = found == sorted(effects)
    return Result(wall, "s", wall <= 60.0 and ok, f"found {', '.join(found)}; {result.problem.simulations} simulations")


def identify_90s_hoad3_declared() -> Result:
    """HOAD3 data, 90 s at 1 kHz, ``hoad3`` declared: error as declared, after the fit, and the time."""
    data = hoad3_record(seed=9, duration_s=90.0)
    identify(make_record({}, seed=1, duration_s=5.0), load_channel("left_wing"), "hoad3")  # compile outside the clock
    t0 = time.perf_counter()
    result = identify(data, load_channel("left_wing"), "hoad3")
    wall = time.perf_counter() - t0
    assert result.as_declared is not None
    final = {o: float((e**2).mean() ** 0.5) for o, e in result.problem.errors_deg(result.final.sim).items()}
    before, floor = result.as_declared.rms_deg, result.problem.sigma_deg
    text = "; ".join(f"{o} {before[o]:.4g}° → {final[o]:.4g}° (floor {floor[o]:.3g}°)" for o in final)
    runs = f", {result.physical.simulations} runs" if result.physical is not None else ""
    return Result(wall, "s", wall <= 300.0, f"{text}; final {result.final_model or result.model}{runs}; added "
                  f"{', '.join(s.effect for s in result.steps) or 'nothing'}")


BENCHMARKS = [Benchmark("identify_90s_record_1khz", "≤ 60 s", identify_90s),
              Benchmark("identify_90s_hoad3_declared", "≤ 300 s", identify_90s_hoad3_declared)]
