"""Second-order actuator fits of section 3.1.1: ωn, ζ and time delay by least squares, with uncertainty.

The model is the basic second order of figure 21 behind a pure delay,
``K·ωn²/(s² + 2ζωn·s + ωn²)·e^(−sτ)``.

* :func:`fit_step` fits a step's time history. The model is simulated exactly on the measured,
  zero-order-held command: the ZOH discretization with a fractional delay (the delay ``τ = d·T + δ``
  splits each sample interval in two, giving two input matrices; ``b``/``a`` for ``lfilter``), so the
  cost is smooth in τ. Gain ``K`` and output bias enter linearly and are projected out (variable
  projection); ωn, ζ, τ go to a bounded trust-region solver from three starts.
* :func:`fit_frequency_response` fits a measured response on its coherent points with the CIFER cost
  (Tischler & Remple): gain error in dB and phase error in degrees weighted 1 : 0.01745 (per deg²),
  each point weighted by ``[1.58·(1 − e^(−γ²))]²``.

Bounds: ωn from 2 rad/s to 2000 rad/s or the record's Nyquist frequency (π/T), whichever is lower;
ζ from 0.05 to 3; the delay from 0 (a held command: nothing answers a command before it is applied)
or from −T (a command sampled from a running demand changed up to one sample before it was logged,
:mod:`ema_sim.analysis.records.command_hold`) to 0.1 s. The Jacobian is taken by central differences, or
one-sided ones inside the bounds for a parameter that sits on one. A fit whose ωn, ζ or delay ends
on a bound is ``on_bound``; one whose ωn or ζ has a standard error over a quarter of its value (or
over 0.25 for ζ below 1) is ``not_determined`` (:mod:`ema_sim.analysis.estimation.quality`).

Uncertainty: the Cramér-Rao/white-noise standard errors are reported beside the ones corrected for
coloured residuals by Morelli & Klein's method (:mod:`ema_sim.analysis.estimation.uncertainty`). The hand
calculation of the report (figure 22) is :func:`hand_calculation`: the 10-90 % rise time
``tr·ωn ≈ 1 − 0.4167ζ + 2.917ζ²`` and the 2 % settling time ``ts ≈ 4/(ζωn)`` solved together.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import brentq, least_squares
from scipy.signal import lfilter, lfilter_zi

from ema_sim.analysis.estimation import causal
from ema_sim.analysis.estimation.frf import COHERENCE_FIT, FrequencyResponse
from ema_sim.analysis.estimation.noise import WhitenessTest, whiteness
from ema_sim.analysis.estimation.quality import Quality
from ema_sim.analysis.estimation.uncertainty import coloured_covariance
from ema_sim.jsontypes import JsonObject

FloatArray = NDArray[np.float64]

UNCERTAINTY_METHOD = ("Morelli & Klein (1997) correction for coloured residuals: Cov = (JᵀJ)⁻¹·Jᵀ·R·J·(JᵀJ)⁻¹ "
                      "with R the Toeplitz residual autocovariance over all lags")
PHASE_WEIGHT = 0.01745
"""CIFER's phase weight per deg² against 1 per dB²."""
WN_BOUNDS = (2.0, 2000.0)
ZETA_BOUNDS = (0.05, 3.0)
MAX_DELAY_S = 0.1
UNDETERMINED = 0.25
"""A standard error over this share of ωn (or of max(ζ, 1)) leaves the parameter not determined."""
NAMES = ("ωn", "ζ", "delay")


@dataclass(frozen=True)
class Estimate:
    """A fitted value with its standard error, coloured-residual corrected and white-noise.

    Parameters
    ----------
    value : float
        The estimate.
    sigma : float
        Standard error corrected for coloured residuals.
    sigma_white : float
        White-noise standard error.
    """

    value: float
    sigma: float
    sigma_white: float

    def as_dict(self) -> dict[str, float]:
        """Plain values for JSON.

        Returns
        -------
        dict
            Plain values for JSON.
        """
        return {"value": self.value, "sigma": self.sigma, "sigma_white": self.sigma_white}


