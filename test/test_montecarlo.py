"""``ema montecarlo``: dispersions from the metadata, reproducible rows on any cluster, resume, built-in campaigns.

The cluster is real: a ``dask scheduler`` and two ``dask worker`` processes on localhost (free ports), shared
by the tests of this module; the local runs start their own ``LocalCluster`` as a user's would.
"""

import json
import math
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import yaml
from distributed import Client

from ema_sim.cli import main
from ema_sim.errors import ConfigError, UnknownNameError
from ema_sim.montecarlo import builtin_campaign, load_campaign, parse_campaign, run_campaign
from ema_sim.montecarlo.builtin import (
    command_error_corners,
    second_order_bandwidth_hz,
    second_order_phase90_hz,
)
from ema_sim.montecarlo.dispersions import sample
from ema_sim.montecarlo.output import finished, read_runs
from ema_sim.montecarlo.runs import run_block

BIN = Path(sys.executable).parent
HOAD3 = {
    "campaign": "hoad3-steps",
    "model": "hoad3",
    "channel": "right_wing",
    "experiments": {"step": {"maneuver": "step:amp_deg=2,lead_s=0.05,hold_s=0.35,back=false", "load": "const:inlb=100",
                             "sample_hz": 1000}},
    "dispersions": [
        {"parameter": "stator_resistance_ohm", "uniform": "report"},
        {"parameter": "bound", "uniform": [-1, 1]},
        {"parameters": ["position_gain_per_s", "lvdt_filter_hz"],
         "normal": {"mean": [43, 13.4], "std": [3, 1], "correlation": [[1, 0.5], [0.5, 1]]}},
        {"parameter": "step.load.inlb", "discrete": [0, 100, 300]},
    ],
    "metrics": ["step", "error", "peak_rate", "final_error"],
    "batch": 2,
}


def _free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="module")
def scheduler():
    """A real Dask cluster on localhost: ``dask scheduler`` and two single-threaded ``dask worker`` processes."""
    port = _free_port()
    address = f"tcp://127.0.0.1:{port}"
    quiet = {"stdout": subprocess.DEVNULL, "stderr": subprocess.DEVNULL}
    procs = [subprocess.Popen([str(BIN / "dask"), "scheduler", "--host", "127.0.0.1", "--port", str(port),
                               "--no-dashboard"], **quiet)]
    try:
        time.sleep(1.0)
        for i in range(2):
            procs.append(subprocess.Popen([str(BIN / "dask"), "worker", address, "--nworkers", "1", "--nthreads", "1",
                                           "--no-dashboard", "--host", "127.0.0.1", "--name", f"test-worker-{i}"],
                                          **quiet))
        with Client(address, timeout="30s") as client:
            client.wait_for_workers(2, timeout=90)
        yield address
    finally:
        for p in reversed(procs):
            p.send_signal(signal.SIGTERM)
        for p in reversed(procs):
            try:
                p.wait(timeout=20)
            except subprocess.TimeoutExpired:
                p.kill()


def _yaml(tmp_path, doc, name="campaign.yaml"):
    path = tmp_path / name
    path.write_text(yaml.safe_dump(doc), encoding="utf-8")
    return path


def _same_rows(a, b):
    assert sorted(a) == sorted(b)
    for key in a:
        assert np.array_equal(a[key], b[key], equal_nan=True), key


# ------------------------------------------------------------------------------------------ dispersions
def test_dispersions_read_the_metadata_and_refuse_what_it_forbids():
    c = parse_campaign(HOAD3, "hoad3-steps")
    vals = sample(c.dispersions, 7, range(400))
    r = vals["stator_resistance_ohm"]
    assert r.min() >= 0.78
    assert r.max() <= 0.98
    assert r.max() - r.min() > 0.15  # table A2: 0.88 ± 0.10 Ω
    assert set(np.unique(vals["step.load.inlb"])) == {0.0, 100.0, 300.0}
    rho = np.corrcoef(vals["position_gain_per_s"], vals["lvdt_filter_hz"])[0, 1]
    assert 0.35 < rho < 0.65
    bad = dict(HOAD3, dispersions=[{"parameter": "stator_resistance_ohm", "uniform": [-1, 1]}])
    with pytest.raises(ConfigError, match="outside its range"):
        parse_campaign(bad)
    with pytest.raises(UnknownNameError, match="stator_resistance_ohm"):
        parse_campaign(dict(HOAD3, dispersions=[{"parameter": "stator_ohm", "uniform": [0, 1]}]))
    with pytest.raises(ConfigError, match="declares no uncertainty"):
        parse_campaign(dict(HOAD3, dispersions=[{"parameter": "inductance_mh", "uniform": "report"}]))


