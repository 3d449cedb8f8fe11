"""A block of runs: one task of a campaign, every run of it stepped together in one compiled call.

:func:`run_block` is what a Dask worker executes. It rebuilds the campaign from its JSON, draws each
run's parameters from (seed, run index) (:func:`~ema_sim.montecarlo.dispersions.sample`), builds one batch
model whose instance 0 is the nominal run and instance ``1 + j`` run ``start + j``, performs every
experiment, and returns the rows (run index, sampled parameters, metrics) with the envelopes of its
runs. Aircraft-in-the-loop campaigns run the offline loop (:func:`ema_sim.ail.loop.run_ail`) once per run.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import TypeVar

import numba as nb
import numpy as np

from ema_sim.config import load_channel
from ema_sim.errors import ConfigError
from ema_sim.models import ActuatorModel, model_class
from ema_sim.models.high_order.models import HighOrderModel
from ema_sim.montecarlo.campaign import Campaign, Experiment, nominal_values, parse_campaign
from ema_sim.montecarlo.dispersions import FloatArray, run_seed, sample
from ema_sim.montecarlo.metrics import RecordData, ResponseData, compute, fourier_coefficients
from ema_sim.signals import parse_load, parse_maneuver
from ema_sim.signals.loads import Load
from ema_sim.signals.maneuvers import Maneuver, Schroeder, Staircase
from ema_sim.signals.spec import Spec
from ema_sim.simulation import dau_times, frame_inputs


@dataclass
class Envelope:
    """The spread of one signal over runs: lowest, highest and sum at each point, and the nominal run.

    Parameters
    ----------
    x : numpy.ndarray
        Where the signal is given (time, s, or frequency, Hz).
    lo, hi, total : numpy.ndarray
        Lowest, highest and sum over the runs seen.
    count : int
        Runs seen.
    nominal : numpy.ndarray or None
        The nominal run's signal (from the block that ran it).
    x_label, y_label : str
        Axis labels for plots.
    """

    x: FloatArray
    lo: FloatArray
    hi: FloatArray
    total: FloatArray
    count: int
    nominal: FloatArray | None
    x_label: str
    y_label: str

    @classmethod
    def of(cls, x: FloatArray, rows: FloatArray, nominal: FloatArray | None, x_label: str,
           y_label: str) -> Envelope:
        """The envelope of a block's rows.

        Parameters
        ----------
        x : numpy.ndarray
            The axis.
        rows : numpy.ndarray
            One signal per run, ``(runs, len(x))``.
        nominal : numpy.ndarray or None
            The nominal run's signal, when the block ran it.
        x_label, y_label : str
            Axis labels.

        Returns
        -------
        Envelope
            Lowest, highest and sum over the rows.
        """
        return cls(x, rows.min(axis=0), rows.max(axis=0), rows.sum(axis=0), rows.shape[0], nominal, x_label, y_label)

    def merge(self, other: Envelope) -> None:
        """Take in another block's envelope of the same signal.

        Parameters
        ----------
        other : Envelope
            The other block's.
        """
        self.lo = np.minimum(self.lo, other.lo)
        self.hi = np.maximum(self.hi, other.hi)
        self.total = self.total + other.total
        self.count += other.count
        if self.nominal is None:
            self.nominal = other.nominal

    @property
    def mean(self) -> FloatArray:
        """The mean over the runs seen."""
        return self.total / max(self.count, 1)


@dataclass
class Block:
    """What one task returns.

    Parameters
    ----------
    start, stop : int
        Its runs, ``[start, stop)``.
    columns : dict
        ``run``, every dispersed parameter and every metric column, one value per run.
    nominal : dict
        The nominal run's metrics (from the block of run 0; empty elsewhere).
    envelopes : dict
        Signal name → its :class:`Envelope` over the block's runs.
    worker : str
        Address of the worker that ran it.
    seconds : float
        Its wall time on the worker.
    peak_rss_mb : float
        The worker process's peak resident memory after it, MiB.
    """

    start: int
    stop: int
    columns: dict[str, np.ndarray]
    nominal: dict[str, float] = field(default_factory=dict)
    envelopes: dict[str, Envelope] = field(default_factory=dict)
    worker: str = "local"
    seconds: float = 0.0
    peak_rss_mb: float = 0.0


@functools.lru_cache(maxsize=8)
def _campaign(campaign_json: str) -> Campaign:
    raw = json.loads(campaign_json)
    return parse_campaign(raw, str(raw.get("campaign", "<campaign>")))


def _worker_address() -> str:
    try:
        from distributed import get_worker  # noqa: PLC0415 - Dask is needed only when a worker runs the block

        return str(get_worker().address)
    except (ImportError, ValueError):
        return "local"


def run_block(campaign_json: str, seed: int, start: int, stop: int, kernel_threads: int | None = None) -> Block:
    """Runs ``[start, stop)`` of a campaign (what a worker executes).

    Parameters
    ----------
    campaign_json : str
        :meth:`Campaign.to_json`.
    seed : int
        The campaign's seed.
    start, stop : int
        The runs.
    kernel_threads : int, optional
        Threads for the kernels' batches in this call (numba's own count otherwise); the outputs are the same
        bit for bit.

    Returns
    -------
    Block
        Their rows and envelopes.
    """
    t0 = time.perf_counter()
    if kernel_threads is not None:  # numba's setting is the calling thread's: this task's
        nb.set_num_threads(kernel_threads)
    c = _campaign(campaign_json)
    runs = list(range(start, stop))
    values = sample(c.dispersions, seed, runs)
    columns: dict[str, np.ndarray] = {"run": np.arange(start, stop, dtype=np.int64), **values}
    if c.kind == "ail":

        from ema_sim.montecarlo.ail import ail_runs  # noqa: PLC0415 - the loop and its bag I/O only for kind: ail

        metrics, nominal = ail_runs(c, seed, runs, values, with_nominal=start == 0)
        envelopes: dict[str, Envelope] = {}
    else:
        metrics, nominal, envelopes = _model_runs(c, seed, runs, values, with_nominal=start == 0)
    columns.update(metrics)
    return Block(start, stop, columns, nominal, envelopes, _worker_address(), time.perf_counter() - t0, peak_rss_mb())


def peak_rss_mb() -> float:
    """This process's peak resident memory so far, MiB (Linux reports KiB).

    Returns
    -------
    float
        MiB.
    """
    import resource  # noqa: PLC0415 - POSIX only: the rest of the module runs anywhere

    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


# ------------------------------------------------------------------------------------------ model runs
_S = TypeVar("_S", bound=Spec)
def _with_nominal(c: Campaign, values: Mapping[str, FloatArray]) -> dict[str, FloatArray]:
    """Each parameter's values with the nominal first (row 0 of every batch)."""
    nom = nominal_values(c)
    return {k: np.concatenate([[nom[k]], v]) for k, v in values.items()}


