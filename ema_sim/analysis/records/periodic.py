"""Periodic commands: repeated cycles recognised by their period, and the waveform they repeat.

A bench drives an actuator through a periodic demand far more often than through a sweep: a square
wave (straight or through the drive's profile generator), a trapezoid, a triangle, a sine, repeated
for a few cycles. Cut into pieces, five identical cycles read as unrelated tests (a move here, a
"triangle" there, a "broadband" tail); read as what they are, they are one test measured five times,
and the spread from cycle to cycle is the uncertainty of every figure (:mod:`ema_sim.analysis.section2.cycles`).

:func:`find_periodic` reads them off the command:

1. the command is split where it holds still for :data:`SPLIT_S` or more (one test's cycles never
   rest that long); each active stretch is searched for a period: the first peak of its
   autocorrelation (mean removed, unbiased) that reaches :data:`MIN_CORRELATION`, refined to a
   twentieth of a sample where the command best repeats itself one period later (within 3 %);
2. the stretch is cut at that period, from each of :data:`PHASES` start phases; a cycle *matches*
   when 90 % of its samples lie within :data:`MATCH` of the command's peak-to-peak of the median
   cycle (a square's edge falls on a different sample from cycle to cycle, hence the percentile);
   the cut is then moved to start every cycle where the median cycle is quietest (the middle of a
   dwell), so a lead-in's half swing makes no cycle of its own;
   the longest run of matching cycles, at least :data:`MIN_CYCLES` of them and covering at least
   :data:`COVER` of the stretch from the command's first departure to its last change, is the
   periodic test;
3. the median cycle's **shape** is named: ``sine`` (its fundamental explains 99.9 % of it, or 99 %
   without sitting still for a tenth of the cycle at its extremes, as a trapezoid does), ``triangle``
   (no dwell, constant speed), ``square`` (two dwell levels joined by edges of at most
   :data:`EDGE_S` or :data:`EDGE_SAMPLES` samples), ``trapezoid`` (two dwells joined by constant-speed
   ramps) or ``profiled square`` (two dwells joined by moves that accelerate, cruise and decelerate),
   else ``other``;
4. its **harmonics**: the median cycle's Fourier amplitudes; a harmonic is *in* the waveform when it
   reaches :data:`EXCITED` of the largest (a square's 1/k, a triangle's 1/k²), and the waveform is
   *odd-harmonic only* when every even harmonic stays under :data:`EVEN_SHARE` of the largest (a
   half-wave symmetric wave: its even "harmonics" in any response are the output's, not the input's).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ema_sim.analysis.records import series

FloatArray = NDArray[np.float64]

SPLIT_S = 3.0
"""A command still for this long separates two tests."""
MIN_CYCLES = 3
"""Fewest matching cycles that make a periodic test."""
COVER = 0.6
"""The matching cycles cover this share of their stretch's motion (a tone whose amplitude grows has a few
middle cycles that match each other, and is no periodic test)."""
MIN_CORRELATION = 0.8
"""The period's autocorrelation peak reaches this."""
MATCH = 0.05
"""A cycle's 90th-percentile departure from the median cycle, as a share of its peak to peak."""
PHASES = 16
"""Start phases tried when cutting the stretch into cycles."""
REFINE_POINTS = 4000
"""Samples of a stretch the period's refinement compares (a long stretch is thinned)."""
MIN_PERIOD_S = 0.1
MIN_PERIOD_SAMPLES = 8
EDGE_S = 0.02
"""A transition this short (plus a sample) is an edge (a step), not a move."""
EDGE_SAMPLES = 4
"""...and so is one of this few samples (too few to tell a profile's acceleration from its cruise)."""
DWELL = 0.02
"""A sample within this share of the peak to peak of an extreme is dwelling there."""
MIN_DWELL_SHARE = 0.1
SINE_R2 = 0.99
"""A fundamental explaining this share of a cycle that does not sit still at its extremes makes a sine..."""
SINE_R2_ALONE = 0.999
"""...and this share makes one whatever it does (a trapezoid's fundamental explains up to 99.8 %)."""
STEADY_SPEED_CV = 0.15
CRUISE = 0.6
"""A ramp within 20 % of its (90th-percentile) top speed this share of its time is a trapezoid's (else a profile's
move, which spends much of its time accelerating)."""
EXCITED = 0.02
"""A harmonic at this share of the largest one is in the waveform."""
EVEN_SHARE = 0.01
"""Even harmonics all under this share of the largest: an odd-harmonic-only (half-wave symmetric) waveform."""


