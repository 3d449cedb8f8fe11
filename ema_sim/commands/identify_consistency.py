"""``ema identify-consistency``: whether several identifications of one actuator give the same parameters."""

from __future__ import annotations

import argparse
from pathlib import Path

from ema_sim.commands.common import Subparsers
from ema_sim.identify.consistency import compare, format_table, read_reports
from ema_sim.identify.report import write_json


def run(args: argparse.Namespace) -> int:
    """Compare the reports, print the table, write the JSON when asked; 0 even when parameters disagree.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line (the options :func:`register` adds).

    Returns
    -------
    int
        The exit status: 0, even when parameters disagree (the table says so).
    """
    result = compare(read_reports(args.reports), sigma=args.sigma)
    print(format_table(result))
    if args.json:
        write_json(result.as_dict(), args.json)
        print(f"wrote {args.json}")
    return 0


def register(sub: Subparsers) -> None:
    """Add ``identify-consistency`` to the ``ema`` parser.

    Parameters
    ----------
    sub : Subparsers
        ``ema``'s subcommands (:func:`ema_sim.cli.build_parser`).
    """
    p = sub.add_parser(
        "identify-consistency", help="compare the parameters several `ema identify` reports give one actuator",
        description="For every model parameter fitted in two reports or more: the inverse-variance weighted mean, "
                    "the chi-square of the values about it and its p-value, the largest pairwise distance in "
                    "combined standard deviations, and a verdict (agree, disagree, undetermined, single); effects "
                    "added in some reports only; a note on reports whose model leaves structure. Exit 0 when it "
                    "ran, whatever the verdicts.",
    )
    p.add_argument("reports", type=Path, nargs="+", metavar="REPORT.json",
                   help="two or more `ema identify --json` reports of one channel")
    p.add_argument("--json", type=Path, default=None, help="write the comparison here (strict JSON)")
    p.add_argument("--sigma", type=float, default=3.0,
                   help="a pair further apart than this many combined standard deviations disagrees (3)")
    p.set_defaults(func=run)
