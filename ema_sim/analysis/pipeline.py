"""``ema analyze``'s engine: recognise a record's tests and run every section-2 test on it.

:func:`analyze_record` takes one :class:`~ema_sim.io.measured.MeasuredData` (a rig's CSV or a bag), and

1. measures each output's noise floor and resolution (:func:`ema_sim.analysis.estimation.noise.output_noise`),
   read where the output cannot move (:func:`ema_sim.analysis.estimation.noise.with_rests`: a limit cycle at
   rest and a floor that grows with the excitation are said, not taken for noise), and whether the command
   is held or sampled (:mod:`ema_sim.analysis.records.command_hold`), on the samples as logged;
2. puts the record on a uniform grid (:func:`ema_sim.analysis.records.series.uniform_record`);
3. recognises its segments (:mod:`ema_sim.analysis.recognize`);
4. runs every test of :data:`ema_sim.analysis.registry.TESTS` in order; a test that finds nothing to
   run on says why in ``not_computed``, and a segment no test runs on gets a note.

:func:`analyze_records` then lets each record use what another record of the same channel measured
(each test's :meth:`~ema_sim.analysis.section2.base.Section2Test.share`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from typing import Any

import numpy as np

from ema_sim.analysis.estimation import slew
from ema_sim.analysis.estimation.noise import NoiseFloor, output_noise, with_rests
from ema_sim.analysis.estimation.second_order_fit import SecondOrderFit
from ema_sim.analysis.estimation.slew import Slew
from ema_sim.analysis.recognize import recognize
from ema_sim.analysis.records import causality, series, stamps
from ema_sim.analysis.records.command_hold import CommandHold, detect_command_hold, given, lag_band
from ema_sim.analysis.registry import TESTS
from ema_sim.analysis.section2.base import Options, RecordAnalysis
from ema_sim.config import CHANNELS, STAND_IN, ChannelConfig, load_channel
from ema_sim.io.measured import MeasuredData

RECOGNISED = 0.1
"""Share of a record's analysis reported done once its tests are recognised."""

__all__ = ["Options", "RecordAnalysis", "analyze_record", "analyze_records", "record_slew", "resolve_channel",
           "spread", "timing_alternatives"]


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


def measure_outputs(data: MeasuredData) -> dict[str, NoiseFloor]:
    """Each output's noise floor and resolution, on the samples as logged, read at the record's rests.

    Parameters
    ----------
    data : MeasuredData
        The record as read.

    Returns
    -------
    dict
        Output name → its :class:`~ema_sim.analysis.estimation.noise.NoiseFloor`.
    """
    given_counts = data.metadata.get("resolution_deg")
    counts = float(given_counts) if given_counts else None
    return {name: with_rests(output_noise(getattr(data, name), counts), data.time_s, data.command_deg,
                             getattr(data, name), data.current_a) for name in data.outputs}


def command_hold(data: MeasuredData, noise: dict[str, NoiseFloor], options: Options) -> CommandHold:
    """How the record's command was logged: given by the user, else detected on the samples as logged.

    Parameters
    ----------
    data : MeasuredData
        The record as read.
    noise : dict
        Each output's noise floor.
    options : Options
        What was asked (``command``: detect, held or sampled).

    Returns
    -------
    CommandHold
        The finding.
    """
    dt = float(np.median(np.diff(data.time_s)))
    name = data.outputs[0]
    nf = noise[name]
    y = getattr(data, name)
    if options.command != "detect":
        return given(options.command, dt, causality.measure(data.time_s, data.command_deg, y,
                                                            lag_band(nf.sigma, nf.resolution)))
    return detect_command_hold(data.time_s, data.command_deg, y, nf.sigma, nf.resolution)


def record_slew(data: MeasuredData, noise: dict[str, NoiseFloor]) -> Slew:
    """The slope of the record's rate-limited moves, on its own stamps: ``ema identify``'s measurement exactly.

    Parameters
    ----------
    data : MeasuredData
        The record as read (its own stamps, nothing straightened or resampled).
    noise : dict
        Each output's noise floor.

    Returns
    -------
    Slew
        :func:`ema_sim.analysis.estimation.slew.measure` on the first output (position, else surface).
    """
    name = "position_deg" if data.position_deg is not None else "surface_deg"
    y = getattr(data, name)
    return slew.measure(data.time_s - data.time_s[0], data.command_deg, y, max(noise[name].sigma, slew.MIN_NOISE))


