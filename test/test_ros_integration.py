"""What a ROS user meets first (issue 15), against real node processes and an rclpy client written here.

The client uses rclpy alone (its own context, executor, QoS profiles and parameter services: none of the
project's helpers) on a ROS domain of its own per test, derived from the pid.
"""

import json
import math
import os
import signal
import subprocess
import sys
import time
import zlib
from pathlib import Path

import numpy as np
import pytest
import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rcl_interfaces.msg import Parameter as ParameterMsg
from rcl_interfaces.msg import ParameterType, ParameterValue
from rcl_interfaces.srv import DescribeParameters, GetParameters, ListParameters, SetParameters
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import String

from ema_sim.config import load_channel
from ema_sim.suite import free_domain_id

pytestmark = pytest.mark.ros
ROOT = Path(__file__).resolve().parents[1]
CONFIG = ROOT / "config"
NS = 1_000_000_000
FRAME_NS = 5_000_000
RELIABLE = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1000, reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.VOLATILE)
DEFAULT_QOS = QoSProfile(depth=10)  # what create_publisher(..., 10) gives: reliable, volatile
CLOCK_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1, reliability=ReliabilityPolicy.BEST_EFFORT,
                       durability=DurabilityPolicy.VOLATILE)  # rclcpp::ClockQoS
LATCHED = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)  # /ema/ready (the contract's LATCHED_QOS)


STATUS = "/emac_left_wing: left_wing"
"""The left wing's status on /diagnostics: its node's full name and the channel."""


def domain(offset):
    return free_domain_id(os.getpid() + 53 * offset)


READY_BOUND_S = 120.0
"""How long a service call waits for its node to come up: a bound for a loaded two-core machine (start-up and
discovery), not a timing; the wait ends as soon as the service is there."""
AFTER_READY_S = 30.0
"""Once the node has called itself ready on ``/ema/ready``, how long its service may still take to be seen."""
READY_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10, reliability=ReliabilityPolicy.RELIABLE,
                       durability=DurabilityPolicy.TRANSIENT_LOCAL)  # the nodes' latched /ema/ready


class Client:
    """A plain rclpy node on its own context and domain."""

    def __init__(self, did, name="probe"):
        self.ctx = rclpy.Context()
        rclpy.init(context=self.ctx, domain_id=did)
        self.node = rclpy.create_node(name, context=self.ctx)
        self.ex = SingleThreadedExecutor(context=self.ctx)
        self.ex.add_node(self.node)
        self.ready = None
        """Node name → when (monotonic) it first said it was ready on ``/ema/ready``; listened to from the first
        service call on (a test of the graph's topics sees no topic of the client's own before)."""

    def spin(self, seconds, until=None):
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            if until is not None and until():
                return True
            self.ex.spin_once(timeout_sec=0.005)
        return until() if until is not None else True

    def _service_up(self, cli, node):
        """The service is there; fails once its node has been ready for :data:`AFTER_READY_S` without it."""
        if cli.service_is_ready():
            return True
        since = self.ready.get(node.rpartition("/")[2]) if node.count("/") == 1 else None
        assert since is None or time.monotonic() - since < AFTER_READY_S, \
            f"{node} has been ready for {AFTER_READY_S:g} s and {cli.srv_name} is still not seen"
        return False

    def call(self, srv_type, name, request, timeout=READY_BOUND_S):
        """Call a node's service once it is there (its node up: the ready signal, within ``timeout``)."""
        if self.ready is None:
            self.ready = {}
            self.node.create_subscription(String, "/ema/ready",
                                          lambda m: self.ready.setdefault(m.data, time.monotonic()), READY_QOS)
        cli = self.node.create_client(srv_type, name)
        node = name.rpartition("/")[0]
        up = self.spin(timeout, lambda: self._service_up(cli, node))
        assert up, f"no service {name} in {timeout:g} s ({node} {'ready' if node[1:] in self.ready else 'never ready'})"
        future = cli.call_async(request)
        assert self.spin(timeout, future.done), f"{name} did not answer"
        self.node.destroy_client(cli)
        return future.result()

    def close(self):
        self.ex.shutdown()
        self.node.destroy_node()
        rclpy.shutdown(context=self.ctx)


