"""Rosbags' MCAP storage writer with a lean message path: the one place that builds on rosbags' internals.

Every other module of :mod:`ema_sim.io.bag` uses rosbags' public API; this one subclasses its MCAP
writer (:func:`fast_storage`), so a rosbags upgrade that moves those internals breaks here only.
"""

from __future__ import annotations

import array
import queue
import struct
import sys
import threading
from collections import defaultdict
from io import BytesIO
from pathlib import Path
from typing import TYPE_CHECKING, BinaryIO

if TYPE_CHECKING:
    from rosbags.interfaces import Connection
    from rosbags.rosbag2.enums import CompressionMode
    from rosbags.rosbag2.storage_mcap import McapWriter

CHUNK_BYTES = 256 * 1024
"""Messages per MCAP chunk, in bytes: small enough that closing one takes well under a frame."""
_MESSAGE = struct.Struct("<BQHIQQ")
"""MCAP Message record header: opcode, record length, channel, sequence, log time, publish time."""


def fast_storage() -> type[McapWriter]:
    """Rosbags' MCAP storage writer with a lean message path (same file layout, same records).

    rosbags writes each message through small ``BytesIO`` records and builds each chunk's message
    index in a Python loop per message: 10 µs a message and a 22 ms stall per 1 MiB chunk, measured
    here. This writes the record header with one ``struct`` call into the chunk and keeps the index
    as arrays of ``(log time, offset)``, written in one piece when the chunk closes (1.4 µs a message).
    The file itself is written by a thread (:class:`_BackgroundFile`): page-cache writes here stall
    up to 4 ms now and then, which must not hold up a node's frame.
    """
    # rosbags' private MCAP internals, loaded only when a bag is written, and kept to this one file
    from rosbags.rosbag2.storage_mcap import McapWriter, PendingChunk, write_record, write_string  # noqa: PLC0415
    from rosbags.rosbag2.storage_mcap import write_uint32 as u32  # noqa: PLC0415
    from rosbags.rosbag2.storage_mcap import write_uint64 as u64  # noqa: PLC0415

    class FastMcapWriter(McapWriter):
        def __init__(self, path: Path, compression: CompressionMode) -> None:
            super().__init__(path, compression)
            self.bio = _BackgroundFile(self.bio)  # type: ignore[assignment]  # duck-typed file
            self._index: dict[int, array.array[int]] = {}
            self._times: list[int] = []

        def write(self, connection: Connection, timestamp: int, data: bytes | memoryview) -> None:
            bio = self.chunk.bio
            cid = connection.id
            index = self._index.get(cid)
            if index is None:
                index = self._index[cid] = array.array("Q")
            index.append(timestamp)
            index.append(bio.tell())
            self._times.append(timestamp)
            self.channel_stats[cid] += 1
            bio.write(_MESSAGE.pack(0x05, 22 + len(data), cid, 0, timestamp, timestamp))
            bio.write(data)
            if bio.tell() > CHUNK_BYTES:
                self.close_chunk()

        def close_chunk(self) -> None:
            times = self._times
            start, end = (min(times), max(times)) if times else (self.chunk.message_start_time, 0)
            self.message_start_time = min(self.message_start_time, start)
            self.message_end_time = max(self.message_end_time, end)
            payload = self.chunk.bio.getbuffer()
            rec = BytesIO()
            u64(rec, start)
            u64(rec, end)
            u64(rec, len(payload))
            u32(rec, 0)
            write_string(rec, "")
            u64(rec, len(payload))
            rec.write(payload)
            del payload
            chunk_start = self.bio.tell()
            write_record(self.bio, 0x06, rec)
            chunk_end = self.bio.tell()
            offsets: list[tuple[int, int]] = []
            for cid, index in self._index.items():
                offsets.append((cid, self.bio.tell()))
                body = index.tobytes() if sys.byteorder == "little" else _swapped(index)
                self.bio.write(struct.pack("<BQHI", 0x07, 6 + len(body), cid, len(body)))
                self.bio.write(body)
            rec = BytesIO()
            u64(rec, start)
            u64(rec, end)
            u64(rec, chunk_start)
            u64(rec, chunk_end - chunk_start)
            u32(rec, len(offsets) * 10)
            for cid, offset in offsets:
                rec.write(struct.pack("<HQ", cid, offset))
            u64(rec, self.bio.tell() - chunk_end)
            write_string(rec, "")
            u64(rec, self.chunk.bio.tell())
            u64(rec, self.chunk.bio.tell())
            self.chunks.append(rec)
            self.chunk = PendingChunk(2**63 - 1, 0, BytesIO(), defaultdict(list))
            self._index = {}
            self._times = []

        def abort(self) -> None:
            self.bio.close()

    return FastMcapWriter


class _BackgroundFile:
    """A file written by a thread: ``write`` queues the bytes and returns at once, ``tell`` is logical.

    The records keep their order (one writer thread); ``close`` drains the queue, so a bag closed on
    SIGINT or SIGTERM has every message written before it.
    """

    def __init__(self, fh: BinaryIO) -> None:
        self._fh = fh
        self._pos = int(fh.tell())
        self._queue: queue.SimpleQueue[bytes | None] = queue.SimpleQueue()
        self._failed: BaseException | None = None
        self._thread = threading.Thread(target=self._run, name="bag-writer", daemon=True)
        self._thread.start()

    def write(self, data: bytes | memoryview) -> int:
        if self._failed is not None:
            raise OSError(f"writing the bag failed: {self._failed}")
        chunk = bytes(data)
        self._queue.put(chunk)
        self._pos += len(chunk)
        return len(chunk)

    def tell(self) -> int:
        return self._pos

    def close(self) -> None:
        if self._thread.is_alive():
            self._queue.put(None)
            self._thread.join()
        self._fh.close()
        if self._failed is not None:
            raise OSError(f"writing the bag failed: {self._failed}")

    def _run(self) -> None:
        while (item := self._queue.get()) is not None:
            try:
                self._fh.write(item)
                if self._queue.empty():
                    self._fh.flush()
            except OSError as exc:
                self._failed = exc


def _swapped(index: array.array[int]) -> bytes:
    copy = array.array("Q", index)
    copy.byteswap()
    return copy.tobytes()
