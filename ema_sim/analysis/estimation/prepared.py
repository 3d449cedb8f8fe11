"""One record prepared once for both tools: its columns read once, the facts both tools start from measured once.

:func:`prepare` reads the record's columns into arrays and measures, on the samples as logged:

* the **channel**: the one asked for, else the one the record's metadata names, else a stand-in
  (:func:`resolve_channel`), with the sentence that says so;
* each output's **noise floor** and **resolution** (:func:`ema_sim.analysis.estimation.noise.output_noise`),
  read where the output cannot move (:func:`ema_sim.analysis.estimation.noise.with_rests`);
* whether the command was **held** between samples or **sampled** from a running demand
  (:mod:`ema_sim.analysis.records.command_hold`);
* the **slew**: the slope of the rate-limited moves on the record's own stamps
  (:func:`ema_sim.analysis.estimation.slew.measure`);
* the **stamps'** scatter about a uniform grid (:mod:`ema_sim.analysis.records.stamps`);
* a **sensor's saturation**: an output logged with no counts that reads exactly its extreme value, again and
  again, is a sensor at its saturation or a clipped log (a continuous reading never repeats by chance; a
  mechanical stop read through a sensor shows its noise) (:func:`sensor_range`);
* the **travel**: a record beyond the declared channel's travel is never clipped silently; the limits come
  from the data (at the output's extreme where the command stays beyond it while the output rests there;
  opened past the data where it shows none), a saturated side being no stop (:func:`travel_limits`);
* the **unit**, and an output logged in radians while named in degrees (:func:`radian_slips`).

A record sampled too slowly or too short to show an actuator move is one error first (:func:`check_sampling`):
stamps logged in another unit than the column says are the usual cause.

The helpers take arrays, not a record to look columns up in. The module lives below ``analysis.pipeline`` and
``ema_sim.identify`` so that both read the same facts and neither reaches into the other's engine.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from ema_sim.analysis.estimation import slew as slew_fit
from ema_sim.analysis.estimation.noise import NoiseFloor, output_noise, with_rests
from ema_sim.analysis.estimation.slew import Slew
from ema_sim.analysis.records import causality
from ema_sim.analysis.records import stamps as stamp_jitter
from ema_sim.analysis.records.command_hold import CommandHold, HoldMode, detect_command_hold, given, lag_band
from ema_sim.config import CHANNELS, STAND_IN, ChannelConfig, load_channel
from ema_sim.errors import DataError
from ema_sim.io.measured import OUTPUTS, MeasuredData

FloatArray = NDArray[np.float64]
Check = Callable[[FloatArray, dict[str, FloatArray]], None]
"""A tool's own test of a record's command and outputs, before anything is measured on them."""
REVERSED_CORRELATION = -0.5
"""An output whose correlation with the command is below this moves opposite to it."""
RADIAN_MATCH = 0.1
"""How close an output's span must come to π/180 (or 180/π) of the command's to be called a unit slip."""
NOISELESS_DEG = 1e-6
"""An output whose white noise is under this is a simulation's, read through no sensor."""
STOP_S = 0.2
"""The command must sit beyond the output's extreme this long, the output resting there, to show a stop."""
MAX_ABS = 1e6
"""No command or output in degrees or millimetres is this large: such a column is not what it is named."""
MIN_SAMPLE_HZ = 5.0
"""Slowest sampling either tool takes: every actuator of the report moves within a fraction of a second, and
identification's simulations cost grows with the span in seconds (a 1 Hz log of 20,000 rows took 7 minutes and
14 GB; ``ema analyze`` failed inside its step fits on a 0.5 Hz log)."""
MIN_SPAN_S = 0.1
"""Shortest record an actuator's move fits in: a step of a 50 rad/s servo takes about this long to settle."""


@dataclass(frozen=True)
class Travel:
    """The travel limits the model is given, and where they come from."""

    declared: tuple[float, float]
    limits: tuple[float, float]
    source: str
    """``declared``, ``data`` or ``data, stop seen``."""
    statement: str
    outside: bool
    """The record goes beyond the declared travel."""


