"""How a suite node's per-frame messages travel: its own DDS endpoints, or a container's in-process bus.

A node gets a :class:`Ports` and asks it for frame publishers and subscriptions; it never sees which
kind it got. Per-frame messages are :class:`~ema_msgs_py.cdr.JointFrame` objects inside the suite
and CDR bytes on the wire (rclpy's ``publish(bytes)`` and ``raw=True`` subscriptions: measured here,
half the CPU of publishing and taking rclpy messages).

* :class:`Ports`, a node alone in its process: DDS endpoints of its own. A subscription may be taken *at the
  frame* (``at_frame=True``): the executor does not wake the process for its messages, which wait in DDS
  (keep last 1000) until the node's frame takes them (:meth:`Ports.take_at_frame`), as a real-time control
  loop reads its inputs at the start of its cycle. A process woken once a frame instead of once a message
  saves the middleware's wake-ups (measured: the ``processes`` layout's messages between bare rclpy processes,
  ``bench/middleware.py``, 41 % of one core against 48 % taking each on arrival). Under lockstep it may send
  several frames as one message (:attr:`Ports.frames_per_message`, :mod:`ema_msgs_py.batch`): the frames a node
  publishes in one turn of its loop go out together when the turn ends (:meth:`Ports.flush`); a batch that
  comes in is handed over frame by frame, whatever the node's own setting.
* :class:`~ema_sim.nodes.container.Bus` ports, a node composed in the container with others: the bus
  hands each frame to the composed subscribers as a Python object and publishes it once on DDS for
  everyone outside (the ROS 2 notion of intra-process communication).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Protocol

from rclpy.clock import ROSClock
from rclpy.exceptions import InvalidHandle
from rclpy.time import Time
from rclpy.time_source import TimeSource
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState

from ema_msgs_py import batch, cdr
from ema_msgs_py import contract as ct
from ema_msgs_py.ros import qos
from ema_sim.errors import EmaError
from ema_sim.nodes.params import Spec

if TYPE_CHECKING:
    from rclpy.node import Node
    from rclpy.qos import QoSProfile
    from rclpy.subscription import Subscription

FrameCallback = Callable[[cdr.JointFrame], None]
ClockCallback = Callable[[int], None]


class FrameOutlet(Protocol):
    """A per-frame publisher: :class:`FramePublisher` (gives the CDR bytes sent) or a container's (gives None)."""

    def publish(self, frame: cdr.JointFrame) -> bytes | None:
        """Publish one frame.

        Parameters
        ----------
        frame : JointFrame
            The frame.
        """


class ClockOutlet(Protocol):
    """A ``/clock`` publisher: :class:`ClockPublisher` or a container's."""

    def publish(self, ns: int) -> None:
        """Publish the time.

        Parameters
        ----------
        ns : int
            The time, ns.
        """


class NodePorts(Protocol):
    """How a node's per-frame messages travel: :class:`Ports` on DDS, or a container's ``ComposedPorts``.

    Each method is :class:`Ports`' of the same name (documented there).
    """

    @property
    def received_ns(self) -> int | None:
        """While :meth:`take_at_frame` hands a message over: when DDS received it (system time, ns); else None."""

    def take_at_frame(self) -> int:
        """Take the messages of the subscriptions taken at the frame; how many."""

    def frame_publisher(self, topic: str) -> FrameOutlet:
        """A publisher of a per-frame contract topic.

        Parameters
        ----------
        topic : str
            The contract topic.
        """

    def frame_subscription(self, topic: str, callback: FrameCallback, on_bad: Callable[[str], None], *,
                           at_frame: bool = False) -> None:
        """Frames of a per-frame topic; a malformed message goes to ``on_bad``.

        Parameters
        ----------
        topic, callback, on_bad, at_frame : as in :meth:`Ports.frame_subscription`
        """

    def raw_subscription(self, topic: str, callback: Callable[[bytes], None], *, at_frame: bool = False) -> None:
        """A per-frame topic's messages as CDR bytes.

        Parameters
        ----------
        topic, callback, at_frame : as in :meth:`Ports.raw_subscription`
        """

    def clock_publisher(self) -> ClockOutlet:
        """The lockstep clock's ``/clock`` publisher."""

    def clock_subscription(self, callback: ClockCallback) -> None:
        """Lockstep ``/clock`` in nanoseconds.

        Parameters
        ----------
        callback : callable
            Takes each ``/clock`` value, ns.
        """

    def publishers(self, topic: str) -> int:
        """Publishers of a topic in the graph.

        Parameters
        ----------
        topic : str
            The contract topic.
        """

    def endpoint_nodes(self) -> list[Node]:
        """Nodes whose endpoints must be matched before this node calls itself ready."""