def test_a_runs_values_depend_only_on_seed_and_run_index():
    c = parse_campaign(HOAD3, "hoad3-steps")
    whole = sample(c.dispersions, 3, range(10))
    parts = [sample(c.dispersions, 3, [r]) for r in (9, 4, 0)]
    for r, part in zip((9, 4, 0), parts, strict=True):
        for k in whole:
            assert part[k][0] == whole[k][r]
    assert not np.array_equal(sample(c.dispersions, 4, range(10))["bound"], whole["bound"])
    corners = parse_campaign(builtin_campaign("command-error"), "command-error")
    kb, off = command_error_corners()
    got = sample(corners.dispersions, 0, range(4))
    assert {(a, b) for a, b in zip(got["kb"], got["offset_deg"], strict=True)} == {
        (s * kb, t * off) for s in (-1, 1) for t in (-1, 1)}


def test_rows_do_not_depend_on_the_batch():
    c = parse_campaign(HOAD3, "hoad3-steps")
    whole = run_block(c.to_json(), 11, 0, 6)
    split = [run_block(c.to_json(), 11, a, b) for a, b in ((0, 1), (1, 4), (4, 6))]
    for key, col in whole.columns.items():
        assert np.array_equal(col, np.concatenate([s.columns[key] for s in split]), equal_nan=True), key
    assert whole.nominal == split[0].nominal
    assert not split[1].nominal
    assert np.all(whole.columns["rms_error_deg"] > 0.0)


def test_bad_campaigns_are_one_line_and_exit_2(tmp_path, capsys):
    cases = {
        "nope": "unknown campaign 'nope'",
        str(_yaml(tmp_path, {**HOAD3, "metrics": ["bandwith"]}, "m.yaml")): "unknown metric 'bandwith'",
        str(_yaml(tmp_path, {**HOAD3, "model": "hoad4"}, "n.yaml")): "unknown model 'hoad4'",
    }
    broken = tmp_path / "broken.yaml"
    broken.write_text("model: [hoad3\n", encoding="utf-8")
    cases[str(broken)] = "not valid YAML"
    for arg, message in cases.items():
        assert main(["montecarlo", arg, "--runs", "2", "--out", str(tmp_path / "out")]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1
        assert message in err[0], err


# ------------------------------------------------------------------------------------------ the engine
def test_a_cluster_gives_the_local_rows_bit_for_bit(tmp_path, scheduler):
    path = _yaml(tmp_path, HOAD3)
    assert main(["montecarlo", str(path), "--runs", "12", "--seed", "5", "--out", str(tmp_path / "local")]) == 0
    assert main(["montecarlo", str(path), "--runs", "12", "--seed", "5", "--out", str(tmp_path / "cluster"),
                 "--scheduler", scheduler]) == 0
    local, remote = read_runs(tmp_path / "local"), read_runs(tmp_path / "cluster")
    _same_rows(local, remote)
    assert list(local["run"]) == list(range(12))
    assert len(finished(tmp_path / "cluster")) == 6
    summary = json.loads((tmp_path / "cluster" / "summary.json").read_text(), parse_constant=pytest.fail)
    assert len(summary["workers"]) == 2
    assert all(w.startswith("tcp://127.0.0.1:") for w in summary["workers"])
    assert summary["runs"] == 12
    assert summary["seed"] == 5
    assert summary["complete"]
    assert summary["metrics"]["overshoot_pct"]["count"] == 12
    assert {"envelope_step_position_deg.png", "histograms.png", "sensitivity.png"} <= set(summary["plots"])


def test_an_interrupted_campaign_resumes_to_the_same_rows(tmp_path, scheduler):
    # Enough work that the interrupt lands mid-campaign whatever the machine's speed (about a second of compute).
    runs = 200
    doc = {**HOAD3, "batch": 1}
    doc["experiments"] = {"step": {**HOAD3["experiments"]["step"], "duration_s": 10.0}}
    path = _yaml(tmp_path, doc)
    out = tmp_path / "cut"
    cmd = [str(BIN / "ema"), "montecarlo", str(path), "--runs", str(runs), "--seed", "9", "--out", str(out),
           "--scheduler", scheduler, "--no-plots"]
    # A job started in the background by a non-interactive shell inherits SIGINT ignored (POSIX), and Python
    # then never raises KeyboardInterrupt: the child gets the default disposition, as from a terminal.
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))  # noqa: PLW1509
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and (not (out / "runs.parquet").is_dir() or len(finished(out)) < 3):
        time.sleep(0.02)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    kept = finished(out)
    assert 3 <= len(kept) < runs
    assert main([*cmd[1:], "--resume"]) == 0
    assert len(finished(out)) == runs
    c = parse_campaign(doc, "hoad3-steps")
    reference = run_block(c.to_json(), 9, 0, runs)
    _same_rows(read_runs(out), {k: np.asarray(v) for k, v in reference.columns.items()})
    assert main([*cmd[1:]]) == 2  # the directory holds a campaign: --resume or another --out


