"""ema monitor: detection at the onset, isolation of the injected kind, its size re-estimated; clear errors."""

from __future__ import annotations

import dataclasses
import json
import math
import subprocess
import sys

import numpy as np
import pytest

from ema_sim.config import load_channel
from ema_sim.errors import DataError
from ema_sim.faults import parse_fault
from ema_sim.io.csv import write_csv
from ema_sim.io.measured import MeasuredData
from ema_sim.monitor import Cusum, Options, check_inputs, from_name, from_report, learn, threshold, watch
from ema_sim.monitor.detect import arl0
from ema_sim.signals import parse_load, parse_maneuver
from ema_sim.simulation import csv_columns, simulate

MANEUVER = parse_maneuver("sine:amp_deg=3,freq_hz=0.5,cycles=20")
HEALTHY_S = 8.0


def record(fault: str | None, seed: int = 0, duration_s: float = 14.0) -> MeasuredData:
    """A loaded LOADA sine with 0.01 deg of sensor noise, and a fault at 10 s."""
    faults = [parse_fault(fault)] if fault else []
    _, rec, _ = simulate("loada", MANEUVER, parse_load("const:inlb=800"), duration_s=duration_s, faults=faults)
    rng = np.random.default_rng(seed)
    n = rec.time_s.size
    return MeasuredData(rec.time_s, rec.command_deg[0], rec.position_deg[0] + rng.normal(0.0, 0.01, n),
                        rec.surface_deg[0] + rng.normal(0.0, 0.01, n), rec.hinge_moment_inlb[0], source="test")


def verdict(fault: str | None):
    """The monitor's verdict on a record against LOADA's nominal model."""
    return watch(record(fault), from_name("loada", load_channel("left_wing")), Options(healthy_s=HEALTHY_S))


def test_the_threshold_meets_the_false_alarm_rate():
    h = threshold(0.1, 0.02)
    assert math.isclose(2.0 * 3600.0 / 0.02 / 0.1, arl0(h, 0.5), rel_tol=1e-6)


def test_cusum_alarms_on_a_shift_not_on_noise():
    rng = np.random.default_rng(1)
    quiet = Cusum(threshold(0.1, 0.02))
    assert not any(quiet.update(float(z)) for z in rng.normal(0.0, 1.0, 5000))
    shifted = Cusum(threshold(0.1, 0.02))
    assert any(shifted.update(float(z)) for z in rng.normal(3.0, 1.0, 50))


def test_a_clean_record_raises_no_alarm():
    assert verdict(None).detections == []


@pytest.mark.parametrize(("fault", "kind", "size"), [
    ("delay:at_s=10,size=0.005", "delay", 0.005),
    ("lvdt_bias:at_s=10,size=0.1", "lvdt_bias", 0.1),
    ("viscous_friction:at_s=10,size=0.5", "viscous_friction", 0.5),
])
def test_a_fault_is_detected_isolated_and_re_estimated(fault, kind, size):
    v = verdict(fault)
    d = v.detections[0]
    assert 10.0 <= d.time_s < 12.0
    assert d.kind == kind
    assert abs(d.size - size) < 0.2 * size


def test_a_jam_is_detected_within_a_tenth_of_a_second():
    d = verdict("jam:at_s=10").detections[0]
    assert d.time_s - 10.0 <= 0.1
    assert d.kind == "jam"


def test_a_record_without_load_is_a_clear_error():
    data = dataclasses.replace(record(None), hinge_moment_inlb=None)
    with pytest.raises(DataError, match="hinge moment"):
        check_inputs(data)


def test_a_report_of_another_channel_is_a_clear_error(tmp_path):
    path = tmp_path / "r.json"
    path.write_text(json.dumps({"data": "x.csv", "channel": "right_rudder", "outputs": ["position_deg"],
                                "final": {"model": "second_order", "params": {"wn_rad_s": 50.0, "zeta": 0.7}}}))
    with pytest.raises(DataError, match="right_rudder"):
        from_report(path, load_channel("left_wing"))


