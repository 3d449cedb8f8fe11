"""``ema simulate``: run a model offline and write the data-contract CSV."""

from __future__ import annotations

import argparse
from pathlib import Path

from ema_sim.commands.common import Subparsers, add_model_args, parse_overrides
from ema_sim.progress import ProgressBar
from ema_sim.signals import parse_load, parse_maneuver


def run(args: argparse.Namespace) -> int:
    """Simulate and write the CSV.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line (the options :func:`register` adds).

    Returns
    -------
    int
        The exit status: 0 on success.
    """
    from ema_sim.faults import parse_fault  # noqa: PLC0415 - loaded when this subcommand runs
    from ema_sim.io.csv import write_csv  # noqa: PLC0415 - keep `ema --help` fast
    from ema_sim.simulation import csv_columns, simulate  # noqa: PLC0415 - loaded when this subcommand runs, not at every ema start

    maneuver = parse_maneuver(args.maneuver)
    faults = [parse_fault(text) for text in args.fault]
    load = parse_load(args.load) if args.load else None
    bar = ProgressBar(f"{args.model} {args.channel}")
    try:
        model, record, meta = simulate(
            args.model, maneuver, load, channel=args.channel, rate_hz=args.rate, duration_s=args.duration,
            frame_hz=args.frame_hz, sample_hz=args.sample_hz, progress=bar, faults=faults,
            **parse_overrides(args.overrides),
        )
    finally:
        bar.close()
    write_csv(args.csv, csv_columns(model, record, faults=faults), meta)
    span = f"{record.time_s.size} samples over {meta['duration_s']} s"
    print(f"wrote {args.csv}: {span} ({model.name}, {model.channel.channel})")
    return 0


def register(sub: Subparsers) -> None:
    """Add ``simulate`` to the ``ema`` parser.

    Parameters
    ----------
    sub : Subparsers
        ``ema``'s subcommands (:func:`ema_sim.cli.build_parser`).
    """
    p = sub.add_parser("simulate", help="run a model offline and write the data-contract CSV",
                       description="Run a model through a section-2 maneuver and write a DAU-like CSV.")
    p.add_argument("--model", required=True, help="model name (ema models)")
    add_model_args(p)
    p.add_argument("--rate", type=float, default=None, help="integration rate of a discrete model, Hz")
    p.add_argument("--maneuver", required=True, help="e.g. step:amp_deg=1 (ema maneuvers lists them)")
    p.add_argument("--load", default=None, help="hinge moment, e.g. const:inlb=500")
    p.add_argument("--duration", type=float, default=None, help="seconds (default: the maneuver's length)")
    p.add_argument("--frame-hz", type=float, default=200.0, help="FMU frame rate of the command (200)")
    p.add_argument("--sample-hz", type=float, default=1000.0, help="DAU sample rate of the CSV (1000)")
    p.add_argument("--fault", action="append", default=[], metavar="KIND:FIELD=VALUE,...",
                   help="inject a fault on a schedule, e.g. coulomb_friction:at_s=5,ramp_s=2,size=0.5 (repeatable; "
                   "kinds: coulomb_friction, viscous_friction, jam, backlash, torque_constant, current_limit, delay, "
                   "lvdt_bias, lvdt_drift, lvdt_scale, linkage, hm_sign; docs/faults.md); the truth goes in "
                   "fault_<kind> columns")
    p.add_argument("--csv", required=True, type=Path, help="output CSV")
    p.set_defaults(func=run)