# ----------------------------------------------------------------------------- built-in campaigns, checked
def test_second_order_bounds_meet_the_analytic_corners(tmp_path, scheduler):
    raw = builtin_campaign("second-order-bounds")
    raw["dispersions"] = [{"parameters": ["wn_rad_s", "zeta", "delay_s"], "corners": "report"}]
    raw["batch"] = 4
    c = parse_campaign(raw, "second-order-bounds")
    doc = run_campaign(c, tmp_path / "so", runs=8, seed=1, scheduler=scheduler, plot=False)
    rows = read_runs(tmp_path / "so")
    for wn, z, d, bw, p90 in zip(rows["wn_rad_s"], rows["zeta"], rows["delay_s"], rows["response.bandwidth_3db_hz"],
                                 rows["response.phase_minus_90_hz"], strict=True):
        assert bw == pytest.approx(second_order_bandwidth_hz(wn, z), rel=2e-3)
        assert p90 == pytest.approx(second_order_phase90_hz(wn, z, d), rel=2e-3)
    f = doc["findings"]["bandwidth_3db_hz"]
    assert f["campaign_min"] == pytest.approx(f["analytic_min (ωn low, ζ high)"], rel=2e-3)
    assert f["campaign_max"] == pytest.approx(f["analytic_max (ωn high, ζ low)"], rel=2e-3)
    overshoot = 100 * math.exp(-math.pi * 0.65 / math.sqrt(1 - 0.65**2))  # the channel's ζ, no delay effect
    assert doc["nominal"]["step.overshoot_pct"] == pytest.approx(overshoot, abs=0.05)


def test_command_error_bounds_are_the_four_corner_lines(tmp_path, scheduler):
    c = load_campaign("command-error")
    doc = run_campaign(c, tmp_path / "ce", runs=4, seed=0, scheduler=scheduler, plot=False)
    assert doc["findings"]["max_difference_deg"] <= 0.010 + 1e-9  # within half the 0.020° command quantum
    raw = builtin_campaign("command-error")
    raw["set"] = {"quantization_deg": 0.0}
    doc = run_campaign(parse_campaign(raw, "command-error"), tmp_path / "ce0", runs=4, seed=0, scheduler=scheduler,
                       plot=False)
    f = doc["findings"]
    assert f["max_difference_deg"] < 1e-9
    assert f["four_corner_upper_deg"][-1] == pytest.approx(40 * 0.0032 + 0.018)


