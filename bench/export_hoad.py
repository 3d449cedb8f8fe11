"""The exported HOAD3 in C beside the numba kernel and JSBSim's actuator chain, in the same run.

The C model is what ``ema export hoad3 --c`` writes, compiled with the export's flags (no fast-math, no fused
multiply-adds) and driven by a small C host: a 10 s sine sweep, one ``ema_advance`` of 10 steps per 1 kHz frame
(the FMU's ``fmi2DoStep``), best of three. The numba kernel runs the same sweep through ``Model.run`` (one call,
its own breakpoints); JSBSim is the run's yardstick at 10 kHz (:func:`ema_sim.benchmark.jsbsim_realtime`).
Figures are steps per second of the 10 kHz model; the targets are ratios: the C model ≥ 100× JSBSim (HOAD3's
own target) and at least half the numba kernel's speed.
"""

from __future__ import annotations

import subprocess
import tempfile
from pathlib import Path

from ema_sim.benchmark import Benchmark, Result, jsbsim_realtime, jsbsim_version
from ema_sim.export import csource, hoad_c
from ema_sim.export.target import resolve

DURATION_S = 10.0
RATE_HZ = 10_000.0
JSBSIM_TARGET = 20.0
"""The C HOAD3 against JSBSim's chain at 10 kHz: a 10 kHz model with room to spare in a host that runs JSBSim."""
NUMBA_TARGET = 0.5
"""The C HOAD3 against the numba kernel (the export must not be the slow way to run the model)."""

HOST = r"""/* a host driving the exported HOAD3: a sine sweep, one frame of 10 steps per ms, best of three */
#define _POSIX_C_SOURCE 199309L
#include <math.h>
#include <stdio.h>
#include <time.h>
#include "ema_actuator.h"

int main(void) {
    const long frames = (long)(DURATION_S * 1000.0);
    double best = 1e30, sink = 0.0;
    char msg[256];
    for (int rep = 0; rep < 4; rep++) {
        ema_model *m = ema_new(ema_default_params, ema_default_rate_hz, 0, 0.0, 0.0, msg, sizeof msg);
        if (!m) { fprintf(stderr, "%s\n", msg); return 2; }
        struct timespec a, b;
        clock_gettime(CLOCK_MONOTONIC, &a);
        for (long k = 0; k < frames; k++) {
            double t = k * 1e-3;
            double f = 0.2 + (18.0 - 0.2) * t / DURATION_S;
            ema_advance(m, sin(2.0 * 3.141592653589793 * f * t), 0.0, 10);
            sink += ema_output(m, EMA_O_POSITION_DEG);
        }
        clock_gettime(CLOCK_MONOTONIC, &b);
        double s = (double)(b.tv_sec - a.tv_sec) + 1e-9 * (double)(b.tv_nsec - a.tv_nsec);
        if (rep > 0 && s < best) best = s;  /* the first run warms the caches */
        ema_delete(m);
    }
    printf("%.9g %.3g\n", (double)frames * 10.0 / best, sink);
    return 0;
}
"""


def c_steps_per_s() -> float:
    """Steps per second of the exported HOAD3 (left_wing, noise on) driven by the C host above."""
    with tempfile.TemporaryDirectory(prefix="ema_bench_hoad_") as tmp:
        d = Path(tmp)
        hoad_c.write_sources(d, hoad_c.target_values(resolve("hoad3", "left_wing")))
        (d / "host.c").write_text(HOST, encoding="utf-8")
        exe = csource.compile_c([d / f for f in (*hoad_c.SOURCES, "host.c")], d / "host", shared=False,
                                include=[d], defines=[f"DURATION_S={DURATION_S!r}"])
        done = subprocess.run([str(exe)], capture_output=True, text=True, check=True)
        return float(done.stdout.split()[0])


def numba_steps_per_s() -> float:
    """Steps per second of the numba HOAD3 on the same sweep (``bench/jsbsim_side.py``'s measurement)."""
    from importlib.util import module_from_spec, spec_from_file_location  # noqa: PLC0415 - the sibling script

    spec = spec_from_file_location("ema_bench_jsbsim_side", Path(__file__).with_name("jsbsim_side.py"))
    if spec is None or spec.loader is None:
        raise FileNotFoundError("bench/jsbsim_side.py")
    side = module_from_spec(spec)
    spec.loader.exec_module(side)
    return float(side.ema_ratio("hoad3", DURATION_S)) * RATE_HZ


def c_vs_jsbsim() -> Result:
    """The C HOAD3 in × JSBSim's chain at 10 kHz, with numba's beside it."""
    ours = c_steps_per_s()
    numba = numba_steps_per_s()
    theirs = jsbsim_realtime(RATE_HZ) * RATE_HZ
    ratio = ours / theirs
    return Result(ratio, "× JSBSim", ratio >= JSBSIM_TARGET,
                  f"C {ours:,.0f} steps/s ({1e9 / ours:.1f} ns/step), numba {numba:,.0f} steps/s "
                  f"({1e9 / numba:.1f} ns/step), JSBSim {jsbsim_version()} {theirs:,.0f} steps/s at 10 kHz")


def c_vs_numba() -> Result:
    """The C HOAD3 over the numba kernel, steps per second."""
    ours = c_steps_per_s()
    numba = numba_steps_per_s()
    ratio = ours / numba
    return Result(ratio, "× numba", ratio >= NUMBA_TARGET,
                  f"C {ours:,.0f} steps/s, numba {numba:,.0f} steps/s (a 10 s sweep at 1 kHz frames)")


BENCHMARKS = [
    Benchmark("hoad3_c_vs_jsbsim_10khz", f"≥ {JSBSIM_TARGET:g}× JSBSim", c_vs_jsbsim),
    Benchmark("hoad3_c_vs_numba", f"≥ {NUMBA_TARGET:g}× numba", c_vs_numba),
]
