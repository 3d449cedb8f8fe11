"""Faults injected on a schedule: each moves its stage from its onset, nothing before, and its truth is recorded."""

from __future__ import annotations

import numpy as np
import pytest

from ema_sim.errors import EmaError, SpecError
from ema_sim.faults import parse_fault, truth_columns
from ema_sim.signals import parse_load, parse_maneuver
from ema_sim.simulation import csv_columns, simulate

MANEUVER = parse_maneuver("sine:amp_deg=2,freq_hz=1,cycles=3")


def run(*faults: str, model: str = "loada", load: str | None = None, **overrides: float):
    """A 3 s faulted run and its fault-free twin."""
    parsed = [parse_fault(f) for f in faults]
    ld = parse_load(load) if load else None
    _, rec, meta = simulate(model, MANEUVER, ld, duration_s=3.0, faults=parsed, **overrides)
    _, ref, _ = simulate(model, MANEUVER, ld, duration_s=3.0, **overrides)
    return rec, ref, meta


def test_no_change_before_onset_and_delay_lags_after():
    rec, ref, _ = run("delay:at_s=1.5,size=0.02")
    before = rec.time_s < 1.5
    assert np.array_equal(rec.position_deg[0, before], ref.position_deg[0, before])
    after = rec.time_s > 1.8
    err = rec.position_deg[0, after] - ref.position_deg[0, after]
    # a 20 ms extra lag on a 2 deg, 1 Hz sine: about 2*pi*1*2*0.02 = 0.25 deg peak error
    assert 0.15 < np.max(np.abs(err)) < 0.4


def test_lvdt_bias_moves_the_reading_not_the_surface():
    rec, ref, meta = run("lvdt_bias:at_s=1,size=0.1")
    after = rec.time_s >= 1.0
    assert np.allclose(rec.position_deg[0, after] - ref.position_deg[0, after], 0.1)
    assert np.array_equal(rec.surface_deg, ref.surface_deg)
    assert meta["faults"] == "lvdt_bias:at_s=1,ramp_s=0,size=0.1"


def test_jam_stops_the_rod():
    rec, _, _ = run("jam:at_s=1")
    held = rec.position_deg[0, (rec.time_s > 1.05)]
    assert np.ptp(held) < 1e-5
    assert np.ptp(rec.command_deg[0, rec.time_s > 1.05]) > 1.5


def test_hinge_moment_sign_error_keeps_the_declared_load_in_the_record():
    rec, ref, _ = run("hm_sign:at_s=1", load="const:inlb=2000", compliance_deg_per_kinlb=0.1)
    assert np.array_equal(rec.hinge_moment_inlb, ref.hinge_moment_inlb)
    after = rec.time_s > 1.5
    assert np.max(np.abs(rec.surface_deg[0, after] - ref.surface_deg[0, after])) > 0.3


def test_a_ramp_is_recorded_as_truth():
    f = parse_fault("viscous_friction:at_s=1,ramp_s=1,size=0.5")
    cols = truth_columns([f], np.array([0.0, 1.0, 1.5, 2.0, 3.0]))
    assert np.allclose(cols["fault_viscous_friction"], [0.0, 0.0, 0.25, 0.5, 0.5])


def test_csv_columns_carry_the_truth():
    faults = [parse_fault("backlash:at_s=1,size=1")]
    model, rec, _ = simulate("loada", MANEUVER, duration_s=2.0, faults=faults)
    cols = csv_columns(model, rec, faults=faults)
    assert cols["fault_backlash"][-1] == 1.0


def test_a_fault_on_a_stage_the_model_lacks_is_one_clear_error():
    with pytest.raises(EmaError, match="coulomb_friction"):
        simulate("loada", MANEUVER, duration_s=1.0, faults=[parse_fault("coulomb_friction:at_s=0.5")])


def test_a_bad_spec_names_the_field():
    with pytest.raises(SpecError, match="size"):
        parse_fault("delay:size=-1")


def test_an_emac_channel_injects_its_faults_frame_by_frame():
    from ema_sim.emac import EmacChannel, EmacSettings  # noqa: PLC0415 - the channel layer, beside the models
    from ema_sim.models import create  # noqa: PLC0415

    def drive(faults: str) -> tuple[list[float], EmacChannel]:
        unit = EmacChannel(create("loada", "left_wing"), EmacSettings(faults=faults))
        out = []
        for k in range(400):  # 2 s at 200 Hz, a 1 Hz sine of 2 deg
            unit.set_command(unit.scaling.command_deg_to_v(2.0 * np.sin(2 * np.pi * k / 200.0)))
            out.append(unit.step(0.0).position_deg)
        return out, unit

    clean, _ = drive("none")
    biased, unit = drive("lvdt_bias:at_s=1,size=0.1")
    diff = np.array(biased) - np.array(clean)
    assert np.allclose(diff[:190], 0.0)
    assert np.allclose(diff[205:], 0.1)
    assert unit.fault_truth() == {"fault_lvdt_bias": 0.1}