def test_compliance_bounds_loes_at_the_mean_curve_is_ema_loes(tmp_path, scheduler, capsys):
    doc = run_campaign(load_campaign("compliance-bounds"), tmp_path / "cb", runs=2, seed=3, scheduler=scheduler,
                       plot=False)
    f = doc["findings"]
    assert f["max_abs_difference"] == 0.0
    assert main(["loes", "--channel", "left_wing"]) == 0
    printed = capsys.readouterr().out
    nom = f["nominal_loes"]
    assert (f"wn {nom['loes_wn_rad_s']:.4g} rad/s, zeta {nom['loes_zeta']:.4g}, "
            f"delay {nom['loes_delay_s'] * 1e3:.3f} ms, DC gain {nom['loes_gain']:.4g}") in printed
    rows = read_runs(tmp_path / "cb")
    assert np.all(np.isfinite(rows["loes_wn_rad_s"]))
    assert np.all(np.abs(rows["bound"]) <= 1.0)


def test_ail_dither_needs_the_noise(tmp_path, scheduler):
    raw = builtin_campaign("ail-dither")
    raw.update(set={"command_noise_v": 0.0, "feedback_noise_v": 0.0}, batch=1)
    raw["dispersions"] = [{"parameter": "environment.noise_rms_v", "corners": [[0.0, 0.003]]}]
    doc = run_campaign(parse_campaign(raw, "ail-dither"), tmp_path / "ail", runs=2, seed=0, scheduler=scheduler,
                       plot=False)
    rows = read_runs(tmp_path / "ail")
    assert list(rows["environment.noise_rms_v"]) == [0.0, 0.003]
    assert list(rows["wings_dithering"]) == [0.0, 2.0]  # section 4.3: no noise, no dither (the study's finding)
    f = doc["findings"]
    assert f["dither"]["probability"] == 0.5
    assert f["none"]["count"] == 2
    assert f["wing_runs"] == 4
    assert 0.05 < f["pp_deg_dither"]["p50"] < 0.3


def test_bounds_come_from_ema_analyze_json(tmp_path):
    doc = {"tool": "ema analyze", "second_order_spread": {"position_deg": {
        "wn_rad_s": {"min": 52.0, "max": 61.0}, "zeta": {"min": 0.6, "max": 0.71}, "delay_s": {"min": 0.0035,
                                                                                                "max": 0.0052}}},
        "command_error_bounds": {"kb_max_abs": 0.004, "offset_max_abs_deg": 0.03}}
    a, b = tmp_path / "a.json", tmp_path / "b.json"
    a.write_text(json.dumps(doc), encoding="utf-8")
    doc["second_order_spread"]["position_deg"]["wn_rad_s"] = {"min": 50.0, "max": 58.0}
    doc["command_error_bounds"]["kb_max_abs"] = -0.005
    b.write_text(json.dumps(doc), encoding="utf-8")
    c = load_campaign("second-order-bounds", analysis=[a, b])
    box = {n: (lo, hi) for d in c.dispersions for n, lo, hi in zip(d.names, d.low, d.high, strict=True)}
    assert box == {"wn_rad_s": (50.0, 61.0), "zeta": (0.6, 0.71), "delay_s": (0.0035, 0.0052)}
    ce = load_campaign("command-error", analysis=[a, b])
    assert ce.dispersions[0].low.tolist() == [-0.005, -0.03]
    assert ce.dispersions[0].high.tolist() == [0.005, 0.03]
    assert json.loads(c.to_json())["dispersions"][0]["uniform"] == [[50.0, 61.0]]  # resolved into the manifest


def test_the_docs_campaign_file_is_a_campaign():
    text = (Path(__file__).resolve().parents[1] / "docs" / "montecarlo.md").read_text(encoding="utf-8")
    block = text[text.index("## A campaign file"):]
    start = block.index("```yaml") + len("```yaml")
    c = parse_campaign(yaml.safe_load(block[start:block.index("```", start)]), "docs")
    assert c.parameters == ("stator_resistance_ohm", "bound", "position_gain_per_s", "lvdt_filter_hz",
                            "step.load.inlb", "response.maneuver.amp_deg", "dwells.load_inlb")
    assert [e.kind for e in c.experiments] == ["record", "multisine", "dwell"]
