"""The real-time record of a driven run: when each frame's command left and when its feedback came back.

Kept in arrays sized for the whole run before the first frame: a structure that grows with the run
stalls it when it grows (a Python dict of 87,000 frames takes 7 ms to resize, measured here; that is
more than a 200 Hz frame), so nothing here allocates per frame.

When the feedback path runs in the driver's own thread (the ``single`` layout), each frame also keeps
the thread's CPU time and context switches at the publish and at the feedback, and a missed frame is
told apart: the thread ran for more than a frame (``suite_busy``: the suite's own work was too slow);
it gave the CPU up (``suite_waited``: it waited for something); another task took the CPU from it
(``preempted``: something of higher priority on this machine); or none of these (``cpu_held``: the
thread was running as far as the kernel knows, and the time passed without it: the hypervisor held the
virtual CPU, which the machine's steal time counts).
"""

from __future__ import annotations

import math
import resource
import time
from collections.abc import Iterable, Sequence

import numpy as np

from ema_sim.jsontypes import JsonObject
from ema_sim.nodes.common import percentile_ms
from ema_sim.nodes.realtime import steal_s

CAUSES = ("unanswered", "suite_busy", "suite_waited", "preempted", "cpu_held")
"""Why a frame was missed (see the module docstring); ``unanswered``: its feedback never came."""


def thread_marks() -> tuple[float, int, int]:
    """This thread's CPU time (s), and its voluntary and involuntary context switches so far."""
    usage = resource.getrusage(resource.RUSAGE_THREAD)
    return time.thread_time(), usage.ru_nvcsw, usage.ru_nivcsw


class FrameTimes:
    """Per-frame command and feedback times of one run (see the module docstring).

    Parameters
    ----------
    frames : int
        Frames in the run (0: none recorded, as under lockstep).
    expect : sequence of str
        The channels whose feedback ends each frame.
    period_s : float
        The frame period (s).
    one_thread : bool
        The feedback path runs in this thread (composed), so a missed frame's cause can be told.
    """

    def __init__(self, frames: int, expect: Sequence[str], period_s: float, *, one_thread: bool) -> None:
        self.period_s = period_s
        self.expect = list(expect)
        self.one_thread = one_thread
        """The feedback path runs in this thread: a missed frame's cause can be told."""
        self._column = {name: i for i, name in enumerate(self.expect)}
        self.count = 0
        """Frames sent so far."""
        self.sent = np.full(frames, np.nan)
        self.back = np.full((frames, len(self.expect)), np.nan)
        self.thread_sent = np.zeros((frames, 3))
        self.thread_back = np.zeros((frames, 3))
        """Thread CPU time (s), voluntary and involuntary switches, at the publish and the last new feedback."""
        self.steal_s: list[float | None] = []
        """The machine's stolen CPU time when the run starts and when its last frame is out."""

    def start(self) -> None:
        """The run starts."""
        self.steal_s = [steal_s()]

    def end(self) -> None:
        """The last frame is out."""
        self.steal_s.append(steal_s())

    def mark_sent(self) -> None:
        """Just before frame ``count``'s command is published (thread marks only; then :meth:`sent_at`)."""
        if self.one_thread:
            self.thread_sent[self.count] = thread_marks()

    def sent_at(self, wall: float) -> None:
        """Frame ``count``'s command left at ``wall`` (monotonic s).

        Parameters
        ----------
        wall : float
            When the publish began (monotonic s).
        """
        self.sent[self.count] = wall
        self.count += 1

    def feedback(self, k: int, names: Iterable[str], wall: float) -> None:
        """Feedback of frame ``k`` for ``names`` arrived at ``wall``; the first arrival per channel counts.

        Parameters
        ----------
        k : int
            The frame.
        names : iterable of str
            The channels in the feedback message.
        wall : float
            When it arrived (monotonic s).
        """
        if not 0 <= k < self.count:
            return
        row = self.back[k]
        new = False
        for name in names:
            col = self._column.get(name)
            if col is not None and math.isnan(row[col]):
                row[col] = wall
                new = True
        if new and self.one_thread:
            self.thread_back[k] = thread_marks()

    def summary(self) -> JsonObject:
        """Frames, latency percentiles and missed frames (with their causes where they can be told)."""
        n = self.count
        sent, back = self.sent[:n], self.back[:n]
        answered = ~np.isnan(back).any(axis=1) if back.shape[1] else np.zeros(n, bool)
        latency = back[answered].max(axis=1, initial=-np.inf) - sent[answered]
        late = np.zeros(n, bool)
        late[answered] = latency > self.period_s
        values = latency.tolist()
        out: JsonObject = {
            "frames": n, "answered": int(answered.sum()), "missed_frames": int((~answered).sum() + late.sum()),
            "latency_p50_ms": percentile_ms(values, 50), "latency_p99_ms": percentile_ms(values, 99),
            "latency_max_ms": percentile_ms(values, 100),
        }
        if self.one_thread:
            cpu = self.thread_back[:n, 0] - self.thread_sent[:n, 0]
            waited = self.thread_back[:n, 1] > self.thread_sent[:n, 1]
            preempted = self.thread_back[:n, 2] > self.thread_sent[:n, 2]
            busy = late & (cpu > self.period_s)
            waited &= late & ~busy
            preempted &= late & ~busy & ~waited
            out.update({
                "missed_unanswered": int((~answered).sum()), "missed_suite_busy": int(busy.sum()),
                "missed_suite_waited": int(waited.sum()), "missed_preempted": int(preempted.sum()),
                "missed_cpu_held": int((late & ~busy & ~waited & ~preempted).sum()),
            })
        if len(self.steal_s) == 2 and None not in self.steal_s:
            out["machine_steal_s"] = round(self.steal_s[1] - self.steal_s[0], 3)  # type: ignore[operator]
        return out
