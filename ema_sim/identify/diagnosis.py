"""What the final model leaves: the residual's structure in words, so nobody takes proxies for findings.

When no effect of the vocabulary pays any more and an output's residual is still not white noise at
its floor, the diagnosis says what is left, for each such output:

* **where in time** — the share of the error above the noise floor (``e² − σ²``, summed) that falls
  while the command moves, within a settling time after it stops, or at rest, against the share of
  time each takes; with a hinge moment, whether the load aids or opposes the motion and its sign;
  with a motor current, the samples near its limit (|i| ≥ 90 % of its largest); the direction of
  motion. A part is named when it holds at least 40 % of the excess and 1.5 times its share of time;
* **at which frequency** — the residual's spectrum (Welch) against the white floor ``2σ²/fs``: the
  frequency below which half the excess power lies, the share above the model's bandwidth, and
  a *line* (ringing, a limit cycle) where the spectrum stands five times above its running median and
  the floor; frequencies above the record's Nyquist frequency alias and cannot be named;
* **with which input** — the share of the residual's variance a short two-sided FIR (±50 ms) of each
  input explains: the command, its rate and acceleration, the direction of motion (friction and
  backlash sign with it), the hinge moment and its rate, the motor current. Chance explains about
  taps/N_eff (N_eff corrected for the residual's and the input's autocorrelation, Bartlett); a share
  counts above ten per cent and five times that.

**Proxies**: an added effect is a finding only if the record agrees with itself about it. The final
fit is linearised (one Gauss-Newton step from the final parameters on each half of the record, with
each half's coloured-residual covariance): a parameter whose two halves disagree by more than three
combined sigma and 20 % changes with what the record excites. An added effect that does so stands in
for structure the vocabulary lacks (a second lag for a resonance, free play for friction); a declared
model's own parameter that does so means the model's structure does not fit the whole record. Each is
said in the diagnosis and in the warnings.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray
from scipy.ndimage import median_filter
from scipy.signal import welch

from ema_sim.analysis.noise import autocorrelation, whiteness
from ema_sim.analysis.series import hold_tolerance
from ema_sim.identify.effects import EFFECTS, FREE, Effect
from ema_sim.identify.fit import Fit, block_covariance
from ema_sim.identify.problem import Problem
from ema_sim.identify.stepwise import Identification
from ema_sim.identify.trust import bandwidth_hz
from ema_sim.models.base import O_RATE

FloatArray = NDArray[np.float64]
STRUCTURED = 1.5
"""An output whose residual rms is above this many noise floors (and not white) has structure left."""
PART_SHARE = 0.4
PART_CONCENTRATION = 1.5
LINE_PROMINENCE = 5.0
MIN_EXPLAINED = 0.1
CHANCE_FACTOR = 5.0
FIR_HALF_S = 0.05
SPLIT_SIGMA = 3.0
SPLIT_RELATIVE = 0.2
FAMILIES = ("motion", "direction", "load sign", "load against motion", "current")
BY_FIELD: dict[str, Effect] = {e.field: e for e in EFFECTS if e.field is not None}
"""The vocabulary effect each model parameter belongs to."""


@dataclass(frozen=True)
class Part:
    """A part of the record and how much of an output's excess error falls in it."""

    family: str
    """What splits the record: ``motion`` (moving, settling, at rest), ``direction``, ``load sign``,
    ``load against motion``, ``current``."""
    name: str
    excess_share: float
    time_share: float

    @property
    def concentration(self) -> float:
        """Share of the excess over share of the time."""
        return self.excess_share / max(self.time_share, 1e-9)

    def as_dict(self) -> dict[str, float | str]:
        """Plain values for JSON."""
        return {"family": self.family, "part": self.name, "excess_share": self.excess_share,
                "time_share": self.time_share}


@dataclass(frozen=True)
class Correlate:
    """An input whose short FIR explains a share of the residual's variance."""

    name: str
    explained: float
    """Share of the residual's variance it explains beyond the inputs named before it."""
    chance: float

    def as_dict(self) -> dict[str, float | str]:
        """Plain values for JSON."""
        return {"input": self.name, "explained_share": self.explained, "chance_share": self.chance}


