"""Frequency response H = Gxy/Gxx of the actuator from sweeps and Schroeder sweeps, and its figures.

Two estimators:

* :func:`from_sweep`: composite-window H1 (:func:`ema_sim.analysis.estimation.spectra.composite`) on a log grid,
  with coherence and normalised random error; for sine sweeps and any broadband record. Command and
  outputs first go through the same anti-alias filter and are decimated to ≈ 6× the top frequency.
* :func:`from_periodic`: a periodic input (a Schroeder sweep) analysed over whole periods with a
  rectangular window, so the DFT at each harmonic (chirp-z) has no leakage; H averages the periods,
  coherence comes from the period-to-period scatter (≥ 2 periods) or from the output's noise floor
  against the harmonic's power (1 period).

The command of the contract is zero-order held between samples, so a DAU sampling command and output
at the same instants sees the response to the held staircase; both estimators divide out that hold
(``sinc(f/fs)·e^(−jπf/fs)``, half a sample of delay) so H is the actuator's own.

A command sampled from a running demand rather than held (:mod:`ema_sim.analysis.records.command_hold`)
is already the actuator's input at the sample instants: no hold is divided out then.

Figures: gain and phase at chosen frequencies, the −3 dB bandwidth, and where the coherence drops. A
figure read where the coherence is under :data:`COHERENCE_GOOD` is ``not_determined``, never ``ok``
(:func:`coherent_where_read`). A periodic command of a few harmonics (a square or trapezoid wave) is
no sweep: :mod:`ema_sim.analysis.section2.cycles` reads it at its own harmonics.

Before a bandwidth is reported, the sweep's command is checked against the actuator's slew
(:func:`check_slew`): along the sweep the output's rate rises to a ceiling, and when the cycles on
that ceiling carry the odd harmonics of a clipped rate, it is the rate limit (a linear actuator
answers a sine with a sine), and the ceiling is the record's measured slew (else one measured on
rate-limited steps of the same record). A −3 dB point at which the linear
output would need 90 % of that slew or more is rate saturation, not the small-signal bandwidth
(quality ``saturated``), and the second-order fit stops below the first saturated cycle.

:class:`FrequencyTest` runs on sweeps, Schroeder sweeps and broadband commands, recognised by
:func:`read_sweep`, :func:`read_schroeder` and :func:`read_broadband`. One test of section 2 in one module
of about 720 lines, as its siblings are: its readers, its slew check and its report section belong together.
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import pairwise
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray
from typing_extensions import override

from ema_sim.analysis.estimation import causal
from ema_sim.analysis.estimation.frf import (
    COHERENCE_GOOD,
    FrequencyResponse,
    at_frequencies,
    bandwidth_3db,
    coherence_statement,
    excitation_band,
    from_periodic,
    from_sweep,
    interp_log,
    low_frequency_gain_db,
    phase_crossing_hz,
)
from ema_sim.analysis.estimation.noise import autocorrelation
from ema_sim.analysis.estimation.quality import Quality, worst
from ema_sim.analysis.estimation.second_order_fit import SecondOrderFit, fit_frequency_response, response
from ema_sim.analysis.formatting import figure
from ema_sim.analysis.formatting.markdown import image, num, pm, quality, table
from ema_sim.analysis.section2.base import RecordAnalysis, Section2Test
from ema_sim.analysis.section2.segments import MovingStretch, Reading, Segment
from ema_sim.analysis.section2.steps import TEST as STEPS
from ema_sim.analysis.section2.steps import slew_rates
from ema_sim.jsontypes import JsonObject
from ema_sim.models import create

FloatArray = NDArray[np.float64]
ComplexArray = NDArray[np.complex128]

# ---------------------------------------------------------------------------------------------- slew check
HARMONIC_EXCESS = 0.005
"""Third harmonic over fundamental (output's, less the command's) that marks a clipped rate (a full triangle
has 0.11; a sine whose rate is clipped by a tenth at its peaks about 0.01)."""
SLEW_SHARE = 0.9
"""A −3 dB point where the linear output would need this share of the slew is rate saturation."""
CEILING = 0.9
"""Cycles whose output rate reaches this share of the sweep's highest are on the rate ceiling."""


