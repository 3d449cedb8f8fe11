"""The EMAC node's counters under an integrator's publisher: what counts as lost, dropped or worth a WARN.

In process, on a scripted wall clock (the harness of ``test_emac_node_time.py``): a publisher that pauses,
one that sends unstamped commands, one that stamps with its ``now()``, and malformed messages.
"""

import argparse
import random
from types import SimpleNamespace

import pytest
from diagnostic_msgs.msg import DiagnosticStatus
from ros_context import ros_context
from scripted_ports import ScriptedPorts
from test_emac_node_time import BASE_NS, F_NS, F_S, Log, replay

from ema_msgs_py import contract as ct
from ema_msgs_py.cdr import JointFrame
from ema_sim.nodes import emac as emac_module
from ema_sim.nodes import emac_frames, emac_receive, emac_state

pytestmark = pytest.mark.ros


@pytest.fixture(scope="module")
def context():
    with ros_context(113) as ctx:
        yield ctx


@pytest.fixture
def make_node(context, monkeypatch):
    """An EMAC node on a scripted wall clock, every ``/diagnostics`` array it publishes kept."""
    nodes = []

    def make():
        wall = {"t": 1000.0}
        for module in (emac_module, emac_state, emac_receive, emac_frames):  # the node's layers read the wall clock
            monkeypatch.setattr(module, "time", SimpleNamespace(monotonic=lambda: wall["t"]))
        node = emac_module.EmacNode(argparse.Namespace(channels=["left_wing"]), ports=ScriptedPorts, context=context)
        node.wall = wall
        node.log = Log()
        node.get_logger = lambda: node.log
        node.diagnostics = []
        node.diag_pub = SimpleNamespace(publish=node.diagnostics.append)
        nodes.append(node)
        return node

    yield make
    for node in nodes:
        node.destroy_node()


def levels(node):
    """Every status the node published: (level, message)."""
    return [(s.level, s.message) for m in node.diagnostics for s in m.status]


def warned(node):
    return [text for level, text in levels(node) if level >= DiagnosticStatus.WARN]


def lost(node):
    return node.drops.get("lost_commands", 0)


def test_a_two_second_pause_in_publishing_is_a_gap_not_lost_commands(make_node):
    """An FMU on the system clock stops publishing for 2 s and resumes on its grid. Before: 399 commands
    "lost on the way, or never sent" and WARN statuses; now a gap (the watchdog braked and released), 0 lost,
    0 WARN."""
    node = make_node()
    t0 = node.wall["t"] + 0.01
    first = [(t0 + k * F_S, BASE_NS + k * F_NS, 0.5) for k in range(200)]
    second = [(t0 + k * F_S, BASE_NS + k * F_NS, 0.5) for k in range(600, 800)]
    replay(node, first + second, until_s=second[-1][0] + 0.05)
    node._publish_diagnostics()
    assert lost(node) == 0
    assert warned(node) == []
    assert node.command_gaps == 1
    assert node.gap_frames == 400
    assert node.units["left_wing"].counters["watchdog_trips"] == 1  # the pause is the watchdog's business
    assert not node.units["left_wing"].last.braked


def test_unstamped_commands_are_a_stamp_policy_stated_once(make_node):
    """Two seconds of unstamped commands (jittered by 0-3 ms): no loss, no WARN, the policy logged once."""
    node = make_node()
    rng = random.Random(3)
    t0 = node.wall["t"] + 0.01
    replay(node, [(t0 + k * F_S + rng.uniform(0.0, 0.003), 0, 0.5) for k in range(400)])
    node._publish_diagnostics()
    assert lost(node) == 0
    assert warned(node) == []
    assert node.log.count("info", "unstamped") == 1
    assert {v.key: v.value for v in node.diagnostics[-1].status[0].values}["command_stamps"] == "unstamped"


