"""Records every topic of the graph into a bag, as ``ros2 bag record -a`` would, raw (no re-serialisation).

Contract topics are subscribed at once with their contract QoS; others are discovered every second
and subscribed with their publishers' reliability. Topics are recorded under their contract names
(``/ema/fmu/command``) whatever the node's namespace; a namespaced recorder records its namespace only.
Messages are written as the CDR bytes they arrived in, straight into the bag; in a container, frames
from composed nodes are serialized once, for the bag. The node's own publications are written as it
publishes them. Per-frame topics the node does not read itself are taken at the node's frame
(:meth:`Recorder.take`, :meth:`~ema_sim.nodes.ports.Ports.take_at_frame`), not on arrival: a recorder of
the ``processes`` layout takes 21 messages a frame, and waking for each was most of its CPU. Under lockstep
the log time of a stamped message is its stamp (a reproducible bag, but for one offset), counted from the
recording's start on the wall clock (whole seconds: ``sim_epoch_ns`` in the bag's metadata), so the bag is
dated when it was recorded, not 1970, while the messages' own stamps keep the suite's time from 0; a message
without a stamp is logged at the suite's time when it came, and ``/rosout`` entries, which rcl stamps with
the system clock, are restamped with it too (an entry then sits with the frames it speaks of). In real time
the log time is the receive time, as rosbag2 does (DDS's, for a message taken at the frame).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable

from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy

from ema_msgs_py import cdr
from ema_msgs_py import contract as ct
from ema_msgs_py import typestore as ts
from ema_msgs_py.ros import message_class, qos
from ema_sim.io.bag import BagWriter
from ema_sim.jsontypes import JsonObject
from ema_sim.nodes.ports import NodePorts

NS = 1_000_000_000

LEADING_STAMP = {"sensor_msgs/msg/JointState", "diagnostic_msgs/msg/DiagnosticArray", "rosgraph_msgs/msg/Clock"}
"""Types whose serialization starts with a time stamp in the suite's time base (``/rosout`` stamps are
always system time, so its messages are logged at their receive time)."""
EXCLUDED = ("/parameter_events",)
RESTAMPED = "/rosout"
"""Under lockstep, the topic whose system-time stamps are replaced by the suite's time when recorded."""


def leading_stamp_ns(raw: bytes) -> int | None:
    """The stamp at the start of a CDR message (after the 4-byte encapsulation header).

    Parameters
    ----------
    raw : bytes
        The message's CDR bytes.

    Returns
    -------
    int or None
        The stamp (ns); None when the message is too short to hold one.
    """
    return cdr.stamp_ns(raw)


