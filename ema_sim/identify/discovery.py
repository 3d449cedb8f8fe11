"""Discovery beyond the vocabulary: what the residual is made of, and the loop closed with it.

When the final model leaves an output's residual structured (not white, above
:data:`STRUCTURED` times its noise floor) and no named effect explains it any more, the residual is
regressed on a library of terms built from the record (:mod:`ema_sim.identify.library`) by stepwise
regression (:mod:`ema_sim.identify.regression`). The terms that hold up in both halves of the record
are *discovered*; those that do not are said to be tried and dropped.

Then the loop is closed, as for any named effect: the discovered terms are added where they act and
the model is refitted with them, in two placements:

* **on the reading**: each output's model plus the best combination of its terms, solved at every
  evaluation of the refit (variable projection), so the model's own parameters move with them: a
  sensor's scale error, drift, tone, bow;
* **inside the loop**: the actuator's terms (the position's, or the surface's without one) added to the
  command the servo follows, their coefficients fitted with the model's parameters: a drag, a
  position-dependent spring, a direction asymmetry, which the servo answers through its own dynamics.

The placement with the lower BIC is kept when it pays (ΔBIC ≤ −10) and leaves no output worse than the
model before it, the baseline or the reference (:mod:`ema_sim.identify.stages`); the report gives the
error before and after each. A model whose parameters cannot be refitted (a fitted physics, the
reference) gets its terms on the reading only, the model as it is.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import least_squares

from ema_sim.analysis.estimation.noise import whiteness
from ema_sim.identify.effects import FREE
from ema_sim.identify.fit import TINY, Fit, block_covariance, difference_points, finite, rms
from ema_sim.identify.library import describe, library
from ema_sim.identify.problem import OUTPUT_COLUMN, Problem
from ema_sim.identify.regression import Regression, Selected, Term, stepwise
from ema_sim.identify.stages import worse
from ema_sim.jsontypes import JsonObject, JsonValue
from ema_sim.models.base import O_RATE
from ema_sim.models.second_order import SecondOrderParams

FloatArray = NDArray[np.float64]
STRUCTURED = 1.5
"""An output whose residual rms is above this many noise floors and not white has structure to discover."""
MAX_DELTA_BIC = -10.0
MAX_LOOP_TERMS = 3
"""Most terms added inside the loop (each a coefficient fitted through the simulation)."""
LOOP_KINDS = ("motion", "either")
MAX_NFEV = 30
WHITENESS_LAGS = 50
EQUIVALENT: dict[str, tuple[str, ...]] = {
    "command_gain": ("command", "position"),
    "command_bias": ("1",),
    "static_threshold": ("sign(rate)",),
    "time_delay": ("rate",),
    "lag_filter": ("rate",),
}
"""Named effects and the library terms that, where they act, do what the effect does: a gain error on the command is
a term in the command (or the position, inside the loop), a bias a constant, a threshold a drag that reverses with
the motion, a delay or a lag a term in the rate. Such a term is reported as the named effect's equivalent."""


@dataclass
class Found:
    """One output's residual and what the regression found in it."""

    output: str
    rms_deg: float
    noise_deg: float
    white: bool
    regression: Regression
    statement: str = ""

    @property
    def structured(self) -> bool:
        """Not white and above :data:`STRUCTURED` times the floor."""
        return not self.white and self.rms_deg > STRUCTURED * self.noise_deg


@dataclass
class Closure:
    """The loop closed with the discovered terms in one placement."""

    where: str
    """``reading`` (each output's model plus its terms) or ``inside the loop`` (added to the command)."""
    terms: dict[str, list[tuple[str, tuple[float, ...], tuple[float, ...], str]]]
    """Output (or ``command``) → (term, coefficients, one-sigma, unit) of each term, as fitted with the model."""
    rms_deg_before: dict[str, float]
    rms_deg_after: dict[str, float]
    delta_bic: float
    kept: bool = False
    reason: str = ""
    fit: Fit | None = field(default=None, repr=False)


