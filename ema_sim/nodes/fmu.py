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
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path

from rcl_interfaces.msg import ParameterType

from ema_msgs_py import cdr
from ema_msgs_py import contract as ct
from ema_sim import __version__
from ema_sim.ail.fmu import EMAC_COMMAND, FEEDBACK, SURFACE, Fmu, FrameInputs
from ema_sim.ail.params import (
    AilConfig,
    AutopilotParams,
    FrameParams,
    HeldCommand,
    HingeMomentParams,
    MeasureParams,
    Setup,
    VehicleParams,
    config_path,
)
from ema_sim.ail.vehicle import STATES
from ema_sim.config import CHANNELS, ros_parameters
from ema_sim.errors import EmaError, UnknownNameError
from ema_sim.jsontypes import JsonObject
from ema_sim.nodes.common import run
from ema_sim.nodes.driver import NS, START_DELAY_S, DriverNode, calibration_metadata, driver_specs, stamped_bag
from ema_sim.nodes.params import Spec, config_specs, names_list, nested
from ema_sim.nodes.ports import Ports, PortsFactory
from ema_sim.nodes.recorder import Recorder
from ema_sim.parameters import ParameterInfo, describe

INPUT_TOPICS = {FEEDBACK: ct.FMU_FEEDBACK, SURFACE: ct.SURFACE, EMAC_COMMAND: ct.EMAC_COMMAND}
MODES = ("closed_loop", "open_loop")
INPUT_FIELDS = {FEEDBACK: "position", SURFACE: "position", EMAC_COMMAND: "position"}


def default_bag(profile: str) -> Path:
    """``bags/ail_<profile>_<UTC time>``.

    Parameters
    ----------
    profile : str
        The test-environment profile.

    Returns
    -------
    pathlib.Path
        The bag directory to create.
    """
    return stamped_bag(f"ail_{profile}")


def _keys(values: Mapping[str, object], section: str) -> list[object]:
    """The keys of one section of the vehicle file (none when it is absent or no mapping: its check says so)."""
    found = values.get(section, {})
    return list(found) if isinstance(found, Mapping) else []


def _declared(values: Mapping[str, object]) -> dict[str, ParameterInfo]:
    """YAML path → the declaration (unit, description) of the vehicle file's vehicle, autopilot and hinge moments."""
    out = {f"vehicle.{p.name}": p for p in describe(VehicleParams)}
    out.update({f"autopilot.{p.name}": p for p in describe(AutopilotParams)})
    for kind in _keys(values, "hinge_moment"):
        out.update({f"hinge_moment.{kind}.{p.name}": p for p in describe(HingeMomentParams)})
    (held,) = describe(HeldCommand)
    out.update({f"held_deg.{ch}": held for ch in _keys(values, "held_deg")})
    for profile in _keys(values, "setup"):
        out.update({f"setup.{profile}.{p.name}": p for p in describe(Setup)})
    out.update({f"measure.{p.name}": p for p in describe(MeasureParams)})
    out.update({p.name: p for p in describe(FrameParams)})
    return out


