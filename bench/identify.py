"""Speed of identification (issue: close the loop): a 90 s record at 1 kHz in ≤ 60 s."""

from __future__ import annotations

import sys
import time
from pathlib import Path

from ema_sim.benchmark import Benchmark, Result
from ema_sim.config import load_channel
from ema_sim.identify.stepwise import identify

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "test"))
from identgen import make_record


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


BENCHMARKS = [Benchmark("identify_90s_record_1khz", "≤ 60 s", identify_90s)]
