"""``ema analyze``'s engine: recognise a record's tests and run every section-2 test on it.

:func:`analyze_record` takes one :class:`~ema_sim.io.measured.MeasuredData` (a rig's CSV or a bag), and

1. prepares the record once (:func:`ema_sim.analysis.estimation.prepared.prepare`, what ``ema identify`` starts
   from too): its channel, its slew, each output's noise floor and resolution, read where the output cannot
   move (a limit cycle at rest and a floor that grows with the excitation are said, not taken for noise), and
   whether the command is held or sampled, on the samples as logged;
2. puts the record on a uniform grid (:func:`ema_sim.analysis.records.series.uniform_record`), never across a
   gap in its stamps nor a dropout of its outputs: :func:`analyze_records` first cuts a record at them into its
   contiguous stretches (:func:`ema_sim.analysis.records.artefacts.split_at_dropouts`,
   :func:`ema_sim.analysis.records.series.split_at_gaps`), each analysed as a record of its own;
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

from ema_sim.analysis.estimation.prepared import PreparedRecord, prepare, resolve_channel
from ema_sim.analysis.estimation.second_order_fit import SecondOrderFit
from ema_sim.analysis.recognize import recognize
from ema_sim.analysis.records import artefacts, series, stamps
from ema_sim.analysis.records.command_hold import CommandHold
from ema_sim.analysis.registry import TESTS
from ema_sim.analysis.section2.base import Options, RecordAnalysis, TimingAlternative
from ema_sim.io.measured import MeasuredData

RECOGNISED = 0.1
"""Share of a record's analysis reported done once its tests are recognised."""

__all__ = ["Options", "RecordAnalysis", "analyze_record", "analyze_records", "resolve_channel", "spread",
           "timing_alternatives"]


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
    channel, note = resolve_channel(data, options.channel)
    p = prepare(data, channel, channel_note=note, command=options.command)
    ra = _analyze(p, options, p.hold, say)
    ra.notes += [line for name, nf in p.noise.items() for line in nf.findings(name, p.unit)]
    ra.notes += p.radians + p.reversed_outputs
    if p.hold.sampled is None and p.hold.source == "detected":
        other = _analyze(p, replace(options, command="sampled"), replace(p.hold, sampled=True), lambda _share: None)
        ra.other_timing = timing_alternatives(ra, other)
        if ra.other_timing:
            ra.notes.append("the record cannot tell a held command from a sampled one: its figures assume held (the "
                            "data contract); what the sampled assumption gives instead is listed beside them")
    return ra


def _analyze(p: PreparedRecord, options: Options, hold: CommandHold, say: Callable[[float], None]) -> RecordAnalysis:
    """:func:`analyze_record` under one timing assumption (``hold``), from the record prepared once."""
    raw_stamps = p.time_s
    data = series.uniform_record(p.data, command_sampled=hold.assumed_sampled)
    rec = recognize(data)
    same = raw_stamps.size == data.time_s.size
    ra = RecordAnalysis(data, p.channel, rec, p.noise, hold, options, stamps=raw_stamps if same else None,
                        slew=p.slew, stand_in=p.channel_note is not None, logged=None if same else raw_stamps.size)
    if p.channel_note:
        ra.notes.append(p.channel_note)
    ra.notes += [data.metadata[k] for k in series.SAID if k in data.metadata]
    jitter = p.stamps
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

    def walk(value: object, path: str) -> None:
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


def timing_alternatives(held: RecordAnalysis, sampled: RecordAnalysis) -> list[TimingAlternative]:
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

    A record with gaps in its stamps or dropouts in its outputs is analysed stretch by stretch
    (:func:`ema_sim.analysis.records.series.split_at_gaps`,
    :func:`ema_sim.analysis.records.artefacts.split_at_dropouts`): one analysis per stretch, in order.

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
        One per record (per stretch of a record with gaps), in order.
    """
    options = options or Options()
    done = []
    for i, d in enumerate(records):
        parts = [g for s in artefacts.split_at_dropouts(d) for g in series.split_at_gaps(s)]
        done += [analyze_record(part, options, None if progress is None else _for_record(progress, i, j, len(parts)))
                 for j, part in enumerate(parts)]
    for ra in done:
        same = [o for o in done if o.channel.channel == ra.channel.channel and o is not ra]
        for test in TESTS:
            test.share(ra, same)
    return done


def _for_record(progress: Callable[[int, float], None], i: int, j: int = 0, parts: int = 1) -> Callable[[float], None]:
    """``progress`` bound to record ``i`` (its stretch ``j`` of ``parts``)."""
    def say(share: float) -> None:
        progress(i, (j + share) / parts)

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
