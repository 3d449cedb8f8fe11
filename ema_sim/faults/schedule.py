"""Running a model with faults: parameter schedules applied frame by frame, sensor and load faults around it.

:func:`run_faulted` cuts the frame grid into blocks over which no scheduled parameter changes (one block
before the first onset, one per frame while a fault ramps, one after), retunes the model at each block's
start and runs it through the block: a fault-free schedule is exactly one :meth:`ActuatorModel.run`.
The load a host applies with the wrong sign goes into the model while the record keeps the declared one;
the LVDT faults move the reported position after the model.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Sequence
from dataclasses import replace

import numpy as np

from ema_sim.errors import EmaError
from ema_sim.faults.kinds import HIGH_ORDER, SECOND_ORDER, Fault, FloatArray, LvdtScale
from ema_sim.models import ActuatorModel, Record


def model_family(model: ActuatorModel) -> str:
    """``second-order`` or ``high-order``: which fault changes apply to ``model``."""
    module = type(model).__module__
    if ".second_order." in module:
        return SECOND_ORDER
    if ".high_order." in module:
        return HIGH_ORDER
    raise EmaError(f"{model.name} has no parameters faults can change (a linear model): use loada, loac, "
                   "second_order, hoac1, hoad2 or hoad3")


def check_faults(model: ActuatorModel, faults: Sequence[Fault]) -> None:
    """One clear error when ``model`` has no stage one of ``faults`` acts on.

    Parameters
    ----------
    model : ActuatorModel
        The model the faults go into.
    faults : sequence of Fault
        The faults.
    """
    family = model_family(model) if any(f.stage == "parameter" for f in faults) else ""
    for f in faults:
        if f.stage != "parameter":
            continue
        changes = f.changes.get(family)
        if not changes:
            models = "hoac1, hoad2, hoad3" if HIGH_ORDER in f.changes else "loada, loac, second_order"
            raise EmaError(f"fault {f.kind!r} acts on no stage of {model.name} (the {family} models): use {models}")
        nominal = float(getattr(model.params[0], changes[0].parameter))  # type: ignore[attr-defined]
        if changes[0].how == "scale" and not (np.isfinite(nominal) and nominal > 0.0):
            raise EmaError(f"fault {f.kind!r}: {model.name}'s {changes[0].parameter} is {nominal:g} (the stage is "
                           f"off), so a relative change does nothing: set it on (--set {changes[0].parameter}=...)")


def parameter_values(model_params: object, faults: Sequence[Fault], family: str, time_s: float,
                     nominal: dict[str, float], held_deg: float = 0.0) -> dict[str, float]:
    """Every scheduled parameter's value at ``time_s`` (the faults applied in order on the nominal values).

    Parameters
    ----------
    model_params : object
        The model's parameter set (for the nominal values not yet in ``nominal``).
    faults : sequence of Fault
        The faults.
    family : str
        The model's family.
    time_s : float
        The instant.
    nominal : dict
        Parameter → nominal value, filled as parameters are first seen.
    held_deg : float
        The position at the onset of a fault that holds it (a jam of the second-order models).

    Returns
    -------
    dict
        Parameter → value.
    """
    values: dict[str, float] = {}
    t = np.array([time_s])
    for f in faults:
        if f.stage != "parameter":
            continue
        ramp = float(f.ramp(t)[0])
        level = float(f.level(t)[0])
        for c in f.changes[family]:
            base = nominal.setdefault(c.parameter, float(getattr(model_params, c.parameter)))
            values[c.parameter] = c.apply(values.get(c.parameter, base), level, ramp, held_deg)
    return values


def applied_load(faults: Sequence[Fault], time_s: FloatArray, hinge_moment_inlb: FloatArray) -> FloatArray:
    """The load the host applies: the declared one, reversed by the share a hinge-moment sign fault has reached."""
    factor = np.ones_like(np.asarray(time_s, dtype=float))
    for f in faults:
        if f.stage == "input":
            factor = factor * (1.0 - 2.0 * f.level(time_s))
    out: FloatArray = np.asarray(hinge_moment_inlb, dtype=float) * factor
    return out


def reported_position(faults: Sequence[Fault], time_s: FloatArray, position_deg: FloatArray) -> FloatArray:
    """The LVDT reading the record reports: the model's position with the sensor faults on it."""
    out = np.array(position_deg, dtype=float, copy=True)
    for f in faults:
        if f.stage != "output":
            continue
        out = out * (1.0 + f.level(time_s)) if isinstance(f, LvdtScale) else out + f.level(time_s)
    return out


def truth_columns(faults: Sequence[Fault], time_s: FloatArray) -> dict[str, FloatArray]:
    """``fault_<kind>`` columns: each fault's size in at each sample (a second fault of a kind gets ``_2``)."""
    cols: dict[str, FloatArray] = {}
    for f in faults:
        name, k = f"fault_{f.kind}", 2
        while name in cols:
            name, k = f"fault_{f.kind}_{k}", k + 1
        cols[name] = np.asarray(f.level(time_s), dtype=float)
    return cols


