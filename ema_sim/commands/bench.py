"""``ema bench``: the speed and memory targets under ``bench/``."""

from __future__ import annotations

import argparse
import datetime
import json
from pathlib import Path

from ema_sim.benchmark import BenchEntry, discover, figures_page, figures_path, record, recorded, recorded_entries
from ema_sim.commands.common import Subparsers


def run(args: argparse.Namespace) -> int:
    """Run the benchmarks; exit 1 when one misses its target.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line (the options :func:`register` adds).

    Returns
    -------
    int
        The exit status: 0, or 1 when a benchmark misses its target.
    """
    before = recorded()
    results: list[dict[str, object]] = []
    figures: dict[str, BenchEntry] = {}
    today = datetime.date.today().isoformat()
    failed = 0
    for bench in discover():
        if args.only and not any(key in bench.name for key in args.only):
            continue
        res = bench.run()
        failed += not res.passed
        mark = "PASS" if res.passed else "FAIL"
        ref = before.get(bench.name)
        ratio = f"{res.value / ref:6.3f}× recorded" if ref else "  (none recorded)"
        print(f"{mark}  {bench.name:34s} {res.value:12.4g} {res.unit:12s} {ratio}  target {bench.target:18s} "
              f"{res.detail}", flush=True)
        results.append({"name": bench.name, "target": bench.target, "value": res.value, "unit": res.unit,
                        "passed": res.passed, "detail": res.detail})
        figures[bench.name] = {"value": res.value, "unit": res.unit, "target": bench.target, "passed": res.passed,
                               "detail": res.detail, "date": today}
    if args.record:
        print(f"recorded in {record(figures)}")
        page = figures_path()
        if page.parent.is_dir():
            page.write_text(figures_page(recorded_entries()), encoding="utf-8")
            print(f"wrote {page}")
    if args.json:
        Path(args.json).write_text(json.dumps(results, indent=2) + "\n", encoding="utf-8")
    return 1 if failed else 0


def register(sub: Subparsers) -> None:
    """Add ``bench`` to the ``ema`` parser.

    Parameters
    ----------
    sub : Subparsers
        ``ema``'s subcommands (:func:`ema_sim.cli.build_parser`).
    """
    p = sub.add_parser("bench", help="run the speed and memory benchmarks under bench/")
    p.add_argument("--only", action="append", help="run benchmarks whose name contains this (repeatable)")
    p.add_argument("--json", default=None, help="write the results as JSON")
    p.add_argument("--record", action="store_true",
                   help="record these figures, with today's date, in bench/baseline.json and docs/figures.md "
                        "(each run prints its ratio to them)")
    p.set_defaults(func=run)
