"""The record's path through ``ema identify``: which modules the record visits, and how often it goes back up.

``ema identify`` reads a record, prepares it and identifies a model on it. This script runs those steps
(channel, preparation, identification: what :func:`ema_sim.commands.identify.run` does between reading the
file and writing the report) on a short generated record, under :func:`sys.setprofile`, and notes every call
of an ``ema_sim`` function that receives the record: the :class:`~ema_sim.io.measured.MeasuredData`, the
prepared record, or one of the record's columns (as an argument, or inside a dict, list or tuple argument).

From the modules those calls are in, consecutive calls in one module merged into one visit, it prints:

* **visits**: the length of that sequence, and the distinct modules in it;
* **returns up**: the steps to a module higher in the import graph than the one before (its height: the
  longest chain of ``ema_sim`` imports below it), i.e. the record handed back up after going down;
* **alternations**: per pair of modules, how often the path goes ``a → b → a``; the largest.

Run: ``.venv/bin/python bench/record_path.py [--effects N] [--seconds S]``. Not a speed benchmark.
"""

from __future__ import annotations

import argparse
import itertools
import sys
from collections import Counter
from functools import cache
from pathlib import Path
from types import FrameType
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "test"))
from identgen import make_record  # noqa: E402
from test_layers import imports, modules  # noqa: E402

from ema_sim.identify.identification import Search, identify  # noqa: E402
from ema_sim.identify.record import prepare  # noqa: E402

try:
    from ema_sim.analysis.estimation.prepared import resolve_channel
except ImportError:  # on a tree from before the record was prepared once for both tools
    from ema_sim.analysis.pipeline import resolve_channel

PACKAGE = str(ROOT / "ema_sim")


def heights() -> dict[str, int]:
    """Each ``ema_sim`` module's height in the import graph: 0 for one importing no ``ema_sim`` module."""
    known = modules()
    graph = {m: {n for n in imports(p, known) if n in known and n != m} for m, p in known.items()}

    @cache
    def height(m: str) -> int:
        return 1 + max((height(n) for n in graph[m]), default=-1)

    return {m: height(m) for m in graph}


def module_of(path: str) -> str:
    """The dotted module name of a source file of ``ema_sim``."""
    parts = list(Path(path).resolve().relative_to(ROOT).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def trace(effects: int, seconds: float) -> list[tuple[str, bool]]:
    """The modules of the calls that receive the record, in order, while it is prepared and identified.

    Each with whether the call received the record object itself (not only its columns).
    """
    def prepare_record() -> Any:
        channel, note = resolve_channel(data, None)
        return prepare(data, channel, channel_note=note)

    data = make_record({"time_delay": 0.008}, seed=3, duration_s=seconds)
    objects: set[int] = {id(data)}
    followed: set[int] = {id(v) for v in vars(data).values() if hasattr(v, "shape")}
    path: list[tuple[str, bool]] = []

    def holds(value: Any, ids: set[int]) -> bool:
        if id(value) in ids:
            return True
        if isinstance(value, dict):
            return any(id(v) in ids for v in value.values())
        if isinstance(value, list | tuple):
            return any(id(v) in ids for v in value)
        return False

    def profile(frame: FrameType, event: str, _arg: object) -> None:
        if event != "call" or not frame.f_code.co_filename.startswith(PACKAGE):
            return
        code = frame.f_code
        n = code.co_argcount + code.co_kwonlyargcount
        names = code.co_varnames[:n]
        args = frame.f_locals
        whole = any(holds(args.get(a), objects) for a in names)
        if whole or any(holds(args.get(a), followed) for a in names):
            path.append((module_of(code.co_filename), whole))

    search = Search(max_effects=effects)
    sys.setprofile(profile)
    try:
        record = prepare_record()
        objects.update({id(record), id(getattr(record, "prepared", record))})
        identify(record, search=search)
    finally:
        sys.setprofile(None)
    return path


def main() -> None:
    """Print the record's path and its counts."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--effects", type=int, default=8, help="most effects the search adds (8, the default)")
    parser.add_argument("--seconds", type=float, default=6.0, help="the generated record's length, s (6)")
    args = parser.parse_args()
    calls = trace(args.effects, args.seconds)
    h = heights()
    print(f"calls receiving the record or its columns: {len(calls)}, the record itself: {sum(w for _, w in calls)}")
    print("\nfollowing the record object:")
    report([m for m, whole in calls if whole], h)
    print("\nfollowing the record object and its columns:")
    report([m for m, _ in calls], h)


def report(calls: list[str], h: dict[str, int]) -> None:
    """Print one path's counts and the path."""
    visits = [m for k, m in enumerate(calls) if k == 0 or calls[k - 1] != m]
    ups = [(a, b) for a, b in itertools.pairwise(visits) if h[b] > h[a]]
    alternations: Counter[tuple[str, str]] = Counter()
    for a, b, c in zip(visits, visits[1:], visits[2:], strict=False):
        if a == c:
            alternations[tuple(sorted((a, b)))] += 1  # type: ignore[index]
    short = [m.removeprefix("ema_sim.") for m in visits]
    print(f"module visits: {len(visits)} ({len(set(visits))} modules)")
    print(f"returns up: {len(ups)}")
    most = alternations.most_common(1)
    print(f"most alternations of one pair: {most[0][1] if most else 0}"
          + (f" ({' / '.join(m.removeprefix('ema_sim.') for m in most[0][0])})" if most else ""))
    print("path: " + " → ".join(short))


if __name__ == "__main__":
    main()