@dataclass(frozen=True)
class HandCalculation:
    """Natural frequency ωn and damping ζ from a step's rise and settling times (figure 22's hand calculation).

    Parameters
    ----------
    rise_s : float
        10-90 % rise time, s.
    settling_s : float
        2 % settling time, s.
    wn_rad_s : float
        Natural frequency, rad/s.
    zeta : float
        Damping ratio.
    """

    rise_s: float
    settling_s: float
    wn_rad_s: float
    zeta: float

    def as_dict(self) -> dict[str, float]:
        """Plain values for JSON.

        Returns
        -------
        dict
            Plain values for JSON.
        """
        return {"rise_s": self.rise_s, "settling_s": self.settling_s, "wn_rad_s": self.wn_rad_s, "zeta": self.zeta}


@dataclass(frozen=True)
class SecondOrderFit:
    """One least-squares estimate of the second-order parameters from one test.

    Parameters
    ----------
    test : str
        Label of the test.
    method : str
        How it was fitted.
    output : str
        Name of the output.
    wn_rad_s : Estimate
        Natural frequency, rad/s.
    zeta : Estimate
        Damping ratio.
    delay_s : Estimate
        Pure delay, s.
    gain : Estimate
        Steady-state gain.
    bias_deg : Estimate or None
        Output bias, deg (time-domain fits).
    rms : float
        RMS of the residual.
    rms_unit : str
        ``deg`` (time) or ``db`` (frequency).
    points : int
        Points fitted.
    start_s : float
        Start of the fitted data, s.
    end_s : float
        End of the fitted data, s.
    residual_whiteness : WhitenessTest
        Ljung-Box test of the residual.
    hand : HandCalculation or None
        The hand calculation beside it.
    quality : Quality
        ``ok``, ``on_bound`` or ``not_determined``.
    quality_note : str
        Why.
    command_sampled : bool
        The command was sampled, not held: the delay is against the sample the change was logged at.
    sample_s : float
        Sample interval, s.
    """

    test: str
    method: str
    output: str
    wn_rad_s: Estimate
    zeta: Estimate
    delay_s: Estimate
    gain: Estimate
    bias_deg: Estimate | None
    rms: float
    rms_unit: str
    points: int
    start_s: float
    end_s: float
    residual_whiteness: WhitenessTest
    hand: HandCalculation | None = None
    quality: Quality = "ok"
    quality_note: str = ""
    command_sampled: bool = False
    """The command was sampled, not held: the delay is against the sample the change was logged at."""
    sample_s: float = 0.0

    @property
    def actuator_delay_s(self) -> float:
        """The actuator's own delay: the fitted one, plus half a sample when the command was sampled."""
        return self.delay_s.value + (0.5 * self.sample_s if self.command_sampled else 0.0)

    def as_dict(self) -> JsonObject:
        """Plain values for JSON.

        Returns
        -------
        dict
            Every estimate as ``{value, sigma, sigma_white}``, the fit's RMS, points, span, residual
            whiteness, quality, and the hand calculation when there is one.
        """
        out: JsonObject = {
            "test": self.test, "method": self.method, "output": self.output,
            "quality": self.quality, "quality_note": self.quality_note,
            "command_sampled": self.command_sampled,
            "actuator_delay_s": {"value": self.actuator_delay_s,
                                 "sigma": float(np.hypot(self.delay_s.sigma, self.sample_s / np.sqrt(12.0)))
                                 if self.command_sampled else self.delay_s.sigma},
            "wn_rad_s": dict(self.wn_rad_s.as_dict()), "wn_hz": self.wn_rad_s.value / (2 * np.pi),
            "zeta": dict(self.zeta.as_dict()), "delay_s": dict(self.delay_s.as_dict()),
            "gain": dict(self.gain.as_dict()), "bias_deg": dict(self.bias_deg.as_dict()) if self.bias_deg else None,
            f"rms_{self.rms_unit}": self.rms, "points": self.points, "start_s": self.start_s, "end_s": self.end_s,
            "residual_whiteness": dict(self.residual_whiteness.as_dict()), "uncertainty": UNCERTAINTY_METHOD,
            "hand_calculation": dict(self.hand.as_dict()) if self.hand else None,
        }
        return out


