"""Frequency response from single-frequency sine dwells (section 3.4), many dwells in one batch run.

The report built the high-fidelity model's frequency response by "applying a time history input of a
single frequency and calculating the gain attenuation and phase shift of the output response", one
frequency at a time. Here every frequency is one instance of a batch model (``n`` = number of
frequencies), so all dwells run in one compiled call: instance ``i`` is trimmed at the bias and load,
driven by ``bias + amp·sin(2π·f_i·t)`` on an input grid, and its gain and phase come from the
single-frequency Fourier coefficient of the output over whole cycles after it has settled, relative
to the same coefficient of the command the model saw.

The same measurement on a record: :class:`SineDwellTest` reads gain and phase of each output at a
recognised sine dwell's frequency (:func:`read_sine`), over whole cycles after the first.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray
from typing_extensions import override

from ema_sim.analysis.estimation import causal
from ema_sim.analysis.estimation.frf import zoh_factor
from ema_sim.analysis.estimation.quality import Quality
from ema_sim.analysis.estimation.sine_fit import sine_at
from ema_sim.analysis.formatting.markdown import quality, table
from ema_sim.analysis.section2.base import RecordAnalysis, Section2Test
from ema_sim.analysis.section2.segments import SINE_R2, MovingStretch, Reading
from ema_sim.errors import EmaError
from ema_sim.jsontypes import JsonObject

if TYPE_CHECKING:
    from ema_sim.models import ActuatorModel

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class FrequencyResponse:
    """Gain (dB) and phase (deg) of an output against the command at each dwell frequency.

    Parameters
    ----------
    freq_hz : numpy.ndarray
        Frequency, Hz.
    gain_db : numpy.ndarray
        Gain at each frequency, dB.
    phase_deg : numpy.ndarray
        Phase at each frequency, deg.
    amp_deg : float
        Dwell amplitude, deg.
    output : str
        Name of the output.
    """

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
        """The lowest frequency where the gain falls through ``level_db`` (linear in log f); NaN if never.

        Parameters
        ----------
        level_db : float
            Gain level, dB.

        Returns
        -------
        float
            The frequency, Hz (NaN when the gain never falls through the level).
        """
        below = np.nonzero(self.gain_db < level_db)[0]
        if below.size == 0 or below[0] == 0:
            return math.nan
        k = below[0]
        f0, f1 = np.log(self.freq_hz[k - 1]), np.log(self.freq_hz[k])
        g0, g1 = self.gain_db[k - 1], self.gain_db[k]
        return float(np.exp(f0 + (level_db - g0) * (f1 - f0) / (g1 - g0)))


def dwell_plan(freq_hz: FloatArray, settle_cycles: float, measure_cycles: int, min_settle_s: float
               ) -> tuple[FloatArray, FloatArray]:
    """Start and end of each dwell's measurement window (whole cycles after the settling time).

    Parameters
    ----------
    freq_hz : numpy.ndarray
        Frequency, Hz.
    settle_cycles : float
        Cycles left to settle before measuring.
    measure_cycles : int
        Whole cycles measured.
    min_settle_s : float
        Shortest settling time, s.

    Returns
    -------
    tuple
        Start and end of each measurement, s.
    """
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

    Parameters
    ----------
    model : ActuatorModel
        The model, one instance per frequency.
    freq_hz : ArrayLike
        Dwell frequencies, Hz (one per model instance).
    amp_deg : float
        Amplitude, deg.
    bias_deg : float
        Command the sine rides on, deg.
    hinge_moment_inlb : float or ArrayLike
        Hinge moment, in·lb.
    settle_cycles : float
        Cycles left to settle before measuring.
    measure_cycles : int
        Whole cycles measured.
    min_settle_s : float
        Shortest settling time, s.
    input_hz : float or None
        Rate the sine is held at, Hz.
    output : str
        Name of the output.
    before_run : Callable[[ActuatorModel], None] or None
        Called with the model after trim, before the run.

    Returns
    -------
    FrequencyResponse
        Gain and phase at every frequency.
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


# ---------------------------------------------------------------------------------------------- measured dwells
@dataclass(frozen=True)
class DwellResult:
    """Gain and phase of one output at a measured sine dwell's frequency (section-2 ``sine`` segment).

    Parameters
    ----------
    output : str
        Name of the output.
    freq_hz : float
        Frequency, Hz.
    command_amplitude_deg : float
        The command's amplitude, deg.
    gain_db : float
        Gain, dB.
    phase_deg : float
        Phase, deg.
    output_r2 : float
        Share of the output's variance the tone explains.
    start_s : float
        Start of the dwell, s.
    end_s : float
        End of the dwell, s.
    hold_corrected : bool
        Half a sample of hold divided out (a held command); not for a sampled one.
    phase_sigma_deg : float
        The phase's standard error from the two sine fits' residuals, deg.
    """

    output: str
    freq_hz: float
    command_amplitude_deg: float
    gain_db: float
    phase_deg: float
    output_r2: float
    start_s: float
    end_s: float
    hold_corrected: bool
    """Half a sample of hold divided out (a held command); not for a sampled one."""
    phase_sigma_deg: float = 0.0
    """The phase's standard error from the two sine fits' residuals, deg."""

    @property
    def quality(self) -> Quality:
        """``not_determined`` below half the output's variance explained, ``non_causal`` for a leading phase."""
        if self.output_r2 < 0.5:
            return "not_determined"
        return "non_causal" if causal.phase_leads(self.phase_deg, self.phase_sigma_deg) else "ok"

    @property
    def quality_note(self) -> str:
        """Why the quality is what it is."""
        if self.quality == "non_causal":
            return causal.phase_note(self.phase_deg, self.phase_sigma_deg, self.freq_hz)
        return f"output R² {self.output_r2:.2f}"

    def as_dict(self) -> JsonObject:
        """Plain values for JSON.

        Returns
        -------
        dict
            Output, frequency, command amplitude, gain, phase, the output's R², span and quality.
        """
        return {"output": self.output, "freq_hz": self.freq_hz, "command_amplitude_deg": self.command_amplitude_deg,
                "gain_db": self.gain_db, "phase_deg": self.phase_deg, "output_r2": self.output_r2,
                "start_s": self.start_s, "end_s": self.end_s, "hold_corrected": self.hold_corrected,
                "phase_sigma_deg": self.phase_sigma_deg, "quality": self.quality, "quality_note": self.quality_note}