@dataclass
class Discovery:
    """What discovery found on each output, the placements tried, and the one kept."""

    found: dict[str, Found] = field(default_factory=dict)
    closures: list[Closure] = field(default_factory=list)
    statements: list[str] = field(default_factory=list)

    @property
    def kept(self) -> Closure | None:
        """The placement kept (None: none paid)."""
        return next((c for c in self.closures if c.kept), None)

    def label(self) -> str:
        """The kept terms, as the final model's name carries them (empty when none was kept)."""
        c = self.kept
        if c is None:
            return ""
        names = [f"{n} ({o.split('_')[0]})" for o, ts in c.terms.items() for n, *_ in ts]
        where = "inside the loop" if c.where == "inside the loop" else "on the reading"
        return f"discovered: {', '.join(names)} {where}"

    def equivalents(self, effects: Sequence[str]) -> list[tuple[str, str]]:
        """(named effect, kept term) pairs where a kept term does what the named effect does (:data:`EQUIVALENT`).

        Parameters
        ----------
        effects : sequence of str
            The named effects (vocabulary names).

        Returns
        -------
        list
            Each named effect with a kept term equivalent to it.
        """
        c = self.kept
        if c is None:
            return []
        names = [n for ts in c.terms.values() for n, *_ in ts]
        return [(e, n) for e in effects for n in names if n in EQUIVALENT.get(e, ())]

    def as_dict(self) -> JsonObject:
        """Plain values for JSON (the report's ``discovered``).

        Returns
        -------
        dict
            Per output the terms that hold and those tried and dropped, the placements and the words.
        """
        outputs: JsonObject = {}
        closures: list[JsonValue] = []
        for o, f in self.found.items():
            reg = f.regression
            outputs[o] = {
                "rms_deg": f.rms_deg, "noise_deg": f.noise_deg, "white": f.white, "structured": f.structured,
                "terms": [_selected(s) for s in reg.selected],
                "dropped": [_selected(s) for s in reg.dropped],
                "explained_share": reg.explained, "excess_explained_share": reg.excess_explained,
                "statement": f.statement,
            }
        for c in self.closures:
            closures.append({
                "where": c.where, "kept": c.kept, "reason": c.reason, "delta_bic": c.delta_bic,
                "rms_deg_before": dict(c.rms_deg_before), "rms_deg_after": dict(c.rms_deg_after),
                "terms": {o: [{"term": n, "coefficient": list(v), "uncertainty": list(s), "unit": u}
                              for n, v, s, u in ts] for o, ts in c.terms.items()},
            })
        return {"outputs": outputs, "closures": closures, "text": list(self.statements)}


def named_stands(named_rms: Mapping[str, float], noise: Mapping[str, float]) -> bool:
    """Whether named effects explain the record: every output within :data:`STRUCTURED` times its noise floor.

    A model of named physical effects that leaves no more than that is not replaced by discovered terms,
    however much better they fit: what is left is within the noise, and the named effects say what it is.

    Parameters
    ----------
    named_rms : mapping
        Each output's rms error of the model with the named effects.
    noise : mapping
        Each output's noise floor.
    """
    return all(v <= STRUCTURED * noise[o] for o, v in named_rms.items())


def _selected(s: Selected) -> JsonObject:
    return {"term": s.term.name, "coefficient": list(s.coef), "uncertainty": list(s.sigma), "unit": s.term.unit,
            "amplitude": s.amplitude, "variance_share": s.share, "p_value": s.p_value,
            "halves": [[v if math.isfinite(v) else None for v in h] for h in s.halves], "holds": s.holds,
            "why": s.why, "meaning": s.term.meaning,
            "acts": s.term.kind}


def _unit(problem: Problem) -> str:
    unit = problem.data.unit
    return "°" if unit == "deg" else f" {unit}"


def _name(output: str) -> str:
    return {"position_deg": "the LVDT", "surface_deg": "the surface"}.get(output, output)


def _terms(problem: Problem, sim: FloatArray, output: str, e: FloatArray) -> list[Term]:
    d = problem.data
    hm = problem.hinge_moment if problem.load_span_inlb > 0.0 else None
    return library(problem.time_s, d.command_deg, sim[:, OUTPUT_COLUMN[output]], sim[:, O_RATE], hm, e, problem.mask,
                   _unit(problem))


