"""Measurement noise and residual tests: the noise floor of a record, whiteness, independence from the input.

Used by the offline analysis (`ema analyze`) to set detection thresholds and by model identification
(`ema identify`) to judge its residuals:

* :func:`noise_floor` estimates the white sensor noise of a signal without a model, from fourth
  differences: at a sample rate well above the signal's bandwidth, ``Δ⁴y`` keeps only (ωT)⁴ of
  the signal (an 18 Hz sweep at 1 kHz leaves 1.6e-4 of it, where a second difference would leave
  1.3e-2, comparable to the noise) and multiplies the noise variance by 70. The median absolute
  deviation makes the estimate ignore the few samples at steps and edges.
* :func:`detect_resolution` finds the step of an output logged in counts (a position written in
  hundredths of a degree, a 5 mV A/D converter through its calibration): every change of such a
  signal is a whole number of counts. :func:`output_noise` is the floor a record can resolve:
  the white noise, but never less than the counts' own quantization error ``q/√12`` (a still output
  that reads the same count for seconds has a fourth-difference MAD of zero, not a zero floor). When
  the changes tell nothing (a drive that moves two counts at a time), the values themselves are
  read for a count grid (:func:`ema_sim.analysis.estimation.grid.value_grid`).
* :func:`with_rests` takes the floor where the output cannot move: the record's rests
  (:mod:`ema_sim.analysis.estimation.rests`), quiet ones only. Where the record's own estimate stands over
  theirs, the difference is motion's (not noise) and the rests' floor is taken; where no rest is quiet
  (every rest hunts, or the output never rests) the record's estimate is kept as an upper bound. What the
  rests show (a limit cycle, a floor that grows with the excitation) is said beside it (:meth:`NoiseFloor.findings`).
* :func:`whiteness` is the Ljung-Box portmanteau test on the residual's autocorrelation.
* :func:`input_independence` tests the residual's cross-correlation with the input (a model that
  explains everything leaves a residual uncorrelated with the input at every lag); the band holds
  all 2L + 1 lags at once with 99 % probability (Bonferroni).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from ema_sim.analysis.estimation.grid import CHANCE, Grid, value_grid
from ema_sim.analysis.estimation.rests import REST_EXCESS, Rests, read_rests

FloatArray = NDArray[np.float64]

MAD_TO_SIGMA = 1.4826
"""Median absolute deviation of Gaussian noise times this is its standard deviation."""
COUNT_TOLERANCE = 0.1
"""A change within this share of a count of a whole number of counts is a whole number of counts."""
COUNT_SHARE = 0.9
"""Share of the small changes that must be whole numbers of counts for a signal to be logged in counts."""
MIN_COUNT_CHANGES = 20
"""Changes of at most ten counts needed before a resolution is claimed."""
COMMAND_COUNTS_SPANNED = 100.0
"""A command's count is a fine grid: the command spans at least this many (a staircase's step is no count)."""


def noise_floor(y: FloatArray) -> float:
    """Standard deviation of the white noise on a signal, from the MAD of its fourth differences.

    Parameters
    ----------
    y : numpy.ndarray
        The signal, uniformly sampled.

    Returns
    -------
    float
        The white-noise standard deviation (0 for fewer than 6 samples). It knows nothing of the
        signal's resolution: :func:`output_noise` adds that.
    """
    y = np.asarray(y, dtype=float)
    if y.size < 6:
        return 0.0
    d4 = np.diff(y, 4)
    return float(MAD_TO_SIGMA * np.median(np.abs(d4 - np.median(d4))) / np.sqrt(70.0))


FLAT_SHARE = 0.2
"""A continuous signal whose fourth differences are exactly zero this often has flat stretches that are no noise."""


def _unclipped_floor(y: FloatArray, white: float) -> float:
    """:func:`noise_floor` without the stretches where a continuous signal repeats itself exactly.

    A signal logged with no counts never repeats a value by chance: a run of identical samples is a sensor
    at its saturation, a clipped log or a stuck reading, and its zero differences would pull the noise
    estimate down by as much as the share of the record they fill. When over :data:`FLAT_SHARE` of the
    fourth differences are exactly zero, the floor is taken from the others.
    """
    d4 = np.diff(np.asarray(y, dtype=float), 4)
    moving = d4[d4 != 0.0]
    if d4.size == 0 or moving.size < 6 or moving.size > (1.0 - FLAT_SHARE) * d4.size:
        return white
    return float(MAD_TO_SIGMA * np.median(np.abs(moving - np.median(moving))) / np.sqrt(70.0))


def detect_resolution(y: FloatArray, min_span: float = 0.0) -> float | None:
    """The count a signal is logged in, when every change of it is a whole number of counts.

    The smallest changes of a signal in counts are one count; a continuous signal's smallest changes
    are arbitrarily small and its small changes are no multiples of anything. The count is the 1st
    percentile of the non-zero changes (robust to a stray rounding glitch), accepted when at least
    90 % of the changes of up to ten counts lie within 0.1 count of a whole number (a calibration
    curve between the counts and the degrees may stretch the count by a few per cent; ten counts
    keep that inside the tolerance) and there are at least 20 of them; a signal that mostly rests
    and jumps (a square wave) has its changes of up to 1000 counts tested instead.

    Parameters
    ----------
    y : numpy.ndarray
        The signal as logged.
    min_span : float
        How many counts the signal must span: 0 for an output (a still one toggling a single count is
        logged in counts all the same), 100 for a command, whose staircase's step is no count.

    Returns
    -------
    float or None
        The count in the signal's unit, or None when the signal is continuous or too still to tell.
    """
    y = np.asarray(y, dtype=float)
    if y.size < 3:
        return None
    scale = max(1.0, float(np.max(np.abs(y))))
    d = np.abs(np.diff(y))
    nz = d[d > 1e-7 * scale]
    if nz.size < MIN_COUNT_CHANGES:
        return None
    span = float(np.ptp(y))
    for q in sorted({float(np.min(nz)), float(np.percentile(nz, 1.0))}):
        count = _whole_counts(nz, q)
        if count is not None and span >= min_span * count:
            return count
    return None


def _whole_counts(changes: FloatArray, q: float) -> float | None:
    """``q`` refined, when the changes are whole numbers of ``q`` (see :func:`detect_resolution`)."""
    ratio = changes / q
    small = ratio[ratio < 10.5]
    if small.size < MIN_COUNT_CHANGES:  # a signal that mostly rests or jumps: its jumps must be whole counts
        small = ratio[ratio < 1000.5]
    if small.size < MIN_COUNT_CHANGES:
        return None
    whole = np.abs(small - np.round(small)) <= COUNT_TOLERANCE
    if float(np.mean(whole)) < COUNT_SHARE:
        return None
    ones = small[whole & (np.round(small) == 1.0)]
    if ones.size == 0:
        return None
    return float(f"{float(np.median(ones * q)):.10g}")


@dataclass(frozen=True)
class NoiseFloor:
    """The noise floor of one measured output: white noise, never below its counts' quantization.

    Parameters
    ----------
    sigma : float
        The floor: ``max(white, resolution/√12)``.
    white : float
        White noise from the fourth differences (:func:`noise_floor`).
    resolution : float or None
        The count the output is logged in (None: continuous).
    resolution_source : str
        How the count was found: ``given``, ``changes`` (every change a whole number of counts), ``values``
        (every value on the grid), or ``none``.
    basis : str
        Where the floor was read: ``record`` (the whole record's fourth differences), ``rests`` (the quiet
        rests, the record's own estimate being motion's too).
    upper_bound : bool
        No stretch where the output cannot move confirms the floor: it may hold more than noise.
    rests : Rests or None
        What the record's rests show (None: not examined, no command given).
    record_white : float or None
        The whole record's white noise when the rests' floor replaced it.
    """

    sigma: float
    """The floor: ``max(white, resolution/√12)``."""
    white: float
    """White noise from the fourth differences (:func:`noise_floor`)."""
    resolution: float | None
    """The count the output is logged in (None: continuous)."""
    resolution_source: str = "changes"
    """How the count was found: ``given``, ``changes``, ``values`` or ``none``."""
    basis: str = "record"
    """Where the floor was read: ``record`` or ``rests``."""
    upper_bound: bool = False
    """No stretch where the output cannot move confirms the floor."""
    rests: Rests | None = None
    """What the record's rests show (None: not examined)."""
    record_white: float | None = None
    """The whole record's white noise when the rests' floor replaced it."""

    @property
    def quantization(self) -> float:
        """Standard deviation of the rounding to whole counts, ``resolution/√12`` (0 when continuous)."""
        return 0.0 if self.resolution is None else self.resolution / np.sqrt(12.0)

    @property
    def limited_by_resolution(self) -> bool:
        """True when the counts, not the noise, set the floor."""
        return self.resolution is not None and self.quantization >= self.white

    def as_dict(self) -> dict[str, object]:
        """Plain values for JSON.

        Returns
        -------
        dict
            ``sigma``, ``white``, ``resolution``, ``resolution_source``, ``limited_by_resolution``, where the floor
            was read (``basis``, ``upper_bound``, ``record_white``) and what the ``rests`` show.
        """
        return {"sigma": self.sigma, "white": self.white, "resolution": self.resolution,
                "resolution_source": self.resolution_source, "limited_by_resolution": self.limited_by_resolution,
                "basis": self.basis, "upper_bound": self.upper_bound, "record_white": self.record_white,
                "rests": self.rests.as_dict() if self.rests is not None else None}

    @property
    def statement(self) -> str:
        """The floor and the count in one sentence."""
        where = ("" if self.basis == "record" else
                 f", read at rest (the whole record's {self.record_white:.3g} holds motion's too)")
        bound = ", an upper bound (no stretch where the output cannot move confirms it)" if self.upper_bound else ""
        if self.resolution is None:
            return (f"continuous (no count grid in the values or their changes), white noise {self.white:.3g}"
                    f"{where}{bound}")
        how = {"given": "given by the metadata", "changes": "every change a whole number of counts",
               "values": "every value on the grid"}.get(self.resolution_source, self.resolution_source)
        return (f"counts of {self.resolution:g} ({how}): floor {self.sigma:.3g} = max(white {self.white:.3g}, "
                f"q/√12 {self.quantization:.3g}){where}{bound}")

    def findings(self, output: str, unit: str) -> list[str]:
        """What the rests say of this floor, one sentence each: where it was read, a line at rest, a growth.

        Parameters
        ----------
        output : str
            The output's name.
        unit : str
            The record's unit (deg, mm, in).

        Returns
        -------
        list of str
            Empty when the rests were not examined or show nothing to say.
        """
        r = self.rests
        if r is None:
            return []
        u = "°" if unit == "deg" else f" {unit}"
        label = output.removesuffix("_deg")  # the channel, not a unit: an mm record's position is no degree
        out = []
        if self.basis == "rests":
            quiet = sum(x.line_hz is None for x in r.rests)
            what = "the hunting's and motion's" if r.line is not None else "motion's"
            out.append(f"{label}'s noise floor {self.sigma:.3g}{u} is read where the output cannot move ({quiet} quiet "
                       f"rest{'s' if quiet != 1 else ''}); the whole record's fourth differences give "
                       f"{self.record_white or 0.0:.3g}{u}, the difference is {what}, not noise")
        if self.upper_bound:
            out.append(f"{label}'s noise floor {self.sigma:.3g}{u} is an upper bound, not a measured noise: "
                       f"{r.why_no_quiet_rest}, so no stretch where the output cannot move shows the floor; at most "
                       "this much of a residual is noise")
        if r.line is not None:
            out.append(r.line.statement(label, unit))
        if r.growth is not None:
            out.append(r.growth.statement(label, unit, r.quiet_floor))
        return out


