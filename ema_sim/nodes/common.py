"""What every node shares: start-up, the executor loop, signals, throttled logs, readiness, summaries.

The executor is rclpy's ``EventsExecutor`` driven by ``spin_once`` calls from our own loop, which
also keeps every deadline itself (no rclpy timers): measured here, taking a message costs 12 µs raw
and 38 µs deserialized with it against 200–290 µs with the ``SingleThreadedExecutor``, and its
``spin()`` does not fire timers in this wheel (see docs/nodes.md, "Executor").
"""

from __future__ import annotations

import argparse
import gc
import json
import math
import os
import signal
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from typing import TYPE_CHECKING, Protocol, TypedDict, Unpack

import numpy as np
import rclpy
from rcl_interfaces.msg import ParameterType
from rclpy.experimental.events_executor import EventsExecutor
from rclpy.impl.rcutils_logger import RcutilsLogger
from rclpy.logging import get_logger
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions
from rclpy.subscription import Subscription
from rclpy.utilities import ok, remove_ros_args
from std_msgs.msg import String

from ema_msgs_py import contract as ct
from ema_msgs_py.ros import qos
from ema_sim.errors import EmaError
from ema_sim.jsontypes import JsonObject
from ema_sim.nodes import lifetime, realtime
from ema_sim.nodes.names import NameClaim
from ema_sim.nodes.params import Declared, Spec, cli_overrides, names_list

if TYPE_CHECKING:
    from rclpy.context import Context
    from rclpy.executors import Executor

SUMMARY_PREFIX = "EMA_SUMMARY "
"""Each node prints one line with this prefix and a JSON summary when it stops."""
MAX_SPIN_S = 0.05
"""Longest wait in one spin, so a stop request is seen within it."""
ROSOUT_LOOK_S = 4.0
"""A node stopping on a fatal error looks this long for ``/rosout`` listeners (:meth:`SuiteNode.fatal`): DDS
discovery on a loaded two-core machine took longer than 1.5 s (a test's listener missed the line)."""
ROSOUT_GRACE_S = 1.0
"""... and stays up this long once one is there, so the line reaches it (the match precedes the delivery); so
does every stopping node's run summary when a listener is there."""
_process_argv: list[str] = []
"""The process's command line, ROS arguments included, as :func:`run_nodes` gave it to ``rclpy.init``."""


def process_age_s() -> float:
    """Seconds since this process started (the kernel's start time, so the interpreter's start-up counts too).

    Returns
    -------
    float
        The age, s (NaN where ``/proc`` does not say).
    """
    try:
        with open("/proc/self/stat", encoding="ascii") as f:
            start_ticks = int(f.read().rsplit(")", 1)[1].split()[19])  # field 22, starttime, in clock ticks
        return time.clock_gettime(time.CLOCK_BOOTTIME) - start_ticks / os.sysconf("SC_CLK_TCK")
    except (OSError, ValueError, IndexError, AttributeError):
        return math.nan


class NodeOptions(TypedDict, total=False):
    """rclpy's node options a suite node passes on (its parameter overrides are its own, from its flags)."""

    context: Context | None
    cli_args: list[str] | None
    namespace: str | None
    use_global_arguments: bool
    enable_rosout: bool
    start_parameter_services: bool
    allow_undeclared_parameters: bool
    automatically_declare_parameters_from_overrides: bool
    enable_logger_service: bool


def command_line(options: NodeOptions) -> list[str]:
    """The command line a node's ROS arguments come from: its process's, then its own ``cli_args``.

    Parameters
    ----------
    options : dict
        The node's rclpy options (``cli_args``, ``use_global_arguments``).

    Returns
    -------
    list of str
        The arguments (the process's are left out when the node does not use them).
    """
    own = list(options.get("cli_args") or [])
    return own if options.get("use_global_arguments") is False else [*_process_argv, *own]


