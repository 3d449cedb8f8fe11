"""One node per name: each suite node claims its full name on ``/ema/nodes``; the younger of two refuses to run.

ROS 2 lets two nodes share a name, and the graph then merges them silently (a left-over
``emac_right_rudder`` joins the next run: its feedback doubled in the bag, listed twice on ``/ema/ready``).
Each suite node publishes one *claim* at start-up, its full name, pid, host and start time, on
``/ema/nodes`` (reliable, transient local), and reads the others'. A node that receives a claim of its own
name from another process, made before its own, refuses to run: the node loop stops it with one error
naming the other (:func:`ema_sim.nodes.common.run_nodes`, exit status 2); the older node logs that a second
one tried and goes on.

Why a topic and not the graph alone: a killed process stays in the graph of the nodes that knew it until its
DDS lease expires (measured here: 20 s after ``kill -9``), which would stop a restarted node for that long;
transient-local data, by contrast, is delivered by its writer itself, so only a live node's claim ever
arrives. A node is ready only once matched with every writer in the graph (the claim subscription among
them, :meth:`~ema_sim.nodes.common.SuiteNode.matched`), so a node that meets an older one of its name
refuses before it calls itself ready.

:func:`running_claims` looks from outside, before a run starts (``ema launch``): which of the run's names have
a live claim on the domain (those nodes would make the run's own refuse), and which are in the graph
without one (a node that died within its lease, or a node that is not the suite's: warned about, not refused).
"""

from __future__ import annotations

import contextlib
import json
import os
import socket
import time
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from typing import TypedDict

import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions
from std_msgs.msg import String

from ema_msgs_py import contract as ct
from ema_msgs_py.ros import qos
from ema_sim.errors import EmaError


class Claim(TypedDict):
    """What a node publishes on ``/ema/nodes``: its full name, pid, host and start time (ns since the epoch)."""

    node: str
    pid: int
    host: str
    since_ns: int


def parse_claim(text: str) -> Claim | None:
    """A claim as published (JSON), or None when the text is no claim.

    Parameters
    ----------
    text : str
        The message's text.
    """
    try:
        doc = json.loads(text)
        if not isinstance(doc, dict):
            return None
        return {"node": str(doc["node"]), "pid": int(doc["pid"]), "host": str(doc["host"]),
                "since_ns": int(doc["since_ns"])}
    except (ValueError, KeyError, TypeError):
        return None


class NameClaim:
    """A node's claim on its full name (see the module docstring).

    Parameters
    ----------
    node : Node
        The node.
    """

    def __init__(self, node: Node) -> None:
        self.node = node
        self.mine: Claim = {"node": node.get_fully_qualified_name(), "pid": os.getpid(),
                            "host": socket.gethostname(), "since_ns": time.time_ns()}
        self.taken_by: Claim | None = None
        """The older node of this name, once its claim came: this node must not run."""
        self.pub = node.create_publisher(String, ct.endpoint(ct.NODES), qos(ct.LATCHED_QOS))
        self.sub = node.create_subscription(String, ct.endpoint(ct.NODES), self._on_claim, qos(ct.LATCHED_QOS))
        self.pub.publish(String(data=json.dumps(self.mine)))

    def _key(self, claim: Claim) -> tuple[int, str, int]:
        return claim["since_ns"], claim["host"], claim["pid"]

    def _on_claim(self, msg: String) -> None:
        other = parse_claim(msg.data)
        if other is None:
            return  # not a claim of ours: nothing to judge by
        if other["node"] != self.mine["node"] or (other["host"], other["pid"]) == (
                self.mine["host"], self.mine["pid"]):
            return  # another name, or a node of this process (nodes composed by a caller, a test)
        if self._key(other) < self._key(self.mine):
            self.taken_by = other
        else:
            self.node.get_logger().warning(
                f"a second node named {self.mine['node']} ({describe(other)}) started after this one: "
                "it refuses to run, this one goes on")

    def refusal(self) -> str | None:
        """The error to stop with when an older node has this name, else None.

        Returns
        -------
        str or None
            One line naming the other node.
        """
        other = self.taken_by
        if other is None:
            return None
        return (f"another node named {self.mine['node']} is running on this ROS domain ({describe(other)}); "
                "stop it, or give this one another name (--ros-args -r __node:=<name>)")


def describe(claim: Claim) -> str:
    """Where a claiming node runs and since when, for a log line.

    Parameters
    ----------
    claim : dict
        Its claim.

    Returns
    -------
    str
        ``pid N on host H, up T s``.
    """
    up_s = (time.time_ns() - claim["since_ns"]) / 1e9
    return f"pid {claim['pid']} on host {claim['host']}, up {up_s:.1f} s"


CLAIMS_GRACE_S = 0.5
"""Once a claim of one of the names came, how much longer :func:`running_claims` looks for the others, s."""


