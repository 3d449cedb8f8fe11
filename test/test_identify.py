"""Identification finds undeclared effects in measured-like data, and adds nothing when there is none.

Data come from ``identgen``: LOAC (not the simulator identification fits with) on a realistic test
sequence with sensor noise. Each case names its effect, a parameter value and a seed; values and seeds
vary across cases so nothing is tuned to one.
"""

from __future__ import annotations

import json
import re
import tempfile

import numpy as np
import pytest
from identgen import EFFECT_FIELDS as FIELD
from identgen import hoad3_record, make_record

from ema_sim.analysis.estimation.noise import input_independence, noise_floor, whiteness
from ema_sim.cli import main
from ema_sim.config import load_channel
from ema_sim.identify.diagnosis import diagnose
from ema_sim.identify.identification import Search, identify
from ema_sim.identify.record import prepare
from ema_sim.identify.report import to_json, write_report
from ema_sim.io.bag import write_bag
from ema_sim.io.csv import write_csv

DURATION_S = 15.0
"""The records' length: the test sequence fitted into 15 s finds every effect within the checks' tolerances
(measured; at 30 s the file took twice the time)."""
HYSTERESIS_S = 30.0
"""Hysteretic damping needs the slow load's three cycles (0.1 Hz): fitted at 2/3 of the truth on 15 s (measured)."""
HOAD3_S = 30.0
"""The slow HOAD3 runs keep the 30 s records their measured figures come from."""
NOISE = (0.003, 0.002)
WING = load_channel("left_wing")


def run_case(effects, seed, *, declared=None, noise=NOISE, duration_s=DURATION_S, **kw):
    data = make_record(effects, seed=seed, duration_s=duration_s, noise_deg=noise, **kw)
    return identify(prepare(data, WING), "second_order", declared or {})


COAST_NOISE = 2.0
"""The error, in noise floors, a final model may leave when its threshold is held at the holds' bound (below)."""


def check(result, effects, expected_names, noise=NOISE):
    names = [s.effect for s in result.steps]
    assert sorted(set(names)) == sorted(expected_names), f"added {names}"
    leaves = 1.5
    for name, value in effects.items():
        if name == "compliance" and "compliance" not in expected_names:
            continue  # declared, not added
        fitted = getattr(result.final.params, FIELD[name])
        assert fitted == pytest.approx(value, rel=0.2), f"{name}: fitted {fitted}, true {value}"
        if name == "static_threshold":
            leaves = max(leaves, check_threshold_bound(result, value))
    for output, sigma in zip(("position_deg", "surface_deg"), noise, strict=True):
        err = result.problem.errors_deg(result.final.sim)[output]
        assert np.sqrt(np.mean(err**2)) <= leaves * sigma, f"{output} rms above {leaves:g}× noise"


def check_threshold_bound(result, true_deg):
    """A threshold is no wider than the largest error the output settles to; held there, it is said to be a bound.

    The generator's servo stops driving at its threshold and the output coasts inward, so every hold settles
    inside the band (at 0.0264 of 0.03, 0.077 of 0.08, 0.037 of 0.04 on these seeds, each ±0.0003): the true
    edge is a figure no hold shows. Held at the largest settled error, the fit reports it as "at least" that,
    with the edge the fit reaches without the bound (the true one) beside it in the evidence; the coast it
    leaves unexplained (the model stops at the bound and coasts further in) costs up to
    :data:`COAST_NOISE` noise floors instead of 1.5. Returns the noise floors the final model may leave.
    """
    settled = result.problem.settled
    fitted = result.final.params.threshold_deg
    assert fitted <= settled.bound * (1.0 + 1e-9), "a threshold wider than any hold shows"
    assert fitted <= true_deg, "a lower bound above the true edge"
    (step,) = [s for s in result.steps if s.effect == "static_threshold"]
    doc = to_json(result, "threshold.csv")
    if fitted < settled.bound * (1.0 - 1e-6):
        assert "lower_bound" not in doc["final"]
        return 1.5  # the fit stopped inside the bound: a point figure that explains the record
    assert "at least" in step.evidence
    assert "no hold shows" in step.evidence
    asked = re.search(r"the fit asked for ([-+.e0-9]+) deg", step.evidence)
    assert asked is not None, step.evidence
    assert float(asked.group(1)) == pytest.approx(true_deg, rel=0.1)  # the edge the dynamics show, said beside
    assert doc["final"]["lower_bound"]["threshold_deg"].startswith("at least")  # the JSON says it is a bound
    with tempfile.TemporaryDirectory() as folder:
        md = write_report(result, doc, folder).read_text(encoding="utf-8")
    reported = doc["final"]["params"]["threshold_deg"]
    assert re.search(rf"^\| threshold_deg \| {reported:.6g} \| .*a lower bound", md, re.M)  # so does report.md
    return COAST_NOISE


