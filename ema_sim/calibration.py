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

import numba as nb
import numpy as np
from numpy.typing import ArrayLike, NDArray

from ema_sim.errors import ConfigError

FloatArray = NDArray[np.float64]
NEWTON_STEPS = 8
"""Newton steps of :func:`cubic_inverse` from the linear guess (exact to rounding on a calibration's range)."""
compiled = nb.njit(cache=True, fastmath=False)
"""The curve's functions are compiled without fast-math, set explicitly: numba would otherwise let a
fast-math kernel that compiles them first decide their floating-point contraction for every caller."""


@nb.njit(cache=True, inline="always")
def _value(c0: float, c1: float, c2: float, c3: float, x: float) -> float:
    """The curve in Horner form: the one place it is written (inlined into the compiled functions below)."""
    return c0 + x * (c1 + x * (c2 + x * c3))


@nb.njit(cache=True, inline="always")
def _slope(c0: float, c1: float, c2: float, c3: float, x: float) -> float:  # noqa: ARG001 - one signature
    """The curve's slope: the one place it is written."""
    return c1 + x * (2.0 * c2 + 3.0 * c3 * x)


@compiled
def cubic(c0: float, c1: float, c2: float, c3: float, x: float) -> float:
    """A third-order calibration curve ``c0 + c1·x + c2·x² + c3·x³`` (Horner form).

    Parameters
    ----------
    c0, c1, c2, c3 : float
        The coefficients.
    x : float
        Where to evaluate it.

    Returns
    -------
    float
        The curve's value.
    """
    return _value(c0, c1, c2, c3, x)


@compiled
def cubic_slope(c0: float, c1: float, c2: float, c3: float, x: float) -> float:
    """The curve's slope ``dy/dx`` at ``x``.

    Parameters
    ----------
    c0, c1, c2, c3 : float
        The coefficients (``c0`` does not enter).
    x : float
        Where to evaluate it.

    Returns
    -------
    float
        ``c1 + 2·c2·x + 3·c3·x²``.
    """
    return _slope(c0, c1, c2, c3, x)


@compiled
def cubic_inverse(c0: float, c1: float, c2: float, c3: float, y: float, tol: float = 0.0) -> float:
    """The ``x`` with ``cubic(x) = y``: at most :data:`NEWTON_STEPS` Newton steps from the linear guess.

    The steps stop once one moves ``x`` by no more than ``tol·(1 + |x|)``. With ``tol = 0`` (what
    :class:`Cubic` and the command path use) only a step that changes nothing stops them, so the result
    is that of every step; the feedback path, evaluated at every sample, stops at 1e-15.

    Parameters
    ----------
    c0, c1, c2, c3 : float
        The coefficients of a curve monotonic over the range used.
    y : float
        The value to invert.
    tol : float
        Relative step below which the iteration stops.

    Returns
    -------
    float
        ``x``.
    """
    x = (y - c0) / c1
    for _ in range(NEWTON_STEPS):
        dx = (_value(c0, c1, c2, c3, x) - y) / _slope(c0, c1, c2, c3, x)
        x = x - dx
        if abs(dx) <= tol * (1.0 + abs(x)):
            break
    return x


@compiled
def _cubic_map(kind: int, c0: float, c1: float, c2: float, c3: float, x: FloatArray, out: FloatArray) -> None:
    """One of the three scalar functions on every element (0 value, 1 slope, 2 inverse)."""
    for j in range(x.shape[0]):
        if kind == 0:
            out[j] = cubic(c0, c1, c2, c3, x[j])
        elif kind == 1:
            out[j] = cubic_slope(c0, c1, c2, c3, x[j])
        else:
            out[j] = cubic_inverse(c0, c1, c2, c3, x[j])


def _apply(kind: int, c: Cubic, x: ArrayLike) -> FloatArray:
    """The compiled scalar function on an array (a 0-d input gives a numpy scalar, which acts as one)."""
    arr = np.asarray(x, dtype=float)
    flat = np.ascontiguousarray(arr.reshape(-1))
    out = np.empty_like(flat)
    _cubic_map(kind, c.c0, c.c1, c.c2, c.c3, flat, out)
    result: FloatArray = out.reshape(arr.shape)[()]  # an array, or (0-d) its scalar
    return result


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
            raise ConfigError(f"a third-order calibration needs 4 finite coefficients, got {list(c)}")
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
        """Evaluate the curve (:func:`cubic`)."""
        return _apply(0, self, x)

    def slope(self, x: ArrayLike) -> FloatArray:
        """dy/dx (:func:`cubic_slope`)."""
        return _apply(1, self, x)

    def inverse(self, y: ArrayLike) -> FloatArray:
        """X such that ``self(x) = y`` (:func:`cubic_inverse`)."""
        return _apply(2, self, y)


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
