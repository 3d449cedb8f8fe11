"""Real time: which stamped FMU commands the EMAC takes, and when it follows a clock that moved.

Each command carries its FMU frame's stamp. The EMAC takes a command stamped after the last one it took
(its *anchor*) and tells the frames missing between the two apart: those the wall time had room for are a
*gap* (the publisher paused, stamps off the frame grid, a publisher's jitter: the watchdog's business, never a
loss), those beyond it are *lost* (the stamps ran ahead of the wall time, a backlog whose queue overflowed:
commands that were sent and never came). The wall time's room is measured from the command that came soonest
after its stamp so far (the largest stamp-minus-arrival *lead*), not from the anchor: a command delivered late
(a loaded machine, the transport's jitter) and the next one on time squeeze the arrivals, never the stamps, and
are no loss. The first :data:`REFERENCE_COMMANDS` commands after the clock (re-)anchors only set that reference
(frames they skip are a gap): the first command of a run often comes hundreds of ms after its stamp, held while
the transport matched the two ends, and alone it would make the next one, on time, look like a backlog.
A command that does not fit the anchor is dropped and counted:

* ``out_of_order``: stamped at or before the anchor (an older frame's command, a duplicate);
* ``future_stamp``: stamped further ahead of the anchor than the wall time since the anchor came plus
  ``tolerance_s`` (a corrupt stamp, a clock stepped forward: an FMU that paused for 10 s and resumes is
  10 s ahead, which fits).

One bad stamp thus costs one command and moves nothing: the next good command fits the anchor. When the
FMU's clock itself moved (a restart that resets its stamps, a clock stepped forward or back), every
command misfits the anchor; once ``resync_after`` consecutive misfits fit each other by the same rule
(each one after the one before, and not implausibly far), the clock *re-anchors* on the newest and takes
commands again from there (:attr:`Verdict.RESYNC`). With the defaults (5 commands, 10 s) an FMU restart
costs 5 frames (25 ms at 200 Hz), shorter than the EMAC's 50 ms watchdog: the brake holds only if the
resynchronisation takes longer than the watchdog, and is released with the first command taken after it.
"""

from __future__ import annotations

import enum
from typing import NamedTuple

NS = 1_000_000_000
REFERENCE_COMMANDS = 5
"""Commands taken after the clock (re-)anchors before a frame they skip may be judged lost (module docstring)."""


class Verdict(enum.Enum):
    """What :meth:`CommandClock.check` made of a command's stamp."""

    TAKEN = "taken"
    """In sequence after the anchor: take the command (it is the new anchor)."""
    RESYNC = "resync"
    """The clock re-anchored on this command: take it; the commands before it in the new sequence were dropped."""
    OUT_OF_ORDER = "out_of_order"
    """Stamped at or before the anchor: drop it."""
    FUTURE = "future_stamp"
    """Stamped implausibly far ahead of the anchor: drop it."""

    @property
    def taken(self) -> bool:
        """The command is taken."""
        return self in (Verdict.TAKEN, Verdict.RESYNC)


class Check(NamedTuple):
    """A command stamp's verdict, and what the caller counts and logs."""

    verdict: Verdict
    missing: int = 0
    """Frames of commands lost between the anchor and this command (taken in sequence only): missing stamps
    beyond what the wall time had room for (measured from :attr:`CommandClock.lead_ns`)."""
    previous_ns: int | None = None
    """The anchor before this command (the stamp the clock jumped from, on a resync)."""
    gap: int = 0
    """Frames of commands missing between the anchor and this command that the wall time also had room for (a
    pause or jitter of the publisher, a late delivery: not a loss)."""


