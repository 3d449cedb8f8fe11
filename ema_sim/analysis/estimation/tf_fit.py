"""Transfer-function fitting to a measured frequency response, with a pure delay: our ``invfreqs``.

Section 3.4 fitted the LOES with MATLAB's ``invfreqs``; scipy has nothing like it, so this is the
classical chain:

1. **Levy** (1959): for a trial delay τ, take the delay out of the data (``H·e^{jωτ}``) and solve the
   linear least-squares problem ``min Σ w·|B(jω) − H·A(jω)|²`` (A monic), which is exact when the
   data are exactly rational but weights the error by ``|A|``.
2. **Sanathanan–Koerner** (1963): repeat Levy with weights ``1/|A_prev(jω)|²`` until the coefficients
   settle, so the fit minimizes the true error ``|B/A − H|`` instead.
3. **Nonlinear least squares** on the complex error of the full model ``B/A·e^{−jωτ}`` against the data,
   numerator, denominator and delay together (scipy's trust-region ``least_squares``), started from
   the best Levy/SK fit over a grid of trial delays.

Frequencies are scaled by the highest one while solving, for conditioning. :func:`loes_cost` is the
mismatch cost of the LOES technique, ``J = (20/n)·Σ[(ΔG dB)² + 0.01745·(Δφ deg)²]``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import least_squares

from ema_sim.errors import EmaError

FloatArray = NDArray[np.float64]
PHASE_WEIGHT = 0.01745
"""Weight of (phase error in degrees)² against (gain error in dB)² in the LOES cost (1 dB ≈ 7.57°)."""


@dataclass(frozen=True)
class TransferFunctionFit:
    """``B(s)/A(s)·e^{−sτ}``; ``num``/``den`` highest power first (``den[0] = 1``), s in rad/s.

    Parameters
    ----------
    num : numpy.ndarray
        Numerator coefficients, highest power first.
    den : numpy.ndarray
        Denominator coefficients, highest power first.
    delay_s : float
        Pure delay, s.
    cost : float
        The LOES mismatch cost J over the fitted points.
    rms_relative_error : float
        RMS of ``|model − data| / |data|`` over the fitted points.
    """

    num: FloatArray
    den: FloatArray
    delay_s: float
    cost: float
    """The LOES mismatch cost J over the fitted points."""
    rms_relative_error: float
    """RMS of ``|model − data| / |data|`` over the fitted points."""

    def response(self, freq_hz: ArrayLike) -> np.ndarray:
        """The fitted model's complex response at ``freq_hz``.

        Parameters
        ----------
        freq_hz : ArrayLike
            Frequency, Hz.

        Returns
        -------
        np.ndarray
            The complex response.
        """
        s = 2j * np.pi * np.asarray(freq_hz, dtype=float)
        return np.polyval(self.num, s) / np.polyval(self.den, s) * np.exp(-s * self.delay_s)


def loes_cost(freq_hz: ArrayLike, model: ArrayLike, data: ArrayLike) -> float:
    """``J = (20/n)·Σ[(ΔG)² + 0.01745·(Δφ)²]``, gains in dB and phases in degrees, over the points given.

    Parameters
    ----------
    freq_hz : ArrayLike
        Frequency, Hz.
    model : ArrayLike
        The model's response.
    data : ArrayLike
        The measured response.

    Returns
    -------
    float
        J.
    """
    f = np.asarray(freq_hz, dtype=float)
    hm = np.asarray(model, dtype=complex)
    hd = np.asarray(data, dtype=complex)
    if not (f.shape == hm.shape == hd.shape) or f.size == 0:
        raise EmaError("loes_cost needs model and data at the same frequencies")
    dg = 20.0 * np.log10(np.abs(hm) / np.abs(hd))
    dphi = np.degrees(np.angle(hm / hd))
    return float(20.0 / f.size * np.sum(dg**2 + PHASE_WEIGHT * dphi**2))


def _levy(w: FloatArray, h: np.ndarray, n_num: int, n_den: int, weight: FloatArray) -> tuple[FloatArray, FloatArray]:
    """One weighted Levy solve on scaled frequencies; returns (num, den) highest power first, den monic."""
    s = 1j * w
    cols = [s**k for k in range(n_num + 1)] + [-h * s**k for k in range(n_den)]
    m = np.stack(cols, axis=1) * np.sqrt(weight)[:, None]
    rhs = h * s**n_den * np.sqrt(weight)
    a = np.vstack([m.real, m.imag])
    b = np.concatenate([rhs.real, rhs.imag])
    x, *_ = np.linalg.lstsq(a, b, rcond=None)
    num = x[: n_num + 1][::-1]
    den = np.concatenate([[1.0], x[n_num + 1 :][::-1]])
    return num, den


def levy_sk(freq_hz: ArrayLike, response: ArrayLike, n_num: int, n_den: int, *, delay_s: float = 0.0,
            weights: ArrayLike | None = None, iterations: int = 20) -> tuple[FloatArray, FloatArray]:
    """Levy's fit refined by Sanathanan–Koerner iterations, for a given delay; (num, den) in rad/s.

    Parameters
    ----------
    freq_hz : ArrayLike
        Frequency, Hz.
    response : ArrayLike
        The measured response.
    n_num : int
        Numerator order.
    n_den : int
        Denominator order.
    delay_s : float
        Pure delay, s.
    weights : ArrayLike or None
        Weight of each point.
    iterations : int
        Sanathanan-Koerner iterations.

    Returns
    -------
    tuple
        Numerator and denominator.
    """
    f = np.asarray(freq_hz, dtype=float)
    h = np.asarray(response, dtype=complex) * np.exp(2j * np.pi * f * delay_s)
    w_user = np.ones_like(f) if weights is None else np.asarray(weights, dtype=float)
    scale = 2.0 * np.pi * f.max()
    w = 2.0 * np.pi * f / scale
    num, den = _levy(w, h, n_num, n_den, w_user)
    for _ in range(iterations):
        weight = w_user / np.abs(np.polyval(den, 1j * w)) ** 2
        new_num, new_den = _levy(w, h, n_num, n_den, weight)
        done = np.allclose(new_den, den, rtol=1e-10, atol=1e-12)
        num, den = new_num, new_den
        if done:
            break
    # Undo the scaling: s_scaled = s/scale, so each coefficient of s^k picks up scale^(n_den − k).
    num = num * scale ** (n_den - np.arange(n_num, -1, -1))
    den = den * scale ** (n_den - np.arange(n_den, -1, -1))
    return num, den


def fit_transfer_function(
    freq_hz: ArrayLike,
    response: ArrayLike,
    n_num: int,
    n_den: int,
    *,
    delay_s: float | None = None,
    max_delay_s: float = 0.05,
    weights: ArrayLike | None = None,
) -> TransferFunctionFit:
    """Fit ``B/A·e^{−sτ}`` (orders ``n_num``/``n_den``) to ``response`` at ``freq_hz``.

    With ``delay_s=None`` the delay is fitted too: Levy/SK over a grid of trial delays up to
    ``max_delay_s`` picks the start, then nonlinear least squares refines everything together.

    Parameters
    ----------
    freq_hz : ArrayLike
        Frequency, Hz.
    response : ArrayLike
        The measured response.
    n_num : int
        Numerator order.
    n_den : int
        Denominator order.
    delay_s : float or None
        Pure delay, s.
    max_delay_s : float
        Largest delay searched, s.
    weights : ArrayLike or None
        Weight of each point.

    Returns
    -------
    TransferFunctionFit
        The fit.
    """
    f = np.asarray(freq_hz, dtype=float).ravel()
    h = np.asarray(response, dtype=complex).ravel()
    if f.shape != h.shape or f.size < n_num + n_den + 2 or np.any(f <= 0.0) or not np.all(np.isfinite(h)):
        raise EmaError("fit_transfer_function needs finite data at enough positive frequencies")
    w_user = np.ones_like(f) if weights is None else np.asarray(weights, dtype=float).ravel()

    def rel_error(num: FloatArray, den: FloatArray, tau: float) -> float:
        s = 2j * np.pi * f
        model = np.polyval(num, s) / np.polyval(den, s) * np.exp(-s * tau)
        return float(np.sum(w_user * np.abs((model - h) / h) ** 2))

    taus = [delay_s] if delay_s is not None else list(np.linspace(0.0, max_delay_s, 101))
    starts = [(rel_error(*levy_sk(f, h, n_num, n_den, delay_s=tau, weights=w_user), tau), tau) for tau in taus]
    _, tau0 = min(starts)
    num0, den0 = levy_sk(f, h, n_num, n_den, delay_s=tau0, weights=w_user)
    # Nonlinear least squares on the relative complex error, coefficients scaled to order one.
    scale = 2.0 * np.pi * f.max()
    num_s = num0 / scale ** (n_den - np.arange(n_num, -1, -1))
    den_s = den0[1:] / scale ** (n_den - np.arange(n_den - 1, -1, -1))
    fit_delay = delay_s is None
    x0 = np.concatenate([num_s, den_s, [tau0 * scale] if fit_delay else []])
    sw = np.sqrt(w_user)
    ws = 2.0 * np.pi * f / scale

    def unpack(x: FloatArray) -> tuple[FloatArray, FloatArray, float]:
        num = x[: n_num + 1]
        den = np.concatenate([[1.0], x[n_num + 1 : n_num + 1 + n_den]])
        tau = x[-1] if fit_delay else tau0 * scale
        return num, den, tau

    def residual(x: FloatArray) -> FloatArray:
        num, den, tau = unpack(x)
        s = 1j * ws
        r = (np.polyval(num, s) / np.polyval(den, s) * np.exp(-s * tau) - h) / h * sw
        return np.concatenate([r.real, r.imag])

    sol = least_squares(residual, x0, method="lm", xtol=1e-14, ftol=1e-14, gtol=1e-14, max_nfev=20_000)
    num, den, tau = unpack(sol.x)
    num = num * scale ** (n_den - np.arange(n_num, -1, -1))
    den = den * scale ** (n_den - np.arange(n_den, -1, -1))
    tau /= scale
    fit = TransferFunctionFit(np.asarray(num, float), np.asarray(den, float), float(tau), 0.0, 0.0)
    model = fit.response(f)
    return TransferFunctionFit(fit.num, fit.den, fit.delay_s, loes_cost(f, model, h),
                               float(np.sqrt(np.mean(np.abs((model - h) / h) ** 2))))


def second_order_coefficients(fit: TransferFunctionFit) -> dict[str, float]:
    """The ωn, ζ, DC gain and delay of a fitted ``b0/(s² + a1·s + a0)·e^{−sτ}``.

    Parameters
    ----------
    fit : TransferFunctionFit
        A second-order fit.

    Returns
    -------
    dict
        The coefficients ωn, ζ, τ and K.
    """
    if fit.den.size != 3 or fit.num.size != 1:
        raise EmaError("second_order_coefficients needs a fit with 0 zeros and 2 poles")
    a1, a0 = fit.den[1], fit.den[2]
    if a0 <= 0.0:
        raise EmaError("the fitted denominator has no oscillatory pair (a0 ≤ 0)")
    wn = float(np.sqrt(a0))
    return {"wn_rad_s": wn, "zeta": float(a1 / (2.0 * wn)), "dc_gain_ratio": float(fit.num[0] / a0),
            "delay_s": fit.delay_s}
