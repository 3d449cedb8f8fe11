"""Command-to-surface timing (section 2.3) when the surface moves under its load before an edge."""

import numpy as np
import pytest

from ema_sim.analysis.pipeline import analyze_record
from ema_sim.io.measured import MeasuredData

SURFACE_DELAY_S = 0.004
FEEDBACK_DELAY_S = 0.002


def _response(t: np.ndarray, edges_s: list[float], levels: list[float], delay_s: float) -> np.ndarray:
    """A critically damped 8 Hz actuator's answer to held steps between ``levels``, ``delay_s`` late."""
    w = 2 * np.pi * 8.0
    y = np.full(t.size, levels[0])
    for te, a, b in zip(edges_s, levels[:-1], levels[1:], strict=True):
        s = np.maximum(t - te - delay_s, 0.0)
        y += (b - a) * (1.0 - (1.0 + w * s) * np.exp(-w * s))
    return y


def _loaded_steps(free_play_deg: float) -> MeasuredData:
    """Steps 0 → 3 → −3 → 0° at 1 kHz while a 0.5 Hz, ±2000 in·lb hinge moment deflects the surface through
    0.15°/kin·lb of compliance and a free play crossed at each zero of the moment (which falls on the edges)."""
    t = np.arange(0, 8, 0.001)
    edges_s, levels = [2.0, 4.0, 6.0], [0.0, 3.0, -3.0, 0.0]
    u = np.array(levels)[np.searchsorted(edges_s, t, side="right")]
    hm = 2000.0 * np.sin(2 * np.pi * 0.5 * t)
    rng = np.random.default_rng(6)
    actuator = _response(t, edges_s, levels, SURFACE_DELAY_S)
    surface = actuator + 0.15e-3 * hm + 0.5 * free_play_deg * np.tanh(hm / 5.0) + rng.normal(0, 0.002, t.size)
    lvdt = _response(t, edges_s, levels, SURFACE_DELAY_S + FEEDBACK_DELAY_S) + rng.normal(0, 0.002, t.size)
    return MeasuredData(time_s=t, command_deg=u, position_deg=lvdt, surface_deg=surface,
                        hinge_moment_inlb=hm + rng.normal(0, 0.1, t.size))


@pytest.mark.parametrize("free_play_deg", [0.0, 0.12])
def test_a_surface_moving_under_its_load_is_not_timed_the_still_lvdt_is(free_play_deg):
    """The surface already moves (compliance, free play) when the command steps: first motion from rest is
    read on the LVDT, whose delay is the surface's plus the feedback's, and nothing is blamed on the data."""
    ra = analyze_record(_loaded_steps(free_play_deg))
    (tm,) = ra.results["timing"]
    assert [e.motion_signal for e in tm.edges] == ["position_deg"] * 3
    assert tm.motion_signal == "position_deg"
    assert tm.command_to_motion_s == pytest.approx(SURFACE_DELAY_S + FEEDBACK_DELAY_S, abs=3e-4)
    assert tm.motion_to_feedback_s is None
    assert tm.quality == "ok"
    assert any("timed on the LVDT position" in n for n in tm.notes)


def test_with_no_still_output_the_edge_is_marked_and_the_stamps_are_not_blamed():
    data = _loaded_steps(0.12)
    data = MeasuredData(time_s=data.time_s, command_deg=data.command_deg, surface_deg=data.surface_deg,
                        hinge_moment_inlb=data.hinge_moment_inlb)
    (tm,) = analyze_record(data).results["timing"]
    assert all(e.moving_before for e in tm.edges)
    assert not tm.early
    assert tm.quality == "not_determined"
    assert "measured against motion under way" in tm.quality_note


@pytest.mark.parametrize(("delay_s", "early"), [(-0.0008, False), (0.0, False), (-0.003, True)])
def test_one_edge_is_blamed_on_the_stamps_only_beyond_its_own_scatter(delay_s, early):
    """One 10° step at 500 Hz: an output that starts 0.4 sample before the logged edge is within
    the first-motion fit's own scatter (a single edge has no spread to measure it by); 1.5 samples is not."""
    t = np.arange(0, 4, 0.002)
    u = np.where(t >= 2.0, 10.0, 0.0)
    y = _response(t, [2.0], [0.0, 10.0], delay_s) + np.random.default_rng(7).normal(0, 0.002, t.size)
    (tm,) = analyze_record(MeasuredData(time_s=t, command_deg=u, position_deg=y)).results["timing"]
    assert tm.command_to_motion_s == pytest.approx(delay_s, abs=0.6e-3)
    assert tm.early is early
    assert ("stamps of command and output are misaligned" in tm.quality_note) is early


def test_a_surface_that_leads_through_its_free_play_is_not_blamed_on_the_stamps():
    """±12° steps at 500 Hz; an aiding load takes the surface through 0.15° of free play in a fast exponential
    from 0.5 ms after each edge, ahead of its actuator (3 ms) and the LVDT (5 ms). The surface's start is no
    parabola: its fitted first motion lands before the edge. It is not read as stamps out of line: the LVDT,
    which did not lead, times the edges."""
    t = np.arange(0, 12, 0.002)
    edges_s, levels = [3.0, 6.0, 9.0], [0.0, 12.0, -12.0, 0.0]
    u = np.array(levels)[np.searchsorted(edges_s, t, side="right")]
    rng = np.random.default_rng(3)
    lead = np.zeros_like(t)
    for te, a, b in zip(edges_s, levels[:-1], levels[1:], strict=True):
        s = np.maximum(t - te - 0.0005, 0.0)
        lead += np.sign(b - a) * 0.15 * (1 - np.exp(-s / 0.0015)) * ((t >= te) & (t < te + 2.9))
    surface = _response(t, edges_s, levels, 0.003) + lead + rng.normal(0, 0.002, t.size)
    lvdt = _response(t, edges_s, levels, 0.005) + rng.normal(0, 0.002, t.size)
    (tm,) = analyze_record(MeasuredData(time_s=t, command_deg=u, position_deg=lvdt,
                                        surface_deg=surface)).results["timing"]
    assert [e.motion_signal for e in tm.edges] == ["position_deg"] * 3
    assert tm.command_to_motion_s == pytest.approx(0.005, abs=5e-4)
    assert not tm.early
    assert tm.quality == "ok"
    assert any("leads the actuator" in n for n in tm.notes)
