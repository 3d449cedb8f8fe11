"""Instruction counts of the kernels every tool runs, guarded against a baseline (``make bench-check``).

Wall-clock figures move with whatever else runs on the machine; ``valgrind --tool=callgrind`` counts the
same instructions for the same binary and inputs. Each workload below runs once uninstrumented (imports,
numba's cache, first-call costs), then once between ``CALLGRIND_START_INSTRUMENTATION`` and a stats dump
named after it (a small C shim built here). The counts are compared with ``bench/baseline.json``:
a count more than :data:`TOLERANCE` above its baseline fails, unless the baseline is re-recorded
(``python bench/callgrind.py record``) in the same commit, with the reason in the commit message.

Counts depend on the binary: the baseline records the CPU numba compiled for and the library versions, and
a machine that differs says so rather than comparing.

usage: python bench/callgrind.py check | record | count [WORKLOAD ...]
"""

from __future__ import annotations

import argparse
import ctypes
import json
import os
import platform
import shutil
import subprocess
import sys
import sysconfig
import tempfile
from collections.abc import Callable
from pathlib import Path

import llvmlite
import llvmlite.binding as llvm
import numba
import numpy as np

from ema_sim.config import load_channel
from ema_sim.identify.fit import evaluate
from ema_sim.identify.problem import Problem
from ema_sim.models import create
from ema_sim.models.second_order import Loada, SecondOrderParams
from ema_sim.signals import parse_maneuver
from ema_sim.simulation import frame_inputs

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
BASELINE = HERE / "baseline.json"
"""The recorded counts (``counts``, ``machine``) beside ``ema bench``'s recorded figures (``bench``)."""
TOLERANCE = 0.05
"""A count may grow by this share of its baseline before the guard fails."""
SHIM = r"""
#include <valgrind/callgrind.h>
void ema_cg_start(void) { CALLGRIND_ZERO_STATS; CALLGRIND_START_INSTRUMENTATION; }
void ema_cg_stop(const char *name) { CALLGRIND_DUMP_STATS_AT(name); CALLGRIND_STOP_INSTRUMENTATION; }
"""


# ------------------------------------------------------------------------------------------- workloads
def _loada_run() -> Callable[[], None]:
    sweep = frame_inputs(parse_maneuver("sweep:f0_hz=0.2,f1_hz=18,amp_deg=1,sweep_s=10,lead_s=0"))
    model = create("loada", "left_wing", rate_hz=800.0)
    samples = np.arange(0, 10_000) / 1000.0

    def run() -> None:
        model.trim(0.0, 0.0)
        model.run(sweep.time_s, sweep.command_deg, sweep.hinge_moment_inlb, sample_times=samples, end_s=10.0)

    return run


def _loada_step() -> Callable[[], None]:
    model = create("loada", "left_wing", rate_hz=800.0)
    commands = 2.0 * np.sin(np.arange(1000) * 0.05)

    def run() -> None:
        model.trim(0.0, 0.0)
        for u in commands:
            model.step_values(float(u), 100.0)

    return run


def _loada_batch() -> Callable[[], None]:
    rng = np.random.default_rng(1)
    base = SecondOrderParams.from_channel(create("loada").channel)
    params = [base.replace(wn_rad_s=base.wn_rad_s * rng.uniform(0.9, 1.1), zeta=base.zeta * rng.uniform(0.9, 1.1))
              for _ in range(100)]
    model = Loada("left_wing", n=100, params=params)
    inputs = frame_inputs(parse_maneuver("steps:amps_deg=1/-1/0.5,lead_s=0.5,hold_s=1.5"), duration_s=10.0)

    def run() -> None:
        model.trim(0.0, 0.0)
        model.run(inputs.time_s, inputs.command_deg, inputs.hinge_moment_inlb, end_s=10.0)

    return run


def _high_order(name: str, duration_s: float) -> Callable[[], Callable[[], None]]:
    def make() -> Callable[[], None]:
        sweep = frame_inputs(parse_maneuver(f"sweep:f0_hz=0.5,f1_hz=20,amp_deg=1,sweep_s={duration_s},lead_s=0"))
        model = create(name, "left_wing")
        samples = np.arange(0, int(duration_s * 1000)) / 1000.0

        def run() -> None:
            model.trim(0.0, 0.0)
            model.run(sweep.time_s, sweep.command_deg, sweep.hinge_moment_inlb, sample_times=samples,
                      end_s=duration_s)

        return run

    return make


def _identify_iteration() -> Callable[[], None]:
    sys.path.insert(0, str(ROOT / "test"))
    from identgen import make_record  # noqa: PLC0415 - the test suite's record generator, on its path only here

    channel = load_channel("left_wing")
    data = make_record({"time_delay": 0.008, "compliance": 0.3}, seed=7, duration_s=5.0)
    problem = Problem(data, channel)
    base = SecondOrderParams.from_channel(channel)

    def run() -> None:
        problem.forget_runs()  # the simulations themselves, each time, not the runs kept from the call before
        evaluate(problem, base, ["wn_rad_s", "zeta", "delay_s", "compliance_deg_per_kinlb"])

    return run


WORKLOADS: dict[str, Callable[[], Callable[[], None]]] = {
    "loada_run_10s": _loada_run,
    "loada_step_1000_frames": _loada_step,
    "loada_batch_100x10s": _loada_batch,
    "hoad3_run_1s": _high_order("hoad3", 1.0),
    "loes_run_10s": _high_order("loes", 10.0),
    "identify_iteration_5s": _identify_iteration,
}
"""Each workload's set-up; it returns the call that is counted."""


