"""The ema_monitor lifecycle node: configured and activated, fed frames in process, it detects an injected LVDT
bias, publishes the detection and says so on /diagnostics (ERROR) after calibrating (WARN) and watching (OK); it
re-baselines on the bias and detects a delay that follows."""

import argparse
import json
from types import SimpleNamespace

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticStatus
from ros_context import ros_context

from ema_msgs_py import contract as ct
from ema_msgs_py.cdr import JointFrame
from ema_msgs_py.contract import scaling_of
from ema_sim.config import load_channel
from ema_sim.faults import parse_fault
from ema_sim.nodes.monitor import MonitorNode
from ema_sim.signals import parse_load, parse_maneuver
from ema_sim.simulation import simulate

pytestmark = pytest.mark.ros


class TakePorts:
    """Test-only ports: the frame callbacks are kept, to be called directly."""

    composed = False

    def __init__(self, node):
        self.node = node
        self.callbacks = {}

    def frame_publisher(self, topic):  # noqa: ARG002 - the ports' signature
        return SimpleNamespace(publish=lambda _msg: None)

    def frame_subscription(self, topic, callback, on_bad, *, at_frame=False):  # noqa: ARG002
        self.callbacks[topic] = callback


def test_the_node_detects_and_reports_on_diagnostics():
    _, rec, _ = simulate("loada", parse_maneuver("sine:amp_deg=3,freq_hz=0.5,cycles=20"), parse_load("const:inlb=500"),
                         duration_s=11.5, sample_hz=200.0,
                         faults=[parse_fault("lvdt_bias:at_s=6,size=0.1"), parse_fault("delay:at_s=8.5,size=0.005")])
    sc = scaling_of(load_channel("left_wing"))
    rng = np.random.default_rng(0)
    with ros_context(97) as ctx:
        node = MonitorNode(argparse.Namespace(healthy_s=4.0), ports=TakePorts, context=ctx,
                           cli_args=["--ros-args", "-p", "window_s:=2.0"])
        try:
            node.trigger_configure()
            node.trigger_activate()
            sent = []
            node.det_pub = SimpleNamespace(publish=sent.append)
            take = node.ports.callbacks
            levels = []
            for k in range(1, rec.time_s.size):
                stamp = int(k * 5e6)
                volts = sc.command_deg_to_v(rec.command_deg[0, k - 1])
                take[ct.EMAC_COMMAND](JointFrame(stamp, ["left_wing"], [volts]))
                take[ct.HINGE_MOMENT](JointFrame(stamp, ["left_wing"], [], [], [rec.hinge_moment_inlb[0, k - 1]]))
                pos = rec.position_deg[0, k] + rng.normal(0.0, 0.005)
                take[ct.EMAC_FEEDBACK](JointFrame(stamp, ["left_wing"], [sc.feedback_deg_to_v(pos)]))
                if k in (100, 1000, rec.time_s.size - 1):
                    levels.append(node.diagnostics().status[0].level)
            assert levels == [DiagnosticStatus.WARN, DiagnosticStatus.OK, DiagnosticStatus.ERROR]
            assert [json.loads(m.data)["kind"] for m in sent] == ["lvdt_bias", "delay"]
            assert json.loads(sent[1].data)["time_s"] >= 8.5
            assert node.diagnostics().status[0].values[-1].value == "2"
        finally:
            node.destroy_node()
