"""Argument helpers shared by several subcommands."""

from __future__ import annotations

import argparse
from collections.abc import Sequence

from ema_sim.errors import SpecError


def parse_overrides(items: Sequence[str] | None) -> dict[str, float]:
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


def add_model_args(p: argparse.ArgumentParser) -> None:
    """``--channel`` and ``--set`` for commands that build a model."""
    p.add_argument("--channel", default="left_wing", help="EMAC channel (default left_wing)")
    p.add_argument("--set", dest="overrides", action="append", metavar="NAME=VALUE",
                   help="override a model parameter (repeatable), e.g. --set delay_s=0")
