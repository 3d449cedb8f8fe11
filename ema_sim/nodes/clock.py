"""``simclock``: the lockstep clock, one FMU frame at a time.

It publishes each frame of ``/clock`` only once every expected EMAC has reported the frame before
(``window`` frames of slack), so a suite runs as fast as it can and the same every time. With
``frames_per_message`` K > 1 it grants K frames at once after the first (``/clock`` jumps K frames), and the
nodes send each grant's frames as one message per topic (:mod:`ema_msgs_py.batch`). It starts
when every node named in ``--wait-for`` has announced itself on ``/ema/ready`` and stops at
``--duration``.

An EMAC that dies or stalls does not stop the run. Silent for ``silent_after_s`` (the EMACs' watchdog) while
the clock waits for it, its channel is ERROR on ``/diagnostics``; silent for ``stall_timeout_s``, it is left
out of lockstep (a WARN line, its status ERROR: the bag says so) and the clock goes on without it. Its feedback
reaching the clock's frame again (a restarted EMAC, which starts on the clock's present frame) puts it back
in lockstep (an INFO line, its status OK). Each gated channel has a status, ``simclock: lockstep <channel>``,
published at each change and once a second, stamped with the clock's present frame.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Sequence
from typing import TYPE_CHECKING

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import ParameterType
from std_msgs.msg import String

from ema_msgs_py import contract as ct
from ema_msgs_py.cdr import JointFrame
from ema_msgs_py.ros import qos
from ema_sim.config import config_dir, ros_parameters
from ema_sim.jsontypes import JsonObject, JsonValue
from ema_sim.nodes.common import MAX_SPIN_S, SuiteNode, run
from ema_sim.nodes.params import Spec, as_float, names_list
from ema_sim.nodes.ports import FRAMES_PER_MESSAGE, Ports, PortsFactory, frames_spec

if TYPE_CHECKING:
    from rclpy.parameter import AllowableParameterValue as ParameterValue

NS = 1_000_000_000
RESEND_S = 0.1
"""While a frame waits this long for the EMACs' feedback, the clock sends its present value again."""
STATUS_EVERY_S = 1.0
"""The lockstep statuses are published at each change and at least this often (wall time)."""


def watchdog_s() -> float:
    """The EMACs' watchdog (``config/emac.yaml``): how long a silent EMAC goes before its status is ERROR, s."""
    return float(ros_parameters(config_dir() / "emac.yaml").get("emac", {}).get("watchdog_timeout_s", 0.05))


