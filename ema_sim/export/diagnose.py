"""A host simulation's recorded integration of the actuator against the truth: does it match, and which fault.

The record (a data-contract CSV or a bag) holds what the host fed its actuator, the command and the hinge
moment, and what it read back. The truth is ema_sim's model driven by the same inputs, held between the
record's samples.

Hosts log a step in more than one honest way, so the usual alignments are tried first
(:data:`ALIGNMENTS`): the record as logged; the outputs after each step logged with its command (one
step late); the outputs before the previous step (one step early); the command stamped with the end
of the frame it drove; the outputs read half a frame late or early. The one that matches passes, and
is named ("logged one step late: the record matches with the outputs shifted 1.25 ms"). Then each fault
a host integration makes is tried in turn (:func:`diagnose`): the truth with that fault planted. A fault
is named only when it explains the record (leaves at most :data:`EXPLAINED` of the difference) and
explains it better than every alignment: a wrong fault named with confidence is the mistake section 4.5
warns about. Section 4.4.1's hinge-moment sign error is the first of them; a delay of the model the host
left out (HOAD3's 2 ms feedback delay) is another.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from ema_sim.errors import DataError
from ema_sim.export.target import CONTINUOUS, ExportTarget
from ema_sim.export.verify import unit_ratios
from ema_sim.io.measured import MeasuredData
from ema_sim.models.arrays import FloatArray

EXPLAINED = 0.2
"""A fault is named when the truth with it planted leaves at most this fraction of the rms difference."""
TOLERANCE_DEG = 0.01
"""The rms difference below which the integration matches (deg)."""
DELAYS_S: tuple[float, ...] = (0.00125, 0.0025, 0.005, 0.0075, 0.01, 0.015, 0.02, 0.03, 0.05)
"""Extra delays tried (s), on the outputs' side: the host reads them late."""
RATES_HZ: tuple[float, ...] = (100.0, 200.0, 400.0, 800.0, 1000.0, 1600.0, 2000.0, 4000.0)
"""Integration rates tried for a discrete model (the declared one is skipped)."""
FRAME_SCALES: tuple[float, ...] = (0.25, 0.5, 0.8, 1.25, 2.0, 4.0)
"""How much longer than the record's clock the host told the model each frame was."""
OUTPUTS: tuple[str, ...] = ("position_deg", "surface_deg")
ALIGNMENT = "alignment"
"""The kind of a hypothesis that is a way of logging, not a fault."""
DELAY_NAMES: dict[str, str] = {"delay_s": "command delay", "command_delay_s": "command delay",
                               "feedback_delay_s": "feedback delay"}
"""The truth's delays a host may leave out, in words."""


@dataclass(frozen=True)
class Hypothesis:
    """One fault planted in the truth, and how close that brings it to the record.

    Parameters
    ----------
    fault : str
        ``alignment`` (a way of logging, not a fault), ``sign``, ``units``, ``delay``, ``delay left out``,
        ``rate`` or ``frame time``.
    detail : str
        The fault or the alignment in words.
    rms_deg : float
        Rms difference to the record over its outputs.
    """

    fault: str
    detail: str
    rms_deg: float

    @property
    def is_alignment(self) -> bool:
        """A way of logging the record, not a fault."""
        return self.fault == ALIGNMENT


