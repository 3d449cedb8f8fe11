"""How a suite node's per-frame messages travel: its own DDS endpoints, or a container's in-process bus.

A node gets a :class:`Ports` and asks it for frame publishers and subscriptions; it never sees which
kind it got. Per-frame messages are :class:`~ema_msgs_py.cdr.JointFrame` objects inside the suite
and CDR bytes on the wire (rclpy's ``publish(bytes)`` and ``raw=True`` subscriptions: measured here,
half the CPU of publishing and taking rclpy messages).

* :class:`Ports`, a node alone in its process: DDS endpoints of its own.
* :class:`~ema_sim.nodes.container.Bus` ports, a node composed in the container with others: the bus
  hands each frame to the composed subscribers as a Python object and publishes it once on DDS for
  everyone outside (the ROS 2 notion of intra-process communication).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from rclpy.time import Time
from rclpy.time_source import TimeSource
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState

from ema_msgs_py import cdr
from ema_msgs_py import contract as ct
from ema_msgs_py.ros import qos

if TYPE_CHECKING:
    from rclpy.node import Node

FrameCallback = Callable[[cdr.JointFrame], None]
ClockCallback = Callable[[int], None]
GRAPH_CACHE_S = 0.1
"""How long a publisher count from the ROS graph is reused (a graph query costs ~100 µs)."""


class FramePublisher:
    """Publishes JointFrames of one topic as CDR bytes.

    Parameters
    ----------
    node : Node
        The node that owns the publisher.
    topic : str
        The contract topic.
    profile : QoSProfile
        Its QoS.
    """

    def __init__(self, node: Node, topic: str, profile: Any) -> None:
        self.topic = topic
        self.dds = node.create_publisher(JointState, ct.endpoint(topic), profile)

    def publish(self, frame: cdr.JointFrame) -> bytes:
        """One frame to every subscriber.

        Parameters
        ----------
        frame : JointFrame
            The frame.

        Returns
        -------
        bytes
            The CDR bytes sent (a recorder of the node's own publications writes them as they are).
        """
        raw = cdr.encode(frame)
        self.dds.publish(raw)
        return raw


class ClockPublisher:
    """Publishes lockstep ``/clock`` frames as CDR bytes.

    Parameters
    ----------
    node : Node
        The node that owns the publisher.
    """

    def __init__(self, node: Node) -> None:
        self.dds = node.create_publisher(Clock, ct.endpoint(ct.CLOCK_TOPIC), qos(ct.CLOCK_QOS))

    def publish(self, ns: int) -> None:
        """The clock at ``ns``.

        Parameters
        ----------
        ns : int
            The time, ns.
        """
        self.dds.publish(cdr.encode_clock(ns))


class Ports:
    """A node alone in its process: every endpoint is its own DDS endpoint.

    Parameters
    ----------
    node : Node
        The node whose endpoints these are.
    """

    composed = False

    def __init__(self, node: Node) -> None:
        self.node = node
        self._counts: dict[str, tuple[float, int]] = {}

    def frame_publisher(self, topic: str) -> FramePublisher:
        """A publisher of a per-frame contract topic (its contract QoS).

        Parameters
        ----------
        topic : str
            The contract topic.

        Returns
        -------
        FramePublisher
            The publisher.
        """
        return FramePublisher(self.node, topic, qos(ct.FRAME_QOS))

    def frame_subscription(self, topic: str, callback: FrameCallback, on_bad: Callable[[str], None]) -> None:
        """Frames of a per-frame topic; a malformed message goes to ``on_bad`` (never raises).

        Parameters
        ----------
        topic : str
            The contract topic.
        callback : callable
            Takes each decoded frame.
        on_bad : callable
            Takes the reason a message could not be decoded.
        """

        def take(raw: bytes) -> None:
            try:
                frame = cdr.decode(raw)
            except ValueError as exc:
                on_bad(f"{topic}: {exc}")
                return
            callback(frame)

        self.node.create_subscription(JointState, ct.endpoint(topic), take, qos(ct.FRAME_QOS), raw=True)

    def raw_subscription(self, topic: str, callback: Callable[[bytes], None]) -> None:
        """A per-frame topic's messages as CDR bytes (a recorder's view).

        Parameters
        ----------
        topic : str
            The contract topic.
        callback : callable
            Takes each message's bytes.
        """
        self.node.create_subscription(JointState, ct.endpoint(topic), callback, qos(ct.FRAME_QOS), raw=True)

    def clock_publisher(self) -> ClockPublisher:
        """The lockstep clock's ``/clock`` publisher.

        Returns
        -------
        ClockPublisher
            The publisher.
        """
        return ClockPublisher(self.node)

    def clock_subscription(self, callback: ClockCallback) -> None:
        """Lockstep ``/clock`` in nanoseconds; it also drives the node's ROS clock (one take, not two).

        Parameters
        ----------
        callback : callable
            Takes each ``/clock`` value, ns.
        """
        feed = TimeFeed([own_time_source(self.node)])

        def take(raw: bytes) -> None:
            ns = cdr.stamp_ns(raw)
            if ns is None:
                return
            feed(ns)
            callback(ns)

        self.node.create_subscription(Clock, ct.endpoint(ct.CLOCK_TOPIC), take, qos(ct.CLOCK_SUB_QOS), raw=True)

    def publishers(self, topic: str) -> int:
        """Publishers of a topic in the graph (a graph query, reused for :data:`GRAPH_CACHE_S`).

        Parameters
        ----------
        topic : str
            The contract topic.

        Returns
        -------
        int
            How many.
        """
        now = time.monotonic()
        cached = self._counts.get(topic)
        if cached is None or now - cached[0] > GRAPH_CACHE_S:
            cached = self._counts[topic] = (now, self.node.count_publishers(ct.endpoint(topic)))
        return cached[1]

    def endpoint_nodes(self) -> list[Node]:
        """Nodes whose endpoints must be matched before this node calls itself ready."""
        return [self.node]


def own_time_source(node: Node) -> Any:
    """Under ``use_sim_time`` rclpy's TimeSource takes ``/clock`` itself; take that over, return the clock.

    The suite's nodes already take every ``/clock`` frame (or get it in-process): their ROS clock is
    then set from that frame (:class:`TimeFeed`) instead of by a second subscription that deserializes
    the same message again.

    Parameters
    ----------
    node : Node
        The node.

    Returns
    -------
    rclpy.clock.Clock or None
        Its ROS clock, or None when the node is not under sim time.
    """
    found = False
    for sub in list(node.subscriptions):
        owner = getattr(sub.callback, "__self__", None)
        if isinstance(owner, TimeSource):  # its /clock subscription, wherever a remapping put it
            node.destroy_subscription(sub)
            found = True
    return node.get_clock() if found else None


class TimeFeed:
    """Sets ROS clocks (of nodes under ``use_sim_time``) to each ``/clock`` frame: one Time for all.

    Parameters
    ----------
    clocks : list or None
        The clocks (None entries, nodes not under sim time, are left out).
    """

    def __init__(self, clocks: list[Any] | None = None) -> None:
        self.clocks = [c for c in clocks or [] if c is not None]

    def __call__(self, ns: int) -> None:
        """Every clock to ``ns``."""
        if self.clocks:
            t = Time(nanoseconds=ns, clock_type=self.clocks[0].clock_type)
            for clock in self.clocks:
                clock.set_ros_time_override(t)
