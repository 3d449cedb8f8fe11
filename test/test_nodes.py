"""The node suite as real processes, each test on its own ROS_DOMAIN_ID (derived from the pid)."""

import json
import math
import os
import signal
import subprocess
import sys
import time
from types import SimpleNamespace

import numpy as np
import pytest
import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from sensor_msgs.msg import JointState
from std_msgs.msg import String

from ema_msgs_py.ros import qos
from ema_sim.cli import main as ema
from ema_sim.config import CHANNELS, scaling
from ema_sim.emac import EmacChannel, EmacSettings
from ema_sim.environment import load_profile
from ema_sim.io.bag import bag_info, read_bag
from ema_sim.models import create
from ema_sim.nodes.common import make_executor
from ema_sim.nodes.frametimes import CAUSES
from ema_sim.suite import Suite, SuiteConfig, free_domain_id, run_suite

pytestmark = pytest.mark.ros
FRAME = 0.005


def domain(offset):
    return free_domain_id(os.getpid() + 17 * offset)


# --------------------------------------------------------------------------- lockstep, AIL profile
AIL_RUN = {"model": "loada", "profile": "ail", "maneuver": "steps:amps_deg=1/5,lead_s=0.2,hold_s=0.5",
           "load": "sine:amp_inlb=300,freq_hz=1", "channels": ["left_wing"], "lockstep": True}


@pytest.fixture(scope="module")
def lockstep_ail(tmp_path_factory):
    """One process per node, one EMAC node per channel."""
    bag = tmp_path_factory.mktemp("suite") / "ail"
    cfg = SuiteConfig(bag=bag, layout="processes", emac="channels", domain_id=domain(1), **AIL_RUN)
    summaries = run_suite(cfg, timeout_s=240)
    return bag, summaries


@pytest.fixture(scope="module", params=[("single", "box"), ("container", "channels")])
def lockstep_composed(request, tmp_path_factory):
    """The composed layouts: everything in one process with the EMAC box (the default), and the EMAC
    channel nodes, test environment and clock in one process with the maneuver node in another."""
    layout, emac = request.param
    bag = tmp_path_factory.mktemp("suite") / f"ail_{layout}"
    cfg = SuiteConfig(bag=bag, layout=layout, emac=emac, domain_id=domain(6 + len(layout)), **AIL_RUN)
    summaries = run_suite(cfg, timeout_s=240)
    return bag, summaries, layout, emac


def test_lockstep_records_every_frame_of_every_channel_exactly_once(lockstep_ail):
    bag, summaries = lockstep_ail
    frames = 440  # 2.2 s at 200 Hz
    info = bag_info(bag)
    assert info.complete
    assert info.topics["/ema/fmu/command"][1] == frames
    assert info.topics["/ema/emac/command"][1] == frames
    assert info.topics["/ema/emac/feedback"][1] == 5 * (frames + 1)  # five EMACs, trim state + one per frame
    assert info.topics["/ema/fmu/feedback"][1] == 5 * (frames + 1)
    assert info.channels == list(CHANNELS)
    assert summaries["simclock"]["frames"] == frames
    assert summaries["simclock"]["stalls"] == 0
    for ch in CHANNELS:
        emac = summaries[f"emac_{ch}"]
        assert emac["counters"][ch]["frames"] == frames
        assert emac["waits_given_up"] == 0
    meta = read_bag(bag).metadata
    assert (meta["test"], meta["model"], meta["profile"], meta["clock"]) == ("steps", "loada", "ail", "lockstep")


