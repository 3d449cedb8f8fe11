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

A limit cycle is a line in the spectrum, so the peak must also stand 15 dB above the spectrum around
it (an octave either side, its own main lobe left out): the slow random toggling of a count between
two values has a broad low-frequency hump that stands above the band's median without being a line.
And a limit cycle must stand clear of what the sensor and its noise make on their own: its folded
peak to peak must reach :data:`LIMIT_COUNTS` counts of an output logged in counts (one count toggling
at a line of the spectrum is the count's own flicker, a vibration at the edge of a count, not a cycle
the loop keeps up) and :data:`LIMIT_SIGMAS` times the output's noise floor.

The test runs on every held stretch of :class:`~ema_sim.analysis.section2.crosstalk.Crosstalk`'s ``hold``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray
from typing_extensions import override

from ema_sim.analysis.estimation import spectra
from ema_sim.analysis.estimation.sine_fit import fit_sine
from ema_sim.analysis.formatting import figure
from ema_sim.analysis.formatting.markdown import image
from ema_sim.analysis.section2.base import Quality, RecordAnalysis, Section2Test
from ema_sim.jsontypes import JsonObject

FloatArray = NDArray[np.float64]

BAND_HZ = (1.0, 50.0)
DETECT_DB = 15.0
PHASE_BINS = 64
MIN_PP_DEG = 1e-4
"""An output steadier than this (a quantized, noise-free feedback) has no limit cycle to look for."""
LIMIT_COUNTS = 3.0
"""A limit cycle's folded peak to peak reaches this many counts of an output logged in counts."""
LIMIT_SIGMAS = 4.0
"""...and this many times the output's noise floor."""


@dataclass(frozen=True)
class DitherResult:
    """Outcome of the limit-cycle search on one held stretch.

    Parameters
    ----------
    output : str
        Name of the output.
    start_s : float
        Start of the held stretch, s.
    end_s : float
        End of the held stretch, s.
    detected : bool
        Whether a limit cycle was found.
    peak_hz : float
        Frequency of the largest spectral peak in the band, Hz.
    peak_db_above_floor : float
        That peak above the band's median level, dB.
    freq_hz : float or None
        Refined frequency of the limit cycle, Hz.
    peak_to_peak_deg : float or None
        Peak to peak of the synchronous average, deg.
    fundamental_amplitude_deg : float or None
        Amplitude of the cycle's fundamental, deg.
    waveform_deg : numpy.ndarray or None
        The synchronous average over one period, deg.
    reason : str
        Why there is no limit cycle.
    local_db : float or None
        The largest peak above the spectrum an octave either side of it, dB.
    resolution_deg : float or None
        The output's count, deg.
    """

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
    local_db: float | None = None
    """The largest peak above the spectrum an octave either side of it, dB."""
    resolution_deg: float | None = None

    @property
    def quality(self) -> Quality:
        """``ok``: a limit cycle is found, or none is, on evidence the record supports."""
        return "ok"

    def as_dict(self) -> JsonObject:
        """Plain values for JSON.

        Returns
        -------
        dict
            Whether a limit cycle was found, the largest peak, its size and waveform, and the statement.
        """
        return {
            "output": self.output, "start_s": self.start_s, "end_s": self.end_s, "detected": self.detected,
            "largest_peak_hz": self.peak_hz, "largest_peak_db_above_floor": self.peak_db_above_floor,
            "largest_peak_db_above_neighbourhood": self.local_db, "resolution_deg": self.resolution_deg,
            "statement": self.statement, "quality": self.quality,
            "detection_db": DETECT_DB, "freq_hz": self.freq_hz, "peak_to_peak_deg": self.peak_to_peak_deg,
            "fundamental_amplitude_deg": self.fundamental_amplitude_deg,
            "waveform_deg": self.waveform_deg.tolist() if self.waveform_deg is not None else None,
        }

    @property
    def statement(self) -> str:
        """One line for the report."""
        if self.reason and not self.detected:
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


def _local_db(f: FloatArray, p: FloatArray, i: int) -> float | None:
    """Peak ``i`` over the median of the spectrum an octave either side, its main lobe (±3 bins) left out."""
    near = (f >= 0.5 * f[i]) & (f <= 2.0 * f[i])
    near[max(0, i - 3):i + 4] = False
    if near.sum() < 4:
        return None
    ref = float(np.median(p[near]))
    return float(10.0 * np.log10(p[i] / ref)) if ref > 0 else float("inf")