class FmuNode(DriverNode):
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
                 name: str = "fmu") -> None:
        super().__init__(name, args)
        self.ports = ports(self)
        self.auto_ready = False  # ready when the run starts, after its recorder is matched
        self.lockstep = self.sim_time
        path = config_path(self.params.declare([Spec(
            "vehicle_config", "", "vehicle and flight-computer parameter file (empty: config/ail_vehicle.yaml)")],
            name)["vehicle_config"] or None)
        file_values = ros_parameters(path)
        own = self.params.declare([
            *driver_specs(24.0, "seconds to fly", profile="ail", frame_hz=float(file_values.get("frame_hz", 200.0)),
                          profile_text="the test environment it runs in: ail, flight, none (its vehicle setup)"),
            Spec("mode", "closed_loop", "closed_loop (the actuators fly the vehicle) or open_loop (a model actuator "
                 "in the simulation does, 2.10)"),
            Spec("aero_input", "", "what drives the aerodynamics: feedback or surface (empty: the setup's)"),
            Spec("surface_load", "", "what loads the surfaces: aerodynamic or bungee (empty: the setup's)"),
            Spec("bungee_inlb", math.nan, "bungee on the wings (NaN: the setup's)", "in·lb"),
            Spec("seed", -1, "the test environment's noise seed, for the metadata (-1: the profile's)", low=-1,
                 high=2**62),
            Spec("disable", [], "elements switched off, for the metadata", kind=ParameterType.PARAMETER_STRING_ARRAY),
            Spec("lockstep_wait_s", 5.0, "lockstep: wall seconds to wait for a frame's inputs", "s", 0.0, 3600.0),
        ], name)
        specs = [spec for spec in config_specs(file_values, path.name, known=_declared(file_values))
                 if spec.name != "frame_hz"]
        vehicle = self.params.declare(specs, f"{name}: {path.name}")
        cfg = AilConfig.from_parameters(nested({**vehicle, "frame_hz": own["frame_hz"]}), f"{name} parameters")
        if own["mode"] not in MODES:
            raise UnknownNameError("mode", own["mode"], MODES)
        open_loop = own["mode"] == "open_loop"
        bungee = None if math.isnan(own["bungee_inlb"]) else own["bungee_inlb"]
        setup = cfg.setup(own["profile"], aero_input=own["aero_input"] or None,
                          surface_load=own["surface_load"] or None, bungee_inlb=bungee)
        self.fmu = Fmu(cfg, setup, open_loop=open_loop)
        self.frame_ns = round(NS / cfg.frame_hz)
        if not own["duration_s"] > 0.0:
            raise EmaError(f"duration_s must be a positive number of seconds, got {own['duration_s']!r}")
        self.frames = max(1, round(own["duration_s"] * cfg.frame_hz))
        self.wait_s = float(own["lockstep_wait_s"])
        args_model, profile, seed, disable = own["model"], own["profile"], own["seed"], own["disable"]
        meta = {
            "test": "ail", "section": "2.10, 4.3", "title": "aircraft in the loop: attitude hold in trimmed flight",
            "channel": "left_wing", "channels": ",".join(CHANNELS), "maneuver": "", "load": setup.surface_load,
            "duration_s": f"{self.frames / cfg.frame_hz:g}", "dynamic": "false", "model": args_model,
            "profile": profile, "mode": "open loop" if open_loop else "closed loop",
            "sim_model": self.fmu.sim_model if open_loop else "", "setup": setup.describe(),
            "vehicle_config": str(path), "seed": "" if seed < 0 else str(seed),
            "disabled": ",".join(disable) or "none", "clock": "lockstep" if self.lockstep else "realtime",
            "frame_hz": f"{cfg.frame_hz:g}", "frames": str(self.frames), "commanded": ",".join(CHANNELS),
            "generator": f"ema_sim {__version__} fmu node", "recorded_utc": dt.datetime.now(dt.UTC).isoformat(),
        }
        meta.update(calibration_metadata(CHANNELS))
        self._open_run(Path(own["bag"]) if own["bag"] else default_bag(profile), meta, own["wait_for"])
        hooks = {topic: self._input_hook(kind) for kind, topic in INPUT_TOPICS.items()}
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
        self.start_ns = 0
        self.get_logger().info(f"aircraft in the loop, profile {profile}, {meta['mode']}: {setup.describe()}; "
                               f"{self.frames} frames; bag {self.bag_path}")

    # ----------------------------------------------------------------- callbacks (never raise)
    def _on_clock(self, ns: int) -> None:
        self.clock_ns = ns if self.clock_ns is None else max(self.clock_ns, ns)

    def _input_hook(self, kind: str) -> Callable[[bytes, int], None]:
        """The recorder's hook for input ``kind``: :meth:`_on_input` with the message (its log time unused)."""
        def hook(raw: bytes, _log_time: int) -> None:
            self._on_input(kind, raw)
        return hook

    def _on_input(self, kind: str, raw: bytes) -> None:
        try:
            msg = cdr.decode(raw)
        except ValueError as exc:  # never lose the node over one message
            self.throttled(f"bad {kind}", f"{INPUT_TOPICS[kind]}: {exc}")
            return
        values = getattr(msg, INPUT_FIELDS[kind])
        if self.lockstep:  # an input stamped for a frame: the suite's time has reached it
            self._on_clock(msg.stamp_ns)
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
        self._take_recorded()  # once the frame is out: its path does not wait for the bag
        oldest = (k - 2) * self.frame_ns
        for table in self.inputs.values():
            for s in [s for s in table if s < oldest]:
                del table[s]

    def poll(self) -> float:  # noqa: D102
        now = time.monotonic()
        self.recorder.discover()
        if self.phase == "waiting":
            self._take_recorded()
            return self._wait_ready()
        if self.phase == "running":
            return self._run_lockstep(now) if self.lockstep else self._run_realtime(now)
        self._take_recorded()
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
        missing = [f"{kind} {ch}" for kind in self.fmu.needs for ch in CHANNELS if ch not in self.latest[kind]]
        if missing:  # nothing to fly on yet: the first frame waits for every input once
            self.throttled("inputs", f"waiting for {', '.join(missing[:4])}{' …' if len(missing) > 4 else ''}")
            self.start_wall = now + self.frame_ns / NS
            self.start_ns = self.get_clock().now().nanoseconds + self.frame_ns
            return self.frame_ns / NS
        if now - due > self.frame_ns / NS:
            self.late_publish += 1
        self._publish_frame(self.k, self.start_ns + self.k * self.frame_ns, self._frame_inputs(self.k, newest=True))
        self.k += 1
        if self.k >= self.frames:
            self._finish(now, 1.0)
            return 0.005
        return max(self.start_wall + self.k * self.frame_ns / NS - time.monotonic(), 0.0)

    def _started(self) -> None:
        """Real time: frames stamped on the frame grid from the first one's ROS time."""
        self.start_ns = self.get_clock().now().nanoseconds + round(START_DELAY_S * NS)

    def _answered(self) -> bool:
        """Lockstep: the feedback of the last frame is in; real time: the newest is what there is."""
        return not self.lockstep or max(self.inputs[FEEDBACK], default=-1) >= self.frames * self.frame_ns

    # ----------------------------------------------------------------- results
    def summary(self) -> JsonObject:  # noqa: D102
        return {"bag": str(self.bag_path), "test": "ail", "frames_commanded": self.k, "frames": self.frames,
                "completed": self.k >= self.frames, "waits_given_up": self.waits_given_up,
                "late_publish": self.late_publish, **self.recorder.summary()}

    def close(self) -> None:  # noqa: D102
        self._close_bag(self.frames)