@dataclass(frozen=True)
class Periodicity:
    """A run of matching cycles of the command, and the waveform it repeats.

    Parameters
    ----------
    start : int
        First sample of the first whole cycle.
    stop : int
        One past the last sample of the last whole cycle.
    period_samples : float
        The period in samples (a fraction of a sample resolved).
    dt : float
        Sample interval, s.
    cycles : int
        Whole matching cycles.
    shape : str
        ``sine``, ``triangle``, ``square``, ``trapezoid``, ``profiled square`` or ``other``.
    amplitude : float
        Half the median cycle's peak to peak.
    centre : float
        The median cycle's mid level.
    template : numpy.ndarray
        The median cycle, on ``round(period_samples)`` phase points from the first cycle's start.
    harmonic_amplitudes : numpy.ndarray
        Amplitude of the median cycle's harmonics 1, 2, ... (index 0 is harmonic 1).
    mismatch : float
        The worst matching cycle's 90th-percentile departure from the median cycle, share of the peak to peak.
    """

    start: int
    stop: int
    period_samples: float
    dt: float
    cycles: int
    shape: str
    amplitude: float
    centre: float
    template: FloatArray
    harmonic_amplitudes: FloatArray
    mismatch: float

    @property
    def period_s(self) -> float:
        """The period, s."""
        return self.period_samples * self.dt

    @property
    def freq_hz(self) -> float:
        """The fundamental, Hz."""
        return 1.0 / self.period_s

    @property
    def harmonics(self) -> tuple[int, ...]:
        """Harmonic numbers in the waveform (module docstring)."""
        a = self.harmonic_amplitudes
        if a.size == 0:
            return ()
        return tuple(int(k) + 1 for k in np.flatnonzero(a >= EXCITED * float(np.max(a))))

    @property
    def odd_only(self) -> bool:
        """True when the waveform carries odd harmonics only (half-wave symmetric), more than one of them."""
        a = self.harmonic_amplitudes
        if a.size < 2:
            return False
        even = a[1::2]
        odd = [k for k in self.harmonics if k % 2 == 1]
        return bool(np.all(even < EVEN_SHARE * float(np.max(a)))) and len(odd) > 1

    @property
    def harmonic_statement(self) -> str:
        """Which harmonics the waveform carries, in words."""
        ks = self.harmonics
        if len(ks) == 1:
            return f"a single frequency, {ks[0] * self.freq_hz:.4g} Hz"
        listed = ", ".join(str(k) for k in ks[:8]) + ("..." if len(ks) > 8 else "")
        top = ks[-1] * self.freq_hz
        odd = "odd harmonics only (half-wave symmetric: even harmonics in a response are the output's own)" \
            if self.odd_only else "harmonics"
        return f"{odd} {listed} of {self.freq_hz:.4g} Hz, up to {top:.4g} Hz"

    @property
    def evidence(self) -> str:
        """What it was recognised from, in one line."""
        return (f"periodic {self.shape} ±{self.amplitude:.4g} about {self.centre:.4g}, period {self.period_s:.4g} s, "
                f"{self.cycles} matching cycles (each within {100 * self.mismatch:.1f} % of the median cycle); "
                f"{self.harmonic_statement}")

    def cycle_starts(self) -> FloatArray:
        """Each whole cycle's start, in (fractional) samples.

        Returns
        -------
        numpy.ndarray
            ``cycles`` start positions.
        """
        return np.asarray(self.start + self.period_samples * np.arange(self.cycles), dtype=float)

    def params(self) -> dict[str, float]:
        """The segment parameters it adds (``cycles`` marks a periodic segment).

        Returns
        -------
        dict
            Period, frequency, cycles, amplitude, centre.
        """
        return {"period_s": self.period_s, "freq_hz": self.freq_hz, "cycles": float(self.cycles),
                "amp_deg": self.amplitude, "centre_deg": self.centre}


