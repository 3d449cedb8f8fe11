"""What the EMAC node makes of an input message before any of it reaches a channel.

A message is taken whole or dropped whole, and a dropped one is counted once, under one reason
(:func:`pick`): a message that lists no names (``no_names``); one whose arrays do not match its names, or
whose value for a hosted channel is not a number or beyond what any converter reads (``malformed``); one
that names no channel of the suite (``unknown_names``: one count a message, however many names it gets
wrong). A malformed message is never applied: the channel holds its last good input.

How a publisher stamps its commands is its *stamp policy* (:class:`StampPolicy`), stated once in the node's
log and in ``/diagnostics`` (``command_stamps``), never counted as losses: stamped on the frame grid (an
FMU's frame), stamped off it (a publisher's ``now()``) or unstamped (each command is the next frame's).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import NamedTuple

from ema_msgs_py import contract as ct

OUT_OF_RANGE_FACTOR = 1.1
"""A command beyond this many times the channel's full scale (±10 V) is malformed, not clamped: no converter
reads it (a wrong unit, degrees or radians for volts, a corrupt value). Up to it, the converter saturates
(the channel clamps it, :meth:`ema_sim.emac.EmacChannel.set_command`), as noise on a full-scale command does."""


class Picked(NamedTuple):
    """A message's values for the hosted channels, or why it was dropped."""

    values: dict[str, float]
    """Each hosted channel's value (empty when dropped or when it names none of them)."""
    reason: str | None = None
    """Why it was dropped (a key of the node's ``drops``), or None when taken."""
    text: str = ""
    """The log line for a drop."""


def pick(names: Sequence[str], array: Sequence[float], hosted: Mapping[str, float], field: str,
         what: str) -> Picked:
    """The hosted channels' values of one message, or the one reason it is dropped whole.

    Parameters
    ----------
    names : sequence of str
        The message's joint names.
    array : sequence of float
        Its values of ``field``.
    hosted : mapping of str to float
        The hosted channels, each with the largest magnitude a value may have (inf: any finite value).
    field : str
        The field (``position``, ``effort``), for the log line.
    what : str
        What the message is (``command``, ``hinge moment``), for the log line.

    Returns
    -------
    Picked
        The values, or the reason and the log line.
    """
    if not names:
        if array:
            return Picked({}, "no_names", f"{what} message without joint names ({len(array)} {field} values) dropped")
        return Picked({})
    if len(array) != len(names):
        return Picked({}, "malformed", f"{what} message with {len(names)} names and {len(array)} {field} values "
                      "dropped whole (which value is whose is unknown)")
    unknown = [n for n in names if n not in ct.CHANNELS]
    out: dict[str, float] = {}
    for i, name in enumerate(names):
        limit = hosted.get(name)
        if limit is None:
            continue
        try:
            v = float(array[i])
        except (TypeError, ValueError):
            v = math.nan
        if not math.isfinite(v) or abs(v) > limit:
            return Picked({}, "malformed", f"{what} message with {name} = {array[i]!r} dropped whole "
                          f"({'not a number' if not math.isfinite(v) else f'beyond ±{limit:g}'}); the channel "
                          "holds its last good value")
        out[name] = v
    if unknown:
        return Picked(out, "unknown_names", f"{what} for unknown joint(s) {', '.join(map(repr, unknown[:5]))} "
                      f"dropped (channels: {', '.join(ct.CHANNELS)})")
    return Picked(out)


POLICIES = {
    "grid": "commands stamped on the {frame_ms:g} ms frame grid: each is its frame's, stamps that skip frames "
            "are a gap in publishing (or, when they run ahead of the wall time, commands lost)",
    "off_grid": "commands stamped off the {frame_ms:g} ms frame grid (a publisher's now()): each is the frame it "
                "falls in; a gap between stamps is a gap in publishing, judged by the wall time, not a loss",
    "unstamped": "unstamped commands: each is the next frame's, stamped when stepped; the node cannot tell a "
                 "gap from a loss and counts neither",
}
"""How a publisher stamps its commands, and what the node makes of it (logged once)."""


class StampPolicy:
    """How the commands are stamped, stated once (and again only if it changes).

    Parameters
    ----------
    frame_ns : int
        The FMU frame, ns.
    """

    def __init__(self, frame_ns: int) -> None:
        self.frame_ns = frame_ns
        self.policy = "none"
        """``grid``, ``off_grid``, ``unstamped`` or ``none`` (no command yet)."""
        self._grid_run = 0

    def observe(self, stamp_ns: int) -> str | None:
        """A command stamped ``stamp_ns`` came; the line to log when the policy is new, else None.

        A stamp on the grid after stamps off it is only believed after :data:`GRID_RUN` in a row (a ``now()``
        stamp falls on the grid once in a while).

        Parameters
        ----------
        stamp_ns : int
            Its stamp, ns (0: unstamped).

        Returns
        -------
        str or None
            The policy's statement, when it is new.
        """
        if not stamp_ns:
            seen = "unstamped"
        elif stamp_ns % self.frame_ns:
            seen = "off_grid"
        else:
            self._grid_run += 1
            seen = "grid" if self.policy != "off_grid" or self._grid_run >= GRID_RUN else "off_grid"
        if seen != "grid":
            self._grid_run = 0
        if seen == self.policy:
            return None
        self.policy = seen
        return POLICIES[seen].format(frame_ms=self.frame_ns / 1e6)


GRID_RUN = 20
"""Consecutive stamps on the frame grid after which a publisher that stamped off it is believed to stamp on it."""
