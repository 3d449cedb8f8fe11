"""The monitor frame by frame, for a node beside a running actuator: the same objects as the offline pass.

:class:`OnlineMonitor` steps the reference one frame at a time on the frame's command and load, forms the
residual of the reported position (and surface, when it comes), averages it over blocks, calibrates the
centre and spread on the first ``healthy_s`` seconds, then runs a :class:`~ema_sim.monitor.detect.Cusum` per
output. It keeps the last seconds of inputs and outputs and a copy of the reference every block, so that
``window_s`` after an alarm it isolates and re-estimates on them exactly as :func:`ema_sim.monitor.watch`
does (:mod:`ema_sim.monitor.isolate`).

After a detection it re-baselines and goes on watching: the reference adopts the re-estimated parameter
(run on from the onset with it, so its state is the faulty actuator's), an LVDT fault becomes a correction
of the reading, a reversed load a flip of the load the reference is given, and the CUSUMs restart at zero
(the healthy window's centre and spread kept). A second fault is then a departure from the first one's model.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, replace

import numpy as np

from ema_sim.io.measured import MeasuredData
from ema_sim.models import ActuatorModel
from ema_sim.models.base import O_CUR, O_POS, O_SURF
from ema_sim.monitor.detect import Cusum, spread, threshold
from ema_sim.monitor.isolate import OUTPUT_KINDS, Candidate, Window, candidates, isolate, jam_values, signature
from ema_sim.monitor.reference import Reference, continue_run, snapshot
from ema_sim.monitor.watch import MIN_SAMPLE_SPREAD_DEG, MIN_SPREAD_DEG, OUTPUTS, Detection, Options, fault_size


@dataclass
class _Frame:
    t: float
    command_deg: float
    hinge_moment_inlb: float
    position_deg: float
    surface_deg: float
    current_a: float
    predicted: tuple[float, float, float]


class OnlineMonitor:
    """One channel watched frame by frame.

    Parameters
    ----------
    reference : Reference
        The reference model.
    options : Options, optional
        How it is watched (the offline pass's).
    frame_s : float
        The frame (s).
    """

    def __init__(self, reference: Reference, options: Options | None = None, frame_s: float = 0.005) -> None:
        self.reference = reference
        self.options = opt = options or Options()
        self.frame_s = frame_s
        self.model: ActuatorModel = reference.build()
        self.h = threshold(opt.false_alarms_per_hour, opt.block_s, opt.k)
        self.per_block = max(1, round(opt.block_s / frame_s))
        keep = math.ceil((3.0 * opt.window_s) / frame_s)
        self.frames: deque[_Frame] = deque(maxlen=keep)
        self.snapshots: deque[tuple[float, ActuatorModel]] = deque(maxlen=int(3.0 * opt.window_s / opt.block_s) + 2)
        self.t = 0.0
        n = len(OUTPUTS)
        self._sum = np.zeros(n)
        self._seen = np.zeros(n, dtype=bool)
        self._n = 0
        self._healthy: list[list[float]] = [[] for _ in OUTPUTS]
        self._sq: list[list[float]] = [[] for _ in OUTPUTS]
        self.centre = np.zeros(n)
        self.spread = np.ones(n)
        self.sample_sigma = [MIN_SAMPLE_SPREAD_DEG] * n
        self.cusums = [Cusum(self.h, opt.k) for _ in OUTPUTS]
        self.alarm: tuple[float, str, float, float] | None = None
        """(time, output, statistic, onset) of the alarm being isolated."""
        self.detections: list[Detection] = []
        """Every detection, in order (each re-baselined on)."""
        self.since_s = opt.healthy_s
        """Where watching (re)started: no onset is placed before it."""
        self.readings: list[tuple[str, float, float]] = []
        """LVDT faults adopted: (kind, estimate, onset), undone from each reading in order."""
        self.flip_load = False
        """A reversed load adopted: the reference is given the opposite load."""
        self.started = False

    @property
    def detection(self) -> Detection | None:
        """The last detection (None before the first)."""
        return self.detections[-1] if self.detections else None

    @property
    def calibrated(self) -> bool:
        """The healthy window is over: the tests run."""
        return self.t > self.options.healthy_s

    @property
    def statistic(self) -> float:
        """The larger CUSUM statistic of the outputs."""
        return max(c.statistic for c in self.cusums)

    def step(self, command_deg: float, hinge_moment_inlb: float, position_deg: float,
             surface_deg: float = math.nan, current_a: float = math.nan) -> Detection | None:
        """One frame: the frame's held command and load, the outputs read at its end (NaN: not measured).

        Returns
        -------
        Detection or None
            The detection, the frame it is complete (``window_s`` after the alarm).
        """
        if not self.started:
            self.model.trim(command_deg, hinge_moment_inlb)
            self.started = True
        if self.flip_load:
            hinge_moment_inlb = -hinge_moment_inlb
        position_deg = self._corrected(position_deg, self.t + self.frame_s)
        if self._n == 0:
            self.snapshots.append((self.t, snapshot(self.model)))
        v = self.model.step_values(command_deg, hinge_moment_inlb, self.frame_s)
        self.t += self.frame_s
        pred = (v[O_POS], v[O_SURF], v[O_CUR])
        if not self.model.has_current:
            current_a = math.nan
        self.frames.append(_Frame(self.t, command_deg, hinge_moment_inlb, position_deg, surface_deg, current_a, pred))
        meas = (position_deg, surface_deg, current_a)
        for j in range(len(OUTPUTS)):
            if math.isfinite(meas[j]):
                self._sum[j] += meas[j] - pred[j]
                self._seen[j] = True
                if not self.calibrated:
                    self._sq[j].append(meas[j] - pred[j])
        self._n += 1
        if self._n >= self.per_block:
            self._block()
        if self.alarm is not None and self.t >= self.alarm[0] + self.options.window_s:
            detection, win, cands = self._diagnose()
            self.detections.append(detection)
            self._rebaseline(detection, win, cands)
            return detection
        return None

    def _corrected(self, position_deg: float, t: float) -> float:
        """A reading with the adopted LVDT faults undone (bias, drift, scale as fitted, in order)."""
        for kind, p, onset in self.readings:
            if kind == "lvdt_bias":
                position_deg -= p
            elif kind == "lvdt_drift":
                position_deg -= p * (t - onset)
            elif 1.0 + p != 0.0:
                position_deg /= 1.0 + p
        return position_deg

    def _rebaseline(self, d: Detection, win: Window, cands: list[Candidate]) -> None:
        """Adopt the detection's fault into the reference and watch on from here (module docstring)."""
        if d.kind in OUTPUT_KINDS:
            self.readings.append((d.kind, d.estimate, win.onset_s))  # the drift's fit is from there
        else:
            cand = next(c for c in cands if c.kind == d.kind)
            values = jam_values(win) if d.kind == "jam" else {} if d.kind == "hm_sign" else cand.values(d.estimate)
            model = snapshot(win.model)
            if values:
                model.retune(**values)
            continue_run(model, win.data, win.onset_s, self.t, flip_load=d.kind == "hm_sign")
            self.model = model
            if d.kind == "hm_sign":
                self.flip_load = not self.flip_load
            self.reference = replace(self.reference, overrides={**self.reference.overrides, **values},
                                     origin=f"{self.reference.origin}; {d.kind} adopted at {self.t:.3f} s")
        self.alarm = None
        self.since_s = self.t
        self.snapshots.clear()
        self.cusums = [Cusum(self.h, self.options.k, history=[0.0]) for _ in OUTPUTS]

    def _block(self) -> None:
        means = self._sum / self._n
        self._sum[:] = 0.0
        self._n = 0
        if not self.calibrated:
            for j in range(len(OUTPUTS)):
                if self._seen[j]:
                    self._healthy[j].append(float(means[j]))
            return
        if not any(self._healthy):
            return
        if all(c.history == [] for c in self.cusums):
            for j in range(len(OUTPUTS)):
                if self._healthy[j]:
                    self.centre[j], self.spread[j] = spread(np.array(self._healthy[j]), MIN_SPREAD_DEG)
                    self.sample_sigma[j] = max(float(np.std(self._sq[j])), MIN_SAMPLE_SPREAD_DEG)
                self.cusums[j].history.append(0.0)
        for j in range(len(OUTPUTS)):
            if not self._seen[j] or not self._healthy[j]:
                continue
            cs = self.cusums[j]
            if cs.update(float((means[j] - self.centre[j]) / self.spread[j])) and self.alarm is None:
                onset = max(self.since_s, self.t - (cs.onset_blocks + 1) * self.options.block_s)
                self.alarm = (self.t, OUTPUTS[j], cs.statistic, onset)

    def _diagnose(self) -> tuple[Detection, Window, list[Candidate]]:
        if self.alarm is None:
            raise RuntimeError("a diagnosis needs an alarm")
        t_det, output, stat, onset = self.alarm
        first_t = self.frames[0].t
        snap_t, snap = next(((t, m) for t, m in reversed(self.snapshots) if first_t <= t <= onset),
                            next((t, m) for t, m in self.snapshots if t >= first_t))
        frames = [f for f in self.frames if f.t >= snap_t]
        # a sample at each frame's end holds the next frame's command and load (the held inputs from then on);
        # a leading sample at 0 keeps the record's clock absolute, the reference copy's own
        ahead, now = frames[1:], frames[:-1]
        times = np.array([0.0] + [f.t for f in now])
        cmd = np.array([ahead[0].command_deg] + [f.command_deg for f in ahead])
        hm = np.array([ahead[0].hinge_moment_inlb] + [f.hinge_moment_inlb for f in ahead])
        pos = np.array([now[0].position_deg] + [f.position_deg for f in now])
        surf = np.array([now[0].surface_deg] + [f.surface_deg for f in now])
        cur = np.array([now[0].current_a] + [f.current_a for f in now])
        data = MeasuredData(times, cmd, pos if np.all(np.isfinite(pos)) else None,
                            surf if np.all(np.isfinite(surf)) else None, hm,
                            current_a=cur if np.all(np.isfinite(cur)) else None, source="online")
        nominal = np.array([f.predicted for f in now])
        win = Window(data, snapshot(snap), snap_t, max(snap_t, onset), now[-1].t + 0.5 * self.frame_s, nominal,
                     tuple(self.sample_sigma),
                     (data.position_deg is not None, data.surface_deg is not None, data.current_a is not None))
        cands = candidates(win.model, data)
        sig = signature(win, hm[1:])
        ranking = isolate(win, cands, sig)
        best = ranking[0]
        return Detection(t_det, output, best.kind, best.parameter, best.estimate, best.uncertainty, stat, onset,
                         best.nominal, fault_size(best.kind, best.parameter, best.nominal, best.estimate), ranking,
                         sig), win, cands
