"""Discovery beyond the vocabulary: the regression, the library's tones, and the loop closed on a record."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from identgen import make_record

from ema_sim.config import load_channel
from ema_sim.identify.diagnosis import Correlate, OutputDiagnosis
from ema_sim.identify.identification import Search, identify
from ema_sim.identify.library import library, locked, tones
from ema_sim.identify.record import prepare
from ema_sim.identify.regression import stepwise

WING = load_channel("left_wing")


def _motion(n: int = 4000, fs: float = 200.0) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    t = np.arange(n) / fs
    u = 5.0 * np.sign(np.sin(2 * np.pi * 0.37 * t)) + 3.0 * np.sin(2 * np.pi * 1.3 * t)
    x = np.convolve(u, np.ones(20) / 20, mode="same")
    v = np.gradient(x, t)
    return t, u, x, v


def test_a_drag_in_the_residual_is_found_with_its_coefficient_and_holds_in_both_halves():
    t, u, x, v = _motion()
    rng = np.random.default_rng(1)
    sigma = 0.003
    e = 0.02 * np.where(np.abs(v) > 0.01 * np.percentile(np.abs(v), 99), np.sign(v), 0.0) + rng.normal(0, sigma, t.size)
    mask = np.ones(t.size, dtype=bool)
    reg = stepwise(e, library(t, u, x, v, None, e, mask), sigma)
    names = [s.term.name for s in reg.selected]
    assert names[0] == "sign(rate)", names
    drag = reg.selected[0]
    assert drag.coef[0] == pytest.approx(0.02, abs=3 * drag.sigma[0] + 1e-3)
    assert drag.holds
    assert drag.p_value < 1e-4


def test_white_noise_has_nothing_to_discover():
    t, u, x, v = _motion()
    e = np.random.default_rng(2).normal(0.0, 0.003, t.size)
    reg = stepwise(e, library(t, u, x, v, None, e, np.ones(t.size, dtype=bool)), 0.003)
    assert reg.selected == []


def test_a_sensor_tone_is_a_tone_but_a_harmonic_of_a_periodic_demand_is_not():
    t = np.arange(8000) / 1000.0
    square = np.sign(np.sin(2 * np.pi * 1.0 * t))
    rng = np.random.default_rng(3)
    tone = 0.05 * np.sin(2 * np.pi * 23.7 * t) + rng.normal(0, 0.005, t.size)
    (found,) = tones(tone, t, limit=1)
    assert found == pytest.approx(23.7, abs=0.05)
    assert not locked(square, t, found)
    # the response error of a square wave repeats each cycle: its lines sit on the command's harmonics
    assert locked(square, t, 3.0)
    assert locked(square, t, 2.0)  # an even harmonic the symmetric command lacks, yet locked to its period
    staircase = np.repeat(rng.uniform(-5, 5, 16), 500)
    assert not locked(staircase, t, 23.7)
    # a long record of a slow square: the skirts between its harmonics are no lines of its own
    t = np.arange(60000) / 1000.0
    slow = np.sign(np.sin(2 * np.pi * 0.5 * t))
    assert locked(slow, t, 23.5)
    assert not locked(slow, t, 23.7)


def test_a_drag_on_the_reading_no_effect_names_is_discovered_and_closes_the_loop():
    """LOAC truth whose LVDT reads an extra 0.05° against the motion: named effects cannot explain it; discovery
    finds sign(rate) on the position, adds it and lowers the error, reported before and after."""
    data = make_record({}, seed=4, duration_s=12.0, sample_hz=500.0, outputs=("position_deg",))
    v = np.gradient(data.position_deg, data.time_s)
    moving = np.abs(v) > 0.02 * np.percentile(np.abs(v), 99)
    data = replace(data, position_deg=data.position_deg + 0.05 * np.where(moving, np.sign(v), 0.0))
    result = identify(prepare(data, WING), "second_order", search=Search(max_effects=3, escalate=False))
    assert result.discovery is not None
    terms = [s.term.name for s in result.discovery.found["position_deg"].regression.selected]
    assert any("sign(rate)" in n for n in terms), terms
    (stage,) = [s for s in result.stages if s.stage == "discovery"]
    assert stage.status == "kept", stage.reason
    # sign(rate) alone: the rate·|rate| and acceleration terms that also cut the error here disagree between the
    # record's halves beyond their uncertainty (their sign, or 2x), so they do not hold
    assert stage.rms_deg_after["position_deg"] < 0.95 * stage.rms_deg_before["position_deg"]
    assert "discovered" in result.discovered


def test_every_effect_reports_the_contract_s_keys():
    """``added[].params`` keys are the data contract's: the linkage mode reports ``freq_hz`` and ``zeta``."""
    from ema_sim.identify.effects import BY_KEY, KEYS  # noqa: PLC0415

    link = next(e for e in BY_KEY.values() if e.name == "linkage_mode")
    keys = {link.contract.get(KEYS[f].name, KEYS[f].name) for f in link.fields}
    assert keys == {"freq_hz", "zeta"}


def test_a_residual_that_fails_its_whiteness_test_is_never_nothing_left_to_explain():
    """Small but coloured: the words say it is not white and what correlates with it (issue 24)."""
    white = OutputDiagnosis("position_deg", 0.012, 0.010, True)
    assert white.sentence("deg", 500.0, 8.0).endswith("white: nothing left to explain")
    small = OutputDiagnosis("position_deg", 0.013, 0.010, False, correlates=[Correlate("rate", 0.66, 1e-9)])
    assert not small.structured
    words = small.sentence("deg", 500.0, 8.0)
    assert "nothing left" not in words
    assert "not white" in words
    assert "rate (a short filter of it explains 66 %" in words
    bare = OutputDiagnosis("surface_deg", 0.013, 0.010, False)
    assert bare.sentence("deg", 500.0, 8.0).endswith("no input explains it")