def sparse_multiple(q: float, grid: Grid) -> bool:
    """Whether a count read from the changes is a multiple of the values' finer grid that too few levels support.

    An output toggling between a handful of levels four counts apart changes by four counts at least:
    its smallest change is no count. When the values are written on a finer grid and so few of them
    populate the coarser one that landing on its multiples could be chance
    (:data:`ema_sim.analysis.estimation.grid.CHANCE`), the finer grid is the count.

    Parameters
    ----------
    q : float
        The count from the changes.
    grid : Grid
        The values' grid.

    Returns
    -------
    bool
        True when ``grid.q`` should be the count instead.
    """
    k = q / grid.q
    whole = k >= 1.5 and abs(k - round(k)) <= 0.01 * k
    return whole and (grid.levels - 1) * float(np.log(round(k))) < float(np.log(CHANCE))


def refines(q: float, grid: Grid) -> bool:
    """Whether the values' grid is the same count as the changes' ``q``, fitted on every value (more exact).

    A coarse count printed to a finer digit (0.0547 logged to 0.01) changes by 0.05 or 0.06: the changes, when
    they pass for whole counts at all, give one of the two; the grid fitted to the values gives the count.

    Parameters
    ----------
    q : float
        The count from the changes.
    grid : Grid
        The values' grid.

    Returns
    -------
    bool
        True when ``grid.q`` differs from ``q`` by less than a fifth of it.
    """
    return q != grid.q and abs(q - grid.q) < 0.2 * grid.q