@pytest.fixture
def client(request):
    did = domain(zlib.crc32(request.node.name.encode()) % 97)  # stable across processes, unlike hash()
    c = Client(did)
    c.did = did
    yield c
    c.close()


def start(did, *args, log=None, cwd=None, env=None, exe=None):
    """A node process (``exe``: an installed executable, else ``python -m``)."""
    full = dict(os.environ, ROS_DOMAIN_ID=str(did), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
                PYTHONUNBUFFERED="1", **(env or {}))
    cmd = [*exe] if exe else [sys.executable, "-m"]
    out = subprocess.DEVNULL if log is None else Path(log).open("w")  # noqa: SIM115  (the child writes it)
    return subprocess.Popen([*cmd, *args], env=full, stdout=out, stderr=subprocess.STDOUT, text=True, cwd=cwd)


def stop(*procs):
    for p in procs:
        if p.poll() is None:
            p.send_signal(signal.SIGTERM)
    for p in procs:
        try:
            p.wait(timeout=20)
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait()


def summary(log):
    line = next(x for x in Path(log).read_text().splitlines() if x.startswith("EMA_SUMMARY "))
    return json.loads(line[len("EMA_SUMMARY "):])


def get_params(c, node, names):
    resp = c.call(GetParameters, f"{node}/get_parameters", GetParameters.Request(names=names))
    return {n: _value(v) for n, v in zip(names, resp.values, strict=True)}


def _value(v):
    return {ParameterType.PARAMETER_BOOL: v.bool_value, ParameterType.PARAMETER_INTEGER: v.integer_value,
            ParameterType.PARAMETER_DOUBLE: v.double_value, ParameterType.PARAMETER_STRING: v.string_value,
            ParameterType.PARAMETER_DOUBLE_ARRAY: list(v.double_array_value),
            ParameterType.PARAMETER_STRING_ARRAY: list(v.string_array_value)}.get(v.type)


def set_param(c, node, name, value):
    v = ParameterValue()
    if isinstance(value, bool):
        v.type, v.bool_value = ParameterType.PARAMETER_BOOL, value
    elif isinstance(value, float):
        v.type, v.double_value = ParameterType.PARAMETER_DOUBLE, value
    else:
        v.type, v.string_value = ParameterType.PARAMETER_STRING, value
    resp = c.call(SetParameters, f"{node}/set_parameters",
                  SetParameters.Request(parameters=[ParameterMsg(name=name, value=v)]))
    return resp.results[0]


def wait_for_node(c, name, timeout=30.0):
    assert c.spin(timeout, lambda: name in c.node.get_node_names()), f"{name} never appeared"


def command_v(deg):
    return float(load_channel("left_wing").deg_to_v(deg))


def hold(c, pub, deg, seconds):
    """Command the left wing to ``deg`` every 5 ms for ``seconds``; returns when the last command left (monotonic)."""
    end = time.monotonic() + seconds
    last = time.monotonic()
    while time.monotonic() < end:
        pub.publish(JointState(name=["left_wing"], position=[command_v(deg)]))
        last = time.monotonic()
        c.spin(0.005)
    return last


