"""The section-2 test signals: command maneuvers and hinge-moment loads, from spec strings."""

from ema_sim.signals.loads import LOADS, Load, parse_load
from ema_sim.signals.maneuvers import MANEUVERS, Maneuver, parse_maneuver

__all__ = ["LOADS", "MANEUVERS", "Load", "Maneuver", "parse_load", "parse_maneuver"]
