"""Aircraft in the loop (issue 7): the vehicle loop, the dither finding, and the ROS run against the offline one."""

import json
import os

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from ema_sim.ail.autopilot import Autopilot
from ema_sim.ail.bag import run_from_bag
from ema_sim.ail.loop import AilOptions, run_ail
from ema_sim.ail.measure import measure
from ema_sim.ail.params import WINGS, config_path, load_ail_config
from ema_sim.ail.vehicle import Vehicle, discretize, matrices
from ema_sim.cli import main as ema
from ema_sim.config import ros_parameters
from ema_sim.errors import EmaError, UnknownNameError
from ema_sim.io.csv import read_csv
from ema_sim.nodes.fmu import _declared
from ema_sim.nodes.params import config_specs
from ema_sim.suite import SuiteConfig, free_domain_id, run_suite

CFG = load_ail_config()
SETTLE = CFG.settle_s
DURATION = 12.0  # 8 s of trimmed flight measured: ≈ 20 periods of a 2.7 Hz cycle


def wings(run):
    return measure(run, SETTLE, channels=WINGS)


# --------------------------------------------------------------------------- vehicle and autopilot
def test_vehicle_is_a_one_hertz_short_period_and_a_first_order_roll_mode():
    a, _ = matrices(CFG.vehicle)
    eig = np.linalg.eigvals(a[:2, :2])
    wn = np.sqrt(np.prod(eig).real)
    assert wn / (2 * np.pi) == pytest.approx(np.sqrt(40.0 + 1.2) / (2 * np.pi), rel=0.02)
    assert np.all(eig.real < 0)
    assert a[3, 3] == pytest.approx(CFG.vehicle.l_p_per_s)