def statement(output: str, reg: Regression, unit: str) -> str:
    """What explains an output's residual, in words.

    Parameters
    ----------
    output : str
        The output.
    reg : Regression
        What the regression found.
    unit : str
        The output's unit symbol.

    Returns
    -------
    str
        One sentence (the terms with their coefficients and meaning, or that none holds).
    """
    who = _name(output)
    if not reg.selected:
        tried = "; ".join(f"{s.term.name}, which would explain {100 * s.share:.0f} % of its variance, dropped: {s.why}"
                          for s in reg.dropped)
        return (f"no term of the library that holds up explains the residual on {who}"
                + (f" ({tried})" if tried else ""))
    eq = " ".join(describe(s.term, s.coef, unit) for s in reg.selected)
    meanings = "; ".join(f"{s.term.name}: {s.term.meaning}" for s in reg.selected)
    return (f"the residual on {who} ≈ {eq} ({100 * reg.excess_explained:.0f} % of its variance above the noise "
            f"explained, each term holding in both halves of the record): {meanings}")


def regress(problem: Problem, fit: Fit) -> Discovery:
    """Regress each output's residual on the library (module docstring), without closing the loop.

    Parameters
    ----------
    problem : Problem
        The record as fitted.
    fit : Fit
        The model whose residual is examined.

    Returns
    -------
    Discovery
        Per output, what was found.
    """
    out = Discovery()
    unit = _unit(problem)
    for o, e in problem.errors_deg(fit.sim).items():
        scale = problem.scale(o)  # the noise floor, with the stamps' timing error in it when the fit weighs it
        sigma = float(np.sqrt(np.mean(np.square(scale))))
        value = float(np.sqrt(np.mean(e**2)))
        white = whiteness(e / scale, lags=WHITENESS_LAGS, fitted_params=len(fit.free)).white
        found = Found(o, value, sigma, white, Regression())
        if found.structured:
            terms = [t.rows(problem.mask) for t in _terms(problem, fit.sim, o, e)]
            found.regression = stepwise(e, terms, sigma)
            found.statement = statement(o, found.regression, unit)
            out.statements.append(found.statement)
        out.found[o] = found
    return out


def _full(problem: Problem, fit: Fit, found: Found) -> list[Term]:
    """The held terms of an output on every sample (the library rebuilt from the same model and residual)."""
    e = problem.errors_deg(fit.sim)[found.output]
    names = {s.term.name for s in found.regression.selected}
    return [t for t in _terms(problem, fit.sim, found.output, e) if t.name in names]


def _on_reading(problem: Problem, cur: Fit, disc: Discovery, refit: Callable[[Problem], Fit] | None) -> Closure | None:
    """Each output's model plus the best combination of its discovered terms, the model refitted with them."""
    full = {o: _full(problem, cur, f) for o, f in disc.found.items() if f.regression.selected}
    if not full:
        return None
    design = {o: np.column_stack([t.columns for t in ts]) for o, ts in full.items()}
    problem.set_output_terms({o: a[problem.mask] for o, a in design.items()})
    try:
        new = refit(problem) if refit is not None else cur
    finally:
        problem.set_output_terms({})
    sim = np.array(new.sim, dtype=float, copy=True)
    terms: dict[str, list[tuple[str, tuple[float, ...], tuple[float, ...], str]]] = {}
    for o, a in design.items():
        col = OUTPUT_COLUMN[o]
        e = problem.observed[o][problem.mask] - sim[problem.mask, col]
        coef = np.linalg.lstsq(a[problem.mask], e, rcond=None)[0]
        r = e - a[problem.mask] @ coef
        sig = np.sqrt(np.clip(np.diag(block_covariance([r], [a[problem.mask]])), 0.0, None))
        sim[:, col] = sim[:, col] + a @ coef
        k = 0
        terms[o] = []
        for t in full[o]:
            terms[o].append((t.name, tuple(float(c) for c in coef[k:k + t.width]),
                             tuple(float(s) for s in sig[k:k + t.width]), t.unit))
            k += t.width
    residual = problem.weighted_residual(sim)
    fit = Fit(new.params, new.flip, new.free, sim, residual, new.jacobian, new.sigma, new.jac_free)
    extra = sum(a.shape[1] for a in design.values())
    return Closure("reading", terms, rms(problem, cur), rms(problem, fit), _delta_bic(problem, cur, fit, extra),
                   fit=fit)