FRAMES_PER_MESSAGE = "frames_per_message"
"""The parameter of the batched option (the clock's grant and the frames a message carries)."""


def frames_spec() -> Spec:
    """The ``frames_per_message`` parameter: lockstep, frames granted at once and sent as one message per topic."""
    return Spec(FRAMES_PER_MESSAGE, 1, "lockstep: frames the clock grants at once, each node sending them as one "
                "message per topic (1: frame by frame, the contract's default)", low=1, high=1000)


def use_batches(ports: NodePorts, frames: int, lockstep: bool, node: str) -> None:
    """Send up to ``frames`` frames a message (:class:`Ports` under lockstep only; one clear error otherwise).

    Parameters
    ----------
    ports : NodePorts
        The node's ports.
    frames : int
        The ``frames_per_message`` parameter.
    lockstep : bool
        The node runs on ``/clock``.
    node : str
        The node's name, for the error.

    Raises
    ------
    EmaError
        Batching asked for in real time, or of a node composed in a container (frames handed over in-process).
    """
    if frames <= 1:
        return
    if not lockstep:
        raise EmaError(f"{node}: frames_per_message {frames} needs lockstep (use_sim_time): in real time each frame "
                       "is answered as it comes")
    if not isinstance(ports, Ports):
        raise EmaError(f"{node}: frames_per_message {frames} needs a node in a process of its own (--layout "
                       "processes): a composed node hands its frames over in-process")
    ports.frames_per_message = frames


PortsFactory = Callable[["Node"], NodePorts]
"""What a node is given to build its ports from itself: the :class:`Ports` class, or a container's ``Bus.ports``."""
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

    def __init__(self, node: Node, topic: str, profile: QoSProfile) -> None:
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


