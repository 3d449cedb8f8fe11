"""The EMAC node's input streams in lockstep: what a frame takes, and when it may go ahead."""

from ema_sim.nodes.emac import SourceStream, Stream

T = 5_000_000


def test_a_later_message_does_not_hold_back_an_earlier_one_from_another_publisher():
    s = Stream()
    s.push(2 * T, "a@2")  # one publisher is a frame ahead of another (DDS orders per writer only)
    s.push(1 * T, "b@1")
    assert s.take_until(1 * T) == [(1 * T, "b@1")]
    assert s.take_until(2 * T) == [(2 * T, "a@2")]
    assert s.take_until(3 * T) == []


def test_take_until_keeps_arrival_order_and_leaves_the_future():
    s = Stream()
    for k, tag in ((1, "x"), (1, "y"), (3, "z"), (2, "w")):
        s.push(k * T, tag)
    assert [tag for _, tag in s.take_until(2 * T)] == ["x", "y", "w"]
    assert [tag for _, tag in s.take_until(9 * T)] == ["z"]


def test_a_frame_waits_for_every_crosstalk_source():
    s = SourceStream()
    s.expected = frozenset({"left_wing", "cowl_door"})
    s.push_from(1 * T, [("left_wing", 0.1)])
    assert not s.reached(1 * T)  # the cowl door has not reported frame 1
    s.push_from(2 * T, [("left_wing", 0.2)])
    assert not s.reached(1 * T)
    s.push_from(1 * T, [("cowl_door", -0.3)])
    assert s.reached(1 * T)
    assert not s.reached(2 * T)
    assert [v for _, item in s.take_until(1 * T) for _, v in item] == [0.1, -0.3]


def test_without_known_sources_any_message_counts():
    s = SourceStream()
    s.push_from(4 * T, [("left_rudder", 0.0)])
    assert s.reached(4 * T)