# --------------------------------------------------------------------------- 1. parameter files
def test_every_node_starts_with_every_shipped_parameter_file(client, tmp_path):
    """rcl parses every file of config/ (mixed int/float lists were refused), and each node takes its own."""
    files = [a for f in sorted(CONFIG.glob("*.yaml")) for a in ("--params-file", str(f))]
    ros = ["--ros-args", *files]
    procs = {
        "container": start(client.did, "ema_sim.nodes.container", "--channels", "all", *ros,
                           log=tmp_path / "container.log"),
        "maneuver": start(client.did, "ema_sim.nodes.maneuver", "--maneuver", "ramp:rate_dps=0.05,peak_deg=5",
                          "--bag", str(tmp_path / "m"), *ros, log=tmp_path / "maneuver.log"),
        "fmu": start(client.did, "ema_sim.nodes.fmu", "--bag", str(tmp_path / "f"), *ros, log=tmp_path / "fmu.log"),
        "simclock": start(client.did, "ema_sim.nodes.clock", "--realtime-factor", "1", *ros,
                          log=tmp_path / "simclock.log"),
        "bridge": start(client.did, "ema_sim.nodes.bridge", *ros, log=tmp_path / "bridge.log"),
    }
    try:
        for node in ("emac_left_wing", "emac_cowl_door", "testenv", "maneuver", "fmu", "simclock", "fmu_bridge"):
            wait_for_node(client, node, 60)
        for ch, breakpoints in (("left_wing", [25.0, 342.6]), ("left_rudder", [10.0, 90.5]),
                                ("cowl_door", [25.0, 342.6])):
            got = get_params(client, f"/emac_{ch}", ["high_order.hoad3.total_breakpoints_lbf", "channel",
                                                      "emac.watchdog_timeout_s", "second_order.wn_rad_s"])
            assert got["high_order.hoad3.total_breakpoints_lbf"] == breakpoints
            assert got["channel"] == ch
            assert got["emac.watchdog_timeout_s"] == 0.05
        env = get_params(client, "/testenv", ["profile", "command.delay_s", "seed"])
        assert env["profile"] in ("ail", "flight")  # both files address testenv: the later one wins
        veh = get_params(client, "/fmu", ["vehicle.m_alpha_per_s2", "setup.ail.aero_input", "frame_hz"])
        assert veh == {"vehicle.m_alpha_per_s2": -40.0, "setup.ail.aero_input": "feedback", "frame_hz": 200.0}
        for name, p in procs.items():
            assert p.poll() is None, (name, (tmp_path / f"{name}.log").read_text()[-2000:])
    finally:
        stop(*procs.values())
    for name in procs:
        text = (tmp_path / f"{name}.log").read_text()
        assert "Traceback" not in text, text[-2000:]


# --------------------------------------------------------------------------- 3. parameters
def check_declared(client, node):
    """Every parameter declared without a file; descriptors with text, unit, range and read-only flags."""
    names = client.call(ListParameters, f"{node}/list_parameters", ListParameters.Request()).result.names
    assert {"emac.failure", "emac.watchdog_timeout_s", "emac.motor_power_on", "second_order.wn_rad_s",
            "high_order.hoad3.total_breakpoints_lbf", "model", "channels"} <= set(names)
    assert len(names) > 100  # no file given: every parameter declared all the same
    described = client.call(DescribeParameters, f"{node}/describe_parameters", DescribeParameters.Request(
        names=["emac.watchdog_timeout_s", "emac.failure", "second_order.wn_rad_s", "emac.frame_hz"])).descriptors
    d = {x.name: x for x in described}
    assert all(x.description for x in described)
    assert "[s]" in d["emac.watchdog_timeout_s"].description
    assert d["emac.watchdog_timeout_s"].floating_point_range[0].from_value > 0.0
    assert not d["emac.watchdog_timeout_s"].read_only
    assert not d["emac.failure"].read_only
    assert d["second_order.wn_rad_s"].read_only
    assert d["emac.frame_hz"].read_only
    assert "(read-only: read when the node starts" in d["emac.frame_hz"].description  # and why
    assert "read-only" not in d["emac.watchdog_timeout_s"].description
    from ema_sim.models.registry import model_parameters  # noqa: PLC0415

    wn = next(p for p in model_parameters("loada") if p.path == "second_order.wn_rad_s")  # the one declaration
    assert d["second_order.wn_rad_s"].description.startswith(wn.description)
    assert f"[{wn.unit}]" in d["second_order.wn_rad_s"].description
    rng = d["second_order.wn_rad_s"].floating_point_range[0]
    assert (rng.from_value, rng.to_value) == (wn.min, wn.max)


