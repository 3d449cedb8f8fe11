"""``ema compare``: error of discrete models against a reference (table 6)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from ema_sim.analysis.studies import model_error
from ema_sim.analysis.studies.model_error import TABLE6_CANDIDATES, TABLE6_MANEUVER
from ema_sim.commands.common import Subparsers, add_model_args, parse_overrides
from ema_sim.errors import SpecError
from ema_sim.signals import parse_load, parse_maneuver


def run(args: argparse.Namespace) -> int:
    """Print the error table (and write JSON).

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line (the options :func:`register` adds).

    Returns
    -------
    int
        The exit status: 0 on success.
    """
    candidates: list[tuple[str, float | None]] = []
    for item in args.models.split(","):
        name, at, rate = item.strip().partition("@")
        try:
            candidates.append((name, float(rate) if at else None))
        except ValueError:
            raise SpecError(f"--models: bad rate in {item!r} (use name@hz)") from None
    overrides = parse_overrides(args.overrides) if args.overrides else dict(model_error.TABLE6_OVERRIDES)
    rows = model_error.model_errors(
        args.reference, candidates, parse_maneuver(args.maneuver),
        parse_load(args.load) if args.load else None, channel=args.channel, output=args.output, **overrides,
    )
    print(f"input: {args.maneuver}; channel {args.channel}; overrides {overrides or 'none'}; output {args.output}")
    print(model_error.format_table(rows, args.reference))
    if args.json:
        Path(args.json).write_text(json.dumps([r.as_dict() for r in rows], indent=2) + "\n", encoding="utf-8")
    return 0


def register(sub: Subparsers) -> None:
    """Add ``compare`` to the ``ema`` parser.

    Parameters
    ----------
    sub : Subparsers
        ``ema``'s subcommands (:func:`ema_sim.cli.build_parser`).
    """
    p = sub.add_parser("compare", help="error of discrete models against a reference (table 6)",
                       description="Mean, spread and maximum |error| of each model against the reference.")
    p.add_argument("--reference", default="loac")
    p.add_argument("--models", default=",".join(f"{m}@{r:g}" for m, r in TABLE6_CANDIDATES),
                   help="comma-separated name@rate_hz")
    p.add_argument("--maneuver", default=TABLE6_MANEUVER)
    p.add_argument("--load", default=None)
    p.add_argument("--output", default="position_deg", choices=["position_deg", "surface_deg"])
    add_model_args(p)
    p.add_argument("--json", default=None, help="also write the rows as JSON")
    p.set_defaults(func=run)
