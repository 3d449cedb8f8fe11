"""Reading suite bags: their topics, metadata and channels, and one channel as measured data.

:func:`read_bag` turns one channel of a bag into :class:`~ema_sim.io.measured.MeasuredData` in degrees
through the calibration curves recorded with it. A bag whose ``metadata.yaml`` never got written (the
writer was killed) is read record by record from its MCAP file up to the last complete chunk.
"""

from __future__ import annotations

import itertools
import json
import math
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from mcap.exceptions import McapError
from mcap.records import Channel, Message, Metadata, Schema
from mcap.stream_reader import StreamReader
from rosbags.rosbag2 import Reader

from ema_msgs_py import contract as ct
from ema_msgs_py import typestore as ts
from ema_sim.config import scaling
from ema_sim.errors import DataError
from ema_sim.io.bag.layout import SIDES, FloatArray
from ema_sim.io.csv import MIN_ROWS
from ema_sim.io.measured import MeasuredData


@dataclass
class _Source:
    """An open bag: its topics and a way to iterate the raw messages of some of them."""

    path: Path
    topics: dict[str, str]
    """topic → msgtype"""
    counts: dict[str, int]
    metadata: dict[str, str]
    complete: bool
    messages: Callable[[set[str]], Iterator[tuple[str, int, bytes]]] = field(repr=False)
    """topics → iterator of (topic, log_time_ns, raw)"""


def resolve(path: str | Path) -> tuple[Path, Path | None, Path | None]:
    """A bag's directory, its ``metadata.yaml`` and its MCAP file, from the directory or the file.

    Parameters
    ----------
    path : str or Path
        The bag directory, or its ``.mcap`` file.

    Returns
    -------
    tuple
        (bag path, metadata.yaml or None, mcap file or None).
    """
    p = Path(path)
    if p.is_file() and p.suffix == ".mcap":
        meta = p.parent / "metadata.yaml"
        return p.parent, meta if meta.is_file() else None, p
    if not p.exists():
        raise DataError(f"{p}: no such bag")
    if not p.is_dir():
        raise DataError(f"{p}: not a rosbag2 bag (a bag is a directory with metadata.yaml and an .mcap file)")
    meta = p / "metadata.yaml"
    mcaps = sorted(p.glob("*.mcap"))
    if not meta.is_file() and not mcaps:
        raise DataError(f"{p}: not a rosbag2 bag (no metadata.yaml and no .mcap file)")
    return p, meta if meta.is_file() else None, mcaps[0] if mcaps else None


def _open(path: str | Path) -> _Source:
    bag, meta, mcap = resolve(path)
    if meta is not None:
        try:
            return _open_rosbags(bag)
        except DataError:
            if mcap is None:
                raise
    if mcap is None:
        raise DataError(f"{bag}: metadata.yaml names no readable .mcap file")
    return _open_stream(bag, mcap)


def _open_rosbags(bag: Path) -> _Source:
    try:
        reader = Reader(bag)
        reader.open()
    except Exception as exc:  # rosbags raises several kinds for a bad bag
        raise DataError(f"{bag}: unreadable bag ({first_line(exc)})") from None
    topics = {c.topic: c.msgtype for c in reader.connections}
    counts = {c.topic: c.msgcount for c in reader.connections}
    custom = getattr(getattr(reader.storage, "metadata", None), "custom", None) or {}
    metadata = {str(k): str(v) for k, v in custom.items()}

    def messages(wanted: set[str]) -> Iterator[tuple[str, int, bytes]]:
        conns = [c for c in reader.connections if c.topic in wanted]
        try:
            for conn, ts, raw in reader.messages(connections=conns):
                yield conn.topic, ts, raw
        except Exception as exc:
            raise DataError(f"{bag}: unreadable bag ({first_line(exc)})") from None

    return _Source(bag, topics, counts, metadata, True, messages)