@dataclass(frozen=True)
class PreparedRecord:
    """A record with its columns read once and the facts both tools start from (module docstring)."""

    data: MeasuredData
    time_s: FloatArray
    command_deg: FloatArray
    outputs: dict[str, FloatArray]
    """The outputs present, position first, as logged."""
    hinge_moment_inlb: FloatArray
    """The hinge moment, zeros when the record has none."""
    channel: ChannelConfig
    """The declared channel (its travel as declared)."""
    channel_note: str | None
    """Why the channel is a stand-in (none given, none in the metadata); None when it was named."""
    noise: dict[str, NoiseFloor]
    hold: CommandHold
    slew: Slew
    """The rate-limited moves' slope on the first output, on the record's own stamps."""
    stamps: stamp_jitter.Stamps
    saturation: dict[str, tuple[float, float]]
    """Output → (lower, upper) saturation its log shows (:func:`sensor_range`)."""
    travel: Travel
    radians: list[str]
    """A warning for each output that looks logged in the other angular unit (:func:`radian_slips`)."""
    reversed_outputs: list[str] = field(default_factory=list)
    """A warning for each output that moves opposite to its command (:func:`reversed_outputs`)."""

    @property
    def unit(self) -> str:
        """Unit of the command and outputs (``deg``, or a linear unit kept as logged)."""
        return self.data.unit

    @property
    def first(self) -> str:
        """The first output (position, else surface)."""
        return next(iter(self.outputs))


def resolve_channel(data: MeasuredData, requested: str | None) -> tuple[ChannelConfig, str | None]:
    """The channel configuration to use (crank arm, calibration slopes) and a note on how it was chosen.

    Parameters
    ----------
    data : MeasuredData
        The record (its metadata may name the channel).
    requested : str or None
        The channel asked for (``--channel``).

    Returns
    -------
    tuple
        The configuration, and a note when it is a stand-in.
    """
    meta = data.metadata.get("channel")
    if requested:
        return load_channel(requested), None
    if meta in CHANNELS:
        return load_channel(meta), None
    why = f"metadata channel {meta!r} is not an X-43A channel" if meta else "no X-43A channel in the metadata"
    return load_channel(STAND_IN), (f"{why} and none given: a generic actuator, its travel measured from the "
                                    "record, its fits started from nominal second-order values; no X-43A figure "
                                    "(travel, rated slew, crosstalk threshold) applies, and a logged load would be "
                                    "converted with a nominal crank arm")


def output_floors(time_s: FloatArray, command_deg: FloatArray, outputs: dict[str, FloatArray],
                  current_a: FloatArray | None, counts: float | None) -> dict[str, NoiseFloor]:
    """Each output's noise floor and resolution, on the samples as logged, read at the record's rests.

    Parameters
    ----------
    time_s, command_deg : numpy.ndarray
        The stamps and the command.
    outputs : dict
        Output name → its samples.
    current_a : numpy.ndarray or None
        The motor current, when logged (a rest's evidence).
    counts : float or None
        The outputs' resolution when the record states it.

    Returns
    -------
    dict
        Output name → its :class:`~ema_sim.analysis.estimation.noise.NoiseFloor`.
    """
    return {name: with_rests(output_noise(y, counts), time_s, command_deg, y, current_a) for name, y in outputs.items()}


def command_timing(time_s: FloatArray, command_deg: FloatArray, y: FloatArray, nf: NoiseFloor,
                   command: HoldMode) -> CommandHold:
    """How the command was logged: as the user says (``held``/``sampled``), else detected on the samples as logged.

    Parameters
    ----------
    time_s, command_deg, y : numpy.ndarray
        The stamps, the command and the first output.
    nf : NoiseFloor
        The first output's noise floor.
    command : {"detect", "held", "sampled"}
        What was asked.

    Returns
    -------
    CommandHold
        The finding.
    """
    if command != "detect":
        dt = float(np.median(np.diff(time_s)))
        return given(command, dt, causality.measure(time_s, command_deg, y, lag_band(nf.sigma, nf.resolution)))
    return detect_command_hold(time_s, command_deg, y, nf.sigma, nf.resolution)