class BatchingPublisher(FramePublisher):
    """Holds the frames of one turn of the node's loop and sends them as one message (:mod:`ema_msgs_py.batch`).

    Frames that cannot share a batch (another layout, a stamp off the step) and the frame past ``limit``
    send the held ones first; one frame alone goes out as itself.

    Parameters
    ----------
    node : Node
        The node that owns the publisher.
    topic : str
        The contract topic.
    profile : QoSProfile
        Its QoS.
    limit : int
        At most this many frames a message.
    held_by : list
        The port's publishers holding frames, in the order they got their first (:meth:`Ports.flush`).
    """

    def __init__(self, node: Node, topic: str, profile: QoSProfile, limit: int,
                 held_by: list[BatchingPublisher]) -> None:
        super().__init__(node, topic, profile)
        self.limit = limit
        self.held: list[cdr.JointFrame] = []
        self._held_by = held_by

    def publish(self, frame: cdr.JointFrame) -> None:  # type: ignore[override]  # held: no bytes sent yet
        """Hold one frame until the turn ends (a frame that cannot join the held ones sends them first).

        Parameters
        ----------
        frame : JointFrame
            The frame.
        """
        held = self.held
        if held:
            first = held[0]
            step = held[1].stamp_ns - first.stamp_ns if len(held) > 1 else frame.stamp_ns - first.stamp_ns
            if (len(held) >= self.limit or step <= 0 or frame.stamp_ns != first.stamp_ns + len(held) * step
                    or not batch.compatible(first, frame)):
                self.send()  # still listed as holding: the new frame goes out at the flush
        else:
            self._held_by.append(self)
        self.held.append(frame)

    def send(self) -> None:
        """Send the held frames as one message."""
        if self.held:
            self.dds.publish(cdr.encode(batch.join(self.held)))
            self.held = []


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
        self.frames_per_message = 1
        """Lockstep: frames a message may carry (1: one a message, the contract's default)."""
        self._held: list[BatchingPublisher] = []
        self._counts: dict[str, tuple[float, int]] = {}
        self._at_frame: list[tuple[Subscription, Callable[[bytes], None]]] = []
        self.received_ns: int | None = None
        """While :meth:`take_at_frame` hands a message over: when DDS received it (system time, ns); else None."""

    def flush(self) -> None:
        """Send the frames held by batching publishers (the end of a turn of the node's loop), in the order held."""
        held = self._held  # the list the publishers add themselves to: emptied in place
        for publisher in held:
            publisher.send()
        held.clear()

    def _subscribe(self, topic: str, callback: Callable[[bytes], None], at_frame: bool) -> None:
        """A raw subscription, dispatched by the executor or taken at the frame (when the node can hide it)."""
        sub = self.node.create_subscription(JointState, ct.endpoint(topic), callback, qos(ct.FRAME_QOS), raw=True)
        hidden: set[object] | None = getattr(self.node, "at_frame", None)  # a SuiteNode's: what its executor skips
        if at_frame and hidden is not None:
            hidden.add(sub)
            self._at_frame.append((sub, callback))

    def take_at_frame(self) -> int:
        """Hand over every message waiting on the subscriptions taken at the frame, oldest first per topic.

        Returns
        -------
        int
            How many.
        """
        n = 0
        gone = []
        for entry in self._at_frame:
            sub, callback = entry
            handle = sub.handle
            try:
                with handle:
                    while (taken := handle.take_message(sub.msg_type, True)) is not None:
                        self.received_ns = taken[1]["received_timestamp"]
                        callback(taken[0])
                        n += 1
            except InvalidHandle:  # destroyed (a managed node's cleanup): nothing more to take from it
                gone.append(entry)
            finally:
                self.received_ns = None
        for entry in gone:
            self._at_frame.remove(entry)
        return n

    def frame_publisher(self, topic: str) -> FramePublisher:
        """A publisher of a per-frame contract topic (its contract QoS), batching when :attr:`frames_per_message` > 1.

        Parameters
        ----------
        topic : str
            The contract topic.

        Returns
        -------
        FramePublisher
            The publisher (a :class:`BatchingPublisher`, whose ``publish`` gives no bytes, when batching).
        """
        if self.frames_per_message > 1:
            return BatchingPublisher(self.node, topic, qos(ct.FRAME_QOS), self.frames_per_message, self._held)
        return FramePublisher(self.node, topic, qos(ct.FRAME_QOS))

    def frame_subscription(self, topic: str, callback: FrameCallback, on_bad: Callable[[str], None], *,
                           at_frame: bool = False) -> None:
        """Frames of a per-frame topic; a malformed message goes to ``on_bad`` (never raises).

        Parameters
        ----------
        topic : str
            The contract topic.
        callback : callable
            Takes each decoded frame.
        on_bad : callable
            Takes the reason a message could not be decoded.
        at_frame : bool
            Taken by :meth:`take_at_frame`, not on arrival.
        """

        def take(raw: bytes) -> None:
            try:
                frame = cdr.decode(raw)
                frames = batch.split(frame) if frame.frame_id.startswith(batch.PREFIX) else (frame,)
            except ValueError as exc:
                on_bad(f"{topic}: {exc}")
                return
            for one in frames:
                callback(one)

        self._subscribe(topic, take, at_frame)

    def raw_subscription(self, topic: str, callback: Callable[[bytes], None], *, at_frame: bool = False) -> None:
        """A per-frame topic's messages as CDR bytes (a recorder's view).

        Parameters
        ----------
        topic : str
            The contract topic.
        callback : callable
            Takes each message's bytes.
        at_frame : bool
            Taken by :meth:`take_at_frame`, not on arrival.
        """

        def take(raw: bytes) -> None:
            if not batch.is_batch(raw):
                callback(raw)
                return
            try:
                frames = batch.split_raw(raw)
            except ValueError:  # a malformed batch: as it came (a recorder keeps what was sent)
                frames = [raw]
            for one in frames:
                callback(one)

        self._subscribe(topic, take, at_frame)

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


def own_time_source(node: Node) -> ROSClock | None:
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
    clock = node.get_clock()
    return clock if found and isinstance(clock, ROSClock) else None


class TimeFeed:
    """Sets ROS clocks (of nodes under ``use_sim_time``) to each ``/clock`` frame: one Time for all.

    Parameters
    ----------
    clocks : list or None
        The clocks (None entries, nodes not under sim time, are left out).
    """

    def __init__(self, clocks: list[ROSClock | None] | None = None) -> None:
        self.clocks: list[ROSClock | None] = [c for c in clocks or [] if c is not None]

    def __call__(self, ns: int) -> None:
        """Every clock to ``ns``."""
        t: Time | None = None
        for clock in self.clocks:
            if clock is not None:  # a node not under sim time, added by a composed node's ports
                if t is None:
                    t = Time(nanoseconds=ns, clock_type=clock.clock_type)
                clock.set_ros_time_override(t)