def build_model(c: Campaign, seed: int, row_runs: Sequence[int], rows: Mapping[str, FloatArray],
                repeat: int = 1) -> ActuatorModel:
    """The batch model: one row per run (``-1``: the nominal run), each row repeated ``repeat`` times.

    Parameters
    ----------
    c : Campaign
        The campaign.
    seed : int
        Its seed (each run's noise streams come from (seed, run)).
    row_runs : sequence of int
        The run of each row (−1 for the nominal run).
    rows : mapping
        Parameter → one value per row.
    repeat : int
        Instances per row (one per dwell frequency).

    Returns
    -------
    ActuatorModel
        The model, ``len(row_runs)·repeat`` instances.
    """
    cls = model_class(c.model)
    ch = load_channel(c.channel)
    n_rows = len(row_runs)
    own = [n for n in rows if n in {p.name for p in cls.parameters()}]
    kwargs: dict[str, object] = dict(c.options)
    make: Callable[..., ActuatorModel] = cls  # a class picked by name: its keywords are its own
    if cls.one_system:
        if own or "bound" in rows:
            raise ConfigError(f"{c.model} is one linear system for every instance: disperse a time-domain model")
        return make(ch, n=n_rows * repeat, **kwargs, **c.fixed)
    base = cls.default_params(ch, **c.fixed)
    params = [base if not own else base.replace(**{n: float(rows[n][i]) for n in own}) for i in range(n_rows)]
    kwargs["params"] = [p for p in params for _ in range(repeat)]
    if "bound" in rows:
        kwargs["bound"] = [float(b) for b in rows["bound"] for _ in range(repeat)]
    if issubclass(cls, HighOrderModel):
        kwargs["seed"] = [run_seed(seed, r) for r in row_runs for _ in range(repeat)]
    return make(ch, n=n_rows * repeat, **kwargs)