def test_parameters_are_declared_described_and_changed_at_run_time_only_where_it_takes_effect(client, tmp_path):
    log = tmp_path / "emac.log"
    proc = start(client.did, "ema_sim.nodes.emac", "--model", "loada", "--channel", "left_wing", log=log)
    node = "/emac_left_wing"
    try:
        wait_for_node(client, "emac_left_wing", 60)
        check_declared(client, node)

        fb, diag = [], {}
        client.node.create_subscription(JointState, "/ema/emac/feedback", fb.append, RELIABLE)
        client.node.create_subscription(
            DiagnosticArray, "/diagnostics",
            lambda m: diag.update({s.name: {**{v.key: v.value for v in s.values}, "_t": time.monotonic()}
                                   for s in m.status}), 10)
        cmd = client.node.create_publisher(JointState, "/ema/emac/command", RELIABLE)
        assert client.spin(20, lambda: cmd.get_subscription_count() > 0 and len(fb) > 2)

        def brake_delay():
            """Command for 0.5 s, stop: seconds until the node reports the brake engaged."""
            # from the last command sent (a loaded client may be held up between its last publish and the check)
            last = hold(client, cmd, 1.0, 0.5)
            assert client.spin(2, lambda: diag.get(STATUS, {}).get("brake_engaged") == "false")
            assert client.spin(5, lambda: diag[STATUS]["brake_engaged"] == "true")
            return diag[STATUS]["_t"] - last

        short = brake_delay()
        result = set_param(client, node, "emac.watchdog_timeout_s", 0.6)
        assert result.successful, result.reason
        long = brake_delay()
        assert short < 0.3, short
        assert 0.5 < long < 1.5, long  # the watchdog took the new timeout
        assert set_param(client, node, "emac.failure", "stuck").successful
        assert client.spin(3, lambda: diag[STATUS].get("failure") == "stuck")
        assert set_param(client, node, "emac.failure", "none").successful
        assert not set_param(client, node, "emac.failure", "melt").successful  # refused, node goes on
        assert set_param(client, node, "emac.motor_power_on", False).successful
        hold(client, cmd, 1.0, 0.5)  # commanded, but unpowered: the brake holds
        assert diag[STATUS]["motor_power_on"] == "false"
        assert diag[STATUS]["brake_engaged"] == "true"
        refused = set_param(client, node, "second_order.wn_rad_s", 80.0)
        assert not refused.successful
        assert "read-only" in refused.reason
        assert not set_param(client, node, "emac.frame_hz", 400.0).successful
        out_of_range = set_param(client, node, "emac.watchdog_timeout_s", -1.0)
        assert not out_of_range.successful
        assert "range" in out_of_range.reason
        assert get_params(client, node, ["second_order.wn_rad_s"])["second_order.wn_rad_s"] == 56.5
    finally:
        stop(proc)
    text = log.read_text()
    assert "emac.watchdog_timeout_s: 0.05 → 0.6 s" in text
    assert "emac.failure: stuck" in text
    assert "emac.motor_power_on: False (brake engaged at the next frame)" in text


def test_the_test_environment_takes_its_elements_at_run_time_and_says_why_the_rest_is_read_only(client, tmp_path):
    """Quantization then noise set on the command path through set_parameters change what the EMAC gets; the
    profile is refused, its descriptor saying why."""
    log = tmp_path / "testenv.log"
    proc = start(client.did, "ema_sim.nodes.testenv", "--profile", "none", log=log)
    node = "/testenv"
    try:
        wait_for_node(client, "testenv", 60)
        out, sent = [], [0]
        client.node.create_subscription(
            JointState, "/ema/emac/command", lambda m: out.append((m.header.stamp.nanosec, m.position[0])), RELIABLE)
        fmu = client.node.create_publisher(JointState, "/ema/fmu/command", RELIABLE)

        def send():
            sent[0] += 1  # each command stamped with its number (the test environment keeps stamps)
            msg = JointState(name=["left_wing"], position=[1.23])
            msg.header.stamp.nanosec = sent[0]
            fmu.publish(msg)

        def through(n):
            """What the test environment passes on for the next ``n`` 1.23 V commands sent from now."""
            first = sent[0]

            def taken():
                send()
                return len([v for k, v in out if k > first]) >= n
            assert client.spin(20, taken), "no command passed on"
            return [v for k, v in out if k > first][:n]

        assert through(5) == [1.23] * 5  # profile none: a pass-through
        described = client.call(DescribeParameters, f"{node}/describe_parameters", DescribeParameters.Request(
            names=["command.quantization_v", "profile", "seed"])).descriptors
        d = {x.name: x for x in described}
        assert not d["command.quantization_v"].read_only
        assert d["profile"].read_only
        assert "read-only: the profile sets every element's default when the node starts" in d["profile"].description
        assert "read-only: every channel's noise stream is seeded once" in d["seed"].description
        refused = set_param(client, node, "profile", "ail")
        assert not refused.successful
        assert "read-only" in refused.reason

        assert set_param(client, node, "command.quantization_v", 0.5).successful
        assert through(5) == [1.0] * 5  # the next frame's command is quantized to 0.5 V
        assert set_param(client, node, "command.noise_rms_v", 0.05).successful
        noisy = np.array(through(200))
        assert 0.03 < noisy.std() < 0.07
        assert abs(noisy.mean() - 1.0) < 0.02
        assert not set_param(client, node, "command.noise_rms_v", -1.0).successful  # out of range: refused
        assert proc.poll() is None
    finally:
        stop(proc)
    text = log.read_text()
    assert "command.quantization_v: 0 → 0.5 (from the next frame); command path now quantization 500 mV" in text
    assert "command.noise_rms_v: 0 → 0.05 (from the next frame)" in text
    assert '"run_time_changes": 2' in text


