from pathlib import Path

import numpy as np
import pytest

from ema_msgs_py import CHANNELS, TOPICS, cdr, failure_topic
from ema_msgs_py import typestore as ts
from ema_sim.config import load_channel, parse_channel, ros_parameters, scaling
from ema_sim.nodes.params import merged, nested

ROOT = Path(__file__).resolve().parents[1]


def test_every_topic_is_on_the_contract_page():
    page = (ROOT / "ema_msgs_py" / "README.md").read_text()
    for name in TOPICS:
        assert f"`{name}`" in page, name
    assert "`/ema/emac/<channel>/failure`" in page
    assert failure_topic("left_wing") == "/ema/emac/left_wing/failure"


def test_fmu_and_emac_sides_are_distinct_topics_of_standard_types():
    assert {"/ema/fmu/command", "/ema/emac/command", "/ema/emac/feedback", "/ema/fmu/feedback"} <= set(TOPICS)
    for spec in TOPICS.values():
        assert spec.msgtype in ts.typestore().types
        assert spec.msgtype.split("/")[0] in {"sensor_msgs", "std_msgs", "rosgraph_msgs", "diagnostic_msgs"}
        if spec.per_frame:
            assert spec.qos.reliability == "reliable"


@pytest.mark.parametrize("channel", CHANNELS)
def test_scaling_matches_the_channel_calibration_and_full_scale(channel):
    sc, cfg = scaling(channel), load_channel(channel)
    deg = np.linspace(-40, 40, 17)
    assert [sc.command_deg_to_v(d) for d in deg] == pytest.approx(cfg.deg_to_v(deg), abs=1e-12)
    volts = np.linspace(-9.5, 9.5, 11)
    assert [sc.command_v_to_deg(v) for v in volts] == pytest.approx(cfg.command_v_to_deg(volts), abs=1e-9)
    assert [sc.feedback_v_to_deg(v) for v in volts] == pytest.approx(cfg.v_to_deg(volts), abs=1e-12)
    assert [sc.feedback_deg_to_v(d) for d in deg] == pytest.approx(cfg.position_deg_to_v(deg), abs=1e-9)
    assert sc.full_scale_v == 10.0
    assert sc.sign == cfg.command_cal.sign
    assert sc.volts_per_deg == pytest.approx(0.235, abs=0.001)


def test_inverse_relation_on_both_wings_and_the_left_rudder():
    assert {c: scaling(c).sign for c in CHANNELS} == {
        "left_wing": -1, "right_wing": -1, "left_rudder": -1, "right_rudder": 1, "cowl_door": 1}


def test_typestore_messages_round_trip_without_ros():
    msg = ts.joint_state(1_234_567_890_123, ["left_wing", "cowl_door"], [1.5, -2.5], [], [0.25, 0.5])
    back = ts.deserialize(ts.serialize(msg), "sensor_msgs/msg/JointState")
    assert ts.stamp_ns(back) == 1_234_567_890_123
    assert list(back.name) == ["left_wing", "cowl_door"]
    assert back.position.tolist() == [1.5, -2.5]
    assert back.velocity.size == 0
    assert ts.deserialize(ts.serialize(ts.string("x")), "std_msgs/msg/String").data == "x"


def test_console_scripts_are_the_node_names():
    text = (ROOT / "setup.py").read_text()
    for script, module in [("emac", "emac"), ("testenv", "testenv"), ("maneuver", "maneuver"),
                           ("simclock", "clock"), ("fmu_bridge", "bridge"), ("ema_container", "container")]:
        assert f'"{script} = ema_sim.nodes.{module}:main"' in text
        assert (ROOT / "ema_sim" / "nodes" / f"{module}.py").is_file()


def test_ros_parameters_merge_over_the_config_files():
    flat = {"second_order.zeta": 0.9, "crank_arm_in": 1.8}
    assert nested(flat) == {"second_order": {"zeta": 0.9}, "crank_arm_in": 1.8}
    base = ROOT / "config" / "left_wing.yaml"
    cfg = parse_channel(merged(ros_parameters(base), nested(flat)))
    assert cfg.section("second_order")["zeta"] == 0.9
    assert cfg.section("second_order")["wn_rad_s"] == 56.5  # untouched values come from the file
    assert cfg.crank_arm_in == 1.8


# --------------------------------------------------------------------------- CDR of the per-frame messages
FRAMES = [
    cdr.JointFrame(5_005_000_000, ["left_wing"], [0.1], [], []),
    cdr.JointFrame(1, list(CHANNELS), [0.1, -0.2, 0.3, 0.4, 9.5], [1.0] * 5, [2.0] * 5),
    cdr.JointFrame(123_456_789_012, ["a", "bb", "ccc"], [], [], [1.5, 2.5, 3.5]),
    cdr.JointFrame(0, [], [], [], []),
    cdr.JointFrame(7, ["xy"], [1.0], [], [2.0], frame_id="ab"),
    cdr.JointFrame(7, ["xy"], [], [1.0], [2.0], frame_id="ab"),  # same length and names, other arrays
]


@pytest.mark.parametrize("frame", FRAMES)
def test_joint_frames_are_the_cdr_bytes_of_rosbags_and_rclpy_reads_them(frame):
    from rclpy.serialization import deserialize_message, serialize_message  # noqa: PLC0415
    from sensor_msgs.msg import JointState  # noqa: PLC0415

    msg = ts.joint_state(frame.stamp_ns, frame.name, frame.position, frame.velocity, frame.effort)
    msg.header.frame_id = frame.frame_id
    raw = cdr.encode(frame)
    assert raw == ts.serialize(msg)  # byte for byte (rosbags zeroes the padding, as we do)
    back = deserialize_message(raw, JointState)
    assert (back.header.stamp.sec * 10**9 + back.header.stamp.nanosec, back.header.frame_id) == \
        (frame.stamp_ns, frame.frame_id)
    assert (list(back.name), list(back.position), list(back.velocity), list(back.effort)) == \
        (frame.name, frame.position, frame.velocity, frame.effort)
    for _ in range(2):  # first parse, then the cached layout
        assert cdr.decode(serialize_message(back)) == frame  # rclpy's bytes carry junk padding and a tail
        assert cdr.decode(raw) == frame
    big = bytes(ts.typestore().serialize_cdr(msg, msg.__msgtype__, little_endian=False))
    assert cdr.decode(big) == frame
    assert cdr.stamp_ns(raw) == frame.stamp_ns


def test_malformed_joint_state_bytes_are_one_value_error():
    raw = cdr.encode(FRAMES[1])
    for bad in (raw[:40], raw[:-8], b"\x00\x01\x00\x00" + b"\xff" * 40):
        with pytest.raises(ValueError, match="malformed JointState"):
            cdr.decode(bad)
    assert cdr.encode_clock(3_000_000_005) == ts.serialize(ts.clock(3_000_000_005))
