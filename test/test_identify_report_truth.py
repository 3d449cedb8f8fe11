"""What ``ema identify`` says is what it found: one final model in report.md, on the console and in the JSON.

Also the figures beside it: a discovered term holds only when its halves agree within their uncertainty;
no static threshold wider than the error the output settles to; a named effect that explains the record
stands against discovered terms that match it; correlations within ±1; an uncertainty of exactly 0 is
not determined; units and evidence that fit the record; a record of no X-43A channel is a generic actuator.
"""

from __future__ import annotations

import json
import re
from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest
from identgen import make_record

from ema_sim.analysis.formatting.units import in_unit, texts_in_unit
from ema_sim.analysis.pipeline import resolve_channel
from ema_sim.config import GENERIC, load_channel
from ema_sim.identify.discovery import Closure, Discovery, named_stands
from ema_sim.identify.effects import BY_KEY, FREE, ramps
from ema_sim.identify.fit import block_covariance, correlation
from ema_sim.identify.identification import Search, identify
from ema_sim.identify.library import library
from ema_sim.identify.record import prepare
from ema_sim.identify.regression import Term, _halves, stepwise
from ema_sim.identify.report import summary, to_json, write_json, write_report
from ema_sim.identify.settled import settled_error

WING = load_channel("left_wing")


def _section(md: str, title: str) -> str:
    m = re.search(rf"^## {re.escape(title)}\s*$(.*?)(?=^## |\Z)", md, re.M | re.S)
    assert m is not None, f"no section {title!r} in report.md"
    return m.group(1)


def _rows(section: str) -> list[list[str]]:
    """A Markdown table's body rows (header and rule left out), cells stripped."""
    rows = [[c.strip() for c in line.strip().strip("|").split("|")] for line in section.splitlines()
            if line.startswith("|")]
    return [r for r in rows[2:] if r]


@pytest.fixture(scope="module")
def drag_run(tmp_path_factory):
    """A record whose reading carries a drag no named effect explains, of no X-43A channel: identified once."""
    data = make_record({}, seed=4, duration_s=12.0, sample_hz=500.0, outputs=("position_deg",))
    v = np.gradient(data.position_deg, data.time_s)
    moving = np.abs(v) > 0.02 * np.percentile(np.abs(v), 99)
    data = replace(data, position_deg=data.position_deg + 0.05 * np.where(moving, np.sign(v), 0.0),
                   metadata={"generator": "test"})
    channel, note = resolve_channel(data, None)
    record = prepare(data, channel, channel_note=note)
    result = identify(record, "second_order", search=Search(max_effects=3, escalate=False))
    report = to_json(result, "drag.csv")
    out = tmp_path_factory.mktemp("drag")
    write_json(report, out / "report.json")
    md = write_report(result, report, out / "report").read_text(encoding="utf-8")
    doc = json.loads((out / "report.json").read_text(encoding="utf-8"))
    return doc, md, summary(report)


def test_report_md_the_console_and_the_json_carry_the_same_final_model_term_by_term(drag_run):
    doc, md, console = drag_run
    final = doc["final"]
    assert doc["discovered_terms"], f"no discovered term kept: {final['model']}"
    assert f"`{final['model']}`" in _section(md, "Final model")
    assert f"final model: {final['model']}" in console
    terms = {r[0]: r for r in _rows(_section(md, "Final model"))}
    for t in doc["discovered_terms"]:
        row = terms.pop(t["term"])
        assert row[1] == t["on"]
        assert row[2] == t["placement"]
        assert [float(c) for c in row[3].split(",")] == pytest.approx(t["coefficient"], rel=1e-5)
        assert f"discovered {t['term']} ({t['on']}, {t['placement']})" in console
    assert not terms, f"report.md has terms the JSON lacks: {list(terms)}"
    params = {r[0]: float(r[1]) for r in _rows(_section(md, "Final parameters"))}
    assert params == pytest.approx(final["params"], rel=1e-5)
    assert "None: no candidate paid" not in _section(md, "Effects added")


def test_a_record_of_no_x43a_channel_is_a_generic_actuator_with_its_travel_from_the_record(drag_run):
    doc, md, _ = drag_run
    assert doc["channel"] == GENERIC
    assert doc["travel_deg"]["source"].startswith("data")
    assert "generic actuator" in md
    assert "left_wing" not in md


