"""What the final model leaves: the residual's structure in words, so nobody takes proxies for findings.

When no effect of the vocabulary pays any more and an output's residual is still not white noise at
its floor, the diagnosis says what is left, for each such output:

* **where in time** — the share of the error above the noise floor (``e² − σ²``, summed) that falls
  while the command moves (outside its levels held 0.1 s or more: a frame-held sweep moves), within a
  settling time after it reaches a new level, or at rest, against the share of
  time each takes; with a hinge moment, whether the load aids or opposes the motion and its sign;
  with a motor current, the samples near its limit (|i| ≥ 90 % of its largest); the direction of
  motion. A part is named when it holds at least 40 % of the excess and 1.5 times its share of time;
* **at which frequency** — the residual's spectrum (Welch) against the white floor ``2σ²/fs``: the
  frequency below which half the excess power lies and the share above the model's bandwidth; and a
  *ring*: the residual in each window after the command reaches a new level (up to 0.5 s) peaks at one
  frequency well above its noise, and a mode rings at the same one after every level, so a ring is
  claimed when at least three windows and half of them agree within 15 % (a residual that bursts only
  at moves is no stationary signal: a peak of its average spectrum proves nothing by itself);
  frequencies above the record's Nyquist frequency alias and cannot be named;
* **with which input** — the share of the residual's variance a short two-sided FIR (±50 ms) of each
  input explains: the command, its rate and acceleration, the direction of motion (friction and
  backlash sign with it), the hinge moment and its rate, the motor current. Inputs are taken greedily,
  each for what it adds to those before it (the rate and the acceleration of one command overlap); one
  counts when it adds at least 10 % and a partial F test on the effective number of samples (N over
  1 + 2Σρₑρₓ, Bartlett: smooth residuals and inputs carry few independent samples) rejects chance at
  1 in 1000.

**Inside or outside the servo loop**: with both sensors, the share of the surface's error above its
noise that the position's error carries too, sample for sample (what ``surface − position`` no longer
holds beyond both floors). At half or more the error is the actuator's own motion, which the LVDT
reads too, not the linkage or the surface's compliance outside the loop: a servo whose dynamics go
beyond the fitted model's (motor and velocity loop, current limit, drive dead band, integral action),
so the remedy is a higher-fidelity declared model (``hoac1``, ``hoad3``), not another surface effect.

**The logger's timing**: a bench logger's sampling instants jitter about the uniform grid its stamps
are straightened to, which adds ``rate × δt`` to the residual: white, but only while the output moves.
The variance model ``σ² + σ_t²·rate²`` is fitted to the squared residual (σ_t the rms jitter); when
the residual divided by its square root is white (Ljung-Box, 1 %) with an rms within 1.5, the error is the logger's
timing, said as such (with the stamps' own scatter), and no structure is claimed.

**Proxies**: an added effect is a finding only if the record agrees with itself about it. The final
fit is linearised (one Gauss-Newton step from the final parameters on each half of the record, with
each half's coloured-residual covariance): a parameter whose two halves disagree by more than three
combined sigma and 20 % changes with what the record excites. An added effect that does so stands in
for structure the vocabulary lacks (a second lag for a resonance, free play for friction); a declared
model's own parameter that does so means the model's structure does not fit the whole record. A fitted
frequency (ωn, a corner) within 25 % of the frequency the residual still rings at stands in for that
mode. Each is said in the diagnosis and in the warnings, with the ring left.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray
from scipy.signal import welch
from scipy.stats import f as fisher

from ema_sim.analysis.estimation.noise import NoiseFloor, autocorrelation, whiteness
from ema_sim.analysis.records.series import Hold, holds
from ema_sim.identify.declared import HIGH_ORDER
from ema_sim.identify.effects import EFFECTS, FREE, Effect
from ema_sim.identify.fit import Fit, block_covariance
from ema_sim.identify.outcome import Identification
from ema_sim.identify.problem import EQUIVALENT_EXCESS, IN_LOOP_SHARE, Problem, in_loop_share
from ema_sim.identify.trust import bandwidth_hz, frequency_hz
from ema_sim.models.base import O_RATE

FloatArray = NDArray[np.float64]
STRUCTURED = 1.5
"""An output whose residual rms is above this many noise floors (and not white) has structure left."""
PART_SHARE = 0.4
PART_CONCENTRATION = 1.5
JITTER_WHITE = 0.01
"""The jitter-normalised residual counts as white when Ljung-Box does not reject it at 1 %."""
HOLD_S = 0.1
"""A command level held this long is at rest; between such holds the command moves."""
RING_S = 0.5
RING_ABOVE_NOISE = 4.0
RING_OCTAVE = 2.0
RING_PERIODS = 3.0
RING_SPREAD = 0.15
RING_MIN_WINDOWS = 3
MIN_EXPLAINED = 0.1
SIGNIFICANCE = 1e-3
FIR_HALF_S = 0.05
SPLIT_SIGMA = 3.0
SPLIT_RELATIVE = 0.2
MODE_MATCH = 0.25
"""A fitted frequency within this share of the frequency the residual still rings at stands in for that mode."""
FAMILIES = ("motion", "direction", "load sign", "load against motion", "current")
BY_FIELD: dict[str, Effect] = {f: e for e in reversed(EFFECTS) for f in e.owned}
"""The vocabulary effect each model parameter belongs to (the first that owns it)."""


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
    p_value: float
    """Chance of explaining as much with an unrelated input (partial F on the effective samples)."""

    def as_dict(self) -> dict[str, float | str]:
        """Plain values for JSON."""
        return {"input": self.name, "explained_share": self.explained, "p_value": self.p_value}


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
    """The frequency it rings at after the command stops (None: no ring the windows agree on)."""
    ring_windows: int = 0
    stop_windows: int = 0
    correlates: list[Correlate] = field(default_factory=list)
    """Inputs that explain more than chance, strongest first."""
    actuator_share: float | None = None
    """Share of this (surface) residual's variance the position's residual explains (None: not examined)."""
    jitter_s: float | None = None
    """Sampling-time jitter (rms, s) that, with the noise floor, explains the residual (None: it does not)."""
    stamp_scatter_s: float = 0.0
    floor_caveat: str = ""
    """Why the noise floor is not known to be noise (an upper bound, a limit cycle at rest; empty: it is)."""

    @property
    def in_loop(self) -> bool:
        """Most of this output's structured error is the actuator's motion, shared with the position."""
        return self.structured and self.actuator_share is not None and self.actuator_share >= IN_LOOP_SHARE

    @property
    def structured(self) -> bool:
        """Not white and well above the noise floor, and not sampling-time jitter: structure the model lacks."""
        return not self.white and self.rms > STRUCTURED * self.noise and self.jitter_s is None

    def jitter_statement(self) -> str:
        """What sampling-time jitter explains, in words (empty when it explains nothing)."""
        if self.jitter_s is None:
            return ""
        stamps = (f"; the stamps scatter {1e3 * self.stamp_scatter_s:.2g} ms rms about a uniform grid"
                  if self.stamp_scatter_s > 0 else "")
        return (f"the error beyond the noise floor on {self.output} is what sampling instants jittering by "
                f"{1e3 * self.jitter_s:.2g} ms rms leave (error ∝ rate; the residual divided by √(σ² + (rate·"
                f"{1e3 * self.jitter_s:.2g} ms)²) is white){stamps}: the logger's timing, not the actuator")

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
        """The diagnosis in a few words (for the warnings).

        Parameters
        ----------
        unit : str
            The record's position unit (deg, mm, in).
        """
        u = "°" if unit == "deg" else f" {unit}"
        bits = [f"{100 * p.excess_share:.0f} % of it {p.name}" for p in self.named_parts()]
        if self.median_hz is not None:
            bits.append(f"half its power above {self.median_hz:.2g} Hz")
        if self.line_hz is not None:
            bits.append(f"ringing at {self.line_hz:.3g} Hz")
        bits += [f"correlates with the {c.name} ({100 * c.explained:.0f} %)" for c in self.correlates]
        if self.in_loop:
            bits.append(f"{100 * (self.actuator_share or 0.0):.0f} % of it is the position's own error (inside the "
                        "servo loop)")
        return (f"residual not white on {self.output} (rms {self.rms:.3g}{u}, {self.rms / self.noise:.3g}× noise): "
                + "; ".join(bits))

    def sentence(self, unit: str, nyquist_hz: float, bandwidth: float) -> str:
        """The diagnosis in words, one sentence.

        Parameters
        ----------
        unit : str
            The record's position unit (deg, mm, in).
        nyquist_hz : float
            Half the sample rate (Hz).
        bandwidth : float
            The final model's −3 dB bandwidth (Hz).
        """
        u = "°" if unit == "deg" else f" {unit}"
        head = (f"{self.output}: rms {self.rms:.3g}{u}, {self.rms / self.noise:.3g}× its noise floor "
                f"{self.noise:.3g}{u}")
        if self.jitter_s is not None:
            return head + ": " + self.jitter_statement()
        if self.white and self.floor_caveat:  # a floor that is no noise cannot say nothing is left
            return head + f", white, but the floor is not shown to be noise: {self.floor_caveat}"
        if self.white:
            return head + ", white: nothing left to explain"
        if not self.structured:  # small, but a whiteness test that fails is never "nothing left"
            said = [f"it correlates with the {c.name} (a short filter of it explains {100 * c.explained:.0f} % of "
                    "the residual's variance)" for c in self.correlates] or ["no input explains it"]
            return (head + ", within 1.5× the floor but not white (Ljung-Box, 1 %): structure is left that the noise "
                    "nearly hides; " + "; ".join(said))
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
            bits.append(f"it rings at {self.line_hz:.3g} Hz after the command stops ({self.ring_windows} of "
                        f"{self.stop_windows} windows agree)")
        for c in self.correlates:
            bits.append(f"it correlates with the {c.name} (a short filter of it explains {100 * c.explained:.0f} % "
                        "of the residual's variance)")
        if not self.correlates:
            bits.append("no input explains it")
        if self.in_loop:
            share = 100 * (self.actuator_share or 0.0)
            bits.append(f"the position's residual carries {share:.0f} % "
                        "of it: the actuator's own motion is off (the LVDT reads it too), not the surface outside "
                        "the loop")
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
                            "above_bandwidth_share": d.above_bandwidth_share, "ring_hz": d.line_hz,
                            "correlates": [c.as_dict() for c in d.correlates],
                            "position_residual_share": d.actuator_share}
                        for o, d in self.outputs.items()},
            "proxies": [{"parameter": p.name, "effect": p.effect, "first_half": p.first, "second_half": p.second,
                         "sigma_of_difference": p.sigma} for p in self.proxies],
            "text": self.text,
        }


# ------------------------------------------------------------------------------------------ where in time
def _holds(problem: Problem) -> list[Hold]:
    """The command's held levels of at least :data:`HOLD_S` (a frame-held sweep or a ramp holds none)."""
    return holds(problem.data.command_deg, max(2, round(HOLD_S * problem.sample_hz)))


