"""Frequency-response estimators and readouts: H = Gxy/Gxx with its coherence, and what is read off it.

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
(:func:`zoh_factor`: ``sinc(f/fs)·e^(−jπf/fs)``, half a sample of delay) so H is the actuator's own.

Pure: no section-2 test, report or figure. The fits (:mod:`ema_sim.analysis.estimation.second_order_fit`) and the
frequency-response test (:mod:`ema_sim.analysis.section2.frequency_response`) both import it, so neither imports
the other to reach the estimators.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ema_sim.analysis.estimation import causal, spectra
from ema_sim.analysis.estimation.noise import noise_floor
from ema_sim.jsontypes import JsonObject

FloatArray = NDArray[np.float64]
ComplexArray = NDArray[np.complex128]

COHERENCE_GOOD = 0.8
"""Coherence below this is called out in the report."""
COHERENCE_FIT = 0.6
"""Points below this coherence are left out of fits and of the bandwidth."""


@dataclass(frozen=True)
class FrequencyResponse:
    """Command-to-``output`` response on ``freq_hz``.

    Parameters
    ----------
    output : str
        Name of the output.
    method : str
        How it was estimated.
    freq_hz : numpy.ndarray
        Frequency, Hz.
    h : numpy.ndarray
        The complex response.
    coherence : numpy.ndarray
        Coherence at each frequency.
    random_error : numpy.ndarray
        Normalised random error at each frequency.
    start_s : float
        Start of the data, s.
    end_s : float
        End of the data, s.
    """

    output: str
    method: str
    freq_hz: FloatArray
    h: ComplexArray
    coherence: FloatArray
    random_error: FloatArray
    start_s: float
    end_s: float

    @property
    def gain_db(self) -> FloatArray:
        """20·log10|H|."""
        return 20.0 * np.log10(np.maximum(np.abs(self.h), 1e-300))

    @property
    def phase_deg(self) -> FloatArray:
        """Phase unwrapped from the lowest frequency, which is kept in (−180°, 180°]."""
        ph = np.degrees(np.unwrap(np.angle(self.h)))
        if ph.size:
            ph = ph - 360.0 * np.round((ph[0] - 1e-9) / 360.0)
        return ph

    def good(self, level: float = COHERENCE_FIT) -> NDArray[np.bool_]:
        """Points whose coherence reaches ``level``.

        Parameters
        ----------
        level : float
            Coherence a point needs.

        Returns
        -------
        numpy.ndarray
            True where the coherence reaches the level.
        """
        return self.coherence >= level


def zoh_factor(freq_hz: FloatArray, fs: float) -> ComplexArray:
    """What holding the command between samples does to a sampled response: sinc(f/fs)·e^(−jπf/fs).

    Parameters
    ----------
    freq_hz : numpy.ndarray
        Frequency, Hz.
    fs : float
        Sample rate, Hz.

    Returns
    -------
    numpy.ndarray
        The factor at each frequency.
    """
    x = np.asarray(freq_hz, dtype=float) / fs
    return np.asarray(np.sinc(x) * np.exp(-1j * np.pi * x), dtype=complex)


def excitation_band(u: FloatArray, fs: float, floor_db: float = 30.0) -> tuple[float, float]:
    """Where the command carries power: within ``floor_db`` of its spectral peak (long-window Welch).

    Parameters
    ----------
    u : numpy.ndarray
        The command, deg.
    fs : float
        Sample rate, Hz.
    floor_db : float
        Depth below the spectral peak, dB.

    Returns
    -------
    tuple
        Lowest and highest excited frequency, Hz.
    """
    sp = spectra.welch(u, u[None, :], fs, min(u.size / fs / 4.0, 20.0))
    f, g = sp.freq_hz[1:], sp.gxx[1:]
    keep = g >= g.max() * 10 ** (-floor_db / 10.0)
    return float(f[keep][0]), float(f[keep][-1])


def _decimated(u: FloatArray, ys: FloatArray, fs: float, f_hi: float) -> tuple[FloatArray, FloatArray, float]:
    """Command and outputs decimated to about 6× the top frequency, through the same anti-alias filter.

    Filtering command and output alike leaves H = Gxy/Gxx and the coherence unchanged wherever the
    filter passes, and cuts the FFT work by the decimation factor.
    """
    from scipy.signal import decimate  # noqa: PLC0415 - scipy.signal loads in ~0.5 s; only a decimated estimate needs it

    q = int(fs // (6.0 * f_hi))
    if q < 2:
        return u, ys, fs
    x = decimate(u, q, ftype="fir", zero_phase=True)
    yd = np.stack([decimate(y, q, ftype="fir", zero_phase=True) for y in ys])
    return x, yd, fs / q


def from_sweep(u: FloatArray, outputs: dict[str, FloatArray], fs: float, band: tuple[float, float], *,
               start_s: float = 0.0, per_decade: int = 60,
               windows_s: tuple[float, ...] | None = None, held: bool = True) -> list[FrequencyResponse]:
    """Composite-window estimates of each output's response over a band.

    Parameters
    ----------
    u : numpy.ndarray
        The command.
    outputs : dict
        Output name → values.
    fs : float
        Sample rate, Hz.
    band : tuple of float
        Lowest and highest frequency, Hz.
    start_s : float
        Time of the first sample, s.
    per_decade : int
        Grid points per decade.
    windows_s : tuple of float, optional
        Window lengths (default: :func:`ema_sim.analysis.estimation.spectra.default_windows`).
    held : bool
        The command is held between samples: divide the hold out.

    Returns
    -------
    list of FrequencyResponse
        One per output (none when the band is too narrow).
    """
    span = u.size / fs
    f_hi = min(band[1], fs / 4.0)
    windows = windows_s or spectra.default_windows(span, f_hi)
    f_lo = max(band[0], 2.0 / windows[0])
    if f_hi <= f_lo:
        return []
    grid = spectra.log_grid(f_lo, f_hi, per_decade)
    names = list(outputs)
    ys = np.stack([outputs[k] for k in names])
    x, ys_d, fs_d = _decimated(u, ys, fs, f_hi)
    comp = spectra.composite(x, ys_d, fs_d, grid, windows)
    corr = zoh_factor(grid, fs) if held else np.ones(grid.size, dtype=complex)
    out = []
    for i, name in enumerate(names):
        with np.errstate(divide="ignore", invalid="ignore"):
            h = np.where(comp.gxx[i] > 0, comp.gxy[i] / np.where(comp.gxx[i] > 0, comp.gxx[i], 1.0), 0.0) / corr
        coh = spectra.coherence(comp.gxx[i], comp.gyy[i], comp.gxy[i])
        err = spectra.random_error(coh, np.maximum(comp.averages[i], 1.0))
        wins = "/".join(f"{w:.3g}" for w in windows)
        method = f"composite-window H1 (Hann, 80 % overlap, windows {wins} s), " + (
            "ZOH-corrected" if held else "no hold correction (sampled command)")
        out.append(FrequencyResponse(name, method, grid, h, coh, err, start_s, start_s + span))
    return out


def from_periodic(u: FloatArray, outputs: dict[str, FloatArray], fs: float, period_s: float,
                  band: tuple[float, float], *, start_s: float = 0.0, held: bool = True) -> list[FrequencyResponse]:
    """Harmonic-by-harmonic estimates over the last whole periods of a periodic command.

    Parameters
    ----------
    u : numpy.ndarray
        The command.
    outputs : dict
        Output name → values.
    fs : float
        Sample rate, Hz.
    period_s : float
        The command's period, s.
    band : tuple of float
        Lowest and highest frequency, Hz.
    start_s : float
        Time of the first sample, s.
    held : bool
        The command is held between samples: divide the hold out.

    Returns
    -------
    list of FrequencyResponse
        One per output (none without a whole period or harmonic in the band).
    """
    n_per = period_s * fs
    periods = int(np.floor(u.size / n_per + 1e-9))
    if periods < 1:
        return []
    k0 = max(1, int(np.ceil(band[0] * period_s - 1e-9)))
    k1 = int(np.floor(min(band[1], fs / 4.0) * period_s + 1e-9))
    if k1 < k0:
        return []
    m = k1 - k0 + 1
    first = u.size - round(periods * n_per)
    length = round(n_per)
    starts = [first + round(p * n_per) for p in range(periods)]

    def per_period(x: FloatArray) -> ComplexArray:
        return np.stack([spectra.dft_at(x[s:s + length], fs, k0 / period_s, 1.0 / period_s, m) for s in starts])

    U = per_period(u)
    freq = (k0 + np.arange(m)) / period_s
    power_u = np.sum(np.abs(U) ** 2, axis=0)
    excited = power_u >= 1e-6 * power_u.max()
    freq, U, power_u = freq[excited], U[:, excited], power_u[excited]
    corr = zoh_factor(freq, fs) if held else np.ones(freq.size, dtype=complex)
    out = []
    for name, y in outputs.items():
        Y = per_period(y)[:, excited]
        cross = np.sum(np.conj(U) * Y, axis=0)
        power_y = np.sum(np.abs(Y) ** 2, axis=0)
        h = cross / power_u / corr
        if periods >= 2:
            coh = spectra.coherence(power_u, power_y, cross)
            how = f"period-to-period scatter of {periods} periods"
        else:
            noise = length * noise_floor(y) ** 2
            coh = np.clip(1.0 - noise / np.maximum(power_y, 1e-300), 0.0, 1.0)
            how = "one period: output noise floor against each harmonic"
        err = spectra.random_error(coh, float(periods))
        method = (f"periodic DFT by chirp-z at {freq.size} harmonics of 1/{period_s:g} s over {periods} whole "
                  f"period(s), rectangular window; coherence from {how}; "
                  + ("ZOH-corrected" if held else "no hold correction (sampled command)"))
        out.append(FrequencyResponse(name, method, freq, h, coh, err, start_s + first / fs, start_s + u.size / fs))
    return out


def interp_log(f: FloatArray, values: FloatArray, at: float) -> float:
    """``values`` (given at the frequencies ``f``) at frequency ``at``, interpolated on a log frequency axis.

    Parameters
    ----------
    f : numpy.ndarray
        Frequencies, increasing (Hz).
    values : numpy.ndarray
        A value at each.
    at : float
        Where it is read (Hz).

    Returns
    -------
    float
        The interpolated value.
    """
    return float(np.interp(np.log(at), np.log(f), values))


def low_frequency_gain_db(fr: FrequencyResponse, level: float = COHERENCE_FIT) -> float | None:
    """Mean gain of the lowest coherent decile of the band: the reference for the −3 dB bandwidth.

    Parameters
    ----------
    fr : FrequencyResponse
        The measured frequency response.
    level : float
        Coherence a point needs.

    Returns
    -------
    float or None
        The reference gain, dB (None with fewer than 3 coherent points).
    """
    good = np.flatnonzero(fr.good(level))
    if good.size < 3:
        return None
    take = good[: max(3, good.size // 10)]
    return float(np.mean(fr.gain_db[take]))


def bandwidth_3db(fr: FrequencyResponse, level: float = COHERENCE_FIT) -> tuple[float | None, str]:
    """First frequency where the gain falls 3 dB below its low-frequency value, and a note.

    Parameters
    ----------
    fr : FrequencyResponse
        The measured frequency response.
    level : float
        Coherence a point needs.

    Returns
    -------
    tuple
        The frequency (None when there is none) and a note.
    """
    ref = low_frequency_gain_db(fr, level)
    if ref is None:
        return None, "fewer than 3 coherent points: no bandwidth"
    good = fr.good(level)
    f, g = fr.freq_hz[good], fr.gain_db[good]
    below = np.flatnonzero(g < ref - 3.0)
    if below.size == 0:
        return None, f"gain stays within 3 dB of {ref:+.2f} dB up to {f[-1]:.3g} Hz (coherent band)"
    i = int(below[0])
    if i == 0:
        return None, "gain already 3 dB down at the lowest coherent frequency"
    x0, x1 = np.log(f[i - 1]), np.log(f[i])
    y0, y1 = g[i - 1] - (ref - 3.0), g[i] - (ref - 3.0)
    fb = float(np.exp(x0 + (x1 - x0) * y0 / (y0 - y1)))
    return fb, f"−3 dB relative to the low-frequency gain {ref:+.2f} dB"


def at_frequencies(fr: FrequencyResponse, freqs_hz: list[float]) -> list[dict[str, Any]]:
    """Gain, phase and coherence interpolated (in log frequency) at each chosen frequency.

    Parameters
    ----------
    fr : FrequencyResponse
        The measured frequency response.
    freqs_hz : list
        Frequencies, Hz.

    Returns
    -------
    list
        One row per frequency: gain, phase, coherence, quality (``not_determined`` where the coherence is under
        :data:`COHERENCE_GOOD`) and note.
    """
    out: list[JsonObject] = []
    f = fr.freq_hz
    gain, phase = fr.gain_db, fr.phase_deg
    for at in freqs_hz:
        if f.size == 0 or at < f[0] or at > f[-1]:
            out.append({"freq_hz": at, "gain_db": None, "phase_deg": None, "coherence": None,
                        "quality": "not_determined", "note": "outside the excited band: not measured"})
            continue
        coh = interp_log(f, fr.coherence, at)
        row: dict[str, Any] = {"freq_hz": at, "gain_db": interp_log(f, gain, at),
                               "phase_deg": interp_log(f, phase, at), "coherence": coh, "quality": "ok"}
        if coh < COHERENCE_GOOD:
            row["note"] = f"coherence {coh:.2f} < {COHERENCE_GOOD}: not measured there"
            row["quality"] = "not_determined"
        else:
            # the phase's standard error is the normalised random error of |H| in radians (Bendat & Piersol)
            sigma = float(np.degrees(interp_log(f, fr.random_error, at)))
            row["phase_sigma_deg"] = sigma
            if causal.phase_leads(row["phase_deg"], sigma):
                row["quality"] = "non_causal"
                row["note"] = causal.phase_note(row["phase_deg"], sigma, at)
        out.append(row)
    return out


def coherence_statement(fr: FrequencyResponse, level: float = COHERENCE_GOOD) -> tuple[float | None, str]:
    """Where the coherence falls below ``level``: the start of the top run of low coherence, and a sentence.

    Parameters
    ----------
    fr : FrequencyResponse
        The measured frequency response.
    level : float
        Coherence a point needs.

    Returns
    -------
    tuple
        Where the top run of low coherence starts (or None) and a sentence.
    """
    low = fr.coherence < level
    if not low.any():
        return None, f"coherence ≥ {level} from {fr.freq_hz[0]:.3g} to {fr.freq_hz[-1]:.3g} Hz"
    if low[-1]:
        i = low.size - 1
        while i > 0 and low[i - 1]:
            i -= 1
        above = float(fr.freq_hz[i])
        rest = low[:i].sum()
        tail = f"; {rest} point(s) below it lower down" if rest else ""
        return above, f"coherence < {level} above {above:.3g} Hz{tail}"
    share = 100.0 * low.mean()
    return None, f"coherence < {level} at {share:.0f} % of the points (between {fr.freq_hz[low][0]:.3g} and " \
                 f"{fr.freq_hz[low][-1]:.3g} Hz), ≥ {level} at the top of the band"


def phase_crossing_hz(fr: FrequencyResponse, phase_deg: float = -90.0, level: float = COHERENCE_FIT) -> float | None:
    """Lowest coherent frequency where the phase crosses ``phase_deg``.

    Parameters
    ----------
    fr : FrequencyResponse
        The measured frequency response.
    phase_deg : float
        Phase to cross, deg.
    level : float
        Coherence a point needs.

    Returns
    -------
    float or None
        The frequency, Hz, or None.
    """
    good = fr.good(level)
    f, ph = fr.freq_hz[good], fr.phase_deg[good]
    below = np.flatnonzero(ph <= phase_deg)
    if below.size == 0 or below[0] == 0:
        return None
    i = int(below[0])
    x0, x1 = np.log(f[i - 1]), np.log(f[i])
    y0, y1 = ph[i - 1] - phase_deg, ph[i] - phase_deg
    return float(np.exp(x0 + (x1 - x0) * y0 / (y0 - y1)))