def parser() -> argparse.ArgumentParser:
    """Command-line flags: shorthands for the node's parameters (ROS arguments go after ``--ros-args``)."""
    p = argparse.ArgumentParser(prog="fmu", description="Flight computer and vehicle simulation in the loop (AIL).",
                                argument_default=argparse.SUPPRESS)
    p.add_argument("--profile", help="parameter profile: the test environment it runs in: ail, flight, none")
    p.add_argument("--open-loop", dest="mode", action="store_const", const="open_loop",
                   help="parameter mode=open_loop: drive the vehicle with a model actuator (2.10)")
    p.add_argument("--sim-model", dest="open_loop.sim_model",
                   help="parameter open_loop.sim_model: open loop, the simulation's model actuator")
    p.add_argument("--duration", dest="duration_s", type=float, help="parameter duration_s: seconds (default 24)")
    p.add_argument("--bag", help="parameter bag: bag directory to create (default bags/ail_<profile>_<time>)")
    p.add_argument("--model", help="parameter model: the EMACs' model, for the bag's metadata")
    p.add_argument("--seed", type=int, help="parameter seed: the test environment's noise seed, for the metadata")
    p.add_argument("--disable", action="append", type=names_list, help="parameter disable: for the metadata")
    p.add_argument("--bungee", dest="bungee_inlb", type=float, help="parameter bungee_inlb: bungee on the wings")
    p.add_argument("--aero-input", dest="aero_input", choices=("feedback", "surface"), help="parameter aero_input")
    p.add_argument("--surface-load", dest="surface_load", choices=("aerodynamic", "bungee"),
                   help="parameter surface_load")
    p.add_argument("--vehicle-config", dest="vehicle_config", help="parameter vehicle_config: parameter file "
                   "(default config/ail_vehicle.yaml)")
    p.add_argument("--frame-hz", dest="frame_hz", type=float, help="parameter frame_hz")
    p.add_argument("--lockstep-wait", dest="lockstep_wait_s", type=float,
                   help="parameter lockstep_wait_s: wall seconds to wait for a frame's inputs")
    p.add_argument("--wait-for", dest="wait_for", action="append", type=names_list,
                   help="parameter wait_for: node names to wait for on ready")
    return p


def main(argv: Sequence[str] | None = None) -> int:
    """Console script ``fmu``.

    Parameters
    ----------
    argv : sequence of str or None
        The command line, ROS arguments included (None: ``sys.argv[1:]``).

    Returns
    -------
    int
        The process's exit status.
    """
    return run(FmuNode, parser(), argv)


if __name__ == "__main__":
    raise SystemExit(main())
