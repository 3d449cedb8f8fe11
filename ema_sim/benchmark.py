"""The harness behind ``ema bench``: speed and memory targets, measured, never asserted in unit tests.

Benchmarks live in the scripts under ``bench/``; each script defines ``BENCHMARKS``, a list of
:class:`Benchmark`. A benchmark measures one number and compares it with its target.

Every speed target is a **ratio against a yardstick measured in the same run**, never an absolute time: a
wall-clock figure on a shared two-core machine says more of what else it runs than of the code. The
yardstick is JSBSim's actuator chain (:func:`jsbsim_realtime`: figure 21's servo written as JSBSim
flight-control components under ``bench/jsbsim``, stepped from Python one frame at a time as a host does),
measured again for each benchmark right beside its workload: a shared machine's speed drifts by a third over
minutes (measured: JSBSim at 10 kHz 20× real time in one sitting, 28× in another, HOAD3 1,354× and 1,858× beside
it), and a yardstick measured minutes before a figure would carry that drift into it. A time is stated in
**JSBSim runs** (:func:`jsbsim_seconds`: how long JSBSim takes to simulate the same span at the model's
rate), a speed in **× JSBSim**.
"""

from __future__ import annotations

import importlib.util
import json
import math
import os
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Required, TypedDict

from ema_sim.errors import EmaError


@dataclass(frozen=True)
class Result:
    """One measured figure."""

    value: float
    unit: str
    passed: bool
    detail: str = ""


class BenchEntry(TypedDict, total=False):
    """One benchmark's recorded entry in ``baseline.json`` (an old entry is its figure alone)."""

    value: Required[float]
    unit: str
    target: str
    passed: bool
    detail: str
    date: str


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
    return {k: float(v["value"]) for k, v in recorded_entries(path).items()}


def recorded_entries(path: Path | None = None) -> dict[str, BenchEntry]:
    """Each benchmark's recorded entry: ``value``, ``unit``, ``target``, ``passed``, ``detail`` and ``date``."""
    file = baseline_path(path)
    if not file.exists():
        return {}
    figures = json.loads(file.read_text(encoding="utf-8")).get("bench", {})
    return {str(k): _entry(v) for k, v in figures.items()}


def _entry(v: object) -> BenchEntry:
    """A recorded entry as read from JSON: its known fields (an old entry, a bare number, is its value)."""
    if not isinstance(v, dict):
        return {"value": _number(v)}
    entry: BenchEntry = {"value": _number(v["value"])}
    if "unit" in v:
        entry["unit"] = str(v["unit"])
    if "target" in v:
        entry["target"] = str(v["target"])
    if isinstance(v.get("passed"), bool):
        entry["passed"] = v["passed"]
    if "detail" in v:
        entry["detail"] = str(v["detail"])
    if "date" in v:
        entry["date"] = str(v["date"])
    return entry


def _number(v: object) -> float:
    """A recorded figure (a JSON number) as a float."""
    if isinstance(v, int | float | str):
        return float(v)
    raise TypeError(f"a recorded figure is a number, not {v!r}")


def record(entries: Mapping[str, BenchEntry], path: Path | None = None) -> Path:
    """Write ``entries`` as the recorded ones (other benchmarks' entries and the counts are kept).

    Each entry is what ``ema bench`` printed (``value``, ``unit``, ``target``, ``passed``, ``detail``) and the
    ``date`` it ran; :func:`figures_page` renders them all as the documentation's one source of figures.
    """
    file = baseline_path(path)
    data = json.loads(file.read_text(encoding="utf-8")) if file.exists() else {}
    data["bench"] = {**data.get("bench", {}), **entries}
    file.write_text(json.dumps(data, indent=1, ensure_ascii=False) + "\n", encoding="utf-8")
    return file


FIGURES_HEAD = """# Figures as measured

Every speed, memory and running-time figure of this project, as `ema bench` last printed it and the date it
ran (`bench/baseline.json`; `ema bench --record` rewrites this page, so the figures here and there are one).
Speeds are ratios against JSBSim's actuator chain measured in the same run (× JSBSim), times are in JSBSim
runs of the same span, so a figure holds whatever else the machine ran; the absolute time is in the detail.
"""


