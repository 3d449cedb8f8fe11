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

Amplitudes are also given in command volts through the channel's command curve slope.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ema_sim.analysis.series import extrema, moving_average
from ema_sim.analysis.sine_fit import sine_at

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
    """Static threshold from slowly growing triangles."""

    output: str
    onset_deg: float | None
    follow_deg: float | None
    volts_per_deg: float
    swing_deg: FloatArray
    output_swing_deg: FloatArray
    gain: float | None
    notes: list[str] = field(default_factory=list)

    def as_dict(self) -> dict[str, Any]:
        """Plain values for JSON."""
        v = self.volts_per_deg
        return {
            "output": self.output, "onset_deg": self.onset_deg, "follow_amplitude_deg": self.follow_deg,
            "onset_v": None if self.onset_deg is None else self.onset_deg * v,
            "follow_amplitude_v": None if self.follow_deg is None else self.follow_deg * v,
            "tracking_gain_above_threshold": self.gain,
            "half_cycles": {"command_swing_deg": self.swing_deg.tolist(),
                            "output_swing_deg": self.output_swing_deg.tolist()},
            "definition": "onset: dead-zone half width d from output swing = g*(command swing - 2d); follow: "
                          "smallest amplitude from which every half cycle moves >= 50 % of the command swing",
            "notes": self.notes,
        }


def static_threshold(t: FloatArray, u: FloatArray, y: FloatArray, noise: float, *, output: str,
                     volts_per_deg: float) -> StaticThreshold | None:
    """See the module docstring; None when there are fewer than 4 half cycles."""
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
    """Dynamic threshold from a tone of growing amplitude."""

    output: str
    freq_hz: float
    onset_deg: float | None
    follow_deg: float | None
    volts_per_deg: float
    command_amp_deg: FloatArray
    output_amp_deg: FloatArray
    r2: FloatArray
    notes: list[str] = field(default_factory=list)

    def as_dict(self) -> dict[str, Any]:
        """Plain values for JSON."""
        v = self.volts_per_deg
        return {
            "output": self.output, "freq_hz": self.freq_hz, "onset_deg": self.onset_deg,
            "follow_amplitude_deg": self.follow_deg, "onset_v": None if self.onset_deg is None else self.onset_deg * v,
            "follow_amplitude_v": None if self.follow_deg is None else self.follow_deg * v,
            "windows": {"command_amplitude_deg": self.command_amp_deg.tolist(),
                        "output_amplitude_deg": self.output_amp_deg.tolist(), "r2": self.r2.tolist()},
            "definition": "onset: command amplitude from which the output tone stays above 6 standard errors of "
                          "the noise; follow: from which R^2 >= 0.9 and gain within 3 dB",
            "notes": self.notes,
        }


def dynamic_threshold(t: FloatArray, u: FloatArray, y: FloatArray, freq_hz: float, noise: float, *,
                      output: str, volts_per_deg: float, periods: int = 2) -> DynamicThreshold | None:
    """See the module docstring; None when the record holds fewer than 4 windows."""
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
