"""What the recogniser hands each section-2 test to read, and what it keeps of the answer.

The recogniser (:mod:`ema_sim.analysis.recognize`) cuts a record into stretches of four shapes and
asks the tests' readers, in order, what each stretch is:

* :class:`EdgeRun`: command edges sharing their holds (a step set, a square wave, a staircase);
* :class:`MoveRun`: holds joined by finite-rate monotone moves (a drive's profiled trapezoids);
* :class:`MovingStretch`: a command that keeps moving (tones, sweeps, broadband signals, ramps);
* :class:`HeldStretch`: a command held for seconds (crosstalk, dither, and the loaded tests).

A reader returns a :class:`Reading` (kind, evidence, parameters) or None; the recogniser keeps the
first reading of each stretch as a :class:`Segment`, and all of them as the :class:`Recognition`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from itertools import pairwise

import numpy as np
from numpy.typing import NDArray

from ema_sim.analysis.estimation.sine_fit import Sine, fit_sine
from ema_sim.analysis.records import series
from ema_sim.analysis.records.periodic import Periodicity
from ema_sim.analysis.records.series import Edge, Hold
from ema_sim.signals import Load, Maneuver

FloatArray = NDArray[np.float64]

LONG_HOLD_S = 0.3
"""A load level held this long is a level of a load test."""
STEADY_CV = 0.15
"""Half periods within this coefficient of variation make a steady tone."""
SINE_R2 = 0.99
"""A steady tone a sine explains to this share is a sine (a triangle's fundamental explains 98.6 %)."""
DWELL_HALVES = 5
"""Half periods of one steady tone (six turning points, as :attr:`MovingStretch.steady` asks) that make a dwell."""


@dataclass(frozen=True)
class Reading:
    """A reader's answer: the kind of test, why, and the parameters it read off the signal.

    Parameters
    ----------
    kind : str
        The segment kind.
    evidence : str
        Why.
    params : dict
        Parameters read off the signal.
    """

    kind: str
    evidence: str
    params: dict[str, float] = field(default_factory=dict)


@dataclass(frozen=True)
class Move:
    """A finite-rate monotone move of the command from one hold to the next.

    Parameters
    ----------
    before : Hold
        The hold before.
    after : Hold
        The hold after.
    cruise_share : float
        Share of the move spent within 10 % of its top speed.
    speed_dps : float
        The command's speed while cruising (median over the cruise), deg/s.
    """

    before: Hold
    after: Hold
    cruise_share: float
    """Share of the move spent within 10 % of its top speed."""
    speed_dps: float
    """The command's speed while cruising (median over the cruise), deg/s."""

    @property
    def jump(self) -> float:
        """New level minus old level."""
        return self.after.value - self.before.value

    @property
    def start(self) -> int:
        """First sample that left the old level."""
        return self.before.stop

    @property
    def stop(self) -> int:
        """First sample of the new hold."""
        return self.after.start


@dataclass(frozen=True)
class Segment:
    """Samples ``[start, stop)`` of one test of kind ``kind``.

    Parameters
    ----------
    kind : str
        The segment kind.
    start : int
        First sample of the segment.
    stop : int
        One past the last sample.
    evidence : str
        What it was recognised from.
    params : dict
        Parameters of the test (band, frequency...).
    edges : tuple
        Its command edges (steps, square waves...).
    holds : tuple
        Its held levels (of the command, or of the load).
    moves : tuple
        Its profiled moves.
    """

    kind: str
    start: int
    stop: int
    evidence: str
    params: dict[str, float] = field(default_factory=dict)
    edges: tuple[Edge, ...] = ()
    holds: tuple[Hold, ...] = ()
    moves: tuple[Move, ...] = ()

    def as_dict(self, t: FloatArray) -> dict[str, object]:
        """Plain values for JSON.

        Parameters
        ----------
        t : numpy.ndarray
            The record's time, s.

        Returns
        -------
        dict
            Kind, start and end time, evidence and parameters.
        """
        return {"kind": self.kind, "start_s": float(t[self.start]), "end_s": float(t[self.stop - 1]),
                "evidence": self.evidence, "params": self.params}


@dataclass(frozen=True)
class Recognition:
    """The segments of a record, in time order, and what the metadata said.

    Parameters
    ----------
    segments : list
        The segments, in time order.
    maneuver : Maneuver or None
        The maneuver spec.
    load : Load or None
        The load spec (None: unloaded).
    notes : list
        Notes.
    command_tolerance_deg : float
        How far the command may wander and still count as held (five times its noise).
    edge_threshold_deg : float
        The smallest jump between two holds read as a command edge.
    periodic : list
        Every run of matching cycles of the command (:class:`~ema_sim.analysis.records.periodic.Periodicity`).
    """

    segments: list[Segment]
    maneuver: Maneuver | None
    load: Load | None
    notes: list[str] = field(default_factory=list)
    command_tolerance_deg: float = 0.0
    """How far the command may wander and still count as held (five times its noise)."""
    edge_threshold_deg: float = 0.0
    """The smallest jump between two holds read as a command edge."""
    periodic: list[Periodicity] = field(default_factory=list)
    """Every run of matching cycles of the command."""

    def of(self, *kinds: str) -> list[Segment]:
        """Segments of the given kinds.

        Parameters
        ----------
        *kinds : str
            Segment kinds (``steps``, ``sweep``...).

        Returns
        -------
        list of Segment
            Those segments, in time order.
        """
        return [s for s in self.segments if s.kind in kinds]


@dataclass(frozen=True)
class EdgeRun:
    """Consecutive edges of the held command, each one's ``after`` hold the next one's ``before``.

    Parameters
    ----------
    edges : tuple
        The command edges.
    dt : float
        Sample interval, s.
    """

    edges: tuple[Edge, ...]
    dt: float

    @cached_property
    def jumps(self) -> FloatArray:
        """Each edge's jump, deg."""
        return np.array([e.jump for e in self.edges])

    @cached_property
    def distinct_levels(self) -> int:
        """How many different levels the command holds."""
        levels = [self.edges[0].before.value] + [e.after.value for e in self.edges]
        return int(np.unique(np.round(levels, 6)).size)

    @cached_property
    def holds_s(self) -> FloatArray:
        """How long each edge's new level is held, s."""
        return np.array([e.after.length * self.dt for e in self.edges])

    @property
    def n(self) -> int:
        """Number of edges."""
        return len(self.edges)

    @cached_property
    def same_direction(self) -> float:
        """Share of consecutive edges that go the same way."""
        j = self.jumps
        return float(np.mean(np.sign(j[1:]) == np.sign(j[:-1]))) if j.size > 1 else 0.0

    @cached_property
    def alternating_equal(self) -> bool:
        """At least 3 edges alternating in sign with equal size (within 10 %) between at most 3 levels.

        The first and last edges may be half ones (a square wave about its centre starts and ends there).
        """
        j = self.jumps
        mags = np.abs(j[1:-1]) if j.size > 4 else np.abs(j[1:]) if j.size > 3 else np.abs(j)
        alternating = j.size >= 3 and bool(np.all(np.sign(j[1:]) != np.sign(j[:-1])))
        return alternating and float(np.ptp(mags)) <= 0.1 * float(np.median(mags)) and self.distinct_levels <= 3

    @cached_property
    def inner_holds_s(self) -> FloatArray:
        """The holds between edges (the last one, which may run on, left out when there are more than 2)."""
        return self.holds_s[:-1] if self.n > 2 else self.holds_s

    @cached_property
    def amplitude_deg(self) -> float:
        """Half the median jump (a square wave's amplitude)."""
        j = np.abs(self.jumps[1:]) if self.n > 3 else np.abs(self.jumps)
        return float(np.median(j) / 2.0)


@dataclass(frozen=True)
class MoveRun:
    """Consecutive moves sharing their holds.

    Parameters
    ----------
    moves : tuple
        The moves.
    dt : float
        Sample interval, s.
    """

    moves: tuple[Move, ...]
    dt: float

    @property
    def n(self) -> int:
        """Number of moves."""
        return len(self.moves)

    @cached_property
    def distinct_levels(self) -> int:
        """How many different levels the command holds."""
        levels = [self.moves[0].before.value] + [m.after.value for m in self.moves]
        return int(np.unique(np.round(levels, 6)).size)

    @cached_property
    def same_direction(self) -> float:
        """Share of consecutive moves that go the same way."""
        j = np.array([m.jump for m in self.moves])
        return float(np.mean(np.sign(j[1:]) == np.sign(j[:-1]))) if j.size > 1 else 0.0

    @cached_property
    def holds_s(self) -> FloatArray:
        """How long each move's new level is held, s."""
        return np.array([m.after.length * self.dt for m in self.moves])


@dataclass(frozen=True)
class MovingStretch:
    """A stretch of a command that keeps moving, with the measures the readers share.

    Parameters
    ----------
    t : numpy.ndarray
        Sample times, s.
    u : numpy.ndarray
        The command, deg.
    """

    t: FloatArray
    u: FloatArray

    @cached_property
    def dt(self) -> float:
        """Median sample interval, s."""
        return float(np.median(np.diff(self.t)))

    @cached_property
    def turns(self) -> NDArray[np.int64]:
        """Indices of the command's turning points."""
        return series.extrema(self.u)

    @cached_property
    def half_periods_s(self) -> FloatArray:
        """Time between consecutive turning points, s."""
        return np.diff(self.t[self.turns])

    @cached_property
    def swings(self) -> FloatArray:
        """Command change between consecutive turning points, deg (absolute)."""
        return np.abs(np.diff(self.u[self.turns]))

    @cached_property
    def steady(self) -> bool:
        """At least 6 turning points at a steady rhythm: one tone."""
        h = self.half_periods_s
        return self.turns.size >= 6 and float(np.std(h) / np.mean(h)) < STEADY_CV

    @cached_property
    def dwells(self) -> tuple[tuple[int, int], ...]:
        """The dwells of a stepped sine: sample ranges ``[start, stop)`` of steady tones (none otherwise).

        A sweep's period shrinks steadily; a stepped sine's is piecewise constant: runs of at least
        ``DWELL_HALVES`` half periods, each run steady (coefficient of variation under ``STEADY_CV``)
        and without a trend, one tone jumping to the next by more than ``STEADY_CV``. The half periods
        are read through a running median of five (a quantised command's turning instants jitter by a
        sample); at most two half periods between two dwells (the one straddling the change of
        tone) belong to neither. The first dwell starts, and the last ends, with the stretch.
        """
        h = self.half_periods_s
        if h.size < 2 * DWELL_HALVES:
            return ()
        smooth = np.array([np.median(h[max(i - 2, 0):i + 3]) for i in range(h.size)])
        jump = np.abs(np.diff(np.log(smooth))) > np.log1p(STEADY_CV)
        bounds = [0, *(np.flatnonzero(jump) + 1).tolist(), h.size]
        runs = [(a, b) for a, b in pairwise(bounds)]
        if len(runs) < 2 or runs[0][1] - runs[0][0] < DWELL_HALVES or runs[-1][1] - runs[-1][0] < DWELL_HALVES:
            return ()
        kept: list[tuple[int, int]] = []
        for lo, hi in runs:
            if hi - lo < DWELL_HALVES:
                if hi - lo > 2 or not kept or kept[-1][1] != lo:
                    return ()  # more than a change of tone between two dwells: a sweep's fast start, or no tone
                kept.append((hi, hi))  # a gap: the next dwell must not join the one before
                continue
            a, b = lo, hi
            ref = float(np.median(h[a:b]))
            off = np.abs(np.log(h[a:b] / ref)) > np.log1p(STEADY_CV)
            while a < b and off[0]:  # the half period straddling a change of tone belongs to neither dwell
                a, off = a + 1, off[1:]
            while b > a and off[-1]:
                b, off = b - 1, off[:-1]
            run = h[a:b]
            third = max(1, run.size // 3)
            trend = abs(float(np.log(np.median(run[-third:]) / np.median(run[:third]))))
            if run.size < DWELL_HALVES or float(np.std(run) / np.mean(run)) >= STEADY_CV \
                    or trend > np.log1p(STEADY_CV) / 3.0:
                return ()
            kept.append((a, b))
        dwells = [r for r in kept if r[1] > r[0]]
        if len(dwells) < 2:
            return ()
        turns = self.turns
        out = [(int(turns[a]), int(turns[b]) + 1) for a, b in dwells]
        out[0] = (0, out[0][1])
        out[-1] = (out[-1][0], self.u.size)
        return tuple(out)

    @cached_property
    def tone_hz(self) -> float:
        """The tone's frequency from the median half period, Hz."""
        return 0.5 / float(np.median(self.half_periods_s))

    @cached_property
    def growth(self) -> float:
        """Last swings over first swings (medians of up to three)."""
        k = max(1, min(3, self.swings.size // 3))
        return float(np.median(self.swings[-k:]) / max(float(np.median(self.swings[:k])), 1e-12))

    @cached_property
    def sine(self) -> Sine | None:
        """A least-squares sine at the tone's frequency."""
        return fit_sine(self.t, self.u, self.tone_hz)

    @cached_property
    def span_s(self) -> float:
        """Length of the stretch, s."""
        return float(self.t[-1] - self.t[0])


@dataclass(frozen=True)
class HeldStretch:
    """Samples ``[start, stop)`` of the record over which the command is held at ``value``.

    Parameters
    ----------
    t : numpy.ndarray
        The record's time, s.
    hinge_moment : numpy.ndarray or None
        The record's hinge moment, in·lb (None when it has none).
    start : int
        First sample of the stretch.
    stop : int
        One past the last sample.
    value : float
        The held command, deg.
    """

    t: FloatArray
    hinge_moment: FloatArray | None
    start: int
    stop: int
    value: float

    @cached_property
    def load(self) -> FloatArray | None:
        """The hinge moment over the stretch (None when the record has none)."""
        return None if self.hinge_moment is None else self.hinge_moment[self.start:self.stop]

    @cached_property
    def swing(self) -> float:
        """Peak-to-peak hinge moment, in·lb (0 without one)."""
        return 0.0 if self.load is None else float(np.ptp(self.load))

    @cached_property
    def load_holds(self) -> tuple[Hold, ...]:
        """Levels the load holds for at least 0.3 s (record indices)."""
        if self.load is None:
            return ()
        seg = self.load
        dt = float(np.median(np.diff(self.t)))
        tol = max(series.hold_tolerance(seg), 1e-3 * self.swing)
        return tuple(Hold(h.start + self.start, h.stop + self.start, h.value)
                     for h in series.holds(seg, round(LONG_HOLD_S / dt), tol))

    @cached_property
    def covered(self) -> float:
        """Share of the stretch on a held load level."""
        return sum(h.length for h in self.load_holds) / max(self.stop - self.start, 1)

    @cached_property
    def load_levels(self) -> int:
        """Distinct load levels (to 1 % of the swing)."""
        return int(np.unique(np.round([h.value / (0.01 * self.swing) for h in self.load_holds])).size)

    @cached_property
    def reversals(self) -> int:
        """How many times the held load changes sign."""
        signs = [np.sign(h.value) if abs(h.value) > 0.05 * self.swing else 0.0 for h in self.load_holds]
        return sum(1 for a, b in pairwise(signs) if a * b < 0)
