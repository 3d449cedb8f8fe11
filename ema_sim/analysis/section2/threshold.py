"""Static and dynamic threshold (section 2.1): the smallest command the surface follows.

The report raised the amplitude of 0.1 Hz triangles (static) or 5 Hz sines (dynamic) from zero until
the external sensor "matched the waveform of the command in a qualitative manner". Quantitatively:

* **static** (:func:`static_threshold`): every half cycle of the triangle between two turning points
  of the command is a swing ``S``; the output's swing ``ΔY`` (0.1 s moving average, read at the turning
  points) is zero below the threshold and ``g·(S − 2d)`` above it, the signature of a dead zone of half
  width ``d`` on the servo error. A line through the half cycles that moved gives ``d`` (motion onset,
  the contract's ``static_threshold.threshold_deg``), and the *follow* amplitude is the smallest
  amplitude from which every half cycle moves at least half as far as commanded.
* **dynamic** (:func:`dynamic_threshold`): windows of two periods of the tone; in each, least-squares
  sines give the command and output amplitudes at the tone's frequency and the share of the output's
  variance the tone explains (R²). Onset: the command amplitude from which the output's tone stays
  above 6 standard errors of the noise; follow: from which R² ≥ 0.9 and the gain is within 3 dB.

Amplitudes are also given in command volts through the channel's command curve slope. Both tests
are recognised from a steady tone whose amplitude grows (:func:`read_growing_tone`).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray
from typing_extensions import override

from ema_sim.analysis.estimation.sine_fit import sine_at
from ema_sim.analysis.formatting import figure
from ema_sim.analysis.formatting.markdown import bullets, image, num, quality
from ema_sim.analysis.records.series import extrema, moving_average
from ema_sim.analysis.section2.base import Quality, RecordAnalysis, Section2Test
from ema_sim.analysis.section2.segments import MovingStretch, Reading
from ema_sim.jsontypes import JsonObject

if TYPE_CHECKING:
    from matplotlib.axes import Axes

FloatArray = NDArray[np.float64]

FOLLOW_SHARE = 0.5
FOLLOW_R2 = 0.9
FOLLOW_GAIN = 10 ** (-3 / 20)


def _first_sustained(flags: NDArray[np.bool_]) -> int | None:
    """Index from which every flag is True (None if the last is False)."""
    if flags.size == 0 or not flags[-1]:
        return None
    bad = np.flatnonzero(~flags)
    return int(bad[-1] + 1) if bad.size else 0


@dataclass(frozen=True)
class StaticThreshold:
    """Static threshold from slowly growing triangles.

    Parameters
    ----------
    output : str
        Name of the output.
    onset_deg : float or None
        Motion onset (dead-zone half width), deg.
    follow_deg : float or None
        Amplitude from which the output follows, deg.
    volts_per_deg : float
        Command volts per degree.
    swing_deg : numpy.ndarray
        Command swing of each half cycle, deg.
    output_swing_deg : numpy.ndarray
        Output swing of each half cycle, deg.
    gain : float or None
        Tracking gain above the threshold.
    notes : list
        What the test could not find.
    start_s : float
        Start of the segment, s.
    end_s : float
        End of the segment, s.
    """

    output: str
    onset_deg: float | None
    follow_deg: float | None
    volts_per_deg: float
    swing_deg: FloatArray
    output_swing_deg: FloatArray
    gain: float | None
    notes: list[str] = field(default_factory=list)
    start_s: float = 0.0
    end_s: float = 0.0

    def as_dict(self) -> JsonObject:
        """Plain values for JSON.

        Returns
        -------
        dict
            Onset and follow amplitude in degrees and volts, the gain, every half cycle, quality, notes.
        """
        v = self.volts_per_deg
        q, why = _quality_note(self.onset_deg, self.follow_deg)
        return {
            "output": self.output, "onset_deg": self.onset_deg, "follow_amplitude_deg": self.follow_deg,
            "quality": q, "quality_note": why,
            "onset_v": None if self.onset_deg is None else self.onset_deg * v,
            "follow_amplitude_v": None if self.follow_deg is None else self.follow_deg * v,
            "tracking_gain_above_threshold": self.gain,
            "half_cycles": {"command_swing_deg": self.swing_deg.tolist(),
                            "output_swing_deg": self.output_swing_deg.tolist()},
            "definition": "onset: dead-zone half width d from output swing = g*(command swing - 2d); follow: "
                          "smallest amplitude from which every half cycle moves >= 50 % of the command swing",
            "notes": [*self.notes],
        }


def static_threshold(t: FloatArray, u: FloatArray, y: FloatArray, noise: float, *, output: str,
                     volts_per_deg: float) -> StaticThreshold | None:
    """See the module docstring; None when there are fewer than 4 half cycles.

    Parameters
    ----------
    t : numpy.ndarray
        Sample times, s.
    u : numpy.ndarray
        The command, deg.
    y : numpy.ndarray
        The output, deg.
    noise : float
        The output's noise floor, deg.
    output : str
        Name of the output.
    volts_per_deg : float
        Command volts per degree.

    Returns
    -------
    StaticThreshold or None
        The threshold, or None with fewer than 4 half cycles.
    """
    dt = float(np.median(np.diff(t)))
    turns = extrema(u)
    if turns.size < 4:
        return None
    ys = moving_average(y, max(1, round(0.1 / dt)))
    lag = round(0.05 / dt)
    idx = np.clip(turns + lag, 0, y.size - 1)
    swing = np.abs(np.diff(u[turns]))
    out = np.abs(np.diff(ys[idx]))
    sigma_s = np.sqrt(2.0) * noise / np.sqrt(max(1, round(0.1 / dt)))
    moved = out > max(6.0 * sigma_s, 1e-9)
    notes: list[str] = []
    onset = gain = None
    if moved.sum() >= 2:
        g, b = np.polyfit(swing[moved], out[moved], 1)
        if g > 0:
            onset = max(0.0, -b / g / 2.0)
            gain = float(g)
    else:
        notes.append("the output never moved clearly: threshold above the largest command amplitude")
    follow_at = _first_sustained(out >= FOLLOW_SHARE * swing)
    follow = float(swing[follow_at] / 2.0) if follow_at is not None else None
    if follow is None:
        notes.append("the output never followed: the last half cycle moved less than half the command swing")
    return StaticThreshold(output, onset, follow, volts_per_deg, swing, out, gain, notes)


@dataclass(frozen=True)
class DynamicThreshold:
    """Dynamic threshold from a tone of growing amplitude.

    Parameters
    ----------
    output : str
        Name of the output.
    freq_hz : float
        Frequency, Hz.
    onset_deg : float or None
        Motion onset, deg.
    follow_deg : float or None
        Amplitude from which the output follows, deg.
    volts_per_deg : float
        Command volts per degree.
    command_amp_deg : numpy.ndarray
        Command amplitude of each window, deg.
    output_amp_deg : numpy.ndarray
        Output amplitude of each window, deg.
    r2 : numpy.ndarray
        Share of the output's variance the tone explains, per window.
    notes : list
        What the test could not find.
    """

    output: str
    freq_hz: float
    onset_deg: float | None
    follow_deg: float | None
    volts_per_deg: float
    command_amp_deg: FloatArray
    output_amp_deg: FloatArray
    r2: FloatArray
    notes: list[str] = field(default_factory=list)

    def as_dict(self) -> JsonObject:
        """Plain values for JSON.

        Returns
        -------
        dict
            Onset and follow amplitude in degrees and volts, every window, quality, notes.
        """
        v = self.volts_per_deg
        q, why = _quality_note(self.onset_deg, self.follow_deg)
        return {
            "output": self.output, "freq_hz": self.freq_hz, "onset_deg": self.onset_deg,
            "quality": q, "quality_note": why,
            "follow_amplitude_deg": self.follow_deg, "onset_v": None if self.onset_deg is None else self.onset_deg * v,
            "follow_amplitude_v": None if self.follow_deg is None else self.follow_deg * v,
            "windows": {"command_amplitude_deg": self.command_amp_deg.tolist(),
                        "output_amplitude_deg": self.output_amp_deg.tolist(), "r2": self.r2.tolist()},
            "definition": "onset: command amplitude from which the output tone stays above 6 standard errors of "
                          "the noise; follow: from which R^2 >= 0.9 and gain within 3 dB",
            "notes": [*self.notes],
        }


def dynamic_threshold(t: FloatArray, u: FloatArray, y: FloatArray, freq_hz: float, noise: float, *,
                      output: str, volts_per_deg: float, periods: int = 2) -> DynamicThreshold | None:
    """See the module docstring; None when the record holds fewer than 4 windows.

    Parameters
    ----------
    t : numpy.ndarray
        Sample times, s.
    u : numpy.ndarray
        The command, deg.
    y : numpy.ndarray
        The output, deg.
    freq_hz : float
        Frequency, Hz.
    noise : float
        The output's noise floor, deg.
    output : str
        Name of the output.
    volts_per_deg : float
        Command volts per degree.
    periods : int
        Periods per window.

    Returns
    -------
    DynamicThreshold or None
        The threshold, or None with fewer than 4 windows.
    """
    dt = float(np.median(np.diff(t)))
    n_win = max(8, round(periods / freq_hz / dt))
    step = max(1, round(1.0 / freq_hz / dt))
    starts = np.arange(0, u.size - n_win + 1, step)
    if starts.size < 4:
        return None
    au, ay, r2 = [], [], []
    for s in starts:
        tt = t[s:s + n_win]
        su = sine_at(tt, u[s:s + n_win], freq_hz)
        sy = sine_at(tt, y[s:s + n_win], freq_hz)
        au.append(su.amplitude)
        ay.append(sy.amplitude)
        r2.append(sy.r2)
    au_a, ay_a, r2_a = np.array(au), np.array(ay), np.array(r2)
    se = noise * np.sqrt(2.0 / n_win)
    notes: list[str] = []
    on = _first_sustained(ay_a > 6.0 * se + 1e-12)
    onset = float(au_a[on]) if on is not None else None
    with np.errstate(divide="ignore", invalid="ignore"):
        gain = np.where(au_a > 0, ay_a / np.where(au_a > 0, au_a, 1.0), 0.0)
    fol = _first_sustained((r2_a >= FOLLOW_R2) & (gain >= FOLLOW_GAIN))
    follow = float(au_a[fol]) if fol is not None else None
    if onset is None:
        notes.append("the output tone never stayed above the noise: threshold above the largest amplitude")
    if follow is None:
        notes.append("the output never followed the tone (R² ≥ 0.9, gain within 3 dB) to the end")
    if onset is not None and on == 0:
        notes.append("the output moved from the first window: the threshold is below the smallest amplitude")
    return DynamicThreshold(output, freq_hz, onset, follow, volts_per_deg, au_a, ay_a, r2_a, notes)


def read_growing_tone(m: MovingStretch) -> Reading | None:
    """A steady tone whose amplitude grows by more than half: a threshold test (static below 1 Hz).

    Parameters
    ----------
    m : MovingStretch
        A moving stretch of the command.

    Returns
    -------
    Reading or None
        ``static_threshold`` or ``dynamic_threshold`` with the tone's frequency, or None.
    """
    if not m.steady or m.growth <= 1.5:
        return None
    freq = m.tone_hz
    kind = "static_threshold" if freq < 1.0 else "dynamic_threshold"
    return Reading(kind, f"{freq:.3g} Hz tone whose amplitude grows {m.growth:.2g}×", {"freq_hz": freq})


def _threshold_output(ra: RecordAnalysis) -> tuple[str, FloatArray]:
    """The external sensor (the LVDT when there is none): thresholds are what the surface follows."""
    return ra.primary(("surface_deg", "position_deg"))


def _quality_note(onset: float | None, follow: float | None) -> tuple[Quality, str]:
    if onset is None:
        return "not_determined", "the output never moved clearly"
    if follow is None:
        return "not_determined", "the output never followed"
    return "ok", ""


class Static(Section2Test[StaticThreshold]):
    """Static threshold of each slowly growing triangle."""

    key = "static_threshold"
    title = "Static threshold (section 2.1.1)"
    kinds = ("static_threshold",)
    absent = "no slow triangles of growing amplitude recognised"

    @override
    def run(self, ra: RecordAnalysis) -> list[StaticThreshold]:
        data, t = ra.data, ra.data.time_s
        name, y = _threshold_output(ra)
        out = []
        for seg in ra.segments(*self.kinds):
            sl = slice(seg.start, seg.stop)
            r = static_threshold(t[sl], data.command_deg[sl], y[sl], ra.noise_deg[name], output=name,
                                 volts_per_deg=ra.volts_per_deg())
            if r:
                out.append(replace(r, start_s=float(t[seg.start]), end_s=float(t[seg.stop - 1])))
        return out


    @override
    def markdown(self, ra: RecordAnalysis, results: list[StaticThreshold],
                 images: list[str | None]) -> list[str]:
        lines: list[str] = []
        for s, img in zip(results, images, strict=True):
            q, why = _quality_note(s.onset_deg, s.follow_deg)
            lines += [f"Motion onset {num(s.onset_deg, '.4f', '°')} "
                      f"({num(None if s.onset_deg is None else s.onset_deg * s.volts_per_deg, '.4f', ' V')}); "
                      f"follows from {num(s.follow_deg, '.4f', '°')} amplitude; gain above threshold "
                      f"{num(s.gain, '.3f')} (on {s.output}). Quality: {quality(q, why)}.", ""]
            lines += bullets(s.notes)
            lines += image(img, "static threshold")
        return lines

    @override
    def summary(self, ra: RecordAnalysis, r: StaticThreshold) -> list[str]:
        return [f"static threshold: onset {num(r.onset_deg, '.4f', '°')}, follows from {num(r.follow_deg, '.4f', '°')}"]

    @override
    def plot(self, ra: RecordAnalysis, r: StaticThreshold, path: Path) -> bool:
        fig, ax = figure.pyplot().subplots(figsize=(7, 4))
        ax.plot(r.swing_deg / 2, r.output_swing_deg / 2, "o", ms=4, label="half cycles")
        if r.onset_deg is not None and r.gain:
            a = np.linspace(0, r.swing_deg.max() / 2, 50)
            ax.plot(a, np.maximum(r.gain * (a - r.onset_deg), 0), "k--", lw=1, label=f"dead zone {r.onset_deg:.4f}°")
        ax.set_xlabel("command amplitude (half swing), deg")
        _finish_threshold_plot(ax, "static threshold")
        figure.save(fig, path)
        return True


class Dynamic(Section2Test[DynamicThreshold]):
    """Dynamic threshold of each tone of growing amplitude."""

    key = "dynamic_threshold"
    title = "Dynamic threshold (section 2.1.2)"
    kinds = ("dynamic_threshold",)
    absent = "no tone of growing amplitude recognised"

    @override
    def run(self, ra: RecordAnalysis) -> list[DynamicThreshold]:
        data, t = ra.data, ra.data.time_s
        name, y = _threshold_output(ra)
        out = []
        for seg in ra.segments(*self.kinds):
            f = seg.params.get("freq_hz")
            if not f:
                continue
            sl = slice(seg.start, seg.stop)
            r = dynamic_threshold(t[sl], data.command_deg[sl], y[sl], f, ra.noise_deg[name], output=name,
                                  volts_per_deg=ra.volts_per_deg())
            if r:
                out.append(r)
        return out


    @override
    def markdown(self, ra: RecordAnalysis, results: list[DynamicThreshold],
                 images: list[str | None]) -> list[str]:
        lines: list[str] = []
        for s, img in zip(results, images, strict=True):
            q, why = _quality_note(s.onset_deg, s.follow_deg)
            lines += [f"{s.freq_hz:g} Hz: motion onset {num(s.onset_deg, '.4f', '°')} amplitude; follows from "
                      f"{num(s.follow_deg, '.4f', '°')} (on {s.output}). Quality: {quality(q, why)}.", ""]
            lines += bullets(s.notes)
            lines += image(img, "dynamic threshold")
        return lines

    @override
    def summary(self, ra: RecordAnalysis, r: DynamicThreshold) -> list[str]:
        return [f"dynamic threshold: onset {num(r.onset_deg, '.4f', '°')}, follows from "
                f"{num(r.follow_deg, '.4f', '°')}"]

    @override
    def plot(self, ra: RecordAnalysis, r: DynamicThreshold, path: Path) -> bool:
        fig, ax = figure.pyplot().subplots(figsize=(7, 4))
        ax.plot(r.command_amp_deg, r.output_amp_deg, "o", ms=3, label="output amplitude")
        twin = ax.twinx()
        twin.plot(r.command_amp_deg, np.clip(r.r2, 0, 1), "-", color="0.6", lw=0.8)
        twin.set_ylim(0, 1.05)
        twin.set_ylabel(f"R² of the {r.freq_hz:g} Hz tone in the output (grey)")
        if r.onset_deg is not None:
            ax.axvline(r.onset_deg, color="r", ls="--", lw=0.8, label=f"onset {r.onset_deg:.4f}°")
        ax.set_xlabel("command amplitude, deg")
        _finish_threshold_plot(ax, f"dynamic threshold, {r.freq_hz:g} Hz")
        figure.save(fig, path)
        return True


def _finish_threshold_plot(ax: Axes, title: str) -> None:
    lim = ax.get_xlim()
    ax.plot(lim, lim, ":", color="0.5", lw=0.8, label="1:1")
    ax.set_ylabel("output amplitude, deg")
    ax.legend(fontsize=8)
    ax.grid(lw=0.3)
    ax.set_title(title)


STATIC = Static()
DYNAMIC = Dynamic()
