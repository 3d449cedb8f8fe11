"""The EMAC node's frames: when a frame is stepped, on which inputs, and what it publishes.

Real time (:meth:`EmacFrames._poll_realtime`): each command is a frame, answered at once, and idle frames keep
the frame rate between commands. Lockstep (:meth:`EmacFrames._poll_lockstep`): one frame per frame of the
node's clock, on the inputs stamped for it, waiting for them while their publishers are alive. Either way a
frame steps every hosted channel at once (:meth:`EmacFrames._step_all`) and publishes its feedback, the
faults' truth at a change, and ``/diagnostics`` once a second of model time or at once on a change.
"""

from __future__ import annotations

import json
import time

from std_msgs.msg import String

from ema_msgs_py import contract as ct
from ema_sim.emac import Feedback
from ema_sim.emac.stamps import Lateness
from ema_sim.nodes.common import MAX_SPIN_S, process_age_s
from ema_sim.nodes.emac_receive import EmacReceiver
from ema_sim.nodes.emac_state import IDLE_AFTER_FRAMES, NS
from ema_sim.nodes.emac_streams import InputStream

CATCH_UP = 20
"""Idle frames a late loop steps to catch up (0.1 s at 200 Hz); beyond that it skips to the present frame."""


class EmacFrames(EmacReceiver):
    """The EMAC node's frame loop (see the module docstring)."""

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
        """Commands stayed late without catching up (their clock lags the frames): follow their stamps.

        A lag within the watchdog's timeout is the node's own doing (idle frames stepped on while it was held up,
        commands stamped with their publishing time a little behind the frame grid): counted and logged, no WARN.
        A longer one is the FMU's clock (stopped, or lagging): WARN on ``/diagnostics``.
        """
        self.command_resyncs += 1
        lag_s = ((self.model_ns or stamp) - stamp) / NS
        text = (f"{self.gate.follow_after} commands in a row came after their frames were stepped without catching "
                f"up (the last stamped {stamp / NS:.6f} s, {lag_s:.3f} s behind the frames; ")
        if lag_s > self.settings.watchdog_timeout_s:
            self.last_fault_wall = time.monotonic()
            self._diagnose_now = True
            self.get_logger().warning(
                f"{text}a clock that stopped or lags): the frames follow their stamps from here "
                f"({self.command_resyncs} resynchronisation(s) so far)")
        else:
            self.get_logger().info(
                f"{text}within the watchdog's {self.settings.watchdog_timeout_s * 1e3:g} ms: the node was held up, "
                f"or the stamps sit behind the frame grid): the frames follow their stamps from here "
                f"({self.command_resyncs} resynchronisation(s) so far)")
        self.model_ns = None

    def _age_wall(self, ch: str, now: float) -> float | None:
        last = self.last_good_wall[ch]
        return None if last is None else max(now - last, 0.0)

    def _poll_lockstep(self) -> float:
        if self.clock_ns is None:
            return 0.05
        self.ports.take_at_frame()
        if self.model_ns is None:  # first tick: report the trimmed state at the start time
            self.model_ns = self.clock_ns
            self.joined_ns = self.clock_ns if self.clock_ns > 0 else None
            self.joined_said = False
            trimmed = {ch: u.last for ch, u in self.units.items()}
            self._observe_own(trimmed)  # as a channel node observes it from the others' first message
            self._publish(self.model_ns, trimmed)
        streams = self._stream_list
        while self.clock_ns >= self.model_ns + self.frame_ns:
            t = self.model_ns
            pending = self._joined([s for s in streams if (s.last_stamp is None or s.last_stamp < t) and not s.gave_up])
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

    def _joined(self, pending: list[InputStream]) -> list[InputStream]:
        """The inputs a frame waits for; of a node that joined a running clock (a restarted EMAC), fewer.

        The frames around the one it joined at had their inputs published when the others stepped to them,
        before this node's subscriptions existed, and no input says which frames those were: until an input has
        brought its first message, a frame goes ahead without it (held values, one line) rather than after the
        wait's timeout. Once it has, it is waited for as usual. A node that started with the clock waits for all.
        """
        if self.joined_ns is None or not pending:
            return pending
        gone = [s for s in pending if s.last_stamp is None and not s.queue]
        if gone and not self.joined_said:
            self.joined_said = True
            self.get_logger().info(f"joined the clock at frame {self.joined_ns / NS:.3f} s: inputs sent before this "
                                   "node subscribed are not waited for; each input is, once it has come")
        return [s for s in pending if s not in gone] if gone else pending

    def _observe_sources(self, items: list[tuple[int, list[tuple[str, float]]]]) -> None:
        for _, seen in items:
            for name, v in seen:
                self.meter.observe(name, v, self.slew_v_per_s[name])

    def _wait(self, pending: list[InputStream], t: int) -> bool:
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
            limit = self.source_wait_s if s is self.source_fb else self.wait_s
            if now - s.waiting_since < limit:
                go = False
            else:
                s.gave_up = True
                self.waits_given_up += 1
                self.throttled("wait", f"no input on {topics[id(s)]} for frame {t / NS:.3f} s after "
                               f"{limit:g} s; stepping with held values")
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
        if not self.published:
            self.first_feedback_s = round(process_age_s(), 3)
        self.published += 1
