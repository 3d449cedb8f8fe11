"""Free play from load reversals (section 2.4): the surface's jump when a small load changes sign.

The report zeroed a dial indicator under a 10 lb load and read it after shifting the load the other
way: 0.179° (right wing) and 0.171° (left wing) on vehicle 1, ≈ 0.200° on vehicles 2 and 3. Here each
reversal of the hinge moment (a step between two held load levels of opposite sign, command held)
gives the jump of the settled surface angle relative to the LVDT position (the free play is outside
the servo loop, so the LVDT motion, if any, is taken out). The jump also holds the elastic deflection
over the load swing; when a compliance is known it is subtracted.
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
    """One load reversal."""

    time_s: float
    load_from_inlb: float
    load_to_inlb: float
    jump_deg: float

    def as_dict(self) -> dict[str, float]:
        """Plain values for JSON."""
        return {"time_s": self.time_s, "load_from_inlb": self.load_from_inlb, "load_to_inlb": self.load_to_inlb,
                "jump_deg": self.jump_deg}


@dataclass(frozen=True)
class FreePlayResult:
    """Free-play width from load reversals."""

    method: str
    width_deg: float
    spread_deg: float
    reversals: list[Reversal]
    elastic_deg: float | None
    notes: list[str] = field(default_factory=list)

    def as_dict(self) -> dict[str, Any]:
        """Plain values for JSON."""
        return {"method": self.method, "width_deg": self.width_deg, "spread_deg": self.spread_deg,
                "elastic_correction_deg": self.elastic_deg, "reversals": [r.as_dict() for r in self.reversals],
                "notes": self.notes}


def reversal_free_play(t: FloatArray, hinge_edges: list[Edge], hinge_moment: FloatArray, surface: FloatArray,
                       position: FloatArray | None,
                       compliance_deg_per_kinlb: float | None = None) -> FreePlayResult | None:
    """Median jump over the sign-changing load edges (None when there is none)."""
    rows = []
    rel = surface - position if position is not None else surface
    elastic_all = []
    for e in hinge_edges:
        h0, _ = settled(hinge_moment, e.before.start, e.before.stop, 0.5)
        h1, _ = settled(hinge_moment, e.after.start, e.after.stop, 0.5)
        if np.sign(h0) == np.sign(h1) or h0 == 0.0 or h1 == 0.0:
            continue
        y0, _ = settled(rel, e.before.start, e.before.stop, 0.4)
        y1, _ = settled(rel, e.after.start, e.after.stop, 0.4)
        jump = y1 - y0
        if compliance_deg_per_kinlb is not None:
            elastic = compliance_deg_per_kinlb * (h1 - h0) * 1e-3
            elastic_all.append(abs(elastic))
            jump -= elastic
        rows.append(Reversal(float(t[e.index]), h0, h1, float(jump)))
    if not rows:
        return None
    widths = np.abs([r.jump_deg for r in rows])
    notes = []
    if position is None:
        notes.append("no LVDT position: the surface jump is taken as it is")
    if compliance_deg_per_kinlb is None:
        notes.append("no compliance given: the width includes the elastic deflection over the load swing")
    method = "settled surface angle minus LVDT position, jump at each load reversal (median)"
    return FreePlayResult(method, float(np.median(widths)), float(np.std(widths)), rows,
                          float(np.mean(elastic_all)) if elastic_all else None, notes)