@dataclass(frozen=True)
class SlewCheck:
    """A sweep's command against the actuator's slew rate.

    Parameters
    ----------
    command_amplitude_deg : float
        The command's amplitude (median over its cycles), deg.
    command_peak_rate_dps : float
        The command's peak rate, deg/s.
    output_rate_ceiling_dps : float or None
        The highest peak rate of the output's fundamental over the sweep's cycles.
    measured_slew_dps : float or None
        The slew the record measured, deg/s.
    slew_source : str
        Where it comes from.
    saturated_from_hz : float or None
        Where the output's rate reaches its ceiling, when the cycles from there on are clipped.
    third_harmonic_excess : float or None
        Mean output-minus-command third harmonic (over fundamental) on the ceiling.
    """

    command_amplitude_deg: float
    command_peak_rate_dps: float
    output_rate_ceiling_dps: float | None
    """The highest peak rate of the output's fundamental over the sweep's cycles."""
    measured_slew_dps: float | None
    slew_source: str
    saturated_from_hz: float | None
    """Where the output's rate reaches its ceiling, when the cycles from there on are clipped."""
    third_harmonic_excess: float | None
    """Mean output-minus-command third harmonic (over fundamental) on the ceiling."""

    def as_dict(self) -> JsonObject:
        """Plain values for JSON.

        Returns
        -------
        dict
            The command's amplitude and peak rate, the output's rate ceiling, the measured slew and
            where it comes from, where saturation starts, and the harmonic evidence.
        """
        return {"command_amplitude_deg": self.command_amplitude_deg,
                "command_peak_rate_dps": self.command_peak_rate_dps,
                "output_rate_ceiling_dps": self.output_rate_ceiling_dps, "measured_slew_dps": self.measured_slew_dps,
                "slew_source": self.slew_source, "rate_saturation_from_hz": self.saturated_from_hz,
                "third_harmonic_excess": self.third_harmonic_excess}


@dataclass(frozen=True)
class Cycle:
    """One command cycle of a sweep: the fundamental and third harmonic of command and output.

    Parameters
    ----------
    freq_hz : float
        Frequency, Hz.
    u1 : complex
        Command's fundamental (complex amplitude).
    y1 : complex
        Output's fundamental.
    h3_u : float
        Command's third harmonic over its fundamental.
    h3_y : float
        Output's third harmonic over its fundamental.
    amplitude_deg : float
        Amplitude, deg.
    """

    freq_hz: float
    u1: complex
    y1: complex
    h3_u: float
    h3_y: float
    amplitude_deg: float

    @property
    def command_rate_dps(self) -> float:
        """Peak rate of the command's fundamental."""
        return 2.0 * np.pi * self.freq_hz * abs(self.u1)

    @property
    def output_rate_dps(self) -> float:
        """Peak rate of the output's fundamental."""
        return 2.0 * np.pi * self.freq_hz * abs(self.y1)


def sweep_cycles(t: FloatArray, u: FloatArray, y: FloatArray) -> list[Cycle]:
    """The command's cycles (between upward crossings of its median), each fitted with a fundamental and a third.

    Parameters
    ----------
    t : numpy.ndarray
        Time, s (uniform).
    u : numpy.ndarray
        The command.
    y : numpy.ndarray
        The output.

    Returns
    -------
    list of Cycle
        Cycles of at least 8 samples, in time order.
    """
    centre = float(np.median(u))
    up = np.flatnonzero((u[:-1] < centre) & (u[1:] >= centre)) + 1
    out = []
    for a, b in pairwise(up):
        if b - a < 8:
            continue
        tt = t[a:b]
        f = 1.0 / float(t[b] - t[a])
        w = 2.0 * np.pi * f * (tt - tt[0])
        x = np.column_stack([np.cos(w), np.sin(w), np.cos(3 * w), np.sin(3 * w), np.ones_like(w)])
        coef, *_ = np.linalg.lstsq(x, np.column_stack([u[a:b], y[a:b]]), rcond=None)
        cu, cy = coef[:, 0], coef[:, 1]
        u1, y1 = complex(cu[0], -cu[1]), complex(cy[0], -cy[1])
        if abs(u1) == 0.0 or abs(y1) == 0.0:
            continue
        out.append(Cycle(f, u1, y1, float(np.hypot(cu[2], cu[3])) / abs(u1), float(np.hypot(cy[2], cy[3])) / abs(y1),
                         0.5 * float(np.ptp(u[a:b]))))
    return out