def test_the_test_environment_is_exactly_the_ail_profile_in_both_directions(lockstep_ail):
    bag, _ = lockstep_ail
    fmu, emac = read_bag(bag, side="fmu"), read_bag(bag)
    stream = CHANNELS.index("left_wing")
    cmd_path = load_profile("ail").command_path(FRAME, stream, fmu.command_v[0])
    assert emac.command_v == pytest.approx([cmd_path.step(v) for v in fmu.command_v], abs=1e-12)
    fb_path = load_profile("ail").feedback_path(FRAME, stream, emac.position_v[0])
    assert fmu.position_v == pytest.approx([fb_path.step(v) for v in emac.position_v], abs=1e-12)
    lag = np.argmax(np.abs(emac.command_deg) > 0.5) - np.argmax(np.abs(fmu.command_deg) > 0.5)
    assert lag * FRAME == pytest.approx(0.026, abs=2 * FRAME)  # the 26 ms harness delay (plus the 50 Hz lag)


def test_lockstep_advances_the_model_exactly_once_per_frame(lockstep_ail):
    """Replaying the EMAC's recorded inputs through the same model, frame by frame, gives the bag bit for bit."""
    bag, _ = lockstep_ail
    data = read_bag(bag)
    replay = EmacChannel(create("loada", "left_wing"), EmacSettings())
    positions, surfaces = [replay.last.position_v], [replay.last.surface_deg]
    for v, hm in zip(data.command_v[:-1], data.hinge_moment_inlb[:-1], strict=True):
        replay.set_command(v)
        replay.set_load(hm)
        fb = replay.step(0.0)
        positions.append(fb.position_v)
        surfaces.append(fb.surface_deg)
    assert data.position_v == pytest.approx(positions, abs=1e-12)
    assert data.surface_deg == pytest.approx(surfaces, abs=1e-12)
    assert 5.0 < data.position_deg.max() < 5.5  # the 5° step, with the second order's overshoot
    assert np.ptp(data.hinge_moment_inlb) == pytest.approx(600.0, abs=1.0)


def test_crosstalk_shows_on_the_right_wing_feedback_while_the_left_wing_slews(lockstep_ail):
    """Every channel moves a little with the AIL command noise; only the right wing's feedback jumps."""
    bag, _ = lockstep_ail
    settled = slice(100, None)  # after the release from the start-up brake

    def jumps(channel):
        return np.abs(np.diff(read_bag(bag, channel).position_v[settled])).max()

    assert 0.005 < jumps("right_wing") <= 0.0201  # section 2.2.1: ≈ 0.02 V peak to peak
    for other in ("left_rudder", "right_rudder", "cowl_door"):
        assert jumps(other) < 0.003  # nominal: only the actuator's smooth response to the command noise


def test_a_lockstep_bag_is_dated_when_recorded_and_its_rosout_is_in_the_suites_time(lockstep_ail):
    """The log times are the stamps from the recording's start (not 1970); ``/rosout`` entries, stamped by rcl
    with the system clock, are restamped with the suite's time: each sits with the frames it speaks of."""
    from rosbags.rosbag2 import Reader  # noqa: PLC0415

    from ema_msgs_py import typestore as ts  # noqa: PLC0415

    bag, _ = lockstep_ail
    epoch = int(read_bag(bag).metadata["sim_epoch_ns"])
    assert 0 < time.time_ns() - epoch < 3600 * 10**9  # the recording's start: today, not 1970
    with Reader(bag) as reader:
        assert reader.start_time >= epoch
        feedback = [c for c in reader.connections if c.topic == "/ema/emac/feedback"]
        for _, log_time, raw in reader.messages(connections=feedback):
            msg = ts.deserialize(raw, "sensor_msgs/msg/JointState")
            assert log_time == epoch + msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec
        rosout = [c for c in reader.connections if c.topic == "/rosout"]
        entries = [(t, ts.deserialize(raw, "rcl_interfaces/msg/Log"))
                   for _, t, raw in reader.messages(connections=rosout)]
    assert len(entries) >= 4  # every node's start-up line at least
    run_ns = round(2.2 * 10**9)  # the run: 440 frames
    for log_time, entry in entries:
        stamp = entry.stamp.sec * 10**9 + entry.stamp.nanosec
        assert 0 <= stamp <= run_ns, (entry.name, entry.msg)  # the suite's time, not the system clock's
        assert log_time == epoch + stamp


