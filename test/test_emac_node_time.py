"""The EMAC node's time: every real-time frame stepped once, stamps that recover, a /clock that goes back.

In process, on a scripted wall clock: the node's inputs are handed to it at chosen instants and its loop
polled as :func:`ema_sim.nodes.common.run_nodes` polls it, so a publisher's jitter, a late command, a
stamp an hour ahead or an FMU restart are replayed exactly and in milliseconds.
"""

import argparse
import itertools
import random
from types import SimpleNamespace

import pytest
from diagnostic_msgs.msg import DiagnosticStatus
from ros_context import ros_context
from scripted_ports import ScriptedPorts

from ema_msgs_py import contract as ct
from ema_msgs_py.cdr import JointFrame
from ema_sim.emac.stamps import CommandClock, FrameGate, Lateness, Verdict
from ema_sim.nodes import emac as emac_module
from ema_sim.nodes import emac_frames, emac_receive, emac_state

F_NS = 5_000_000
F_S = 0.005
BASE_NS = 1_700_000_000_000_000_000
"""FMU stamps on the system clock's epoch, as an FMU on a synchronised clock stamps them."""


# --------------------------------------------------------------------------- the stamp rule alone
def test_one_wild_stamp_costs_one_command_and_moves_nothing():
    clock = CommandClock(F_NS, tolerance_s=0.1, resync_after=5)
    wall = 0.0
    assert clock.check(BASE_NS, wall).verdict is Verdict.TAKEN
    assert clock.check(BASE_NS + 3600 * 10**9, wall + F_S).verdict is Verdict.FUTURE  # an hour ahead
    assert clock.check(BASE_NS, wall + 2 * F_S).verdict is Verdict.OUT_OF_ORDER  # a duplicate
    for k in range(1, 20):
        assert clock.check(BASE_NS + k * F_NS, wall + (k + 2) * F_S).verdict is Verdict.TAKEN
    assert clock.resyncs == 0


def test_a_pause_a_burst_and_a_gap_fit_but_a_clock_that_moved_is_followed_after_five_commands():
    clock = CommandClock(F_NS, tolerance_s=0.1, resync_after=5)
    assert clock.check(BASE_NS, 0.0).verdict is Verdict.TAKEN
    assert clock.check(BASE_NS + 10 * 10**9, 10.0).verdict is Verdict.TAKEN  # the FMU paused 10 s
    burst = [clock.check(BASE_NS + 10 * 10**9 + k * F_NS, 10.001) for k in range(1, 1000)]
    assert all(c.verdict is Verdict.TAKEN for c in burst)  # stamps faster than the wall clock, one frame apart
    gap = clock.check(BASE_NS + 10 * 10**9 + 1003 * F_NS, 10.002)
    assert (gap.verdict, gap.missing) == (Verdict.TAKEN, 3)
    restart = [clock.check(k * F_NS, 11.0 + k * F_S).verdict for k in range(6)]  # the FMU restarted at 0
    assert restart == [Verdict.OUT_OF_ORDER] * 4 + [Verdict.RESYNC, Verdict.TAKEN]
    forward = [clock.check(BASE_NS * 2 + k * F_NS, 12.0 + k * F_S).verdict for k in range(6)]  # stepped ahead
    assert forward == [Verdict.FUTURE] * 4 + [Verdict.RESYNC, Verdict.TAKEN]
    assert clock.resyncs == 2


def test_a_late_delivery_then_a_pause_is_a_gap_not_a_loss():
    clock = CommandClock(F_NS, tolerance_s=0.1, resync_after=5)
    for k in range(4):  # real time, each delivered at once
        assert clock.check(BASE_NS + k * F_NS, k * F_S).missing == 0
    late = clock.check(BASE_NS + 4 * F_NS, 8 * F_S)  # delivered 4 frames late (a loaded machine)
    paused = clock.check(BASE_NS + 7 * F_NS, 8.1 * F_S)  # the FMU skipped frames 5 and 6; behind it in the queue
    assert (late.missing, late.gap) == (0, 0)
    assert (paused.verdict, paused.missing, paused.gap) == (Verdict.TAKEN, 0, 2)
    ahead = clock.check(BASE_NS + 20 * F_NS, 9 * F_S)  # 12 frames missing, the stamps 11 frames ahead of the wall
    assert (ahead.missing, ahead.gap) == (11, 1)


def test_a_first_command_held_while_the_transport_matched_makes_no_loss():
    clock = CommandClock(F_NS, tolerance_s=10.0, resync_after=5)
    assert clock.check(BASE_NS, 0.392).verdict is Verdict.TAKEN  # came 392 ms after its stamp
    on_time = clock.check(BASE_NS + 77 * F_NS, 0.392 + 0.001)  # the FMU skipped 76 frames meanwhile; on time
    assert (on_time.missing, on_time.gap) == (0, 76)
    for k in range(78, 82):
        assert clock.check(BASE_NS + k * F_NS, 0.392 + (k - 77) * F_S).missing == 0
    burst = clock.check(BASE_NS + 100 * F_NS, 0.392 + 5 * F_S)  # the reference known: 18 frames skipped in a frame
    assert (burst.missing, burst.gap) == (18, 0)


