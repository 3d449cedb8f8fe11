"""A speed plateau is the record's evidence of a rate limit: found on moves and swings, never on a linear response."""

import numpy as np
import pytest
from scipy.signal import lsim

from ema_sim.analysis.estimation import slew
from ema_sim.analysis.pipeline import Options, analyze_record
from ema_sim.config import load_channel
from ema_sim.identify.identification import Search, identify
from ema_sim.identify.record import prepare
from ema_sim.io.measured import MeasuredData

FINE_S = 2e-4


def _limited_servo(t: np.ndarray, demand: np.ndarray, kp: float, rate: float) -> np.ndarray:
    """A position loop: speed = clip(kp·error, ±rate), integrated on a fine grid."""
    y = np.zeros_like(demand)
    for k in range(1, t.size):
        v = min(max(kp * (demand[k - 1] - y[k - 1]), -rate), rate)
        y[k] = y[k - 1] + v * FINE_S
    return y


def _log(t: np.ndarray, signals: list[np.ndarray], rate_hz: float, seed: int) -> list[np.ndarray]:
    """Sample at ``rate_hz`` with ±1 ms jitter of the instants (stamped as taken), position counts of 0.001."""
    rng = np.random.default_rng(seed)
    grid = np.arange(0.05, t[-1] - 0.05, 1.0 / rate_hz)
    stamps = grid + rng.uniform(-1e-3, 1e-3, grid.size)
    idx = np.round(stamps / FINE_S).astype(int)
    return [t[idx]] + [np.round(s[idx] / 1e-3) * 1e-3 for s in signals]


def test_rate_limited_squares_and_a_sweep_past_the_limit_show_the_plateau():
    """Squares (held steps) and a sine sweep on a speed-limited servo: the plateau is the limit within 2 %."""
    t = np.arange(0.0, 16.0, FINE_S)
    squares = np.where(np.mod(t - 1.0, 3.0) < 1.5, 5.0, -5.0) * (t >= 1.0)
    y = _limited_servo(t, squares, 40.0, 90.0)
    ts, u, yl = _log(t, [squares, y], 100.0, 1)
    found = slew.plateau(ts, u, yl, 3e-4)
    assert found.rate == pytest.approx(90.0, rel=0.02)
    assert found.runs >= 4
    freq = 0.2 + (6.0 - 0.2) * t / t[-1]
    sweep = 5.0 * np.sin(2 * np.pi * np.cumsum(freq) * FINE_S)
    ys = _limited_servo(t, sweep, 40.0, 90.0)
    ts, u, yl = _log(t, [sweep, ys], 100.0, 2)
    swept = slew.measure(ts, u, yl, 3e-4)
    assert swept.source == "plateau"  # no rest between the swings: the straight-move test finds nothing
    assert swept.rate == pytest.approx(90.0, rel=0.02)
    assert swept.plateau is not None
    assert swept.plateau.below > 0


@pytest.mark.parametrize("zeta", [0.3, 0.7, 1.0, 2.0])
def test_a_linear_second_order_has_no_plateau(zeta):
    """Steps of several sizes through a linear second order: its speed never flattens, whatever the amplitude."""
    t = np.arange(0.0, 16.0, FINE_S)
    steps = np.select([np.mod(t, 4.0) < 1.0, np.mod(t, 4.0) < 2.0, np.mod(t, 4.0) < 3.0], [0.0, 10.0, 1.0], 5.0)
    wn = 40.0
    _, y, _ = lsim(([wn * wn], [1.0, 2 * zeta * wn, wn * wn]), steps, t)
    ts, u, yl = _log(t, [steps, y], 100.0, 3)
    assert slew.plateau(ts, u, yl, 3e-4).rate is None


def test_an_actuator_following_a_profile_is_not_rate_limited_at_the_profile_speed():
    """A profile at 60/s that the servo follows: the output's flat top is the command's own speed, no limit."""
    t = np.arange(0.0, 16.0, FINE_S)
    target = np.where(np.mod(t, 2.0) < 1.0, 10.0, 0.0)
    profile = _limited_servo(t, target, 200.0, 60.0)  # the drive's profile generator
    y = _limited_servo(t, profile, 60.0, 500.0)  # a servo that keeps up (limit far above the profile)
    ts, u, yl = _log(t, [profile, y], 100.0, 4)
    assert slew.plateau(ts, u, yl, 3e-4).rate is None


def test_both_tools_find_the_rate_limit_at_the_plateau():
    """ema analyze calls the moves at the plateau rate-limited; ema identify adds the rate limit within 10 %."""
    t = np.arange(0.0, 14.0, FINE_S)
    squares = np.where(np.mod(t - 1.0, 2.5) < 1.25, 4.0, -4.0) * (t >= 1.0)
    y = _limited_servo(t, squares, 35.0, 75.0)
    ts, u, yl = _log(t, [squares, y], 100.0, 5)
    data = MeasuredData(time_s=ts, command_deg=u, position_deg=yl, source="limited", unit="mm")
    ra = analyze_record(data, Options())
    steps = ra.results["steps"]
    assert steps
    assert all(s.rate_limited for s in steps if abs(s.command_to_deg - s.command_from_deg) > 4.0)
    assert ra.slew is not None
    assert ra.slew.rate == pytest.approx(75.0, rel=0.05)
    result = identify(prepare(data, load_channel("left_wing")), "second_order",
                      search=Search(escalate=False, discover_terms=False))
    added = {s.effect: s.params for s in result.steps}
    assert "rate_limit" in added
    assert added["rate_limit"]["rate_dps"] == pytest.approx(75.0, rel=0.10)
