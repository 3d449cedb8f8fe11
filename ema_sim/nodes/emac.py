"""``emac``: one EMAC channel (or an EMAC box of several) on the topic contract.

Subscribes to ``/ema/emac/command`` (its FMU command, after the test environment) and
``/ema/load/hinge_moment``; publishes ``/ema/emac/feedback`` (LVDT position and motor current, V and A),
``/ema/sensor/surface`` (the external sensor's surface angle) and, for models with a motor,
``/ema/sensor/bus``, once per FMU frame. Two clocks:

* real time: each command message is one frame, stepped and answered at once (the FMU's frame is
  the clock); when no command comes for :data:`IDLE_AFTER_FRAMES` frames the channel steps on with the
  held command and the watchdog brakes it after ``watchdog_timeout_s``. Every frame is stepped once: a
  command that comes after its frame was stepped without it is applied from the next frame and counted
  (``late_commands``), and the feedback stamps increase strictly. The command stamps are judged by
  :class:`ema_sim.emac.stamps.CommandClock`: an out-of-order or implausibly future stamp is dropped and
  counted, and after ``emac.resync_commands`` consecutive commands of a clock that moved (an FMU restart)
  the node follows them (``command_resyncs``, a WARN line);
* lockstep (``use_sim_time``): the model advances exactly one frame per frame of ``/clock``, with the
  inputs stamped for that frame; it waits for them while their publishers are alive, so a run is
  reproducible whatever the machine's load. A ``/clock`` that jumps backwards (a reset, a replay)
  restarts the node's time base there (``clock_resets``, a WARN line), the brake engaged until the new
  time's commands come.

Run-time failures: ``std_msgs/String`` on ``/ema/emac/<channel>/failure`` or the ``emac.failure``
parameter (``stuck``, ``hard_over:direction=-1``, ``zero``, ``power_loss``, ``stall``, ``none``).
"""

from __future__ import annotations

import argparse
import json
import math
import time
from collections.abc import Callable, Sequence
from typing import Any

from rclpy.impl.implementation_singleton import rclpy_implementation
from rclpy.lifecycle import LifecycleNodeMixin, LifecycleState, TransitionCallbackReturn
from std_msgs.msg import String

from ema_msgs_py import contract as ct
from ema_msgs_py.cdr import JointFrame
from ema_msgs_py.ros import qos
from ema_sim.config import CHANNELS, config_dir, load_channel, parse_channel, ros_parameters, scaling
from ema_sim.emac import ActivityMeter, EmacChannel, EmacSettings, Feedback, InputStatus, parse_failure
from ema_sim.emac.stamps import CommandClock, FrameGate, Lateness, Verdict
from ema_sim.errors import EmaError, UnknownNameError
from ema_sim.models import create, model_names
from ema_sim.nodes.common import MAX_SPIN_S, DurationHistogram, SuiteNode, command_line, run
from ema_sim.nodes.emac_inputs import OUT_OF_RANGE_FACTOR, StampPolicy, pick
from ema_sim.nodes.emac_params import (
    channel_specs,
    check_files,
    default_name,
    emac_specs,
    node_specs,
    resolve_channels,
)
from ema_sim.nodes.emac_streams import Outputs, SourceStream, Stream, diagnostics
from ema_sim.nodes.params import names_list, nested
from ema_sim.nodes.ports import Ports
from ema_sim.signals.plans import channel_list
from ema_sim.switches import element_names, model_overrides

__all__ = [
    "EmacNode",
    "ManagedEmacNode",
    "SourceStream",
    "Stream",
    "channel_specs",
    "default_name",
    "emac_specs",
    "main",
    "node",
    "node_specs",
    "parser",
]

NS = 1_000_000_000
DROPS = ("malformed", "unknown_names", "no_names", "lost_commands", "out_of_order", "future_stamp")
"""Why an input was dropped, each message under one reason (:func:`~ema_sim.nodes.emac_inputs.pick`): a
message whose arrays do not match its names or whose value for a hosted channel is not a number or out of
range (dropped whole); names that are no channel; a message without names; commands sent and lost (stamps
that ran further ahead than the wall time since: a backlog that overflowed a queue; a pause in publishing is
a gap, ``command_gaps``, not a loss); a command older than the last one taken; an input stamped implausibly
far ahead (real time:
of the last command and the wall time since, :class:`~ema_sim.emac.stamps.CommandClock`; lockstep: of the
node's clock by more than :data:`LOCKSTEP_LEAD_FRAMES`)."""
LOCKSTEP_LEAD_FRAMES = 20
"""Lockstep: how far ahead of the node's clock an input may be stamped (inputs come frame by frame)."""
IDLE_AFTER_FRAMES = 2.0
"""Real time: a frame without a command is stepped this many frames after the last command came (a frame of
grace for a late command: the FMU's publishing jitter), then every frame."""
CATCH_UP = 20
"""Idle frames a late loop steps to catch up (0.1 s at 200 Hz); beyond that it skips to the present frame."""
FAULT_HOLD_S = 2.0
"""``/diagnostics`` warns for this long (wall time) after the last dropped input, then is OK again."""



