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
"""

from __future__ import annotations

import json
import os
import socket
import time
from typing import Any

from rclpy.node import Node
from std_msgs.msg import String

from ema_msgs_py import contract as ct
from ema_msgs_py.ros import qos
from ema_sim.jsontypes import JsonObject


class NameClaim:
    """A node's claim on its full name (see the module docstring).

    Parameters
    ----------
    node : Node
        The node.
    """

    def __init__(self, node: Node) -> None:
        self.node = node
        self.mine: JsonObject = {"node": node.get_fully_qualified_name(), "pid": os.getpid(),
                                     "host": socket.gethostname(), "since_ns": time.time_ns()}
        self.taken_by: JsonObject | None = None
        """The older node of this name, once its claim came: this node must not run."""
        self.pub = node.create_publisher(String, ct.endpoint(ct.NODES), qos(ct.LATCHED_QOS))
        self.sub = node.create_subscription(String, ct.endpoint(ct.NODES), self._on_claim, qos(ct.LATCHED_QOS))
        self.pub.publish(String(data=json.dumps(self.mine)))

    def _key(self, claim: dict[str, Any]) -> tuple[int, str, int]:
        return int(claim["since_ns"]), str(claim["host"]), int(claim["pid"])

    def _on_claim(self, msg: String) -> None:
        try:
            other = json.loads(msg.data)
            if other.get("node") != self.mine["node"] or (other["host"], other["pid"]) == (
                    self.mine["host"], self.mine["pid"]):
                return  # another name, or a node of this process (nodes composed by a caller, a test)
            if self._key(other) < self._key(self.mine):
                self.taken_by = other
            else:
                self.node.get_logger().warning(
                    f"a second node named {self.mine['node']} ({describe(other)}) started after this one: "
                    "it refuses to run, this one goes on")
        except (ValueError, KeyError, TypeError):
            return  # not a claim of ours: nothing to judge by

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


def describe(claim: dict[str, Any]) -> str:
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
    up_s = (time.time_ns() - int(claim["since_ns"])) / 1e9
    return f"pid {claim['pid']} on host {claim['host']}, up {up_s:.1f} s"
