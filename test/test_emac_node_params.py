"""The EMAC node's parameters as ROS users write them, and its names as ROS tools expect them (issue 25).

In process, on a ROS domain of this module's own: parameter files under a namespace, a node-name remapping,
a copied and edited file and two vehicles on one graph; every declared parameter read back through the
standard GetParameters service, dumped and reloaded; ``/clock`` and ``/diagnostics`` absolute, statuses named
after the node's full name, ``frame_id`` set, ``use_sim_time`` honoured.
"""

import argparse
import time
from pathlib import Path
from types import SimpleNamespace

import pytest
import rclpy
import yaml
from rcl_interfaces.msg import ParameterType
from rcl_interfaces.srv import GetParameters, ListParameters, SetParameters
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from ros_context import ros_context
from test_ros_integration import READY_BOUND_S

from ema_msgs_py.cdr import JointFrame
from ema_sim.errors import ConfigError, EmaError
from ema_sim.nodes.emac import EmacNode
from ema_sim.nodes.emac_params import check_files
from ema_sim.nodes.params import key_matches
from ema_sim.nodes.ports import Ports
from ema_sim.run import from_launch_arguments

pytestmark = pytest.mark.ros
CONFIG = Path(__file__).resolve().parents[1] / "config"


class QuietPorts:
    """Test-only ports: no frame endpoints; the frames the node publishes are kept."""

    composed = False

    def __init__(self, node):
        self.node = node
        self.sent = {}

    def frame_publisher(self, topic):
        return SimpleNamespace(publish=self.sent.setdefault(topic, []).append)

    def frame_subscription(self, topic, callback, on_bad, *, at_frame=False):
        pass

    def take_at_frame(self):
        return 0

    def clock_subscription(self, callback):
        pass

    def publishers(self, topic):  # noqa: ARG002
        return 1

    def endpoint_nodes(self):
        return [self.node]


@pytest.fixture(scope="module")
def context():
    with ros_context(89) as ctx:
        yield ctx


@pytest.fixture
def emac(context):
    """``emac(*ros_args, channel=None)``: an EMAC node as ``emac [--channel C] --ros-args ...`` starts it."""
    nodes = []

    def make(*ros_args, channel=None, ports=QuietPorts):
        args = argparse.Namespace(**({"channels": [channel]} if channel else {}))
        node = EmacNode(args, ports=ports, context=context, cli_args=["--ros-args", *ros_args])
        nodes.append(node)
        return node

    yield make
    for node in nodes:
        node.destroy_node()


def _file(tmp_path, name, doc):
    path = tmp_path / name
    path.write_text(yaml.safe_dump(doc))
    return str(path)


def _copy(tmp_path, channel, key, **changes):
    """``config/<channel>.yaml``, copied under another key with some values edited."""
    (params,) = yaml.safe_load((CONFIG / f"{channel}.yaml").read_text()).values()
    params["ros__parameters"].update(changes)
    return _file(tmp_path, f"{channel}_copy.yaml", {key: params})


# --------------------------------------------------------------------------- which channel, from where
def test_the_rcl_key_rules():
    assert key_matches("/**", "/aircraft2/emac_left_wing")
    assert key_matches("/**/emac_left_wing", "/aircraft2/emac_left_wing")
    assert key_matches("emac_left_wing", "/emac_left_wing")
    assert not key_matches("emac_left_wing", "/aircraft2/emac_left_wing")  # a bare key is the root namespace's
    assert key_matches("/aircraft2/*", "/aircraft2/emac")
    assert not key_matches("/aircraft2/*", "/aircraft1/emac")


def test_a_channel_file_alone_runs_its_channel_in_any_namespace(emac):
    """Before, ``--params-file config/right_wing.yaml`` ran as the left wing."""
    for ns in ("/", "/aircraft2"):
        node = emac("--params-file", str(CONFIG / "right_wing.yaml"), "-r", f"__ns:={ns}")
        assert (node.get_namespace(), node.get_name(), node.channels) == (ns, "emac_right_wing", ["right_wing"])
        assert node.get_parameter("channel").value == "right_wing"
        assert node.get_parameter("command_cal_v").value[1] == pytest.approx(-0.234524)  # the right wing's curve
        node.destroy_node()


