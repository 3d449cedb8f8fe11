"""Offline runs: a model driven by a maneuver and a load on the FMU frame grid, sampled like a DAU."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ema_sim import __version__
from ema_sim.errors import EmaError
from ema_sim.faults import Fault, run_faulted, truth_columns
from ema_sim.models import ActuatorModel, Record, create
from ema_sim.signals import Load, Maneuver
from ema_sim.signals.loads import NoLoad

FloatArray = NDArray[np.float64]
FRAME_HZ = 200.0
"""The FMU and simulation frame rate (table 5)."""
DAU_HZ = 1000.0


@dataclass(frozen=True)
class Inputs:
    """Zero-order-held inputs on the frame grid."""

    time_s: FloatArray
    command_deg: FloatArray
    hinge_moment_inlb: FloatArray
    duration_s: float


def frame_inputs(maneuver: Maneuver, load: Load | None = None, *, duration_s: float | None = None,
                 frame_hz: float = FRAME_HZ) -> Inputs:
    """The maneuver's command and the load at each frame, for ``duration_s`` (default: natural length)."""
    load = load or NoLoad()
    if duration_s is None:
        duration_s = max(maneuver.duration_s, load.duration_s)
    if not duration_s > 0.0:
        raise EmaError(f"duration must be positive, got {duration_s}")
    if not frame_hz > 0.0:
        raise EmaError(f"frame rate must be positive, got {frame_hz}")
    n = int(np.floor(duration_s * frame_hz + 1e-9))
    t = np.arange(max(n, 1)) / frame_hz
    cmd = maneuver.command_deg(t)
    return Inputs(t, cmd, load.hinge_moment_inlb(t, cmd), float(duration_s))


def dau_times(duration_s: float, sample_hz: float = DAU_HZ) -> FloatArray:
    """Sample instants of a DAU at ``sample_hz`` over ``[0, duration_s]``."""
    if not sample_hz > 0.0:
        raise EmaError(f"sample rate must be positive, got {sample_hz}")
    return np.arange(int(np.floor(duration_s * sample_hz + 1e-9)) + 1) / sample_hz


def run_maneuver(model: ActuatorModel, inputs: Inputs, *, sample_hz: float = DAU_HZ,
                 progress: Callable[[float], None] | None = None, faults: Sequence[Fault] = ()) -> Record:
    """Trim the model at the first input and run it through ``inputs``, sampled at ``sample_hz``.

    ``faults`` are injected on their schedules (:func:`ema_sim.faults.run_faulted`).
    """
    model.trim(inputs.command_deg[0], inputs.hinge_moment_inlb[0])
    samples = dau_times(inputs.duration_s, sample_hz)
    if faults:
        return run_faulted(model, inputs.time_s, inputs.command_deg, inputs.hinge_moment_inlb, samples,
                           inputs.duration_s, faults, progress=progress)
    return model.run(inputs.time_s, inputs.command_deg, inputs.hinge_moment_inlb,
                     sample_times=samples, end_s=inputs.duration_s, progress=progress)


def csv_columns(model: ActuatorModel, record: Record, i: int = 0,
                faults: Sequence[Fault] = ()) -> dict[str, FloatArray]:
    """The data-contract columns of one instance, with the ±10 V signals and current where known.

    With ``faults``, the injected truth follows: one ``fault_<kind>`` column each, its size at each sample.
    """
    ch = model.channel
    cols = {
        "time_s": record.time_s,
        "command_deg": record.command_deg[i],
        "position_deg": record.position_deg[i],
        "surface_deg": record.surface_deg[i],
        "hinge_moment_inlb": record.hinge_moment_inlb[i],
    }
    if model.has_current:
        cols["current_a"] = record.current_a[i]
    cols["command_v"] = np.asarray(ch.deg_to_v(record.command_deg[i]))
    cols["position_v"] = np.asarray(ch.position_deg_to_v(record.position_deg[i]))
    cols.update(truth_columns(faults, record.time_s))
    return cols


def simulate(model_name: str, maneuver: Maneuver, load: Load | None = None, *, channel: str = "left_wing",
             rate_hz: float | None = None, duration_s: float | None = None, frame_hz: float = FRAME_HZ,
             sample_hz: float = DAU_HZ, progress: Callable[[float], None] | None = None,
             faults: Sequence[Fault] = (), **overrides: object) -> tuple[ActuatorModel, Record, dict[str, str]]:
    """Build ``model_name`` for ``channel`` and run the maneuver; returns model, record and metadata.

    ``faults`` are injected on their schedules; the metadata names them (``faults``, ``;``-separated specs).
    """
    kwargs: dict[str, object] = dict(overrides)
    if rate_hz is not None:
        kwargs["rate_hz"] = rate_hz
    model = create(model_name, channel, **kwargs)
    inputs = frame_inputs(maneuver, load, duration_s=duration_s, frame_hz=frame_hz)
    record = run_maneuver(model, inputs, sample_hz=sample_hz, progress=progress, faults=faults)
    meta = {
        "generator": f"ema simulate (ema_sim {__version__})",
        "model": model.name,
        "channel": model.channel.channel,
        "rate_hz": "continuous" if model.continuous else f"{model.rate_hz:g}",
        "maneuver": maneuver.spec(),
        "load": (load or NoLoad()).spec(),
        "frame_hz": f"{frame_hz:g}",
        "sample_hz": f"{sample_hz:g}",
        "duration_s": f"{inputs.duration_s:g}",
    }
    if faults:
        meta["faults"] = ";".join(f.spec() for f in faults)
    if overrides:
        meta["overrides"] = ",".join(f"{k}={v}" for k, v in overrides.items())
    return model, record, meta
