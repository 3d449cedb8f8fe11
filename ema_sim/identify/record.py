"""The record as identification sees it: noise floors, how the command was logged, stamps, travel, units.

Before anything is fitted, the facts a careful engineer checks first are read off the record, each
with the sentence the report carries:

* each output's **noise floor**, never below its counts' own quantization (``q/√12``), and its
  resolution (:func:`ema_sim.analysis.estimation.noise.output_noise`); the fit weighs each output by it;
  read where the output cannot move (:func:`ema_sim.analysis.estimation.noise.with_rests`), or said to be an
  upper bound; a limit cycle at rest and a floor that grows with the excitation are warned of, not taken
  for noise;
* whether the command was **held** between samples (the contract) or **sampled** from a running
  demand (:mod:`ema_sim.analysis.records.command_hold`); a sampled command is reconstructed between samples
  by linear interpolation (:class:`~ema_sim.identify.problem.Problem`), which is the expected
  response when a logged change happened anywhere in the sample before it was logged;
* the record's **own stamps**: the model is run between them and read at them, jittery, rounded or gapped
  as they are; nothing is straightened or resampled, so no output is read where it was not sampled;
* the **travel**: a record that goes beyond the declared channel's travel is never clipped silently;
  the model's limits are taken from the data (at the output's extreme where the record shows a stop:
  the command beyond it while the output rests there; opened past the data where it shows none), and
  a warning says so. A record in a linear unit kept as logged, or on a stand-in channel, has no
  declared travel to compare with: its limits always come from the data;
* a **sensor's range**: an output logged with no counts that reads exactly its extreme value, again and
  again, is a sensor at its saturation or a clipped log (a continuous reading never repeats by chance; a
  mechanical stop read through a sensor shows its noise): the model's output is clipped there as the
  sensor clips it (:attr:`Record.sensor_range`), and that side is no stop of the travel;
* the **unit**: positions kept in mm or in are named, so no one reads them as degrees.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import NDArray

from ema_sim.analysis.estimation.noise import NoiseFloor
from ema_sim.analysis.pipeline import command_hold, measure_outputs
from ema_sim.analysis.records import stamps as stamp_jitter
from ema_sim.analysis.records.command_hold import CommandHold, HoldMode
from ema_sim.analysis.section2.base import Options
from ema_sim.config import ChannelConfig
from ema_sim.errors import DataError
from ema_sim.io.measured import MeasuredData

MAX_ABS = 1e6
"""No command or output in degrees or millimetres is this large: such a column is not what it is named."""
RADIAN_MATCH = 0.1
"""How close an output's span must come to π/180 (or 180/π) of the command's to be called a unit slip."""
NOISELESS_DEG = 1e-6
"""An output whose white noise is under this is a simulation's, read through no sensor."""
STOP_S = 0.2
"""The command must sit beyond the output's extreme this long, the output resting there, to show a stop."""


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


@dataclass
class Record:
    """A measured record prepared for identification, with what was found and done on the way."""

    data: MeasuredData
    channel: ChannelConfig
    """The channel's configuration, its travel replaced when the data required it."""
    noise: dict[str, NoiseFloor]
    hold: CommandHold
    travel: Travel
    notes: list[str] = field(default_factory=list)
    """What was found and done, one line each (for the report's header)."""
    warnings: list[str] = field(default_factory=list)
    stamp_scatter_s: float = 0.0
    """Rms of the logged stamps about the least-squares line through them (0 for uniform stamps)."""
    sensor_range: dict[str, tuple[float, float]] = field(default_factory=dict)
    """Output → (lower, upper) saturation its log shows (:func:`sensor_range`); the model's output is clipped there."""
    stamps: stamp_jitter.Stamps | None = None
    """The stamps' scatter about a uniform grid (:mod:`ema_sim.analysis.records.stamps`)."""
    generic: bool = False
    """No X-43A channel given or named by the record: a generic actuator, its travel measured from the record."""

    @property
    def unit(self) -> str:
        """Unit of the command and outputs (``deg``, or a linear unit kept as logged)."""
        return self.data.unit

    @property
    def command_sampled(self) -> bool:
        """Whether the fit reconstructs the command between samples (sampled) or holds it."""
        return self.hold.assumed_sampled


def _extent(data: MeasuredData) -> tuple[float, float]:
    values = [data.command_deg, *(data.column(o) for o in data.outputs)]
    return float(min(np.min(v) for v in values)), float(max(np.max(v) for v in values))