def make_executor(context: Context | None = None) -> Executor:
    """The executor every node uses (see the module docstring for the measurement behind it).

    Parameters
    ----------
    context : rclpy.context.Context or None
        Its context (None: the default one).

    Returns
    -------
    EventsExecutor
        rclpy's events executor.
    """
    return EventsExecutor(context=context)


class SuiteNode(Node):
    """Base of the suite's nodes: ``poll`` does the deadline work, ``close`` the last words.

    Every node declares its parameters (:mod:`ema_sim.nodes.params`) in its constructor, ``peers`` here.

    Parameters
    ----------
    name : str
        The node's name (a ``-r __node:=`` remapping renames it).
    args : argparse.Namespace or None
        The flags given on the node's command line (parameter overrides, :func:`params.cli_overrides`).
    exclude : tuple of str
        Flags of ``args`` the node resolves itself (not parameter overrides).
    **kwargs : NodeOptions
        rclpy node options (``context``, ``cli_args``, ``namespace``...).
    """

    def __init__(self, name: str, args: argparse.Namespace | None = None, *, exclude: tuple[str, ...] = (),
                 **kwargs: Unpack[NodeOptions]) -> None:
        """The node, its ``peers`` declared (see the class docstring for the arguments)."""
        overrides = cli_overrides(args, exclude) if args is not None else []
        self.at_frame: set[Subscription] = set()
        """Subscriptions the node takes at its frame (:meth:`~ema_sim.nodes.ports.Ports.take_at_frame`), not the
        executor on arrival: inputs a frame reads but need not wake the process for."""
        super().__init__(name, parameter_overrides=overrides, **kwargs)
        self.params = Declared(self)
        self.done = False
        self.ends_process = True
        """Its being done ends its process (not a composed clock's: :func:`ema_sim.nodes.container.compose`)."""
        self.peers: set[str] = set(self.params.declare([Spec(
            "peers", [], "suite nodes to see in the graph (and be matched with) before calling itself ready",
            kind=ParameterType.PARAMETER_STRING_ARRAY)], "peers")["peers"]) - {self.get_name()}
        """Suite nodes that must be in the graph before this one calls itself ready: the others, by the name this
        node has in the graph (a process's ``-r __node:=`` renames the ``name`` its class defaults to)."""
        self.auto_ready = True
        """Announce readiness as soon as matched (the maneuver node announces itself when it starts)."""
        self._last_log: dict[str, float] = {}
        self._ready_pub = self.create_publisher(String, ct.endpoint(ct.READY), qos(ct.LATCHED_QOS))
        self.name_claim = NameClaim(self)
        """Its claim on its name: an older node of the same name stops this one (:mod:`ema_sim.nodes.names`)."""
        self._ready_sent = False
        self._matched_since: float | None = None
        self.running_cpu_s: float | None = None
        """Process CPU when this node's first frame came (start-up excluded from the run's CPU)."""

    @property
    def subscriptions(self) -> Iterator[Subscription]:
        """The subscriptions the executor dispatches: every one but those taken at the frame (:attr:`at_frame`)."""
        return (s for s in self.every_subscription() if s not in self.at_frame)

    def every_subscription(self) -> list[Subscription]:
        """Every subscription of the node, those taken at the frame included.

        Returns
        -------
        list of rclpy.subscription.Subscription
            The subscriptions.
        """
        return list(Node.subscriptions.fget(self))  # type: ignore[attr-defined]  # rclpy's property, by name

    def destroy_subscription(self, subscription: Subscription) -> bool:
        """Destroy a subscription (:meth:`rclpy.node.Node.destroy_subscription`), taken at the frame or not.

        Parameters
        ----------
        subscription : rclpy.subscription.Subscription
            The subscription.

        Returns
        -------
        bool
            True when it was the node's.
        """
        self.at_frame.discard(subscription)
        return bool(Node.destroy_subscription(self, subscription))

    def get_logger(self) -> RcutilsLogger:
        """The node's logger (:meth:`rclpy.node.Node.get_logger`, which rclpy leaves unannotated, typed).

        Returns
        -------
        rclpy.impl.rcutils_logger.RcutilsLogger
            The logger rclpy gave the node.
        """
        logger: RcutilsLogger = Node.get_logger(self)  # by name, not super(): mypy's untyped_calls_exclude sees it
        return logger

    def destroy_node(self) -> None:
        """Destroy the node (:meth:`rclpy.node.Node.destroy_node`, which rclpy leaves unannotated, typed)."""
        Node.destroy_node(self)  # by name, as get_logger: no class between SuiteNode and Node defines it

    def mark_running(self) -> None:
        """The first frame of the test: note the process CPU so far."""
        if self.running_cpu_s is None:
            self.running_cpu_s = time.process_time()

    @property
    def sim_time(self) -> bool:
        """True under ``use_sim_time`` (lockstep)."""
        return bool(self.get_parameter("use_sim_time").value)

    def poll(self) -> float:
        """Work that is due; returns seconds until something is next due."""
        return MAX_SPIN_S

    def close(self) -> None:
        """Called once when the node stops (signal, end of test or error)."""

    def summary(self) -> JsonObject:
        """Printed as one JSON line when the node stops."""
        return {}

    def announce_ready(self) -> None:
        """Tell the clock and the maneuver node this node is up (latched ``/ema/ready``)."""
        self._ready_pub.publish(String(data=self.get_name()))
        self._ready_sent = True

    def matched(self) -> bool:
        """Every peer is in the graph and every endpoint of ours is matched with all the graph has.

        Messages on a reliable, volatile topic reach only the readers a writer has matched when it
        publishes, so a node is ready only when its endpoints are matched, held for 0.2 s.
        """
        now = time.monotonic()
        ok = self.peers <= set(self.get_node_names())
        ports = getattr(self, "ports", None)
        for node in ports.endpoint_nodes() if ports is not None else [self]:
            ok = ok and all(p.get_subscription_count() >= self.count_subscribers(p.topic_name)
                            for p in node.publishers) \
                and all(s.get_publisher_count() >= self.count_publishers(s.topic_name) for s in _every(node))
        if not ok:
            self._matched_since = None
            return False
        if self._matched_since is None:
            self._matched_since = now
        return now - self._matched_since >= 0.2

    def check_ready(self) -> None:
        """Announce readiness once matched (called by the loop until it is sent)."""
        if self.auto_ready and not self._ready_sent and self.matched():
            self.announce_ready()

    def fatal(self, message: str) -> None:
        """A fatal error (the node is about to stop), through the node's logger: console, log file and ``/rosout``.

        ``/rosout`` is reliable and transient-local, so a listener that matches the node's ``/rosout`` writer
        before the node is destroyed gets the line: in a node's own process, when one is in the graph (a look of
        at most :data:`ROSOUT_LOOK_S`, discovery under load), the node stays up :data:`ROSOUT_GRACE_S` for it.

        Parameters
        ----------
        message : str
            The error, one line.
        """
        self.get_logger().fatal(message)
        self.last_words_out(ROSOUT_LOOK_S)

    def last_words_out(self, look_s: float) -> None:
        """Stay up :data:`ROSOUT_GRACE_S` when a ``/rosout`` listener is in the graph (looked for ``look_s``).

        A line logged just before the node is destroyed is otherwise lost now and then: a reliable writer that
        is gone cannot resend what a loaded listener missed (2 of 39 stops under load lost it, 0 of 30 with a
        grace). Only in a node's own process: composed in a caller's (a test), it goes on, the node with it.

        Parameters
        ----------
        look_s : float
            How long to look for a listener first, s (0: only one already there).
        """
        if not _process_argv:
            return
        end = time.monotonic() + look_s
        while True:
            if self.count_subscribers("/rosout") > 0:
                time.sleep(ROSOUT_GRACE_S)
                return
            if time.monotonic() >= end:
                return
            time.sleep(0.02)

    def throttled(self, key: str, message: str, *, period_s: float = 1.0, level: str = "warning") -> None:
        """Log at most once per ``period_s`` (wall time) per key, at ``level``.

        Parameters
        ----------
        key : str
            What is throttled together (one kind of message).
        message : str
            The line.
        period_s : float
            At most one line per key this often, s.
        level : str
            ``info``, ``warning`` or ``error``.
        """
        now = time.monotonic()
        if now - self._last_log.get(key, -math.inf) >= period_s:
            self._last_log[key] = now
            # one call site per severity: rclpy's logger refuses a call site whose severity changes
            logger = self.get_logger()
            if level == "info":
                logger.info(message)
            elif level == "error":
                logger.error(message)
            else:
                logger.warning(message)


