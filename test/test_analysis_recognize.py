"""Every section-2 test is recognised from its signals alone, and the metadata confirms or relabels it."""

from dataclasses import replace

import numpy as np
import pytest
from analysis_data import delayed, measured

from ema_sim.analysis.pipeline import analyze_record
from ema_sim.analysis.recognize import recognize
from ema_sim.analysis.records import series
from ema_sim.io.measured import MeasuredData
from ema_sim.signals import parse_maneuver

CASES = [
    ("sweep:f0_hz=0.2,f1_hz=18,amp_deg=1,sweep_s=60", None, ["sweep"]),
    ("schroeder:f0_hz=0.2,f1_hz=18,amp_deg=1,period_s=20,periods=2", None, ["schroeder"]),
    ("steps:amps_deg=0.5/1/20", None, ["steps"]),
    ("square:freq_hz=1,amp_deg=4.3,cycles=5", None, ["square"]),
    ("staircase:step_deg=5,max_deg=40,hold_s=3", None, ["staircase"]),
    ("static_threshold:amp_max_deg=0.3,cycles=6", None, ["static_threshold"]),
    ("dynamic_threshold", None, ["dynamic_threshold"]),
    ("hold:value_deg=0,hold_s=10", None, ["hold"]),
    ("triangle:freq_hz=0.5,amp_deg=2.15,cycles=5", None, ["triangle"]),
    ("sine:freq_hz=3,amp_deg=0.4,cycles=20", None, ["sine"]),
    ("hold:value_deg=15,hold_s=67", "steps:step_inlb=222.5,max_inlb=1780,hold_s=2", ["load_steps"]),
    ("hold:value_deg=0,hold_s=30", "steps:step_inlb=470,max_inlb=470,hold_s=5", ["load_steps"]),
    ("hold:value_deg=0,hold_s=11", "reversal:inlb=50,period_s=2,reversals=4", ["load_reversal"]),
    ("hold:value_deg=0,hold_s=90", "sine:amp_inlb=500,freq_hz=0.0333,cycles=3", ["load_sine"]),
    ("regen", None, ["regen"]),
    ("pid", None, ["steps", "sweep", "schroeder"]),
    ("ramp:rate_dps=0.05,peak_deg=2", None, ["ramp"]),
]


IDS = [c[0].split(":")[0] + (":" + c[1].split(":")[0] if c[1] else "") for c in CASES]


@pytest.mark.parametrize(("maneuver", "load", "kinds"), CASES, ids=IDS)
@pytest.mark.parametrize("with_metadata", [True, False], ids=["metadata", "signals"])
def test_each_test_is_recognised(maneuver, load, kinds, with_metadata):
    data = measured("loada", maneuver, load, metadata=with_metadata)
    rec = recognize(data)
    assert [s.kind for s in rec.segments] == kinds
    for s in rec.segments:
        assert s.evidence.startswith("signal: ")
        assert ("metadata agrees" in s.evidence) is with_metadata or s.kind == "hold"


def test_signal_parameters_match_the_spec():
    rec = recognize(measured("loada", "sweep:f0_hz=0.5,f1_hz=12,amp_deg=1,sweep_s=40", metadata=False))
    (s,) = rec.segments
    assert s.params["f0_hz"] == pytest.approx(0.5, rel=0.5)
    assert s.params["f1_hz"] == pytest.approx(12, rel=0.15)
    rec = recognize(measured("loada", "schroeder:f0_hz=0.5,f1_hz=10,period_s=12.5,periods=2", metadata=False))
    assert rec.segments[0].params["period_s"] == pytest.approx(12.5, abs=0.002)


def test_metadata_relabels_a_compatible_reading_and_keeps_a_contradicted_one():
    data = measured("loada", "square:freq_hz=1,amp_deg=2,cycles=3")
    relabel = replace(data, metadata={**data.metadata, "maneuver": "steps:amps_deg=2"})
    (s,) = recognize(relabel).segments
    assert s.kind == "steps"
    assert "metadata says steps" in s.evidence
    contra = replace(data, metadata={**data.metadata, "maneuver": "sweep"})
    rec = recognize(contra)
    assert rec.segments[0].kind == "square"
    assert any("no such test found" in n for n in rec.notes)
    ra = analyze_record(contra)
    assert ra.not_computed["sweep (the metadata's maneuver)"].startswith("commanded by the metadata (sweep)")


def test_unparseable_metadata_is_a_note_not_an_error():
    data = measured("loada", "steps:amps_deg=1")
    rec = recognize(replace(data, metadata={"maneuver": "wobble:x=1"}))
    assert rec.segments[0].kind == "steps"
    assert "not understood" in rec.notes[0]


