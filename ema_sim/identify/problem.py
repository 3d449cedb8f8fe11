"""A measured record set up for output-error fitting: inputs as breakpoints, outputs, noise weights.

The model is simulated with the *measured* command and hinge moment and compared with the measured
LVDT position and/or surface angle; each output's residual is divided by its own noise floor (never
below the counts' quantization, :func:`ema_sim.analysis.estimation.noise.output_noise`) so outputs with
different sensors weigh the same and a perfect model leaves unit variance.

A held command (the data contract) is the model's input from one sample to the next. A command
the rig *sampled* from a running demand changed anywhere within the sample before it was logged: the
model is then driven by the linear interpolation between the logged samples (on a grid of the
simulator's step, each value taken half a step on so the staircase carries no lag of its own), the
expected input when a change is equally likely anywhere in the interval, and exact for a profile's
constant-speed segments.
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
from numpy.typing import NDArray
from scipy.signal import savgol_filter, welch

from ema_sim.analysis.estimation import slew
from ema_sim.analysis.estimation.noise import NoiseFloor, output_noise
from ema_sim.analysis.estimation.prepared import PreparedRecord
from ema_sim.analysis.estimation.slew import Slew
from ema_sim.config import ChannelConfig
from ema_sim.errors import DataError
from ema_sim.identify.settled import Settled, settled_error
from ema_sim.io.measured import MeasuredData
from ema_sim.models.base import O_POS, O_RATE, O_SURF
from ema_sim.models.second_order import SecondOrder, SecondOrderParams

FloatArray = NDArray[np.float64]
OUTPUT_COLUMN = {"position_deg": O_POS, "surface_deg": O_SURF}
SETTLE_S = 0.3
"""Samples before this (from the start) are not fitted: the record may not start in equilibrium (less when it
visibly does: :func:`start_left_out_s`)."""
AT_REST_SIGMAS = 5.0
"""Before the first command change, outputs within this many noise sigmas of their median are at rest."""
MIN_NOISE_DEG = 1e-3
"""Floor on a noise estimate: no sensor of table A3 is better (laser tracker ±0.0014°), and a
noise-free (simulated) output must not outweigh a measured one a thousandfold."""
IN_LOOP_SHARE = 0.5
"""Share of the surface's error above its floor the position's error must carry to place it inside the loop."""
KEPT_RUNS_BYTES = 96 * 2**20
"""Most memory the simulations kept for reuse may take (about 40 runs of a 30 s record at 1 kHz)."""
EQUIVALENT_EXCESS = 3.0
"""Final rms over the noise floor beyond which the fitted parameters are said to be equivalents."""


class Cancelled(Exception):  # noqa: N818 - a fit stopped, not an error
    """A fit the search no longer needs, stopped at its next simulation (:meth:`Problem.cancel`)."""


@dataclass
class Tally:
    """Simulations asked for by one thread's work, and how many of them were kept runs (:meth:`Problem.tally`)."""

    simulations: int = 0
    reused: int = 0
    token: str = ""
    """What the work is cancelled by (empty: it is not)."""