def detect_dither(t: FloatArray, y: FloatArray, *, output: str, fold_always: bool = False,
                  fold_periods: int | None = None, resolution: float | None = None,
                  noise: float | None = None) -> DitherResult | None:
    """Search a held stretch for a limit cycle.

    Parameters
    ----------
    t : numpy.ndarray
        Time, s (uniform).
    y : numpy.ndarray
        The held output, deg.
    output : str
        Its name.
    fold_always : bool
        Also measure the largest peak that falls short of the detection level (frequency, synchronous
        peak to peak, fundamental), so a report can say how small it is; ``detected`` stays False.
    fold_periods : int, optional
        Fold windows of that many periods and keep the median one (module docstring).
    resolution : float, optional
        The output's count: a folded cycle smaller than three of them is not a limit cycle.
    noise : float, optional
        The output's noise floor: a folded cycle smaller than four times it is not a limit cycle.

    Returns
    -------
    DitherResult or None
        None when the stretch is shorter than 4 periods of the lowest frequency searched, or sampled too slowly
        to see it.
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
    if not band.any():  # sampled too slowly for the band (below 2.5× its lowest frequency)
        return None
    fb, pb = f[band], p[band]
    i = int(np.argmax(pb))
    mask = np.ones(pb.size, dtype=bool)
    mask[max(0, i - 3):i + 4] = False
    floor = float(np.median(pb[mask])) if mask.any() else float(np.median(pb))
    ratio_db = float(10.0 * np.log10(pb[i] / floor)) if floor > 0 else float("inf")
    local = _local_db(f, p, int(np.flatnonzero(band)[i]))
    detected = ratio_db >= DETECT_DB
    reason = ""
    if detected and local is not None and local < DETECT_DB:
        detected = False
        reason = (f"the {fb[i]:.3g} Hz peak stands {ratio_db:.0f} dB above the band's median but only {local:.1f} dB "
                  "above the spectrum an octave either side: a broad hump, not a line")
    if not (detected or fold_always):
        return DitherResult(output, float(t[0]), float(t[-1]), False, float(fb[i]), ratio_db, None, None, None, None,
                            reason, local, resolution)
    sine = fit_sine(t, yd, float(fb[i]))
    assert sine is not None
    wave = _fold(t, yd, sine.freq_hz)
    if fold_periods is not None:
        window = fold_periods / sine.freq_hz
        starts = np.arange(t[0], t[-1] - window + 0.5 / fs, window)
        if starts.size:
            waves = [_fold(t[sel], yd[sel], sine.freq_hz) for sel in ((t >= a) & (t < a + window) for a in starts)]
            wave = waves[int(np.argsort([np.ptp(w) for w in waves])[len(waves) // 2])]
    pp = float(np.ptp(wave))
    if detected and resolution is not None and pp < LIMIT_COUNTS * resolution:
        detected = False
        reason = (f"the {sine.freq_hz:.3g} Hz component folds to {pp:.3g}° peak to peak, {pp / resolution:.2g} of the "
                  f"output's counts of {resolution:g}° (a limit cycle needs {LIMIT_COUNTS:g}): the count toggling, "
                  "not a cycle the loop keeps up")
    elif detected and noise is not None and pp < LIMIT_SIGMAS * noise:
        detected = False
        reason = (f"the {sine.freq_hz:.3g} Hz component folds to {pp:.3g}° peak to peak, under {LIMIT_SIGMAS:g}× the "
                  f"output's noise floor {noise:.2g}°: not told from the noise")
    return DitherResult(output, float(t[0]), float(t[-1]), detected, float(fb[i]), ratio_db, sine.freq_hz,
                        pp, sine.amplitude, wave, reason, local, resolution)


class Dither(Section2Test[DitherResult]):
    """A limit cycle on every held stretch of at least 4 s with a constant load."""

    key = "dither"
    title = "Dither (sections 2.10, 4.3)"
    kinds = ("hold",)
    absent = "no command held for ≥ 5 s with a constant load"

    @override
    def run(self, ra: RecordAnalysis) -> list[DitherResult]:
        t = ra.data.time_s
        name, y = ra.primary(("position_deg", "surface_deg"))
        out = []
        for seg in ra.segments(*self.kinds):
            sl = slice(seg.start, seg.stop)
            d = detect_dither(t[sl], y[sl], output=name, resolution=ra.resolution_deg.get(name),
                              noise=ra.noise_deg[name])
            if d:
                out.append(d)
        return out


    @override
    def markdown(self, ra: RecordAnalysis, results: list[DitherResult],
                 images: list[str | None]) -> list[str]:
        lines: list[str] = []
        for x, img in zip(results, images, strict=True):
            lines += [f"{x.output}, {x.start_s:.1f}-{x.end_s:.1f} s: {x.statement}.", ""]
            lines += image(img, "dither")
        return lines

    @override
    def summary(self, ra: RecordAnalysis, r: DitherResult) -> list[str]:
        return [f"dither: {r.statement}"]

    @override
    def plot(self, ra: RecordAnalysis, r: DitherResult, path: Path) -> bool:
        d = ra.data
        sl = (d.time_s >= r.start_s) & (d.time_s <= r.end_s)
        y = getattr(d, r.output)[sl]
        y = y - y.mean()
        fs = d.sample_hz
        sp = spectra.welch(y, y[None, :], fs, min(8.0, y.size / fs / 2), overlap=0.5)
        fig, ax = figure.pyplot().subplots(1, 2, figsize=(11, 3.8))
        ax[0].loglog(sp.freq_hz[1:], sp.gxx[1:], lw=0.8)
        ax[0].axvline(r.peak_hz, color="r", ls="--", lw=0.8)
        ax[0].set_xlabel("frequency, Hz")
        ax[0].set_ylabel("deg²/Hz")
        ax[0].set_title(r.statement, fontsize=8, wrap=True)
        ax[0].grid(which="both", lw=0.3)
        if r.waveform_deg is not None:
            ph = np.linspace(0, 1, r.waveform_deg.size, endpoint=False)
            ax[1].plot(ph, r.waveform_deg, "o-", ms=3)
            if r.resolution_deg:
                ax[1].axhspan(-r.resolution_deg / 2, r.resolution_deg / 2, color="0.9", label="± half a count")
                ax[1].legend(fontsize=8)
            ax[1].set_xlabel("phase of the limit cycle, cycles")
            ax[1].set_ylabel("deg (synchronous average)")
            ax[1].grid(lw=0.3)
        else:
            ax[1].axis("off")
        figure.save(fig, path)
        return True


TEST = Dither()
