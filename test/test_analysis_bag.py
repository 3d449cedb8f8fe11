"""Issue 14, bags: every recorded signal reaches the analysis, and every commanded test is analysed or listed.

:func:`suite_bag` writes what the node suite records for one channel through the AIL test environment
(section 4.3): the flight computer's command, the EMAC's command after 26 ms of delay, a 50 Hz lag,
5 mV quantization and 3 mV of noise, the actuator's LVDT feedback and surface angle, and the bus
voltage on ``/ema/sensor/bus``.
"""

import json

import numpy as np
import pytest

from ema_msgs_py import contract as ct
from ema_msgs_py import typestore as ts
from ema_sim.analysis.pipeline import analyze_record
from ema_sim.config import scaling
from ema_sim.io import load_data
from ema_sim.io.bag import BagWriter
from ema_sim.models import create
from ema_sim.signals import parse_maneuver

CHANNEL = "left_wing"
FRAME_HZ = 200.0
ENV_DELAY_S = 0.026


def suite_bag(path, maneuver="steps:amps_deg=0.5/1/20,lead_s=0.5,hold_s=1.5", *, noise_v=0.003, seed=1):
    man = parse_maneuver(maneuver)
    t = np.arange(int(man.duration_s * FRAME_HZ)) / FRAME_HZ
    fmu = man.command_deg(t)
    sc = scaling(CHANNEL)
    rng = np.random.default_rng(seed)
    delayed = np.interp(t - ENV_DELAY_S, t, fmu, left=fmu[0])
    alpha = 1.0 - np.exp(-2 * np.pi * 50.0 / FRAME_HZ)
    lagged = np.empty_like(delayed)
    acc = delayed[0]
    for k, x in enumerate(delayed):
        acc += alpha * (x - acc)
        lagged[k] = acc
    volts = np.array([sc.command_deg_to_v(float(x)) for x in lagged]) + rng.normal(0, noise_v, t.size)
    volts = 0.005 * np.round(volts / 0.005)
    emac = np.array([sc.command_v_to_deg(float(v)) for v in volts])
    model = create("loada", CHANNEL)
    model.trim(float(emac[0]), 0.0)
    rec = model.run(t, emac, np.zeros_like(t), sample_times=t, end_s=float(t[-1]))
    pos, surf, rate = rec.position_deg[0], rec.surface_deg[0], rec.rate_dps[0]
    bus = 150.0 + 12.0 * np.exp(-np.clip(t - 6.6, 0, None) / 0.01) * (t >= 6.6)
    meta = {"channel": CHANNEL, "channels": CHANNEL, "test": "steps", "maneuver": maneuver, "load": "none",
            "model": "loada", "profile": "ail", f"calibration.{CHANNEL}": json.dumps(
                {"command_cal_v": list(sc.command), "feedback_cal_deg": list(sc.feedback)})}
    with BagWriter(path, meta) as bag:
        for k in range(t.size):
            ns = round(t[k] * 1e9)
            bag.write_message(ct.FMU_COMMAND, ns, ts.joint_state(ns, [CHANNEL], [sc.command_deg_to_v(float(fmu[k]))]))
            bag.write_message(ct.EMAC_COMMAND, ns, ts.joint_state(ns, [CHANNEL], [float(volts[k])]))
            pv = sc.feedback_deg_to_v(float(pos[k]))
            bag.write_message(ct.EMAC_FEEDBACK, ns, ts.joint_state(ns, [CHANNEL], [pv]))
            bag.write_message(ct.FMU_FEEDBACK, ns, ts.joint_state(ns, [CHANNEL], [pv]))
            bag.write_message(ct.SURFACE, ns, ts.joint_state(ns, [CHANNEL], [float(surf[k])], [float(rate[k])], [0.0]))
            bag.write_message(ct.BUS, ns, ts.joint_state(ns, [CHANNEL], [float(bus[k])]))
    return path


@pytest.fixture(scope="module")
def steps_bag(tmp_path_factory):
    return suite_bag(tmp_path_factory.mktemp("bags") / "steps")


def test_the_bag_reader_hands_over_every_recorded_signal(steps_bag):
    d = load_data(steps_bag)
    assert d.bus_v is not None
    assert d.bus_v.max() == pytest.approx(162.0, abs=0.5)
    assert d.rate_dps is not None
    assert set(d.extra) == {"fmu_command_deg", "fmu_position_deg"}
    assert sorted(np.unique(np.round(d.extra["fmu_command_deg"], 6))) == [0.0, 0.5, 1.0, 20.0]


def test_every_step_of_the_bag_is_analysed_and_timed_from_both_sides(steps_bag):
    ra = analyze_record(load_data(steps_bag))
    steps = ra.results["steps"]
    assert [round(s.command_step_deg, 1) for s in steps] == [0.5, -0.5, 1.0, -1.0, 20.0, -20.0]
    assert [s.rate_limited for s in steps] == [False] * 4 + [True] * 2
    assert all(s.fit is not None and s.fit.quality == "ok" for s in steps[:4])
    assert not [k for k in ra.not_computed if k.startswith("steps")]
    (tm,) = ra.results["timing"]
    # LOADA's first motion is within a frame of the command it received; the FMU's is the environment's 26 ms later.
    assert 0.0 < tm.command_to_motion_s < 0.012
    assert tm.fmu_to_motion_s == pytest.approx(tm.command_to_motion_s + ENV_DELAY_S, abs=0.004)
    assert tm.quality == "ok"
    (g,) = ra.results["regeneration"]
    assert g.peak_v == pytest.approx(162.0, abs=0.5)
    assert "regeneration" not in ra.not_computed


def test_a_commanded_step_the_command_does_not_show_is_listed_with_its_reason(tmp_path):
    """0.05° steps under 3 mV of command noise (0.013°) and 5 mV counts: not edges, and the report says so."""
    bag = suite_bag(tmp_path / "tiny", "steps:amps_deg=0.05/1,lead_s=0.5,hold_s=1.5")
    ra = analyze_record(load_data(bag))
    assert [round(s.command_step_deg, 1) for s in ra.results["steps"]] == [1.0, -1.0]
    missing = {k: v for k, v in ra.not_computed.items() if k.startswith("steps: ")}
    assert set(missing) == {"steps: +0.05° at 0.500 s", "steps: -0.05° at 2.000 s"}
    for why in missing.values():
        assert "not found in the command as an edge" in why
        assert "as stepping from" in why