# --------------------------------------------------------------------------- 2. /clock from any publisher
@pytest.mark.parametrize(("qos_name", "clock_every"), [("default", 1), ("clockqos", 1), ("clockqos", 7)])
def test_lockstep_follows_any_clock_publisher_and_keeps_every_frame(client, tmp_path, qos_name, clock_every):
    """Default-QoS and ClockQoS (best effort) /clock both drive the node; with most ticks missing, the stamped
    commands still give every frame exactly once, the same values as the model replayed offline."""
    from ema_sim.emac import EmacChannel, EmacSettings  # noqa: PLC0415
    from ema_sim.models import create  # noqa: PLC0415

    log = tmp_path / "emac.log"
    frames = 120
    fb = {}
    ready = []
    # the client's endpoints exist before the node starts, and the node is told to see the client as a peer: it
    # announces itself on /ema/ready only once its own side of every match is made (SuiteNode.matched)
    sub = client.node.create_subscription(
        JointState, "/ema/emac/feedback",
        lambda m: fb.setdefault(m.header.stamp.sec * NS + m.header.stamp.nanosec, []).append(m.position[0]),
        RELIABLE)
    clock = client.node.create_publisher(Clock, "/clock", DEFAULT_QOS if qos_name == "default" else CLOCK_QOS)
    cmd = client.node.create_publisher(JointState, "/ema/emac/command", RELIABLE)
    client.node.create_subscription(String, "/ema/ready", lambda m: ready.append(m.data), LATCHED)
    proc = start(client.did, "ema_sim.nodes.emac", "--model", "loada", "--channel", "left_wing",
                 "--ros-args", "-p", "use_sim_time:=true", "-p", f"peers:=[{client.node.get_name()}]", log=log)
    try:
        wait_for_node(client, "emac_left_wing", 60)
        # discovery of three endpoints: 20 s was once not enough with numba compiling beside it on two cores
        assert client.spin(60, lambda: min(clock.get_subscription_count(), cmd.get_subscription_count(),
                                           sub.get_publisher_count()) > 0 and "emac_left_wing" in ready), ready
        volts = [command_v(2.0 * math.sin(k / 15.0)) for k in range(frames)]

        def tick(ns):
            m = Clock()
            m.clock.sec, m.clock.nanosec = divmod(ns, NS)
            clock.publish(m)

        tick(0)
        for k in range(frames):
            msg = JointState(name=["left_wing"], position=[volts[k]])
            msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(k * FRAME_NS, NS)
            cmd.publish(msg)
            if (k + 1) % clock_every == 0:
                tick((k + 1) * FRAME_NS)
            client.spin(0.002)
        tick(frames * FRAME_NS)  # the run's end
        assert client.spin(20, lambda: (frames * FRAME_NS) in fb), sorted(fb)[-3:]
    finally:
        stop(proc)
    assert sorted(fb) == [k * FRAME_NS for k in range(frames + 1)]
    assert all(len(v) == 1 for v in fb.values())  # each frame exactly once
    replay = EmacChannel(create("loada", "left_wing"), EmacSettings())
    want = [replay.last.position_v]
    for v in volts:
        replay.set_command(v)
        want.append(replay.step(0.0).position_v)
    assert [fb[k * FRAME_NS][0] for k in range(frames + 1)] == pytest.approx(want, abs=1e-12)


