"""Free play from load reversals (section 2.4): the surface's jump when a small load changes sign.

The report zeroed a dial indicator under a 10 lb load and read it after shifting the load the other
way: 0.179° (right wing) and 0.171° (left wing) on vehicle 1, ≈ 0.200° on vehicles 2 and 3. Here each
reversal of the hinge moment (a step between two held load levels of opposite sign, command held)
gives the jump of the settled surface angle relative to the LVDT position (the free play is outside
the servo loop, so the LVDT motion, if any, is taken out). The jump also holds the elastic deflection
over the load swing; when a compliance is known (given, measured in the same record, or measured on
a load staircase of the same channel in the same run) it is subtracted. A width below the external
sensor's resolution is not determined by the record.

The test is recognised from a held command under a load that reverses between two levels
(:func:`read_load_reversal`).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from numpy.typing import NDArray
from typing_extensions import override

from ema_sim.analysis.formatting import figure
from ema_sim.analysis.formatting.markdown import bullets, image, quality
from ema_sim.analysis.records import series
from ema_sim.analysis.records.series import Edge, Hold, settled
from ema_sim.analysis.section2.base import Quality, RecordAnalysis, Section2Test
from ema_sim.analysis.section2.compliance import TEST as COMPLIANCE
from ema_sim.analysis.section2.segments import HeldStretch, Reading
from ema_sim.jsontypes import JsonObject

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class Reversal:
    """One load reversal: the raw jump of surface minus LVDT, elastic part included.

    Parameters
    ----------
    time_s : float
        Time of the reversal, s.
    load_from_inlb : float
        Settled load before, in·lb.
    load_to_inlb : float
        Settled load after, in·lb.
    jump_deg : float
        Jump of surface minus LVDT, deg.
    """

    time_s: float
    load_from_inlb: float
    load_to_inlb: float
    jump_deg: float

    def as_dict(self) -> dict[str, float]:
        """Plain values for JSON.

        Returns
        -------
        dict
            Time, load before and after, and the raw jump.
        """
        return {"time_s": self.time_s, "load_from_inlb": self.load_from_inlb, "load_to_inlb": self.load_to_inlb,
                "raw_jump_deg": self.jump_deg}


@dataclass(frozen=True)
class FreePlayResult:
    """Free-play width from load reversals.

    Parameters
    ----------
    method : str
        How the width was measured.
    width_deg : float
        Median width, deg.
    spread_deg : float
        Standard deviation over the reversals, deg.
    reversals : list
        Every reversal.
    compliance_deg_per_kinlb : float or None
        Compliance taken out of the jumps, deg per 1000 in·lb.
    compliance_source : str or None
        Where that compliance comes from.
    has_position : bool
        Whether the LVDT was taken out.
    notes : list
        What was and was not taken out.
    start : int
        First sample.
    stop : int
        Samples of the load-reversal segment.
    resolution_deg : float or None
        The surface sensor's count.
    """

    method: str
    width_deg: float
    spread_deg: float
    reversals: list[Reversal]
    compliance_deg_per_kinlb: float | None
    compliance_source: str | None
    has_position: bool
    notes: list[str] = field(default_factory=list)
    start: int = 0
    stop: int = 0
    """Samples of the load-reversal segment."""
    resolution_deg: float | None = None
    """The surface sensor's count."""

    @property
    def quality(self) -> Quality:
        """``not_determined`` when the width is below the surface sensor's count."""
        return "not_determined" if self.resolution_deg and self.width_deg < self.resolution_deg else "ok"

    @property
    def quality_note(self) -> str:
        """Why the quality is what it is."""
        if self.quality == "ok":
            return ""
        return f"below the surface sensor's count {self.resolution_deg:g}°"

    def as_dict(self) -> JsonObject:
        """Plain values for JSON.

        Returns
        -------
        dict
            Method, width, spread, compliance removed, each reversal, quality and notes.
        """
        return {"method": self.method, "width_deg": self.width_deg, "spread_deg": self.spread_deg,
                "compliance_removed_deg_per_kinlb": self.compliance_deg_per_kinlb,
                "compliance_source": self.compliance_source, "reversals": [{**r.as_dict()} for r in self.reversals],
                "quality": self.quality, "quality_note": self.quality_note, "notes": [*self.notes]}

    def with_compliance(self, deg_per_kinlb: float, source: str) -> FreePlayResult:
        """The same reversals with the elastic deflection of ``deg_per_kinlb`` taken out.

        Parameters
        ----------
        deg_per_kinlb : float
            The total compliance, degrees per 1000 in·lb.
        source : str
            Where it was measured.

        Returns
        -------
        FreePlayResult
            The new result (same segment).
        """
        out = summarize(self.reversals, deg_per_kinlb, source, has_position=self.has_position)
        return replace(out, start=self.start, stop=self.stop, resolution_deg=self.resolution_deg)


