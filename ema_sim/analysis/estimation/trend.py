"""Whether a figure measured on successive parts of a record changes over it, and how: steady, falls, grows, wanders.

One figure fitted to a whole record is an average. Measured on parts of it (windows of the record, cycles of
a repeating command), each with its own uncertainty, the values say whether the actuator changed while it
was recorded:

* it **changes** when the values disagree beyond their uncertainty (χ² of the values about their weighted
  mean with p below :data:`CHANGE_P`) by at least :data:`MIN_CHANGE` of its value (a model's mismatch with
  a plant moves a fitted value by a few per cent between parts that excite it alike);
* its **trend** is the weighted straight line through the values: it *falls* or *grows* when the line's
  slope is :data:`TREND_SIGMA` of its uncertainty and the line explains at least :data:`LINEAR_SHARE` of
  the values' spread about their mean; otherwise it *wanders*.

``ema analyze`` (the cycles of a periodic test) and ``ema identify`` (the final model refitted on windows)
both decide with :func:`trend`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray
from scipy.stats import chi2 as chi2_dist

FloatArray = NDArray[np.float64]
TrendKind = Literal["steady", "falls", "grows", "wanders", "not determined"]
CHANGE_P = 1e-3
"""p-value below which the parts disagree beyond their uncertainty."""
MIN_CHANGE = 0.05
"""Smallest range over the parts, as a share of the mean, that counts as a change."""
TREND_SIGMA = 3.0
"""Standard errors the slope needs for a straight trend."""
LINEAR_SHARE = 0.8
"""Share of the spread about the mean the straight line must explain for a trend (else: wanders)."""


@dataclass(frozen=True)
class Trend:
    """A figure over the parts of a record and what its values say."""

    values: tuple[float, ...]
    sigma: tuple[float, ...]
    times_s: tuple[float, ...]
    """Each part's middle, s from the record's start."""
    chi2: float
    dof: int
    p_value: float
    slope_per_s: float
    slope_sigma: float
    kind: TrendKind

    @property
    def changed(self) -> bool:
        """The figure changes over the record beyond its uncertainty."""
        return self.kind in ("falls", "grows", "wanders")


def trend(values: FloatArray, sigma: FloatArray, times_s: FloatArray, usable: NDArray[np.bool_] | None = None
          ) -> Trend:
    """Classify a figure measured on parts of a record (module docstring).

    Parameters
    ----------
    values : numpy.ndarray
        The figure on each part.
    sigma : numpy.ndarray
        Its standard error on each part (non-finite or 0: not usable).
    times_s : numpy.ndarray
        Each part's middle, s.
    usable : numpy.ndarray of bool, optional
        Parts to decide on (a value on its search's bound is no measurement); all by default.

    Returns
    -------
    Trend
        The values as given, the test's statistics on the usable parts, and the kind; ``not determined``
        with fewer than two usable parts.
    """
    v_all, s_all, x_all = (np.asarray(a, dtype=float) for a in (values, sigma, times_s))
    ok = np.isfinite(v_all) & np.isfinite(s_all) & (s_all > 0.0)
    if usable is not None:
        ok &= np.asarray(usable, dtype=bool)
    base = (tuple(v_all.tolist()), tuple(s_all.tolist()), tuple(x_all.tolist()))
    if ok.sum() < 2:
        return Trend(*base, math.nan, 0, math.nan, math.nan, math.nan, "not determined")
    v, s, x = v_all[ok], s_all[ok], x_all[ok]
    w = 1.0 / s**2
    mean = float(np.sum(w * v) / np.sum(w))
    chi2 = float(np.sum(w * (v - mean) ** 2))
    dof = int(v.size - 1)
    p = float(chi2_dist.sf(chi2, dof))
    xm = float(np.sum(w * x) / np.sum(w))
    sxx = float(np.sum(w * (x - xm) ** 2))
    slope = float(np.sum(w * (x - xm) * (v - mean)) / sxx) if sxx > 0 else 0.0
    line = mean + slope * (x - xm)
    chi2_line = float(np.sum(w * (v - line) ** 2))
    inflate = max(1.0, chi2_line / max(v.size - 2, 1))
    slope_sigma = math.sqrt(inflate / sxx) if sxx > 0 else math.inf
    relative = float(np.ptp(v)) / max(abs(mean), 1e-300)
    kind: TrendKind
    if p >= CHANGE_P or relative < MIN_CHANGE:
        kind = "steady"
    elif abs(slope) >= TREND_SIGMA * slope_sigma and (chi2 - chi2_line) >= LINEAR_SHARE * chi2:
        kind = "falls" if slope < 0 else "grows"
    else:
        kind = "wanders"
    return Trend(*base, chi2, dof, p, slope, slope_sigma, kind)