def _open_stream(bag: Path, mcap_path: Path) -> _Source:
    """An MCAP without (valid) metadata.yaml: read every complete record in order."""
    channels: dict[int, tuple[str, str]] = {}
    schemas: dict[int, str] = {}
    rows: list[tuple[str, int, bytes]] = []
    metadata: dict[str, str] = {}
    complete = False
    try:
        with mcap_path.open("rb") as fh:
            for record in StreamReader(fh, record_size_limit=1 << 30).records:
                if isinstance(record, Schema):
                    schemas[record.id] = record.name
                elif isinstance(record, Channel):
                    channels[record.id] = (record.topic, schemas.get(record.schema_id, ""))
                elif isinstance(record, Message) and record.channel_id in channels:
                    rows.append((channels[record.channel_id][0], record.log_time, bytes(record.data)))
                elif isinstance(record, Metadata) and record.name == "rosbag2":
                    metadata.update(custom_data(record.metadata.get("serialized_metadata", "")))
            complete = True
    except (McapError, EOFError, ValueError, OSError, KeyError) as exc:
        if not rows:
            why = "cut short before its first complete chunk" if channels or isinstance(exc, EOFError) or \
                type(exc).__name__ == "EndOfFile" else first_line(exc)
            raise DataError(f"{mcap_path}: no readable message ({why})") from None
    topics = dict(channels.values())
    counts = dict.fromkeys(topics, 0)
    for topic, _, _ in rows:
        counts[topic] += 1

    def messages(wanted: set[str]) -> Iterator[tuple[str, int, bytes]]:
        return (r for r in rows if r[0] in wanted)

    return _Source(bag, topics, counts, metadata, complete, messages)


def custom_data(text: str) -> dict[str, str]:
    """The test parameters in a bag's ``metadata.yaml`` text (``custom_data``; empty when unreadable).

    Parameters
    ----------
    text : str
        The YAML text.

    Returns
    -------
    dict
        Key → value, as strings.
    """
    import yaml  # noqa: PLC0415 - PyYAML only when a bag's metadata is read

    try:
        doc = yaml.safe_load(text) or {}
    except yaml.YAMLError:
        return {}
    custom = doc.get("custom_data") if isinstance(doc, dict) else None
    return {str(k): str(v) for k, v in (custom or {}).items()}