def _stops(problem: Problem) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Where each held level starts and ends, as indices among the fitted samples."""
    first = int(np.argmax(problem.mask))
    spans = [(h.start - first, h.stop - first) for h in _holds(problem) if h.start > first]
    return (np.array([a for a, _ in spans], dtype=np.int64), np.array([b for _, b in spans], dtype=np.int64))


def _parts(problem: Problem, fit: Fit, excess: FloatArray, bandwidth: float) -> list[Part]:
    """Shares of the excess error and of the time in each part of the record (module docstring)."""
    d = problem.data
    m = problem.mask
    settle_s = min(max(2.0 / bandwidth if math.isfinite(bandwidth) and bandwidth > 0 else 0.25, 0.25), 1.0)
    settle = round(settle_s * problem.sample_hz)
    moving = np.ones(m.size, dtype=bool)
    settling = np.zeros(m.size, dtype=bool)
    for h in _holds(problem):
        moving[h.start:h.stop] = False
        settling[h.start:min(h.stop, h.start + settle)] = True
    parts = {("motion", "while the command moves"): moving,
             ("motion", f"within {settle_s:.2g} s after the command reaches a new level"): settling,
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


# ------------------------------------------------------------------------------------------ the logger's timing
def _jitter(e: FloatArray, sigma: float, rate: FloatArray, fitted: int) -> float | None:
    """The rms sampling-time jitter that explains ``e`` with the noise floor, or None (module docstring)."""
    x = rate**2
    if not np.any(x):
        return None
    var_t = float(np.dot(x, e**2 - sigma**2) / np.dot(x, x))
    if var_t <= 0.0:
        return None
    z = e / np.sqrt(sigma**2 + var_t * x)
    test = whiteness(z, lags=50, fitted_params=fitted)
    ok = test.p_value >= JITTER_WHITE and float(np.sqrt(np.mean(z**2))) <= STRUCTURED
    return math.sqrt(var_t) if ok else None


# ------------------------------------------------------------------------------------------ frequency
def _spectrum(e: FloatArray, sigma: float, fs: float, bandwidth: float) -> tuple[float | None, float | None]:
    """Frequency below which half the excess power lies, and its share above ``bandwidth`` (module docstring)."""
    nper = int(min(e.size, 2 ** int(np.log2(max(fs * 4.0, 16.0)))))
    f, pxx = welch(e - np.mean(e), fs=fs, nperseg=nper)
    ex = np.clip(pxx - 2.0 * sigma**2 / fs, 0.0, None)
    ex[0] = 0.0
    if ex.sum() <= 0:
        return None, None
    cum = np.cumsum(ex)
    median = float(f[np.searchsorted(cum, 0.5 * cum[-1])])
    above = float(ex[f > bandwidth].sum() / ex.sum()) if math.isfinite(bandwidth) else None
    return median, above


def _decay(w: FloatArray) -> FloatArray:
    """The least-squares constant plus one decaying exponential through ``w`` (time constant from a grid)."""
    k = np.arange(w.size, dtype=float)
    best, fitted = np.inf, np.full(w.size, np.mean(w))
    for tau in np.geomspace(0.5, 2.0 * w.size, 24):
        a = np.column_stack([np.ones(w.size), np.exp(-k / tau)])
        coef, *_ = np.linalg.lstsq(a, w, rcond=None)
        fit = a @ coef
        rss = float(np.sum((w - fit) ** 2))
        if rss < best:
            best, fitted = rss, fit
    return fitted


def _ring(e: FloatArray, sigma: float, fs: float, stops: NDArray[np.int64], next_change: NDArray[np.int64]
          ) -> tuple[float | None, int, int]:
    """The frequency the residual rings at after the command reaches a level, the windows that agree, all windows.

    Each window runs from the start of a held command level to its end (at most :data:`RING_S`, at
    least 8 samples). What does not oscillate is taken out first: the best constant plus one decaying
    exponential (:func:`_decay`; a mismatched real pole leaves just that). A ring decays from the
    window's start, so what is left is tapered by the falling half of a Hann window only; its spectrum
    peaks at one frequency (at least three periods a window), counted when the peak is narrow (twice
    the spectrum an octave below and above: a ring, not a shape) and stands four times above what
    the noise floor σ alone gives (no chance over all bins). A mode rings at the same frequency after
    every level: a ring is claimed when at least three windows and half of those counted agree within
    15 % (their median).
    """
    peaks = []
    for a, nxt in zip(stops, next_change, strict=True):
        w = e[a:min(nxt, a + round(RING_S * fs))]
        if w.size < 8:
            continue
        w = w - _decay(w)
        taper = np.cos(0.5 * np.pi * np.arange(w.size) / (w.size - 1)) ** 2
        n = max(1024, 1 << int(np.ceil(np.log2(8 * w.size))))
        spec = np.abs(np.fft.rfft(w * taper, n))
        freqs = np.fft.rfftfreq(n, 1.0 / fs)
        noise = sigma * np.sqrt(np.sum(taper**2))
        low = int(np.searchsorted(freqs, RING_PERIODS * fs / w.size))
        j = low + int(np.argmax(spec[low:]))
        octave = np.interp([freqs[j] / 2.0, min(2.0 * freqs[j], freqs[-1])], freqs, spec)
        if j > low and spec[j] >= RING_ABOVE_NOISE * noise and spec[j] >= RING_OCTAVE * float(np.max(octave)):
            peaks.append(float(freqs[j]))
    best: list[float] = []
    for f0 in peaks:
        cluster = [f for f in peaks if abs(f - f0) <= RING_SPREAD * f0]
        if len(cluster) > len(best):
            best = cluster
    if len(best) >= max(RING_MIN_WINDOWS, 0.5 * len(peaks)):
        return float(np.median(best)), len(best), len(peaks)
    return None, len(best), len(peaks)


# ------------------------------------------------------------------------------------------ inputs
def _regressors(problem: Problem, fit: Fit) -> dict[str, FloatArray]:
    d = problem.data
    t = problem.time_s
    u = d.command_deg
    rate = fit.sim[:, O_RATE]
    out = {"command": u, "command rate": np.gradient(u, t),
           "command acceleration": np.gradient(np.gradient(u, t), t),
           "direction of motion (sign of the rate: friction, backlash)":
               np.where(np.abs(rate) > 0.01 * max(float(np.max(np.abs(rate))), 1e-12), np.sign(rate), 0.0)}
    if problem.load_span_inlb > 20.0:
        out |= {"hinge moment": problem.hinge_moment, "hinge moment rate": np.gradient(problem.hinge_moment, t)}
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


def _what_is_left(result: Identification) -> str:
    """What a structured residual is, said of the final model (the vocabulary's effects, or a model's physics)."""
    if result.physical is not None:
        return (f"what is left is structure {result.physical.model}'s physics, fitted, does not explain; its "
                "parameters are the best that structure allows, not a description of what is left")
    added = ", ".join(s.effect for s in result.steps) or "nothing"
    return (f"what is left is structure no effect of the vocabulary explains (added: {added}); the "
            "model's parameters are the best this structure allows, not a description of it")


def _what_the_structure_means(result: Identification, left: list[OutputDiagnosis]) -> list[str]:
    """What a structured residual says about the fitted parameters and where the missing structure lies.

    Parameters
    ----------
    result : Identification
        The outcome.
    left : list of OutputDiagnosis
        The outputs whose residual is structured.
    """
    lines: list[str] = []
    if not left:
        return lines
    worst = max(left, key=lambda d: d.rms / d.noise)
    if worst.rms > EQUIVALENT_EXCESS * worst.noise:
        line = (f"the fitted parameters are equivalents of a model that leaves {worst.rms / worst.noise:.3g}× the "
                f"noise on {worst.output}: their uncertainties cover the noise, not the missing structure, so "
                "another maneuver of the same actuator can give values that differ beyond them (fitted delays "
                "hold the lags the model lacks)")
        lines.append(line)
    servo = (": the servo's dynamics go beyond the fitted model's (motor and velocity loop, current limit, drive "
             "dead band, integral action)")
    remedy = ("" if result.final_model else
              servo + f"; the declared {result.model}'s own structure carries them, its second-order-family "
              "equivalent does not" if result.model.strip().lower() in HIGH_ORDER else
              servo + "; a higher-fidelity declared model (--model hoac1 or hoad3) is what it asks for, not another "
              "surface effect")
    lines += [f"{100 * (d.actuator_share or 0.0):.0f} % of the residual on {d.output} is the position's own error: "
              f"the actuator's motion is off inside the servo loop, not the surface outside it{remedy}"
              for d in left if d.in_loop]
    return lines


def _share(e: FloatArray, a: FloatArray) -> float:
    """Share of ``e``'s variance the least-squares combination of the columns of ``a`` explains."""
    e = e - np.mean(e)
    tss = float(np.dot(e, e))
    if tss <= 0 or a.shape[1] == 0:
        return 0.0
    coef, *_ = np.linalg.lstsq(a, e, rcond=None)
    fitted = a @ coef
    return float(np.dot(fitted, fitted) / tss)


