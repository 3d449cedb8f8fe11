"""The response at a periodic command's own harmonics, averaged over its cycles.

A periodic command (:mod:`ema_sim.analysis.records.periodic`) excites only its harmonics: a square wave its odd
ones, falling as 1/k; a triangle its odd ones as 1/k²; a trapezoid whose ramps take a fifth of the
period none at 5, 15, ... This module reads the response there and nowhere else:

* each cycle's command and output are fitted with a Fourier series of the period (least squares on the
  cycle's own samples, each at its own stamp: a period that is no whole number of samples leaks
  nothing, and a jittery logger's samples are where it took them, :func:`cycle_phases`);
* at each harmonic the waveform carries, H = ΣU*Y/Σ|U|² over the cycles, with the coherence of the
  cycles' scatter and the standard error of gain and phase over the cycles (:func:`harmonic_response`).
  No other frequency is read: an odd-harmonic-only waveform has nothing at its even harmonics (an
  output's even harmonics there are its own asymmetry). A harmonic whose coherence is under
  :data:`~ema_sim.analysis.estimation.frf.COHERENCE_GOOD` is ``not_determined``; every harmonic is
  ``saturated`` when the output's moves are rate-limited (the ratio is then the rate limit's
  describing function at that amplitude, not the small-signal response);
* the **bandwidth** (:func:`bandwidth`): where the gain, from the lowest harmonic up, first falls
  3 dB, interpolated in log frequency between the two harmonics that bracket it (half the bracket is
  its uncertainty); not measured when the coherence falls below the threshold first, when the
  harmonics end before the gain falls 3 dB, or for a waveform of a single frequency;
* the **lag** at the fundamental, −phase/360f (:func:`lag_at_fundamental`), its uncertainty the spread
  over the cycles and the resolution of the record's stamps.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ema_sim.analysis.estimation import causal
from ema_sim.analysis.estimation.frf import COHERENCE_GOOD, zoh_factor
from ema_sim.analysis.estimation.quality import Measurement, Quality
from ema_sim.analysis.records.periodic import EXCITED, Periodicity
from ema_sim.jsontypes import JsonObject

FloatArray = NDArray[np.float64]
ComplexArray = NDArray[np.complex128]

FIT_EXTRA = 4
"""The fit holds every harmonic the waveform carries and this many above the highest (the rest of a cycle sampled
evenly in phase is orthogonal to them)."""


@dataclass(frozen=True)
class Harmonic:
    """The response at one harmonic of the waveform, over the cycles.

    Parameters
    ----------
    k : int
        Harmonic number.
    freq_hz : float
        Its frequency, Hz.
    command_amplitude : float
        The command's amplitude there (mean over cycles).
    gain_db : float
        20·log10|H|.
    gain_sigma_db : float
        Standard error of the gain over the cycles, dB.
    phase_deg : float
        Phase of H (unwrapped from the lowest harmonic), deg.
    phase_sigma_deg : float
        Standard error of the phase over the cycles, deg.
    coherence : float
        Coherence of the cycles' scatter.
    quality : Quality
        ``ok``, ``not_determined`` (coherence) or ``saturated`` (rate-limited transitions).
    note : str
        Why, when not ``ok``.
    """

    k: int
    freq_hz: float
    command_amplitude: float
    gain_db: float
    gain_sigma_db: float
    phase_deg: float
    phase_sigma_deg: float
    coherence: float
    quality: Quality
    note: str = ""

    def as_dict(self) -> JsonObject:
        """Plain values for JSON.

        Returns
        -------
        dict
            The harmonic's figures.
        """
        return {"harmonic": self.k, "freq_hz": self.freq_hz, "command_amplitude": self.command_amplitude,
                "gain_db": self.gain_db, "gain_sigma_db": self.gain_sigma_db, "phase_deg": self.phase_deg,
                "phase_sigma_deg": self.phase_sigma_deg, "coherence": self.coherence, "quality": self.quality,
                "note": self.note}


def _fourier(tau: FloatArray, x: FloatArray, ks: NDArray[np.int64]) -> ComplexArray:
    """Complex amplitudes of harmonics ``ks`` of one cycle, per column of ``x`` (least squares; ``tau`` in cycles)."""
    w = 2.0 * np.pi * tau[:, None] * ks[None, :]
    a = np.column_stack([np.ones_like(tau), np.cos(w), np.sin(w)])
    coef, *_ = np.linalg.lstsq(a, x, rcond=None)
    m = ks.size
    return np.asarray(coef[1:m + 1] - 1j * coef[m + 1:], dtype=complex)


def cycle_phases(tb: FloatArray, t: FloatArray, p: Periodicity, margin: float = 0.0
                 ) -> list[tuple[NDArray[np.int64], FloatArray]]:
    """Each whole cycle's samples and their phase in the cycle (0 to 1), on the record's own stamps.

    The cycles were cut on the uniform grid; their samples were taken at the instants the stamps give
    (a jittery logger's samples sit up to half a sample off the grid, which on a fast ramp is a large
    part of a degree), so each sample's phase comes from its own stamp.

    Parameters
    ----------
    tb : numpy.ndarray
        The record's own stamps (or the uniform grid when it was resampled), s.
    t : numpy.ndarray
        The uniform grid, s.
    p : Periodicity
        The cycles.
    margin : float
        Phase beyond each end of the cycle to include as well (so a curve interpolated on the cycle has
        samples on both sides of its ends).

    Returns
    -------
    list of tuple
        Per cycle: the sample indices and their phases.
    """
    out = []
    idx_all = np.arange(t.size)
    pad = 3 + int(np.ceil(margin * p.period_samples))
    for s in p.cycle_starts():
        t0 = float(np.interp(s, idx_all, t)) - float(t[0]) + float(tb[0])
        lo = max(0, int(np.floor(s)) - pad)
        hi = min(t.size, int(np.ceil(s + p.period_samples)) + pad)
        idx = np.arange(lo, hi)
        tau = (tb[idx] - t0) / p.period_s
        keep = (tau >= -margin) & (tau < 1.0 + margin)
        out.append((idx[keep], tau[keep]))
    return out


def cycle_spectra(tb: FloatArray, t: FloatArray, u: FloatArray, y: FloatArray, p: Periodicity
                  ) -> tuple[ComplexArray, ComplexArray, NDArray[np.int64]]:
    """Each cycle's command and output at every harmonic the fit can hold.

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

    Returns
    -------
    tuple
        Command and output amplitudes, (cycles, harmonics), and the harmonic numbers (those the waveform carries
        and :data:`FIT_EXTRA` more).
    """
    k_max = max(1, min(p.harmonic_amplitudes.size, max(p.harmonics, default=1) + FIT_EXTRA))
    ks = np.arange(1, k_max + 1)
    uu, yy = [], []
    for idx, tau in cycle_phases(tb, t, p):
        fit = ks[: max(1, min(k_max, (idx.size - 1) // 2 - 1))]
        both = np.zeros((ks.size, 2), complex)
        both[: fit.size] = _fourier(tau, np.column_stack([u[idx], y[idx]]), fit)
        uu.append(both[:, 0])
        yy.append(both[:, 1])
    return np.array(uu), np.array(yy), ks


def harmonic_response(tb: FloatArray, t: FloatArray, u: FloatArray, y: FloatArray, p: Periodicity, fs: float, *,
                      held: bool, saturated: str = "") -> list[Harmonic]:
    """The response at every harmonic the waveform carries (module docstring).

    Parameters
    ----------
    tb : numpy.ndarray
        The record's own stamps (or the uniform grid when it was resampled), s.
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
    held : bool
        The command is held between samples: divide the hold out.
    saturated : str
        Why the transitions are rate-limited ("" when they are not).

    Returns
    -------
    list of Harmonic
        In order of frequency.
    """
    uc, yc, ks = cycle_spectra(tb, t, u, y, p)
    keep = [k for k in p.harmonics if k <= ks.size]
    out: list[Harmonic] = []
    phases: list[float] = []
    for k in keep:
        uk, yk = uc[:, k - 1], yc[:, k - 1]
        if np.any(np.abs(uk) == 0.0):
            continue
        f = k * p.freq_hz
        corr = complex(zoh_factor(np.array([f]), fs)[0]) if held else 1.0
        cross = complex(np.sum(np.conj(uk) * yk))
        pu, py = float(np.sum(np.abs(uk) ** 2)), float(np.sum(np.abs(yk) ** 2))
        h = cross / pu / corr
        coh = abs(cross) ** 2 / (pu * py) if py > 0 else 0.0
        each = yk / uk / corr
        n = each.size
        g_each = 20.0 * np.log10(np.maximum(np.abs(each), 1e-300))
        dph = np.degrees(np.angle(each / h)) if h != 0 else np.zeros(n)
        g_se = float(np.std(g_each, ddof=1) / np.sqrt(n)) if n > 1 else float("nan")
        p_se = float(np.std(dph, ddof=1) / np.sqrt(n)) if n > 1 else float("nan")
        q: Quality = "ok"
        note = ""
        if coh < COHERENCE_GOOD:
            q, note = "not_determined", f"coherence {coh:.2f} < {COHERENCE_GOOD} over the {n} cycles"
        elif saturated:
            q, note = "saturated", saturated
        phases.append(float(np.angle(h)))
        out.append(Harmonic(k, f, float(np.mean(np.abs(uk))), float(20.0 * np.log10(max(abs(h), 1e-300))), g_se,
                            0.0, p_se, float(coh), q, note))
    if out:
        ph = np.degrees(np.unwrap(np.array(phases)))
        ph -= 360.0 * np.round((ph[0] - 1e-9) / 360.0)
        out = [_causal(Harmonic(h.k, h.freq_hz, h.command_amplitude, h.gain_db, h.gain_sigma_db, float(v),
                                h.phase_sigma_deg, h.coherence, h.quality, h.note))
               for h, v in zip(out, ph, strict=True)]
    return out


def _causal(h: Harmonic) -> Harmonic:
    """The harmonic flagged ``non_causal`` when its phase leads beyond its uncertainty (:mod:`.causal`)."""
    if h.quality == "not_determined" or not causal.phase_leads(h.phase_deg, h.phase_sigma_deg):
        return h
    note = causal.phase_note(h.phase_deg, h.phase_sigma_deg, h.freq_hz)
    return Harmonic(h.k, h.freq_hz, h.command_amplitude, h.gain_db, h.gain_sigma_db, h.phase_deg, h.phase_sigma_deg,
                    h.coherence, "non_causal", f"{h.note}; {note}" if h.note else note)


def bandwidth(harmonics: list[Harmonic], saturated: str = "") -> Measurement:
    """The −3 dB frequency read from the harmonics (module docstring).

    Parameters
    ----------
    harmonics : list of Harmonic
        The response at the waveform's harmonics, in order of frequency.
    saturated : str
        Why the transitions are rate-limited ("" when they are not).

    Returns
    -------
    Measurement
        The frequency with half its bracket as the uncertainty, or "not measured: why".
    """
    if len(harmonics) < 2:
        return Measurement(None, None, "not_determined",
                       "not measured: the waveform carries a single frequency; a bandwidth needs a band")
    ref = harmonics[0]
    if ref.coherence < COHERENCE_GOOD:
        return Measurement(None, None, "not_determined", f"not measured: coherence {ref.coherence:.2f} < "
                       f"{COHERENCE_GOOD} already at the fundamental {ref.freq_hz:.3g} Hz")
    prev = ref
    for h in harmonics[1:]:
        if h.coherence < COHERENCE_GOOD:
            return Measurement(None, None, "not_determined",
                           f"not measured: the gain is {prev.gain_db - ref.gain_db:+.2f} dB from the fundamental's at "
                           f"{prev.freq_hz:.3g} Hz, and the coherence falls to {h.coherence:.2f} (< {COHERENCE_GOOD}) "
                           f"at the next harmonic, {h.freq_hz:.3g} Hz, before the gain falls 3 dB")
        if h.gain_db < ref.gain_db - 3.0:
            x0, x1 = np.log(prev.freq_hz), np.log(h.freq_hz)
            y0, y1 = prev.gain_db - (ref.gain_db - 3.0), h.gain_db - (ref.gain_db - 3.0)
            fb = float(np.exp(x0 + (x1 - x0) * y0 / (y0 - y1)))
            half = 0.5 * (h.freq_hz - prev.freq_hz)
            q: Quality = "saturated" if saturated else "ok"
            why = f"; {saturated}" if saturated else ""
            return Measurement(fb, half, q, f"−3 dB at {fb:.3g} Hz, interpolated between harmonics {prev.k} and {h.k} "
                                        f"({prev.freq_hz:.3g} and {h.freq_hz:.3g} Hz: ± {half:.2g} Hz){why}")
        prev = h
    return Measurement(None, None, "not_determined",
                   f"not measured: the gain stays within 3 dB of the fundamental's up to {prev.freq_hz:.3g} Hz, the "
                   f"highest harmonic the waveform carries (above {100 * EXCITED:g} % of its largest) with coherence "
                   f"≥ {COHERENCE_GOOD}")


def lag_at_fundamental(harmonics: list[Harmonic], stamp_s: float = 0.0) -> Measurement:
    """The output's lag behind the command at the fundamental, −phase/(360·f), or why not.

    Parameters
    ----------
    harmonics : list of Harmonic
        The response at the waveform's harmonics.
    stamp_s : float
        The resolution of the record's time stamps (a logger writing whole milliseconds: 0.001 s); its
        ``/√12`` is added in quadrature to the spread over the cycles (a stamp's rounding is common to
        command and output, but no spread over the cycles shows a rounding that is the same in each).

    Returns
    -------
    Measurement
        The lag, s, with its uncertainty.
    """
    h = next((x for x in harmonics if x.k == 1), None)
    if h is None:
        return Measurement(None, None, "not_determined", "not measured: the waveform has no fundamental")
    if h.coherence < COHERENCE_GOOD:
        return Measurement(None, None, "not_determined",
                       f"not measured: coherence {h.coherence:.2f} < {COHERENCE_GOOD} at the fundamental")
    lag = -h.phase_deg / 360.0 / h.freq_hz
    se = float(np.hypot(h.phase_sigma_deg / 360.0 / h.freq_hz, stamp_s / np.sqrt(12.0)))
    text = f"lag {1e3 * lag:.1f} ± {1e3 * se:.2g} ms at {h.freq_hz:.3g} Hz (phase {h.phase_deg:.1f}°)"
    if causal.delay_leads(lag, se):
        return Measurement(lag, se, "non_causal", f"{text}; {causal.delay_note(lag, se)}")
    return Measurement(lag, se, "ok" if h.quality == "non_causal" else h.quality, text)
