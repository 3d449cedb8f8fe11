"""What a careful engineer flags in an identification: the contract's rules for every report.

* the **reference**: the rms of the trivial model position = command (and surface = command), so a
  reader sees at once whether the fitted model explains anything; a final model no better is flagged;
* a parameter on a **bound** of its range (the range of its declaration, :mod:`ema_sim.parameters`);
* a **frequency** (any parameter in rad/s or Hz) at or above half the record's Nyquist frequency:
  a mode with fewer than four samples a period is not resolved by the record;
* a **sample rate too low** for the dynamics found: below ten times the fitted linear model's −3 dB
  bandwidth (its 10–90 % rise then spans fewer than about three samples);
* **identifiability**, from the final fit's parameter covariance (coloured-residual corrected): a
  parameter whose one-sigma uncertainty exceeds a quarter of its value (of its typical size when it
  is zero) is not determined by the record; one the record cannot move at all (a zero Jacobian column)
  is infinitely uncertain, without making the others so; and two whose estimates correlate beyond 0.95
  cannot be told apart by it; each warning says what excitation the record had (its length, the
  command's changes, span and bandwidth).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from itertools import pairwise

import numpy as np
from numpy.typing import NDArray
from scipy.signal import welch

from ema_sim.analysis.estimation.noise import COMMAND_COUNTS_SPANNED, detect_resolution
from ema_sim.analysis.records.series import holds
from ema_sim.identify.effects import FREE, KEYS, Free
from ema_sim.identify.fit import Fit, covariance
from ema_sim.identify.fit import correlation as correlation_of
from ema_sim.identify.outcome import REFERENCE, Identification
from ema_sim.identify.problem import Problem
from ema_sim.models.second_order import SecondOrderParams
from ema_sim.parameters import metas

FloatArray = NDArray[np.float64]
NOT_DETERMINED = 0.25
"""One-sigma uncertainty above this share of the value: the record does not determine the parameter."""
INSEPARABLE = 0.95
FAR_FROM_DECLARED = 3.0
"""A fitted physical parameter more than this factor from its declared value is said to be so."""
"""Correlation of two estimates above this: the record cannot tell them apart."""
NYQUIST_SHARE = 0.5
"""A frequency at or above this share of the Nyquist frequency is not resolved (fewer than 4 samples a period)."""
SAMPLES_PER_BANDWIDTH = 10.0
CONTENT_DB = 1e-4
"""The command's content reaches the highest frequency where its spectrum is within 40 dB of its peak (and
ten times above the white floor of its counts, when it is logged in counts)."""
BOUND_SHARE = 1e-3
"""Within this share of its range (of the ratio, for a log-scaled one) a value sits on a bound."""


def reference(problem: Problem) -> dict[str, dict[str, float]]:
    """The trivial model position = command (surface = command): its rms and largest error, per output.

    Parameters
    ----------
    problem : Problem
        The record as fitted (the same samples the fits are judged on).

    Returns
    -------
    dict
        ``rms_deg`` and ``max_abs_deg``, each output → value.
    """
    u = problem.data.command_deg[problem.mask]
    err = {o: problem.observed[o][problem.mask] - u for o in problem.outputs}
    return {"rms_deg": {o: float(np.sqrt(np.mean(e**2))) for o, e in err.items()},
            "max_abs_deg": {o: float(np.max(np.abs(e))) for o, e in err.items()}}


def _rms(problem: Problem, fit: Fit) -> dict[str, float]:
    return {o: float(np.sqrt(np.mean(e**2))) for o, e in problem.errors_deg(fit.sim).items()}


def on_bound(value: float, free: Free) -> str | None:
    """``"lower"`` or ``"upper"`` when ``value`` sits on that bound of its range, else None.

    Parameters
    ----------
    value : float
        The parameter's value.
    free : Free
        Its fitted range.
    """
    if free.log and free.low > 0.0:
        span = math.log(free.high / free.low)
        if math.log(value / free.low) <= BOUND_SHARE * span:
            return "lower"
        if math.log(free.high / value) <= BOUND_SHARE * span:
            return "upper"
        return None
    span = free.high - free.low
    if value <= free.low + BOUND_SHARE * span:
        return "lower"
    if value >= free.high - BOUND_SHARE * span:
        return "upper"
    return None


def frequency_hz(name: str, value: float) -> float | None:
    """The value of a parameter in Hz when it is a frequency (unit rad/s or Hz), else None.

    Parameters
    ----------
    name : str
        A model parameter.
    value : float
        The parameter's value.
    """
    meta = metas(SecondOrderParams).get(name)
    if meta is None:
        return None
    if meta.unit == "rad/s":
        return value / (2.0 * math.pi)
    if meta.unit == "Hz":
        return value
    return None


def bandwidth_hz(p: SecondOrderParams) -> float:
    """−3 dB bandwidth of the model's linear command → position dynamics (ωn, ζ and the lags on).

    Parameters
    ----------
    p : SecondOrderParams
        The model.
    """
    f = np.geomspace(1e-3, 1e4, 4000)
    s = 2j * np.pi * f
    h = p.wn_rad_s**2 / (s**2 + 2.0 * p.zeta * p.wn_rad_s * s + p.wn_rad_s**2)
    for corner in (p.command_lag_hz, p.feedback_lag_hz):
        if corner > 0.0:
            h = h / (1.0 + s / (2.0 * np.pi * corner))
    below = np.flatnonzero(np.abs(h) < 1.0 / math.sqrt(2.0))
    return float(f[below[0]]) if below.size else math.inf


@dataclass(frozen=True)
class Excitation:
    """What the record offers a fit: its length and what its command does."""

    duration_s: float
    changes: int
    """Command changes from one held level (at least 0.1 s) to another (steps, moves), by 2 % of the span or more."""
    span: float
    bandwidth_hz: float
    """Highest frequency at which the command's spectrum is within 40 dB of its peak."""

    def statement(self, unit: str) -> str:
        """One clause for a warning.

        Parameters
        ----------
        unit : str
            The record's position unit (deg, mm, in).
        """
        u = "°" if unit == "deg" else f" {unit}"
        return (f"{self.duration_s:.3g} s, {self.changes} change(s) of the command's level over {self.span:.3g}{u}, "
                f"command within 40 dB of its peak up to {self.bandwidth_hz:.2g} Hz")


