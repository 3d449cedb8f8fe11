import json
import shutil

import numpy as np
import pytest

from ema_sim.errors import DataError
from ema_sim.io import is_bag, load_data
from ema_sim.io.bag import METADATA_KEYS, bag_channels, bag_info, read_bag, write_bag
from ema_sim.io.csv import write_csv
from ema_sim.signals import parse_load, parse_maneuver
from ema_sim.simulation import csv_columns, simulate


def simulated(maneuver="step:amp_deg=2", load="sine:amp_inlb=300,freq_hz=0.5", channel="right_rudder"):
    model, record, meta = simulate("loada", parse_maneuver(maneuver), parse_load(load), channel=channel,
                                   sample_hz=200.0)
    meta = {**meta, "test": "steps", "profile": "none"}
    return csv_columns(model, record), meta


@pytest.fixture(scope="module")
def bag(tmp_path_factory):
    cols, meta = simulated()
    path = tmp_path_factory.mktemp("bags") / "step"
    write_bag(path, cols, meta, channel="right_rudder")
    return path, cols


def test_a_bag_reads_back_in_degrees_with_its_test_metadata(bag):
    path, cols = bag
    data = read_bag(path)
    assert len(data) == cols["time_s"].size
    assert data.time_s == pytest.approx(cols["time_s"] - cols["time_s"][0], abs=1e-9)
    for name in ("command_deg", "position_deg", "surface_deg", "hinge_moment_inlb"):
        assert getattr(data, name) == pytest.approx(cols[name], abs=1e-9), name
    assert data.command_v == pytest.approx(cols["command_v"], abs=1e-12)
    assert data.current_a is None  # LOADA has no motor: no current column, rather than an invented one
    for key in METADATA_KEYS:
        assert data.metadata[key], key
    assert data.metadata["maneuver"].startswith("step:amp_deg=2")
    assert data.metadata["channel"] == "right_rudder"
    assert data.metadata["bag_complete"] == "true"


def test_bag_info_lists_channels_topics_and_duration(bag):
    path, cols = bag
    info = bag_info(path)
    assert info.channels == ["right_rudder"] == bag_channels(path)
    assert info.topics["/ema/emac/feedback"] == ("sensor_msgs/msg/JointState", cols["time_s"].size)
    assert info.duration_s == pytest.approx(cols["time_s"][-1] - cols["time_s"][0])
    assert info.complete


def test_load_data_dispatches_csv_and_bags(tmp_path, bag):
    path, cols = bag
    csv = tmp_path / "x.csv"
    write_csv(csv, cols, {"channel": "right_rudder"})
    assert is_bag(path)
    assert not is_bag(csv)
    a, b = load_data(csv), load_data(path)
    assert a.position_deg == pytest.approx(b.position_deg, abs=1e-6)
    mcap = next(path.glob("*.mcap"))
    assert len(load_data(mcap)) == len(b)
    assert len(load_data(path, "right_rudder")) == len(b)
    with pytest.raises(DataError, match="holds channel 'right_rudder', not 'left_wing'"):
        load_data(csv, "left_wing")
    with pytest.raises(DataError, match="channel 'left_wing' has no data; channels: right_rudder"):
        load_data(path, "left_wing")


def test_a_bag_without_metadata_yaml_is_read_from_its_mcap(tmp_path, bag):
    path, cols = bag
    copy = tmp_path / "copy"
    shutil.copytree(path, copy)
    (copy / "metadata.yaml").unlink()
    data = read_bag(copy)
    assert data.position_deg == pytest.approx(cols["position_deg"], abs=1e-9)
    assert data.metadata["test"] == "steps"


def test_a_bag_cut_short_keeps_every_complete_chunk(tmp_path):
    cols, meta = simulated("sweep:f0_hz=0.2,f1_hz=5,sweep_s=58", "none", "left_wing")
    path = tmp_path / "long"
    write_bag(path, cols, meta, channel="left_wing")
    (path / "metadata.yaml").unlink()
    mcap = next(path.glob("*.mcap"))
    raw = mcap.read_bytes()
    mcap.write_bytes(raw[: int(len(raw) * 0.7)])  # the writer died mid-file
    data = read_bag(path)
    assert 100 < len(data) < cols["time_s"].size
    n = len(data)
    assert data.position_deg == pytest.approx(cols["position_deg"][:n], abs=1e-9)
    assert data.metadata["bag_complete"] == "false"


