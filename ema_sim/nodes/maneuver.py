"""``maneuver``: drives a test of section 2 as the FMU and the load rig would, and records the bag.

Publishes ``/ema/fmu/command`` (volts, through each channel's command curve, every channel every frame:
the channels a test does not drive are held at 0°) and ``/ema/load/hinge_moment``, in real time from
its own 200 Hz loop or one frame per ``/clock`` frame under lockstep; records every topic of the
graph into a rosbag2 (MCAP) under ``bags/`` with the test's parameters in the bag's metadata. SIGINT
or SIGTERM closes the bag: every message received so far is in it. In real time it measures, per
frame, the time from publishing a command to receiving that frame's feedback back on the FMU side
(:mod:`ema_sim.nodes.frametimes`, which also tells why a frame was missed where it can).
"""

from __future__ import annotations

import argparse
import datetime as dt
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from rcl_interfaces.msg import ParameterType

from ema_msgs_py import cdr
from ema_msgs_py import contract as ct
from ema_sim import __version__
from ema_sim.config import load_channel
from ema_sim.jsontypes import JsonObject
from ema_sim.nodes.common import run
from ema_sim.nodes.driver import NS, START_DELAY_S, DriverNode, calibration_metadata, driver_specs, stamped_bag
from ema_sim.nodes.frametimes import FrameTimes
from ema_sim.nodes.params import Spec, names_list
from ema_sim.nodes.ports import FRAMES_PER_MESSAGE, Ports, PortsFactory, frames_spec, use_batches
from ema_sim.nodes.recorder import Recorder
from ema_sim.signals.plans import build_plan, channel_list


def default_bag(test: str) -> Path:
    """``bags/<test>_<UTC time>``.

    Parameters
    ----------
    test : str
        The section-2 test's name.

    Returns
    -------
    pathlib.Path
        The bag directory to create.
    """
    return stamped_bag(test)


