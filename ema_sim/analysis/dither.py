"""Dither detection (sections 2.10 and 4.3): a limit cycle on a held surface, its frequency and size.

Closed-loop AIL tests showed a stable ≈ 3 Hz dither of ≈ 0.1° peak to peak on the position feedback
in trimmed flight. While the command is held, the detrended output's spectrum (Welch, Hann, 50 %
overlap) is searched between 1 and 50 Hz for a peak standing at least 15 dB above the median
spectral level (the noise floor); its frequency is refined by least squares, and the peak-to-peak
size is read from the synchronous average of the output folded at that period (64 phase bins), which
keeps the limit cycle's own waveform (PWM dither is not a sine) while averaging the sensor noise out.
A cycle whose frequency wanders (noise kicks a loop's limit cycle about) averages itself down over a
long stretch; ``fold_periods`` then folds consecutive windows of that many periods and takes the
median window, the size one reads off a strip chart.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ema_sim.analysis import spectra
from ema_sim.analysis.sine_fit import fit_sine

FloatArray = NDArray[np.float64]

BAND_HZ = (1.0, 50.0)
DETECT_DB = 15.0
PHASE_BINS = 64
MIN_PP_DEG = 1e-4
"""An output steadier than this (a quantized, noise-free feedback) has no limit cycle to look for."""


@dataclass(frozen=True)
class DitherResult:
    """Outcome of the limit-cycle search on one held stretch."""

    output: str
    start_s: float
    end_s: float
    detected: bool
    peak_hz: float
    peak_db_above_floor: float
    freq_hz: float | None
    peak_to_peak_deg: float | None
    fundamental_amplitude_deg: float | None
    waveform_deg: FloatArray | None
    reason: str = ""

    def as_dict(self) -> dict[str, Any]:
        """Plain values for JSON."""
        return {
            "output": self.output, "start_s": self.start_s, "end_s": self.end_s, "detected": self.detected,
            "largest_peak_hz": self.peak_hz, "largest_peak_db_above_floor": self.peak_db_above_floor,
            "detection_db": DETECT_DB, "freq_hz": self.freq_hz, "peak_to_peak_deg": self.peak_to_peak_deg,
            "fundamental_amplitude_deg": self.fundamental_amplitude_deg,
            "waveform_deg": self.waveform_deg.tolist() if self.waveform_deg is not None else None,
        }

    @property
    def statement(self) -> str:
        """One line for the report."""
        if self.reason:
            return f"no limit cycle: {self.reason}"
        if self.detected:
            return (f"limit cycle at {self.freq_hz:.3g} Hz, {self.peak_to_peak_deg:.3g}° peak to peak "
                    f"({self.peak_db_above_floor:.0f} dB above the noise floor)")
        return (f"no limit cycle: largest peak {self.peak_db_above_floor:.1f} dB above the noise floor at "
                f"{self.peak_hz:.3g} Hz (needs {DETECT_DB:g} dB)")


def _fold(t: FloatArray, yd: FloatArray, freq_hz: float) -> FloatArray:
    """Synchronous average of ``yd`` over ``PHASE_BINS`` phase bins of period ``1/freq_hz``."""
    phase = np.mod((t - t[0]) * freq_hz, 1.0)
    bins = np.minimum((phase * PHASE_BINS).astype(int), PHASE_BINS - 1)
    counts = np.bincount(bins, minlength=PHASE_BINS)
    return np.bincount(bins, weights=yd, minlength=PHASE_BINS) / np.maximum(counts, 1)


def detect_dither(t: FloatArray, y: FloatArray, *, output: str, fold_always: bool = False,
                  fold_periods: int | None = None) -> DitherResult | None:
    """Search a held stretch for a limit cycle (None when shorter than 4 periods of the lowest frequency searched).

    ``fold_always`` also measures the largest peak that falls short of the detection level (frequency,
    synchronous peak to peak, fundamental), so a report can say how small it is; ``detected`` stays False.
    ``fold_periods`` folds windows of that many periods and keeps the median one (module docstring).
    """
    fs = 1.0 / float(np.median(np.diff(t)))
    span = float(t[-1] - t[0]) + 1.0 / fs  # the record's length: n samples of 1/fs each
    if span < 4.0 / BAND_HZ[0] - 1e-9:
        return None
    yd = y - np.polyval(np.polyfit(t - t[0], y, 1), t - t[0])
    if np.ptp(yd) < MIN_PP_DEG:
        return DitherResult(output, float(t[0]), float(t[-1]), False, 0.0, 0.0, None, None, None, None,
                            f"the output does not move (peak to peak < {MIN_PP_DEG:g}°)")
    sp = spectra.welch(yd, yd[None, :], fs, min(8.0, span / 2.0), overlap=0.5)
    f, p = sp.freq_hz, sp.gxx
    band = (f >= BAND_HZ[0]) & (f <= min(BAND_HZ[1], fs / 2.5))
    fb, pb = f[band], p[band]
    i = int(np.argmax(pb))
    mask = np.ones(pb.size, dtype=bool)
    mask[max(0, i - 3):i + 4] = False
    floor = float(np.median(pb[mask])) if mask.any() else float(np.median(pb))
    ratio_db = float(10.0 * np.log10(pb[i] / floor)) if floor > 0 else float("inf")
    detected = ratio_db >= DETECT_DB
    if not (detected or fold_always):
        return DitherResult(output, float(t[0]), float(t[-1]), False, float(fb[i]), ratio_db, None, None, None, None)
    sine = fit_sine(t, yd, float(fb[i]))
    assert sine is not None
    wave = _fold(t, yd, sine.freq_hz)
    if fold_periods is not None:
        window = fold_periods / sine.freq_hz
        starts = np.arange(t[0], t[-1] - window + 0.5 / fs, window)
        if starts.size:
            waves = [_fold(t[sel], yd[sel], sine.freq_hz) for sel in ((t >= a) & (t < a + window) for a in starts)]
            wave = waves[int(np.argsort([np.ptp(w) for w in waves])[len(waves) // 2])]
    return DitherResult(output, float(t[0]), float(t[-1]), detected, float(fb[i]), ratio_db, sine.freq_hz,
                        float(np.ptp(wave)), sine.amplitude, wave)
