"""``fmu``: the flight computer and its vehicle simulation in the loop (aircraft in the loop, 2.10, 4.3).

Runs :class:`~ema_sim.ail.fmu.Fmu` (attitude-hold autopilot, rigid-body vehicle, aerodynamic hinge
moments; ``config/ail_vehicle.yaml``) one FMU frame at a time: takes ``/ema/fmu/feedback`` (the LVDT
feedback after the test environment), ``/ema/sensor/surface`` (the true surface angles) and, open loop,
``/ema/emac/command`` (what reached the actuators, for the simulation's model actuator); publishes
``/ema/fmu/command`` (volts, every channel), ``/ema/load/hinge_moment`` (what loads the real surfaces)
and ``/ema/fmu/vehicle`` (the vehicle's states); records every topic of the graph into a rosbag2 (MCAP)
as the maneuver node does, the run's parameters in its metadata.

Lockstep (``use_sim_time``): frame *k* is computed when ``/clock`` has reached *kT* and the inputs the
frame uses (:attr:`~ema_sim.ail.fmu.Fmu.needs`) stamped for it have arrived, so the run is the offline
``ema ail`` run frame for frame. Real time: frames are paced by the wall clock at the FMU rate and use
the newest inputs received.
"""

from __future__ import annotations

import argparse
import datetime as dt
import math
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from ema_msgs_py import cdr
from ema_msgs_py import contract as ct
from ema_sim import __version__
from ema_sim.ail.fmu import EMAC_COMMAND, FEEDBACK, SURFACE, Fmu, FrameInputs
from ema_sim.ail.params import config_path, load_ail_config
from ema_sim.ail.vehicle import STATES
from ema_sim.config import CHANNELS
from ema_sim.errors import EmaError
from ema_sim.nodes.common import run
from ema_sim.nodes.driver import NS, DriverNode, calibration_metadata, stamped_bag
from ema_sim.nodes.params import overrides
from ema_sim.nodes.ports import Ports
from ema_sim.nodes.recorder import Recorder

INPUT_TOPICS = {FEEDBACK: ct.FMU_FEEDBACK, SURFACE: ct.SURFACE, EMAC_COMMAND: ct.EMAC_COMMAND}
INPUT_FIELDS = {FEEDBACK: "position", SURFACE: "position", EMAC_COMMAND: "position"}


def default_bag(profile: str) -> Path:
    """``bags/ail_<profile>_<UTC time>``."""
    return stamped_bag(f"ail_{profile}")