def test_the_command_writes_detections_with_the_contract_keys(tmp_path):
    faults = [parse_fault("lvdt_bias:at_s=10,size=0.1")]
    model, rec, meta = simulate("loada", MANEUVER, parse_load("const:inlb=800"), duration_s=13.0, faults=faults)
    csv = tmp_path / "f.csv"
    write_csv(csv, csv_columns(model, rec, faults=faults), meta)
    out = tmp_path / "v.json"
    done = subprocess.run([sys.executable, "-m", "ema_sim.cli", "monitor", str(csv), "--model", "loada",
                           "--healthy-s", "8", "--json", str(out)], capture_output=True, text=True, check=False)
    assert done.returncode == 0, done.stderr
    d = json.loads(out.read_text())["detections"][0]
    assert {"time_s", "output", "kind", "parameter", "estimate", "uncertainty", "statistic"} <= set(d)
    assert d["kind"] == "lvdt_bias"


def test_a_small_fault_campaign_writes_its_table_and_scores(tmp_path):
    import pyarrow.parquet as pq  # noqa: PLC0415 - Parquet only here

    from ema_sim.montecarlo.faults import Case, plot_campaign, run_campaign, summarize  # noqa: PLC0415

    common = {"duration_s": 14.0, "onset_s": 10.0, "healthy_s": 8.0}
    rows = run_campaign([Case("lvdt_bias", 0.1, MANEUVER.spec(), 0, **common),
                         Case("none", 0.0, MANEUVER.spec(), 1, **common)], tmp_path, workers=0)
    s = summarize(rows)
    assert pq.read_table(tmp_path / "cases.parquet").num_rows == 2
    assert s["confusion"] == {"lvdt_bias": {"lvdt_bias": 1}}
    assert s["false_alarms"] == 0
    assert all(p.is_file() for p in plot_campaign(rows, tmp_path))


def test_a_report_escalated_to_the_high_order_physics_gives_that_reference(tmp_path):
    path = tmp_path / "r.json"
    path.write_text(json.dumps({"data": "x.csv", "channel": "left_wing", "outputs": ["position_deg"],
                                "final": {"model": "hoad3 (physical parameters fitted)",
                                          "params": {"command_delay_s": 0.005, "coulomb_friction_lbf": 41.0}}}))
    ref = from_report(path, load_channel("left_wing"))
    assert ref.model == "hoad3"
    assert ref.overrides == {"command_delay_s": 0.005, "coulomb_friction_lbf": 41.0}


def test_the_command_watches_a_bag_and_finds_the_fault_in_it(tmp_path):
    """``ema monitor BAG``: a suite bag (MCAP) of a run with a delay fault, read back and watched."""
    from ema_sim.cli import main  # noqa: PLC0415 - the command in process
    from ema_sim.io.bag import write_bag  # noqa: PLC0415 - bags only here

    faults = [parse_fault("delay:at_s=10,size=0.005")]
    _, rec, _ = simulate("loada", MANEUVER, parse_load("const:inlb=800"), duration_s=14.0, sample_hz=200.0,
                         faults=faults)
    rng = np.random.default_rng(3)
    n = rec.time_s.size
    bag = write_bag(tmp_path / "run", {"time_s": rec.time_s, "command_deg": rec.command_deg[0],
                                       "position_deg": rec.position_deg[0] + rng.normal(0.0, 0.01, n),
                                       "surface_deg": rec.surface_deg[0] + rng.normal(0.0, 0.01, n),
                                       "hinge_moment_inlb": rec.hinge_moment_inlb[0]},
                    {"test": "monitor"}, channel="left_wing", frame_hz=200.0)
    out = tmp_path / "v.json"
    assert main(["monitor", str(bag), "--model", "loada", "--channel", "left_wing", "--healthy-s", "8",
                 "--json", str(out)]) == 0
    d = json.loads(out.read_text())["detections"][0]
    assert d["kind"] == "delay"
    assert 10.0 <= d["time_s"] <= 10.5
    assert abs(d["size"] - 0.005) < 0.2 * 0.005