def run_faulted(model: ActuatorModel, time_s: FloatArray, command_deg: FloatArray, hinge_moment_inlb: FloatArray,
                sample_times: FloatArray, end_s: float, faults: Sequence[Fault], *,
                progress: Callable[[float], None] | None = None) -> Record:
    """Run ``model`` (trimmed) through held inputs with ``faults`` on their schedules.

    Parameters
    ----------
    model : ActuatorModel
        The model, trimmed at the first input (every instance gets the same parameter values).
    time_s, command_deg, hinge_moment_inlb : numpy.ndarray
        The frames' instants and held inputs (the declared load).
    sample_times : numpy.ndarray
        Where the outputs are read.
    end_s : float
        Where the run ends.
    faults : sequence of Fault
        The faults.
    progress : callable, optional
        Called with the fraction done.

    Returns
    -------
    Record
        The outputs, the declared load in ``hinge_moment_inlb`` and the LVDT faults on ``position_deg``.
    """
    check_faults(model, faults)
    hm_in = applied_load(faults, time_s, hinge_moment_inlb)
    params = [f for f in faults if f.stage == "parameter"]
    if not params:
        rec = model.run(time_s, command_deg, hm_in, sample_times=sample_times, end_s=end_s, progress=progress)
    else:
        rec = _run_blocks(model, time_s, command_deg, hm_in, sample_times, end_s, params, progress)
    held = np.clip(np.searchsorted(time_s, sample_times, side="right") - 1, 0, time_s.size - 1)
    return replace(rec, hinge_moment_inlb=np.broadcast_to(np.asarray(hinge_moment_inlb)[held], rec.position_deg.shape)
                   .copy(), position_deg=reported_position(faults, sample_times, rec.position_deg))


def _run_blocks(model: ActuatorModel, time_s: FloatArray, command_deg: FloatArray, hm_in: FloatArray,
                sample_times: FloatArray, end_s: float, faults: Sequence[Fault],
                progress: Callable[[float], None] | None) -> Record:
    family = model_family(model)
    base = model.params[0]  # type: ignore[attr-defined]
    nominal: dict[str, float] = {}
    ramps = np.stack([f.ramp(time_s) for f in faults], axis=1)
    starts = [0, *(np.flatnonzero(np.any(ramps[1:] != ramps[:-1], axis=1)) + 1).tolist()]
    bounds = [*starts, time_s.size]
    parts: list[Record] = []
    held_deg, holding = float(command_deg[0]), False
    for a, b in itertools.pairwise(bounds):
        t_stop = float(time_s[b]) if b < time_s.size else end_s
        last = b >= time_s.size
        lo = int(np.searchsorted(sample_times, time_s[a], side="left")) if a else 0
        hi = sample_times.size if last else int(np.searchsorted(sample_times, t_stop, side="left"))
        if not holding and parts and parts[-1].time_s.size:
            held_deg = float(parts[-1].position_deg[0, -1])  # where the actuator is when a jam may set in
        holding = holding or any(c.how == "hold" and r > 0.0 for f, r in zip(faults, ramps[a], strict=True)
                                 for c in f.changes[family])
        values = parameter_values(base, faults, family, float(time_s[a]), nominal, held_deg)
        if values:
            model.retune(**values)
        parts.append(model.run(time_s[a:b], command_deg[a:b], hm_in[a:b], sample_times=sample_times[lo:hi],
                               end_s=t_stop))
        if progress is not None:
            progress(t_stop / max(end_s, 1e-12))
    first = parts[0]
    cat = {name: np.concatenate([getattr(p, name) for p in parts], axis=1)
           for name in ("command_deg", "hinge_moment_inlb", "position_deg", "surface_deg", "rate_dps", "current_a",
                        "bus_v", "flags")}
    return Record(model=first.model, channel=first.channel, time_s=np.concatenate([p.time_s for p in parts]), **cat)


class FaultSchedule:
    """Faults applied frame by frame to a model stepped one frame at a time (an EMAC channel's).

    The same schedule as :func:`run_faulted`: at each frame the scheduled parameters are retuned when they
    changed, the load the host applies is reversed by a sign fault, and the reported LVDT reading carries the
    sensor faults.

    Parameters
    ----------
    model : ActuatorModel
        The stepped model (one instance).
    faults : sequence of Fault
        The faults, their times from the channel's start.
    """

    def __init__(self, model: ActuatorModel, faults: Sequence[Fault]) -> None:
        check_faults(model, faults)
        self.model = model
        self.faults = tuple(faults)
        self._params = [f for f in self.faults if f.stage == "parameter"]
        self._family = model_family(model) if self._params else ""
        self._base = model.params[0] if self._params else None  # type: ignore[attr-defined]
        self._nominal: dict[str, float] = {}
        self._last: dict[str, float] = {}
        self._held_deg: float | None = None

    def frame(self, time_s: float, position_deg: float) -> None:
        """Retune the model for the frame starting at ``time_s`` (``position_deg``: where the actuator is)."""
        if not self._params:
            return
        t = np.array([time_s])
        if self._held_deg is None and any(float(f.ramp(t)[0]) > 0.0 for f in self._params
                                          for c in f.changes[self._family] if c.how == "hold"):
            self._held_deg = position_deg
        values = parameter_values(self._base, self._params, self._family, time_s, self._nominal,
                                  position_deg if self._held_deg is None else self._held_deg)
        if values != self._last:
            self.model.retune(**values)
            self._last = values

    def load(self, time_s: float, hinge_moment_inlb: float) -> float:
        """The load the host applies at ``time_s``."""
        return float(applied_load(self.faults, np.array([time_s]), np.array([hinge_moment_inlb]))[0])

    def reading(self, time_s: float, position_deg: float) -> float:
        """The LVDT reading reported at ``time_s``."""
        return float(reported_position(self.faults, np.array([time_s]), np.array([position_deg]))[0])

    def truth(self, time_s: float) -> dict[str, float]:
        """Each fault's size in at ``time_s`` (``fault_<kind>`` keys, as the CSV columns)."""
        return {k: float(v[0]) for k, v in truth_columns(self.faults, np.array([time_s])).items()}