@dataclass
class Taken:
    """The names of a run already used on its domain (:func:`running_claims`)."""

    claimed: dict[str, Claim] = field(default_factory=dict)
    """Full name → the live claim of a suite node of that name (its run's node would refuse to start)."""
    graph_only: list[str] = field(default_factory=list)
    """Full names in the graph without a live claim: a node killed within its DDS lease, or not a suite node."""

    def refusal(self, domain_id: int) -> str | None:
        """One error naming the claimed names, or None when none is.

        Parameters
        ----------
        domain_id : int
            The run's ROS domain (named in the error).

        Returns
        -------
        str or None
            The error, one line.
        """
        if not self.claimed:
            return None
        which = "; ".join(f"{name} ({describe(claim)})" for name, claim in sorted(self.claimed.items()))
        return (f"nodes with this run's names are running on ROS domain {domain_id}: {which}; stop them, or give "
                "the run another --domain-id or --namespace")


@contextlib.contextmanager
def _environment(**values: str) -> Iterator[None]:
    """These environment variables set for the block, then as they were."""
    saved = {key: os.environ.get(key) for key in values}
    os.environ.update(values)
    try:
        yield
    finally:
        for key, value in saved.items():
            if value is None:
                os.environ.pop(key, None)
            else:
                os.environ[key] = value


def running_claims(names: Iterable[str], domain_id: int, look_s: float, discovery_range: str = "LOCALHOST") -> Taken:
    """Which of these full node names are in use on a domain, looked at from a probe node for ``look_s``.

    A claim is transient local, so every live suite node's comes once discovery has matched the probe with
    it; the look is a bound on that, not a proof (the younger node's own refusal stays the last word). It ends
    :data:`CLAIMS_GRACE_S` after the first claim of one of the names.

    Parameters
    ----------
    names : iterable of str
        Full node names (``/emac_left_wing``, ``/aircraft2/testenv``).
    domain_id : int
        The ROS domain to look at.
    look_s : float
        How long to look, s (wall time).
    discovery_range : str
        ``ROS_AUTOMATIC_DISCOVERY_RANGE`` of the look (the run's nodes').

    Returns
    -------
    Taken
        The names claimed by live nodes, and those only in the graph.
    """
    wanted = set(names)
    claimed: dict[str, Claim] = {}

    def on_claim(msg: String) -> None:
        claim = parse_claim(msg.data)
        if claim is not None and claim["node"] in wanted:  # None: not a claim, nothing to judge by
            claimed[claim["node"]] = claim

    context = Context()
    with _environment(ROS_DOMAIN_ID=str(domain_id), ROS_AUTOMATIC_DISCOVERY_RANGE=discovery_range):
        # the middleware reads both here (init's domain_id is not taken); the caller's signal handlers stay its own
        rclpy.init(args=[], context=context, signal_handler_options=SignalHandlerOptions.NO)
    try:
        node = Node(f"_ema_names_probe_{os.getpid()}", context=context, start_parameter_services=False,
                    enable_rosout=False)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        try:
            for namespace in {n.rpartition("/")[0] or "/" for n in wanted}:
                topic = f"{namespace.rstrip('/')}/{ct.endpoint(ct.NODES)}"
                node.create_subscription(String, topic, on_claim, qos(ct.LATCHED_QOS))
            end = time.monotonic() + look_s
            while (left := end - time.monotonic()) > 0:
                executor.spin_once(timeout_sec=min(left, 0.05))
                if claimed:  # a refusal: the look ends soon after, once a left-over run's other claims came too
                    end = min(end, time.monotonic() + CLAIMS_GRACE_S)
            graph = {(ns.rstrip("/") + "/" + name) for name, ns in node.get_node_names_and_namespaces()}
        finally:
            executor.shutdown()
            node.destroy_node()
    finally:
        rclpy.shutdown(context=context)
    return Taken(claimed, sorted((wanted & graph) - set(claimed)))


def refuse_taken(names: Iterable[str], domain_id: int, look_s: float, discovery_range: str) -> Taken:
    """:func:`running_claims`, refusing a run whose names live nodes claim (they would merge with its own).

    Parameters
    ----------
    names : iterable of str
        The run's nodes by full name.
    domain_id : int
        The run's ROS domain.
    look_s : float
        How long to look at most, s.
    discovery_range : str
        ``ROS_AUTOMATIC_DISCOVERY_RANGE`` of the look (the run's nodes').

    Returns
    -------
    Taken
        What the look found (names only in the graph, for a warning) when no live node claims one.

    Raises
    ------
    EmaError
        One line naming each node that claims one of the names (pid, host, how long it has been up).
    """
    taken = running_claims(names, domain_id, look_s, discovery_range)
    refusal = taken.refusal(domain_id)
    if refusal is not None:
        raise EmaError(refusal)
    return taken
