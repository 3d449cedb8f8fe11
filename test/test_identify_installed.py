"""Issue 13's installed-actuator vocabulary: each new effect alone and with an old one, at 1 kHz and 200 Hz,
with a coarse sensor and a reversed load column; a null under heavy load adds nothing.

Truth is LOAC with figure 26's installed-actuator stages (``identgen``); identification starts from the
basic second order. Checks: the right effects named, parameters within 20 %, final rms ≤ 1.5× the
record's noise floor (the floor the report states, never below the counts' quantization).
"""

from __future__ import annotations

import numpy as np
import pytest
from identgen import make_record

from ema_sim.config import load_channel
from ema_sim.identify.stepwise import identify

WING = load_channel("left_wing")
DURATION_S = 20.0

CASES = [
    # id, truth (model fields), effects expected, fields checked, record options, seed
    ("linkage_mode@1kHz", {"linkage_freq_hz": 18.0, "linkage_zeta": 0.12}, {"linkage_mode"},
     ("linkage_freq_hz", "linkage_zeta"), {}, 101),
    ("nonlinear_compliance@200Hz,coarse,reversed",
     {"compliance_deg_per_kinlb": 0.6, "compliance_knee_inlb": 300.0, "compliance_stiff_deg_per_kinlb": 0.2},
     {"compliance", "nonlinear_compliance", "hinge_moment_sign"},
     ("compliance_deg_per_kinlb", "compliance_knee_inlb", "compliance_stiff_deg_per_kinlb"),
     {"sample_hz": 200.0, "resolution_deg": 0.01, "reverse_load_column": True}, 102),
    ("current_limit+time_delay@1kHz", {"accel_limit_dps2": 3000.0, "velocity_loop_hz": 200.0, "delay_s": 0.006},
     {"current_limit", "time_delay"}, ("accel_limit_dps2", "delay_s"), {}, 103),
    ("linkage_mode+free_play@200Hz", {"linkage_freq_hz": 12.0, "linkage_zeta": 0.2, "free_play_deg": 0.15},
     {"linkage_mode", "free_play"}, ("linkage_freq_hz", "free_play_deg"), {"sample_hz": 200.0}, 104),
]


@pytest.mark.parametrize(("truth", "named", "fields", "options", "seed"), [c[1:] for c in CASES],
                         ids=[c[0] for c in CASES])
def test_an_installed_actuator_effect_is_named_fitted_and_leaves_noise(truth, named, fields, options, seed):
    data = make_record({}, seed=seed, duration_s=DURATION_S, load_amp_inlb=800.0, **options, **truth)
    result = identify(data, WING, "second_order")
    assert {s.effect for s in result.steps} == named, [s.effect for s in result.steps]
    for f in fields:
        assert getattr(result.final.params, f) == pytest.approx(truth[f], rel=0.2), f
    for o, e in result.problem.errors_deg(result.final.sim).items():
        rms = float(np.sqrt(np.mean(e**2)))
        floor = result.problem.sigma_deg[o]
        assert rms <= 1.5 * floor, f"{o}: {rms:.4g} against floor {floor:.4g}"


def test_a_null_under_heavy_load_adds_nothing():
    data = make_record({}, seed=105, duration_s=DURATION_S, load_amp_inlb=3000.0)
    result = identify(data, WING, "second_order")
    assert result.steps == []
