"""``testenv``: the test environment between FMU and EMACs, both directions (section 4.3).

``/ema/fmu/command`` → command path → ``/ema/emac/command`` and ``/ema/emac/feedback`` → feedback path
→ ``/ema/fmu/feedback``, per channel, one frame per message, stamps kept: the frame a value leaves in
is the frame it came in, its content is what the environment made of it. The profile (``--profile
ail|flight|none`` or a parameter file) sets transport delay, the FMU's 50 Hz lags, 5 mV quantization
and noise; ``--disable`` switches elements off. A non-finite value passes through untouched and
unfiltered (it does not poison the filters); the EMAC rejects it and counts it.
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Sequence
from typing import Any

from ema_msgs_py import contract as ct
from ema_msgs_py.cdr import JointFrame
from ema_sim.environment import Profile, SignalPath, TransportDelay, load_profile
from ema_sim.environment.profile import PATHS
from ema_sim.nodes.common import SuiteNode, run
from ema_sim.nodes.params import merged, overrides
from ema_sim.nodes.ports import Ports


class TestEnvNode(SuiteNode):
    """The node (see the module docstring)."""

    def __init__(self, args: argparse.Namespace, ports: Any = Ports) -> None:
        super().__init__("testenv", automatically_declare_parameters_from_overrides=True)
        self.ports = ports(self)
        profile = load_profile(args.profile)
        own = overrides(self)
        if any(k in own for k in (*PATHS, "seed", "full_scale_v")):
            base = {"profile": profile.name, "seed": profile.seed, "full_scale_v": profile.full_scale_v,
                    "command": profile.command.as_dict(), "feedback": profile.feedback.as_dict()}
            profile = Profile.from_parameters(merged(base, own), "testenv parameters")
        disable = [d for item in (args.disable or []) for d in item.split(",") if d.strip()]
        self.profile = profile.without(*disable) if disable else profile
        if args.seed is not None:
            self.profile = self.profile.with_seed(args.seed)
        self.frame_s = 1.0 / args.frame_hz
        self.cmd_paths: dict[str, SignalPath] = {}
        self.fb_paths: dict[str, SignalPath] = {}
        self.cur_delays: dict[str, TransportDelay] = {}
        self.frames = {"command": 0, "feedback": 0}
        self.passed_bad = 0
        self.cmd_pub = self.ports.frame_publisher(ct.EMAC_COMMAND)
        self.fb_pub = self.ports.frame_publisher(ct.FMU_FEEDBACK)
        self.ports.frame_subscription(ct.FMU_COMMAND, self._on_command, self._bad_message)
        self.ports.frame_subscription(ct.EMAC_FEEDBACK, self._on_feedback, self._bad_message)
        d = self.profile.describe()
        self.get_logger().info(f"profile {d['profile']}: command {d['command_path']}; feedback {d['feedback_path']}")

    def _path(self, table: dict[str, Any], channel: str, make: Any, value: float) -> Any:
        path = table.get(channel)
        if path is None:
            stream = ct.CHANNELS.index(channel) if channel in ct.CHANNELS else len(table) + len(ct.CHANNELS)
            path = table[channel] = make(self.frame_s, stream, value if math.isfinite(value) else 0.0)
        return path

    def _through(self, path: Any, value: float) -> float:
        if not math.isfinite(value):
            self.passed_bad += 1
            self.throttled("bad", f"non-finite value passed through untouched ({self.passed_bad} so far)")
            return value
        return float(path.step(value))

    def _bad_message(self, text: str) -> None:
        self.throttled("drop", f"message dropped: {text}")

    def _on_command(self, msg: JointFrame) -> None:
        try:
            pos = msg.position
            values = []
            for i, name in enumerate(msg.name):
                v = float(pos[i]) if i < len(pos) else math.nan
                values.append(self._through(self._path(self.cmd_paths, name, self.profile.command_path, v), v))
            self.frames["command"] += 1
            self.mark_running()
            self.cmd_pub.publish(JointFrame(msg.stamp_ns, msg.name, values, frame_id=msg.frame_id))
        except Exception as exc:  # a bad message never kills the node
            self.throttled("drop", f"command message dropped: {exc}")

    def _on_feedback(self, msg: JointFrame) -> None:
        try:
            pos, cur = [], []
            position, effort = msg.position, msg.effort
            with_current = len(effort) == len(msg.name)
            for i, name in enumerate(msg.name):
                v = float(position[i]) if i < len(position) else math.nan
                pos.append(self._through(self._path(self.fb_paths, name, self.profile.feedback_path, v), v))
                if with_current:
                    a = float(effort[i])
                    delay = self.cur_delays.get(name)
                    if delay is None:
                        delay = self.cur_delays[name] = self.profile.current_delay(self.frame_s)
                        delay.reset(a if math.isfinite(a) else 0.0)
                    cur.append(float(delay.step(a)) if math.isfinite(a) else a)
            self.frames["feedback"] += 1
            self.fb_pub.publish(JointFrame(msg.stamp_ns, msg.name, pos, [], cur, msg.frame_id))
        except Exception as exc:
            self.throttled("drop", f"feedback message dropped: {exc}")

    def summary(self) -> dict[str, Any]:  # noqa: D102
        return {"profile": self.profile.describe(), "frames": dict(self.frames), "passed_bad": self.passed_bad}


def parser() -> argparse.ArgumentParser:
    """Command-line arguments."""
    p = argparse.ArgumentParser(prog="testenv", description="Test environment between FMU and EMACs (section 4.3).")
    p.add_argument("--profile", default="none", help="ail, flight, none, or a profile parameter file")
    p.add_argument("--disable", action="append", default=[],
                   help="switch elements off: delay, lag, quantization, noise, or command.X / feedback.X")
    p.add_argument("--seed", type=int, default=None, help="noise seed (default: the profile's)")
    p.add_argument("--frame-hz", type=float, default=ct.FRAME_HZ, help="FMU frame rate (200)")
    return p


def main(argv: Sequence[str] | None = None) -> int:
    """Console script ``testenv``."""
    return run(TestEnvNode, parser(), argv)


if __name__ == "__main__":
    raise SystemExit(main())
