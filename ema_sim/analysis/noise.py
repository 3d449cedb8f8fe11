"""Measurement noise and residual tests: the noise floor of a record, whiteness, independence from the input.

Used by the offline analysis (`ema analyze`) to set detection thresholds and by model identification
(`ema identify`) to judge its residuals:

* :func:`noise_floor` estimates the white sensor noise of a signal without a model, from fourth
  differences: at a sample rate well above the signal's bandwidth, ``Δ⁴y`` keeps only (ωT)⁴ of
  the signal (an 18 Hz sweep at 1 kHz leaves 1.6e-4 of it, where a second difference would leave
  1.3e-2, comparable to the noise) and multiplies the noise variance by 70. The median absolute
  deviation makes the estimate ignore the few samples at steps and edges.
* :func:`whiteness` is the Ljung-Box portmanteau test on the residual's autocorrelation.
* :func:`input_independence` tests the residual's cross-correlation with the input (a model that
  explains everything leaves a residual uncorrelated with the input at every lag); the band holds
  all 2L + 1 lags at once with 99 % probability (Bonferroni).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

MAD_TO_SIGMA = 1.4826
"""Median absolute deviation of Gaussian noise times this is its standard deviation."""


def noise_floor(y: FloatArray) -> float:
    """Standard deviation of the white noise on ``y``, from the MAD of its fourth differences."""
    y = np.asarray(y, dtype=float)
    if y.size < 6:
        return 0.0
    d4 = np.diff(y, 4)
    return float(MAD_TO_SIGMA * np.median(np.abs(d4 - np.median(d4))) / np.sqrt(70.0))


def autocovariance(x: FloatArray, max_lag: int) -> FloatArray:
    """Biased autocovariance r(k), k = 0…max_lag, by FFT (for coloured-residual covariances)."""
    x = np.asarray(x, dtype=float) - np.mean(x)
    n = x.size
    max_lag = min(int(max_lag), n - 1)
    nfft = 1 << int(np.ceil(np.log2(2 * n - 1)))
    f = np.fft.rfft(x, nfft)
    return np.fft.irfft(f * np.conj(f), nfft)[: max_lag + 1] / n


def autocorrelation(x: FloatArray, max_lag: int | None = None) -> FloatArray:
    """Normalised autocorrelation ρ(k), k = 0…max_lag, biased estimator (ρ(0) = 1), by FFT."""
    x = np.asarray(x, dtype=float) - np.mean(x)
    n = x.size
    max_lag = n - 1 if max_lag is None else min(int(max_lag), n - 1)
    nfft = 1 << int(np.ceil(np.log2(2 * n - 1)))
    f = np.fft.rfft(x, nfft)
    acov = np.fft.irfft(f * np.conj(f), nfft)[: max_lag + 1] / n
    return acov / acov[0] if acov[0] > 0 else np.zeros(max_lag + 1)


def cross_correlation(x: FloatArray, y: FloatArray, max_lag: int) -> tuple[NDArray[np.int64], FloatArray]:
    """Normalised cross-correlation r_xy(k) = E[x(t)·y(t+k)], k = −max_lag…max_lag, by FFT."""
    x = np.asarray(x, dtype=float) - np.mean(x)
    y = np.asarray(y, dtype=float) - np.mean(y)
    n = x.size
    max_lag = min(int(max_lag), n - 1)
    nfft = 1 << int(np.ceil(np.log2(2 * n - 1)))
    c = np.fft.irfft(np.conj(np.fft.rfft(x, nfft)) * np.fft.rfft(y, nfft), nfft)
    norm = np.sqrt(np.sum(x * x) * np.sum(y * y))
    lags = np.arange(-max_lag, max_lag + 1)
    vals = np.concatenate([c[nfft - max_lag:], c[: max_lag + 1]])
    return lags, (vals / norm if norm > 0 else np.zeros_like(vals))


@dataclass(frozen=True)
class WhitenessTest:
    """Ljung-Box test of a residual for whiteness."""

    lags: int
    q_statistic: float
    p_value: float
    fraction_outside: float
    """Share of the lags 1…``lags`` whose |ρ| exceeds the 95 % band 1.96/√N."""
    white: bool
    """True when the test does not reject whiteness at the 5 % level."""

    def as_dict(self) -> dict[str, float | int | bool]:
        """Plain values for JSON."""
        return {"lags": self.lags, "q_statistic": self.q_statistic, "p_value": self.p_value,
                "fraction_outside_95": self.fraction_outside, "white": self.white}


def whiteness(residual: FloatArray, lags: int = 20, fitted_params: int = 0) -> WhitenessTest:
    """Ljung-Box Q = N(N+2)·Σ ρ(k)²/(N−k) over ``lags`` lags, χ² with ``lags − fitted_params`` dof."""
    from scipy.stats import chi2  # noqa: PLC0415

    r = np.asarray(residual, dtype=float)
    n = r.size
    lags = max(1, min(int(lags), n // 4))
    rho = autocorrelation(r, lags)[1:]
    k = np.arange(1, lags + 1)
    q = float(n * (n + 2) * np.sum(rho * rho / (n - k)))
    dof = max(1, lags - int(fitted_params))
    p = float(chi2.sf(q, dof))
    outside = float(np.mean(np.abs(rho) > 1.96 / np.sqrt(n)))
    return WhitenessTest(lags, q, p, outside, p >= 0.05)


@dataclass(frozen=True)
class IndependenceTest:
    """Whether a residual is uncorrelated with the input at every lag up to ``max_lag``."""

    max_lag: int
    peak_correlation: float
    peak_lag: int
    bound: float
    """The band uncorrelated sequences stay inside at every lag with 99 % probability (Bonferroni over the lags)."""
    independent: bool

    def as_dict(self) -> dict[str, float | int | bool]:
        """Plain values for JSON."""
        return {"max_lag": self.max_lag, "peak_correlation": self.peak_correlation, "peak_lag": self.peak_lag,
                "bound_99_all_lags": self.bound, "independent": self.independent}


def input_independence(residual: FloatArray, u: FloatArray, max_lag: int = 50) -> IndependenceTest:
    """Cross-correlation of the input ``u`` (prewhitened by differencing) with the residual.

    Differencing the input removes its own strong low-frequency autocorrelation, which would widen
    the band of a raw cross-correlation far beyond 2.58/√N.
    """
    from scipy.stats import norm  # noqa: PLC0415

    du = np.diff(np.asarray(u, dtype=float))
    r = np.asarray(residual, dtype=float)[1:]
    n = r.size
    bound = float(norm.isf(0.005 / (2 * max_lag + 1))) / np.sqrt(max(n, 1))
    if np.allclose(du, 0.0):
        return IndependenceTest(max_lag, 0.0, 0, bound, True)
    lags, c = cross_correlation(du, r, max_lag)
    i = int(np.argmax(np.abs(c)))
    return IndependenceTest(int(max_lag), float(c[i]), int(lags[i]), float(bound), bool(abs(c[i]) <= bound))