def sensor_range(time_s: FloatArray, outputs: dict[str, FloatArray], noise: dict[str, NoiseFloor]
                 ) -> dict[str, tuple[float, float]]:
    """Each output's saturation, where its log shows one (module docstring); ±inf on a side that shows none.

    A side saturates when the output reads exactly its extreme for at least :data:`STOP_S` in all, on most of
    the samples within the noise of it, and the output is neither logged in counts nor free of noise (a
    simulated output settles on exactly one value with no sensor in the way).

    Parameters
    ----------
    time_s : numpy.ndarray
        The stamps.
    outputs : dict
        Output name → its samples.
    noise : dict
        Each output's noise floor.

    Returns
    -------
    dict
        Output → (lower, upper) saturation; only the outputs that show one.
    """
    dt = float(np.median(np.diff(time_s)))
    out: dict[str, tuple[float, float]] = {}
    for name, y in outputs.items():
        nf = noise[name]
        if nf.resolution is not None or nf.white <= NOISELESS_DEG:
            continue
        sides = []
        for extreme in (float(np.min(y)), float(np.max(y))):
            at = int(np.count_nonzero(y == extreme))
            near = int(np.count_nonzero(np.abs(y - extreme) <= 4.0 * nf.sigma))
            sides.append(extreme if at * dt >= STOP_S and at >= 0.5 * near else None)
        if sides[0] is not None or sides[1] is not None:
            out[name] = (-np.inf if sides[0] is None else sides[0], np.inf if sides[1] is None else sides[1])
    return out


def _stop(dt: float, command_deg: FloatArray, y: FloatArray, nf: NoiseFloor, side: int) -> float | None:
    """The output's extreme on one side (+1 upper, −1 lower) when the record shows a stop there."""
    y = side * y
    u = side * command_deg
    band = max(4.0 * nf.sigma, 2.0 * (nf.resolution or 0.0))
    top = float(np.max(y))
    pinned = (u > top + band) & (y >= top - band)
    return side * top if pinned.sum() * dt >= STOP_S else None


def _spikeless(y: FloatArray) -> FloatArray:
    """``y`` through a three-sample median: a single sample's glitch sets no travel, a reading held two does."""
    if y.size < 3:
        return y
    mid = np.median(np.stack([y[:-2], y[1:-1], y[2:]]), axis=0)
    return np.concatenate([[np.median(y[:2])], mid, [np.median(y[-2:])]])


def travel_limits(time_s: FloatArray, command_deg: FloatArray, outputs: dict[str, FloatArray], unit: str,
                  channel: ChannelConfig, noise: dict[str, NoiseFloor], *, stand_in: bool,
                  saturation: dict[str, tuple[float, float]] | None = None) -> Travel:
    """The model's travel on this record (see the module docstring).

    Parameters
    ----------
    time_s, command_deg : numpy.ndarray
        The stamps and the command.
    outputs : dict
        Output name → its samples, the first one read for stops.
    unit : str
        The record's unit (``deg``, or a linear unit kept as logged: no declared travel applies).
    channel : ChannelConfig
        The declared channel (its ``position_min_deg`` / ``position_max_deg``).
    noise : dict
        Each output's noise floor (what "resting at the extreme" means).
    stand_in : bool
        The channel is a stand-in (none given or named by the record): its travel says nothing.
    saturation : dict, optional
        The outputs' :func:`sensor_range`, when already read (None: read here); a saturated side is no stop.

    Returns
    -------
    Travel
        The limits to simulate with and the sentence that says where they come from.
    """
    declared = (channel.position_min_deg, channel.position_max_deg)
    values = [command_deg, *(_spikeless(y) for y in outputs.values())]
    lo, hi = float(min(np.min(v) for v in values)), float(max(np.max(v) for v in values))
    sign = "°" if unit == "deg" else f" {unit}"
    outside = unit == "deg" and not stand_in and (lo < declared[0] or hi > declared[1])
    if unit == "deg" and not stand_in and not outside:
        return Travel(declared, declared, "declared", f"within {channel.channel}'s travel "
                      f"{declared[0]:g}…{declared[1]:g}°", False)
    span = hi - lo
    saturation = sensor_range(time_s, outputs, noise) if saturation is None else saturation
    first = next(iter(outputs))
    clipped = saturation.get(first, (-np.inf, np.inf))
    dt = float(np.median(np.diff(time_s)))
    y, nf = outputs[first], noise[first]
    stops = tuple(None if math.isfinite(clipped[side > 0]) else _stop(dt, command_deg, y, nf, side)
                  for side in (-1, +1))
    limits = (stops[0] if stops[0] is not None else lo - span, stops[1] if stops[1] is not None else hi + span)
    seen = [f"a stop at {s:.4g}{sign}" for s in stops if s is not None]
    how = (f"limits at {', '.join(seen)} where the command stays beyond the output"
           if seen else "no stop seen: limits opened past the data")
    source = "data, stop seen" if seen else "data"
    if outside:
        text = (f"the record spans {lo:.4g}…{hi:.4g}°, outside {channel.channel}'s declared travel "
                f"{declared[0]:g}…{declared[1]:g}°: travel taken from the data ({how}), not clipped")
    elif unit != "deg":
        text = f"positions in {unit} as logged: travel taken from the data ({how})"
    else:
        text = f"no channel named: travel taken from the data spanning {lo:.4g}…{hi:.4g}° ({how})"
    return Travel(declared, limits, source, text, outside)


