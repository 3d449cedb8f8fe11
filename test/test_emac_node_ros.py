"""The EMAC node as flight software meets it (issue 25): managed lifecycle, two vehicles, its logger on /rosout.

Real node processes, each test on a ROS domain of its own, probed by the plain rclpy client of
``test_ros_integration.py``.
"""

import itertools
import time

import pytest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from lifecycle_msgs.msg import State, Transition
from lifecycle_msgs.srv import ChangeState, GetState
from rcl_interfaces.msg import Log
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from test_ros_integration import NS, RELIABLE, Client, domain, start, stop, summary

from ema_sim.config import load_channel

pytestmark = pytest.mark.ros
ROSOUT_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1000, reliability=ReliabilityPolicy.RELIABLE,
                        durability=DurabilityPolicy.TRANSIENT_LOCAL)
"""What rcl's ``/rosout`` writers offer (a late listener still gets a node's lines while the node lives)."""
LW = load_channel("left_wing")


@pytest.fixture
def client(request):
    did = domain(hash(request.node.name) % 97 + 11)
    c = Client(did)
    c.did = did
    yield c
    c.close()


def _deg(volts):
    return float(LW.v_to_deg(volts))


def _command(deg, stamp_ns=None):
    msg = JointState(name=["left_wing"], position=[float(LW.deg_to_v(deg))])
    if stamp_ns is not None:
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp_ns, NS)
    return msg


# --------------------------------------------------------------------------- lifecycle
def _state(c, node):
    return c.call(GetState, f"{node}/get_state", GetState.Request()).current_state.id


def _change(c, node, transition):
    return c.call(ChangeState, f"{node}/change_state",
                  ChangeState.Request(transition=Transition(id=transition))).success


def test_a_managed_emac_steps_only_while_active_through_the_standard_lifecycle_services(client, tmp_path):
    log = tmp_path / "emac.log"
    proc = start(client.did, "ema_sim.nodes.emac", "--lifecycle", "--channel", "left_wing", log=log)
    node = "/emac_left_wing"
    fb = []
    diag = []
    try:
        client.node.create_subscription(JointState, "/ema/emac/feedback", fb.append, RELIABLE)
        client.node.create_subscription(DiagnosticArray, "/diagnostics",
                                        lambda m: diag.extend((s.name, s.level, s.message) for s in m.status), 100)
        cmd = client.node.create_publisher(JointState, "/ema/emac/command", RELIABLE)
        assert _state(client, node) == State.PRIMARY_STATE_UNCONFIGURED
        assert client.node.count_publishers("/ema/emac/feedback") == 0  # unconfigured: no topics

        assert _change(client, node, Transition.TRANSITION_CONFIGURE)
        assert _state(client, node) == State.PRIMARY_STATE_INACTIVE
        assert client.spin(20, lambda: cmd.get_subscription_count() > 0 and
                           client.node.count_publishers("/ema/emac/feedback") == 1)
        for _ in range(100):  # inactive: commands are dropped, nothing is published
            cmd.publish(_command(3.0))
            client.spin(0.005)
        assert fb == []
        assert client.spin(5, lambda: (f"{node}: left_wing", DiagnosticStatus.WARN,
                                       "inactive (managed node): brake held") in diag), diag

        assert _change(client, node, Transition.TRANSITION_ACTIVATE)
        assert _state(client, node) == State.PRIMARY_STATE_ACTIVE
        for _ in range(300):  # 1.5 s of commands at the frame rate
            cmd.publish(_command(3.0))
            client.spin(0.005)
        assert len(fb) > 100
        assert _deg(fb[-1].position[0]) == pytest.approx(3.0, abs=0.05)  # the surface followed the commands
        stamps = [m.header.stamp.sec * NS + m.header.stamp.nanosec for m in fb]
        assert all(b > a for a, b in itertools.pairwise(stamps))

        assert _change(client, node, Transition.TRANSITION_DEACTIVATE)
        assert _state(client, node) == State.PRIMARY_STATE_INACTIVE
        client.spin(0.2)
        n = len(fb)
        for _ in range(100):  # commanded elsewhere while inactive: no frame, the surface held where it was
            cmd.publish(_command(-4.0))
            client.spin(0.005)
        assert len(fb) == n

        assert _change(client, node, Transition.TRANSITION_ACTIVATE)  # again: brake until a fresh command
        client.spin(20, lambda: len(fb) > n)
        assert _deg(fb[n].position[0]) == pytest.approx(3.0, abs=0.05)  # held position, not the dropped -4°
        assert _change(client, node, Transition.TRANSITION_DEACTIVATE)
        assert _change(client, node, Transition.TRANSITION_CLEANUP)
        assert _state(client, node) == State.PRIMARY_STATE_UNCONFIGURED
        assert client.spin(20, lambda: client.node.count_publishers("/ema/emac/feedback") == 0)

        assert _change(client, node, Transition.TRANSITION_UNCONFIGURED_SHUTDOWN)
        proc.wait(timeout=20)  # shutdown ends the process
    finally:
        stop(proc)
    assert proc.returncode == 0
    assert summary(log)["frames_published"] == len(fb)