def output_noise(y: FloatArray, resolution: float | None = None) -> NoiseFloor:
    """The noise floor of a measured output, aware of the counts it is logged in.

    Parameters
    ----------
    y : numpy.ndarray
        The output, uniformly sampled.
    resolution : float, optional
        Its count when known (a rig's data sheet); detected by :func:`detect_resolution` otherwise.

    Returns
    -------
    NoiseFloor
        ``sigma = max(white, resolution/√12)``: a position logged in counts of 0.01 has a floor of at
        least 0.0029 from the counts alone. The count comes from the signal's changes
        (:func:`detect_resolution`), else from its values (:func:`ema_sim.analysis.estimation.grid.value_grid`),
        which also win when the changes' count is a multiple of theirs that too few levels support
        (:func:`sparse_multiple`).
    """
    white = noise_floor(y)
    source = "given"
    q = float(resolution) if resolution is not None else None
    if q is None:
        q, source = detect_resolution(y), "changes"
        grid = value_grid(y)
        if grid is not None and (q is None or sparse_multiple(q, grid) or refines(q, grid)):
            q, source = grid.q, "values"
        elif q is None:
            source = "none"
            white = _unclipped_floor(y, white)
    floor = max(white, q / np.sqrt(12.0)) if q is not None else white
    return NoiseFloor(float(floor), white, q, source)


