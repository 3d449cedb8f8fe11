"""A periodic test whose actuator changed while it was recorded: the trend test and the per-cycle fits."""

import numpy as np
import pytest
from scipy.signal import chirp

from ema_sim.analysis.estimation.cycle_changes import CycleChanges, _on_bound, bandwidth_hz
from ema_sim.analysis.estimation.trend import trend
from ema_sim.analysis.pipeline import Options, analyze_record
from ema_sim.io.measured import MeasuredData

FINE_HZ = 2000.0
LOG_HZ = 200.0
PERIOD_S = 10.0
CYCLES = 6


def test_the_trend_test_tells_steady_falling_and_wandering_values_apart_and_needs_two_measurements() -> None:
    x = np.arange(8.0) * 10.0
    sigma = np.full(8, 0.05)
    rng = np.random.default_rng(3)
    assert trend(7.0 + rng.normal(0, 0.05, 8), sigma, x).kind == "steady"
    falling = trend(8.0 - 0.02 * x, sigma, x)
    assert falling.kind == "falls"
    assert falling.slope_per_s == pytest.approx(-0.02, rel=1e-9)
    assert trend(np.array([3.0, 6.0, 11.0, 6.5, 2.8, 9.0, 10.0, 3.5]), sigma, x).kind == "wanders"
    # a change of 1 % is a model's mismatch, not an actuator that changed, however small its uncertainty
    assert trend(7.0 * (1.0 + 0.01 * np.sin(x)), np.full(8, 1e-6), x).kind == "steady"
    on_bound = np.array([True] + [False] * 7)
    assert trend(8.0 - 0.02 * x, np.where(on_bound, np.inf, 0.05), x, usable=~on_bound).kind == "falls"
    assert trend(np.array([1.0, 2.0]), np.array([np.inf, 0.1]), np.array([0.0, 1.0])).kind == "not determined"


def _excitation(t: np.ndarray, amp: float) -> np.ndarray:
    """Four steps, then a 0.5-6 Hz sweep, repeating every PERIOD_S: every cycle carries the same test."""
    tb = np.mod(t, PERIOD_S)
    steps = np.select([tb < 1.0, tb < 2.0, tb < 3.0, tb < 4.0], [amp, -amp, 0.5 * amp, -0.5 * amp], 0.0)
    sweep = np.where((tb >= 4.5) & (tb < 9.5), 0.6 * amp * chirp(tb - 4.5, 0.5, 5.0, 6.0, method="logarithmic"),
                     0.0)
    return steps + sweep


def _record(wn_of_t: np.ndarray, delay_of_t: np.ndarray, seed: int) -> MeasuredData:
    """A second-order servo (ζ 0.7) on a fine grid, its ωn and command delay varying as given, logged at LOG_HZ."""
    n = wn_of_t.size
    t = np.arange(n) / FINE_HZ
    demand = _excitation(t, 3.0)
    delayed = demand[np.clip(np.arange(n) - np.round(delay_of_t * FINE_HZ).astype(int), 0, n - 1)]
    dt = 1.0 / FINE_HZ
    x, v = 0.0, 0.0
    y = np.empty(n)
    for i in range(n):  # semi-implicit Euler at 2 kHz (ωn·dt ≤ 0.03)
        w = wn_of_t[i]
        v += dt * (w * w * (delayed[i] - x) - 2.0 * 0.7 * w * v)
        x += dt * v
        y[i] = x
    step = int(FINE_HZ / LOG_HZ)
    rng = np.random.default_rng(seed)
    held = demand[::step]
    return MeasuredData(time_s=t[::step], command_deg=held, position_deg=y[::step] + rng.normal(0, 2e-3, held.size),
                        source="synthetic periodic")


def _changes(data: MeasuredData) -> CycleChanges:
    ra = analyze_record(data, Options(command="sampled"))
    (r,) = ra.results["periodic"]
    assert r.periodicity.cycles >= CYCLES - 1
    return r.changes


@pytest.fixture(scope="module")
def span() -> np.ndarray:
    return np.arange(int(CYCLES * PERIOD_S * FINE_HZ)) / FINE_HZ


def test_a_servo_whose_bandwidth_falls_over_the_test_is_said_to_fall_cycle_by_cycle(span: np.ndarray) -> None:
    wn = 60.0 * (1.0 - 0.25 * span / span[-1])
    ch = _changes(_record(wn, np.full(span.size, 0.004), 1))
    assert ch.bandwidth is not None
    assert ch.bandwidth.kind == "falls"
    first, last = ch.bandwidth.values[0], ch.bandwidth.values[-1]
    mid0, mid1 = ch.times_s[0], ch.times_s[-1]
    truth = [bandwidth_hz(60.0 * (1.0 - 0.25 * m / span[-1]), 0.7) for m in (mid0, mid1)]
    assert first == pytest.approx(truth[0], rel=0.06)
    assert last == pytest.approx(truth[1], rel=0.06)
    assert any("falls" in s for s in ch.statements)


def test_a_delay_that_wanders_over_the_test_is_said_to_wander_with_each_cycles_value(span: np.ndarray) -> None:
    delay = 0.007 + 0.005 * np.sin(2.0 * np.pi * span / 35.0 + 0.3)
    ch = _changes(_record(np.full(span.size, 60.0), delay, 2))
    assert ch.delay is not None
    assert ch.delay.kind == "wanders"
    for mid, value in zip(ch.times_s, ch.delay.values, strict=True):  # within what the cycle's delay went through
        inside = delay[np.abs(span - mid) <= PERIOD_S / 2]
        assert float(inside.min()) - 0.001 <= value <= float(inside.max()) + 0.001
    assert max(ch.delay.values) - min(ch.delay.values) > 0.005
    assert any("wanders" in s and "delay" in s.lower() for s in ch.statements)


def test_a_servo_that_does_not_change_is_not_said_to(span: np.ndarray) -> None:
    ch = _changes(_record(np.full(span.size, 60.0), np.full(span.size, 0.004), 3))
    assert ch.bandwidth is not None
    assert ch.delay is not None
    assert not ch.changed, ch.statements
    assert all("holds" in s for s in ch.statements)


def test_a_delay_held_at_its_bound_leaves_the_cycles_bandwidth_measured() -> None:
    """Only the parameters the fit's note puts on a bound are no measurement."""
    assert _on_bound("delay on its lower bound 0 (the response starts at the command's sample)") == {"delay"}
    assert _on_bound("ωn on its upper bound 314.2; delay on its lower bound -0.01") == {"ωn", "delay"}
    assert _on_bound("") == set()
