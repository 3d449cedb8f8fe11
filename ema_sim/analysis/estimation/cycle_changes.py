"""Whether the actuator changed over a periodic test: the second order fitted on each cycle, and its trend.

A periodic test's figures are averages over its cycles. When the actuator changed while it was recorded
(a winding that heats and loses gain, a fieldbus whose delay wanders), the average describes no cycle
well. Each cycle is a test of its own: the response at the waveform's coherent harmonics, cycle by cycle
(:func:`ema_sim.analysis.estimation.harmonics.cycle_spectra`), is fitted with the delayed second order of
figure 21 (:func:`ema_sim.analysis.estimation.second_order_fit.fit_frequency_response`, its uncertainty from
the fit's residual). The bandwidth that second order gives and its delay, cycle by cycle, are then
tested with :func:`ema_sim.analysis.estimation.trend.trend`, the test ``ema identify`` applies to its
windows: *steady*, *falls*, *grows* or *wanders*, with the values per cycle.

Rate-limited cycles are not read (their ratio is a describing function that changes with amplitude,
not with time); fewer than :data:`MIN_CYCLES` fitted cycles say nothing.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from ema_sim.analysis.estimation.frf import FrequencyResponse, zoh_factor
from ema_sim.analysis.estimation.harmonics import Harmonic, cycle_spectra
from ema_sim.analysis.estimation.second_order_fit import NAMES, fit_frequency_response
from ema_sim.analysis.estimation.trend import Trend, trend
from ema_sim.analysis.records.periodic import Periodicity
from ema_sim.jsontypes import JsonObject

FloatArray = NDArray[np.float64]
MIN_CYCLES = 4
"""Fewest fitted cycles a trend is read on."""
MIN_POINTS = 8
"""Coherent harmonics a cycle's fit needs (as the frequency-response fit does)."""


def bandwidth_hz(wn_rad_s: float, zeta: float) -> float:
    """The −3 dB frequency of the unit-gain second order, Hz (a delay does not change the gain).

    Parameters
    ----------
    wn_rad_s : float
        Natural frequency, rad/s.
    zeta : float
        Damping ratio.
    """
    a = 1.0 - 2.0 * zeta * zeta
    return wn_rad_s * math.sqrt(a + math.sqrt(a * a + 1.0)) / (2.0 * math.pi)


def _bandwidth_sigma(wn: float, zeta: float, s_wn: float, s_zeta: float) -> float:
    """Standard error of :func:`bandwidth_hz` from those of ωn and ζ (taken independent)."""
    d_wn = bandwidth_hz(wn, zeta) / wn
    h = 1e-6 * max(zeta, 1e-3)
    d_z = (bandwidth_hz(wn, zeta + h) - bandwidth_hz(wn, max(zeta - h, 0.0))) / (zeta + h - max(zeta - h, 0.0))
    return math.hypot(d_wn * s_wn, d_z * s_zeta)


def _on_bound(note: str) -> set[str]:
    """The parameters a fit's quality note says sit on a bound of the search.

    A value on a bound is no measurement; the others are (a delay held at 0 leaves ωn and ζ measured).
    """
    return {name for name in NAMES if f"{name} on its" in note}


@dataclass(frozen=True)
class CycleChanges:
    """The second order on each cycle of a periodic test, and whether its bandwidth and delay changed."""

    times_s: tuple[float, ...] = ()
    """Each fitted cycle's middle, s."""
    bandwidth: Trend | None = None
    """The fitted second order's −3 dB frequency per cycle, Hz."""
    delay: Trend | None = None
    """The fitted delay per cycle, s."""
    skipped: str = ""
    """Why nothing was read ("" when it was)."""
    statements: list[str] = field(default_factory=list)

    @property
    def changed(self) -> bool:
        """Bandwidth or delay changes over the test beyond its uncertainty."""
        return any(t is not None and t.changed for t in (self.bandwidth, self.delay))

    def as_dict(self) -> JsonObject:
        """Plain values for JSON (the delay in s, the bandwidth in Hz)."""
        def one(t: Trend | None) -> JsonObject | None:
            if t is None:
                return None
            return {"trend": t.kind, "values": list(t.values), "sigma": [s if math.isfinite(s) else None
                                                                          for s in t.sigma],
                    "chi2": t.chi2 if math.isfinite(t.chi2) else None, "dof": t.dof,
                    "p_value": t.p_value if math.isfinite(t.p_value) else None,
                    "slope_per_s": t.slope_per_s if math.isfinite(t.slope_per_s) else None,
                    "slope_sigma_per_s": t.slope_sigma if math.isfinite(t.slope_sigma) else None}
        return {"changed": self.changed, "cycle_mid_s": list(self.times_s), "bandwidth_hz": one(self.bandwidth),
                "delay_s": one(self.delay), "skipped": self.skipped or None, "statements": [*self.statements]}


