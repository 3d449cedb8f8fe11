"""Several frames a message (``--frames-per-message``): the batched form, the batching publisher, the run's checks,
and a batched lockstep run recording the frames of an unbatched one, byte for byte."""

import os

import pytest

from ema_msgs_py import batch, cdr
from ema_msgs_py import contract as ct
from ema_sim.errors import EmaError
from ema_sim.nodes.ports import BatchingPublisher, Ports
from ema_sim.run import RunDescription

STEP = 5_000_000


def frames(n, start=0, names=("left_wing", "right_wing"), frame_id="", effort=True):
    return [cdr.JointFrame(start + i * STEP, list(names), [0.1 * i + 1e-17, -2.0 / 3.0], [],
                           [float(i), 1e300] if effort else [], frame_id) for i in range(n)]


def test_a_batch_gives_back_each_frame_and_its_bytes_exactly():
    sent = frames(7, start=3 * STEP, frame_id="left_wing")
    raw = cdr.encode(batch.join(sent))
    assert batch.is_batch(raw)
    assert batch.split(cdr.decode(raw)) == sent
    assert batch.split_raw(raw) == [cdr.encode(f) for f in sent]
    assert not batch.is_batch(cdr.encode(sent[0]))
    assert batch.join(sent[:1]) == sent[0]  # one frame: sent as itself


@pytest.mark.parametrize("bad", [
    frames(2) + frames(1, start=5 * STEP),  # a stamp off the step
    frames(1) + frames(1, start=STEP, names=("left_wing",)),  # another layout
    frames(1) + frames(1, start=STEP, effort=False),
])
def test_frames_that_cannot_share_a_batch_are_refused(bad):
    with pytest.raises(ValueError, match="a batch takes frames of one layout"):
        batch.join(bad)


def test_a_malformed_batch_is_one_clear_error():
    joined = batch.join(frames(3))
    joined.position.pop()  # not a whole number of frames
    with pytest.raises(ValueError, match="malformed batch"):
        batch.split(joined)
    with pytest.raises(ValueError, match="malformed batch frame_id"):
        batch.split(cdr.JointFrame(0, ["x"], [1.0], frame_id=f"{batch.PREFIX}two:5"))


class FakeNode:
    """What a publisher needs of a node: its DDS publishers, here lists of the bytes each sent."""

    def __init__(self):
        self.sent = []

    def create_publisher(self, _type, _topic, _profile):
        node = self

        class Out:
            def publish(self, raw):
                node.sent.append(raw)

        return Out()


def test_the_frames_of_one_turn_go_out_as_one_message_at_the_flush():
    node = FakeNode()
    ports = Ports.__new__(Ports)
    ports.node, ports.frames_per_message, ports._held = node, 4, []
    pub = ports.frame_publisher(ct.EMAC_FEEDBACK)
    assert isinstance(pub, BatchingPublisher)
    sent = frames(6)
    for f in sent[:3]:
        pub.publish(f)
    assert node.sent == []  # held until the turn ends
    ports.flush()
    assert [cdr.decode(r) for r in node.sent] == [batch.join(sent[:3])]
    node.sent.clear()
    for f in [*sent[3:], *frames(1, start=20 * STEP)]:  # a stamp off the step: what is held goes first
        pub.publish(f)
    ports.flush()
    assert [batch.split(cdr.decode(r)) for r in node.sent] == [sent[3:], frames(1, start=20 * STEP)]
    node.sent.clear()
    for f in frames(9):  # at most four frames a message
        pub.publish(f)
    ports.flush()
    assert [len(batch.split(cdr.decode(r))) for r in node.sent] == [4, 4, 1]
    assert node.sent[-1] == cdr.encode(frames(9)[-1])  # one frame alone: the per-frame message


@pytest.mark.parametrize(("change", "needs"), [
    ({"lockstep": False}, "needs lockstep"),
    ({"layout": "single"}, "needs --layout processes"),
    ({"frames_per_message": 1001}, "needs a number of frames from 1 to 1000"),
])
def test_a_run_refuses_batches_where_they_cannot_hold(change, needs):
    run = {"bag": None, "maneuver": "step", "lockstep": True, "layout": "processes", "frames_per_message": 8,
           **change}
    with pytest.raises(EmaError, match=f"--frames-per-message {run['frames_per_message']} {needs}"):
        RunDescription(**run)


def test_a_closed_loop_fmu_is_refused_batches():
    with pytest.raises(EmaError, match="FMU closes its loop every frame"):
        RunDescription(bag=None, fmu=True, duration_s=1.0, lockstep=True, layout="processes", frames_per_message=8)


def test_every_node_of_a_batched_run_is_given_the_option():
    run = RunDescription(bag=None, maneuver="step", lockstep=True, layout="processes", emac="channels",
                         frames_per_message=8)
    params = run.parameters()
    assert {name: p.get("frames_per_message") for name, p in params.items()} == dict.fromkeys(params, 8)
    assert "frames_per_message" not in RunDescription(bag=None, maneuver="step", lockstep=True).parameters()["simclock"]


@pytest.mark.ros
def test_a_batched_lockstep_run_records_the_frames_of_an_unbatched_one(tmp_path):
    """The processes layout, the AIL test environment (noise, delays, lags) and crosstalk: every per-frame topic
    of the bag is the same bytes at the same log times; only ``/clock`` has one message a grant."""
    from ema_sim.io.bag.reader import _open  # noqa: PLC0415 - the raw messages
    from ema_sim.suite import SuiteConfig, free_domain_id, run_suite  # noqa: PLC0415

    runs = {}
    for k in (1, 16):
        cfg = SuiteConfig(bag=tmp_path / f"k{k}", model="loada", profile="ail", channels=["left_wing", "right_wing"],
                          maneuver="steps:amps_deg=1/5,lead_s=0.1,hold_s=0.3", load="sine:amp_inlb=300,freq_hz=1",
                          lockstep=True, layout="processes", emac="channels", frames_per_message=k,
                          domain_id=free_domain_id(os.getpid() + 241 + k))
        summaries = run_suite(cfg, timeout_s=300)
        assert summaries["simclock"]["stalls"] == 0
        assert all(s.get("waits_given_up", 0) == 0 for s in summaries.values())
        src = _open(cfg.bag_dir)
        epoch = int(src.metadata["sim_epoch_ns"])
        runs[k] = {t: sorted((log - epoch, raw) for _, log, raw in src.messages({t}))
                   for t, spec in ct.TOPICS.items() if spec.per_frame or t == ct.CLOCK_TOPIC}
    frames_run = len(runs[1][ct.FMU_COMMAND])
    assert frames_run > 100
    for topic, got in runs[1].items():
        if topic != ct.CLOCK_TOPIC:
            assert runs[16][topic] == got, topic
    assert len(runs[1][ct.EMAC_FEEDBACK]) == 5 * (frames_run + 1)
    assert len(runs[16][ct.CLOCK_TOPIC]) == 1 + -(-frames_run // 16)  # the first frame, then a grant of 16
