"""Hysteretic damping from sinusoidal load cycles (sections 2.9 and 3.2.2, figures 17 and 18).

For a sinusoidal load the hysteretic damping constant is ``h = A/(π·Pk²)`` (ref. 9 of the report):
``A`` the area inside the loop of force against deflection, ``Pk`` the peak deflection. Units as the
report's rw13 case (4.88 in·lb and 0.02155 in give 3,344.84 lb/in):

* force ``F`` at the actuator in lb: hinge moment / crank arm (``crank_arm_in`` of the channel);
* deflection ``x`` at the actuator in inches: the surface angle in radians times the crank arm;
* ``A = ∮ F dx`` in in·lb, per whole load cycle (trapezoidal sum; positive for a loop that dissipates
  energy, i.e. deflection lagging a load that aids it); ``Pk`` half the peak-to-peak deflection of the
  cycle (lightly smoothed) in inches.

The cycles are the whole periods of a sine fitted to the load. The surface angle (external sensor)
is used when present: it sees the gear train and linkages; the LVDT sees only the servo loop.

The test is recognised from a held command under a continuously moving load (:func:`read_load_sine`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray
from typing_extensions import override

from ema_sim.analysis.estimation.sine_fit import fit_sine
from ema_sim.analysis.formatting import figure
from ema_sim.analysis.formatting.markdown import bullets, image
from ema_sim.analysis.records.series import moving_average
from ema_sim.analysis.section2.base import RecordAnalysis, Section2Test
from ema_sim.analysis.section2.segments import HeldStretch, Reading
from ema_sim.jsontypes import JsonObject

FloatArray = NDArray[np.float64]

RW13_AREA_INLB = 4.88
RW13_PEAK_IN = 0.02155
"""The report's rw13 hysteresis case (section 3.2.2): 4.88 in·lb and 0.02155 in give 3,344.84 lb/in."""
MIN_LOAD_SWING_INLB = 20.0
"""A held command under a smaller load swing is a plain hold."""


def hysteretic_damping_constant(area_inlb: float, peak_in: float) -> float:
    """``h = A/(π·Pk²)`` in lb/in, from the loop area in in·lb and the peak deflection in inches.

    Parameters
    ----------
    area_inlb : float
        Loop area, in·lb.
    peak_in : float
        Peak deflection, in.

    Returns
    -------
    float
        The hysteretic damping constant h, lb/in.
    """
    return float(area_inlb / (np.pi * peak_in * peak_in))


@dataclass(frozen=True)
class LoadCycle:
    """One whole load cycle.

    Parameters
    ----------
    start_s : float
        Start of the cycle, s.
    end_s : float
        End of the cycle, s.
    area_inlb : float
        Loop area, in·lb.
    peak_in : float
        Peak deflection, in.
    """

    start_s: float
    end_s: float
    area_inlb: float
    peak_in: float

    @property
    def h_lb_per_in(self) -> float:
        """Hysteretic damping constant of the cycle."""
        return hysteretic_damping_constant(abs(self.area_inlb), self.peak_in)

    def as_dict(self) -> dict[str, float]:
        """Plain values for JSON.

        Returns
        -------
        dict
            Plain values for JSON.
        """
        return {"start_s": self.start_s, "end_s": self.end_s, "area_inlb": self.area_inlb, "peak_in": self.peak_in,
                "h_lb_per_in": self.h_lb_per_in}


