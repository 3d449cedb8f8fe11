"""``ema identify-consistency``: parameters of one actuator identified from several maneuvers, compared.

Fast: the reports are built here, shaped like :func:`ema_sim.identify.report.to_json`'s output; the
end-to-end check that runs ``ema identify`` on three records is marked slow.
"""

import json
import math

import pytest
from identgen import make_record
from scipy.stats import chi2

from ema_sim.cli import main
from ema_sim.config import load_channel
from ema_sim.identify.consistency import compare, compare_field, format_table, parse_report, read_reports
from ema_sim.io.csv import write_csv
from ema_sim.models.second_order import SecondOrderParams

OWN = {"wn_rad_s": "wn_rad_s", "zeta": "zeta", "delay_s": "delay_s"}
TRUTH = {"wn_rad_s": 69.0, "zeta": 0.73, "delay_s": 0.007}
SIGMA = {"wn_rad_s": 1.0, "zeta": 0.005, "delay_s": 0.0002}


def report(params, sigma, *, fields=None, channel="left_wing", added=(), rms=(0.012, 0.0022),
           noise=(0.0113, 0.002), not_determined=(), data="rec.csv", model="loada"):
    """An ``ema identify`` report as ``to_json`` writes it (the keys a reader meets, with the same nesting)."""
    fields = fields if fields is not None else {k: k for k in params}
    outputs = ["position_deg", "surface_deg"]
    rms_deg = dict(zip(outputs, rms, strict=True))
    noise_deg = dict(zip(outputs, noise, strict=True))
    return {
        "data": data,
        "outputs": outputs,
        "unit": "deg",
        "noise_deg": noise_deg,
        "resolution_deg": {"position_deg": 0.02125, "surface_deg": None},
        "reference": {"model": "position/surface = command", "rms_deg": {"position_deg": 2.1, "surface_deg": 1.9},
                      "max_abs_deg": {"position_deg": 20.0, "surface_deg": 20.3}},
        "baseline": {"model": model, "params": {"wn_rad_s": 74.2, "zeta": 0.63},
                     "rms_deg": {"position_deg": 0.29, "surface_deg": 0.12}, "start": None},
        "added": [{"effect": e, "params": {}, "uncertainty": {}, "rms_deg_before": rms_deg, "rms_deg_after": rms_deg,
                   "evidence": "test", "where": w} for e, w in added],
        "removed": [],
        "final": {
            "model": " + ".join([model, *(e for e, _ in added)]),
            "params": params,
            "fields": fields,
            "uncertainty": sigma,
            "relative_uncertainty": {k: s / params[k] for k, s in sigma.items() if isinstance(s, float)},
            "correlation": {},
            "not_determined": list(not_determined),
            "hinge_moment_reversed": False,
            "rms_deg": rms_deg,
            "rms_over_noise": {o: rms_deg[o] / noise_deg[o] for o in outputs},
        },
        "warnings": [],
        "channel": channel,
        "samples": 15000,
        "sample_hz": 1000.0,
    }


def agreeing(offsets=(0.5, -0.3, 0.1)):
    """Three reports of the same actuator, each value off the truth by a fraction of its sigma."""
    return [report({k: v + o * SIGMA[k] for k, v in TRUTH.items()}, dict(SIGMA), data=f"m{i}.csv")
            for i, o in enumerate(offsets)]


def parsed(docs):
    return [parse_report(d, f"r{i}.json") for i, d in enumerate(docs)]


def by_field(result):
    return {f.field: f for f in result.fields}


