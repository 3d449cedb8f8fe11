"""Speed and accuracy of the high-order family: HOAC1 and a LOES refit against JSBSim in the same run, figure 40.

HOAD3 beside JSBSim is ``bench/jsbsim_side.py``'s.
"""

from __future__ import annotations

import itertools
import time

import numpy as np

from ema_sim.analysis.studies.loes import fit_loes
from ema_sim.analysis.studies.model_error import FIGURE40_RATES_HZ, figure40
from ema_sim.benchmark import Benchmark, Result, jsbsim_realtime, jsbsim_seconds, timed
from ema_sim.models import create
from ema_sim.signals import parse_maneuver
from ema_sim.simulation import frame_inputs

SWEEP = "sweep:f0_hz=0.2,f1_hz=18,amp_deg=1,sweep_s=60,lead_s=0"
HOAC1_TARGET = 0.1
"""HOAC1's continuous solver against JSBSim's discrete chain at 10 kHz (a tenth of its speed or better)."""
LOES_TARGET = 5.0
"""A LOES refit within this many JSBSim runs of 60 s at 10 kHz."""


def _sweep_ratio(name: str, **kwargs: object) -> tuple[float, float]:
    sweep = frame_inputs(parse_maneuver(SWEEP))
    model = create(name, "left_wing", **kwargs)
    samples = np.arange(0, 60_000) / 1000.0

    def once() -> None:
        model.trim(0.0, 0.0)
        model.run(sweep.time_s, sweep.command_deg, sweep.hinge_moment_inlb, sample_times=samples, end_s=60.0)

    wall = timed(once)
    return 60.0 / wall, wall


def hoac1_realtime() -> Result:
    """The continuous reference on the same sweep: adaptive Dormand–Prince with located events, × JSBSim at 10 kHz."""
    ratio, wall = _sweep_ratio("hoac1")
    theirs = jsbsim_realtime(10_000.0)
    return Result(ratio / theirs, "× JSBSim", ratio / theirs >= HOAC1_TARGET,
                  f"60 s simulated in {wall:.2f} s ({ratio:.2f}× real time), JSBSim {theirs:.1f}× at 10 kHz")


def figure40_errors() -> Result:
    """Figure 40: HOAD2 at 10, 20, 50, 100 kHz against HOAC1 (mean |error| of position, deg)."""
    rows = figure40()
    means = [r.mean_abs_deg for r in rows]
    detail = "; ".join(f"{r.rate_hz / 1000:g} kHz mean {r.mean_abs_deg:.2e} max {r.max_abs_deg:.2e}" for r in rows)
    falling = all(a > b for a, b in itertools.pairwise(means))
    return Result(means[0], "deg", falling and len(rows) == len(FIGURE40_RATES_HZ), detail)


def loes_fit() -> Result:
    """Refit one channel's LOES: 24 sine dwells of HOAD3 in one batch, then the transfer-function fit.

    Its time in JSBSim runs: the wall time over what JSBSim takes to simulate 60 s at 10 kHz.
    """
    t0 = time.perf_counter()
    fit = fit_loes("left_wing")
    wall = time.perf_counter() - t0
    runs = wall / jsbsim_seconds(60.0, 10_000.0)
    c = fit.coefficients
    detail = (f"{wall:.2f} s; wn {c['wn_rad_s']:.2f} rad/s, zeta {c['zeta']:.3f}, delay {c['delay_s'] * 1e3:.2f} ms, "
              f"J {fit.cost:.3f}")
    return Result(runs, "JSBSim 60 s runs", runs <= LOES_TARGET, detail)


BENCHMARKS = [
    Benchmark("hoac1_one_channel", f"≥ {HOAC1_TARGET:g}× JSBSim at 10 kHz", hoac1_realtime),
    Benchmark("figure40_hoad2_vs_hoac1", "error falls with rate", figure40_errors),
    Benchmark("loes_refit_left_wing", f"≤ {LOES_TARGET:g} JSBSim 60 s runs", loes_fit),
]
