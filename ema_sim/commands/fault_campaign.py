"""``ema fault-campaign``: fault kinds × sizes × maneuvers × seeds, simulated and watched by the monitor."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from ema_sim.commands.common import Subparsers
from ema_sim.errors import EmaError


def run(args: argparse.Namespace) -> int:
    """Run the campaign, write the Parquet table, the summary JSON and the plots.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line (the options :func:`register` adds).

    Returns
    -------
    int
        The exit status: 0 on success.
    """
    from ema_sim.montecarlo.faults import (  # noqa: PLC0415 - loaded when this subcommand runs
        DEFAULT_MANEUVERS,
        DEFAULT_SIZES,
        HIGH_ORDER_SIZES,
        cases,
        model_has_current,
        plot_campaign,
        run_campaign,
        summarize,
    )

    sizes = HIGH_ORDER_SIZES if model_has_current(args.model) else DEFAULT_SIZES
    kinds = sizes
    if args.kinds:
        unknown = sorted(set(args.kinds) - set(sizes))
        if unknown:
            raise EmaError(f"fault kinds {args.model} has no stage for, or unknown: {', '.join(unknown)} "
                           f"(kinds: {', '.join(sizes)})")
        kinds = {k: sizes[k] for k in args.kinds}
    if args.seeds < 1:
        raise EmaError(f"--seeds must be at least 1, got {args.seeds}")
    all_cases = cases(kinds, args.maneuver or DEFAULT_MANEUVERS, seeds=args.seeds, clean=args.clean,
                      reference=args.reference, model=args.model, load=args.load, environment=args.environment)
    print(f"{len(all_cases)} cases")
    table = run_campaign(all_cases, args.out, workers=args.workers, scheduler=args.scheduler)
    summary = summarize(table)
    (args.out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n", encoding="utf-8")
    plots = plot_campaign(table, args.out)
    print(json.dumps({k: summary[k] for k in ("cases", "detected", "faulty_cases", "false_alarms",
                                             "false_alarms_per_hour", "isolation_top1", "isolation_top1_fits_only",
                                             "cpu_share_per_channel")}))
    print(f"wrote {args.out / 'cases.parquet'}, {args.out / 'summary.json'}, {', '.join(map(str, plots))}")
    return 0


def register(sub: Subparsers) -> None:
    """Add ``fault-campaign`` to the ``ema`` parser.

    Parameters
    ----------
    sub : Subparsers
        ``ema``'s subcommands (:func:`ema_sim.cli.build_parser`).
    """
    p = sub.add_parser("fault-campaign", help="inject faults across kinds, sizes, maneuvers and seeds; score the "
                       "monitor (delay, misses, false alarms, confusion matrix)",
                       description="Each case simulates the truth model with one fault (or none), measures it "
                       "with the AIL test environment's feedback noise and quantum, and runs ema monitor on it.")
    p.add_argument("out", type=Path, help="output directory (cases.parquet, summary.json, plots)")
    p.add_argument("--kinds", nargs="*", default=None, help="fault kinds (default: every second-order one)")
    p.add_argument("--maneuver", action="append", default=None, help="maneuver spec (repeatable)")
    p.add_argument("--load", default="const:inlb=800", help="hinge moment of every case (const:inlb=800)")
    p.add_argument("--seeds", type=int, default=2, help="noise seeds per kind, size and maneuver (2)")
    p.add_argument("--clean", type=int, default=2, help="clean cases per seed and maneuver (2)")
    p.add_argument("--model", default="loada", help="truth model: loada, loac (second order) or hoad2, hoad3")
    p.add_argument("--reference", choices=("nominal", "learned"), default="nominal",
                   help="the monitor's reference: the truth model's nominal parameters, or learned (healthy window)")
    p.add_argument("--environment", choices=("feedback", "ail"), default="feedback",
                   help="feedback: the AIL feedback's noise and quantum on the readings; ail: also the AIL command "
                        "path between the recorded command and the actuator (use with --reference learned)")
    p.add_argument("--workers", type=int, default=None, help="local Dask workers (0: run in this process)")
    p.add_argument("--scheduler", default=None, help="a Dask scheduler's address")
    p.set_defaults(func=run)
