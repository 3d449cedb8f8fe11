"""Dropouts (stale readings) in a record's outputs: ``ema analyze`` cuts the record there, never reads across them.

The records are made with numpy alone (``servo_records``): a damped, rate-limited servo following a held
staircase at 1 kHz; a dropout repeats the position's last reading for 200 ms in the middle of a move, then jumps
to catch up.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from servo_records import servo

from ema_sim.analysis.pipeline import analyze_records
from ema_sim.analysis.records import artefacts
from ema_sim.analysis.report import to_json
from ema_sim.io.measured import MeasuredData

RATE_DPS = 80.0
LEVELS = [(0.0, 0.0), (1.0, 0.5), (2.0, -0.5), (3.0, 2.0), (4.0, -2.0), (5.0, 10.0), (6.0, -10.0), (7.0, 0.0)]


def _record(dropout: bool) -> tuple[MeasuredData, slice]:
    t = np.arange(0.0, 8.0, 1e-3)
    u, y = servo(t, LEVELS, rate_dps=RATE_DPS)
    a, b = np.searchsorted(t, [5.05, 5.25])
    if dropout:
        y[a:b] = y[a - 1]
    data = MeasuredData(time_s=t, command_deg=u, position_deg=y, metadata={"channel": "generic"}, source="dropout")
    return data, slice(int(a), int(b))


def _peak_rates(analyses: list) -> list[float]:
    """Every step's peak rate, as the ``--json`` report gives it."""
    return [abs(float(s["peak_rate_dps"])) for r in to_json(analyses)["records"] for s in r["steps"]]


def test_a_dropout_cuts_the_record_and_no_analysis_reads_across_it():
    """The 200 ms stale reading: two stretches on either side, the stale samples in neither, the cut said; no step
    reads the catch-up jump as a rate (it read 950 °/s against the servo's 80 before)."""
    data, stale = _record(dropout=True)
    found = artefacts.find(data.time_s, data.command_deg, {"position_deg": data.position_deg},
                           {"position_deg": artefacts.robust_floor(data.position_deg)})
    assert [a.kind for a in found] == ["stale"]
    assert set(found[0].indices) == set(range(stale.start, stale.stop))
    parts = artefacts.split_at_dropouts(data)
    assert len(parts) == 2
    assert parts[0].time_s[-1] < data.time_s[stale.start]
    assert parts[1].time_s[0] >= data.time_s[stale.stop]
    assert all("a dropout, cut out" in p.metadata["dropouts"] for p in parts)
    analyses = analyze_records([data])
    assert len(analyses) == 2
    assert all(any("dropout" in n for n in ra.notes) for ra in analyses)
    rates = _peak_rates(analyses)
    assert rates, "the steps on either side are still analysed"
    assert max(rates) < 1.2 * RATE_DPS


def test_a_record_without_dropouts_is_left_whole():
    data, _ = _record(dropout=False)
    assert artefacts.split_at_dropouts(data) == [data]
    analyses = analyze_records([data])
    assert len(analyses) == 1
    assert not any("dropout" in n for n in analyses[0].notes)


def test_a_servo_resting_in_counts_then_moving_is_no_dropout():
    """A slewing servo read through 0.01° counts at 100 Hz, its command a ±22.1° square: each move ends on a short
    last sample (0.2°), the output rests four samples on one count, and the next move's first sample jumps a full
    0.8°, four times the last. It goes on at that speed, so it is no catch-up of a stale reading (the jump alone
    would have said it was, at every reversal)."""
    t = np.arange(0.0, 8.0, 0.01)
    levels = [(0.0, -22.1), *((0.6 * k, 22.1 if k % 2 else -22.1) for k in range(1, 13))]
    u = np.array([next(v for a, v in reversed(levels) if a <= x + 1e-9) for x in t])
    y = np.full_like(t, -22.11)  # one count off its first command: the record shows the counts
    step = RATE_DPS * 0.01
    for k in range(1, t.size):
        y[k] = y[k - 1] + float(np.clip(u[k - 1] - y[k - 1], -step, step))
    y = np.round(y / 0.01) * 0.01
    bad, _, _ = artefacts.stale(y, artefacts.robust_floor(y))
    assert bad == []
    data = MeasuredData(time_s=t, command_deg=u, position_deg=y, metadata={"channel": "generic"}, source="counts")
    assert artefacts.split_at_dropouts(data) == [data]


def test_a_stale_surface_reading_cuts_every_column_alike():
    """A dropout on the surface output alone: every column (command, position, surface) loses the same samples."""
    data, stale = _record(dropout=False)
    surface = data.position_deg.copy()
    surface[stale] = surface[stale.start - 1]
    data = replace(data, surface_deg=surface)
    parts = artefacts.split_at_dropouts(data)
    assert len(parts) == 2
    for p in parts:
        assert p.time_s.size == p.command_deg.size == p.position_deg.size == p.surface_deg.size
        assert "surface_deg" in p.metadata["dropouts"]