def _statement(what: str, t: Trend, scale: float, unit: str, digits: str) -> str:
    per = ", ".join(f"{scale * v:{digits}}" + (f" ± {scale * s:.2g}" if math.isfinite(s) else " (on a bound)")
                    for v, s in zip(t.values, t.sigma, strict=True))
    if t.kind == "not determined":
        return (f"{what}: a change not determined (fewer than two cycles' fits off their bounds, where a value is "
                f"the search's limit, not a measurement): {per} {unit}")
    if not t.changed:
        return f"{what} holds over the cycles: {per} {unit} (χ² {t.chi2:.3g} on {t.dof} degrees of freedom)"
    if t.kind == "wanders":
        how = (f"wanders between {scale * min(t.values):{digits}} and {scale * max(t.values):{digits}} {unit} (not "
               "a straight trend: the line through the cycles leaves most of their spread)")
    else:
        span = t.times_s[-1] - t.times_s[0]
        mean = float(np.mean(t.values))
        how = (f"{t.kind} from {scale * t.values[0]:{digits}} to {scale * t.values[-1]:{digits}} {unit} (slope "
               f"{scale * t.slope_per_s:+.3g} ± {scale * t.slope_sigma:.2g} {unit} per s, "
               f"{100 * t.slope_per_s * span / mean if mean else 0.0:+.0f} % over {span:.3g} s)")
    return (f"{what} changes over the record beyond its uncertainty: it {how}; per cycle {per} {unit} "
            f"(χ² {t.chi2:.3g} on {t.dof} degrees of freedom, p {t.p_value:.2g}): the test's averaged figures "
            "describe no single cycle")


def cycle_changes(tb: FloatArray, t: FloatArray, u: FloatArray, y: FloatArray, p: Periodicity, fs: float, *,
                  harmonics: list[Harmonic], held: bool, output: str) -> CycleChanges:
    """Fit each cycle and test the bandwidth and delay for a change (module docstring).

    Parameters
    ----------
    tb : numpy.ndarray
        The record's own stamps (or the uniform grid), s.
    t : numpy.ndarray
        The uniform grid, s.
    u : numpy.ndarray
        The record's command.
    y : numpy.ndarray
        The record's output.
    p : Periodicity
        The cycles.
    fs : float
        Sample rate, Hz.
    harmonics : list of Harmonic
        The response over all cycles: its coherent (``ok``) harmonics are the ones each cycle is fitted on.
    held : bool
        The command is held between samples: its hold is divided out, as in the averaged response.
    output : str
        The output's name.

    Returns
    -------
    CycleChanges
        The trends, or why none was read.
    """
    good = [h for h in harmonics if h.quality in ("ok", "non_causal")]
    if p.cycles < MIN_CYCLES:
        return CycleChanges(skipped=f"{p.cycles} cycles: a change over the test needs at least {MIN_CYCLES}")
    if len(good) < MIN_POINTS:
        return CycleChanges(skipped=f"{len(good)} coherent harmonics: a cycle's fit needs {MIN_POINTS}")
    uc, yc, _ = cycle_spectra(tb, t, u, y, p)
    ks = np.array([h.k for h in good])
    freq = np.array([h.freq_hz for h in good])
    coh = np.array([h.coherence for h in good])
    corr = zoh_factor(freq, fs) if held else np.ones(freq.size, complex)
    starts = p.cycle_starts()
    if uc.shape[0] != starts.size:
        return CycleChanges(skipped="the cycles could not be read one by one")
    mids, bw, bw_s, dl, dl_s = [], [], [], [], []
    for c in range(uc.shape[0]):
        uk, yk = uc[c, ks - 1], yc[c, ks - 1]
        if np.any(uk == 0.0):
            continue
        a = math.floor(starts[c])
        b = min(t.size - 1, math.ceil(starts[c] + p.period_samples))
        fr = FrequencyResponse(output, f"cycle {c + 1}", freq, yk / uk / corr, coh, np.zeros(freq.size),
                               float(t[a]), float(t[b]))
        fit = fit_frequency_response(fr, test=f"cycle {c + 1}", level=0.0, sample_hz=fs)
        if fit is None or fit.quality == "not_determined":
            continue
        wn, z = fit.wn_rad_s, fit.zeta
        bound = _on_bound(fit.quality_note) if fit.quality == "on_bound" else set()
        mids.append(0.5 * (float(t[a]) + float(t[b])))
        bw.append(bandwidth_hz(wn.value, z.value))
        bw_s.append(math.inf if bound & {"ωn", "ζ"} else _bandwidth_sigma(wn.value, z.value, wn.sigma, z.sigma))
        dl.append(fit.delay_s.value)
        dl_s.append(math.inf if "delay" in bound else fit.delay_s.sigma)
    if len(mids) < MIN_CYCLES:
        return CycleChanges(skipped=f"{len(mids)} cycles fitted: a change over the test needs {MIN_CYCLES}")
    x = np.array(mids)
    band = trend(np.array(bw), np.array(bw_s), x)
    delay = trend(np.array(dl), np.array(dl_s), x)
    statements = [_statement("The bandwidth (the second order fitted on each cycle)", band, 1.0, "Hz", ".3g"),
                  _statement("The delay (the second order fitted on each cycle)", delay, 1e3, "ms", ".3g")]
    return CycleChanges(tuple(mids), band, delay, "", statements)