def radian_slips(command_deg: FloatArray, outputs: dict[str, FloatArray], unit: str) -> list[str]:
    """A warning for each output whose span is the command's in radians (or the command's in degrees in radians).

    An output whose span (5th to 95th percentile, so an overshoot or a spike does not count) is π/180 (or 180/π)
    of the command's, within :data:`RADIAN_MATCH`, was logged in the other unit: no actuator's gain is off by
    that much, and a fit would take it for a gain or a scale error.

    Parameters
    ----------
    command_deg : numpy.ndarray
        The command.
    outputs : dict
        Output name → its samples.
    unit : str
        The record's unit (only ``deg`` records are checked).

    Returns
    -------
    list of str
        One warning per output that looks logged in the other unit.
    """
    if unit != "deg":
        return []

    def span(x: FloatArray) -> float:
        lo, hi = np.percentile(x, [5.0, 95.0])
        return float(hi - lo)

    span_u = span(command_deg)
    out = []
    for name, y in outputs.items():
        ratio = span(y) / span_u if span_u > 0.0 else 0.0
        for factor, other in ((math.pi / 180.0, "radians"), (180.0 / math.pi, "degrees, the command in radians")):
            if abs(ratio / factor - 1.0) <= RADIAN_MATCH:
                out.append(f"{name} spans {ratio:.4g} of the command's span, {factor:.4g} within {RADIAN_MATCH:.0%}: "
                           f"it looks logged in {other}, not as named; fit it in the command's unit")
    return out


def reversed_outputs(command_deg: FloatArray, outputs: dict[str, FloatArray]) -> list[str]:
    """A warning for each output that moves opposite to its command: a sign reversed in the wiring or the log.

    A servo follows its command; an output that mirrors it is a column (or a command) whose sign is reversed,
    which no effect of the vocabulary stands for: a model fitted to it explains it with terms that mean nothing.

    Parameters
    ----------
    command_deg : numpy.ndarray
        The command.
    outputs : dict
        Output name → its samples.

    Returns
    -------
    list of str
        One warning per reversed output.
    """
    out = []
    for name, y in outputs.items():
        if np.ptp(command_deg) <= 0.0 or np.ptp(y) <= 0.0:
            continue
        r = float(np.corrcoef(command_deg, y)[0, 1])
        if r < REVERSED_CORRELATION:
            slope = float(np.polyfit(command_deg, y, 1)[0])
            out.append(f"{name} moves opposite to the command (correlation {r:.2f}, slope {slope:.3g}): a servo "
                       "follows its command, so the column's sign (or the command's) is reversed; negate it before "
                       "fitting, or the fit's terms stand for the reversal, not for the actuator")
    return out