def analyze_record(data: MeasuredData, options: Options | None = None,
                   progress: Callable[[float], None] | None = None) -> RecordAnalysis:
    """Recognise and analyse one record (see the module docstring).

    Parameters
    ----------
    data : MeasuredData
        The record as read.
    options : Options, optional
        What was asked.
    progress : callable, optional
        Called with the share done (0 at the start, then after the recognition and after each test).

    Returns
    -------
    RecordAnalysis
        Every test's results, what was not computed and why, and notes.
    """
    options = options or Options()
    say = progress or (lambda _share: None)
    say(0.0)
    noise = measure_outputs(data)
    hold = command_hold(data, noise, options)
    ra = _analyze(data, options, noise, hold, say)
    ra.notes += [line for name, nf in noise.items() for line in nf.findings(name, data.unit)]
    if hold.sampled is None and hold.source == "detected":
        other = _analyze(data, replace(options, command="sampled"), noise,
                         replace(hold, sampled=True), lambda _share: None)
        ra.other_timing = timing_alternatives(ra, other)
        if ra.other_timing:
            ra.notes.append("the record cannot tell a held command from a sampled one: its figures assume held (the "
                            "data contract); what the sampled assumption gives instead is listed beside them")
    return ra


def _analyze(data: MeasuredData, options: Options, noise: dict[str, NoiseFloor], hold: CommandHold,
             say: Callable[[float], None]) -> RecordAnalysis:
    """:func:`analyze_record` under one timing assumption (``hold``)."""
    measured_slew = record_slew(data, noise)
    raw_stamps = data.time_s
    data = series.uniform_record(data, command_sampled=hold.assumed_sampled)
    ch, ch_note = resolve_channel(data, options.channel)
    rec = recognize(data)
    ra = RecordAnalysis(data, ch, rec, noise, hold, options,
                        stamps=raw_stamps if raw_stamps.size == data.time_s.size else None, slew=measured_slew,
                        stand_in=ch_note is not None)
    if ch_note:
        ra.notes.append(ch_note)
    if "resampled" in data.metadata:
        ra.notes.append(data.metadata["resampled"])
    jitter = stamps.measure(raw_stamps)
    if jitter.jitters and data.outputs:
        ra.notes.append(f"{jitter.statement(stamps.output_rate(jitter, data.column(data.outputs[0])), data.unit)}; no "
                        "effect of the actuator is read into it")
    ra.notes += rec.notes
    say(RECOGNISED)
    for k, test in enumerate(TESTS):
        results = test.run(ra)
        say(RECOGNISED + (1.0 - RECOGNISED) * (k + 1) / len(TESTS))
        ra.results[test.key] = results
        for r in results:
            ra.fits += test.fits(r)
        if not results and test.key not in ra.not_computed:
            ra.not_computed[test.key] = test.absent or f"no {test.key} segment recognised"
    if rec.maneuver is not None and any("no such test found" in n for n in rec.notes):
        ra.not_computed[f"{rec.maneuver.kind} (the metadata's maneuver)"] = (
            f"commanded by the metadata ({data.metadata.get('maneuver')}) but not recognised in the command "
            f"(the command counts as held within {rec.command_tolerance_deg:.2g}° and as stepping from "
            f"{rec.edge_threshold_deg:.3g}°)")
    claimed = {k for test in TESTS for k in test.kinds}
    t = data.time_s
    for seg in rec.segments:
        if seg.kind not in claimed:
            why = seg.evidence.removeprefix("signal: ")
            ra.notes.append(f"{seg.kind} at {t[seg.start]:.1f}-{t[seg.stop - 1]:.1f} s ({why}): tracking is in the "
                            "time-history plot; no figure of this tool applies to it")
    return ra


def _timing_figures(ra: RecordAnalysis) -> dict[str, tuple[str, float, float | None]]:
    """Every phase (deg) and delay (s) a record's analysis reports, keyed by where it is (for pairing)."""
    out: dict[str, tuple[str, float, float | None]] = {}
    for k, f in enumerate(ra.fits):
        key = f"fit {k}: {f.test} on {f.output}"
        out[key] = ("delay_s", f.actuator_delay_s, f.delay_s.sigma)

    def walk(value: Any, path: str) -> None:
        if isinstance(value, dict):
            if isinstance(value.get("phase_deg"), int | float) and isinstance(value.get("freq_hz"), int | float):
                sigma = value.get("phase_sigma_deg")
                out[f"{path} at {value['freq_hz']:.4g} Hz"] = ("phase_deg", float(value["phase_deg"]),
                                                              float(sigma) if isinstance(sigma, int | float) else None)
                return
            for k, v in value.items():
                if k not in ("second_order_fit", "moves", "edges"):
                    walk(v, f"{path}/{k}")
        elif isinstance(value, list):
            for i, v in enumerate(value):
                walk(v, f"{path}[{i}]")

    for key, results in ra.results.items():
        for i, r in enumerate(results):
            walk(r.as_dict(), f"{key}[{i}]")
    return out


