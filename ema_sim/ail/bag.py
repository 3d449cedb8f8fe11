"""An aircraft-in-the-loop bag (``ema launch --fmu``) as an :class:`~ema_sim.ail.loop.AilRun`.

The same rows as the offline run: one per FMU frame, the command over the frame and the state at its
start, read through :func:`ema_sim.io.bag.read_bag` (both sides of the test environment, every channel)
and :func:`ema_sim.io.bag.read_joint_topic` (``/ema/fmu/vehicle``). Signals a bag does not carry (the
aerodynamic hinge moments and the deflections the simulation saw) are NaN.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ema_msgs_py import contract as ct
from ema_sim.ail.loop import SIGNALS, AilRun, FloatArray
from ema_sim.ail.vehicle import STATES
from ema_sim.config import CHANNELS
from ema_sim.errors import DataError
from ema_sim.io.bag import bag_info, read_bag, read_joint_topic


def run_from_bag(path: str | Path) -> AilRun:
    """Read the bag (every channel, both sides, the vehicle) into rows per FMU frame.

    Parameters
    ----------
    path : str or Path
        The bag directory ``ema launch --fmu`` recorded.

    Returns
    -------
    AilRun
        The run, its signals the offline run's (NaN where the bag does not carry one).

    Raises
    ------
    DataError
        A channel's feedback is missing, or the two sides' frames differ.
    """
    info = bag_info(path)
    missing = [ch for ch in CHANNELS if ch not in info.channels]
    if missing:
        raise DataError(f"{path}: not an aircraft-in-the-loop bag: no feedback from {', '.join(missing)}")
    emac = {ch: read_bag(path, ch) for ch in CHANNELS}
    fmu = {ch: read_bag(path, ch, side="fmu") for ch in CHANNELS}
    start = round(float(emac[CHANNELS[0]].metadata["start_stamp_s"]) * 1e9)
    stamps = np.round(emac[CHANNELS[0]].time_s * 1e9).astype(np.int64) + start
    n = stamps.size
    for ch in CHANNELS:
        for side in (emac[ch], fmu[ch]):
            if side.time_s.size != n or not np.allclose(side.time_s, emac[CHANNELS[0]].time_s, atol=1e-9):
                raise DataError(f"{path}: {ch}: the frames of the two sides differ")
    nan = np.full(n, np.nan)
    signals: dict[str, dict[str, FloatArray]] = {}
    for ch in CHANNELS:
        sig: dict[str, FloatArray | None] = {name: nan.copy() for name in SIGNALS}
        for prefix, side in (("", emac[ch]), ("fmu_", fmu[ch])):
            for name in ("command_v", "command_deg", "position_v", "position_deg"):
                sig[prefix + name] = getattr(side, name)
        for name in ("surface_deg", "hinge_moment_inlb", "current_a"):
            sig[name] = getattr(emac[ch], name)
        signals[ch] = {k: nan.copy() if v is None else np.asarray(v, dtype=float) for k, v in sig.items()}
    vehicle = {name: nan.copy() for name in STATES}
    if ct.VEHICLE in info.topics:
        series = read_joint_topic(path, ct.VEHICLE)
        for name in STATES:
            got = series.get(name, {})
            vehicle[name] = np.array([got.get(int(s), np.nan) for s in stamps])
    meta = {k: v for k, v in info.metadata.items() if not k.startswith("calibration.")}
    return AilRun((stamps - stamps[0]) * 1e-9, signals, vehicle, {**meta, "source": str(path)})