def _delta_bic(problem: Problem, cur: Fit, new: Fit, extra: int) -> float:
    n = problem.n_fit
    return n * math.log(max(new.rss, TINY) / max(cur.rss, TINY)) + extra * math.log(n)


class _InLoop:
    """The model with terms added to the command: its parameters and the terms' coefficients fitted together."""

    def __init__(self, problem: Problem, cur: Fit, signals: FloatArray, scale: FloatArray) -> None:
        self.problem = problem
        self.cur = cur
        self.free = [FREE[f].capped(problem.caps.get(f)) for f in cur.free]
        self.signals = signals
        """``(terms, breakpoints)``: each term's signal at the model's input breakpoints."""
        self.scale = scale
        self.p = len(self.free)
        self.runs = 0
        self.hi = np.array([f.x_bounds()[1] for f in self.free] + [np.inf] * signals.shape[0], dtype=float)
        """Upper bounds: a difference step that would cross one is taken backwards."""

    def params(self, x: FloatArray) -> SecondOrderParams:
        return self.cur.params.replace(**{f.field: f.from_x(float(v)) for f, v in zip(self.free, x[:self.p],
                                                                                     strict=True)})

    def coef(self, x: FloatArray) -> FloatArray:
        return np.asarray(x[self.p:] * self.scale, dtype=float)

    def sims(self, xs: Sequence[FloatArray]) -> FloatArray:
        self.runs += len(xs)
        return self.problem.simulate([self.params(x) for x in xs], [self.cur.flip] * len(xs),
                                     [self.coef(x) @ self.signals for x in xs])

    def residual(self, x: FloatArray) -> FloatArray:
        r = self.problem.weighted_residual(self.sims([x])[0])
        return finite(r)

    def jacobian(self, x: FloatArray) -> FloatArray:
        points, steps = difference_points(x, self.hi)
        sims = self.sims([x, *points])
        r0 = finite(self.problem.weighted_residual(sims[0]))
        cols = [(finite(self.problem.weighted_residual(s)) - r0) / h for s, h in zip(sims[1:], steps, strict=True)]
        jac = np.column_stack(cols)
        return np.where(np.isfinite(jac), jac, 0.0)


