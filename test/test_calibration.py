import numpy as np
import pytest

from ema_sim.calibration import CommandError, Cubic, command_error, four_corner_bounds


def test_cubic_inverse_round_trips_over_the_stroke():
    fb = Cubic(0.004, -4.25, -0.0002, -0.0005)
    v = np.linspace(-10, 10, 201)
    assert np.max(np.abs(fb.inverse(fb(v)) - v)) < 1e-12


def test_cubic_fit_recovers_coefficients():
    truth = Cubic(0.01, 4.2, 0.003, -0.0004)
    x = np.linspace(-10, 10, 50)
    fit = Cubic.fit(x, truth(x))
    assert fit.coefficients() == pytest.approx(truth.coefficients(), abs=1e-9)


@pytest.mark.parametrize(("kb", "offset"), [(0.003, 0.02), (-0.005, -0.01), (0.0, 0.0)])
def test_command_error_recovers_a_known_slope_and_bias(kb, offset):
    fb = Cubic(0.002, -4.25, 0.0001, -0.0005)
    nominal = np.linspace(-40, 40, 161)
    cmd = Cubic.fit(nominal, fb.inverse((1 + kb) * nominal + offset))
    err = command_error(cmd, fb, np.linspace(-40, 40, 81))
    assert err.kb == pytest.approx(kb, abs=2e-5)
    assert err.offset_deg == pytest.approx(offset, abs=2e-4)


def test_four_corner_bounds_enclose_every_calibration_line():
    errors = [CommandError(0.002, 0.01), CommandError(-0.004, 0.02), CommandError(0.001, -0.03)]
    nominal = np.linspace(-30, 30, 61)
    lo, hi = four_corner_bounds(errors, nominal)
    for e in errors:
        line = e(nominal) - nominal
        assert np.all(line >= lo - 1e-12)
        assert np.all(line <= hi + 1e-12)
    assert hi[-1] == pytest.approx(0.004 * 30 + 0.03)
    assert lo[0] == pytest.approx(-(0.004 * 30) - 0.03)
