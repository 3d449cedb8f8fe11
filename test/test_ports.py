"""Inputs taken at the frame (issue 25): the executor never wakes the node for them; the node's frame takes each.

A lone node's :class:`~ema_sim.nodes.ports.Ports` on real DDS, in process, on a ROS domain of its own.
"""

import time

import pytest
from rclpy.node import Node
from ros_context import ros_context
from sensor_msgs.msg import JointState

from ema_msgs_py import cdr
from ema_msgs_py import contract as ct
from ema_msgs_py.ros import qos
from ema_sim.nodes.common import SuiteNode, make_executor
from ema_sim.nodes.ports import Ports

pytestmark = pytest.mark.ros


@pytest.fixture
def graph():
    with ros_context(97) as ctx:
        node = SuiteNode("ports_probe", context=ctx)
        sender = Node("ports_sender", context=ctx)
        executor = make_executor(ctx)
        executor.add_node(node)
        yield node, sender, executor
        executor.shutdown()
        node.destroy_node()
        sender.destroy_node()


def _spin(executor, seconds):
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        executor.spin_once(timeout_sec=0.01)


def _frame(k):
    return cdr.encode(cdr.JointFrame(k * 5_000_000, ["left_wing"], [0.1 * k]))


def test_a_subscription_taken_at_the_frame_waits_for_the_frame_in_order_with_its_receive_time(graph):
    node, sender, executor = graph
    ports = Ports(node)
    on_arrival, at_frame = [], []
    ports.frame_subscription(ct.EMAC_COMMAND, on_arrival.append, pytest.fail)
    ports.frame_subscription(ct.HINGE_MOMENT, lambda f: at_frame.append((f, ports.received_ns)), pytest.fail,
                             at_frame=True)
    pubs = {t: sender.create_publisher(JointState, ct.endpoint(t), qos(ct.FRAME_QOS))
            for t in (ct.EMAC_COMMAND, ct.HINGE_MOMENT)}
    deadline = time.monotonic() + 10.0
    while any(p.get_subscription_count() == 0 for p in pubs.values()) and time.monotonic() < deadline:
        _spin(executor, 0.05)
    before = time.time_ns()
    for k in range(5):
        for pub in pubs.values():
            pub.publish(_frame(k))
    _spin(executor, 0.5)
    assert [f.stamp_ns for f in on_arrival] == [k * 5_000_000 for k in range(5)]  # the executor's, on arrival
    assert at_frame == []  # waiting in DDS: the executor never handed them over
    # hidden from the executor, yet the node's own (readiness counts its matches)
    assert len(list(node.subscriptions)) == len(node.every_subscription()) - 1
    assert ports.take_at_frame() == 5
    assert [(f.stamp_ns, f.position) for f, _ in at_frame] == [(k * 5_000_000, [0.1 * k]) for k in range(5)]
    received = [r for _, r in at_frame]
    assert all(before <= r <= time.time_ns() for r in received)  # DDS's receive time, set during the take only
    assert received == sorted(received)
    assert ports.received_ns is None
    assert ports.take_at_frame() == 0


def test_a_destroyed_subscription_taken_at_the_frame_is_forgotten(graph):
    node, _sender, _executor = graph
    ports = Ports(node)
    ports.frame_subscription(ct.HINGE_MOMENT, pytest.fail, pytest.fail, at_frame=True)
    sub = next(s for s in node.every_subscription() if s.topic_name.endswith(ct.HINGE_MOMENT))
    node.destroy_subscription(sub)
    assert sub not in node.at_frame
    assert ports.take_at_frame() == 0
    assert ports._at_frame == []
