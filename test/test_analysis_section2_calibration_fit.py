"""`analysis/section2/calibration_fit.py`: a staircase whose command error and curves are known by construction."""

import numpy as np
import pytest

from ema_sim.analysis.records.series import Hold
from ema_sim.analysis.section2.calibration_fit import fit_calibration, pooled_bounds
from ema_sim.calibration import CommandError
from ema_sim.io.measured import MeasuredData

KB, OFFSET_DEG = 0.004, -0.03
LEVELS_DEG = np.arange(-20.0, 20.1, 5.0)
HOLD = 500  # samples per level


def _staircase(*, volts):
    """Held levels; the servo holds the LVDT volts at the command volts, the LVDT curve reads them as degrees."""
    cmd = np.repeat(LEVELS_DEG, HOLD)
    t = np.arange(cmd.size) * 0.001
    command_v = -0.24 * cmd + 0.01  # the FMU's command curve
    a = -(1.0 + KB) / 0.24  # the LVDT curve deg = a·V + b that makes position = (1 + Kb)·command + offset
    b = OFFSET_DEG - 0.01 * a
    position = a * command_v + b
    holds = [Hold(k * HOLD, (k + 1) * HOLD, float(v)) for k, v in enumerate(LEVELS_DEG)]
    extra = {"command_v": command_v, "position_v": command_v} if volts else {}
    return MeasuredData(t, cmd, position_deg=position, **extra), holds


def test_the_direct_error_is_the_line_the_staircase_was_made_with():
    data, holds = _staircase(volts=False)
    cal = fit_calibration(data, holds)
    assert cal.direct.kb == pytest.approx(KB, abs=1e-9)
    assert cal.direct.offset_deg == pytest.approx(OFFSET_DEG, abs=1e-9)
    assert cal.direct_reference == "position_deg"
    assert cal.command_curve is None
    assert any("no command_v/position_v" in n for n in cal.notes)
    lo, hi = cal.bounds_deg  # figure 28's four corners: ±|Kb|·angle ± |offset|
    assert np.allclose(hi, KB * np.abs(cal.nominal_deg) + abs(OFFSET_DEG))
    assert np.allclose(lo, -hi)


def test_the_curves_are_fitted_and_give_the_same_error():
    data, holds = _staircase(volts=True)
    cal = fit_calibration(data, holds)
    assert cal.command_curve_rms_v < 1e-9  # a line is a cubic
    assert cal.feedback_curve_rms_deg < 1e-9  # so is a quadratic
    assert cal.curve_error.kb == pytest.approx(KB, abs=1e-6)
    assert cal.curve_error.offset_deg == pytest.approx(OFFSET_DEG, abs=1e-6)


def test_pooled_bounds_take_the_largest_error_of_each_kind():
    pooled = pooled_bounds([CommandError(0.002, 0.01), CommandError(-0.004, -0.02)], -10.0, 10.0)
    assert pooled["calibrations"] == 2
    assert pooled["kb_max_abs"] == 0.004
    assert pooled["offset_max_abs_deg"] == 0.02
    lo, hi, nominal = (np.array(pooled[k]) for k in ("lower_deg", "upper_deg", "nominal_deg"))
    assert np.all(lo <= hi)
    both = np.array([CommandError(0.002, 0.01)(nominal), CommandError(-0.004, -0.02)(nominal)]) - nominal  # errors
    assert np.allclose(hi, 0.004 * np.abs(nominal) + 0.02)
    assert np.all(lo <= both.min(axis=0) + 1e-12)
    assert np.all(hi >= both.max(axis=0) - 1e-12)
