"""Stepwise regression of a residual on candidate terms, in the manner of SIDPAC's ``swr``.

A residual that no named effect explains is regressed on a library of terms built from the record
(:mod:`ema_sim.identify.library`). Terms enter one at a time, the one that removes the most of what is
left first, while

* a partial F test rejects chance at :data:`ALPHA_IN`, on the *effective* number of samples: a smooth
  residual and a smooth term share few independent samples (N/(1 + 2Σρₑρₓ), Bartlett), so a raw F on
  10⁵ correlated samples would take any wiggle for a finding; and
* it removes at least :data:`MIN_SHARE` of the residual's variance above the noise floor.

After each entry a term already in that no longer passes (:data:`ALPHA_OUT`) leaves again. Each term's
coefficients carry a coloured-residual uncertainty (Morelli and Klein), its share of the variance (what
it adds when entered last), its significance, and whether the record agrees with itself about it: the
same terms fitted on each half of the record must give coefficients within three combined sigma (never
more than six of the whole record's) and of the same sign (a share of their size is no excuse: two halves
that disagree beyond their uncertainty say the term is no property of the record), and each half must find
it on its own (its coefficient :data:`HALF_FOUND` standard errors of that half from zero: halves 14×
apart that "agree" only within a wide uncertainty have not both found it). A half that does not excite a
term gives no coefficient for it. A term that does not hold up is returned as tried and dropped, with why.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import NDArray
from scipy.stats import f as fisher

from ema_sim.analysis.estimation.noise import autocorrelation
from ema_sim.identify.fit import block_covariance

FloatArray = NDArray[np.float64]
ALPHA_IN = 1e-4
"""A term enters when chance would explain as much at most this often."""
ALPHA_OUT = 1e-3
MIN_SHARE = 0.02
"""Share of the residual's variance above the noise floor a term must remove to enter."""
MAX_TERMS = 6
HALF_SIGMA = 3.0
HALF_FOUND = 2.0
"""Standard errors of its own half a term's coefficient must reach on each half that excites it."""
UNEXCITED = 0.05
"""A half in which a term's columns carry less than this share of their energy in the other half does not
excite it: the halves are still compared, within their (then large) combined uncertainty."""
MAX_LAG = 200
CONSTANT = "1"
"""The constant term's name."""


@dataclass(frozen=True)
class Term:
    """One candidate: its columns on the fitted samples, and what it means."""

    name: str
    """How the term reads in an equation (``sign(rate)``, ``position³``, ``sin/cos 50 Hz``)."""
    columns: FloatArray
    """``(samples, k)``: the regressors (a tone has a sine and a cosine), on every sample of the record until cut
    to the fitted ones (:meth:`rows`)."""
    unit: str
    """Unit of the coefficient (the residual's unit per the term's), for the report."""
    meaning: str
    """What a residual of this shape is, in words."""
    kind: str
    """``sensor`` (acts on a reading), ``motion`` (acts on the actuator: inside the loop where it can), ``time``."""
    signal: FloatArray | None = None
    """The term's one-column signal on every sample of the record (for adding it inside the loop)."""

    @property
    def width(self) -> int:
        """Number of columns."""
        return int(self.columns.shape[1])

    def rows(self, mask: NDArray[np.bool_]) -> Term:
        """The term on some samples only (the fitted ones).

        Parameters
        ----------
        mask : numpy.ndarray
            Which samples to keep.

        Returns
        -------
        Term
            The same term, its columns cut to ``mask``.
        """
        return replace(self, columns=self.columns[mask])


@dataclass(frozen=True)
class Selected:
    """A term the regression took, with its figures."""

    term: Term
    coef: tuple[float, ...]
    sigma: tuple[float, ...]
    share: float
    """Share of the residual's variance it explains when entered last."""
    p_value: float
    halves: tuple[tuple[float, ...], tuple[float, ...]]
    holds: bool
    why: str = ""
    """Why it does not hold up (empty when it does), or how it was judged (one half excited)."""

    @property
    def amplitude(self) -> float:
        """Size of the term's contribution: rms of its fitted columns."""
        fitted = self.term.columns @ np.asarray(self.coef)
        return float(np.sqrt(np.mean(fitted**2)))