# ---------------------------------------------------------------------------------------------- model
def _zoh_blocks(wn: float, zeta: float, t: float) -> tuple[FloatArray, FloatArray]:
    """``e^(At)`` and ``∫₀ᵗ e^(Aσ)dσ·B`` of the second order's state space (position, rate), in closed form.

    With σ = ζωn and ωd = ωn√(1−ζ²) (imaginary when over-damped, the formulas stay real), the unit step
    response from rest is ``s = 1 − e^(−σt)(cos ωd·t + σ/ωd·sin ωd·t)`` and the free response from unit
    rate ``g = e^(−σt)·sin(ωd·t)/ωd``.
    """
    if abs(zeta - 1.0) < 1e-7:
        zeta = 1.0 + 1e-7
    sig = zeta * wn
    wd = wn * np.sqrt(complex(1.0 - zeta * zeta))
    ex = np.exp(-sig * t)
    c, sn = np.cos(wd * t), np.sin(wd * t) / wd
    s = (1.0 - ex * (c + sig * sn)).real
    ds = (wn * wn * ex * sn).real
    g = (ex * sn).real
    dg = (ex * (c - sig * sn)).real
    phi = np.array([[1.0 - s, g], [-ds, dg]])
    return phi, np.array([s, ds])


def discrete_second_order(wn: float, zeta: float, delay_s: float, dt: float) -> tuple[FloatArray, FloatArray]:
    """``(b, a)`` of the exact ZOH discretization at ``dt`` of the delayed second order (unit DC gain).

    Parameters
    ----------
    wn : float
        Natural frequency, rad/s.
    zeta : float
        Damping ratio.
    delay_s : float
        Pure delay, s.
    dt : float
        Sample interval, s.

    Returns
    -------
    tuple
        Numerator and denominator for ``lfilter``.
    """
    d = int(np.floor(delay_s / dt + 1e-9))
    frac = max(delay_s - d * dt, 0.0)
    phi, _ = _zoh_blocks(wn, zeta, dt)
    phi_a, g_a = _zoh_blocks(wn, zeta, dt - frac)
    _, g_b = _zoh_blocks(wn, zeta, frac)
    g0 = g_a  # input of this interval, applied for dt − frac
    g1 = phi_a @ g_b  # previous input, applied for the first frac
    tr = phi[0, 0] + phi[1, 1]
    det = phi[0, 0] * phi[1, 1] - phi[0, 1] * phi[1, 0]
    a = np.array([1.0, -tr, det])
    # C·adj(zI − Φ)·g = g[0]·z + (Φ01·g[1] − Φ11·g[0])
    c0 = phi[0, 1] * g0[1] - phi[1, 1] * g0[0]
    c1 = phi[0, 1] * g1[1] - phi[1, 1] * g1[0]
    b = np.concatenate([np.zeros(d), [0.0, g0[0], c0 + g1[0], c1]])
    return b, a


def simulate(u: FloatArray, dt: float, wn: float, zeta: float, delay_s: float) -> FloatArray:
    """Response of the unit-gain delayed second order to the held command, at rest at its first value.

    Parameters
    ----------
    u : numpy.ndarray
        The command, held over each sample interval ``dt``.
    dt : float
        Sample interval, s.
    wn : float
        Natural frequency, rad/s.
    zeta : float
        Damping ratio.
    delay_s : float
        Delay, s; down to ``−dt`` (an advance of up to one sample: the command of a sample applied
        from the sample before, as a command sampled from a running demand may have been).

    Returns
    -------
    numpy.ndarray
        The response at the samples.
    """
    if delay_s < 0.0:
        if delay_s < -dt * (1.0 + 1e-9):
            raise ValueError(f"an advance of {-delay_s:g} s is more than one sample ({dt:g} s)")
        u = np.append(u[1:], u[-1])
        delay_s = max(delay_s + dt, 0.0)
    b, a = discrete_second_order(wn, zeta, delay_s, dt)
    zi = lfilter_zi(b, a) * u[0]
    y, _ = lfilter(b, a, u, zi=zi)
    return np.asarray(y, dtype=float)


