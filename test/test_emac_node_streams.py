"""The EMAC node's input streams in lockstep: what a frame takes, and when it may go ahead."""

import functools

import pytest
from ros_context import ros_context
from scripted_ports import ScriptedPorts

from ema_msgs_py import contract as ct
from ema_msgs_py.cdr import JointFrame
from ema_sim.config import CHANNELS, config_dir, ros_parameters
from ema_sim.emac import ActivityMeter, EmacChannel, EmacSettings
from ema_sim.models import create
from ema_sim.nodes.emac import EmacNode, SourceStream, Stream
from ema_sim.run import RunDescription

T = 5_000_000


def test_a_later_message_does_not_hold_back_an_earlier_one_from_another_publisher():
    s = Stream()
    s.push(2 * T, "a@2")  # one publisher is a frame ahead of another (DDS orders per writer only)
    s.push(1 * T, "b@1")
    assert s.take_until(1 * T) == [(1 * T, "b@1")]
    assert s.take_until(2 * T) == [(2 * T, "a@2")]
    assert s.take_until(3 * T) == []


def test_take_until_keeps_arrival_order_and_leaves_the_future():
    s = Stream()
    for k, tag in ((1, "x"), (1, "y"), (3, "z"), (2, "w")):
        s.push(k * T, tag)
    assert [tag for _, tag in s.take_until(2 * T)] == ["x", "y", "w"]
    assert [tag for _, tag in s.take_until(9 * T)] == ["z"]


def test_a_frame_waits_for_every_crosstalk_source():
    s = SourceStream()
    s.expected = frozenset({"left_wing", "cowl_door"})
    s.push_from(1 * T, [("left_wing", 0.1)])
    assert not s.reached(1 * T)  # the cowl door has not reported frame 1
    s.push_from(2 * T, [("left_wing", 0.2)])
    assert not s.reached(1 * T)
    s.push_from(1 * T, [("cowl_door", -0.3)])
    assert s.reached(1 * T)
    assert not s.reached(2 * T)
    assert [v for _, item in s.take_until(1 * T) for _, v in item] == [0.1, -0.3]


def test_without_known_sources_any_message_counts():
    s = SourceStream()
    s.push_from(4 * T, [("left_rudder", 0.0)])
    assert s.reached(4 * T)


# --------------------------------------------------------------------------- a channel node as a run starts it
FRAMES = 15
LAST = ("command", "load", "left_wing", "cowl_door", "clock")
"""The input that arrives last in frame k is LAST[k % 5]: every one of them in turn."""


def _source_v(channel, k):
    """Feedback the other EMACs report at frame k: the left wing slews unevenly, the others rest."""
    if channel != "left_wing":
        return 0.0
    return sum(0.01 * (1 + (7 * j) % 5) for j in range(k))


@pytest.fixture
def right_wing_node(tmp_path):
    """The right wing's EMAC as the one-process-per-node layout starts it: the run's parameter file, renamed."""
    run = RunDescription(bag=tmp_path / "bag", profile="ail", maneuver="step", lockstep=True, layout="processes",
                         emac="channels")
    (proc,) = [p for p in run.processes() if p.nodes == ("emac_right_wing",)]
    params = run.write(tmp_path / "run.yaml")
    nodes = []
    with ros_context(53) as ctx:

        def make():
            every_channel = functools.partial(ScriptedPorts, alive={ct.EMAC_FEEDBACK: len(CHANNELS)})  # the suite's
            nodes.append(EmacNode(None, ports=every_channel, context=ctx, cli_args=run.ros_arguments(proc, params)))
            return nodes[-1]

        yield make
        for node in nodes:
            node.destroy_node()


