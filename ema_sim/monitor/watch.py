"""The offline monitor: a record watched against its reference, first departure detected, isolated, re-estimated.

:func:`watch` runs the reference on the record's command and load, forms each output's residual, calibrates
its centre and spread on the first ``healthy_s`` seconds (stated healthy), runs a CUSUM per output on 20 ms
block means from there on, and at the first alarm isolates the fault on the window that follows
(:mod:`ema_sim.monitor.isolate`: the fits, and the signature's vote) and re-estimates its parameter on a window
sliding to the record's end. The verdict latches: one detection per record, the first departure from the
reference (the node's frame-by-frame monitor re-baselines and watches on: :mod:`ema_sim.monitor.online`).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ema_sim.errors import DataError
from ema_sim.faults.kinds import FAULTS, FloatArray
from ema_sim.io.measured import MeasuredData
from ema_sim.jsontypes import JsonObject
from ema_sim.monitor.detect import Cusum, block_means, spread, threshold
from ema_sim.monitor.isolate import Candidate, Estimate, Window, candidates, fit_candidate, isolate, signature
from ema_sim.monitor.reference import Reference, predict

OUTPUTS = ("position_deg", "surface_deg", "current_a")
MIN_SPREAD_DEG = 1e-4
"""Floor on a block mean's spread (a noise-free simulated record would otherwise have none)."""
MIN_SAMPLE_SPREAD_DEG = 1e-3
"""Floor on a sample residual's spread, for the fits' weights."""


@dataclass(frozen=True)
class Options:
    """How a record is watched.

    Parameters
    ----------
    healthy_s : float
        The first seconds, stated healthy: the residuals' centre and spread (and a learned model) come from them.
    false_alarms_per_hour : float
        The false-alarm rate the detection threshold is set for.
    block_s : float
        The residual block (s).
    k : float
        The CUSUM drift (spreads): half the smallest shift of a block mean it is tuned for.
    window_s : float
        How long after a detection the isolation looks (s), and the re-estimation window's length.
    estimates : int
        How many re-estimations on the sliding window after the isolation (0: none).
    """

    healthy_s: float = 30.0
    false_alarms_per_hour: float = 0.1
    block_s: float = 0.02
    k: float = 0.5
    window_s: float = 5.0
    estimates: int = 6


@dataclass
class Detection:
    """The first departure: when, on which output, the isolated fault and its parameter's estimate."""

    time_s: float
    output: str
    kind: str
    parameter: str
    estimate: float
    uncertainty: float
    statistic: float
    onset_s: float
    nominal: float
    size: float
    """The estimate as a fault size (relative or absolute as the kind's ``--fault`` size is)."""
    ranking: list[Estimate] = field(default_factory=list)
    signature: dict[str, Any] = field(default_factory=dict)

    def as_dict(self) -> JsonObject:
        """Strict-JSON fields (no NaN or infinity: null)."""
        def num(x: float) -> float | None:
            return float(x) if math.isfinite(x) else None

        return {
            "time_s": num(self.time_s), "output": self.output, "kind": self.kind, "parameter": self.parameter,
            "estimate": num(self.estimate), "uncertainty": num(self.uncertainty), "statistic": num(self.statistic),
            "onset_s": num(self.onset_s), "nominal": num(self.nominal), "size": num(self.size),
            "signature": self.signature,
            "ranking": [{"kind": e.kind, "parameter": e.parameter, "estimate": num(e.estimate),
                         "uncertainty": num(e.uncertainty), "score": num(e.score), "veto": e.veto}
                        for e in self.ranking],
        }


@dataclass
class Timeline:
    """What the plot shows: block residuals and statistics per output, estimates over time."""

    block_t: FloatArray
    z: dict[str, FloatArray]
    statistic: dict[str, FloatArray]
    estimate_t: list[float] = field(default_factory=list)
    estimate: list[float] = field(default_factory=list)
    estimate_sigma: list[float] = field(default_factory=list)


@dataclass
class Verdict:
    """The monitor's answer on one record."""

    reference: Reference
    threshold: float
    healthy_s: float
    detections: list[Detection]
    timeline: Timeline
    watched_s: float
    cpu_s: float
    """Process time the detection pass took (reference run and CUSUM; isolation excluded)."""

    def as_dict(self) -> JsonObject:
        """The ``--json`` document."""
        return {
            "reference": {"model": self.reference.model, "origin": self.reference.origin,
                          "params": {k: v for k, v in self.reference.overrides.items() if math.isfinite(v)}},
            "threshold": self.threshold, "healthy_s": self.healthy_s, "watched_s": self.watched_s,
            "detection_cpu_share": self.cpu_s / self.watched_s if self.watched_s > 0 else None,
            "detections": [d.as_dict() for d in self.detections],
        }


def fault_size(kind: str, parameter: str, nominal: float, estimate: float) -> float:
    """An estimate as the size ``--fault`` takes for the kind (relative change, or absolute amount)."""
    cls = FAULTS[kind]
    if cls.stage == "output" or kind in ("jam", "hm_sign"):
        return estimate
    if cls.relative:
        power = next((c.power for cs in cls.changes.values() for c in cs if c.parameter == parameter), 1.0)
        return float((estimate / nominal) ** (1.0 / power) - 1.0) if nominal > 0.0 and estimate >= 0.0 else math.nan
    return estimate - nominal


