"""Frequency response from single-frequency sine dwells (section 3.4), many dwells in one batch run.

The report built the high-fidelity model's frequency response by "applying a time history input of a
single frequency and calculating the gain attenuation and phase shift of the output response", one
frequency at a time. Here every frequency is one instance of a batch model (``n`` = number of
frequencies), so all dwells run in one compiled call: instance ``i`` is trimmed at the bias and load,
driven by ``bias + amp·sin(2π·f_i·t)`` on an input grid, and its gain and phase come from the
single-frequency Fourier coefficient of the output over whole cycles after it has settled, relative
to the same coefficient of the command the model saw.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ema_sim.errors import EmaError
from ema_sim.models import ActuatorModel

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class FrequencyResponse:
    """Gain (dB) and phase (deg) of an output against the command at each dwell frequency."""

    freq_hz: FloatArray
    gain_db: FloatArray
    phase_deg: FloatArray
    amp_deg: float
    output: str

    @property
    def complex(self) -> np.ndarray:
        """The response as complex numbers."""
        return 10.0 ** (self.gain_db / 20.0) * np.exp(1j * np.radians(self.phase_deg))

    def bandwidth_hz(self, level_db: float = -3.0) -> float:
        """The lowest frequency where the gain falls through ``level_db`` (linear in log f); NaN if never."""
        below = np.nonzero(self.gain_db < level_db)[0]
        if below.size == 0 or below[0] == 0:
            return math.nan
        k = below[0]
        f0, f1 = np.log(self.freq_hz[k - 1]), np.log(self.freq_hz[k])
        g0, g1 = self.gain_db[k - 1], self.gain_db[k]
        return float(np.exp(f0 + (level_db - g0) * (f1 - f0) / (g1 - g0)))


def dwell_plan(freq_hz: FloatArray, settle_cycles: float, measure_cycles: int, min_settle_s: float
               ) -> tuple[FloatArray, FloatArray]:
    """Start and end of each dwell's measurement window (whole cycles after the settling time)."""
    start = np.maximum(settle_cycles / freq_hz, min_settle_s)
    start = np.ceil(start * freq_hz) / freq_hz  # begin on a zero crossing of the command
    return start, start + measure_cycles / freq_hz


def sine_dwell(
    model: ActuatorModel,
    freq_hz: ArrayLike,
    amp_deg: float = 1.0,
    *,
    bias_deg: float = 0.0,
    hinge_moment_inlb: float | ArrayLike = 0.0,
    settle_cycles: float = 2.0,
    measure_cycles: int = 4,
    min_settle_s: float = 0.3,
    input_hz: float | None = None,
    output: str = "position_deg",
    before_run: Callable[[ActuatorModel], None] | None = None,
) -> FrequencyResponse:
    """Dwell ``model`` (one instance per frequency) and measure the response of ``output``.

    ``input_hz`` is the grid the sine is held on (default: the model's own rate, or 10 kHz for a
    continuous model), so a discrete model sees a fresh input every step.
    """
    f = np.asarray(freq_hz, dtype=float).ravel()
    if model.n != f.size:
        raise EmaError(f"sine dwell: the model has {model.n} instances for {f.size} frequencies")
    if not (amp_deg > 0.0 and np.all(f > 0.0) and measure_cycles >= 1):
        raise EmaError("sine dwell needs a positive amplitude, positive frequencies and at least one cycle")
    rate = input_hz or (model.rate_hz if not model.continuous else 10_000.0)
    start, stop = dwell_plan(f, settle_cycles, measure_cycles, min_settle_s)
    duration = float(stop.max())
    t = np.arange(math.floor(duration * rate) + 2) / rate
    command = bias_deg + amp_deg * np.sin(2.0 * np.pi * f[:, None] * t[None, :])
    hm = np.broadcast_to(np.asarray(hinge_moment_inlb, dtype=float), (f.size,))
    model.trim(bias_deg, hm)
    if before_run is not None:
        before_run(model)
    record = model.run(t, command, np.repeat(hm[:, None], t.size, axis=1), sample_times=t[:-1], end_s=t[-1])
    y = getattr(record, output)
    u = record.command_deg
    gain = np.empty(f.size)
    phase = np.empty(f.size)
    ts = record.time_s
    for i in range(f.size):
        keep = (ts >= start[i] - 0.5 / rate) & (ts < stop[i] - 0.5 / rate)
        ref = np.exp(-2j * np.pi * f[i] * ts[keep])
        yi = np.sum((y[i, keep] - y[i, keep].mean()) * ref)
        ui = np.sum((u[i, keep] - u[i, keep].mean()) * ref)
        h = yi / ui
        gain[i] = 20.0 * np.log10(abs(h))
        phase[i] = math.degrees(np.angle(h))
    return FrequencyResponse(f, gain, np.degrees(np.unwrap(np.radians(phase))), amp_deg, output)
