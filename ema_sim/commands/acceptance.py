"""``ema acceptance``: the table 1 / table A2 figures measured on a model."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from ema_sim.analysis.studies.acceptance import acceptance, format_acceptance
from ema_sim.commands.common import Subparsers


def run(args: argparse.Namespace) -> int:
    """Measure and print the figures; exit 1 when one misses its requirement.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line (the options :func:`register` adds).

    Returns
    -------
    int
        The exit status: 0 when every figure meets its requirement, 1 otherwise.
    """
    figures = acceptance(args.model, args.channel)
    print(f"{args.model}, {args.channel}: table 1 and table A2")
    print(format_acceptance(figures))
    if args.json:
        Path(args.json).write_text(json.dumps([f.as_dict() for f in figures], indent=2) + "\n", encoding="utf-8")
    return 0 if all(f.passed for f in figures) else 1


def register(sub: Subparsers) -> None:
    """Add ``acceptance`` to the ``ema`` parser.

    Parameters
    ----------
    sub : Subparsers
        ``ema``'s subcommands (:func:`ema_sim.cli.build_parser`).
    """
    p = sub.add_parser("acceptance", help="measure the table 1 / A2 specifications on a high-order model",
                       description="Slew, force versus rate at 125 V, stall, bandwidth, backlash, stiffness, "
                                   "brake and bus regeneration, each as its acceptance test measures it.")
    p.add_argument("--model", default="hoac1", help="a model with a motor: hoac1, hoad2 or hoad3")
    p.add_argument("--channel", default="left_wing")
    p.add_argument("--json", default=None, help="also write the figures as JSON")
    p.set_defaults(func=run)