class FmuNode(DriverNode):
    """The node (see the module docstring)."""

    def __init__(self, args: argparse.Namespace, ports: Any = Ports) -> None:
        super().__init__("fmu", automatically_declare_parameters_from_overrides=True)
        self.ports = ports(self)
        self.auto_ready = False  # ready when the run starts, after its recorder is matched
        self.lockstep = self.sim_time
        cfg = load_ail_config(args.vehicle_config, overrides(self))
        if abs(cfg.frame_hz - args.frame_hz) > 1e-9:
            raise EmaError(f"--frame-hz {args.frame_hz:g} differs from the vehicle parameters' {cfg.frame_hz:g} Hz")
        setup = cfg.setup(args.profile, aero_input=args.aero_input, surface_load=args.surface_load,
                          bungee_inlb=args.bungee)
        self.fmu = Fmu(cfg, setup, open_loop=args.open_loop, sim_model=args.sim_model)
        self.frame_ns = round(NS / cfg.frame_hz)
        if not (math.isfinite(args.duration) and args.duration > 0.0):
            raise EmaError(f"--duration must be a positive number of seconds, got {args.duration!r}")
        self.frames = max(1, round(args.duration * cfg.frame_hz))
        self.wait_s = float(args.lockstep_wait)
        meta = {
            "test": "ail", "section": "2.10, 4.3", "title": "aircraft in the loop: attitude hold in trimmed flight",
            "channel": "left_wing", "channels": ",".join(CHANNELS), "maneuver": "", "load": setup.surface_load,
            "duration_s": f"{self.frames / cfg.frame_hz:g}", "dynamic": "false", "model": args.model,
            "profile": args.profile, "mode": "open loop" if args.open_loop else "closed loop",
            "sim_model": self.fmu.sim_model if args.open_loop else "", "setup": setup.describe(),
            "vehicle_config": str(config_path(args.vehicle_config)),
            "seed": "" if args.seed is None else str(args.seed),
            "disabled": ",".join(args.disable) or "none", "clock": "lockstep" if self.lockstep else "realtime",
            "frame_hz": f"{cfg.frame_hz:g}", "frames": str(self.frames), "commanded": ",".join(CHANNELS),
            "generator": f"ema_sim {__version__} fmu node", "recorded_utc": dt.datetime.now(dt.UTC).isoformat(),
        }
        meta.update(calibration_metadata(CHANNELS))
        self._open_run(Path(args.bag) if args.bag else default_bag(args.profile), meta, args.wait_for)
        hooks = {topic: (lambda raw, _log_time, kind=kind: self._on_input(kind, raw))
                 for kind, topic in INPUT_TOPICS.items()}
        self.recorder = Recorder(self, self.writer, lockstep=self.lockstep, ports=self.ports,
                                 own=(ct.FMU_COMMAND, ct.HINGE_MOMENT, ct.VEHICLE), hooks=hooks,
                                 on_clock=self._on_clock)
        self.cmd_pub = self.ports.frame_publisher(ct.FMU_COMMAND)
        self.load_pub = self.ports.frame_publisher(ct.HINGE_MOMENT)
        self.vehicle_pub = self.ports.frame_publisher(ct.VEHICLE)
        self.clock_ns: int | None = None
        self.inputs: dict[str, dict[int, dict[str, float]]] = {kind: {} for kind in INPUT_TOPICS}
        self.latest: dict[str, dict[str, float]] = {kind: {} for kind in INPUT_TOPICS}
        self.waiting_since: float | None = None
        self.waits_given_up = 0
        self.get_logger().info(f"aircraft in the loop, profile {args.profile}, {meta['mode']}: {setup.describe()}; "
                               f"{self.frames} frames; bag {self.bag_path}")

    # ----------------------------------------------------------------- callbacks (never raise)
    def _on_clock(self, ns: int) -> None:
        self.clock_ns = ns if self.clock_ns is None else max(self.clock_ns, ns)

    def _on_input(self, kind: str, raw: bytes) -> None:
        try:
            msg = cdr.decode(raw)
        except ValueError as exc:  # never lose the node over one message
            self.throttled(f"bad {kind}", f"{INPUT_TOPICS[kind]}: {exc}")
            return
        values = getattr(msg, INPUT_FIELDS[kind])
        frame = self.inputs[kind].setdefault(msg.stamp_ns, {}) if self.lockstep else {}
        for i, name in enumerate(msg.name):
            if name in CHANNELS and i < len(values):
                frame[name] = float(values[i])
                self.latest[kind][name] = float(values[i])

    # ----------------------------------------------------------------- frames
    def _stamp_of(self, kind: str, k: int) -> int:
        """The stamp a frame's input carries: the EMAC-side command is the previous frame's."""
        return (k - 1) * self.frame_ns if kind == EMAC_COMMAND else k * self.frame_ns

    def _have(self, k: int) -> bool:
        return all(set(CHANNELS) <= self.inputs[kind].get(self._stamp_of(kind, k), {}).keys()
                   for kind in self.fmu.needs)

    def _frame_inputs(self, k: int, *, newest: bool) -> FrameInputs:
        def pick(kind: str) -> dict[str, float]:
            if newest:
                return dict(self.latest[kind])
            got = self.inputs[kind].get(self._stamp_of(kind, k), {})
            return {ch: got.get(ch, self.latest[kind].get(ch, math.nan)) for ch in CHANNELS}

        return FrameInputs(pick(FEEDBACK), pick(SURFACE), pick(EMAC_COMMAND) if self.fmu.open_loop else None)

    def _publish_frame(self, k: int, stamp: int, inputs: FrameInputs) -> None:
        out = self.fmu.frame(inputs)
        names = list(CHANNELS)
        load = cdr.JointFrame(stamp, names, [], [], [float(out.hinge_moment_inlb[ch]) for ch in CHANNELS])
        cmd = cdr.JointFrame(stamp, names, [float(out.command_v[ch]) for ch in CHANNELS])
        vehicle = cdr.JointFrame(stamp, list(STATES), [float(v) for v in out.vehicle.values()])
        self.load_pub.publish(load)
        self.cmd_pub.publish(cmd)
        self.vehicle_pub.publish(vehicle)
        for topic, frame in ((ct.HINGE_MOMENT, load), (ct.FMU_COMMAND, cmd), (ct.VEHICLE, vehicle)):
            self.recorder.record_own(topic, cdr.encode(frame), stamp)
        oldest = (k - 2) * self.frame_ns
        for table in self.inputs.values():
            for s in [s for s in table if s < oldest]:
                del table[s]

    def poll(self) -> float:  # noqa: D102
        now = time.monotonic()
        self.recorder.discover()
        if self.phase == "waiting":
            return self._wait_ready()
        if self.phase == "running":
            return self._run_lockstep(now) if self.lockstep else self._run_realtime(now)
        return self._finish_up(now)

    def _run_lockstep(self, now: float) -> float:
        if self.clock_ns is None:
            return 0.01
        while self.k < self.frames and self.k * self.frame_ns <= self.clock_ns:
            if not self._have(self.k):
                if self.waiting_since is None:
                    self.waiting_since = now
                if now - self.waiting_since < self.wait_s:
                    return 0.002
                self.waits_given_up += 1
                self.throttled("wait", f"inputs {sorted(self.fmu.needs)} of frame {self.k} missing after "
                               f"{self.wait_s:g} s; going on with the newest values")
            self.waiting_since = None
            self._publish_frame(self.k, self.k * self.frame_ns, self._frame_inputs(self.k, newest=False))
            self.k += 1
        if self.k >= self.frames:
            self._finish(now, 10.0)
        return 0.01

    def _run_realtime(self, now: float) -> float:
        due = self.start_wall + self.k * self.frame_ns / NS
        if now < due:
            return due - now
        if now - due > self.frame_ns / NS:
            self.late_publish += 1
        self._publish_frame(self.k, self.get_clock().now().nanoseconds, self._frame_inputs(self.k, newest=True))
        self.k += 1
        if self.k >= self.frames:
            self._finish(now, 1.0)
            return 0.005
        return max(self.start_wall + self.k * self.frame_ns / NS - time.monotonic(), 0.0)

    def _answered(self) -> bool:
        """Lockstep: the feedback of the last frame is in; real time: the newest is what there is."""
        return not self.lockstep or max(self.inputs[FEEDBACK], default=-1) >= self.frames * self.frame_ns

    # ----------------------------------------------------------------- results
    def summary(self) -> dict[str, Any]:  # noqa: D102
        return {"bag": str(self.bag_path), "test": "ail", "frames_commanded": self.k, "frames": self.frames,
                "completed": self.k >= self.frames, "waits_given_up": self.waits_given_up,
                "late_publish": self.late_publish, **self.recorder.summary()}

    def close(self) -> None:  # noqa: D102
        self._close_bag(self.frames)


