"""Degree/volt calibration curves and the command error they imply (sections 2.6, 3.1.2.2, 4.4.1).

The FMU turns a surface command in degrees into volts with a third-order *command* curve and turns
the LVDT feedback volts back into degrees with a third-order *feedback* curve. Where the two curves
are not exact inverses the actuator settles at ``feedback(command(δ)) ≠ δ``; the report fits that
error with a line, slope ``Kb`` and bias ``offset``, which the second-order models apply as the
command error ``(1 + Kb)·δ + offset``. Three of the four surfaces have an inverse degrees-to-volts
relation (negative slope), the trap behind the hinge-moment sign error of section 4.4.1.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class Cubic:
    """``y = c0 + c1·x + c2·x² + c3·x³``, monotonic over the range it is used on."""

    c0: float
    c1: float
    c2: float
    c3: float

    @classmethod
    def from_list(cls, coeffs: ArrayLike) -> Cubic:
        """Build from ``[c0, c1, c2, c3]`` as the config files hold them."""
        c = np.asarray(coeffs, dtype=float).ravel()
        if c.size != 4 or not np.all(np.isfinite(c)):
            raise ValueError(f"a third-order calibration needs 4 finite coefficients, got {list(c)}")
        return cls(*map(float, c))

    @classmethod
    def fit(cls, x: ArrayLike, y: ArrayLike) -> Cubic:
        """Least-squares third-order fit, as the report fits calibration data (section 2.6)."""
        c = np.polynomial.polynomial.polyfit(np.asarray(x, float), np.asarray(y, float), 3)
        return cls(*map(float, c))

    def coefficients(self) -> list[float]:
        """``[c0, c1, c2, c3]``."""
        return [self.c0, self.c1, self.c2, self.c3]

    @property
    def sign(self) -> int:
        """+1 when y grows with x at the origin, −1 for an inverse relation."""
        return 1 if self.c1 >= 0.0 else -1

    def __call__(self, x: ArrayLike) -> FloatArray:
        """Evaluate the curve."""
        x = np.asarray(x, dtype=float)
        return self.c0 + x * (self.c1 + x * (self.c2 + x * self.c3))

    def slope(self, x: ArrayLike) -> FloatArray:
        """dy/dx."""
        x = np.asarray(x, dtype=float)
        return self.c1 + x * (2.0 * self.c2 + 3.0 * self.c3 * x)

    def inverse(self, y: ArrayLike, iterations: int = 8) -> FloatArray:
        """X such that ``self(x) = y`` (Newton from the linear guess; exact to rounding on the range)."""
        y = np.asarray(y, dtype=float)
        x = (y - self.c0) / self.c1
        for _ in range(iterations):
            x = x - (self(x) - y) / self.slope(x)
        return x


@dataclass(frozen=True)
class CommandError:
    """The linear command error ``position = (1 + kb)·command + offset_deg`` (figure 27)."""

    kb: float
    offset_deg: float

    def __call__(self, command_deg: ArrayLike) -> FloatArray:
        """Position for a command."""
        return (1.0 + self.kb) * np.asarray(command_deg, float) + self.offset_deg


def command_error(
    command_v_per_deg: Cubic, feedback_deg_per_v: Cubic, nominal_deg: ArrayLike
) -> CommandError:
    """Fit Kb and offset the way section 3.1.2.2 does.

    Nominal angles go through the command curve to volts, the volts through the feedback curve back
    to degrees; a line fitted to (feedback − nominal) against nominal gives the slope Kb and bias.
    """
    nominal = np.asarray(nominal_deg, dtype=float)
    error = feedback_deg_per_v(command_v_per_deg(nominal)) - nominal
    slope, bias = np.polyfit(nominal, error, 1)
    return CommandError(kb=float(slope), offset_deg=float(bias))


def four_corner_bounds(
    errors: list[CommandError], nominal_deg: ArrayLike
) -> tuple[FloatArray, FloatArray]:
    """Monte Carlo command-error limits from several calibrations (section 3.1.2.2, figures 27–28).

    The largest |Kb| and |offset| over all calibrations give four lines (±slope × ±offset); at each
    nominal angle the highest and lowest of the four are the upper and lower bounds.
    """
    nominal = np.asarray(nominal_deg, dtype=float)
    kb = max(abs(e.kb) for e in errors)
    off = max(abs(e.offset_deg) for e in errors)
    corners = np.array([s * kb * nominal + o * off for s in (-1.0, 1.0) for o in (-1.0, 1.0)])
    return corners.min(axis=0), corners.max(axis=0)