def test_holds_survive_noise_spikes_and_edges_need_real_jumps():
    x = np.concatenate([np.zeros(500), np.ones(500)])
    noisy = x + np.random.default_rng(1).normal(0, 0.001, x.size)
    noisy[200] += 0.02  # a spike inside the first hold
    hs = series.holds(noisy, 50)
    assert [(h.start, round(h.value)) for h in hs] == [(0, 0), (500, 1)]
    (e,) = series.edges(noisy, 0.001)
    assert e.index == 500
    assert e.jump == pytest.approx(1.0, abs=0.01)
    assert series.edges(0.01 * x, 0.001) == []  # below 0.05°: not a step


def test_a_slow_sine_under_a_noisy_command_is_not_a_hold():
    """Per-sample changes below the hold tolerance still add up: a 0.3 Hz, 1° sine at 200 Hz with
    0.013° of command noise (the AIL environment's, on the EMAC side) moves 0.01° per sample."""
    t = np.arange(0, 20, 0.005)
    u = np.sin(2 * np.pi * 0.3 * t) + np.random.default_rng(2).normal(0, 0.013, t.size)
    assert series.holds(u, 60) == []


def test_a_slow_sweep_cut_short_by_the_signal_takes_the_spec_window():
    spec = "sweep:f0_hz=0.2,f1_hz=18,amp_deg=1,bias_deg=0,sweep_s=58,log=True,lead_s=1"
    man = parse_maneuver(spec)
    t = np.arange(0, 59, 0.005)
    rng = np.random.default_rng(3)
    u = man.command_deg(t) + rng.normal(0, 0.013, t.size)
    u = 0.0213 * np.round(u / 0.0213)  # 5 mV quantization in degrees
    data = MeasuredData(time_s=t, command_deg=u, position_deg=u, metadata={"maneuver": spec})
    (seg,) = recognize(data).of("sweep")
    assert t[seg.start] == pytest.approx(1.0, abs=0.01)
    assert t[seg.stop - 1] == pytest.approx(59.0, abs=0.01)


def test_a_threshold_test_quantised_by_the_command_counts_is_moving_not_a_staircase():
    """A 0.2 Hz triangle growing to 0.3° logged in 0.01° counts at 250 Hz spans only 60 counts (under
    the 100 a command's counts usually span) but travels hundreds of them one count at a time: it is a
    static threshold test, not hundreds of one-count steps."""
    t = np.arange(0, 40, 0.004)
    u = 0.3 * t / 40 * (2 / np.pi) * np.arcsin(np.sin(2 * np.pi * 0.2 * t))
    uq = 0.01 * np.round(u / 0.01)
    y = np.where(np.abs(u) > 0.03, u - 0.03 * np.sign(u), 0.0) + np.random.default_rng(4).normal(0, 0.001, t.size)
    rec = recognize(MeasuredData(time_s=t, command_deg=uq, position_deg=y))
    assert [s.kind for s in rec.segments] == ["static_threshold"]
    assert rec.segments[0].params["freq_hz"] == pytest.approx(0.2, rel=0.05)
    assert rec.edge_threshold_deg == pytest.approx(0.03)  # three counts: a one-count change is no edge


def test_sine_dwells_one_after_another_are_each_a_dwell_not_a_sweep():
    """Tones at 0.6, 1.5 and 4 Hz, 6 s each, joined without a pause (a period piecewise constant,
    shrinking in steps): three sine dwells, each analysed (a 10 ms delay: phase −360·f·τ)."""
    t = np.arange(0, 18, 0.004)
    k = np.minimum((t // 6).astype(int), 2)
    f = np.array([0.6, 1.5, 4.0])[k]
    u = 0.7 * np.sin(2 * np.pi * f * (t - 6 * k))
    y = delayed(t, u, 0.01) + np.random.default_rng(5).normal(0, 0.002, t.size)
    data = MeasuredData(time_s=t, command_deg=u, position_deg=y)
    rec = recognize(data)
    assert [s.kind for s in rec.segments] == ["sine"] * 3
    assert [s.params["freq_hz"] for s in rec.segments] == pytest.approx([0.6, 1.5, 4.0], rel=0.01)
    assert [round(t[s.start]) for s in rec.segments] == [0, 6, 12]
    dwells = [r for r in analyze_record(data).results["sine_dwell"] if r.output == "position_deg"]
    assert [r.freq_hz for r in dwells] == pytest.approx([0.6, 1.5, 4.0], rel=0.01)
    lag = 0.01 - 0.004 / 2  # the analysis takes a held command's half sample of hold out
    assert [r.phase_deg for r in dwells] == pytest.approx([-360 * fr * lag for fr in (0.6, 1.5, 4.0)], abs=0.3)
    # a sweep over the same band (its period shrinks steadily) is still one sweep
    sweep = np.sin(2 * np.pi * (0.6 * t + (4.0 - 0.6) * t**2 / (2 * 18)))
    assert [s.kind for s in recognize(MeasuredData(time_s=t, command_deg=sweep, position_deg=sweep)).segments] \
        == ["sweep"]
