"""Compliance from a load staircase (sections 2.8 and 3.2.1, figures 16, 34 and 35).

The command is held while the hinge moment steps 0 → +max → −max → 0. At each held load level the
settled LVDT position (compliance inside the servo loop) and external surface angle (total
compliance) are averaged into the two compliance curves, deflection against hinge moment from the
first zero-load level.

* Linear compliance: ``δ = a + c·hm + (g/2)·sign(hm)`` fitted to the levels above 20 % of the peak
  load, outside the free-play region; ``c`` is the compliance (°/1000 in·lb), ``g`` the gap between
  the positive- and negative-load lines at zero load (free play, when the curve is the surface's).
* Share outside the servo loop: ``1 − c_LVDT/c_total`` (slopes), and ``1 − span_LVDT/span_total``
  (deflection from −max to +max load, free play included), the report's 81 % (wings, vehicle 2).
* Three-segment model (figure 35): the bisector of the loading and unloading branches, against force
  at the crank arm (hinge moment / crank arm), fitted with ``δ = δ₀ + sign(F)·g(|F|)``, ``g``
  piecewise linear and continuous with knots ``b₁ < b₂`` (free-play region, moderate load, high
  load), knots by exhaustive search, slopes by least squares. Upper and lower bounds: the same knots
  fitted to each branch, the largest and smallest slope of each segment.

The test is recognised from a held command under a staircase of load levels (:func:`read_load_steps`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray
from typing_extensions import override

from ema_sim.analysis.formatting import figure
from ema_sim.analysis.formatting.markdown import bullets, image, num, table
from ema_sim.analysis.records.series import Hold, settled
from ema_sim.analysis.section2.base import RecordAnalysis, Section2Test
from ema_sim.analysis.section2.segments import HeldStretch, Reading
from ema_sim.jsontypes import JsonObject

FloatArray = NDArray[np.float64]

LINEAR_FROM = 0.2
"""Levels above this share of the peak load define the linear compliance."""
KNOT_CANDIDATES = 40


@dataclass(frozen=True)
class ThreeSegment:
    """``δ = offset + sign(F)·g(|F|)``, ``g`` with slopes ``s`` (deg/lb) between knots (lb).

    Parameters
    ----------
    knots_lb : tuple
        The two knots, lb.
    slopes_deg_per_lb : tuple
        Slope of each segment, deg/lb.
    offset_deg : float
        Deflection at zero force, deg.
    rms_deg : float
        RMS of the fit, deg.
    """

    knots_lb: tuple[float, float]
    slopes_deg_per_lb: tuple[float, float, float]
    offset_deg: float
    rms_deg: float

    def __call__(self, force_lb: FloatArray) -> FloatArray:
        """Deflection at ``force_lb``."""
        f = np.asarray(force_lb, dtype=float)
        return np.asarray(self.offset_deg + np.sign(f) * (_basis(np.abs(f), self.knots_lb)
                                                          @ np.array(self.slopes_deg_per_lb)), dtype=float)

    def stiffness_lb_per_in(self, crank_arm_in: float) -> list[float | None]:
        """Each segment as a stiffness at the actuator: force over ball-screw deflection (arc at the crank).

        Parameters
        ----------
        crank_arm_in : float
            Crank arm, in.

        Returns
        -------
        list
            Each segment's stiffness, lbf/in (None for a segment without slope).
        """
        return [1.0 / (s * np.pi / 180.0 * crank_arm_in) if s > 0 else None for s in self.slopes_deg_per_lb]

    def as_dict(self, crank_arm_in: float | None = None) -> JsonObject:
        """Plain values for JSON.

        Parameters
        ----------
        crank_arm_in : float or None
            Crank arm, in.

        Returns
        -------
        dict
            Plain values for JSON.
        """
        out: JsonObject = {"knots_lb": list(self.knots_lb), "slopes_deg_per_lb": list(self.slopes_deg_per_lb),
                               "offset_deg": self.offset_deg, "rms_deg": self.rms_deg}
        if crank_arm_in:
            out["stiffness_lb_per_in"] = list(self.stiffness_lb_per_in(crank_arm_in))
        return out


def _basis(a: FloatArray, knots: tuple[float, float]) -> FloatArray:
    b1, b2 = knots
    return np.column_stack([np.minimum(a, b1), np.clip(a - b1, 0.0, b2 - b1), np.maximum(a - b2, 0.0)])


def _fit_segments(force: FloatArray, defl: FloatArray, knots: tuple[float, float]) -> ThreeSegment:
    X = np.column_stack([np.ones_like(force), np.sign(force)[:, None] * _basis(np.abs(force), knots)])
    coef, *_ = np.linalg.lstsq(X, defl, rcond=None)
    rms = float(np.sqrt(np.mean((X @ coef - defl) ** 2)))
    return ThreeSegment(knots, (float(coef[1]), float(coef[2]), float(coef[3])), float(coef[0]), rms)


def fit_three_segments(force: FloatArray, defl: FloatArray) -> ThreeSegment | None:
    """Best three-segment model over a grid of knot pairs (None with fewer than 4 load magnitudes).

    Parameters
    ----------
    force : numpy.ndarray
        Force at the crank arm, lb.
    defl : numpy.ndarray
        Deflection, deg.

    Returns
    -------
    ThreeSegment or None
        The best model, or None.
    """
    mags = np.unique(np.round(np.abs(force), 6))
    mags = mags[mags > 0]
    if mags.size < 3:
        return None
    top = float(mags.max())
    cands = np.linspace(top / KNOT_CANDIDATES, top * (1 - 1 / KNOT_CANDIDATES), KNOT_CANDIDATES - 1)
    best: ThreeSegment | None = None
    a = np.abs(force)
    for i, b1 in enumerate(cands):
        if not np.any((a > 0) & (a <= b1)):
            continue
        for b2 in cands[i + 1:]:
            if not (np.any((a > b1) & (a <= b2)) and np.any(a > b2)):
                continue
            fit = _fit_segments(force, defl, (float(b1), float(b2)))
            if best is None or fit.rms_deg < best.rms_deg - 1e-15:
                best = fit
    return best


@dataclass(frozen=True)
class ComplianceCurve:
    """Deflection against hinge moment at each load level, and its fits.

    Parameters
    ----------
    name : str
        ``lvdt`` or ``total``.
    load_inlb : numpy.ndarray
        Settled hinge moment of each level, in·lb.
    deflection_deg : numpy.ndarray
        Deflection at each level from the first zero-load level, deg.
    direction : numpy.ndarray
        Loading direction at each level (+1 rising, −1 falling).
    slope_deg_per_kinlb : float or None
        Linear compliance, deg per 1000 in·lb.
    gap_deg : float or None
        Gap between the positive- and negative-load lines at zero load, deg.
    span_deg : float
        Deflection from −max to +max load, deg.
    bisector_load_inlb : numpy.ndarray
        Load levels of the bisector, in·lb.
    bisector_deg : numpy.ndarray
        Bisector of the loading and unloading branches, deg.
    mean : ThreeSegment or None
        Three-segment fit to the bisector.
    upper : ThreeSegment or None
        Upper three-segment bound.
    lower : ThreeSegment or None
        Lower three-segment bound.
    crank_arm_in : float
        Crank arm, in.
    """

    name: str
    load_inlb: FloatArray
    deflection_deg: FloatArray
    direction: NDArray[np.int64]
    slope_deg_per_kinlb: float | None
    gap_deg: float | None
    span_deg: float
    bisector_load_inlb: FloatArray
    bisector_deg: FloatArray
    mean: ThreeSegment | None
    upper: ThreeSegment | None
    lower: ThreeSegment | None
    crank_arm_in: float

    def as_dict(self) -> JsonObject:
        """Plain values for JSON.

        Returns
        -------
        dict
            Plain values for JSON.
        """
        return {
            "load_inlb": self.load_inlb.tolist(), "deflection_deg": self.deflection_deg.tolist(),
            "loading_direction": self.direction.tolist(),
            "compliance_deg_per_kinlb": self.slope_deg_per_kinlb, "zero_load_gap_deg": self.gap_deg,
            "span_deg": self.span_deg,
            "bisector": {"load_inlb": self.bisector_load_inlb.tolist(), "deflection_deg": self.bisector_deg.tolist()},
            "three_segment": {k: (v.as_dict(self.crank_arm_in) if v else None)
                              for k, v in (("mean", self.mean), ("upper", self.upper), ("lower", self.lower))},
        }


def _linear(load: FloatArray, defl: FloatArray) -> tuple[float | None, float | None]:
    peak = float(np.max(np.abs(load)))
    sel = np.abs(load) >= LINEAR_FROM * peak
    if sel.sum() < 3:
        return None, None
    X = np.column_stack([np.ones(sel.sum()), load[sel], 0.5 * np.sign(load[sel])])
    has_both = np.any(load[sel] > 0) and np.any(load[sel] < 0)
    if not has_both:
        X = X[:, :2]
    coef, *_ = np.linalg.lstsq(X, defl[sel], rcond=None)
    return float(coef[1] * 1000.0), (float(coef[2]) if has_both else None)


def _curve(name: str, load: FloatArray, defl: FloatArray, direction: NDArray[np.int64],
           crank_in: float) -> ComplianceCurve:
    peak = float(np.max(np.abs(load)))
    tol = 0.02 * peak
    keys = np.round(load / max(tol, 1e-9)) * tol
    uniq = np.unique(keys)
    bis = []
    for k in uniq:
        at = keys == k
        means = [float(np.mean(defl[at & (direction == s)])) for s in (1, -1) if np.any(at & (direction == s))]
        bis.append(float(np.mean(means)) if means else float(np.mean(defl[at])))
    bis_load = np.array([float(np.mean(load[keys == k])) for k in uniq])
    bis_defl = np.array(bis)
    slope, gap = _linear(load, defl)
    hi = bis_defl[np.argmax(bis_load)]
    lo = bis_defl[np.argmin(bis_load)]
    mean = fit_three_segments(bis_load / crank_in, bis_defl)
    upper = lower = None
    if mean is not None:
        fits = []
        for s in (1, -1):
            sel = direction == s
            if np.unique(np.round(np.abs(load[sel]), 6)).size >= 3:
                fits.append(_fit_segments(load[sel] / crank_in, defl[sel], mean.knots_lb))
        if fits:
            fits.append(mean)
            slopes = np.array([f.slopes_deg_per_lb for f in fits])
            offs = np.array([f.offset_deg for f in fits])
            hi_s, lo_s = slopes.max(axis=0), slopes.min(axis=0)
            upper = ThreeSegment(mean.knots_lb, (float(hi_s[0]), float(hi_s[1]), float(hi_s[2])), float(offs.max()),
                                 mean.rms_deg)
            lower = ThreeSegment(mean.knots_lb, (float(lo_s[0]), float(lo_s[1]), float(lo_s[2])), float(offs.min()),
                                 mean.rms_deg)
    return ComplianceCurve(name, load, defl, direction, slope, gap, float(hi - lo), bis_load, bis_defl,
                           mean, upper, lower, crank_in)


@dataclass(frozen=True)
class ComplianceResult:
    """LVDT and total compliance of one load staircase.

    Parameters
    ----------
    command_deg : float
        Commanded level, deg.
    crank_arm_in : float
        Crank arm, in.
    lvdt : ComplianceCurve or None
        Compliance curve of the LVDT (inside the servo loop).
    total : ComplianceCurve or None
        Compliance curve of the surface (total).
    notes : list
        What could not be computed, and why.
    """

    command_deg: float
    crank_arm_in: float
    lvdt: ComplianceCurve | None
    total: ComplianceCurve | None
    notes: list[str] = field(default_factory=list)

    @property
    def share_outside(self) -> float | None:
        """``1 − c_LVDT/c_total`` from the linear compliances."""
        if not (self.lvdt and self.total and self.lvdt.slope_deg_per_kinlb is not None
                and self.total.slope_deg_per_kinlb):
            return None
        return 1.0 - self.lvdt.slope_deg_per_kinlb / self.total.slope_deg_per_kinlb

    @property
    def share_outside_span(self) -> float | None:
        """``1 − span_LVDT/span_total`` over the whole load range (free play included)."""
        if not (self.lvdt and self.total and self.total.span_deg):
            return None
        return 1.0 - self.lvdt.span_deg / self.total.span_deg

    def as_dict(self) -> JsonObject:
        """Plain values for JSON.

        Returns
        -------
        dict
            Plain values for JSON.
        """
        return {
            "command_deg": self.command_deg, "crank_arm_in": self.crank_arm_in,
            "lvdt": self.lvdt.as_dict() if self.lvdt else None, "total": self.total.as_dict() if self.total else None,
            "share_outside_servo_loop": self.share_outside, "share_outside_servo_loop_span": self.share_outside_span,
            "free_play_deg": self.total.gap_deg if self.total else None, "notes": [*self.notes],
        }


def load_levels(hinge_moment: FloatArray, holds: list[Hold]) -> tuple[FloatArray, NDArray[np.int64]]:
    """Settled load of each hold and its loading direction (+1 rising, −1 falling).

    Parameters
    ----------
    hinge_moment : numpy.ndarray
        Hinge moment, in·lb.
    holds : list
        The held levels, in order.

    Returns
    -------
    tuple
        Settled load of each hold, in·lb, and its loading direction.
    """
    load = np.array([settled(hinge_moment, h.start, h.stop, 0.5)[0] for h in holds])
    d = np.sign(np.diff(load)).astype(np.int64)
    direction = np.concatenate([[d[0] if d.size else 0], d])
    return load, direction


def analyze_compliance(position: FloatArray | None, surface: FloatArray | None, hinge_moment: FloatArray,
                       holds: list[Hold], command_deg: float, crank_arm_in: float) -> ComplianceResult:
    """Compliance curves and fits of a load staircase whose held levels are ``holds``.

    Parameters
    ----------
    position : numpy.ndarray or None
        LVDT position, deg (None: not recorded).
    surface : numpy.ndarray or None
        External surface angle, deg (None: not recorded).
    hinge_moment : numpy.ndarray
        Hinge moment, in·lb.
    holds : list
        The held levels, in order.
    command_deg : float
        Commanded level, deg.
    crank_arm_in : float
        Crank arm, in.

    Returns
    -------
    ComplianceResult
        Both curves and their fits.
    """
    notes: list[str] = []
    load, direction = load_levels(hinge_moment, holds)
    ref = int(np.argmin(np.abs(load)))

    def curve(name: str, y: FloatArray | None) -> ComplianceCurve | None:
        if y is None:
            return None
        vals = np.array([settled(y, h.start, h.stop, 0.5)[0] for h in holds])
        return _curve(name, load, vals - vals[ref], direction, crank_arm_in)

    if surface is None:
        notes.append("no external surface angle: total compliance and the share outside the servo loop not computed")
    if position is None:
        notes.append("no LVDT position: compliance inside the servo loop not computed")
    lvdt, total = curve("lvdt", position), curve("total", surface)
    for c in (lvdt, total):
        if c is not None and c.mean is None:
            notes.append(f"{c.name}: fewer than 3 load magnitudes: no three-segment fit")
    return ComplianceResult(command_deg, crank_arm_in, lvdt, total, notes)


def read_load_steps(h: HeldStretch) -> Reading | None:
    """A held command under a load staircase: at least three held load levels covering 70 % of the stretch.

    Parameters
    ----------
    h : HeldStretch
        A held stretch of the command.

    Returns
    -------
    Reading or None
        ``load_steps``, or None.
    """
    if h.load is None or h.covered < 0.7 or h.load_levels < 3:
        return None
    return Reading("load_steps", f"command held; load staircase over {h.load_levels} levels ({h.swing:.4g} in·lb "
                                 "swing)")


class Compliance(Section2Test[ComplianceResult]):
    """LVDT and total compliance curves of each load staircase."""

    key = "compliance"
    title = "Compliance (sections 2.8, 3.2.1)"
    kinds = ("load_steps",)
    absent = "no load staircase with the command held recognised"

    @override
    def run(self, ra: RecordAnalysis) -> list[ComplianceResult]:
        data = ra.data
        if data.hinge_moment_inlb is None:
            ra.not_computed[self.key] = "no hinge moment: compliance not computed"
            return []
        out = []
        for seg in ra.segments(*self.kinds):
            holds = list(seg.holds)
            if len(holds) < 3:
                continue
            out.append(analyze_compliance(data.position_deg, data.surface_deg, data.hinge_moment_inlb, holds,
                                          seg.params.get("command_deg", float(data.command_deg[seg.start])),
                                          ra.channel.crank_arm_in))
        return out


    @override
    def markdown(self, ra: RecordAnalysis, results: list[ComplianceResult],
                 images: list[str | None]) -> list[str]:
        lines: list[str] = []
        for c, img in zip(results, images, strict=True):
            lines += [f"Command {c.command_deg:g}°.", ""]
            rows = []
            for cur in (c.lvdt, c.total):
                if cur is None:
                    continue
                m = cur.mean
                seg = ("—" if m is None else
                       f"knots {m.knots_lb[0]:.0f} / {m.knots_lb[1]:.0f} lb; slopes "
                       + " / ".join(f"{1e3 * s:.3g}" for s in m.slopes_deg_per_lb) + " °/klb")
                rows.append(["LVDT (inside the loop)" if cur.name == "lvdt" else "total (surface)",
                             num(cur.slope_deg_per_kinlb, ".4f"), num(cur.span_deg, ".4f"), num(cur.gap_deg, ".4f"),
                             seg])
            lines += table(["curve", "compliance, °/kin·lb", "span, °", "gap at zero load, °",
                            "three-segment (mean)"], rows)
            so, sp = c.share_outside, c.share_outside_span
            lines += [f"Share of the compliance outside the servo loop: {num(None if so is None else 100 * so, '.1f')}"
                      f" % (slopes), {num(None if sp is None else 100 * sp, '.1f')} % (span, free play included); "
                      "the report: > 81 % (wings, vehicle 2), 77 % (vehicle 3).", ""]
            lines += bullets(c.notes)
            lines += image(img, "compliance")
        return lines

    @override
    def summary(self, ra: RecordAnalysis, r: ComplianceResult) -> list[str]:
        share = "—" if r.share_outside is None else f"{100 * r.share_outside:.1f} %"
        return [f"compliance: share outside the servo loop {share}"]

    @override
    def plot(self, ra: RecordAnalysis, r: ComplianceResult, path: Path) -> bool:
        fig, ax = figure.pyplot().subplots(1, 2, figsize=(12, 4.2))
        for cur, col in ((r.lvdt, figure.COLORS["position_deg"]), (r.total, figure.COLORS["surface_deg"])):
            if cur is None:
                continue
            label = "LVDT (inside the servo loop)" if cur.name == "lvdt" else "total (surface)"
            ax[0].plot(cur.load_inlb, cur.deflection_deg, "o-", ms=3, lw=0.8, color=col, label=label)
            if cur.mean is not None:
                f = cur.bisector_load_inlb / r.crank_arm_in
                ff = np.linspace(f.min(), f.max(), 400)
                ax[1].plot(f, cur.bisector_deg, "o", ms=3, color=col, label=f"{cur.name} bisector")
                ax[1].plot(ff, cur.mean(ff), "-", color=col, lw=1.2, label=f"{cur.name} three-segment mean")
                if cur.upper and cur.lower:
                    ax[1].plot(ff, cur.upper(ff), "--", color=col, lw=0.8, label=f"{cur.name} upper / lower")
                    ax[1].plot(ff, cur.lower(ff), "--", color=col, lw=0.8)
        ax[0].set_xlabel("hinge moment, in·lb")
        ax[0].set_ylabel("deflection, deg")
        ax[0].set_title(f"compliance curves (figure 16), command {r.command_deg:g}°")
        ax[1].set_xlabel("force at the crank arm, lb")
        ax[1].set_ylabel("deflection, deg")
        ax[1].set_title("three-segment model (figure 35)")
        for a in ax:
            a.legend(fontsize=7)
            a.grid(lw=0.3)
        figure.save(fig, path)
        return True


TEST = Compliance()
