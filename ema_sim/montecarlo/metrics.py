"""Metrics: the figures a campaign computes for every run, each a named function of one experiment's result.

An experiment gives either a **record** (the model's outputs through a maneuver, one row per instance)
or a **response** (gain and phase against frequency: sine dwells, or a Schroeder multisine read at its
harmonics). Row 0 of every batch is the nominal run (no parameter dispersed); the metrics of the other
rows are the campaign's, and "error against the nominal run" is measured against row 0.

Every metric is computed row by row with a fixed order of operations (compiled loops, or numpy on one
row), so a run's figures do not depend on which other runs share its batch: the same seed gives the
same rows on one machine or a cluster.

==================  ===========  ==============================================================
metric              experiment   columns
==================  ===========  ==============================================================
``bandwidth_3db``   response     ``bandwidth_3db_hz``: where the gain first falls through −3 dB
``phase_90``        response     ``phase_minus_90_hz``: where the phase first falls through −90°
``gain_phase``      response     ``gain_db@F`` and ``phase_deg@F`` at each of ``at_hz``
``loes``            response     ``loes_wn_rad_s``, ``loes_zeta``, ``loes_delay_s``, ``loes_gain``,
                                 ``loes_cost_j``: the LOES fit of section 3.4 (:mod:`ema_sim.analysis.studies.loes`)
``error``           record       ``rms_error_deg``, ``max_error_deg`` against the nominal run
``peak_rate``       record       ``peak_rate_dps``: the largest |rate|
``step``            record       ``overshoot_pct``, ``rise_time_s`` (10-90 %), ``settling_time_s`` (2 %)
                                 of the first command step
``final_error``     record       ``final_error_deg``: output minus command at the last sample
``settled_error``   record       ``error_deg@Adeg``: settled output minus command at each level of a
                                 staircase (mean over its visits; the last quarter of each hold)
``dither``          ail          per wing: ``<wing>.dither`` (1/0), ``.freq_hz``, ``.pp_deg``,
                                 ``.peak_db`` (:mod:`ema_sim.ail.measure`)
==================  ===========  ==============================================================
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numba as nb
import numpy as np
from numpy.typing import NDArray

from ema_sim.analysis.estimation.tf_fit import fit_transfer_function, second_order_coefficients
from ema_sim.errors import ConfigError, UnknownNameError
from ema_sim.jsontypes import JsonObject

FloatArray = NDArray[np.float64]
ComplexArray = NDArray[np.complex128]
STEP_BAND = 0.02
"""Settling band: ±2 % of the step."""


@dataclass(frozen=True)
class RecordData:
    """A record experiment's outputs for a batch (row 0: the nominal run).

    Parameters
    ----------
    time_s : numpy.ndarray
        Sample instants (s), shape ``(k,)``.
    command_deg : numpy.ndarray
        The command in effect at each sample, ``(n, k)``.
    output_deg : numpy.ndarray
        The measured output (position or surface), ``(n, k)``.
    rate_dps : numpy.ndarray
        The rate, ``(n, k)``.
    levels_deg : numpy.ndarray or None
        A staircase's held levels (for ``settled_error``).
    hold_s : float
        A staircase's hold per level.
    """

    time_s: FloatArray
    command_deg: FloatArray
    output_deg: FloatArray
    rate_dps: FloatArray
    levels_deg: FloatArray | None = None
    hold_s: float = 0.0


@dataclass(frozen=True)
class ResponseData:
    """A frequency response for a batch (row 0: the nominal run).

    Parameters
    ----------
    freq_hz : numpy.ndarray
        Frequencies, ascending, ``(f,)``.
    response : numpy.ndarray
        Output over command at each frequency, ``(n, f)`` complex.
    """

    freq_hz: FloatArray
    response: ComplexArray

    @property
    def gain_db(self) -> FloatArray:
        """Gain, dB, ``(n, f)``."""
        return np.asarray(20.0 * np.log10(np.abs(self.response)), dtype=float)

    @property
    def phase_deg(self) -> FloatArray:
        """Phase, deg, unwrapped from the lowest frequency (which is taken within ±180°), ``(n, f)``."""
        return np.asarray(np.degrees(np.unwrap(np.angle(self.response), axis=1)), dtype=float)


@dataclass(frozen=True)
class MetricSpec:
    """One metric a campaign asks for.

    Parameters
    ----------
    name : str
        The metric (:data:`METRICS`).
    experiment : str
        The experiment it reads.
    options : dict
        Its options (``at_hz`` for ``gain_phase``).
    """

    name: str
    experiment: str
    options: Mapping[str, list[float]] = field(default_factory=dict)

    def as_dict(self) -> JsonObject:
        """Plain values (the campaign's YAML form)."""
        return {"metric": self.name, "experiment": self.experiment, **{k: [*v] for k, v in self.options.items()}}


# ---------------------------------------------------------------------------------- compiled row loops
@nb.njit(cache=True)
def _fourier(y: FloatArray, cos_t: FloatArray, sin_t: FloatArray) -> ComplexArray:  # pragma: no cover - compiled
    """Σ y·e^{−jωt} of every row at every frequency of the tables (rows independent, fixed order)."""
    n, k = y.shape
    f = cos_t.shape[0]
    out = np.empty((n, f), dtype=np.complex128)
    for i in range(n):
        for j in range(f):
            re = 0.0
            im = 0.0
            for s in range(k):
                re += y[i, s] * cos_t[j, s]
                im -= y[i, s] * sin_t[j, s]
            out[i, j] = complex(re, im)
    return out


@nb.njit(cache=True)
def _rms_max(d: FloatArray) -> tuple[FloatArray, FloatArray]:  # pragma: no cover - compiled
    """Row-wise rms and largest |value|."""
    n, k = d.shape
    rms = np.empty(n)
    top = np.empty(n)
    for i in range(n):
        acc = 0.0
        m = 0.0
        for s in range(k):
            v = d[i, s]
            acc += v * v
            m = max(m, abs(v))
        rms[i] = math.sqrt(acc / k) if k else math.nan
        top[i] = m
    return rms, top


def fourier_coefficients(y: FloatArray, time_s: FloatArray, freq_hz: FloatArray) -> ComplexArray:
    """Single-frequency Fourier sums ``Σ y(t)·e^{−j2πft}`` of every row (a compiled loop, row by row).

    Parameters
    ----------
    y : numpy.ndarray
        Signals, ``(n, k)``.
    time_s : numpy.ndarray
        Their instants, ``(k,)``.
    freq_hz : numpy.ndarray
        Frequencies, ``(f,)``.

    Returns
    -------
    numpy.ndarray
        ``(n, f)`` complex sums.
    """
    arg = 2.0 * np.pi * np.outer(freq_hz, time_s)
    return np.asarray(_fourier(np.ascontiguousarray(y, dtype=float), np.cos(arg), np.sin(arg)))


# ------------------------------------------------------------------------------------ response metrics
def _crossing(freq_hz: FloatArray, values: FloatArray, level: float) -> float:
    """The first frequency where ``values`` falls through ``level`` (linear in log f); NaN when it never does."""
    below = np.nonzero(values < level)[0]
    if below.size == 0 or below[0] == 0:
        return math.nan
    k = int(below[0])
    f0, f1 = math.log(freq_hz[k - 1]), math.log(freq_hz[k])
    v0, v1 = float(values[k - 1]), float(values[k])
    return math.exp(f0 + (level - v0) * (f1 - f0) / (v1 - v0))


def bandwidth_3db(data: ResponseData) -> dict[str, FloatArray]:
    """The −3 dB bandwidth of every row.

    Parameters
    ----------
    data : ResponseData
        The batch's responses.

    Returns
    -------
    dict
        ``bandwidth_3db_hz``.
    """
    gain = data.gain_db
    return {"bandwidth_3db_hz": np.array([_crossing(data.freq_hz, g, -3.0) for g in gain])}


def phase_90(data: ResponseData) -> dict[str, FloatArray]:
    """The frequency where the phase first passes −90° (the second order's ωn with no delay).

    Parameters
    ----------
    data : ResponseData
        The batch's responses.

    Returns
    -------
    dict
        ``phase_minus_90_hz``.
    """
    phase = data.phase_deg
    return {"phase_minus_90_hz": np.array([_crossing(data.freq_hz, p, -90.0) for p in phase])}


def point_name(value: float) -> str:
    """A frequency or angle as a column suffix (``5``, ``0.5``, ``-40``).

    Parameters
    ----------
    value : float
        The number.

    Returns
    -------
    str
        Its shortest form.
    """
    return f"{value:g}"


def gain_phase(data: ResponseData, at_hz: list[float]) -> dict[str, FloatArray]:
    """Gain and phase at named frequencies (interpolated linearly in log f between measured points).

    Parameters
    ----------
    data : ResponseData
        The batch's responses.
    at_hz : list of float
        The frequencies (within the measured band).

    Returns
    -------
    dict
        ``gain_db@F`` and ``phase_deg@F`` for each F.
    """
    logf = np.log(data.freq_hz)
    gain, phase = data.gain_db, data.phase_deg
    out: dict[str, FloatArray] = {}
    for f in at_hz:
        x = math.log(f)
        out[f"gain_db@{point_name(f)}hz"] = np.array([np.interp(x, logf, g) for g in gain])
        out[f"phase_deg@{point_name(f)}hz"] = np.array([np.interp(x, logf, p) for p in phase])
    return out


def loes(data: ResponseData) -> dict[str, FloatArray]:
    """The LOES of section 3.4 fitted to every row (second order plus delay, :mod:`ema_sim.analysis.estimation.tf_fit`).

    Parameters
    ----------
    data : ResponseData
        The batch's responses.

    Returns
    -------
    dict
        ``loes_wn_rad_s``, ``loes_zeta``, ``loes_delay_s``, ``loes_gain`` (the DC gain ratio K) and
        ``loes_cost_j`` (J over the band).
    """
    keys = ("wn_rad_s", "zeta", "delay_s", "dc_gain_ratio")
    names = ("loes_wn_rad_s", "loes_zeta", "loes_delay_s", "loes_gain")
    out = {n: np.empty(data.response.shape[0]) for n in (*names, "loes_cost_j")}
    for i, h in enumerate(data.response):
        fit = fit_transfer_function(data.freq_hz, h, 0, 2)
        c = second_order_coefficients(fit)
        for key, name in zip(keys, names, strict=True):
            out[name][i] = c[key]
        out["loes_cost_j"][i] = fit.cost
    return out


# -------------------------------------------------------------------------------------- record metrics
def error_vs_nominal(data: RecordData) -> dict[str, FloatArray]:
    """RMS and largest |output − nominal output| of every row (row 0 is the nominal: zeros).

    Parameters
    ----------
    data : RecordData
        The batch's records.

    Returns
    -------
    dict
        ``rms_error_deg`` and ``max_error_deg``.
    """
    rms, top = _rms_max(np.ascontiguousarray(data.output_deg - data.output_deg[0]))
    return {"rms_error_deg": rms, "max_error_deg": top}


def peak_rate(data: RecordData) -> dict[str, FloatArray]:
    """The largest |rate| of every row.

    Parameters
    ----------
    data : RecordData
        The batch's records.

    Returns
    -------
    dict
        ``peak_rate_dps``.
    """
    return {"peak_rate_dps": np.max(np.abs(data.rate_dps), axis=1)}


@nb.njit(cache=True)
def _step_rows(t: FloatArray, u: FloatArray, y: FloatArray, band: float) -> FloatArray:  # noqa: PLR0912 - one compiled loop
    """Overshoot (%), 10-90 % rise and settling time of the first command step of every row (NaN: none)."""
    n, k = u.shape
    out = np.full((n, 3), np.nan)
    for i in range(n):
        k0 = -1
        for s in range(k):
            if abs(u[i, s] - u[i, 0]) > 1e-12:
                k0 = s
                break
        if k0 < 0:
            continue
        target = u[i, k0]
        k1 = k
        for s in range(k0, k):
            if abs(u[i, s] - target) > 1e-12:
                k1 = s
                break
        size = target - u[i, 0]
        top = -np.inf
        r10 = -1
        r90 = -1
        last_out = -1
        for s in range(k0, k1):
            v = (y[i, s] - u[i, 0]) / size
            top = max(top, v)
            if r10 < 0 and v >= 0.1:
                r10 = s
            if r90 < 0 and v >= 0.9:
                r90 = s
            if abs(v - 1.0) > band:
                last_out = s
        out[i, 0] = max(top - 1.0, 0.0) * 100.0
        if r10 >= 0 and r90 >= 0:
            out[i, 1] = t[r90] - t[r10]
        if last_out < 0:
            out[i, 2] = 0.0
        elif last_out + 1 < k1:
            out[i, 2] = t[last_out + 1] - t[k0]
    return out


def step(data: RecordData) -> dict[str, FloatArray]:
    """Overshoot, rise time and settling time of the first command step, measured on the output.

    The step runs from the command's first change to its next one (or the record's end); the output is
    normalised to 0 before and 1 at the new command.

    Parameters
    ----------
    data : RecordData
        The batch's records.

    Returns
    -------
    dict
        ``overshoot_pct``, ``rise_time_s`` (10-90 %) and ``settling_time_s`` (last entry into ±2 %; NaN
        where the output has not settled when the command next changes).
    """
    u = np.ascontiguousarray(np.broadcast_to(data.command_deg, data.output_deg.shape))
    arr = _step_rows(np.ascontiguousarray(data.time_s), u, np.ascontiguousarray(data.output_deg), STEP_BAND)
    return {"overshoot_pct": arr[:, 0], "rise_time_s": arr[:, 1], "settling_time_s": arr[:, 2]}


def final_error(data: RecordData) -> dict[str, FloatArray]:
    """Output minus command at the last sample.

    Parameters
    ----------
    data : RecordData
        The batch's records.

    Returns
    -------
    dict
        ``final_error_deg``.
    """
    return {"final_error_deg": data.output_deg[:, -1] - data.command_deg[:, -1]}


def settled_error(data: RecordData) -> dict[str, FloatArray]:
    """Settled output minus command at each level of a staircase (section 3.1.2.2's error against angle).

    The mean over the last quarter of each hold, averaged over the level's visits.

    Parameters
    ----------
    data : RecordData
        The batch's records (a ``staircase`` maneuver).

    Returns
    -------
    dict
        ``error_deg@A`` for each level A (deg).
    """
    if data.levels_deg is None:
        raise ConfigError("settled_error needs a staircase maneuver")
    t = data.time_s
    err = data.output_deg - data.command_deg
    sums: dict[float, FloatArray] = {}
    counts: dict[float, int] = {}
    for j, level in enumerate(data.levels_deg):
        keep = (t >= (j + 0.75) * data.hold_s) & (t < (j + 1) * data.hold_s)
        if not keep.any():
            continue
        seg = np.array([float(np.mean(row[keep])) for row in err])
        key = float(level)
        sums[key] = sums[key] + seg if key in sums else seg
        counts[key] = counts.get(key, 0) + 1
    return {f"error_deg@{point_name(a)}deg": sums[a] / counts[a] for a in sorted(sums)}


RESPONSE_METRICS: dict[str, Callable[..., dict[str, FloatArray]]] = {
    "bandwidth_3db": bandwidth_3db, "phase_90": phase_90, "gain_phase": gain_phase, "loes": loes,
}
RECORD_METRICS: dict[str, Callable[..., dict[str, FloatArray]]] = {
    "error": error_vs_nominal, "peak_rate": peak_rate, "step": step, "final_error": final_error,
    "settled_error": settled_error,
}
AIL_METRICS = ("dither",)
METRICS: tuple[str, ...] = (*RESPONSE_METRICS, *RECORD_METRICS, *AIL_METRICS)
"""Every metric name a campaign may ask for."""
OPTIONS: dict[str, tuple[str, ...]] = {"gain_phase": ("at_hz",)}
"""The options each metric takes."""


def parse_metric(entry: Any, experiments: Mapping[str, str], where: str) -> MetricSpec:
    """One ``metrics`` entry: a name, or ``{metric: NAME, experiment: E, <options>}``.

    Parameters
    ----------
    entry : str or mapping
        The entry.
    experiments : mapping
        Experiment name → its kind (``record``, ``response``, ``ail``).
    where : str
        The entry's place, for messages.

    Returns
    -------
    MetricSpec
        The checked entry.
    """
    spec: dict[str, Any] = {"metric": entry} if isinstance(entry, str) else dict(entry)
    name = spec.pop("metric", None)
    if not isinstance(name, str) or name not in METRICS:
        raise UnknownNameError("metric", str(name), METRICS)
    wanted = "response" if name in RESPONSE_METRICS else "record" if name in RECORD_METRICS else "ail"
    exp = spec.pop("experiment", None)
    if exp is None:
        fitting = [e for e, kind in experiments.items() if kind == wanted]
        if len(fitting) != 1:
            raise ConfigError(f"{where}: metric {name} needs experiment: one of the campaign's {wanted} experiments")
        exp = fitting[0]
    if exp not in experiments:
        raise UnknownNameError("experiment", str(exp), experiments)
    if experiments[exp] != wanted:
        raise ConfigError(f"{where}: metric {name} reads a {wanted} experiment; {exp!r} is a {experiments[exp]}")
    unknown = sorted(set(spec) - set(OPTIONS.get(name, ())))
    if unknown:
        raise ConfigError(f"{where}: metric {name} has no option {unknown[0]!r}")
    if name == "gain_phase":
        at = spec.get("at_hz")
        values = [at] if isinstance(at, int | float) else at
        if not values or not all(isinstance(v, int | float) and v > 0 for v in values):
            raise ConfigError(f"{where}: gain_phase needs at_hz: a positive frequency or a list of them")
        spec["at_hz"] = [float(v) for v in values]
    return MetricSpec(name, str(exp), spec)


def compute(spec: MetricSpec, data: RecordData | ResponseData) -> dict[str, FloatArray]:
    """The columns of one metric for a batch.

    Parameters
    ----------
    spec : MetricSpec
        The metric.
    data : RecordData or ResponseData
        Its experiment's result.

    Returns
    -------
    dict
        Column → one value per row (row 0: the nominal run).
    """
    if spec.name in RESPONSE_METRICS:
        if not isinstance(data, ResponseData):
            raise ConfigError(f"metric {spec.name} needs a frequency response")
        return RESPONSE_METRICS[spec.name](data, **spec.options)
    if not isinstance(data, RecordData):
        raise ConfigError(f"metric {spec.name} needs a record")
    return RECORD_METRICS[spec.name](data, **spec.options)