@dataclass
class OutputDiagnosis:
    """What one output's residual holds beyond its noise."""

    output: str
    rms: float
    noise: float
    white: bool
    parts: list[Part] = field(default_factory=list)
    """Every part examined, most concentrated first."""
    median_hz: float | None = None
    """Half the excess power lies below this frequency."""
    above_bandwidth_share: float | None = None
    line_hz: float | None = None
    correlates: list[Correlate] = field(default_factory=list)
    """Inputs that explain more than chance, strongest first."""

    @property
    def structured(self) -> bool:
        """Not white and well above the noise floor: structure the model does not explain."""
        return not self.white and self.rms > STRUCTURED * self.noise

    def named_parts(self) -> list[Part]:
        """The parts that hold the error (module docstring): in each family, one that stands out from the others."""
        out = []
        for p in self.parts:
            others = [q.concentration for q in self.parts if q.family == p.family and q is not p]
            if (p.excess_share >= PART_SHARE and p.concentration >= PART_CONCENTRATION
                    and all(p.concentration >= PART_CONCENTRATION * c for c in others)):
                out.append(p)
        return sorted(out, key=lambda p: FAMILIES.index(p.family))

    def short(self, unit: str) -> str:
        """The diagnosis in a few words (for the warnings)."""
        u = "°" if unit == "deg" else f" {unit}"
        bits = [f"{100 * p.excess_share:.0f} % of it {p.name}" for p in self.named_parts()]
        if self.median_hz is not None:
            bits.append(f"half its power above {self.median_hz:.2g} Hz")
        if self.line_hz is not None:
            bits.append(f"ringing at {self.line_hz:.3g} Hz")
        bits += [f"correlates with the {c.name} ({100 * c.explained:.0f} %)" for c in self.correlates]
        return (f"residual not white on {self.output} (rms {self.rms:.3g}{u}, {self.rms / self.noise:.3g}× noise): "
                + "; ".join(bits))

    def sentence(self, unit: str, nyquist_hz: float, bandwidth: float) -> str:
        """The diagnosis in words, one sentence."""
        u = "°" if unit == "deg" else f" {unit}"
        head = (f"{self.output}: rms {self.rms:.3g}{u}, {self.rms / self.noise:.3g}× its noise floor "
                f"{self.noise:.3g}{u}")
        if not self.structured:
            return head + (", white" if self.white else ", within 1.5× the floor") + ": nothing left to explain"
        bits = []
        for p in self.named_parts():
            bits.append(f"{100 * p.excess_share:.0f} % of the error above the noise falls {p.name} "
                        f"({100 * p.time_share:.0f} % of the time)")
        if self.median_hz is not None:
            freq = f"half of its power lies above {self.median_hz:.2g} Hz"
            if self.above_bandwidth_share is not None and math.isfinite(bandwidth):
                freq += f", {100 * self.above_bandwidth_share:.0f} % above the model's bandwidth ({bandwidth:.2g} Hz)"
            bits.append(freq)
        if self.line_hz is not None:
            bits.append(f"it rings at {self.line_hz:.3g} Hz (a line in its spectrum)")
        for c in self.correlates:
            bits.append(f"it correlates with the {c.name} (a short filter of it explains {100 * c.explained:.0f} % "
                        "of the residual's variance)")
        if not self.correlates:
            bits.append("no input explains it")
        return (head + ", not white: " + "; ".join(bits)
                + f" (structure above the Nyquist frequency, {nyquist_hz:.3g} Hz, cannot be seen)")


@dataclass(frozen=True)
class Proxy:
    """A parameter whose value changes with the part of the record it is estimated on."""

    name: str
    effect: str | None
    """The added effect it belongs to (None: the declared model's own)."""
    first: float
    second: float
    sigma: float
    """Combined one-sigma uncertainty of the difference."""


