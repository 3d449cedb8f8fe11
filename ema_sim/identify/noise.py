"""Model-free noise floor and residual diagnostics (whiteness, independence from the input)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

_D4 = np.array([1.0, -4.0, 6.0, -4.0, 1.0])
_D4_GAIN = float(np.sqrt(np.sum(_D4**2)))  # √70: std of the 4th difference of unit white noise


def noise_floor(y: FloatArray) -> float:
    """Standard deviation of the white measurement noise on a sampled signal, without any model.

    The fourth difference removes a smooth signal (an actuator sampled far above its bandwidth leaves
    (ωT)⁴ of it) and keeps white noise scaled by √70; the median absolute deviation ignores the few
    samples around steps.
    """
    y = np.asarray(y, dtype=float)
    if y.size < 16:
        return float("nan")
    d4 = np.convolve(y, _D4, mode="valid")
    mad = np.median(np.abs(d4 - np.median(d4)))
    return float(1.4826 * mad / _D4_GAIN)


def _xcorr(a: FloatArray, b: FloatArray, lags: int) -> FloatArray:
    """Normalised cross-correlation ρ_ab(k) for k = −lags…lags (FFT)."""
    a = a - a.mean()
    b = b - b.mean()
    n = a.size
    size = 1 << int(np.ceil(np.log2(2 * n)))
    fa = np.fft.rfft(a, size)
    fb = np.fft.rfft(b, size)
    cc = np.fft.irfft(fa * np.conj(fb), size)
    cc = np.concatenate([cc[-lags:], cc[: lags + 1]])
    denom = np.sqrt(np.dot(a, a) * np.dot(b, b))
    return cc / denom if denom > 0 else np.zeros(2 * lags + 1)


@dataclass(frozen=True)
class Whiteness:
    """How white a residual is: autocorrelation beyond the 95 % band, Ljung–Box statistic."""

    lags: int
    outside_fraction: float
    """Share of autocorrelation lags 1…lags outside ±1.96/√N (≈ 0.05 for white noise)."""
    max_abs_rho: float
    ljung_box_q: float
    white: bool

    def as_dict(self) -> dict[str, float | int | bool]:
        """Plain values for JSON."""
        return {"lags": self.lags, "outside_fraction": round(self.outside_fraction, 4),
                "max_abs_rho": round(self.max_abs_rho, 4), "ljung_box_q": round(self.ljung_box_q, 1),
                "white": self.white}


def whiteness(residual: FloatArray, lags: int = 50) -> Whiteness:
    """Autocorrelation test of a residual (white when ≤ 10 % of lags leave the 95 % band)."""
    r = np.asarray(residual, dtype=float)
    n = r.size
    rho = _xcorr(r, r, lags)[lags + 1:]
    band = 1.96 / np.sqrt(n)
    q = float(n * (n + 2) * np.sum(rho**2 / (n - np.arange(1, lags + 1))))
    outside = float(np.mean(np.abs(rho) > band))
    return Whiteness(lags, outside, float(np.max(np.abs(rho))), q, outside <= 0.10)


@dataclass(frozen=True)
class Independence:
    """How far a residual is from being independent of an input: cross-correlation over ±lags."""

    signal: str
    lags: int
    outside_fraction: float
    max_abs_rho: float
    independent: bool

    def as_dict(self) -> dict[str, float | int | bool | str]:
        """Plain values for JSON."""
        return {"signal": self.signal, "lags": self.lags, "outside_fraction": round(self.outside_fraction, 4),
                "max_abs_rho": round(self.max_abs_rho, 4), "independent": self.independent}


def independence(residual: FloatArray, signal: FloatArray, name: str, lags: int = 50) -> Independence:
    """Cross-correlation of a residual with an input (independent when ≤ 10 % leave the 95 % band)."""
    r = np.asarray(residual, dtype=float)
    s = np.asarray(signal, dtype=float)
    if np.ptp(s) == 0.0:
        return Independence(name, lags, 0.0, 0.0, True)
    rho = _xcorr(r, s, lags)
    band = 1.96 / np.sqrt(r.size)
    outside = float(np.mean(np.abs(rho) > band))
    return Independence(name, lags, outside, float(np.max(np.abs(rho))), outside <= 0.10)


def autocovariance(residual: FloatArray, lags: int) -> FloatArray:
    """Biased autocovariance r(k), k = 0…lags (for the coloured-residual parameter covariance)."""
    r = np.asarray(residual, dtype=float) - np.mean(residual)
    n = r.size
    size = 1 << int(np.ceil(np.log2(2 * n)))
    f = np.fft.rfft(r, size)
    return np.fft.irfft(f * np.conj(f), size)[: lags + 1] / n