def _stop(data: MeasuredData, noise: dict[str, NoiseFloor], side: int) -> float | None:
    """The output's extreme on one side (+1 upper, −1 lower) when the record shows a stop there."""
    name = data.outputs[0]
    y = side * data.column(name)
    u = side * data.command_deg
    nf = noise[name]
    band = max(4.0 * nf.sigma, 2.0 * (nf.resolution or 0.0))
    top = float(np.max(y))
    pinned = (u > top + band) & (y >= top - band)
    dt = float(np.median(np.diff(data.time_s)))
    return side * top if pinned.sum() * dt >= STOP_S else None


def sensor_range(data: MeasuredData, noise: dict[str, NoiseFloor]) -> dict[str, tuple[float, float]]:
    """Each output's saturation, where its log shows one (module docstring); ±inf on a side that shows none.

    A side saturates when the output reads exactly its extreme for at least :data:`STOP_S` in all, on most of
    the samples within the noise of it, and the output is neither logged in counts nor free of noise (a
    simulated output settles on exactly one value with no sensor in the way).

    Parameters
    ----------
    data : MeasuredData
        The record.
    noise : dict
        Each output's noise floor.

    Returns
    -------
    dict
        Output → (lower, upper) saturation; only the outputs that show one.
    """
    dt = float(np.median(np.diff(data.time_s)))
    out: dict[str, tuple[float, float]] = {}
    for name in data.outputs:
        y, nf = data.column(name), noise[name]
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


def _radians(data: MeasuredData) -> list[str]:
    """A warning for each output whose span is the command's in radians (or the command's in degrees in radians).

    An output whose span (5th to 95th percentile, so an overshoot or a spike does not count) is π/180 (or 180/π)
    of the command's, within :data:`RADIAN_MATCH`, was logged in the other unit: no actuator's gain is off by
    that much, and a fit would take it for a gain or a scale error.
    """
    if data.unit != "deg":
        return []

    def span(x: NDArray[np.float64]) -> float:
        lo, hi = np.percentile(x, [5.0, 95.0])
        return float(hi - lo)

    span_u = span(data.command_deg)
    out = []
    for name in data.outputs:
        ratio = span(data.column(name)) / span_u if span_u > 0.0 else 0.0
        for factor, unit in ((math.pi / 180.0, "radians"), (180.0 / math.pi, "degrees, the command in radians")):
            if abs(ratio / factor - 1.0) <= RADIAN_MATCH:
                out.append(f"{name} spans {ratio:.4g} of the command's span, {factor:.4g} within {RADIAN_MATCH:.0%}: "
                           f"it looks logged in {unit}, not as named; fit it in the command's unit")
    return out


def check_identifiable(data: MeasuredData) -> None:
    """One clear error for a record nothing can be identified from (its columns are legal but say nothing).

    Parameters
    ----------
    data : MeasuredData
        The record as read.
    """
    source = data.source or "data"
    for name in ("command_deg", *data.outputs):
        x = data.column(name)
        if float(np.max(np.abs(x))) > MAX_ABS:
            raise DataError(f"{source}: {name} reaches {float(np.max(np.abs(x))):.3g} {data.unit}: no actuator moves "
                            f"beyond ±{MAX_ABS:g}; is the column mapped to the right signal and unit?")
    span = float(np.ptp(data.command_deg))
    if span == 0.0:
        raise DataError(f"{source}: the command never changes ({data.command_deg[0]:g} {data.unit} throughout): "
                        "there is nothing to identify")
    for name in data.outputs:
        if float(np.ptp(data.column(name))) == 0.0:
            raise DataError(f"{source}: {name} never changes while the command spans {span:.4g} {data.unit}: the "
                            "actuator did not move, or the column is not its position")


