"""PNG plots of ``ema analyze --report``: one image per result, drawn by the result's own test.

Each test of :data:`ema_sim.analysis.registry.TESTS` draws its results the way the report draws
them (Bode plots with coherence and the fit, figures 24 and 25; step responses against the fit,
figure 22; compliance curves, figure 16, and the three-segment model, figure 35; hysteresis loops,
figure 17; command error, figure 27...). This module adds the two plots that belong to no single
test: each record's time history with its recognised segments, and the spread of the second-order
estimates across tests (figure 23).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from ema_sim.analysis.estimation.noise import output_noise
from ema_sim.analysis.formatting import figure
from ema_sim.analysis.registry import TESTS
from ema_sim.analysis.section2.base import RecordAnalysis

SEGMENT_COLORS = ("#e8f0fe", "#fde8e8", "#e8fde9", "#fdf6e3", "#f1e8fd")


def has_load(ra: RecordAnalysis) -> bool:
    """Whether the record measured a hinge moment worth a panel: one that is not zero within its own noise.

    Parameters
    ----------
    ra : RecordAnalysis
        The record.

    Returns
    -------
    bool
        False when there is no hinge-moment column or it reads zero (to ten times its noise).
    """
    hm = ra.data.hinge_moment_inlb
    if hm is None or hm.size == 0:
        return False
    floor = output_noise(hm).sigma
    return bool(np.max(np.abs(hm)) > 10.0 * floor and np.max(np.abs(hm)) > 0.0)


def overview(ra: RecordAnalysis, path: Path) -> None:
    """The record's time history: command and outputs, their difference, the load when measured, the segments.

    Parameters
    ----------
    ra : RecordAnalysis
        The record.
    path : pathlib.Path
        The PNG to write.
    """
    d = ra.data
    t = d.time_s
    loaded = has_load(ra)
    rows = 2 + loaded
    fig, ax = figure.pyplot().subplots(rows, 1, figsize=(10, 2.2 * rows + 0.5), sharex=True)
    ax[0].plot(t, d.command_deg, color=figure.COLORS["command"], lw=0.8, label="command")
    for name in d.outputs:
        ax[0].plot(t, getattr(d, name), color=figure.COLORS[name], lw=0.7, label=name)
    unit = "deg" if d.unit == "deg" else d.unit
    ax[0].set_ylabel(unit)
    ax[0].legend(loc="upper right", fontsize=8)
    main = d.position_deg if d.position_deg is not None else d.surface_deg
    assert main is not None
    ax[1].plot(t, main - d.command_deg, color="tab:red", lw=0.6)
    ax[1].set_ylabel(f"output − command, {unit}")
    if loaded:
        assert d.hinge_moment_inlb is not None
        ax[2].plot(t, d.hinge_moment_inlb, color="tab:purple", lw=0.8)
        ax[2].set_ylabel("hinge moment, in·lb")
    for k, s in enumerate(ra.recognition.segments):
        for a in ax:
            a.axvspan(t[s.start], t[s.stop - 1], color=SEGMENT_COLORS[k % len(SEGMENT_COLORS)], zorder=0)
        ax[0].text(t[s.start], ax[0].get_ylim()[1], f" {s.kind}", va="top", fontsize=8)
    ax[-1].set_xlabel("time, s")
    ax[0].set_title(f"{Path(d.source).name or 'record'}: {ra.channel_name}")
    figure.save(fig, path)


def spread_plot(records: Sequence[RecordAnalysis], path: Path) -> None:
    """Figure 23: every second-order estimate with its standard error, and the range of the determined ones.

    Parameters
    ----------
    records : sequence of RecordAnalysis
        The records.
    path : pathlib.Path
        The PNG to write.
    """
    fits = [f for r in records for f in r.fits]
    fig, ax = figure.pyplot().subplots(1, 3, figsize=(12, 3.8))
    for a, key, scale, label in ((ax[0], "wn_rad_s", 1.0, "ωn, rad/s"), (ax[1], "zeta", 1.0, "ζ"),
                                 (ax[2], "delay_s", 1e3, "delay, ms")):
        seen: set[str] = set()
        for k, f in enumerate(fits):
            e = getattr(f, key)
            mark = "o" if f.method.startswith("time") else "s"
            a.errorbar(k, scale * e.value, yerr=scale * e.sigma, fmt=mark, color=figure.COLORS.get(f.output, "k"),
                       ms=4, mfc="none" if f.quality != "ok" else None, label=None if f.output in seen else f.output)
            seen.add(f.output)
        vals = [scale * getattr(f, key).value for f in fits if f.quality == "ok"]
        for v in (min(vals), max(vals)) if vals else ():
            a.axhline(v, color="0.4", ls="--", lw=0.8)
        a.set_ylabel(label)
        a.set_xlabel("test (o step, □ frequency response; hollow: not determined)")
        a.grid(lw=0.3)
    ax[0].set_title("second-order estimates across tests (figure 23)", fontsize=9)
    ax[0].legend(fontsize=7)
    figure.save(fig, path)


def write_plots(records: Sequence[RecordAnalysis], out_dir: Path) -> dict[str, str]:
    """Draw every plot into a folder.

    Parameters
    ----------
    records : sequence of RecordAnalysis
        The records.
    out_dir : pathlib.Path
        The folder (created when missing).

    Returns
    -------
    dict
        Plot key → file name relative to ``out_dir``: ``r{i}_overview``, ``r{i}_{test}{j}`` for
        result ``j`` of a test on record ``i``, and ``spread``.
    """
    out_dir.mkdir(parents=True, exist_ok=True)
    made: dict[str, str] = {}
    for i, ra in enumerate(records):
        key = f"r{i}_overview"
        overview(ra, out_dir / f"{key}.png")
        made[key] = f"{key}.png"
        for test in TESTS:
            for j, r in enumerate(ra.of(test)):
                key = plot_key(i, test.key, j)
                if test.plot(ra, r, out_dir / f"{key}.png"):
                    made[key] = f"{key}.png"
    if sum(len(r.fits) for r in records) > 1:
        spread_plot(records, out_dir / "spread.png")
        made["spread"] = "spread.png"
    return made


def plot_key(record: int, test: str, result: int) -> str:
    """The key (and file stem) of one result's plot.

    Parameters
    ----------
    record : int
        The record's index.
    test : str
        The test's key.
    result : int
        The result's index within the test.

    Returns
    -------
    str
        ``r{record}_{test}{result}``.
    """
    return f"r{record}_{test}{result}"