def summarize(rows: list[Reversal], compliance_deg_per_kinlb: float | None, source: str | None, *,
              has_position: bool) -> FreePlayResult:
    """Median width of the reversals, less ``compliance × load swing`` when a compliance is known.

    Parameters
    ----------
    rows : list of Reversal
        The reversals.
    compliance_deg_per_kinlb : float or None
        The total compliance to take out.
    source : str or None
        Where that compliance comes from.
    has_position : bool
        Whether the LVDT position was taken out of the jumps.

    Returns
    -------
    FreePlayResult
        The width and its spread.
    """
    c = compliance_deg_per_kinlb
    widths = np.array([abs(r.jump_deg - (c * (r.load_to_inlb - r.load_from_inlb) * 1e-3 if c is not None else 0.0))
                       for r in rows])
    notes = []
    if not has_position:
        notes.append("no LVDT position: the surface jump is taken as it is")
    if c is None:
        notes.append("no compliance given: the width includes the elastic deflection over the load swing")
    else:
        notes.append(f"elastic deflection removed with {c:.4g}°/1000 in·lb ({source})")
    method = "settled surface angle minus LVDT position, jump at each load reversal (median)"
    return FreePlayResult(method, float(np.median(widths)), float(np.std(widths)), rows, c, source, has_position,
                          notes)


def reversal_free_play(t: FloatArray, hinge_edges: list[Edge], hinge_moment: FloatArray, surface: FloatArray,
                       position: FloatArray | None, compliance_deg_per_kinlb: float | None = None,
                       compliance_source: str | None = None) -> FreePlayResult | None:
    """Median jump of surface minus LVDT over the sign-changing load edges.

    Parameters
    ----------
    t : numpy.ndarray
        Time, s.
    hinge_edges : list of Edge
        Edges of the held hinge moment.
    hinge_moment : numpy.ndarray
        Hinge moment, in·lb.
    surface : numpy.ndarray
        External surface angle, deg.
    position : numpy.ndarray or None
        LVDT position, deg.
    compliance_deg_per_kinlb : float, optional
        Total compliance to take out of each jump.
    compliance_source : str, optional
        Where it comes from.

    Returns
    -------
    FreePlayResult or None
        None when no edge reverses the load.
    """
    rows = []
    rel = surface - position if position is not None else surface
    for e in hinge_edges:
        h0, _ = settled(hinge_moment, e.before.start, e.before.stop, 0.5)
        h1, _ = settled(hinge_moment, e.after.start, e.after.stop, 0.5)
        if np.sign(h0) == np.sign(h1) or h0 == 0.0 or h1 == 0.0:
            continue
        y0, _ = settled(rel, e.before.start, e.before.stop, 0.4)
        y1, _ = settled(rel, e.after.start, e.after.stop, 0.4)
        rows.append(Reversal(float(t[e.index]), h0, h1, float(y1 - y0)))
    if not rows:
        return None
    return summarize(rows, compliance_deg_per_kinlb, compliance_source, has_position=position is not None)


def read_load_reversal(h: HeldStretch) -> Reading | None:
    """A held command under a load that reverses (at least twice) between at most three levels.

    Parameters
    ----------
    h : HeldStretch
        A held stretch of the command.

    Returns
    -------
    Reading or None
        ``load_reversal``, or None.
    """
    if h.load is None or h.covered < 0.7 or h.reversals < 2 or h.load_levels > 3:
        return None
    nonzero = [x.value for x in h.load_holds if abs(x.value) > 0.05 * h.swing]
    return Reading("load_reversal", f"command held; load reversing {h.reversals} times between {min(nonzero):.3g} "
                                    f"and {max(nonzero):.3g} in·lb")


def _shifted(e: Edge, offset: int) -> Edge:
    return Edge(e.index + offset, Hold(e.before.start + offset, e.before.stop + offset, e.before.value),
                Hold(e.after.start + offset, e.after.stop + offset, e.after.value))