def _drive(node, adversarial):
    """Every frame's inputs; in the adversarial order the one LAST names is held back over a poll.

    Returns the right wing's reported feedback volts, stamp by stamp; asserts that no frame went ahead
    without its last input.
    """
    take, sent = node.ports.take, node.ports.sent[ct.EMAC_FEEDBACK]
    take[ct.CLOCK_TOPIC](0)
    node.poll()  # the trimmed state at t = 0
    for k in range(FRAMES):
        s = k * T
        inputs = {"command": (ct.EMAC_COMMAND, JointFrame(s, ["right_wing"], [0.5])),
                  "load": (ct.HINGE_MOMENT, JointFrame(s, ["right_wing"], [], [], [100.0])),
                  **{ch: (ct.EMAC_FEEDBACK, JointFrame(s, [ch], [_source_v(ch, k)]))
                     for ch in CHANNELS if ch != "right_wing"},
                  "clock": (ct.CLOCK_TOPIC, (k + 1) * T)}
        late = LAST[k % len(LAST)] if adversarial else None
        for name, (topic, msg) in inputs.items():
            if name != late:
                take[topic](msg)
        if late is not None:
            node.poll()
            assert len(sent) == k + 1, f"frame {k} went ahead without its {late}"
            take[inputs[late][0]](inputs[late][1])
        node.poll()
        assert [m.stamp_ns for m in sent] == [j * T for j in range(k + 2)]
    return [m.position[0] for m in sent]


@pytest.mark.ros
def test_a_channel_node_started_by_a_run_waits_for_every_input_of_a_frame(right_wing_node):
    """Whichever input of a frame comes last (command, hinge moment, a crosstalk source's feedback, the clock),
    the frame waits for it: the feedback is the same in any order, and the one the frame's inputs make."""
    friendly = _drive(right_wing_node(), adversarial=False)
    node = right_wing_node()
    assert _drive(node, adversarial=True) == friendly
    assert node.get_name() == "emac_right_wing"
    assert node.peers == {"emac_left_wing", "emac_left_rudder", "emac_right_rudder", "emac_cowl_door", "testenv",
                          "maneuver", "simclock"}
    pp_v = ros_parameters(config_dir() / "emac.yaml")["emac"]["crosstalk"]["right_wing_pp_v"]
    want, quiet = [], []
    for noise, out in ((pp_v, want), (0.0, quiet)):
        unit = EmacChannel(create("loada", "right_wing"), EmacSettings(), crosstalk_noise_pp_v=noise,
                           stream=CHANNELS.index("right_wing"))
        meter = ActivityMeter(T / 1e9)
        out.append(unit.last.position_v)
        for k in range(FRAMES):
            for ch in CHANNELS:
                if ch != "right_wing":
                    meter.observe(ch, _source_v(ch, k), node.slew_v_per_s[ch])
            unit.set_command(0.5)
            unit.set_load(100.0)
            out.append(unit.step(0.0, meter.activity_except("right_wing")).position_v)
    assert friendly == want
    assert sum(a != b for a, b in zip(want, quiet, strict=True)) >= FRAMES - 2  # the crosstalk shows in the frames


@pytest.mark.ros
def test_a_node_that_joins_a_running_clock_waits_only_for_the_inputs_that_have_come(right_wing_node):
    """A restarted EMAC takes the clock at frame k0: the others' feedback of the frames around k0 went out before it
    subscribed, so those frames go ahead without it; once the others' feedback has come, each frame waits for it."""
    node = right_wing_node()
    take, sent = node.ports.take, node.ports.sent[ct.EMAC_FEEDBACK]
    k0 = 1000

    def frame(k, sources):
        s = k * T
        take[ct.EMAC_COMMAND](JointFrame(s, ["right_wing"], [0.5]))
        take[ct.HINGE_MOMENT](JointFrame(s, ["right_wing"], [], [], [100.0]))
        for ch in sources:
            take[ct.EMAC_FEEDBACK](JointFrame(s, [ch], [_source_v(ch, k)]))
        take[ct.CLOCK_TOPIC]((k + 1) * T)
        node.poll()

    others = [ch for ch in CHANNELS if ch != "right_wing"]
    take[ct.CLOCK_TOPIC](k0 * T)
    node.poll()  # the trimmed state at the frame it joined
    for k in range(k0, k0 + 3):
        frame(k, [])
    assert [m.stamp_ns for m in sent] == [j * T for j in range(k0, k0 + 4)]
    frame(k0 + 3, others)
    frame(k0 + 4, others[1:])  # the left wing's feedback of this frame is late: the frame waits for it
    assert len(sent) == 5
    take[ct.EMAC_FEEDBACK](JointFrame((k0 + 4) * T, [others[0]], [_source_v(others[0], k0 + 4)]))
    node.poll()
    assert [m.stamp_ns for m in sent][-2:] == [(k0 + 4) * T, (k0 + 5) * T]
