"""Least-squares sine fits: the frequency, amplitude and phase of a tone in a record.

The frequency is found from the FFT peak (Hann, zero-padded), then refined by minimising the
least-squares residual (bounded scalar search over ±1 bin); amplitude and phase are linear least
squares on ``[sin, cos, 1]``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import minimize_scalar

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class Sine:
    """``offset + amplitude·sin(2π·freq·t + phase)``.

    Parameters
    ----------
    freq_hz : float
        Frequency, Hz.
    amplitude : float
        Amplitude.
    phase_rad : float
        Phase, rad.
    offset : float
        Offset.
    r2 : float
        Share of the variance the sine explains.
    """

    freq_hz: float
    amplitude: float
    phase_rad: float
    offset: float
    r2: float
    """Share of the variance the sine explains."""

    def __call__(self, t: FloatArray) -> FloatArray:
        """Evaluate."""
        return self.offset + self.amplitude * np.sin(2 * np.pi * self.freq_hz * np.asarray(t) + self.phase_rad)


def sine_at(t: FloatArray, y: FloatArray, freq_hz: float) -> Sine:
    """Amplitude, phase and offset of the tone at ``freq_hz`` (linear least squares).

    Parameters
    ----------
    t : numpy.ndarray
        Sample times, s.
    y : numpy.ndarray
        The signal.
    freq_hz : float
        Frequency, Hz.

    Returns
    -------
    Sine
        The tone.
    """
    w = 2 * np.pi * freq_hz * t
    X = np.column_stack([np.sin(w), np.cos(w), np.ones_like(t)])
    coef, *_ = np.linalg.lstsq(X, y, rcond=None)
    a, b, c = coef
    resid = y - X @ coef
    tot = float(np.sum((y - y.mean()) ** 2))
    r2 = 1.0 - float(resid @ resid) / tot if tot > 0 else 0.0
    return Sine(float(freq_hz), float(np.hypot(a, b)), float(np.arctan2(b, a)), float(c), r2)


def dominant_frequency(t: FloatArray, y: FloatArray, f_min: float = 0.0, f_max: float | None = None) -> float | None:
    """Frequency of the largest spectral peak of ``y`` in ``[f_min, f_max]``.

    Parameters
    ----------
    t : numpy.ndarray
        Sample times, s.
    y : numpy.ndarray
        The signal.
    f_min : float
        Lowest frequency searched, Hz.
    f_max : float or None
        Highest frequency searched, Hz (None: Nyquist).

    Returns
    -------
    float or None
        Its frequency, Hz (None when the band is empty).
    """
    dt = float(np.median(np.diff(t)))
    n = y.size
    nfft = 1 << int(np.ceil(np.log2(4 * n)))
    spec = np.abs(np.fft.rfft((y - y.mean()) * np.hanning(n), nfft))
    f = np.fft.rfftfreq(nfft, dt)
    sel = (f > max(f_min, 0.0)) & (f <= (f_max if f_max else f[-1]))
    if not sel.any():
        return None
    return float(f[sel][np.argmax(spec[sel])])


def fit_sine(t: FloatArray, y: FloatArray, freq_hz: float | None = None, f_min: float = 0.0,
             f_max: float | None = None) -> Sine | None:
    """The dominant tone of ``y`` (or the tone near ``freq_hz``), frequency refined by least squares.

    Parameters
    ----------
    t : numpy.ndarray
        Sample times, s.
    y : numpy.ndarray
        The signal.
    freq_hz : float or None
        Frequency to refine from (default: the largest spectral peak), Hz.
    f_min : float
        Lowest frequency searched, Hz.
    f_max : float or None
        Highest frequency searched, Hz (None: Nyquist).

    Returns
    -------
    Sine or None
        The tone (None for a flat or too short signal).
    """
    if t.size < 8 or np.ptp(y) == 0.0:
        return None
    f0 = freq_hz or dominant_frequency(t, y, f_min, f_max)
    if f0 is None:
        return None
    span = float(t[-1] - t[0])
    df = 1.0 / span
    res = minimize_scalar(lambda f: -sine_at(t, y, f).r2, bounds=(max(f0 - df, 1e-6), f0 + df),
                          method="bounded", options={"xatol": 1e-6 * f0})
    return sine_at(t, y, float(res.x))
