"""Command error from a calibration staircase (sections 2.6 and 3.1.2.2, figures 27 and 28).

At every held level of the staircase the settled command (degrees and volts), LVDT feedback (volts
and degrees) and external surface angle are averaged. Two estimates of the command error
``position = (1 + Kb)·command + offset`` come out:

* **calibration curves**, the report's method: a third-order *command* curve (degrees → volts)
  fitted to the command data, a third-order *feedback* curve (volts → degrees) fitted to the feedback
  volts against the measured surface angle; nominal angles go through the command curve to volts and
  the volts through the feedback curve back to degrees (the loop nulls command volts against
  feedback volts); a line through (feedback − nominal) gives Kb and offset
  (:func:`ema_sim.calibration.command_error`).
* **direct**: a line through the settled surface angle (or LVDT position) minus the command, against
  the command, with the regression's standard errors.

The four-corner Monte Carlo bounds (:func:`ema_sim.calibration.four_corner_bounds`) take the largest
|Kb| and |offset| of the calibrations at hand.

The test is recognised from a command that steps (or moves, under a drive's profile) through at
least five held levels, mostly one way (:func:`read_staircase`).
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
from ema_sim.analysis.section2.segments import EdgeRun, MoveRun, Reading
from ema_sim.calibration import CommandError, Cubic, command_error, four_corner_bounds
from ema_sim.io.measured import MeasuredData
from ema_sim.jsontypes import JsonObject, JsonValue

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class Calibration:
    """The command error found on one staircase.

    Parameters
    ----------
    levels : dict
        Settled value of each recorded column at each held level, in staircase order.
    direct : CommandError
        Kb and offset of the line through settled output minus command.
    direct_sigma : tuple
        Standard errors of that Kb and offset.
    direct_reference : str
        The output the direct line is measured on.
    command_curve : Cubic or None
        Third-order command curve, degrees → volts.
    command_curve_rms_v : float or None
        RMS of its fit, V.
    feedback_curve : Cubic or None
        Third-order feedback curve, volts → degrees.
    feedback_curve_rms_deg : float or None
        RMS of its fit, deg.
    feedback_reference : str or None
        The output the feedback curve is fitted against.
    curve_error : CommandError or None
        Kb and offset from the two curves (section 3.1.2.2).
    nominal_deg : numpy.ndarray
        Nominal angles the bounds are given at, deg.
    bounds_deg : tuple
        Four-corner lower and upper bounds at those angles, deg.
    notes : list
        What could not be computed, and why.
    """

    levels: dict[str, list[float]]
    """Settled value of each recorded column at each held level, in staircase order."""
    direct: CommandError
    direct_sigma: tuple[float, float]
    direct_reference: str
    command_curve: Cubic | None
    command_curve_rms_v: float | None
    feedback_curve: Cubic | None
    feedback_curve_rms_deg: float | None
    feedback_reference: str | None
    curve_error: CommandError | None
    nominal_deg: FloatArray
    bounds_deg: tuple[FloatArray, FloatArray]
    notes: list[str] = field(default_factory=list)

    @property
    def error(self) -> CommandError:
        """The calibration's command error: from the curves when they exist, else the direct fit."""
        return self.curve_error or self.direct

    def as_dict(self) -> JsonObject:
        """Plain values for JSON.

        Returns
        -------
        dict
            Plain values for JSON.
        """
        def curve(c: Cubic | None) -> list[JsonValue] | None:
            return [*c.coefficients()] if c else None

        return {
            "levels": len(self.nominal_levels), "settled": {k: [*v] for k, v in self.levels.items()},
            "command_curve_v_per_deg": curve(self.command_curve), "command_curve_rms_v": self.command_curve_rms_v,
            "feedback_curve_deg_per_v": curve(self.feedback_curve),
            "feedback_curve_rms_deg": self.feedback_curve_rms_deg, "feedback_curve_against": self.feedback_reference,
            "curve_error": ({"kb": self.curve_error.kb, "offset_deg": self.curve_error.offset_deg}
                            if self.curve_error else None),
            "direct_error": {"kb": self.direct.kb, "kb_sigma": self.direct_sigma[0],
                             "offset_deg": self.direct.offset_deg, "offset_sigma_deg": self.direct_sigma[1],
                             "against": self.direct_reference},
            "kb": self.error.kb, "offset_deg": self.error.offset_deg,
            "four_corner_bounds": {"nominal_deg": self.nominal_deg.tolist(), "lower_deg": self.bounds_deg[0].tolist(),
                                   "upper_deg": self.bounds_deg[1].tolist()},
            "notes": [*self.notes],
        }

    @property
    def nominal_levels(self) -> list[float]:
        """The commanded levels."""
        return self.levels["command_deg"]