def check_slew(t: FloatArray, u: FloatArray, y: FloatArray, known_slew: tuple[float, str] | None = None,
               cycles: list[Cycle] | None = None) -> SlewCheck:
    """The command's amplitude and rate against the actuator's slew (see the module docstring).

    A linear actuator answers a sine with a sine; a rate limit clips the output's rate and adds odd
    harmonics (a full triangle's third is a ninth of its fundamental). Along the sweep the output's
    fundamental peak rate ``2πf|Y₁|`` rises to a ceiling; from the first cycle that reaches 90 % of
    it, the output's third harmonic (over its fundamental, less the command's own) is averaged over
    the cycles: a mean of at least 0.005 and three standard errors says the ceiling is the rate limit.

    Parameters
    ----------
    t : numpy.ndarray
        Time, s (uniform).
    u : numpy.ndarray
        The sweep's command.
    y : numpy.ndarray
        The output.
    known_slew : tuple, optional
        A slew rate measured elsewhere in the record (°/s) and where.
    cycles : list of Cycle, optional
        The sweep's cycles when already computed (:func:`sweep_cycles`).

    Returns
    -------
    SlewCheck
        The check.
    """
    cycles = sweep_cycles(t, u, y) if cycles is None else cycles
    du = np.gradient(u, t)
    peak_rate = float(np.max(np.abs(du))) if du.size else 0.0
    amp = float(np.median([c.amplitude_deg for c in cycles])) if cycles else 0.5 * float(np.ptp(u))
    slew, source = (known_slew if known_slew is not None else (None, "none measured"))
    if len(cycles) < 3:
        return SlewCheck(amp, peak_rate, None, slew, source, None, None)
    rates = np.array([c.output_rate_dps for c in cycles])
    smooth = np.array([float(np.median(rates[max(0, k - 1):k + 2])) for k in range(rates.size)])
    ceiling = float(np.max(smooth))
    first = int(np.argmax(smooth >= CEILING * ceiling))
    on = cycles[first:]
    excess = np.array([c.h3_y - c.h3_u for c in on])
    mean = float(np.mean(excess))
    se = float(np.std(excess, ddof=1) / np.sqrt(excess.size)) if excess.size > 1 else np.inf
    clipped = excess.size >= 2 and mean >= max(HARMONIC_EXCESS, 3.0 * se) \
        and on[-1].command_rate_dps > on[0].command_rate_dps
    sat_from = cycles[first].freq_hz if clipped else None
    if clipped and known_slew is None:
        slew, source = ceiling, "the output's rate ceiling in this sweep (fundamental's peak rate)"
    return SlewCheck(amp, peak_rate, ceiling, slew, source, sat_from, mean)


def coherent_where_read(fr: FrequencyResponse, bw_hz: float | None, q: Quality, note: str) -> tuple[Quality, str]:
    """A bandwidth read where the coherence is under :data:`COHERENCE_GOOD` is not determined.

    The −3 dB point is searched among the points of coherence :data:`COHERENCE_FIT` or more; where it
    lands the coherence must still reach :data:`COHERENCE_GOOD` for the figure to be ``ok``.

    Parameters
    ----------
    fr : FrequencyResponse
        The measured response.
    bw_hz : float or None
        The −3 dB frequency.
    q : Quality
        Its quality so far.
    note : str
        Why.

    Returns
    -------
    tuple
        The quality and its note, ``not_determined`` when the coherence at the bandwidth is too low.
    """
    if bw_hz is None or fr.freq_hz.size == 0:
        return q, note
    coh = interp_log(fr.freq_hz, fr.coherence, bw_hz)
    if coh >= COHERENCE_GOOD:
        return q, note
    why = f"the coherence at {bw_hz:.3g} Hz is {coh:.2f} (< {COHERENCE_GOOD}): the gain there is not measured"
    return worst(q, "not_determined"), (f"{note}; {why}" if note else why)


