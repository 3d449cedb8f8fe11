"""HOALM and LOES (sections 3.4, 4.2.7, 4.2.8) and the tools they are built with."""

import json
import math

import numpy as np
import pytest
from conftest import frames

from ema_sim.analysis.estimation.tf_fit import fit_transfer_function, levy_sk, loes_cost, second_order_coefficients
from ema_sim.analysis.section2.sine_dwell import sine_dwell
from ema_sim.analysis.studies.loes import fit_loes, write_loes
from ema_sim.cli import main
from ema_sim.config import config_dir, load_channel
from ema_sim.errors import EmaError, UnknownNameError
from ema_sim.io.csv import read_csv
from ema_sim.models import create

FIT = np.geomspace(0.5, 20.0, 24)


def second_order(f, wn, zeta, delay, gain=1.0):
    s = 2j * np.pi * np.asarray(f)
    return gain * wn**2 / (s**2 + 2 * zeta * wn * s + wn**2) * np.exp(-s * delay)


# ------------------------------------------------------------------------------------- tf_fit
def test_levy_sk_recovers_a_rational_response_exactly():
    f = np.geomspace(0.1, 30.0, 30)
    s = 2j * np.pi * f
    h = (3.0 * s + 120.0) / (s**3 + 40.0 * s**2 + 900.0 * s + 120.0)
    num, den = levy_sk(f, h, 1, 3)
    assert np.allclose(num, [3.0, 120.0], rtol=1e-8)
    assert np.allclose(den, [1.0, 40.0, 900.0, 120.0], rtol=1e-8)


def test_fit_recovers_a_second_order_plus_delay_and_its_cost_is_zero():
    h = second_order(FIT, 58.0, 0.62, 0.0071, 0.98)
    fit = fit_transfer_function(FIT, h, 0, 2)
    c = second_order_coefficients(fit)
    assert c["wn_rad_s"] == pytest.approx(58.0, rel=1e-8)
    assert c["zeta"] == pytest.approx(0.62, rel=1e-8)
    assert c["delay_s"] == pytest.approx(0.0071, rel=1e-7)
    assert c["dc_gain_ratio"] == pytest.approx(0.98, rel=1e-8)
    assert fit.cost < 1e-12


def test_fit_with_measurement_error_stays_close_and_the_nonlinear_step_beats_levy():
    rng = np.random.default_rng(4)
    h = second_order(FIT, 64.0, 0.75, 0.0085) * (1 + 0.02 * (rng.standard_normal(FIT.size)
                                                           + 1j * rng.standard_normal(FIT.size)))
    fit = fit_transfer_function(FIT, h, 0, 2)
    c = second_order_coefficients(fit)
    assert c["wn_rad_s"] == pytest.approx(64.0, rel=0.03)
    assert c["zeta"] == pytest.approx(0.75, rel=0.05)
    assert c["delay_s"] == pytest.approx(0.0085, abs=5e-4)
    num, den = levy_sk(FIT, h, 0, 2, delay_s=fit.delay_s)
    s = 2j * np.pi * FIT
    levy_only = np.polyval(num, s) / np.polyval(den, s) * np.exp(-s * fit.delay_s)
    assert fit.cost <= loes_cost(FIT, levy_only, h) + 1e-12


def test_loes_cost_is_the_mil_standard_mismatch_function():
    f = np.array([1.0, 2.0, 4.0, 8.0])
    data = np.ones(4, dtype=complex)
    model = 10 ** (1.0 / 20) * np.exp(1j * np.radians([0.0, 10.0, 0.0, -10.0]))  # 1 dB; 0/±10°
    expected = 20.0 / 4 * (4 * 1.0**2 + 0.01745 * (2 * 10.0**2))
    assert loes_cost(f, model, data) == pytest.approx(expected, rel=1e-9)
    with pytest.raises(EmaError, match="same frequencies"):
        loes_cost(f, model[:3], data)


def test_bad_fit_input_is_one_clear_error():
    with pytest.raises(EmaError, match="enough positive frequencies"):
        fit_transfer_function([1.0, 2.0], [1.0, 1.0], 0, 2)