def test_a_node_name_remapping_gives_the_channel_and_a_conflict_is_one_error(emac):
    """Before, ``-r __node:=emac_right_wing`` ran a hybrid: right-wing calibration on the left-wing channel."""
    node = emac("-r", "__node:=emac_right_wing")
    assert node.channels == ["right_wing"]
    assert node.get_parameter("channel").value == "right_wing"
    node.destroy_node()
    with pytest.raises(ConfigError, match=r"given differently \(--channel: left_wing; the node's name "
                                          r"emac_right_wing: right_wing\)"):
        emac("-r", "__node:=emac_right_wing", channel="left_wing")
    with pytest.raises(ConfigError, match=r"keyed for emac_right_wing .* not for this node"):
        emac("--params-file", str(CONFIG / "right_wing.yaml"), channel="left_wing")
    with pytest.raises(ConfigError, match="give different channels"):
        emac("--params-file", str(CONFIG / "left_wing.yaml"), "--params-file", str(CONFIG / "right_wing.yaml"))


def test_a_copied_and_edited_file_applies_under_a_namespace_and_a_remapped_name(emac, tmp_path):
    """Before, ``free_play_deg: 0.555`` in a copied file under ``-r __ns:=`` gave 0.2 without a word."""
    wild = _copy(tmp_path, "right_wing", "/**", free_play_deg=0.555)
    node = emac("--params-file", wild, "-r", "__ns:=/vehicle1", "-r", "__node:=rw_emac")
    assert (node.get_fully_qualified_name(), node.channels) == ("/vehicle1/rw_emac", ["right_wing"])
    assert node.get_parameter("free_play_deg").value == 0.555
    assert node.units["right_wing"].model.channel.free_play_deg == 0.555
    node.destroy_node()
    bare = _copy(tmp_path, "left_wing", "emac_left_wing", free_play_deg=0.555)  # a bare key: the root namespace's
    node = emac("--params-file", bare, "-r", "__ns:=/vehicle1")
    warned = []
    check_files(["--ros-args", "--params-file", bare], node.get_namespace(), node.get_name(),
                node.get_fully_qualified_name(), SimpleNamespace(warning=warned.append))
    assert node.get_parameter("free_play_deg").value == 0.2  # rcl's rule, said out loud
    assert "applies to /emac_left_wing only" in warned[0]
    assert "'/**/emac_left_wing'" in warned[0]


def test_two_vehicles_on_one_graph_take_their_own_sections_of_one_file(emac, tmp_path):
    both = _file(tmp_path, "fleet.yaml", {
        "/vehicle1/emac_left_wing": {"ros__parameters": {"free_play_deg": 0.3}},
        "/vehicle2/emac_left_wing": {"ros__parameters": {"free_play_deg": 0.4}},
    })
    one = emac("--params-file", both, "-r", "__ns:=/vehicle1")
    two = emac("--params-file", both, "-r", "__ns:=/vehicle2")
    assert [n.get_parameter("free_play_deg").value for n in (one, two)] == [0.3, 0.4]
    names = []
    for node in (one, two):
        node.diag_pub = SimpleNamespace(publish=lambda m: names.extend(s.name for s in m.status))
        node._publish_diagnostics()
    assert names == ["/vehicle1/emac_left_wing: left_wing", "/vehicle2/emac_left_wing: left_wing"]  # no collision


# --------------------------------------------------------------------------- through the standard services
def _call(ex, client, request):
    assert client.wait_for_service(timeout_sec=READY_BOUND_S)  # the node is in this process: a bound, not a wait
    future = client.call_async(request)
    end = time.monotonic() + READY_BOUND_S
    while not future.done() and time.monotonic() < end:
        ex.spin_once(timeout_sec=0.01)
    assert future.done()
    return future.result()


def _value(v):
    return {ParameterType.PARAMETER_BOOL: v.bool_value, ParameterType.PARAMETER_INTEGER: v.integer_value,
            ParameterType.PARAMETER_DOUBLE: v.double_value, ParameterType.PARAMETER_STRING: v.string_value,
            ParameterType.PARAMETER_BOOL_ARRAY: list(v.bool_array_value),
            ParameterType.PARAMETER_INTEGER_ARRAY: list(v.integer_array_value),
            ParameterType.PARAMETER_DOUBLE_ARRAY: list(v.double_array_value),
            ParameterType.PARAMETER_STRING_ARRAY: list(v.string_array_value)}[v.type]


def _dump(ex, probe, fqn):
    """Every parameter of a node through ListParameters and GetParameters, as ``ros2 param dump`` reads them."""
    names = list(_call(ex, probe.create_client(ListParameters, f"{fqn}/list_parameters"),
                       ListParameters.Request()).result.names)
    values = _call(ex, probe.create_client(GetParameters, f"{fqn}/get_parameters"),
                   GetParameters.Request(names=names)).values
    assert len(values) == len(names)  # before, any request naming peers or disable came back empty
    return dict(zip(names, map(_value, values), strict=True))