def bandwidth_quality(bw_hz: float | None, check: SlewCheck, cycles: list[Cycle]) -> tuple[Quality, str]:
    """Whether a −3 dB point is the small-signal bandwidth or rate saturation.

    Parameters
    ----------
    bw_hz : float or None
        The −3 dB frequency.
    check : SlewCheck
        The sweep's slew check.
    cycles : list of Cycle
        The sweep's cycles, for the command's rate at ``bw_hz``.

    Returns
    -------
    tuple
        ``saturated`` and why, or ``ok``.
    """
    if bw_hz is None or check.measured_slew_dps is None:
        return "ok", ""
    f = np.array([c.freq_hz for c in cycles])
    rate = np.array([c.command_rate_dps for c in cycles])
    order = np.argsort(f)
    rc = float(np.interp(bw_hz, f[order], rate[order])) if f.size else 2 * np.pi * bw_hz * check.command_amplitude_deg
    need = rc / np.sqrt(2.0)
    s = check.measured_slew_dps
    if need >= SLEW_SHARE * s or (check.saturated_from_hz is not None and bw_hz >= check.saturated_from_hz):
        small = 0.5 * s / (2 * np.pi * bw_hz / np.sqrt(2.0))
        return "saturated", (f"at {bw_hz:.3g} Hz the command's peak rate is {rc:.0f} °/s: a linear output there would "
                             f"need {need:.0f} °/s against the {s:.0f} °/s slew ({check.slew_source}), so the −3 dB "
                             f"point is rate saturation, not the small-signal bandwidth; a sweep of at most "
                             f"±{small:.2g}° would measure it")
    return "ok", ""


# ---------------------------------------------------------------------------------------------- the test
FIT_BAND_TRIM = 0.05
"""Share of a sweep's band (in log frequency) left out of the fit at each end (see FrequencyResult)."""


@dataclass(frozen=True)
class FrequencyResult:
    """One measured frequency response with its figures and fits.

    The fit leaves out the first and last 5 % of a sweep's band in log frequency: the sweep starts
    and ends there, so every window that sees those frequencies also sees the record's start or end
    (on a noise-free SLOAC sweep 0.2-18 Hz the estimate is 0.5° off at 0.2 Hz and 6° at 18 Hz, under
    0.4° in between).

    Parameters
    ----------
    kind : str
        The segment kind.
    response : FrequencyResponse
        The measured response.
    bandwidth_hz : float or None
        The −3 dB frequency, Hz.
    bandwidth_note : str
        How it was found, or why there is none.
    at : list
        Gain, phase and coherence at the chosen frequencies.
    low_coherence_above_hz : float or None
        Where the top run of low coherence starts, Hz.
    coherence_note : str
        The coherence in a sentence.
    phase_90_hz : float or None
        Where the phase crosses −90°, Hz.
    fit : SecondOrderFit or None
        The second-order fit.
    fit_band_hz : tuple
        The band the fit used, Hz.
    overlay : FrequencyResponse or None
        A model simulated on the same command, analysed the same way.
    overlay_model : str or None
        That model's name.
    slew : SlewCheck or None
        The command against the actuator's slew.
    bandwidth_quality : Quality
        The bandwidth's quality (``saturated`` when it is rate saturation).
    bandwidth_quality_note : str
        Why.
    """

    kind: str
    response: FrequencyResponse
    bandwidth_hz: float | None
    bandwidth_note: str
    at: list[dict[str, Any]]
    low_coherence_above_hz: float | None
    coherence_note: str
    phase_90_hz: float | None
    fit: SecondOrderFit | None
    fit_band_hz: tuple[float, float]
    overlay: FrequencyResponse | None = None
    overlay_model: str | None = None
    slew: SlewCheck | None = None
    bandwidth_quality: Quality = "ok"
    bandwidth_quality_note: str = ""

    @property
    def leads(self) -> str:
        """Why the response is not causal: its coherent points whose phase leads beyond their uncertainty ("": none)."""
        r = self.response
        coherent = r.coherence >= COHERENCE_GOOD
        phase = [float(v) for v in r.phase_deg]
        sigma = [float(v) for v in np.degrees(r.random_error)]
        ahead = [int(i) for i in np.flatnonzero(coherent) if causal.phase_leads(phase[i], sigma[i])]
        if not ahead:
            return ""
        worst_i = max(ahead, key=lambda i: phase[i] / max(sigma[i], 1e-12))
        return (f"{len(ahead)} of {int(coherent.sum())} coherent points lead the command; the largest, "
                + causal.phase_note(phase[worst_i], sigma[worst_i], float(r.freq_hz[worst_i])))

    @property
    def quality(self) -> Quality:
        """The worse of the bandwidth's and the fit's, and ``non_causal`` where coherent points lead."""
        own = worst(self.bandwidth_quality, self.fit.quality if self.fit else "not_determined")
        return worst(own, "non_causal") if self.leads else own

    def as_dict(self) -> JsonObject:
        """Plain values for JSON.

        Returns
        -------
        dict
            The response's arrays, its figures, the slew check, the fit, the model overlay and quality.
        """
        r = self.response
        out: dict[str, Any] = {
            "test": self.kind, "output": r.output, "method": r.method, "start_s": r.start_s, "end_s": r.end_s,
            "freq_hz": r.freq_hz.tolist(), "gain_db": r.gain_db.tolist(), "phase_deg": r.phase_deg.tolist(),
            "coherence": r.coherence.tolist(), "random_error": r.random_error.tolist(),
            "bandwidth_3db_hz": self.bandwidth_hz, "bandwidth_note": self.bandwidth_note,
            "bandwidth_quality": self.bandwidth_quality, "bandwidth_quality_note": self.bandwidth_quality_note,
            "slew_check": self.slew.as_dict() if self.slew else None,
            "phase_minus_90_hz": self.phase_90_hz, "at": self.at,
            "low_coherence_above_hz": self.low_coherence_above_hz, "coherence_note": self.coherence_note,
            "fit_band_hz": list(self.fit_band_hz), "second_order_fit": self.fit.as_dict() if self.fit else None,
            "quality": self.quality, "quality_note": self.leads,
        }
        if self.overlay is not None:
            out["model_overlay"] = {"model": self.overlay_model, "at": at_frequencies(self.overlay, [
                a["freq_hz"] for a in self.at]), "bandwidth_3db_hz": bandwidth_3db(self.overlay)[0]}
        return out