def _effective_samples(e: FloatArray, x: FloatArray) -> float:
    """Independent samples behind a correlation of ``e`` with ``x``: N/(1 + 2Σρₑρₓ) (Bartlett)."""
    k_max = min(200, e.size // 4)
    rho = float(np.sum(autocorrelation(e, k_max)[1:] * autocorrelation(x, k_max)[1:]))
    return e.size / max(1.0 + 2.0 * rho, 1.0)


def _correlates(e: FloatArray, inputs: dict[str, FloatArray], fs: float) -> list[Correlate]:
    """Inputs that explain the residual beyond chance, chosen greedily: each counts only for what it adds.

    An input counts when it explains at least 10 % of the residual's variance beyond the inputs named
    before it and the partial F test on the effective samples rejects chance at 1 in 1000.
    """
    cols = {name: _lagged(x, fs) for name, x in inputs.items() if np.ptp(x) > 0}
    chosen: list[Correlate] = []
    base = np.zeros((e.size, 0))
    explained = 0.0
    while cols:
        shares = {name: _share(e, np.column_stack([base, a])) for name, a in cols.items()}
        name = max(shares, key=lambda k: shares[k])
        gain = shares[name] - explained
        taps, total = cols[name].shape[1], base.shape[1] + cols[name].shape[1]
        dof = _effective_samples(e, inputs[name]) - total - 1.0
        if gain < MIN_EXPLAINED or dof <= 0:
            break
        p = float(fisher.sf((gain / taps) / (max(1.0 - shares[name], 1e-12) / dof), taps, dof))
        if p > SIGNIFICANCE:
            break
        chosen.append(Correlate(name, gain, p))
        base = np.column_stack([base, cols.pop(name)])
        explained = shares[name]
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


def _floor_caveat(nf: NoiseFloor | None, output: str, unit: str) -> str:
    """Why an output's floor is not known to be noise: a line at rest, an upper bound (empty: it is noise)."""
    if nf is None or nf.rests is None:
        return ""
    label = output.removesuffix("_deg")
    bits = []
    if nf.rests.line is not None and nf.upper_bound:
        bits.append(nf.rests.line.statement(label, unit) + "; the floor holds it, so what the model leaves at that "
                    "floor is this behaviour, unexplained, not nothing")
    elif nf.upper_bound:
        bits.append(f"it is an upper bound ({nf.rests.why_no_quiet_rest}): at most that much of the residual is noise")
    if nf.rests.growth is not None and nf.basis != "rests":
        bits.append(nf.rests.growth.statement(label, unit, nf.rests.quiet_floor))
    return "; ".join(bits)


def _hunting_rings(p: Problem, left: list[OutputDiagnosis]) -> list[str]:
    """A ring left at the frequency an output hunts at at rest: the limit cycle, not a mode (one line each)."""
    out = []
    for o, ring in [(d.output, d.line_hz) for d in left if d.line_hz is not None]:
        lc = r.limit_cycle if (r := p.noise[o].rests if p.noise else None) is not None else None
        if lc is not None and abs(lc.freq_hz - ring) <= MODE_MATCH * ring:
            out.append(f"{o.removesuffix('_deg')} rings at {ring:.3g} Hz, the frequency it hunts at at rest "
                       f"({lc.freq_hz:.3g} Hz, ±{lc.amplitude:.2g}): the limit cycle, not a mode; no effect of the "
                       "vocabulary models it")
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
    bw = math.inf if result.final_model else bandwidth_hz(fit.params)
    outputs: dict[str, OutputDiagnosis] = {}
    errors = p.errors_deg(fit.sim)
    scatter = result.record.stamp_scatter_s if result.record else 0.0
    for o, e in errors.items():
        sigma = p.sigma_deg[o]
        rms = float(np.sqrt(np.mean(e**2)))
        white = whiteness(e / sigma, lags=50, fitted_params=len(fit.free)).white
        d = OutputDiagnosis(o, rms, sigma, white, stamp_scatter_s=scatter,
                            floor_caveat=_floor_caveat(p.noise[o] if p.noise else None, o, unit))
        if not white and rms > STRUCTURED * sigma:
            d.jitter_s = _jitter(e, sigma, fit.sim[p.mask, O_RATE], len(fit.free))
        if not white and not d.structured and d.jitter_s is None:
            d.correlates = _correlates(e, {k: x[p.mask] for k, x in _regressors(p, fit).items()}, fs)
        if d.structured:
            excess = e**2 - sigma**2
            d.parts = _parts(p, fit, excess, bw)
            d.median_hz, d.above_bandwidth_share = _spectrum(e, sigma, fs, bw)
            d.line_hz, d.ring_windows, d.stop_windows = _ring(e, sigma, fs, *_stops(p))
            d.correlates = _correlates(e, {k: x[p.mask] for k, x in _regressors(p, fit).items()}, fs)
            if o == "surface_deg" and "position_deg" in errors:
                d.actuator_share = in_loop_share(e, errors["position_deg"], sigma, p.sigma_deg["position_deg"])
        outputs[o] = d
    proxies = []
    own = set(result.baseline.free)
    for proxy in _halves(p, fit):
        effect = None if proxy.name in own else (BY_FIELD[proxy.name].name if proxy.name in BY_FIELD else proxy.name)
        proxies.append(Proxy(proxy.name, effect, proxy.first, proxy.second, proxy.sigma))
    nyquist = 0.5 * fs
    text = [d.sentence(unit, nyquist, bw) for d in outputs.values()]
    warnings = [d.short(unit) for d in outputs.values() if d.structured]
    warnings += [d.jitter_statement() for d in outputs.values() if d.jitter_s is not None]
    left = [d for d in outputs.values() if d.structured]
    if left:
        text.append(_what_is_left(result))
    for line in [*_what_the_structure_means(result, left), *_hunting_rings(p, left)]:
        text.append(line)
        warnings.append(line)
    rings = [(d.output, d.line_hz) for d in left if d.line_hz is not None]
    seen = "; ".join(f"{o} rings at {f:.3g} Hz" for o, f in rings)
    for px in proxies:
        what = (f"the added {px.effect} stands in for structure the vocabulary lacks, not a finding"
                if px.effect else "the declared model's structure does not fit the whole record")
        line = (f"{px.name} changes with the part of the record it is estimated on ({px.first:.4g} from the first "
                f"half, {px.second:.4g} from the second, ±{px.sigma:.2g}): {what}" + (f" ({seen})" if seen else ""))
        text.append(line)
        warnings.append(line)
    for name in fit.free:
        f = frequency_hz(name, float(getattr(fit.params, name)))
        for o, ring in rings:
            if f is not None and abs(f - ring) <= MODE_MATCH * ring:
                line = (f"{name} ({f:.3g} Hz) sits at the frequency {o} still rings at ({ring:.3g} Hz): the fitted "
                        "dynamics stand in for a mode the model lacks; read it as that mode, not as the servo's own")
                text.append(line)
                warnings.append(line)
    return Diagnosis(outputs, proxies, text, warnings)