SINGLE = [
    ("time_delay", 0.005, 11),
    ("time_delay", 0.013, 12),
    ("lag_filter", 12.0, 13),
    ("lag_filter", 32.0, 14),
    ("lag_filter/feedback", 25.0, 15),
    ("command_gain", 0.025, 16),
    ("command_gain", -0.04, 17),
    ("command_bias", 0.08, 18),
    ("command_bias", -0.15, 19),
    ("quantization", 0.02, 20),
    ("quantization", 0.035, 21),
    ("rate_limit", 70.0, 22),
    ("rate_limit", 100.0, 23),
    ("static_threshold", 0.03, 24),
    ("static_threshold", 0.08, 25),
    ("free_play", 0.12, 26),
    ("free_play", 0.3, 27),
    ("compliance", 0.15, 28),
    ("compliance", 0.4, 29),
]


@pytest.mark.parametrize(("effect", "value", "seed"), SINGLE, ids=[f"{e}={v:g}" for e, v, _ in SINGLE])
def test_each_effect_on_its_own_is_named_fitted_and_leaves_noise(effect, value, seed):
    result = run_case({effect: value}, seed)
    check(result, {effect: value}, [effect.split("/")[0]])
    if effect == "lag_filter/feedback":
        assert result.steps[0].where == "feedback"


@pytest.mark.parametrize(("h", "seed"), [(3344.84, 31), (8000.0, 32)])
def test_hysteretic_damping_on_a_model_that_declares_its_compliance(h, seed):
    result = run_case({"compliance": 0.3, "hysteretic_damping": h}, seed,
                      declared={"compliance_deg_per_kinlb": 0.3}, duration_s=HYSTERESIS_S)
    check(result, {"hysteretic_damping": h}, ["hysteretic_damping"])
    assert result.final.params.compliance_deg_per_kinlb == pytest.approx(0.3, rel=0.05)
    assert result.final.params.hysteresis_freq_hz == pytest.approx(0.1, rel=0.05)


def test_hinge_moment_sign_with_a_declared_compliance():
    result = run_case({"compliance": 0.3}, 33, declared={"compliance_deg_per_kinlb": 0.3},
                      reverse_load_column=True)
    check(result, {}, ["hinge_moment_sign"])
    assert result.final.flip
    assert result.final.params.compliance_deg_per_kinlb == pytest.approx(0.3, rel=0.05)


def test_hinge_moment_sign_found_with_the_compliance_it_hides():
    result = run_case({"compliance": 0.25, "free_play": 0.2}, 34, reverse_load_column=True)
    check(result, {"compliance": 0.25, "free_play": 0.2}, ["hinge_moment_sign", "compliance", "free_play"])
    assert result.final.flip
    assert "reversed" in result.steps[0].evidence


PAIRS = [
    ({"time_delay": 0.006, "compliance": 0.3}, 41),
    ({"free_play": 0.15, "rate_limit": 90.0}, 42),
    ({"command_gain": -0.02, "command_bias": 0.08}, 43),
    ({"lag_filter": 20.0, "quantization": 0.02}, 44),
    ({"static_threshold": 0.04, "time_delay": 0.01}, 45),
    ({"quantization": 0.02, "command_bias": 0.05}, 46),
    ({"compliance": 0.3, "hysteretic_damping": 5000.0}, 47),
]


SLOW_PAIRS = {44, 45}
"""The two slowest pairs run with ``make test-slow`` (the suite's budget); each effect alone stays in the suite."""


@pytest.mark.parametrize(("effects", "seed"), [
    pytest.param(e, seed, id="+".join(e), marks=[pytest.mark.slow] if seed in SLOW_PAIRS else [])
    for e, seed in PAIRS])
def test_pairs_of_effects_are_both_found(effects, seed):
    result = run_case(effects, seed, duration_s=HYSTERESIS_S if "hysteretic_damping" in effects else DURATION_S)
    check(result, effects, [e.split("/")[0] for e in effects])


