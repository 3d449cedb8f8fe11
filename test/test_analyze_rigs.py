"""Issue 24: ``ema analyze`` on other actuators' bench records, from a drive model of our own (:mod:`rigs`).

Every record is a single channel logged at 70–100 Hz with jittery integer-ms stamps, positions in
counts of 0.01, no metadata about the X-43A. Each record is written as the data contract's CSV, read
back and analysed once (module fixture); the tests then hold every figure to the issue: a periodic
waveform is one test averaged over its cycles, with the cycle-to-cycle spread as its uncertainty; a
frequency response only at the harmonics the waveform has, never ``ok`` under the coherence
threshold; no crosstalk or limit-cycle verdict without its measurement; steps read against the
command; the count grid stated; one slope for ``analyze`` and ``identify``; a progress line at once.
Each figure is either a measurement with its uncertainty or "not measured: why".
"""

import json
import math
from dataclasses import replace

import numpy as np
import pytest
from rigs import STEP_S, Drive, corpus, log, write_rig_csv

from ema_sim.analysis import pipeline
from ema_sim.analysis.estimation import grid
from ema_sim.analysis.estimation.frf import COHERENCE_GOOD
from ema_sim.analysis.estimation.noise import detect_resolution, output_noise
from ema_sim.analysis.pipeline import analyze_record
from ema_sim.analysis.report import record_json
from ema_sim.analysis.section2 import steps
from ema_sim.cli import main
from ema_sim.config import load_channel
from ema_sim.io.csv import read_csv

FAMILIES = {"square": "profiled square", "trapezoid": "trapezoid", "triangle": "triangle", "sine": "sine"}


@pytest.fixture(scope="module")
def rigs(tmp_path_factory):
    """Each record of the corpus: its truth, its CSV, its analysis and its JSON."""
    folder = tmp_path_factory.mktemp("rigs")
    out = {}
    for name, rec in corpus().items():
        path = write_rig_csv(rec, folder)
        ra = analyze_record(read_csv(path))
        out[name] = (rec, path, ra, json.loads(json.dumps(record_json(ra), allow_nan=False)))
    return out


def periodic(ra):
    (r,) = ra.results["periodic"]
    return r


def is_figure(reading):
    """A stated measurement with its uncertainty, or "not measured: why"."""
    if reading["value"] is None:
        return reading["statement"].startswith("not measured: ") and len(reading["statement"]) > 20
    return reading["sigma"] is not None and math.isfinite(reading["sigma"]) and reading["sigma"] >= 0.0


# ---------------------------------------------------------------------------------------------- 1: one test
@pytest.mark.parametrize("name", list(FAMILIES))
def test_a_periodic_waveform_is_one_test_averaged_over_its_cycles(rigs, name):
    rec, _, ra, _ = rigs[name]
    r = periodic(ra)
    p = r.periodicity
    assert p.shape == FAMILIES[name]
    assert p.period_s == pytest.approx(rec.period_s, rel=2e-3)
    assert rec.cycles - 1 <= p.cycles <= rec.cycles
    # no other test cut out of the cycles: every segment overlapping them is the one that stands for them
    overlapping = [s for s in ra.recognition.segments if s.start < p.stop and s.stop > p.start]
    assert len(overlapping) == 1
    assert "cycles" in overlapping[0].params


def test_the_profiled_square_was_cut_into_pieces_and_is_now_one_periodic_test(rigs):
    _, _, _ra, doc = rigs["square"]
    assert [t["kind"] for t in doc["tests"]] == ["periodic"]
    assert "profiled square" in doc["tests"][0]["evidence"]
    assert doc["crosstalk"] == []  # the pieces read as a "triangle" were judged as crosstalk


@pytest.mark.parametrize("name", list(FAMILIES))
def test_responses_only_at_the_harmonics_the_waveform_has(rigs, name):
    _, _, ra, _doc = rigs[name]
    r = periodic(ra)
    ks = [h.k for h in r.harmonics]
    assert ks == sorted(ks)
    assert set(ks) <= set(r.periodicity.harmonics)
    if name == "sine":
        assert ks == [1]
        assert r.bandwidth.value is None
        assert "single frequency" in r.bandwidth.statement
    else:
        assert r.periodicity.odd_only
        assert all(k % 2 == 1 for k in ks)
        assert any("no even harmonics" in n for n in r.notes)
    if name == "trapezoid":  # ramps of a fifth of the period: the 5th harmonic is a null of the waveform
        assert 5 not in ks
        assert 3 in ks
        assert 7 in ks