def response(freq_hz: FloatArray, wn: float, zeta: float, delay_s: float = 0.0,
             gain: float = 1.0) -> NDArray[np.complex128]:
    """``K·ωn²/(s² + 2ζωn·s + ωn²)·e^(−sτ)`` at ``s = j2πf``.

    Parameters
    ----------
    freq_hz : numpy.ndarray
        Frequency, Hz.
    wn : float
        Natural frequency, rad/s.
    zeta : float
        Damping ratio.
    delay_s : float
        Pure delay, s.
    gain : float
        Steady-state gain.

    Returns
    -------
    numpy.ndarray
        The complex response.
    """
    s = 2j * np.pi * np.asarray(freq_hz, dtype=float)
    return gain * wn * wn / (s * s + 2.0 * zeta * wn * s + wn * wn) * np.exp(-s * delay_s)


def _gain_phase(freq_hz: FloatArray, wn: FloatArray | float, zeta: FloatArray | float, delay_s: FloatArray | float,
                gain_db: FloatArray | float) -> tuple[FloatArray, FloatArray]:
    """Gain (dB) and continuous phase (deg, 0 to −180 plus the delay's) of the delayed second order."""
    w = 2.0 * np.pi * freq_hz
    re = wn * wn - w * w
    im = 2.0 * zeta * wn * w
    g = gain_db + 20.0 * np.log10(wn * wn) - 10.0 * np.log10(re * re + im * im)
    ph = -np.degrees(np.arctan2(im, re)) - 360.0 * freq_hz * delay_s
    return g, ph


# ---------------------------------------------------------------------------------------------- hand calc
def _rise_factor(zeta: float) -> float:
    return 1.0 - 0.4167 * zeta + 2.917 * zeta * zeta


def hand_calculation(rise_s: float, settling_s: float) -> HandCalculation | None:
    """Solve ``tr·ωn = 1 − 0.4167ζ + 2.917ζ²`` and ``ts·ζωn = 4`` for ωn and ζ (None when out of range).

    Parameters
    ----------
    rise_s : float
        10-90 % rise time, s.
    settling_s : float
        2 % settling time, s.

    Returns
    -------
    HandCalculation or None
        The natural frequency and damping, or None when no ζ in range fits.
    """
    if not (rise_s > 0.0 and settling_s > 0.0):
        return None
    target = 4.0 * rise_s / settling_s

    def f(z: float) -> float:
        return z * _rise_factor(z) - target

    lo, hi = ZETA_BOUNDS
    if f(lo) > 0.0 or f(hi) < 0.0:
        return None
    zeta = float(brentq(f, lo, hi))
    return HandCalculation(rise_s, settling_s, 4.0 / (zeta * settling_s), zeta)


# ---------------------------------------------------------------------------------------------- fits
def _estimate(values: FloatArray, cov_sigma: FloatArray, cov_white: FloatArray, i: int) -> Estimate:
    return Estimate(float(values[i]), float(cov_sigma[i]), float(cov_white[i]))


def _steps(x: FloatArray, lo: FloatArray, hi: FloatArray, rel: float) -> tuple[FloatArray, FloatArray]:
    """Finite-difference points about ``x`` that stay inside ``[lo, hi]``: (up, down) offsets per parameter.

    Central differences where there is room, one-sided ones at a bound (a parameter on its bound
    must not be evaluated outside it: a delay of −h is no delay the model can take).
    """
    h = rel * np.maximum(np.abs(x), 1e-3)
    up = np.where(x + h <= hi, h, 0.0)
    dn = np.where(x - h >= lo, h, 0.0)
    one_sided = (up == 0.0) & (dn == 0.0)
    dn = np.where(one_sided, np.minimum(h, x - lo), dn)
    return up, dn


