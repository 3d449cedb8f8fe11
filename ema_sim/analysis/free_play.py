"""Free play from load reversals (section 2.4): the surface's jump when a small load changes sign.

The report zeroed a dial indicator under a 10 lb load and read it after shifting the load the other
way: 0.179° (right wing) and 0.171° (left wing) on vehicle 1, ≈ 0.200° on vehicles 2 and 3. Here each
reversal of the hinge moment (a step between two held load levels of opposite sign, command held)
gives the jump of the settled surface angle relative to the LVDT position (the free play is outside
the servo loop, so the LVDT motion, if any, is taken out). The jump also holds the elastic deflection
over the load swing; when a compliance is known (given, measured in the same record, or measured on
a load staircase of the same channel in the same run) it is subtracted.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ema_sim.analysis.series import Edge, settled

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class Reversal:
    """One load reversal: the raw jump of surface minus LVDT, elastic part included."""

    time_s: float
    load_from_inlb: float
    load_to_inlb: float
    jump_deg: float

    def as_dict(self) -> dict[str, float]:
        """Plain values for JSON."""
        return {"time_s": self.time_s, "load_from_inlb": self.load_from_inlb, "load_to_inlb": self.load_to_inlb,
                "raw_jump_deg": self.jump_deg}


@dataclass(frozen=True)
class FreePlayResult:
    """Free-play width from load reversals."""

    method: str
    width_deg: float
    spread_deg: float
    reversals: list[Reversal]
    compliance_deg_per_kinlb: float | None
    compliance_source: str | None
    has_position: bool
    notes: list[str] = field(default_factory=list)

    def as_dict(self) -> dict[str, Any]:
        """Plain values for JSON."""
        return {"method": self.method, "width_deg": self.width_deg, "spread_deg": self.spread_deg,
                "compliance_removed_deg_per_kinlb": self.compliance_deg_per_kinlb,
                "compliance_source": self.compliance_source, "reversals": [r.as_dict() for r in self.reversals],
                "notes": self.notes}

    def with_compliance(self, deg_per_kinlb: float, source: str) -> FreePlayResult:
        """The same reversals with the elastic deflection of ``deg_per_kinlb`` taken out."""
        return summarize(self.reversals, deg_per_kinlb, source, has_position=self.has_position)


def summarize(rows: list[Reversal], compliance_deg_per_kinlb: float | None, source: str | None, *,
              has_position: bool) -> FreePlayResult:
    """Median width of the reversals, less ``compliance × load swing`` when a compliance is known."""
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
    """Median jump over the sign-changing load edges (None when there is none)."""
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
