"""``simclock``: the lockstep clock, one FMU frame at a time.

It publishes each frame of ``/clock`` only once every expected EMAC has reported the frame before
(``window`` frames of slack), so a suite runs as fast as it can and the same every time. It starts
when every node named in ``--wait-for`` has announced itself on ``/ema/ready`` and stops at
``--duration``.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Sequence
from typing import Any

from std_msgs.msg import String

from ema_msgs_py import contract as ct
from ema_msgs_py.cdr import JointFrame
from ema_msgs_py.ros import qos
from ema_sim.nodes.common import SuiteNode, run
from ema_sim.nodes.ports import Ports

NS = 1_000_000_000


class ClockNode(SuiteNode):
    """The node (see the module docstring)."""

    def __init__(self, args: argparse.Namespace, ports: Any = Ports) -> None:
        super().__init__("simclock")
        self.ports = ports(self)
        self.auto_ready = False
        self.frame_ns = round(NS / args.frame_hz)
        self.last_frame = round(args.duration * args.frame_hz) if args.duration > 0 else None
        self.window = max(1, int(args.window))
        self.expected = [c for item in args.channels for c in item.split(",") if c]
        self.wait_for = {n for item in args.wait_for for n in item.split(",") if n}
        self.stall_s = args.stall_timeout
        self.rtf = args.realtime_factor
        self.ready: set[str] = set()
        self.reported: dict[str, int] = {}
        self.k = -1
        self.started_wall: float | None = None
        self.waiting_since = time.monotonic()
        self.stalls = 0
        self.pub = self.ports.clock_publisher()
        self.create_subscription(String, ct.READY, lambda m: self.ready.add(m.data), qos(ct.LATCHED_QOS))
        self.ports.frame_subscription(ct.EMAC_FEEDBACK, self._on_feedback,
                                      lambda text: self.throttled("bad", f"feedback message ignored: {text}"))
        self.get_logger().info(f"lockstep at {args.frame_hz:g} Hz, waiting for {sorted(self.wait_for) or 'nobody'}")

    def _on_feedback(self, msg: JointFrame) -> None:
        ns = msg.stamp_ns
        for name in msg.name:
            if ns > self.reported.get(name, -1):
                self.reported[name] = ns

    def _tick(self) -> None:
        self.k += 1
        ns = self.k * self.frame_ns
        self.pub.publish(ns)
        self.waiting_since = time.monotonic()

    def poll(self) -> float:  # noqa: D102
        now = time.monotonic()
        if self.started_wall is None:
            if not (self.wait_for <= self.ready and self.matched()):
                return 0.01
            self.started_wall = now
            self.mark_running()
            self._tick()
            return 0.0
        if self.last_frame is not None and self.k >= self.last_frame:
            if self._barrier(self.k) or now - self.waiting_since > self.stall_s:
                self.done = True
                self.finished_wall = now
            return 0.002
        need = (self.k + 1 - self.window) * self.frame_ns
        if need >= 0 and not self._barrier(self.k + 1 - self.window):
            if now - self.waiting_since <= self.stall_s:
                return 0.002
            self.stalls += 1
            self.throttled("stall", f"no feedback for frame {need / NS:.3f} s from "
                           f"{[c for c in self.expected if self.reported.get(c, -1) < need]} after "
                           f"{self.stall_s:g} s; going on")
        if self.rtf > 0.0:
            due = self.started_wall + (self.k + 1) * self.frame_ns / NS / self.rtf
            if now < due:
                return due - now
        self._tick()
        return 0.0

    def _barrier(self, k: int) -> bool:
        need = k * self.frame_ns
        return all(self.reported.get(c, -1) >= need for c in self.expected)

    def summary(self) -> dict[str, Any]:  # noqa: D102
        frames = max(self.k, 0)
        if self.started_wall is None:
            return {"frames": 0}
        wall = getattr(self, "finished_wall", time.monotonic()) - self.started_wall
        sim = frames * self.frame_ns / NS
        return {"frames": frames, "sim_s": sim, "wall_s": wall, "realtime_factor": sim / wall if wall > 0 else 0.0,
                "stalls": self.stalls}


def parser() -> argparse.ArgumentParser:
    """Command-line arguments."""
    p = argparse.ArgumentParser(prog="simclock", description="Lockstep /clock for the node suite.")
    p.add_argument("--frame-hz", type=float, default=ct.FRAME_HZ)
    p.add_argument("--duration", type=float, default=0.0, help="simulated seconds to run (0: until stopped)")
    p.add_argument("--channels", action="append", default=[], help="EMAC channels whose feedback gates each frame")
    p.add_argument("--wait-for", action="append", default=[], help="node names to wait for on /ema/ready")
    p.add_argument("--window", type=int, default=1, help="frames the clock may run ahead of the slowest EMAC")
    p.add_argument("--stall-timeout", type=float, default=5.0, help="wall seconds to wait for a frame's feedback")
    p.add_argument("--realtime-factor", type=float, default=0.0, help="pace to this multiple of real time (0: free)")
    return p


def main(argv: Sequence[str] | None = None) -> int:
    """Console script ``simclock``."""
    return run(ClockNode, parser(), argv)


if __name__ == "__main__":
    raise SystemExit(main())