@dataclass(frozen=True)
class HysteresisResult:
    """Hysteresis loops of a sinusoidal load test and their damping constant.

    Parameters
    ----------
    output : str
        Name of the output.
    freq_hz : float
        Load frequency, Hz.
    load_amplitude_inlb : float
        Amplitude of the load, in·lb.
    crank_arm_in : float
        Crank arm, in.
    cycles : list
        Every whole load cycle.
    force_lb : numpy.ndarray
        Force at the crank arm over the cycles, lb.
    deflection_in : numpy.ndarray
        Deflection at the actuator over the cycles, in.
    notes : list
        What to check.
    """

    output: str
    freq_hz: float
    load_amplitude_inlb: float
    crank_arm_in: float
    cycles: list[LoadCycle]
    force_lb: FloatArray
    deflection_in: FloatArray
    notes: list[str] = field(default_factory=list)

    @property
    def area_inlb(self) -> float:
        """Mean loop area."""
        return float(np.mean([c.area_inlb for c in self.cycles]))

    @property
    def peak_in(self) -> float:
        """Mean peak deflection."""
        return float(np.mean([c.peak_in for c in self.cycles]))

    @property
    def h_lb_per_in(self) -> float:
        """``A/(π·Pk²)`` from the mean area and peak."""
        return hysteretic_damping_constant(abs(self.area_inlb), self.peak_in)

    def as_dict(self) -> JsonObject:
        """Plain values for JSON.

        Returns
        -------
        dict
            Plain values for JSON.
        """
        hs = [c.h_lb_per_in for c in self.cycles]
        return {
            "output": self.output, "load_freq_hz": self.freq_hz, "load_omega_rad_s": 2 * np.pi * self.freq_hz,
            "load_amplitude_inlb": self.load_amplitude_inlb, "force_amplitude_lb": self.load_amplitude_inlb
            / self.crank_arm_in, "crank_arm_in": self.crank_arm_in, "cycles": [{**c.as_dict()} for c in self.cycles],
            "area_inlb": self.area_inlb, "peak_deflection_in": self.peak_in, "h_lb_per_in": self.h_lb_per_in,
            "h_spread_lb_per_in": float(np.std(hs)) if len(hs) > 1 else None,
            "formula": "h = A / (pi * Pk^2); A = loop area of force (hinge moment / crank arm, lb) against actuator "
                       "deflection (surface rad x crank arm, in), in in*lb; Pk = half peak-to-peak deflection, in",
            "notes": [*self.notes],
        }


def analyze_hysteresis(t: FloatArray, hinge_moment: FloatArray, deflection_deg: FloatArray, *, output: str,
                       crank_arm_in: float, freq_hz: float | None = None) -> HysteresisResult | None:
    """Loops of every whole load cycle (None when the record holds less than one).

    Parameters
    ----------
    t : numpy.ndarray
        Sample times, s.
    hinge_moment : numpy.ndarray
        Hinge moment, in·lb.
    deflection_deg : numpy.ndarray
        Surface (or LVDT) angle, deg.
    output : str
        Name of the output.
    crank_arm_in : float
        Crank arm, in.
    freq_hz : float or None
        Load frequency when known (else fitted), Hz.

    Returns
    -------
    HysteresisResult or None
        The loops, or None when the record holds less than one cycle.
    """
    fs = 1.0 / float(np.median(np.diff(t)))
    sine = fit_sine(t, hinge_moment, freq_hz)
    if sine is None:
        return None
    period = 1.0 / sine.freq_hz
    # Upward zero crossings of the fitted load, 2π·f·t + φ = 2πk: the cycle boundaries.
    cyc = sine.phase_rad / (2 * np.pi)
    half = 0.5 / fs * sine.freq_hz  # half a sample, in cycles: a crossing that close to an end counts
    k = np.arange(np.ceil(t[0] * sine.freq_hz + cyc - half), np.floor(t[-1] * sine.freq_hz + cyc + half))
    starts = (k - cyc) / sine.freq_hz
    force = hinge_moment / crank_arm_in
    x = np.radians(deflection_deg) * crank_arm_in
    cycles = []
    keep = np.zeros(t.size, dtype=bool)
    for s in starts:
        i0 = int(np.searchsorted(t, s))
        i1 = min(int(np.searchsorted(t, s + period)), t.size - 1)
        if i1 - i0 < 20 or t[i1] - t[i0] < 0.98 * period:
            continue
        f_c, x_c = force[i0:i1 + 1], x[i0:i1 + 1]
        area = float(np.sum(0.5 * (f_c[1:] + f_c[:-1]) * np.diff(x_c)))
        xs = moving_average(x_c, max(1, round(0.005 * period * fs)))
        peak = 0.5 * float(xs.max() - xs.min())
        cycles.append(LoadCycle(float(t[i0]), float(t[i1]), area, peak))
        keep[i0:i1 + 1] = True
    if not cycles:
        return None
    notes = []
    if np.mean([c.area_inlb for c in cycles]) < 0:
        notes.append("loop runs the non-dissipative way (deflection leads the load): check the hinge-moment sign")
    if output != "surface_deg":
        notes.append("no external surface angle: loops from the LVDT position (servo loop only)")
    return HysteresisResult(output, sine.freq_hz, sine.amplitude, crank_arm_in, cycles, force[keep], x[keep], notes)


