"""A host simulation's recorded integration of the actuator against the truth: does it match, and which fault.

The record (a data-contract CSV or a bag) holds what the host fed its actuator, the command and the hinge
moment, and what it read back. The truth is ema_sim's model driven by the same inputs, held between the
record's samples. When the two differ by more than the tolerance, each fault a host integration makes
is tried in turn (:func:`diagnose`): the truth with that fault planted, and the fault that brings it
closest to the record is named, when it explains the difference (leaves at most :data:`EXPLAINED` of
it). Section 4.4.1's hinge-moment sign error is the first of them.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ema_sim.errors import DataError
from ema_sim.export.target import CONTINUOUS, ExportTarget
from ema_sim.export.verify import unit_ratios
from ema_sim.io.csv import MeasuredData
from ema_sim.models import create
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


@dataclass(frozen=True)
class Hypothesis:
    """One fault planted in the truth, and how close that brings it to the record.

    Parameters
    ----------
    fault : str
        ``none``, ``sign``, ``units``, ``delay``, ``rate`` or ``frame time``.
    detail : str
        The fault in words.
    rms_deg : float
        Rms difference to the record over its outputs.
    """

    fault: str
    detail: str
    rms_deg: float


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
        Every fault tried, ``none`` first.
    """

    source: str
    target: ExportTarget
    tolerance_deg: float
    tried: list[Hypothesis] = field(default_factory=list)

    @property
    def as_is(self) -> Hypothesis:
        """The truth without a fault."""
        return self.tried[0]

    @property
    def matches(self) -> bool:
        """The integration is the truth within the tolerance."""
        return self.as_is.rms_deg <= self.tolerance_deg

    @property
    def fault(self) -> Hypothesis | None:
        """The fault that explains the difference (None when it matches, or when none explains it)."""
        if self.matches:
            return None
        best = min(self.tried[1:], key=lambda h: h.rms_deg, default=None)
        if best is None or not best.rms_deg <= max(self.tolerance_deg, EXPLAINED * self.as_is.rms_deg):
            return None
        return best

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready.

        Returns
        -------
        dict
            The verdict and every hypothesis.
        """
        fault = self.fault
        return {"record": self.source, "model": self.target.truth, "channel": self.target.channel,
                "matches": self.matches, "tolerance_deg": self.tolerance_deg, "rms_deg": self.as_is.rms_deg,
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
            return [head, f"  MATCHES the truth: rms {self.as_is.rms_deg:.3g}° ≤ {self.tolerance_deg:g}°", "PASS"]
        out = [head, f"  does not match: rms {self.as_is.rms_deg:.3g}° > {self.tolerance_deg:g}°"]
        fault = self.fault
        if fault is None:
            out.append("  no single fault explains it (closest below)")
        else:
            out.append(f"  likely fault: {fault.fault}: {fault.detail} (rms {fault.rms_deg:.3g}° with it)")
        for h in sorted(self.tried[1:], key=lambda h: h.rms_deg)[:3]:
            out.append(f"    {h.fault:10s} {h.detail}: rms {h.rms_deg:.3g}°")
        out.append("FAIL")
        return out


Simulate = Callable[[FloatArray, FloatArray, FloatArray], dict[str, FloatArray]]
"""``simulate(time_s, command_deg, hinge_moment_inlb)`` → outputs at the record's samples."""


def _simulator(target: ExportTarget, rate_hz: float | None = None) -> Simulate:
    if target.truth in CONTINUOUS:
        model = create(target.truth, target.channel, params=target.params)
    else:
        model = create(target.truth, target.channel, params=target.params, rate_hz=rate_hz or target.rate_hz)

    def simulate(t: FloatArray, cmd: FloatArray, hm: FloatArray) -> dict[str, FloatArray]:
        model.trim(cmd[0], hm[0])
        with np.errstate(all="ignore"):
            block = model.run_outputs(t, cmd, hm, sample_times=t, end_s=float(t[-1]))[0]
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
    result = Diagnosis(data.source, target, tolerance_deg, [Hypothesis("none", "the truth as it is", score(base))])
    tried = result.tried
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