def start_left_out_s(time_s: FloatArray, command: FloatArray, outputs: Mapping[str, FloatArray],
                     sigma_deg: Mapping[str, float]) -> float:
    """How much of a record's start not to fit: :data:`SETTLE_S`, or less for a short record that starts at rest.

    A record shorter than ten times :data:`SETTLE_S` whose command first changes before :data:`SETTLE_S`, its
    outputs at rest until then (within :data:`AT_REST_SIGMAS` noise sigmas), is fitted from halfway to that
    change: a short record's only step is not left out. A longer record keeps the whole :data:`SETTLE_S` out,
    which costs it little and spares its fit the start of a simulation that need not match the record's
    (measured: fitted from its first change, a 15 s record with a command bias took in a spurious compliance).

    Parameters
    ----------
    time_s : numpy.ndarray
        Sample times from 0, s.
    command : numpy.ndarray
        The command, deg.
    outputs : mapping of str to numpy.ndarray
        Each measured output, deg.
    sigma_deg : mapping of str to float
        Each output's noise, deg.

    Returns
    -------
    float
        The start left out, s.
    """
    changed = np.flatnonzero(np.abs(command - command[0]) > 1e-9 * max(1.0, float(np.max(np.abs(command)))))
    if time_s[-1] > 10.0 * SETTLE_S or changed.size == 0 or time_s[changed[0]] >= SETTLE_S or changed[0] < 10:
        return SETTLE_S
    k = int(changed[0])
    for o, y in outputs.items():
        before = y[:k]
        if np.max(np.abs(before - np.median(before))) > AT_REST_SIGMAS * sigma_deg[o]:
            return SETTLE_S
    return float(time_s[k // 2])


@dataclass
class Problem:
    """Everything the fits need from one record, and the batched simulator that compares against it."""

    data: MeasuredData
    channel: ChannelConfig
    step_s: float = 1e-3
    settle_s: float = SETTLE_S
    noise: dict[str, NoiseFloor] | None = None
    """Each output's noise floor (measured on the record when not given)."""
    command_sampled: bool = False
    """The command was sampled from a running demand, not held (see the module docstring)."""
    output_range: dict[str, tuple[float, float]] = field(default_factory=dict)
    """Output → (lower, upper) saturation of its sensor: every run's output is clipped there as the sensor
    clips it (:func:`ema_sim.analysis.estimation.prepared.sensor_range`)."""
    prepared: PreparedRecord | None = None
    """The record prepared once (:mod:`ema_sim.analysis.estimation.prepared`): its outputs, hinge moment, noise floors
    and slew are taken from it, not read or measured again."""
    outputs: list[str] = field(init=False)
    slew: Slew | None = field(init=False, default=None)
    """The rate-limited moves' slope on the first output, when the record was prepared (measured here when not)."""
    observed: dict[str, FloatArray] = field(init=False)
    """Each output as logged, read once from the record."""
    hinge_moment: FloatArray = field(init=False)
    """The hinge moment, zeros when the record has none."""
    time_s: FloatArray = field(init=False)
    sigma_deg: dict[str, float] = field(init=False)
    simulations: int = field(init=False, default=0)
    """Runs asked for, the search's cost (:attr:`reused` of them were not run again)."""
    dense: bool = field(init=False, default=False)
    """A held command has a breakpoint at every sample (so a signal can be added to it sample by sample)."""
    weights: dict[str, float] = field(init=False, default_factory=dict)
    """Extra weight of an output in the weighted residual (none: every output weighs by its noise floor alone)."""
    projections: dict[str, FloatArray] = field(init=False, default_factory=dict)
    """Per output, an orthonormal basis of terms whose combination is solved for at every evaluation and taken
    out of the weighted residual (variable projection: :meth:`set_output_terms`)."""
    reused: int = field(init=False, default=0)
    """Of :attr:`simulations`, the runs answered from the ones kept instead of run again."""
    timing_s: float = field(init=False, default=0.0)
    """Rms error of the stamps against the instants the outputs were sampled at, when the record shows one
    (:meth:`set_timing`); 0: none."""
    timing_rates: dict[str, FloatArray] = field(init=False, default_factory=dict)
    """Per output, the measured rate at every sample the timing weights were made from (:meth:`set_timing`)."""
    sample_sigma: dict[str, FloatArray] = field(init=False, default_factory=dict)
    """Per output, each fitted sample's floor with the stamps' timing error in it (empty: the noise floor alone)."""
    _kept: OrderedDict[tuple[object, ...], FloatArray] = field(init=False, repr=False, compare=False,
                                                               default_factory=OrderedDict)
    """The latest runs, by what determines them: a fit's Jacobian restarts from the point its residual has just
    run, and each stage restarts from the model the one before ended on."""
    _inputs: int = field(init=False, repr=False, compare=False, default=0)
    """Which inputs the model is driven with (each change of them, one more): part of a kept run's key."""
    _cancelled: set[str] = field(init=False, repr=False, compare=False, default_factory=set)
    """Tokens of the fits cancelled (:meth:`cancel`)."""
    _tally: threading.local = field(init=False, repr=False, compare=False, default_factory=threading.local)
    """This thread's :class:`Tally`, while one is open (:meth:`tally`)."""
    _lock: threading.Lock = field(init=False, repr=False, compare=False, default_factory=threading.Lock)
    """Guards the kept runs and the counts: a round's candidate fits simulate from threads of one process
    (:mod:`ema_sim.identify.parallel`)."""

    def __post_init__(self) -> None:
        d, p = self.data, self.prepared
        if p is not None:
            self.observed, self.hinge_moment, self.slew = dict(p.outputs), p.hinge_moment_inlb, p.slew
            self.noise = p.noise if self.noise is None else self.noise
        else:
            self.observed = {o: d.column(o) for o in d.outputs}
            self.hinge_moment = d.hinge_moment
        self.outputs = list(self.observed)
        if not self.outputs:
            raise DataError(f"{d.source or 'data'}: needs a position_deg or surface_deg column to identify")
        self.time_s = d.time_s - d.time_s[0]
        if self.noise is None:
            self.noise = {o: output_noise(y) for o, y in self.observed.items()}
        self.sigma_deg = {o: max(self.noise[o].sigma, MIN_NOISE_DEG) for o in self.outputs}
        if self.settle_s == SETTLE_S:
            self.settle_s = start_left_out_s(self.time_s, d.command_deg, self.observed,
                                              self.sigma_deg)
        if self.time_s[-1] < 2.0 * self.settle_s:
            raise DataError(f"{d.source or 'data'}: {self.time_s[-1]:.2f} s of data is too short to identify")
        self.mask = self.time_s >= self.settle_s
        self.set_command_sampled(self.command_sampled)

    @property
    def unfitted_start(self) -> str | None:
        """What the start left out of the fit says: over a tenth of the record, the command moving in it (or None)."""
        left_out = self.time_s < self.settle_s
        n = int(np.count_nonzero(left_out))
        cmd = self.data.command_deg[left_out]
        if n <= 0.1 * self.time_s.size or not np.any(cmd != cmd[0]):
            return None
        return (f"the first {self.settle_s:.3g} s ({n} of {self.time_s.size} samples, the command moving in them) "
                "are not fitted: the record may not start at rest")

    def set_command_sampled(self, sampled: bool) -> None:
        """Drive the model with the command held between samples, or interpolated (sampled).

        Parameters
        ----------
        sampled : bool
            True: interpolate the command between samples; False: hold it.
        """
        self.command_sampled = sampled
        with self._lock:  # the model's inputs change: a run still going elsewhere is never kept as one of theirs
            self._kept.clear()
            self._inputs += 1
        cmd = self.data.command_deg
        hm = self.hinge_moment
        if sampled:
            grid = np.arange(0.0, float(self.time_s[-1]), self.step_s)
            mid = np.minimum(grid + 0.5 * self.step_s, self.time_s[-1])
            self._bp_t, self._bp_u, self._bp_h = grid, np.interp(mid, self.time_s, cmd), np.interp(mid, self.time_s, hm)
            return
        keep = np.ones(cmd.size, dtype=bool)
        if not self.dense:
            keep[1:] = (np.diff(cmd) != 0.0) | (np.diff(hm) != 0.0)
        self._bp_t = self.time_s[keep]
        self._bp_u = cmd[keep]
        self._bp_h = hm[keep]

    def set_dense(self, dense: bool) -> None:
        """Give a held command a breakpoint at every sample (True) or only where it changes (False).

        Parameters
        ----------
        dense : bool
            Every sample a breakpoint (the same input, held; a per-sample signal can then be added to it).
        """
        self.dense = dense
        self.set_command_sampled(self.command_sampled)

    def drive_like(self, other: Problem) -> None:
        """Drive the model with another problem's inputs (a decimated copy of a record keeps the record's own).

        Parameters
        ----------
        other : Problem
            The problem whose breakpoints this one's runs take.
        """
        with self._lock:
            self._kept.clear()
            self._inputs += 1
        self._bp_t, self._bp_u, self._bp_h = other.breakpoints

    def on_breakpoints(self, signal: FloatArray) -> FloatArray:
        """A signal given at the record's samples, at the model's input breakpoints (held or interpolated).

        Parameters
        ----------
        signal : numpy.ndarray
            One value per sample of the record.

        Returns
        -------
        numpy.ndarray
            One value per breakpoint.
        """
        if self.command_sampled:
            mid = np.minimum(self._bp_t + 0.5 * self.step_s, self.time_s[-1])
            out: FloatArray = np.interp(mid, self.time_s, signal)
            return out
        idx = np.clip(np.searchsorted(self.time_s, self._bp_t + 1e-12, side="right") - 1, 0, self.time_s.size - 1)
        return np.asarray(signal, dtype=float)[idx]

    def set_timing(self, timing_s: float, rates: Mapping[str, FloatArray]) -> None:
        """Weigh each sample by its noise floor with the stamps' timing error in it: ``√(σ² + (rate·timing)²)``.

        A stamp ``δt`` off the instant its sample was taken at leaves ``rate × δt`` between any model and the
        output (:mod:`ema_sim.analysis.records.stamps`): that share of the error is the logger's, so a sample
        taken while the output moves fast weighs less, and no effect of the actuator pays for absorbing it.

        Parameters
        ----------
        timing_s : float
            The stamps' rms timing error, s (0: every sample weighs by the noise floor alone again).
        rates : mapping
            Output → its measured rate at every sample of the record (unit/s).
        """
        self.timing_s = timing_s
        self.timing_rates = {o: np.asarray(r, dtype=float) for o, r in rates.items()} if timing_s > 0.0 else {}
        self.sample_sigma = {} if timing_s <= 0.0 else {
            o: np.sqrt(self.sigma_deg[o] ** 2 + (timing_s * np.asarray(rates[o])[self.mask]) ** 2)
            for o in self.outputs}

    def scale(self, output: str) -> float | FloatArray:
        """What an output's error is divided by in the weighted residual: its floor (per sample with timing).

        Parameters
        ----------
        output : str
            The output column.
        """
        return self.sample_sigma.get(output, self.sigma_deg[output])

    def set_output_terms(self, terms: dict[str, FloatArray]) -> None:
        """Terms whose best combination is added to each output's model at every evaluation (variable projection).

        Parameters
        ----------
        terms : dict
            Output → columns on the fitted samples (``(fitted, k)``); an empty dict removes them.
        """
        self.projections = {}
        for o, cols in terms.items():
            if cols.size == 0:
                continue
            scale = self.scale(o)
            u, sv, _ = np.linalg.svd(cols / (scale[:, None] if isinstance(scale, np.ndarray) else scale),
                                     full_matrices=False)
            self.projections[o] = u[:, sv > 1e-10 * float(sv[0])]

    @property
    def breakpoints(self) -> tuple[FloatArray, FloatArray, FloatArray]:
        """The model's inputs: breakpoint times (s, from the record's start), command (deg), hinge moment (in·lb).

        Each is held to the next breakpoint (a sampled command is its interpolation: module docstring).
        """
        return self._bp_t, self._bp_u, self._bp_h

    # ---------------------------------------------------------------- facts about the record
    @property
    def n_fit(self) -> int:
        """Number of residual entries a fit sees (samples × outputs)."""
        return int(self.mask.sum()) * len(self.outputs)

    @property
    def sample_hz(self) -> float:
        """Median sample rate."""
        return float(1.0 / np.median(np.diff(self.time_s)))

    @cached_property
    def load_span_inlb(self) -> float:
        """Robust peak-to-peak of the hinge moment (1st to 99th percentile)."""
        hm = self.hinge_moment
        return float(np.percentile(hm, 99) - np.percentile(hm, 1))

    @cached_property
    def load_reverses(self) -> bool:
        """True when the hinge moment takes both signs by more than its noise."""
        hm = self.hinge_moment
        return bool(np.percentile(hm, 99) > 5.0 and np.percentile(hm, 1) < -5.0)

    @cached_property
    def measured_rate_dps(self) -> float:
        """Fastest the measured output moves (99.9th percentile of a smoothed derivative).

        Samples taken out of the fit after its start (a sensor's spike, a stale reading: :mod:`.artefacts`) are
        bridged first: a 10⁴° glitch read as a 10⁵ °/s move started a rate limit beyond its range.
        """
        output = "position_deg" if "position_deg" in self.outputs else "surface_deg"
        y = self.observed[output]
        out = ~self.mask & (self.time_s >= self.settle_s)
        if out.any() and not out.all():
            y = y.copy()
            y[out] = np.interp(self.time_s[out], self.time_s[~out], y[~out])
        window = max(round(0.015 * self.sample_hz) | 1, 5)
        window = min(window, y.size if y.size % 2 else y.size - 1)  # never longer than the record
        rate = savgol_filter(y, window, 2, deriv=1, delta=1.0 / self.sample_hz)
        return float(np.percentile(np.abs(rate), 99.9))

    @cached_property
    def caps(self) -> dict[str, float]:
        """The record's own upper bounds on fitted parameters.

        A dead band no wider than the holds' settled errors show (:attr:`ema_sim.identify.settled.Settled.bound`):
        a threshold the holds support is fitted within that.
        """
        settled = self.settled
        if settled is None:
            return {}
        return {"threshold_deg": settled.bound}

    @cached_property
    def settled(self) -> Settled | None:
        """Where the actuator's output settles at the end of the command's holds (:mod:`ema_sim.identify.settled`)."""
        output = "position_deg" if "position_deg" in self.outputs else "surface_deg"
        count = None if self.noise is None else self.noise[output].resolution
        return settled_error(self.time_s, self.data.command_deg, self.observed[output], count)

    @cached_property
    def measured_slew(self) -> Slew:
        """The record's rate-limited moves' slope (:mod:`ema_sim.analysis.estimation.slew`), on its first output."""
        output = "position_deg" if "position_deg" in self.outputs else "surface_deg"
        if self.slew is not None:
            return self.slew
        return slew.measure(self.time_s, self.data.command_deg, self.observed[output], self.sigma_deg[output])

    @cached_property
    def load_freq_hz(self) -> float:
        """Dominant frequency of the hinge moment (what hysteretic damping's h/ω is evaluated at)."""
        hm = self.hinge_moment - np.mean(self.hinge_moment)
        if not np.any(hm):
            return 0.1
        spec = np.abs(np.fft.rfft(hm * np.hanning(hm.size)))
        freqs = np.fft.rfftfreq(hm.size, 1.0 / self.sample_hz)
        spec[0] = 0.0
        return float(max(freqs[int(np.argmax(spec))], 1.0 / self.time_s[-1]))

    # ---------------------------------------------------------------- simulation
    def simulate(self, params: Sequence[SecondOrderParams], flips: Sequence[bool] | None = None,
                 command_offsets: Sequence[FloatArray] | None = None) -> FloatArray:
        """Outputs ``(n, samples, 3)`` — position, surface, rate — of each parameter set on this record.

        ``flips[i]`` runs instance ``i`` with the hinge moment reversed (the hinge_moment_sign effect).

        Parameters
        ----------
        params : sequence of SecondOrderParams
            One parameter set per instance.
        flips : sequence of bool, optional
            Per instance, run with the hinge moment reversed.
        command_offsets : sequence of numpy.ndarray, optional
            Per instance, a signal added to the command at each breakpoint (a term acting inside the loop).
        """
        tally: Tally | None = getattr(self._tally, "open", None)
        if tally is not None and tally.token and tally.token in self._cancelled:
            raise Cancelled(tally.token)
        n = len(params)
        flips = [False] * n if flips is None else list(flips)
        offsets = None if command_offsets is None else np.asarray(command_offsets, dtype=float).reshape(
            n, self._bp_u.size)
        keys: list[tuple[object, ...]] = [
            (self._inputs, self.step_s, repr(p), bool(f), None if offsets is None else offsets[i].tobytes())
            for i, (p, f) in enumerate(zip(params, flips, strict=True))]
        first: dict[tuple[object, ...], int] = {}
        for i, k in enumerate(keys):
            first.setdefault(k, i)
        out = np.empty((n, self.time_s.size, 3))
        with self._lock:
            todo = []
            for k, i in first.items():
                kept = self._kept.get(k)
                if kept is None:
                    todo.append(i)
                else:
                    self._kept.move_to_end(k)
                    out[i] = kept
        runs = self.saturate(self._run([params[i] for i in todo], [flips[i] for i in todo],
                                       None if offsets is None else offsets[todo])) if todo else out[:0]
        for i, run in zip(todo, runs, strict=True):
            out[i] = run
        for i, k in enumerate(keys):
            if first[k] != i:
                out[i] = out[first[k]]
        with self._lock:
            for i, run in zip(todo, runs, strict=True):
                self._keep(keys[i], run)
            counts = self if tally is None else tally
            counts.simulations += n
            counts.reused += n - len(todo)
        return out

    def saturate(self, runs: FloatArray) -> FloatArray:
        """Runs' outputs as the record's sensors read them: clipped at each one's saturation, in place.

        Parameters
        ----------
        runs : numpy.ndarray
            Outputs ``(..., samples, 3)``: position, surface, rate.

        Returns
        -------
        numpy.ndarray
            ``runs``, clipped.
        """
        for o, (lo, hi) in self.output_range.items():
            col = runs[..., OUTPUT_COLUMN[o]]
            np.clip(col, lo, hi, out=col)
        return runs

    def cancel(self, token: str) -> None:
        """Stop the fit opened with ``token`` (:meth:`tally`) at its next simulation, which raises :class:`Cancelled`.

        Parameters
        ----------
        token : str
            The fit's token.
        """
        with self._lock:
            self._cancelled.add(token)

    @contextmanager
    def tally(self, token: str = "") -> Iterator[Tally]:
        """Count this thread's simulations apart from :attr:`simulations`, for a caller that adds them itself.

        A worker's candidate fit (:func:`~ema_sim.identify.stepwise.remote_candidate`) counts once the search
        takes it, so a fit the search stopped before needing is not counted, whichever thread ran it.

        Parameters
        ----------
        token : str
            What :meth:`cancel` stops this work by (empty: nothing does).

        Yields
        ------
        Tally
            The counts so far.
        """
        outer = getattr(self._tally, "open", None)
        self._tally.open = counts = Tally(token=token)
        try:
            yield counts
        finally:
            self._tally.open = outer

    def __getstate__(self) -> dict[str, object]:
        """Pickled (to a Dask worker) without the kept runs: a worker keeps its own."""
        state = dict(self.__dict__)
        state["_kept"] = OrderedDict()
        del state["_lock"], state["_tally"]
        return state

    def __setstate__(self, state: dict[str, object]) -> None:
        """Unpickled on a worker with a lock of its own."""
        self.__dict__.update(state)
        self._lock = threading.Lock()
        self._tally = threading.local()

    def _run(self, params: Sequence[SecondOrderParams], flips: Sequence[bool],
             offsets: FloatArray | None) -> FloatArray:
        """Simulate each parameter set: each instance's run is its own, whatever else is in the batch."""
        n = len(params)
        sign = np.where(np.asarray(flips, dtype=bool), -1.0, 1.0)[:, None]
        model = SecondOrder(self.channel, params=list(params), step_s=self.step_s)
        h = sign * self._bp_h[None, :]
        u = np.broadcast_to(self._bp_u, (n, self._bp_u.size))
        if offsets is not None:
            u = u + offsets
        model.trim(np.ascontiguousarray(u[:, 0]), h[:, 0])
        out = model.run_outputs(self._bp_t, u, h, sample_times=self.time_s, end_s=float(self.time_s[-1]))
        return out[:, :, [O_POS, O_SURF, O_RATE]]

    def forget_runs(self) -> None:
        """Drop the runs kept for reuse (a benchmark that counts the simulator's work, not a copy of it)."""
        with self._lock:
            self._kept.clear()

    def _keep(self, key: tuple[object, ...], run: FloatArray) -> None:
        """Keep a run for reuse, the least recently used dropped beyond :data:`KEPT_RUNS_BYTES` (runs of one size)."""
        self._kept[key] = run
        while len(self._kept) > max(1, KEPT_RUNS_BYTES // run.nbytes):
            self._kept.popitem(last=False)

    def weighted_residual(self, sim: FloatArray) -> FloatArray:
        """Stacked ``(measured − model)/σ`` over the fitted samples of every output, for one simulation.

        Parameters
        ----------
        sim : numpy.ndarray
            One simulation's outputs (samples × position, surface, rate).
        """
        parts = []
        for o in self.outputs:
            part = (self.observed[o][self.mask] - sim[self.mask, OUTPUT_COLUMN[o]]) / self.scale(o)
            if o in self.weights:
                part = part * self.weights[o]
            basis = self.projections.get(o)
            if basis is not None:
                part = part - basis @ (basis.T @ part)
            parts.append(part)
        return np.concatenate(parts)

    def errors_deg(self, sim: FloatArray) -> dict[str, FloatArray]:
        """Measured − model per output, in degrees, over the fitted samples.

        Parameters
        ----------
        sim : numpy.ndarray
            One simulation's outputs (samples × position, surface, rate).
        """
        return {o: self.observed[o][self.mask] - sim[self.mask, OUTPUT_COLUMN[o]] for o in self.outputs}

    def max_rate_dps(self, sim: FloatArray) -> float:
        """Largest surface rate the model reaches on this record.

        Parameters
        ----------
        sim : numpy.ndarray
            One simulation's outputs (samples × position, surface, rate).
        """
        return float(np.max(np.abs(sim[:, 2])))

    def max_accel_dps2(self, sim: FloatArray) -> float:
        """Largest acceleration the model reaches on this record (its rate's slope between samples).

        Parameters
        ----------
        sim : numpy.ndarray
            One simulation's outputs (samples × position, surface, rate).
        """
        return float(np.max(np.abs(np.diff(sim[:, 2]) / np.diff(self.time_s))))

    def ringing_hz(self, sim: FloatArray) -> float:
        """Where the surface residual's spectrum peaks between 3 Hz and 0.4× the sample rate (0: no clear peak).

        A mode the model lacks leaves a narrow peak there; a broad residual leaves none.

        Parameters
        ----------
        sim : numpy.ndarray
            One simulation's outputs (samples × position, surface, rate).
        """
        if "surface_deg" not in self.outputs:
            return 0.0
        r = self.errors_deg(sim)["surface_deg"]
        fs = self.sample_hz
        nper = int(min(r.size, max(256, 2 ** round(np.log2(fs)))))
        freqs, psd = welch(r - np.mean(r), fs=fs, nperseg=nper)
        band = (freqs >= 3.0) & (freqs <= 0.4 * fs)
        if not np.any(band):
            return 0.0
        k = int(np.argmax(np.where(band, psd, 0.0)))
        return float(freqs[k]) if psd[k] > 5.0 * float(np.median(psd[band])) else 0.0


def in_loop_share(surface: FloatArray, position: FloatArray, sigma_surface: float, sigma_position: float
                   ) -> float | None:
    """Share of the surface's error above its noise that the position's error carries too, sample for sample.

    An error in the actuator's motion moves the surface one for one, so it cancels in ``surface − position``;
    what stays there beyond both noise floors is the surface's own (linkage, compliance outside the loop).
    The same share from a filter of the position's residual would credit any mode the command excites
    in both, so the comparison is at zero lag with unit gain.

    Parameters
    ----------
    surface : numpy.ndarray
        The surface's residual (deg).
    position : numpy.ndarray
        The position's residual on the same samples (deg).
    sigma_surface : float
        The surface's noise floor (deg).
    sigma_position : float
        The position's noise floor (deg).
    """
    excess = float(np.mean(surface**2)) - sigma_surface**2
    if excess <= 0.0:
        return None
    own = float(np.mean((surface - position) ** 2)) - sigma_surface**2 - sigma_position**2
    return min(max(1.0 - own / excess, 0.0), 1.0)
