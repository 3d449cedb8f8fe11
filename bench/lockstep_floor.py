"""The middleware's floor under the ``processes`` layout in lockstep, with K frames to a message.

Eight bare rclpy processes (EventsExecutor, raw CDR, the contract's QoS) pass the lockstep frame as the
``processes`` layout does, five channels, as fast as they can: the clock grants a frame on ``/clock`` (to
the seven others) once every EMAC's feedback of the frame before is in; the FMU answers the grant with the
hinge moment and the command and records every other per-frame topic (taken at the frame); the test
environment relays the command once and each channel's feedback; each EMAC answers its command with its
feedback, surface and bus messages (the hinge moment taken at the frame; the right wing also takes the
others' feedback, its crosstalk sources). No model, no test environment's filters, no bag: rclpy's and
Fast DDS's cost of moving the frame. With ``K`` frames to a message the clock grants K frames at once and
every message carries K frames' values (a ``JointState`` of K times the names): the messages a simulated
frame costs fall K-fold. What is measured: wall and CPU time (summed over the eight processes) a simulated
frame, and the real-time factor the messaging alone would allow.

Run as a process: ``python bench/lockstep_floor.py ROLE FRAMES K``.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from typing import Any

import rclpy
from rclpy.experimental.events_executor import EventsExecutor
from rclpy.serialization import serialize_message
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState

from ema_msgs_py import cdr
from ema_msgs_py import contract as ct
from ema_msgs_py.ros import qos
from ema_sim import config
from ema_sim.benchmark import Benchmark, Result
from ema_sim.nodes.common import SuiteNode
from ema_sim.suite import free_domain_id

CHANNELS = list(config.CHANNELS)
ROLES = ["clock", "testenv", *(f"emac_{ch}" for ch in CHANNELS), "fmu"]
SHORT = os.environ.get("EMA_BENCH_SHORT", "") not in ("", "0")
FRAMES = int(os.environ.get("EMA_BENCH_FLOOR_FRAMES", "2000" if SHORT else "6000"))
BATCHES = (1, 4, 16, 50)
FRAME_NS = 5_000_000


def _role(role: str, frames: int, k: int) -> dict[str, Any]:  # noqa: PLR0912, PLR0915 (one process: its whole part)
    """One process of the pattern until the clock's last grant; its CPU and wall time from the first grant."""
    rclpy.init()
    node = SuiteNode(f"floor_{role}")
    executor = EventsExecutor()
    executor.add_node(node)
    profile = qos(ct.FRAME_QOS)
    every = serialize_message(JointState(name=CHANNELS * k, position=[0.1] * 5 * k, effort=[0.2] * 5 * k))
    one = serialize_message(JointState(name=[role] * k, position=[0.1] * k, velocity=[0.3] * k, effort=[0.2] * k))
    state: dict[str, Any] = {"taken": 0, "start": None, "cpu0": 0.0, "end": False}
    held: list[Any] = []
    last = (frames // k) * k  # the last frame granted (a whole number of batches)

    def pub(topic: str) -> Any:
        return node.create_publisher(JointState, ct.endpoint(topic), profile)

    def sub(topic: str, callback: Any, later: bool = False) -> Any:
        s = node.create_subscription(JointState, ct.endpoint(topic), callback, profile, raw=True)
        if later:
            node.at_frame.add(s)
            held.append(s)
        return s

    def take_held() -> None:
        for s in held:
            with s.handle:
                while s.handle.take_message(s.msg_type, True) is not None:
                    state["taken"] += 1

    def count(_raw: bytes) -> None:
        state["taken"] += 1

    def started() -> None:
        if state["start"] is None:
            state["start"], state["cpu0"] = time.monotonic(), time.process_time()

    def on_clock(raw: bytes) -> None:
        started()
        state["taken"] += 1
        if (cdr.stamp_ns(raw) or 0) >= (last - 1) * FRAME_NS:
            state["end"] = True

    clock_pub = node.create_publisher(Clock, ct.endpoint(ct.CLOCK_TOPIC), qos(ct.CLOCK_QOS)) if role == "clock" \
        else None
    if role != "clock":
        act = on_clock
        if role == "fmu":
            cmd, hinge = pub(ct.FMU_COMMAND), pub(ct.HINGE_MOMENT)
            for topic in (ct.FMU_FEEDBACK, ct.EMAC_COMMAND, ct.EMAC_FEEDBACK, ct.SURFACE, ct.BUS):
                sub(topic, count, later=True)

            def act(raw: bytes) -> None:
                on_clock(raw)
                take_held()
                hinge.publish(every)
                cmd.publish(every)
        node.create_subscription(Clock, ct.endpoint(ct.CLOCK_TOPIC), act, qos(ct.CLOCK_SUB_QOS), raw=True)
    if role == "testenv":
        emac_cmd, fb = pub(ct.EMAC_COMMAND), pub(ct.FMU_FEEDBACK)

        def relay_command(raw: bytes) -> None:
            count(raw)
            emac_cmd.publish(every)

        def relay_feedback(raw: bytes) -> None:
            count(raw)
            fb.publish(one)

        sub(ct.FMU_COMMAND, relay_command)
        sub(ct.EMAC_FEEDBACK, relay_feedback)
    elif role.startswith("emac_"):
        out = [pub(ct.EMAC_FEEDBACK), pub(ct.SURFACE), pub(ct.BUS)]
        sub(ct.HINGE_MOMENT, count, later=True)
        if role == "emac_right_wing":
            sub(ct.EMAC_FEEDBACK, count, later=True)

        def step(raw: bytes) -> None:
            count(raw)
            take_held()
            for p in out:
                p.publish(one)

        sub(ct.EMAC_COMMAND, step)
    reported = [0]

    def report(raw: bytes) -> None:
        count(raw)
        reported[0] += 1

    if role == "clock":
        sub(ct.EMAC_FEEDBACK, report)
    deadline = time.monotonic() + 60.0  # the graph: every process, then a settling second
    while len(node.get_node_names()) < len(ROLES) and time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.05)
    settle = time.monotonic() + 3.0
    while time.monotonic() < settle:
        executor.spin_once(timeout_sec=0.05)
    if clock_pub is not None:
        granted = 0
        started()
        while granted < last:
            granted += k
            reported[0] = 0
            clock_pub.publish(cdr.encode_clock((granted - 1) * FRAME_NS))  # the last frame granted
            wait = time.monotonic() + 5.0
            while reported[0] < len(CHANNELS) and time.monotonic() < wait:
                executor.spin_once(timeout_sec=0.5)
        state["end"] = True
    else:
        wait = time.monotonic() + 600.0
        while not state["end"] and time.monotonic() < wait:
            executor.spin_once(timeout_sec=0.1)
        linger = time.monotonic() + 0.05  # the last frame's answers
        while time.monotonic() < linger:
            executor.spin_once(timeout_sec=0.01)
    cpu, wall = time.process_time() - state["cpu0"], time.monotonic() - (state["start"] or time.monotonic())
    node.destroy_node()
    rclpy.shutdown()
    return {"role": role, "cpu_s": cpu, "wall_s": wall, "taken": state["taken"], "frames": last}


