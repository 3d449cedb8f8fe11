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
from functools import partial

import numpy as np

from ema_sim.analysis.estimation import prepared as shared
from ema_sim.analysis.estimation.noise import NoiseFloor
from ema_sim.analysis.estimation.prepared import FloatArray, PreparedRecord, Travel, sensor_range, travel_limits
from ema_sim.analysis.records import stamps as stamp_jitter
from ema_sim.analysis.records.command_hold import CommandHold, HoldMode
from ema_sim.config import ChannelConfig
from ema_sim.errors import DataError
from ema_sim.io.measured import MeasuredData

__all__ = ["Record", "Travel", "check_identifiable", "prepare", "rest_warnings", "sensor_range",
           "travel_limits"]


@dataclass
class Record:
    """A measured record prepared for identification, with what was found and done on the way.

    Its facts are those of :attr:`prepared`, measured once there, held here as plain fields so that every stage
    reads them without a call back into this module.
    """

    prepared: PreparedRecord
    """The record's columns and the facts measured once on them (:mod:`ema_sim.analysis.estimation.prepared`)."""
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
    """Output → (lower, upper) saturation its log shows; the model's output is clipped there."""
    stamps: stamp_jitter.Stamps | None = None
    """The stamps' scatter about a uniform grid (:mod:`ema_sim.analysis.records.stamps`)."""
    generic: bool = False
    """No X-43A channel given or named by the record: a generic actuator, its travel measured from the record."""
    unit: str = "deg"
    """Unit of the command and outputs (``deg``, or a linear unit kept as logged)."""
    command_sampled: bool = False
    """Whether the fit reconstructs the command between samples (sampled) or holds it."""


def check_identifiable(source: str, unit: str, command_deg: FloatArray, outputs: dict[str, FloatArray]) -> None:
    """One clear error for a record nothing can be identified from (its columns are legal but say nothing).

    Parameters
    ----------
    source : str
        Where the record was read from (for the message).
    unit : str
        The record's unit.
    command_deg : numpy.ndarray
        The command.
    outputs : dict
        Output name → its samples.
    """
    source = source or "data"
    span = float(np.ptp(command_deg))
    if span == 0.0:
        raise DataError(f"{source}: the command never changes ({command_deg[0]:g} {unit} throughout): "
                        "there is nothing to identify")
    for name, y in outputs.items():
        if float(np.ptp(y)) == 0.0:
            raise DataError(f"{source}: {name} never changes while the command spans {span:.4g} {unit}: the "
                            "actuator did not move, or the column is not its position")


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
    check = partial(check_identifiable, data.source, data.unit)
    return identification_record(shared.prepare(data, channel, channel_note=channel_note, command=command, check=check))


def _stamps_notes(stamps: stamp_jitter.Stamps, y: FloatArray, unit: str) -> list[str]:
    """The stamps' gaps (a pause of the logger, first: also a warning) and jitter, each a note."""
    out = []
    if stamps.gaps:
        out.append(f"{stamp_jitter.gap_statement(stamps.gaps, stamps.interval_s)}: a pause of the logger, not "
                   "jitter; the model runs through it on the command last logged before it (held), so an output "
                   "that moved in it is error after it")
    if stamps.jitters:
        out.append(f"{stamps.statement(stamp_jitter.output_rate(stamps, y), unit)}: fitted on the record's own "
                   "stamps, nothing straightened or resampled")
    return out


def identification_record(p: PreparedRecord) -> Record:
    """The record as identification takes it: the travel the data requires, and what was found, worded.

    Parameters
    ----------
    p : PreparedRecord
        The record prepared once (:func:`ema_sim.analysis.estimation.prepared.prepare`).

    Returns
    -------
    Record
        Its channel with the travel used, its notes and warnings.
    """
    channel, travel, hold, unit = p.channel, p.travel, p.hold, p.unit
    if travel.limits != travel.declared:
        channel = replace(channel, position_min_deg=travel.limits[0], position_max_deg=travel.limits[1])
    notes: list[str] = []
    warnings: list[str] = []
    if p.channel_note:
        notes.append(p.channel_note)
    cut = [f"truncated: {p.data.metadata['truncated']}"] if "truncated" in p.data.metadata else []
    notes += cut
    warnings += p.radians + p.reversed_outputs + cut
    if unit != "deg":
        line = (f"positions in {unit} as logged (no --crank-arm-in): every *_deg figure of this report is "
                f"in {unit}, every rate in {unit}/s")
        notes.append(line)
        warnings.append(line)
    for name, nf in p.noise.items():
        if nf.resolution is not None:
            notes.append(f"{name} logged in counts of {nf.resolution:g}: noise floor {nf.sigma:.3g} "
                         f"({'the counts' if nf.limited_by_resolution else 'white noise'} set it)")
    for name, nf in p.noise.items():
        notes += nf.findings(name, unit)
        warnings += rest_warnings(name, nf, unit)
    if hold.sampled is None and hold.source == "detected":
        notes.append(f"command: undecided ({hold.evidence}); ema analyze says the same: held and sampled both "
                     "fitted, each reported, the better taken (below)")
    else:
        notes.append(f"command {hold.statement}")
    if hold.leads:
        warnings.append(hold.leads)
    stamps = p.stamps
    said = _stamps_notes(stamps, p.outputs[p.first], unit)
    notes += said
    if stamps.gaps:
        warnings.append(said[0])
    notes.append(f"travel: {travel.statement}")
    if travel.outside:
        warnings.append(f"data outside the declared travel: {travel.statement}")
    for name, (lo, hi) in p.saturation.items():
        y = p.outputs[name]
        sides = [f"{v:.4g}{'°' if unit == 'deg' else ' ' + unit} ({int(np.count_nonzero(y == v))} samples)"
                 for v in (lo, hi) if math.isfinite(v)]
        notes.append(f"{name} reads exactly {' and '.join(sides)} again and again, with no noise on them: a sensor's "
                     "saturation or a clipped log, not a mechanical stop (which shows the noise); the model's "
                     f"{name} is clipped there as the sensor clips it")
    return Record(p, p.data, channel, p.noise, hold, travel, notes, warnings, stamps.scatter_s, p.saturation, stamps,
                  generic=p.channel_note is not None, unit=unit, command_sampled=hold.assumed_sampled)
