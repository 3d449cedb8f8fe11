"""``/ema/joint_states`` is in SI units (REP 103): radians and rad/s, whatever the FMU side's volts say."""

import math

import pytest
import rclpy
from rclpy.executors import SingleThreadedExecutor
from ros_context import ros_context
from sensor_msgs.msg import JointState

from ema_msgs_py import contract as ct
from ema_msgs_py.ros import qos
from ema_sim.config import CHANNELS, scaling
from ema_sim.nodes.bridge import BridgeNode

pytestmark = pytest.mark.ros
NS = 1_000_000_000
FRAME_NS = 5_000_000


@pytest.fixture
def graph():
    with ros_context(71) as ctx:
        bridge = BridgeNode(context=ctx)
        probe = rclpy.create_node("probe", context=ctx)
        ex = SingleThreadedExecutor(context=ctx)
        ex.add_node(bridge)
        ex.add_node(probe)
        yield bridge, probe, ex
        ex.shutdown()
        probe.destroy_node()
        bridge.destroy_node()


def _spin(ex, until, seconds=10.0):
    import time  # noqa: PLC0415

    end = time.monotonic() + seconds
    while time.monotonic() < end and not until():
        ex.spin_once(timeout_sec=0.01)
    return until()


def test_joint_states_carry_radians_and_radians_per_second_from_feedback_volts(graph):
    _, probe, ex = graph
    states = []
    probe.create_subscription(JointState, ct.JOINT_STATES, states.append, qos(ct.JOINT_STATES))
    fb = probe.create_publisher(JointState, ct.FMU_FEEDBACK, qos(ct.FMU_FEEDBACK))
    assert _spin(ex, lambda: fb.get_subscription_count() > 0 and probe.count_publishers(ct.JOINT_STATES) > 0)
    # two frames: every surface 10° then 10.5° (inverse channels: negative volts), one frame apart
    angles = {ch: 10.0 + i for i, ch in enumerate(CHANNELS)}
    for k, step_deg in enumerate((0.0, 0.5)):
        msg = JointState(name=list(CHANNELS),
                         position=[scaling(ch).feedback_deg_to_v(angles[ch] + step_deg) for ch in CHANNELS])
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(NS + k * FRAME_NS, NS)
        fb.publish(msg)
        assert _spin(ex, lambda k=k: len(states) > k)
    last = states[-1]
    assert list(last.name) == list(CHANNELS)
    for i, ch in enumerate(CHANNELS):
        assert last.position[i] == pytest.approx(math.radians(angles[ch] + 0.5), abs=1e-6)  # not 10.5 (degrees)
        assert last.velocity[i] == pytest.approx(math.radians(0.5) / (FRAME_NS / NS), rel=1e-4)  # rad/s
    assert list(last.effort) == []  # no joint torque is measured on the FMU side: "not measured", not amps
