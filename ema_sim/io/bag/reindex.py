"""Repairing a bag whose writer was killed: the MCAP records salvaged up to the last complete chunk, re-indexed."""

from __future__ import annotations

import json
import shutil
import struct
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

from mcap.records import Chunk
from mcap.stream_reader import get_chunk_data_stream
from rosbags.interfaces import Connection
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.rosbag2.metadata import parse_qos

from ema_msgs_py import contract as ct
from ema_msgs_py import typestore as ts
from ema_sim.errors import DataError
from ema_sim.io.bag.reader import custom_data, first_line, resolve

MCAP_MAGIC = b"\x89MCAP0\r\n"
_OP_SCHEMA, _OP_CHANNEL, _OP_MESSAGE, _OP_CHUNK, _OP_METADATA, _OP_DATA_END, _OP_FOOTER = 3, 4, 5, 6, 12, 15, 2


@dataclass(frozen=True)
class ReindexReport:
    """What :func:`reindex_bag` recovered."""

    path: Path
    messages: dict[str, int]
    """topic → messages in the repaired bag"""
    chunks: int
    """Complete chunks read."""
    partial_chunk_messages: int
    """Complete messages taken from a chunk cut short (uncompressed chunks only)."""
    dropped_bytes: int
    """Bytes at the end that held no complete record (an incomplete message, a chunk header)."""
    backup: Path | None
    """The original file, kept beside the repaired one."""

    @property
    def message_count(self) -> int:
        """Messages in the repaired bag."""
        return sum(self.messages.values())


@dataclass
class _Salvage:
    schemas: dict[int, tuple[str, str, bytes]] = field(default_factory=dict)
    """id → (name, encoding, data)"""
    channels: dict[int, tuple[str, int, str, dict[str, str]]] = field(default_factory=dict)
    """id → (topic, schema id, message encoding, metadata)"""
    messages: list[tuple[int, int, bytes]] = field(default_factory=list)
    """(channel id, log time, data) in file order"""
    custom: dict[str, str] = field(default_factory=dict)
    chunks: int = 0
    partial: int = 0
    end: int = 0


def _records(buf: memoryview, start: int, end: int) -> Iterator[tuple[int, memoryview, int]]:
    """(opcode, content, offset after it) of each complete record in ``buf[start:end]``."""
    at = start
    while at + 9 <= end:
        op = buf[at]
        (length,) = struct.unpack_from("<Q", buf, at + 1)
        if at + 9 + length > end:
            return
        yield op, buf[at + 9:at + 9 + length], at + 9 + length
        at += 9 + length


def _mcap_string(buf: memoryview, at: int) -> tuple[str, int]:
    (n,) = struct.unpack_from("<I", buf, at)
    return bytes(buf[at + 4:at + 4 + n]).decode("utf-8"), at + 4 + n


def _mcap_map(buf: memoryview, at: int) -> tuple[dict[str, str], int]:
    (size,) = struct.unpack_from("<I", buf, at)
    at += 4
    stop = at + size
    out = {}
    while at < stop:
        key, at = _mcap_string(buf, at)
        out[key], at = _mcap_string(buf, at)
    return out, stop


def _take(found: _Salvage, op: int, rec: memoryview) -> None:
    """A schema, channel or message record (inside a chunk or not); the rosbag2 metadata record."""
    if op == _OP_SCHEMA:
        (sid,) = struct.unpack_from("<H", rec, 0)
        name, at = _mcap_string(rec, 2)
        encoding, at = _mcap_string(rec, at)
        (n,) = struct.unpack_from("<I", rec, at)
        found.schemas[sid] = (name, encoding, bytes(rec[at + 4:at + 4 + n]))
    elif op == _OP_CHANNEL:
        cid, sid = struct.unpack_from("<HH", rec, 0)
        topic, at = _mcap_string(rec, 4)
        encoding, at = _mcap_string(rec, at)
        meta, _ = _mcap_map(rec, at)
        found.channels[cid] = (topic, sid, encoding, meta)
    elif op == _OP_MESSAGE:
        cid, _seq, log_time, _pub = struct.unpack_from("<HIQQ", rec, 0)
        found.messages.append((cid, log_time, bytes(rec[22:])))
    elif op == _OP_METADATA:
        name, at = _mcap_string(rec, 0)
        if name == "rosbag2":
            meta, _ = _mcap_map(rec, at)
            found.custom.update(custom_data(meta.get("serialized_metadata", "")))


def _salvage(data: bytes) -> _Salvage:
    """Every complete record of an MCAP file, in order, up to where the file stops making sense."""
    if not data.startswith(MCAP_MAGIC):
        raise DataError("not an MCAP file (no magic bytes)")
    buf = memoryview(data)
    found = _Salvage(end=len(MCAP_MAGIC))
    for op, rec, after in _records(buf, len(MCAP_MAGIC), len(buf)):
        if op == _OP_CHUNK:
            start, end, usize, crc = struct.unpack_from("<QQQI", rec, 0)
            compression, at = _mcap_string(rec, 28)
            (size,) = struct.unpack_from("<Q", rec, at)
            inner = bytes(rec[at + 8:at + 8 + size])
            if compression:  # mcap's own decompression (zstd, lz4)
                stream, n = get_chunk_data_stream(Chunk(compression=compression, data=inner, message_end_time=end,
                                                        message_start_time=start, uncompressed_crc=crc,
                                                        uncompressed_size=usize))
                inner = stream.read(n)
            for iop, irec, _ in _records(memoryview(inner), 0, len(inner)):
                _take(found, iop, irec)
            found.chunks += 1
        elif op in (_OP_DATA_END, _OP_FOOTER):
            found.end = after
            break
        else:
            _take(found, op, rec)
        found.end = after
    else:
        _salvage_cut_chunk(buf, found)
    return found


