"""The record every tool reads: the data contract's columns as arrays, their unit and the record's metadata.

Readers (:mod:`ema_sim.io.csv` for the contract's CSV and rigs' files, :mod:`ema_sim.io.bag` for rosbag2)
produce a :class:`MeasuredData`; ``ema analyze``, ``ema identify``, ``ema monitor`` and ``ema verify``
consume it. It lives apart from any parser so that the readers and the tools depend on it, not on each
other.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from ema_sim.errors import DataError

FloatArray = NDArray[np.float64]

REQUIRED = ("time_s", "command_deg")
"""The columns every record has."""
OUTPUTS = ("position_deg", "surface_deg")
"""The outputs, position first."""
OPTIONAL = ("hinge_moment_inlb", "current_a", "command_v", "position_v", "bus_v", "rate_dps")
"""Recognised optional columns; ``bus_v`` (150 V bus, for regeneration) and ``rate_dps`` (surface rate)
extend the contract's table and are read when a file has them."""
KNOWN = REQUIRED + OUTPUTS + OPTIONAL


@dataclass(frozen=True)
class MeasuredData:
    """One record of actuator data: the contract's columns as arrays, plus its metadata.

    Parameters
    ----------
    time_s : numpy.ndarray
        Sample times, s.
    command_deg : numpy.ndarray
        Surface command, deg.
    position_deg : numpy.ndarray or None
        LVDT position feedback, deg.
    surface_deg : numpy.ndarray or None
        External surface angle, deg.
    hinge_moment_inlb : numpy.ndarray or None
        Hinge moment, in·lb (positive aids positive deflection).
    current_a : numpy.ndarray or None
        Motor current, A.
    command_v : numpy.ndarray or None
        The command's ±10 V signal.
    position_v : numpy.ndarray or None
        The LVDT's ±10 V signal.
    metadata : dict
        ``# key: value`` lines of a CSV, a bag's test parameters.
    source : str
        Where the record was read from.
    bus_v : numpy.ndarray or None
        Motor bus voltage (section 2.5), when the rig or model records it.
    rate_dps : numpy.ndarray or None
        Surface rate, when recorded.
    unit : str
        Unit of the command and outputs: ``deg``, or a rig's linear unit (``mm``, ``in``) kept as logged.
    extra : dict
        Further recorded signals outside the contract's columns (a bag's FMU-side command and feedback).
    """

    time_s: FloatArray
    command_deg: FloatArray
    position_deg: FloatArray | None = None
    surface_deg: FloatArray | None = None
    hinge_moment_inlb: FloatArray | None = None
    current_a: FloatArray | None = None
    command_v: FloatArray | None = None
    position_v: FloatArray | None = None
    metadata: dict[str, str] = field(default_factory=dict)
    source: str = ""
    bus_v: FloatArray | None = None
    """Motor bus voltage (section 2.5), when the rig or model records it."""
    rate_dps: FloatArray | None = None
    """Surface rate, when recorded."""
    unit: str = "deg"
    """Unit of the command and outputs: ``deg``, or a rig's linear unit (``mm``, ``in``) kept as logged."""
    extra: dict[str, FloatArray] = field(default_factory=dict)
    """Further recorded signals outside the contract's columns (a bag's FMU-side command and feedback)."""

    @property
    def outputs(self) -> list[str]:
        """The output columns present, position first."""
        return [name for name in OUTPUTS if getattr(self, name) is not None]

    @property
    def hinge_moment(self) -> FloatArray:
        """The hinge moment, zeros when the file has none."""
        return self.hinge_moment_inlb if self.hinge_moment_inlb is not None else np.zeros_like(self.time_s)

    def column(self, name: str) -> FloatArray:
        """A present column by name.

        Parameters
        ----------
        name : str
            The column (``position_deg``...).

        Returns
        -------
        numpy.ndarray
            Its values.
        """
        value = getattr(self, name, None)
        if value is None:
            raise DataError(f"{self.source or 'data'}: no column {name!r}")
        return np.asarray(value, dtype=float)

    @property
    def sample_hz(self) -> float:
        """Median sample rate."""
        return float(1.0 / np.median(np.diff(self.time_s)))

    def __len__(self) -> int:
        return int(self.time_s.size)