def test_commands_stamped_with_the_publishers_now_are_a_stamp_policy_not_losses(make_node):
    """A publisher that stamps with its now() (off the frame grid) at 200 Hz with 0-3 ms of jitter. Before,
    lost commands were counted where two stamps lay more than 1.5 frames apart, and /diagnostics warned."""
    node = make_node()
    rng = random.Random(5)
    t0 = node.wall["t"] + 0.01
    arrivals = []
    for k in range(400):
        wall = t0 + k * F_S + rng.uniform(0.0, 0.003)
        arrivals.append((wall + 0.0002, BASE_NS + round((wall - 1000.0) * 1e9) + 1234, 0.5))
    replay(node, arrivals)
    node._publish_diagnostics()
    assert lost(node) == 0
    assert warned(node) == []
    assert node.log.count("info", "stamped off the") == 1
    assert {v.key: v.value for v in node.diagnostics[-1].status[0].values}["command_stamps"] == "off_grid"


def test_a_burst_that_outruns_the_frames_still_counts_the_commands_it_lost(make_node):
    """The loss a node can tell from a gap: stamps that jump further than the wall time since (a backlog whose
    queue overflowed). Counted as lost, and a WARN (the publisher sends faster than the link carries)."""
    node = make_node()
    t0 = node.wall["t"] + 0.01
    burst = [(t0 + k * 1e-5, BASE_NS + k * F_NS, 0.5) for k in range(100)]
    burst += [(t0 + 0.001 + (k - 900) * 1e-5, BASE_NS + k * F_NS, 0.5) for k in range(900, 1000)]
    replay(node, burst)
    node._publish_diagnostics()
    assert lost(node) == 800
    assert node.gap_frames == 0
    assert warned(node)


def test_a_command_with_an_unknown_name_is_counted_once_under_one_reason(make_node):
    node = make_node()
    take = node.ports.take[ct.EMAC_COMMAND]
    take(JointFrame(BASE_NS, ["left_wing", "tail", "canard"], [0.5]))  # unknown names and short arrays
    take(JointFrame(BASE_NS + F_NS, ["tail"], [0.5]))
    take(JointFrame(BASE_NS + 2 * F_NS, ["tail", "canard"], [0.5, 0.1]))
    assert sum(node.drops.values()) == 3
    assert node.drops["malformed"] == 1  # which value belongs to which name is unknown: malformed, nothing else
    assert node.drops["unknown_names"] == 2  # one a message, however many names it misspells


@pytest.mark.parametrize("lockstep", [False, True])
def test_a_malformed_command_is_never_applied_and_counted_once(make_node, lockstep):
    """Short or long arrays, NaN, a value no converter reads: dropped whole, counted once each under
    ``malformed``, the channel holding its last good command (before, ``position=[1.0, 2.0]`` was counted and
    still drove the channel to 0.99 V); in lockstep the frame goes ahead on the held command, without a wait."""
    node = make_node()
    take = node.ports.take[ct.EMAC_COMMAND]
    if lockstep:
        node.lockstep = True
        node.ports.take[ct.CLOCK_TOPIC] = node._on_clock
        node.ports.alive = {ct.HINGE_MOMENT: 0}
        node._on_clock(BASE_NS)
        node.poll()
    bad = [["left_wing"], [1.0, 2.0]], [["left_wing"], [float("nan")]], [["left_wing"], [50.0]], [["left_wing"], []]
    messages = [(["left_wing"], [0.5])] * 3 + list(bad) + [(["left_wing"], [0.5])]
    for k, (names, values) in enumerate(messages):
        take(JointFrame(BASE_NS + k * F_NS, names, values))
        node.wall["t"] += F_S
        if lockstep:
            node._on_clock(BASE_NS + (k + 1) * F_NS)
        node.poll()
    unit = node.units["left_wing"]
    assert node.drops["malformed"] == len(bad)
    assert sum(node.drops.values()) == len(bad)
    assert unit.command_v == 0.5
    assert unit.counters["rejected_commands"] == unit.counters["clamped_commands"] == 0
    assert node.waits_given_up == 0
    if lockstep:
        assert len(node.ports.sent[ct.EMAC_FEEDBACK]) == len(messages) + 1  # every frame stepped, the start's too
