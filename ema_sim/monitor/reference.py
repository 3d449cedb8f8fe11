"""The reference model a monitor compares the actuator against, and its run on the measured inputs.

Three ways to name it: a fidelity (``loada``, ``hoad2``: the channel's nominal parameters), an ``ema
identify`` report (its final model), or nothing, and then the nominal model is learned from a first
window the user states is healthy (:func:`ema_sim.monitor.learning.learn`).
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ema_sim.config import ChannelConfig
from ema_sim.errors import DataError, EmaError
from ema_sim.faults.kinds import FloatArray
from ema_sim.identify.consistency import read_report
from ema_sim.io.measured import MeasuredData
from ema_sim.models import ActuatorModel, create, model_names
from ema_sim.models.base import O_CUR, O_POS, O_SURF
from ema_sim.models.registry import model_class

COLUMNS = [O_POS, O_SURF, O_CUR]
"""The model outputs a monitor watches: position, surface, current (:data:`ema_sim.monitor.watch.OUTPUTS`)."""
LEARNED_FIELDS = ("wn_rad_s", "zeta", "delay_s", "offset_deg")
"""What a learned nominal model fits on the healthy window (the rest stays at the channel's values)."""
DITHER_SEED = 0x5EED
"""The seed of a high-order reference's own command noise (any: only its statistics must be the actuator's)."""


@dataclass(frozen=True)
class Reference:
    """A reference model: registry name, channel, parameter values, and where it came from.

    Parameters
    ----------
    model : str
        Registry name.
    channel : ChannelConfig
        The channel.
    overrides : dict
        Parameter values that replace the channel's.
    origin : str
        One line: a fidelity, a report, or the healthy window it was learned on.
    """

    model: str
    channel: ChannelConfig
    overrides: dict[str, float] = field(default_factory=dict)
    origin: str = ""

    def build(self) -> ActuatorModel:
        """A fresh instance; a high-order one keeps its command noise in the loop, not its LVDT noise.

        The command noise dithers the drive's dead band and the friction, as it does the actuator's: a
        noise-free reference sticks where the actuator slips, so its Coulomb friction would have to be
        smaller to match (fitted +30 % for a +50 % fault). Identification runs its physics the same way
        (:func:`ema_sim.identify.physical.run_model`). The LVDT's noise is measurement noise only.
        """
        kwargs: dict[str, object] = dict(self.overrides)
        if self.model in ("hoad2", "hoad3"):
            kwargs.update(noise=True, seed=DITHER_SEED, feedback_noise_v=0.0)
        return create(self.model, self.channel, **kwargs)


def held_inputs(data: MeasuredData) -> tuple[FloatArray, FloatArray, FloatArray]:
    """The record's command and load as held breakpoints (one where either changes), times from 0."""
    t = data.time_s - data.time_s[0]
    u, h = data.command_deg, data.hinge_moment
    keep = np.ones(t.size, dtype=bool)
    keep[1:] = (np.diff(u) != 0.0) | (np.diff(h) != 0.0)
    return t[keep], u[keep], h[keep]


def predict(model: ActuatorModel, data: MeasuredData, *, until_s: float | None = None) -> FloatArray:
    """Trim ``model`` at the record's first input and run it on the record; ``(samples, 3)``.

    The columns are position, surface and current (zeros for a model without a motor).

    With ``until_s``, the run stops there and only the samples before it are returned (the model is left at
    ``until_s``, ready to go on: :func:`continue_run`).
    """
    bp_t, bp_u, bp_h = held_inputs(data)
    t = data.time_s - data.time_s[0]
    model.trim(bp_u[0], bp_h[0])
    end = float(t[-1]) if until_s is None else float(until_s)
    samples = t[t < end] if until_s is not None else t
    keep = bp_t < end if until_s is not None else np.ones(bp_t.size, dtype=bool)
    out = model.run_outputs(bp_t[keep], bp_u[keep], bp_h[keep], sample_times=samples, end_s=end)
    return np.ascontiguousarray(out[0][:, COLUMNS])


def continue_run(model: ActuatorModel, data: MeasuredData, start_s: float, end_s: float, *,
                 flip_load: bool = False) -> FloatArray:
    """Run a model left at ``start_s`` on to ``end_s``; ``(samples, 3)`` at the record's samples in between.

    ``flip_load`` applies the load with the opposite sign (a hinge-moment sign error).
    """
    bp_t, bp_u, bp_h = held_inputs(data)
    t = data.time_s - data.time_s[0]
    i0 = max(int(np.searchsorted(bp_t, start_s, side="right")) - 1, 0)
    i1 = int(np.searchsorted(bp_t, end_s, side="left"))
    seg_t = np.concatenate([[start_s], bp_t[i0 + 1:i1]])
    seg_u, seg_h = bp_u[i0:i1], bp_h[i0:i1]
    if flip_load:
        seg_h = -seg_h
    samples = t[(t >= start_s) & (t < end_s)]
    out = model.run_outputs(seg_t, seg_u, seg_h, sample_times=samples, end_s=end_s)
    return np.ascontiguousarray(out[0][:, COLUMNS])


def snapshot(model: ActuatorModel) -> ActuatorModel:
    """An independent copy of a model in its present state (to run on from it several ways)."""
    return copy.deepcopy(model)


def from_name(model: str, channel: ChannelConfig) -> Reference:
    """The channel's nominal model of one fidelity."""
    if model not in model_names():
        raise EmaError(f"unknown model {model!r} (models: {', '.join(model_names())})")
    return Reference(model, channel, {}, f"{model}, the channel's nominal parameters")


def from_report(path: str | Path, channel: ChannelConfig) -> Reference:
    """The final model of an ``ema identify`` report of this channel.

    Raises
    ------
    DataError
        The report is of another channel, or unreadable.
    """
    rep = read_report(path)
    if rep.channel and rep.channel != channel.channel:
        raise DataError(f"{path}: an identification of channel {rep.channel!r}, not {channel.channel!r}")
    named = rep.model.split()[0] if rep.model else ""  # "hoad3 (physical parameters fitted)"
    model = named if named in model_names() else "second_order"
    cls = model_class(model)
    defaults = cls.default_params(channel)
    # the scalar parameters only: a report gives a curve's (tuple-valued) parameters one number each
    values = {k: float(v) for k, v in rep.values.items()
              if isinstance(getattr(defaults, k, None), float) and math.isfinite(v)}
    return Reference(model, channel, values, f"{model} of the identify report {path}")


def window(data: MeasuredData, start_s: float, end_s: float) -> MeasuredData:
    """The part of a record between two times from its start (the arrays sliced, the rest kept)."""
    t = data.time_s - data.time_s[0]
    sel = (t >= start_s) & (t < end_s)

    def cut(a: FloatArray | None) -> FloatArray | None:
        return None if a is None else a[sel]

    return replace(data, time_s=data.time_s[sel], command_deg=data.command_deg[sel],
                   position_deg=cut(data.position_deg), surface_deg=cut(data.surface_deg),
                   hinge_moment_inlb=cut(data.hinge_moment_inlb), current_a=cut(data.current_a),
                   command_v=cut(data.command_v), position_v=cut(data.position_v), bus_v=cut(data.bus_v),
                   rate_dps=cut(data.rate_dps), extra={})