def _spearman(x: FloatArray) -> float:
    r = np.argsort(np.argsort(x)).astype(float)
    i = np.arange(x.size, dtype=float)
    return float(np.corrcoef(i, r)[0, 1]) if x.size > 2 else 0.0


def _period_by_autocorrelation(u: FloatArray, dt: float) -> tuple[float, float] | None:
    """Lag (≥ 1 s, ≤ 60 % of the record) of the highest unbiased autocorrelation, refined parabolically."""
    n = u.size
    lo = round(1.0 / dt)
    hi = int(0.6 * n)
    if hi < lo + 2:
        return None
    rho = autocorrelation(u, hi)
    # The biased estimator shrinks by (1 − k/N); undo it so a repeat late in the record counts fully.
    k = np.arange(rho.size)
    rho = rho / (1.0 - k / n)
    i = lo + int(np.argmax(rho[lo:hi]))
    lag = float(i)
    if lo < i < hi - 1:
        den = rho[i - 1] - 2 * rho[i] + rho[i + 1]
        if den < 0:
            lag += 0.5 * (rho[i - 1] - rho[i + 1]) / den
    return float(lag * dt), float(rho[i])


def read_sweep(m: MovingStretch) -> Reading | None:
    """At least 12 turning points whose spacing shrinks steadily over more than a 3:1 band: a sine sweep.

    A spacing that shrinks in steps (tones one after another, :attr:`MovingStretch.dwells`) is no sweep.

    Parameters
    ----------
    m : MovingStretch
        A moving stretch of the command.

    Returns
    -------
    Reading or None
        ``sweep`` with its band, or None.
    """
    if m.turns.size < 12:
        return None
    half = m.half_periods_s
    f0, f1 = 0.5 / float(np.median(half[:3])), 0.5 / float(np.median(half[-3:]))
    if _spearman(half) >= -0.9 or f1 / f0 <= 3.0 or m.dwells:
        return None
    return Reading("sweep", f"sine sweep {f0:.3g}-{f1:.3g} Hz (period shrinks steadily)", {"f0_hz": f0, "f1_hz": f1})


def read_schroeder(m: MovingStretch) -> Reading | None:
    """A command that repeats (autocorrelation > 0.9 at a lag of at least 1 s, twice in the stretch).

    Parameters
    ----------
    m : MovingStretch
        A moving stretch of the command.

    Returns
    -------
    Reading or None
        ``schroeder`` with its period, or None.
    """
    if m.turns.size <= 3:
        return None
    per = _period_by_autocorrelation(m.u, m.dt)
    if per is None or per[1] <= 0.9 or m.span_s < 1.9 * per[0]:
        return None
    return Reading("schroeder", f"broadband command repeating every {per[0]:.4g} s (autocorrelation {per[1]:.3f})",
                   {"period_s": per[0]})