def _spec_rows(exp: Experiment, rows: Mapping[str, FloatArray], n_rows: int) -> tuple[list[Maneuver], list[Load]]:
    """The maneuver and load of every row (the experiment's, with its dispersed fields replaced)."""
    man, load = parse_maneuver(exp.maneuver), parse_load(exp.load)
    mk = {k.rsplit(".", 1)[1]: v for k, v in rows.items() if k.startswith(f"{exp.name}.maneuver.")}
    lk = {k.rsplit(".", 1)[1]: v for k, v in rows.items() if k.startswith(f"{exp.name}.load.")}

    def row(spec: _S, changed: Mapping[str, FloatArray], i: int) -> _S:
        if not changed:
            return spec
        kinds = {f.name: type(getattr(spec, f.name)) for f in dataclasses.fields(spec)}
        return dataclasses.replace(spec, **{k: kinds[k](v[i]) for k, v in changed.items()})

    return [row(man, mk, i) for i in range(n_rows)], [row(load, lk, i) for i in range(n_rows)]


def _inputs(exp: Experiment, rows: Mapping[str, FloatArray], n_rows: int
            ) -> tuple[FloatArray, FloatArray, FloatArray, float, Maneuver]:
    """Frame times, command and load of every row (shared rows when nothing of them is dispersed)."""
    mans, loads = _spec_rows(exp, rows, n_rows)
    duration = exp.duration_s if exp.duration_s is not None else max(max(m.duration_s, ld.duration_s)
                                                                      for m, ld in zip(mans, loads, strict=True))
    if all(m is mans[0] for m in mans) and all(ld is loads[0] for ld in loads):
        inp = frame_inputs(mans[0], loads[0], duration_s=duration, frame_hz=exp.frame_hz)
        return inp.time_s, inp.command_deg, inp.hinge_moment_inlb, duration, mans[0]
    each = [frame_inputs(m, ld, duration_s=duration, frame_hz=exp.frame_hz) for m, ld in zip(mans, loads, strict=True)]
    return (each[0].time_s, np.stack([e.command_deg for e in each]), np.stack([e.hinge_moment_inlb for e in each]),
            duration, mans[0])


def _first(a: FloatArray) -> FloatArray:
    return a[:, 0] if a.ndim == 2 else np.asarray(a[0])


def _record(c: Campaign, exp: Experiment, seed: int, runs: Sequence[int], rows: Mapping[str, FloatArray]
            ) -> tuple[RecordData, ActuatorModel]:
    """A record experiment of every row."""
    model = build_model(c, seed, [-1, *runs], rows)
    t, cmd, hm, duration, man = _inputs(exp, rows, model.n)
    model.trim(_first(cmd), _first(hm))
    rec = model.run(t, cmd, hm, sample_times=dau_times(duration, exp.sample_hz), end_s=duration)
    stair = man if isinstance(man, Staircase) else None
    return RecordData(rec.time_s, rec.command_deg, getattr(rec, exp.output), rec.rate_dps,
                      np.asarray(stair.levels_deg, dtype=float) if stair else None,
                      float(stair.hold_s) if stair else 0.0), model