def figures_page(entries: Mapping[str, BenchEntry]) -> str:
    """The documentation's page of figures (``docs/figures.md``) from the recorded entries.

    Parameters
    ----------
    entries : dict
        :func:`recorded_entries`.

    Returns
    -------
    str
        The Markdown page.
    """
    rows = ["| benchmark | measured | target | verdict | date | detail |", "| --- | --- | --- | --- | --- | --- |"]
    for name in sorted(entries):
        e = entries[name]
        passed = e.get("passed")
        verdict = "" if passed is None else ("pass" if passed else "**miss**")
        detail = str(e.get("detail", "")).replace("|", "/")
        rows.append(f"| `{name}` | {float(e['value']):.4g} {e.get('unit', '')} | {e.get('target', '')} | {verdict} "
                    f"| {e.get('date', '')} | {detail} |")
    return FIGURES_HEAD + "\n" + "\n".join(rows) + "\n"


def figures_path(path: Path | None = None) -> Path:
    """Where :func:`figures_page` is written: ``docs/figures.md`` beside the ``bench/`` scripts."""
    return (path or bench_dir()).parent / "docs" / "figures.md"


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


def timed(fn: Callable[[], object], repeat: int = 3) -> float:
    """Best wall time of ``repeat`` calls (after one warm-up call that pays for compilation)."""
    fn()
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


YARDSTICK_S = 10.0
"""Simulated seconds of each yardstick measurement (best of three)."""


def jsbsim_realtime(rate_hz: float) -> float:
    """JSBSim's real-time ratio on the X-43A servo at ``rate_hz``: the yardstick (module docstring), measured now.

    The command changes every 5 ms frame (a sine), the model is stepped one JSBSim frame at a time from Python,
    as a host simulation drives an actuator; the best of three runs of :data:`YARDSTICK_S`.

    Parameters
    ----------
    rate_hz : float
        JSBSim's frame rate (the rate of the model it is compared with).

    Returns
    -------
    float
        Simulated seconds per wall second.
    """
    import jsbsim  # noqa: PLC0415 - a benchmark tool's dependency, loaded only when a benchmark runs

    root = bench_dir() / "jsbsim"
    jsbsim.FGJSBBase().debug_lvl = 0  # no start-up banner
    fdm = jsbsim.FGFDMExec(str(root), None)
    fdm.set_debug_level(0)
    if not fdm.load_model("ema_actuator"):
        raise EmaError(f"JSBSim could not load {root}/aircraft/ema_actuator")
    fdm.set_dt(1.0 / rate_hz)
    fdm.run_ic()
    steps = round(YARDSTICK_S * rate_hz)
    per_frame = max(round(rate_hz * 0.005), 1)
    best = math.inf
    for _ in range(3):
        t0 = time.perf_counter()
        for k in range(steps):
            if k % per_frame == 0:
                fdm["fcs/ema-cmd-deg"] = math.sin(2.0 * math.pi * k / rate_hz)
            fdm.run()
        best = min(best, time.perf_counter() - t0)
    return YARDSTICK_S / best


def jsbsim_seconds(simulated_s: float, rate_hz: float) -> float:
    """How long JSBSim's actuator chain takes to simulate ``simulated_s`` at ``rate_hz`` in this run.

    Parameters
    ----------
    simulated_s : float
        Simulated span, s.
    rate_hz : float
        JSBSim's frame rate.

    Returns
    -------
    float
        Wall seconds (a benchmark's time divided by this is its time in JSBSim runs).
    """
    return simulated_s / jsbsim_realtime(rate_hz)


def jsbsim_version() -> str:
    """JSBSim's version, for the benchmarks' details."""
    import jsbsim  # noqa: PLC0415 - a benchmark tool's dependency, loaded only when a benchmark runs

    return str(jsbsim.__version__)
