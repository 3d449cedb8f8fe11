"""``ema models`` and ``ema maneuvers``: what the registries hold."""

from __future__ import annotations

import argparse

from ema_sim.commands.common import Subparsers
from ema_sim.models import model_class, model_names
from ema_sim.signals.loads import load_help
from ema_sim.signals.maneuvers import maneuver_help


def models(args: argparse.Namespace) -> int:  # noqa: ARG001
    """List the registered models.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line (the options :func:`register` adds).

    Returns
    -------
    int
        The exit status: 0 on success.
    """
    for name in model_names():
        cls = model_class(name)
        rate = "continuous" if cls.continuous else f"{cls.default_rate_hz:g} Hz"
        print(f"{name:7s} {rate:>11s}  {cls.title}")
    return 0


def maneuvers(args: argparse.Namespace) -> int:  # noqa: ARG001
    """List maneuver and load specs with their defaults.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line (the options :func:`register` adds).

    Returns
    -------
    int
        The exit status: 0 on success.
    """
    print("maneuvers (--maneuver kind:field=value,...):")
    print(maneuver_help())
    print("\nloads (--load kind:field=value,...):")
    print(load_help())
    return 0


def register(sub: Subparsers) -> None:
    """Add ``models`` and ``maneuvers`` to the ``ema`` parser.

    Parameters
    ----------
    sub : Subparsers
        ``ema``'s subcommands (:func:`ema_sim.cli.build_parser`).
    """
    sub.add_parser("models", help="list the models").set_defaults(func=models)
    sub.add_parser("maneuvers", help="list maneuver and load specs").set_defaults(func=maneuvers)
