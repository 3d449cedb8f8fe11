"""The EMAC node's streams: its inputs queued frame by frame, its outputs assembled and published.

Inputs (:class:`Stream`, :class:`SourceStream`): every stamped message of an input topic (commands, hinge
moments, the other channels' feedback) waits here until the node takes it, at once in real time or frame
by frame in lockstep. Outputs (:class:`Outputs`): the frame's feedback (LVDT volts, motor amps), the
surface sensor (degrees, deg/s, in·lb) and the bus (volts) as one ``JointFrame`` each, and the per-channel
``/diagnostics`` status (:func:`diagnostics`). The node (:mod:`ema_sim.nodes.emac`) decides when.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Mapping
from typing import Generic, TypeVar

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.node import Node

from ema_msgs_py import contract as ct
from ema_msgs_py.cdr import JointFrame
from ema_msgs_py.ros import qos
from ema_sim.emac import EmacChannel, Feedback
from ema_sim.nodes.ports import NodePorts

T = TypeVar("T")

CommandItem = tuple[dict[str, float], float, bool]
"""A command message as kept: each channel's command (V), when it arrived (monotonic, s), and whether its stamp
resynchronized the frame clock."""


class Stream(Generic[T]):
    """Stamped messages of one input topic, consumed frame by frame (lockstep) or as they come."""

    def __init__(self) -> None:
        self.queue: deque[tuple[int, T]] = deque()
        self.last_stamp: int | None = None
        self.waiting_since: float | None = None
        self.gave_up = False

    def push(self, stamp: int, item: T) -> None:
        """A message arrived.

        Parameters
        ----------
        stamp : int
            Its stamp, ns.
        item : object
            What the node keeps of it.
        """
        self.queue.append((stamp, item))
        self.last_stamp = stamp if self.last_stamp is None else max(self.last_stamp, stamp)
        self.gave_up = False

    def reached(self, t_ns: int) -> bool:
        """A message for frame ``t_ns`` (or later) has arrived.

        Parameters
        ----------
        t_ns : int
            The frame's time, ns.

        Returns
        -------
        bool
            True once one has.
        """
        return self.last_stamp is not None and self.last_stamp >= t_ns

    def restart(self, t_ns: int) -> None:
        """Time restarted at ``t_ns``: keep what is stamped at or before it (the new time's), drop the rest.

        Parameters
        ----------
        t_ns : int
            The new time, ns.
        """
        kept = [item for item in self.queue if item[0] <= t_ns]
        self.queue.clear()
        self.queue.extend(kept)
        self.last_stamp = max((stamp for stamp, _ in kept), default=None)
        self.waiting_since = None
        self.gave_up = False

    def take_until(self, t_ns: int) -> list[tuple[int, T]]:
        """(stamp, item) stamped at or before ``t_ns``, in arrival order.

        Every such item, not only those before the first later one: messages of different publishers
        (the crosstalk sources) may arrive out of stamp order, and a later frame's message from one
        must not hold back this frame's from another.

        Parameters
        ----------
        t_ns : int
            The frame's time, ns.

        Returns
        -------
        list of (int, item)
            The messages taken, in arrival order.
        """
        queue = self.queue
        if not queue:
            return []
        out = [item for item in queue if item[0] <= t_ns]
        if len(out) == len(queue):  # the usual case: everything queued is due
            queue.clear()
        elif out:
            kept = [item for item in queue if item[0] > t_ns]
            queue.clear()
            queue.extend(kept)
        return out


class SourceStream(Stream[list[tuple[str, float]]]):
    """The other channels' feedback (crosstalk sources): a frame is there when every source has sent it.

    Which sources exist is the node's to say (:attr:`expected`; the EMAC node takes them from the suite's
    peers, its ``emac_<channel>`` nodes): a frame waits for each of them, so the crosstalk a channel sees
    does not depend on which source's message came first. Without them (a node run on its own) any
    source's message counts, as it cannot know better.

    Parameters
    ----------
    expected : frozenset of str
        The sources every frame waits for (empty: any source's message counts).
    """

    def __init__(self, expected: frozenset[str] = frozenset()) -> None:
        super().__init__()
        self.expected = expected
        """The sources every frame waits for (empty: any source's message counts); known before the first message."""
        self._latest: dict[str, int] = {}

    def restart(self, t_ns: int) -> None:  # noqa: D102
        super().restart(t_ns)
        self._latest = {}
        for stamp, item in self.queue:
            self._note(stamp, item)

    def _note(self, stamp: int, item: list[tuple[str, float]]) -> None:
        for name, _ in item:
            if stamp > self._latest.get(name, -1):
                self._latest[name] = stamp
        if self.expected:
            latest = [self._latest.get(name) for name in self.expected]
            self.last_stamp = None if any(x is None for x in latest) else min(latest)  # type: ignore[type-var]
        else:
            self.last_stamp = stamp if self.last_stamp is None else max(self.last_stamp, stamp)

    def push_from(self, stamp: int, item: list[tuple[str, float]]) -> None:
        """A message arrived carrying these sources' values.

        Parameters
        ----------
        stamp : int
            Its stamp, ns.
        item : list of (str, float)
            Each source's name and position feedback, V.
        """
        self.queue.append((stamp, item))
        self.gave_up = False
        self._note(stamp, item)


InputStream = Stream[CommandItem] | Stream[dict[str, float]] | SourceStream
"""One of an EMAC node's input streams: its commands, hinge moments, or crosstalk sources."""


class Outputs:
    """The node's per-frame publishers and how a frame's feedback becomes their messages.

    Parameters
    ----------
    node : Node
        The node that owns the diagnostics publisher.
    ports : NodePorts
        Its :class:`~ema_sim.nodes.ports.Ports` (or a container's), which make the frame publishers.
    channels : list of str
        The hosted channels, in the order every message lists them.
    frame_id : str
        The messages' header ``frame_id``.
    has_current : bool
        The model has a motor: feedback carries its current, and the bus is published.
    """

    def __init__(self, node: Node, ports: NodePorts, channels: list[str], frame_id: str, has_current: bool) -> None:
        self.channels = channels
        self.frame_id = frame_id
        self.has_current = has_current
        self.feedback = ports.frame_publisher(ct.EMAC_FEEDBACK)
        self.surface = ports.frame_publisher(ct.SURFACE)
        self.bus = ports.frame_publisher(ct.BUS) if has_current else None
        self.diagnostics = node.create_publisher(DiagnosticArray, ct.endpoint(ct.DIAGNOSTICS), qos(ct.EVENT_QOS))

    def publish(self, stamp: int, out: Mapping[str, Feedback]) -> None:
        """One frame's messages, stamped ``stamp`` (the end of the frame).

        Parameters
        ----------
        stamp : int
            The frame's stamp, ns.
        out : mapping of str to Feedback
            Each hosted channel's feedback of the frame.
        """
        names, fid = self.channels, self.frame_id
        if len(names) == 1:
            f = out[names[0]]
            self.feedback.publish(JointFrame(stamp, names, [f.position_v], [],
                                             [f.current_a] if self.has_current else [], fid))
            self.surface.publish(JointFrame(stamp, names, [f.surface_deg], [f.rate_dps], [f.hinge_moment_inlb], fid))
            if self.bus is not None:
                self.bus.publish(JointFrame(stamp, names, [f.bus_v], frame_id=fid))
        else:
            fbs = [out[c] for c in names]
            self.feedback.publish(JointFrame(stamp, names, [f.position_v for f in fbs],
                                             [], [f.current_a for f in fbs] if self.has_current else [], fid))
            self.surface.publish(JointFrame(stamp, names, [f.surface_deg for f in fbs],
                                            [f.rate_dps for f in fbs], [f.hinge_moment_inlb for f in fbs], fid))
            if self.bus is not None:
                self.bus.publish(JointFrame(stamp, names, [f.bus_v for f in fbs], frame_id=fid))


def diagnostics(stamp: Time, fqn: str, units: Mapping[str, EmacChannel], counters: Mapping[str, str], *,
                recent_fault: bool, hold_s: float, inactive: bool = False) -> DiagnosticArray:
    """Per channel: ERROR while failing, WARN while inactive or after a recent dropped input, else OK.

    WARN is for what an operator must act on (a publisher that sends what the node drops, a managed node left
    inactive). A brake engaged is the channel doing its job (the watchdog when commands pause, the motor power
    switched off): OK, and the message says why.

    Parameters
    ----------
    stamp : Time
        The message's stamp (the node's clock).
    fqn : str
        The node's full name: each status is named ``<full name>: <channel>``.
    units : mapping of str to EmacChannel
        The hosted channels.
    counters : mapping of str to str
        The node's counters, added to every channel's values.
    recent_fault : bool
        An input was dropped within ``hold_s``.
    hold_s : float
        How long a dropped input keeps the status WARN, s (for the message).
    inactive : bool
        A managed node that is not active (no frames stepped, brake held).

    Returns
    -------
    DiagnosticArray
        One status per channel.
    """
    msg = DiagnosticArray()
    msg.header.stamp = stamp
    for ch, unit in units.items():
        st = unit.status()
        failing = unit.failure.kind != "none"
        level = DiagnosticStatus.ERROR if failing else (
            DiagnosticStatus.WARN if recent_fault or inactive else DiagnosticStatus.OK)
        braked = ("brake engaged (motor power off)" if not unit.motor_power_on else
                  "brake engaged (no command within the watchdog)")
        text = (f"failure {unit.failure.spec()}" if failing else "inactive (managed node): brake held" if inactive
                else f"inputs dropped in the last {hold_s:g} s" if recent_fault else
                braked if unit.last.braked else "nominal")
        st.update(counters)
        msg.status.append(DiagnosticStatus(
            level=level, name=f"{fqn}: {ch}", message=text, hardware_id=unit.model.name,
            values=[KeyValue(key=k, value=v) for k, v in st.items()]))
    return msg
