"""The machine's real-time floor, beside which the node suite's real-time figures are read.

``rtfloor.c`` (compiled here with the system's C compiler) keeps the suite's frame timing: 200 Hz
frames, 0.5 ms of CPU work each (the suite's median command-to-feedback window), SCHED_FIFO 20, memory
locked. It is run as long as the suite's real-time benchmark (``EMA_BENCH_REALTIME_S``, default 600 s),
with the suite's real-time set-up (a 0 µs PM QoS CPU latency request held) and without it. Frames
whose fixed work took over a frame are frames the machine did not give the thread: no program can
miss fewer here, so a suite's missed frames are judged against this count.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import tempfile
from pathlib import Path

from ema_sim.benchmark import Benchmark, Result
from ema_sim.nodes.realtime import steal_s

DURATION_S = float(os.environ.get("EMA_BENCH_REALTIME_S", "600"))
SOURCE = Path(__file__).with_name("rtfloor.c")
PRIORITY = 20
PERIOD_MS = 5.0
WORK_MS = 0.5


def floor(cpu_latency_us: int) -> dict:
    """Run the probe once; its JSON summary (``cpu_latency_us`` < 0: no request held)."""
    cc = shutil.which("cc") or shutil.which("gcc")
    if cc is None:
        raise RuntimeError("no C compiler (cc) to build bench/rtfloor.c")
    with tempfile.TemporaryDirectory(prefix="ema_rtfloor_") as tmp:
        exe = Path(tmp) / "rtfloor"
        subprocess.run([cc, "-O2", "-o", str(exe), str(SOURCE)], check=True)
        steal0 = steal_s()
        out = subprocess.run([str(exe), f"{DURATION_S:g}", str(PRIORITY), f"{PERIOD_MS:g}", f"{WORK_MS:g}",
                              str(cpu_latency_us)], check=True, capture_output=True, text=True,
                             timeout=DURATION_S * 2 + 60).stdout
        steal1 = steal_s()
    got = json.loads(out)
    got["steal_s"] = steal1 - steal0 if steal0 is not None and steal1 is not None else float("nan")
    return got


def machine_floor(cpu_latency_us: int) -> Result:
    """Missed frames of the fixed-work probe (target 0, as the suite's)."""
    got = floor(cpu_latency_us)
    held = f"{cpu_latency_us} µs CPU latency request held" if got["cpu_latency_held"] else "no CPU latency request"
    setup = f"SCHED_FIFO {got['sched_fifo']}, memory {'locked' if got['memory_locked'] else 'not locked'}, {held}"
    return Result(got["missed"], "missed frames", got["missed"] == 0,
                  f"C loop, {WORK_MS:g} ms of work every {PERIOD_MS:g} ms for {DURATION_S:g} s ({setup}): "
                  f"{got['frames']} frames, {got['missed']} with the work window over a frame "
                  f"({got['missed_off_cpu']} of them with the thread's CPU time under a frame), "
                  f"longest window {got['max_window_ms']:.2f} ms; {got['late_wakeups']} wake-ups over a frame late; "
                  f"the machine's stolen CPU time {got['steal_s']:.2f} s")


BENCHMARKS = [
    Benchmark("machine_floor_realtime_setup", "0 missed (the suite's real-time target, asked of any program)",
              lambda: machine_floor(0)),
    Benchmark("machine_floor_cpu_idle", "0 missed (the same, idle CPUs halting: no CPU latency request)",
              lambda: machine_floor(-1)),
]
