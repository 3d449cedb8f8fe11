"""``fmu_bridge``: the JointState pair of topic_based_ros2_control, so a ros2_control stack is the FMU.

topic_based_ros2_control (``TopicBasedSystem``) publishes every joint's command in one JointState on
its ``joint_commands_topic`` and reads the latest JointState on its ``joint_states_topic``, keeping
only the last message it got in a read cycle, so every state message here carries all joints. Point
its URDF parameters at ``/ema/joint_commands`` and ``/ema/joint_states``; joints are named after the
channels (or ``--joint-prefix``), in SI units as REP 103 asks: positions are surface angles in radians,
velocities rad/s; ``effort`` is left empty (JointState's "not measured"): the FMU reads no hinge moment, and
the motor current it reads is no joint torque.

The bridge is the FMU's converters: it turns joint commands into command volts through each
channel's command curve and holds them like a D/A, publishing ``/ema/fmu/command`` every frame (real
time, or each ``/clock`` frame under lockstep) while a joint-command publisher exists: when the
ros2_control stack goes away the commands stop and the EMACs' watchdogs brake the surfaces.
Feedback volts become radians through the feedback curve; velocity is the frame-to-frame difference.
"""

from __future__ import annotations

import argparse
import math
import time
from collections.abc import Sequence
from typing import Unpack

from rcl_interfaces.msg import ParameterType
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState

from ema_msgs_py import contract as ct
from ema_msgs_py.ros import qos, set_stamp, stamp_ns
from ema_sim.config import scaling
from ema_sim.jsontypes import JsonObject
from ema_sim.nodes.common import NodeOptions, SuiteNode, run
from ema_sim.nodes.params import Spec, names_list
from ema_sim.signals.plans import channel_list

NS = 1_000_000_000