def _rms(x: FloatArray) -> float:
    return float(np.sqrt(np.mean(np.square(x))))


def fit_calibration(data: MeasuredData, holds: list[Hold]) -> Calibration:
    """Command error of a staircase whose held levels are ``holds`` (see the module docstring).

    Parameters
    ----------
    data : MeasuredData
        The record.
    holds : list
        The held levels, in order.

    Returns
    -------
    Calibration
        The command error, both ways.
    """
    notes: list[str] = []
    cols = [c for c in ("command_deg", "command_v", "position_v", "position_deg", "surface_deg")
            if getattr(data, c) is not None]
    levels = {c: [settled(getattr(data, c), h.start, h.stop, 0.5)[0] for h in holds] for c in cols}
    cmd = np.array(levels["command_deg"])
    ref_name = "surface_deg" if data.surface_deg is not None else "position_deg"
    if ref_name == "position_deg":
        notes.append("no external surface angle: direct error taken from the LVDT position")
    measured = np.array(levels[ref_name])
    A = np.column_stack([cmd, np.ones_like(cmd)])
    coef, *_ = np.linalg.lstsq(A, measured - cmd, rcond=None)
    resid = measured - cmd - A @ coef
    dof = max(cmd.size - 2, 1)
    cov = np.linalg.pinv(A.T @ A) * float(resid @ resid) / dof
    direct = CommandError(float(coef[0]), float(coef[1]))
    sig = (float(np.sqrt(cov[0, 0])), float(np.sqrt(cov[1, 1])))

    command_curve = feedback_curve = None
    c_rms = f_rms = None
    fb_ref = None
    curve_err = None
    if "command_v" in levels and "position_v" in levels:
        cv, pv = np.array(levels["command_v"]), np.array(levels["position_v"])
        command_curve = Cubic.fit(cmd, cv)
        c_rms = _rms(command_curve(cmd) - cv)
        fb_ref = ref_name
        if ref_name == "position_deg":
            notes.append("feedback curve fitted against the recorded LVDT degrees (no external surface angle): "
                         "it reproduces the recorder's own calibration")
        feedback_curve = Cubic.fit(pv, measured)
        f_rms = _rms(feedback_curve(pv) - measured)
    else:
        notes.append("no command_v/position_v columns: calibration curves not computed (direct error only)")
    nominal = np.linspace(cmd.min(), cmd.max(), 81)
    if command_curve is not None and feedback_curve is not None:
        curve_err = command_error(command_curve, feedback_curve, nominal)
    err = curve_err or direct
    bounds = four_corner_bounds([err], nominal)
    return Calibration(levels, direct, sig, ref_name, command_curve, c_rms, feedback_curve, f_rms, fb_ref,
                       curve_err, nominal, bounds, notes)


def pooled_bounds(errors: list[CommandError], lo_deg: float, hi_deg: float) -> JsonObject:
    """Four-corner bounds over several calibrations (figure 27: three calibrations of vehicle 1).

    Parameters
    ----------
    errors : list
        The calibrations' command errors.
    lo_deg : float
        Lowest nominal angle, deg.
    hi_deg : float
        Highest nominal angle, deg.

    Returns
    -------
    dict
        Calibrations pooled, largest |Kb| and |offset|, and the bounds over the nominal angles.
    """
    nominal = np.linspace(lo_deg, hi_deg, 81)
    lo, hi = four_corner_bounds(errors, nominal)
    return {"calibrations": len(errors), "kb_max_abs": max(abs(e.kb) for e in errors),
            "offset_max_abs_deg": max(abs(e.offset_deg) for e in errors), "nominal_deg": nominal.tolist(),
            "lower_deg": lo.tolist(), "upper_deg": hi.tolist()}


def read_staircase(run: EdgeRun | MoveRun) -> Reading | None:
    """At least 6 edges (or moves) over at least 5 held levels, held ≥ 0.8 s, mostly one way: a calibration.

    Parameters
    ----------
    run : EdgeRun or MoveRun
        Consecutive steps, or profiled moves, of the command.

    Returns
    -------
    Reading or None
        ``staircase``, or None.
    """
    if not (run.n >= 6 and run.distinct_levels >= 5 and float(np.median(run.holds_s)) >= 0.8
            and run.same_direction >= 0.6):
        return None
    how = "edges" if isinstance(run, EdgeRun) else "profiled moves"
    return Reading("staircase", f"{run.n} {how} over {run.distinct_levels} held levels, mostly one way "
                                "(calibration staircase)")


