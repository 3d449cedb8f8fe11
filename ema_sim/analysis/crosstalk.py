"""Crosstalk noise on an observed channel (section 2.2) against its threshold.

Static crosstalk: the observed channel is held while the others move; its feedback should not move.
Dynamic crosstalk: it follows a slow 0.5 Hz triangle while the others move; noise would ride on the
ramp. The noise is what is left after removing what the command explains:

* held command: the output minus its mean and linear trend;
* moving command: the output minus a second order with delay, gain and bias fitted to it on the same
  command (:func:`ema_sim.analysis.second_order_fit.fit_step`), which takes out the tracking and the
  actuator's own transients at the triangle's corners.

Peak-to-peak and RMS of that residual, the RMS in excess of the white sensor noise floor, the same in
volts through the feedback curve's slope, and the verdict against the threshold: the report's right
wing saw 0.02 V (≈ 0.086°) of noise, "below the threshold command level".
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ema_sim.analysis.second_order_fit import fit_step, simulate
from ema_sim.analysis.sine_fit import dominant_frequency

FloatArray = NDArray[np.float64]

@dataclass(frozen=True)
class CrosstalkResult:
    """Noise on the observed channel and how it compares with the threshold."""

    output: str
    kind: str
    peak_to_peak_deg: float
    rms_deg: float
    excess_rms_deg: float
    sensor_noise_deg: float
    dominant_hz: float | None
    volts_per_deg: float
    threshold_deg: float
    threshold_source: str
    residual: FloatArray
    notes: list[str] = field(default_factory=list)

    @property
    def below_threshold(self) -> bool:
        """Peak-to-peak noise below the threshold amplitude."""
        return self.peak_to_peak_deg < self.threshold_deg

    def as_dict(self) -> dict[str, Any]:
        """Plain values for JSON."""
        v = self.volts_per_deg
        return {
            "output": self.output, "test": self.kind, "peak_to_peak_deg": self.peak_to_peak_deg,
            "peak_to_peak_v": self.peak_to_peak_deg * v, "rms_deg": self.rms_deg, "rms_v": self.rms_deg * v,
            "excess_rms_over_sensor_noise_deg": self.excess_rms_deg, "sensor_noise_deg": self.sensor_noise_deg,
            "dominant_hz": self.dominant_hz, "threshold_deg": self.threshold_deg,
            "threshold_source": self.threshold_source, "below_threshold": self.below_threshold, "notes": self.notes,
        }


def _tracking_residual(t: FloatArray, u: FloatArray, y: FloatArray) -> tuple[FloatArray, str]:
    """``y`` less a second order with delay fitted to it on the same command (time domain)."""
    fit = fit_step(t, u, y, test="tracking", output_name="", wn0=50.0, zeta0=0.7, delay0=0.005)
    dt = float(np.median(np.diff(t)))
    model = fit.gain.value * simulate(u, dt, fit.wn_rad_s.value, fit.zeta.value, fit.delay_s.value)
    model += fit.bias_deg.value if fit.bias_deg else 0.0
    how = (f"tracking removed by a fitted second order (ωn {fit.wn_rad_s.value:.1f} rad/s, ζ {fit.zeta.value:.2f}, "
           f"delay {1e3 * fit.delay_s.value:.1f} ms)")
    return y - model, how


def crosstalk_noise(t: FloatArray, u: FloatArray, y: FloatArray, sensor_noise: float, *, output: str,
                    threshold_deg: float, threshold_source: str, volts_per_deg: float) -> CrosstalkResult:
    """Residual noise of the observed channel (see the module docstring)."""
    notes: list[str] = []
    held = np.ptp(u) <= 1e-9 * max(1.0, float(np.max(np.abs(u))))
    if held:
        coef = np.polyfit(t - t[0], y, 1)
        resid = y - np.polyval(coef, t - t[0])
        kind = "static (command held)"
    else:
        resid, how = _tracking_residual(t, u, y)
        kind = "dynamic (command moving)"
        notes.append(how)
    rms = float(np.sqrt(np.mean(resid**2)))
    excess = float(np.sqrt(max(rms * rms - sensor_noise * sensor_noise, 0.0)))
    dom = dominant_frequency(t, resid, f_min=0.2)
    return CrosstalkResult(output, kind, float(np.ptp(resid)), rms, excess, sensor_noise, dom, volts_per_deg,
                           threshold_deg, threshold_source, resid, notes)
