"""Isolation and re-estimation: which fault explains the residual after a detection, and how big it is.

Every fault kind the reference model has a stage for is a candidate, with its implicated parameter. From the
estimated onset, the reference (a copy of it in its state there) is run on with that one parameter free and
fitted over the window by bounded least squares; the sensor faults are solved in closed form on the nominal
prediction; a jam and a reversed load have no parameter and are run as they are. The candidate that leaves
the least normalized residual, two per fitted parameter added (Akaike), is the isolated fault. The parameter's
one-sigma uncertainty is identification's coloured-residual covariance
(:func:`ema_sim.identify.fit.block_covariance`).

The signature (which outputs depart, moving or at rest, with the direction of motion, with the load, whether
the rod still moves) votes where it discriminates: a candidate it contradicts ranks after every candidate it
does not, whatever their scores (:func:`contradiction`). An LVDT fault is in the reading only, so it cannot
make the surface or the current depart; a fault of the actuator moves the rod, so the surface follows it and
it cannot leave the surface and the current as predicted while the reading departs; a jam stops the rod, so
it cannot be the fault while the rod goes on moving. The fits decide among the candidates the signature
leaves; when it contradicts them all, the fits alone decide.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import minimize_scalar

from ema_sim.faults.kinds import FAULTS, SECOND_ORDER, FloatArray, Jam
from ema_sim.faults.schedule import model_family
from ema_sim.identify.fit import block_covariance
from ema_sim.io.measured import MeasuredData
from ema_sim.models import ActuatorModel
from ema_sim.monitor.reference import continue_run, snapshot
from ema_sim.parameters import metas

OUTPUT_KINDS = ("lvdt_bias", "lvdt_drift", "lvdt_scale")
DEPARTS = 3.0
"""An output departs when its residual's rms over the window exceeds this many healthy spreads."""
QUIET = 1.5
"""An output is as predicted when its residual's rms stays under this many healthy spreads."""
STILL = 0.5
"""The rod goes on moving when its measured travel over the window is above this share of the predicted."""
MAX_SAMPLES = 1500
"""Samples of the window each output contributes to a fit (decimated evenly beyond that: the cost stays bounded)."""


@dataclass(frozen=True)
class Candidate:
    """A fault kind the reference can carry, with its implicated parameter and range."""

    kind: str
    parameter: str
    nominal: float
    low: float
    high: float
    followers: tuple[tuple[str, float], ...] = ()
    """Other parameters the fault moves in proportion (name, nominal): stiction with Coulomb friction."""

    @property
    def free(self) -> int:
        """Fitted parameters: 1, or 0 for a jam and a reversed load."""
        return 0 if self.kind in ("jam", "hm_sign") else 1

    def values(self, p: float) -> dict[str, float]:
        """Kernel parameter values with the implicated one at ``p``."""
        out = {self.parameter: p}
        ratio = p / self.nominal if self.nominal else 1.0
        for name, nominal in self.followers:
            out[name] = nominal * ratio
        return out


@dataclass
class Estimate:
    """One candidate fitted on a window."""

    kind: str
    parameter: str
    nominal: float
    estimate: float
    uncertainty: float
    cost: float
    score: float
    veto: str = ""
    """What in the signature contradicts this candidate (empty: nothing)."""


