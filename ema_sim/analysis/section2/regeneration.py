"""Voltage regeneration (section 2.5): the 150 V bus peak against the 185 V allowed.

Decelerating the motor's inertia (or an aiding load) makes the motor a generator that raises the
bus; the report watched an oscilloscope on the bus during a 5 % FS square sweep 0.1-5 Hz for spikes
above the manufacturer's 185 Vdc. Here, from a ``bus_v`` column (a rig's, or a bag's
``/ema/sensor/bus``): the nominal bus (median), the peak, its time, the rise above nominal, and the
margin to the limit. The square sweep itself is recognised from the command (:func:`read_regen`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray
from typing_extensions import override

from ema_sim.analysis.formatting import figure
from ema_sim.analysis.formatting.markdown import image
from ema_sim.analysis.section2.base import RecordAnalysis, Section2Test
from ema_sim.analysis.section2.segments import EdgeRun, Reading
from ema_sim.jsontypes import JsonObject

FloatArray = NDArray[np.float64]

BUS_LIMIT_V = 185.0
"""The manufacturer's allowable bus voltage (section 2.5)."""


@dataclass(frozen=True)
class RegenerationResult:
    """Bus-voltage peak of a record.

    Parameters
    ----------
    nominal_v : float
        Median bus voltage, V.
    peak_v : float
        Peak, V.
    peak_time_s : float
        When it peaked, s.
    limit_v : float
        The allowed peak, V.
    """

    nominal_v: float
    peak_v: float
    peak_time_s: float
    limit_v: float

    @property
    def rise_v(self) -> float:
        """Peak above nominal."""
        return self.peak_v - self.nominal_v

    @property
    def margin_v(self) -> float:
        """Limit minus peak (negative: over the limit)."""
        return self.limit_v - self.peak_v

    def as_dict(self) -> JsonObject:
        """Plain values for JSON.

        Returns
        -------
        dict
            Nominal, peak, its time, rise, limit, margin and whether the peak is within the limit.
        """
        return {"nominal_v": self.nominal_v, "peak_v": self.peak_v, "peak_time_s": self.peak_time_s,
                "rise_v": self.rise_v, "limit_v": self.limit_v, "margin_v": self.margin_v,
                "within_limit": self.peak_v <= self.limit_v, "quality": "ok"}


def bus_peak(t: FloatArray, bus_v: FloatArray, limit_v: float = BUS_LIMIT_V) -> RegenerationResult:
    """Nominal, peak and margin of the bus voltage.

    Parameters
    ----------
    t : numpy.ndarray
        Time, s.
    bus_v : numpy.ndarray
        Bus voltage, V.
    limit_v : float
        The allowed peak, V.

    Returns
    -------
    RegenerationResult
        The figures.
    """
    i = int(np.argmax(bus_v))
    return RegenerationResult(float(np.median(bus_v)), float(bus_v[i]), float(t[i]), limit_v)


def read_regen(run: EdgeRun) -> Reading | None:
    """A square wave whose holds shrink to under half their first length: the regeneration square sweep.

    Parameters
    ----------
    run : EdgeRun
        Consecutive command edges.

    Returns
    -------
    Reading or None
        ``regen`` with the swept band, or None.
    """
    inner = run.inner_holds_s
    if not run.alternating_equal or float(np.std(inner) / np.mean(inner)) < 0.15 or inner[-1] >= 0.5 * inner[0]:
        return None
    f0, f1 = 0.5 / float(inner[0]), 0.5 / float(inner[-1])
    return Reading("regen", f"square wave swept {f0:.3g}-{f1:.3g} Hz, ±{run.amplitude_deg:.3g}°",
                   {"f0_hz": f0, "f1_hz": f1})


class Regeneration(Section2Test[RegenerationResult]):
    """Bus peak against 185 V wherever the record carries the bus voltage."""

    key = "regeneration"
    title = "Voltage regeneration (section 2.5)"
    kinds = ("regen",)

    @override
    def run(self, ra: RecordAnalysis) -> list[RegenerationResult]:
        data = ra.data
        if data.bus_v is None:
            ra.not_computed[self.key] = "no bus voltage column (bus_v): regeneration not assessed"
            return []
        if not ra.segments("regen"):
            ra.notes.append("bus voltage assessed on a record that is not the regeneration square sweep")
        return [bus_peak(data.time_s, data.bus_v)]


    @override
    def as_json(self, results: list[RegenerationResult], ra: RecordAnalysis) -> JsonObject:
        return {self.key: results[0].as_dict() if results else None}

    @override
    def markdown(self, ra: RecordAnalysis, results: list[RegenerationResult],
                 images: list[str | None]) -> list[str]:
        lines: list[str] = []
        for g, img in zip(results, images, strict=True):
            lines += [f"Bus nominal {g.nominal_v:.1f} V, peak {g.peak_v:.1f} V at {g.peak_time_s:.2f} s "
                      f"(+{g.rise_v:.1f} V): {'within' if g.peak_v <= g.limit_v else 'OVER'} the {g.limit_v:g} V "
                      f"limit, margin {g.margin_v:.1f} V.", ""]
            lines += image(img, "bus voltage")
        return lines

    @override
    def summary(self, ra: RecordAnalysis, r: RegenerationResult) -> list[str]:
        return [f"regeneration: peak {r.peak_v:.1f} V, margin {r.margin_v:.1f} V to {r.limit_v:g} V"]

    @override
    def plot(self, ra: RecordAnalysis, r: RegenerationResult, path: Path) -> bool:
        d = ra.data
        assert d.bus_v is not None
        fig, ax = figure.pyplot().subplots(figsize=(9, 3.5))
        ax.plot(d.time_s, d.bus_v, lw=0.6)
        ax.axhline(r.limit_v, color="r", ls="--", label=f"{r.limit_v:g} V limit")
        ax.plot(r.peak_time_s, r.peak_v, "rv", label=f"peak {r.peak_v:.1f} V")
        ax.set_xlabel("time, s")
        ax.set_ylabel("bus, V")
        ax.legend(fontsize=8)
        ax.grid(lw=0.3)
        figure.save(fig, path)
        return True


TEST = Regeneration()