def test_every_parameter_reads_back_through_get_parameters_and_a_dump_reloads(context, emac, tmp_path):
    probe = rclpy.create_node("probe", context=context)
    ex = SingleThreadedExecutor(context=context)
    try:
        node = emac("-r", "__ns:=/vehicle1")
        ex.add_node(node)
        ex.add_node(probe)
        got = _dump(ex, probe, "/vehicle1/emac_left_wing")
        assert {k: got[k] for k in ("peers", "disable", "channels", "frame_id")} == {
            "peers": [], "disable": [], "channels": ["left_wing"], "frame_id": "left_wing"}
        assert len(got) > 100
        refused = _call(ex, probe.create_client(SetParameters, "/vehicle1/emac_left_wing/set_parameters"),
                        SetParameters.Request(parameters=[Parameter("use_sim_time", value=True).to_parameter_msg()]))
        assert not refused.results[0].successful
        assert "read when the node starts" in refused.results[0].reason
        doc = {}
        for name, value in got.items():  # nested by the dots, as ros2 param dump writes it
            *path, leaf = name.split(".")
            here = doc
            for part in path:
                here = here.setdefault(part, {})
            here[leaf] = value
        dumped = _file(tmp_path, "dump.yaml", {"/vehicle1/emac_left_wing": {"ros__parameters": doc}})
        ex.remove_node(node)
        node.destroy_node()
        again = emac("--params-file", dumped, "-r", "__ns:=/vehicle1")
        ex.add_node(again)
        assert _dump(ex, probe, "/vehicle1/emac_left_wing") == got
    finally:
        ex.shutdown()
        probe.destroy_node()


# --------------------------------------------------------------------------- ROS conventions
def test_clock_and_diagnostics_are_absolute_feedback_has_a_frame_and_use_sim_time_selects_lockstep(emac):
    node = emac("-r", "__ns:=/vehicle1", "-p", "use_sim_time:=true", ports=Ports)
    assert node.lockstep
    subs = {s.topic_name for s in node.subscriptions}
    pubs = {p.topic_name for p in node.publishers}
    assert "/clock" in subs  # before: /vehicle1/clock, and no frame from the graph's clock
    assert "/diagnostics" in pubs
    assert {"/vehicle1/ema/emac/command", "/vehicle1/ema/emac/feedback"} <= subs | pubs
    node.destroy_node()
    box = emac("-p", "frame_id:=emac_box_7", channel="all")
    for sent in box.ports.sent.values():
        sent.clear()
    box._publish(0, {ch: u.last for ch, u in box.units.items()})
    frames = [f for msgs in box.ports.sent.values() for f in msgs]
    assert frames
    assert all(isinstance(f, JointFrame) and f.frame_id == "emac_box_7" for f in frames)
    assert emac(channel="cowl_door").frame_id == "cowl_door"  # by default: the channel's name
    assert from_launch_arguments({"maneuver": "step", "use_sim_time": "true"}, "single").lockstep
    with pytest.raises(EmaError, match="disagree"):
        from_launch_arguments({"maneuver": "step", "lockstep": "true", "use_sim_time": "false"}, "single")


# --------------------------------------------------------------------------- a standby's head start
def test_a_standby_warms_the_model_its_node_will_build(tmp_path):
    """``warm`` builds the model the node's own sections name (remapped name or flags), not another node's."""
    import subprocess  # noqa: PLC0415
    import sys  # noqa: PLC0415

    from ema_sim.nodes.emac import warm  # noqa: PLC0415

    params = tmp_path / "run.yaml"
    params.write_text(yaml.safe_dump({"emac_left_wing": {"ros__parameters": {"model": "nosuch"}},
                                      "emac_right_wing": {"ros__parameters": {"model": "loada",
                                                                              "channels": ["right_wing"]}}}))
    warm(["--ros-args", "--params-file", str(params), "-r", "__node:=emac_right_wing"])  # the left wing's is not read
    with pytest.raises(EmaError, match="unknown model 'nosuch'"):
        warm(["--ros-args", "--params-file", str(params), "-r", "__node:=emac_left_wing"])
    with pytest.raises(EmaError, match="unknown model 'nosuch'"):
        warm(["--model", "nosuch", "--channel", "right_wing"])
    # a standby whose head start fails says so and still waits for its word (here: none, so it ends quietly)
    out = subprocess.run([sys.executable, "-m", "ema_sim.nodes.standby", "ema_sim.nodes.emac", "--model", "nosuch"],
                         input="", capture_output=True, text=True, timeout=120, check=False)
    assert out.returncode == 0, out.stderr
    assert "standby: no head start for ema_sim.nodes.emac (UnknownNameError: " in out.stderr