def read_sine(m: MovingStretch) -> Reading | None:
    """A steady tone a sine explains (R² > 0.99): a sine dwell.

    Parameters
    ----------
    m : MovingStretch
        A moving stretch of the command.

    Returns
    -------
    Reading or None
        ``sine`` with its frequency and amplitude, or None.
    """
    if not m.steady or m.sine is None or m.sine.r2 <= SINE_R2:
        return None
    freq = m.sine.freq_hz
    return Reading("sine", f"steady {freq:.4g} Hz sine (sine R² {m.sine.r2:.3f})",
                   {"freq_hz": freq, "amp_deg": float(np.median(m.swings) / 2)})


class SineDwellTest(Section2Test[DwellResult]):
    """Gain and phase of every output at each sine dwell's frequency, over whole cycles after the first."""

    key = "sine_dwell"
    title = "Sine dwell"
    kinds = ("sine",)
    absent = "no sine dwell recognised"

    @override
    def run(self, ra: RecordAnalysis) -> list[DwellResult]:
        data = ra.data
        out: list[DwellResult] = []
        held = not ra.command.assumed_sampled
        for seg in ra.segments(*self.kinds):
            sl = slice(seg.start, seg.stop)
            t, u = data.time_s[sl], data.command_deg[sl]
            f = seg.params.get("freq_hz")
            where = f"sine at {t[0]:.2f}-{t[-1]:.2f} s"
            if not f:
                ra.not_computed[f"{self.key}: {where}"] = "no frequency read from the signal or the metadata"
                continue
            per = 1.0 / f
            keep = (t >= t[0] + per) & (t <= t[0] + per * np.floor((t[-1] - t[0]) / per))
            if keep.sum() < 20:
                ra.not_computed[f"{self.key}: {where}"] = (
                    f"{f:.3g} Hz: fewer than 20 samples in whole cycles after the first (the first cycle is the "
                    "start-up transient)")
                continue
            su = sine_at(t[keep], u[keep], f)
            for name, y in ra.outputs(sl).items():
                sy = sine_at(t[keep], y[keep], f)
                h = (sy.amplitude / su.amplitude) * np.exp(1j * (sy.phase_rad - su.phase_rad))
                if held:
                    h = h / zoh_factor(np.array([f]), data.sample_hz)[0]
                n = int(keep.sum())
                sigma = math.degrees(math.sqrt((max(1.0 - su.r2, 0.0) + max(1.0 - sy.r2, 0.0)) / n))
                out.append(DwellResult(name, f, su.amplitude, float(20 * np.log10(abs(h))),
                                       float(np.degrees(np.angle(h))), sy.r2, float(t[0]), float(t[-1]), held,
                                       sigma))
        return out


    @override
    def markdown(self, ra: RecordAnalysis, results: list[DwellResult],
                 images: list[str | None]) -> list[str]:
        lines = table(["output", "f, Hz", "command amplitude, °", "gain, dB", "phase, °", "quality"],
                      [[s.output, f"{s.freq_hz:g}", f"{s.command_amplitude_deg:.3g}", f"{s.gain_db:+.2f}",
                        f"{s.phase_deg:.1f}", quality(s.quality, s.quality_note)] for s in results])
        if results and not results[0].hold_corrected:
            lines += ["The command is sampled, not held: no hold correction.", ""]
        return lines

    @override
    def summary(self, ra: RecordAnalysis, r: DwellResult) -> list[str]:
        return [f"sine dwell {r.freq_hz:.3g} Hz → {r.output}: gain {r.gain_db:+.2f} dB, phase {r.phase_deg:.1f}°"]


SINE_DWELL = SineDwellTest()
