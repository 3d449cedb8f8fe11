"""The EMAC node's inputs: the callbacks that judge every message and queue what it is worth.

A command, a hinge moment, another channel's feedback, a ``/clock`` tick or a failure request is taken here
(never raising: a bad message is dropped and counted under one reason, :data:`~ema_sim.nodes.emac_state.DROPS`)
and queued on its stream; the frames (:mod:`ema_sim.nodes.emac_frames`) apply the queues into the channels
(:meth:`EmacReceiver._apply_commands`, :meth:`EmacReceiver._apply_loads`). Real time, the command stamps are
judged by :class:`~ema_sim.emac.stamps.CommandClock`; lockstep, every input's stamp moves the node's clock
(:meth:`EmacReceiver._on_input_stamp`) and a ``/clock`` that goes back restarts it.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable

from std_msgs.msg import String

from ema_msgs_py import contract as ct
from ema_msgs_py.cdr import JointFrame
from ema_msgs_py.ros import qos
from ema_sim.emac import InputStatus
from ema_sim.emac.stamps import Check, Verdict
from ema_sim.errors import EmaError
from ema_sim.nodes.emac_inputs import OUT_OF_RANGE_FACTOR, pick
from ema_sim.nodes.emac_state import NS, EmacState
from ema_sim.nodes.emac_streams import CommandItem

LOCKSTEP_LEAD_FRAMES = 20
"""Lockstep: how far ahead of the node's clock an input may be stamped (inputs come frame by frame)."""


class EmacReceiver(EmacState):
    """The EMAC node's input callbacks and subscriptions (see the module docstring)."""

    def _make_topics(self) -> None:
        """The publishers (:meth:`_make_outputs`) and the subscriptions, each to its callback."""
        self._make_outputs()
        ports = self.ports
        # A command is the frame's event (real time), or the last of its inputs to come (lockstep: it passes the
        # test environment after the FMU saw the previous frame's feedback); the frame takes the hinge moment and
        # the crosstalk sources waiting for it (sent before the command, they need not wake the process). Lockstep
        # waits for any not in yet (:meth:`~ema_sim.nodes.emac_frames.EmacFrames._poll_lockstep`).
        ports.frame_subscription(ct.EMAC_COMMAND, self._on_command, self._bad)
        ports.frame_subscription(ct.HINGE_MOMENT, self._on_load, self._bad, at_frame=True)
        for ch in self.channels:
            self.create_subscription(String, ct.endpoint(ct.failure_topic(ch)), self._failure_callback(ch),
                                     qos(ct.FAILURE_QOS))
        if self.sources:  # batched, a frame waits for its sources' batch: taken as it comes, not at a 2 ms poll
            ports.frame_subscription(ct.EMAC_FEEDBACK, self._on_source, self._bad,
                                     at_frame=getattr(ports, "frames_per_message", 1) == 1)
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

    def _stamp_taken(self, check: Check, stamp: int) -> bool:
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
        assert check.previous_ns is not None  # every verdict but TAKEN names the anchor it is judged against
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
    def _apply_commands(self, items: list[tuple[int, CommandItem]]) -> None:
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
