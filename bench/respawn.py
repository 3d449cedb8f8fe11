"""A run that survives a node: one EMAC channel process killed (SIGKILL) again and again in a lockstep run.

``ema launch --layout processes --emac channels --lockstep --respawn emacs`` with the defaults a user gets
(``--stall-timeout`` 5 s), HOAD3, the five channels. While the run goes on, the right wing's process is killed
``KILLS`` times, each once the channel is back in lockstep and its next standby has said it is ready. Measured
from each kill, on the run's own messages: the clock's ERROR for the channel on ``/diagnostics``, and the channel
resynchronised (its lockstep status OK again, and its feedback at the clock's frame). The target: every kill
resynchronised within 5 s while the run goes on (the other channels' frames keep coming).

    EMA_BENCH_MODEL=loada ema bench --only nodes_respawn
"""

from __future__ import annotations

import os
import signal
import statistics
import tempfile
import threading
import time
from collections.abc import Callable
from pathlib import Path

import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState

from ema_msgs_py import contract as ct
from ema_msgs_py.ros import qos
from ema_sim.benchmark import Benchmark, Result
from ema_sim.nodes.common import make_executor
from ema_sim.suite import Suite, SuiteConfig, free_domain_id

MODEL = os.environ.get("EMA_BENCH_MODEL", "hoad3")
KILLS = int(os.environ.get("EMA_BENCH_KILLS", "3"))
KILLED = "right_wing"
STATUS = f"simclock: lockstep {KILLED}"
RESYNC_MAX_S = 5.0
"""The target: a killed EMAC restarted and back in lockstep within this many seconds of the kill."""
READY = "standby: ema_sim.nodes.emac ready"
"""A standby's line in its node's log once it has imported and warmed: a kill is timed only against a ready one
(the suite starts the next standby 5 s after a restart; a kill before it is ready measures its start-up)."""
OK, ERROR = (int.from_bytes(level, "little") for level in (DiagnosticStatus.OK, DiagnosticStatus.ERROR))


class _Watch:
    """The run as a listener sees it: the clock, the killed channel's feedback, its lockstep status."""

    def __init__(self, context: rclpy.Context) -> None:
        self.node = rclpy.create_node("respawn_bench", context=context)
        self.executor = make_executor(context)
        self.executor.add_node(self.node)
        self.clock_ns = -1
        self.feedback_ns = -1
        self.others = 0
        """Feedback messages of the channels not killed (the run going on)."""
        self.statuses: list[tuple[float, int, str]] = []
        self.node.create_subscription(Clock, "/clock", self._on_clock, qos(ct.CLOCK_SUB_QOS))
        self.node.create_subscription(JointState, ct.EMAC_FEEDBACK, self._on_feedback, qos(ct.FRAME_QOS))
        self.node.create_subscription(DiagnosticArray, ct.DIAGNOSTICS, self._on_diag, qos(ct.EVENT_QOS))

    def _on_clock(self, msg: Clock) -> None:
        self.clock_ns = max(self.clock_ns, msg.clock.sec * 10**9 + msg.clock.nanosec)

    def _on_feedback(self, msg: JointState) -> None:
        if KILLED in msg.name:
            self.feedback_ns = max(self.feedback_ns, msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec)
        else:
            self.others += 1

    def _on_diag(self, msg: DiagnosticArray) -> None:
        self.statuses += [(time.monotonic(), int.from_bytes(s.level, "little"), s.message)
                          for s in msg.status if s.name == STATUS]

    def until(self, what: str, done: Callable[[], bool], timeout_s: float = 120.0) -> float:
        """Spin until ``done()``; the wall time it became true."""
        deadline = time.monotonic() + timeout_s
        while not done():
            if time.monotonic() > deadline:
                raise TimeoutError(f"no {what} within {timeout_s:g} s")
            self.executor.spin_once(timeout_sec=0.02)
        return time.monotonic()

    def first(self, since: float, level: int, text: str = "") -> float | None:
        """Wall time of the first such status after ``since``."""
        return next((w for w, lv, m in self.statuses if w >= since and lv == level and text in m), None)


def _kill_once(suite: Suite, watch: _Watch) -> tuple[float, float, float, bool]:
    """One kill: seconds to the ERROR, to OK in lockstep, to feedback at the clock's frame; whether left out."""
    proc = suite.procs[f"emac_{KILLED}"]
    os.kill(proc.pid, signal.SIGKILL)
    t_kill = time.monotonic()
    others = watch.others
    t_err = watch.until("ERROR status", lambda: watch.first(t_kill, ERROR) is not None)
    t_ok = watch.until("OK again", lambda: watch.first(t_err, OK, "in lockstep") is not None)
    at = watch.clock_ns
    t_fb = watch.until("the restarted channel's feedback at the clock's frame", lambda: watch.feedback_ns >= at)
    if suite.procs[f"emac_{KILLED}"].pid == proc.pid or watch.others <= others:
        raise RuntimeError("the channel was not restarted, or the run did not go on")
    return t_err - t_kill, t_ok - t_kill, t_fb - t_kill, watch.first(t_kill, ERROR, "left out") is not None


def respawn() -> Result:
    """Kill the right wing's EMAC ``KILLS`` times in one lockstep run; time each return."""
    rows: list[tuple[float, float, float, bool]] = []
    with tempfile.TemporaryDirectory(prefix="ema_bench_respawn_") as tmp:
        cfg = SuiteConfig(bag=Path(tmp) / "bag", model=MODEL, maneuver="sine:freq_hz=2,amp_deg=1,cycles=7200,lead_s=0",
                          duration_s=3600.0, layout="processes", emac="channels", lockstep=True,
                          respawn=["emacs"], domain_id=free_domain_id(os.getpid() + 41))
        suite = Suite(cfg)
        context = rclpy.Context()
        rclpy.init(context=context, domain_id=cfg.domain_id)
        watch = _Watch(context)
        try:
            suite.start()
            threading.Thread(target=suite.wait, daemon=True).start()  # the launcher's loop restarts
            watch.until("feedback of the channel to kill", lambda: watch.feedback_ns >= 10**9, 180.0)
            log = suite.log_dir / f"emac_{KILLED}.log"
            for k in range(KILLS):
                watch.until("a ready standby", lambda k=k: log.read_text().count(READY) > k, 180.0)
                rows.append(_kill_once(suite, watch))
        finally:
            suite.stop()
            watch.node.destroy_node()
            context.try_shutdown()
    back = [max(ok, fb) for _, ok, fb, _ in rows]
    worst = max(back)
    load = os.getloadavg()[0]
    return Result(worst, "s worst kill → resynchronised", worst <= RESYNC_MAX_S,
                  f"{MODEL}, processes layout, lockstep, 5 channels, default stall timeout: {KILLS} kills of "
                  f"{KILLED}'s process; ERROR after {', '.join(f'{e:.2f}' for e, _, _, _ in rows)} s; back in "
                  f"lockstep after {', '.join(f'{b:.2f}' for b in back)} s (median {statistics.median(back):.2f}); "
                  f"left out {sum(r[3] for r in rows)} times; load {load:.1f}")


BENCHMARKS = [Benchmark(f"nodes_respawn_lockstep_{MODEL}", f"resynchronised ≤ {RESYNC_MAX_S:g} s", respawn)]
