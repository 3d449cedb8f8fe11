"""``emac``: one EMAC channel (or an EMAC box of several) on the topic contract.

Subscribes to ``/ema/emac/command`` (its FMU command, after the test environment) and
``/ema/load/hinge_moment``; publishes ``/ema/emac/feedback`` (LVDT position and motor current, V and A),
``/ema/sensor/surface`` (the external sensor's surface angle) and, for models with a motor,
``/ema/sensor/bus``, once per FMU frame. Two clocks:

* real time: each command message is one frame, stepped and answered at once (the FMU's frame is
  the clock); when no command comes for 1.5 frames the channel steps on with the held command and
  the watchdog brakes it after ``watchdog_timeout_s``;
* lockstep (``use_sim_time``): the model advances exactly one frame per frame of ``/clock``, with the
  inputs stamped for that frame; it waits for them while their publishers are alive, so a run is
  reproducible whatever the machine's load.

Run-time failures: ``std_msgs/String`` on ``/ema/emac/<channel>/failure`` or the ``emac.failure``
parameter (``stuck``, ``hard_over:direction=-1``, ``zero``, ``power_loss``, ``stall``, ``none``).
"""

from __future__ import annotations

import argparse
import math
import time
from collections import deque
from collections.abc import Sequence
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import SetParametersResult
from std_msgs.msg import String

from ema_msgs_py import contract as ct
from ema_msgs_py.cdr import JointFrame
from ema_msgs_py.ros import qos
from ema_sim.config import CHANNELS, config_dir, load_channel, parse_channel, ros_parameters
from ema_sim.emac import ActivityMeter, EmacChannel, EmacSettings, Feedback, InputStatus, parse_failure
from ema_sim.errors import EmaError, UnknownNameError
from ema_sim.models import create, model_names
from ema_sim.nodes.common import DurationHistogram, SuiteNode, run
from ema_sim.nodes.params import merged, overrides
from ema_sim.nodes.ports import Ports
from ema_sim.signals.plans import channel_list
from ema_sim.switches import element_names, model_overrides

NS = 1_000_000_000


class Stream:
    """Stamped messages of one input topic, consumed frame by frame (lockstep) or as they come."""

    def __init__(self) -> None:
        self.queue: deque[tuple[int, Any]] = deque()
        self.last_stamp: int | None = None
        self.waiting_since: float | None = None
        self.gave_up = False

    def push(self, stamp: int, item: Any) -> None:
        """A message arrived."""
        self.queue.append((stamp, item))
        self.last_stamp = stamp if self.last_stamp is None else max(self.last_stamp, stamp)
        self.gave_up = False

    def reached(self, t_ns: int) -> bool:
        """A message for frame ``t_ns`` (or later) has arrived."""
        return self.last_stamp is not None and self.last_stamp >= t_ns

    def take_until(self, t_ns: int) -> list[tuple[int, Any]]:
        """(stamp, item) stamped at or before ``t_ns``, in arrival order.

        Every such item, not only those before the first later one: messages of different publishers
        (the crosstalk sources) may arrive out of stamp order, and a later frame's message from one
        must not hold back this frame's from another.
        """
        queue = self.queue
        if not queue:
            return []
        out = [item for item in queue if item[0] <= t_ns]
        if len(out) == len(queue):  # the usual case: everything queued is due
            queue.clear()
        elif out:
            kept = [item for item in queue if item[0] > t_ns]
            queue.clear()
            queue.extend(kept)
        return out


class SourceStream(Stream):
    """The other channels' feedback (crosstalk sources): a frame is there when every source has sent it.

    Which sources exist is learnt from the suite's ``--peers`` (``emac_<channel>`` nodes): a frame waits
    for each of them, so the crosstalk a channel sees does not depend on which source's message came
    first. Without peers (a node run on its own) any source's message counts, as it cannot know better.
    """

    def __init__(self) -> None:
        super().__init__()
        self.expected: frozenset[str] = frozenset()
        self._latest: dict[str, int] = {}

    def push_from(self, stamp: int, item: list[tuple[str, float]]) -> None:
        """A message arrived carrying these sources' values."""
        for name, _ in item:
            if stamp > self._latest.get(name, -1):
                self._latest[name] = stamp
        self.queue.append((stamp, item))
        self.gave_up = False
        if self.expected:
            latest = [self._latest.get(name) for name in self.expected]
            self.last_stamp = None if any(x is None for x in latest) else min(latest)  # type: ignore[type-var]
        else:
            self.last_stamp = stamp if self.last_stamp is None else max(self.last_stamp, stamp)


