"""Auto- and cross-spectra of a command and its responses: Welch averaging, composite windows, chirp-z.

* :func:`welch` averages Hann-windowed FFTs of overlapping segments (80 % overlap, as CIFER does for
  sweeps), the command's transform computed once for every output.
* :func:`composite` combines several window lengths on one logarithmic frequency grid, the composite
  windows of Tischler & Remple (*Aircraft and Rotorcraft System Identification*, ch. 8): long windows
  resolve the low frequencies, short ones average more segments at the high frequencies. At each grid
  frequency the windows' spectra are averaged with weights 1/ε², ε the normalised random error of
  each window's estimate, and a window only contributes where it holds at least two periods.
* :func:`dft_at` is the chirp-z transform at equally spaced frequencies that need not be FFT bins
  (the harmonics of a Schroeder sweep, say).

Spectra are one-sided densities (unit²/Hz).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
ComplexArray = NDArray[np.complex128]

OVERLAP = 0.8
HANN_ENBW_BINS = 1.5
"""Equivalent noise bandwidth of the Hann window, in bins: neighbouring bins are not independent."""
MAX_COHERENCE = 0.9999
"""Coherence is capped here when turned into a random error (a noise-free record is not infinitely good)."""


@dataclass(frozen=True)
class CrossSpectra:
    """One window length: ``gxx`` (F,), ``gyy`` and ``gxy`` (outputs, F), on FFT bins ``freq_hz``.

    Parameters
    ----------
    freq_hz : numpy.ndarray
        Frequency, Hz.
    gxx : numpy.ndarray
        Command auto-spectrum.
    gyy : numpy.ndarray
        Output auto-spectrum.
    gxy : numpy.ndarray
        Cross-spectrum.
    averages : float
        Effective number of independent averages (overlap accounted for).
    window_s : float
        Window length, s.
    """

    freq_hz: FloatArray
    gxx: FloatArray
    gyy: FloatArray
    gxy: ComplexArray
    averages: float
    """Effective number of independent averages (overlap accounted for)."""
    window_s: float


def effective_averages(n_segments: int, nperseg: int, step: int) -> float:
    """Welch's equivalent number of independent segments for overlapping Hann windows.

    Parameters
    ----------
    n_segments : int
        Segments averaged.
    nperseg : int
        Samples per segment.
    step : int
        Samples between segment starts.

    Returns
    -------
    float
        Effective number of independent averages.
    """
    w = np.hanning(nperseg)
    denom = float(np.sum(w * w))
    total = 1.0
    for k in range(1, n_segments):
        shift = k * step
        if shift >= nperseg:
            break
        rho = float(np.sum(w[: nperseg - shift] * w[shift:])) / denom
        total += 2.0 * (1.0 - k / n_segments) * rho * rho
    return n_segments / total


def welch(x: FloatArray, ys: FloatArray, fs: float, window_s: float, overlap: float = OVERLAP) -> CrossSpectra:
    """Hann-windowed, mean-removed, overlapped segment averages of ``x`` against each row of ``ys``.

    Parameters
    ----------
    x : numpy.ndarray
        The command.
    ys : numpy.ndarray
        The outputs, one per row.
    fs : float
        Sample rate, Hz.
    window_s : float
        Window length, s.
    overlap : float
        Overlap of consecutive segments.

    Returns
    -------
    CrossSpectra
        The spectra.
    """
    ys = np.atleast_2d(ys)
    n = x.size
    nperseg = min(n, max(8, round(window_s * fs)))
    step = max(1, round(nperseg * (1.0 - overlap)))
    n_seg = 1 + (n - nperseg) // step
    starts = np.arange(n_seg) * step
    w = np.hanning(nperseg)
    scale = 2.0 / (fs * float(np.sum(w * w)))
    idx = starts[:, None] + np.arange(nperseg)[None, :]
    xs = x[idx]
    xs = (xs - xs.mean(axis=1, keepdims=True)) * w
    X = np.fft.rfft(xs, axis=1)
    gxx = scale * np.mean(np.abs(X) ** 2, axis=0)
    gyy = np.empty((ys.shape[0], gxx.size))
    gxy = np.empty((ys.shape[0], gxx.size), dtype=complex)
    Xc = np.conj(X)
    for i, y in enumerate(ys):
        seg = y[idx]
        Y = np.fft.rfft((seg - seg.mean(axis=1, keepdims=True)) * w, axis=1)
        gyy[i] = scale * np.mean(np.abs(Y) ** 2, axis=0)
        gxy[i] = scale * np.mean(Xc * Y, axis=0)
    gxx[0] *= 0.5
    gyy[:, 0] *= 0.5
    gxy[:, 0] *= 0.5
    freq = np.asarray(np.fft.rfftfreq(nperseg, 1.0 / fs), dtype=float)
    return CrossSpectra(freq, gxx, gyy, gxy, effective_averages(n_seg, nperseg, step), nperseg / fs)


def log_grid(f_lo: float, f_hi: float, per_decade: int = 60) -> FloatArray:
    """Logarithmically spaced frequencies from ``f_lo`` to ``f_hi``.

    Parameters
    ----------
    f_lo : float
        Lowest frequency, Hz.
    f_hi : float
        Highest frequency, Hz.
    per_decade : int
        Points per decade.

    Returns
    -------
    numpy.ndarray
        The frequencies, Hz.
    """
    n = max(2, int(np.ceil(np.log10(f_hi / f_lo) * per_decade)) + 1)
    return np.geomspace(f_lo, f_hi, n)


def coherence(gxx: FloatArray, gyy: FloatArray, gxy: ComplexArray) -> FloatArray:
    """Magnitude-squared coherence |Gxy|²/(Gxx·Gyy), 0 where a spectrum vanishes.

    Parameters
    ----------
    gxx : numpy.ndarray
        Command auto-spectrum.
    gyy : numpy.ndarray
        Output auto-spectrum.
    gxy : numpy.ndarray
        Cross-spectrum.

    Returns
    -------
    numpy.ndarray
        The coherence γ², between 0 and 1.
    """
    den = gxx * gyy
    with np.errstate(divide="ignore", invalid="ignore"):
        g = np.where(den > 0.0, np.abs(gxy) ** 2 / np.where(den > 0.0, den, 1.0), 0.0)
    return np.clip(g, 0.0, 1.0)


def random_error(coh: FloatArray, averages: FloatArray | float) -> FloatArray:
    """Normalised random error of a frequency-response estimate: √(1−γ²) / (|γ|·√(2ν)).

    Parameters
    ----------
    coh : numpy.ndarray
        Coherence.
    averages : numpy.ndarray or float
        Effective number of averages.

    Returns
    -------
    numpy.ndarray
        The normalised random error.
    """
    g = np.clip(coh, 1e-6, MAX_COHERENCE)
    return np.asarray(np.sqrt(1.0 - g) / (np.sqrt(g) * np.sqrt(2.0 * np.asarray(averages, dtype=float))), dtype=float)


def _on_grid(sp: CrossSpectra, grid: FloatArray) -> tuple[FloatArray, FloatArray, ComplexArray, FloatArray]:
    """A window's spectra averaged into the grid's cells (interpolated where a cell holds no bin)."""
    ratio = grid[1] / grid[0]
    f = sp.freq_hz
    cell = np.full(f.size, -1)
    pos = f > 0
    cell[pos] = np.floor(np.log(f[pos] / grid[0]) / np.log(ratio) + 0.5).astype(int)
    inside = (cell >= 0) & (cell < grid.size)
    c = cell[inside]
    m = grid.size
    count = np.bincount(c, minlength=m).astype(float)
    have = count > 0
    safe = np.where(have, count, 1.0)

    def avg(values: FloatArray) -> FloatArray:
        out = np.bincount(c, weights=values[inside], minlength=m) / safe
        return np.where(have, out, np.interp(grid, f, values))

    gxx = avg(sp.gxx)
    gyy = np.stack([avg(row) for row in sp.gyy])
    gxy = np.stack([avg(row.real) + 1j * avg(row.imag) for row in sp.gxy])
    nu = sp.averages * np.maximum(1.0, count / HANN_ENBW_BINS)
    return gxx, gyy, gxy, nu


@dataclass(frozen=True)
class CompositeSpectra:
    """Spectra on ``freq_hz`` combined over ``windows_s``; one row per output in every array.

    Parameters
    ----------
    freq_hz : numpy.ndarray
        Frequency, Hz.
    gxx : numpy.ndarray
        (outputs, F): the command's spectrum, weighted as each output's estimate weights the windows.
    gyy : numpy.ndarray
        Output auto-spectrum.
    gxy : numpy.ndarray
        Cross-spectrum.
    averages : numpy.ndarray
        (outputs, F): effective averages behind each composite estimate.
    windows_s : tuple
        Window lengths, s.
    """

    freq_hz: FloatArray
    gxx: FloatArray
    """(outputs, F): the command's spectrum, weighted as each output's estimate weights the windows."""
    gyy: FloatArray
    gxy: ComplexArray
    averages: FloatArray
    """(outputs, F): effective averages behind each composite estimate."""
    windows_s: tuple[float, ...]


def default_windows(span_s: float, f_max_hz: float, count: int = 5) -> tuple[float, ...]:
    """Window lengths from half the record down, halving, but never below 20 periods of ``f_max_hz``.

    Parameters
    ----------
    span_s : float
        Record length, s.
    f_max_hz : float
        Top frequency, Hz.
    count : int
        Number of windows.

    Returns
    -------
    tuple
        Window lengths, s.
    """
    longest = span_s / 2.0
    shortest = max(20.0 / f_max_hz, longest / 2 ** (count - 1))
    out = [longest]
    while len(out) < count and out[-1] / 2.0 >= shortest * 0.999:
        out.append(out[-1] / 2.0)
    return tuple(out)


def composite(x: FloatArray, ys: FloatArray, fs: float, grid: FloatArray,
              windows_s: tuple[float, ...]) -> CompositeSpectra:
    """Composite-window spectra of ``x`` against each row of ``ys`` on ``grid`` (see the module docstring).

    Parameters
    ----------
    x : numpy.ndarray
        The command.
    ys : numpy.ndarray
        The outputs, one per row.
    fs : float
        Sample rate, Hz.
    grid : numpy.ndarray
        Frequency grid, Hz.
    windows_s : tuple
        Window lengths, s.

    Returns
    -------
    CompositeSpectra
        The combined spectra.
    """
    ys = np.atleast_2d(ys)
    n_out = ys.shape[0]
    sw = np.zeros((n_out, grid.size))
    sxx = np.zeros((n_out, grid.size))
    syy = np.zeros((n_out, grid.size))
    sxy = np.zeros((n_out, grid.size), dtype=complex)
    snu = np.zeros((n_out, grid.size))
    for win in windows_s:
        sp = welch(x, ys, fs, win)
        gxx, gyy, gxy, nu = _on_grid(sp, grid)
        valid = grid >= 2.0 / sp.window_s
        for i in range(n_out):
            coh = coherence(gxx, gyy[i], gxy[i])
            eps = random_error(coh, nu)
            w = np.where(valid & (gxx > 0), 1.0 / (eps * eps), 0.0)
            sw[i] += w
            sxx[i] += w * gxx
            syy[i] += w * gyy[i]
            sxy[i] += w * gxy[i]
            snu[i] = np.maximum(snu[i], np.where(valid, nu, 0.0))
    safe = np.where(sw > 0, sw, 1.0)
    return CompositeSpectra(grid, sxx / safe, syy / safe, np.asarray(sxy / safe, dtype=complex), snu, tuple(windows_s))


def dft_at(x: FloatArray, fs: float, f0_hz: float, df_hz: float, m: int) -> ComplexArray:
    """``Σₙ x[n]·exp(−2πj·fₖ·n/fs)`` at ``fₖ = f0 + k·df``, k < m, by the chirp-z transform.

    Parameters
    ----------
    x : numpy.ndarray
        The signal.
    fs : float
        Sample rate, Hz.
    f0_hz : float
        First frequency, Hz.
    df_hz : float
        Frequency step, Hz.
    m : int
        Number of frequencies.

    Returns
    -------
    numpy.ndarray
        The DFT at each frequency.
    """
    from scipy.signal import czt  # noqa: PLC0415 - scipy.signal loads in ~0.5 s; only the zoom DFT needs it

    w = np.exp(-2j * np.pi * df_hz / fs)
    a = np.exp(2j * np.pi * f0_hz / fs)
    return np.asarray(czt(np.asarray(x, dtype=float), m, w, a), dtype=complex)