def test_values_within_noise_agree_and_the_statistics_are_the_inverse_variance_ones():
    result = compare(parsed(agreeing()))
    fields = by_field(result)
    assert [f.verdict for f in result.fields] == ["agree"] * 3
    wn = fields["wn_rad_s"]
    assert wn.mean == pytest.approx(69.0 + 0.1)  # equal sigmas: the plain mean of +0.5, −0.3, +0.1
    assert wn.mean_sigma == pytest.approx(1.0 / math.sqrt(3))
    assert wn.worst.z == pytest.approx(0.8 / math.sqrt(2))
    assert {wn.worst.a, wn.worst.b} == {"r0.json", "r1.json"}
    assert wn.unit == "rad/s"
    assert fields["delay_s"].unit == "s"
    assert result.counts() == {"agree": 3, "disagree": 0, "undetermined": 0, "single": 0}


def test_a_value_moved_by_ten_sigma_disagrees_naming_the_report_and_the_distance():
    docs = agreeing()
    docs[2]["final"]["params"]["zeta"] = TRUTH["zeta"] + 10.0 * SIGMA["zeta"]
    result = compare(parsed(docs))
    zeta = by_field(result)["zeta"]
    assert zeta.verdict == "disagree"
    assert by_field(result)["wn_rad_s"].verdict == "agree"
    # r0 sits at +0.5σ, r1 at −0.3σ: r2 at +10σ is 10.3σ / √2 from r1, 9.5σ / √2 from r0
    assert [(p.a, p.b) for p in zeta.beyond] == [("r1.json", "r2.json"), ("r0.json", "r2.json")]
    assert zeta.beyond[0].z == pytest.approx(10.3 / math.sqrt(2))
    assert zeta.worst == zeta.beyond[0]
    assert "r1.json and r2.json by 7.3σ" in zeta.reason
    table = format_table(result)
    assert "disagree: zeta: beyond 3σ: r1.json and r2.json by 7.3σ, r0.json and r2.json by 6.7σ" in table
    # a looser limit takes the same pairs as agreeing
    assert by_field(compare(parsed(docs), sigma=8.0))["zeta"].verdict == "agree"


def test_chi_square_and_its_p_value_against_a_hand_computation():
    docs = [report({"wn_rad_s": v}, {"wn_rad_s": s}) for v, s in ((1.0, 0.1), (1.3, 0.2), (0.9, 0.1))]
    wn = compare(parsed(docs)).fields[0]
    # weights 100, 25, 100: mean 222.5 / 225 = 89/90, sigma 1/15; χ² = (100 + 25·28² + 100·8²) / 90² = 29/9
    assert wn.mean == pytest.approx(89 / 90)
    assert wn.mean_sigma == pytest.approx(1 / 15)
    assert wn.chi_square == pytest.approx(29 / 9)
    assert wn.dof == 2
    assert wn.p_value == pytest.approx(math.exp(-29 / 18))  # χ² with 2 dof: sf(x) = exp(−x/2)
    assert wn.p_value == pytest.approx(chi2.sf(29 / 9, 2))
    assert wn.worst.z == pytest.approx(0.4 / math.hypot(0.2, 0.1))  # r1 against r2


def test_missing_or_unbounded_uncertainty_and_not_determined_are_undetermined_naming_the_report():
    docs = agreeing()
    del docs[1]["final"]["uncertainty"]["wn_rad_s"]
    docs[2]["final"]["uncertainty"]["delay_s"] = "unbounded"
    docs[0]["final"]["not_determined"] = ["zeta"]
    fields = by_field(compare(parsed(docs)))
    assert {f.verdict for f in fields.values()} == {"undetermined"}
    assert fields["wn_rad_s"].reason == ("r1.json gives no finite uncertainty; "
                                         "the others differ by up to 0.3σ (r0.json and r2.json)")
    assert fields["delay_s"].reason.startswith("r2.json gives no finite uncertainty")
    assert fields["zeta"].reason.startswith("r0.json says its record does not determine it")
    assert fields["wn_rad_s"].mean == pytest.approx(69.0 + 0.3 * 1.0)  # the determined two still compared
    assert fields["wn_rad_s"].as_dict()["undetermined_in"] == ["r1.json"]


