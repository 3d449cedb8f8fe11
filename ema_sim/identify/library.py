"""The candidate terms a residual is regressed on when no named effect explains it.

The library is built from the record and the current model, not from the effect vocabulary: the
command, the model's output and its rate and acceleration (the model's, not the measured ones, so
the regressors carry no measurement noise), the hinge moment, the direction of motion, powers of the
position (a kinematic nonlinearity or an asymmetric spring), the speed's magnitude (a direction
asymmetry) and square, time (drift), the tones the residual's own spectrum shows (never one the demand
carries: a line at a harmonic of a periodic command is the model's error repeating with each cycle, a
dynamics it lacks, not a pickup or a mode, and fitting it on the reading would be a proxy), and products of
the motion signals (a drag that grows with the position or the load, a compliance that changes across
the travel). Each term says what a residual of its shape is (:attr:`Term.meaning`) and where it can
act: on a reading only (``sensor``: a tone, a drift), on the actuator's motion (``motion``: a drag, a
compliance), or either (``either``: an offset, a gain, a position nonlinearity).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from ema_sim.identify.regression import CONSTANT, Term

FloatArray = NDArray[np.float64]
DEADBAND = 0.01
"""Below this share of its 99th percentile, the rate counts as at rest (the direction of motion is 0)."""
MAX_TONES = 2
TONE_PROMINENCE = 20.0
"""A spectral line counts as a tone when its power is this many times the median around it."""
MIN_TONE_HZ = 0.5
COMMAND_LINE = 10.0
"""The command carries a line when its power there is this many times the median around it."""
LINE_DEPTH = 1e-4
"""A command line counts within 40 dB of the command's strongest."""
PERIODIC = 0.9
"""A command that correlates this well with itself one period later is periodic."""
LOCK_BINS = 2.0
"""A tone within this many spectral bins of a command line, or of a harmonic of its strongest, is locked to it."""


def _column(x: FloatArray) -> FloatArray:
    return np.asarray(x, dtype=float).reshape(-1, 1)


def _term(name: str, x: FloatArray, unit: str, meaning: str, kind: str) -> Term:
    return Term(name, _column(x), unit, meaning, kind, np.asarray(x, dtype=float))


def _direction(rate: FloatArray) -> FloatArray:
    peak = float(np.percentile(np.abs(rate), 99)) if rate.size else 0.0
    return np.where(np.abs(rate) > DEADBAND * max(peak, 1e-12), np.sign(rate), 0.0)