def test_the_online_monitor_re_baselines_and_detects_a_second_fault():
    """A longer delay, then a bias of the reading: each detected, isolated and sized against the model before it."""
    from ema_sim.monitor.online import OnlineMonitor  # noqa: PLC0415 - the frame-by-frame path

    faults = [parse_fault("delay:at_s=10,size=0.005"), parse_fault("lvdt_bias:at_s=16,size=0.1")]
    _, rec, _ = simulate("loada", MANEUVER, parse_load("const:inlb=800"), duration_s=22.0, sample_hz=200.0,
                         faults=faults)
    rng = np.random.default_rng(5)
    mon = OnlineMonitor(from_name("loada", load_channel("left_wing")), Options(healthy_s=HEALTHY_S, window_s=3.0))
    found = []
    for k in range(1, rec.time_s.size):
        d = mon.step(rec.command_deg[0, k - 1], rec.hinge_moment_inlb[0, k - 1],
                     rec.position_deg[0, k] + rng.normal(0.0, 0.01), rec.surface_deg[0, k] + rng.normal(0.0, 0.01))
        if d is not None:
            found.append(d)
    assert [d.kind for d in found] == ["delay", "lvdt_bias"]
    assert 10.0 <= found[0].time_s < 11.0
    assert 16.0 <= found[1].time_s < 17.0
    assert abs(found[0].size - 0.005) < 0.001
    assert abs(found[1].size - 0.1) < 0.02
    assert mon.reference.overrides["delay_s"] == found[0].estimate
    assert mon.readings[0][:2] == ("lvdt_bias", found[1].estimate)


def test_a_high_order_coulomb_friction_growth_is_sized_within_a_fifth():
    """HOAD2's friction +50 % under steps and a reversing load: the reference dithers its friction as the actuator
    does (a noise-free one sticks where the actuator slips and sizes the growth near +30 %)."""
    from ema_sim.montecarlo.faults import Case, run_case  # noqa: PLC0415 - a campaign's case

    row = run_case(Case("coulomb_friction", 0.5, "square:amp_deg=4,freq_hz=0.5,cycles=20", 3, model="hoad2",
                        load="sine:amp_inlb=1500,freq_hz=0.25"))
    assert row["isolated"] == "coulomb_friction"
    assert row["delay_s"] <= 1.0
    assert abs(row["size_estimate"] - 0.5) <= 0.1


def test_a_learned_reference_is_the_fidelity_that_reproduces_the_healthy_window(monkeypatch):
    """A LOADA record learns the second order. A HOAD3 actuator under steps and a reversing load, its command delay
    and friction off the channel's values, learns HOAD3's physics with its delay fitted (no second order reproduces
    its step transients, nor HOAD3 at the channel's values its delay), and its clean record raises no alarm."""
    import ema_sim.montecarlo.faults as campaign  # noqa: PLC0415 - a campaign's record
    from ema_sim.models import create  # noqa: PLC0415 - the off-nominal actuator

    ch = load_channel("left_wing")
    assert learn(record(None), ch, HEALTHY_S).model == "second_order"
    monkeypatch.setattr(campaign, "create", lambda name, channel, **kw: create(
        name, channel, **kw, command_delay_s=0.006, coulomb_friction_lbf=48.0))
    data = campaign.measured(campaign.Case("none", 0.0, "square:amp_deg=4,freq_hz=0.5,cycles=20", 1001,
                                           model="hoad3", load="sine:amp_inlb=1500,freq_hz=0.25"))
    ref = learn(data, ch, 20.0)
    assert ref.model == "hoad3"
    assert ref.overrides["command_delay_s"] > 0.0045
    assert watch(data, ref, Options(healthy_s=20.0)).detections == []


@pytest.mark.parametrize(("fault", "ruled_out"), [
    ("lvdt_bias:at_s=10,size=0.1", {"viscous_friction", "backlash", "delay", "hm_sign", "jam"}),
    ("delay:at_s=10,size=0.005", {"lvdt_bias", "lvdt_drift", "lvdt_scale", "jam"}),
    ("jam:at_s=10", {"lvdt_bias", "lvdt_drift", "lvdt_scale"}),
])
def test_the_signature_rules_out_the_kinds_it_contradicts(fault, ruled_out):
    """A bias moves the reading, not the surface; a delay moves both; a jam stops the rod: the kinds the signature
    contradicts rank after the others, whatever their fits' scores."""
    d = verdict(fault).detections[0]
    assert {e.kind for e in d.ranking if e.veto} == ruled_out
    vetoed = [bool(e.veto) for e in d.ranking]
    assert vetoed == sorted(vetoed)
