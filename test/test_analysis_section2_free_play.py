"""`analysis/section2/free_play.py` on a surface whose free play and compliance are known by construction."""

import numpy as np
import pytest

from ema_sim.analysis.records.series import edges
from ema_sim.analysis.section2.free_play import reversal_free_play

DT_S = 0.001
FREE_PLAY_DEG = 0.2
COMPLIANCE = 0.3  # deg per 1000 in·lb


def _record(noise_deg=0.0):
    t = np.arange(0.0, 4.0, DT_S)
    hm = np.where((t // 0.5) % 2 == 0, -1000.0, 1000.0)  # load reversals every 0.5 s
    hm[t < 0.5] = 500.0  # a first load change that keeps its sign: no reversal
    position = np.full_like(t, 1.0)
    surface = position + 0.5 * FREE_PLAY_DEG * np.sign(hm) + COMPLIANCE * hm / 1000.0
    surface += noise_deg * np.random.default_rng(5).standard_normal(t.size)
    return t, hm, surface, position


def test_each_reversal_jumps_by_the_free_play_plus_the_elastic_swing():
    t, hm, surface, position = _record()
    r = reversal_free_play(t, edges(hm, DT_S), hm, surface, position)
    assert r is not None
    assert len(r.reversals) == 6  # 7 load changes, the first keeps its sign
    assert all(abs(abs(x.jump_deg) - (FREE_PLAY_DEG + COMPLIANCE * 2.0)) < 1e-9 for x in r.reversals)
    assert r.width_deg == pytest.approx(FREE_PLAY_DEG + 2.0 * COMPLIANCE)  # no compliance given: it is in the width
    assert any("no compliance given" in n for n in r.notes)


def test_the_known_compliance_is_taken_out_of_each_jump():
    t, hm, surface, position = _record(noise_deg=0.002)
    r = reversal_free_play(t, edges(hm, DT_S), hm, surface, position, COMPLIANCE, "test")
    assert r is not None
    assert r.width_deg == pytest.approx(FREE_PLAY_DEG, abs=0.002)
    assert r.spread_deg < 0.002
    assert r.compliance_deg_per_kinlb == COMPLIANCE


def test_loads_that_never_change_sign_give_no_result():
    t, hm, surface, position = _record()
    hm = np.abs(hm)
    assert reversal_free_play(t, edges(hm, DT_S), hm, surface, position) is None