def test_halves_that_disagree_beyond_their_uncertainty_do_not_hold():
    t = np.arange(8000) / 200.0
    u = 5.0 * np.sign(np.sin(2 * np.pi * 0.37 * t)) + 3.0 * np.sin(2 * np.pi * 1.3 * t)
    x = np.convolve(u, np.ones(20) / 20, mode="same")
    v = np.gradient(x, t)
    drag = np.where(np.abs(v) > 0.01 * np.percentile(np.abs(v), 99), np.sign(v), 0.0)
    gain = np.where(t < t[-1] / 2, 0.02, 0.025)  # a 25 % change, far beyond the halves' uncertainty
    e = gain * drag + np.random.default_rng(5).normal(0.0, 0.001, t.size)
    reg = stepwise(e, library(t, u, x, v, None, e, np.ones(t.size, dtype=bool)), 0.001)
    held = {s.term.name: s for s in reg.selected}
    dropped = {s.term.name: s for s in reg.dropped}
    assert "sign(rate)" not in held
    assert "beyond their uncertainty" in dropped["sign(rate)"].why


def test_halves_never_agree_beyond_six_of_the_whole_record_s_reported_sigma():
    rng = np.random.default_rng(11)
    n = 20_000
    column = rng.normal(0.0, 1.0, n)
    noise = rng.normal(0.0, 1.0, n)
    whole = 1.0 / np.sqrt(n)  # the coefficient's standard error on white noise of unit rms
    step = 5.0 * whole  # the halves' coefficients 5 whole-record sigma apart: within 3·(2σ), chance can do it
    e = np.where(np.arange(n) < n // 2, 0.1, 0.1 + step) * column + noise
    term = Term("x", column[:, None], "", "a column", "motion")
    holds, _, (first, second) = _halves(e, [term], np.array([whole]))[term.name]
    assert holds
    assert 4.0 * whole < second[0] - first[0] < 6.0 * whole
    # the same halves against a whole record that reports half that uncertainty: 10 of its sigma apart
    holds, why, _ = _halves(e, [term], np.array([whole / 2.0]))[term.name]
    assert not holds
    assert "beyond their uncertainty" in why


def test_a_threshold_wider_than_the_settled_error_is_not_added():
    t = np.arange(4000) / 100.0
    cmd = np.repeat(np.tile([0.0, 1.0], 20), 100)
    pos = cmd + 0.004 * np.sign(np.sin(t))  # settles within 0.004 of the command at every hold
    settled = settled_error(t, cmd, pos, 0.001)
    assert settled is not None
    assert settled.max_abs == pytest.approx(0.004)
    problem = SimpleNamespace(settled=settled, sigma_deg={"position_deg": 0.001}, outputs=["position_deg"],
                              data=SimpleNamespace(unit="mm"))
    check = BY_KEY["static_threshold/feedback"].check
    ctx = SimpleNamespace(problem=problem)
    # the largest settled error and half a count: what the holds show, no noise margin added to the point
    assert settled.bound == pytest.approx(0.004 + 0.0005)
    assert check({"threshold_deg": 0.0045}, ctx) is None
    assert check({"threshold_deg": 0.0047}, ctx) is not None
    why = check({"threshold_deg": 0.764}, ctx)
    assert why is not None
    assert "settles to" in why


def test_an_output_in_counts_that_settles_on_its_command_leaves_room_for_half_a_count_and_no_more():
    """The floor of an output that sits on its counts is the count's own q/√12: the half count covers it, once."""
    t = np.arange(4000) / 100.0
    cmd = np.repeat(np.tile([0.0, 1.0], 20), 100)
    settled = settled_error(t, cmd, cmd.copy(), 0.01)
    assert settled is not None
    assert settled.median_abs == 0.0
    assert settled.bound == pytest.approx(0.005)
    assert settled.max_se == 0.0


def test_the_largest_settled_error_carries_the_standard_error_of_its_own_median():
    """Each hold's settled error is a median of its tail: its uncertainty is the tail's noise × √(π/2)/√n."""
    t = np.arange(40000) / 1000.0
    cmd = np.repeat(np.tile([0.0, 1.0], 20), 1000)
    offset = np.repeat(np.tile([0.002, -0.003], 20), 1000)
    offset[-1000:] = 0.006  # one hold stops furthest off
    pos = cmd + offset + np.random.default_rng(7).normal(0.0, 0.002, t.size)
    settled = settled_error(t, cmd, pos)
    assert settled is not None
    assert settled.max_abs == pytest.approx(0.006, abs=3e-4)
    assert settled.max_se == pytest.approx(1.2533 * 0.002 / np.sqrt(300), rel=0.15)
    assert settled.bound == settled.max_abs  # its uncertainty is said beside the bound, not added to it
    text = settled.held(lambda v: f"{v:.2g}", "mm")
    assert text.startswith(f"at least {settled.bound:.2g} ± ")
    assert "no hold shows" in text


def test_a_fitted_dead_band_is_bounded_by_what_the_records_holds_allow():
    """The record's own bound lowers the search's upper bound, never below its lower one."""
    free = FREE["threshold_deg"]
    assert free.capped(None) is free
    assert free.capped(free.high * 2) is free
    capped = free.capped(0.05)
    assert capped.high == 0.05
    assert capped.low == free.low
    assert free.capped(free.low / 10).high == free.low


def test_a_named_effect_that_explains_the_record_stands_and_a_matching_term_is_its_equivalent():
    closure = Closure("inside the loop", {"command": [("position", (-0.035,), (0.001,), "mm/mm")]}, {}, {}, -901.0,
                      kept=True)
    disc = Discovery(closures=[closure])
    assert disc.equivalents(["command_gain"]) == [("command_gain", "position")]
    assert disc.equivalents(["rate_limit"]) == []
    assert named_stands({"position_deg": 0.0031}, {"position_deg": 0.003})
    assert not named_stands({"position_deg": 0.009}, {"position_deg": 0.003})


@pytest.mark.slow
def test_a_command_gain_on_a_clean_second_order_record_is_found_and_kept():
    data = make_record({"command_gain": -0.035}, seed=17, duration_s=15.0, noise_deg=(0.003, 0.002))
    result = identify(prepare(data, WING), "second_order", {})
    assert [s.effect for s in result.steps] == ["command_gain"]
    assert result.final.params.kb == pytest.approx(-0.035, rel=0.05)
    assert not result.removed


def test_correlations_stay_within_one_on_a_coloured_residual():
    rng = np.random.default_rng(7)
    n = 3000
    base = rng.normal(size=n)
    jac = np.column_stack([base, base + 1e-3 * rng.normal(size=n), rng.normal(size=n)])
    residual = np.convolve(rng.normal(size=n), np.ones(40), mode="same")  # strongly coloured
    corr = correlation(block_covariance([residual], [jac]))
    finite = corr[np.isfinite(corr)]
    assert np.all(np.abs(finite) <= 1.0)
    assert correlation(np.array([[1.0, 1.2], [1.2, 1.0]]))[0, 1] == 1.0


def test_an_uncertainty_of_exactly_zero_is_not_determined():
    report = {"data": "x", "samples": 10, "sample_hz": 100.0, "noise_deg": {"position_deg": 0.01}, "unit": "mm",
              "baseline": {"model": "second_order", "params": {"wn_rad_s": 50.0}, "rms_deg": {"position_deg": 0.02}},
              "added": [{"effect": "static_threshold", "params": {"threshold_deg": 0.01},
                         "uncertainty": {"threshold_deg": None}, "rms_deg_before": {"position_deg": 0.02},
                         "rms_deg_after": {"position_deg": 0.01}, "evidence": "e"}],
              "discovered_terms": [{"term": "sign(rate)", "on": "position", "placement": "reading",
                                    "coefficient": [0.01], "uncertainty": [None], "unit": "mm"}],
              "final": {"model": "m", "params": {"wn_rad_s": 50.0}, "rms_deg": {"position_deg": 0.01},
                        "rms_over_noise": {"position_deg": 1.0}}}
    text = summary(report)
    assert "± not determined" in text
    assert "± 0" not in text


def test_texts_of_a_mm_record_are_in_mm_and_phases_stay_in_degrees():
    assert in_unit("square wave 0.5 Hz, ±0.5°, 23 edges", "mm") == "square wave 0.5 Hz, ±0.5 mm, 23 edges"
    assert in_unit("peak rate 12.1 °/s; rms, deg", "mm") == "peak rate 12.1 mm/s; rms, mm"
    assert in_unit("harmonics: phase -0.6°, -2.0°", "mm") == "harmonics: phase -0.6°, -2.0°"
    assert in_unit("±0.5°", "deg") == "±0.5°"
    doc = texts_in_unit({"data": "a_0.5°.csv", "note": ["step +0.30°"]}, "mm")
    assert doc == {"data": "a_0.5°.csv", "note": ["step +0.30 mm"]}


def test_evidence_speaks_of_ramps_only_when_the_command_ramps():
    square = np.repeat(np.tile([0.0, 1.0], 10), 50)
    ramp = np.linspace(0.0, 1.0, 200)
    effect = BY_KEY["static_threshold/feedback"]
    assert not ramps(square)
    assert "ramps" not in effect.evidence(square)
    assert "ramps" in effect.evidence(ramp)


def test_a_generic_actuator_s_report_exports_on_the_stand_in_configuration(tmp_path):
    from ema_sim.export.target import resolve  # noqa: PLC0415 - the export layer only for this test

    path = tmp_path / "report.json"
    path.write_text(json.dumps({"channel": GENERIC, "baseline": {"model": "second_order"}, "final": {
        "model": "second_order + time_delay", "params": {"wn_rad_s": 61.0, "zeta": 0.7, "delay_s": 0.006},
        "fields": {"wn_rad_s": "wn_rad_s", "zeta": "zeta", "delay_s": "delay_s"}}}))
    target = resolve(str(path))
    assert target.channel == "left_wing"
    assert target.params.delay_s == 0.006
