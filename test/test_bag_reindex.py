"""``ema bag reindex``: a bag whose writer was SIGKILLed mid-chunk is readable by mcap and rosbags again."""

import os
import signal
import struct
import subprocess
import sys
import time
from pathlib import Path

import pytest
from mcap.reader import make_reader
from rosbags.rosbag2 import Reader

from ema_sim.cli import main as ema

WRITER = """
import sys, time
from ema_sim.io.bag import storage, writer
from ema_msgs_py import typestore as ts, contract as ct

def slow(self):  # a slow disk: a chunk reaches the file 4 KiB at a time
    while (item := self._queue.get()) is not None:
        for i in range(0, len(item), 4096):
            self._fh.write(item[i:i + 4096])
            self._fh.flush()
            if len(item) > 100_000:
                time.sleep(0.01)

storage._BackgroundFile._run = slow
w = writer.BagWriter(sys.argv[1], {"test": "killed"})
w.write_message(ct.TEST, 0, ts.string('{"test": "killed", "channel": "left_wing", "model": "loada"}'))
n = 0
while True:
    ns = n * 5_000_000
    w.write_message(ct.EMAC_FEEDBACK, ns, ts.joint_state(ns, ["left_wing"], [float(n)]))
    n += 1
    if n % 2000 == 0:
        time.sleep(0.05)
"""


def complete_messages(data):
    """An MCAP file's complete message records, walked by hand: (channel id, payload) in file order."""
    out, at = [], 8
    while at + 9 <= len(data):
        op, length = data[at], struct.unpack_from("<Q", data, at + 1)[0]
        body = data[at + 9:at + 9 + length]
        if op == 0x06:  # a chunk: its records, complete or cut short (uncompressed)
            (n,) = struct.unpack_from("<I", body, 28)
            inner = body[28 + 4 + n + 8:]
            k = 0
            while k + 9 <= len(inner):
                iop, ilen = inner[k], struct.unpack_from("<Q", inner, k + 1)[0]
                if k + 9 + ilen > len(inner):
                    break
                if iop == 0x05:
                    out.append((struct.unpack_from("<H", inner, k + 9)[0], bytes(inner[k + 9 + 22:k + 9 + ilen])))
                k += 9 + ilen
        if at + 9 + length > len(data):
            break
        at += 9 + length
    return out


@pytest.fixture
def killed_bag(tmp_path):
    bag = tmp_path / "killed"
    proc = subprocess.Popen([sys.executable, "-c", WRITER, str(bag)], env=dict(os.environ, PYTHONUNBUFFERED="1"))
    mcap = bag / "killed.mcap"
    deadline = time.monotonic() + 60
    while not (mcap.is_file() and mcap.stat().st_size > 650_000) and time.monotonic() < deadline:
        time.sleep(0.01)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    return bag


def test_reindex_makes_a_killed_bag_readable_and_loses_no_complete_record(killed_bag, capsys):
    mcap = killed_bag / "killed.mcap"
    data = mcap.read_bytes()
    written = complete_messages(data)
    test_channel = written[0][0]  # /ema/test is written first
    feedback = [p for c, p in written if c != test_channel]  # the JointStates, in the order written
    assert len(feedback) > 5000
    assert not (killed_bag / "metadata.yaml").exists()
    with pytest.raises(Exception):  # noqa: B017, PT011  (rosbags: no metadata.yaml)
        Reader(killed_bag).open()
    with mcap.open("rb") as fh, pytest.raises(Exception):  # noqa: B017, PT011  (mcap: no footer, no summary)
        list(make_reader(fh).iter_messages())

    assert ema(["bag", "reindex", str(killed_bag)]) == 0
    out = capsys.readouterr().out
    assert f"{len(written)} messages on 2 topics" in out
    assert "from the chunk cut short" in out  # it was killed mid-chunk

    with mcap.open("rb") as fh:
        reader = make_reader(fh)
        got = [m.data for _, c, m in reader.iter_messages() if c.topic == "/ema/emac/feedback"]
        assert reader.get_summary().statistics.message_count == len(written)
    assert got == feedback  # every complete record, in order
    with Reader(killed_bag) as reader:
        counts = {c.topic: c.msgcount for c in reader.connections}
        assert sum(1 for _ in reader.messages()) == len(written)
    assert counts == {"/ema/test": 1, "/ema/emac/feedback": len(feedback)}
    assert (killed_bag / "killed.mcap.orig").read_bytes() == data  # the original is kept
    from ema_sim.io.bag import bag_info  # noqa: PLC0415

    info = bag_info(killed_bag)
    assert info.complete
    assert info.metadata["completed"] == "false"
    assert info.metadata["model"] == "loada"


def test_reindex_of_a_bag_that_is_no_bag_is_one_line(tmp_path, capsys):
    (tmp_path / "junk").mkdir()
    (tmp_path / "junk" / "junk.mcap").write_bytes(b"not an mcap at all")
    assert ema(["bag", "reindex", str(tmp_path / "junk")]) == 2
    err = capsys.readouterr().err
    assert "not an MCAP file" in err
    assert len(err.strip().splitlines()) == 1
    assert Path(tmp_path / "junk" / "junk.mcap").read_bytes() == b"not an mcap at all"