def read_load_sine(h: HeldStretch) -> Reading | None:
    """A held command under a load that moves continuously (swing of at least 20 in·lb, not held in levels).

    Parameters
    ----------
    h : HeldStretch
        A held stretch of the command.

    Returns
    -------
    Reading or None
        ``load_sine``, or None.
    """
    if h.load is None or h.swing < MIN_LOAD_SWING_INLB:
        return None
    return Reading("load_sine", f"command held; load moving continuously ({h.swing:.4g} in·lb swing)")


class Hysteresis(Section2Test[HysteresisResult]):
    """Hysteretic damping of each sinusoidal-load segment."""

    key = "hysteresis"
    title = "Hysteretic damping (section 3.2.2)"
    kinds = ("load_sine",)
    absent = "no sinusoidal load with the command held recognised"

    @override
    def run(self, ra: RecordAnalysis) -> list[HysteresisResult]:
        data, t = ra.data, ra.data.time_s
        hm = data.hinge_moment_inlb
        if hm is None:
            ra.not_computed[self.key] = "no hinge moment: hysteretic damping not computed"
            return []
        out = []
        name, y = ra.primary(("surface_deg", "position_deg"))
        for seg in ra.segments(*self.kinds):
            sl = slice(seg.start, seg.stop)
            h = analyze_hysteresis(t[sl], hm[sl], y[sl], output=name, crank_arm_in=ra.channel.crank_arm_in,
                                   freq_hz=seg.params.get("freq_hz"))
            if h:
                out.append(h)
        return out


    @override
    def markdown(self, ra: RecordAnalysis, results: list[HysteresisResult],
                 images: list[str | None]) -> list[str]:
        lines: list[str] = []
        for h, img in zip(results, images, strict=True):
            lines += [f"{len(h.cycles)} load cycle(s) at {h.freq_hz:.4g} Hz ({2 * np.pi * h.freq_hz:.4g} rad/s), "
                      f"±{h.load_amplitude_inlb:.4g} in·lb (±{h.load_amplitude_inlb / h.crank_arm_in:.4g} lb at the "
                      f"{h.crank_arm_in:g} in crank arm), on {h.output}: A = {h.area_inlb:.4g} in·lb, Pk = "
                      f"{h.peak_in:.5f} in, **h = A/(π·Pk²) = {h.h_lb_per_in:,.2f} lb/in**. The report's rw13: "
                      f"{RW13_AREA_INLB} in·lb and {RW13_PEAK_IN} in give "
                      f"{hysteretic_damping_constant(RW13_AREA_INLB, RW13_PEAK_IN):,.2f} lb/in.", ""]
            lines += bullets(h.notes)
            lines += image(img, "hysteresis loop")
        return lines

    @override
    def summary(self, ra: RecordAnalysis, r: HysteresisResult) -> list[str]:
        return [f"hysteresis: A {r.area_inlb:.4g} in·lb, Pk {r.peak_in:.5f} in, h {r.h_lb_per_in:,.2f} lb/in"]

    @override
    def plot(self, ra: RecordAnalysis, r: HysteresisResult, path: Path) -> bool:
        fig, ax = figure.pyplot().subplots(figsize=(7, 5))
        ax.plot(r.deflection_in - r.deflection_in.mean(), r.force_lb, lw=0.7)
        ax.set_xlabel("deflection at the actuator, in")
        ax.set_ylabel("force at the crank arm, lb")
        ax.set_title(f"hysteresis loop, {2 * np.pi * r.freq_hz:.4g} rad/s: A {r.area_inlb:.3g} in·lb, "
                     f"Pk {r.peak_in:.4g} in, h {r.h_lb_per_in:,.0f} lb/in", fontsize=9)
        ax.grid(lw=0.3)
        figure.save(fig, path)
        return True


TEST = Hysteresis()