def _every(node: Node) -> list[Subscription]:
    """Every subscription of a node (a suite node's taken at the frame included)."""
    return node.every_subscription() if isinstance(node, SuiteNode) else list(node.subscriptions)


def _join_lists(args: argparse.Namespace) -> None:
    """Repeated list options (``--channel a --channel b,c``) as one list each."""
    for key, value in vars(args).items():
        if isinstance(value, list) and value and all(isinstance(v, list) for v in value):
            setattr(args, key, [item for part in value for item in part])


def ros_args(argv: Sequence[str] | None) -> list[str]:
    """The full argv (ROS arguments included) for ``rclpy.init``.

    Parameters
    ----------
    argv : sequence of str or None
        The arguments after the program's name (None: the process's).

    Returns
    -------
    list of str
        The program's name and the arguments.
    """
    return list(sys.argv if argv is None else ["node", *argv])


def run(factory: Callable[[argparse.Namespace], SuiteNode], parser: argparse.ArgumentParser,
        argv: Sequence[str] | None = None) -> int:
    """One node in its process: parse arguments, start rclpy, loop until stopped, close cleanly.

    SIGINT and SIGTERM end the loop; the node's ``close`` then runs (a recorder closes its bag, so every
    message it received is readable). A user error is one line on stderr and status 2.

    Parameters
    ----------
    factory : callable
        Makes the node from the parsed flags.
    parser : argparse.ArgumentParser
        The node's flags.
    argv : sequence of str or None
        The arguments (None: the process's).

    Returns
    -------
    int
        The exit status.
    """
    return run_nodes(lambda args: ([factory(args)], None), parser, argv)