def check_inputs(data: MeasuredData, *, assume_no_load: bool = False) -> None:
    """One clear error for a record the monitor cannot watch.

    Raises
    ------
    DataError
        No output, or no load (unless ``assume_no_load``).
    """
    if data.position_deg is None and data.surface_deg is None:
        raise DataError(f"{data.source or 'data'}: no position_deg or surface_deg to watch")
    if data.hinge_moment_inlb is None and not assume_no_load:
        raise DataError(f"{data.source or 'data'}: no hinge moment recorded (a bag without its load topic, a CSV "
                        "without hinge_moment_inlb): the reference needs the load; pass --assume-no-load if "
                        "the actuator ran unloaded")


def watch(data: MeasuredData, reference: Reference, options: Options | None = None) -> Verdict:
    """Watch one record against a reference.

    Parameters
    ----------
    data : MeasuredData
        The record.
    reference : Reference
        The reference model.
    options : Options, optional
        How it is watched.

    Returns
    -------
    Verdict
        The detections (at most one) and the timeline.
    """
    opt = options or Options()
    t = data.time_s - data.time_s[0]
    if t[-1] <= opt.healthy_s + 4 * opt.block_s:
        raise DataError(f"{data.source or 'data'}: {t[-1]:.1f} s of data leaves nothing to watch after the "
                        f"{opt.healthy_s:g} s healthy window")
    cpu0 = time.process_time()
    model = reference.build()
    pred = predict(model, data)
    present = tuple(getattr(data, o) is not None and (o != "current_a" or model.has_current) for o in OUTPUTS)
    h = threshold(opt.false_alarms_per_hour, opt.block_s, opt.k)
    healthy = t < opt.healthy_s
    z: dict[str, FloatArray] = {}
    stats: dict[str, FloatArray] = {}
    sample_sigma = [MIN_SAMPLE_SPREAD_DEG] * len(OUTPUTS)
    block_t = np.zeros(0)
    first: tuple[int, str, Cusum] | None = None
    for j, name in enumerate(OUTPUTS):
        if not present[j]:
            continue
        r = np.asarray(getattr(data, name)) - pred[:, j]
        sample_sigma[j] = max(float(np.std(r[healthy])), MIN_SAMPLE_SPREAD_DEG)
        block_t, means = block_means(t, r, opt.block_s)
        centre, sigma = spread(means[block_t <= opt.healthy_s], MIN_SPREAD_DEG)
        zj = (means - centre) / sigma
        cs = Cusum(h, opt.k)
        s = np.zeros(zj.size)
        fired = False
        for b in np.flatnonzero(block_t > opt.healthy_s).tolist():
            alarm = cs.update(float(zj[b]))
            s[b] = cs.statistic
            if alarm and not fired:
                fired = True
                if first is None or b < first[0]:
                    first = (b, name, Cusum(h, opt.k, cs.up, cs.down, cs.since_up, cs.since_down))
        z[name], stats[name] = zj, s
    cpu = time.process_time() - cpu0
    timeline = Timeline(block_t, z, stats)
    verdict = Verdict(reference, h, opt.healthy_s, [], timeline, float(t[-1] - opt.healthy_s), cpu)
    if first is None:
        return verdict
    i, name, cs = first
    t_det = float(block_t[i])
    onset = max(opt.healthy_s, t_det - (cs.onset_blocks + 1) * opt.block_s)
    verdict.detections.append(_diagnose(data, reference, pred, present, sample_sigma, onset, t_det, name,
                                        cs.statistic, opt, timeline))
    return verdict


def _window(data: MeasuredData, reference: Reference, pred: FloatArray, present: tuple[bool, ...],
            sigma: list[float], onset: float, start: float, end: float) -> Window:
    model = reference.build()
    predict(model, data, until_s=onset)
    t = data.time_s - data.time_s[0]
    sel = (t >= onset) & (t < end)
    return Window(data, model, onset, start, end, pred[sel], tuple(sigma), present)


def _diagnose(data: MeasuredData, reference: Reference, pred: FloatArray, present: tuple[bool, ...],
              sigma: list[float], onset: float, t_det: float, output: str, statistic: float, opt: Options,
              timeline: Timeline) -> Detection:
    t_end = float(data.time_s[-1] - data.time_s[0])
    end = min(t_det + opt.window_s, t_end)
    win = _window(data, reference, pred, present, sigma, onset, onset, end)
    cands = candidates(win.model, data)
    hm = None if data.hinge_moment_inlb is None else data.hinge_moment_inlb[
        ((data.time_s - data.time_s[0]) >= onset) & ((data.time_s - data.time_s[0]) < end)]
    sig = signature(win, hm)
    ranking = isolate(win, cands, sig)
    best = ranking[0]
    chosen: Candidate = next(c for c in cands if c.kind == best.kind)
    est = best
    if chosen.free:
        for k in range(1, opt.estimates + 1):
            stop = min(end + k * opt.window_s / 2.0, t_end)
            if timeline.estimate_t and stop <= timeline.estimate_t[-1]:
                break
            w = _window(data, reference, pred, present, sigma, onset, max(onset, stop - opt.window_s), stop)
            e = fit_candidate(w, chosen)
            timeline.estimate_t.append(stop)
            timeline.estimate.append(e.estimate)
            timeline.estimate_sigma.append(e.uncertainty)
            est = e
            if stop >= t_end:
                break
    return Detection(t_det, output, best.kind, best.parameter, est.estimate, est.uncertainty, statistic, onset,
                     best.nominal, fault_size(best.kind, best.parameter, best.nominal, est.estimate), ranking, sig)