def test_composed_layouts_record_the_same_bag_as_one_process_per_node(lockstep_ail, lockstep_composed):
    """In-process hand-over changes nothing a frame carries: every value of every channel, both sides."""
    bag, _, layout, emac = lockstep_composed
    reference, _ = lockstep_ail
    frames = 440
    info = bag_info(bag)
    assert info.complete
    assert info.channels == list(CHANNELS)
    for topic, per_channel in (("/ema/emac/feedback", frames + 1), ("/ema/sensor/surface", frames + 1),
                               ("/ema/fmu/feedback", frames + 1), ("/ema/emac/command", frames)):
        names = [n for m in _messages(bag, topic) for n in m.name]
        assert sorted(names) == sorted(list(CHANNELS) * per_channel), (layout, topic)  # each channel once a frame
    for ch in CHANNELS:
        for side in ("emac", "fmu"):
            got, want = read_bag(bag, ch, side=side), read_bag(reference, ch, side=side)
            assert np.array_equal(got.time_s, want.time_s)
            assert np.array_equal(got.command_v, want.command_v), (layout, emac, ch, side)
            assert np.array_equal(got.position_v, want.position_v), (layout, emac, ch, side)
            assert np.array_equal(got.surface_deg, want.surface_deg), (layout, emac, ch, side)
    assert read_bag(bag).metadata["clock"] == "lockstep"


def test_a_container_runs_until_its_driver_outside_is_done(tmp_path):
    """The composed clock's last frame does not end the container: the last frames its nodes hand out may not
    have reached the maneuver in the other process yet (seen under load: a bag short of its last two frames)."""
    suite = Suite(SuiteConfig(bag=tmp_path / "bag", layout="container", emac="box", lockstep=True, maneuver="step",
                              duration_s=0.2, domain_id=domain(9)))
    suite.start()
    try:
        assert suite.wait(120) == 0
        alive = suite.procs["container"].poll() is None
    finally:
        suite.stop()
    assert alive
    summaries = suite.summaries()
    assert summaries["simclock"]["frames"] == 40
    assert summaries["maneuver"]["messages"]["/ema/emac/feedback"] == 41  # trim state + one per frame


def _messages(bag, topic):
    from rosbags.rosbag2 import Reader  # noqa: PLC0415

    from ema_msgs_py import typestore as ts  # noqa: PLC0415

    with Reader(bag) as reader:
        conns = [c for c in reader.connections if c.topic == topic]
        return [ts.deserialize(raw, "sensor_msgs/msg/JointState") for _, _, raw in reader.messages(connections=conns)]


# --------------------------------------------------------------------------- real time
@pytest.mark.parametrize("layout", ["single", "container"])
def test_real_time_run_measures_command_to_feedback_latency(tmp_path, layout):
    bag = tmp_path / "rt"
    rt = 20 if layout == "single" else 0  # the real-time set-up, where the machine allows it
    cfg = SuiteConfig(bag=bag, model="loada", profile="flight", maneuver="steps:amps_deg=20,lead_s=0.2,hold_s=0.5",
                      channels=["left_wing"], emac_box=True, layout=layout, domain_id=domain(2 + 11 * len(layout)),
                      rt_priority=rt)
    summaries = run_suite(cfg, timeout_s=120)
    man = summaries["maneuver"]
    assert man["frames_commanded"] == man["frames"] == 240
    assert man["answered"] > 0
    assert 0.0 < man["latency_p50_ms"] <= man["latency_p99_ms"] <= man["latency_max_ms"]
    causes = {k: v for k, v in man.items() if k.startswith("missed_") and k != "missed_frames"}
    if layout == "single":  # the whole feedback path in the maneuver's thread: every missed frame has a cause
        assert set(causes) == {f"missed_{c}" for c in CAUSES}
        assert sum(causes.values()) == man["missed_frames"]
        assert set(man["realtime"]) >= {"sched_fifo", "memory_locked", "cpu_latency_us"}
        assert man["realtime"]["sched_fifo"] in (0, rt)
    else:
        assert not causes
        assert "realtime" not in man
    data = read_bag(bag)
    assert data.metadata["clock"] == "realtime"
    assert float(data.metadata["realtime.frames"]) == 240
    assert 19.9 < data.position_deg.max() < 20.6
    right = read_bag(bag, "right_wing").position_v[40:]  # in an EMAC box the channels couple inside it
    assert 0.008 < np.abs(np.diff(right)).max() <= 0.0201  # 35 frames of full slew: noise up to ±0.01 V


