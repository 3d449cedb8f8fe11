"""The two commands' running times, as a newcomer meets them: ``make demo`` and the test suite of ``make test``.

These are budgets, not speed targets: the suite must finish within ten minutes on two cores (CI runs it on a
fresh clone), and so should the main job. Each is run as its own process from the checkout, as the Makefile
runs it (the venv already built), and its wall time is recorded with the date (``ema bench --record``), the one
source the documentation's figures of both come from (``docs/figures.md``).
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

from ema_sim.benchmark import Benchmark, Result

ROOT = Path(__file__).resolve().parents[1]
BUDGET_S = 600.0


def _timed(cmd: list[str], env: dict[str, str] | None = None) -> tuple[float, str]:
    t0 = time.perf_counter()
    done = subprocess.run(cmd, cwd=ROOT, env={**os.environ, **(env or {})}, capture_output=True, text=True,
                          check=False)
    wall = time.perf_counter() - t0
    tail = (done.stdout.strip().splitlines() or [""])[-1]
    if done.returncode:
        tail = f"exit {done.returncode}: {tail}"
    return wall, tail


def demo() -> Result:
    """``make demo``'s job: ``python -m ema_sim.demo`` (the node suite twice, identification, AIL, table 6)."""
    wall, tail = _timed([sys.executable, "-m", "ema_sim.demo"])
    return Result(wall, "s", wall <= BUDGET_S and not tail.startswith("exit"), tail[:160])


def suite() -> Result:
    """``make test``'s pytest run (two workers, the tests not marked slow), as the Makefile runs it."""
    wall, tail = _timed([sys.executable, "-m", "pytest", "-q", "-n", "2", "--dist", "loadgroup", "-m", "not slow"],
                        {"NUMBA_NUM_THREADS": "1"})
    return Result(wall, "s", wall <= BUDGET_S and not tail.startswith("exit"), tail[:160])


BENCHMARKS = [
    Benchmark("make_demo_wall", "≤ 600 s on two cores", demo),
    Benchmark("make_test_pytest_wall", "≤ 600 s on two cores", suite),
]