def travel_limits(data: MeasuredData, channel: ChannelConfig, noise: dict[str, NoiseFloor], *,
                  stand_in: bool, saturation: dict[str, tuple[float, float]] | None = None) -> Travel:
    """The model's travel on this record (see the module docstring).

    Parameters
    ----------
    data : MeasuredData
        The record.
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
    lo, hi = _extent(data)
    unit = "°" if data.unit == "deg" else f" {data.unit}"
    outside = data.unit == "deg" and not stand_in and (lo < declared[0] or hi > declared[1])
    if data.unit == "deg" and not stand_in and not outside:
        return Travel(declared, declared, "declared", f"within {channel.channel}'s travel "
                      f"{declared[0]:g}…{declared[1]:g}°", False)
    span = hi - lo
    saturation = sensor_range(data, noise) if saturation is None else saturation
    clipped = saturation.get(data.outputs[0], (-np.inf, np.inf))
    stops = tuple(None if math.isfinite(clipped[side > 0]) else _stop(data, noise, side) for side in (-1, +1))
    limits = (stops[0] if stops[0] is not None else lo - span, stops[1] if stops[1] is not None else hi + span)
    seen = [f"a stop at {s:.4g}{unit}" for s in stops if s is not None]
    how = (f"limits at {', '.join(seen)} where the command stays beyond the output"
           if seen else "no stop seen: limits opened past the data")
    source = "data, stop seen" if seen else "data"
    if outside:
        text = (f"the record spans {lo:.4g}…{hi:.4g}°, outside {channel.channel}'s declared travel "
                f"{declared[0]:g}…{declared[1]:g}°: travel taken from the data ({how}), not clipped")
    elif data.unit != "deg":
        text = f"positions in {data.unit} as logged: travel taken from the data ({how})"
    else:
        text = f"no channel named: travel taken from the data spanning {lo:.4g}…{hi:.4g}° ({how})"
    return Travel(declared, limits, source, text, outside)


def rest_warnings(name: str, nf: NoiseFloor, unit: str) -> list[str]:
    """What the rests show that is behaviour, not noise: a line at rest, a floor that grows with the excitation.

    Parameters
    ----------
    name : str
        The output.
    nf : NoiseFloor
        Its floor, read at the rests (:func:`ema_sim.analysis.estimation.noise.with_rests`).
    unit : str
        The record's unit.

    Returns
    -------
    list of str
        One warning each.
    """
    r = nf.rests
    if r is None:
        return []
    label = name.removesuffix("_deg")
    out = [r.line.statement(label, unit)] if r.line is not None else []
    return out + ([r.growth.statement(label, unit, r.quiet_floor)] if r.growth is not None else [])


def prepare(data: MeasuredData, channel: ChannelConfig, *, channel_note: str | None = None,
            command: HoldMode = "detect") -> Record:
    """Noise floors, command hold, uniform stamps, travel and unit of one record (module docstring).

    Parameters
    ----------
    data : MeasuredData
        The record as read.
    channel : ChannelConfig
        The declared channel.
    channel_note : str, optional
        Why the channel is a stand-in (none given, none in the metadata); None when it was named.
    command : {"detect", "held", "sampled"}
        How the command was logged: detected from the record, or as the user says.

    Returns
    -------
    Record
        The prepared record, its notes and warnings.
    """
    check_identifiable(data)
    noise = measure_outputs(data)
    hold = command_hold(data, noise, Options(command=command))
    saturation = sensor_range(data, noise)
    travel = travel_limits(data, channel, noise, stand_in=channel_note is not None, saturation=saturation)
    if travel.limits != travel.declared:
        channel = replace(channel, position_min_deg=travel.limits[0], position_max_deg=travel.limits[1])
    notes: list[str] = []
    warnings: list[str] = []
    if channel_note:
        notes.append(channel_note)
    warnings += _radians(data)
    if data.unit != "deg":
        line = (f"positions in {data.unit} as logged (no --crank-arm-in): every *_deg figure of this report is "
                f"in {data.unit}, every rate in {data.unit}/s")
        notes.append(line)
        warnings.append(line)
    for name, nf in noise.items():
        if nf.resolution is not None:
            notes.append(f"{name} logged in counts of {nf.resolution:g}: noise floor {nf.sigma:.3g} "
                         f"({'the counts' if nf.limited_by_resolution else 'white noise'} set it)")
    for name, nf in noise.items():
        notes += nf.findings(name, data.unit)
        warnings += rest_warnings(name, nf, data.unit)
    if hold.sampled is None and hold.source == "detected":
        notes.append(f"command: undecided ({hold.evidence}); ema analyze says the same: held and sampled both "
                     "fitted, each reported, the better taken (below)")
    else:
        notes.append(f"command {hold.statement}")
    if hold.leads:
        warnings.append(hold.leads)
    stamps = stamp_jitter.measure(data.time_s)
    scatter = stamps.scatter_s
    if stamps.jitters:
        rate = stamp_jitter.output_rate(stamps, data.column(data.outputs[0]))
        notes.append(f"{stamps.statement(rate, data.unit)}: fitted on the record's own stamps, nothing straightened "
                     "or resampled")
    notes.append(f"travel: {travel.statement}")
    if travel.outside:
        warnings.append(f"data outside the declared travel: {travel.statement}")
    for name, (lo, hi) in saturation.items():
        y = data.column(name)
        sides = [f"{v:.4g}{'°' if data.unit == 'deg' else ' ' + data.unit} ({int(np.count_nonzero(y == v))} samples)"
                 for v in (lo, hi) if math.isfinite(v)]
        notes.append(f"{name} reads exactly {' and '.join(sides)} again and again, with no noise on them: a sensor's "
                     "saturation or a clipped log, not a mechanical stop (which shows the noise); the model's "
                     f"{name} is clipped there as the sensor clips it")
    return Record(data, channel, noise, hold, travel, notes, warnings, scatter, saturation, stamps,
                  generic=channel_note is not None)