def with_rests(nf: NoiseFloor, time_s: FloatArray, command: FloatArray, y: FloatArray,
               current: FloatArray | None = None) -> NoiseFloor:
    """The floor of :func:`output_noise` read where the output cannot move (module docstring).

    Parameters
    ----------
    nf : NoiseFloor
        The floor from the whole record (:func:`output_noise`).
    time_s : numpy.ndarray
        Stamps, s.
    command : numpy.ndarray
        The command.
    y : numpy.ndarray
        The output.
    current : numpy.ndarray, optional
        The drive's current, A (None: not logged).

    Returns
    -------
    NoiseFloor
        The rests' floor (never below the counts' quantization) when the record's estimate is
        :data:`ema_sim.analysis.estimation.rests.REST_EXCESS` times over it; the record's, marked as an upper
        bound, when no rest is quiet; the record's otherwise. With what the rests show.
    """
    rests = read_rests(time_s, command, y, current, nf.resolution or 0.0)
    if rests.quiet_floor is None:
        return replace(nf, upper_bound=True, rests=rests)
    at_rest = max(rests.quiet_floor, nf.quantization)
    if nf.white > REST_EXCESS * at_rest:
        return replace(nf, sigma=float(at_rest), white=rests.quiet_floor, basis="rests", rests=rests,
                       record_white=nf.white)
    return replace(nf, rests=rests)