def _inside_loop(problem: Problem, cur: Fit, disc: Discovery) -> Closure | None:
    """The actuator's discovered terms added to the command, fitted with the model's parameters."""
    actuator = "position_deg" if "position_deg" in disc.found else "surface_deg"
    found = disc.found.get(actuator)
    if found is None or not found.regression.selected:
        return None
    chosen = [s for s in found.regression.selected if s.term.kind in LOOP_KINDS and s.term.width == 1]
    chosen = sorted(chosen, key=lambda s: -s.share)[:MAX_LOOP_TERMS]
    if not chosen:
        return None
    full = {t.name: t for t in _full(problem, cur, found)}
    terms = [full[s.term.name] for s in chosen if s.term.name in full]
    if not terms:
        return None
    dense = problem.dense
    problem.set_dense(True)
    try:
        signals = np.array([problem.on_breakpoints(np.asarray(t.signal, dtype=float)) for t in terms])
        start = np.array([s.coef[0] for s in chosen[:len(terms)]], dtype=float)
        scale = np.maximum(np.abs(start), 1e-6)
        obj = _InLoop(problem, cur, signals, scale)
        x_model = np.array([f.to_x(float(getattr(cur.params, f.field))) for f in obj.free], dtype=float)
        lo = np.concatenate([[f.x_bounds()[0] for f in obj.free], np.full(len(terms), -np.inf)])
        hi = np.concatenate([[f.x_bounds()[1] for f in obj.free], np.full(len(terms), np.inf)])
        x0 = np.concatenate([np.clip(x_model, lo[:obj.p] + 1e-9, hi[:obj.p] - 1e-9), start / scale])
        res = least_squares(obj.residual, x0, jac=obj.jacobian, bounds=(lo, hi), method="trf", max_nfev=MAX_NFEV,
                            xtol=1e-8, ftol=1e-10, gtol=1e-10)
        x = np.asarray(res.x, dtype=float)
        sim = obj.sims([x])[0]
        jac = obj.jacobian(x)
    finally:
        problem.set_dense(dense)
    residual = problem.weighted_residual(sim)
    if not np.all(np.isfinite(residual)):
        return None
    params = obj.params(x)
    coef = obj.coef(x)
    block = int(problem.mask.sum())
    k = len(problem.outputs)
    cov = block_covariance([residual[b * block:(b + 1) * block] for b in range(k)],
                           [jac[b * block:(b + 1) * block] for b in range(k)])
    sig = np.sqrt(np.clip(np.diag(cov), 0.0, None))[obj.p:] * scale
    fit = Fit(params, cur.flip, cur.free, sim, residual, jac[:, :obj.p], cur.sigma, cur.jac_free)
    described: dict[str, list[tuple[str, tuple[float, ...], tuple[float, ...], str]]] = {
        "command": [(t.name, (float(c),), (float(s),), t.unit) for t, c, s in zip(terms, coef, sig, strict=True)]}
    return Closure("inside the loop", described, rms(problem, cur), rms(problem, fit),
                   _delta_bic(problem, cur, fit, len(terms)), fit=fit)


def _pays(c: Closure, cur: Fit, limit: Mapping[str, float]) -> bool:
    """Whether a placement lowers the error, pays for its coefficients and leaves no output worse (its reason)."""
    if c.fit is None or c.fit.rss >= cur.rss:
        c.reason = "the refit with the terms does not lower the error"
    elif c.delta_bic > MAX_DELTA_BIC:
        c.reason = f"does not pay for its coefficients (ΔBIC {c.delta_bic:.1f})"
    elif worse(c.rms_deg_after, limit):
        bad = ", ".join(worse(c.rms_deg_after, limit))
        c.reason = f"leaves {bad} worse than the model before it, the baseline or the reference: not kept"
    else:
        c.reason = f"pays (ΔBIC {c.delta_bic:.1f})"
        return True
    return False


def discover(problem: Problem, cur: Fit, limit: Mapping[str, float], refit: Callable[[Problem], Fit] | None,
             say: Callable[[str], None] | None = None) -> Discovery:
    """Regress what ``cur`` leaves, close the loop with what holds, keep the placement that pays (module docstring).

    Parameters
    ----------
    problem : Problem
        The record as fitted.
    cur : Fit
        The model so far.
    limit : mapping
        Per output, the rms no model may exceed.
    refit : callable or None
        Refits the model's own parameters on a problem (None: the model cannot be refitted; the terms then
        go on the reading only, the model as it is).
    say : callable, optional
        Progress lines.

    Returns
    -------
    Discovery
        What was found, each placement tried and the one kept (its fit in :attr:`Closure.fit`).
    """
    tell = say or (lambda _m: None)
    disc = regress(problem, cur)
    for line in disc.statements:
        tell(f"  discovered: {line}")
    if not any(f.regression.selected for f in disc.found.values()):
        return disc
    tries: list[Closure | None] = [_on_reading(problem, cur, disc, refit)]
    if refit is not None:
        tries.append(_inside_loop(problem, cur, disc))
    best: Closure | None = None
    for c in tries:
        if c is None:
            continue
        disc.closures.append(c)
        if _pays(c, cur, limit) and (best is None or c.delta_bic < best.delta_bic):
            best = c
    if best is not None:
        best.kept = True
        for c in disc.closures:
            if c is not best and not c.reason.startswith(("does not", "leaves", "the refit")):
                c.reason += f"; the {best.where} placement fits better (ΔBIC {best.delta_bic:.1f})"
    return disc