class Recorder:
    """Raw subscriptions of a node feeding a :class:`~ema_sim.io.bag.BagWriter`.

    Parameters
    ----------
    node : rclpy.node.Node
        The node whose subscriptions these are.
    writer : BagWriter
        The bag.
    lockstep : bool
        The suite runs on ``/clock``: a stamped message is logged at its stamp (a reproducible bag).
    ports : Ports or ComposedPorts
        The node's per-frame topic ports (raw subscriptions, ``/clock``).
    own : iterable of str
        The node's own publications, written by :meth:`record_own` as it publishes them.
    hooks : dict of str to callable or None
        Per topic, called with (raw, log time) after its message is written (in real time the log time is
        when the message was received, taken at the frame or not).
    on_clock : callable or None
        Called with each new ``/clock`` time (ns) once it is written.
    hooks_at_frame : bool
        The hooked topics too are taken at the frame (a driver that reads them once a frame, in real time).
    """

    def __init__(self, node: Node, writer: BagWriter, *, lockstep: bool, ports: NodePorts, own: Iterable[str] = (),
                 hooks: dict[str, Callable[[bytes, int], None]] | None = None,
                 on_clock: Callable[[int], None] | None = None, hooks_at_frame: bool = False) -> None:
        self.node = node
        self.writer = writer
        self.lockstep = lockstep
        self.topics: dict[str, str] = {}
        self.hooks: dict[str, Callable[[bytes, int], None]] = dict(hooks or {})
        """Called with (raw, log time) after a topic's message is written (the node's own use of it)."""
        self.on_clock = on_clock
        self.last_message = time.monotonic()
        self.errors = 0
        self._next_discovery = 0.0
        self._last_clock = -1
        self.namespace = node.get_namespace()
        self.ports = ports
        self._now_ns: Callable[[], int] = (lambda: node.get_clock().now().nanoseconds) if lockstep else time.time_ns
        self.epoch_ns = time.time_ns() // NS * NS if lockstep else 0
        """Lockstep: what the log times add to the suite's time (the recording's start, whole seconds); 0 in real
        time."""
        if lockstep:
            writer.set_metadata("sim_epoch_ns", str(self.epoch_ns))
        for topic in own:  # the node's own publications: written as it publishes them, not taken back
            self._add(topic, ct.TOPICS[topic].msgtype)
        for name, spec in ct.TOPICS.items():
            if name in self.topics:
                continue
            if name == ct.CLOCK_TOPIC:
                self._add(name, spec.msgtype)
                ports.clock_subscription(self._record_clock)
            elif spec.per_frame:
                self._add(name, spec.msgtype)
                ports.raw_subscription(name, self._callback(name, spec.msgtype, True),
                                       at_frame=hooks_at_frame or name not in self.hooks)
            else:
                self._subscribe(name, spec.msgtype, qos(spec.qos if spec.qos.durability == "volatile"
                                                       else ct.QosSpec(spec.qos.reliability, spec.qos.durability,
                                                                       100)))

    def _add(self, topic: str, msgtype: str) -> None:
        self.topics[topic] = msgtype
        self.writer.add_topic(topic, msgtype, ct.TOPICS[topic].qos if topic in ct.TOPICS else None)

    def _record_clock(self, ns: int) -> None:
        if ns <= self._last_clock:  # a clock sent again while it waits (best-effort readers may miss one)
            return
        self._last_clock = ns
        try:
            self.writer.write(ct.CLOCK_TOPIC, ct.CLOCK, ns + self.epoch_ns if self.lockstep else self._now_ns(),
                              cdr.encode_clock(ns))
            self.last_message = time.monotonic()
            if self.on_clock is not None:
                self.on_clock(ns)
        except Exception as exc:  # never lose the node over one message
            self.errors += 1
            self.node.get_logger().error(f"recording {ct.CLOCK_TOPIC}: {exc}", throttle_duration_sec=1.0)

    def _subscribe(self, topic: str, msgtype: str, profile: QoSProfile, resolved: str | None = None) -> None:
        """Record ``topic`` (its contract name; ``resolved``: its full name when discovered)."""
        if topic in self.topics or topic in EXCLUDED or msgtype not in ts.typestore().types:
            return
        self._add(topic, msgtype)
        stamped = msgtype in LEADING_STAMP
        self.node.create_subscription(message_class(msgtype), resolved or ct.endpoint(topic),
                                      self._callback(topic, msgtype, stamped), profile, raw=True)

    def record_own(self, topic: str, raw: bytes, stamp_ns: int) -> None:
        """One of the node's own publications (stamped ``stamp_ns``), with the log time a take would give it.

        Parameters
        ----------
        topic : str
            One of the ``own`` topics.
        raw : bytes
            The message's CDR bytes.
        stamp_ns : int
            Its stamp (ns).
        """
        self.writer.write(topic, self.topics[topic], stamp_ns + self.epoch_ns if self.lockstep else self._now_ns(),
                          raw)

    def take(self) -> int:
        """Record the messages waiting on the topics taken at the frame (the node calls it once a frame).

        Returns
        -------
        int
            How many.
        """
        n: int = self.ports.take_at_frame()
        return n

    def _callback(self, topic: str, msgtype: str, stamped: bool) -> Callable[[bytes], None]:
        ports = self.ports

        restamp = self.lockstep and topic == RESTAMPED

        def record(raw: bytes) -> None:
            try:
                stamp = leading_stamp_ns(raw) if stamped and self.lockstep else None
                received = None if self.lockstep else ports.received_ns  # DDS's receive time is system time
                log_time = stamp if stamp is not None else (received or self._now_ns())
                if restamp:  # the suite's time, as every other stamp of the bag
                    raw = cdr.restamp(raw, log_time)
                log_time += self.epoch_ns
                self.writer.write(topic, msgtype, log_time, raw)
                self.last_message = time.monotonic()
                hook = self.hooks.get(topic)
                if hook is not None:
                    hook(raw, log_time)
            except Exception as exc:  # never lose the node over one message
                self.errors += 1
                self.node.get_logger().error(f"recording {topic}: {exc}", throttle_duration_sec=1.0)
        return record

    def discover(self) -> None:
        """Subscribe to topics that appeared since the last call (at most once a second)."""
        now = time.monotonic()
        if now < self._next_discovery:
            return
        self._next_discovery = now + 1.0
        for resolved, types in self.node.get_topic_names_and_types():
            topic = ct.canonical(resolved, self.namespace)
            if topic is None or topic in self.topics or topic in EXCLUDED or len(types) != 1:
                continue
            infos = self.node.get_publishers_info_by_topic(resolved)
            if not infos:
                continue
            offered = infos[0].qos_profile
            profile = QoSProfile(  # type: ignore[no-untyped-call]  # rclpy's QoSProfile(**kwargs) carries no annotations
                depth=1000, reliability=offered.reliability, durability=offered.durability)
            if offered.reliability not in (ReliabilityPolicy.RELIABLE, ReliabilityPolicy.BEST_EFFORT):
                profile.reliability = ReliabilityPolicy.BEST_EFFORT
            self._subscribe(topic, types[0], profile, resolved)

    def summary(self) -> JsonObject:
        """Messages recorded per topic."""
        return {"messages": dict(self.writer.counts), "errors": self.errors}