# --------------------------------------------------------------------------- SIGTERM keeps the bag
def test_sigterm_mid_run_leaves_a_readable_bag(tmp_path):
    bag = tmp_path / "cut"
    suite = Suite(SuiteConfig(bag=bag, maneuver="ramp:rate_dps=0.05,peak_deg=5", lockstep=True, emac_box=True,
                              domain_id=domain(3)))
    suite.start()
    try:
        log = suite.log_dir / f"{suite.fmu_process}.log"
        deadline = time.monotonic() + 60
        while "running" not in log.read_text() and time.monotonic() < deadline:
            time.sleep(0.1)
        time.sleep(3.0)
        man = suite.procs[suite.fmu_process]
        os.kill(man.pid, signal.SIGTERM)
        assert man.wait(timeout=20) == 0
    finally:
        suite.stop()
    info = bag_info(bag)
    assert info.complete
    data = read_bag(bag)
    assert len(data) >= 100
    assert data.metadata["completed"] == "false"
    assert int(data.metadata["frames_commanded"]) < int(data.metadata["frames"])


def test_ema_launch_stops_cleanly_on_sigterm_and_leaves_a_complete_bag(tmp_path):
    bag = tmp_path / "launch"
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain(5)))
    cmd = [sys.executable, "-m", "ema_sim.cli", "launch", "--maneuver", "ramp:rate_dps=0.05,peak_deg=5",
           "--lockstep", "--emac-box", "--bag", str(bag)]
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    log = tmp_path / "launch.logs" / "suite.log"  # the default layout: every node in one process
    deadline = time.monotonic() + 60
    while not (log.is_file() and "running" in log.read_text()) and time.monotonic() < deadline:
        time.sleep(0.1)
    time.sleep(2.0)
    proc.send_signal(signal.SIGTERM)
    out, _ = proc.communicate(timeout=30)
    assert proc.returncode == 130
    assert "interrupted; closing the bag" in out
    for node_log in (tmp_path / "launch.logs").glob("*.log"):
        assert "EMA_SUMMARY" in node_log.read_text(), node_log.name  # every node stopped on its own
    data = read_bag(bag)
    assert bag_info(bag).complete
    assert data.metadata["completed"] == "false"
    assert len(data) >= 100


