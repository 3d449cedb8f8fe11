"""Parameter uncertainty of a least-squares fit whose residuals are coloured (Morelli & Klein).

The textbook covariance ``σ²(JᵀJ)⁻¹`` assumes white residuals. Residuals of an actuator fit never
are: sensor noise is filtered, quantization and the small nonlinearities the model leaves out are
correlated over many samples, and the white-noise formula then understates the error by a factor of
several. Morelli & Klein (J. Aircraft 34(3), 1997; *Aircraft System Identification*, 2006, §6.5)
replace the middle of the sandwich with the residual's own autocovariance:

    Cov(θ) = (JᵀJ)⁻¹ · [Σᵢ Σⱼ Jᵢ R(i−j) Jⱼᵀ] · (JᵀJ)⁻¹,   R(k) = (1/N) Σ v(t)·v(t+k)

over all lags. With the biased autocovariance the middle term is ``Jᵀ·T·J`` for a positive
semi-definite Toeplitz ``T``, so the result is always a valid covariance. It is evaluated here in the
frequency domain (zero-padded FFTs), ``Jᵀ T J = (1/(N·M)) Σ_f |V(f)|² Re(J(f)ᴴ J(f))``, in
O(p·N log N) rather than O(N²).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class Covariance:
    """Parameter covariances of one fit: corrected for coloured residuals, and the white-noise one.

    Parameters
    ----------
    coloured : numpy.ndarray
        Covariance corrected for coloured residuals.
    white : numpy.ndarray
        Covariance under white residuals.
    """

    coloured: FloatArray
    white: FloatArray

    @property
    def sigma(self) -> FloatArray:
        """Standard deviations corrected for coloured residuals."""
        return np.sqrt(np.clip(np.diag(self.coloured), 0.0, None))

    @property
    def sigma_white(self) -> FloatArray:
        """Standard deviations under the white-residual assumption."""
        return np.sqrt(np.clip(np.diag(self.white), 0.0, None))


def _middle(jac: FloatArray, residual: FloatArray) -> FloatArray:
    """``Jᵀ T J`` with ``T`` the Toeplitz matrix of the biased residual autocovariance."""
    n = residual.size
    nfft = 1 << int(np.ceil(np.log2(2 * n - 1)))
    v = np.fft.rfft(residual, nfft)
    jf = np.fft.rfft(jac, nfft, axis=0)
    w = (np.abs(v) ** 2)[:, None]
    # One-sided spectrum: every bin but DC and Nyquist stands for two.
    weight = np.full(jf.shape[0], 2.0)
    weight[0] = 1.0
    if nfft % 2 == 0:
        weight[-1] = 1.0
    m = (np.conj(jf) * (w * weight[:, None])).T @ jf
    return np.asarray(np.real(m) / (n * nfft), dtype=float)


def coloured_covariance(jac: FloatArray, residual: FloatArray | Sequence[FloatArray],
                        blocks: Sequence[slice] | None = None) -> Covariance:
    """Covariance of least-squares estimates from the Jacobian of the model output and the residual.

    ``jac`` is ``(N, p)``: ∂(model output)/∂θ at the estimate, one row per residual. When the
    residual vector stacks several independent sequences (gain and phase of a frequency response, say),
    give their ``blocks``; the autocovariance is then taken within each block and cross-block
    correlation is assumed zero.

    Parameters
    ----------
    jac : numpy.ndarray
        ∂(model output)/∂θ at the estimate, one row per residual.
    residual : numpy.ndarray or Sequence[numpy.ndarray]
        The residual.
    blocks : Sequence[slice] or None
        Independent blocks of the residual (each its own autocovariance).

    Returns
    -------
    Covariance
        Both covariances.
    """
    jac = np.asarray(jac, dtype=float)
    r = np.asarray(residual, dtype=float).ravel()
    n, p = jac.shape
    if r.size != n:
        raise ValueError(f"residual has {r.size} rows, Jacobian {n}")
    info = jac.T @ jac
    inv = np.linalg.pinv(info)
    dof = max(n - p, 1)
    white = inv * float(r @ r) / dof
    blocks = list(blocks) if blocks else [slice(0, n)]
    middle = np.zeros((p, p))
    for b in blocks:
        rb = r[b]
        if rb.size:
            middle += _middle(jac[b], rb)
    middle *= n / dof  # same small-sample correction as the white-noise estimate
    coloured = inv @ middle @ inv
    return Covariance(coloured=0.5 * (coloured + coloured.T), white=white)