def first_line(exc: BaseException) -> str:
    """The first line of an exception's message (its type's name when it has none), for one-line errors.

    Parameters
    ----------
    exc : BaseException
        The exception.

    Returns
    -------
    str
        One line.
    """
    text = str(exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__


def _test_metadata(src: _Source) -> dict[str, str]:
    """custom_data, completed from the latched /ema/test message when the bag was not closed."""
    meta = dict(src.metadata)
    if ct.TEST in src.topics:
        for _, _, raw in src.messages({ct.TEST}):
            try:
                doc = json.loads(ts.deserialize(raw, ct.STRING).data)
            except (ValueError, AttributeError, KeyError):
                continue
            for key, value in doc.items():
                meta.setdefault(str(key), value if isinstance(value, str) else json.dumps(value))
            break
    return meta


@dataclass(frozen=True)
class BagInfo:
    """What a bag holds.

    Parameters
    ----------
    path : pathlib.Path
        The bag directory.
    topics : dict
        Topic → (message type, message count).
    start_s : float
        First log time, s.
    duration_s : float
        From the first log time to the last, s.
    metadata : dict
        The test's parameters.
    channels : list of str
        Channels whose EMAC feedback was recorded.
    complete : bool
        False when the bag was never closed (read record by record).
    """

    path: Path
    topics: dict[str, tuple[str, int]]
    """topic → (message type, message count)"""
    start_s: float
    duration_s: float
    metadata: dict[str, str]
    channels: list[str]
    complete: bool
    """False when the bag was never closed (read record by record)."""

    @property
    def message_count(self) -> int:
        """All messages."""
        return sum(c for _, c in self.topics.values())


def bag_info(path: str | Path) -> BagInfo:
    """Topics, counts, time span, test metadata and channels of a bag.

    Parameters
    ----------
    path : str or pathlib.Path
        The bag directory (or its ``.mcap`` file).

    Returns
    -------
    BagInfo
        What it holds.
    """
    src = _open(path)
    lo, hi = math.inf, -math.inf
    channels: set[str] = set()
    for topic, stamp, raw in src.messages(set(src.topics)):
        lo, hi = min(lo, stamp), max(hi, stamp)
        if topic == ct.EMAC_FEEDBACK:
            channels.update(ts.deserialize(raw, ct.JOINT_STATE).name)
    meta = _test_metadata(src)
    if not channels and meta.get("channels"):
        channels.update(c for c in meta["channels"].split(",") if c)
    return BagInfo(
        path=src.path,
        topics={t: (src.topics[t], src.counts.get(t, 0)) for t in sorted(src.topics)},
        start_s=lo * 1e-9 if math.isfinite(lo) else 0.0,
        duration_s=(hi - lo) * 1e-9 if math.isfinite(lo) else 0.0,
        metadata=meta,
        channels=[c for c in ct.CHANNELS if c in channels] + sorted(channels - set(ct.CHANNELS)),
        complete=src.complete,
    )


def bag_channels(path: str | Path) -> list[str]:
    """The channels whose EMAC feedback the bag recorded.

    Parameters
    ----------
    path : str or pathlib.Path
        The bag directory (or its ``.mcap`` file).

    Returns
    -------
    list of str
        The channels, the contract's order first.
    """
    return bag_info(path).channels


def _joint_series(src: _Source, topic: str, channel: str, field_name: str) -> dict[int, float]:
    """stamp_ns → value of ``field_name`` for ``channel`` (NaN when the field is empty)."""
    out: dict[int, float] = {}
    for _, _, raw in src.messages({topic}):
        try:
            msg = ts.deserialize(raw, ct.JOINT_STATE)
        except Exception as exc:
            raise DataError(f"{src.path}: topic {topic}: malformed JointState ({first_line(exc)})") from None
        names = list(msg.name)
        if channel not in names:
            continue
        i = names.index(channel)
        values = getattr(msg, field_name)
        out[ts.stamp_ns(msg)] = float(values[i]) if len(values) > i else math.nan
    return out


def _scaling(meta: Mapping[str, str], channel: str) -> ct.Scaling:
    text = meta.get(f"calibration.{channel}")
    if not text:
        return scaling(channel)
    try:
        doc = json.loads(text)
        c0, c1, c2, c3 = (float(x) for x in doc["command_cal_v"])
        f0, f1, f2, f3 = (float(x) for x in doc["feedback_cal_deg"])
        return ct.Scaling(channel, (c0, c1, c2, c3), (f0, f1, f2, f3))
    except (ValueError, KeyError, TypeError):
        raise DataError(f"calibration.{channel}: malformed calibration in the bag's metadata") from None


def _pick_channel(src: _Source, path: str | Path, meta: Mapping[str, str], channel: str | None) -> str:
    """The channel asked for, else the test's, else the only one in the bag."""
    if channel is None:
        channel = meta.get("channel") or None
    if channel is None:
        have = bag_channels(path)
        if len(have) != 1:
            raise DataError(f"{src.path}: name a channel; the bag has {', '.join(have) or 'none'}")
        channel = have[0]
    return channel


def _on_frames(series: Mapping[int, float], stamps: list[int]) -> FloatArray | None:
    """A recorded series on the frames: each frame's value, else the last one before it (None if never recorded)."""
    if not series:
        return None
    out = np.array([series.get(s, math.nan) for s in stamps])
    if not np.isfinite(out).any():
        return None
    first = out[np.isfinite(out)][0]
    last = first
    for k, v in enumerate(out):
        if math.isfinite(v):
            last = v
        else:
            out[k] = last
    return out


def _optional_columns(src: _Source, channel: str, stamps: list[int], fb_topic: str) -> dict[str, FloatArray | None]:
    """Surface angle and rate, applied hinge moment, motor current and bus voltage on the frames, where recorded."""
    cols: dict[str, FloatArray | None] = {"surface_deg": None, "hinge_moment_inlb": None, "current_a": None,
                                          "bus_v": None, "rate_dps": None}
    has_surface = ct.SURFACE in src.topics
    surface = _joint_series(src, ct.SURFACE, channel, "position") if has_surface else {}
    applied = _joint_series(src, ct.SURFACE, channel, "effort") if has_surface else {}
    load = _joint_series(src, ct.HINGE_MOMENT, channel, "effort") if ct.HINGE_MOMENT in src.topics else {}
    if surface and all(s in surface for s in stamps):
        cols["surface_deg"] = np.array([surface[s] for s in stamps])
    if has_surface:
        cols["rate_dps"] = _on_frames(_joint_series(src, ct.SURFACE, channel, "velocity"), stamps)
    if applied or load:
        nxt = dict(itertools.pairwise(stamps))
        hm: list[float] = []
        for s in stamps:  # the load over frame s is reported with the feedback at the frame's end
            value = applied.get(nxt.get(s, -1), load.get(s, math.nan))
            hm.append(value if math.isfinite(value) else (hm[-1] if hm else 0.0))
        cols["hinge_moment_inlb"] = np.array(hm)
    current = _joint_series(src, fb_topic, channel, "effort")
    cur = np.array([current.get(s, math.nan) for s in stamps])
    if np.isfinite(cur).any():
        cols["current_a"] = np.where(np.isfinite(cur), cur, 0.0)
    if ct.BUS in src.topics:
        cols["bus_v"] = _on_frames(_joint_series(src, ct.BUS, channel, "position"), stamps)
    return cols


def _other_side(src: _Source, channel: str, stamps: list[int], side: str, sc: ct.Scaling) -> dict[str, FloatArray]:
    """The other side of the test environment on the frames, in degrees (``fmu_command_deg``...)."""
    other = "fmu" if side == "emac" else "emac"
    out: dict[str, FloatArray] = {}
    for what, convert, name in (("command", sc.command_v_to_deg, "command_deg"),
                                ("feedback", sc.feedback_v_to_deg, "position_deg")):
        topic = f"/ema/{other}/{what}"
        if topic not in src.topics:
            continue
        volts = _on_frames(_joint_series(src, topic, channel, "position"), stamps)
        if volts is not None:
            out[f"{other}_{name}"] = np.array([convert(v) for v in volts])
    return out


def read_joint_topic(path: str | Path, topic: str, field_name: str = "position") -> dict[str, dict[int, float]]:
    """Every name of a ``JointState`` topic → {stamp_ns: value of ``field_name``} (e.g. ``/ema/fmu/vehicle``).

    Parameters
    ----------
    path : str or pathlib.Path
        The bag directory (or its ``.mcap`` file).
    topic : str
        A ``sensor_msgs/JointState`` topic.
    field_name : str
        ``position``, ``velocity`` or ``effort``.

    Returns
    -------
    dict
        Name → {stamp in ns: value}.
    """
    src = _open(path)
    if topic not in src.topics:
        raise DataError(f"{src.path}: no topic {topic} (topics: {', '.join(sorted(src.topics)) or 'none'})")
    if src.topics[topic] != ct.JOINT_STATE:
        raise DataError(f"{src.path}: {topic} is {src.topics[topic]}, not {ct.JOINT_STATE}")
    names: set[str] = set()
    for _, _, raw in src.messages({topic}):
        names.update(ts.deserialize(raw, ct.JOINT_STATE).name)
    return {name: _joint_series(src, topic, name, field_name) for name in sorted(names)}


def read_bag(path: str | Path, channel: str | None = None, *, side: str = "emac") -> MeasuredData:
    """One channel of a suite bag as data-contract columns, in degrees, with every other signal it recorded.

    Parameters
    ----------
    path : str or pathlib.Path
        The bag directory (or its ``.mcap`` file).
    channel : str, optional
        The channel to read (default: the test's, else the only one).
    side : {"emac", "fmu"}
        ``emac`` (default) reads what the actuator saw and reported, the EMAC side of the test
        environment; ``fmu`` what the flight computer sent and read.

    Returns
    -------
    MeasuredData
        Rows are the frames with both a command and a feedback; the command holds over its frame,
        position and surface are at the frame's start, the hinge moment is the one applied over the
        frame. Besides the contract's columns: ``bus_v`` (``/ema/sensor/bus``), ``rate_dps`` (the
        surface topic's velocity) and, in ``extra``, the other side's command and feedback
        (``fmu_command_deg``, ``fmu_position_deg`` on the EMAC side).
    """
    if side not in SIDES:
        raise DataError(f"side must be one of {', '.join(SIDES)}, got {side!r}")
    src = _open(path)
    meta = _test_metadata(src)
    cmd_topic, fb_topic = f"/ema/{side}/command", f"/ema/{side}/feedback"
    for needed in (cmd_topic, fb_topic):
        if needed not in src.topics:
            raise DataError(f"{src.path}: no topic {needed} (topics: {', '.join(sorted(src.topics)) or 'none'})")
    channel = _pick_channel(src, path, meta, channel)
    command_v = _joint_series(src, cmd_topic, channel, "position")
    if not command_v:
        have = bag_channels(path)
        raise DataError(f"{src.path}: channel {channel!r} has no data; channels: {', '.join(have) or 'none'}")
    position_v = _joint_series(src, fb_topic, channel, "position")
    stamps = sorted(set(command_v) & set(position_v))
    if len(stamps) < MIN_ROWS:
        raise DataError(f"{src.path}: {len(stamps)} frames of channel {channel!r} with command and feedback; "
                        f"the contract needs at least {MIN_ROWS}")
    sc = _scaling(meta, channel)
    t = np.array(stamps, dtype=np.int64)
    cv = np.array([command_v[s] for s in stamps])
    pv = np.array([position_v[s] for s in stamps])
    for name, arr in (("command", cv), ("feedback", pv)):
        bad = ~np.isfinite(arr)
        if bad.any():
            k = int(np.argmax(bad))
            raise DataError(f"{src.path}: {side} {name} of {channel!r} is not finite at stamp {t[k] * 1e-9:.6f} s")
    t0 = int(t[0])
    meta = {**meta, "source": "rosbag2", "side": side, "channel": channel,
            "bag_complete": str(src.complete).lower(), "start_stamp_s": f"{t0 * 1e-9:.9f}"}
    cols = _optional_columns(src, channel, stamps, fb_topic)
    return MeasuredData(
        time_s=np.asarray((t - t0) * 1e-9, dtype=float),
        command_deg=np.array([sc.command_v_to_deg(v) for v in cv]),
        position_deg=np.array([sc.feedback_v_to_deg(v) for v in pv]),
        surface_deg=cols["surface_deg"],
        hinge_moment_inlb=cols["hinge_moment_inlb"],
        current_a=cols["current_a"],
        command_v=cv,
        position_v=pv,
        metadata=meta,
        source=str(src.path),
        bus_v=cols["bus_v"],
        rate_dps=cols["rate_dps"],
        extra=_other_side(src, channel, stamps, side, sc),
    )


def read_fault_truth(path: str | Path, channel: str) -> list[tuple[float, dict[str, float]]]:
    """The faults a run's EMAC injected into one channel, from ``/ema/faults/truth``: (time, sizes) at each change.

    Parameters
    ----------
    path : str or pathlib.Path
        The bag.
    channel : str
        The channel.

    Returns
    -------
    list of tuple
        Channel time (s from its start) and ``fault_<kind>`` → size from then on; empty without faults.
    """
    src = _open(path)
    out: list[tuple[float, dict[str, float]]] = []
    if ct.FAULT_TRUTH not in src.topics:
        return out
    for _, _, raw in src.messages({ct.FAULT_TRUTH}):
        try:
            doc = json.loads(ts.deserialize(raw, ct.STRING).data)
        except (ValueError, AttributeError, KeyError):
            continue
        if doc.get("channel") == channel:
            out.append((float(doc["time_s"]), {str(k): float(v) for k, v in doc["faults"].items()}))
    return out