@pytest.mark.parametrize(("seed", "noise"), [(51, (0.003, 0.002)), (52, (0.001, 0.004)), (53, (0.006, 0.006))])
def test_null_case_adds_nothing(seed, noise):
    result = run_case({}, seed, noise=noise)
    assert result.steps == []
    (effects,) = [s for s in result.stages if s.stage == "effects"]
    assert effects.reason.endswith(f"({result.search_ended})")  # the report says why the search ended
    assert result.search_ended.startswith("it stopped")
    for output, sigma in zip(("position_deg", "surface_deg"), noise, strict=True):
        assert result.problem.sigma_deg[output] == pytest.approx(sigma, rel=0.1)


def test_position_only_data_cannot_see_compliance_outside_the_loop():
    result = run_case({"compliance": 0.3}, 54, outputs=("position_deg",))
    assert result.steps == []


def test_noise_floor_and_residual_diagnostics():
    rng = np.random.default_rng(3)
    t = np.arange(20000) / 1000.0
    smooth = np.sin(2 * np.pi * 2.0 * t) + np.where(t > 10, 5.0, 0.0)
    white = rng.normal(0, 0.004, t.size)
    assert noise_floor(smooth + white) == pytest.approx(0.004, rel=0.05)
    assert whiteness(white).white
    coloured = np.convolve(white, np.ones(20) / 20, mode="same")
    assert not whiteness(coloured).white
    assert input_independence(white, smooth).independent
    assert not input_independence(white + 0.01 * np.gradient(smooth), smooth).independent


def test_cli_writes_the_contract_json_and_report(tmp_path, capsys):
    data = make_record({"time_delay": 0.007}, seed=61, duration_s=DURATION_S)
    csv = tmp_path / "h.csv"
    write_csv(csv, {k: getattr(data, k) for k in ("time_s", "command_deg", "position_deg", "surface_deg",
                                                   "hinge_moment_inlb")}, {"channel": "left_wing"})
    out = tmp_path / "h.json"
    assert main(["identify", str(csv), "--json", str(out), "--report", str(tmp_path / "rep"), "-q"]) == 0
    report = json.loads(out.read_text())
    for key in ("data", "outputs", "noise_deg", "baseline", "added", "final"):
        assert key in report
    assert report["baseline"]["model"] == "second_order"
    assert set(report["baseline"]["params"]) == {"wn_rad_s", "zeta"}
    (added,) = report["added"]
    assert added["effect"] == "time_delay"
    assert added["params"]["delay_s"] == pytest.approx(0.007, rel=0.05)
    assert set(added["rms_deg_before"]) == {"position_deg", "surface_deg"}
    assert added["evidence"]
    assert report["final"]["params"]["delay_s"] == pytest.approx(0.007, rel=0.05)
    assert report["final"]["rms_deg"]["position_deg"] < 0.2 * report["baseline"]["rms_deg"]["position_deg"]
    assert (tmp_path / "rep" / "report.md").is_file()
    assert (tmp_path / "rep" / "residual.png").stat().st_size > 10_000
    assert "time_delay" in capsys.readouterr().out