def test_a_transition_the_state_machine_does_not_have_is_refused(client):
    proc = start(client.did, "ema_sim.nodes.emac", "--lifecycle", "--channel", "left_wing")
    try:
        assert not _change(client, "/emac_left_wing", Transition.TRANSITION_ACTIVATE)  # unconfigured → active: no
        assert _state(client, "/emac_left_wing") == State.PRIMARY_STATE_UNCONFIGURED
    finally:
        stop(proc)
    assert proc.returncode == 0


# --------------------------------------------------------------------------- two vehicles
def test_two_vehicles_of_one_channel_on_one_graph_each_follow_their_own_commands(client):
    vehicles = ("/vehicle1", "/vehicle2")
    procs = [start(client.did, "ema_sim.nodes.emac", "--channel", "left_wing", "--ros-args", "-r", f"__ns:={ns}")
             for ns in vehicles]
    fb = {ns: [] for ns in vehicles}
    names = set()
    try:
        cmd = {}
        for ns in vehicles:
            client.node.create_subscription(JointState, f"{ns}/ema/emac/feedback", fb[ns].append, RELIABLE)
            cmd[ns] = client.node.create_publisher(JointState, f"{ns}/ema/emac/command", RELIABLE)
        client.node.create_subscription(DiagnosticArray, "/diagnostics",
                                        lambda m: names.update(s.name for s in m.status), 100)
        assert client.spin(60, lambda: all(p.get_subscription_count() > 0 for p in cmd.values())
                           and all(len(f) > 5 for f in fb.values()))

        def drive(targets, seconds):
            end = time.monotonic() + seconds
            while time.monotonic() < end:
                for ns, deg in targets.items():
                    cmd[ns].publish(_command(deg))
                client.spin(0.005)

        drive({"/vehicle1": 2.0}, 1.0)  # the first vehicle alone: the second stays at its trim, braked
        assert _deg(fb["/vehicle1"][-1].position[0]) == pytest.approx(2.0, abs=0.05)
        assert _deg(fb["/vehicle2"][-1].position[0]) == pytest.approx(0.0, abs=0.05)
        drive({"/vehicle1": 2.0, "/vehicle2": -3.0}, 1.0)
        assert _deg(fb["/vehicle1"][-1].position[0]) == pytest.approx(2.0, abs=0.05)
        assert _deg(fb["/vehicle2"][-1].position[0]) == pytest.approx(-3.0, abs=0.05)
        assert client.spin(5, lambda: {f"{ns}/emac_left_wing: left_wing" for ns in vehicles} <= names), names
    finally:
        stop(*procs)
    assert [p.returncode for p in procs] == [0, 0]


# --------------------------------------------------------------------------- the node's logger
def test_the_run_summary_and_a_fatal_configuration_error_reach_rosout(client, tmp_path):
    lines = []
    client.node.create_subscription(Log, "/rosout", lines.append, ROSOUT_QOS)
    logs = tmp_path / "ros_logs"
    # the node's name says the right wing, --channel the left: a configuration error, exit status 2
    bad = start(client.did, "ema_sim.nodes.emac", "--channel", "left_wing", "--ros-args", "-r",
                "__node:=emac_right_wing", log=tmp_path / "bad.log", env={"ROS_LOG_DIR": str(logs)})
    assert client.spin(60, lambda: bad.poll() is not None)  # a listener spins, as rqt_console does
    assert bad.returncode == 2
    assert "emac: error: " in (tmp_path / "bad.log").read_text()  # the one line on stderr, as before

    def fatal():
        return [m for m in lines if m.name == "emac_right_wing" and m.level == Log.FATAL]

    assert client.spin(10, lambda: bool(fatal())), [(m.name, m.msg) for m in lines]
    assert "the channel is given differently" in fatal()[0].msg
    assert any("the channel is given differently" in p.read_text() for p in logs.rglob("*.log"))  # the log file

    good = start(client.did, "ema_sim.nodes.emac", "--channel", "left_wing", log=tmp_path / "good.log")
    try:
        assert client.spin(60, lambda: any(m.name == "emac_left_wing" for m in lines))  # it speaks on /rosout
    finally:
        stop(good)
    assert good.returncode == 0
    assert client.spin(10, lambda: any(m.name == "emac_left_wing" and m.msg.startswith("run summary: ")
                                       for m in lines))
    said = next(m.msg for m in lines if m.msg.startswith("run summary: "))
    assert said[len("run summary: "):] == (tmp_path / "good.log").read_text().split("EMA_SUMMARY ")[1].split("\n")[0]