def excitation(problem: Problem) -> Excitation:
    """The record's excitation (see :class:`Excitation`).

    Parameters
    ----------
    problem : Problem
        The record as fitted.

    Returns
    -------
    Excitation
        Length, command changes, span and bandwidth.
    """
    u = problem.data.command_deg
    dt = 1.0 / problem.sample_hz
    span = float(np.ptp(u))
    levels = holds(u, max(2, round(0.1 / dt))) if span > 0 else []
    moves = sum(abs(b.value - a.value) >= 0.02 * span for a, b in pairwise(levels))
    freqs, power = welch(u - np.mean(u), fs=1.0 / dt, nperseg=min(u.size, 4096))
    q = detect_resolution(u, min_span=COMMAND_COUNTS_SPANNED)
    floor = 10.0 * 2.0 * dt * (q * q / 12.0) if q else 0.0  # ten times the white floor of the command's counts
    above = np.flatnonzero(power >= max(CONTENT_DB * float(np.max(power)), floor))
    band = float(freqs[above[-1]]) if above.size else 0.0
    return Excitation(float(problem.time_s[-1]), moves, span, band)


@dataclass(frozen=True)
class Identifiability:
    """How well the record determines each parameter of a fit (its covariance and correlations)."""

    relative_sigma: dict[str, float]
    """One-sigma uncertainty over the value (inf when the record cannot move the parameter)."""
    correlation: dict[str, dict[str, float]]
    not_determined: list[str]
    inseparable: list[tuple[str, str, float]]


def identifiability(problem: Problem, fit: Fit) -> Identifiability:
    """Relative uncertainty and correlations of the fitted parameters (module docstring).

    Parameters
    ----------
    problem : Problem
        The record as fitted.
    fit : Fit
        The fit (its Jacobian columns follow ``fit.jac_free``).

    Returns
    -------
    Identifiability
        Per parameter and per pair.
    """
    names = list(fit.jac_free)
    cov = covariance(problem, fit.residual, fit.jacobian) if names else np.zeros((0, 0))
    corr = correlation_of(cov)
    rel = {}
    for name in fit.free:
        value = float(getattr(fit.params, name))
        sigma = fit.sigma.get(name, math.inf)
        # at zero (a bias, an offset) the parameter's typical size stands in for its value
        size = abs(value) if value != 0.0 else (FREE[name].scale if name in FREE else 0.0)
        rel[name] = sigma / size if size > 0.0 else math.inf
    correlation = {a: {b: float(corr[i, j]) for j, b in enumerate(names) if j != i and np.isfinite(corr[i, j])}
                   for i, a in enumerate(names)}
    pairs = [(a, b, float(corr[i, j])) for i, a in enumerate(names) for j, b in enumerate(names)
             if j > i and np.isfinite(corr[i, j]) and abs(corr[i, j]) > INSEPARABLE]
    undetermined = [n for n, r in rel.items() if not r <= NOT_DETERMINED]
    return Identifiability(rel, correlation, undetermined, pairs)


def label(result: Identification, name: str) -> str:
    """A parameter as the report names it: an added effect's key, with the model parameter when they differ.

    Parameters
    ----------
    result : Identification
        The identification.
    name : str
        A model parameter.
    """
    key = name if name in result.baseline.free or name not in KEYS else KEYS[name].name
    return name if key == name else f"{key}: {name}"


def _value(name: str, value: float, unit: str, result: Identification) -> str:
    meta = metas(SecondOrderParams).get(name)
    u = meta.unit if meta and meta.unit != "-" else ""
    if unit != "deg" and u.startswith("deg"):
        u = unit + u[3:]
    return f"{label(result, name)} = {value:.4g} {u}".rstrip()


