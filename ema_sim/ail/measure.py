"""The dither finding from a run: limit-cycle frequency and size per surface, and a verdict.

Each surface's LVDT position (EMAC side, the signal of figures 41 and 43) is searched over the trimmed
stretch after ``settle_s`` with :func:`ema_sim.analysis.section2.dither.detect_dither`: the largest spectral peak
between 1 and 50 Hz, its level above the median spectral floor, and the synchronous (folded) peak to
peak at its frequency, taken over windows of :data:`FOLD_PERIODS` periods (median window): noise kicks
the limit cycle's frequency about by a few per cent, which would average a 20 s fold down.

**Dither** means both: a peak at least :data:`~ema_sim.analysis.section2.dither.DETECT_DB` (15 dB) above the
floor, and a synchronous peak to peak of at least :data:`DITHER_MIN_PP_DEG` (0.05°, the lower end of
the AIL's 0.05–0.2°, more than two 5 mV converter steps of ≈ 0.021°). **None** is everything else: no
peak stands out, or what stands out is smaller than that: a quantizer's own one-step hunting (a 5 mV
D/A or A/D, or LOADA's 0.020° stage, closing a loop with integrators) cycles by one step and no more.
Every figure is reported either way, so the verdict can be checked against the numbers.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TypedDict

import numpy as np

from ema_sim.ail.loop import AilRun
from ema_sim.analysis.section2.dither import DETECT_DB, DitherResult, detect_dither
from ema_sim.config import CHANNELS
from ema_sim.errors import EmaError

DITHER_MIN_PP_DEG = 0.05
"""Smallest synchronous peak to peak called a dither (see the module docstring)."""
FOLD_PERIODS = 10
"""Periods per synchronous-average window."""


class DitherReport(TypedDict):
    """:meth:`SurfaceDither.as_dict`: one surface's verdict and the thresholds it was reached with."""

    channel: str
    dither: bool
    freq_hz: float | None
    peak_to_peak_deg: float
    peak_db_above_floor: float
    detection_db: float
    dither_min_pp_deg: float


@dataclass(frozen=True)
class SurfaceDither:
    """One surface's measurement."""

    channel: str
    """The surface's channel."""
    result: DitherResult | None
    """None when the stretch is too short to search (under 4 s)."""

    @property
    def dither(self) -> bool:
        """The verdict: a limit cycle standing out of the noise and at least 0.05° peak to peak."""
        r = self.result
        return bool(r is not None and r.detected and (r.peak_to_peak_deg or 0.0) >= DITHER_MIN_PP_DEG)

    @property
    def freq_hz(self) -> float | None:
        """Frequency of the largest peak (refined), Hz."""
        r = self.result
        return None if r is None else (r.freq_hz if r.freq_hz is not None else r.peak_hz)

    @property
    def peak_to_peak_deg(self) -> float:
        """Synchronous peak to peak at that frequency, deg (0 when the output does not move)."""
        r = self.result
        return 0.0 if r is None or r.peak_to_peak_deg is None else float(r.peak_to_peak_deg)

    @property
    def peak_db(self) -> float:
        """Level of the largest peak above the spectral floor, dB."""
        return 0.0 if self.result is None else float(self.result.peak_db_above_floor)

    @property
    def statement(self) -> str:
        """One line: the verdict and its numbers."""
        if self.result is None:
            return "not measured: the trimmed stretch is shorter than 4 s"
        if self.result.reason:
            return f"none: {self.result.reason}"
        core = (f"{self.freq_hz:.2f} Hz, {self.peak_to_peak_deg:.3f}° peak to peak, "
                f"{self.peak_db:.0f} dB above the floor")
        return f"dither: {core}" if self.dither else f"none (largest peak: {core})"

    def as_dict(self) -> DitherReport:
        """Plain values for JSON and CSV metadata."""
        return {"channel": self.channel, "dither": self.dither, "freq_hz": self.freq_hz,
                "peak_to_peak_deg": self.peak_to_peak_deg, "peak_db_above_floor": self.peak_db,
                "detection_db": DETECT_DB, "dither_min_pp_deg": DITHER_MIN_PP_DEG}


def measure(run: AilRun, settle_s: float, *, signal: str = "position_deg",
            channels: tuple[str, ...] = CHANNELS) -> dict[str, SurfaceDither]:
    """Each surface's dither over the run after ``settle_s`` (see the module docstring).

    Parameters
    ----------
    run : AilRun
        An offline or bag run.
    settle_s : float
        Time to leave out at the start (the engagement transient), s.
    signal : str, optional
        The signal searched (a key of ``run.signals[channel]``).
    channels : tuple[str, ...], optional
        The surfaces measured.

    Returns
    -------
    dict[str, SurfaceDither]
        The measurement per channel.

    Raises
    ------
    EmaError
        Fewer than two samples remain after ``settle_s``.
    """
    keep = run.time_s >= settle_s
    if int(keep.sum()) < 2:
        raise EmaError(f"nothing to measure after {settle_s:g} s of a {run.time_s[-1]:.3g} s run")
    t = run.time_s[keep]
    return {ch: SurfaceDither(ch, detect_dither(t, run.signals[ch][signal][keep], output=f"{ch}.{signal}",
                                                fold_always=True, fold_periods=FOLD_PERIODS)) for ch in channels}


def vehicle_cycle(run: AilRun, settle_s: float, state: str) -> DitherResult | None:
    """The same search on a vehicle state (pitch rate, roll rate...): where the dither shows in the flight data.

    Parameters
    ----------
    run : AilRun
        An offline or bag run.
    settle_s : float
        Time to leave out at the start, s.
    state : str
        One of :data:`~ema_sim.ail.vehicle.STATES`.

    Returns
    -------
    DitherResult or None
        The search's result (None when the stretch is too short).
    """
    keep = run.time_s >= settle_s
    return detect_dither(run.time_s[keep], np.asarray(run.vehicle[state])[keep], output=state, fold_always=True,
                         fold_periods=FOLD_PERIODS)
