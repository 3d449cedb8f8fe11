"""Gaps and wandering instants in a record's stamps: never bridged, never taken for jitter.

The records are made with numpy alone (``servo_records``): a damped servo following a held staircase,
sampled either on a uniform grid with one long pause of the logger, or at instants whose every interval
jitters (so they drift as a random walk), now and then a sample late by one or two intervals, stamped in
integer ms.
"""

from __future__ import annotations

import numpy as np
import pytest
from servo_records import servo

from ema_sim.analysis.estimation.prepared import prepare, resolve_channel
from ema_sim.analysis.pipeline import analyze_records
from ema_sim.analysis.records import series, stamps
from ema_sim.analysis.report import to_json
from ema_sim.identify.record import identification_record
from ema_sim.io.measured import MeasuredData


def _gapped(gap_s: float = 5.0) -> MeasuredData:
    """Two 6 s stretches at 500 Hz with a pause of ``gap_s`` between, the command held at 2° across it."""
    first = np.arange(0.0, 6.0, 0.002)
    t = np.concatenate([first, first + 6.0 + gap_s])
    levels = [(0.0, 0.0), (1.0, 1.0), (2.5, 0.0), (3.5, 2.0), (6.0 + gap_s + 3.0, -1.0), (6.0 + gap_s + 4.5, 0.0)]
    command, position = servo(t, levels)
    return MeasuredData(time_s=t, command_deg=command, position_deg=position, source="gapped.csv")


def _wandering(n: int = 4000, seed: int = 3) -> MeasuredData:
    """500 Hz nominal: every interval jitters 0.3 ms rms, 1 % of them 2-3 ms longer; integer-ms stamps."""
    rng = np.random.default_rng(seed)
    dt = 2e-3 + rng.normal(0.0, 0.3e-3, n)
    late = rng.random(n) < 0.01
    dt[late] += rng.choice([2e-3, 3e-3], int(late.sum()))
    true = np.cumsum(dt)
    levels = [(0.0, 0.0), (1.0, 3.0), (2.5, -2.0), (4.0, 0.0), (5.5, 1.0)]
    command, position = servo(true, levels, seed)
    stamp = np.round(true * 1e3) / 1e3
    keep = np.concatenate([[True], np.diff(stamp) > 0])
    return MeasuredData(time_s=stamp[keep], command_deg=command[keep], position_deg=position[keep],
                        source="wandering.csv")


def test_a_gap_is_a_gap_not_jitter():
    t = _gapped().time_s
    st = stamps.measure(t)
    assert [(g.index, g.start_s) for g in st.gaps] == [(3000, pytest.approx(5.998))]
    assert st.gaps[0].duration_s == pytest.approx(5.002)
    assert not st.jitters
    assert st.interval_s == pytest.approx(0.002)
    assert "5.002 s at 5.998 s" in stamps.gap_statement(st.gaps, st.interval_s)


def test_the_jitter_of_wandering_instants_is_their_spread_about_the_local_grid():
    st = stamps.measure(_wandering().time_s)
    assert st.gaps == ()
    assert st.jitters
    # 0.3 ms per interval and the integer-ms rounding (0.29 ms): the spread a model on the stamps feels
    assert 0.2e-3 <= st.scatter_s <= 0.5e-3
    assert st.peak_s <= 1.5e-3
    assert st.interval_s == pytest.approx(2e-3, rel=0.02)


def test_split_at_gaps_gives_each_stretch_on_its_own_and_leaves_out_the_short_ones():
    data = _gapped()
    parts = series.split_at_gaps(data)
    assert [p.time_s.size for p in parts] == [3000, 3000]
    assert all(np.max(np.diff(p.time_s)) <= 0.0021 for p in parts)
    assert parts[0].source == "gapped.csv [0-5.998 s]"
    assert "stretch 2 of 2" in parts[1].metadata["gaps"]
    t = data.time_s
    short = MeasuredData(time_s=np.concatenate([t, t[-1] + 10.0 + 0.002 * np.arange(50)]),
                         command_deg=np.zeros(t.size + 50), position_deg=np.zeros(t.size + 50), source="s.csv")
    kept = series.split_at_gaps(short)
    assert len(kept) == 2
    assert "1 stretch(es) under 100 samples not analysed" in kept[0].metadata["gaps"]
    assert series.split_at_gaps(parts[0]) == [parts[0]]


def test_analyze_never_runs_a_test_across_a_gap():
    data = _gapped()
    done = analyze_records([data])
    assert len(done) == 2
    assert sum(ra.data.time_s.size for ra in done) == data.time_s.size
    for ra in done:
        assert np.max(np.diff(ra.data.time_s)) <= 0.0021
        assert ra.logged is None
        assert any("gap" in n and "never across a gap" in n for n in ra.notes)
        assert not ra.results["dither"]  # the 2° held across the pause is no 5 s hold in either stretch


def test_a_resampled_record_counts_the_samples_as_logged():
    data = _wandering()
    (ra,) = analyze_records([data])
    assert ra.logged == data.time_s.size
    record = to_json([ra])["records"][0]
    assert record["samples"] == data.time_s.size
    assert record["samples_resampled"] == ra.data.time_s.size
    assert any(f"{ra.data.time_s.size} samples on the grid from the {data.time_s.size} logged" in n for n in ra.notes)


def test_identify_says_a_gap_and_no_jitter_floor_from_it():
    data = _gapped()
    channel, note = resolve_channel(data, None)
    rec = identification_record(prepare(data, channel, channel_note=note))
    assert any("gap(s) in the time stamps" in w and "not jitter" in w for w in rec.warnings)
    assert not any("time stamps jitter" in n for n in rec.notes)