@dataclass
class Window:
    """The record from the onset on, what the reference predicted there, and how residuals are weighed."""

    data: MeasuredData
    model: ActuatorModel
    """The reference in its state at ``onset_s``."""
    onset_s: float
    start_s: float
    end_s: float
    nominal: FloatArray
    """The nominal prediction at the samples in ``[onset_s, end_s)``, ``(samples, 3)``."""
    sigma: tuple[float, ...]
    """Per-sample residual spread of position, surface and current on the healthy window."""
    outputs: tuple[bool, ...] = (True, True, False)
    times: FloatArray = field(init=False)
    measured: FloatArray = field(init=False)
    pick: NDArray[np.int64] = field(init=False)

    def __post_init__(self) -> None:
        t = self.data.time_s - self.data.time_s[0]
        sel = (t >= self.onset_s) & (t < self.end_s)
        self.times = t[sel]
        cols = [self.data.position_deg, self.data.surface_deg, self.data.current_a]
        self.measured = np.column_stack([c[sel] if c is not None else np.zeros(int(sel.sum())) for c in cols])
        idx = np.flatnonzero(self.times >= self.start_s)
        step = max(1, math.ceil(idx.size / MAX_SAMPLES))
        self.pick = idx[::step]

    def residual(self, predicted: FloatArray) -> FloatArray:
        """Measured minus predicted over the fitted samples, normalized, outputs stacked."""
        parts = [(self.measured[self.pick, j] - predicted[self.pick, j]) / self.sigma[j]
                 for j in range(3) if self.outputs[j]]
        return np.concatenate(parts)


def candidates(model: ActuatorModel, data: MeasuredData) -> list[Candidate]:
    """Every fault kind ``model`` has a stage for, with its implicated parameter's nominal value and range."""
    family = model_family(model)
    prm = model.params[0]  # type: ignore[attr-defined]
    info = metas(type(prm))
    out: list[Candidate] = []
    for kind, cls in FAULTS.items():
        if cls.stage == "output":
            if data.position_deg is not None:
                out.append(Candidate(kind, {"lvdt_bias": "bias_deg", "lvdt_drift": "drift_dps",
                                            "lvdt_scale": "scale"}[kind], 0.0, -math.inf, math.inf))
            continue
        if cls.stage == "input":
            if data.hinge_moment_inlb is not None and np.any(data.hinge_moment_inlb != 0.0):
                out.append(Candidate(kind, "load_sign", 1.0, -1.0, 1.0))
            continue
        changes = cls.changes.get(family, ())
        if not changes:
            continue
        name = changes[0].parameter
        nominal = float(getattr(prm, name))
        if cls is Jam:
            out.append(Candidate(kind, "jammed", 0.0, 0.0, 1.0))
            continue
        if not math.isfinite(nominal) or (nominal == 0.0 and changes[0].how == "scale" and kind != "backlash"):
            continue  # the stage is off in the reference: a change of it cannot be fitted from its nominal
        m = info[name]
        low = m.min if m.min is not None and math.isfinite(m.min) else 0.0
        high = m.max if m.max is not None and math.isfinite(m.max) else max(10.0 * abs(nominal), 1.0)
        if kind == "backlash":
            high = max(high if m.max is not None else 0.0, 20.0 * nominal, 1.0 if family == SECOND_ORDER else 0.05)
        followers = tuple((c.parameter, float(getattr(prm, c.parameter))) for c in changes[1:] if c.how == "scale")
        out.append(Candidate(kind, name, nominal, low, high, followers))
    return out


def _run(win: Window, values: dict[str, float] | None, *, flip: bool = False) -> FloatArray:
    model = snapshot(win.model)
    if values:
        model.retune(**values)
    return continue_run(model, win.data, win.onset_s, win.end_s, flip_load=flip)


def jam_values(win: Window) -> dict[str, float]:
    """The reference's parameters seized where the window starts (a jam has no size to fit)."""
    family = model_family(win.model)
    held = float(win.nominal[0, 0]) if win.nominal.size else 0.0
    nominal: dict[str, float] = {}
    values: dict[str, float] = {}
    for c in Jam.changes[family]:
        base = nominal.setdefault(c.parameter, float(getattr(win.model.params[0], c.parameter)))  # type: ignore[attr-defined]
        values[c.parameter] = c.apply(base, 1.0, 1.0, held)
    return values