def autocovariance(x: FloatArray, max_lag: int) -> FloatArray:
    """Biased autocovariance r(k), k = 0…max_lag, by FFT (for coloured-residual covariances).

    Parameters
    ----------
    x : numpy.ndarray
        The signal.
    max_lag : int
        The largest lag, samples.

    Returns
    -------
    numpy.ndarray
        The autocovariance r(0) … r(max_lag).
    """
    x = np.asarray(x, dtype=float) - np.mean(x)
    n = x.size
    max_lag = min(int(max_lag), n - 1)
    nfft = 1 << int(np.ceil(np.log2(2 * n - 1)))
    f = np.fft.rfft(x, nfft)
    return np.fft.irfft(f * np.conj(f), nfft)[: max_lag + 1] / n


def autocorrelation(x: FloatArray, max_lag: int | None = None) -> FloatArray:
    """Normalised autocorrelation ρ(k), k = 0…max_lag, biased estimator (ρ(0) = 1), by FFT.

    Parameters
    ----------
    x : numpy.ndarray
        The signal.
    max_lag : int or None
        The largest lag, samples.

    Returns
    -------
    numpy.ndarray
        The autocorrelation ρ(0) … ρ(max_lag).
    """
    x = np.asarray(x, dtype=float) - np.mean(x)
    n = x.size
    max_lag = n - 1 if max_lag is None else min(int(max_lag), n - 1)
    nfft = 1 << int(np.ceil(np.log2(2 * n - 1)))
    f = np.fft.rfft(x, nfft)
    acov = np.fft.irfft(f * np.conj(f), nfft)[: max_lag + 1] / n
    return acov / acov[0] if acov[0] > 0 else np.zeros(max_lag + 1)


def cross_correlation(x: FloatArray, y: FloatArray, max_lag: int) -> tuple[NDArray[np.int64], FloatArray]:
    """Normalised cross-correlation r_xy(k) = E[x(t)·y(t+k)], k = −max_lag…max_lag, by FFT.

    Parameters
    ----------
    x : numpy.ndarray
        The signal.
    y : numpy.ndarray
        The other signal.
    max_lag : int
        The largest lag, samples.

    Returns
    -------
    tuple
        The lags and r_xy at each.
    """
    x = np.asarray(x, dtype=float) - np.mean(x)
    y = np.asarray(y, dtype=float) - np.mean(y)
    n = x.size
    max_lag = min(int(max_lag), n - 1)
    nfft = 1 << int(np.ceil(np.log2(2 * n - 1)))
    c = np.fft.irfft(np.conj(np.fft.rfft(x, nfft)) * np.fft.rfft(y, nfft), nfft)
    norm = np.sqrt(np.sum(x * x) * np.sum(y * y))
    lags = np.arange(-max_lag, max_lag + 1)
    vals = np.concatenate([c[nfft - max_lag:], c[: max_lag + 1]])
    return lags, (vals / norm if norm > 0 else np.zeros_like(vals))


@dataclass(frozen=True)
class WhitenessTest:
    """Ljung-Box test of a residual for whiteness.

    Parameters
    ----------
    lags : int
        Number of lags tested.
    q_statistic : float
        Ljung-Box Q.
    p_value : float
        Its p-value.
    fraction_outside : float
        Share of the lags 1…``lags`` whose |ρ| exceeds the 95 % band 1.96/√N.
    white : bool
        True when the test does not reject whiteness at the 5 % level.
    """

    lags: int
    q_statistic: float
    p_value: float
    fraction_outside: float
    """Share of the lags 1…``lags`` whose |ρ| exceeds the 95 % band 1.96/√N."""
    white: bool
    """True when the test does not reject whiteness at the 5 % level."""

    def as_dict(self) -> dict[str, float | int | bool]:
        """Plain values for JSON.

        Returns
        -------
        dict
            Plain values for JSON.
        """
        return {"lags": self.lags, "q_statistic": self.q_statistic, "p_value": self.p_value,
                "fraction_outside_95": self.fraction_outside, "white": self.white}


