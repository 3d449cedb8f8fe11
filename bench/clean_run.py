"""A clean real-time run with pauses: what one EMAC counts as lost and how often ``/diagnostics`` says WARN.

An outside flight computer (a plain rclpy node on a domain of its own) commands the left wing at 200 Hz: a
2 Hz sine, stamped on the frame grid of its wall clock (``--stamps grid``) or with its publishing time
(``--stamps now``), pausing ``--pause-s`` every ``--period-s``. Nothing is lost and nothing is wrong, so
every ``dropped_*`` count should stay 0 and every status of the channel OK; a pause is the watchdog's business
(the brake), not a fault. The EMAC runs as ``emac --channel left_wing`` in its own process, under whatever load
the machine has. Prints one JSON line; ``--out`` also writes it.

    python bench/clean_run.py --duration-s 3600 [--stamps grid|now] [--pause-s 2] [--period-s 30] [--out F]
                              [--domain-id N]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import signal
import subprocess
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rclpy.executors import SingleThreadedExecutor
from rclpy.publisher import Publisher
from rclpy.qos import QoSProfile
from sensor_msgs.msg import JointState

from ema_msgs_py import contract as ct
from ema_sim.config import load_channel
from ema_sim.suite import free_domain_id

FRAME_NS = 5_000_000
NS = 1_000_000_000
STATUS = "/emac_left_wing: left_wing"
LEVELS = {DiagnosticStatus.OK: "OK", DiagnosticStatus.WARN: "WARN", DiagnosticStatus.ERROR: "ERROR",
          DiagnosticStatus.STALE: "STALE"}


def _summary(log: Path) -> dict[str, object]:
    line = next((x for x in log.read_text().splitlines() if x.startswith("EMA_SUMMARY ")), None)
    return {} if line is None else json.loads(line[len("EMA_SUMMARY "):])


class Statuses:
    """The channel's statuses on ``/diagnostics`` from the first command on: levels, non-OK messages, the last."""

    def __init__(self) -> None:
        self.started = False
        self.levels: Counter[str] = Counter()
        self.messages: Counter[str] = Counter()
        self.last: dict[str, str] = {}

    def on_diag(self, msg: DiagnosticArray) -> None:
        """Count one ``/diagnostics`` message's status of the channel."""
        for s in msg.status:
            if s.name == STATUS and self.started:
                self.levels[LEVELS.get(s.level, str(s.level))] += 1
                if s.level != DiagnosticStatus.OK:
                    self.messages[s.message] += 1
                self.last = {v.key: v.value for v in s.values}


def _drive(ex: SingleThreadedExecutor, pub: Publisher, stamps: str, duration_s: float, pause_s: float,
           period_s: float) -> tuple[int, int]:
    """The FMU: a 2 Hz sine at 200 Hz, pausing ``pause_s`` every ``period_s``; commands sent and pauses made."""
    scale = load_channel("left_wing")
    msg = JointState(name=["left_wing"], position=[0.0])
    t0 = time.monotonic()
    grid0 = time.time_ns() // FRAME_NS * FRAME_NS
    sent = pauses = 0
    while (elapsed := time.monotonic() - t0) < duration_s:
        if elapsed % period_s > period_s - pause_s:  # the FMU pauses
            pauses += 1
            end = time.monotonic() + pause_s
            while time.monotonic() < end:
                ex.spin_once(timeout_sec=0.01)
            continue
        # one command a frame, the frame the wall clock is in: a held-up FMU skips frames, never bursts
        frame = round((time.monotonic() - t0) * NS) // FRAME_NS
        stamp = time.time_ns() if stamps == "now" else grid0 + frame * FRAME_NS
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp, NS)
        msg.position[0] = float(scale.deg_to_v(2.0 * math.sin(2.0 * math.pi * 2.0 * elapsed)))
        pub.publish(msg)
        sent += 1
        next_wall = t0 + (frame + 1) * FRAME_NS / NS
        while (left := next_wall - time.monotonic()) > 0.0:
            ex.spin_once(timeout_sec=left)
    return sent, pauses


