"""How far a discrete implementation strays from its continuous reference (table 6, figure 40)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ema_sim.jsontypes import JsonObject
from ema_sim.models import create
from ema_sim.signals import Load, Maneuver, parse_maneuver
from ema_sim.simulation import FRAME_HZ, frame_inputs, run_maneuver

TABLE6_MANEUVER = "steps:amps_deg=1/20/0.5,lead_s=0.5,hold_s=1.5"
"""The documented input of our table 6: section 2.7's step set (1°, 20°, 0.5°), each up and back."""
TABLE6_CANDIDATES: tuple[tuple[str, float], ...] = (
    ("loadf", 200.0), ("loada", 200.0), ("loada", 400.0), ("loada", 800.0), ("loada", 1000.0), ("loada", 2000.0),
)
TABLE6_OVERRIDES: dict[str, Any] = {"delay_s": 0.0}
"""The delay is exact in LOAC but falls on a step of each discrete model; leaving it out isolates the
integrators, which is what table 6 compares."""


@dataclass(frozen=True)
class ErrorRow:
    """Position error statistics of one model against the reference, degrees.

    Parameters
    ----------
    model : str
        The model's name.
    rate_hz : float
        Its rate, Hz.
    mean_abs_deg : float
        Mean absolute error, deg.
    std_abs_deg : float
        Standard deviation of the absolute error, deg.
    max_abs_deg : float
        Largest absolute error, deg.
    """

    model: str
    rate_hz: float
    mean_abs_deg: float
    std_abs_deg: float
    max_abs_deg: float

    def as_dict(self) -> JsonObject:
        """Plain values for JSON.

        Returns
        -------
        dict
            Plain values for JSON.
        """
        return {"model": self.model, "rate_hz": self.rate_hz, "mean_abs_deg": self.mean_abs_deg,
                "std_abs_deg": self.std_abs_deg, "max_abs_deg": self.max_abs_deg}


def model_errors(
    reference: str,
    candidates: Sequence[tuple[str, float | None]],
    maneuver: Maneuver | str = TABLE6_MANEUVER,
    load: Load | None = None,
    *,
    channel: str = "left_wing",
    sample_hz: float = FRAME_HZ,
    output: str = "position_deg",
    **overrides: float,
) -> list[ErrorRow]:
    """Run the reference and each (model, rate) on the same input; |error| statistics of ``output``.

    Outputs are compared at the 200 Hz simulation frame by default, where every implementation has a
    fresh output; sampling faster would add each discrete model's output hold to its error.

    Parameters
    ----------
    reference : str
        The reference model's name.
    candidates : sequence
        (model, rate) pairs compared with the reference.
    maneuver : Maneuver or str
        The maneuver spec.
    load : Load or None
        The load spec (None: unloaded).
    channel : str
        The channel (``left_wing``...).
    sample_hz : float
        Sample rate of the comparison, Hz.
    output : str
        Name of the output.
    **overrides : float
        Parameter overrides of every model.

    Returns
    -------
    list
        One row per candidate.
    """
    man = parse_maneuver(maneuver) if isinstance(maneuver, str) else maneuver
    inputs = frame_inputs(man, load)
    ref = getattr(run_maneuver(create(reference, channel, **overrides), inputs, sample_hz=sample_hz), output)[0]
    rows = []
    for name, rate in candidates:
        kwargs: dict[str, object] = dict(overrides)
        if rate is not None:
            kwargs["rate_hz"] = rate
        model = create(name, channel, **kwargs)
        out = getattr(run_maneuver(model, inputs, sample_hz=sample_hz), output)[0]
        err = np.abs(out - ref)
        rows.append(ErrorRow(name, model.rate_hz, float(err.mean()), float(err.std()), float(err.max())))
    return rows


def table6(channel: str = "left_wing") -> list[ErrorRow]:
    """Our reproduction of table 6: LOADF and LOADA at 200–2000 Hz against LOAC.

    Parameters
    ----------
    channel : str
        The channel (``left_wing``...).

    Returns
    -------
    list
        One row per candidate.
    """
    return model_errors("loac", TABLE6_CANDIDATES, TABLE6_MANEUVER, channel=channel, **TABLE6_OVERRIDES)


FIGURE40_MANEUVER = "steps:amps_deg=0.5/1/2,lead_s=0.5,hold_s=1.0"
"""Figure 40's input: small steps (0.5°, 1°, 2°), where section 4.2.6 judged HOAD2 against HOAC1."""
FIGURE40_RATES_HZ: tuple[float, ...] = (10_000.0, 20_000.0, 50_000.0, 100_000.0)
FIGURE40_OVERRIDES: dict[str, Any] = {
    "command_delay_s": 0.0, "feedback_delay_s": 0.0, "quantization_v": 0.0, "noise": 0.0,
}
"""HOAD2's flight/test elements (delay, quantization, noise) are not in HOAC1: left out, the comparison
isolates the discretization, as table 6 does for the second-order family."""


def figure40(channel: str = "left_wing", rates_hz: Sequence[float] = FIGURE40_RATES_HZ) -> list[ErrorRow]:
    """Figure 40: HOAD2 at each rate against HOAC1, position compared at the 1 kHz DAU rate.

    Parameters
    ----------
    channel : str
        The channel (``left_wing``...).
    rates_hz : sequence
        The rates, Hz.

    Returns
    -------
    list
        One row per rate.
    """
    return model_errors("hoac1", [("hoad2", r) for r in rates_hz], FIGURE40_MANEUVER, channel=channel,
                        sample_hz=1000.0, **FIGURE40_OVERRIDES)


def format_table(rows: Sequence[ErrorRow], reference: str) -> str:
    """A Markdown table like the report's table 6.

    Parameters
    ----------
    rows : sequence
        Table rows.
    reference : str
        The reference model's name.

    Returns
    -------
    str
        The table as text.
    """
    head = f"| model (against {reference.upper()}) | rate | mean abs error, deg | std of abs error, deg |"
    lines = [head + " max abs error, deg |", "| --- | --- | --- | --- | --- |"]
    for r in rows:
        stats = f"{r.mean_abs_deg:.4f} | {r.std_abs_deg:.4f} | {r.max_abs_deg:.4f}"
        lines.append(f"| {r.model.upper()} | {r.rate_hz:,.0f} Hz | {stats} |")
    return "\n".join(lines)