class CommandClock:
    """The stamps a real-time EMAC takes commands by (see the module docstring).

    Parameters
    ----------
    frame_ns : int
        The FMU frame, ns (stamps on its grid: a gap of ``n`` frames is ``n - 1`` missing commands).
    tolerance_s : float
        How far a stamp may run ahead of the anchor's stamp plus the wall time since the anchor came.
    resync_after : int
        Consecutive commands that misfit the anchor but fit each other, after which the clock re-anchors.
    """

    def __init__(self, frame_ns: int, tolerance_s: float = 10.0, resync_after: int = 5) -> None:
        if frame_ns <= 0 or tolerance_s < 0.0 or resync_after < 1:
            raise ValueError("frame_ns > 0, tolerance_s >= 0 and resync_after >= 1")
        self.frame_ns = frame_ns
        self.tolerance_ns = round(tolerance_s * NS)
        self.resync_after = resync_after
        self.anchor: tuple[int, float] | None = None
        """The last stamp taken (ns) and the wall time it came (monotonic s)."""
        self.resyncs = 0
        """Times the clock re-anchored."""
        self.lead_ns: int | None = None
        """The largest stamp-minus-arrival of the commands taken since the clock (re-)anchored, ns: the command
        that came soonest after its stamp, the reference a later stamp is judged against for losses."""
        self._misfit: tuple[int, float] | None = None
        self._misfits = 0
        self._taken = 0
        """Commands taken since the clock (re-)anchored."""

    def _fits(self, stamp_ns: int, wall_s: float, after: tuple[int, float]) -> bool:
        ref_ns, ref_wall = after
        elapsed_ns = max(round((wall_s - ref_wall) * NS), 0)
        return ref_ns < stamp_ns <= ref_ns + elapsed_ns + self.tolerance_ns

    def check(self, stamp_ns: int, wall_s: float) -> Check:
        """Judge a command stamped ``stamp_ns`` that came at ``wall_s``; a taken one becomes the anchor.

        Parameters
        ----------
        stamp_ns : int
            The command's stamp, ns.
        wall_s : float
            When it came (monotonic wall time), s.

        Returns
        -------
        Check
            The verdict, the frames lost before it (taken in sequence), the anchor before it and the frames of
            a gap in publishing before it.
        """
        anchor = self.anchor
        lead = stamp_ns - round(wall_s * NS)
        if anchor is None or self.lead_ns is None:
            self.anchor, self.lead_ns, self._taken = (stamp_ns, wall_s), lead, 1
            return Check(Verdict.TAKEN)
        if self._fits(stamp_ns, wall_s, anchor):
            self.anchor = (stamp_ns, wall_s)
            self._misfit, self._misfits = None, 0
            missing = max(round((stamp_ns - anchor[0]) / self.frame_ns) - 1, 0)
            ahead = max(round((lead - self.lead_ns) / self.frame_ns), 0) if self._taken >= REFERENCE_COMMANDS else 0
            lost = min(missing, ahead)
            self.lead_ns = max(self.lead_ns, lead)
            self._taken += 1
            return Check(Verdict.TAKEN, lost, anchor[0], missing - lost)
        in_run = self._misfit is not None and self._fits(stamp_ns, wall_s, self._misfit)
        self._misfits = self._misfits + 1 if in_run else 1
        self._misfit = (stamp_ns, wall_s)
        if self._misfits >= self.resync_after:
            self.anchor, self.lead_ns, self._taken = (stamp_ns, wall_s), lead, 1
            self._misfit, self._misfits = None, 0
            self.resyncs += 1
            return Check(Verdict.RESYNC, 0, anchor[0])
        return Check(Verdict.OUT_OF_ORDER if stamp_ns <= anchor[0] else Verdict.FUTURE, 0, anchor[0])


class Lateness(enum.Enum):
    """What :meth:`FrameGate.judge` made of a taken command against the frames already stepped."""

    STEP = "step"
    """Its frame is still to come: step it now."""
    LATE = "late"
    """Its frame was stepped without it (an idle frame stood in): apply it from the next frame, step nothing."""
    FOLLOW = "follow"
    """Late, and the commands before it too without catching up: their clock lags the frames; step it and
    follow their stamps from here (the feedback's stamp goes back once)."""


class FrameGate:
    """Real time: whether a taken command steps a frame, so that no frame is stepped twice.

    A real-time EMAC steps an idle frame when a command is late (:data:`ema_sim.nodes.emac.IDLE_AFTER_FRAMES`),
    standing in for it. When the command then comes, its frame has been stepped: stepping it again would
    publish a second feedback for that frame, stamped not after the one before. The command is applied from
    the next frame instead (:attr:`Lateness.LATE`). A command stamped less than half a frame before the next
    frame to step is on time (stepping it still publishes a later stamp), which keeps FMUs that stamp
    commands with their publishing time, off the frame grid, on time.

    Late commands catch up: a publisher that stalled sends its backlog, each command a frame closer to the
    frames stepped. Commands that stay late (``follow_after`` in a row, their lag shrinking by less than a
    frame), come from a clock that lags the frames, e.g. an FMU whose stamps stopped while it paused: the
    frames then follow their stamps (:attr:`Lateness.FOLLOW`) rather than stand in for them forever.

    Parameters
    ----------
    frame_ns : int
        The FMU frame, ns.
    follow_after : int
        Consecutive late commands that do not catch up, after which the frames follow their stamps.
    """

    def __init__(self, frame_ns: int, follow_after: int = 5) -> None:
        self.frame_ns = frame_ns
        self.follow_after = follow_after
        self.late = 0
        """Late commands so far."""
        self.follows = 0
        """Times the frames followed the commands' stamps."""
        self._run = 0
        self._first_lag = 0

    def judge(self, stamp_ns: int, next_ns: int | None) -> Lateness:
        """Judge a command stamped ``stamp_ns`` when the next frame to step starts at ``next_ns``.

        Parameters
        ----------
        stamp_ns : int
            The command's stamp (its frame's start), ns.
        next_ns : int or None
            Start of the next frame to step, ns (None: no frame stepped on this command clock yet).

        Returns
        -------
        Lateness
            Step its frame, apply it from the next frame, or step it and follow its stamps from here.
        """
        if next_ns is None or stamp_ns >= next_ns - self.frame_ns // 2:
            self._run = 0
            return Lateness.STEP
        lag = next_ns - stamp_ns
        if self._run == 0:
            self._first_lag = lag
        self._run += 1
        if self._run >= self.follow_after:
            if lag > self._first_lag - self.frame_ns:  # not catching up: a lagging clock
                self._run = 0
                self.follows += 1
                return Lateness.FOLLOW
            self._run, self._first_lag = 1, lag  # a backlog catching up: judge the next ones from here
        self.late += 1
        return Lateness.LATE