# ------------------------------------------------------------------------------------- sine dwell
def test_sine_dwell_measures_a_known_linear_model_exactly():
    """SLOAC's response is known in closed form: the batch dwell reproduces it."""
    f = np.array([0.5, 2.0, 7.5, 15.0])
    model = create("sloac", n=f.size)
    fr = sine_dwell(model, f, 1.0, measure_cycles=3)
    gain, phase = model.frequency_response(f)
    assert np.allclose(fr.gain_db, gain, atol=0.01)  # the 10 kHz hold of the input: ≤ 0.05 ms of lag
    assert np.allclose(fr.phase_deg, phase, atol=0.3)
    assert fr.bandwidth_hz() == pytest.approx(float(np.interp(-3.0, gain[::-1], f[::-1])), rel=0.05)
    with pytest.raises(EmaError, match="4 instances for 3 frequencies"):
        sine_dwell(create("sloac", n=4), f[:3], 1.0)


# ------------------------------------------------------------------------------------- HOALM
def _hoad3_vs_hoalm(load_inlb, amp_deg):
    f = np.array([1.0, 5.0, 10.0, 15.0, 20.0])
    fr = sine_dwell(create("hoad3", n=f.size, noise=False), f, amp_deg, hinge_moment_inlb=load_inlb)
    gain, phase = create("hoalm", load_inlb=load_inlb).frequency_response(f)
    return f, gain - fr.gain_db, phase - fr.phase_deg


def test_hoalm_is_hoad3_linearized_with_its_delays_exact():
    lin = create("hoalm")
    assert lin.delay_s == 0.004
    assert lin.position_delay_s == 0.002
    assert lin.system.nstates == 7
    assert np.all(np.real(np.linalg.eigvals(lin.system.A)) < 0.0)
    # The surface output has the command delay only; the position output 2 ms more (section 2.3).
    f = np.array([5.0])
    pos = lin.complex_response(f, 0) / np.exp(-2j * np.pi * f * 0.002)
    s = 2j * np.pi * f
    raw = lin.system.C[0] @ np.linalg.solve(s[0] * np.eye(7) - lin.system.A, lin.system.B[:, 0])
    assert pos[0] == pytest.approx(raw * np.exp(-s[0] * 0.004), rel=1e-12)
    # Stepped at 10 kHz it holds its trim and follows a step to the linear steady state.
    t = frames(1.5)
    lin.trim(0.0, -500.0)
    rec = lin.run(t, np.where(t >= 0.2, 1.0, 0.0), np.full_like(t, -500.0), end_s=1.5)
    assert np.ptp(rec.position_deg[0, t < 0.2]) < 1e-12
    assert rec.position_deg[0, -1] == pytest.approx(1.0, abs=0.01)


def test_hoalm_under_predicts_like_section_4_2_7():
    """At low load HOALM under-predicts the wing gain at the top of the band; better at high load;
    and it under-predicts the phase loss through the control band at every load."""
    f, dg_low, dp_low = _hoad3_vs_hoalm(0.0, 0.4)
    assert np.min(dg_low[f >= 15.0]) < -1.0  # dB: HOALM below HOAD3
    assert np.all(dp_low[f <= 5.0] > 3.0)  # deg: HOALM lags less than HOAD3
    _, dg_high, dp_high = _hoad3_vs_hoalm(-1780.0, 1.0)
    assert np.max(np.abs(dg_high)) < 0.6
    assert np.max(np.abs(dg_high)) < 0.5 * np.max(np.abs(dg_low))
    assert np.all(dp_high[f <= 10.0] > 0.0)


def test_hoalm_options_and_errors():
    upper = create("hoalm", load_inlb=1000.0, bound="upper")
    lower = create("hoalm", load_inlb=1000.0, bound="lower")
    assert upper.linearized.total_stiffness_lbf_per_in < lower.linearized.total_stiffness_lbf_per_in
    assert create("hoalm", load_inlb=3000.0).linearized.total_stiffness_lbf_per_in == pytest.approx(70000.0)
    with pytest.raises(UnknownNameError, match="high-order parameter 'kp'"):
        create("hoalm", kp=3.0)