# --------------------------------------------------------------------------- 4. namespaces
def test_a_namespace_moves_every_topic_of_a_node(client):
    procs = [start(client.did, "ema_sim.nodes.emac", "--channel", "all", "--ros-args", "-r", "__ns:=/aircraft2"),
             start(client.did, "ema_sim.nodes.testenv", "--ros-args", "-r", "__ns:=/aircraft2")]
    try:
        got = []
        client.node.create_subscription(JointState, "/aircraft2/ema/fmu/feedback", got.append, RELIABLE)
        cmd = client.node.create_publisher(JointState, "/aircraft2/ema/fmu/command", RELIABLE)
        assert client.spin(60, lambda: cmd.get_subscription_count() > 0 and len(got) > 5)
        end = time.monotonic() + 1.0
        while time.monotonic() < end:
            cmd.publish(JointState(name=["left_wing"], position=[command_v(3.0)]))
            client.spin(0.005)
        assert load_channel("left_wing").v_to_deg(got[-1].position[0]) == pytest.approx(3.0, abs=0.05)
        wanted = {"/aircraft2/ema/emac/feedback", "/aircraft2/ema/emac/command", "/diagnostics",
                  "/aircraft2/ema/emac/left_wing/failure", "/aircraft2/ema/ready"}

        def ours():
            return {n for n, _ in client.node.get_topic_names_and_types() if n not in ("/rosout", "/parameter_events")}

        assert client.spin(20, lambda: wanted <= ours()), sorted(wanted - ours())
        # every topic in the namespace but ROS's global ones (/diagnostics: statuses named by the node's full name)
        assert all(t.startswith("/aircraft2/") for t in ours() - {"/diagnostics"}), sorted(ours())
    finally:
        stop(*procs)


