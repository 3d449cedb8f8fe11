"""The instruction-count guard (``make bench-check``): its verdicts and its baseline (issue 27).

The counting itself runs under valgrind for minutes, so the suite checks the decision and the recorded
baseline; ``make bench-check`` counts.
"""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import pytest

BENCH = Path(__file__).resolve().parents[1] / "bench"


def _guard():
    spec = importlib.util.spec_from_file_location("ema_callgrind_guard", BENCH / "callgrind.py")
    assert spec is not None
    assert spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_a_count_over_the_tolerance_fails_and_one_within_it_passes():
    guard = _guard()
    base = {"a": 1_000_000, "b": 2_000_000}
    assert guard.compare({"a": 1_049_000, "b": 1_500_000}, base) == []
    lines = guard.compare({"a": 1_051_000, "b": 2_000_000}, base)
    assert len(lines) == 1
    assert lines[0].startswith("a: 1,051,000")
    assert "+5.1%" in lines[0]
    assert guard.compare({"c": 5}, base) == ["c: 5 instructions, no baseline (record one)"]
    assert guard.compare({"a": 1_100_000}, base, tolerance=0.2) == []


def test_the_baseline_counts_every_workload_and_names_its_machine():
    guard = _guard()
    recorded = json.loads((BENCH / "baseline.json").read_text())
    assert set(recorded["counts"]) == set(guard.WORKLOADS)
    assert all(isinstance(n, int) and n > 100_000 for n in recorded["counts"].values())
    assert {"cpu", "numba", "llvmlite", "numpy", "python"} <= set(recorded["machine"])


def test_an_unknown_workload_is_refused(capsys):
    guard = _guard()
    with pytest.raises(SystemExit) as exc:
        guard.main(["count", "no_such_kernel"])
    assert exc.value.code == 2
    assert "unknown workload(s) no_such_kernel" in capsys.readouterr().err