@dataclass
class Diagnosis:
    """Every output's diagnosis, the proxies found, and the words."""

    outputs: dict[str, OutputDiagnosis]
    proxies: list[Proxy]
    text: list[str]
    warnings: list[str]

    def as_dict(self) -> dict[str, object]:
        """Plain values for JSON."""
        return {
            "outputs": {o: {"rms_deg": d.rms, "noise_deg": d.noise, "white": d.white, "structured": d.structured,
                            "parts": [p.as_dict() for p in d.parts], "median_hz": d.median_hz,
                            "above_bandwidth_share": d.above_bandwidth_share, "line_hz": d.line_hz,
                            "correlates": [c.as_dict() for c in d.correlates]}
                        for o, d in self.outputs.items()},
            "proxies": [{"parameter": p.name, "effect": p.effect, "first_half": p.first, "second_half": p.second,
                         "sigma_of_difference": p.sigma} for p in self.proxies],
            "text": self.text,
        }


# ------------------------------------------------------------------------------------------ where in time
def _parts(problem: Problem, fit: Fit, excess: FloatArray, bandwidth: float) -> list[Part]:
    """Shares of the excess error and of the time in each part of the record (module docstring)."""
    d = problem.data
    m = problem.mask
    dt = 1.0 / problem.sample_hz
    u = d.command_deg
    tol = hold_tolerance(u)
    step = np.concatenate([[False], np.abs(np.diff(u)) > tol])
    moving = step | np.concatenate([step[1:], [False]])
    settle_s = min(max(2.0 / bandwidth if math.isfinite(bandwidth) and bandwidth > 0 else 0.25, 0.25), 1.0)
    last = np.where(moving, np.arange(u.size), -1)
    last = np.maximum.accumulate(last)
    since = np.where(last >= 0, (np.arange(u.size) - last) * dt, np.inf)
    settling = ~moving & (since <= settle_s)
    parts = {("motion", "while the command moves"): moving,
             ("motion", f"within {settle_s:.2g} s after the command stops"): settling,
             ("motion", "with the command at rest"): ~moving & ~settling}
    rate = fit.sim[:, O_RATE]
    fast = np.abs(rate) > 0.01 * max(float(np.max(np.abs(rate))), 1e-12)
    parts |= {("direction", "moving in the positive direction"): fast & (rate > 0),
              ("direction", "moving in the negative direction"): fast & (rate < 0)}
    hm = problem.hinge_moment
    if problem.load_span_inlb > 20.0:
        parts |= {("load sign", "with the hinge moment positive"): hm > 0,
                  ("load sign", "with the hinge moment negative"): hm < 0,
                  ("load against motion", "while the hinge moment opposes the motion"): fast & (hm * rate < 0),
                  ("load against motion", "while the hinge moment aids the motion"): fast & (hm * rate > 0)}
    if d.current_a is not None:
        i = np.abs(d.current_a)
        parts[("current", "near the current limit (|i| ≥ 90 % of its largest)")] = (
            i >= 0.9 * float(np.percentile(i, 99.9)))
    total = float(np.sum(excess))
    out = []
    for (family, name), sel in parts.items():
        s = sel[m]
        if not s.any() or total <= 0:
            continue
        out.append(Part(family, name, float(np.sum(excess[s])) / total, float(np.mean(s))))
    return sorted(out, key=lambda p: -p.concentration)


# ------------------------------------------------------------------------------------------ frequency
def _spectrum(e: FloatArray, sigma: float, fs: float, bandwidth: float
              ) -> tuple[float | None, float | None, float | None]:
    """Median frequency of the excess power, its share above ``bandwidth``, and a line (module docstring)."""
    nper = int(min(e.size, 2 ** int(np.log2(max(fs * 4.0, 16.0)))))
    f, pxx = welch(e - np.mean(e), fs=fs, nperseg=nper)
    floor = 2.0 * sigma**2 / fs
    ex = np.clip(pxx - floor, 0.0, None)
    ex[0] = 0.0
    if ex.sum() <= 0:
        return None, None, None
    cum = np.cumsum(ex)
    median = float(f[np.searchsorted(cum, 0.5 * cum[-1])])
    above = float(ex[f > bandwidth].sum() / ex.sum()) if math.isfinite(bandwidth) else None
    smooth = median_filter(pxx, size=9, mode="nearest")
    ratio = np.where((f > 2.0 * f[1]) & (pxx > LINE_PROMINENCE * floor), pxx / np.maximum(smooth, 1e-300), 0.0)
    k = int(np.argmax(ratio))
    line = float(f[k]) if ratio[k] >= LINE_PROMINENCE else None
    return median, above, line


