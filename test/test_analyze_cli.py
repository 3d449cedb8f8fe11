"""``ema analyze`` end to end: JSON, Markdown and PNGs; bad input is one line and exit status 2."""

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from analysis_data import measured

import ema_sim.io
from ema_sim.analysis.records import loading
from ema_sim.cli import main
from ema_sim.errors import DataError
from ema_sim.io.csv import write_csv

RECORD_KEYS = {
    "data", "channel", "samples", "sample_hz", "duration_s", "outputs", "metadata", "noise_deg", "tests",
    "frequency_response", "sine_dwell", "steps", "slew_rates", "second_order_fits", "timing", "command_error",
    "static_threshold", "dynamic_threshold", "crosstalk", "dither", "compliance", "hysteresis", "free_play",
    "regeneration", "not_computed", "notes", "resolution_deg", "noise", "command", "unit", "profiled_moves",
    "periodic", "slew",
}


def write(data, path):
    cols = {k: getattr(data, k) for k in ("time_s", "command_deg", "position_deg", "surface_deg", "hinge_moment_inlb",
                                          "command_v", "position_v") if getattr(data, k) is not None}
    write_csv(path, cols, data.metadata)
    return str(path)


@pytest.fixture(scope="module")
def csvs(tmp_path_factory):
    d = tmp_path_factory.mktemp("rig")
    return {
        "sweep": write(measured("loada", "sweep:f0_hz=0.2,f1_hz=18,amp_deg=1,sweep_s=30"), d / "sweep.csv"),
        "steps": write(measured("loac", "steps:amps_deg=0.5/1/20"), d / "steps.csv"),
        "compliance": write(measured("loada", "hold:value_deg=15,hold_s=67", "steps:step_inlb=222.5,max_inlb=1780",
                                     kcp_per_kinlb=0.008, compliance_deg_per_kinlb=0.5), d / "compliance.csv"),
        "staircase": write(measured("loada", "staircase:step_deg=10,max_deg=40,hold_s=2"), d / "staircase.csv"),
    }


def test_json_and_report_of_several_records(csvs, tmp_path, capsys):
    out, rep = tmp_path / "a.json", tmp_path / "rep"
    rc = main(["analyze", csvs["sweep"], csvs["steps"], csvs["compliance"], csvs["staircase"], "--json", str(out),
               "--report", str(rep), "--model", "loada"])
    assert rc == 0
    printed = capsys.readouterr().out
    assert "sweep → position_deg: −3 dB" in printed
    assert "compliance: share outside the servo loop 80.6 %" in printed
    doc = json.loads(out.read_text())
    assert doc["tool"] == "ema analyze"
    assert len(doc["records"]) == 4
    for rec in doc["records"]:
        assert set(rec) == RECORD_KEYS
    sweep, steps, comp, cal = doc["records"]
    fr = sweep["frequency_response"][0]
    assert fr["second_order_fit"]["wn_rad_s"]["value"] == pytest.approx(57.8, rel=0.02)
    assert {"value", "sigma", "sigma_white"} <= set(fr["second_order_fit"]["zeta"])
    assert fr["model_overlay"]["model"] == "loada"
    assert len(fr["freq_hz"]) == len(fr["gain_db"]) == len(fr["coherence"])
    assert steps["slew_rates"]["large_amplitude_dps"] == pytest.approx(115.8, rel=0.01)
    assert steps["timing"]["command_to_motion_s"] == pytest.approx(0.004, abs=5e-4)
    assert comp["compliance"][0]["share_outside_servo_loop"] == pytest.approx(0.806, abs=0.01)
    assert comp["not_computed"]["frequency_response"].startswith("no sweep")
    assert cal["command_error"][0]["kb"] == pytest.approx(0.0021, abs=2e-4)
    spread = doc["second_order_spread"]["position_deg"]
    assert spread["wn_rad_s"]["count"] == 5  # four small steps and the sweep
    assert spread["wn_rad_s"]["min"] <= spread["wn_rad_s"]["mean"] <= spread["wn_rad_s"]["max"]
    assert doc["command_error_bounds"]["calibrations"] == 1
    assert doc["rw13_check"]["h_lb_per_in"] == pytest.approx(3344.84, abs=0.01)
    # The report: Markdown that links every plot, and the plots exist.
    md = (rep / "report.md").read_text()
    links = [line.split("](")[1].rstrip(")") for line in md.splitlines() if line.startswith("![")]
    assert "r0_frequency_response0.png" in links
    assert {"r1_steps0.png", "r1_steps3.png", "r1_timing0.png", "r2_compliance0.png", "r3_command_error0.png",
            "spread.png"} <= set(links)
    for name in links:
        png = rep / name
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        assert png.stat().st_size > 10_000
    assert "Spread across tests (figure 23)" in md
    assert "Share of the compliance outside the servo loop: 80.6 %" in md


def test_json_is_strict(csvs, tmp_path):
    out = tmp_path / "s.json"
    assert main(["analyze", csvs["steps"], "--json", str(out)]) == 0
    text = out.read_text()
    assert "NaN" not in text
    assert "Infinity" not in text


@pytest.mark.parametrize(
    ("make", "message"),
    [
        (lambda p: p.write_text("time_s,command_deg\n" + "\n".join(f"{i},0" for i in range(200))),
         "needs a 'position_deg' or 'surface_deg'"),
        (lambda p: p.write_text("time_s,command_deg,position_deg\n"
                                + "\n".join(f"{i * 0.001},0,x" for i in range(200))),
         "line 2, column 'position_deg': not a number"),
        (lambda _p: None, "no such file"),
    ],
)
def test_malformed_data_is_one_line_and_status_2(tmp_path, capsys, make, message):
    path = tmp_path / "bad.csv"
    make(path)
    assert main(["analyze", str(path)]) == 2
    err = capsys.readouterr().err
    assert message in err
    assert len(err.strip().splitlines()) == 1


