"""The harness behind ``ema bench``: speed and memory targets, measured, never asserted in unit tests.

Benchmarks live in the scripts under ``bench/``; each script defines ``BENCHMARKS``, a list of
:class:`Benchmark`. A benchmark measures one number and compares it with its target.
"""

from __future__ import annotations

import importlib.util
import json
import os
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ema_sim.errors import EmaError


@dataclass(frozen=True)
class Result:
    """One measured figure."""

    value: float
    unit: str
    passed: bool
    detail: str = ""


@dataclass(frozen=True)
class Benchmark:
    """A named measurement with its target (``target`` says it in words, ``run`` decides pass)."""

    name: str
    target: str
    run: Callable[[], Result]


def bench_dir() -> Path:
    """The ``bench/`` scripts: ``$EMA_SIM_BENCH`` or the source tree's."""
    env = os.environ.get("EMA_SIM_BENCH")
    path = Path(env) if env else Path(__file__).resolve().parents[1] / "bench"
    if not path.is_dir():
        raise EmaError(f"no bench directory at {path} (set EMA_SIM_BENCH)")
    return path


def baseline_path(path: Path | None = None) -> Path:
    """The recorded figures: ``baseline.json`` beside the scripts (``bench`` figures, callgrind ``counts``)."""
    return (path or bench_dir()) / "baseline.json"


def recorded(path: Path | None = None) -> dict[str, float]:
    """Each benchmark's recorded figure (empty when none is recorded)."""
    file = baseline_path(path)
    if not file.exists():
        return {}
    figures = json.loads(file.read_text(encoding="utf-8")).get("bench", {})
    return {str(k): float(v) for k, v in figures.items()}


def record(figures: dict[str, float], path: Path | None = None) -> Path:
    """Write ``figures`` as the recorded ones (other benchmarks' figures and the counts are kept)."""
    file = baseline_path(path)
    data = json.loads(file.read_text(encoding="utf-8")) if file.exists() else {}
    data["bench"] = {**data.get("bench", {}), **figures}
    file.write_text(json.dumps(data, indent=1) + "\n", encoding="utf-8")
    return file


def discover(path: Path | None = None) -> list[Benchmark]:
    """Every benchmark of every ``bench/*.py`` script, in file then definition order."""
    found: list[Benchmark] = []
    for script in sorted((path or bench_dir()).glob("*.py")):
        spec = importlib.util.spec_from_file_location(f"ema_bench_{script.stem}", script)
        if spec is None or spec.loader is None:
            continue
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        found.extend(getattr(module, "BENCHMARKS", []))
    return found


def timed(fn: Callable[[], Any], repeat: int = 3) -> float:
    """Best wall time of ``repeat`` calls (after one warm-up call that pays for compilation)."""
    fn()
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best
