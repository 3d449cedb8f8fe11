"""Real time: what a node process's set-up does, and how the maneuver node tells why a frame was missed."""

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from ema_sim.nodes import realtime
from ema_sim.nodes.common import DurationHistogram, percentile_ms
from ema_sim.nodes.frametimes import FrameTimes

PROBE = r"""
import json, os, sys
from ema_sim.nodes import realtime
from ema_sim.nodes.common import DurationHistogram, percentile_ms
setup = realtime.apply(int(sys.argv[1]))
status = dict(line.split(":", 1) for line in open("/proc/self/status") if ":" in line)
tasks = os.listdir("/proc/self/task")
print(json.dumps({
    "setup": setup.summary(),
    "fifo_threads": sum(os.sched_getscheduler(int(t)) == os.SCHED_FIFO for t in tasks),
    "threads": len(tasks),
    "priority": os.sched_getparam(0).sched_priority,
    "locked_kb": int(status["VmLck"].split()[0]),
    "latency_us": realtime.cpu_latency_request_us(),
}))
"""


def _probe(priority: int) -> dict:
    out = subprocess.run([sys.executable, "-c", PROBE, str(priority)], capture_output=True, text=True, check=True,
                         timeout=60, env=dict(os.environ, OPENBLAS_NUM_THREADS="2"))
    return json.loads(out.stdout)


def test_real_time_set_up_reports_what_is_in_force():
    got = _probe(20)
    setup = got["setup"]
    # What the set-up says it did is what the process has, whether or not this machine allows it.
    assert (setup["sched_fifo"] == 20) == (got["fifo_threads"] == got["threads"] and got["priority"] == 20)
    assert setup["memory_locked"] == (got["locked_kb"] > 0)
    if setup["cpu_latency_us"] is not None:
        assert got["latency_us"] == 0  # the request is in force while the process holds it
    refused = setup["sched_fifo"] != 20 or not setup["memory_locked"] or setup["cpu_latency_us"] is None
    assert bool(setup.get("notes")) == refused  # whatever was not done is said


def test_no_real_time_asked_changes_nothing():
    got = _probe(0)
    assert got["setup"] == {"sched_fifo": 0, "memory_locked": False, "cpu_latency_us": None}
    assert got["fifo_threads"] == 0
    assert got["locked_kb"] == 0


def test_an_impossible_priority_is_a_note_not_a_crash():
    got = _probe(1000)
    assert got["setup"]["sched_fifo"] == 0
    assert any("SCHED_FIFO 1000" in note for note in got["setup"]["notes"])
    assert got["fifo_threads"] == 0


@pytest.mark.skipif(realtime.steal_s() is None, reason="no /proc/stat")
def test_steal_time_is_a_count_of_seconds():
    first = realtime.steal_s()
    assert first is not None
    assert first >= 0.0
    assert realtime.steal_s() >= first


# --------------------------------------------------------------------------- why a frame was missed
PERIOD_S = 0.005


def _record(frames: list[tuple[float, float | None, float, float, int, int]], *,
            one_thread: bool = True) -> FrameTimes:
    """A run's record: per frame (sent, back, thread CPU at send, at back, waits and preemptions between)."""
    times = FrameTimes(len(frames) + 3, ["left_wing"], PERIOD_S, one_thread=one_thread)
    times.steal_s = [10.0, 10.5]
    for k, (sent, back, cpu0, cpu1, waits, preemptions) in enumerate(frames):
        times.thread_sent[k] = (cpu0, 7, 3)
        times.sent_at(sent)
        if back is not None:
            times.back[k, 0] = back
            times.thread_back[k] = (cpu1, 7 + waits, 3 + preemptions)
    return times


def test_missed_frames_are_told_apart_by_the_thread_s_cpu_and_waits():
    times = _record([
        (0.000, 0.0006, 1.0, 1.0005, 0, 0),  # on time
        (0.005, 0.0160, 2.0, 2.0005, 0, 0),  # 11 ms late, 0.5 ms of CPU, no switch at all: the CPU was held
        (0.010, 0.0170, 3.0, 3.0065, 0, 1),  # 7 ms, 6.5 ms of CPU: the suite was busy
        (0.015, 0.0260, 4.0, 4.0010, 1, 1),  # 11 ms, gave the CPU up: the suite waited
        (0.020, None, 5.0, 0.0, 0, 0),       # never answered
        (0.025, 0.0298, 6.0, 6.0010, 0, 0),  # 4.8 ms: on time
        (0.030, 0.0400, 7.0, 7.0010, 0, 2),  # 10 ms, preempted twice
    ])
    got = times.summary()
    assert got["frames"] == 7  # the frames sent, not the room made for the run
    assert got["answered"] == 6
    assert got["missed_frames"] == 5
    assert (got["missed_cpu_held"], got["missed_suite_busy"], got["missed_suite_waited"], got["missed_preempted"],
            got["missed_unanswered"]) == (1, 1, 1, 1, 1)
    assert got["machine_steal_s"] == 0.5
    assert got["latency_max_ms"] == pytest.approx(11.0)
    assert got["latency_p50_ms"] == pytest.approx(7.0)


def test_across_processes_no_cause_is_claimed():
    got = _record([(0.0, 0.012, 1.0, 1.0, 0, 0)], one_thread=False).summary()
    assert got["missed_frames"] == 1
    assert not any(key.startswith("missed_") and key != "missed_frames" for key in got)


def test_feedback_counts_once_per_channel_and_only_for_frames_sent():
    times = FrameTimes(4, ["left_wing", "right_wing"], PERIOD_S, one_thread=False)
    times.sent_at(1.000)
    times.feedback(0, ["left_wing"], 1.001)
    times.feedback(0, ["left_wing", "cowl_door"], 1.009)  # a repeat and an unexpected channel: ignored
    times.feedback(1, ["left_wing"], 1.002)  # frame 1 was not sent yet
    assert times.summary()["answered"] == 0  # the right wing has not reported
    times.feedback(0, ["right_wing"], 1.003)
    got = times.summary()
    assert got["answered"] == 1
    assert got["latency_max_ms"] == pytest.approx(3.0)
    assert np.isnan(times.back[1]).all()


def test_duration_histogram_gives_the_percentiles_of_the_samples_to_its_bin():
    rng = np.random.default_rng(4)
    samples = np.concatenate([rng.gamma(4.0, 1.5e-4, 20_000), [0.0123, 2.5]])  # one past the last bin
    hist = DurationHistogram()
    for s in samples:
        hist.add(float(s))
    for q in (50, 90, 99, 99.9):
        exact = percentile_ms(samples.tolist(), q)
        assert exact <= hist.percentile_ms(q) <= exact + DurationHistogram.BIN_S * 1e3
    assert hist.percentile_ms(100) == 2500.0
    assert hist.n == len(samples)
    assert np.isnan(DurationHistogram().percentile_ms(50))