def _salvage_cut_chunk(buf: memoryview, found: _Salvage) -> None:
    """The complete records of an uncompressed chunk the writer did not finish (it was killed)."""
    at = found.end
    if at + 9 > len(buf) or buf[at] != _OP_CHUNK:
        return
    try:
        compression, inner = _mcap_string(buf, at + 9 + 28)
    except (struct.error, UnicodeDecodeError):
        return
    if compression:
        return  # a compressed chunk cut short cannot be decompressed
    for iop, irec, after in _records(buf, inner + 8, len(buf)):
        before = len(found.messages)
        _take(found, iop, irec)
        found.partial += len(found.messages) - before
        found.end = after


def reindex_bag(path: str | Path, *, keep_original: bool = True) -> ReindexReport:
    """Make a bag whose writer was killed readable again, losing no complete record (``ros2 bag reindex``).

    Reads every complete record of the bag's MCAP file (complete chunks, and the complete messages of an
    uncompressed chunk cut short), and writes them into a new MCAP file with its index, summary and footer
    and the bag's ``metadata.yaml`` (per-topic counts, times, QoS). The test's parameters come from the
    file's rosbag2 metadata when it has one, else from the latched ``/ema/test`` message. The original
    file is kept beside the new one as ``<name>.mcap.orig`` unless ``keep_original`` is false.

    Parameters
    ----------
    path : str or Path
        The bag directory (or its ``.mcap`` file).
    keep_original : bool
        Keep the cut file beside the new one as ``<name>.mcap.orig``.

    Returns
    -------
    ReindexReport
        Records recovered per topic, bytes dropped, and the paths written.
    """
    bag, _, mcap_path = resolve(path)
    if mcap_path is None:
        raise DataError(f"{bag}: no .mcap file to reindex")
    try:
        data = mcap_path.read_bytes()
        found = _salvage(data)
    except (OSError, struct.error, UnicodeDecodeError) as exc:
        raise DataError(f"{mcap_path}: cannot read ({first_line(exc)})") from None
    except DataError as exc:
        raise DataError(f"{mcap_path}: {exc}") from None
    custom = dict(found.custom) or _salvaged_test_metadata(found)
    tmp = bag.parent / f".{bag.name}.reindex"
    shutil.rmtree(tmp, ignore_errors=True)
    writer = Writer(tmp, version=9, storage_plugin=StoragePlugin.MCAP)
    writer.open()
    conns: dict[int, Connection] = {}
    store = ts.typestore()
    for cid, (topic, sid, encoding, meta) in sorted(found.channels.items()):
        msgtype, _, schema = found.schemas.get(sid, ("", "", b""))
        known = msgtype in store.types
        conns[cid] = writer.add_connection(
            topic, msgtype, typestore=store if known else None, msgdef=None if known else schema.decode(),
            rihs01=None if known else "RIHS01_" + "0" * 64, serialization_format=encoding or "cdr",
            offered_qos_profiles=parse_qos(meta.get("offered_qos_profiles", "[]")))
    counts = dict.fromkeys((found.channels[c][0] for c in conns), 0)
    for cid, log_time, raw in found.messages:
        conn = conns.get(cid)
        if conn is not None:
            writer.write(conn, log_time, raw)
            counts[conn.topic] += 1
    for key, value in custom.items():
        writer.set_custom_data(key, value)
    writer.close()
    backup = mcap_path.with_name(mcap_path.name + ".orig") if keep_original else None
    if backup is not None:
        mcap_path.replace(backup)
    else:
        mcap_path.unlink()
    (new,) = tmp.glob("*.mcap")
    new.replace(mcap_path)
    meta_text = (tmp / "metadata.yaml").read_text(encoding="utf-8").replace(new.name, mcap_path.name)
    (bag / "metadata.yaml").write_text(meta_text, encoding="utf-8")
    shutil.rmtree(tmp, ignore_errors=True)
    return ReindexReport(bag, counts, found.chunks, found.partial, len(data) - found.end, backup)


def _salvaged_test_metadata(found: _Salvage) -> dict[str, str]:
    """The test's parameters from the latched ``/ema/test`` message, ``completed`` false (the run was cut)."""
    test = [cid for cid, ch in found.channels.items() if ch[0] == ct.TEST]
    for cid, _, data in found.messages:
        if cid in test:
            try:
                doc = json.loads(ts.deserialize(data, ct.STRING).data)
            except (ValueError, AttributeError, KeyError):
                continue
            out = {str(k): v if isinstance(v, str) else json.dumps(v) for k, v in doc.items()}
            return {**out, "completed": "false", "reindexed": "true"}
    return {"reindexed": "true"}