# --------------------------------------------------------------------------- 9. idle feedback
def test_idle_feedback_keeps_the_frame_rate_with_stamps_on_the_frame_grid(client, tmp_path):
    """Every frame, stamped on the grid; a frame missing only where the node says it skipped it.

    A process held up more than ``CATCH_UP`` frames (a loaded machine) jumps to the present frame by design,
    with the stamps kept on the grid, and counts the frames it skipped in its summary.
    """
    log = tmp_path / "emac.log"
    proc = start(client.did, "ema_sim.nodes.emac", "--channel", "left_wing", log=log)
    rows = []
    try:
        client.node.create_subscription(
            JointState, "/ema/emac/feedback",
            lambda m: rows.append((time.time_ns(), m.header.stamp.sec * NS + m.header.stamp.nanosec)), RELIABLE)
        assert client.spin(60, lambda: len(rows) > 20)
        rows.clear()
        client.spin(3.0)
    finally:
        stop(proc)
    wall, stamp = np.array(rows, dtype=np.int64).T
    gaps = np.diff(stamp)
    assert np.all(gaps > 0), gaps[gaps != FRAME_NS]  # in order
    assert np.all(gaps % FRAME_NS == 0), gaps[gaps != FRAME_NS]  # on the grid
    missing = int(gaps.sum() // FRAME_NS - gaps.size)
    assert missing <= summary(log)["skipped_frames"], (missing, gaps[gaps != FRAME_NS])  # every frame not skipped
    period_ms = np.median(np.diff(wall)) / 1e6
    assert 4.5 < period_ms < 5.5, period_ms  # was 7.5 ms (133 Hz)
    slope = np.polyfit((wall - wall[0]) / 1e9, (stamp - stamp[0]) / 1e9, 1)[0]
    assert 0.98 < slope < 1.02, slope  # stamps advance with the wall clock: was 0.67 (1 s behind after 3 s)


def test_a_node_held_up_skips_frames_on_the_grid_and_counts_each_one(client, tmp_path):
    log = tmp_path / "emac.log"
    proc = start(client.did, "ema_sim.nodes.emac", "--channel", "left_wing", log=log)
    stamps = []
    try:
        client.node.create_subscription(
            JointState, "/ema/emac/feedback",
            lambda m: stamps.append(m.header.stamp.sec * NS + m.header.stamp.nanosec), RELIABLE)
        assert client.spin(60, lambda: len(stamps) > 20)  # kept: the frames before the hold
        proc.send_signal(signal.SIGSTOP)  # held up 0.5 s: 100 frames, more than the 20 it catches up
        client.spin(0.5)
        proc.send_signal(signal.SIGCONT)
        assert client.spin(60, lambda: len(stamps) > 220)
    finally:
        proc.send_signal(signal.SIGCONT)
        stop(proc)
    gaps = np.diff(stamps)
    assert np.all(gaps > 0), gaps[gaps != FRAME_NS]
    assert np.all(gaps % FRAME_NS == 0), gaps[gaps != FRAME_NS]
    missing = int(gaps.sum() // FRAME_NS - gaps.size)
    assert missing >= 60, gaps[gaps != FRAME_NS]  # the hold is not stepped frame by frame afterwards
    assert missing <= summary(log)["skipped_frames"], (missing, gaps[gaps != FRAME_NS])


# --------------------------------------------------------------------------- 10. drops counted
def _good_commands_until_nominal(client, cmd, msg, t_good, diag):
    """Good commands only, until the drop warning ages out; the frames their stamps spanned and the last status.

    The commands are stamped on the frame grid by the wall time since the first (an FMU's frames): a publisher
    slowed by a loaded machine leaves gaps in its stamps, never stamps that lag the wall time (which the node
    rightly flags as a lagging clock). The warning ages out FAULT_HOLD_S (2 s) after the last drop. On a loaded
    machine a stalled node may still lose a good command from its queue (counted, and it restarts the hold), so
    the status must read nominal within 15 s, 2 s after the last drop the node counted.
    """
    start_good = time.monotonic()
    frame = -1

    def status():
        return next(s for s in diag[-1].status if s.name == STATUS)

    while time.monotonic() < start_good + 15.0:
        frame = max(frame + 1, int((time.monotonic() - start_good) * NS) // FRAME_NS)
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(t_good + frame * FRAME_NS, NS)
        cmd.publish(msg)
        client.spin(0.005)
        if time.monotonic() - start_good > 2.5 and status().level == DiagnosticStatus.OK:
            break
    return frame + 1, status()


def test_every_dropped_command_is_counted_and_logged_and_diagnostics_recover(client, tmp_path):
    log = tmp_path / "emac.log"
    # the burst's stamps run 50 s ahead of the wall: a node stalled in it (a loaded machine) must still judge the
    # commands after the stall as lost, not as future stamps (config/emac.yaml: a burst may run ahead by less)
    proc = start(client.did, "ema_sim.nodes.emac", "--channel", "left_wing",
                 "--ros-args", "-p", "emac.stamp_tolerance_s:=120.0", log=log)
    diag = []
    try:
        client.node.create_subscription(DiagnosticArray, "/diagnostics", diag.append, 100)
        # the node's own depth (ct.FRAME_QOS): a node starved of CPU gets the good commands repaired, not lost; the
        # burst still overruns it
        cmd = client.node.create_publisher(JointState, "/ema/emac/command", QoSProfile(depth=1000))
        assert client.spin(60, lambda: cmd.get_subscription_count() > 0 and len(diag) > 0)
        cmd.publish(JointState(name=["tail", "canard"], position=[0.1, 0.2]))   # no such channels
        cmd.publish(JointState(name=[], position=[0.3]))                         # no names
        cmd.publish(JointState(name=["left_wing", "tail"], position=[0.5]))      # ours first, arrays short
        client.spin(0.3)
        base = (time.time_ns() // FRAME_NS + 200) * FRAME_NS
        msg = JointState(name=["left_wing"], position=[command_v(1.0)])
        for k in range(10_000):  # a burst: far faster than the node's frames
            msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(base + k * FRAME_NS, NS)
            cmd.publish(msg)
        client.spin(1.0)
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(base + 10_000 * FRAME_NS, NS)
        cmd.publish(msg)  # the last frame: every gap before it is known
        client.spin(0.5)
        faulted = [s for m in diag for s in m.status if s.level == DiagnosticStatus.WARN and "dropped" in s.message]
        assert faulted
        good, last = _good_commands_until_nominal(client, cmd, msg, base + 10_001 * FRAME_NS, diag)
        assert (last.level, last.message) == (DiagnosticStatus.OK, "nominal"), \
            f"{last.message}: " + ", ".join(f"{v.key}={v.value}" for v in last.values)
        burst = 10_001

        def accounted():  # the last good commands may still be on their way: stopping now would not count them
            values = {v.key: v.value for s in diag[-1].status if s.name == STATUS for v in s.values}
            return (int(values["commands"]) + int(values["dropped_lost_commands"]) + int(values["gap_frames"])
                    == burst + good)
        ok = client.spin(15.0, accounted)
        values = {v.key: v.value for s in diag[-1].status if s.name == STATUS for v in s.values}
        assert ok, f"the node never accounted for every frame sent ({good} good after the burst): {values}"
    finally:
        stop(proc)
    s = summary(log)
    dropped = s["dropped"]
    assert (dropped["unknown_names"], dropped["no_names"], dropped["malformed"]) == (1, 1, 1)  # one a message
    # every frame of the burst and of the good commands after it: taken, lost (a queue that overflowed) or a gap
    # (the wall time had room for it: the good commands' publisher paused)
    assert s["commands"] + dropped["lost_commands"] + s["gap_frames"] == burst + good
    assert int(values["dropped_lost_commands"]) == dropped["lost_commands"]
    text = log.read_text()
    assert "unknown joint(s) 'tail', 'canard'" in text
    assert "without joint names" in text
    assert "names and 1 position values" in text
    if dropped["lost_commands"]:
        assert "frame(s) of commands lost" in text


# --------------------------------------------------------------------------- 7. the launcher owns its nodes
def _children(pid):
    out = []
    for task in Path(f"/proc/{pid}/task").iterdir():
        out += [int(x) for x in (task / "children").read_text().split()]
    return out


def _alive(pid):
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except FileNotFoundError:
        return False
    return state != "Z"


@pytest.mark.parametrize("sig", [signal.SIGHUP, signal.SIGTERM, signal.SIGKILL], ids=["hup", "term", "kill"])
def test_no_node_outlives_the_launcher_and_the_bag_is_closed(client, tmp_path, sig):
    """``ema launch`` in a namespace: every topic under it; SIGHUP, SIGTERM or SIGKILL of the launcher ends every
    node (the kernel's parent-death signal when the launcher cannot act), each bag closed and complete."""
    from rosbags.rosbag2 import Reader  # noqa: PLC0415

    bag = tmp_path / "run"
    env = dict(os.environ, ROS_DOMAIN_ID=str(client.did), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    cmd = [sys.executable, "-m", "ema_sim.cli", "launch", "--maneuver", "ramp:rate_dps=0.05,peak_deg=5", "--lockstep",
           "--layout", "container", "--bag", str(bag), "--namespace", "/aircraft2"]
    with (tmp_path / "launch.out").open("w") as out:
        proc = subprocess.Popen(cmd, env=env, stdout=out, stderr=subprocess.STDOUT, start_new_session=True)
    try:
        log = tmp_path / "run.logs" / "maneuver.log"
        assert client.spin(90, lambda: log.is_file() and "running" in log.read_text()), (tmp_path / "launch.out")
        kids = _children(proc.pid)
        assert len(kids) == 2  # the container (EMACs, test environment, clock) and the maneuver

        def run_topics():  # the run's topics as the graph shows them (discovery takes longer under load)
            return {n for n, _ in client.node.get_topic_names_and_types()} - {"/rosout", "/parameter_events"}

        assert client.spin(60, lambda: any(t.startswith("/aircraft2/") for t in run_topics())), run_topics()
        seen = []  # the run is under way: the FMU's commands flow (the recorder, a little behind, has over 100)
        client.node.create_subscription(JointState, "/aircraft2/ema/fmu/command", seen.append, RELIABLE)
        assert client.spin(60, lambda: len(seen) > 300), len(seen)
        topics = run_topics()
        assert all(t.startswith("/aircraft2/") for t in topics - {"/clock", "/diagnostics"}), sorted(topics)
        os.kill(proc.pid, sig)
        proc.wait(timeout=30)
        assert client.spin(30, lambda: not any(_alive(k) for k in kids)), [k for k in kids if _alive(k)]
    finally:
        if proc.poll() is None:
            proc.kill()
    with Reader(bag) as reader:  # metadata.yaml written: closed, not cut
        counts = {c.topic: c.msgcount for c in reader.connections}
    assert counts["/ema/fmu/command"] > 100  # recorded under the contract's names
    assert counts["/ema/emac/feedback"] > 100