def run(duration_s: float, stamps: str, pause_s: float, period_s: float, domain_id: int | None = None
        ) -> dict[str, object]:
    """One clean run; its counts (see the module docstring)."""
    did = free_domain_id(os.getpid() + 7) if domain_id is None else domain_id
    env = dict(os.environ, ROS_DOMAIN_ID=str(did), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", PYTHONUNBUFFERED="1")
    with tempfile.TemporaryDirectory(prefix="ema_clean_") as tmp:
        log = Path(tmp) / "emac.log"
        with log.open("w") as out:
            proc = subprocess.Popen([sys.executable, "-m", "ema_sim.nodes.emac", "--channel", "left_wing"], env=env,
                                    stdout=out, stderr=subprocess.STDOUT)
        ctx = rclpy.Context()
        rclpy.init(context=ctx, domain_id=did)
        node = rclpy.create_node("clean_run_fmu", context=ctx)
        ex = SingleThreadedExecutor(context=ctx)
        ex.add_node(node)
        seen = Statuses()
        node.create_subscription(DiagnosticArray, "/diagnostics", seen.on_diag, 100)
        pub = node.create_publisher(JointState, ct.EMAC_COMMAND, QoSProfile(depth=1000))
        try:
            wait_end = time.monotonic() + 60.0
            while pub.get_subscription_count() == 0 and time.monotonic() < wait_end:
                ex.spin_once(timeout_sec=0.05)
            if pub.get_subscription_count() == 0:
                raise RuntimeError("the EMAC never subscribed to the commands")
            seen.started = True
            sent, pauses = _drive(ex, pub, stamps, duration_s, pause_s, period_s)
            end = time.monotonic() + 3.0  # the last statuses
            while time.monotonic() < end:
                ex.spin_once(timeout_sec=0.05)
        finally:
            if proc.poll() is None:
                proc.send_signal(signal.SIGINT)
            try:
                proc.wait(timeout=30)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
            ex.shutdown()
            node.destroy_node()
            rclpy.shutdown(context=ctx)
        summary = _summary(log)
        if os.environ.get("EMA_CLEAN_KEEP_LOG"):
            Path(os.environ["EMA_CLEAN_KEEP_LOG"]).write_text(log.read_text())
        lines = [x for x in log.read_text().splitlines() if "[WARN]" in x or "[ERROR]" in x]
    last = seen.last
    dropped = {k: int(v) for k, v in last.items() if k.startswith("dropped_")}
    return {"duration_s": duration_s, "stamps": stamps, "pause_s": pause_s, "period_s": period_s,
            "commands_sent": sent, "pauses": pauses, "statuses": dict(seen.levels),
            "non_ok_messages": dict(seen.messages),
            "dropped": dropped, "commands_counted": int(last.get("commands", -1)),
            "watchdog_trips": int(last.get("watchdog_trips", -1)), "warn_log_lines": len(lines),
            "warn_log_examples": lines[:5], "summary_dropped": summary.get("dropped"),
            "load_1min": os.getloadavg()[0]}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration-s", type=float, default=600.0)
    ap.add_argument("--stamps", choices=("grid", "now"), default="grid")
    ap.add_argument("--pause-s", type=float, default=2.0)
    ap.add_argument("--period-s", type=float, default=30.0)
    ap.add_argument("--out", type=Path, default=None)
    ap.add_argument("--domain-id", type=int, default=None,
                    help="ROS domain (default: one derived from the pid; give one no test suite uses beside it)")
    a = ap.parse_args()
    result = run(a.duration_s, a.stamps, a.pause_s, a.period_s, a.domain_id)
    text = json.dumps(result)
    print(text)
    if a.out is not None:
        a.out.write_text(text + "\n")
    clean = not any(result["dropped"].values()) and set(result["statuses"]) <= {"OK"}  # type: ignore[union-attr]
    return 0 if clean else 1


if __name__ == "__main__":
    sys.exit(main())
