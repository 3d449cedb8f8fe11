"""Voltage regeneration (section 2.5): the 150 V bus peak against the 185 V allowed.

Decelerating the motor's inertia (or an aiding load) makes the motor a generator that raises the
bus; the report watched an oscilloscope on the bus during a 5 % FS square sweep 0.1-5 Hz for spikes
above the manufacturer's 185 Vdc. Here, from a ``bus_v`` column: the nominal bus (median), the peak,
its time, the rise above nominal, and the margin to the limit.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

BUS_LIMIT_V = 185.0
"""The manufacturer's allowable bus voltage (section 2.5)."""


@dataclass(frozen=True)
class RegenerationResult:
    """Bus-voltage peak of a record."""

    nominal_v: float
    peak_v: float
    peak_time_s: float
    limit_v: float

    @property
    def rise_v(self) -> float:
        """Peak above nominal."""
        return self.peak_v - self.nominal_v

    @property
    def margin_v(self) -> float:
        """Limit minus peak (negative: over the limit)."""
        return self.limit_v - self.peak_v

    def as_dict(self) -> dict[str, Any]:
        """Plain values for JSON."""
        return {"nominal_v": self.nominal_v, "peak_v": self.peak_v, "peak_time_s": self.peak_time_s,
                "rise_v": self.rise_v, "limit_v": self.limit_v, "margin_v": self.margin_v,
                "within_limit": self.peak_v <= self.limit_v}


def bus_peak(t: FloatArray, bus_v: FloatArray, limit_v: float = BUS_LIMIT_V) -> RegenerationResult:
    """Nominal, peak and margin of the bus voltage."""
    i = int(np.argmax(bus_v))
    return RegenerationResult(float(np.median(bus_v)), float(bus_v[i]), float(t[i]), limit_v)
