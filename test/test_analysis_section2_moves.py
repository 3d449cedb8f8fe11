"""`analysis/section2/moves.py`: which transitions between holds are moves, read on profiles known by construction."""

import numpy as np
import pytest

from ema_sim.analysis.records.series import hold_tolerance, holds
from ema_sim.analysis.section2.moves import find_moves

FS_HZ = 1000.0
DT_S = 1.0 / FS_HZ


def _profile(pieces):
    """Concatenated pieces: ("hold", seconds) or ("ramp", seconds, to_deg)."""
    u = [0.0]
    for piece in pieces:
        n = round(piece[1] * FS_HZ)
        end = u[-1] if piece[0] == "hold" else piece[2]
        u.extend(np.linspace(u[-1], end, n + 1)[1:])
    u = np.asarray(u)
    return np.arange(u.size) * DT_S, u


def _moves(t, u):
    tol = hold_tolerance(u)
    return find_moves(t, u, holds(u, 40, tol), min_jump=0.05, max_gap=20, counts=0.0, tol=tol)


def test_a_trapezoid_is_one_run_of_two_moves_at_its_own_speed():
    t, u = _profile([("hold", 1.0), ("ramp", 0.5, 10.0), ("hold", 1.0), ("ramp", 0.5, 0.0), ("hold", 1.0)])
    runs = _moves(t, u)
    assert len(runs) == 1
    (up, down) = runs[0]
    assert up.after == down.before  # consecutive moves share their hold
    assert up.jump == pytest.approx(10.0)
    assert down.jump == pytest.approx(-10.0)
    assert up.speed_dps == pytest.approx(20.0, rel=1e-3)
    assert down.speed_dps == pytest.approx(20.0, rel=1e-3)
    assert up.cruise_share > 0.8


def test_steps_are_not_moves():
    t, u = _profile([("hold", 1.0), ("ramp", 0.005, 5.0), ("hold", 1.0), ("ramp", 0.005, 0.0), ("hold", 1.0)])
    assert _moves(t, u) == []  # a 5 ms transition is a step's (max_gap 20 samples)


def test_moves_of_two_speeds_each_read_their_own():
    t, u = _profile([("hold", 1.0), ("ramp", 1.0, 10.0), ("hold", 1.0), ("ramp", 0.25, 0.0), ("hold", 1.0)])
    (run,) = _moves(t, u)
    assert [round(m.speed_dps, 1) for m in run] == [10.0, 40.0]