def fit_candidate(win: Window, cand: Candidate) -> Estimate:
    """Fit one candidate on the window.

    Parameters
    ----------
    win : Window
        The window.
    cand : Candidate
        The candidate.

    Returns
    -------
    Estimate
        Its estimate, one-sigma uncertainty, cost and score.
    """
    if cand.kind == "jam":
        r = win.residual(_run(win, jam_values(win)))
        return _estimate(cand, 1.0, math.nan, r)
    if cand.kind == "hm_sign":
        r = win.residual(_run(win, None, flip=True))
        return _estimate(cand, 1.0, math.nan, r)
    if cand.kind in OUTPUT_KINDS:
        return _sensor(win, cand)
    grid = _grid(cand)

    def cost(p: float) -> float:
        r = win.residual(_run(win, cand.values(float(p))))
        return float(r @ r)

    costs = [cost(p) for p in grid]
    i = int(np.argmin(costs))
    lo, hi = grid[max(i - 1, 0)], grid[min(i + 1, grid.size - 1)]
    best_p, best_c = float(grid[i]), costs[i]
    if hi > lo:
        res = minimize_scalar(cost, bounds=(lo, hi), method="bounded",
                              options={"xatol": 1e-3 * max(abs(best_p), (hi - lo) * 0.01), "maxiter": 14})
        if float(res.fun) < best_c:
            best_p = float(res.x)
    # the Jacobian by a secant wide enough to see through a stepped (quantized) parameter
    step = max(0.05 * abs(best_p), 0.05 * (hi - lo), 1e-9)
    r = win.residual(_run(win, cand.values(best_p)))
    up = win.residual(_run(win, cand.values(min(best_p + step, cand.high))))
    down = win.residual(_run(win, cand.values(max(best_p - step, cand.low))))
    width = min(best_p + step, cand.high) - max(best_p - step, cand.low)
    jac = ((down - up) / width)[:, None] if width > 0.0 else np.zeros((r.size, 1))  # d(residual)/dp is -d(model)
    return _estimate(cand, best_p, _sigma(win, r, jac), r)


def _grid(cand: Candidate) -> FloatArray:
    """The coarse values a candidate's parameter is first tried at (a stepped parameter has no gradient)."""
    if FAULTS[cand.kind].relative and cand.nominal > 0.0:
        points = cand.nominal * np.array([0.3, 0.5, 0.7, 0.85, 1.0, 1.15, 1.3, 1.5, 2.0, 3.0, 5.0])
    elif FAULTS[cand.kind].relative:
        points = np.linspace(cand.low, cand.low + (cand.high - cand.low) / 4.0, 11)
    else:
        points = cand.nominal + np.array([0.0, 0.00125, 0.0025, 0.005, 0.0075, 0.01, 0.015, 0.02, 0.04])
    return np.unique(np.clip(points, cand.low, cand.high))