def tones(residual: FloatArray, time_s: FloatArray, limit: int = MAX_TONES) -> list[float]:
    """Frequencies of the narrow lines in a residual's spectrum, strongest first (Hz).

    Parameters
    ----------
    residual : numpy.ndarray
        The residual.
    time_s : numpy.ndarray
        Its sample times (uniform or nearly so; each line is refined on the times themselves).
    limit : int
        Most lines returned.

    Returns
    -------
    list of float
        Each line's frequency, refined by least squares on the sample times.
    """
    n = residual.size
    if n < 64:
        return []
    dt = float(np.median(np.diff(time_s)))
    e = residual - np.mean(residual)
    spec = np.abs(np.fft.rfft(e * np.hanning(n))) ** 2
    freqs = np.fft.rfftfreq(n, dt)
    found: list[float] = []
    width = max(3, n // 400)
    taken = np.zeros(spec.size, dtype=bool)
    taken[freqs < MIN_TONE_HZ] = True
    for _ in range(limit):
        masked = np.where(taken, 0.0, spec)
        k = int(np.argmax(masked))
        if masked[k] <= 0.0:
            break
        lo, hi = max(0, k - 20 * width), min(spec.size, k + 20 * width + 1)
        around = np.median(spec[lo:hi])
        taken[max(0, k - 2 * width):k + 2 * width + 1] = True
        if spec[k] < TONE_PROMINENCE * max(float(around), 1e-300):
            break
        found.append(_refine(e, time_s, float(freqs[k]), float(freqs[1] - freqs[0])))
    return found


def locked(command: FloatArray, time_s: FloatArray, freq_hz: float) -> bool:
    """Whether a residual line at ``freq_hz`` is one the demand carries (module docstring).

    Parameters
    ----------
    command : numpy.ndarray
        The command on the same samples as the residual.
    time_s : numpy.ndarray
        Their times.
    freq_hz : float
        The residual's line.

    Returns
    -------
    bool
        True when the command has a line there, or it is periodic and ``freq_hz`` is a harmonic of its period.
    """
    n = command.size
    if n < 64 or np.ptp(command) == 0.0:
        return False
    x = np.asarray(command, dtype=float)
    spec = np.abs(np.fft.rfft((x - np.mean(x)) * np.hanning(n))) ** 2
    freqs = np.fft.rfftfreq(n, float(np.median(np.diff(time_s))))
    df = float(freqs[1] - freqs[0])
    tol = LOCK_BINS * df
    width = max(3, n // 400)
    k = int(np.argmin(np.abs(freqs - freq_hz)))
    lo = max(0, k - int(LOCK_BINS))
    top = lo + int(np.argmax(spec[lo:k + int(LOCK_BINS) + 1]))
    wide = spec[max(0, top - 3 * int(LOCK_BINS)):top + 3 * int(LOCK_BINS) + 1]
    around = spec[max(0, k - 20 * width):k + 20 * width + 1]
    if (spec[top] >= float(np.max(wide)) and spec[top] > COMMAND_LINE * max(float(np.median(around)), 1e-300)
            and spec[top] >= LINE_DEPTH * float(np.max(spec[1:]))):
        return True  # a line of the command's own (a peak, not the skirt of a neighbour's)
    usable = freqs >= MIN_TONE_HZ / 5
    if not np.any(usable):
        return False
    f0 = float(freqs[usable][int(np.argmax(spec[usable]))])
    if not _periodic(x, time_s, 1.0 / f0):
        return False
    h = round(freq_hz / f0)
    return h >= 1 and abs(freq_hz - h * f0) <= tol


def _periodic(x: FloatArray, time_s: FloatArray, period_s: float) -> bool:
    """Whether ``x`` repeats after ``period_s`` (its correlation with itself one period later; two periods seen)."""
    span = float(time_s[-1] - time_s[0])
    if period_s <= 0.0 or 2.0 * period_s > span:
        return False
    later = np.interp(time_s + period_s, time_s, x)
    keep = time_s + period_s <= time_s[-1]
    a, b = x[keep] - np.mean(x[keep]), later[keep] - np.mean(later[keep])
    den = float(np.sqrt(np.dot(a, a) * np.dot(b, b)))
    return den > 0.0 and float(np.dot(a, b)) / den >= PERIODIC


def _refine(e: FloatArray, t: FloatArray, f0: float, df: float) -> float:
    """The frequency within a bin of ``f0`` whose sine and cosine explain most of ``e``."""
    best, best_gain = f0, -1.0
    for f in np.linspace(f0 - df, f0 + df, 41):
        if f <= 0.0:
            continue
        a = np.column_stack([np.sin(2 * np.pi * f * t), np.cos(2 * np.pi * f * t)])
        c = np.linalg.lstsq(a, e, rcond=None)[0]
        gain = float(np.dot(a @ c, a @ c))
        if gain > best_gain:
            best, best_gain = float(f), gain
    return best


def library(time_s: FloatArray, command: FloatArray, output: FloatArray, rate: FloatArray,
            hinge_moment: FloatArray | None, residual: FloatArray, mask: NDArray[np.bool_], unit: str = "°"
            ) -> list[Term]:
    """The candidate terms for one output's residual, each on every sample of the record.

    Parameters
    ----------
    time_s : numpy.ndarray
        Sample times from the record's start, s.
    command : numpy.ndarray
        The command.
    output : numpy.ndarray
        The model's value of the output (position or surface).
    rate : numpy.ndarray
        The model's rate, per s.
    hinge_moment : numpy.ndarray or None
        The hinge moment, in·lb (None: the record has no load).
    residual : numpy.ndarray
        The residual on the fitted samples (where tones are looked for).
    mask : numpy.ndarray
        The fitted samples.
    unit : str
        The output's unit symbol (``°`` or `` mm``...).

    Returns
    -------
    list of Term
        The library (module docstring).
    """
    t = np.asarray(time_s, dtype=float)
    u = np.asarray(command, dtype=float)
    x = np.asarray(output, dtype=float)
    v = np.asarray(rate, dtype=float)
    acc = np.gradient(v, t) if t.size > 2 else np.zeros_like(v)
    s = _direction(v)
    tc = t - 0.5 * (t[0] + t[-1])
    one = unit.strip() or "1"
    per_s = f"{unit}/({unit}/s)"
    terms = [
        Term(CONSTANT, np.ones((t.size, 1)), one, "a constant offset: a zero error of the reading or a bias on the "
             "command", "either", np.ones(t.size)),
        _term("command", u, f"{unit}/{unit}", "proportional to the command: a calibration (gain) error", "either"),
        _term("position", x, f"{unit}/{unit}", "proportional to the position: a scale error of the reading or a gain "
              "error in the loop", "either"),
        _term("rate", v, per_s, "proportional to the rate: a timing error (a delay or lead the model lacks)", "motion"),
        _term("acceleration", acc, f"{unit}/({unit}/s²)", "proportional to the acceleration: inertia or dynamics the "
              "model lacks", "motion"),
        _term("sign(rate)", s, one, "a constant drag that reverses with the motion: friction or backlash the model "
              "lacks", "motion"),
        _term("|rate|", np.abs(v), per_s, "the same sign whichever way it moves: the actuator is faster one way than "
              "the other (a direction asymmetry)", "motion"),
        _term("rate·|rate|", v * np.abs(v), f"{unit}/({unit}/s)²", "grows with the square of the speed: a quadratic "
              "drag", "motion"),
        _term("position²", x * x, f"{unit}/{unit}²", "even in the position: the two sides of the travel differ (an "
              "asymmetric spring, a sensor's bow)", "either"),
        _term("position³", x**3, f"{unit}/{unit}³", "odd and growing with the cube of the position: a kinematic "
              "nonlinearity (a crank, a non-linear sensor) or a stiffening spring", "either"),
        _term("time", tc, f"{unit}/s", "a slow drift (a sensor's zero, temperature)", "sensor"),
        _term("time²", tc * tc, f"{unit}/s²", "a slow drift that turns (a sensor's zero, temperature)", "sensor"),
        _term("position·sign(rate)", x * s, f"{unit}/{unit}", "a drag that grows with the position", "motion"),
    ]
    if hinge_moment is not None and np.ptp(hinge_moment) > 0.0:
        hk = np.asarray(hinge_moment, dtype=float) / 1000.0
        terms += [
            _term("hinge moment", hk, f"{unit}/kin·lb", "proportional to the hinge moment: a compliance the model "
                  "lacks", "motion"),
            _term("hinge moment·sign(rate)", hk * s, f"{unit}/kin·lb", "a drag that grows with the load (friction "
                  "under load)", "motion"),
            _term("position·hinge moment", x * hk, f"{unit}/({unit}·kin·lb)", "a compliance that changes across the "
                  "travel", "motion"),
            _term("rate·hinge moment", v * hk, f"{unit}/({unit}/s·kin·lb)", "a lag that the load changes (a "
                  "load-dependent rate)", "motion"),
        ]
    for f in tones(residual, t[mask]):
        if locked(u[mask], t[mask], f):
            continue
        cols = np.column_stack([np.sin(2 * np.pi * f * t), np.cos(2 * np.pi * f * t)])
        terms.append(Term(f"tone {f:.4g} Hz", cols, unit.strip() or "1", f"a tone at {f:.4g} Hz: a pickup, a "
                          "vibration or a mode the model lacks", "sensor"))
    return [tm for tm in terms if np.all(np.isfinite(tm.columns))]


def describe(term: Term, coef: tuple[float, ...], unit: str = "°") -> str:
    """The term with its coefficient, as an equation reads (``0.021°·sign(rate)``).

    Parameters
    ----------
    term : Term
        The term.
    coef : tuple of float
        Its coefficient(s).
    unit : str
        The output's unit symbol.

    Returns
    -------
    str
        The term in words.
    """
    if term.width == 2:
        amp = math.hypot(*coef)
        return f"{amp:.3g}{unit} {term.name}"
    c = coef[0]
    if term.name == CONSTANT:
        return f"{c:+.3g}{unit}"
    return f"{c:+.3g}·{term.name}"
