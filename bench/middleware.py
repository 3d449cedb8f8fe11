"""The middleware's floor under the ``processes`` layout: its message pattern, and nothing else.

Seven bare rclpy processes (EventsExecutor, raw CDR, the contract's QoS) exchange exactly the messages of
the ``processes`` layout at 200 Hz, five channels: the FMU publishes the hinge moment and the command and
records every other per-frame topic; the test environment relays the command once and each channel's
feedback; each EMAC channel answers a command with its feedback, surface and bus messages, the right wing
also taking the others' feedback (its crosstalk sources). No model, no test environment, no bag: what is
left is rclpy's and Fast DDS's cost of moving the frame. It is run twice: every message taken on
arrival, and taken as the suite takes them (the hinge moment, the crosstalk sources and the recorder's
topics at the frame, :meth:`ema_sim.nodes.ports.Ports.take_at_frame`). A third run measures a design the
suite does not use: time-triggered, each process asleep until fixed phases of the 5 ms frame (the FMU at 0,
the test environment at 0.5 ms for the command and 2.5 ms for the feedback, each EMAC at 1.2 ms), taking all
its inputs then and never woken by a message. The suite's ``processes`` figure (:mod:`bench.nodes`) is read
against them: the target of at most 60 % of one core cannot be met below the floor of the design in use.

Run as a process: ``python bench/middleware.py ROLE SECONDS MODE`` (``arrival``, ``frame`` or ``clock``).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from collections.abc import Callable
from typing import Any

import rclpy
from rclpy.experimental.events_executor import EventsExecutor
from rclpy.serialization import serialize_message
from sensor_msgs.msg import JointState

from ema_msgs_py import contract as ct
from ema_msgs_py.ros import qos
from ema_sim import config
from ema_sim.benchmark import Benchmark, Result
from ema_sim.nodes.common import SuiteNode
from ema_sim.suite import free_domain_id

CHANNELS = list(config.CHANNELS)
ROLES = ["testenv", *(f"emac_{ch}" for ch in CHANNELS), "fmu"]
SECONDS = float(os.environ.get("EMA_BENCH_MIDDLEWARE_S", "30"))
PERIOD_S = 0.005


def _role(role: str, seconds: float, mode: str) -> dict[str, Any]:  # noqa: PLR0912, PLR0915 (one process: its whole part)
    """One process of the pattern for ``seconds``; its CPU share of one core and what it took."""
    rclpy.init()
    node = SuiteNode(f"floor_{role}")
    executor = EventsExecutor()
    executor.add_node(node)
    profile = qos(ct.FRAME_QOS)
    every = serialize_message(JointState(name=CHANNELS, position=[0.1] * 5, effort=[0.2] * 5))
    one = serialize_message(JointState(name=[role], position=[0.1], velocity=[0.3], effort=[0.2]))
    at_frame, clock = mode in ("frame", "clock"), mode == "clock"
    taken = [0]
    held: list[Any] = []
    phases: list[tuple[float, Callable[[], None]]] = []  # time-triggered: (offset in the frame, s; what is done)

    def pub(topic: str) -> Any:
        return node.create_publisher(JointState, ct.endpoint(topic), profile)

    def sub(topic: str, callback: Callable[[bytes], None], later: bool = False) -> Any:
        s = node.create_subscription(JointState, ct.endpoint(topic), callback, profile, raw=True)
        if (later and at_frame) or clock:
            node.at_frame.add(s)
            held.append(s)
        return s

    def take(s: Any) -> int:
        n = 0
        with s.handle:
            while s.handle.take_message(s.msg_type, True) is not None:
                n += 1
        taken[0] += n
        return n

    def take_held() -> None:
        for s in held:
            take(s)

    def count(_raw: bytes) -> None:
        taken[0] += 1

    if role == "fmu":
        cmd, hinge = pub(ct.FMU_COMMAND), pub(ct.HINGE_MOMENT)
        sub(ct.FMU_FEEDBACK, count, later=True)
        for topic in (ct.EMAC_COMMAND, ct.EMAC_FEEDBACK, ct.SURFACE, ct.BUS):
            sub(topic, count, later=True)

        def fmu_frame() -> None:
            take_held()
            hinge.publish(every)
            cmd.publish(every)

        phases.append((0.0, fmu_frame))
    elif role == "testenv":
        emac_cmd, fb = pub(ct.EMAC_COMMAND), pub(ct.FMU_FEEDBACK)
        commands = sub(ct.FMU_COMMAND, lambda _raw: emac_cmd.publish(every))
        feedback = sub(ct.EMAC_FEEDBACK, fb.publish)

        def relay_commands() -> None:
            for _ in range(take(commands)):
                emac_cmd.publish(every)

        def relay_feedback() -> None:
            for _ in range(take(feedback)):
                fb.publish(one)

        phases.extend([(0.0005, relay_commands), (0.0025, relay_feedback)])
    else:
        out = [pub(ct.EMAC_FEEDBACK), pub(ct.SURFACE), pub(ct.BUS)]
        inputs = [0]

        def step() -> None:
            for p in out:
                p.publish(one)

        def on_input(_raw: bytes) -> None:  # on arrival: a frame once both inputs are in
            inputs[0] += 1
            if inputs[0] == 2:
                inputs[0] = 0
                step()

        if clock:
            for topic in (ct.EMAC_COMMAND, ct.HINGE_MOMENT, *([ct.EMAC_FEEDBACK] if role == "emac_right_wing" else [])):
                sub(topic, count)
            phases.append((0.0012, lambda: (take_held(), step())[1]))
        elif at_frame:
            sub(ct.HINGE_MOMENT, count, later=True)
            if role == "emac_right_wing":
                sub(ct.EMAC_FEEDBACK, count, later=True)
            sub(ct.EMAC_COMMAND, lambda _raw: (take_held(), step()))
        else:
            sub(ct.EMAC_COMMAND, on_input)
            sub(ct.HINGE_MOMENT, on_input)
            if role == "emac_right_wing":
                sub(ct.EMAC_FEEDBACK, count)
    deadline = time.monotonic() + 60.0  # the graph: every process, then a settling second
    while len(node.get_node_names()) < len(ROLES) and time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.05)
    settle = time.monotonic() + 3.0
    while time.monotonic() < settle:
        executor.spin_once(timeout_sec=0.05)
    cpu0, start = time.process_time(), time.monotonic()
    frames = 0
    if clock:  # every process on the same 5 ms grid of the monotonic clock (one clock for the whole machine)
        first = (start // PERIOD_S + 1) * PERIOD_S
        for k in range(round(seconds / PERIOD_S)):
            for offset, act in phases:
                if (left := first + k * PERIOD_S + offset - time.monotonic()) > 0:
                    time.sleep(left)
                act()
            frames += role == "fmu"
    elif role == "fmu":
        due = start
        for _ in range(round(seconds / PERIOD_S)):
            due += PERIOD_S
            hinge.publish(every)
            cmd.publish(every)
            frames += 1
            take_held()
            while (left := due - time.monotonic()) > 0:
                executor.spin_once(timeout_sec=left)
    end = start + seconds + 0.5
    while time.monotonic() < end:
        executor.spin_once(timeout_sec=0.05)
        take_held()
    cpu = time.process_time() - cpu0
    node.destroy_node()
    rclpy.shutdown()
    return {"role": role, "cpu": cpu / seconds, "taken": taken[0], "frames": frames}


def run(mode: str, seconds: float = SECONDS) -> dict[str, Any]:
    """The seven processes once (``mode``: ``arrival``, ``frame`` or ``clock``); each one's CPU share of one core."""
    env = dict(os.environ, ROS_DOMAIN_ID=str(free_domain_id(os.getpid() + {"frame": 11, "arrival": 13}.get(mode, 17))),
               ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    procs = [subprocess.Popen([sys.executable, __file__, role, f"{seconds:g}", mode], env=env,
                              stdout=subprocess.PIPE, text=True) for role in ROLES]
    results = {}
    for p in procs:
        out, _ = p.communicate(timeout=seconds + 180)
        line = json.loads(out.strip().splitlines()[-1])
        results[line.pop("role")] = line
    return results


def middleware_floor() -> Result:
    """The pattern's CPU, messages taken on arrival, at the frame (the suite's way) and time-triggered; target: 60 %."""
    shares = {mode: run(mode) for mode in ("arrival", "frame", "clock")}
    total = {mode: sum(r["cpu"] for r in got.values()) for mode, got in shares.items()}
    fmu = shares["frame"]["fmu"]
    per = ", ".join(f"{role} {r['cpu']:.1%}" for role, r in shares["frame"].items())
    return Result(total["frame"] * 100, "% of one core", total["frame"] <= 0.60,
                  f"the processes layout's messages alone, 7 bare rclpy processes, {SECONDS:g} s at 200 Hz: "
                  f"{total['arrival']:.0%} of one core taking every message on arrival, {total['frame']:.0%} "
                  f"taking them as the suite does ({per}), {total['clock']:.0%} time-triggered (not the suite's "
                  f"design); the FMU recorded {fmu['taken']} messages over {fmu['frames']} frames")


BENCHMARKS = [
    Benchmark("nodes_middleware_floor", "the processes layout's messages alone, ≤ 60 % of one core", middleware_floor),
]


if __name__ == "__main__":
    print(json.dumps(_role(sys.argv[1], float(sys.argv[2]), sys.argv[3])), flush=True)