def test_fmu_side_reads_what_the_flight_computer_saw(bag):
    path, cols = bag
    data = read_bag(path, side="fmu")
    assert data.metadata["side"] == "fmu"
    assert data.position_deg == pytest.approx(cols["position_deg"], abs=1e-9)
    with pytest.raises(DataError, match="side must be one of"):
        read_bag(path, side="vehicle")


@pytest.mark.parametrize(("make", "message"), [
    (lambda _: None, "no such bag"),
    (lambda p: p.mkdir(), "not a rosbag2 bag"),
    (lambda p: (p.mkdir(), (p / "x.mcap").write_bytes(b"not an mcap at all")), "no readable message"),
    (lambda p: (p.mkdir(), (p / "metadata.yaml").write_text("rosbag2_bagfile_information: 3\n")), "unreadable bag"),
    (lambda p: p.write_text("a,b\n1,2\n"), "not a rosbag2 bag"),
])
def test_malformed_bags_are_one_clear_line(tmp_path, make, message):
    path = tmp_path / "bad"
    make(path)
    with pytest.raises(DataError, match=message) as err:
        read_bag(path)
    assert "\n" not in str(err.value)


def test_too_short_a_bag_is_refused_like_a_short_csv(tmp_path):
    cols, meta = simulated("step:amp_deg=1,lead_s=0.1,hold_s=0.1,back=false")
    short = {k: v[:50] for k, v in cols.items()}
    path = tmp_path / "short"
    write_bag(path, short, meta, channel="right_rudder")
    with pytest.raises(DataError, match=r"\d+ frames .* at least 100"):
        read_bag(path)


def test_calibration_recorded_in_the_bag_is_the_one_used(bag):
    path, cols = bag
    data = read_bag(path)
    info = bag_info(path)
    cal = json.loads(info.metadata["calibration.right_rudder"])
    volts = np.polynomial.polynomial.polyval(cols["command_deg"], cal["command_cal_v"])
    assert data.command_v == pytest.approx(volts, abs=1e-12)


def test_the_lean_mcap_writer_makes_the_bag_rosbags_writer_makes(tmp_path):
    """Several chunks, several topics, out-of-order log times: both readers see rosbags' own bag."""
    from mcap.reader import make_reader  # noqa: PLC0415
    from rosbags.rosbag2 import Reader, StoragePlugin, Writer  # noqa: PLC0415

    from ema_msgs_py import contract as ct  # noqa: PLC0415
    from ema_msgs_py import typestore as ts  # noqa: PLC0415
    from ema_sim.io.bag import BagWriter  # noqa: PLC0415

    topics = [ct.FMU_COMMAND, ct.EMAC_FEEDBACK, ct.SURFACE]
    rng = np.random.default_rng(5)
    rows = []
    for k in range(6000):  # ≈ 0.8 MB: four chunks of 256 KiB
        topic = topics[k % 3]
        stamp = k * 1_000_000 + int(rng.integers(-3, 3)) * 1_000_000
        raw = ts.serialize(ts.joint_state(stamp, ["left_wing", "right_wing"], rng.normal(size=2), [], [1.0, 2.0]))
        rows.append((topic, stamp, raw))
    ours = BagWriter(tmp_path / "ours", {"test": "steps"})
    theirs = Writer(tmp_path / "theirs", version=9, storage_plugin=StoragePlugin.MCAP)
    theirs.open()
    conns = {t: theirs.add_connection(t, ct.JOINT_STATE, typestore=ts.typestore(),
                                      offered_qos_profiles=ts.qos_profiles(ct.FRAME_QOS)) for t in topics}
    theirs.set_custom_data("test", "steps")
    for topic, stamp, raw in rows:
        ours.write(topic, ct.JOINT_STATE, stamp, raw)
        theirs.write(conns[topic], stamp, raw)
    ours.close()
    theirs.close()

    def content(path):
        with Reader(path) as reader:
            msgs = sorted((c.topic, t, bytes(r)) for c, t, r in reader.messages())
            meta = (reader.duration, reader.start_time, reader.message_count,
                    {c.topic: c.msgcount for c in reader.connections},
                    (path / "metadata.yaml").read_text().count("test: steps"))
        with next(path.glob("*.mcap")).open("rb") as fh:  # the summary and the chunk and message indexes
            mcap = make_reader(fh)
            indexed = sorted((ch.topic, m.log_time, bytes(m.data)) for _, ch, m in mcap.iter_messages())
            chunks = len(mcap.get_summary().chunk_indexes)
        return msgs, meta, indexed, chunks

    mine, want = content(tmp_path / "ours"), content(tmp_path / "theirs")
    assert mine[:3] == want[:3]
    assert mine[0] == sorted(rows)
    assert mine[3] >= 4