def test_a_bag_without_the_node_suite_says_so(tmp_path, capsys, monkeypatch):
    monkeypatch.delattr(ema_sim.io, "load_data", raising=False)
    bag = tmp_path / "bag"
    bag.mkdir()
    (bag / "metadata.yaml").write_text("rosbag2_bagfile_information: {}\n")
    (bag / "bag_0.mcap").write_bytes(b"\x89MCAP0\r\n")
    assert main(["analyze", str(bag)]) == 2
    err = capsys.readouterr().err
    assert "a rosbag2 bag; reading bags needs the node suite's reader" in err
    assert len(err.strip().splitlines()) == 1


def test_bags_go_through_the_node_suite_reader_when_it_exists(monkeypatch):
    calls = []

    def load_data(path, channel=None):
        calls.append((Path(path).name, channel))
        if channel == "cowl_door":
            raise DataError(f"{path}: no channel 'cowl_door' in the bag")
        return measured("loac", "steps:amps_deg=1")

    monkeypatch.setattr(ema_sim.io, "load_data", load_data, raising=False)
    data = loading.load_record("run1", channel="left_wing")
    assert calls == [("run1", "left_wing")]
    assert data.command_deg.max() == 1.0
    assert main(["analyze", "run1", "--channel", "cowl_door"]) == 2


def test_channel_mismatch_and_bad_options(csvs, capsys):
    assert main(["analyze", csvs["steps"], "--channel", "right_rudder"]) == 2
    assert "holds channel 'left_wing', not 'right_rudder'" in capsys.readouterr().err
    assert main(["analyze", csvs["steps"], "--model", "hoad9"]) == 2
    assert "unknown model 'hoad9'" in capsys.readouterr().err
    assert main(["analyze", csvs["steps"], "--at-hz", "1,x"]) == 2
    assert "--at-hz expects" in capsys.readouterr().err


def test_unrecognisable_record_says_what_is_missing(tmp_path):
    t = np.arange(0, 3, 0.001)
    rng = np.random.default_rng(0)
    path = tmp_path / "noise.csv"
    write_csv(path, {"time_s": t, "command_deg": rng.normal(0, 1, t.size).round(3),
                     "position_deg": rng.normal(0, 1, t.size)})
    out = tmp_path / "n.json"
    assert main(["analyze", str(path), "--json", str(out)]) == 0
    rec = json.loads(out.read_text())["records"][0]
    assert rec["not_computed"]["compliance"] == "no hinge moment: compliance not computed"
    assert rec["not_computed"]["regeneration"].startswith("no bus voltage column")
    assert any("no X-43A channel in the metadata" in n and "generic actuator" in n for n in rec["notes"])
    assert rec["channel"] == "generic"


def test_a_reader_failure_is_one_data_error_line(monkeypatch, capsys):
    def load_data(path, channel=None):
        raise KeyError(f"topic /{channel or 'left_wing'}/position missing in {path}")

    monkeypatch.setattr(ema_sim.io, "load_data", load_data, raising=False)
    assert main(["analyze", "broken_bag"]) == 2
    err = capsys.readouterr().err
    assert "broken_bag: cannot read (KeyError" in err
    assert len(err.strip().splitlines()) == 1


def test_every_plot_is_drawn(tmp_path):
    """One record of each remaining kind through --report: every plot function runs and writes a PNG."""
    d = tmp_path / "more"
    d.mkdir()
    hold = measured("loada", "hold:value_deg=1,hold_s=12", noise_deg=0.002)
    t = hold.time_s
    dither = replace(hold, position_deg=hold.position_deg + 0.05 * np.sin(2 * np.pi * 3 * t))
    regen = measured("loada", "regen:sweep_s=10")
    bus = 150 + 5 * (np.abs(np.diff(regen.command_deg, prepend=0)) > 0)
    files = [
        write(dither, d / "dither.csv"),
        write(measured("loada", "static_threshold:amp_max_deg=0.3,cycles=4", threshold_deg=0.05), d / "sth.csv"),
        write(measured("loada", "dynamic_threshold:amp0_deg=0,amp1_deg=0.3,ramp_s=10", threshold_deg=0.05),
              d / "dth.csv"),
        write(measured("loada", "hold:value_deg=0,hold_s=11", "reversal:inlb=50"), d / "fp.csv"),
        write(measured("loada", "hold:value_deg=0,hold_s=90", "sine:amp_inlb=500,freq_hz=0.05,cycles=3"), d / "h.csv"),
        write(measured("loada", "schroeder:f0_hz=0.5,f1_hz=10,period_s=5,periods=2"), d / "sch.csv"),
    ]
    rpath = d / "regen.csv"
    cols = {k: getattr(regen, k) for k in ("time_s", "command_deg", "position_deg")}
    write_csv(rpath, {**cols, "bus_v": bus}, regen.metadata)
    files.append(str(rpath))
    rep = tmp_path / "rep"
    assert main(["analyze", *files, "--report", str(rep), "--model", "loada"]) == 0
    names = {p.name for p in rep.glob("*.png")}
    for key in ("r0_dither0", "r0_crosstalk0", "r1_static_threshold0", "r2_dynamic_threshold0", "r3_free_play0",
                "r4_hysteresis0", "r5_frequency_response0", "r6_regeneration0"):
        assert f"{key}.png" in names
    md = (rep / "report.md").read_text()
    assert "limit cycle at 3 Hz" in md
    assert "Voltage regeneration" in md
    assert "h = A/(π·Pk²)" in md