class CommandErrorTest(Section2Test[Calibration]):
    """Command error of every calibration staircase."""

    key = "command_error"
    title = "Command error (section 3.1.2.2)"
    kinds = ("staircase",)
    absent = "no calibration staircase recognised"

    @override
    def run(self, ra: RecordAnalysis) -> list[Calibration]:
        return [fit_calibration(ra.data, list(seg.holds)) for seg in ra.segments(*self.kinds)]


    @override
    def markdown(self, ra: RecordAnalysis, results: list[Calibration],
                 images: list[str | None]) -> list[str]:
        lines: list[str] = []
        for c, img in zip(results, images, strict=True):
            rows = []
            if c.curve_error:
                rows.append(["calibration curves", f"{c.curve_error.kb:+.5f}", f"{c.curve_error.offset_deg:+.4f}",
                             f"command curve RMS {num(c.command_curve_rms_v, '.2g')} V, feedback curve RMS "
                             f"{num(c.feedback_curve_rms_deg, '.2g')}° (against {c.feedback_reference})"])
            rows.append(["direct (settled − command)", f"{c.direct.kb:+.5f} ± {c.direct_sigma[0]:.1g}",
                         f"{c.direct.offset_deg:+.4f} ± {c.direct_sigma[1]:.1g}", f"against {c.direct_reference}"])
            lines += table(["method", "Kb", "offset, °", "fit"], rows)
            if c.command_curve and c.feedback_curve:
                lines += [f"Command curve (deg → V): {', '.join(f'{x:.6g}' for x in c.command_curve.coefficients())};"
                          f" feedback curve (V → deg): "
                          f"{', '.join(f'{x:.6g}' for x in c.feedback_curve.coefficients())}.", ""]
            lines += [f"Four-corner bounds at ±{max(abs(c.nominal_deg)):.0f}°: {c.bounds_deg[0][-1]:+.4f}° to "
                      f"{c.bounds_deg[1][-1]:+.4f}°.", ""]
            lines += bullets(c.notes)
            lines += image(img, "command error")
        return lines

    @override
    def summary(self, ra: RecordAnalysis, r: Calibration) -> list[str]:
        return [f"command error: Kb {r.error.kb:+.5f}, offset {r.error.offset_deg:+.4f}°"]

    @override
    def plot(self, ra: RecordAnalysis, r: Calibration, path: Path) -> bool:
        fig, ax = figure.pyplot().subplots(1, 2, figsize=(11, 4))
        cmd = np.array(r.levels["command_deg"])
        meas = np.array(r.levels[r.direct_reference])
        ax[0].plot(cmd, meas - cmd, "o", ms=4, label=f"settled {r.direct_reference} − command")
        ax[0].plot(r.nominal_deg, r.direct(r.nominal_deg) - r.nominal_deg, "-", lw=1, label="direct line")
        if r.curve_error:
            ax[0].plot(r.nominal_deg, r.curve_error(r.nominal_deg) - r.nominal_deg, "-", lw=1.5,
                       label=f"curves: Kb {r.curve_error.kb:+.5f}, offset {r.curve_error.offset_deg:+.4f}°")
        ax[0].fill_between(r.nominal_deg, r.bounds_deg[0], r.bounds_deg[1], color="0.9", label="four-corner bounds")
        ax[0].set_xlabel("nominal command, deg")
        ax[0].set_ylabel("error, deg")
        ax[0].legend(fontsize=8)
        ax[0].grid(lw=0.3)
        if r.command_curve and r.feedback_curve and "command_v" in r.levels and "position_v" in r.levels:
            cv, pv = np.array(r.levels["command_v"]), np.array(r.levels["position_v"])
            ax[1].plot(cmd, 1e3 * (cv - r.command_curve(cmd)), "o-", ms=4, lw=0.8,
                       label=f"command curve, deg → V (RMS {1e3 * (r.command_curve_rms_v or 0):.2g} mV)")
            ax[1].plot(meas, 1e3 * (meas - r.feedback_curve(pv)) * abs(float(r.command_curve.c1)), "s-", ms=3, lw=0.8,
                       label=f"feedback curve, V → deg (RMS {1e3 * (r.feedback_curve_rms_deg or 0):.2g} m°), in mV")
            ax[1].set_xlabel("degrees")
            ax[1].set_ylabel("third-order fit residual, mV")
            ax[1].set_title("calibration curves: what the third-order fits leave", fontsize=9)
            ax[1].legend(fontsize=8)
            ax[1].grid(lw=0.3)
        else:
            ax[1].axis("off")
        ax[0].set_title("command error (figure 27)")
        figure.save(fig, path)
        return True


TEST = CommandErrorTest()