@dataclass
class Diagnosis:
    """The verdict on a host's integration.

    Parameters
    ----------
    source : str
        The record.
    target : ExportTarget
        The truth's model and values.
    tolerance_deg : float
        The rms below which it matches.
    tried : list of Hypothesis
        Every alignment and fault tried, the record as logged first.
    """

    source: str
    target: ExportTarget
    tolerance_deg: float
    tried: list[Hypothesis] = field(default_factory=list)

    @property
    def as_is(self) -> Hypothesis:
        """The truth against the record as logged."""
        return self.tried[0]

    @property
    def best_alignment(self) -> Hypothesis:
        """The way of logging that brings the truth closest to the record (as logged on a tie)."""
        return min((h for h in self.tried if h.is_alignment), key=lambda h: h.rms_deg)

    @property
    def fault(self) -> Hypothesis | None:
        """The fault that explains the record better than every alignment (None: no fault does)."""
        best = min((h for h in self.tried if not h.is_alignment), key=lambda h: h.rms_deg, default=None)
        aligned = self.best_alignment.rms_deg
        if best is None or not best.rms_deg <= max(self.tolerance_deg, EXPLAINED * self.as_is.rms_deg):
            return None
        if aligned <= self.tolerance_deg:  # an honest alignment matches: a fault must do clearly better
            return best if best.rms_deg < EXPLAINED * aligned else None
        return best if best.rms_deg < aligned else None

    @property
    def matches(self) -> bool:
        """The integration is the truth within the tolerance, as logged or in one of the usual alignments."""
        return self.best_alignment.rms_deg <= self.tolerance_deg and self.fault is None

    @property
    def alignment(self) -> Hypothesis | None:
        """The alignment the record matches in (None: as logged, or no match)."""
        if not self.matches or self.as_is.rms_deg <= self.tolerance_deg:
            return None
        return self.best_alignment

    def as_dict(self) -> dict[str, object]:
        """JSON-ready.

        Returns
        -------
        dict
            The verdict and every hypothesis.
        """
        fault = self.fault
        aligned = self.alignment
        return {"record": self.source, "model": self.target.truth, "channel": self.target.channel,
                "matches": self.matches, "tolerance_deg": self.tolerance_deg, "rms_deg": self.as_is.rms_deg,
                "alignment": None if aligned is None else aligned.detail,
                "aligned_rms_deg": None if aligned is None else aligned.rms_deg,
                "fault": None if fault is None else fault.fault, "detail": None if fault is None else fault.detail,
                "tried": [h.__dict__ for h in self.tried]}

    def lines(self) -> list[str]:
        """The verdict as text lines.

        Returns
        -------
        list of str
            Verdict first, then the closest hypotheses.
        """
        head = f"{self.source}: a host's integration of {self.target.truth} ({self.target.channel})"
        if self.matches:
            aligned = self.alignment
            if aligned is None:
                return [head, f"  MATCHES the truth: rms {self.as_is.rms_deg:.3g}° ≤ {self.tolerance_deg:g}°", "PASS"]
            name, _, rest = aligned.detail.partition(": ")
            return [head, f"  {name}: matches {rest}: rms {aligned.rms_deg:.3g}° ≤ {self.tolerance_deg:g}° (as logged: "
                          f"rms {self.as_is.rms_deg:.3g}°)", "  MATCHES the truth in that alignment", "PASS"]
        out = [head, f"  does not match: rms {self.as_is.rms_deg:.3g}° > {self.tolerance_deg:g}° as logged, "
                     f"{self.best_alignment.rms_deg:.3g}° in the closest alignment"]
        fault = self.fault
        if fault is None:
            out.append("  no single fault explains it better than the usual alignments (closest below)")
        else:
            out.append(f"  likely fault: {fault.fault}: {fault.detail} (rms {fault.rms_deg:.3g}° with it)")
        for h in sorted(self.tried[1:], key=lambda h: h.rms_deg)[:3]:
            out.append(f"    {h.fault:10s} {h.detail}: rms {h.rms_deg:.3g}°")
        out.append("FAIL")
        return out


Simulate = Callable[..., dict[str, FloatArray]]
"""``simulate(time_s, command_deg, hinge_moment_inlb, shift_s=0)`` → outputs at the record's samples (shifted)."""


def _simulator(target: ExportTarget, rate_hz: float | None = None) -> Simulate:
    if rate_hz is not None and target.truth not in CONTINUOUS:
        target = replace(target, rate_hz=rate_hz)
    model = target.truth_model()

    def simulate(t: FloatArray, cmd: FloatArray, hm: FloatArray, shift_s: float = 0.0) -> dict[str, FloatArray]:
        model.trim(cmd[0], hm[0])
        samples = np.maximum(t + shift_s, 0.0)
        with np.errstate(all="ignore"):
            block = model.run_outputs(t, cmd, hm, sample_times=samples, end_s=float(max(t[-1], samples[-1])))[0]
        return {"position_deg": block[:, 0], "surface_deg": block[:, 1]}

    return simulate


def _rms(record: dict[str, FloatArray], sim: dict[str, FloatArray]) -> float:
    errors = [record[o] - sim[o] for o in record]
    e = np.concatenate(errors)
    return float(np.sqrt(np.mean(e**2))) if np.all(np.isfinite(e)) else math.inf


def _delayed(sim: dict[str, FloatArray], t: FloatArray, delay_s: float) -> dict[str, FloatArray]:
    """Outputs read ``delay_s`` late (zero-order hold on the record's samples)."""
    idx = np.clip(np.searchsorted(t, t - delay_s + 1e-9, side="right") - 1, 0, t.size - 1)
    return {o: v[idx] for o, v in sim.items()}


