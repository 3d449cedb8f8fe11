"""``ema_container``: the EMAC channel nodes, the test environment and (lockstep) the clock in one process.

The ROS 2 component-container pattern, for rclpy, which has neither component containers nor
intra-process communication. Each composed node is a whole node: its own name, parameters (a channel's
``config/<channel>.yaml`` addresses ``/**/emac_<channel>``), failure topic, diagnostics and readiness, the
same classes as the one-process-per-node layout. What changes is how per-frame messages travel:

* between composed nodes they are handed over in-process as :class:`~ema_msgs_py.cdr.JointFrame`
  objects (no serialization, no middleware, no wake-up): testenv → EMAC channels → testenv → clock;
* for everyone outside (the maneuver's recorder, instruments, an FMU) each contract topic is still
  published on DDS, once: the composed channels' frames of one stamp leave as one JointState listing
  those channels, as an EMAC box's would (the contract allows any subset of channels per message);
* inputs from outside (``/ema/fmu/command``, ``/ema/load/hinge_moment``, ``/clock`` when the clock is
  not composed) are taken once per process and handed to every composed subscriber.

A topic published inside the container is carried inside only: the container does not also take it
from DDS (rclpy cannot ignore a process's own publications), so the container should host every EMAC
of the suite. Measured here: a lockstep frame of five HOAD3 channels with the AIL environment moves 2
messages into the container and 6 out, instead of about 40 cross-process messages.

The process ends when a composed driver (maneuver, fmu) is done, or when it is stopped; a composed clock's
last frame does not end it, as the last frames may not have reached a driver in another process yet.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable, Sequence
from typing import ParamSpec, TypeVar

from rcl_interfaces.msg import ParameterType
from rclpy.node import Node

from ema_msgs_py import contract as ct
from ema_msgs_py.cdr import JointFrame, decode, encode
from ema_msgs_py.ros import qos
from ema_sim.errors import UnknownNameError
from ema_sim.jsontypes import JsonObject
from ema_sim.nodes import clock as clock_node
from ema_sim.nodes import emac as emac_node
from ema_sim.nodes import fmu as fmu_node
from ema_sim.nodes import maneuver as maneuver_node
from ema_sim.nodes import testenv as testenv_node
from ema_sim.nodes.common import SuiteNode, run_nodes
from ema_sim.nodes.params import Spec, names_list
from ema_sim.nodes.ports import GRAPH_CACHE_S, ClockPublisher, FramePublisher, Ports, TimeFeed, own_time_source
from ema_sim.signals.plans import channel_list

P = ParamSpec("P")
R = TypeVar("R")

NAME = "ema_container"
MERGED = (ct.EMAC_FEEDBACK, ct.SURFACE, ct.BUS)
"""Topics the composed EMAC channels publish: one message per stamp leaves the container."""


class BusyMeter:
    """Time the container's thread spends on each composed node: its polls and in-process callbacks.

    Exclusive of nested calls into other nodes (a callback that publishes runs its subscribers'
    callbacks, which are charged to them). Wall time from ``perf_counter``: a thread-CPU clock costs a
    system call (0.9 µs) here; under SCHED_FIFO, with nothing preempting the thread, the two agree.

    Parameters
    ----------
    enabled : bool
        Account the time (off: :meth:`wrap` gives the callables back as they are, at no cost).
    """

    def __init__(self, enabled: bool = True) -> None:
        self.enabled = enabled
        """Off by default in the container: the accounting costs about 1 µs a call (≈ 30 µs a frame)."""
        self.seconds: dict[str, float] = {}
        self._stack: list[str] = []
        self._mark = 0.0

    def wrap(self, name: str, fn: Callable[P, R]) -> Callable[P, R]:
        """``fn`` with its own time charged to ``name`` (``fn`` itself when the meter is off).

        Parameters
        ----------
        name : str
            The composed node the time is charged to.
        fn : callable
            The node's poll or callback.

        Returns
        -------
        callable
            ``fn``, timed.
        """
        if not self.enabled:
            return fn
        clock = time.perf_counter
        seconds, stack = self.seconds, self._stack
        seconds.setdefault(name, 0.0)

        def timed(*args: P.args, **kwargs: P.kwargs) -> R:
            now = clock()
            if stack:
                seconds[stack[-1]] += now - self._mark
            self._mark = now
            stack.append(name)
            try:
                return fn(*args, **kwargs)
            finally:
                now = clock()
                seconds[stack.pop()] += now - self._mark
                self._mark = now

        return timed


class Outlet:
    """One topic published inside the container: in-process delivery, and DDS once for the outside.

    With several composed publishers (the EMAC channels) the frames of one stamp are merged. A stamp
    is complete when every publisher has given it, and then it and every older stamp go out, oldest
    first (in lockstep every channel gives every stamp, so the grouping is reproducible); a stamp some
    publisher skipped goes out once every publisher has moved past it, or after ``stale_s``.

    Parameters
    ----------
    bus : Bus
        The container's bus.
    topic : str
        The topic (its contract name).
    """

    def __init__(self, bus: Bus, topic: str) -> None:
        self.bus = bus
        self.topic = topic
        self.sources: list[str] = []
        self.dds: FramePublisher | None = None
        self.pending: dict[int, dict[str, JointFrame]] = {}
        self.since: dict[int, float] = {}
        self.latest: dict[str, int] = {}
        self.stale_s = 0.01
        self._outside = (0.0, False)

    def publisher(self, source: str) -> _OutletPublisher:
        """A composed node's publisher on this topic.

        Parameters
        ----------
        source : str
            The composed node's name.

        Returns
        -------
        _OutletPublisher
            Its publisher (``publish(frame)``).
        """
        self.sources.append(source)
        return _OutletPublisher(self, source)

    def outside(self) -> bool:
        """Someone outside the container subscribes (a middleware query, reused for 0.1 s)."""
        now = time.monotonic()
        if now - self._outside[0] > GRAPH_CACHE_S:
            self._outside = (now, self.dds is not None and self.dds.dds.get_subscription_count() > 0)
        return self._outside[1]

    def emit(self, frame: JointFrame) -> None:
        """Deliver one (merged) frame: in-process first (the feedback path to the FMU), then on DDS.

        Parameters
        ----------
        frame : JointFrame
            The frame (all the stamp's channels once merged).
        """
        bus = self.bus
        bus.progress = True
        for callback in bus.subscribers.get(self.topic, ()):
            callback(frame)
        raws = bus.raw_subscribers.get(self.topic)
        outside = self.outside()
        if raws or outside:
            raw = encode(frame)
            for raw_callback in raws or ():
                raw_callback(raw)
            if outside and self.dds is not None:  # outside: someone subscribes to its DDS publisher
                self.dds.dds.publish(raw)

    def put(self, source: str, frame: JointFrame) -> None:
        """A composed publisher's frame: out at once, or once its stamp is complete (merged).

        Parameters
        ----------
        source : str
            The composed node that published it.
        frame : JointFrame
            Its frame.
        """
        n = len(self.sources)
        if n == 1:
            self.emit(frame)
            return
        stamp = frame.stamp_ns
        slot = self.pending.get(stamp)
        if slot is None:
            slot = self.pending[stamp] = {}
            self.since[stamp] = time.monotonic()
        slot[source] = frame
        if stamp > self.latest.get(source, -1):
            self.latest[source] = stamp
        if len(slot) == n:
            self._emit_through(stamp)

    def _emit_through(self, last: int) -> None:
        for stamp in sorted(s for s in self.pending if s <= last):
            slot = self.pending.pop(stamp)
            del self.since[stamp]
            self.emit(_merge(stamp, [slot[s] for s in self.sources if s in slot]))

    def release(self, now: float) -> None:
        """Emit the oldest stamps that every publisher moved past, or that waited ``stale_s``.

        Parameters
        ----------
        now : float
            Monotonic time (s).
        """
        while self.pending:
            stamp = min(self.pending)
            slot = self.pending[stamp]
            moved_on = all(s in slot or self.latest.get(s, -1) > stamp for s in self.sources)
            if not moved_on and now - self.since[stamp] < self.stale_s:
                return
            self._emit_through(stamp)


def _merge(stamp: int, frames: list[JointFrame]) -> JointFrame:
    if len(frames) == 1:
        return frames[0]
    fid = frames[0].frame_id
    if any(f.frame_id != fid for f in frames):
        fid = "emac"  # channel nodes' frames merged: the EMAC box's frame
    out = JointFrame(stamp, [], [], [], [], fid)
    for f in frames:
        out.name.extend(f.name)
        out.position.extend(f.position)
        out.velocity.extend(f.velocity)
        out.effort.extend(f.effort)
    return out


class _OutletPublisher:
    def __init__(self, outlet: Outlet, source: str) -> None:
        self.outlet = outlet
        self.source = source

    def publish(self, frame: JointFrame) -> None:
        self.outlet.put(self.source, frame)


class _ClockOutlet:
    def __init__(self, bus: Bus, dds: ClockPublisher) -> None:
        self.bus = bus
        self.dds = dds
        self._outside = (0.0, False)

    def publish(self, ns: int) -> None:
        now = time.monotonic()
        if now - self._outside[0] > GRAPH_CACHE_S:
            self._outside = (now, self.dds.dds.get_subscription_count() > 0)
        if self._outside[1]:
            self.dds.publish(ns)  # the outside first: an FMU in another process starts its frame meanwhile
        self.bus.progress = True
        for callback in self.bus.clock_subscribers:
            callback(ns)


class Bus:
    """The container's in-process message passing (see the module docstring).

    Parameters
    ----------
    host : rclpy.node.Node
        The container's own node (its DDS endpoints carry what goes out and comes in).
    meter : BusyMeter
        Accounts the thread's time to each composed node.
    """

    def __init__(self, host: Node, meter: BusyMeter) -> None:
        self.host = host
        self.meter = meter
        self.subscribers: dict[str, list[Callable[[JointFrame], None]]] = {}
        self.raw_subscribers: dict[str, list[Callable[[bytes], None]]] = {}
        self.bad: dict[str, list[Callable[[str], None]]] = {}
        self.outlets: dict[str, Outlet] = {}
        self.clock_subscribers: list[Callable[[int], None]] = []
        self.time_feed = TimeFeed()
        """The ROS clocks of the composed nodes under ``use_sim_time``, set at each ``/clock`` frame."""
        self.clock_outlet: _ClockOutlet | None = None
        self.progress = False
        """Set whenever something was delivered in-process (the container polls again before it waits)."""
        self._host_ports = Ports(host)

    def ports(self, node: Node) -> ComposedPorts:
        """Ports for a node composed in this container.

        Parameters
        ----------
        node : rclpy.node.Node
            The composed node.

        Returns
        -------
        ComposedPorts
            Its ports on this bus.
        """
        return ComposedPorts(self, node)

    def wire(self, lockstep: bool) -> None:
        """After every node is composed: DDS for the outside (publishers, and inputs nobody inside makes).

        Parameters
        ----------
        lockstep : bool
            The suite runs on ``/clock`` (merged stamps then wait for every channel longer).
        """
        for topic, outlet in self.outlets.items():
            if outlet.dds is None:  # the merged EMAC topics: the container's node publishes them
                outlet.dds = FramePublisher(self.host, topic, qos(ct.FRAME_QOS))
            outlet.stale_s = 5.0 if lockstep else 0.01
        for topic in {*self.subscribers, *self.raw_subscribers}:
            if topic not in self.outlets:
                self._host_ports.raw_subscription(topic, self._inlet(topic))
        if self.clock_subscribers and self.clock_outlet is None:
            self._host_ports.clock_subscription(self._tick)

    def _inlet(self, topic: str) -> Callable[[bytes], None]:
        """A topic from outside: its bytes to composed recorders, its frames to composed nodes."""
        frames = self.subscribers.get(topic, [])
        raws = self.raw_subscribers.get(topic, [])
        bad = self.bad.get(topic, [])

        def take(raw: bytes) -> None:
            self.progress = True
            for callback in raws:
                callback(raw)
            if not frames:
                return
            try:
                frame = decode(raw)
            except ValueError as exc:
                for report in bad:
                    report(f"{topic}: {exc}")
                return
            for frame_callback in frames:
                frame_callback(frame)

        return take

    def _tick(self, ns: int) -> None:
        self.progress = True
        for callback in self.clock_subscribers:
            callback(ns)

    def release(self) -> None:
        """Emit merged frames that waited too long for a composed publisher (see :class:`Outlet`)."""
        now = time.monotonic()
        for outlet in self.outlets.values():
            if outlet.pending:
                outlet.release(now)


class ComposedPorts:
    """A composed node's view of the bus (the interface of :class:`~ema_sim.nodes.ports.Ports`).

    Parameters
    ----------
    bus : Bus
        The container's bus.
    node : rclpy.node.Node
        The composed node.
    """

    composed = True

    def __init__(self, bus: Bus, node: Node) -> None:
        self.bus = bus
        self.node = node
        self.name = node.get_name()

    def frame_publisher(self, topic: str) -> _OutletPublisher:
        """In-process delivery and, for the outside, one DDS publisher per topic.

        Parameters
        ----------
        topic : str
            A per-frame topic (contract name).

        Returns
        -------
        _OutletPublisher
            The node's publisher on it (``publish(frame)``).
        """
        outlet = self.bus.outlets.get(topic)
        if outlet is None:
            outlet = self.bus.outlets[topic] = Outlet(self.bus, topic)
        if topic not in MERGED:  # a single composed publisher (the test environment): its own DDS publisher
            outlet.dds = FramePublisher(self.node, topic, qos(ct.FRAME_QOS))
        return outlet.publisher(self.name)

    def frame_subscription(self, topic: str, callback: Callable[[JointFrame], None],
                           on_bad: Callable[[str], None], *, at_frame: bool = False) -> None:
        """Frames of a topic, from a composed publisher or (taken once per process) from outside.

        Parameters
        ----------
        topic : str
            A per-frame topic (contract name).
        callback : callable
            Called with each :class:`~ema_msgs_py.cdr.JointFrame`.
        on_bad : callable
            Called with the error of a message from outside that does not decode.
        at_frame : bool
            Unused: a frame handed over in-process costs no wake-up (:meth:`take_at_frame`).
        """
        del at_frame
        self.bus.subscribers.setdefault(topic, []).append(self.bus.meter.wrap(self.name, callback))
        self.bus.bad.setdefault(topic, []).append(on_bad)

    def raw_subscription(self, topic: str, callback: Callable[[bytes], None], *, at_frame: bool = False) -> None:
        """A per-frame topic as CDR bytes (a composed recorder).

        Frames from inside are serialized once; messages from outside arrive as they were sent.

        Parameters
        ----------
        topic : str
            A per-frame topic (contract name).
        callback : callable
            Called with each message's CDR bytes.
        at_frame : bool
            Unused, as for :meth:`frame_subscription`.
        """
        del at_frame
        self.bus.raw_subscribers.setdefault(topic, []).append(self.bus.meter.wrap(self.name, callback))

    received_ns = None
    """As :attr:`Ports.received_ns <ema_sim.nodes.ports.Ports.received_ns>`: nothing is taken at the frame here."""

    def take_at_frame(self) -> int:
        """Nothing waits: the bus hands every frame over as it comes (the process's one wake-up covers it).

        Returns
        -------
        int
            0.
        """
        return 0

    def clock_publisher(self) -> _ClockOutlet:
        """The composed clock: in-process to the composed nodes, on DDS for the outside."""
        self.bus.clock_outlet = _ClockOutlet(self.bus, ClockPublisher(self.node))
        return self.bus.clock_outlet

    def clock_subscription(self, callback: Callable[[int], None]) -> None:
        """Lockstep ``/clock``; it also drives the node's ROS clock.

        Parameters
        ----------
        callback : callable
            Called with each ``/clock`` time (ns).
        """
        self.bus.time_feed.clocks.append(own_time_source(self.node))
        self.bus.clock_subscribers.append(self.bus.meter.wrap(self.name, callback))

    def publishers(self, topic: str) -> int:
        """Publishers of a topic: the composed ones, and the graph's when it comes from outside.

        Parameters
        ----------
        topic : str
            The topic (contract name).

        Returns
        -------
        int
            How many publish it.
        """
        outlet = self.bus.outlets.get(topic)
        if outlet is not None:
            return len(outlet.sources)
        return self.bus._host_ports.publishers(topic)

    def endpoint_nodes(self) -> list[Node]:
        """This node's endpoints and the container's (which carry this node's inputs from outside)."""
        return [self.node, self.bus.host]


class HostNode(SuiteNode):
    """The container's own node: DDS endpoints shared by the composed nodes, and the process's summary.

    Parameters
    ----------
    args : argparse.Namespace or None
        The flags given on the container's command line (parameter overrides, and the nodes to compose).
    """

    def __init__(self, args: argparse.Namespace | None = None) -> None:
        super().__init__(NAME, args)
        self.auto_ready = False
        self.ports = Ports(self)
        self.meter: BusyMeter | None = None
        own = self.params.declare([
            Spec("nodes", [], "the nodes to compose (emac, emac_<channel>, testenv, maneuver, fmu, simclock); "
                 "empty: from channels and emac_box", kind=ParameterType.PARAMETER_STRING_ARRAY),
            Spec("channels", ["all"], "EMAC channels to compose when nodes is empty",
                 kind=ParameterType.PARAMETER_STRING_ARRAY),
            Spec("emac_box", False, "one EMAC node hosting every channel (an EMAC box) instead of one node per "
                 "channel, when nodes is empty"),
            Spec("measure_busy", False, "account the thread's time to each composed node (summary busy_s; costs "
                 "≈ 1 µs a call)"),
        ], NAME)
        self.measure_busy = bool(own["measure_busy"])
        channels = channel_list(own["channels"] or ["all"])
        self.emac_channels = channels
        self.from_channels = not own["nodes"]
        """Composed from ``channels`` and ``emac_box`` (each EMAC node is told its channels)."""
        self.composed = own["nodes"] or ["testenv", *(["emac"] if own["emac_box"] else [f"emac_{c}" for c in channels])]
        unknown = [n for n in self.composed if _node_class(n) is None]
        if unknown:
            raise UnknownNameError("node to compose", unknown[0], ["emac", "emac_<channel>", *CLASSES])

    def summary(self) -> JsonObject:
        """The process's CPU, and the thread's time on each composed node (the rest: DDS, executor, bus)."""
        composed = dict(self.meter.seconds) if self.meter is not None else {}
        return {"composed_busy_s": {k: round(v, 3) for k, v in composed.items()}}


CLASSES: dict[str, Callable[..., SuiteNode]] = {
    "testenv": testenv_node.TestEnvNode, "maneuver": maneuver_node.ManeuverNode, "fmu": fmu_node.FmuNode,
    "simclock": clock_node.ClockNode,
}
"""Composed nodes by name (``emac`` and ``emac_<channel>`` are EMAC nodes)."""
RANK = {"simclock": 0, "maneuver": 1, "fmu": 1, "testenv": 2}
"""Polled in the order a frame flows (clock, FMU, environment, EMACs): one round does a whole frame."""


def _node_class(name: str) -> Callable[..., SuiteNode] | None:
    if name == "emac" or name.startswith("emac_"):
        return emac_node.EmacNode
    return CLASSES.get(name)


def compose(args: argparse.Namespace) -> tuple[list[SuiteNode], Bus]:
    """The container's node, then the composed ones, each reading its own section of the parameter file.

    Parameters
    ----------
    args : argparse.Namespace
        The container's command-line flags (``--peers`` is given to every composed node).

    Returns
    -------
    list of SuiteNode
        The container's node first, then the composed nodes.
    Bus
        Their bus, wired.
    """
    host = HostNode(args)
    meter = BusyMeter(enabled=host.measure_busy)
    bus = Bus(host, meter)
    nodes: list[SuiteNode] = [host]
    given = {"peers": args.peers} if getattr(args, "peers", None) else {}  # --peers: every composed node's
    for name in host.composed:
        cls = _node_class(name)
        assert cls is not None, name  # HostNode has checked every name it composes
        flags = dict(given)
        if host.from_channels and cls is emac_node.EmacNode:
            flags["channels"] = host.emac_channels if name == "emac" else [name[len("emac_"):]]
        nodes.append(cls(argparse.Namespace(**flags), ports=bus.ports, name=name))
    lockstep = any(getattr(n, "lockstep", False) for n in nodes)
    for node in nodes:
        if isinstance(node, clock_node.ClockNode) and len(nodes) > 2:
            # The clock's last frame does not end the run: its composed nodes' last frames (fed back in the same
            # round) still have to reach a driver outside, which may lag; the process ends with its driver.
            node.ends_process = False
    for node in nodes:  # under use_sim_time: every composed node's ROS clock follows the in-process clock
        bus.time_feed.clocks.append(own_time_source(node))
    bus.time_feed.clocks = [c for c in bus.time_feed.clocks if c is not None]
    if bus.time_feed.clocks:
        bus.clock_subscribers.insert(0, bus.time_feed)
    bus.wire(lockstep)
    for node in nodes[1:]:
        node.poll = meter.wrap(node.get_name(), node.poll)  # type: ignore[method-assign]
    host.meter = meter
    nodes[1:] = sorted(nodes[1:], key=lambda n: RANK.get(n.get_name(), 3))
    return nodes, bus


def parser() -> argparse.ArgumentParser:
    """Command-line flags: shorthands for the container's parameters (the composed nodes read the parameter file)."""
    p = argparse.ArgumentParser(prog="ema_container", argument_default=argparse.SUPPRESS,
                                description="EMAC channel nodes, test environment, clock and driver in one process.")
    p.add_argument("--nodes", action="append", type=names_list, help="parameter nodes: the nodes to compose")
    p.add_argument("--channels", action="append", type=names_list,
                   help="parameter channels: EMAC channels to compose (default all)")
    p.add_argument("--emac-box", dest="emac_box", action="store_true",
                   help="parameter emac_box: one EMAC node hosting every channel instead of one node per channel")
    p.add_argument("--measure-busy", dest="measure_busy", action="store_true",
                   help="parameter measure_busy: account the thread's time to each composed node")
    return p


def main(argv: Sequence[str] | None = None) -> int:
    """Console script ``ema_container``.

    Parameters
    ----------
    argv : sequence of str or None
        The command line, ROS arguments included (None: ``sys.argv[1:]``).

    Returns
    -------
    int
        The process's exit status.
    """
    return run_nodes(compose, parser(), argv)


if __name__ == "__main__":
    raise SystemExit(main())
