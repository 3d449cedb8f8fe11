"""``testenv``: the test environment between FMU and EMACs, both directions (section 4.3).

``/ema/fmu/command`` → command path → ``/ema/emac/command`` and ``/ema/emac/feedback`` → feedback path
→ ``/ema/fmu/feedback``, per channel, one frame per message, stamps kept: the frame a value leaves in
is the frame it came in, its content is what the environment made of it. The profile (``--profile
ail|flight|none`` or a parameter file) sets transport delay, the FMU's 50 Hz lags, 5 mV quantization
and noise; ``--disable`` switches elements off. A non-finite value passes through untouched and
unfiltered (it does not poison the filters); the EMAC rejects it and counts it.

Each path's elements (``command.noise_rms_v``, ``feedback.delay_s``, ``command.lag_hz``,
``command.quantization_v``...) can be set at run time (``ros2 param set``, a ``set_parameters`` call): the
change is logged and applies from the next frame, each channel's path rebuilt in steady state at its last
input (the delay line and the lag start from it; the noise restarts its stream). The profile, the elements
switched off, the seed, the full scale and the frame rate are read when the node starts.

It sees every channel's feedback pass: a channel still commanded whose EMAC has sent no feedback for
``silent_after_s`` (wall time; default the EMACs' watchdog) is ERROR on ``/diagnostics`` (``<node>: feedback
<channel>``, a WARN line), OK again (an INFO line) when its feedback comes back, a restarted EMAC's. In lockstep
the commands stop with the clock, which reports a silent EMAC itself (:mod:`ema_sim.nodes.clock`).
"""

from __future__ import annotations

import argparse
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import replace
from typing import TYPE_CHECKING

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import ParameterType

from ema_msgs_py import contract as ct
from ema_msgs_py.cdr import JointFrame
from ema_msgs_py.ros import qos
from ema_sim.environment import Profile, SignalPath, TransportDelay, load_profile
from ema_sim.environment.profile import PATHS, PathSpec
from ema_sim.jsontypes import JsonObject, JsonValue
from ema_sim.nodes.clock import watchdog_s
from ema_sim.nodes.common import MAX_SPIN_S, SuiteNode, run
from ema_sim.nodes.params import Spec, as_float, names_list, nested
from ema_sim.nodes.ports import FRAMES_PER_MESSAGE, Ports, PortsFactory, frames_spec, use_batches
from ema_sim.parameters import metas

if TYPE_CHECKING:
    from rclpy.parameter import AllowableParameterValue as ParameterValue

CHECK_EVERY_S = 0.01
"""How often the feedback of the commanded channels is checked (wall time)."""
STATUS_EVERY_S = 1.0
"""The feedback statuses are published at each change and at least this often."""


def profile_specs(profile: Profile) -> list[Spec]:
    """The profile's parameters (a profile file such as ``config/ail.yaml`` sets them); the paths' run-time.

    Each path element's description, unit and range come from its declaration (:class:`PathSpec`'s metadata).

    Parameters
    ----------
    profile : Profile
        The defaults (the profile the node starts from).

    Returns
    -------
    list of Spec
        The seed and full scale, then one declaration per element of each path (``command.lag_hz``...).
    """
    out = [Spec("seed", profile.seed, "noise seed of the test environment", low=0, high=2**62,
                why="every channel's noise stream is seeded once, at start, so a run is reproducible"),
           Spec("full_scale_v", profile.full_scale_v, "converters' full scale", "V", 0.1, 1000.0)]
    for path in PATHS:
        for key, m in metas(PathSpec).items():
            high = m.max if math.isfinite(m.max) else None
            out.append(Spec(f"{path}.{key}", getattr(getattr(profile, path), key), f"{path} path: {m.description}",
                            m.unit, min(m.min, m.off if m.off is not None else m.min), high, read_only=False))
    return out