def test_zero_order_hold_discretization_matches_integrating_a_held_input():
    a, b = matrices(CFG.vehicle)
    ad, bd = discretize(a, b, 0.005)
    x0 = np.array([0.3, -2.0, 0.1, 5.0, -0.4])
    u = np.array([0.7, -0.2])
    sol = solve_ivp(lambda _t, x: a @ x + b @ u, (0.0, 0.005), x0, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(ad @ x0 + bd @ u, sol.y[:, -1], atol=1e-9)


def test_at_trim_the_autopilot_commands_the_trim_and_the_vehicle_stays_put():
    veh = Vehicle(CFG.vehicle, 0.005)
    ap = Autopilot(CFG.autopilot, 0.005)
    for _ in range(400):
        cmd = ap.command(veh.state)
        veh.advance(cmd.left_deg, cmd.right_deg)
    s = veh.state
    assert cmd.left_deg == pytest.approx(CFG.autopilot.trim_elevon_deg, abs=1e-12)
    assert cmd.right_deg == pytest.approx(CFG.autopilot.trim_elevon_deg, abs=1e-12)
    assert s.alpha_deg == pytest.approx(CFG.vehicle.trim_alpha_deg, abs=1e-12)
    assert abs(s.q_dps) < 1e-12
    assert abs(s.p_dps) < 1e-12


def test_a_pitch_disturbance_is_held_out_by_the_autopilot_with_ideal_actuators():
    veh = Vehicle(CFG.vehicle, 0.005)
    ap = Autopilot(CFG.autopilot, 0.005)
    veh.x[1] = 5.0  # a 5 deg/s pitch-rate gust
    theta0 = veh.state.theta_deg
    peak = 0.0
    for _ in range(1600):
        cmd = ap.command(veh.state)
        veh.advance(cmd.left_deg, cmd.right_deg)
        peak = max(peak, abs(veh.state.theta_deg - theta0))
    assert peak > 0.01  # it was disturbed
    assert abs(veh.state.theta_deg - CFG.vehicle.trim_theta_deg) < 0.02 * peak  # and brought back
    assert abs(veh.state.q_dps) < 0.01


# --------------------------------------------------------------------------- the finding (section 4.3)
@pytest.fixture(scope="module")
def ail_closed():
    return run_ail(AilOptions(profile="ail", model="hoad3", duration_s=DURATION))


def test_closed_loop_ail_dithers_near_3_hz_by_about_a_tenth_of_a_degree(ail_closed):
    for w in wings(ail_closed).values():
        assert w.dither, w.statement
        assert 2.0 <= w.freq_hz <= 4.0, w.statement
        assert 0.05 <= w.peak_to_peak_deg <= 0.2, w.statement
    # the cycle shows in the flight data too: pitch rate at the same frequency (section 2.10)
    q = ail_closed.vehicle["q_dps"][ail_closed.time_s >= SETTLE]
    spec = np.abs(np.fft.rfft(q - q.mean()))
    f = np.fft.rfftfreq(q.size, 0.005)
    assert abs(f[np.argmax(spec)] - wings(ail_closed)["left_wing"].freq_hz) < 0.3


@pytest.mark.parametrize(("name", "options", "settle_s"), [
    ("open loop", {"profile": "ail", "open_loop": True}, SETTLE),
    ("flight", {"profile": "flight"}, SETTLE),
    ("no PWM dead band", {"profile": "ail", "disable": ("dead_band",)}, SETTLE),
    ("no test-set delay", {"profile": "ail", "disable": ("delay",)}, SETTLE),
    # without noise nothing kicks the actuator out of the dead band: the start-up cycle dies within ≈ 10 s
    ("no noise", {"profile": "ail", "disable": ("noise",), "duration_s": 24.0}, 12.0),
    ("second-order model (LOADA)", {"profile": "ail", "model": "loada"}, SETTLE),
])
def test_no_dither_without_the_interaction(name, options, settle_s):
    run = run_ail(AilOptions(**{"model": "hoad3", "duration_s": DURATION, **options}))
    for w in measure(run, settle_s, channels=WINGS).values():
        assert not w.dither, f"{name}: {w.statement}"
        assert w.peak_to_peak_deg < 0.05, f"{name}: {w.statement}"


def test_the_bungee_of_section_4_3_does_not_stop_the_dither():
    setup = CFG.setup("ail", bungee_inlb=100.0)
    run = run_ail(AilOptions(profile="ail", model="hoad3", duration_s=DURATION, setup=setup))
    assert all(w.dither for w in wings(run).values())
    assert np.allclose(run.signals["left_wing"]["hinge_moment_inlb"], 100.0)


def test_the_run_is_reproducible_and_the_seed_matters(ail_closed):
    again = run_ail(AilOptions(profile="ail", model="hoad3", duration_s=2.0))
    np.testing.assert_array_equal(again.signals["left_wing"]["position_v"],
                                  ail_closed.signals["left_wing"]["position_v"][:400])
    other = run_ail(AilOptions(profile="ail", model="hoad3", duration_s=2.0, seed=7))
    assert not np.array_equal(other.signals["left_wing"]["position_v"], again.signals["left_wing"]["position_v"])


# --------------------------------------------------------------------------- the CLI
def test_ema_ail_writes_a_contract_csv_and_json(tmp_path, capsys):
    out, js = tmp_path / "ail.csv", tmp_path / "ail.json"
    assert ema(["ail", "--profile", "ail", "--duration", "8", "--csv", str(out), "--json", str(js)]) == 0
    text = capsys.readouterr().out
    assert "left_wing     dither:" in text
    data = read_csv(out)
    assert data.time_s.size == 1600
    assert data.position_deg is not None
    doc = json.loads(js.read_text())
    assert doc["surfaces"]["left_wing"]["dither"] is True
    assert doc["surfaces"]["cowl_door"]["dither"] is False


def test_ema_ail_study_runs_named_cases(tmp_path):
    md = tmp_path / "study.md"
    assert ema(["ail", "--study", "--cases", "ail,no_dead_band", "--seeds", "43", "--duration", "10",
                "--markdown", str(md)]) == 0
    rows = md.read_text().splitlines()
    assert len(rows) == 4
    assert "| **yes** |" in rows[2]
    assert "| no |" in rows[3]


@pytest.mark.parametrize(("args", "message"), [
    (["ail", "--disable", "flux"], "unknown element 'flux'"),
    (["ail", "--model", "loada", "--disable", "dead_band"], "loada has no PWM dead band"),
    (["ail", "--model", "nope"], "unknown model 'nope'"),
    (["ail", "--duration", "5"], "--duration must leave at least 4 s"),
    (["ail", "--study", "--cases", "nope"], "unknown study case 'nope'"),
    (["ail", "--study", "--seeds", "x"], "--seeds takes comma-separated integers"),
    (["ail", "--profile", "nope"], "nope"),
])
def test_bad_input_is_one_line_and_status_2(args, message, capsys):
    assert ema(args) == 2
    err = capsys.readouterr().err.strip()
    assert message in err
    assert len(err.splitlines()) == 1


def test_unknown_element_lists_the_known_ones():
    with pytest.raises(UnknownNameError, match="dead_band"):
        run_ail(AilOptions(disable=("flux",), duration_s=1.0))
    with pytest.raises(EmaError):
        run_ail(AilOptions(duration_s=float("nan")))


# --------------------------------------------------------------------------- the node suite, lockstep
@pytest.mark.ros
@pytest.mark.parametrize(("layout", "open_loop"), [("single", False), ("container", True)])
def test_the_lockstep_suite_flies_the_offline_run_frame_for_frame(tmp_path, layout, open_loop):
    """``ema launch --fmu --lockstep`` records the same numbers, frame for frame, as ``ema ail``."""
    duration = 3.0
    bag = tmp_path / "ail"
    cfg = SuiteConfig(bag=bag, model="hoad3", profile="ail", lockstep=True, layout=layout, emac="box",
                      fmu=True, duration_s=duration, fmu_args=["--open-loop"] if open_loop else [],
                      domain_id=free_domain_id(os.getpid() + 31 + open_loop))
    summaries = run_suite(cfg, timeout_s=240)
    assert summaries["fmu"]["completed"] is True
    ros = run_from_bag(bag)
    off = run_ail(AilOptions(profile="ail", model="hoad3", duration_s=duration, open_loop=open_loop))
    assert ros.time_s.size == off.time_s.size == 600
    for ch in ros.signals:
        for sig in ("fmu_command_v", "command_v", "position_v", "fmu_position_v", "surface_deg",
                    "hinge_moment_inlb"):
            np.testing.assert_array_equal(ros.signals[ch][sig], off.signals[ch][sig], err_msg=f"{ch} {sig}")
    for state in off.vehicle:
        np.testing.assert_array_equal(ros.vehicle[state], off.vehicle[state], err_msg=state)


def test_every_number_of_the_vehicle_file_is_declared_with_its_unit():
    """The fmu node's descriptors take units from the declarations (no suffix table): none is left without."""
    values = ros_parameters(config_path())
    specs = config_specs(values, "ail_vehicle.yaml", known=_declared(values))
    numbers = [s for s in specs if isinstance(s.default, int | float) and not isinstance(s.default, bool)]
    assert len(numbers) > 30
    assert [s.name for s in numbers if not s.unit] == []
    units = {s.name: s.unit for s in numbers}
    assert units["frame_hz"] == "Hz"
    assert units["measure.settle_s"] == "s"
    assert units["setup.ail.bungee_inlb"] == "in·lb"
    assert all(units[n] == "deg" for n in units if n.startswith("held_deg."))
    assert any(n.startswith("held_deg.") for n in units)