def parser() -> argparse.ArgumentParser:
    """Command-line arguments (ROS arguments go after ``--ros-args``)."""
    p = argparse.ArgumentParser(prog="fmu", description="Flight computer and vehicle simulation in the loop (AIL).")
    p.add_argument("--profile", default="ail", help="the test environment it runs in: ail, flight, none (its setup)")
    p.add_argument("--open-loop", action="store_true", help="drive the vehicle with a model actuator (2.10)")
    p.add_argument("--sim-model", default=None, help="open loop: the simulation's model actuator (default loada)")
    p.add_argument("--duration", type=float, default=24.0, help="seconds (default 24)")
    p.add_argument("--bag", default=None, help="bag directory to create (default bags/ail_<profile>_<time>)")
    p.add_argument("--model", default="", help="the EMACs' model, for the bag's metadata")
    p.add_argument("--seed", type=int, default=None, help="the test environment's noise seed, for the metadata")
    p.add_argument("--disable", action="append", default=[], help="disabled elements, for the metadata")
    p.add_argument("--bungee", type=float, default=None, help="load the wings with a bungee, in·lb")
    p.add_argument("--aero-input", choices=("feedback", "surface"), default=None)
    p.add_argument("--surface-load", choices=("aerodynamic", "bungee"), default=None)
    p.add_argument("--vehicle-config", default=None, help="parameter file (default config/ail_vehicle.yaml)")
    p.add_argument("--frame-hz", type=float, default=ct.FRAME_HZ)
    p.add_argument("--lockstep-wait", type=float, default=5.0, help="wall seconds to wait for a frame's inputs")
    p.add_argument("--wait-for", action="append", default=[], help="node names to wait for on /ema/ready")
    return p


def main(argv: Sequence[str] | None = None) -> int:
    """Console script ``fmu``."""
    return run(FmuNode, parser(), argv)


if __name__ == "__main__":
    raise SystemExit(main())
