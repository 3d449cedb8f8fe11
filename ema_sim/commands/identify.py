"""``ema identify``: fit a declared model to measured data, find what it lacks, add it, report."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from ema_sim import io as ema_io
from ema_sim.analysis.estimation.prepared import resolve_channel
from ema_sim.commands.common import Subparsers, add_data_args, check_channel, check_outputs, parse_overrides, rig_format
from ema_sim.errors import EmaError, UnknownNameError
from ema_sim.identify.declared import DECLARED
from ema_sim.identify.identification import Search, identify
from ema_sim.identify.record import prepare
from ema_sim.identify.report import summary, to_json, write_json, write_report, write_residuals

if TYPE_CHECKING:
    from ema_sim.io.csv import RigFormat
    from ema_sim.io.measured import MeasuredData


def load_measured(path: Path, channel: str | None, rig: RigFormat | None = None) -> MeasuredData:
    """A measured record from a data-contract CSV, a rig's own file, or a rosbag2.

    Parameters
    ----------
    path : Path
        The file or bag directory.
    channel : str or None
        The channel to read (a bag holds several; None: the only one).
    rig : RigFormat, optional
        A rig file's layout (:func:`~ema_sim.commands.common.rig_format`).

    Returns
    -------
    MeasuredData
        The record.
    """
    return ema_io.load_data(path, channel=channel, rig=rig)


def run(args: argparse.Namespace) -> int:
    """Identify and print the summary; write JSON, the report and the residuals when asked.

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
    if args.workers < 0:
        raise EmaError(f"--workers must be 0 or more, got {args.workers}")
    if args.model.strip().lower() not in DECLARED:
        raise UnknownNameError("declared model for identification", args.model, DECLARED)
    overrides = parse_overrides(args.overrides)
    check_outputs([args.json, args.residuals], [args.report])
    data = load_measured(args.data, args.channel, rig_format(args))
    channel, note = resolve_channel(data, args.channel)
    record = prepare(data, channel, channel_note=note, command=args.command_hold)
    say = None if args.quiet else (lambda msg: print(msg, file=sys.stderr))
    search = Search(max_effects=args.max_effects, escalate=not args.no_escalate, workers=args.workers,
                    scheduler=args.scheduler)
    result = identify(record, args.model, overrides, search=search, log=say)
    report = to_json(result, str(args.data))
    print(summary(report))
    if args.json:
        write_json(report, args.json)
    if args.report:
        path = write_report(result, report, args.report)
        print(f"report: {path}")
    if args.residuals:
        print(f"residuals: {write_residuals(result, args.residuals)}")
    return 0


def register(sub: Subparsers) -> None:
    """Add ``identify`` to the ``ema`` parser.

    Parameters
    ----------
    sub : Subparsers
        ``ema``'s subcommands (:func:`ema_sim.cli.build_parser`).
    """
    p = sub.add_parser(
        "identify", help="fit a model to measured data and add the effects it lacks",
        description="Output-error fit of a declared model, then stepwise addition of the vocabulary effects "
                    "(data contract) that pay for themselves; reports the error before and after.",
    )
    p.add_argument("data", type=Path, help="a data-contract CSV or a rosbag2 directory")
    p.add_argument("--model", default="second_order", help=f"declared starting model: {', '.join(DECLARED)}")
    p.add_argument("--channel", default=None, help="channel (default: the data's metadata, else left_wing)")
    p.add_argument("--set", dest="overrides", action="append", metavar="NAME=VALUE",
                   help="declare a stage of the starting model, e.g. --set compliance_deg_per_kinlb=0.2")
    p.add_argument("--max-effects", type=int, default=8, help="most effects to add (8)")
    p.add_argument("--no-escalate", action="store_true",
                   help="keep the declared model and its effects even when they leave more than 3x the noise "
                        "on a record of LVDT and surface (default: fit HOAD3's physical parameters then, and "
                        "report the declared model beside them as the equivalent)")
    p.add_argument("--json", type=Path, default=None, help="write the report JSON here")
    p.add_argument("--report", type=Path, default=None, help="write report.md and plots in this directory")
    p.add_argument("--residuals", type=Path, default=None, metavar="FILE.csv",
                   help="write time, measured, baseline and final model outputs and residuals per output (CSV)")
    p.add_argument("--command", dest="command_hold", default="detect", choices=("detect", "held", "sampled"),
                   help="how the rig logged its command: held between samples (the data contract), sampled from a "
                        "running demand, or detect it (a record that cannot tell is fitted both ways)")
    p.add_argument("--workers", type=int, default=2, metavar="N",
                   help="fit a round's candidate effects and the physics' extra starts at once on a local Dask "
                        "cluster of N threads in this process (2; 0 or 1: one after another; a record under "
                        "40,000 fitted samples is always fitted here); the same result either way")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="send those fits to a running Dask scheduler (e.g. tcp://host:8786) instead")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress lines on stderr")
    add_data_args(p)
    p.set_defaults(func=run)
