"""Speed and accuracy of the high-order family (issue 3): HOAD3 in real time, figure 40, HOAC1, LOES."""

from __future__ import annotations

import itertools
import time

import numpy as np

from ema_sim.analysis.studies.loes import fit_loes
from ema_sim.analysis.studies.model_error import FIGURE40_RATES_HZ, figure40
from ema_sim.benchmark import Benchmark, Result, timed
from ema_sim.models import create
from ema_sim.signals import parse_maneuver
from ema_sim.simulation import frame_inputs

SWEEP = "sweep:f0_hz=0.2,f1_hz=18,amp_deg=1,sweep_s=60,lead_s=0"


def _sweep_ratio(name: str, **kwargs: object) -> tuple[float, float]:
    sweep = frame_inputs(parse_maneuver(SWEEP))
    model = create(name, "left_wing", **kwargs)
    samples = np.arange(0, 60_000) / 1000.0

    def once() -> None:
        model.trim(0.0, 0.0)
        model.run(sweep.time_s, sweep.command_deg, sweep.hinge_moment_inlb, sample_times=samples, end_s=60.0)

    wall = timed(once)
    return 60.0 / wall, wall


def hoad3_realtime() -> Result:
    """One left-wing HOAD3 at 10 kHz, noise and quantization on, through a 60 s sweep sampled at 1 kHz."""
    ratio, wall = _sweep_ratio("hoad3")
    return Result(ratio, "× real time", ratio >= 3000.0,
                  f"60 s simulated in {wall * 1e3:.1f} ms ({wall / 600_000 * 1e9:.0f} ns a step)")


def hoac1_realtime() -> Result:
    """The continuous reference on the same sweep: adaptive Dormand–Prince with located events."""
    ratio, wall = _sweep_ratio("hoac1")
    return Result(ratio, "× real time", ratio >= 1.0, f"60 s simulated in {wall:.2f} s")


def figure40_errors() -> Result:
    """Figure 40: HOAD2 at 10, 20, 50, 100 kHz against HOAC1 (mean |error| of position, deg)."""
    rows = figure40()
    means = [r.mean_abs_deg for r in rows]
    detail = "; ".join(f"{r.rate_hz / 1000:g} kHz mean {r.mean_abs_deg:.2e} max {r.max_abs_deg:.2e}" for r in rows)
    falling = all(a > b for a, b in itertools.pairwise(means))
    return Result(means[0], "deg", falling and len(rows) == len(FIGURE40_RATES_HZ), detail)


def loes_fit() -> Result:
    """Refit one channel's LOES: 24 sine dwells of HOAD3 in one batch, then the transfer-function fit."""
    t0 = time.perf_counter()
    fit = fit_loes("left_wing")
    wall = time.perf_counter() - t0
    c = fit.coefficients
    detail = f"wn {c['wn_rad_s']:.2f} rad/s, zeta {c['zeta']:.3f}, delay {c['delay_s'] * 1e3:.2f} ms, J {fit.cost:.3f}"
    return Result(wall, "s", wall <= 10.0, detail)


BENCHMARKS = [
    Benchmark("hoad3_10khz_one_channel", "≥ 3,000× real time", hoad3_realtime),
    Benchmark("hoac1_one_channel", "≥ 1× real time", hoac1_realtime),
    Benchmark("figure40_hoad2_vs_hoac1", "error falls with rate", figure40_errors),
    Benchmark("loes_refit_left_wing", "≤ 10 s", loes_fit),
]