# ------------------------------------------------------------------------------------- LOES
def test_loes_is_the_stored_second_order_plus_delay():
    model = create("loes", "left_wing")
    c = model.coefficients
    gain, phase = model.frequency_response(FIT)
    h = second_order(FIT, c["wn_rad_s"], c["zeta"], c["delay_s"], c["dc_gain_ratio"])
    assert np.allclose(gain, 20 * np.log10(np.abs(h)), atol=1e-9)
    assert np.allclose(phase, np.degrees(np.unwrap(np.angle(h))), atol=1e-6)
    assert 55.0 < c["wn_rad_s"] < 75.0
    assert 0.6 < c["zeta"] < 0.9
    assert 0.006 < c["delay_s"] < 0.012  # the 4 + 2 ms delays and the lags an order 2 leaves out
    with pytest.raises(UnknownNameError, match="LOES parameter 'wn'"):
        create("loes", wn=3.0)


def test_stored_loes_is_what_the_fit_to_hoad3_gives_and_matches_it_well(tmp_path):
    fit = fit_loes("left_wing")
    stored = load_channel("left_wing").section("loes")
    for key in ("wn_rad_s", "zeta", "delay_s", "dc_gain_ratio"):
        assert fit.coefficients[key] == pytest.approx(stored[key], rel=1e-3), key
    assert fit.cost < 2.0  # J over 0.5–20 Hz; the LOES literature calls J ≤ 10 a good match
    gain, phase = fit.model_db_deg()
    assert np.max(np.abs(gain - fit.data.gain_db)) < 0.5
    assert np.max(np.abs(phase - fit.data.phase_deg)) < 5.0
    # write_loes updates the numbers in place and keeps everything else.
    copy = tmp_path / "left_wing.yaml"
    original = (config_dir() / "left_wing.yaml").read_text()
    copy.write_text(original.replace("zeta: " + str(stored["zeta"]), "zeta: 0.5"))
    write_loes(fit, copy)
    text = copy.read_text()
    assert f"zeta: {fit.coefficients['zeta']:.6g}" in text
    assert f"J = {fit.cost:.3f}" in text
    assert len(text.splitlines()) == len(original.splitlines())


# ------------------------------------------------------------------------------------- CLI
@pytest.mark.parametrize("name", ["hoac1", "hoad2", "hoad3", "hoalm", "loes"])
def test_every_new_model_simulates_from_the_cli(tmp_path, name):
    out = tmp_path / f"{name}.csv"
    args = ["simulate", "--model", name, "--maneuver", "step:amp_deg=2,hold_s=0.5", "--load", "const:inlb=-300",
            "--csv", str(out)]
    if name in ("hoad2", "hoad3"):
        args += ["--set", "noise=0", "--set", "seed=2"]
    assert main(args) == 0
    data = read_csv(out)
    assert data.metadata["model"] == name
    held = (data.time_s > 0.85) & (data.time_s < 1.0)  # the step: 0.5 s of lead, then 0.5 s held
    assert np.max(np.abs(data.position_deg[held] - 2.0)) < 0.06
    if name.startswith("hoa") and name != "hoalm":
        assert data.current_a is not None
        assert np.all(np.isfinite(data.current_a))


def test_ema_loes_prints_the_fit_and_its_cost(tmp_path, capsys):
    out = tmp_path / "loes.json"
    assert main(["loes", "--channel", "left_rudder", "--json", str(out)]) == 0
    text = capsys.readouterr().out
    assert "LOES of HOAD3, left_rudder" in text
    assert "J = " in text
    fit = json.loads(out.read_text())
    assert fit["cost_j"] == pytest.approx(float(text.split("J = ")[1].split()[0]), abs=1e-3)
    assert math.isclose(fit["wn_rad_s"], load_channel("left_rudder").section("loes")["wn_rad_s"], rel_tol=1e-3)
