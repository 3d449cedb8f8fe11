"""Writing suite bags: :class:`BagWriter` (topics added on first use, raw CDR) and :func:`write_bag`."""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike
from rosbags.interfaces import Connection
from rosbags.rosbag2 import StoragePlugin, Writer, WriterError

from ema_msgs_py import contract as ct
from ema_msgs_py import typestore as ts
from ema_sim.config import scaling
from ema_sim.errors import DataError
from ema_sim.io.bag.storage import fast_storage

if TYPE_CHECKING:
    from rosbags.rosbag2.writer import StorageWriter


class BagWriter:
    """A rosbag2 (MCAP) bag being written; topics are added on first use.

    Parameters
    ----------
    path : str or Path
        The bag directory to create (must not exist).
    metadata : mapping, optional
        Test parameters for the bag's ``custom_data`` (strings, or values written as JSON).
    """

    def __init__(self, path: str | Path, metadata: Mapping[str, object] | None = None) -> None:
        class _Writer(Writer):
            STORAGE_PLUGINS: Mapping[StoragePlugin, type[StorageWriter]] = {
                **Writer.STORAGE_PLUGINS, StoragePlugin.MCAP: fast_storage()}

        self.path = Path(path)
        try:
            self._writer = _Writer(self.path, version=9, storage_plugin=StoragePlugin.MCAP)
            self._writer.open()
        except (WriterError, OSError) as exc:
            raise DataError(f"{self.path}: cannot create bag ({exc})") from None
        storage = self._writer.storage
        if storage is None:  # open() always sets it; narrows the type
            raise DataError(f"{self.path}: the bag writer opened no storage")
        self._storage = storage
        self._connections: dict[str, Connection] = {}
        self.counts: dict[str, int] = {}
        self._first_ns = 2**63 - 1
        self._last_ns = 0
        self.metadata: dict[str, str] = {}
        for key, value in (metadata or {}).items():
            self.set_metadata(key, value)
        self.closed = False

    def set_metadata(self, key: str, value: object) -> None:
        """A test parameter for the bag's ``custom_data`` (written at close).

        Parameters
        ----------
        key : str
            The parameter's name.
        value : object
            A string, kept as is, or any value, kept as its JSON text.
        """
        text = value if isinstance(value, str) else json.dumps(value)
        self.metadata[key] = text
        self._writer.set_custom_data(key, text)

    def add_topic(self, topic: str, msgtype: str, qos: ct.QosSpec | None = None) -> None:
        """Register a topic (its type's definition goes into the bag).

        Parameters
        ----------
        topic : str
            The topic's name.
        msgtype : str
            Its ROS message type (``sensor_msgs/msg/JointState``).
        qos : QosSpec, optional
            The offered QoS; by default the topic contract's, else the frame QoS.
        """
        if topic in self._connections:
            return
        spec = qos or (ct.TOPICS[topic].qos if topic in ct.TOPICS else ct.FRAME_QOS)
        self._connections[topic] = self._writer.add_connection(
            topic, msgtype, typestore=ts.typestore(), offered_qos_profiles=ts.qos_profiles(spec))
        self.counts[topic] = 0

    def write(self, topic: str, msgtype: str, log_time_ns: int, raw: bytes | memoryview) -> None:
        """One serialized message (straight into the open chunk: no copy, no parsing).

        Parameters
        ----------
        topic : str
            The topic (registered on first use).
        msgtype : str
            Its ROS message type.
        log_time_ns : int
            The record's log time, ns.
        raw : bytes or memoryview
            The CDR-serialized message.
        """
        conn = self._connections.get(topic)
        if conn is None:
            self.add_topic(topic, msgtype)
            conn = self._connections[topic]
        ns = int(log_time_ns)
        self._storage.write(conn, ns, raw)
        self.counts[topic] += 1
        self._first_ns = min(self._first_ns, ns)
        self._last_ns = max(self._last_ns, ns)

    def write_message(self, topic: str, log_time_ns: int, msg: ts.Message) -> None:
        """One typestore message.

        Parameters
        ----------
        topic : str
            The topic (registered on first use).
        log_time_ns : int
            The record's log time, ns.
        msg : Message
            A rosbags typestore message (its ``__msgtype__`` names the type).
        """
        self.write(topic, msg.__msgtype__, log_time_ns, ts.serialize(msg))

    def close(self) -> None:
        """Write the summary and ``metadata.yaml``; the bag is complete."""
        if not self.closed:
            self.closed = True
            w = self._writer
            for topic, conn in self._connections.items():  # the per-topic counts of metadata.yaml
                w.counts[conn.id] = self.counts[topic]
            w.min_timestamp, w.max_timestamp = self._first_ns, self._last_ns
            w.close()

    def __enter__(self) -> BagWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def write_bag(path: str | Path, columns: Mapping[str, ArrayLike], metadata: Mapping[str, object], *,
              channel: str, frame_hz: float | None = None) -> Path:
    """Write data-contract columns as a suite bag of one channel (both sides identical, no environment).

    ``columns`` has ``time_s`` and ``command_deg`` and optionally ``position_deg``, ``surface_deg``,
    ``hinge_moment_inlb``, ``current_a``. The calibration of ``config/<channel>.yaml`` makes the volts.

    Parameters
    ----------
    path : str or Path
        The bag directory to create.
    columns : mapping
        Data-contract columns (arrays of one length).
    metadata : mapping
        Test parameters for the bag's ``custom_data``.
    channel : str
        The channel the columns belong to (its calibration makes the volts).
    frame_hz : float, optional
        The frame rate recorded in the metadata.

    Returns
    -------
    Path
        The bag directory.
    """
    sc = scaling(channel)
    t = np.asarray(columns["time_s"], dtype=float)
    n = t.size
    cmd = np.asarray(columns["command_deg"], dtype=float)
    pos = np.asarray(columns.get("position_deg", columns.get("surface_deg")), dtype=float)
    surf = np.asarray(columns.get("surface_deg", pos), dtype=float)
    hm = np.asarray(columns.get("hinge_moment_inlb", np.zeros(n)), dtype=float)
    cur = columns.get("current_a")
    stamps = np.round(t * 1e9).astype(np.int64)
    meta = {"channel": channel, "channels": channel, "clock": "offline", "generator": "ema_sim.io.bag.write_bag",
            "frame_hz": f"{frame_hz:g}" if frame_hz else "", **{k: str(v) for k, v in metadata.items()}}
    meta[f"calibration.{channel}"] = json.dumps({"command_cal_v": list(sc.command),
                                                 "feedback_cal_deg": list(sc.feedback)})
    with BagWriter(path, meta) as bag:
        bag.write_message(ct.TEST, int(stamps[0]), ts.string(json.dumps(meta)))
        for k in range(n):
            ns = int(stamps[k])
            cv = sc.command_deg_to_v(float(cmd[k]))
            for topic in (ct.FMU_COMMAND, ct.EMAC_COMMAND):
                bag.write_message(topic, ns, ts.joint_state(ns, [channel], [cv]))
            pv = sc.feedback_deg_to_v(float(pos[k]))
            effort = [] if cur is None else [float(np.asarray(cur)[k])]
            for topic in (ct.EMAC_FEEDBACK, ct.FMU_FEEDBACK):
                bag.write_message(topic, ns, ts.joint_state(ns, [channel], [pv], [], effort))
            bag.write_message(ct.HINGE_MOMENT, ns, ts.joint_state(ns, [channel], [], [], [float(hm[k])]))
            applied = float(hm[k - 1]) if k else float(hm[0])
            bag.write_message(ct.SURFACE, ns, ts.joint_state(ns, [channel], [float(surf[k])], [], [applied]))
    return Path(path)