@pytest.mark.parametrize("when", ["importing", "nodes importing"])
def test_ema_launch_interrupted_in_its_first_second_prints_no_traceback(tmp_path, when):
    """Ctrl-C while ``ema`` imports its command, or once the suite's processes are started and importing: one
    line, status 130, no traceback anywhere (the nodes, stopped with SIGTERM, end quietly). Python's verbose
    imports say when each process is importing (numpy: well into its imports)."""
    bag = tmp_path / "early"
    logs = tmp_path / "early.logs"
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain(12 + len(when))), PYTHONUNBUFFERED="1", PYTHONVERBOSE="1")
    cmd = [sys.executable, "-m", "ema_sim.cli", "launch", "--maneuver", "step", "--lockstep", "--layout",
           "processes", "--bag", str(bag)]
    # Ctrl-C as a terminal's foreground job gets it: a test worker may ignore SIGINT, which a child inherits
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))  # noqa: PLW1509
    mark = "import 'numpy'" if when == "importing" else "ema launch:"
    seen = ""
    while mark not in seen:
        seen = proc.stdout.readline()
        assert seen, "ema ended before it got there"
    if when == "nodes importing":
        deadline = time.monotonic() + 60
        names = {"emac.log", "testenv.log", "simclock.log", "maneuver.log"}
        while not (names <= {p.name for p in logs.glob("*.log")}
                   and all("import 'numpy'" in (logs / n).read_text(errors="replace") for n in names)):
            assert time.monotonic() < deadline, "the nodes never imported numpy"
            assert proc.poll() is None
        assert not any("EMA_SUMMARY" in p.read_text(errors="replace") for p in logs.glob("*.log"))
    proc.send_signal(signal.SIGINT)
    out, _ = proc.communicate(timeout=60)
    assert "Traceback" not in out, out[-3000:]
    assert proc.returncode == 130, (proc.returncode, out[-3000:])  # what the process said, should it ever not be
    assert ("ema: interrupted" if when == "importing" else "ema launch: interrupted; closing the bag") in out
    for node_log in logs.glob("*.log"):
        assert "Traceback" not in node_log.read_text(errors="replace"), node_log.name