def _cycles(u: FloatArray, start: float, period: float, n: int, m: int) -> FloatArray:
    """``n`` cycles of ``u`` from ``start`` (fractional samples), each on ``m`` phase points (linear interpolation)."""
    pos = start + period * (np.arange(n)[:, None] + np.arange(m)[None, :] / m)
    return np.asarray(np.interp(pos, np.arange(u.size), u), dtype=float)


def _mismatch(cyc: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Each cycle's 90th-percentile departure from the median cycle (share of its peak to peak), and that cycle."""
    template = np.median(cyc, axis=0)
    span = max(float(np.ptp(template)), 1e-12)
    return np.percentile(np.abs(cyc - template), 90, axis=1) / span, template


def _longest_run(ok: NDArray[np.bool_]) -> tuple[int, int]:
    best, cur, best_end = 0, 0, 0
    for i, v in enumerate(ok):
        cur = cur + 1 if v else 0
        if cur > best:
            best, best_end = cur, i + 1
    return best_end - best, best_end


def _first_period(u: FloatArray, dt: float) -> float | None:
    """The lag (samples, refined parabolically) of the first autocorrelation peak reaching MIN_CORRELATION."""
    n = u.size
    lo = max(MIN_PERIOD_SAMPLES, round(MIN_PERIOD_S / dt))
    hi = n // MIN_CYCLES + 1
    if hi <= lo + 2:
        return None
    x = u - np.mean(u)
    nfft = 1 << int(np.ceil(np.log2(2 * n - 1)))
    f = np.fft.rfft(x, nfft)
    acov = np.fft.irfft(f * np.conj(f), nfft)[: hi + 1]
    if acov[0] <= 0:
        return None
    rho = acov / acov[0] / (1.0 - np.arange(hi + 1) / n)
    peaks = [i for i in range(lo, hi) if rho[i] >= rho[i - 1] and rho[i] >= rho[i + 1] and rho[i] >= MIN_CORRELATION]
    if not peaks:
        return None
    top = max(rho[i] for i in peaks)
    i = next(i for i in peaks if rho[i] >= 0.95 * top)
    den = rho[i - 1] - 2 * rho[i] + rho[i + 1]
    return float(i + (0.5 * (rho[i - 1] - rho[i + 1]) / den if den < 0 else 0.0))


def _cut(u: FloatArray, period: float, phases: FloatArray | None = None) -> tuple[float, int, int, float] | None:
    """The best start phase: (start, first matching cycle, matching cycles, worst mismatch) over PHASES starts."""
    m = round(period)
    best: tuple[float, int, int, float] | None = None
    for ph in (np.arange(PHASES) / PHASES if phases is None else phases):
        start = ph * period
        n = int(np.floor((u.size - 1 - start) / period))
        if n < MIN_CYCLES:
            continue
        mis, _ = _mismatch(_cycles(u, start, period, n, m))
        a, b = _longest_run(mis <= MATCH)
        if b - a < MIN_CYCLES:
            continue
        worst = float(np.max(mis[a:b]))
        if best is None or b - a > best[2] or (b - a == best[2] and worst < best[3]):
            best = (start, a, b - a, worst)
    return best


def _quietest(template: FloatArray) -> int:
    """The phase point at the middle of the cycle's quietest tenth (least total change, circularly)."""
    m = template.size
    change = np.abs(np.diff(np.concatenate([template, template[:1]])))
    w = max(1, m // 10)
    window = np.convolve(np.concatenate([change, change[:w]]), np.ones(w), mode="valid")[:m]
    return int((int(np.argmin(window)) + w // 2) % m)


def _repeat_error(u: FloatArray, lag: float, idx: FloatArray) -> float:
    """Mean |u(i + lag) − u(i)| over the indices ``idx`` that stay inside the stretch."""
    keep = idx + lag <= u.size - 1
    if not keep.any():
        return float("inf")
    return float(np.mean(np.abs(np.interp(idx[keep] + lag, np.arange(u.size), u) - np.interp(idx[keep],
                                                                                          np.arange(u.size), u))))


def _refine(u: FloatArray, period: float) -> float:
    """The lag near ``period`` (±3 %, ±2 samples at least) at which the command best repeats itself.

    Best: the least mean |u(i + P) − u(i)|, over whole samples first, then to a twentieth of a sample
    about the best (on at most :data:`REFINE_POINTS` samples of the stretch).
    """
    idx = np.arange(0, u.size, max(1, u.size // REFINE_POINTS), dtype=float)
    reach = max(2, int(np.ceil(0.03 * period)))
    coarse = np.round(period) + np.arange(-reach, reach + 1)
    coarse = coarse[coarse >= 1]
    best = float(coarse[int(np.argmin([_repeat_error(u, float(p), idx) for p in coarse]))])
    fine = best + np.arange(-1.0, 1.0 + 1e-9, 0.05)
    return float(fine[int(np.argmin([_repeat_error(u, float(p), idx) for p in fine]))])


def _runs_circular(mask: NDArray[np.bool_]) -> list[tuple[int, int]]:
    """Runs [a, b) of True in a circular mask (b may exceed its length: the run wraps)."""
    n = mask.size
    if mask.all():
        return [(0, n)]
    if not mask.any():
        return []
    shift = int(np.flatnonzero(~mask)[0])
    rolled = np.roll(mask, -shift)
    padded = np.concatenate([[False], rolled, [False]])
    d = np.flatnonzero(np.diff(padded.astype(np.int8)))
    return [(int(a) + shift, int(b) + shift) for a, b in zip(d[::2], d[1::2], strict=True)]


def dwell_runs(template: FloatArray, tol: float) -> tuple[list[tuple[int, int]], list[tuple[int, int]]]:
    """The median cycle's dwells at its top and at its bottom, as circular runs of phase points.

    Parameters
    ----------
    template : numpy.ndarray
        The median cycle.
    tol : float
        How far the command may wander and still count as held.

    Returns
    -------
    tuple
        Runs at the top and at the bottom, each ``(a, b)`` with ``b`` possibly past the cycle's end.
    """
    lo, hi = float(np.min(template)), float(np.max(template))
    band = max(DWELL * (hi - lo), tol)
    return _runs_circular(template >= hi - band), _runs_circular(template <= lo + band)


def _shape(template: FloatArray, amps: FloatArray, dt: float, tol: float) -> str:
    """The waveform's name (module docstring)."""
    m = template.size
    top, bottom = dwell_runs(template, tol)
    dwelling = sum(b - a for a, b in top + bottom) / m
    speed = np.abs(np.diff(np.concatenate([template, template[:1]])))
    r2 = float(amps[0] ** 2 / max(np.sum(amps**2), 1e-300)) if amps.size else 0.0
    near = np.zeros(m, dtype=bool)
    for a, b in top + bottom:
        near[np.arange(a, b) % m] = True
    flat = float(np.mean(near & (speed <= max(tol, 1e-3 * float(np.max(speed))))))
    if r2 >= SINE_R2_ALONE or (r2 >= SINE_R2 and flat < MIN_DWELL_SHARE):
        return "sine"
    if dwelling < MIN_DWELL_SHARE:
        moving = speed[speed > 0.05 * float(np.max(speed))]
        core = np.sort(moving)[int(0.1 * moving.size): max(int(0.9 * moving.size), 1)]
        steady = core.size > 3 and float(np.std(core) / np.mean(core)) < STEADY_SPEED_CV
        return "triangle" if steady else "other"
    if len(top) != 1 or len(bottom) != 1:
        return "other"
    (a1, b1), (a0, b0) = top[0], bottom[0]
    # the two transitions: bottom's end to top's start, top's end to bottom's start (circular lengths)
    rise = (a1 - b0) % m
    fall = (a0 - b1) % m
    if max(rise, fall) <= max(EDGE_S / dt + 1.0, EDGE_SAMPLES):
        return "square"
    shares = []
    for a, n in ((b0, rise), (b1, fall)):
        seg = speed[(a + np.arange(n)) % m]
        if seg.size:
            shares.append(float(np.mean(seg >= 0.8 * float(np.percentile(seg, 90)))))
    return "trapezoid" if shares and min(shares) >= CRUISE else "profiled square"


def _harmonics(template: FloatArray, k_max: int) -> FloatArray:
    """Amplitudes of the median cycle's harmonics 1…k_max (it spans exactly one period)."""
    c = np.fft.rfft(template - np.mean(template)) * 2.0 / template.size
    return np.abs(c[1: k_max + 1])


def _active_stretches(u: FloatArray, dt: float, tol: float) -> list[tuple[int, int]]:
    """Stretches of the command between holds of SPLIT_S or more."""
    rests = series.holds(u, max(2, round(SPLIT_S / dt)), tol)
    edges = [0]
    for h in rests:
        edges += [h.start, h.stop]
    edges.append(u.size)
    return [(a, b) for a, b in zip(edges[::2], edges[1::2], strict=True) if b - a > 2 * MIN_PERIOD_SAMPLES]


def find_periodic(t: FloatArray, u: FloatArray, tol: float) -> list[Periodicity]:
    """Every run of at least :data:`MIN_CYCLES` matching cycles of the command (module docstring).

    Parameters
    ----------
    t : numpy.ndarray
        Time, s (uniform).
    u : numpy.ndarray
        The command.
    tol : float
        How far the command may wander and still count as held (its noise, or the rounding of a digital one).

    Returns
    -------
    list of Periodicity
        In time order.
    """
    dt = float(np.median(np.diff(t)))
    out = []
    for a, b in _active_stretches(u, dt, tol):
        seg = u[a:b]
        if float(np.ptp(seg)) <= 10.0 * tol:
            continue
        period = _first_period(seg, dt)
        if period is None:
            continue
        period = _refine(seg, period)
        cut = _cut(seg, period)
        if cut is None:
            continue
        start, first, n, worst = cut
        moved = np.flatnonzero(np.abs(seg - seg[0]) > tol)
        settled = np.flatnonzero(np.abs(seg - seg[-1]) > tol)
        motion = (int(settled[-1]) - int(moved[0]) + 1) if moved.size and settled.size else seg.size
        if n * period < COVER * motion:
            continue
        start += first * period
        m = round(period)
        _, template = _mismatch(_cycles(seg, start, period, n, m))
        # Cut again with every cycle starting where the waveform is quietest (the middle of a dwell, a sine's
        # peak): a cycle that begins with the lead-in's half swing then no longer matches.
        quiet = _quietest(template)
        recut = _cut(seg, period, np.array([((start + quiet * period / m) / period) % 1.0]))
        if recut is None:
            continue
        start, first, n, worst = recut
        if n * period < COVER * motion:
            continue
        start += first * period
        _, template = _mismatch(_cycles(seg, start, period, n, m))
        k_max = max(1, min(m // 2 - 1, int(period / 4.0)))
        amps = _harmonics(template, k_max)
        lo = a + round(start)
        hi = min(b, a + round(start + n * period))
        out.append(Periodicity(lo, hi, period, dt, n, _shape(template, amps, dt, tol),
                               0.5 * float(np.ptp(template)), 0.5 * float(np.max(template) + np.min(template)),
                               template, amps, worst))
    return out