@pytest.mark.parametrize("name", [*list(FAMILIES), "stall"])
def test_every_periodic_figure_is_a_measurement_with_its_uncertainty_or_not_measured(rigs, name):
    _, _, _, doc = rigs[name]
    (p,) = doc["periodic"]
    for h in p["response"]:
        assert math.isfinite(h["gain_sigma_db"])
        assert math.isfinite(h["phase_sigma_deg"])
        if h["coherence"] < COHERENCE_GOOD:
            assert h["quality"] == "not_determined"
            assert "coherence" in h["note"]
        if h["quality"] == "ok":
            assert h["coherence"] >= COHERENCE_GOOD
    assert is_figure(p["bandwidth_3db_hz"])
    assert is_figure(p["lag_s"])
    for tr in p["transitions"]:
        assert is_figure(tr["settling_command"])
        assert tr["error_left_sigma"] is not None
        assert tr["error_left_sigma"] > 0
    assert p["repeatability_rms"] >= 0.0


def test_the_rate_limited_square_is_saturated_and_its_bandwidth_says_so(rigs):
    _, _, ra, _ = rigs["square"]
    r = periodic(ra)
    assert r.quality == "saturated"
    assert all(h.quality != "ok" for h in r.harmonics)
    assert r.bandwidth.quality in ("saturated", "not_determined")
    if r.bandwidth.value is not None:
        assert "rate-limited" in r.bandwidth.statement


def test_tracking_lags_are_read_at_the_fundamental_with_their_spread(rigs):
    for name in ("triangle", "sine"):
        r = periodic(rigs[name][2])
        assert r.lag.value is not None
        assert 0.0 < r.lag.value < 0.1
        assert 0.0 < r.lag.sigma < 0.1 * r.lag.value


# ---------------------------------------------------------------------------------------------- 2: no verdict
@pytest.mark.parametrize("name", ["triangle", "hold"])
def test_a_single_channel_gets_crosstalk_figures_but_no_verdict(rigs, name):
    _, _, _ra, doc = rigs[name]
    (c,) = doc["crosstalk"]
    assert c["verdict"] == "not judged"
    assert c["quality"] == "not_determined"
    assert c["threshold_deg"] is None
    assert c["below_threshold"] is None
    assert "no second channel moves" in c["quality_note"]
    assert "table A2's belongs to the X-43A" in c["threshold_source"]
    assert c["peak_to_peak_deg"] > 0.0


def test_crosstalk_is_judged_only_with_a_moving_second_channel_and_a_named_channel(rigs):
    _, _, ra, _ = rigs["hold"]
    named = replace(ra.data, metadata={"channel": "right_wing"})
    (c,) = analyze_record(named).results["crosstalk"]
    assert c.verdict == "not judged"  # an X-43A channel, but nothing else moves
    assert c.threshold_deg == pytest.approx(0.0075 * load_channel("right_wing").deg_per_in)
    suite = replace(ra.data, metadata={"channel": "right_wing", "test": "static_crosstalk"})
    (c,) = analyze_record(suite).results["crosstalk"]
    assert c.quality == "ok"
    assert c.verdict == "below"
    assert c.sources


def test_a_count_toggling_at_the_rigs_vibration_is_no_limit_cycle(rigs):
    _, _, _ra, doc = rigs["hold"]
    (d,) = doc["dither"]
    assert not d["detected"]
    assert "counts" in d["statement"]
    assert "needs 3" in d["statement"]


def test_a_limit_cycle_of_several_counts_is_still_one():
    t = np.arange(0.0, 12.0, STEP_S)
    rec = log("shaking", "hold", t, np.full(t.size, 3.005), Drive(), period_s=0.0, amp=0.0, cycles=0,
              rate_hz=80.0, seed=7, vibration=(0.05, 6.0))
    (d,) = analyze_record(rec.data).results["dither"]
    assert d.detected
    assert d.freq_hz == pytest.approx(6.0, rel=0.01)
    assert d.peak_to_peak_deg == pytest.approx(0.1, abs=0.015)


# ---------------------------------------------------------------------------------------------- 3: steps
def test_a_servo_that_stops_short_is_unsettled_with_the_error_left(rigs):
    _rec, _, ra, _ = rigs["stall"]
    steps_ = ra.results["steps"]
    assert len(steps_) >= 10
    for s in steps_:
        c = s.against_command
        assert not c.settled
        assert c.settling_final_s is not None  # flat: it "settles" against its own last value
        assert s.settling_s is not None
        assert abs(c.error_left) == pytest.approx(0.25, abs=0.015)  # the drive's truth: 3 °/s over kp 12
        assert np.sign(c.error_left) == -np.sign(s.command_step_deg)
    r = periodic(ra)
    for tr in r.transitions:
        assert tr.settled == 0
        assert tr.settling_command.value is None
        err, sigma = tr.error_left
        assert abs(err) == pytest.approx(0.25, abs=0.01)
        assert sigma < 0.01
        assert f"unsettled at {len(tr.readings)} of {len(tr.readings)}" in tr.settling_command.statement