class EmacNode(SuiteNode):
    """The node (see the module docstring).

    Parameters
    ----------
    args : argparse.Namespace or None
        The command line's flags (parameter overrides; ``channels`` is resolved here).
    ports : object
        How per-frame messages travel (:class:`~ema_sim.nodes.ports.Ports`, or a container's).
    name : str or None
        The node's name (None: from the channels, :func:`~ema_sim.nodes.emac_params.default_name`).
    **options : Any
        rclpy node options (``context``, ``cli_args``...), as a process's ROS arguments give them.

    Raises
    ------
    EmaError
        A configuration error (logged at FATAL through the node's logger, and the node destroyed, first).
    """

    managed = False
    """A managed (lifecycle) node, :class:`ManagedEmacNode`: topics made at ``configure``, frames only when active."""

    def __init__(self, args: argparse.Namespace | None = None, ports: Any = Ports, name: str | None = None,
                 **options: Any) -> None:
        """The node, built from its parameters (see the class docstring for the arguments)."""
        flag = channel_list(getattr(args, "channels", None) or []) or None
        argv = command_line(options)
        if name is None:
            name = default_name(flag, argv, options.get("namespace"))
        super().__init__(name, args, exclude=("channels",), **options)
        try:
            self._build(flag, argv, ports)
        except BaseException as exc:  # a user error (one line, from run) or a bug: the node leaves the graph first
            if isinstance(exc, EmaError):  # through its logger (/rosout) before it goes
                self.fatal(str(exc))
                exc.logged = True  # type: ignore[attr-defined]
            self.destroy_node()
            raise

    def _build(self, flag: list[str] | None, argv: list[str], ports: Any) -> None:
        """The node's parameters, channels, streams and topics (the constructor's work once the node exists)."""
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
        self.fqn = self.get_fully_qualified_name()
        """The node's full name: its diagnostics' status names are ``<full name>: <channel>``."""
        self.lockstep = self.sim_time
        base = ros_parameters(config_dir() / "emac.yaml").get("emac", {})
        settings = self.params.declare(emac_specs(base), f"{name}: emac")
        self.settings = EmacSettings.from_parameters(
            {k: v for k, v in nested(settings)["emac"].items() if not isinstance(v, dict)}, f"{name}: emac")
        self.wait_s = float(settings["emac.lockstep_wait_s"])
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
        if self.configured:
            self._make_topics()
        self._on_changes()
        self.get_logger().info(
            f"{self.model_name} on {', '.join(self.channels)}; {'lockstep' if self.lockstep else 'real time'} at "
            f"{self.settings.frame_hz:g} Hz; watchdog {self.settings.watchdog_timeout_s * 1e3:g} ms")
        if self.lockstep and self.sources and not self.source_fb.expected:
            self.get_logger().warning(
                f"lockstep: no emac_<channel> peers name the crosstalk sources ({', '.join(self.sources)}); each "
                "frame takes whichever source feedback has come, so the crosstalk may differ from run to run")

    def _init_streams(self) -> None:
        """The input streams and the node's time base."""
        self.commands = Stream()
        self.loads = Stream()
        self.source_fb = SourceStream(frozenset(c for c in self.sources if f"emac_{c}" in self.peers))
        """The crosstalk sources: the peers' EMAC channel nodes (see :class:`SourceStream`)."""
        self._stream_list = [self.commands, self.loads, *([self.source_fb] if self.sources else [])]
        self._diagnostics_every = round(self.settings.frame_hz)
        self._frames_to_diagnostics = self._diagnostics_every
        self._diagnose_now = False
        """A run-time change was applied: the next frame's diagnostics show it."""
        self.last_good_ns: dict[str, int | None] = dict.fromkeys(self.channels)
        self.last_good_wall: dict[str, float | None] = dict.fromkeys(self.channels)
        self.clock_ns: int | None = None
        self.model_ns: int | None = None
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
        kwargs: dict[str, Any] = {"rate_hz": own["rate_hz"]} if own["rate_hz"] > 0.0 else {}
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
        def on(name: str, apply: Callable[[Any], str]) -> None:
            def applied(value: Any) -> str:
                self._diagnose_now = True  # the next frame's diagnostics show the change
                return apply(value)
            self.params.on_change(name, applied)

        def setting(key: str, unit: str) -> None:
            def apply(value: Any) -> str:
                old = getattr(self.settings, key)
                self.settings = EmacSettings.from_parameters({**vars(self.settings), key: value}, "emac")
                for u in self.units.values():
                    u.settings = self.settings
                return f"emac.{key}: {old:g} → {value:g} {unit} (from the next frame)"
            on(f"emac.{key}", apply)

        def failure(value: Any) -> str:
            failure = parse_failure(str(value))
            for u in self.units.values():
                u.set_failure(failure)
            return f"emac.failure: {failure.spec()} on {', '.join(self.channels)} (from the next frame)"

        def power(value: Any) -> str:
            for u in self.units.values():
                u.motor_power_on = bool(value)
            return f"emac.motor_power_on: {bool(value)} (brake {'released' if value else 'engaged'} at the next frame)"

        def wait(value: Any) -> str:
            old, self.wait_s = self.wait_s, float(value)
            return f"emac.lockstep_wait_s: {old:g} → {self.wait_s:g} s"

        def faults(value: Any) -> str:
            specs = [u.set_faults(str(value)) for u in self.units.values()]
            text = "; ".join(f.spec() for f in specs[0]) if specs and specs[0] else "none"
            return f"emac.faults: {text} on {', '.join(self.channels)} (times from each channel's start)"

        setting("watchdog_timeout_s", "s")
        on("emac.faults", faults)
        setting("hinge_moment_limit_inlb", "in·lb")
        on("emac.failure", failure)
        on("emac.motor_power_on", power)
        on("emac.lockstep_wait_s", wait)

    def _make_topics(self) -> None:
        ports = self.ports
        self.outputs = Outputs(self, ports, self.channels, self.frame_id, self.has_current)
        self.diag_pub = self.outputs.diagnostics
        self.truth_pub = self.create_publisher(String, ct.endpoint(ct.FAULT_TRUTH), qos(ct.EVENT_QOS))
        self._truth: dict[str, dict[str, float]] = {}
        # Real time: a command is the frame's event; the frame takes the hinge moment and the crosstalk sources
        # waiting for it (they need not wake the process). Lockstep waits on every input of the frame.
        at_frame = not self.lockstep
        ports.frame_subscription(ct.EMAC_COMMAND, self._on_command, self._bad)
        ports.frame_subscription(ct.HINGE_MOMENT, self._on_load, self._bad, at_frame=at_frame)
        for ch in self.channels:
            self.create_subscription(String, ct.endpoint(ct.failure_topic(ch)), self._failure_callback(ch),
                                     qos(ct.FAILURE_QOS))
        if self.sources:
            ports.frame_subscription(ct.EMAC_FEEDBACK, self._on_source, self._bad, at_frame=at_frame)
        if self.lockstep:
            ports.clock_subscription(self._on_clock)

    # ----------------------------------------------------------------- callbacks (never raise)
    def _on_command(self, msg: JointFrame) -> None:
        if not self.active:
            return
        self.arrivals += 1
        try:
            values = self._pick(msg, msg.position, "position", "command", self._command_limits)
            stamp = msg.stamp_ns
            now = time.monotonic()
            fresh = False
            if self.lockstep:  # a command for frame t: the suite's time has reached t
                if not self._on_input_stamp(stamp, "command"):
                    return
                if values is None:  # dropped: the frame goes ahead on the held command (no wait for it)
                    self.commands.push(stamp, ({}, now, False))
                    return
            if values and (line := self.stamp_policy.observe(stamp)) is not None:
                self.get_logger().info(line)
            # real time: an unstamped command (0) is the next frame's, stamped when stepped
            if not self.lockstep and stamp and values:
                check = self.command_clock.check(stamp, now)
                if not self._stamp_taken(check, stamp):
                    return
                fresh = check.verdict is Verdict.RESYNC
            if values:  # None (dropped) or {} (none of ours): nothing to apply
                self.commands.push(stamp, (values, now, fresh))
                self.commands_taken += 1
                self.mark_running()
        except Exception as exc:  # a bad message never kills the node
            self._drop("malformed", f"command message dropped: {exc}")

    def _stamp_taken(self, check: Any, stamp: int) -> bool:
        """Real time: count, log and say whether to take a command the command clock judged (``check``)."""
        verdict = check.verdict
        if verdict is Verdict.TAKEN:
            if check.gap > 0:
                self.command_gaps += 1
                self.gap_frames += check.gap
            if check.missing > 0:
                self._drop("lost_commands", f"{check.missing} frame(s) of commands lost before the one stamped "
                           f"{stamp / NS:.6f} s (its stamp ran {check.missing} frames further ahead than the wall "
                           "time since the last one: sent faster than the frames and dropped on the way)",
                           check.missing)
            return True
        last = check.previous_ns / NS
        if verdict is Verdict.RESYNC:
            self.command_resyncs += 1
            self.last_fault_wall = time.monotonic()
            self._diagnose_now = True
            n = self.command_clock.resync_after
            self.get_logger().warning(
                f"command stamps jumped from {last:.6f} s to {stamp / NS:.6f} s and {n} consecutive commands agree on "
                f"the new clock (an FMU restart or a stepped clock): the command clock follows it from here (the "
                f"{n - 1} before this one were dropped; {self.command_resyncs} resynchronisation(s) so far)")
            return True
        if verdict is Verdict.OUT_OF_ORDER:
            text = (f"command stamped {stamp / NS:.6f} s after one stamped {last:.6f} s: dropped (an older frame's "
                    "command)")
        else:
            text = (f"command stamped {stamp / NS:.6f} s, {(stamp - check.previous_ns) / NS:.3f} s after the last "
                    f"one taken ({last:.6f} s), further than the wall time since allows: dropped (implausible stamp)")
        self._drop(verdict.value, f"{text}; {self.command_clock.resync_after} consecutive such commands that agree "
                   "re-anchor the command clock")
        return False

    def _on_load(self, msg: JointFrame) -> None:
        if not self.active:
            return
        self.arrivals += 1
        try:
            values = self._pick(msg, msg.effort, "effort", "hinge moment", self._load_limits)
            if self.lockstep and not self._on_input_stamp(msg.stamp_ns, "hinge moment"):
                return
            if values is None and self.lockstep:  # dropped: the frame goes ahead on the held hinge moment
                self.loads.push(msg.stamp_ns, {})
            elif values:
                self.loads.push(msg.stamp_ns, values)
        except Exception as exc:
            self._bad(f"hinge-moment message dropped: {exc}")

    def _on_source(self, msg: JointFrame) -> None:
        if not self.active:
            return
        self.arrivals += 1
        try:
            pos = msg.position
            seen = [(name, float(pos[i])) for i, name in enumerate(msg.name) if name in self.sources and i < len(pos)]
            # the other EMACs stepped the frame ending here: the clock got there
            if seen and (not self.lockstep or self._on_input_stamp(msg.stamp_ns, "feedback")):
                self.source_fb.push_from(msg.stamp_ns, seen)
        except Exception as exc:
            self._bad(f"feedback message dropped: {exc}")

    def _on_clock(self, ns: int) -> None:
        """Lockstep time from ``/clock``: forward to any value; a jump backwards restarts the time base there."""
        if not self.active:
            return
        last = self.last_clock_topic_ns
        self.last_clock_topic_ns = ns
        if last is not None and ns < last:
            self._restart_time(last, ns)
        if self.clock_ns is None or ns > self.clock_ns:
            self.clock_ns = ns

    def _on_input_stamp(self, ns: int, what: str) -> bool:
        """Lockstep time from an input stamped for a frame (its frame has come); False: drop the input.

        An input stamped more than :data:`LOCKSTEP_LEAD_FRAMES` ahead of the node's clock is dropped
        (``future_stamp``): inputs come frame by frame, each at most a frame ahead of the clock it raised, so
        it is no frame of this run (an input of the time before a ``/clock`` reset, still on its way), and the
        node's clock does not jump on its word.
        """
        clock = self.clock_ns
        if clock is not None and ns > clock + LOCKSTEP_LEAD_FRAMES * self.frame_ns:
            self._drop("future_stamp", f"{what} stamped {ns / NS:.6f} s, more than {LOCKSTEP_LEAD_FRAMES} frames "
                       f"ahead of the clock ({clock / NS:.6f} s): dropped")
            return False
        if clock is None or ns > clock:
            self.clock_ns = ns
        return True

    def _restart_time(self, old: int, ns: int) -> None:
        """``/clock`` went back from ``old`` to ``ns`` (a reset, a replay): the node's time restarts at ``ns``.

        The model keeps its state; the next poll reports it at ``ns`` (as the first frame of a run does),
        inputs queued for the time before are dropped, and the brake holds until the new time's commands come.
        """
        self.clock_resets += 1
        self.clock_ns = ns
        self.model_ns = None
        for s in self._stream_list:
            s.restart(ns)
        self.last_good_ns = dict.fromkeys(self.channels)
        self._diagnose_now = True
        self.last_fault_wall = time.monotonic()
        self.get_logger().warning(
            f"/clock jumped back from {old / NS:.6f} s to {ns / NS:.6f} s (a reset or a replay): the time base "
            f"restarts there, inputs of the time before are dropped ({self.clock_resets} reset(s) so far)")

    def _failure_callback(self, channel: str) -> Callable[[String], None]:
        return lambda msg: self._on_failure(channel, msg.data)

    def _on_failure(self, channel: str, text: str) -> None:
        try:
            failure = self.units[channel].set_failure(text)
            self.get_logger().warning(f"{channel}: failure {failure.spec()}")
            self._publish_diagnostics()
        except EmaError as exc:
            self._bad(f"{channel}: failure request ignored: {exc}")

    def _pick(self, msg: JointFrame, array: list[float], field: str, what: str,
              limits: dict[str, float]) -> dict[str, float] | None:
        """This node's channels out of a frame, or None when it is dropped whole (counted once, logged throttled).

        See :func:`~ema_sim.nodes.emac_inputs.pick`: a malformed message is never applied.
        """
        picked = pick(msg.name, array, limits, field, what)
        if picked.reason is not None:
            self._drop(picked.reason, picked.text)
            if picked.reason != "unknown_names":
                return None
        return picked.values

    @property
    def _command_limits(self) -> dict[str, float]:
        """The largest command each hosted channel takes (beyond it a command is malformed), V."""
        return {ch: OUT_OF_RANGE_FACTOR * u.scaling.full_scale_v for ch, u in self.units.items()}

    @property
    def _load_limits(self) -> dict[str, float]:
        """Any finite hinge moment is taken (the channel clamps it to its limit)."""
        return dict.fromkeys(self.units, math.inf)

    def _bad(self, text: str) -> None:
        """A message that could not be decoded."""
        self._drop("malformed", text)

    def _drop(self, reason: str, text: str, count: int = 1) -> None:
        self.drops[reason] += count
        self.last_fault_wall = time.monotonic()
        self.throttled(f"drop-{reason}", f"{text} ({self.drops[reason]} {reason.replace('_', ' ')} so far)")

    # ----------------------------------------------------------------- inputs into the channels
    def _apply_commands(self, items: list[tuple[int, Any]]) -> None:
        for stamp, (values, wall, _) in items:
            for ch, v in values.items():
                status = self.units[ch].set_command(v)
                if status is not InputStatus.REJECTED:
                    self.last_good_wall[ch] = wall
                    self.last_good_ns[ch] = stamp
                if status is not InputStatus.OK:
                    unit = self.units[ch]
                    self.throttled(f"cmd-{ch}", f"{ch}: command {v!r} V {status.value} "
                                   f"({unit.counters['rejected_commands']} rejected, "
                                   f"{unit.counters['clamped_commands']} clamped so far)")

    def _apply_loads(self, items: list[tuple[int, dict[str, float]]]) -> None:
        for _, values in items:
            for ch, h in values.items():
                status = self.units[ch].set_load(h)
                if status is not InputStatus.OK:
                    unit = self.units[ch]
                    self.throttled(f"load-{ch}", f"{ch}: hinge moment {h!r} in·lb {status.value} "
                                   f"({unit.counters['rejected_loads']} rejected, "
                                   f"{unit.counters['clamped_loads']} clamped so far)")

    # ----------------------------------------------------------------- stepping
    def poll(self) -> float:  # noqa: D102
        if not self.active:  # a managed node, not active: no frames; configured, its status once a second
            if self.configured and time.monotonic() >= self._inactive_status_due:
                self._inactive_status_due = time.monotonic() + 1.0
                self._publish_diagnostics()
            return MAX_SPIN_S
        return self._poll_lockstep() if self.lockstep else self._poll_realtime()

    def _poll_realtime(self) -> float:
        """Each command is a frame, answered at once; without commands the frames go on at the frame rate.

        A command stamped for a frame not yet stepped is applied and its frame stepped (the feedback stamped
        one frame after it); an unstamped one is the next frame's. A command whose frame was already stepped
        without it (an idle frame stood in) is applied from the next frame and counted as late, never stepped
        again (:class:`~ema_sim.emac.stamps.FrameGate`): every frame is stepped once and the feedback stamps
        increase strictly while commands come. The first command, and the first after a resynchronisation,
        starts a stream: the frames follow its stamp from there (the idle frames before it were the node's
        own); so do commands that stay late without catching up (a clock that lags the frames). An idle frame
        is due :data:`IDLE_AFTER_FRAMES` after the last command came, once the executor has handed over every
        input waiting in it, then every frame, its stamp one frame after the last: the feedback keeps the frame
        rate and its stamps stay on the frame grid of the last command, advancing as the wall clock does. A
        loop that fell behind catches up (at most :data:`CATCH_UP` frames at once) and beyond that skips frames
        (counted).
        """
        now = time.monotonic()
        self.ports.take_at_frame()
        if self.loads.queue:
            self._apply_loads(self.loads.take_until(1 << 62))
        if self.source_fb.queue:
            self._observe_sources(self.source_fb.take_until(1 << 62))
        if self.commands.queue:
            stepped = False
            while self.commands.queue:
                stepped = self._take_command(*self.commands.queue.popleft(), now) or stepped
            self._idle_check = None
            if stepped:
                self.last_step_wall = now
                self.next_idle = now + IDLE_AFTER_FRAMES * self.frame_s
            return max(self.next_idle - now, 0.0)
        if now < self.next_idle:
            return self.next_idle - now
        # An idle frame is due. Inputs that came while the node was held up wait in the executor, which hands
        # over one per spin: take them first (an idle frame stepped before its command, waiting there, would
        # make the command late, and the frames would run ahead of every command after it).
        if self._idle_check != self.arrivals:
            self._idle_check = self.arrivals
            return 0.0
        self._idle_check = None
        if self.model_ns is None:  # no frame yet: start on the ROS clock's frame grid, the schedule from now
            # The feedback is stamped with the present frame's start (not the next one's): the first command of
            # an FMU on the same clock, stamped for the present frame, is answered one frame later, after it.
            now_ns = self.get_clock().now().nanoseconds
            self.model_ns = now_ns - now_ns % self.frame_ns - self.frame_ns
            self.next_idle = now
        behind = int((now - self.next_idle) / self.frame_s)
        if behind > CATCH_UP:  # the process was held up: jump to the present frame, stamps on the grid
            self.skipped_frames += behind
            self.model_ns += behind * self.frame_ns
            self.next_idle += behind * self.frame_s
            self.throttled("skip", f"the process was held up {behind * self.frame_s * 1e3:.0f} ms: {behind} idle "
                           f"frames skipped, the stamps kept on the frame grid ({self.skipped_frames} so far)")
        if any((age := self._age_wall(c, now)) is not None and age <= self.settings.watchdog_timeout_s
               for c in self.units):
            self.late_frames += 1
        self._step_all(self.model_ns, {ch: self._age_wall(ch, now) for ch in self.units})
        self.last_step_wall = now
        self.next_idle += self.frame_s
        return max(self.next_idle - time.monotonic(), 0.0)

    def _take_command(self, stamp: int, item: tuple[dict[str, float], float, bool], now: float) -> bool:
        """Real time: apply a command and step its frame unless it was stepped without it; True when stepped."""
        self._apply_commands([(stamp, item)])
        if item[2] or self.first_command:  # the idle frames before were the node's own: follow its stamp
            self.first_command = False
            self.model_ns = None
        if not stamp:  # unstamped: the next frame, or now when the frames fell behind the ROS clock
            now_ns = self.get_clock().now().nanoseconds
            stamp = now_ns if self.model_ns is None else max(self.model_ns, now_ns)
        else:
            lateness = self.gate.judge(stamp, self.model_ns)
            if lateness is Lateness.LATE:
                self.throttled("late", f"command for the frame at {stamp / NS:.6f} s came after that frame was "
                               f"stepped with the held command: applied from the next frame "
                               f"({self.late_commands} late so far)", level="info")
                return False
            if lateness is Lateness.FOLLOW:
                self._follow(stamp)
        self._step_all(stamp, {ch: self._age_wall(ch, now) for ch in self.units})
        self.turnaround.add(time.monotonic() - item[1])  # command received → feedback published
        return True

    def _follow(self, stamp: int) -> None:
        """Commands stayed late without catching up (their clock lags the frames): follow their stamps."""
        self.command_resyncs += 1
        self.last_fault_wall = time.monotonic()
        self._diagnose_now = True
        self.get_logger().warning(
            f"{self.gate.follow_after} commands in a row came after their frames were stepped without catching up "
            f"(the last stamped {stamp / NS:.6f} s, {((self.model_ns or stamp) - stamp) / NS:.3f} s behind the "
            "frames; a clock that stopped or lags): the frames follow their stamps from here "
            f"({self.command_resyncs} resynchronisation(s) so far)")
        self.model_ns = None

    @property
    def late_commands(self) -> int:
        """Real time: commands that came after their frame was stepped without them (applied from the next)."""
        return self.gate.late

    def _age_wall(self, ch: str, now: float) -> float | None:
        last = self.last_good_wall[ch]
        return None if last is None else max(now - last, 0.0)

    def _poll_lockstep(self) -> float:
        if self.clock_ns is None:
            return 0.05
        if self.model_ns is None:  # first tick: report the trimmed state at the start time
            self.model_ns = self.clock_ns
            trimmed = {ch: u.last for ch, u in self.units.items()}
            self._observe_own(trimmed)  # as a channel node observes it from the others' first message
            self._publish(self.model_ns, trimmed)
        streams = self._stream_list
        while self.clock_ns >= self.model_ns + self.frame_ns:
            t = self.model_ns
            pending = [s for s in streams if (s.last_stamp is None or s.last_stamp < t) and not s.gave_up]
            if pending:
                for s in streams:
                    if s not in pending:
                        s.waiting_since = None
                if not self._wait(pending, t):
                    return 0.002
            else:
                for s in streams:
                    s.waiting_since = None
            if self.commands.queue:
                self._apply_commands(self.commands.take_until(t))
            if self.loads.queue:
                self._apply_loads(self.loads.take_until(t))
            if self.source_fb.queue:
                self._observe_sources(self.source_fb.take_until(t))
            last_good = self.last_good_ns
            self._step_all(t, {ch: None if (good := last_good[ch]) is None else (t - good) / NS for ch in self.units})
        return 0.05

    def _observe_sources(self, items: list[tuple[int, list[tuple[str, float]]]]) -> None:
        for _, seen in items:
            for name, v in seen:
                self.meter.observe(name, v, self.slew_v_per_s[name])

    def _wait(self, pending: list[Stream], t: int) -> bool:
        """True when the frame may go ahead without the pending inputs (their publishers are gone or late)."""
        now = time.monotonic()
        topics = {id(self.commands): ct.EMAC_COMMAND, id(self.loads): ct.HINGE_MOMENT,
                  id(self.source_fb): ct.EMAC_FEEDBACK}
        go = True
        for s in pending:
            publishers = self.ports.publishers(topics[id(s)]) - (1 if s is self.source_fb else 0)
            if publishers <= 0:
                continue
            if s.waiting_since is None:
                s.waiting_since = now
            if now - s.waiting_since < self.wait_s:
                go = False
            else:
                s.gave_up = True
                self.waits_given_up += 1
                self.throttled("wait", f"no input on {topics[id(s)]} for frame {t / NS:.3f} s after "
                               f"{self.wait_s:g} s; stepping with held values")
        if go:
            for s in pending:
                s.waiting_since = None
        return go

    def _step_all(self, start_ns: int, ages: dict[str, float | None]) -> None:
        """One frame of every hosted channel; ``ages``: how old each channel's last good command is."""
        out: dict[str, Feedback] = {}
        meter = self.meter
        changed = False
        for ch, unit in self.units.items():
            was = (unit.last.braked, unit.failure)
            fb = out[ch] = unit.step(ages[ch], meter.activity_except(ch) if self.sources or self.coupled else 0.0)
            changed = changed or fb.braked is not was[0] or unit.failure is not was[1]
        self.model_ns = start_ns + self.frame_ns
        self._observe_own(out)
        self._publish(self.model_ns, out)
        self._publish_truth()
        # After the frame's feedback is out (0.2 ms for five channels), once a second of model time and at
        # once when a brake or a failure changed (once for the frame, however many channels changed).
        self._frames_to_diagnostics -= 1
        if changed or self._diagnose_now or self._frames_to_diagnostics <= 0:
            self._diagnose_now = False
            self._frames_to_diagnostics = self._diagnostics_every
            self._publish_diagnostics()

    def _publish_truth(self) -> None:
        """The injected faults' sizes on their own topic, at each change (a bag of the run can be scored)."""
        for ch, unit in self.units.items():
            if not unit.schedule.faults:
                continue
            truth = unit.fault_truth()
            if truth != self._truth.get(ch):
                self._truth[ch] = truth
                msg = String()
                msg.data = json.dumps({"channel": ch, "time_s": unit.counters["frames"] * unit.frame_s,
                                       "faults": truth})
                self.truth_pub.publish(msg)

    def _observe_own(self, out: dict[str, Feedback]) -> None:
        """An EMAC box: its channels are each other's crosstalk sources."""
        if self.coupled and len(self.units) > 1:
            for ch, fb in out.items():
                self.meter.observe(ch, fb.position_v, self.slew_v_per_s[ch])

    def _publish(self, stamp: int, out: dict[str, Feedback]) -> None:
        self.outputs.publish(stamp, out)
        self.published += 1

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

    def summary(self) -> dict[str, Any]:  # noqa: D102
        return {
            "channels": self.channels, "mode": "lockstep" if self.lockstep else "realtime",
            "frames_published": self.published, "late_frames": self.late_frames,
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


RCLError = rclpy_implementation.RCLError
"""What rcl's lifecycle state machine raises on a transition it does not have."""


class ManagedEmacNode(LifecycleNodeMixin, EmacNode):
    """The EMAC node as a managed (lifecycle) node: ``emac --lifecycle``.

    Constructed *unconfigured*: parameters declared and models built (so ``ros2 param`` works and the first
    frame does not compile), but no topic. ``configure`` makes its publishers and subscriptions (*inactive*):
    inputs are dropped, no frame is stepped and nothing is published, so the surface stays where it is, the
    brake held. ``activate`` starts a new time base: the brake stays engaged until a fresh command comes (as at
    start-up), then frames are stepped and published as by :class:`EmacNode`. ``deactivate`` stops them again;
    ``cleanup`` removes the topics; ``shutdown`` ends the process. The transitions are served by the standard
    lifecycle services (``<node>/change_state``, ``<node>/get_state``...), on the node's own executor loop.

    Parameters
    ----------
    args : argparse.Namespace or None
        The command line's flags (parameter overrides).
    ports : object
        How per-frame messages travel (:class:`~ema_sim.nodes.ports.Ports`).
    name : str or None
        The node's name (None: from the channels, :func:`~ema_sim.nodes.emac_params.default_name`).
    **options : Any
        rclpy node options (``context``, ``cli_args``).
    """

    managed = True

    def __init__(self, args: argparse.Namespace | None = None, ports: Any = Ports, name: str | None = None,
                 **options: Any) -> None:
        EmacNode.__init__(self, args, ports, name, **options)
        LifecycleNodeMixin.__init__(self)
        self._lifecycle_entities: list[Any] = []
        service = self._service_change_state
        change = service.callback

        def guarded(request: Any, response: Any) -> Any:
            # rclpy's own callback raises on a transition the present state lacks (activate while unconfigured),
            # which would end the process: the request is refused instead, as rclcpp refuses it
            try:
                return change(request, response)
            except RCLError as exc:
                self.get_logger().warning(f"lifecycle transition {request.transition.id} "
                                          f"{request.transition.label!r} refused: {exc}")
                response.success = False
                return response

        service.callback = guarded

    def check_ready(self) -> None:
        """Announce readiness only once active (a managed node's topics come at ``configure``)."""
        if self.active:
            super().check_ready()

    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Make the topics (publishers and subscriptions); inactive: nothing stepped or published.

        Parameters
        ----------
        state : LifecycleState
            The state before the transition.

        Returns
        -------
        TransitionCallbackReturn
            SUCCESS.
        """
        pubs, subs = set(self.publishers), set(self.every_subscription())
        self._make_topics()
        self._lifecycle_entities = [*(p for p in self.publishers if p not in pubs),
                                    *(s for s in self.every_subscription() if s not in subs)]
        self.configured = True
        self._publish_diagnostics()  # inactive: brake held
        self.get_logger().info(f"configured from {state.label}: topics up, inactive (brake held, no feedback)")
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Step and publish from now on, the brake engaged until a fresh command comes.

        Parameters
        ----------
        state : LifecycleState
            The state before the transition.

        Returns
        -------
        TransitionCallbackReturn
            SUCCESS.
        """
        self._new_time_base()
        self.active = True
        self._diagnose_now = True
        self.get_logger().info(f"activated from {state.label}: stepping frames, brake engaged until a command comes")
        return TransitionCallbackReturn.SUCCESS

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Stop stepping and publishing; inputs are dropped until activated again.

        Parameters
        ----------
        state : LifecycleState
            The state before the transition.

        Returns
        -------
        TransitionCallbackReturn
            SUCCESS.
        """
        self.active = False
        self._publish_diagnostics()
        self.get_logger().info(f"deactivated from {state.label}: no frames, brake held")
        return TransitionCallbackReturn.SUCCESS

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Remove the topics made at ``configure`` (unconfigured again; the models keep their state).

        Parameters
        ----------
        state : LifecycleState
            The state before the transition.

        Returns
        -------
        TransitionCallbackReturn
            SUCCESS.
        """
        self._drop_topics()
        self.get_logger().info(f"cleaned up from {state.label}: topics removed")
        return TransitionCallbackReturn.SUCCESS

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Stop: the process ends after this transition's answer (its summary printed and logged).

        Parameters
        ----------
        state : LifecycleState
            The state before the transition.

        Returns
        -------
        TransitionCallbackReturn
            SUCCESS.
        """
        self.active = False
        self.done = True
        self.get_logger().info(f"shut down from {state.label}")
        return TransitionCallbackReturn.SUCCESS

    def close(self) -> None:  # noqa: D102
        super().close()
        self._drop_topics()

    def _drop_topics(self) -> None:
        for entity in self._lifecycle_entities:
            if entity in self.publishers:
                self.destroy_publisher(entity)
            else:
                self.destroy_subscription(entity)
        self._lifecycle_entities = []
        self.configured = False

    def _new_time_base(self) -> None:
        """Forget the frames and inputs of before: the next command starts the frames; brake until it comes."""
        for s in self._stream_list:
            s.queue.clear()
            s.last_stamp = None
            s.waiting_since = None
            s.gave_up = False
        self.model_ns = None
        self.clock_ns = None
        self.last_clock_topic_ns = None
        self.first_command = True
        self.last_good_ns = dict.fromkeys(self.channels)
        self.last_good_wall = dict.fromkeys(self.channels)
        self.command_clock = CommandClock(self.frame_ns, self.settings.stamp_tolerance_s,
                                          self.settings.resync_commands)
        late, self.gate = self.gate.late, FrameGate(self.frame_ns, self.settings.resync_commands)
        self.gate.late = late
        self.last_step_wall = time.monotonic()
        self.next_idle = self.last_step_wall + IDLE_AFTER_FRAMES * self.frame_s


def parser() -> argparse.ArgumentParser:
    """Command-line flags: shorthands for the node's parameters (ROS arguments go after ``--ros-args``)."""
    p = argparse.ArgumentParser(prog="emac", description="One EMAC channel (or several: an EMAC box).",
                                argument_default=argparse.SUPPRESS)
    p.add_argument("--model", help="parameter model: model name (ema models); default loada")
    p.add_argument("--channel", dest="channels", action="append", type=names_list,
                   help="parameter channels: channel (repeatable, comma-separated, or 'all' for an EMAC box of five)")
    p.add_argument("--rate", dest="rate_hz", type=float, help="parameter rate_hz: integration rate of a discrete "
                   "model, Hz")
    p.add_argument("--frame-hz", dest="emac.frame_hz", type=float, help="parameter emac.frame_hz: FMU frame rate "
                   "(default from config/emac.yaml)")
    p.add_argument("--disable", action="append", type=names_list,
                   help="parameter disable: switch the model's own elements off: dead_band (the PWM's), quantization, "
                        "noise (others, the test environment's, are accepted and left to it)")
    p.add_argument("--lifecycle", action="store_true", help="a managed (lifecycle) node: unconfigured until told "
                   "(configure, activate, deactivate, cleanup, shutdown through <node>/change_state)")
    return p


def node(args: argparse.Namespace) -> EmacNode:
    """The node a command line asks for: an :class:`EmacNode`, or with ``--lifecycle`` a :class:`ManagedEmacNode`.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed flags (``lifecycle`` is taken out; the others are parameter overrides).

    Returns
    -------
    EmacNode
        The node.
    """
    return (ManagedEmacNode if vars(args).pop("lifecycle", False) else EmacNode)(args)


def main(argv: Sequence[str] | None = None) -> int:
    """Console script ``emac``.

    Parameters
    ----------
    argv : sequence of str or None
        The arguments (None: the process's).

    Returns
    -------
    int
        The exit status.
    """
    return run(node, parser(), argv)


if __name__ == "__main__":
    raise SystemExit(main())
