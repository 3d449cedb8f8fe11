"""The EMAC node's state: what it is built from, what it counts, and what it says of itself.

The node (:mod:`ema_sim.nodes.emac`) is four layers of one class, each a module: this one (its parameters
declared, its channels' models built, its input streams and counters, the parameters it applies at run time,
its ``/diagnostics`` status and summary), its inputs (:mod:`ema_sim.nodes.emac_receive`: the callbacks that
judge and queue every message), its frames (:mod:`ema_sim.nodes.emac_frames`: when a frame is stepped, in real
time and in lockstep, and what it publishes) and the node itself with its lifecycle (:mod:`ema_sim.nodes.emac`).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from std_msgs.msg import String

from ema_msgs_py import contract as ct
from ema_msgs_py.ros import qos
from ema_sim.config import CHANNELS, config_dir, load_channel, parse_channel, ros_parameters, scaling
from ema_sim.emac import ActivityMeter, EmacChannel, EmacSettings, parse_failure
from ema_sim.emac.stamps import CommandClock, FrameGate
from ema_sim.errors import UnknownNameError
from ema_sim.jsontypes import JsonObject, JsonValue
from ema_sim.models import create, model_names
from ema_sim.nodes.common import DurationHistogram, SuiteNode
from ema_sim.nodes.emac_inputs import StampPolicy
from ema_sim.nodes.emac_params import channel_specs, check_files, emac_specs, node_specs, resolve_channels
from ema_sim.nodes.emac_streams import CommandItem, InputStream, Outputs, SourceStream, Stream, diagnostics
from ema_sim.nodes.params import as_float, nested
from ema_sim.nodes.ports import FRAMES_PER_MESSAGE, PortsFactory, use_batches
from ema_sim.signals.plans import channel_list
from ema_sim.switches import element_names, model_overrides

if TYPE_CHECKING:
    from rclpy.parameter import AllowableParameterValue as ParameterValue

NS = 1_000_000_000
DROPS = ("malformed", "unknown_names", "no_names", "lost_commands", "out_of_order", "future_stamp")
"""Why an input was dropped, each message under one reason (:func:`~ema_sim.nodes.emac_inputs.pick`): a
message whose arrays do not match its names or whose value for a hosted channel is not a number or out of
range (dropped whole); names that are no channel; a message without names; commands sent and lost (stamps
that ran further ahead than the wall time since: a backlog that overflowed a queue; a pause in publishing is
a gap, ``command_gaps``, not a loss); a command older than the last one taken; an input stamped implausibly
far ahead (real time:
of the last command and the wall time since, :class:`~ema_sim.emac.stamps.CommandClock`; lockstep: of the
node's clock by more than :data:`~ema_sim.nodes.emac_receive.LOCKSTEP_LEAD_FRAMES`)."""
IDLE_AFTER_FRAMES = 2.0
"""Real time: a frame without a command is stepped this many frames after the last command came (a frame of
grace for a late command: the FMU's publishing jitter), then every frame."""
FAULT_HOLD_S = 2.0
"""``/diagnostics`` warns for this long (wall time) after the last dropped input, then is OK again."""


class EmacState(SuiteNode):
    """The EMAC node's parameters, channels, streams, counters and status (see the module docstring).

    Built by :meth:`_build_state` from the node's constructor (:class:`~ema_sim.nodes.emac.EmacNode`), once
    the ROS node exists: its parameters are declared on it.
    """

    managed = False
    """A managed (lifecycle) node, :class:`~ema_sim.nodes.emac.ManagedEmacNode`: topics made at ``configure``, frames
    only when active."""

    def _build_state(self, flag: list[str] | None, argv: list[str], ports: PortsFactory) -> None:
        """The node's parameters, channels, streams and counters (its topics come after, from the node)."""
        name = self.get_name()
        fqn = self.get_fully_qualified_name()
        given = resolve_channels(flag, name, self._parameter_overrides, fqn)
        check_files(argv, self.get_namespace(), name, fqn, self.get_logger())
        self.ports = ports(self)
        own = self.params.declare(node_specs(given), name)
        if own["model"] not in model_names():
            raise UnknownNameError("model", own["model"], model_names())
        self.channels = channel_list(own["channels"])
        self.frame_id = str(own["frame_id"])
        use_batches(self.ports, int(own[FRAMES_PER_MESSAGE]), self.sim_time, name)
        self.fqn = self.get_fully_qualified_name()
        """The node's full name: its diagnostics' status names are ``<full name>: <channel>``."""
        self.lockstep = self.sim_time
        base = ros_parameters(config_dir() / "emac.yaml").get("emac", {})
        settings = self.params.declare(emac_specs(base), f"{name}: emac")
        self.settings = EmacSettings.from_parameters(
            {k: v for k, v in nested(settings)["emac"].items() if not isinstance(v, dict)}, f"{name}: emac")
        self.wait_s = float(settings["emac.lockstep_wait_s"])
        self.source_wait_s = float(settings["emac.lockstep_source_wait_s"])
        self.frame_ns = round(NS / self.settings.frame_hz)
        self.frame_s = self.frame_ns / NS
        self.model_name = own["model"]
        self.units = self._build_units(own, name, nested(settings)["emac"].get("crosstalk", {}))
        self.has_current = all(u.model.has_current for u in self.units.values())
        self.meter = ActivityMeter(self.frame_s)
        self.coupled = any(u.crosstalk.active for u in self.units.values())
        self.sources = [c for c in CHANNELS if c not in self.units] if self.coupled else []
        self.slew_v_per_s = {c: load_channel(c).slew_rate_dps * scaling(c).volts_per_deg for c in CHANNELS}
        self._init_streams()
        self._init_counters()
        self.configured = not self.managed
        """Its topics exist (a managed node's from ``configure`` to ``cleanup``)."""
        self.active = not self.managed
        """It steps frames and publishes (a managed node only while ``active``); inactive, its inputs are dropped."""

    def _init_streams(self) -> None:
        """The input streams and the node's time base."""
        self.commands: Stream[CommandItem] = Stream()
        self.loads: Stream[dict[str, float]] = Stream()
        self.source_fb = SourceStream(frozenset(c for c in self.sources if f"emac_{c}" in self.peers))
        """The crosstalk sources: the peers' EMAC channel nodes (see :class:`SourceStream`)."""
        self._stream_list: list[InputStream] = [self.commands, self.loads, *([self.source_fb] if self.sources else [])]
        self._diagnostics_every = round(self.settings.frame_hz)
        self._frames_to_diagnostics = self._diagnostics_every
        self._diagnose_now = False
        """A run-time change was applied: the next frame's diagnostics show it."""
        self.last_good_ns: dict[str, int | None] = dict.fromkeys(self.channels)
        self.last_good_wall: dict[str, float | None] = dict.fromkeys(self.channels)
        self.clock_ns: int | None = None
        self.model_ns: int | None = None
        self.joined_ns: int | None = None
        """Lockstep: the frame at which the node took a clock already running (None: it started with it)."""
        self.joined_said = False
        self.last_step_wall = time.monotonic()
        self.next_idle = self.last_step_wall + IDLE_AFTER_FRAMES * self.frame_s
        """Real time: when the next frame without a command is due (frames keep the frame rate when idle)."""

    def _init_counters(self) -> None:
        """What the node counts: frames late or skipped, waits, messages, inputs dropped."""
        self.command_clock = CommandClock(self.frame_ns, self.settings.stamp_tolerance_s,
                                          self.settings.resync_commands)
        """Real time: which command stamps are taken (see :mod:`ema_sim.emac.stamps`)."""
        self.gate = FrameGate(self.frame_ns, self.settings.resync_commands)
        """Real time: whether a command steps its frame or came after it was stepped (see :class:`FrameGate`)."""
        self.first_command = True
        self.arrivals = 0
        """Input messages taken from the executor (every topic): an idle frame waits until none is pending."""
        self._idle_check: int | None = None
        self.command_resyncs = 0
        """Real time: times the command clock re-anchored on a clock that moved."""
        self.clock_resets = 0
        """Lockstep: times ``/clock`` jumped backwards and the node's time base restarted."""
        self.last_clock_topic_ns: int | None = None
        """Lockstep: the last value ``/clock`` itself gave (inputs' stamps aside)."""
        self.late_frames = 0
        self.skipped_frames = 0
        self.turnaround = DurationHistogram()
        self.waits_given_up = 0
        self.published = 0
        self.first_feedback_s: float | None = None
        """Seconds from the process's start to its first feedback published (start-up, :func:`process_age_s`)."""
        self.commands_taken = 0
        """Command messages taken (each a frame in real time)."""
        self.command_gaps = 0
        """Real time: gaps in publishing (stamps that skipped frames the wall time also skipped): not losses."""
        self.gap_frames = 0
        """Real time: frames without a command in those gaps (the watchdog brakes a channel in a long one)."""
        self.stamp_policy = StampPolicy(self.frame_ns)
        """How the commands are stamped, stated once (see :mod:`ema_sim.nodes.emac_inputs`)."""
        self.drops = dict.fromkeys(DROPS, 0)
        """Inputs dropped, by reason (:data:`DROPS`): each is counted, logged (throttled) and in ``/diagnostics``."""
        self.last_fault_wall = -math.inf
        self._inactive_status_due = 0.0
        """A managed node while inactive: when its ``/diagnostics`` status is next due."""

    @property
    def bad_messages(self) -> int:
        """Messages dropped whole or in part (malformed, unknown or missing names, undecodable)."""
        return self.drops["malformed"] + self.drops["unknown_names"] + self.drops["no_names"]

    def _build_units(self, own: dict[str, Any], name: str, crosstalk: dict[str, Any]) -> dict[str, EmacChannel]:
        """A model and an EMAC channel for each hosted channel, from the declared channel parameters."""
        units: dict[str, EmacChannel] = {}
        single = len(self.channels) == 1
        kwargs: dict[str, object] = {"rate_hz": own["rate_hz"]} if own["rate_hz"] > 0.0 else {}
        kwargs.update(model_overrides(self.model_name, element_names(own["disable"])))
        for ch in self.channels:
            values = self.params.declare(channel_specs(ch, "" if single else ch), f"{name}: {ch}")
            n = 0 if single else len(ch) + 1
            cfg = parse_channel(nested({k[n:]: v for k, v in values.items()}), f"{name} parameters ({ch})")
            model = create(self.model_name, cfg, **kwargs)
            if not units:  # compiled code loads on first use: take that hit now, not in the first frame
                create(self.model_name, cfg, **kwargs).step_values(0.0, 0.0, self.frame_s)
            pp_v = float(crosstalk.get(f"{ch}_pp_v", 0.0))
            units[ch] = EmacChannel(model, self.settings, crosstalk_noise_pp_v=pp_v, stream=CHANNELS.index(ch))
        return units

    def _on_changes(self) -> None:
        """The parameters a running EMAC applies at its next frame (every other one is read-only)."""
        def on(name: str, apply: Callable[[ParameterValue], str]) -> None:
            def applied(value: ParameterValue) -> str:
                self._diagnose_now = True  # the next frame's diagnostics show the change
                return apply(value)
            self.params.on_change(name, applied)

        def setting(key: str, unit: str) -> None:
            def apply(value: object) -> str:
                old = getattr(self.settings, key)
                self.settings = EmacSettings.from_parameters({**vars(self.settings), key: value}, "emac")
                for u in self.units.values():
                    u.settings = self.settings
                return f"emac.{key}: {old:g} → {value:g} {unit} (from the next frame)"
            on(f"emac.{key}", apply)

        def failure(value: object) -> str:
            failure = parse_failure(str(value))
            for u in self.units.values():
                u.set_failure(failure)
            return f"emac.failure: {failure.spec()} on {', '.join(self.channels)} (from the next frame)"

        def power(value: object) -> str:
            for u in self.units.values():
                u.motor_power_on = bool(value)
            return f"emac.motor_power_on: {bool(value)} (brake {'released' if value else 'engaged'} at the next frame)"

        def wait(value: ParameterValue) -> str:
            old, self.wait_s = self.wait_s, as_float(value)
            return f"emac.lockstep_wait_s: {old:g} → {self.wait_s:g} s"

        def source_wait(value: ParameterValue) -> str:
            old, self.source_wait_s = self.source_wait_s, as_float(value)
            return f"emac.lockstep_source_wait_s: {old:g} → {self.source_wait_s:g} s"

        def faults(value: object) -> str:
            specs = [u.set_faults(str(value)) for u in self.units.values()]
            text = "; ".join(f.spec() for f in specs[0]) if specs and specs[0] else "none"
            return f"emac.faults: {text} on {', '.join(self.channels)} (times from each channel's start)"

        setting("watchdog_timeout_s", "s")
        on("emac.faults", faults)
        setting("hinge_moment_limit_inlb", "in·lb")
        on("emac.failure", failure)
        on("emac.motor_power_on", power)
        on("emac.lockstep_wait_s", wait)
        on("emac.lockstep_source_wait_s", source_wait)

    def _make_outputs(self) -> None:
        """The publishers: feedback, sensors and ``/diagnostics`` (:class:`Outputs`), and the faults' truth."""
        self.outputs = Outputs(self, self.ports, self.channels, self.frame_id, self.has_current)
        self.diag_pub = self.outputs.diagnostics
        self.truth_pub = self.create_publisher(String, ct.endpoint(ct.FAULT_TRUTH), qos(ct.EVENT_QOS))
        self._truth: dict[str, dict[str, float]] = {}

    @property
    def late_commands(self) -> int:
        """Real time: commands that came after their frame was stepped without them (applied from the next)."""
        return self.gate.late

    def _publish_diagnostics(self) -> None:
        """Per channel: ERROR while failing, WARN while braked or within :data:`FAULT_HOLD_S` of a dropped input."""
        counters = {"commands": str(self.commands_taken), "late_frames": str(self.late_frames),
                    "late_commands": str(self.late_commands), "command_resyncs": str(self.command_resyncs),
                    "clock_resets": str(self.clock_resets), "skipped_frames": str(self.skipped_frames),
                    "bad_messages": str(self.bad_messages), "waits_given_up": str(self.waits_given_up),
                    "command_stamps": self.stamp_policy.policy, "command_gaps": str(self.command_gaps),
                    "gap_frames": str(self.gap_frames),
                    **{f"dropped_{k}": str(v) for k, v in self.drops.items()}}
        self.diag_pub.publish(diagnostics(
            self.get_clock().now().to_msg(), self.fqn, self.units, counters,
            recent_fault=time.monotonic() - self.last_fault_wall < FAULT_HOLD_S, hold_s=FAULT_HOLD_S,
            inactive=not self.active))

    def summary(self) -> JsonObject:  # noqa: D102
        return {
            "channels": list[JsonValue](self.channels), "mode": "lockstep" if self.lockstep else "realtime",
            "frames_published": self.published, "first_feedback_s": self.first_feedback_s,
            "late_frames": self.late_frames,
            "waits_given_up": self.waits_given_up, "bad_messages": self.bad_messages,
            "skipped_frames": self.skipped_frames, "dropped": dict(self.drops), "commands": self.commands_taken,
            "late_commands": self.late_commands, "command_resyncs": self.command_resyncs,
            "clock_resets": self.clock_resets, "command_stamps": self.stamp_policy.policy,
            "command_gaps": self.command_gaps, "gap_frames": self.gap_frames,
            "turnaround_p50_ms": self.turnaround.percentile_ms(50),
            "turnaround_p99_ms": self.turnaround.percentile_ms(99),
            "turnaround_max_ms": self.turnaround.percentile_ms(100),
            "counters": {ch: dict(u.counters) for ch, u in self.units.items()},
        }

    def close(self) -> None:  # noqa: D102
        if self.configured:
            self._publish_diagnostics()