def whiteness(residual: FloatArray, lags: int = 20, fitted_params: int = 0) -> WhitenessTest:
    """Ljung-Box Q = N(N+2)·Σ ρ(k)²/(N−k) over ``lags`` lags, χ² with ``lags − fitted_params`` dof.

    Parameters
    ----------
    residual : numpy.ndarray
        The residual.
    lags : int
        Number of lags tested.
    fitted_params : int
        Parameters the model fitted (degrees of freedom lost).

    Returns
    -------
    WhitenessTest
        The test.
    """
    from scipy.stats import chi2  # noqa: PLC0415 - scipy.stats loads in ~0.5 s; only the whiteness test needs it

    r = np.asarray(residual, dtype=float)
    n = r.size
    lags = max(1, min(int(lags), n // 4))
    rho = autocorrelation(r, lags)[1:]
    k = np.arange(1, lags + 1)
    q = float(n * (n + 2) * np.sum(rho * rho / (n - k)))
    dof = max(1, lags - int(fitted_params))
    p = float(chi2.sf(q, dof))
    outside = float(np.mean(np.abs(rho) > 1.96 / np.sqrt(n)))
    return WhitenessTest(lags, q, p, outside, p >= 0.05)


@dataclass(frozen=True)
class IndependenceTest:
    """Whether a residual is uncorrelated with the input at every lag up to ``max_lag``.

    Parameters
    ----------
    max_lag : int
        The largest lag, samples.
    peak_correlation : float
        Largest cross-correlation.
    peak_lag : int
        Its lag, samples.
    bound : float
        The band uncorrelated sequences stay inside at every lag with 99 % probability (Bonferroni over the lags).
    independent : bool
        Whether every lag stays inside the band.
    """

    max_lag: int
    peak_correlation: float
    peak_lag: int
    bound: float
    """The band uncorrelated sequences stay inside at every lag with 99 % probability (Bonferroni over the lags)."""
    independent: bool

    def as_dict(self) -> dict[str, float | int | bool]:
        """Plain values for JSON.

        Returns
        -------
        dict
            Plain values for JSON.
        """
        return {"max_lag": self.max_lag, "peak_correlation": self.peak_correlation, "peak_lag": self.peak_lag,
                "bound_99_all_lags": self.bound, "independent": self.independent}


def input_independence(residual: FloatArray, u: FloatArray, max_lag: int = 50) -> IndependenceTest:
    """Cross-correlation of the input ``u`` (prewhitened by differencing) with the residual.

    Differencing the input removes its own strong low-frequency autocorrelation, which would widen
    the band of a raw cross-correlation far beyond 2.58/√N.

    Parameters
    ----------
    residual : numpy.ndarray
        The residual.
    u : numpy.ndarray
        The command, deg.
    max_lag : int
        The largest lag, samples.

    Returns
    -------
    IndependenceTest
        The test.
    """
    from scipy.stats import norm  # noqa: PLC0415 - scipy.stats loads in ~0.5 s; only this test needs it

    du = np.diff(np.asarray(u, dtype=float))
    r = np.asarray(residual, dtype=float)[1:]
    n = r.size
    bound = float(norm.isf(0.005 / (2 * max_lag + 1))) / np.sqrt(max(n, 1))
    if np.allclose(du, 0.0):
        return IndependenceTest(max_lag, 0.0, 0, bound, True)
    lags, c = cross_correlation(du, r, max_lag)
    i = int(np.argmax(np.abs(c)))
    return IndependenceTest(int(max_lag), float(c[i]), int(lags[i]), float(bound), bool(abs(c[i]) <= bound))