class BridgeNode(SuiteNode):
    """The node (see the module docstring).

    Parameters
    ----------
    args : argparse.Namespace or None
        The command line's flags (parameter overrides).
    name : str
        The node's name.
    **options : NodeOptions
        rclpy node options (``context``...).
    """

    def __init__(self, args: argparse.Namespace | None = None, name: str = "fmu_bridge",
                 **options: Unpack[NodeOptions]) -> None:
        """The node and its topics (see the class docstring for the arguments)."""
        super().__init__(name, args, **options)
        own = self.params.declare([
            Spec("channels", ["all"], "channels to bridge", kind=ParameterType.PARAMETER_STRING_ARRAY),
            Spec("joint_prefix", "", "URDF joint name = prefix + channel"),
            Spec("frame_hz", ct.FRAME_HZ, "FMU frame rate", "Hz", 1.0, 1e5),
        ], name)
        self.channels = channel_list(own["channels"] or ["all"])
        self.joint = {ch: f"{own['joint_prefix']}{ch}" for ch in self.channels}
        self.channel_of = {j: ch for ch, j in self.joint.items()}
        self.scaling = {ch: scaling(ch) for ch in self.channels}
        self.frame_ns = round(NS / own["frame_hz"])
        self.lockstep = self.sim_time
        self.held_v: dict[str, float] = {}
        self.state: dict[str, tuple[int, float, float]] = {}
        self.clock_ns: int | None = None
        self.next_ns: int | None = None
        self.next_wall = time.monotonic()
        self.next_stamp: int | None = None
        """Real time: the stamp of the next command, on the frame grid from the first one's ROS time."""
        self.rejected = 0
        self.frames = 0
        fq = qos(ct.FRAME_QOS)
        self.cmd_pub = self.create_publisher(JointState, ct.endpoint(ct.FMU_COMMAND), fq)
        self.js_pub = self.create_publisher(JointState, ct.endpoint(ct.JOINT_STATES), fq)
        self.create_subscription(JointState, ct.endpoint(ct.JOINT_COMMANDS), self._on_joint_commands, qos(ct.EVENT_QOS))
        self.create_subscription(JointState, ct.endpoint(ct.FMU_FEEDBACK), self._on_feedback, fq)
        if self.lockstep:
            self.create_subscription(Clock, ct.endpoint(ct.CLOCK_TOPIC), self._on_clock, qos(ct.CLOCK_SUB_QOS))

    def _on_joint_commands(self, msg: JointState) -> None:
        try:
            for i, name in enumerate(msg.name):
                ch = self.channel_of.get(name)
                if ch is None:
                    continue
                rad = float(msg.position[i]) if i < len(msg.position) else math.nan
                if not math.isfinite(rad):
                    self.rejected += 1
                    self.throttled("bad", f"{name}: non-finite joint command ignored ({self.rejected} so far)")
                    continue
                self.held_v[ch] = self.scaling[ch].command_deg_to_v(math.degrees(rad))
        except Exception as exc:  # a bad message never kills the node
            self.throttled("drop", f"joint command dropped: {exc}")

    def _on_feedback(self, msg: JointState) -> None:
        try:
            stamp = stamp_ns(msg)
            for i, ch in enumerate(msg.name):
                if ch not in self.scaling or i >= len(msg.position):
                    continue
                rad = math.radians(self.scaling[ch].feedback_v_to_deg(float(msg.position[i])))
                last = self.state.get(ch)
                rate = 0.0 if last is None or stamp <= last[0] else (rad - last[1]) / ((stamp - last[0]) / NS)
                self.state[ch] = (stamp, rad, rate)
            out = JointState()
            set_stamp(out, stamp)
            known = [ch for ch in self.channels if ch in self.state]
            out.name = [self.joint[ch] for ch in known]
            out.position = [self.state[ch][1] for ch in known]
            out.velocity = [self.state[ch][2] for ch in known]
            self.js_pub.publish(out)
        except Exception as exc:
            self.throttled("drop", f"feedback dropped: {exc}")

    def _on_clock(self, msg: Clock) -> None:
        self.clock_ns = msg.clock.sec * NS + msg.clock.nanosec

    def _publish(self, stamp: int) -> None:
        if not self.held_v or self.count_publishers(ct.endpoint(ct.JOINT_COMMANDS)) == 0:
            return
        out = JointState()
        set_stamp(out, stamp)
        names = [ch for ch in self.channels if ch in self.held_v]
        out.name = names
        out.position = [self.held_v[ch] for ch in names]
        self.cmd_pub.publish(out)
        self.frames += 1

    def poll(self) -> float:  # noqa: D102
        if self.lockstep:
            if self.clock_ns is None:
                return 0.05
            if self.next_ns is None:
                self.next_ns = self.clock_ns
            while self.next_ns <= self.clock_ns:
                self._publish(self.next_ns)
                self.next_ns += self.frame_ns
            return 0.05
        now = time.monotonic()
        if now >= self.next_wall:
            if self.next_stamp is None:
                self.next_stamp = self.get_clock().now().nanoseconds
            self._publish(self.next_stamp)
            self.next_wall += self.frame_ns / NS
            self.next_stamp += self.frame_ns
            if now - self.next_wall > 1.0:  # held up for a second: on from the present frame (stamps on the grid)
                skipped = int((now - self.next_wall) * NS) // self.frame_ns
                self.next_wall += skipped * self.frame_ns / NS
                self.next_stamp += skipped * self.frame_ns
        return self.next_wall - now

    def summary(self) -> JsonObject:  # noqa: D102
        return {"frames": self.frames, "rejected": self.rejected}


def parser() -> argparse.ArgumentParser:
    """Command-line flags: shorthands for the node's parameters."""
    p = argparse.ArgumentParser(prog="fmu_bridge", description="topic_based_ros2_control JointState pair ↔ the suite.",
                                argument_default=argparse.SUPPRESS)
    p.add_argument("--channels", action="append", type=names_list, help="parameter channels: channels to bridge")
    p.add_argument("--joint-prefix", dest="joint_prefix", help="parameter joint_prefix: URDF joint = prefix + channel")
    p.add_argument("--frame-hz", dest="frame_hz", type=float, help="parameter frame_hz")
    return p


def main(argv: Sequence[str] | None = None) -> int:
    """Console script ``fmu_bridge``.

    Parameters
    ----------
    argv : sequence of str or None
        The arguments (None: the process's).

    Returns
    -------
    int
        The exit status.
    """
    return run(BridgeNode, parser(), argv)


if __name__ == "__main__":
    raise SystemExit(main())