def assess(values: dict[str, float], sigmas: dict[str, float], active: NDArray[np.int_],
           bounds: tuple[FloatArray, FloatArray], nyquist_rad_s: float | None) -> tuple[Quality, str]:
    """The quality of a second-order fit from its bounds and its standard errors.

    Parameters
    ----------
    values : dict
        ``wn_rad_s``, ``zeta``, ``delay_s`` estimates.
    sigmas : dict
        Their standard errors (coloured-residual corrected).
    active : numpy.ndarray
        The solver's active-bound mask for (ωn, ζ, delay): −1 lower, +1 upper, 0 free.
    bounds : tuple of numpy.ndarray
        Lower and upper bounds of (ωn, ζ, delay).
    nyquist_rad_s : float or None
        The record's Nyquist frequency, rad/s.

    Returns
    -------
    tuple
        The quality and why.
    """
    lo, hi = bounds
    names = ("wn_rad_s", "zeta", "delay_s")
    on = []
    for k, name in enumerate(names):
        near = 1e-6 * max(abs(hi[k] - lo[k]), 1e-12)
        at = active[k] if k < active.size else 0
        if at or values[name] - lo[k] <= near or hi[k] - values[name] <= near:
            side = "upper" if (at > 0 or hi[k] - values[name] <= near) else "lower"
            bound = hi[k] if side == "upper" else lo[k]
            what = f"{NAMES[k]} on its {side} bound {bound:.4g}"
            if k == 0 and side == "upper" and nyquist_rad_s is not None and bound >= nyquist_rad_s * (1 - 1e-9):
                what += " (the record's Nyquist frequency)"
            if k == 2 and side == "lower" and bound == 0.0:
                what += " (the response starts at the command's sample: a sampled command?)"
            elif k == 2 and side == "lower" and bound < 0.0:
                what += (" (the earliest a command sampled from a running demand can have changed before it was "
                         "logged; an output earlier still leads its command, which no servo does: the logging, "
                         "a resampling, or a demand that is itself a filtered target)")
            on.append(what)
    if on:
        return "on_bound", "; ".join(on)
    loose = []
    if sigmas["wn_rad_s"] > UNDETERMINED * values["wn_rad_s"]:
        loose.append(f"ωn ± {sigmas['wn_rad_s']:.3g} rad/s")
    if sigmas["zeta"] > UNDETERMINED * max(values["zeta"], 1.0):
        loose.append(f"ζ ± {sigmas['zeta']:.3g}")
    if loose:
        return "not_determined", "the record does not determine " + " and ".join(loose)
    return "ok", ""


