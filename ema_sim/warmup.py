"""Compile every numba kernel ahead of its first use (``make venv`` runs this; ``python -m ema_sim.warmup``).

Numba compiles a kernel on its first call and caches the machine code beside its source, so a fresh
install would pay about two minutes of compilation (on two cores) on its first simulations and fits,
once in every process that gets there first. This drives each model of the registry and the compiled
analysis kernels once, on small inputs of the types the package passes them (C-contiguous float64
arrays, which :mod:`ema_sim.models.base` guarantees), in parallel processes, one group each.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor, as_completed
from functools import partial

import numpy as np

from ema_sim.calibration import Cubic
from ema_sim.identify.quantization import _costs
from ema_sim.models.registry import create, model_names
from ema_sim.models.stages import quantize_array
from ema_sim.montecarlo.metrics import _rms_max, _step_rows, fourier_coefficients

VARIANTS: dict[str, list[dict[str, float]]] = {
    "loada": [{}, {"integral_hz": 1.0}],
    "loadf": [{}, {"integral_hz": 1.0}],
}
"""Parameter overrides that select a kernel of their own: LOADA's and LOADF's kernels are compiled per stage
set (:mod:`ema_sim.models.second_order.stage_set`), the report's and the one with identification's stages."""


def warm_model(name: str) -> None:
    """Trim, run and step model ``name`` on one instance and on a batch of two, in each of its :data:`VARIANTS`.

    A variant's batch also runs 60 s at once, long enough for the fixed-step kernels' parallel twin
    (:data:`ema_sim.models.second_order.loada.PARALLEL_STEPS`).
    """
    for overrides in VARIANTS.get(name, [{}]):
        _warm_variant(name, overrides)
        if name in VARIANTS:
            t = np.arange(0.0, 60.0, 0.005)
            create(name, n=2, **overrides).run(t, np.zeros_like(t), np.zeros_like(t))


def _warm_variant(name: str, overrides: dict[str, float]) -> None:
    t = np.arange(0.0, 0.1, 0.005)
    u = np.where(t < 0.02, 0.0, 1.0)
    hm = np.full_like(t, 100.0)
    for n in (1, 2):
        model = create(name, n=n, **overrides)
        model.run(t, u, hm)
        model.step(0.5, 50.0)
        model.trim(command_deg=0.2, hinge_moment_inlb=10.0)
        model.run(t + 1.0, u, hm, sample_times=t + 1.0025)


def warm_analysis() -> None:
    """The compiled kernels outside the models: fits, Monte Carlo metrics, calibration curves."""
    x = np.linspace(-1.0, 1.0, 64)
    rows = np.ascontiguousarray(np.vstack([x, x]))
    idx = np.array([0], dtype=np.int64)
    _costs(x, x, 0.0, np.array([0.01, 0.02]), np.array([1.0]), np.array([1.0]), np.ones_like(x), idx,
           np.array([x.size], dtype=np.int64), 0)
    fourier_coefficients(rows, np.linspace(0.0, 1.0, x.size), np.array([1.0, 2.0]))
    _rms_max(rows)
    _step_rows(np.linspace(0.0, 1.0, x.size), rows, rows, 0.02)
    quantize_array(x, 0.01)
    cubic = Cubic(0.0, 1.0, 0.01, 0.001)
    cubic(x), cubic.slope(x), cubic.inverse(x)


TOGETHER = {"loac": ("loac", "second_order")}
"""Models compiled in one process, one after the other: LOAC and the identification simulator share figure 26's
functions, which two processes at once would both compile (measured: every group 130 CPU-s apart, 121 s in turn)."""


def warm_models(names: tuple[str, ...]) -> None:
    """:func:`warm_model` on each of ``names``, in turn.

    Parameters
    ----------
    names : tuple of str
        Registry names.
    """
    for name in names:
        warm_model(name)


_MERGED = {name for names in TOGETHER.values() for name in names}
GROUPS: dict[str, Callable[[], None]] = {
    **{name: partial(warm_models, names) for name, names in TOGETHER.items()},
    **{name: partial(warm_model, name) for name in model_names() if name not in _MERGED},
    "analysis": warm_analysis,
}
"""What compiles in one process: a model of the registry (or models of :data:`TOGETHER`), or the kernels outside
the models."""
SLOWEST_FIRST = ("loac", "loadf", "loada", "hoac1", "hoad3", "analysis", "sloac", "hoad2")
"""The groups by compilation time, longest first (45.4, 21.8, 20.1, 10.0, 6.5, 3.2 s… measured two at a time on the
idle machine), so the processes end together."""


def warm(group: str) -> tuple[str, float]:
    """Compile one group; its name and the seconds it took."""
    start = time.perf_counter()
    GROUPS[group]()
    return group, time.perf_counter() - start


def main(argv: list[str] | None = None) -> int:
    """Compile every group, ``--jobs`` processes at once (default: one per core)."""
    parser = argparse.ArgumentParser(prog="python -m ema_sim.warmup", description=__doc__.splitlines()[0])
    parser.add_argument("--jobs", type=int, default=os.cpu_count() or 1, help="processes at once")
    parser.add_argument("-q", "--quiet", action="store_true", help="print nothing but errors")
    args = parser.parse_args(argv)
    start = time.perf_counter()
    order = sorted(GROUPS, key=lambda g: SLOWEST_FIRST.index(g) if g in SLOWEST_FIRST else len(SLOWEST_FIRST))
    with ProcessPoolExecutor(max_workers=max(1, args.jobs)) as pool:
        for done in as_completed([pool.submit(warm, g) for g in order]):
            group, seconds = done.result()
            if not args.quiet:
                print(f"compiled {group} in {seconds:.1f} s", flush=True)
    if not args.quiet:
        print(f"every kernel compiled and cached in {time.perf_counter() - start:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
