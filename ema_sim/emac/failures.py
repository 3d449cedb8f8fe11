"""Failure modes for off-nominal runs, switchable at run time, as spec strings.

``none``, ``stuck`` (the actuator jams where it is), ``hard_over:direction=1`` (runs to a stop),
``zero`` (the command line reads 0 V), ``power_loss`` (motor power lost: the brake engages and holds)
and ``stall:load_factor=1.25`` (a hinge moment beyond the stall force opposes deflection, as the
launch vehicle's rudder actuator stalled in flight 1, section 1.3).
"""

from __future__ import annotations

from abc import ABC
from dataclasses import dataclass
from typing import ClassVar

from ema_sim.errors import SpecError
from ema_sim.signals.spec import Spec, describe, param, parse


@dataclass(frozen=True)
class Failure(Spec, ABC):
    """A failure mode of one EMAC channel."""

    family: ClassVar[str] = "failure"
    holds_position: ClassVar[bool] = False
    """The surface stays where it was (jam or brake)."""
    powered: ClassVar[bool] = True
    """Motor power is on."""


@dataclass(frozen=True)
class Nominal(Failure):
    """No failure."""

    kind: ClassVar[str] = "none"


@dataclass(frozen=True)
class Stuck(Failure):
    """The actuator jams at its present position whatever it is commanded."""

    kind: ClassVar[str] = "stuck"
    holds_position: ClassVar[bool] = True


@dataclass(frozen=True)
class HardOver(Failure):
    """A runaway to the position limit in ``direction`` (+1 or −1), whatever it is commanded."""

    kind: ClassVar[str] = "hard_over"
    direction: int = param(1)

    def validate(self) -> None:  # noqa: D102
        if self.direction not in (-1, 1):
            raise SpecError(f"failure 'hard_over': field 'direction' must be 1 or -1, got {self.direction}")


@dataclass(frozen=True)
class Zero(Failure):
    """The command line reads 0 V (open or shorted input): the actuator goes to the 0 V position."""

    kind: ClassVar[str] = "zero"


@dataclass(frozen=True)
class PowerLoss(Failure):
    """Loss of motor power: the brake, engaged when unpowered, holds the surface (section 1.4)."""

    kind: ClassVar[str] = "power_loss"
    holds_position: ClassVar[bool] = True
    powered: ClassVar[bool] = False


@dataclass(frozen=True)
class Stall(Failure):
    """An opposing hinge moment of ``load_factor`` × the stall force × crank arm (section 1.3)."""

    kind: ClassVar[str] = "stall"
    load_factor: float = param(1.25, low=0.0, strict=True)


FAILURES: dict[str, type[Failure]] = {c.kind: c for c in (Nominal, Stuck, HardOver, Zero, PowerLoss, Stall)}


def parse_failure(text: str) -> Failure:
    """A failure mode from its spec string, e.g. ``hard_over:direction=-1``.

    Parameters
    ----------
    text : str
        The spec.

    Returns
    -------
    Failure
        The mode.
    """
    return parse(text, FAILURES, "failure")


def failure_help() -> str:
    """Every failure mode with its fields and defaults."""
    return "\n".join(describe(FAILURES))  # type: ignore[arg-type]