class ClockNode(SuiteNode):
    """The node (see the module docstring).

    Parameters
    ----------
    args : argparse.Namespace or None
        The flags given on the node's command line (parameter overrides, :func:`~ema_sim.nodes.params.cli_overrides`).
    ports : callable
        Builds the node's topic ports from the node: :class:`~ema_sim.nodes.ports.Ports` on DDS, or a
        container's :meth:`~ema_sim.nodes.container.Bus.ports` when composed.
    name : str
        The node's name (a ``-r __node:=`` remapping renames it).
    """

    def __init__(self, args: argparse.Namespace | None = None, ports: PortsFactory = Ports,
                 name: str = "simclock") -> None:
        super().__init__(name, args)
        self.ports = ports(self)
        self.auto_ready = False
        strings = ParameterType.PARAMETER_STRING_ARRAY
        own = self.params.declare([
            Spec("frame_hz", ct.FRAME_HZ, "FMU frame rate", "Hz", 1.0, 1e5),
            Spec("duration_s", 0.0, "simulated seconds to run (0: until stopped)", "s", 0.0, 1e7),
            Spec("channels", [], "EMAC channels whose feedback gates each frame", kind=strings),
            Spec("wait_for", [], "nodes to wait for on ready before the first frame", kind=strings),
            Spec("window", 1, "frames the clock may run ahead of the slowest EMAC", low=1, high=1000),
            Spec("stall_timeout_s", 5.0, "wall seconds to wait for a silent EMAC's feedback before going on without "
                 "it (it rejoins when its feedback reaches the clock again)", "s", 0.0, 3600.0, read_only=False),
            Spec("silent_after_s", watchdog_s(), "wall seconds without a waited-for EMAC's feedback before its "
                 "lockstep status is ERROR (default: the EMACs' watchdog)", "s", 0.0, 3600.0, read_only=False),
            Spec("realtime_factor", 0.0, "pace to this multiple of real time (0: as fast as the suite goes)",
                 low=0.0, high=1e6),
            frames_spec(),
        ], name)
        self.grant = int(own[FRAMES_PER_MESSAGE])
        """Frames granted at once after the first (``frames_per_message``): the nodes send them as one message."""
        frame_hz: float = own["frame_hz"]
        self.frame_ns = round(NS / frame_hz)
        self.last_frame = round(own["duration_s"] * frame_hz) if own["duration_s"] > 0 else None
        self.window = int(own["window"])
        self.expected = list(own["channels"])
        self.wait_for = set(own["wait_for"])
        self.stall_s: float = own["stall_timeout_s"]
        self.silent_s: float = own["silent_after_s"]
        self.rtf: float = own["realtime_factor"]
        self.params.on_change("stall_timeout_s", self._set_stall)
        self.params.on_change("silent_after_s", self._set_silent)
        self.silent: dict[str, float] = {}
        """Channels whose feedback is overdue by more than ``silent_after_s``: when they fell silent (wall)."""
        self.left_out: dict[str, float] = {}
        """Channels left out of lockstep (silent beyond ``stall_timeout_s``): when they were left out (wall)."""
        self.left_out_count = 0
        self.rejoined = 0
        self.rejoin_s: list[float] = []
        """Each rejoin: wall seconds from being left out to being back in lockstep."""
        self.status_due = 0.0
        self.diag_pub = self.create_publisher(DiagnosticArray, ct.endpoint(ct.DIAGNOSTICS), qos(ct.EVENT_QOS))
        self.last_sent = time.monotonic()
        self.ready: set[str] = set()
        self.reported: dict[str, int] = {}
        self.k = -1
        self.started_wall: float | None = None
        self.waiting_since = time.monotonic()
        self.stalls = 0
        self.resent = 0
        self.pub = self.ports.clock_publisher()
        self.create_subscription(String, ct.endpoint(ct.READY), self._on_ready, qos(ct.LATCHED_QOS))
        self.ports.frame_subscription(ct.EMAC_FEEDBACK, self._on_feedback,
                                      lambda text: self.throttled("bad", f"feedback message ignored: {text}"))
        self.get_logger().info(f"lockstep at {frame_hz:g} Hz, waiting for {sorted(self.wait_for) or 'nobody'}")

    def _on_ready(self, msg: String) -> None:
        self.ready.add(msg.data)

    def _set_stall(self, value: ParameterValue) -> str:
        old, self.stall_s = self.stall_s, as_float(value)
        return f"stall_timeout_s: {old:g} → {self.stall_s:g} s"

    def _set_silent(self, value: ParameterValue) -> str:
        old, self.silent_s = self.silent_s, as_float(value)
        return f"silent_after_s: {old:g} → {self.silent_s:g} s"

    def _on_feedback(self, msg: JointFrame) -> None:
        ns = msg.stamp_ns
        for name in msg.name:
            if ns > self.reported.get(name, -1):
                self.reported[name] = ns

    def _next(self) -> int:
        """The frame the next tick grants: the first, then :attr:`grant` frames on (never past the last)."""
        k = self.k + (1 if self.k < 0 else self.grant)
        return k if self.last_frame is None else min(k, self.last_frame)

    def _tick(self) -> None:
        self.k = self._next()
        self.pub.publish(self.k * self.frame_ns)
        self.waiting_since = self.last_sent = time.monotonic()

    def _resend(self, now: float) -> float:
        """While waiting, the present frame again every :data:`RESEND_S`.

        A subscriber may take ``/clock`` best effort (rclcpp's ClockQoS) and have missed it; a repeated value
        changes nothing for one that has it.
        """
        if self.k >= 0 and now - self.last_sent >= RESEND_S:
            self.pub.publish(self.k * self.frame_ns)
            self.last_sent = now
            self.resent += 1
        return 0.002

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
            if not self.done and (self._barrier(self.k) or now - self.waiting_since > self.stall_s):
                self.done = True
                self.finished_wall = now
            return MAX_SPIN_S if self.done else self._resend(now)  # done and composed: its driver ends the process
        need = (self.k + 1 - self.window) * self.frame_ns
        self._back_in_step(need, now)
        if need >= 0 and not self._barrier(self.k + 1 - self.window):
            waited = now - self.waiting_since
            if waited > self.silent_s:
                self._fall_silent(need, now, waited)
            if waited <= self.stall_s:
                return self._resend(now) if now < self.status_due else self._status(now)
            self.stalls += 1
            self._leave_out(need, now, waited)
        elif now >= self.status_due:
            self._status(now)
        if self.rtf > 0.0:
            due = self.started_wall + self._next() * self.frame_ns / NS / self.rtf
            if now < due:
                return due - now
        self._tick()
        return 0.0

    def _barrier(self, k: int) -> bool:
        """Every channel in lockstep (none left out) has reported frame ``k``."""
        need = k * self.frame_ns
        return all(self.reported.get(c, -1) >= need for c in self.expected if c not in self.left_out)

    def _missing(self, need: int) -> list[str]:
        """The channels in lockstep that have not reported the frame at ``need`` ns."""
        return [c for c in self.expected if c not in self.left_out and self.reported.get(c, -1) < need]

    def _fall_silent(self, need: int, now: float, waited: float) -> None:
        """Channels overdue beyond ``silent_after_s``: ERROR (once each, until they report again)."""
        new = [c for c in self._missing(need) if c not in self.silent]
        for c in new:
            self.silent[c] = now - waited
            self.get_logger().warning(f"{c}: no feedback for frame {need / NS:.3f} s for {waited * 1e3:.0f} ms "
                                      f"(silent_after_s {self.silent_s:g} s): ERROR until it reports")
        if new:
            self._status(now)

    def _leave_out(self, need: int, now: float, waited: float) -> None:
        """Channels silent beyond ``stall_timeout_s``: the clock goes on without them until they catch up."""
        for c in self._missing(need):
            self.left_out[c] = now
            self.silent.pop(c, None)
            self.left_out_count += 1
            self.get_logger().warning(
                f"{c}: no feedback for frame {need / NS:.3f} s after {waited:.2f} s (stall_timeout_s "
                f"{self.stall_s:g} s): left out of lockstep, the clock goes on without it until its feedback "
                "reaches the clock's frame again")
        self._status(now)

    def _back_in_step(self, need: int, now: float) -> None:
        """Silent or left-out channels whose feedback reached the frame the clock waits for: in lockstep again."""
        changed = False
        for c in [c for c in self.silent if self.reported.get(c, -1) >= need]:
            del self.silent[c]
            changed = True
        for c, since in list(self.left_out.items()):
            if self.reported.get(c, -1) >= need:
                del self.left_out[c]
                self.rejoined += 1
                self.rejoin_s.append(now - since)
                changed = True
                self.get_logger().info(f"{c}: back in lockstep at frame {need / NS:.3f} s, {now - since:.2f} s "
                                       f"after it was left out ({self.rejoined} rejoin(s) so far)")
        if changed:
            self._status(now)

    def _status(self, now: float) -> float:
        """Publish each gated channel's lockstep status (``/diagnostics``); the next poll's delay, s."""
        self.status_due = now + STATUS_EVERY_S
        frame_ns = max(self.k, 0) * self.frame_ns
        msg = DiagnosticArray()
        msg.header.stamp = Time(sec=frame_ns // NS, nanosec=frame_ns % NS)
        for c in self.expected:
            last = self.reported.get(c, -1)
            if c in self.left_out:
                level, text = DiagnosticStatus.ERROR, (f"left out of lockstep {now - self.left_out[c]:.2f} s ago: "
                                                       "the clock goes on without it")
            elif c in self.silent:
                level, text = DiagnosticStatus.ERROR, f"silent for {now - self.silent[c]:.2f} s: the clock waits"
            else:
                level, text = DiagnosticStatus.OK, "in lockstep"
            values = {"last_frame_s": f"{last / NS:.6f}" if last >= 0 else "none",
                      "left_out": str(self.left_out_count), "rejoined": str(self.rejoined)}
            msg.status.append(DiagnosticStatus(level=level, name=f"{self.get_name()}: lockstep {c}", message=text,
                                               hardware_id=c,
                                               values=[KeyValue(key=k, value=v) for k, v in values.items()]))
        self.diag_pub.publish(msg)
        return 0.002

    def summary(self) -> JsonObject:  # noqa: D102
        frames = max(self.k, 0)
        if self.started_wall is None:
            return {"frames": 0}
        wall = getattr(self, "finished_wall", time.monotonic()) - self.started_wall
        sim = frames * self.frame_ns / NS
        return {"frames": frames, "sim_s": sim, "wall_s": wall, "realtime_factor": sim / wall if wall > 0 else 0.0,
                "stalls": self.stalls, "resent": self.resent, "left_out": self.left_out_count,
                "rejoined": self.rejoined, "rejoin_s": [round(x, 3) for x in self.rejoin_s],
                "out_of_lockstep": list[JsonValue](sorted(self.left_out))}


def parser() -> argparse.ArgumentParser:
    """Command-line flags: shorthands for the node's parameters."""
    p = argparse.ArgumentParser(prog="simclock", description="Lockstep /clock for the node suite.",
                                argument_default=argparse.SUPPRESS)
    p.add_argument("--frame-hz", dest="frame_hz", type=float, help="parameter frame_hz")
    p.add_argument("--duration", dest="duration_s", type=float, help="parameter duration_s: simulated seconds to run "
                   "(0: until stopped)")
    p.add_argument("--channels", action="append", type=names_list, help="parameter channels: EMAC channels whose "
                   "feedback gates each frame")
    p.add_argument("--wait-for", dest="wait_for", action="append", type=names_list,
                   help="parameter wait_for: node names to wait for on ready")
    p.add_argument("--window", type=int, help="parameter window: frames the clock may run ahead of the slowest EMAC")
    p.add_argument("--stall-timeout", dest="stall_timeout_s", type=float,
                   help="parameter stall_timeout_s: wall seconds to wait for a silent EMAC before going on without it")
    p.add_argument("--silent-after", dest="silent_after_s", type=float,
                   help="parameter silent_after_s: wall seconds of silence before an EMAC's lockstep status is ERROR")
    p.add_argument("--realtime-factor", dest="realtime_factor", type=float,
                   help="parameter realtime_factor: pace to this multiple of real time (0: free)")
    return p


def main(argv: Sequence[str] | None = None) -> int:
    """Console script ``simclock``.

    Parameters
    ----------
    argv : sequence of str or None
        The command line, ROS arguments included (None: ``sys.argv[1:]``).

    Returns
    -------
    int
        The process's exit status.
    """
    return run(ClockNode, parser(), argv)


if __name__ == "__main__":
    raise SystemExit(main())