def check_sampling(source: str, time_s: FloatArray) -> None:
    """One clear error for a record sampled too slowly (:data:`MIN_SAMPLE_HZ`) or too short (:data:`MIN_SPAN_S`).

    Whole-number stamps a whole second or more apart are, as a rule, milliseconds logged under ``time_s``: the
    message says how to read them as such. A record a fraction of a millisecond long with thousands of rows is, as
    a rule, microseconds or nanoseconds logged as seconds.

    Parameters
    ----------
    source : str
        Where the record was read from (for the message).
    time_s : numpy.ndarray
        The record's stamps, s.
    """
    where = source or "data"
    interval = float(np.median(np.diff(time_s))) if time_s.size > 1 else 0.0
    span = float(time_s[-1] - time_s[0]) if time_s.size else 0.0
    if interval > 1.0 / MIN_SAMPLE_HZ:
        hint = ""
        if np.all(time_s == np.round(time_s)):
            hint = (f"; whole-number stamps {interval:g} apart look like milliseconds: if they are, read them as "
                    "such (--columns time_ms=<the time column>,...)")
        raise DataError(f"{where}: sampled every {interval:g} s over {span:g} s, slower than the {MIN_SAMPLE_HZ:g} Hz "
                        f"needed to see an actuator move{hint}")
    if span < MIN_SPAN_S:
        raise DataError(f"{where}: {time_s.size} samples over {span:g} s, shorter than the {MIN_SPAN_S:g} s an "
                        "actuator's move takes; are the stamps in another unit than the column says (µs or ns "
                        "logged under time_s)?")


def _check_values(source: str, unit: str, command_deg: FloatArray, outputs: dict[str, FloatArray]) -> None:
    """One clear error for a command or output beyond :data:`MAX_ABS` (in ``unit``), its first row named."""
    for name, x in {"command_deg": command_deg, **outputs}.items():
        beyond = np.flatnonzero(np.abs(x) > MAX_ABS)
        if beyond.size:
            k = int(beyond[0])
            rows = f"data row {k + 1}" + (f" and {beyond.size - 1} more" if beyond.size > 1 else "")
            raise DataError(f"{source or 'data'}: {name} reaches {float(x[k]):.3g} {unit} at {rows}: no actuator "
                            f"moves beyond ±{MAX_ABS:g}; is the column mapped to the right signal and unit?")


def prepare(data: MeasuredData, channel: ChannelConfig, *, channel_note: str | None = None,
            command: HoldMode = "detect", check: Check | None = None) -> PreparedRecord:
    """Read the record's columns once and measure what both tools start from (module docstring).

    Parameters
    ----------
    data : MeasuredData
        The record as read.
    channel : ChannelConfig
        The declared channel (:func:`resolve_channel`).
    channel_note : str, optional
        Why the channel is a stand-in; None when it was named.
    command : {"detect", "held", "sampled"}
        How the command was logged: detected from the record, or as the user says.
    check : callable, optional
        Called with the command and the outputs as read, before anything is measured: a tool's own test that
        the record can serve it (raises :class:`~ema_sim.errors.DataError` when not).

    Returns
    -------
    PreparedRecord
        The columns and the facts.
    """
    time_s = np.asarray(data.time_s, dtype=float)
    check_sampling(data.source, time_s)
    command_deg = np.asarray(data.command_deg, dtype=float)
    columns = {name: getattr(data, name) for name in OUTPUTS}
    outputs = {name: np.asarray(y, dtype=float) for name, y in columns.items() if y is not None}
    if not outputs:
        raise DataError(f"{data.source or 'data'}: needs a position_deg or surface_deg column")
    _check_values(data.source, data.unit, command_deg, outputs)
    if check is not None:
        check(command_deg, outputs)
    given_counts = data.metadata.get("resolution_deg")
    noise = output_floors(time_s, command_deg, outputs, data.current_a, float(given_counts) if given_counts else None)
    first = next(iter(outputs))
    y = outputs[first]
    hold = command_timing(time_s, command_deg, y, noise[first], command)
    slope = slew_fit.measure(time_s - time_s[0], command_deg, y, max(noise[first].sigma, slew_fit.MIN_NOISE))
    saturation = sensor_range(time_s, outputs, noise)
    travel = travel_limits(time_s, command_deg, outputs, data.unit, channel, noise, stand_in=channel_note is not None,
                           saturation=saturation)
    slips = radian_slips(command_deg, outputs, data.unit)
    return PreparedRecord(data, time_s, command_deg, outputs, data.hinge_moment, channel, channel_note, noise, hold,
                          slope, stamp_jitter.measure(time_s), saturation, travel, slips,
                          reversed_outputs(command_deg, outputs))