def test_the_step_metrics_are_the_step_plots_own_numbers(rigs):
    """The plot of an unsettled step runs to the next edge: its last samples less the command are the error left."""
    _, _, ra, _ = rigs["stall"]
    d = ra.data
    for s in ra.results["steps"]:
        sl = steps.plot_window(ra, s)
        c = s.against_command
        assert sl.stop == s.stop
        y, u = d.position_deg[sl], d.command_deg[sl]
        assert float(np.mean(y[-3:])) - float(u[-1]) == pytest.approx(c.error_left, abs=1e-12)
        after = y[s.edge - sl.start:]
        past = max(0.0, float(np.max((after - u[-1]) * np.sign(s.command_step_deg))))
        assert 100 * past / abs(s.command_step_deg) == pytest.approx(c.overshoot_command_pct, abs=1e-9)


def test_a_settled_transition_settles_to_the_command(rigs):
    r = periodic(rigs["trapezoid"][2])
    for tr in r.transitions:
        assert tr.settled == len(tr.readings)
        s = tr.settling_command
        assert s.value is not None
        assert 0.0 <= s.value < 0.5
        assert s.sigma > 0.0


# ---------------------------------------------------------------------------------------------- 4: counts
@pytest.mark.parametrize("name", ["square", "trapezoid", "triangle", "sine", "stall", "hold"])
def test_the_count_grid_is_stated_and_the_floor_is_never_below_it(rigs, name):
    _, _, _ra, doc = rigs[name]
    assert doc["resolution_deg"]["position_deg"] == pytest.approx(0.01)
    assert doc["noise"]["position_deg"]["sigma"] >= 0.01 / math.sqrt(12) - 1e-12


def test_values_on_a_grid_give_the_count_when_the_changes_do_not():
    """A drive read every two to five counts: no change of one count, every value a hundredth."""
    rng = np.random.default_rng(3)
    y = np.round(3.0 + 0.01 * np.cumsum(rng.choice([0, 0, 0, 2, 3, -2, -5], 600)), 2)
    assert detect_resolution(y) is None
    nf = output_noise(y)
    assert nf.resolution == pytest.approx(0.01)
    assert nf.resolution_source == "values"
    assert nf.sigma >= 0.01 / math.sqrt(12)
    # a still output between moves of 2-5 counts: no white noise at all, and it used to read "noise 0, continuous"
    still = np.round(np.repeat(3.0 + 0.01 * np.cumsum(rng.choice([2, 3, -2, -5, 4], 20)), 40), 2)
    nf = output_noise(still)
    assert nf.white == 0.0
    assert nf.resolution == pytest.approx(0.01)
    assert nf.sigma == pytest.approx(0.01 / math.sqrt(12))
    continuous = np.sin(np.linspace(0, 20, 600)) + rng.normal(0, 0.003, 600)
    assert grid.value_grid(np.round(continuous, 6)) is None
    assert grid.value_grid(np.round(3.0 + 0.04 * np.sign(np.sin(np.arange(600))), 2)).q == pytest.approx(0.01)


# ---------------------------------------------------------------------------------------------- 5: one slope
def test_analyze_and_identify_measure_one_slope(rigs):
    from ema_sim.identify.problem import Problem  # noqa: PLC0415
    from ema_sim.identify.record import prepare  # noqa: PLC0415

    _rec, path, ra, doc = rigs["square"]
    data = read_csv(path)
    prepared = prepare(data, load_channel("left_wing"), channel_note="stand-in")
    slope = Problem(prepared.data, prepared.channel, noise=prepared.noise).measured_slew
    assert ra.slew == slope
    # the truth: the drive's output crosses the middle of each move at 103.9 °/s (its speed loop overshoots 95)
    assert ra.slew.rate == pytest.approx(103.9, rel=0.01)
    assert ra.slew.moves >= 8
    assert doc["slew"]["statement"].startswith(f"{ra.slew.rate:.4g}")
    assert "ema identify" in doc["slew"]["method"]
    assert periodic(ra).slope.rate == pytest.approx(ra.slew.rate, rel=0.01)


def test_no_slope_where_nothing_is_rate_limited(rigs):
    for name in ("trapezoid", "triangle", "sine", "stall"):
        _, _, ra, doc = rigs[name]
        assert ra.slew.rate is None
        assert doc["slew"]["statement"].startswith("not measured: ")


# ---------------------------------------------------------------------------------------------- 6: progress
def test_a_long_record_says_so_before_any_work(rigs, tmp_path, capsys, monkeypatch):
    _, path, _, _ = rigs["square"]
    seen = []
    real = pipeline.recognize

    def recognize(data):
        seen.append(capsys.readouterr().err)
        return real(data)

    monkeypatch.setattr(pipeline, "recognize", recognize)
    out = tmp_path / "a.json"
    assert main(["analyze", str(path), "--json", str(out)]) == 0
    assert seen
    assert seen[0].startswith(f"analysing {path}: ")
    doc = json.loads(out.read_text(), parse_constant=lambda c: pytest.fail(f"non-strict JSON: {c}"))
    assert doc["records"][0]["periodic"][0]["shape"] == "profiled square"