def _multisine(c: Campaign, exp: Experiment, seed: int, runs: Sequence[int], rows: Mapping[str, FloatArray]
               ) -> ResponseData:
    """A Schroeder multisine of every row, read at its harmonics over its last period (hold divided out)."""
    from ema_sim.analysis.estimation.frf import zoh_factor  # noqa: PLC0415 - scipy.signal only for responses
    model = build_model(c, seed, [-1, *runs], rows)
    t, cmd, hm, duration, man = _inputs(exp, rows, model.n)
    if not isinstance(man, Schroeder):  # parse_experiment admits no other
        raise ConfigError(f"{exp.name}: a multisine experiment takes a schroeder maneuver, not {man.kind!r}")
    model.trim(_first(cmd), _first(hm))
    start = man.lead_s + (man.periods - 1) * man.period_s
    keep = (t >= start - 1e-9) & (t < start + man.period_s - 1e-9)
    samples = t[keep]
    rec = model.run(t, cmd, hm, sample_times=samples, end_s=duration)
    freq = np.asarray(man.frequencies_hz, dtype=float)
    u = np.broadcast_to(cmd, (model.n, t.size))[:, keep]
    y = getattr(rec, exp.output)
    h = fourier_coefficients(y, samples, freq) / fourier_coefficients(u, samples, freq)
    return ResponseData(freq, h / zoh_factor(freq, exp.frame_hz)[None, :])


def _dwell(c: Campaign, exp: Experiment, seed: int, runs: Sequence[int], rows: Mapping[str, FloatArray],
           with_nominal: bool) -> ResponseData:
    """Sine dwells of every row: one batch run per row, one instance per frequency (NaN: the nominal not run)."""
    from ema_sim.analysis.section2.sine_dwell import sine_dwell  # noqa: PLC0415 - scipy.signal only for responses
    freq = np.asarray(exp.freq_hz)
    loads = rows.get(f"{exp.name}.load_inlb")
    row_runs = [-1, *runs]
    out = np.full((len(row_runs), freq.size), np.nan, dtype=complex)
    for i in range(0 if with_nominal else 1, len(row_runs)):
        model = build_model(c, seed, [row_runs[i]], {k: v[i:i + 1] for k, v in rows.items()}, repeat=freq.size)
        load = exp.load_inlb if loads is None else float(loads[i])
        out[i] = sine_dwell(model, freq, exp.amp_deg, hinge_moment_inlb=load, output=exp.output).complex
    return ResponseData(freq, out)


def _model_runs(c: Campaign, seed: int, runs: Sequence[int], values: Mapping[str, FloatArray], *,
                with_nominal: bool) -> tuple[dict[str, np.ndarray], dict[str, float], dict[str, Envelope]]:
    """Every experiment and metric of a model campaign for one block."""
    rows = _with_nominal(c, values)
    metrics: dict[str, np.ndarray] = {}
    nominal: dict[str, float] = {}
    envelopes: dict[str, Envelope] = {}
    for exp in c.experiments:
        wanted = [m for m in c.metrics if m.experiment == exp.name]
        if exp.kind == "record":
            data, _ = _record(c, exp, seed, runs, rows)
            out = data.output_deg
            envelopes[f"{exp.name}.{exp.output}"] = Envelope.of(
                data.time_s, out[1:], out[0] if with_nominal else None, "time, s", exp.output.replace("_", ", "))
            result: RecordData | ResponseData = data
        else:
            resp = (_multisine(c, exp, seed, runs, rows) if exp.kind == "multisine"
                    else _dwell(c, exp, seed, runs, rows, with_nominal))
            gain, phase = resp.gain_db, resp.phase_deg
            envelopes[f"{exp.name}.gain_db"] = Envelope.of(resp.freq_hz, gain[1:], gain[0] if with_nominal else None,
                                                           "frequency, Hz", "gain, dB")
            envelopes[f"{exp.name}.phase_deg"] = Envelope.of(resp.freq_hz, phase[1:],
                                                             phase[0] if with_nominal else None,
                                                             "frequency, Hz", "phase, deg")
            result = resp
        for m in wanted:
            if exp.kind == "dwell" and not with_nominal:
                res = compute(m, ResponseData(result.freq_hz, result.response[1:]))  # type: ignore[union-attr]
                cols = {k: np.concatenate([[math.nan], v]) for k, v in res.items()}
            else:
                cols = compute(m, result)
            for name, col in cols.items():
                key = name if len(c.experiments) == 1 else f"{exp.name}.{name}"
                metrics[key] = np.asarray(col[1:], dtype=float)
                if with_nominal:
                    nominal[key] = float(col[0])
    return metrics, nominal, envelopes