def test_a_parameter_found_on_a_grid_is_undetermined_whatever_its_spacing_says():
    """Kb and offset before a quantizer are grid-searched: ``identify`` gives the grid's spacing as their ±, and
    the HOAD3 maneuvers' offsets differ by 42 such spacings. Listed in ``final.grid_searched``, they are not
    compared as if that spacing were a standard deviation."""
    docs = agreeing()
    docs[1]["final"]["params"]["delay_s"] += 50 * SIGMA["delay_s"]
    docs[1]["final"]["grid_searched"] = ["delay_s"]
    fields = by_field(compare(parsed(docs)))
    assert fields["delay_s"].verdict == "undetermined"
    assert fields["delay_s"].reason.startswith("r1.json found it on a grid before the quantizer")
    assert fields["wn_rad_s"].verdict == "agree"


def test_a_field_in_one_report_only_is_single_and_not_compared():
    docs = agreeing()
    docs[1]["final"]["params"]["freq_hz"] = 29.0
    docs[1]["final"]["fields"]["freq_hz"] = "linkage_freq_hz"
    docs[1]["final"]["uncertainty"]["freq_hz"] = 0.3
    link = by_field(compare(parsed(docs)))["linkage_freq_hz"]
    assert link.verdict == "single"
    assert link.reason == "fitted in r1.json only"
    assert link.worst is None
    assert math.isnan(link.mean)
    assert link.unit == "Hz"


def test_keys_are_matched_through_final_fields_with_the_reported_unit_taken_back_to_the_field_s():
    arm = SecondOrderParams.from_channel(load_channel("left_wing")).moment_arm_in
    k2, k2_sigma = 0.0036, 0.0004  # °/s per lbf
    own = report({"free_play_deg": 0.15, "k2_dps_per_lb": k2, "deg_per_kinlb": 0.40},
                 {"free_play_deg": 0.01, "k2_dps_per_lb": k2_sigma, "deg_per_kinlb": 0.01},
                 fields={"free_play_deg": "free_play_deg", "k2_dps_per_lb": "k2_dps_per_lb",
                         "deg_per_kinlb": "compliance_deg_per_kinlb"})
    # the same quantities under the vocabulary's keys (an added effect): free play as width_deg, K2 per 1000
    # in·lb of hinge moment; and this report's deg_per_kinlb is the LVDT's compliance, not the surface's
    added = report({"width_deg": 0.16, "dps_per_kinlb": 1.02 * k2 * 1000.0 / arm, "deg_per_kinlb": 0.07},
                   {"width_deg": 0.01, "dps_per_kinlb": k2_sigma * 1000.0 / arm, "deg_per_kinlb": 0.01},
                   fields={"width_deg": "free_play_deg", "dps_per_kinlb": "k2_dps_per_lb",
                           "deg_per_kinlb": "lvdt_compliance_deg_per_kinlb"})
    fields = by_field(compare(parsed([own, added])))
    assert fields["free_play_deg"].verdict == "agree"
    assert fields["free_play_deg"].worst.z == pytest.approx(0.01 / math.hypot(0.01, 0.01))
    k2_field = fields["k2_dps_per_lb"]
    assert [e.key for e in k2_field.entries] == ["k2_dps_per_lb", "dps_per_kinlb"]
    assert k2_field.entries[1].value == pytest.approx(1.02 * k2)
    assert k2_field.entries[1].sigma == pytest.approx(k2_sigma)
    assert k2_field.worst.z == pytest.approx(0.02 * k2 / math.hypot(k2_sigma, k2_sigma))
    assert k2_field.unit == "deg/s/lbf"
    assert fields["compliance_deg_per_kinlb"].verdict == "single"
    assert fields["lvdt_compliance_deg_per_kinlb"].verdict == "single"


def test_a_report_without_final_fields_maps_the_vocabulary_s_keys():
    doc = report({"wn_rad_s": 69.0, "width_deg": 0.15}, {"wn_rad_s": 1.0, "width_deg": 0.01})
    del doc["final"]["fields"]
    assert parse_report(doc, "old.json").keys == {"wn_rad_s": "wn_rad_s", "free_play_deg": "width_deg"}