class Handover(Protocol):
    """What the loop needs of a container's bus (:class:`ema_sim.nodes.container.Bus`)."""

    progress: bool
    """Whether a composed node handed something over in-process this round."""

    def release(self) -> None:
        """Emit merged frames that waited too long for a composed publisher."""


MAX_ROUNDS = 50
"""Polling rounds of composed nodes between two looks at the middleware (in-process work first)."""


def run_nodes(factory: Callable[[argparse.Namespace], tuple[list[SuiteNode], Handover | None]],
              parser: argparse.ArgumentParser, argv: Sequence[str] | None = None) -> int:
    """Several nodes in one process (:mod:`ema_sim.nodes.container`), or one: the loop of :func:`run`.

    ``factory`` returns the nodes and the container's bus (None for a lone node). The nodes are polled
    in order, again while something was handed over in-process, then the executor waits for the next
    message from outside, at most until the earliest deadline a node asked for.

    Parameters
    ----------
    factory : callable
        Makes the nodes and the bus from the parsed flags.
    parser : argparse.ArgumentParser
        The process's flags.
    argv : sequence of str or None
        The arguments (None: the process's).

    Returns
    -------
    int
        The exit status (0; 2 after a user error; 130 after a keyboard interrupt).
    """
    full = ros_args(argv)
    _process_argv[:] = full
    parser.add_argument("--peers", action="append", type=names_list, default=argparse.SUPPRESS,
                        help="suite node names to see in the graph (and be matched with) before calling ready")
    parser.add_argument("--rt-priority", type=int, default=0,
                        help="real time: SCHED_FIFO at this priority, memory locked, CPUs kept out of idle halts "
                             "(0: off; see ema_sim.nodes.realtime)")
    args = parser.parse_args(remove_ros_args(full)[1:])
    _join_lists(args)
    lifetime.follow_parent()  # started by `ema launch`: end with it, however it ends
    stop: dict[str, int | None] = {"signal": None}
    rt = realtime.apply(args.__dict__.pop("rt_priority"))  # before rclpy starts its threads: they inherit it

    def on_signal(signum: int, frame: object) -> None:  # noqa: ARG001
        stop["signal"] = signum

    rclpy.init(args=full, signal_handler_options=SignalHandlerOptions.NO)
    signal.signal(signal.SIGINT, on_signal)
    signal.signal(signal.SIGTERM, on_signal)
    nodes: list[SuiteNode] = []
    bus: Handover | None = None
    status = 0
    try:
        nodes, bus = factory(args)
        executor = make_executor()
        for node in nodes:
            executor.add_node(node)
        # Per-frame objects die by reference counting; keep the collector's full passes (whose pauses
        # grow with the heap, e.g. a long recording's index) out of the frame loop.
        gc.collect()
        gc.freeze()
        gc.set_threshold(50_000, 50, 1_000)
        _loop(nodes, bus, executor, stop)
    except EmaError as exc:
        print(f"{parser.prog}: error: {exc}", file=sys.stderr)
        status = 2
        if nodes:  # stopped while running: through its first node's logger
            nodes[0].fatal(str(exc))
        elif not getattr(exc, "logged", False):  # no node to speak for it: the process's logger (console, log file)
            get_logger(parser.prog).fatal(str(exc))
    except KeyboardInterrupt:
        status = 130
    finally:
        _finish(nodes, bus, rt)
    return status