# ------------------------------------------------------------------------------------------ inputs
def _regressors(problem: Problem, fit: Fit) -> dict[str, FloatArray]:
    d = problem.data
    dt = 1.0 / problem.sample_hz
    u = d.command_deg
    rate = fit.sim[:, O_RATE]
    out = {"command": u, "command rate": np.gradient(u, dt),
           "command acceleration": np.gradient(np.gradient(u, dt), dt),
           "direction of motion (sign of the rate: friction, backlash)":
               np.where(np.abs(rate) > 0.01 * max(float(np.max(np.abs(rate))), 1e-12), np.sign(rate), 0.0)}
    if problem.load_span_inlb > 20.0:
        out |= {"hinge moment": problem.hinge_moment, "hinge moment rate": np.gradient(problem.hinge_moment, dt)}
    if d.current_a is not None:
        out["motor current"] = d.current_a
    return out


def _lagged(x: FloatArray, fs: float) -> FloatArray:
    """Columns of ``x`` at lags over ±50 ms (at most 11), for a two-sided FIR."""
    x = x - np.mean(x)
    half = max(1, round(FIR_HALF_S * fs))
    lags = np.unique(np.linspace(-half, half, min(2 * half + 1, 11)).round().astype(int))
    n = x.size
    cols = []
    for k in lags:
        c = np.zeros(n)
        if k > 0:
            c[k:] = x[:n - k]
        elif k < 0:
            c[:k] = x[-k:]
        else:
            c[:] = x
        cols.append(c)
    return np.column_stack(cols)


def _share(e: FloatArray, a: FloatArray) -> float:
    """Share of ``e``'s variance the least-squares combination of the columns of ``a`` explains."""
    e = e - np.mean(e)
    tss = float(np.dot(e, e))
    if tss <= 0 or a.shape[1] == 0:
        return 0.0
    coef, *_ = np.linalg.lstsq(a, e, rcond=None)
    fitted = a @ coef
    return float(np.dot(fitted, fitted) / tss)