# --------------------------------------------------------------------------- bad messages, failures
@pytest.fixture(scope="module")
def ros_context():
    """rclpy in this process (once per module), on a domain of its own."""
    did = domain(4)
    saved = {k: os.environ.get(k) for k in ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE")}
    os.environ["ROS_DOMAIN_ID"] = str(did)
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"

    rclpy.init()
    yield did
    rclpy.shutdown()
    for key, value in saved.items():
        if value is None:
            os.environ.pop(key, None)
        else:
            os.environ[key] = value


@pytest.fixture
def ros_probe(ros_context, request):


    node = rclpy.create_node(f"probe_{request.node.name[:40].replace('-', '_').replace('[', '_').replace(']', '_')}")
    ex = make_executor()
    ex.add_node(node)
    yield ros_context, node, ex
    ex.remove_node(node)
    node.destroy_node()


def spin_until(ex, cond, timeout=15.0):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if cond():
            return True
        ex.spin_once(timeout_sec=0.01)
    return cond()


def start_node(did, module, *args, log=None):
    env = dict(os.environ, ROS_DOMAIN_ID=str(did), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", PYTHONUNBUFFERED="1")
    out = subprocess.DEVNULL if log is None else log.open("w")
    return subprocess.Popen([sys.executable, "-m", f"ema_sim.nodes.{module}", *args], env=env,
                            stdout=out, stderr=subprocess.STDOUT, text=True)


def send_garbage(cmd, load):
    for bad in ([math.nan], [math.inf], [-math.inf], [1e9], []):
        cmd.publish(JointState(name=["left_wing"], position=bad))
    cmd.publish(JointState(name=["left_wing", "tail"], position=[0.5]))
    cmd.publish(JointState(name=["nobody"], position=[3.0]))
    load.publish(JointState(name=["left_wing"], effort=[math.nan]))


def test_a_node_never_dies_on_bad_messages_and_failures_switch_at_run_time(ros_probe, tmp_path):


    did, node, ex = ros_probe
    log = tmp_path / "emac.log"
    proc = start_node(did, "emac", "--model", "loada", "--channel", "left_wing", log=log)
    try:
        fb, diag = [], {}
        node.create_subscription(JointState, "/ema/emac/feedback", fb.append, qos("/ema/emac/feedback"))
        node.create_subscription(DiagnosticArray, "/diagnostics",
                                 lambda m: diag.update({s.name: {v.key: v.value for v in s.values} for s in m.status}),
                                 qos("/diagnostics"))
        cmd = node.create_publisher(JointState, "/ema/emac/command", qos("/ema/emac/command"))
        load = node.create_publisher(JointState, "/ema/load/hinge_moment", qos("/ema/load/hinge_moment"))
        fail = node.create_publisher(String, "/ema/emac/left_wing/failure", qos("/ema/emac/command"))
        assert spin_until(ex, lambda: len(fb) > 5 and cmd.get_subscription_count() > 0)
        sc = scaling("left_wing")

        held = {"deg": 0.0}

        def command(deg, seconds, until=None):
            held["deg"] = deg
            end = time.monotonic() + seconds
            while time.monotonic() < end and not (until is not None and until()):
                cmd.publish(JointState(name=["left_wing"], position=[sc.command_deg_to_v(deg)]))
                spin_until(ex, lambda: False, 0.005)

        def failure(spec):  # switch, holding the last command until the node says it switched
            fail.publish(String(data=spec))
            command(held["deg"], 15.0, until=lambda: diag.get("/emac_left_wing: left_wing", {}).get("failure") == spec)
            assert diag["/emac_left_wing: left_wing"]["failure"] == spec

        command(2.0, 1.0)
        send_garbage(cmd, load)
        command(2.0, 1.0)
        assert proc.poll() is None
        values = np.array([p for m in fb for p in m.position])
        assert np.isfinite(values).all()
        assert sc.feedback_v_to_deg(fb[-1].position[0]) == pytest.approx(2.0, abs=0.05)
        failure("stuck")
        command(6.0, 1.0)
        assert sc.feedback_v_to_deg(fb[-1].position[0]) == pytest.approx(2.0, abs=0.05)
        failure("none")
        command(6.0, 1.0)
        assert sc.feedback_v_to_deg(fb[-1].position[0]) == pytest.approx(6.0, abs=0.05)
        fail.publish(String(data="melt"))  # an unknown failure is refused, the node goes on
        command(6.0, 0.3)
        assert proc.poll() is None
    finally:
        proc.send_signal(signal.SIGTERM)
        proc.wait(timeout=20)
    assert proc.returncode == 0
    check_counters(log.read_text())


def check_counters(out):
    summary = json.loads(next(line for line in out.splitlines() if line.startswith("EMA_SUMMARY "))[12:])
    counters = summary["counters"]["left_wing"]
    assert counters["rejected_commands"] == counters["clamped_commands"] == counters["rejected_loads"] == 0
    # NaN, ±inf, 1e9 V, no value, short arrays, a NaN load (none applied) and the unknown failure request
    assert summary["dropped"]["malformed"] == 8
    assert summary["dropped"]["unknown_names"] == 1
    assert "failure request ignored" in out


def test_ros2_control_drives_the_suite_through_the_joint_state_pair(ros_probe, tmp_path):


    did, node, ex = ros_probe
    procs = [start_node(did, "emac", "--model", "loada", "--channel", "all"),
             start_node(did, "testenv", "--profile", "none"),
             start_node(did, "bridge", log=tmp_path / "bridge.log")]
    try:
        states = []
        node.create_subscription(JointState, "/ema/joint_states", states.append, qos("/ema/joint_states"))
        cmd = node.create_publisher(JointState, "/ema/joint_commands", 1)  # topic_based_ros2_control's QoS(1)
        assert spin_until(ex, lambda: cmd.get_subscription_count() > 0, 30)
        assert spin_until(ex, lambda: bool(states) and len(states[-1].name) == len(CHANNELS), 30)
        target = {"left_wing": 0.05, "right_rudder": -0.1}
        end = time.monotonic() + 2.0
        while time.monotonic() < end:
            cmd.publish(JointState(name=list(target), position=list(target.values())))
            spin_until(ex, lambda: False, 0.02)
        last = states[-1]
        assert list(last.name) == list(CHANNELS)  # every joint in every message
        got = dict(zip(last.name, last.position, strict=True))
        for joint, rad in target.items():
            assert got[joint] == pytest.approx(rad, abs=1e-3)
        assert got["cowl_door"] == pytest.approx(0.0, abs=1e-3)
        assert len(last.velocity) == len(last.name)
    finally:
        for p in procs:
            p.send_signal(signal.SIGTERM)
        for p in procs:
            p.wait(timeout=20)
    assert all(p.returncode == 0 for p in procs)


# --------------------------------------------------------------------------- executor, CLI
def test_the_executor_is_the_events_executor_and_its_spin_loop_delivers_and_times_out(ros_probe):

    _, node, ex = ros_probe
    assert "EventsExecutor" in type(ex).__name__
    got = []
    node.create_subscription(String, "/loop", got.append, 100)
    pub = node.create_publisher(String, "/loop", 100)
    for i in range(50):
        pub.publish(String(data=str(i)))
    assert spin_until(ex, lambda: len(got) == 50, 10)
    assert [m.data for m in got] == [str(i) for i in range(50)]
    t0 = time.monotonic()
    ex.spin_once(timeout_sec=0.05)
    assert 0.03 < time.monotonic() - t0 < 1.0  # nothing to do: returns at its timeout (our loop keeps deadlines)


@pytest.mark.parametrize(("args", "message"), [
    (["--model", "hoad9", "--maneuver", "step"], "unknown model 'hoad9'"),
    (["--maneuver", "step", "--profile", "lab"], "unknown profile 'lab'"),
    (["--model", "loada"], "give --maneuver SPEC, --test SPEC"),
    (["--maneuver", "sweep"], "limits dynamic tests to 60 s"),
    (["--fmu", "--maneuver", "step"], "no --maneuver or --test with it"),
    (["--maneuver", "step", "--open-loop"], "add --fmu"),
    (["--fmu", "--disable", "flux"], "unknown element 'flux'"),
    (["--fmu", "--model", "loada", "--disable", "dead_band"], "loada has no PWM dead band"),
])
def test_launch_bad_input_is_one_line_and_status_2(tmp_path, capsys, args, message):
    assert ema(["launch", *args, "--bag", str(tmp_path / "b")]) == 2
    err = capsys.readouterr().err
    assert message in err
    assert len(err.strip().splitlines()) == 1
    assert not (tmp_path / "b").exists()


def test_a_lone_node_loop_polls_spins_and_stops_as_the_composed_loop_does():
    """A node alone in its process runs :func:`common._loop_one` (fewer calls a message): it announces readiness
    until sent, waits in the executor at most until the node's next deadline (never less than 0, never more than
    ``MAX_SPIN_S``), and stops when the node is done or a signal came, without spinning after the last poll."""
    from ema_sim.nodes import common  # noqa: PLC0415

    class Node:
        def __init__(self, timeouts):
            self.timeouts = list(timeouts)
            self.done, self.ends_process, self._ready_sent, self.checks = False, True, False, 0
            self.name_claim = SimpleNamespace(taken_by=None)  # no other node of its name

        def check_ready(self):
            self.checks += 1
            self._ready_sent = self.checks >= 2

        def poll(self):
            timeout = self.timeouts.pop(0)
            self.done = not self.timeouts
            return timeout

    class Executor:
        def __init__(self):
            self.waits = []

        def spin_once(self, timeout_sec):
            self.waits.append(timeout_sec)

    node, ex = Node([0.002, -0.001, 7.0, 0.0, 0.01]), Executor()
    common._loop([node], None, ex, {"signal": None})
    assert ex.waits == [0.002, 0.0, common.MAX_SPIN_S, 0.0]  # the last poll left the node done: no spin after it
    assert node.checks == 2  # until the announcement was sent

    node, ex = Node([0.01] * 5), Executor()
    stop = {"signal": None}

    def signalled(timeout_sec):  # a signal during the first wait
        assert timeout_sec == 0.01
        stop["signal"] = signal.SIGINT

    ex.spin_once = signalled
    common._loop([node], None, ex, stop)
    assert len(node.timeouts) == 4  # polled once, then stopped