def assess(result: Identification) -> tuple[list[str], Identifiability, Excitation]:
    """Every warning of the contract's rules the identification earns (module docstring), one line each.

    Parameters
    ----------
    result : Identification
        The outcome.

    Returns
    -------
    tuple
        The warnings, the final fit's identifiability and the record's excitation.
    """
    p = result.problem
    final = result.final
    record = result.record
    unit = record.unit if record else "deg"
    out: list[str] = list(record.warnings) if record else []
    nyquist = 0.5 * p.sample_hz
    ref = reference(p)["rms_deg"]
    rms = _rms(p, final)
    if result.final_model == REFERENCE:
        base = _rms(p, result.baseline)
        out.append(f"the declared {result.model} fits worse than {result.final_model} "
                   f"({', '.join(f'{o} rms {base[o]:.4g} against {ref[o]:.4g}' for o in p.outputs)}), and no effect "
                   f"of the vocabulary closes the gap: the final model is {result.final_model}; the fitted "
                   f"{result.model} is the baseline only")
    for name in final.free:
        value = float(getattr(final.params, name))
        free = FREE.get(name)
        side = on_bound(value, free) if free else None
        if side and free is not None:
            out.append(f"{_value(name, value, unit, result)} sits on the {side} bound of its range "
                       f"({free.low:g}…{free.high:g}): the fit pushed it as far as it may, so the value is no estimate")
        f = frequency_hz(name, value)
        if f is not None and f >= NYQUIST_SHARE * nyquist:
            where = "above" if f >= nyquist else "near"
            out.append(f"{_value(name, value, unit, result)} ({f:.3g} Hz) is {where} the record's Nyquist frequency "
                       f"({nyquist:.3g} Hz at {p.sample_hz:.4g} Hz): the record cannot resolve it")
    bw = bandwidth_hz(final.params)
    if not result.final_model and p.sample_hz < SAMPLES_PER_BANDWIDTH * bw:
        out.append(f"sample rate {p.sample_hz:.4g} Hz is too low for the dynamics found: the fitted model's bandwidth "
                   f"is {bw:.3g} Hz, which needs at least {SAMPLES_PER_BANDWIDTH * bw:.3g} Hz to be determined")
    for o in p.outputs:
        if not result.final_model and rms[o] >= ref[o]:
            out.append(f"the final model is no better than {o.split('_')[0]} = command on {o}: rms {rms[o]:.4g} "
                       f"against {ref[o]:.4g}")
    for removal in result.removed:
        out.append(f"{removal.effect} ({removal.where}) taken out again: {removal.reason}")
    ident = identifiability(p, final)
    exc = excitation(p)
    if ident.not_determined:
        which = ", ".join(
            f"{label(result, n)} (±1σ {100 * ident.relative_sigma[n]:.0f} % of its "
            f"{'value' if getattr(final.params, n) else 'typical size'})"
            if math.isfinite(ident.relative_sigma[n]) else f"{label(result, n)} (the record cannot move it)"
            for n in ident.not_determined)
        out.append(f"not determined by this record, too short or too poorly excited for them: {which}; the record "
                   f"has {exc.statement(unit)}")
    for a, b, rho in ident.inseparable:
        out.append(f"{label(result, a)} and {label(result, b)} cannot be told apart by this record: their estimates "
                   f"correlate {rho:+.3f}, so only "
                   "a combination of them is determined")
    return out + physical_warnings(result), ident, exc


def physical_warnings(result: Identification) -> list[str]:
    """What a reader must know of a high-order model's fitted physical parameters (the final model).

    Why a declared second-order model was replaced; the parameters the record could not determine (held
    at their declared values); pairs whose estimates correlate beyond :data:`INSEPARABLE`; values more
    than :data:`FAR_FROM_DECLARED` times off their declared ones.

    Parameters
    ----------
    result : Identification
        The outcome.

    Returns
    -------
    list of str
        One line each.
    """
    pf = result.physical
    if pf is None:
        return []
    out = []
    if result.escalated:
        out.append(f"{result.escalated}: the declared {result.model} ran out of vocabulary, so the final model is "
                   f"{pf.model} with its physical parameters fitted (section 4.2.5's loop); {result.model} with its "
                   "effects is under `equivalent`, its parameters equivalents of that servo")
    if pf.held:
        out.append(f"{pf.model}: not determined by this record, held at their declared values: {', '.join(pf.held)}")
    seen = set()
    for a, row in pf.correlation.items():
        for b, rho in row.items():
            if abs(rho) > INSEPARABLE and (b, a) not in seen:
                seen.add((a, b))
                out.append(f"{pf.model}: {a} and {b} cannot be told apart by this record: their estimates correlate "
                           f"{rho:+.3f}, so only a combination of them is determined")
    values = pf.scalars()
    for name in pf.fitted:
        d = pf.declared[name]
        ref = float(d[0] if isinstance(d, tuple) else d)
        if ref > 0.0 and values[name] > 0.0 and max(values[name] / ref, ref / values[name]) > FAR_FROM_DECLARED:
            out.append(f"{pf.model}: {name} = {values[name]:.4g} is more than {FAR_FROM_DECLARED:g}× off its "
                       f"declared {ref:.4g}: the record's actuator differs from the declared channel there, or the "
                       "element stands in for another")
    return out
