"""``ema montecarlo``: a campaign of runs with dispersed parameters, on a local Dask cluster or any scheduler."""

from __future__ import annotations

import argparse

from ema_sim.commands.common import Subparsers, check_channel
from ema_sim.montecarlo import load_campaign, run_campaign
from ema_sim.montecarlo.builtin import BUILTIN
from ema_sim.progress import ProgressBar


def run(args: argparse.Namespace) -> int:
    """Run (or resume) a campaign and print where its results are.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line (the options :func:`register` adds).

    Returns
    -------
    int
        The exit status: 0 on success.
    """
    check_channel(args.channel)
    campaign = load_campaign(args.campaign, channel=args.channel, analysis=args.analysis or ())
    bar = ProgressBar(f"{campaign.name} {args.runs} runs", delay_s=0.0 if args.progress else 2.0)
    try:
        doc = run_campaign(campaign, args.out, runs=args.runs, seed=args.seed, scheduler=args.scheduler,
                           workers=args.workers, resume=args.resume, plot=not args.no_plots, progress=bar)
    finally:
        bar.close()
    print(f"{campaign.name}: {doc['runs']} runs, seed {doc['seed']}, {len(doc['workers'])} workers, "
          f"{doc['wall_s']:.1f} s → {args.out}/runs.parquet, {args.out}/summary.json")
    for name, stats in list(doc["metrics"].items())[:12]:
        if stats.get("mean") is not None:
            print(f"  {name:34s} mean {stats['mean']:.5g}  min {stats['min']:.5g}  max {stats['max']:.5g}")
    return 0


def register(sub: Subparsers) -> None:
    """Add ``montecarlo`` to the ``ema`` parser.

    Parameters
    ----------
    sub : Subparsers
        ``ema``'s subcommands (:func:`ema_sim.cli.build_parser`).
    """
    p = sub.add_parser("montecarlo", help="a Monte Carlo campaign on Dask (local cluster, or --scheduler)",
                       description="Run a campaign: a built-in one (" + ", ".join(BUILTIN) + ") or a YAML file.")
    p.add_argument("campaign", help="built-in campaign name or campaign YAML file")
    p.add_argument("--runs", type=int, default=1000, help="number of runs (default 1000)")
    p.add_argument("--seed", type=int, default=0, help="seed: run i draws from (seed, i)")
    p.add_argument("--out", required=True, help="output directory (runs.parquet, summary.json, plots)")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="a Dask scheduler (tcp://host:port); default: a local cluster, one worker per core")
    p.add_argument("--workers", type=int, default=None, help="worker processes of the local cluster")
    p.add_argument("--resume", action="store_true", help="complete the campaign the output directory holds")
    p.add_argument("--channel", default=None, help="channel of a built-in campaign (default left_wing)")
    p.add_argument("--analysis", action="append", metavar="JSON",
                   help="ema analyze --json output whose spread bounds the dispersions (repeatable)")
    p.add_argument("--no-plots", action="store_true", help="skip the PNG plots")
    p.add_argument("--progress", action="store_true", help="draw the progress bar from the start")
    p.set_defaults(func=run)