def fit_step(time_s: FloatArray, command_deg: FloatArray, output: FloatArray, *, test: str, output_name: str,
             wn0: float = 50.0, zeta0: float = 0.7, delay0: float = 0.005,
             hand: HandCalculation | None = None, sampled: bool = False) -> SecondOrderFit:
    """Least-squares ωn, ζ, τ (and gain, bias) of a time history; see the module docstring.

    Parameters
    ----------
    time_s : numpy.ndarray
        Sample times, s (uniform).
    command_deg : numpy.ndarray
        The command (held between samples, or sampled when ``sampled``).
    output : numpy.ndarray
        The measured output.
    test : str
        Label of the test the fit belongs to.
    output_name : str
        Name of the output.
    wn0 : float
        Starting natural frequency, rad/s.
    zeta0 : float
        Starting damping ratio.
    delay0 : float
        Starting delay, s.
    hand : HandCalculation, optional
        The hand calculation to report beside the fit.
    sampled : bool
        The command was sampled from a running demand: the delay may go down to −T.

    Returns
    -------
    SecondOrderFit
        The estimates, their standard errors and the fit's quality.
    """
    dt = float(np.median(np.diff(time_s)))
    u = np.asarray(command_deg, dtype=float)
    y = np.asarray(output, dtype=float)
    ones = np.ones_like(u)
    max_delay = min(MAX_DELAY_S, 0.25 * (time_s[-1] - time_s[0]))
    nyquist = np.pi / dt
    min_delay = -dt if sampled else 0.0
    scale = np.array([wn0, 1.0, 0.01])

    def shape(theta: FloatArray) -> FloatArray:
        wn, zeta, tau = theta * scale
        return simulate(u, dt, wn, zeta, tau)

    def project(s: FloatArray) -> tuple[FloatArray, FloatArray]:
        x = np.column_stack([s, ones])
        coef, *_ = np.linalg.lstsq(x, y, rcond=None)
        return coef, x @ coef - y

    def residual(theta: FloatArray) -> FloatArray:
        return project(shape(theta))[1]

    lo_phys = np.array([WN_BOUNDS[0], ZETA_BOUNDS[0], min_delay])
    hi_phys = np.array([min(WN_BOUNDS[1], nyquist), ZETA_BOUNDS[1], max_delay])
    lo, hi = lo_phys / scale, hi_phys / scale
    d0 = min(max(delay0, min_delay), 0.99 * max_delay)
    wn0c = min(wn0, 0.9 * hi_phys[0])
    starts = [np.array([wn0c, zeta0, d0]), np.array([0.7 * wn0c, min(1.2, 1.4 * zeta0), d0]),
              np.array([min(1.4 * wn0c, 0.95 * hi_phys[0]), 0.7 * zeta0, 0.5 * d0])]
    best = None
    for s0 in starts:
        x0 = np.clip(s0 / scale, lo + 1e-9, hi - 1e-9)
        sol = least_squares(residual, x0, bounds=(lo, hi), x_scale="jac", xtol=1e-10, ftol=1e-12, gtol=1e-12)
        if best is None or sol.cost < best.cost:
            best = sol
    assert best is not None
    theta = best.x * scale
    coef, r = project(shape(best.x))
    gain, bias = coef

    # Jacobian of the model output K·s(θ) + b with respect to (ωn, ζ, τ, K, b), inside the bounds.
    base = shape(best.x)
    jac = np.empty((u.size, 5))
    up, dn = _steps(best.x, lo, hi, 1e-5)
    for k in range(3):
        xu, xd = best.x.copy(), best.x.copy()
        xu[k] += up[k]
        xd[k] -= dn[k]
        jac[:, k] = gain * (shape(xu) - shape(xd)) / ((up[k] + dn[k]) * scale[k])
    jac[:, 3] = base
    jac[:, 4] = 1.0
    cov = coloured_covariance(jac, r)
    values = np.array([*theta, gain, bias])
    sig, sig_w = cov.sigma, cov.sigma_white
    quality, note = assess({"wn_rad_s": theta[0], "zeta": theta[1], "delay_s": theta[2]},
                           {"wn_rad_s": sig[0], "zeta": sig[1], "delay_s": sig[2]}, best.active_mask,
                           (lo_phys, hi_phys), nyquist)
    rms = float(np.sqrt(np.mean(r * r)))
    if not sampled and theta[2] <= 1e-9 * max_delay:
        # On the 0 bound: what the record says when the command may have changed up to a sample early.
        early = fit_step(time_s, command_deg, output, test=test, output_name=output_name, wn0=theta[0],
                         zeta0=theta[1], delay0=0.0, sampled=True)
        note += (f"; with the command allowed to have changed up to a sample before it was logged (sampled, "
                 f"not held) the fit gives a delay of {1e3 * early.delay_s.value:.2f} ms and RMS {early.rms:.3g} "
                 f"(against {rms:.3g}): rerun with --command sampled if the rig samples its demand")
    if sampled and quality in ("ok", "on_bound") and causal.delay_leads(theta[2] + 0.5 * dt, sig[2]):
        # A lead is flagged with its causes whether or not it sits on the search's bound: on the bound it is
        # the largest lead the search allows, and no servo leads at all.
        lead = causal.delay_note(theta[2] + 0.5 * dt, sig[2])
        quality, note = "non_causal", f"{lead}; {note}" if note else lead
    return SecondOrderFit(
        test=test, method="time-domain least squares on the step", output=output_name,
        wn_rad_s=_estimate(values, sig, sig_w, 0), zeta=_estimate(values, sig, sig_w, 1),
        delay_s=_estimate(values, sig, sig_w, 2), gain=_estimate(values, sig, sig_w, 3),
        bias_deg=_estimate(values, sig, sig_w, 4), rms=rms, rms_unit="deg",
        points=int(u.size), start_s=float(time_s[0]), end_s=float(time_s[-1]),
        residual_whiteness=whiteness(r, fitted_params=5), hand=hand, quality=quality, quality_note=note,
        command_sampled=sampled, sample_s=dt,
    )


def _fr_weights(coh: FloatArray) -> FloatArray:
    return 1.58 * (1.0 - np.exp(-coh))  # square root of CIFER's [1.58(1 − e^(−γ²))]²