def _loop(nodes: list[SuiteNode], bus: Handover | None, executor: Executor, stop: dict[str, int | None]) -> None:
    if bus is None and len(nodes) == 1:
        _loop_one(nodes[0], executor, stop)
        return

    def finished() -> bool:
        return any(n.done and n.ends_process for n in nodes)

    while stop["signal"] is None and not finished():
        for node in nodes:
            if node.name_claim.taken_by is not None:
                raise EmaError(node.name_claim.refusal() or "")
            if not node._ready_sent:
                node.check_ready()
        timeout = MAX_SPIN_S
        for _ in range(MAX_ROUNDS):
            if bus is not None:
                bus.progress = False
            timeout = min(node.poll() for node in nodes)
            if bus is None or not bus.progress:
                break
        if bus is not None:
            bus.release()
        if finished():
            break
        executor.spin_once(timeout_sec=min(max(timeout, 0.0), MAX_SPIN_S))


def _loop_one(node: SuiteNode, executor: Executor, stop: dict[str, int | None]) -> None:
    """:func:`_loop` for a node alone in its process (the ``processes`` layout): the same steps, fewer calls.

    The loop runs once per message taken (a channel node of the ``processes`` layout: 2 to 7 a frame, its
    driver 21), so its own overhead counts: no closures or generators, the bound methods looked up once.
    """
    poll, check_ready, spin_once, claim = node.poll, node.check_ready, executor.spin_once, node.name_claim
    ports = getattr(node, "ports", None)
    if getattr(ports, "frames_per_message", 1) > 1:  # batched: a turn's frames go out as it ends
        _loop_batched(node, executor, stop, ports.flush)  # type: ignore[union-attr]  # a Ports: it batches
        return
    while stop["signal"] is None and not (node.done and node.ends_process):
        if claim.taken_by is not None:  # an older node has this name: stop with one error naming it
            raise EmaError(claim.refusal() or "")
        if not node._ready_sent:
            check_ready()
        timeout = poll()
        if node.done and node.ends_process:
            break
        spin_once(timeout_sec=MAX_SPIN_S if timeout > MAX_SPIN_S else (timeout if timeout > 0.0 else 0.0))