def timing_alternatives(held: RecordAnalysis, sampled: RecordAnalysis) -> list[dict[str, Any]]:
    """Each phase and delay of a record analysed with its command taken as held and as sampled, side by side.

    Parameters
    ----------
    held : RecordAnalysis
        The analysis with the command held (the data contract).
    sampled : RecordAnalysis
        The same record with the command taken as sampled from a running demand.

    Returns
    -------
    list of dict
        ``figure``, ``quantity`` (``phase_deg`` or ``delay_s``), ``held``, ``sampled`` and their ``sigma``;
        only figures both analyses report.
    """
    a, b = _timing_figures(held), _timing_figures(sampled)
    return [{"figure": k, "quantity": q, "held": v, "sampled": b[k][1], "sigma": s}
            for k, (q, v, s) in a.items() if k in b and b[k][0] == q]


def analyze_records(records: list[MeasuredData], options: Options | None = None,
                    progress: Callable[[int, float], None] | None = None) -> list[RecordAnalysis]:
    """Analyse several records, then let each use what another of the same channel measured.

    A crosstalk record judged against table A2's threshold is judged again against a static threshold
    measured on the same channel; free-play jumps with no compliance taken out get the total compliance
    measured on a load staircase of the same channel.

    Parameters
    ----------
    records : list of MeasuredData
        The records as read.
    options : Options, optional
        What was asked.
    progress : callable, optional
        Called with a record's index and the share of it done.

    Returns
    -------
    list of RecordAnalysis
        One per record, in order.
    """
    options = options or Options()
    done = [analyze_record(d, options, None if progress is None else _for_record(progress, i))
            for i, d in enumerate(records)]
    for ra in done:
        same = [o for o in done if o.channel.channel == ra.channel.channel and o is not ra]
        for test in TESTS:
            test.share(ra, same)
    return done


def _for_record(progress: Callable[[int, float], None], i: int) -> Callable[[float], None]:
    """``progress`` bound to record ``i``."""
    def say(share: float) -> None:
        progress(i, share)

    return say


# ---------------------------------------------------------------------------------------------- across tests
def spread(fits: list[SecondOrderFit]) -> dict[str, Any]:
    """Figure 23: the estimates of every test whose fit the record determines, and their range, per output.

    Parameters
    ----------
    fits : list of SecondOrderFit
        Every fit (those of a quality other than ``ok`` are listed but left out of the range).

    Returns
    -------
    dict
        Output → the tests and the min, max, mean, std and count of ωn, ζ and delay.
    """
    out: dict[str, Any] = {}
    for output in sorted({f.output for f in fits}):
        every = [f for f in fits if f.output == output]
        rows = [f for f in every if f.quality == "ok"]
        entry: dict[str, Any] = {"tests": [{"test": f.test, "method": f.method, "wn_rad_s": f.wn_rad_s.value,
                                            "wn_sigma": f.wn_rad_s.sigma, "zeta": f.zeta.value,
                                            "zeta_sigma": f.zeta.sigma, "delay_s": f.delay_s.value,
                                            "delay_sigma_s": f.delay_s.sigma, "quality": f.quality} for f in every]}
        for key in ("wn_rad_s", "zeta", "delay_s"):
            vals = np.array([getattr(f, key).value for f in rows])
            entry[key] = ({"min": float(vals.min()), "max": float(vals.max()), "mean": float(vals.mean()),
                           "std": float(vals.std(ddof=1)) if vals.size > 1 else None, "count": int(vals.size)}
                          if vals.size else None)
        entry["left_out"] = len(every) - len(rows)
        entry["bounds"] = ("uniform between the minimum and maximum over the tests whose fit is determined (quality "
                           "ok), as section 3.1.1 defines the model's uncertainty")
        out[output] = entry
    return out