def read_broadband(m: MovingStretch) -> Reading:
    """Any moving command no other test claims: broadband.

    Parameters
    ----------
    m : MovingStretch
        A moving stretch of the command.

    Returns
    -------
    Reading
        ``broadband``.
    """
    if m.turns.size <= 3:
        return Reading("broadband", "moving command with few turning points")
    return Reading("broadband", f"broadband command ({m.turns.size} irregular turning points)")


def _overlay(ra: RecordAnalysis, sl: slice) -> FloatArray | None:
    """The named model's LVDT position on the segment, simulated on the measured command and load.

    The model runs from the record's first sample (trimmed there), so a discrete model's internal
    step grid keeps the alignment with the command frames it had when the record was made.
    """
    if not ra.options.model:
        return None

    data = ra.data
    model = create(ra.options.model, ra.channel.channel)
    stop = sl.stop
    t = data.time_s[:stop] - data.time_s[0]
    u = data.command_deg[:stop]
    hm = data.hinge_moment[:stop]
    model.trim(u[0], hm[0])
    rec = model.run(t, u, hm, sample_times=t, end_s=float(t[-1]))
    return np.asarray(rec.position_deg[0][sl.start:stop], dtype=float)


def _known_slew(ra: RecordAnalysis) -> tuple[float, str] | None:
    """A slew rate measured on rate-limited steps of the same record."""
    steps = ra.of(STEPS)
    rates = slew_rates(steps, ra.slew) if steps else None
    large = rates.large_dps if rates else None
    return (large, f"rate-limited steps in this record: {rates.large_source}") if rates and large else None