class TestEnvNode(SuiteNode):
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
                 name: str = "testenv") -> None:
        super().__init__(name, args)
        self.ports = ports(self)
        own = self.params.declare([
            Spec("profile", "none", "test environment: ail, flight, none, or a profile parameter file",
                 why="the profile sets every element's default when the node starts; set the elements themselves "
                     "(command.noise_rms_v...) at run time"),
            Spec("disable", [], "elements switched off: delay, lag, quantization, noise, or command.X / feedback.X",
                 kind=ParameterType.PARAMETER_STRING_ARRAY,
                 why="applied to the profile when the node starts; set an element to 0 at run time to switch it off"),
            Spec("frame_hz", ct.FRAME_HZ, "FMU frame rate", "Hz", 1.0, 1e5,
                 why="the delay lines and the lags are sampled on this frame, set up at start"),
            Spec("silent_after_s", watchdog_s(), "wall seconds a commanded channel may go without its EMAC's "
                 "feedback before its status is ERROR (default: the EMACs' watchdog)", "s", 0.0, 3600.0,
                 read_only=False),
            frames_spec(),
        ], name)
        use_batches(self.ports, int(own[FRAMES_PER_MESSAGE]), self.sim_time, name)
        self.silent_s: float = own["silent_after_s"]
        self.params.on_change("silent_after_s", self._set_silent)
        loaded = load_profile(own["profile"])
        values = self.params.declare(profile_specs(loaded), f"{name}: profile {loaded.name}")
        profile = Profile.from_parameters({"profile": loaded.name, **nested(values)}, f"{name} parameters")
        self.profile = profile.without(*own["disable"]) if own["disable"] else profile
        self.frame_s = 1.0 / own["frame_hz"]
        self.cmd_paths: dict[str, SignalPath] = {}
        self.fb_paths: dict[str, SignalPath] = {}
        self.cur_delays: dict[str, TransportDelay] = {}
        self.last_in: dict[str, dict[str, float]] = {"command": {}, "feedback": {}, "current": {}}
        """Each path's last finite input per channel: a path rebuilt at run time starts steady there."""
        self.frames = {"command": 0, "feedback": 0}
        self.passed_bad = 0
        self.changes = 0
        """Run-time changes applied (elements set through the parameters)."""
        self.commanded_at: dict[str, float] = {}
        """Each channel's last command (wall) and, in ``first_command``, its first."""
        self.first_command: dict[str, float] = {}
        self.heard: dict[str, float] = {}
        """Each channel's last feedback (wall)."""
        self.silent: dict[str, float] = {}
        """Channels commanded without feedback beyond ``silent_after_s``: since when (wall)."""
        self.silences = 0
        self.silences_by_channel: dict[str, int] = {}
        """Each channel's silences (a killed EMAC's, told from a busy machine's hold-up of another)."""
        self.next_check = 0.0
        self.status_due = 0.0
        self.diag_pub = self.create_publisher(DiagnosticArray, ct.endpoint(ct.DIAGNOSTICS), qos(ct.EVENT_QOS))
        for path in PATHS:
            for key in metas(PathSpec):
                self.params.on_change(f"{path}.{key}", self._element_change(path, key))
        self.cmd_pub = self.ports.frame_publisher(ct.EMAC_COMMAND)
        self.fb_pub = self.ports.frame_publisher(ct.FMU_FEEDBACK)
        self.ports.frame_subscription(ct.FMU_COMMAND, self._on_command, self._bad_message)
        self.ports.frame_subscription(ct.EMAC_FEEDBACK, self._on_feedback, self._bad_message)
        d = self.profile.describe()
        self.get_logger().info(f"profile {d['profile']}: command {d['command_path']}; feedback {d['feedback_path']}")

    def _set_silent(self, value: ParameterValue) -> str:
        old, self.silent_s = self.silent_s, as_float(value)
        return f"silent_after_s: {old:g} → {self.silent_s:g} s"

    def poll(self) -> float:
        """Check the commanded channels' feedback every :data:`CHECK_EVERY_S`; statuses at a change and each second."""
        if not self.commanded_at:
            return MAX_SPIN_S
        now = time.monotonic()
        if now < self.next_check:
            return self.next_check - now
        self.next_check = now + CHECK_EVERY_S
        changed = False
        for ch, last in self.commanded_at.items():
            heard = self.heard.get(ch, self.first_command[ch])
            if now - last < self.silent_s and now - heard > self.silent_s:  # commanded, and no feedback
                if ch not in self.silent:
                    self.silent[ch] = heard
                    self.silences += 1
                    self.silences_by_channel[ch] = self.silences_by_channel.get(ch, 0) + 1
                    changed = True
                    self.get_logger().warning(f"{ch}: no feedback from its EMAC for {(now - heard) * 1e3:.0f} ms "
                                              f"while commanded (silent_after_s {self.silent_s:g} s): ERROR")
            elif ch in self.silent and self.heard.get(ch, -math.inf) > self.silent[ch]:
                since = self.silent.pop(ch)
                changed = True
                self.get_logger().info(f"{ch}: feedback back after {now - since:.2f} s without")
        if changed or now >= self.status_due:
            self._status(now)
        return CHECK_EVERY_S

    def _status(self, now: float) -> None:
        """Each commanded channel's feedback status on ``/diagnostics``."""
        self.status_due = now + STATUS_EVERY_S
        msg = DiagnosticArray()
        msg.header.stamp = self.get_clock().now().to_msg()
        fqn = self.get_fully_qualified_name()
        for ch in self.commanded_at:
            if ch in self.silent:
                level, text = DiagnosticStatus.ERROR, (f"no feedback from its EMAC for {now - self.silent[ch]:.2f} s "
                                                       "while commanded")
            else:
                level, text = DiagnosticStatus.OK, "feedback flowing"
            msg.status.append(DiagnosticStatus(level=level, name=f"{fqn}: feedback {ch}", message=text, hardware_id=ch,
                                               values=[KeyValue(key="silences", value=str(self.silences))]))
        self.diag_pub.publish(msg)

    def _element_change(self, path: str, key: str) -> Callable[[ParameterValue], str]:
        """The run-time change of one element of one path (a :meth:`~ema_sim.nodes.params.Parameters.on_change`)."""
        def apply(value: ParameterValue) -> str:
            old = getattr(self.profile, path)
            spec = PathSpec.from_mapping({**old.as_dict(), key: as_float(value)}, f"{self.get_name()}: {path}")
            self.profile = replace(self.profile, command=spec) if path == "command" else \
                replace(self.profile, feedback=spec)
            paths = self.cmd_paths if path == "command" else self.fb_paths
            make = self.profile.command_path if path == "command" else self.profile.feedback_path
            for ch in paths:
                stream = ct.CHANNELS.index(ch) if ch in ct.CHANNELS else list(paths).index(ch) + len(ct.CHANNELS)
                paths[ch] = make(self.frame_s, stream, self.last_in[path].get(ch, 0.0))
            if path == "feedback" and key == "delay_s":  # the motor current rides the feedback harness
                for ch in self.cur_delays:
                    self.cur_delays[ch] = self.profile.current_delay(self.frame_s)
                    self.cur_delays[ch].reset(self.last_in["current"].get(ch, 0.0))
            self.changes += 1
            now = make(self.frame_s).describe()
            return (f"{path}.{key}: {getattr(old, key):g} → {as_float(value):g} (from the next frame); {path} path now "
                    f"{now}")
        return apply

    def _path(self, table: dict[str, SignalPath], channel: str, make: Callable[[float, int, float], SignalPath],
              value: float) -> SignalPath:
        path = table.get(channel)
        if path is None:
            stream = ct.CHANNELS.index(channel) if channel in ct.CHANNELS else len(table) + len(ct.CHANNELS)
            path = table[channel] = make(self.frame_s, stream, value if math.isfinite(value) else 0.0)
        return path

    def _through(self, path: SignalPath, value: float) -> float:
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
            last = self.last_in["command"]
            now = time.monotonic()
            at = self.commanded_at
            for i, name in enumerate(msg.name):
                if name not in at:
                    self.first_command[name] = now
                at[name] = now
                v = float(pos[i]) if i < len(pos) else math.nan
                values.append(self._through(self._path(self.cmd_paths, name, self.profile.command_path, v), v))
                if math.isfinite(v):
                    last[name] = v
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
            last, last_a = self.last_in["feedback"], self.last_in["current"]
            now = time.monotonic()
            heard = self.heard
            for i, name in enumerate(msg.name):
                heard[name] = now
                v = float(position[i]) if i < len(position) else math.nan
                pos.append(self._through(self._path(self.fb_paths, name, self.profile.feedback_path, v), v))
                if math.isfinite(v):
                    last[name] = v
                if with_current:
                    a = float(effort[i])
                    if math.isfinite(a):
                        last_a[name] = a
                    delay = self.cur_delays.get(name)
                    if delay is None:
                        delay = self.cur_delays[name] = self.profile.current_delay(self.frame_s)
                        delay.reset(a if math.isfinite(a) else 0.0)
                    cur.append(float(delay.step(a)) if math.isfinite(a) else a)
            self.frames["feedback"] += 1
            self.fb_pub.publish(JointFrame(msg.stamp_ns, msg.name, pos, [], cur, msg.frame_id))
        except Exception as exc:
            self.throttled("drop", f"feedback message dropped: {exc}")

    def summary(self) -> JsonObject:  # noqa: D102
        return {"profile": dict[str, JsonValue](self.profile.describe()), "frames": dict(self.frames),
                "passed_bad": self.passed_bad,
                "run_time_changes": self.changes, "silences": self.silences,
                "silences_by_channel": dict(self.silences_by_channel)}


def parser() -> argparse.ArgumentParser:
    """Command-line flags: shorthands for the node's parameters."""
    p = argparse.ArgumentParser(prog="testenv", description="Test environment between FMU and EMACs (section 4.3).",
                                argument_default=argparse.SUPPRESS)
    p.add_argument("--profile", help="parameter profile: ail, flight, none, or a profile parameter file")
    p.add_argument("--disable", action="append", type=names_list,
                   help="parameter disable: switch elements off: delay, lag, quantization, noise, or command.X / "
                        "feedback.X")
    p.add_argument("--seed", type=int, help="parameter seed: noise seed (default: the profile's)")
    p.add_argument("--frame-hz", dest="frame_hz", type=float, help="parameter frame_hz: FMU frame rate (200)")
    return p


def main(argv: Sequence[str] | None = None) -> int:
    """Console script ``testenv``.

    Parameters
    ----------
    argv : sequence of str or None
        The command line, ROS arguments included (None: ``sys.argv[1:]``).

    Returns
    -------
    int
        The process's exit status.
    """
    return run(TestEnvNode, parser(), argv)


if __name__ == "__main__":
    raise SystemExit(main())
