"""A run that survives a node: an EMAC killed mid-run (SIGKILL) in ``--layout processes``, lockstep and real time.

Lockstep: the clock marks the dead channel ERROR on ``/diagnostics``, leaves it out after ``stall_timeout_s``
and goes on; the suite restarts the EMAC (``respawn``); the restarted EMAC starts on the clock's present frame
and is back in lockstep; the bag says all of it. Waits on the run's own messages (``/clock``, ``/diagnostics``,
the feedback), on a ROS domain of its own. Real time: the test environment marks the channel ERROR while it is
commanded without feedback, and OK once the restarted EMAC answers. The times from the kill to each are printed
(``-s``).
"""

import os
import signal
import threading
import time

import pytest
import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from ros_context import ros_context
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState

from ema_msgs_py import contract as ct
from ema_msgs_py.ros import qos
from ema_sim.nodes.common import make_executor
from ema_sim.suite import Suite, SuiteConfig, free_domain_id

pytestmark = pytest.mark.ros
OFFSET = 197
KILLED = "right_wing"
STATUS = f"simclock: lockstep {KILLED}"
FEEDBACK_STATUS = f"/testenv: feedback {KILLED}"
FRAME_NS = 5_000_000  # the suite's 200 Hz frame
DURATION_S = 60.0
OK, ERROR = (int.from_bytes(level, "little") for level in (DiagnosticStatus.OK, DiagnosticStatus.ERROR))
"""The levels as numbers (rclpy gives bytes, a bag's messages numbers)."""


class Watch:
    """What the test sees of the run: the clock, the killed channel's feedback stamps and lockstep status."""

    def __init__(self, context, status=STATUS):
        self.status = status
        self.node = rclpy.create_node("respawn_watch", context=context)
        self.executor = make_executor(context)
        self.executor.add_node(self.node)
        self.clock_ns = -1
        self.feedback_ns = -1
        self.statuses = []
        """(wall time, level, message) of the killed channel's lockstep status, as they come."""
        self.node.create_subscription(Clock, "/clock", self._on_clock, qos(ct.CLOCK_SUB_QOS))
        self.node.create_subscription(JointState, ct.EMAC_FEEDBACK, self._on_feedback, qos(ct.FRAME_QOS))
        self.node.create_subscription(DiagnosticArray, ct.DIAGNOSTICS, self._on_diag, qos(ct.EVENT_QOS))

    def _on_clock(self, msg):
        self.clock_ns = max(self.clock_ns, msg.clock.sec * 10**9 + msg.clock.nanosec)

    def _on_feedback(self, msg):
        if KILLED in msg.name:
            self.feedback_ns = max(self.feedback_ns, msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec)

    def _on_diag(self, msg):
        stamp = msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec  # the clock's frame
        self.statuses += [(time.monotonic(), stamp, int.from_bytes(s.level, "little"), s.message)
                          for s in msg.status if s.name == self.status]

    def until(self, what, done, timeout_s=120.0):
        """Spin until ``done()``; the wall time it became true."""
        deadline = time.monotonic() + timeout_s
        while not done():
            assert time.monotonic() < deadline, f"no {what} within {timeout_s:g} s"
            self.executor.spin_once(timeout_sec=0.05)
        return time.monotonic()

    def level_since(self, t, level, text):
        """The clock's frame of the first such status that came after ``t`` (wall), or None."""
        return next((stamp for w, stamp, lv, m in self.statuses if w >= t and lv == level and text in m), None)