class FreePlay(Section2Test[FreePlayResult]):
    """Free play from each load-reversal segment."""

    key = "free_play"
    title = "Free play (section 2.4)"
    kinds = ("load_reversal",)

    @override
    def run(self, ra: RecordAnalysis) -> list[FreePlayResult]:
        data, t = ra.data, ra.data.time_s
        hm = data.hinge_moment_inlb
        if hm is None:
            ra.not_computed[self.key] = "no hinge moment: free play not computed"
            return []
        compliance = ra.options.compliance_deg_per_kinlb
        source = "given (--compliance)" if compliance is not None else None
        if compliance is None:
            measured = [c.total.slope_deg_per_kinlb for c in ra.of(COMPLIANCE) if c.total and
                        c.total.slope_deg_per_kinlb]
            compliance = measured[0] if measured else None
            source = "total compliance measured in this record" if measured else None
        out = []
        for seg in ra.segments(*self.kinds):
            if data.surface_deg is None:
                ra.not_computed[self.key] = ("no external surface angle: free play lies outside the servo loop, "
                                             "the LVDT cannot see it")
                continue
            sl = slice(seg.start, seg.stop)
            swing = float(np.ptp(hm[sl]))
            found = series.edges(hm[sl], ra.sample_s(), min_hold_s=0.2, min_jump=0.3 * swing,
                                 tol=max(series.hold_tolerance(hm[sl]), 1e-3 * swing))
            fp = reversal_free_play(t, [_shifted(e, seg.start) for e in found], hm, data.surface_deg,
                                    data.position_deg, compliance, source)
            if fp:
                out.append(replace(fp, start=seg.start, stop=seg.stop,
                                   resolution_deg=ra.resolution_deg.get("surface_deg")))
        if not out and self.key not in ra.not_computed:
            gaps = [c for c in ra.of(COMPLIANCE) if c.total and c.total.gap_deg is not None]
            reason = "no load reversal recognised"
            if gaps:
                reason += "; see compliance.free_play_deg (gap between the load lines at zero load)"
            ra.not_computed[self.key] = reason
        return out

    @override
    def share(self, ra: RecordAnalysis, others: list[RecordAnalysis]) -> None:
        slopes = [(c.total.slope_deg_per_kinlb, o.data.source) for o in others for c in o.of(COMPLIANCE)
                  if c.total and c.total.slope_deg_per_kinlb]
        if slopes:
            value, src = slopes[0]
            ra.results[self.key] = [f.with_compliance(value, f"total compliance measured in {src}")
                                    if f.compliance_deg_per_kinlb is None else f for f in ra.of(self)]


    @override
    def markdown(self, ra: RecordAnalysis, results: list[FreePlayResult],
                 images: list[str | None]) -> list[str]:
        lines: list[str] = []
        for fp, img in zip(results, images, strict=True):
            lines += [f"{fp.width_deg:.4f}° ± {fp.spread_deg:.2g}° over {len(fp.reversals)} reversal(s) "
                      f"({fp.method}); the report: 0.171-0.179° (vehicle 1), ≈ 0.200° (vehicles 2, 3). Quality: "
                      f"{quality(fp.quality, fp.quality_note)}.", ""]
            lines += bullets(fp.notes)
            lines += image(img, "free play")
        return lines

    @override
    def summary(self, ra: RecordAnalysis, r: FreePlayResult) -> list[str]:
        return [f"free play: {r.width_deg:.4f}°"]

    @override
    def plot(self, ra: RecordAnalysis, r: FreePlayResult, path: Path) -> bool:
        d = ra.data
        assert d.surface_deg is not None
        assert d.hinge_moment_inlb is not None
        sl = slice(r.start, r.stop)
        rel = d.surface_deg[sl] - (d.position_deg[sl] if d.position_deg is not None else 0.0)
        fig, ax = figure.pyplot().subplots(2, 1, figsize=(9, 5), sharex=True)
        ax[0].plot(d.time_s[sl], rel, lw=0.7, color=figure.COLORS["surface_deg"])
        ax[0].set_ylabel("surface − LVDT, deg")
        ax[0].set_title(f"free play {r.width_deg:.4f}° (median of {len(r.reversals)} reversals)")
        ax[1].plot(d.time_s[sl], d.hinge_moment_inlb[sl], color="tab:purple", lw=0.8)
        ax[1].set_ylabel("hinge moment, in·lb")
        ax[1].set_xlabel("time, s")
        for a in ax:
            a.grid(lw=0.3)
        figure.save(fig, path)
        return True


TEST = FreePlay()