def _loop_batched(node: SuiteNode, executor: Executor, stop: dict[str, int | None], flush: Callable[[], None]) -> None:
    """:func:`_loop_one` for a node sending several frames a message.

    What a poll or a callback published goes out when it returns (:meth:`~ema_sim.nodes.ports.Ports.flush`).
    """
    while stop["signal"] is None and not (node.done and node.ends_process):
        if node.name_claim.taken_by is not None:
            raise EmaError(node.name_claim.refusal() or "")
        if not node._ready_sent:
            node.check_ready()
        timeout = node.poll()
        flush()
        if node.done and node.ends_process:
            break
        executor.spin_once(timeout_sec=min(max(timeout, 0.0), MAX_SPIN_S))
        flush()


def _finish(nodes: list[SuiteNode], bus: object, rt: realtime.Setup) -> None:
    """Each node's last words and its summary line.

    ``cpu_s``: the process's CPU; ``cpu_run_s``: since the first frame of the test (start-up left out);
    a composed node's ``busy_s``: the container thread's time on its behalf (see the container);
    ``realtime``: what the process's real-time set-up did, when one was asked for.
    """
    busy = getattr(getattr(bus, "meter", None), "seconds", {})
    marks = [n.running_cpu_s for n in nodes if n.running_cpu_s is not None]
    try:
        for node in nodes:
            node.close()
            name = node.get_name()
            cpu = time.process_time()
            usage: JsonObject = {"cpu_s": round(cpu, 3)}
            if marks:
                usage["cpu_run_s"] = round(cpu - min(marks), 3)
            if name in busy:
                usage = {"busy_s": round(busy[name], 3)}
            if rt.priority or rt.notes:
                usage["realtime"] = rt.summary()
            text = json.dumps({"node": name, **usage, **node.summary()})
            print(SUMMARY_PREFIX + text, flush=True)
            node.get_logger().info(f"run summary: {text}")  # console, log file and /rosout too
        if nodes:
            nodes[0].last_words_out(0.0)
    finally:
        for node in nodes:
            node.destroy_node()
    if ok():
        rclpy.shutdown()


class DurationHistogram:
    """Durations in 10 µs bins up to 1 s (the last bin takes the rest), for a node's percentiles.

    Fixed memory however long a node runs, and nothing allocated per sample: a list growing 200 times a
    second is a leak over hours and stalls a frame whenever it is reallocated.

    Parameters
    ----------
    top_s : float
        The longest duration binned apart, s.
    """

    BIN_S = 1e-5

    def __init__(self, top_s: float = 1.0) -> None:
        self.counts = np.zeros(round(top_s / self.BIN_S) + 1, dtype=np.int64)
        self.n = 0
        self.max_s = 0.0

    def add(self, seconds: float) -> None:
        """One duration.

        Parameters
        ----------
        seconds : float
            The duration, s.
        """
        i = min(max(int(seconds / self.BIN_S), 0), len(self.counts) - 1)
        self.counts[i] += 1
        self.n += 1
        self.max_s = max(self.max_s, seconds)

    def percentile_ms(self, q: float) -> float:
        """A percentile, ms, to the upper edge of its bin (the maximum itself for q = 100; NaN when empty).

        Parameters
        ----------
        q : float
            The percentile, 0 to 100.

        Returns
        -------
        float
            The duration, ms.
        """
        if self.n == 0:
            return math.nan
        if q >= 100.0:
            return self.max_s * 1e3
        rank = min(self.n, max(1, math.ceil(q / 100.0 * self.n)))
        i = int(np.searchsorted(np.cumsum(self.counts), rank))
        return min((i + 1) * self.BIN_S, self.max_s) * 1e3


def percentile_ms(values: Sequence[float], q: float) -> float:
    """A percentile of seconds, in ms (NaN when empty).

    Parameters
    ----------
    values : sequence of float
        Durations, s.
    q : float
        The percentile, 0 to 100.

    Returns
    -------
    float
        The duration, ms.
    """
    if not values:
        return math.nan
    ordered = sorted(values)
    k = min(len(ordered) - 1, max(0, math.ceil(q / 100.0 * len(ordered)) - 1))
    return ordered[k] * 1e3