def alignments(t: FloatArray, cmd: FloatArray, hm: FloatArray, rec: dict[str, FloatArray],
               base: dict[str, FloatArray], truth: Simulate) -> list[Hypothesis]:
    """The usual ways a host logs a step, each as the truth aligned to the record (beyond the record as logged).

    Parameters
    ----------
    t : numpy.ndarray
        The record's times from 0 (s).
    cmd, hm : numpy.ndarray
        Its inputs.
    rec : dict
        Its outputs.
    base : dict
        The truth at the record's samples, as logged.
    truth : callable
        The truth (:data:`Simulate`).

    Returns
    -------
    list of Hypothesis
        One per alignment, its rms over the rows it aligns.
    """
    if t.size < 3:
        return []
    frame = float(np.median(np.diff(t)))
    ms = f"{1e3 * frame:g} ms"
    half = f"{0.5e3 * frame:g} ms"

    def shifted(k: int) -> float:
        """The record's outputs against the truth's ``k`` rows later."""
        a = {o: v[: v.size - k] if k > 0 else v[-k:] for o, v in rec.items()}
        b = {o: base[o][k:] if k > 0 else base[o][: base[o].size + k] for o in rec}
        return _rms(a, b)

    advanced = truth(t, np.append(cmd[1:], cmd[-1]), np.append(hm[1:], hm[-1]))
    return [
        Hypothesis(ALIGNMENT, f"logged one step late: with the outputs shifted {ms} (the outputs after each step "
                              "logged with its command)", shifted(1)),
        Hypothesis(ALIGNMENT, f"logged one step early: with the outputs shifted -{ms} (the outputs before the "
                              "step logged with the next command)", shifted(-1)),
        Hypothesis(ALIGNMENT, f"time stamped at the frame end: with the commands shifted -{ms} (each command "
                              "logged at the end of the frame it drove)", _rms(rec, {o: advanced[o] for o in rec})),
        Hypothesis(ALIGNMENT, f"a half-frame offset: with the outputs shifted {half} (read half a frame after "
                              "the command)",
                   _rms(rec, {o: v for o, v in truth(t, cmd, hm, 0.5 * frame).items() if o in rec})),
        Hypothesis(ALIGNMENT, f"a half-frame offset: with the outputs shifted -{half} (read half a frame before "
                              "the command)",
                   _rms(rec, {o: v for o, v in truth(t, cmd, hm, -0.5 * frame).items() if o in rec})),
    ]


def diagnose(data: MeasuredData, target: ExportTarget, *, tolerance_deg: float = TOLERANCE_DEG) -> Diagnosis:
    """Compare a host's recorded integration with the truth and name the likely fault.

    Parameters
    ----------
    data : MeasuredData
        The record: the command and hinge moment the host fed, the outputs it read back.
    target : ExportTarget
        The truth's model and values.
    tolerance_deg : float
        The rms difference below which the integration matches.

    Returns
    -------
    Diagnosis
        The verdict and every fault tried.
    """
    outputs = [o for o in OUTPUTS if getattr(data, o) is not None]
    if not outputs:
        raise DataError(f"{data.source or 'the record'}: no position_deg or surface_deg column to compare")
    t = np.asarray(data.time_s, dtype=float) - float(data.time_s[0])
    cmd = np.asarray(data.command_deg, dtype=float)
    hm = np.asarray(data.hinge_moment, dtype=float)
    rec = {o: data.column(o) for o in outputs}
    truth = _simulator(target)

    def score(sim: dict[str, FloatArray]) -> float:
        return _rms(rec, {o: sim[o] for o in outputs})

    base = truth(t, cmd, hm)
    result = Diagnosis(data.source, target, tolerance_deg, [Hypothesis(ALIGNMENT, "as logged", score(base))])
    tried = result.tried
    tried.extend(alignments(t, cmd, hm, rec, base, truth))
    for name, value in target.delay_params().items():
        left_out = _simulator(target.with_values(**{name: 0.0}))
        tried.append(Hypothesis("delay left out", f"the model's {1e3 * value:g} ms {DELAY_NAMES[name]} left out "
                                                  "(the outputs lead the truth)", score(left_out(t, cmd, hm))))
    if np.any(hm != 0.0):
        tried.append(Hypothesis("sign", "the hinge moment reversed (an aiding load fed as an opposing one, "
                                        "section 4.4.1)", score(truth(t, cmd, -hm))))
    tried.append(Hypothesis("sign", "the position read with its sign flipped", score({o: -v for o, v in base.items()})))
    tried.append(Hypothesis("sign", "the command fed with its sign flipped", score(truth(t, -cmd, hm))))
    for what, k in unit_ratios(target.channel).items():
        planted = truth(t, k * cmd, hm) if "command" in what else {o: k * v for o, v in base.items()}
        tried.append(Hypothesis("units", f"degrees and volts mixed: {what} (×{k:.4g})", score(planted)))
    for d in DELAYS_S:
        tried.append(Hypothesis("delay", f"the outputs read {1e3 * d:g} ms late", score(_delayed(base, t, d))))
    if target.truth not in CONTINUOUS:
        for r in RATES_HZ:
            if r != target.rate_hz:
                tried.append(Hypothesis("rate", f"the model integrated at {r:g} Hz, not {target.rate_hz:g} Hz",
                                        score(_simulator(target, r)(t, cmd, hm))))
    for f in FRAME_SCALES:
        tried.append(Hypothesis("frame time", f"each frame given to the model as {f:g}× the record's",
                                score(truth(t * f, cmd, hm))))
    return result