class ManeuverNode(DriverNode):
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
                 name: str = "maneuver") -> None:
        super().__init__(name, args)
        self.ports = ports(self)
        self.auto_ready = False  # ready when the test starts, after its recorder is matched
        self.lockstep = self.sim_time
        strings = ParameterType.PARAMETER_STRING_ARRAY
        own = self.params.declare([
            *driver_specs(0.0, "seconds to run (0: the test's length)"),
            Spec("test", "", "section-2 test spec (ema tests), e.g. static_crosstalk:observed=right_wing"),
            Spec("maneuver", "", "maneuver spec of the driven channels (ema maneuvers)"),
            Spec("load", "", "hinge-moment spec of the driven channels"),
            Spec("channels", ["left_wing"], "driven channels", kind=strings),
            Spec("command_channels", ["all"], "channels the FMU commands", kind=strings),
            Spec("expect_feedback", [], "channels whose feedback ends each frame (empty: the driven ones)",
                 kind=strings),
            frames_spec(),
        ], name)
        use_batches(self.ports, int(own[FRAMES_PER_MESSAGE]), self.lockstep, name)
        frame_hz: float = own["frame_hz"]
        self.plan = build_plan(own["test"] or None, maneuver=own["maneuver"] or None, load=own["load"] or None,
                               channels=own["channels"] or ["left_wing"], duration_s=own["duration_s"] or None)
        self.frame_ns = round(NS / frame_hz)
        self.frames = max(1, round(self.plan.duration_s * frame_hz))
        self.commanded = channel_list(own["command_channels"] or ["all"])
        self.expect = channel_list(own["expect_feedback"]) or list(self.plan.channels)
        t = np.arange(self.frames) / frame_hz
        self.volts = {ch: np.asarray(load_channel(ch).deg_to_v(self.plan.command_deg(ch, t)), dtype=float)
                      for ch in self.commanded}
        self.loads = {ch: self.plan.hinge_moment_inlb(ch, t) for ch in self.commanded}
        meta = self.plan.metadata()
        meta.update({
            "model": own["model"], "profile": own["profile"], "clock": "lockstep" if self.lockstep else "realtime",
            "frame_hz": f"{frame_hz:g}", "frames": str(self.frames), "commanded": ",".join(self.commanded),
            "generator": f"ema_sim {__version__} maneuver node", "recorded_utc": dt.datetime.now(dt.UTC).isoformat(),
        })
        meta.update(calibration_metadata(self.commanded))
        self._open_run(Path(own["bag"]) if own["bag"] else default_bag(self.plan.test), meta, own["wait_for"])
        self.clock_ns: int | None = None
        self.recorder = Recorder(self, self.writer, lockstep=self.lockstep, ports=self.ports,
                                 own=(ct.FMU_COMMAND, ct.HINGE_MOMENT),
                                 hooks={ct.FMU_FEEDBACK: self._on_fmu_feedback}, on_clock=self._on_clock,
                                 hooks_at_frame=True)
        """The FMU's feedback too is read once a frame (as a flight computer reads its inputs), each message's
        arrival being the time DDS received it. Under lockstep ``/clock`` wakes the node: the clock's frame and the
        FMU feedback ending the frame before it leave the EMACs' feedback at the same time, two hops from it (the
        clock; the test environment), so the five feedback messages need not wake it too."""
        self.cmd_pub = self.ports.frame_publisher(ct.FMU_COMMAND)
        self.load_pub = self.ports.frame_publisher(ct.HINGE_MOMENT)
        self._names = list(self.commanded)
        self.start_ns = 0
        self.times = FrameTimes(0 if self.lockstep else self.frames, self.expect, self.frame_ns / NS,
                                one_thread=bool(getattr(self.ports, "composed", False)))
        """Real time: per-frame command and feedback times (composed, the path runs in this thread)."""
        self.last_fb_stamp: dict[str, int] = {}
        self.get_logger().info(f"test {self.plan.test} ({self.plan.title}) on {', '.join(self.plan.channels)}; "
                               f"{self.plan.duration_s:g} s; bag {self.bag_path}")

    # ----------------------------------------------------------------- callbacks
    def _on_clock(self, ns: int) -> None:
        if self.clock_ns is None or ns > self.clock_ns:
            self.clock_ns = ns

    def _on_fmu_feedback(self, raw: bytes, log_time: int) -> None:
        msg = cdr.decode(raw)
        stamp = msg.stamp_ns
        for name in msg.name:
            if stamp > self.last_fb_stamp.get(name, -1):
                self.last_fb_stamp[name] = stamp
        if self.lockstep:  # the feedback ending a frame: the suite's time has reached its stamp
            self._on_clock(stamp)
        elif self.phase != "waiting":
            # feedback of frame k is stamped at its end; it arrived when received (the log time, system clock)
            arrived = time.monotonic() - max(time.time_ns() - log_time, 0) / NS
            self.times.feedback((stamp - self.start_ns) // self.frame_ns - 1, msg.name, arrived)

    # ----------------------------------------------------------------- the test
    def _publish_frame(self, k: int, stamp: int) -> float:
        """Frame ``k``'s load, then its command; returns when the command's publish began (monotonic)."""
        load = cdr.JointFrame(stamp, self._names, [], [], [float(self.loads[ch][k]) for ch in self._names])
        cmd = cdr.JointFrame(stamp, self._names, [float(self.volts[ch][k]) for ch in self._names])
        load_raw = self.load_pub.publish(load)
        if not self.lockstep:
            self.times.mark_sent()
        sent = time.monotonic()
        cmd_raw = self.cmd_pub.publish(cmd)
        # the bytes sent on DDS (a composed publisher hands the frame over in-process and gives none back)
        self.recorder.record_own(ct.HINGE_MOMENT, load_raw if isinstance(load_raw, bytes) else cdr.encode(load), stamp)
        self.recorder.record_own(ct.FMU_COMMAND, cmd_raw if isinstance(cmd_raw, bytes) else cdr.encode(cmd), stamp)
        return sent

    def poll(self) -> float:  # noqa: D102
        now = time.monotonic()
        if self.lockstep or self.phase != "running" or self._slack(now) > 0.003:
            self.recorder.discover()  # a graph query: in real time only where a frame has room for it
        if self.phase == "waiting":
            self._take_recorded()
            return self._wait_ready()
        if self.phase == "running":
            return self._run_lockstep(now) if self.lockstep else self._run_realtime(now)
        self._take_recorded()
        return self._finish_up(now)

    def _started(self) -> None:
        self.start_ns = self.get_clock().now().nanoseconds + round(START_DELAY_S * NS)
        if not self.lockstep:
            self.times.start()

    def _answered(self) -> bool:
        end = self.start_ns + self.frames * self.frame_ns
        return all(self.last_fb_stamp.get(c, -1) >= end for c in self.expect)

    def _slack(self, now: float) -> float:
        return self.start_wall + self.k * self.frame_ns / NS - now

    def _run_realtime(self, now: float) -> float:
        due = self.start_wall + self.k * self.frame_ns / NS
        if now < due:
            return due - now
        if now - due > self.frame_ns / NS:
            self.late_publish += 1
        self.times.sent_at(self._publish_frame(self.k, self.start_ns + self.k * self.frame_ns))
        self._take_recorded()  # once the frame is out (and counted: its feedback may be in already)
        self.k += 1
        if self.k >= self.frames:
            self.times.end()
            self._finish(now, 1.0)
            return 0.005
        return self.start_wall + self.k * self.frame_ns / NS - time.monotonic()

    def _run_lockstep(self, now: float) -> float:
        if self.clock_ns is None:
            return 0.01
        if self.k == 0:
            self.start_ns = 0
        while self.k < self.frames and self.k * self.frame_ns <= self.clock_ns:
            self._publish_frame(self.k, self.k * self.frame_ns)
            self.k += 1
        self._take_recorded()
        if self.k >= self.frames:
            self._finish(now, 10.0)
        return 0.01

    # ----------------------------------------------------------------- results
    def latency(self) -> JsonObject:
        """Command-to-feedback latency per frame (all expected channels back), real time only."""
        return {**self.times.summary(), "late_publish": self.late_publish}

    def summary(self) -> JsonObject:  # noqa: D102
        out: JsonObject = {"bag": str(self.bag_path), "test": self.plan.test, "frames_commanded": self.k,
                               "completed": self.phase in ("finishing", "draining") or self.done,
                               **self.recorder.summary()}
        if not self.lockstep:
            out.update(self.latency())
        return out

    def close(self) -> None:  # noqa: D102
        extra = {}
        if not self.lockstep and self.times.count:
            extra = {f"realtime.{key}": f"{value:.4g}" if isinstance(value, float) else str(value)
                     for key, value in self.latency().items()}
        self._close_bag(self.frames, extra)


def parser() -> argparse.ArgumentParser:
    """Command-line flags: shorthands for the node's parameters."""
    p = argparse.ArgumentParser(prog="maneuver", description="Drive a section-2 test and record the bag.",
                                argument_default=argparse.SUPPRESS)
    p.add_argument("--test", help="parameter test: test spec (ema tests lists them), e.g. "
                   "static_crosstalk:observed=right_wing")
    p.add_argument("--maneuver", help="parameter maneuver: maneuver spec for the driven channels (ema maneuvers)")
    p.add_argument("--load", help="parameter load: load spec for the driven channels")
    p.add_argument("--channels", action="append", type=names_list, help="parameter channels: driven channels")
    p.add_argument("--duration", dest="duration_s", type=float, help="parameter duration_s: seconds (default: the "
                   "test's length)")
    p.add_argument("--bag", help="parameter bag: bag directory to create (default bags/<test>_<time>)")
    p.add_argument("--model", help="parameter model: model name, for the bag's metadata")
    p.add_argument("--profile", help="parameter profile: test-environment profile, for the bag's metadata")
    p.add_argument("--frame-hz", dest="frame_hz", type=float, help="parameter frame_hz")
    p.add_argument("--command-channels", dest="command_channels", action="append", type=names_list,
                   help="parameter command_channels: channels the FMU commands (default all)")
    p.add_argument("--expect-feedback", dest="expect_feedback", action="append", type=names_list,
                   help="parameter expect_feedback: channels whose feedback ends each frame (default: the driven ones)")
    p.add_argument("--wait-for", dest="wait_for", action="append", type=names_list,
                   help="parameter wait_for: node names to wait for on ready")
    return p


def main(argv: Sequence[str] | None = None) -> int:
    """Console script ``maneuver``.

    Parameters
    ----------
    argv : sequence of str or None
        The command line, ROS arguments included (None: ``sys.argv[1:]``).

    Returns
    -------
    int
        The process's exit status.
    """
    return run(ManeuverNode, parser(), argv)


if __name__ == "__main__":
    raise SystemExit(main())