def test_the_structured_residual_note_is_given_only_to_the_report_above_three_times_its_noise():
    docs = agreeing()
    docs[1]["final"]["rms_deg"] = {"position_deg": 0.030, "surface_deg": 0.0021}  # position 2.65×: below
    docs[2]["final"]["rms_deg"] = {"position_deg": 0.012, "surface_deg": 0.045}  # surface 22.5×
    result = compare(parsed(docs))
    assert len(result.notes) == 1
    assert result.notes[0].startswith("r2.json: final rms above 3× its noise floor (surface_deg 22.5×)")
    assert "the model lacks structure, not that the actuator changed" in result.notes[0]
    assert [r["structured_residual"] for r in result.as_dict()["reports"]] == [False, False, True]


def test_effects_added_in_some_reports_only_are_listed_with_where():
    docs = agreeing()
    docs[0] = report(docs[0]["final"]["params"], dict(SIGMA), added=[("time_delay", "command"),
                                                                      ("compliance", "surface")])
    docs[1] = report(docs[1]["final"]["params"], dict(SIGMA), added=[("time_delay", "command")])
    docs[2] = report(docs[2]["final"]["params"], dict(SIGMA), added=[("time_delay", "command"),
                                                                      ("compliance", "feedback")])
    result = compare(parsed(docs))
    assert result.common_effects == (("time_delay", "command"),)
    some = {(e.effect, e.where): (e.added_in, e.not_in) for e in result.effects}
    assert some == {("compliance", "surface"): (("r0.json",), ("r1.json", "r2.json")),
                    ("compliance", "feedback"): (("r2.json",), ("r0.json", "r1.json"))}
    assert "effect compliance (surface) added in r0.json, not in r1.json, r2.json" in format_table(result)


def test_compare_field_with_a_nonpositive_sigma_is_undetermined():
    from ema_sim.identify.consistency import Entry  # noqa: PLC0415

    entries = [Entry("a", "zeta", 0.7, 0.01, True), Entry("b", "zeta", 0.7, 0.0, False)]
    assert compare_field("zeta", entries, 3.0).verdict == "undetermined"


def _strict_loads(text):
    def refuse(token):
        raise ValueError(f"non-strict JSON token {token}")

    return json.loads(text, parse_constant=refuse)


def _write(tmp_path, docs):
    paths = []
    for i, d in enumerate(docs):
        path = tmp_path / f"m{i + 1}.json"
        path.write_text(json.dumps(d), encoding="utf-8")
        paths.append(str(path))
    return paths


def test_cli_prints_the_table_writes_strict_json_and_exits_0_when_parameters_disagree(tmp_path, capsys):
    docs = agreeing()
    docs[2]["final"]["params"]["zeta"] = TRUTH["zeta"] + 10.0 * SIGMA["zeta"]
    docs[0]["final"]["uncertainty"]["delay_s"] = "unbounded"
    docs[1]["final"]["params"]["kb"] = 0.0034  # single, no uncertainty at all
    docs[1]["final"]["fields"]["kb"] = "kb"
    out = tmp_path / "c.json"
    assert main(["identify-consistency", *_write(tmp_path, docs), "--json", str(out)]) == 0
    text = capsys.readouterr().out
    assert "| zeta | - | 0.7325 ± 0.005 | 0.7285 ± 0.005 | 0.78 ± 0.005 |" in text
    assert "verdicts: 1 agree, 1 disagree, 1 undetermined, 1 single" in text
    doc = _strict_loads(out.read_text(encoding="utf-8"))
    fields = {f["field"]: f for f in doc["fields"]}
    assert fields["zeta"]["verdict"] == "disagree"
    assert fields["zeta"]["beyond"][0] == {"reports": ["m2.json", "m3.json"], "z": pytest.approx(10.3 / math.sqrt(2))}
    assert fields["delay_s"]["values"]["m1.json"]["sigma"] == "unbounded"
    assert fields["kb"]["verdict"] == "single"
    assert fields["kb"]["weighted_mean"] is None
    assert doc["channel"] == "left_wing"
    assert doc["sigma"] == 3.0
    assert doc["verdicts"] == {"agree": 1, "disagree": 1, "undetermined": 1, "single": 1}


