"""Data in and out: the measured-data CSV contract and rosbag2 (MCAP) bags of the node suite.

:func:`load_data` is the one entry point of the offline tools: a CSV file or a bag directory (or its
``.mcap`` file) becomes :class:`~ema_sim.io.measured.MeasuredData`.
"""

from __future__ import annotations

from pathlib import Path

from ema_sim.errors import DataError
from ema_sim.io.csv import RigFormat, read_csv, read_rig
from ema_sim.io.measured import MeasuredData


def is_bag(path: str | Path) -> bool:
    """A rosbag2 directory (metadata.yaml or an .mcap inside) or an .mcap file.

    Parameters
    ----------
    path : str or pathlib.Path
        The path.

    Returns
    -------
    bool
        True for a bag.
    """
    p = Path(path)
    if p.is_dir():
        return (p / "metadata.yaml").is_file() or any(p.glob("*.mcap"))
    return p.suffix == ".mcap"


def load_data(path: str | Path, channel: str | None = None, rig: RigFormat | None = None) -> MeasuredData:
    """Measured data from a CSV, a rig's own file or a bag.

    Parameters
    ----------
    path : str or pathlib.Path
        A data-contract CSV, a rig's file, or a rosbag2 directory (or its ``.mcap`` file).
    channel : str, optional
        Picks one channel of a bag (or checks a CSV's metadata).
    rig : RigFormat, optional
        A rig file's delimiter, column names and units (ignored for a bag).

    Returns
    -------
    MeasuredData
        The record.
    """
    if is_bag(path):
        from ema_sim.io.bag import read_bag  # noqa: PLC0415 - rosbags only when a bag is read

        return read_bag(path, channel)
    if Path(path).is_dir():
        raise DataError(f"{path}: a directory that is not a rosbag2 bag (no metadata.yaml or .mcap file)")
    data = read_rig(path, rig) if rig is not None else read_csv(path)
    declared = data.metadata.get("channel")
    if channel is not None and declared is not None and declared != channel:
        raise DataError(f"{path}: holds channel {declared!r}, not {channel!r}")
    return data


__all__ = ["MeasuredData", "RigFormat", "is_bag", "load_data"]