# ---------------------------------------------------------------------------------------------- child
def child(names: list[str], shim: str) -> None:
    """Under callgrind: set up and warm each workload, then count one call of it."""
    lib = ctypes.CDLL(shim)
    for name in names:
        call = WORKLOADS[name]()
        call()
        call()
        lib.ema_cg_start()
        call()
        lib.ema_cg_stop(name.encode())


# --------------------------------------------------------------------------------------------- parent
def machine() -> dict[str, str]:
    """What the counts depend on: the CPU numba compiles for and the versions of the compilers in the path."""
    return {"cpu": llvm.get_host_cpu_name(), "python": platform.python_version(), "numba": numba.__version__,
            "llvmlite": llvmlite.__version__, "numpy": np.__version__}


def build_shim(out_dir: Path) -> Path:
    """Compile the two client requests into a shared library."""
    cc = shutil.which("cc") or shutil.which("gcc")
    if cc is None:
        raise SystemExit("callgrind guard: no C compiler (cc) to build the shim")
    src = out_dir / "shim.c"
    src.write_text(SHIM)
    lib = out_dir / "libemacg.so"
    subprocess.run([cc, "-O2", "-shared", "-fPIC", "-o", str(lib), str(src)], check=True)
    return lib


def count(names: list[str]) -> dict[str, int]:
    """Instruction counts of the named workloads, from one callgrind run of this script."""
    if shutil.which("valgrind") is None:
        raise SystemExit("callgrind guard: valgrind is not installed")
    with tempfile.TemporaryDirectory() as tmp:
        out_dir = Path(tmp)
        shim = build_shim(out_dir)
        # the interpreter the venv links to, with the venv's packages on the path: valgrind on the venv's
        # own python wrote nothing here (../shared/notes/measuring-speed.md)
        python = os.path.realpath(sys.executable)
        path = os.pathsep.join([sysconfig.get_paths()["purelib"], str(ROOT)])
        env = {**os.environ, "PYTHONPATH": path, "PYTHONHASHSEED": "0", "NUMBA_NUM_THREADS": "1"}
        cmd = ["valgrind", "--tool=callgrind", "--instr-atstart=no",
               f"--callgrind-out-file={out_dir}/cg.%p", python, __file__, "child", "--shim", str(shim), *names]
        done = subprocess.run(cmd, check=False, env=env, capture_output=True, text=True)
        if done.returncode != 0:
            raise SystemExit(f"callgrind guard: the counted run failed\n{done.stderr[-3000:]}")
        counts: dict[str, int] = {}
        for dump in out_dir.glob("cg.*.*"):
            text = dump.read_text(errors="replace")
            trigger = next((ln for ln in text.splitlines() if ln.startswith("desc: Trigger: Client Request: ")), None)
            total = next((ln for ln in text.splitlines() if ln.startswith("summary: ")), None)
            if trigger and total:
                counts[trigger.rsplit(": ", 1)[1]] = int(total.split()[1])
    missing = set(names) - set(counts)
    if missing:
        raise SystemExit(f"callgrind guard: no count for {', '.join(sorted(missing))}")
    return {name: counts[name] for name in names}


def compare(counts: dict[str, int], baseline: dict[str, int], tolerance: float = TOLERANCE) -> list[str]:
    """The workloads whose count grew by more than ``tolerance`` of the baseline (one line each).

    Parameters
    ----------
    counts : dict
        Measured instruction counts.
    baseline : dict
        Recorded counts.
    tolerance : float
        Allowed growth, a share of the baseline.

    Returns
    -------
    list of str
        One line per regression; empty when none.
    """
    lines = []
    for name, n in counts.items():
        ref = baseline.get(name)
        if ref is None:
            lines.append(f"{name}: {n:,} instructions, no baseline (record one)")
        elif n > ref * (1.0 + tolerance):
            lines.append(f"{name}: {n:,} instructions, {n / ref - 1.0:+.1%} over the baseline {ref:,} "
                         f"(limit +{tolerance:.0%})")
    return lines


def main(argv: list[str] | None = None) -> int:
    """``check``, ``record`` or ``count``; ``child`` is the run under valgrind."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("action", choices=["check", "record", "count", "child"])
    ap.add_argument("workloads", nargs="*", help="names (default: all)")
    ap.add_argument("--shim", help=argparse.SUPPRESS)
    args = ap.parse_intermixed_args(argv)
    names = args.workloads or list(WORKLOADS)
    unknown = set(names) - set(WORKLOADS)
    if unknown:
        ap.error(f"unknown workload(s) {', '.join(sorted(unknown))}; known: {', '.join(WORKLOADS)}")
    if args.action == "child":
        child(names, args.shim)
        return 0
    counts = count(names)
    here = machine()
    recorded = json.loads(BASELINE.read_text()) if BASELINE.exists() else {"machine": {}, "counts": {}}
    base = recorded["counts"]
    for name, n in counts.items():
        ref = base.get(name)
        ratio = f"{n / ref:6.3f}× baseline" if ref else "no baseline"
        print(f"{name:26s} {n:>14,} instructions  {ratio}")
    if args.action == "record":
        BASELINE.write_text(json.dumps({**recorded, "machine": here, "counts": {**base, **counts}}, indent=1) + "\n")
        print(f"recorded {BASELINE.relative_to(ROOT)}")
        return 0
    if args.action == "count":
        return 0
    if recorded["machine"] != here:
        print(f"callgrind guard: the baseline was counted on {recorded['machine']}, this is {here}: "
              "counts are not comparable; re-record on this machine to guard it")
        return 0
    failures = compare(counts, base)
    for line in failures:
        print(f"REGRESSION {line}")
    print("callgrind guard: " + ("FAIL" if failures else f"PASS (each count within +{TOLERANCE:.0%})"))
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