def run(k: int, frames: int = FRAMES) -> dict[str, Any]:
    """The eight processes once, ``k`` frames to a message: CPU and wall a frame, the real-time factor."""
    env = dict(os.environ, ROS_DOMAIN_ID=str(free_domain_id(os.getpid() + 19 + k)),
               ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    procs = [subprocess.Popen([sys.executable, __file__, role, str(frames), str(k)], env=env,
                              stdout=subprocess.PIPE, text=True) for role in ROLES]
    got = {}
    for p in procs:
        out, _ = p.communicate(timeout=900)
        line = json.loads(out.strip().splitlines()[-1])
        got[line.pop("role")] = line
    n = got["clock"]["frames"]
    wall = got["clock"]["wall_s"]
    cpu = sum(r["cpu_s"] for r in got.values())
    return {"k": k, "frames": n, "wall_ms": wall / n * 1e3, "cpu_ms": cpu / n * 1e3,
            "rtf": n * FRAME_NS / 1e9 / wall, "taken_per_frame": sum(r["taken"] for r in got.values()) / n}


def lockstep_floor() -> Result:
    """The lockstep pattern's wall and CPU a frame with 1, 4, 16 and 50 frames to a message."""
    rows = [run(k) for k in BATCHES]
    text = "; ".join(f"K={r['k']}: {r['cpu_ms']:.3f} ms CPU and {r['wall_ms']:.3f} ms wall a frame, "
                     f"{r['rtf']:.1f}× real time, {r['taken_per_frame']:.1f} messages taken a frame" for r in rows)
    return Result(rows[0]["rtf"], "× real time (K=1)", True,
                  f"the processes layout's lockstep messages alone, 8 bare rclpy processes, {FRAMES} frames: {text}")


BENCHMARKS = [
    Benchmark("nodes_middleware_lockstep_floor", "the lockstep messages' floor, K frames to a message", lockstep_floor),
]


if __name__ == "__main__":
    if len(sys.argv) == 2:  # python bench/lockstep_floor.py K: one run, its figures
        print(json.dumps(run(int(sys.argv[1]))), flush=True)
    else:
        print(json.dumps(_role(sys.argv[1], int(sys.argv[2]), int(sys.argv[3]))), flush=True)