class EmacNode(SuiteNode):
    """The node (see the module docstring)."""

    def __init__(self, args: argparse.Namespace, ports: Any = Ports) -> None:
        channels = channel_list(args.channel or ["left_wing"])
        name = f"emac_{channels[0]}" if len(channels) == 1 else "emac"
        super().__init__(name, automatically_declare_parameters_from_overrides=True)
        self.ports = ports(self)
        if args.model not in model_names():
            raise UnknownNameError("model", args.model, model_names())
        self.channels = channels
        self.lockstep = self.sim_time
        base = ros_parameters(config_dir() / "emac.yaml").get("emac", {})
        node_params = merged(base, overrides(self, "emac"))
        self.settings = EmacSettings.from_parameters(
            {k: v for k, v in node_params.items() if not isinstance(v, dict)}, f"{name}: emac")
        if args.frame_hz:
            self.settings = EmacSettings.from_parameters({**vars(self.settings), "frame_hz": args.frame_hz})
        crosstalk = node_params.get("crosstalk", {})
        self.wait_s = float(node_params.get("lockstep_wait_s", 5.0))
        self.frame_ns = round(NS / self.settings.frame_hz)
        self.frame_s = self.frame_ns / NS
        self.units = self._build_units(args, name, crosstalk)
        self.has_current = all(u.model.has_current for u in self.units.values())
        self.meter = ActivityMeter(self.frame_s)
        self.coupled = any(u.crosstalk.active for u in self.units.values())
        self.sources = [c for c in CHANNELS if c not in self.units] if self.coupled else []
        self.slew_v_per_s = {c: load_channel(c).slew_rate_dps * ct.scaling(c).volts_per_deg for c in CHANNELS}
        # streams
        self.commands = Stream()
        self.loads = Stream()
        self.source_fb = SourceStream()
        self._stream_list = [self.commands, self.loads, *([self.source_fb] if self.sources else [])]
        self._diagnostics_every = round(self.settings.frame_hz)
        self._frames_to_diagnostics = self._diagnostics_every
        self.last_good_ns: dict[str, int | None] = dict.fromkeys(channels)
        self.last_good_wall: dict[str, float | None] = dict.fromkeys(channels)
        self.clock_ns: int | None = None
        self.model_ns: int | None = None
        self.last_step_wall = time.monotonic()
        self.late_frames = 0
        self.turnaround = DurationHistogram()
        self.waits_given_up = 0
        self.published = 0
        self.bad_messages = 0
        self._make_topics()
        self.get_logger().info(
            f"{args.model} on {', '.join(channels)}; {'lockstep' if self.lockstep else 'real time'} at "
            f"{self.settings.frame_hz:g} Hz; watchdog {self.settings.watchdog_timeout_s * 1e3:g} ms")

    def _build_units(self, args: argparse.Namespace, name: str, crosstalk: dict[str, Any]) -> dict[str, EmacChannel]:
        """A model and an EMAC channel for each hosted channel."""
        units: dict[str, EmacChannel] = {}
        for ch in self.channels:
            cfg = load_channel(ch)
            if len(self.channels) == 1:  # a single channel takes its ROS parameters (--params-file config/<ch>.yaml)
                own = overrides(self, "", exclude=("use_sim_time",))
                own.pop("emac", None)
                if own:
                    cfg = parse_channel(merged(ros_parameters(config_dir() / f"{ch}.yaml"), own), f"{name} parameters")
            kwargs: dict[str, Any] = {"rate_hz": args.rate} if args.rate else {}
            kwargs.update(model_overrides(args.model, element_names(args.disable)))
            model = create(args.model, cfg, **kwargs)
            if not units:  # compiled code loads on first use: take that hit now, not in the first frame
                create(args.model, cfg, **kwargs).step_values(0.0, 0.0, self.frame_s)
            pp_v = float(crosstalk.get(f"{ch}_pp_v", 0.0))
            units[ch] = EmacChannel(model, self.settings, crosstalk_noise_pp_v=pp_v, stream=CHANNELS.index(ch))
        return units

    def _make_topics(self) -> None:
        ports = self.ports
        self.fb_pub = ports.frame_publisher(ct.EMAC_FEEDBACK)
        self.surface_pub = ports.frame_publisher(ct.SURFACE)
        self.bus_pub = ports.frame_publisher(ct.BUS) if self.has_current else None
        self.diag_pub = self.create_publisher(DiagnosticArray, ct.DIAGNOSTICS, qos(ct.EVENT_QOS))
        ports.frame_subscription(ct.EMAC_COMMAND, self._on_command, self._bad)
        ports.frame_subscription(ct.HINGE_MOMENT, self._on_load, self._bad)
        for ch in self.channels:
            self.create_subscription(String, ct.failure_topic(ch), lambda m, ch=ch: self._on_failure(ch, m.data),
                                     qos(ct.FAILURE_QOS))
        if self.sources:
            ports.frame_subscription(ct.EMAC_FEEDBACK, self._on_source, self._bad)
        if self.lockstep:
            ports.clock_subscription(self._on_clock)
        self.add_on_set_parameters_callback(self._on_parameters)

    # ----------------------------------------------------------------- callbacks (never raise)
    def _on_command(self, msg: JointFrame) -> None:
        try:
            values = self._pick(msg, msg.position, "position", "command")
            if values:
                stamp = msg.stamp_ns
                if not stamp and not self.lockstep:  # an unstamped command in real time: now
                    stamp = self.get_clock().now().nanoseconds
                self.commands.push(stamp, (values, time.monotonic()))
                self.mark_running()
        except Exception as exc:  # a bad message never kills the node
            self._bad(f"command message dropped: {exc}")

    def _on_load(self, msg: JointFrame) -> None:
        try:
            values = self._pick(msg, msg.effort, "effort", "hinge moment")
            if values:
                self.loads.push(msg.stamp_ns, values)
        except Exception as exc:
            self._bad(f"hinge-moment message dropped: {exc}")

    def _on_source(self, msg: JointFrame) -> None:
        try:
            pos = msg.position
            seen = [(name, float(pos[i])) for i, name in enumerate(msg.name) if name in self.sources and i < len(pos)]
            if seen:
                self.source_fb.push_from(msg.stamp_ns, seen)
        except Exception as exc:
            self._bad(f"feedback message dropped: {exc}")

    def _on_clock(self, ns: int) -> None:
        if self.clock_ns is None or ns > self.clock_ns:
            self.clock_ns = ns

    def _on_failure(self, channel: str, text: str) -> None:
        try:
            failure = self.units[channel].set_failure(text)
            self.get_logger().warning(f"{channel}: failure {failure.spec()}")
            self._publish_diagnostics()
        except EmaError as exc:
            self._bad(f"{channel}: failure request ignored: {exc}")

    def _on_parameters(self, params: Sequence[Any]) -> SetParametersResult:
        for p in params:
            try:
                if p.name == "emac.failure":
                    for unit in self.units.values():
                        unit.set_failure(parse_failure(str(p.value)))
                elif p.name == "emac.motor_power_on":
                    for unit in self.units.values():
                        unit.motor_power_on = bool(p.value)
            except EmaError as exc:
                return SetParametersResult(successful=False, reason=str(exc))
        return SetParametersResult(successful=True)

    def _pick(self, msg: JointFrame, array: list[float], field: str, what: str) -> dict[str, float]:
        """This node's channels out of a frame (missing values are rejected and counted)."""
        out: dict[str, float] = {}
        for i, name in enumerate(msg.name):
            if name in self.units:
                if i < len(array):
                    out[name] = float(array[i])
                else:
                    out[name] = math.nan
                    self._bad(f"{what} for {name} has no {field} value ({len(msg.name)} names, {len(array)} values)")
        return out

    def _bad(self, text: str) -> None:
        self.bad_messages += 1
        self.throttled("bad", f"{text} ({self.bad_messages} so far)")

    # ----------------------------------------------------------------- inputs into the channels
    def _apply_commands(self, items: list[tuple[int, Any]]) -> None:
        for stamp, (values, wall) in items:
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
        return self._poll_lockstep() if self.lockstep else self._poll_realtime()

    def _poll_realtime(self) -> float:
        now = time.monotonic()
        if self.loads.queue:
            self._apply_loads(self.loads.take_until(1 << 62))
        if self.source_fb.queue:
            self._observe_sources(self.source_fb.take_until(1 << 62))
        stepped = False
        while self.commands.queue:
            stamp, item = self.commands.queue.popleft()
            self._apply_commands([(stamp, item)])
            self._step_all(stamp, {ch: self._age_wall(ch, now) for ch in self.units})
            self.turnaround.add(time.monotonic() - item[1])  # command received → feedback published
            stepped = True
        if stepped:
            self.last_step_wall = now
            return 1.5 * self.frame_s
        due = self.last_step_wall + 1.5 * self.frame_s
        if now >= due:
            if any(self._age_wall(c, now) is not None and self._age_wall(c, now) <= self.settings.watchdog_timeout_s
                   for c in self.units):
                self.late_frames += 1
            start = self.model_ns if self.model_ns is not None else self.get_clock().now().nanoseconds
            self._step_all(start, {ch: self._age_wall(ch, now) for ch in self.units})
            self.last_step_wall = now if now - due > self.frame_s else due
            due = self.last_step_wall + 1.5 * self.frame_s
        return due - now

    def _age_wall(self, ch: str, now: float) -> float | None:
        last = self.last_good_wall[ch]
        return None if last is None else max(now - last, 0.0)

    def _learn_sources(self) -> None:
        """The crosstalk sources that exist: the peers' EMAC channel nodes (see :class:`SourceStream`)."""
        if self.sources and not self.source_fb.expected and self.peers:
            self.source_fb.expected = frozenset(c for c in self.sources if f"emac_{c}" in self.peers)

    def _poll_lockstep(self) -> float:
        if self.clock_ns is None:
            return 0.05
        self._learn_sources()
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
            self._step_all(t, {ch: None if last_good[ch] is None else (t - last_good[ch]) / NS for ch in self.units})
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
        # After the frame's feedback is out (0.2 ms for five channels), once a second of model time and at
        # once when a brake or a failure changed (once for the frame, however many channels changed).
        self._frames_to_diagnostics -= 1
        if changed or self._frames_to_diagnostics <= 0:
            self._frames_to_diagnostics = self._diagnostics_every
            self._publish_diagnostics()

    def _observe_own(self, out: dict[str, Feedback]) -> None:
        """An EMAC box: its channels are each other's crosstalk sources."""
        if self.coupled and len(self.units) > 1:
            for ch, fb in out.items():
                self.meter.observe(ch, fb.position_v, self.slew_v_per_s[ch])

    def _publish(self, stamp: int, out: dict[str, Feedback]) -> None:
        names = self.channels
        if len(names) == 1:
            f = out[names[0]]
            self.fb_pub.publish(JointFrame(stamp, names, [f.position_v], [], [f.current_a] if self.has_current else []))
            self.surface_pub.publish(JointFrame(stamp, names, [f.surface_deg], [f.rate_dps], [f.hinge_moment_inlb]))
            if self.bus_pub is not None:
                self.bus_pub.publish(JointFrame(stamp, names, [f.bus_v]))
        else:
            fbs = [out[c] for c in names]
            self.fb_pub.publish(JointFrame(stamp, names, [f.position_v for f in fbs],
                                           [], [f.current_a for f in fbs] if self.has_current else []))
            self.surface_pub.publish(JointFrame(stamp, names, [f.surface_deg for f in fbs],
                                                [f.rate_dps for f in fbs], [f.hinge_moment_inlb for f in fbs]))
            if self.bus_pub is not None:
                self.bus_pub.publish(JointFrame(stamp, names, [f.bus_v for f in fbs]))
        self.published += 1

    def _publish_diagnostics(self) -> None:
        msg = DiagnosticArray()
        msg.header.stamp = self.get_clock().now().to_msg()
        for ch, unit in self.units.items():
            st = unit.status()
            failing = unit.failure.kind != "none"
            level = DiagnosticStatus.ERROR if failing else (
                DiagnosticStatus.WARN if unit.last.braked or self.bad_messages else DiagnosticStatus.OK)
            text = (f"failure {unit.failure.spec()}" if failing else
                    "brake engaged" if unit.last.braked else "nominal")
            st.update({"late_frames": str(self.late_frames), "bad_messages": str(self.bad_messages),
                       "waits_given_up": str(self.waits_given_up)})
            msg.status.append(DiagnosticStatus(
                level=level, name=f"emac/{ch}", message=text, hardware_id=unit.model.name,
                values=[KeyValue(key=k, value=v) for k, v in st.items()]))
        self.diag_pub.publish(msg)

    def summary(self) -> dict[str, Any]:  # noqa: D102
        return {
            "channels": self.channels, "mode": "lockstep" if self.lockstep else "realtime",
            "frames_published": self.published, "late_frames": self.late_frames,
            "waits_given_up": self.waits_given_up, "bad_messages": self.bad_messages,
            "turnaround_p50_ms": self.turnaround.percentile_ms(50),
            "turnaround_p99_ms": self.turnaround.percentile_ms(99),
            "turnaround_max_ms": self.turnaround.percentile_ms(100),
            "counters": {ch: dict(u.counters) for ch, u in self.units.items()},
        }

    def close(self) -> None:  # noqa: D102
        self._publish_diagnostics()


def parser() -> argparse.ArgumentParser:
    """Command-line arguments (ROS arguments go after ``--ros-args``)."""
    p = argparse.ArgumentParser(prog="emac", description="One EMAC channel (or several: an EMAC box).")
    p.add_argument("--model", default="loada", help="model name (ema models); default loada")
    p.add_argument("--channel", action="append", default=[],
                   help="channel (repeatable, comma-separated, or 'all' for an EMAC box of five)")
    p.add_argument("--rate", type=float, default=None, help="integration rate of a discrete model, Hz")
    p.add_argument("--frame-hz", type=float, default=None, help="FMU frame rate (default from config/emac.yaml)")
    p.add_argument("--disable", action="append", default=[],
                   help="switch the model's own elements off: dead_band (the PWM's), quantization, noise "
                        "(others, the test environment's, are accepted and left to it)")
    return p


def main(argv: Sequence[str] | None = None) -> int:
    """Console script ``emac``."""
    return run(EmacNode, parser(), argv)


if __name__ == "__main__":
    raise SystemExit(main())