def test_bare_nan_and_infinity_of_an_older_report_are_read_as_no_number_and_the_output_stays_strict(tmp_path,
                                                                                                   capsys):
    docs = agreeing()
    docs[0]["final"]["uncertainty"]["zeta"] = math.inf
    docs[1]["final"]["params"]["delay_s"] = math.nan
    paths = _write(tmp_path, docs)
    assert "Infinity" in (tmp_path / "m1.json").read_text(encoding="utf-8")
    out = tmp_path / "c.json"
    assert main(["identify-consistency", *paths, "--json", str(out)]) == 0
    assert "undetermined: zeta: m1.json gives no finite uncertainty" in capsys.readouterr().out
    fields = {f["field"]: f for f in _strict_loads(out.read_text(encoding="utf-8"))["fields"]}
    assert fields["zeta"]["values"]["m1.json"]["sigma"] == "unbounded"
    assert fields["delay_s"]["values"]["m2.json"]["value"] is None
    assert fields["delay_s"]["reason"].startswith("m2.json gives no finite value")
    assert fields["wn_rad_s"]["verdict"] == "agree"


def test_reports_with_the_same_file_name_are_named_by_path(tmp_path):
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    for sub, d in zip(("a", "b"), agreeing()[:2], strict=True):
        (tmp_path / sub / "report.json").write_text(json.dumps(d), encoding="utf-8")
    names = [r.name for r in read_reports([tmp_path / "a" / "report.json", tmp_path / "b" / "report.json"])]
    assert names == [str(tmp_path / "a" / "report.json"), str(tmp_path / "b" / "report.json")]


@pytest.mark.parametrize(
    ("case", "message"),
    [
        ("missing", "nope.json: no such file"),
        ("malformed", "m2.json: malformed JSON: Expecting ',' delimiter (line 1"),
        ("one", "a consistency check needs two reports or more, got 1"),
        ("not_a_report", "m2.json: not an `ema identify` report (no final object)"),
        ("a_list", "m2.json: not an `ema identify` report (a JSON list, not an object)"),
        ("channels", "reports of different channels cannot be compared: m1.json left_wing, m2.json right_rudder"),
        ("units", "reports of different units cannot be compared: m1.json deg, m2.json mm"),
        ("sigma", "--sigma must be a positive number, got 0"),
    ],
)
def test_bad_input_is_one_line_and_exit_status_2(tmp_path, capsys, case, message):
    docs = agreeing()[:2]
    extra: list[str] = []
    if case == "channels":
        docs[1]["channel"] = "right_rudder"
    elif case == "units":
        docs[1]["unit"] = "mm"
    paths = _write(tmp_path, docs)
    if case == "missing":
        paths[1] = str(tmp_path / "nope.json")
    elif case == "malformed":
        (tmp_path / "m2.json").write_text('{"final": {"params": {} "x": 1}}', encoding="utf-8")
    elif case == "one":
        paths = paths[:1]
    elif case == "not_a_report":
        (tmp_path / "m2.json").write_text(json.dumps({"data": "x.csv", "tests": {}}), encoding="utf-8")
    elif case == "a_list":
        (tmp_path / "m2.json").write_text("[1, 2]", encoding="utf-8")
    elif case == "sigma":
        extra = ["--sigma", "0"]
    out = tmp_path / "c.json"
    rc = main(["identify-consistency", *paths, "--json", str(out), *extra])
    err = capsys.readouterr().err
    assert rc == 2
    assert err.startswith("ema identify-consistency: error: ")
    assert message in err
    assert len(err.strip().splitlines()) == 1
    assert "Traceback" not in err
    assert not out.exists()