def _chance(e: FloatArray, x: FloatArray, taps: int) -> float:
    """The share ``taps`` columns of ``x`` explain of ``e`` by chance: taps/N_eff (Bartlett's correction)."""
    k_max = min(200, e.size // 4)
    rho = float(np.sum(autocorrelation(e, k_max)[1:] * autocorrelation(x, k_max)[1:]))
    return min(1.0, taps * max(1.0 + 2.0 * rho, 1.0) / e.size)


def _correlates(e: FloatArray, inputs: dict[str, FloatArray], fs: float) -> list[Correlate]:
    """Inputs that explain the residual beyond chance, chosen greedily: each counts only for what it adds."""
    cols = {name: _lagged(x, fs) for name, x in inputs.items() if np.ptp(x) > 0}
    chosen: list[Correlate] = []
    base = np.zeros((e.size, 0))
    explained = 0.0
    while cols:
        gains = {name: _share(e, np.column_stack([base, a])) - explained for name, a in cols.items()}
        name = max(gains, key=lambda k: gains[k])
        chance = _chance(e, inputs[name], cols[name].shape[1])
        if gains[name] < max(MIN_EXPLAINED, CHANCE_FACTOR * chance):
            break
        chosen.append(Correlate(name, gains[name], chance))
        base = np.column_stack([base, cols.pop(name)])
        explained += gains[name]
    return chosen


# ------------------------------------------------------------------------------------------ proxies
def _halves(problem: Problem, fit: Fit) -> list[Proxy]:
    """Parameters whose first- and second-half estimates disagree (module docstring)."""
    names = list(fit.jac_free)
    if not names:
        return []
    block = int(problem.mask.sum())
    t = problem.time_s[problem.mask]
    mid = 0.5 * (t[0] + t[-1])
    estimates = []
    for sel in (t < mid, t >= mid):
        rs = [fit.residual[b * block:(b + 1) * block][sel] for b in range(len(problem.outputs))]
        js = [fit.jacobian[b * block:(b + 1) * block][sel] for b in range(len(problem.outputs))]
        jtj = sum(j.T @ j for j in js)
        try:
            dx = np.linalg.solve(jtj, sum(j.T @ r for j, r in zip(js, rs, strict=True)))
        except np.linalg.LinAlgError:
            return []
        cov = block_covariance(rs, js)
        estimates.append((dx, np.sqrt(np.clip(np.diag(cov), 0.0, None))))
    out = []
    for i, name in enumerate(names):
        free = FREE[name]
        x0 = free.to_x(float(getattr(fit.params, name)))
        lo, hi = free.x_bounds()
        (d1, s1), (d2, s2) = estimates
        v1 = free.from_x(min(max(x0 + d1[i], lo), hi))
        v2 = free.from_x(min(max(x0 + d2[i], lo), hi))
        sigma = math.hypot(s1[i] * free.derivative(v1), s2[i] * free.derivative(v2))
        if not math.isfinite(sigma):
            continue
        scale = max(abs(v1), abs(v2), 1e-12)
        if abs(v1 - v2) > SPLIT_SIGMA * sigma and abs(v1 - v2) > SPLIT_RELATIVE * scale:
            out.append(Proxy(name, None, v1, v2, sigma))
    return out


def diagnose(result: Identification) -> Diagnosis:
    """The residual diagnosis of an identification (module docstring).

    Parameters
    ----------
    result : Identification
        The outcome.

    Returns
    -------
    Diagnosis
        Per output, the proxies, the words and the warnings.
    """
    p = result.problem
    fit = result.final
    unit = result.record.unit if result.record else "deg"
    fs = p.sample_hz
    bw = bandwidth_hz(fit.params)
    outputs: dict[str, OutputDiagnosis] = {}
    errors = p.errors_deg(fit.sim)
    for o, e in errors.items():
        sigma = p.sigma_deg[o]
        rms = float(np.sqrt(np.mean(e**2)))
        white = whiteness(e / sigma, lags=50, fitted_params=len(fit.free)).white
        d = OutputDiagnosis(o, rms, sigma, white)
        if d.structured:
            excess = e**2 - sigma**2
            d.parts = _parts(p, fit, excess, bw)
            d.median_hz, d.above_bandwidth_share, d.line_hz = _spectrum(e, sigma, fs, bw)
            d.correlates = _correlates(e, {k: x[p.mask] for k, x in _regressors(p, fit).items()}, fs)
        outputs[o] = d
    proxies = []
    own = set(result.baseline.free)
    for proxy in _halves(p, fit):
        effect = None if proxy.name in own else (BY_FIELD[proxy.name].name if proxy.name in BY_FIELD else proxy.name)
        proxies.append(Proxy(proxy.name, effect, proxy.first, proxy.second, proxy.sigma))
    nyquist = 0.5 * fs
    text = [d.sentence(unit, nyquist, bw) for d in outputs.values()]
    warnings = [d.short(unit) for d in outputs.values() if d.structured]
    left = [d for d in outputs.values() if d.structured]
    if left:
        added = ", ".join(s.effect for s in result.steps) or "nothing"
        text.append(f"what is left is structure no effect of the vocabulary explains (added: {added}); the "
                    "model's parameters are the best this structure allows, not a description of it")
    for px in proxies:
        what = (f"the added {px.effect} stands in for structure the vocabulary lacks, not a finding"
                if px.effect else "the declared model's structure does not fit the whole record")
        line = (f"{px.name} changes with the part of the record it is estimated on ({px.first:.4g} from the first "
                f"half, {px.second:.4g} from the second, ±{px.sigma:.2g}): {what}")
        text.append(line)
        warnings.append(line)
    return Diagnosis(outputs, proxies, text, warnings)