@dataclass
class Regression:
    """The terms that hold, the ones tried and dropped, and what they explain."""

    selected: list[Selected] = field(default_factory=list)
    dropped: list[Selected] = field(default_factory=list)
    explained: float = 0.0
    """Share of the residual's variance the terms that hold explain together."""
    excess_explained: float = 0.0
    """Share of the variance above the noise floor they explain."""
    fitted: FloatArray = field(default_factory=lambda: np.zeros(0))
    """Their combined contribution on the fitted samples."""


def effective_samples(e: FloatArray, x: FloatArray) -> float:
    """Independent samples behind a correlation of ``e`` with ``x``: N/(1 + 2Σρₑρₓ) (Bartlett).

    A constant ``x`` has ρₓ = 1 at every lag: the samples behind a mean of ``e``.

    Parameters
    ----------
    e : numpy.ndarray
        The residual (what is left once the term is in).
    x : numpy.ndarray
        The regressor.

    Returns
    -------
    float
        The effective number of samples (never above N, never below 1).
    """
    k_max = min(MAX_LAG, e.size // 4)
    if k_max < 1 or np.ptp(e) == 0.0:
        return float(e.size)
    rho_e = autocorrelation(e, k_max)[1:]
    rho_x = autocorrelation(x, k_max)[1:] if np.ptp(x) > 0.0 else np.ones(k_max)
    rho = float(np.sum(rho_e * rho_x))
    return e.size / max(1.0 + 2.0 * rho, 1.0)


def _usable(term: Term, n: int) -> bool:
    """A term with a column per sample, finite, and not constant (the constant term excepted)."""
    c = term.columns
    if c.ndim != 2 or c.shape[0] != n or c.shape[1] == 0 or not np.all(np.isfinite(c)):
        return False
    return term.name == CONSTANT or float(np.min(np.ptp(c, axis=0))) > 0.0


def _design(terms: Sequence[Term]) -> FloatArray:
    if not terms:
        return np.zeros((0, 0))
    return np.column_stack([t.columns for t in terms])


def _lstsq(a: FloatArray, y: FloatArray) -> FloatArray:
    if a.shape[1] == 0:
        return np.zeros(0)
    return np.asarray(np.linalg.lstsq(a, y, rcond=None)[0], dtype=float)


def _ss(a: FloatArray, y: FloatArray) -> float:
    """Residual sum of squares of ``y`` after least squares on the columns of ``a``."""
    r = _rest(a, y)
    return float(np.dot(r, r))


def _rest(a: FloatArray, y: FloatArray) -> FloatArray:
    """What least squares on the columns of ``a`` leaves of ``y``."""
    return y - a @ _lstsq(a, y) if a.shape[1] else y


def _partial(e: FloatArray, chosen: Sequence[Term], term: Term, ss_with: float, ss_without: float) -> float:
    """p-value of ``term`` beside ``chosen``: partial F on the samples the fit with it leaves independent."""
    q = term.width
    p = sum(t.width for t in chosen) + q
    a = _design([*chosen, term])
    n_eff = effective_samples(_rest(a, e), term.columns[:, 0])
    dof = n_eff - p - 1.0
    if dof <= 0.0 or ss_with <= 0.0:
        return 0.0 if ss_with <= 0.0 < ss_without else 1.0
    stat = ((ss_without - ss_with) / q) / (ss_with / dof)
    return float(fisher.sf(max(stat, 0.0), q, dof))


def stepwise(e: FloatArray, terms: Sequence[Term], sigma: float, *, max_terms: int = MAX_TERMS) -> Regression:
    """Regress the residual ``e`` on ``terms`` (module docstring).

    Parameters
    ----------
    e : numpy.ndarray
        The residual on the fitted samples.
    terms : sequence of Term
        The candidate library.
    sigma : float
        The residual's noise floor (its white part).
    max_terms : int
        Most terms taken.

    Returns
    -------
    Regression
        The terms that hold, those tried and dropped, and what they explain.
    """
    e = np.asarray(e, dtype=float)
    pool = [t for t in terms if _usable(t, e.size)]
    tss = float(np.dot(e, e))
    excess = max(tss - e.size * sigma**2, 1e-12 * max(tss, 1e-300))
    chosen: list[Term] = []
    ss_now = tss
    for _ in range(4 * max_terms):
        if len(chosen) >= max_terms:
            break
        base = _design(chosen)
        gains: list[tuple[float, Term, float]] = []
        for term in pool:
            if term in chosen:
                continue
            a = np.column_stack([base, term.columns]) if base.size else term.columns
            ss = _ss(a, e)
            if ss_now - ss >= MIN_SHARE * excess:
                gains.append((ss_now - ss, term, ss))
        entering = next(((t, ss) for _, t, ss in sorted(gains, key=lambda g: -g[0])
                         if _partial(e, chosen, t, ss, ss_now) <= ALPHA_IN), None)
        if entering is None:
            break
        term, ss = entering
        chosen.append(term)
        ss_now = ss
        # backward: a term the newcomer made redundant leaves
        for old in list(chosen[:-1]):
            rest = [t for t in chosen if t is not old]
            ss_without = _ss(_design(rest), e) if rest else tss
            if _partial(e, rest, old, ss_now, ss_without) > ALPHA_OUT:
                chosen.remove(old)
                ss_now = _ss(_design(chosen), e)
    return _summarise(e, chosen, tss, excess)


def _summarise(e: FloatArray, chosen: list[Term], tss: float, excess: float) -> Regression:
    """Coefficients, uncertainties, shares and the halves check of the chosen terms."""
    out = Regression(fitted=np.zeros_like(e))
    if not chosen:
        return out
    a = _design(chosen)
    coef = _lstsq(a, e)
    r = e - a @ coef
    cov = block_covariance([r], [a])
    sig = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    ss_all = float(np.dot(r, r))
    halves = _halves(e, chosen, sig)
    col = 0
    held: list[Term] = []
    for term in chosen:
        k = slice(col, col + term.width)
        col += term.width
        rest = [t for t in chosen if t is not term]
        share = (_ss(_design(rest), e) - ss_all) / tss if rest else (tss - ss_all) / tss
        p = _partial(e, rest, term, ss_all, _ss(_design(rest), e) if rest else tss)
        holds, why, pair = halves[term.name]
        sel = Selected(term, tuple(float(c) for c in coef[k]), tuple(float(s) for s in sig[k]), float(share), p,
                       pair, holds, why)
        if holds:
            out.selected.append(sel)
            held.append(term)
        else:
            out.dropped.append(sel)
    if held:
        a_held = _design(held)
        c_held = _lstsq(a_held, e)
        out.fitted = a_held @ c_held
        r_held = e - out.fitted
        out.explained = 1.0 - float(np.dot(r_held, r_held)) / tss
        out.excess_explained = min((tss - float(np.dot(r_held, r_held))) / excess, 1.0)
        if len(held) < len(chosen):  # the coefficients of the terms that hold, without the dropped ones
            _refresh(out, e, held, c_held)
    return out


def _refresh(out: Regression, e: FloatArray, held: list[Term], coef: FloatArray) -> None:
    a = _design(held)
    r = e - a @ coef
    sig = np.sqrt(np.clip(np.diag(block_covariance([r], [a])), 0.0, None))
    col = 0
    fresh = []
    for s in out.selected:
        k = slice(col, col + s.term.width)
        col += s.term.width
        fresh.append(Selected(s.term, tuple(float(c) for c in coef[k]), tuple(float(x) for x in sig[k]), s.share,
                              s.p_value, s.halves, s.holds, s.why))
    out.selected = fresh


Halves = tuple[bool, str, tuple[tuple[float, ...], tuple[float, ...]]]
"""Whether a term holds on both halves, why not, and its coefficients on each."""


def _halves(e: FloatArray, chosen: list[Term], whole_sigma: FloatArray) -> dict[str, Halves]:
    """Each term's coefficients on the first and the second half, and whether they agree (module docstring).

    Two halves that both excite a term differ, by chance alone, by about twice the whole record's standard
    error (each half has half the samples); their own coloured-residual errors, estimated from half the
    samples each, scatter about that. The halves are compared within the smaller of the two, so a term
    whose halves differ beyond six of the whole record's standard errors (the uncertainty reported beside
    it) is never said to hold.
    """
    n = e.size
    mid = n // 2
    parts = (slice(0, mid), slice(mid, n))
    fits = []
    for s in parts:
        a = _design(chosen)[s]
        y = e[s]
        c = _lstsq(a, y)
        r = y - a @ c
        with np.errstate(all="ignore"):
            cov = block_covariance([r], [a])
        fits.append((c, np.sqrt(np.clip(np.diag(cov), 0.0, None)), np.sum(a * a, axis=0)))
    out: dict[str, Halves] = {}
    col = 0
    for term in chosen:
        k = slice(col, col + term.width)
        col += term.width
        (c1, s1, n1), (c2, s2, n2) = fits
        e1, e2 = float(np.sum(n1[k])), float(np.sum(n2[k]))
        unexcited = min(e1, e2) < UNEXCITED * max(e1, e2)
        # a half that does not excite the term measures nothing about it: no coefficient (NaN)
        quiet1, quiet2 = unexcited and e1 < e2, unexcited and e2 <= e1
        pair = (tuple(math.nan if quiet1 else float(v) for v in c1[k]),
                tuple(math.nan if quiet2 else float(v) for v in c2[k]))
        if term.width == 2:  # a tone: compare its amplitude and phase as one complex number
            z1, z2 = complex(c1[k][0], c1[k][1]), complex(c2[k][0], c2[k][1])
            r1, r2 = float(np.hypot(*s1[k])), float(np.hypot(*s2[k]))
            spread = math.hypot(r1, r2)
            if not unexcited:
                spread = min(spread, 2.0 * float(np.hypot(*whole_sigma[k])))
            agree = abs(z1 - z2) <= HALF_SIGMA * spread
            found = abs(z1) > HALF_FOUND * r1 and abs(z2) > HALF_FOUND * r2
            same_sign = True
        else:
            d = np.abs(c1[k] - c2[k])
            spread_v = np.hypot(s1[k], s2[k])
            if not unexcited:
                spread_v = np.minimum(spread_v, 2.0 * whole_sigma[k])
            agree = bool(np.all(d <= HALF_SIGMA * spread_v))
            found = bool(np.all(np.abs(c1[k]) > HALF_FOUND * s1[k]) and np.all(np.abs(c2[k]) > HALF_FOUND * s2[k]))
            same_sign = unexcited or bool(np.all(np.sign(c1[k]) == np.sign(c2[k])))
        if agree and same_sign and (found or unexcited):
            out[term.name] = (True, "excited in one half of the record only: the other half's wide uncertainty "
                                    "agrees with it" if unexcited else "", pair)
        elif agree and same_sign:
            text = ", ".join(f"{a:.3g} ± {sa:.2g} / {b:.3g} ± {sb:.2g}"
                             for a, b, sa, sb in zip(c1[k], c2[k], s1[k], s2[k], strict=True))
            out[term.name] = (False, f"not found by each half of the record on its own ({text}): the whole "
                                     "record's significance rests on one part of it", pair)
        else:
            text = ", ".join(f"{a:.3g} / {b:.3g}" for a, b in zip(c1[k], c2[k], strict=True))
            out[term.name] = (False, f"the two halves of the record disagree about it beyond their uncertainty "
                                     f"({text})", pair)
    return out