def test_a_backlog_that_catches_up_stays_late_but_a_clock_that_lags_the_frames_is_followed():
    gate = FrameGate(F_NS, follow_after=5)
    next_ns, seen = 20 * F_NS, []  # a stalled publisher: idle frames stood in for frames 10 to 19
    for k in range(10, 25):
        seen.append(gate.judge(k * F_NS, next_ns))
        if seen[-1] is Lateness.STEP:
            next_ns = (k + 1) * F_NS
    assert seen == [Lateness.LATE] * 10 + [Lateness.STEP] * 5
    assert gate.judge(25 * F_NS - F_NS // 3, next_ns) is Lateness.STEP  # stamped off the grid, a little early
    lagging = [gate.judge((k - 3) * F_NS, k * F_NS) for k in range(40, 46)]  # an FMU clock 3 frames behind
    assert lagging == [Lateness.LATE] * 4 + [Lateness.FOLLOW, Lateness.LATE]
    assert (gate.late, gate.follows) == (15, 1)


# --------------------------------------------------------------------------- the node on a scripted clock
class Log:
    """The node's log lines by level."""

    def __init__(self):
        self.lines = []

    def __getattr__(self, level):
        return lambda text, **_: self.lines.append((level, text))

    def count(self, level, words):
        return sum(1 for lv, text in self.lines if lv == level and words in text)


@pytest.fixture(scope="module")
def context():
    with ros_context(71) as ctx:
        yield ctx


@pytest.fixture
def make_node(context, monkeypatch):
    """An EMAC node on a scripted wall clock (``node.wall["t"]``), its log and diagnostics kept."""
    nodes = []

    def make(*ros_args):
        wall = {"t": 1000.0}
        for module in (emac_module, emac_state, emac_receive, emac_frames):  # the node's layers read the wall clock
            monkeypatch.setattr(module, "time", SimpleNamespace(monotonic=lambda: wall["t"]))
        node = emac_module.EmacNode(argparse.Namespace(channels=["left_wing"]), ports=ScriptedPorts,
                                    context=context, cli_args=["--ros-args", *ros_args] if ros_args else None)
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


def replay(node, arrivals, until_s=None, held=None):
    """Hand the node its commands ``(wall s, stamp ns, volts)`` as its loop takes them, on the scripted clock.

    The loop polls the node, then its executor hands over one message that has come (or waits until the node's
    next deadline); ``held``: a (start, end) wall interval in which the process is held up (no poll, no take).
    """
    wall, take = node.wall, node.ports.take[ct.EMAC_COMMAND]
    arrivals = sorted(arrivals)
    end = (arrivals[-1][0] if until_s is None else until_s) + 1e-9
    i = 0
    while wall["t"] < end:
        due = wall["t"] + min(max(node.poll(), 0.0), 0.05)
        came = arrivals[i][0] if i < len(arrivals) else float("inf")
        wake = min(due, max(came, wall["t"]))
        if held is not None and held[0] <= wake < held[1]:
            wall["t"] = held[1]  # held up: the next poll is at its end, before anything is taken
        elif came <= due:
            wall["t"] = max(wall["t"], came)
            take(JointFrame(arrivals[i][1], ["left_wing"], [arrivals[i][2]]))
            i += 1
        else:
            wall["t"] = max(due, wall["t"] + 1e-6)


def feedback_stamps(node):
    return [m.stamp_ns for m in node.ports.sent[ct.EMAC_FEEDBACK]]


def diagnostics(node):
    node._publish_diagnostics()
    (status,) = node.diagnostics[-1].status
    return {v.key: v.value for v in status.values}


@pytest.mark.ros
def test_real_time_steps_every_frame_once_under_publisher_jitter_and_late_commands(make_node):
    """The issue's client: commands on the 5 ms grid, 0–3 ms of jitter, one in 40 published 9 ms late by a
    publisher that sends in order. Before, 29 of 657 feedback frames had a stamp not after the one before
    (48 duplicates) for 600 commands; now every stamp is later than the one before and appears once."""
    node = make_node()
    rng = random.Random(1)
    t0, last, arrivals = node.wall["t"] + 0.2, 0.0, []  # the node idles on its own clock for 0.2 s first
    for k in range(600):
        last = max(last, k * F_S + rng.uniform(0.0, 0.003) + (0.009 if rng.random() < 1 / 40 else 0.0))
        arrivals.append((t0 + last, BASE_NS + k * F_NS, 0.5))
    replay(node, arrivals, until_s=arrivals[-1][0] + 0.05)
    stamps = feedback_stamps(node)
    idle = stamps.index(BASE_NS + F_NS)  # the first command's frame: the frames follow its stamps from there
    assert 35 <= idle <= 40
    stamps = stamps[idle:]
    assert all(b > a for a, b in itertools.pairwise(stamps))  # strictly increasing: no frame twice
    assert all((s - BASE_NS) % F_NS == 0 for s in stamps)  # on the FMU's frame grid
    assert node.commands_taken == 600
    assert 0 < node.late_commands < 40  # the late ones, applied from the next frame
    assert set(stamps) >= {BASE_NS + (k + 1) * F_NS for k in range(600)}  # no frame left out
    assert diagnostics(node)["late_commands"] == str(node.late_commands)
    steady = make_node()  # 3 ms of jitter alone: no command is late (was 34 of 3,000 frames stepped twice)
    replay(steady, [(steady.wall["t"] + k * F_S + rng.uniform(0.0, 0.003), BASE_NS + k * F_NS, 0.5)
                    for k in range(1000)])
    assert steady.late_commands == 0
    assert feedback_stamps(steady) == [BASE_NS + (k + 1) * F_NS for k in range(1000)]


@pytest.mark.ros
def test_commands_that_came_while_the_node_was_held_up_are_taken_before_an_idle_frame(make_node):
    """The node held up for 40 ms (8 frames): the commands wait in its executor, and are each stepped when it
    resumes (before, the idle frames it owed stepped first, one per message taken, and every command after was
    late by as much: 8 duplicate stamps and one going back in a run of the processes layout)."""
    node = make_node()
    t0 = node.wall["t"] + 0.001
    replay(node, _stream(t0, 0, 300, 0.5), held=(t0 + 100 * F_S, t0 + 108 * F_S))
    assert node.late_commands == node.command_resyncs == 0
    assert feedback_stamps(node) == [BASE_NS + (k + 1) * F_NS for k in range(300)]


@pytest.mark.ros
def test_an_idle_node_held_up_past_its_catch_up_skips_the_frames_on_the_grid_and_says_so(make_node):
    """No commands, the process held up 200 ms (40 frames, over the 20 it catches up): it jumps to the present
    frame, counts the frames it skipped, logs it once, and its stamps stay strictly increasing on the grid."""
    node = make_node()
    t0 = node.wall["t"]
    replay(node, [], until_s=t0 + 0.5, held=(t0 + 0.1, t0 + 0.3))
    stamps = feedback_stamps(node)
    gaps = [(b - a) // F_NS for a, b in itertools.pairwise(stamps)]
    assert all((b - a) % F_NS == 0 and b > a for a, b in itertools.pairwise(stamps))
    (jump,) = [g for g in gaps if g > 1]
    assert 38 <= jump <= 41
    assert node.skipped_frames == jump - 1
    assert (stamps[-1] - stamps[0]) // F_NS + 1 == len(stamps) + node.skipped_frames  # each stepped or skipped
    assert 96 <= len(stamps) + node.skipped_frames <= 101  # 0.5 s of frames: the loop caught up with the wall
    assert node.log.count("warning", f"{node.skipped_frames} idle frames skipped") == 1
    assert diagnostics(node)["skipped_frames"] == str(node.skipped_frames)


def _stream(t0, k0, n, volts, stamp=lambda k: BASE_NS + k * F_NS):
    return [(t0 + (k - k0) * F_S, stamp(k), volts) for k in range(k0, k0 + n)]


@pytest.mark.ros
def test_a_command_stamped_an_hour_ahead_is_dropped_alone(make_node):
    """Before, every later command was dropped as out of order (600 of 600) and the brake held."""
    node = make_node()
    t0 = node.wall["t"]
    wild = [(t0 + 40 * F_S, BASE_NS + 3600 * 10**9, 1.0)]
    replay(node, _stream(t0, 0, 40, 1.0) + wild + _stream(t0 + 40.5 * F_S, 40, 200, -2.0))
    unit = node.units["left_wing"]
    assert (unit.command_v, unit.last.braked) == (-2.0, False)
    assert node.drops["future_stamp"] == 1
    assert node.drops["out_of_order"] == node.drops["lost_commands"] == node.command_resyncs == 0
    assert node.log.count("warning", "implausible stamp") == 1
    stamps = feedback_stamps(node)
    assert stamps[-1] == BASE_NS + 240 * F_NS
    assert all(b > a for a, b in itertools.pairwise(stamps))


@pytest.mark.ros
@pytest.mark.parametrize("jump", ["restart", "forward"])
def test_an_fmu_clock_that_moved_is_followed_after_five_commands_and_the_brake_released(make_node, jump):
    """An FMU restart that resets its stamps to 0 (or a clock stepped a day ahead): five commands dropped,
    then the node follows the new stamps, says so once (WARN) and counts it in /diagnostics."""
    node = make_node()
    t0 = node.wall["t"]
    new = (lambda k: (k - 100) * F_NS) if jump == "restart" else (lambda k: BASE_NS + 86_400 * 10**9 + k * F_NS)
    replay(node, _stream(t0, 0, 100, 1.0) + _stream(t0 + 100 * F_S, 100, 200, -2.0, stamp=new))
    unit = node.units["left_wing"]
    assert (unit.command_v, unit.last.braked) == (-2.0, False)
    assert unit.counters["watchdog_trips"] == 0  # 25 ms of dropped commands: within the 50 ms watchdog
    dropped = "out_of_order" if jump == "restart" else "future_stamp"
    assert node.drops[dropped] == 4
    assert node.command_resyncs == 1
    assert node.log.count("warning", "the command clock follows it from here") == 1
    assert diagnostics(node)["command_resyncs"] == "1"
    assert feedback_stamps(node)[-1] == new(299) + F_NS  # the frames follow the new clock


def _status(node):
    node._publish_diagnostics()
    (status,) = node.diagnostics[-1].status
    return status.level, status.message


@pytest.mark.ros
@pytest.mark.parametrize(("lag_frames", "warn"), [(2, False), (40, True)])
def test_commands_that_lag_the_frames_are_followed_and_warn_only_beyond_the_watchdog(make_node, lag_frames, warn):
    """Commands that resume after a pause stamped behind the idle frames the node stepped meanwhile: 10 ms
    behind (stamps that sit behind the grid, a node that was held up) is followed with an info line and
    /diagnostics stays OK; 200 ms behind (an FMU clock that stopped while it paused) is a WARN."""
    node = make_node()
    t0 = node.wall["t"]
    before = _stream(t0, 0, 100, 0.5)
    resume = t0 + 100 * F_S + 1.0  # a 1 s pause: the node steps idle frames on its own clock
    after = [(resume + (k - 300) * F_S, BASE_NS + (k - lag_frames) * F_NS, 0.5) for k in range(300, 400)]
    replay(node, before + after)
    assert node.command_resyncs == 1  # followed once, then every command is on time again
    assert node.drops["lost_commands"] == node.drops["out_of_order"] == 0
    level, message = _status(node)
    assert (level == DiagnosticStatus.WARN) is warn, message
    assert node.log.count("warning", "a clock that stopped or lags") == int(warn)
    assert node.log.count("info", "within the watchdog") == int(not warn)
    assert feedback_stamps(node)[-1] == BASE_NS + (399 - lag_frames) * F_NS + F_NS  # the frames follow the stamps


@pytest.mark.ros
def test_a_clock_that_jumps_back_restarts_the_lockstep_time_base(make_node):
    """A /clock reset (or a replay from the start) after 30 frames: logged once, counted, the node steps the new
    time's frames (before: it froze without a word); an input still on its way from before is dropped."""
    node = make_node("-p", "use_sim_time:=true")
    assert node.lockstep
    take = node.ports.take

    def frames(first, n):
        for k in range(first, first + n):
            take[ct.EMAC_COMMAND](JointFrame(k * F_NS, ["left_wing"], [0.4]))
            take[ct.HINGE_MOMENT](JointFrame(k * F_NS, ["left_wing"], [], [], [50.0]))
            take[ct.CLOCK_TOPIC]((k + 1) * F_NS)
            node.poll()

    take[ct.CLOCK_TOPIC](0)
    node.poll()  # the trimmed state at 0
    frames(0, 30)
    assert feedback_stamps(node) == [k * F_NS for k in range(31)]
    take[ct.CLOCK_TOPIC](0)  # reset
    node.poll()  # the state at the new start
    take[ct.EMAC_COMMAND](JointFrame(29 * F_NS, ["left_wing"], [9.0]))  # sent before the reset, late
    frames(0, 10)
    assert feedback_stamps(node)[31:] == [k * F_NS for k in range(11)]
    assert node.clock_resets == 1
    assert node.drops["future_stamp"] == 1
    assert node.units["left_wing"].command_v == 0.4
    assert not node.units["left_wing"].last.braked
    assert node.log.count("warning", "/clock jumped back from 0.150000 s to 0.000000 s") == 1
    assert diagnostics(node)["clock_resets"] == "1"


@pytest.mark.ros
def test_throttled_lines_of_any_severity_reach_the_node_logger(make_node):
    """rclpy refuses a logging call site whose severity changes: a late command (info) after a drop (warning)
    once raised out of the node's loop."""
    node = make_node()
    del node.get_logger  # the node's own rclpy logger
    node.throttled("a", "a warning")
    node.throttled("b", "an info line", level="info")
    node.throttled("c", "an error", level="error")