class FrequencyTest(Section2Test[FrequencyResult]):
    """Frequency response, bandwidth, phase and second-order fit of every sweep and broadband segment."""

    key = "frequency_response"
    title = "Frequency response"
    kinds = ("sweep", "schroeder", "broadband")
    absent = "no sweep, Schroeder sweep or broadband command recognised"

    @override
    def run(self, ra: RecordAnalysis) -> list[FrequencyResult]:
        out: list[FrequencyResult] = []
        for seg in ra.segments(*self.kinds):
            out += self._segment(ra, seg)
        return out

    def _segment(self, ra: RecordAnalysis, seg: Segment) -> list[FrequencyResult]:

        data = ra.data
        fs = data.sample_hz
        stop = seg.stop
        periodic = seg.kind == "schroeder" and "period_s" in seg.params
        if periodic:
            # Whole periods from the start of the sweep (the command holds its value after the last change).
            n_per = seg.params["period_s"] * fs
            periods = int(np.floor((seg.stop - seg.start) / n_per + 0.02))
            stop = max(stop, min(len(data), seg.start + round(periods * n_per)))
        sl = slice(seg.start, stop)
        u = data.command_deg[sl]
        outs = ra.outputs(sl)
        t0 = float(data.time_s[seg.start])
        held = not ra.command.assumed_sampled
        band = ((seg.params["f0_hz"], seg.params["f1_hz"]) if "f0_hz" in seg.params and "f1_hz" in seg.params
                else excitation_band(u, fs))
        model_y = _overlay(ra, sl)
        if periodic:
            period = seg.params["period_s"]
            responses = from_periodic(u, outs, fs, period, band, start_s=t0, held=held)
            overlays = (from_periodic(u, {"model": model_y}, fs, period, band, start_s=t0, held=held)
                        if model_y is not None else [])
            fit_band = (band[0], band[1])
        else:
            responses = from_sweep(u, outs, fs, band, start_s=t0, held=held)
            overlays = from_sweep(u, {"model": model_y}, fs, band, start_s=t0, held=held) if model_y is not None else []
            trim = (band[1] / band[0]) ** FIT_BAND_TRIM if band[1] > band[0] else 1.0
            fit_band = (band[0] * trim, band[1] / trim)
        if not responses:
            ra.not_computed[f"{self.key}: {seg.kind} at {t0:.2f} s"] = (
                f"band {band[0]:.3g}-{band[1]:.3g} Hz too narrow for a response")
            return []
        t = data.time_s[sl]
        known = _known_slew(ra)
        out = []
        for r in responses:
            cycles = sweep_cycles(t, u, outs[r.output])
            check = check_slew(t, u, outs[r.output], known, cycles)
            top = fit_band[1] if check.saturated_from_hz is None else min(fit_band[1], check.saturated_from_hz)
            band_r = (fit_band[0], top)
            bw, bw_note = bandwidth_3db(r)
            bq, bq_note = bandwidth_quality(bw, check, cycles)
            bq, bq_note = coherent_where_read(r, bw, bq, bq_note)
            above, coh_note = coherence_statement(r)
            in_band = (r.freq_hz >= band_r[0] * (1 - 1e-9)) & (r.freq_hz <= band_r[1] * (1 + 1e-9))
            sub = FrequencyResponse(r.output, r.method, r.freq_hz[in_band], r.h[in_band], r.coherence[in_band],
                                    r.random_error[in_band], r.start_s, r.end_s)
            label = f"{seg.kind} {band[0]:.3g}-{band[1]:.3g} Hz at {t0:.2f} s"
            fit = fit_frequency_response(sub, test=label, sample_hz=fs)
            out.append(FrequencyResult(
                seg.kind, r, bw, bw_note, at_frequencies(r, list(ra.options.at_hz)), above, coh_note,
                phase_crossing_hz(r), fit, band_r, overlays[0] if overlays else None, ra.options.model, check,
                bq, bq_note))
        return out


    @override
    def fits(self, r: FrequencyResult) -> list[SecondOrderFit]:
        return [r.fit] if r.fit is not None else []

    @override
    def markdown(self, ra: RecordAnalysis, results: list[FrequencyResult],
                 images: list[str | None]) -> list[str]:
        lines: list[str] = []
        for fr, img in zip(results, images, strict=True):
            r = fr.response
            lines += [f"**{fr.kind}, {r.output}** ({r.start_s:.2f}-{r.end_s:.2f} s): {r.method}.", ""]
            lines.append(f"- −3 dB bandwidth: {num(fr.bandwidth_hz, '.3f', ' Hz')} ({fr.bandwidth_note}); quality "
                         f"{quality(fr.bandwidth_quality, fr.bandwidth_quality_note)}; phase −90° at "
                         f"{num(fr.phase_90_hz, '.3f', ' Hz')}")
            if fr.slew:
                sc = fr.slew
                sat = (f"; rate saturation from {sc.saturated_from_hz:.3g} Hz" if sc.saturated_from_hz else "")
                lines.append(f"- command ±{sc.command_amplitude_deg:.3g}°, peak rate {sc.command_peak_rate_dps:.0f} °/s"
                             f"; slew {num(sc.measured_slew_dps, '.0f', ' °/s')} ({sc.slew_source}){sat}")
            lines.append(f"- {fr.coherence_note}")
            if fr.leads:
                lines.append(f"- not causal: {fr.leads}")
            if fr.fit:
                ft = fr.fit
                lines.append(f"- second order fitted over {fr.fit_band_hz[0]:.3g}-{fr.fit_band_hz[1]:.3g} Hz: "
                             f"ωn {pm(ft.wn_rad_s.value, ft.wn_rad_s.sigma)} rad/s "
                             f"({ft.wn_rad_s.value / 2 / np.pi:.3f} Hz), ζ {pm(ft.zeta.value, ft.zeta.sigma, '.4f')}, "
                             f"delay {pm(1e3 * ft.delay_s.value, 1e3 * ft.delay_s.sigma, '.3f')} ms, gain "
                             f"{ft.gain.value:.4f}, fit RMS {ft.rms:.3g} dB; quality "
                             f"{quality(ft.quality, ft.quality_note)}")
            else:
                lines.append("- second order: fewer than 8 coherent points in the fit band, not fitted")
            lines.append("")
            rows = [[f"{a['freq_hz']:g}", num(a["gain_db"], "+.2f"), num(a["phase_deg"], ".1f"),
                     num(a["coherence"], ".3f"), a.get("note", "")] for a in fr.at]
            head = ["f, Hz", "gain, dB", "phase, °", "coherence", "note"]
            if fr.overlay is not None:
                ov = at_frequencies(fr.overlay, [a["freq_hz"] for a in fr.at])
                for row, o in zip(rows, ov, strict=True):
                    row.insert(3, f"{num(o['gain_db'], '+.2f')} / {num(o['phase_deg'], '.1f')}")
                head.insert(3, f"{fr.overlay_model}: gain / phase")
            lines += table(head, rows)
            lines += image(img, "Bode plot")
        return lines

    @override
    def summary(self, ra: RecordAnalysis, r: FrequencyResult) -> list[str]:
        bw = f"{r.bandwidth_hz:.2f} Hz" if r.bandwidth_hz else "—"
        if r.bandwidth_quality != "ok":
            bw += f" [{r.bandwidth_quality}]"
        fit = r.fit
        fit_s = ""
        if fit:
            fit_s = (f"; ωn {fit.wn_rad_s.value:.2f} ± {fit.wn_rad_s.sigma:.2g} rad/s, ζ {fit.zeta.value:.3f} ± "
                     f"{fit.zeta.sigma:.2g}, delay {1e3 * fit.delay_s.value:.2f} ± {1e3 * fit.delay_s.sigma:.2g} ms")
            if fit.quality != "ok":
                fit_s += f" [{fit.quality}: {fit.quality_note}]"
        lines = [f"{r.kind} → {r.response.output}: −3 dB {bw}; {r.coherence_note}{fit_s}"]
        return [*lines, f"  not causal: {r.leads}"] if r.leads else lines

    @override
    def plot(self, ra: RecordAnalysis, r: FrequencyResult, path: Path) -> bool:

        fr = r
        resp = fr.response
        fig, ax = figure.pyplot().subplots(3, 1, figsize=(8, 8), sharex=True,
                                           gridspec_kw={"height_ratios": [3, 3, 1.4]})
        color = figure.COLORS.get(resp.output, "tab:blue")
        ax[0].semilogx(resp.freq_hz, resp.gain_db, color=color, lw=1.2, label=f"measured ({resp.output})")
        ax[1].semilogx(resp.freq_hz, resp.phase_deg, color=color, lw=1.2)
        ax[2].semilogx(resp.freq_hz, resp.coherence, color=color, lw=1.0)
        if fr.fit:
            f = fr.fit
            h = response(resp.freq_hz, f.wn_rad_s.value, f.zeta.value, f.delay_s.value, f.gain.value)
            ax[0].semilogx(resp.freq_hz, 20 * np.log10(np.abs(h)), "k--", lw=1.0,
                           label=f"2nd order: ωn {f.wn_rad_s.value:.1f} rad/s, ζ {f.zeta.value:.3f}, τ "
                                 f"{1e3 * f.delay_s.value:.2f} ms ({f.quality})")
            ph = np.degrees(np.unwrap(np.angle(h)))
            ax[1].semilogx(resp.freq_hz, ph - 360 * np.round((ph[0] - resp.phase_deg[0]) / 360), "k--", lw=1.0)
            for a in ax[:2]:
                a.axvspan(fr.fit_band_hz[0], fr.fit_band_hz[1], color="0.95", zorder=0)
        if fr.overlay is not None:
            o = fr.overlay
            ax[0].semilogx(o.freq_hz, o.gain_db, color=figure.COLORS["model"], lw=1.0, ls=":",
                           label=f"{fr.overlay_model} simulated on the same command")
            ax[1].semilogx(o.freq_hz, o.phase_deg, color=figure.COLORS["model"], lw=1.0, ls=":")
        ref = low_frequency_gain_db(resp)
        if ref is not None:
            ax[0].axhline(ref - 3.0, color="0.6", lw=0.6, ls="-.")
        if fr.bandwidth_hz and ref is not None:
            ax[0].axvline(fr.bandwidth_hz, color="0.6", lw=0.6, ls="-.")
            ax[0].text(fr.bandwidth_hz, ref - 3.0, f" −3 dB at {fr.bandwidth_hz:.2f} Hz ({fr.bandwidth_quality})",
                       fontsize=8, va="bottom")
        if fr.slew and fr.slew.saturated_from_hz:
            for a in ax[:2]:
                a.axvspan(fr.slew.saturated_from_hz, resp.freq_hz[-1], color="tab:red", alpha=0.08)
            ax[0].text(fr.slew.saturated_from_hz, ax[0].get_ylim()[0], " rate saturation", fontsize=8, color="tab:red")
        ax[2].axhline(0.8, color="r", lw=0.6, ls="--")
        ax[0].set_ylabel("gain, dB")
        ax[1].set_ylabel("phase, deg")
        ax[2].set_ylabel("coherence")
        ax[2].set_ylim(0, 1.05)
        ax[2].set_xlabel("frequency, Hz")
        ax[0].legend(fontsize=8, loc="lower left")
        ax[0].set_title(f"{fr.kind}: command → {resp.output}")
        for a in ax:
            a.grid(True, which="both", lw=0.3)
        figure.save(fig, path)
        return True


TEST = FrequencyTest()
