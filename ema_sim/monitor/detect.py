"""Sequential detection on normalized residuals: a two-sided CUSUM whose threshold meets a false-alarm rate.

Residuals are averaged over short blocks (20 ms by default: ten 1 kHz samples, four 200 Hz frames), normalized by
the long-run spread the healthy window showed (their autocorrelation accounted for), and fed to Page's CUSUM with
drift ``k`` (half the smallest shift, in spreads, it is tuned for). The threshold ``h`` comes from Siegmund's
approximation of the in-control run length, ARL₀ ≈ (e^{2k(h+1.166)} − 2k(h+1.166) − 1)/(2k²), set to the number of
blocks in an hour over the user's false alarms per hour (halved for two sides).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import brentq

from ema_sim.errors import EmaError
from ema_sim.faults.kinds import FloatArray

SIEGMUND_SHIFT = 1.166
"""The overshoot correction of Siegmund's run-length approximation (for normal increments)."""


def arl0(h: float, k: float) -> float:
    """Siegmund's mean run length of a one-sided CUSUM in control (blocks)."""
    b = h + SIEGMUND_SHIFT
    return (math.exp(2.0 * k * b) - 2.0 * k * b - 1.0) / (2.0 * k * k)


def threshold(false_alarms_per_hour: float, block_s: float, k: float = 0.5) -> float:
    """The CUSUM threshold whose two-sided false-alarm rate is ``false_alarms_per_hour`` at ``block_s`` blocks.

    Parameters
    ----------
    false_alarms_per_hour : float
        The rate the user accepts.
    block_s : float
        The block length (s).
    k : float
        The drift (spreads).

    Returns
    -------
    float
        ``h`` in spreads.
    """
    if not (false_alarms_per_hour > 0.0 and math.isfinite(false_alarms_per_hour)):
        raise EmaError(f"the false-alarm rate must be a positive number per hour, got {false_alarms_per_hour}")
    target = 2.0 * (3600.0 / block_s) / false_alarms_per_hour
    return float(brentq(lambda h: math.log(arl0(h, k)) - math.log(target), 0.0, 300.0 / max(k, 1e-3)))


@dataclass
class Cusum:
    """A two-sided CUSUM on one output's normalized block residuals, stepped one block at a time.

    Parameters
    ----------
    h : float
        The threshold (spreads).
    k : float
        The drift (spreads).
    """

    h: float
    k: float = 0.5
    up: float = 0.0
    down: float = 0.0
    since_up: int = 0
    """Blocks since the upper sum last left zero (the change-point estimate when it alarms)."""
    since_down: int = 0
    history: list[float] = field(default_factory=list)

    @property
    def statistic(self) -> float:
        """The larger of the two sums."""
        return max(self.up, self.down)

    def update(self, z: float) -> bool:
        """Add one normalized block residual; True when the statistic crosses the threshold."""
        self.up = max(0.0, self.up + z - self.k)
        self.down = max(0.0, self.down - z - self.k)
        self.since_up = self.since_up + 1 if self.up > 0.0 else 0
        self.since_down = self.since_down + 1 if self.down > 0.0 else 0
        return self.statistic > self.h

    @property
    def onset_blocks(self) -> int:
        """Blocks back to where the alarming sum last left zero."""
        return self.since_up if self.up >= self.down else self.since_down


def block_means(time_s: FloatArray, residual: FloatArray, block_s: float) -> tuple[FloatArray, FloatArray]:
    """The residual averaged over consecutive ``block_s`` blocks: block end times and means (NaN-free)."""
    idx = np.floor((time_s - time_s[0]) / block_s + 1e-9).astype(np.int64)
    n = int(idx[-1]) + 1
    counts = np.bincount(idx, minlength=n).astype(float)
    sums = np.bincount(idx, weights=residual, minlength=n)
    ok = counts > 0
    ends = (np.arange(n) + 1) * block_s + time_s[0]
    return ends[ok], sums[ok] / counts[ok]


def spread(means: FloatArray, floor: float, lags: int = 50) -> tuple[float, float]:
    """Centre and long-run spread of healthy block means.

    The centre is the median; the spread 1.4826·MAD (at least half the standard deviation and ``floor``),
    times the square root of the long-run variance factor 1 + 2·Σ w_k·ρ_k (Bartlett weights over ``lags``
    blocks): successive block means of a model's residual are not independent, and a CUSUM fed correlated
    increments alarms far more often than its run-length formula says unless they are scaled this way.
    """
    centre = float(np.median(means))
    mad = float(np.median(np.abs(means - centre))) * 1.4826
    std = float(np.std(means))
    sigma = max(mad, 0.5 * std, floor)
    x = means - float(np.mean(means))
    denom = float(x @ x)
    factor = 1.0
    if denom > 0.0 and x.size > 4 * lags:
        rho = np.array([float(x[:-k] @ x[k:]) / denom for k in range(1, lags + 1)])
        weights = 1.0 - np.arange(1, lags + 1) / (lags + 1.0)
        factor = max(1.0, 1.0 + 2.0 * float(weights @ rho))
    return centre, sigma * math.sqrt(factor)