def test_a_killed_emac_is_left_out_restarted_and_back_in_lockstep_while_the_run_goes_on(tmp_path):
    bag = tmp_path / "bag"
    # The restart must come while the run goes on: the clock does not wait for a channel left out, and publishes its
    # statuses only while it runs. 30 s simulated took about 15 s of wall time, and once on a loaded machine no
    # "in lockstep" came after the kill; 60 s gives the standby twice the time.
    cfg = SuiteConfig(bag=bag, maneuver="steps:amps_deg=1/5,lead_s=0.2,hold_s=0.5", duration_s=DURATION_S,
                      channels=["left_wing"], emac_channels=["left_wing", KILLED], layout="processes",
                      emac="channels", lockstep=True, respawn=["emacs"], stall_timeout_s=0.5,
                      domain_id=free_domain_id(os.getpid() + OFFSET))
    suite = Suite(cfg)
    ended = {}
    with ros_context(OFFSET) as context:
        watch = Watch(context)
        suite.start()
        waiter = threading.Thread(target=lambda: ended.update(status=suite.wait(timeout_s=600)), daemon=True)
        try:
            waiter.start()
            watch.until("feedback of the channel to kill", lambda: watch.feedback_ns >= 10**9)
            killed = suite.procs[f"emac_{KILLED}"]
            os.kill(killed.pid, signal.SIGKILL)
            t_kill = time.monotonic()
            t_error = watch.until("ERROR status", lambda: watch.level_since(t_kill, ERROR, "") is not None)
            t_out = watch.until("left-out status",
                                lambda: watch.level_since(t_kill, ERROR, "left out of lockstep") is not None)
            t_back = watch.until("the channel back in lockstep",
                                 lambda: watch.level_since(t_out, OK, "in lockstep") is not None)
            # the clock went on while the channel was out: its frame when the channel came back is further on (by
            # how much depends on how soon the standby took over: 8 frames when it was quick)
            out_frame = watch.level_since(t_kill, ERROR, "left out of lockstep")
            assert watch.level_since(t_out, OK, "in lockstep") >= out_frame + FRAME_NS
            assert suite.procs[f"emac_{KILLED}"].pid != killed.pid
            resumed = watch.clock_ns
            watch.until("feedback of the restarted channel", lambda: watch.feedback_ns >= resumed)
            print(f"kill → ERROR {t_error - t_kill:.3f} s, → left out {t_out - t_kill:.3f} s, "
                  f"→ back in lockstep {t_back - t_kill:.3f} s")
            waiter.join(timeout=600)
            assert ended.get("status") == 0
        finally:
            suite.stop()
            watch.node.destroy_node()
    assert suite.restarts == {f"emac_{KILLED}": 1}
    assert "started again (its standby" in (suite.log_dir / f"emac_{KILLED}.log").read_text()
    clock = suite.summaries()["simclock"]
    # every channel left out came back (on a loaded machine the restarted EMAC may stall once more while it warms)
    assert clock["left_out"] == clock["rejoined"] >= 1
    assert clock["out_of_lockstep"] == []
    assert clock["frames"] == round(DURATION_S * 1e9 / FRAME_NS)

    from rosbags.rosbag2 import Reader  # noqa: PLC0415

    from ema_msgs_py import typestore as ts  # noqa: PLC0415

    with Reader(bag) as reader:  # the bag says so: the channel's ERROR (left out) then OK again
        conns = [c for c in reader.connections if c.topic == ct.DIAGNOSTICS]
        said = [(s.level, s.message) for _, _, raw in reader.messages(connections=conns)
                for s in ts.deserialize(raw, "diagnostic_msgs/msg/DiagnosticArray").status if s.name == STATUS]
    first_out = next(k for k, (_, m) in enumerate(said) if "left out" in m)
    assert said[first_out][0] == ERROR
    assert (OK, "in lockstep") in said[:first_out]
    assert (OK, "in lockstep") in said[first_out:]


def test_a_killed_emac_in_real_time_is_error_while_commanded_and_ok_once_restarted(tmp_path):
    cfg = SuiteConfig(bag=tmp_path / "bag", maneuver="steps:amps_deg=1/5,lead_s=0.2,hold_s=0.5", duration_s=60.0,
                      channels=["left_wing"], emac_channels=["left_wing", KILLED], layout="processes",
                      emac="channels", respawn=["emacs"], domain_id=free_domain_id(os.getpid() + OFFSET + 1))
    suite = Suite(cfg)
    with ros_context(OFFSET + 1) as context:
        watch = Watch(context, FEEDBACK_STATUS)
        suite.start()
        waiter = threading.Thread(target=suite.wait, daemon=True)  # the launcher's loop: it restarts the EMAC
        try:
            waiter.start()
            t_ok = watch.until("the channel's feedback status OK", lambda: watch.level_since(0.0, OK, "") is not None)
            watch.until("feedback of the channel to kill", lambda: watch.feedback_ns > 0)
            killed = suite.procs[f"emac_{KILLED}"]
            os.kill(killed.pid, signal.SIGKILL)
            t_kill = time.monotonic()
            assert t_kill > t_ok
            t_error = watch.until("ERROR status", lambda: watch.level_since(t_kill, ERROR, "no feedback") is not None)
            t_back = watch.until("OK again", lambda: watch.level_since(t_error, OK, "feedback flowing") is not None)
            print(f"real time: kill → ERROR {t_error - t_kill:.3f} s, → feedback back {t_back - t_kill:.3f} s")
            assert suite.procs[f"emac_{KILLED}"].pid != killed.pid
            assert suite.procs["maneuver"].poll() is None  # the run went on
        finally:
            suite.stop()
            watch.node.destroy_node()
    assert suite.restarts == {f"emac_{KILLED}": 1}
    # the killed channel fell silent, and the testenv said so; on a busy machine the restarted process may pause
    # beyond the 50 ms silence again while it warms up, and another EMAC may be held beyond it too
    assert suite.summaries()["testenv"]["silences_by_channel"][KILLED] >= 1
