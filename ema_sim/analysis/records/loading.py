"""The one entry point through which ``ema analyze`` reads a record: a rig's CSV or a rosbag2 bag.

Bags are read by the node suite's reader, ``ema_sim.io.load_data(path, channel=None)``, which
dispatches CSV against bag and turns the wire's volts into degrees through the calibration. When this
build has no such reader, CSVs are read here (:func:`ema_sim.io.csv.read_csv`) and a bag gets a clear
error instead of a traceback. Whatever the reader raises on a malformed bag reaches the user as one
:class:`~ema_sim.errors.DataError` line.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from pathlib import Path

from ema_sim.errors import DataError, EmaError
from ema_sim.io.csv import RigFormat, read_csv, read_rig
from ema_sim.io.measured import MeasuredData

BAG_SUFFIXES = (".mcap", ".db3")


def _bag_reader() -> Callable[..., MeasuredData] | None:
    """``ema_sim.io.load_data`` when the node suite provides it."""
    return getattr(importlib.import_module("ema_sim.io"), "load_data", None)


def looks_like_bag(path: Path) -> bool:
    """A rosbag2 directory (``metadata.yaml`` or MCAP/SQLite files inside) or a bag file.

    Parameters
    ----------
    path : pathlib.Path
        Where to read or write.

    Returns
    -------
    bool
        True for a bag.
    """
    if path.is_dir():
        return (path / "metadata.yaml").is_file() or any(p.suffix in BAG_SUFFIXES for p in path.iterdir())
    return path.suffix in BAG_SUFFIXES


def load_record(path: str | Path, channel: str | None = None, rig: RigFormat | None = None) -> MeasuredData:
    """Read a record for analysis.

    Parameters
    ----------
    path : str or pathlib.Path
        A CSV, a rig's own file or a bag.
    channel : str, optional
        Picks one channel of a multi-channel bag; a single-channel CSV whose metadata names another
        channel is an error.
    rig : RigFormat, optional
        A rig file's delimiter, column names and units.

    Returns
    -------
    MeasuredData
        The record.
    """
    path = Path(path)
    reader = _bag_reader()
    if reader is not None:
        try:
            return reader(path, channel=channel, rig=rig) if rig is not None else reader(path, channel=channel)
        except EmaError:
            raise
        except Exception as exc:  # untrusted input: any failure of the reader is the data's
            raise DataError(f"{path}: cannot read ({type(exc).__name__}: {exc})") from exc
    if not path.exists():
        raise DataError(f"{path}: no such file or directory")
    if looks_like_bag(path):
        raise DataError(f"{path}: a rosbag2 bag; reading bags needs the node suite's reader "
                        "(ema_sim.io.load_data), which this build does not have: export the bag to CSV or install it")
    if path.is_dir():
        raise DataError(f"{path}: a directory that is not a rosbag2 bag (no metadata.yaml or .mcap file)")
    data = read_rig(path, rig) if rig is not None else read_csv(path)
    meta_channel = data.metadata.get("channel")
    if channel and meta_channel and meta_channel != channel:
        raise DataError(f"{path}: holds channel {meta_channel!r}, not {channel!r}")
    return data