def fit_frequency_response(fr: FrequencyResponse, *, test: str, level: float = COHERENCE_FIT,
                           sample_hz: float | None = None) -> SecondOrderFit | None:
    """CIFER-cost fit of ωn, ζ, τ and gain to the coherent points of a measured response.

    Parameters
    ----------
    fr : FrequencyResponse
        The measured response.
    test : str
        Label of the test.
    level : float
        Coherence a point needs to enter the fit.
    sample_hz : float, optional
        The record's sample rate: ωn is bounded by its Nyquist frequency.

    Returns
    -------
    SecondOrderFit or None
        None when fewer than 8 points are coherent.
    """
    good = fr.good(level)
    if good.sum() < 8:
        return None
    f = fr.freq_hz[good]
    g_meas = fr.gain_db[good]
    p_meas = fr.phase_deg[good]
    w = _fr_weights(fr.coherence[good])
    pw = np.sqrt(PHASE_WEIGHT)
    n = f.size
    nyquist = np.pi * sample_hz if sample_hz else None

    def model(p: FloatArray) -> tuple[FloatArray, FloatArray]:
        return _gain_phase(f, *p)

    def residual(p: FloatArray) -> FloatArray:
        gdb, ph = model(p)
        dph = (ph - p_meas + 180.0) % 360.0 - 180.0
        return np.concatenate([w * (gdb - g_meas), w * pw * dph])

    wn_hi = min(WN_BOUNDS[1], nyquist) if nyquist else WN_BOUNDS[1]
    # Start: the best of a coarse grid over ωn, ζ and τ (vectorised), gain from the low-frequency level.
    k0 = float(np.mean(g_meas[: max(3, n // 10)]))
    wn_g, z_g, tau_g = np.meshgrid(np.geomspace(5.0, min(1000.0, wn_hi), 40), [0.3, 0.5, 0.7, 1.0, 1.5],
                                   [0.0, 0.005, 0.015, 0.03], indexing="ij")
    gdb, ph = _gain_phase(f[None, :], wn_g.ravel()[:, None], z_g.ravel()[:, None], tau_g.ravel()[:, None], k0)
    dph = (ph - p_meas + 180.0) % 360.0 - 180.0
    costs = np.sum((w * (gdb - g_meas)) ** 2 + (w * pw * dph) ** 2, axis=1)
    best = int(np.argmin(costs))
    p0 = np.array([wn_g.ravel()[best], z_g.ravel()[best], tau_g.ravel()[best], k0])
    lo = np.array([WN_BOUNDS[0], ZETA_BOUNDS[0], 0.0, -40.0])
    hi = np.array([wn_hi, ZETA_BOUNDS[1], MAX_DELAY_S, 40.0])
    sol = least_squares(residual, np.clip(p0, lo + 1e-9, hi - 1e-9), bounds=(lo, hi),
                        x_scale=np.array([50, 0.5, 0.01, 1]),
                        xtol=1e-12, ftol=1e-12, gtol=1e-12)
    p = sol.x
    r = residual(p)
    jac = np.empty((2 * n, 4))
    up, dn = _steps(p, lo, hi, 1e-6)
    for k in range(4):
        pu, pd = p.copy(), p.copy()
        pu[k] += up[k]
        pd[k] -= dn[k]
        gu, phu = model(pu)
        gd, phd = model(pd)
        jac[:n, k] = w * (gu - gd) / (up[k] + dn[k])
        jac[n:, k] = w * pw * (phu - phd) / (up[k] + dn[k])
    cov = coloured_covariance(jac, r, blocks=[slice(0, n), slice(n, 2 * n)])
    sig, sig_w = cov.sigma, cov.sigma_white
    gain = 10 ** (p[3] / 20.0)
    gain_est = Estimate(gain, gain * np.log(10) / 20 * sig[3], gain * np.log(10) / 20 * sig_w[3])
    rms_db = float(np.sqrt(np.mean((r[:n] / np.maximum(w, 1e-9)) ** 2)))
    quality, note = assess({"wn_rad_s": p[0], "zeta": p[1], "delay_s": p[2]},
                           {"wn_rad_s": sig[0], "zeta": sig[1], "delay_s": sig[2]}, sol.active_mask[:3],
                           (lo[:3], hi[:3]), nyquist)
    return SecondOrderFit(
        test=test, method="frequency-response least squares (CIFER cost)", output=fr.output,
        wn_rad_s=_estimate(p, sig, sig_w, 0), zeta=_estimate(p, sig, sig_w, 1), delay_s=_estimate(p, sig, sig_w, 2),
        gain=gain_est, bias_deg=None, rms=rms_db, rms_unit="db", points=int(n), start_s=fr.start_s,
        end_s=fr.end_s, residual_whiteness=whiteness(r[:n], fitted_params=4), quality=quality, quality_note=note,
    )
