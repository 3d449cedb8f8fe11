"""``ema models`` and ``ema maneuvers``: what the registries hold."""

from __future__ import annotations

import argparse
from typing import Any


def models(args: argparse.Namespace) -> int:  # noqa: ARG001
    """List the registered models."""
    from ema_sim.models import model_class, model_names  # noqa: PLC0415 - loaded when this subcommand runs, not at every ema start

    for name in model_names():
        cls = model_class(name)
        rate = "continuous" if cls.continuous else f"{cls.default_rate_hz:g} Hz"
        print(f"{name:7s} {rate:>11s}  {cls.title}")
    return 0


def maneuvers(args: argparse.Namespace) -> int:  # noqa: ARG001
    """List maneuver and load specs with their defaults."""
    from ema_sim.signals.loads import load_help  # noqa: PLC0415 - loaded when this subcommand runs, not at every ema start
    from ema_sim.signals.maneuvers import maneuver_help  # noqa: PLC0415 - loaded when this subcommand runs, not at every ema start

    print("maneuvers (--maneuver kind:field=value,...):")
    print(maneuver_help())
    print("\nloads (--load kind:field=value,...):")
    print(load_help())
    return 0


def register(sub: Any) -> None:
    """Add ``models`` and ``maneuvers`` to the ``ema`` parser."""
    sub.add_parser("models", help="list the models").set_defaults(func=models)
    sub.add_parser("maneuvers", help="list maneuver and load specs").set_defaults(func=maneuvers)