@pytest.mark.parametrize(
    ("content", "message"),
    [
        ("time_s,command_deg\n" + "\n".join(f"{i / 1000},0" for i in range(200)), "position_deg"),
        ("time_s,command_deg,position_deg\n" + "\n".join(f"{i / 1000},x,0" for i in range(200)), "not a number"),
        ("time_s,command_deg,position_deg\n1,2,3\n", "at least 100"),
    ],
)
def test_malformed_data_is_one_line_and_exit_2(tmp_path, capsys, content, message):
    path = tmp_path / "bad.csv"
    path.write_text(content)
    assert main(["identify", str(path), "-q"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1
    assert message in err[0]


@pytest.mark.parametrize(("truth", "in_loop"), [
    ({"current_limit": {"accel_limit_dps2": 3000.0, "velocity_loop_hz": 40.0}, "time_delay": 0.006}, True),
    ({"lag_filter": 6.0}, True),
    ({"linkage_mode": {"linkage_freq_hz": 18.0, "linkage_zeta": 0.12}}, False),
], ids=["current_limit+delay", "command_lag", "linkage_mode"])
def test_the_diagnosis_tells_an_error_inside_the_servo_loop_from_one_outside(truth, in_loop):
    """Nothing added (max_effects=0), so the declared second order leaves the truth's effect in the residual.
    A servo the model lacks moves the actuator, which the LVDT and the surface both see: measured share 1.0
    for both servo cases. A linkage mode is the surface's own: measured share 0.0. The warnings say which, and
    that parameters fitted under such a residual are equivalents."""
    data = make_record(truth, seed=3, duration_s=20.0)
    result = identify(prepare(data, WING), search=Search(max_effects=0))
    assert result.physical is None  # nothing replaces a model declared with no effects
    assert not result.escalated
    diagnosis = diagnose(result)
    surface = diagnosis.outputs["surface_deg"]
    assert surface.structured
    assert surface.actuator_share is not None
    assert (surface.actuator_share >= 0.9) if in_loop else (surface.actuator_share <= 0.1)
    assert surface.in_loop is in_loop
    inside = [w for w in diagnosis.warnings if "the actuator's motion is off inside the servo loop" in w]
    assert len(inside) == (1 if in_loop else 0)
    if in_loop:
        assert "--model hoac1 or hoad3" in inside[0]
    assert any(w.startswith("the fitted parameters are equivalents") for w in diagnosis.warnings)


@pytest.mark.slow
def test_across_fidelities_hoad3_data_declared_loada():
    """HOAD3 plays the real actuator; LOADA is declared. What LOADA lacks: the linkage compliance
    outside the servo loop and the LVDT filter. Both are found and the error drops on both outputs."""
    data = hoad3_record(seed=71, duration_s=HOAD3_S)
    result = identify(prepare(data, WING), "loada", search=Search(escalate=False))
    found = {(s.effect, s.where) for s in result.steps}
    assert ("compliance", "surface") in found
    assert found & {("lag_filter", "feedback"), ("feedback_filter", "feedback")}
    before = {o: float(np.sqrt(np.mean(e**2))) for o, e in result.problem.errors_deg(result.baseline.sim).items()}
    after = {o: float(np.sqrt(np.mean(e**2))) for o, e in result.problem.errors_deg(result.final.sim).items()}
    assert after["position_deg"] < 0.5 * before["position_deg"]
    assert after["surface_deg"] < 0.8 * before["surface_deg"]
    # HOAD3's wing linkage (illustrative curves): about 0.5°/1000 in·lb total, LVDT filter 13.4 Hz.
    assert 0.3 < result.final.params.compliance_deg_per_kinlb < 0.7
    lvdt_hz = (result.final.params.zeta * result.final.params.wn_rad_s / np.pi
               if result.final.params.feedback_filter_in_loop else result.final.params.feedback_lag_hz)
    assert 8.0 < lvdt_hz < 18.0  # measured 16.3 Hz with the in-loop filter (it also carries the loop's own lag)
    # What is left on the surface is mostly the actuator's own motion (HOAD3's servo beyond a second order), and
    # the diagnosis says so instead of offering another surface effect (measured: 66 % on a 15 s record).
    surface = diagnose(result).outputs["surface_deg"]
    assert surface.in_loop
    assert result.physical is None  # --no-escalate keeps the declared family


@pytest.mark.slow
@pytest.mark.parametrize("declared_model", ["loada", "second_order"])
def test_hoad3_data_three_maneuvers_ends_with_the_drives_physics(declared_model):
    """HOAD3 plays the real actuator on three maneuvers (the test sequence in 15, 20 and 30 s under ±600, ±1000
    and ±400 in·lb), LOADA or the second order declared. The declared family with every effect that pays ends
    at 3.0–3.8× (position) and 18–23× (surface) its floor: it has run out of vocabulary. The tool then fits
    HOAD3's physical parameters (section 4.2.5's loop) and keeps them, with the equivalent beside: both
    outputs within 2× the floor (measured 1.07–1.08× / 1.12–1.15×), HOAD3's 4 ms and 2 ms delays found
    (within 0.02 ms), and every physical parameter fitted in two or more reports agrees across the maneuvers
    within 3σ (measured: 13 of 13 with LOADA)."""
    from ema_sim.identify.consistency import compare, parse_report  # noqa: PLC0415
    from ema_sim.identify.report import to_json  # noqa: PLC0415

    docs = []
    for seed, duration_s, amp in ((91, 15.0, 600.0), (92, 20.0, 1000.0), (93, 30.0, 400.0)):
        record = prepare(hoad3_record(seed=seed, duration_s=duration_s, load_amp_inlb=amp), WING)
        result = identify(record, declared_model)
        doc = json.loads(json.dumps(to_json(result, f"m{seed}.csv")))
        assert doc["final"]["model"] == "hoad3 (physical parameters fitted)"
        assert all(v <= 2.0 for v in doc["final"]["rms_over_noise"].values()), doc["final"]["rms_over_noise"]
        equivalent = doc["equivalent"]
        assert equivalent["model"].startswith(f"{declared_model} + ")
        assert max(equivalent["rms_over_noise"].values()) > 3.0
        assert "× the noise on" in equivalent["escalated_because"]
        assert any("ran out of vocabulary" in w for w in doc["warnings"])
        p = doc["final"]["params"]
        assert p["command_delay_s"] == pytest.approx(0.004, abs=1e-4)
        assert p["feedback_delay_s"] == pytest.approx(0.002, abs=1e-4)
        assert any("physical parameters fitted" in n for n in doc["notes"])
        docs.append(doc)
    consistency = compare([parse_report(d, f"m{i}.json") for i, d in enumerate(docs)])
    verdicts = {f.field: f.verdict for f in consistency.fields}
    compared = {f for f, v in verdicts.items() if v != "single"}
    assert compared >= {"command_delay_s", "feedback_delay_s", "position_gain_per_s", "velocity_gain_a_per_in_s",
                        "pwm_dead_band_v", "lvdt_filter_hz", "position_integral_per_s2",
                        "linkage_damping_lbf_s_per_in", "total_mean_stiffness_lbf_per_in", "surface_inertia_inlbs2"}
    assert all(verdicts[f] == "agree" for f in compared), verdicts


@pytest.mark.slow
def test_from_a_suite_bag_hoad3_declared_loada(tmp_path, capsys):
    """The same question asked of a rosbag2 bag in the node suite's format (200 Hz frames): LOADA's stages
    named, then HOAD3's physics kept (measured on a 30 s record: see docs/identify.md's suite-bag figures)."""
    data = hoad3_record(seed=73, duration_s=HOAD3_S)
    frames = slice(0, None, 5)  # the FMU's 200 Hz frames
    bag = write_bag(tmp_path / "hoad3_bag", {
        "time_s": data.time_s[frames], "command_deg": data.command_deg[frames],
        "position_deg": data.position_deg[frames], "surface_deg": data.surface_deg[frames],
        "hinge_moment_inlb": data.hinge_moment_inlb[frames]}, {"model": "hoad3"}, channel="left_wing", frame_hz=200.0)
    out = tmp_path / "bag.json"
    assert main(["identify", str(bag), "--model", "loada", "--json", str(out), "-q"]) == 0
    report = json.loads(out.read_text())
    assert report["sample_hz"] == pytest.approx(200.0)
    found = {(a["effect"], a["where"]) for a in report["added"]}
    assert ("compliance", "surface") in found
    assert found & {("lag_filter", "feedback"), ("feedback_filter", "feedback")}
    before, after = report["baseline"]["rms_deg"], report["final"]["rms_deg"]
    assert after["position_deg"] < 0.5 * before["position_deg"]
    assert after["surface_deg"] < 0.8 * before["surface_deg"]
    after = report.get("equivalent", report["final"])["rms_deg"]  # LOADA's own, escalated or not
    # the declared LOADA at 800 Hz with the fitted stages (in-loop filter, linkage): bounded, an error figure
    # well under the fit's residual (measured 0.0118° / 0.0116° against 0.0754° / 0.0418°; issue 13)
    impl = report["declared_implementation_error_deg"]
    assert set(impl) == {"position_deg", "surface_deg"}
    assert all(impl[o] < 0.5 * after[o] for o in impl), (impl, after)
    assert not any("diverges on this record" in w for w in report["warnings"])
    assert "loada" in capsys.readouterr().out
    # LOADA's family runs out of vocabulary on it; HOAD3's physics, fitted, ends within 3× the floor the bag
    # carries on both outputs and finds both delays
    assert report["final"]["model"] == "hoad3 (physical parameters fitted)"
    assert all(v <= 3.0 for v in report["final"]["rms_over_noise"].values()), report["final"]["rms_over_noise"]
    assert report["final"]["params"]["command_delay_s"] == pytest.approx(0.004, abs=3e-4)
    assert report["final"]["params"]["feedback_delay_s"] == pytest.approx(0.002, abs=3e-4)
