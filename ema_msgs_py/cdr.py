"""The per-frame messages as plain Python and their CDR bytes, fast and without ROS.

Every per-frame signal of the contract is a ``sensor_msgs/JointState``; the node suite handles it as a
:class:`JointFrame` (stamp, names and the three arrays as Python lists) and puts it on the wire as the
CDR bytes rmw_fastrtps would produce for the same message (XCDR1, little endian), so a node publishes
bytes and takes bytes (rclpy's ``publish(bytes)`` and ``raw=True`` subscriptions) and never builds an
rclpy message: measured here, that halves the CPU of a publish and of a take. :func:`decode` also
reads big-endian CDR (other middlewares). ``test_contract.py`` checks both directions against rclpy's
and rosbags' serializers byte for byte.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field
from functools import lru_cache

NS = 1_000_000_000
CDR_LE = b"\x00\x01\x00\x00"
"""Encapsulation header: plain CDR, little endian, no options."""
_HEAD = struct.Struct("<iI")


@dataclass(slots=True)
class JointFrame:
    """One ``sensor_msgs/JointState``: ``name`` lists channels; an empty array means "not measured"."""

    stamp_ns: int
    """Header stamp, ns: the FMU frame the values belong to."""
    name: list[str]
    """The channels (or states) the arrays list."""
    position: list[float] = field(default_factory=list)
    """One value per name, or empty."""
    velocity: list[float] = field(default_factory=list)
    """One value per name, or empty."""
    effort: list[float] = field(default_factory=list)
    """One value per name, or empty."""
    frame_id: str = ""
    """Header frame id (empty on the contract's messages)."""


def _string(out: bytearray, text: str) -> None:
    data = text.encode() + b"\x00"
    _align(out, 4)
    out += struct.pack("<I", len(data))
    out += data


def _align(out: bytearray, n: int) -> None:
    pad = (-(len(out) - 4)) % n  # alignment counts from the end of the encapsulation header
    out += b"\x00" * pad


@lru_cache(maxsize=256)
def _layout(frame_id: str, names: tuple[str, ...], counts: tuple[int, int, int]) -> tuple[struct.Struct, bytes]:
    """A struct for everything after the stamp: names as fixed bytes, then the three double arrays."""
    out = bytearray(CDR_LE + b"\x00" * 8)
    _string(out, frame_id)
    _align(out, 4)
    out += struct.pack("<I", len(names))
    for name in names:
        _string(out, name)
    prefix = bytes(out[12:])
    fmt = ["<", f"{len(prefix)}s"]
    offset = len(out) - 4
    for count in counts:
        pad = (-offset) % 4
        fmt.append(f"{pad}xI")
        offset += pad + 4
        if count:
            pad = (-offset) % 8
            fmt.append(f"{pad}x{count}d")
            offset += pad + 8 * count
    return struct.Struct("".join(fmt)), prefix


def encode(frame: JointFrame) -> bytes:
    """CDR bytes of a JointState, as rmw_fastrtps serializes it.

    Parameters
    ----------
    frame : JointFrame
        The message.

    Returns
    -------
    bytes
        Its XCDR1 little-endian serialization, encapsulation header first.
    """
    pos, vel, eff = frame.position, frame.velocity, frame.effort
    body, prefix = _layout(frame.frame_id, tuple(frame.name), (len(pos), len(vel), len(eff)))
    ns = frame.stamp_ns
    return CDR_LE + _HEAD.pack(ns // NS, ns % NS) + body.pack(prefix, len(pos), *pos, len(vel), *vel, len(eff), *eff)


def encode_clock(stamp_ns: int) -> bytes:
    """CDR bytes of a ``rosgraph_msgs/Clock``.

    Parameters
    ----------
    stamp_ns : int
        The clock's time, ns.

    Returns
    -------
    bytes
        The serialized message.
    """
    return CDR_LE + _HEAD.pack(stamp_ns // NS, stamp_ns % NS)


def stamp_ns(raw: bytes | memoryview) -> int | None:
    """The stamp at the start of a CDR message (Header, Clock, DiagnosticArray).

    Parameters
    ----------
    raw : bytes or memoryview
        The serialized message, either endianness.

    Returns
    -------
    int or None
        The stamp in ns; None when the message is too short to hold one.
    """
    if len(raw) < 12:
        return None
    sec: int
    nsec: int
    sec, nsec = struct.unpack_from("<iI" if raw[1] == 1 else ">iI", raw, 4)
    return sec * NS + nsec


def restamp(raw: bytes | memoryview, ns: int) -> bytes:
    """The message with its leading stamp (the first field, a ``builtin_interfaces/Time``) set to ``ns``.

    Parameters
    ----------
    raw : bytes or memoryview
        The serialized message, either endianness, starting with a stamp (``rcl_interfaces/Log``, a Header...).
    ns : int
        The new stamp, ns (≥ 0).

    Returns
    -------
    bytes
        The same message, restamped.

    Raises
    ------
    ValueError
        The message is too short to hold a stamp.
    """
    if len(raw) < 12:
        raise ValueError(f"a message of {len(raw)} bytes holds no stamp")
    out = bytearray(raw)
    struct.pack_into("<iI" if out[1] == 1 else ">iI", out, 4, ns // NS, ns % NS)
    return bytes(out)


_KNOWN: dict[int, list[tuple[bytes, struct.Struct, tuple[str, ...], str, tuple[int, int, int]]]] = {}
"""Layouts seen before, by message length: a publisher's names rarely change, so most takes are one
``startswith`` and one ``unpack_from``."""
_KNOWN_MAX = 512


def decode(raw: bytes | memoryview) -> JointFrame:
    """A JointFrame from the CDR bytes of a JointState (either endianness).

    Parameters
    ----------
    raw : bytes or memoryview
        The serialized message as a subscription takes it.

    Returns
    -------
    JointFrame
        The message.

    Raises
    ------
    ValueError
        The bytes are not a JointState (a node counts and drops the message: it never stops on one).
    """
    raw = bytes(raw)
    for prefix, body, names, frame_id, counts in _KNOWN.get(len(raw), ()):
        if raw[1] == 1 and raw.startswith(prefix, 12):
            v = body.unpack_from(raw, 12)
            a, b, c = counts
            if v[1] == a and v[2 + a] == b and v[3 + a + b] == c:
                sec, nsec = _HEAD.unpack_from(raw, 4)
                return JointFrame(sec * NS + nsec, list(names), list(v[2:2 + a]), list(v[3 + a:3 + a + b]),
                                  list(v[4 + a + b:]), frame_id)
    try:
        frame = _decode(raw)
    except (struct.error, UnicodeDecodeError, IndexError, ValueError) as exc:
        raise ValueError(f"malformed JointState ({exc})") from None
    if raw[1] == 1:
        counts = (len(frame.position), len(frame.velocity), len(frame.effort))
        body, prefix = _layout(frame.frame_id, tuple(frame.name), counts)
        if sum(len(v) for v in _KNOWN.values()) >= _KNOWN_MAX:
            _KNOWN.clear()
        _KNOWN.setdefault(len(raw), []).append((prefix, body, tuple(frame.name), frame.frame_id, counts))
    return frame


def _decode(raw: bytes) -> JointFrame:
    e = "<" if raw[1] == 1 else ">"
    u32 = struct.Struct(e + "I").unpack_from
    sec, nsec = struct.unpack_from(e + "iI", raw, 4)
    off = 12

    def string(off: int) -> tuple[str, int]:
        off += (-(off - 4)) % 4
        (n,) = u32(raw, off)
        if n == 0 or off + 4 + n > len(raw):
            raise ValueError("string out of bounds")
        return raw[off + 4:off + 3 + n].decode(), off + 4 + n

    frame_id, off = string(off)
    off += (-(off - 4)) % 4
    (count,) = u32(raw, off)
    off += 4
    if count > len(raw):
        raise ValueError("sequence out of bounds")
    names = []
    for _ in range(count):
        name, off = string(off)
        names.append(name)
    arrays = []
    for _ in range(3):
        off += (-(off - 4)) % 4
        (count,) = u32(raw, off)
        off += 4
        if count:
            off += (-(off - 4)) % 8
            if off + 8 * count > len(raw):
                raise ValueError("sequence out of bounds")
            arrays.append(list(struct.unpack_from(f"{e}{count}d", raw, off)))
            off += 8 * count
        else:
            arrays.append([])
    return JointFrame(sec * NS + nsec, names, arrays[0], arrays[1], arrays[2], frame_id)