@pytest.mark.slow
def test_end_to_end_three_maneuvers_of_one_actuator_agree_and_a_different_actuator_is_named(tmp_path, capsys):
    """``ema identify`` on three records of one LOAC actuator (delay and compliance undeclared; different
    lengths, loads and noise draws), and on a fourth whose compliance is 10 % stiffer: the three agree on
    every parameter, the fourth disagrees on the compliance only."""
    paths = []
    for seed, duration_s, load_inlb, compliance in ((1, 12.0, 600.0, 0.3), (2, 16.0, 900.0, 0.3),
                                                    (3, 20.0, 400.0, 0.3), (4, 12.0, 600.0, 0.27)):
        d = make_record({"time_delay": 0.006, "compliance": compliance}, seed=seed, duration_s=duration_s,
                        load_amp_inlb=load_inlb)
        csv = tmp_path / f"r{seed}.csv"
        write_csv(csv, {k: getattr(d, k) for k in ("time_s", "command_deg", "position_deg", "surface_deg",
                                                   "hinge_moment_inlb")}, d.metadata)
        paths.append(str(tmp_path / f"r{seed}.json"))
        assert main(["identify", str(csv), "--json", paths[-1], "-q"]) == 0
    capsys.readouterr()
    out = tmp_path / "same.json"
    assert main(["identify-consistency", *paths[:3], "--json", str(out)]) == 0
    same = {f["field"]: f for f in _strict_loads(out.read_text(encoding="utf-8"))["fields"]}
    assert set(same) == {"wn_rad_s", "zeta", "delay_s", "compliance_deg_per_kinlb"}
    assert {f["verdict"] for f in same.values()} == {"agree"}
    assert same["delay_s"]["weighted_mean"] == pytest.approx(0.006, rel=1e-3)
    assert same["compliance_deg_per_kinlb"]["weighted_mean"] == pytest.approx(0.3, rel=1e-3)
    assert main(["identify-consistency", *paths, "--json", str(out)]) == 0
    text = capsys.readouterr().out
    four = {f["field"]: f for f in _strict_loads(out.read_text(encoding="utf-8"))["fields"]}
    assert four["compliance_deg_per_kinlb"]["verdict"] == "disagree"
    assert all("r4.json" in p["reports"] for p in four["compliance_deg_per_kinlb"]["beyond"])
    assert len(four["compliance_deg_per_kinlb"]["beyond"]) == 3
    assert {four[f]["verdict"] for f in ("wn_rad_s", "zeta", "delay_s")} == {"agree"}
    assert "disagree: compliance_deg_per_kinlb: beyond 3σ: " in text


def test_identify_lists_the_parameters_it_found_on_a_grid():
    """LOADA declares a 0.02° quantizer, so Kb and the offset are grid-searched: the report says so, and a
    consistency check of two such reports calls them undetermined instead of comparing grid spacings."""
    from identgen import make_record  # noqa: PLC0415

    from ema_sim.config import load_channel  # noqa: PLC0415
    from ema_sim.identify.identification import Search, identify  # noqa: PLC0415
    from ema_sim.identify.record import prepare  # noqa: PLC0415
    from ema_sim.identify.report import to_json  # noqa: PLC0415

    data = make_record({"quantization": 0.02, "command_gain": 0.01}, seed=4, duration_s=10.0)
    doc = to_json(identify(prepare(data, load_channel("left_wing")), "loada", search=Search(max_effects=0)), "q.csv")
    assert sorted(doc["final"]["grid_searched"]) == ["kb", "offset_deg"]
    assert "wn_rad_s" not in doc["final"]["grid_searched"]
    fields = by_field(compare(parsed([doc, json.loads(json.dumps(doc))])))
    assert fields["kb"].verdict == fields["offset_deg"].verdict == "undetermined"
    assert fields["wn_rad_s"].verdict == "agree"