def _sigma(win: Window, residual: FloatArray, jac: FloatArray) -> float:
    n = win.pick.size
    blocks = [slice(i * n, (i + 1) * n) for i in range(residual.size // max(n, 1))]
    cov = block_covariance([residual[b] for b in blocks], [np.asarray(jac)[b] for b in blocks])
    return float(math.sqrt(cov[0, 0])) if np.isfinite(cov[0, 0]) and cov[0, 0] >= 0.0 else math.inf


def _sensor(win: Window, cand: Candidate) -> Estimate:
    """Bias, drift or scale of the LVDT reading in closed form on the nominal prediction."""
    t = win.times[win.pick]
    basis: Callable[[], FloatArray] = {
        "lvdt_bias": lambda: np.ones(t.size),
        "lvdt_drift": lambda: t - win.onset_s,
        "lvdt_scale": lambda: win.nominal[win.pick, 0],
    }[cand.kind]
    col = basis() / win.sigma[0]
    r0 = win.residual(win.nominal)
    n = win.pick.size
    jac = np.zeros((r0.size, 1))
    jac[:n, 0] = col
    denom = float(col @ col)
    p = float(col @ r0[:n]) / denom if denom > 0.0 else 0.0
    r = r0 - jac[:, 0] * p
    return _estimate(cand, p, _sigma(win, r, jac), r)


def _estimate(cand: Candidate, p: float, sigma: float, residual: FloatArray) -> Estimate:
    cost = float(residual @ residual)
    return Estimate(cand.kind, cand.parameter, cand.nominal, p, sigma, cost, cost + 2.0 * cand.free)


def isolate(win: Window, cands: list[Candidate], sig: dict[str, object] | None = None) -> list[Estimate]:
    """Every candidate fitted on the window, best first.

    Without ``sig`` by score; with it, the candidates it does not contradict by score, then the others by score
    (the signature votes only where it discriminates: :func:`contradiction`).
    """
    fitted = [fit_candidate(win, c) for c in cands]
    if sig is not None:
        for e in fitted:
            e.veto = contradiction(e.kind, sig)
        if all(e.veto for e in fitted):
            for e in fitted:
                e.veto = ""
    return sorted(fitted, key=lambda e: (bool(e.veto), e.score))


def contradiction(kind: str, sig: dict[str, object]) -> str:
    """What in a window's signature rules a fault kind out (module docstring); empty when nothing does.

    Parameters
    ----------
    kind : str
        The fault kind.
    sig : dict
        :func:`signature`'s.

    Returns
    -------
    str
        The reason, or "".
    """
    rms = sig.get("outputs")
    if not isinstance(rms, dict):
        return ""
    pos = rms.get("position_deg")
    others = {k: v for k, v in rms.items() if k != "position_deg"}
    if kind in OUTPUT_KINDS:
        loud = [k for k, v in others.items() if v > DEPARTS]
        return f"{' and '.join(loud)} depart too: not the reading alone" if loud else ""
    if kind == "jam":
        travel = sig.get("travel_share")
        if isinstance(travel, float) and travel > STILL:
            return f"the rod travels {travel:.0%} of the predicted: it has not stopped"
    if kind not in ("linkage",) and pos is not None and pos > DEPARTS and others \
            and all(v < QUIET for v in others.values()):
        return "only the position reading departs: the surface and current follow the prediction"
    return ""


def signature(win: Window, hinge_moment_inlb: FloatArray | None) -> dict[str, object]:
    """Where the residual departs: which outputs, moving or at rest, with the direction, with the load.

    Parameters
    ----------
    win : Window
        The window (nominal prediction against the measurement).
    hinge_moment_inlb : numpy.ndarray, optional
        The load over the window's samples.

    Returns
    -------
    dict
        ``outputs`` (the normalized rms of each), ``moving_share`` (of the squared residual, while the
        predicted rate exceeds 1 deg/s), ``direction_correlation``, ``load_correlation`` and
        ``travel_share`` (:func:`travel`).
    """
    r = (win.measured - win.nominal) / np.array(win.sigma)
    names = ("position_deg", "surface_deg", "current_a")
    rms = {name: float(np.sqrt(np.mean(r[:, j] ** 2))) for j, name in enumerate(names)
           if win.outputs[j] and r.shape[0]}
    j = 0 if win.outputs[0] else 1
    rate = np.gradient(win.nominal[:, j], win.times) if win.times.size > 2 else np.zeros(win.times.size)
    moving = np.abs(rate) > 1.0
    energy = r[:, j] ** 2
    share = float(energy[moving].sum() / energy.sum()) if energy.sum() > 0.0 else 0.0

    def corr(a: FloatArray, b: FloatArray) -> float:
        if a.size < 3 or np.std(a) == 0.0 or np.std(b) == 0.0:
            return 0.0
        return float(np.corrcoef(a, b)[0, 1])

    load = np.zeros(win.times.size) if hinge_moment_inlb is None else hinge_moment_inlb
    return {"outputs": rms, "moving_share": share, "direction_correlation": corr(r[:, j], np.sign(rate)),
            "load_correlation": corr(r[:, j], load), "travel_share": travel(win.measured[:, j], win.nominal[:, j])}


def travel(measured: FloatArray, predicted: FloatArray) -> float:
    """The measured travel over a window as a share of the predicted (5th to 95th percentile: noise-proof)."""
    if measured.size < 3:
        return 1.0
    want = float(np.percentile(predicted, 95) - np.percentile(predicted, 5))
    got = float(np.percentile(measured, 95) - np.percentile(measured, 5))
    return got / want if want > 0.0 else 1.0
