"""``ema``: the command-line entry point (one subcommand per job).

Every user error (unknown model, malformed spec or data...) is one line on stderr and exit status 2.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from ema_sim import __version__
from ema_sim.errors import EmaError, SpecError

Handler = Callable[[argparse.Namespace], int]


def _overrides(items: Sequence[str] | None) -> dict[str, float]:
    """``--set name=value`` pairs as model parameter overrides."""
    out: dict[str, float] = {}
    for item in items or []:
        key, eq, value = item.partition("=")
        if not eq or not key.strip():
            raise SpecError(f"--set expects name=value, got {item!r}")
        try:
            out[key.strip()] = float(value)
        except ValueError:
            raise SpecError(f"--set {key.strip()}: not a number: {value!r}") from None
    return out


def _add_model_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--channel", default="left_wing", help="EMAC channel (default left_wing)")
    p.add_argument("--set", dest="overrides", action="append", metavar="NAME=VALUE",
                   help="override a model parameter (repeatable), e.g. --set delay_s=0")


# ---------------------------------------------------------------------------- simulate
def _cmd_simulate(args: argparse.Namespace) -> int:
    from ema_sim.io.csv import write_csv  # noqa: PLC0415 - keep `ema --help` fast
    from ema_sim.progress import ProgressBar  # noqa: PLC0415
    from ema_sim.signals import parse_load, parse_maneuver  # noqa: PLC0415
    from ema_sim.simulation import csv_columns, simulate  # noqa: PLC0415

    maneuver = parse_maneuver(args.maneuver)
    load = parse_load(args.load) if args.load else None
    bar = ProgressBar(f"{args.model} {args.channel}")
    try:
        model, record, meta = simulate(
            args.model, maneuver, load, channel=args.channel, rate_hz=args.rate, duration_s=args.duration,
            frame_hz=args.frame_hz, sample_hz=args.sample_hz, progress=bar, **_overrides(args.overrides),
        )
    finally:
        bar.close()
    write_csv(args.csv, csv_columns(model, record), meta)
    span = f"{record.time_s.size} samples over {meta['duration_s']} s"
    print(f"wrote {args.csv}: {span} ({model.name}, {model.channel.channel})")
    return 0


def _add_simulate(sub: Any) -> None:
    p = sub.add_parser("simulate", help="run a model offline and write the data-contract CSV",
                       description="Run a model through a section-2 maneuver and write a DAU-like CSV.")
    p.add_argument("--model", required=True, help="model name (ema models)")
    _add_model_args(p)
    p.add_argument("--rate", type=float, default=None, help="integration rate of a discrete model, Hz")
    p.add_argument("--maneuver", required=True, help="e.g. step:amp_deg=1 (ema maneuvers lists them)")
    p.add_argument("--load", default=None, help="hinge moment, e.g. const:inlb=500")
    p.add_argument("--duration", type=float, default=None, help="seconds (default: the maneuver's length)")
    p.add_argument("--frame-hz", type=float, default=200.0, help="FMU frame rate of the command (200)")
    p.add_argument("--sample-hz", type=float, default=1000.0, help="DAU sample rate of the CSV (1000)")
    p.add_argument("--csv", required=True, type=Path, help="output CSV")
    p.set_defaults(func=_cmd_simulate)


# ---------------------------------------------------------------------------- compare
def _cmd_compare(args: argparse.Namespace) -> int:
    from ema_sim.analysis import model_error  # noqa: PLC0415
    from ema_sim.signals import parse_load, parse_maneuver  # noqa: PLC0415

    candidates: list[tuple[str, float | None]] = []
    for item in args.models.split(","):
        name, at, rate = item.strip().partition("@")
        try:
            candidates.append((name, float(rate) if at else None))
        except ValueError:
            raise SpecError(f"--models: bad rate in {item!r} (use name@hz)") from None
    overrides = _overrides(args.overrides) if args.overrides else dict(model_error.TABLE6_OVERRIDES)
    rows = model_error.model_errors(
        args.reference, candidates, parse_maneuver(args.maneuver),
        parse_load(args.load) if args.load else None, channel=args.channel, output=args.output, **overrides,
    )
    print(f"input: {args.maneuver}; channel {args.channel}; overrides {overrides or 'none'}; output {args.output}")
    print(model_error.format_table(rows, args.reference))
    if args.json:
        Path(args.json).write_text(json.dumps([r.as_dict() for r in rows], indent=2) + "\n", encoding="utf-8")
    return 0


def _add_compare(sub: Any) -> None:
    from ema_sim.analysis.model_error import TABLE6_CANDIDATES, TABLE6_MANEUVER  # noqa: PLC0415

    p = sub.add_parser("compare", help="error of discrete models against a reference (table 6)",
                       description="Mean, spread and maximum |error| of each model against the reference.")
    p.add_argument("--reference", default="loac")
    p.add_argument("--models", default=",".join(f"{m}@{r:g}" for m, r in TABLE6_CANDIDATES),
                   help="comma-separated name@rate_hz")
    p.add_argument("--maneuver", default=TABLE6_MANEUVER)
    p.add_argument("--load", default=None)
    p.add_argument("--output", default="position_deg", choices=["position_deg", "surface_deg"])
    _add_model_args(p)
    p.add_argument("--json", default=None, help="also write the rows as JSON")
    p.set_defaults(func=_cmd_compare)


# ---------------------------------------------------------------------------- listings
def _cmd_models(args: argparse.Namespace) -> int:  # noqa: ARG001
    from ema_sim.models import model_class, model_names  # noqa: PLC0415

    for name in model_names():
        cls = model_class(name)
        rate = "continuous" if cls.continuous else f"{cls.default_rate_hz:g} Hz"
        print(f"{name:7s} {rate:>11s}  {cls.title}")
    return 0


def _cmd_maneuvers(args: argparse.Namespace) -> int:  # noqa: ARG001
    from ema_sim.signals.loads import load_help  # noqa: PLC0415
    from ema_sim.signals.maneuvers import maneuver_help  # noqa: PLC0415

    print("maneuvers (--maneuver kind:field=value,...):")
    print(maneuver_help())
    print("\nloads (--load kind:field=value,...):")
    print(load_help())
    return 0


# ---------------------------------------------------------------------------- bench
def _cmd_bench(args: argparse.Namespace) -> int:
    from ema_sim.benchmark import discover  # noqa: PLC0415

    results = []
    failed = 0
    for bench in discover():
        if args.only and not any(key in bench.name for key in args.only):
            continue
        res = bench.run()
        failed += not res.passed
        mark = "PASS" if res.passed else "FAIL"
        print(f"{mark}  {bench.name:34s} {res.value:12.4g} {res.unit:12s} target {bench.target:18s} {res.detail}",
              flush=True)
        results.append({"name": bench.name, "target": bench.target, "value": res.value, "unit": res.unit,
                        "passed": res.passed, "detail": res.detail})
    if args.json:
        Path(args.json).write_text(json.dumps(results, indent=2) + "\n", encoding="utf-8")
    return 1 if failed else 0


def _add_bench(sub: Any) -> None:
    p = sub.add_parser("bench", help="run the speed and memory benchmarks under bench/")
    p.add_argument("--only", action="append", help="run benchmarks whose name contains this (repeatable)")
    p.add_argument("--json", default=None, help="write the results as JSON")
    p.set_defaults(func=_cmd_bench)


# ---------------------------------------------------------------------------- main
def build_parser() -> argparse.ArgumentParser:
    """The ``ema`` parser with every subcommand."""
    parser = argparse.ArgumentParser(
        prog="ema", description="X-43A electromechanical actuator emulation (NASA/TM-2008-214637)."
    )
    parser.add_argument("--version", action="version", version=f"ema_sim {__version__}")
    parser.add_argument("-v", "--verbose", action="store_true", help="log at INFO level")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for add in (_add_simulate, _add_compare, _add_bench):
        add(sub)
    sub.add_parser("models", help="list the models").set_defaults(func=_cmd_models)
    sub.add_parser("maneuvers", help="list maneuver and load specs").set_defaults(func=_cmd_maneuvers)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``ema``; returns the exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING,
                        format="%(levelname)s %(name)s: %(message)s")
    try:
        return int(args.func(args))
    except EmaError as exc:
        print(f"ema {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"ema {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
