"""Speed of the ROS 2 node suite: lockstep real-time factor, real-time latency, the executor.

Parametrised by model: ``EMA_BENCH_MODEL`` (default ``hoad3``) and by duration:
``EMA_BENCH_REALTIME_S`` (default 600 s, ten minutes) and ``EMA_BENCH_LOCKSTEP_S`` (default
30 s of simulated time); ``EMA_BENCH_SHORT=1`` makes them 45 s and 10 s (each run then takes about a
minute). Each run is the whole suite on a ROS domain of its own: five EMAC channels, the AIL test
environment, the maneuver node recording the bag, and under lockstep the clock, hosted as ``ema launch``
hosts them by default (``single``: one process, the EMAC box), the EMACs, the test environment and the
clock composed with the maneuver node in a process of its own (``container``), and one process per node
with one EMAC node per channel (``processes``, its target: < 0.1 % of frames missed and at most
60 % CPU, the processes' CPU time over the run's wall time, of one core, at 200 Hz on two cores; in lockstep
also ``_batched``: ``EMA_BENCH_BATCH`` frames a message, default 50, ``--frames-per-message``). The
``_fifo`` runs use the real-time set-up of :mod:`ema_sim.nodes.realtime` (``--rt-priority 20``): SCHED_FIFO,
memory locked, and idle CPUs that poll instead of halting (their time is the idle task's, not counted in
the processes' CPU; a waker then need not interrupt a halted virtual CPU, the likely reason the request alone
lowers the processes' CPU, see docs/nodes.md). ``nodes_emac_startup``: one EMAC channel process started three
times, its first feedback as published (the node's count from its process's start) and as received by a listener
already on the domain (Fast DDS discovery included), then its idle CPU and resident memory.
"""

from __future__ import annotations

import json
import os
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from ema_sim.benchmark import Benchmark, Result
from ema_sim.nodes.frametimes import CAUSES
from ema_sim.suite import SuiteConfig, free_domain_id, run_suite

MODEL = os.environ.get("EMA_BENCH_MODEL", "hoad3")
SHORT = os.environ.get("EMA_BENCH_SHORT", "") not in ("", "0")
REALTIME_S = float(os.environ.get("EMA_BENCH_REALTIME_S", "45" if SHORT else "600"))
LOCKSTEP_S = float(os.environ.get("EMA_BENCH_LOCKSTEP_S", "10" if SHORT else "30"))
SINE = "sine:freq_hz=2,amp_deg=1,cycles={c:d},lead_s=0"
"""A long sine (not a 60 s-limited dynamic test): the actuator moves on every frame."""


HOSTING = {"single": ("single", "box"), "container": ("container", "box"), "processes": ("processes", "channels")}
"""Benchmark label → (layout, EMAC hosting)."""
MISSED_MAX = 0.001
"""The ``processes`` layout's target: fewer than 0.1 % of frames missed..."""
CPU_MAX = 0.60
"""... and at most 60 % CPU (of one core: CPU seconds of every process over the run's wall seconds)."""


def _describe(hosting: str) -> str:
    return {"single": "one process, EMAC box",
            "container": "EMAC box, test environment and clock composed, the maneuver node in its own process",
            "processes": "one process per node, one EMAC node per channel"}[hosting]


def _per_process(sums: dict[str, Any]) -> dict[str, Any]:
    """One summary per process (composed nodes share their process's CPU figures)."""
    return {s.get("process", k): s for k, s in sums.items()}


def _suite(lockstep: bool, hosting: str, duration_s: float, rt: int = 0, offset: int = 0,
           batch: int = 1) -> dict[str, Any]:
    layout, emac = HOSTING[hosting]
    with tempfile.TemporaryDirectory(prefix="ema_bench_") as tmp:
        cfg = SuiteConfig(bag=Path(tmp) / "bag", model=MODEL, profile="ail",
                          maneuver=SINE.format(c=round(2 * duration_s)), channels=["left_wing"],
                          duration_s=duration_s, lockstep=lockstep, layout=layout, emac=emac,
                          domain_id=free_domain_id(os.getpid() + 31 * offset), rt_priority=rt,
                          frames_per_message=batch)
        return run_suite(cfg, timeout_s=duration_s * 20 + 120)


LOCKSTEP_RTF: dict[str, float] = {}
"""Each layout's lockstep real-time factor measured in this sitting (the processes layout is judged against the
single layout's)."""
PROCESSES_RTF_MIN = 2.0
"""The processes layout in lockstep: at least this multiple of real time on two cores..."""
PROCESSES_OF_SINGLE_MIN = 0.5
"""... and at least this share of the single layout's speed (when that ran in the same sitting)."""


BATCH = int(os.environ.get("EMA_BENCH_BATCH", "50"))
"""Frames a message in the batched processes run (``--frames-per-message``)."""


def lockstep(hosting: str, batch: int = 1) -> Result:
    sums = _suite(True, hosting, LOCKSTEP_S, offset=1 + len(hosting) + batch, batch=batch)
    clock = sums["simclock"]
    rtf = LOCKSTEP_RTF[hosting if batch == 1 else f"{hosting}_batched"] = clock["realtime_factor"]
    cpu = sum(s.get("cpu_s", 0.0) for s in _per_process(sums).values())
    run_cpu = sum(s.get("cpu_run_s", 0.0) for s in _per_process(sums).values())  # from the first frame
    ok = rtf >= 10.0
    versus = ""
    if hosting == "processes":
        single = LOCKSTEP_RTF.get("single")
        ok = rtf >= PROCESSES_RTF_MIN and (single is None or rtf >= PROCESSES_OF_SINGLE_MIN * single)
        versus = f"; {rtf / single:.2f} of the single layout's speed" if single else ""
    if batch > 1:
        plain = LOCKSTEP_RTF.get(hosting)
        versus += f"; {rtf / plain:.1f}× the unbatched run's" if plain else ""
    return Result(rtf, "× real time", ok,
                  f"{MODEL}, {_describe(hosting)}{f', {batch} frames a message' if batch > 1 else ''}: "
                  f"{clock['sim_s']:g} s simulated "
                  f"in {clock['wall_s']:.1f} s, {clock['stalls']} stalls; CPU {cpu:.1f} s over all processes, "
                  f"{run_cpu:.1f} s from the first frame ({run_cpu / max(clock['frames'], 1) * 1e3:.2f} ms a "
                  f"frame){versus}")


def realtime(hosting: str, rt: int) -> Result:
    sums = _suite(False, hosting, REALTIME_S, rt=rt, offset=3 + len(hosting))
    man = sums["maneuver"]
    p99, missed, frames = man["latency_p99_ms"], man["missed_frames"], max(man["frames"], 1)
    late = sum(s.get("late_frames", 0) for s in sums.values())
    turn = max((s["turnaround_p99_ms"] for s in sums.values() if "turnaround_p99_ms" in s), default=float("nan"))
    causes = ", ".join(f"{man[f'missed_{c}']} {c.replace('_', ' ')}" for c in CAUSES if f"missed_{c}" in man)
    setup = man.get("realtime", {})
    procs = _per_process(sums)
    share = sum(s.get("cpu_run_s", 0.0) for s in procs.values()) / REALTIME_S
    per = ", ".join(f"{name} {s.get('cpu_run_s', 0.0) / REALTIME_S:.1%}" for name, s in procs.items())
    ok = (missed / frames < MISSED_MAX and share <= CPU_MAX) if hosting == "processes" else (p99 <= 2.0 and missed == 0)
    return Result(p99, "ms p99", ok,
                  f"{MODEL}, {_describe(hosting)}, "
                  f"{'real-time set-up ' + json.dumps(setup) if rt else 'normal scheduling'}: {man['frames']} frames "
                  f"over {REALTIME_S:g} s; CPU {share:.0%} of one core over the run ({per}); "
                  f"p50 {man['latency_p50_ms']:.2f} ms, max {man['latency_max_ms']:.2f} ms; "
                  f"{missed} missed frames ({missed / frames:.2%}){' (' + causes + ')' if causes else ''}; "
                  f"{man['late_publish']} commands published over a frame late; "
                  f"{late} EMAC frames without a timely command; inside the EMAC node, "
                  f"command received to feedback published p99 {turn:.2f} ms; "
                  f"the machine's stolen CPU time {man.get('machine_steal_s', float('nan')):.2f} s")


PINGPONG = r'''
import sys, time
import rclpy
from rclpy.node import Node
from sensor_msgs.msg import JointState
role, kind, n = sys.argv[1], sys.argv[2], int(sys.argv[3])
rclpy.init()
node = Node("pp_" + role)
if kind == "events":
    from rclpy.experimental import EventsExecutor
    ex = EventsExecutor()
elif kind == "multi":
    from rclpy.executors import MultiThreadedExecutor
    ex = MultiThreadedExecutor()
else:
    from rclpy.executors import SingleThreadedExecutor
    ex = SingleThreadedExecutor()
ex.add_node(node)
got = []
if role == "echo":
    pub = node.create_publisher(JointState, "pong", 100)
    node.create_subscription(JointState, "ping", lambda m: (pub.publish(m), got.append(1)), 100)
    end = time.time() + 600
    while len(got) < n and time.time() < end:
        ex.spin_once(timeout_sec=0.1)
else:
    pub = node.create_publisher(JointState, "ping", 100)
    node.create_subscription(JointState, "pong", lambda m: got.append(time.perf_counter() - m.position[0]), 100)
    while pub.get_subscription_count() == 0 or node.count_publishers("pong") == 0:
        ex.spin_once(timeout_sec=0.05)
    time.sleep(0.5)
    for i in range(n):
        k = len(got)
        pub.publish(JointState(name=["x"], position=[time.perf_counter()]))
        end = time.time() + 2
        while len(got) == k and time.time() < end:
            ex.spin_once(timeout_sec=0.5)
    print(sorted(got)[len(got) // 2] * 1e6)
'''


def _roundtrip_us(kind: str, n: int = 1000) -> float:
    env = dict(os.environ, ROS_DOMAIN_ID=str(free_domain_id(os.getpid() + 7)),
               ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    echo = subprocess.Popen([sys.executable, "-c", PINGPONG, "echo", kind, str(n)], env=env)
    try:
        out = subprocess.run([sys.executable, "-c", PINGPONG, "ping", kind, str(n)], env=env, check=True,
                             capture_output=True, text=True, timeout=600).stdout
    finally:
        echo.wait(timeout=30)
    return float(out.strip().splitlines()[-1])


def executor_choice() -> Result:
    """Median cross-process round trip with each executor, spin_once loops as the nodes use them."""
    counts = {"events": 1000, "single": 1000, "multi": 200}  # the multi-threaded one is too slow for more
    rtt = {kind: statistics.median(_roundtrip_us(kind, n) for _ in range(2)) for kind, n in counts.items()}
    best = min(rtt, key=rtt.get)  # type: ignore[arg-type]
    detail = ", ".join(f"{k} {v:.0f} µs" for k, v in rtt.items())
    return Result(rtt["events"], "µs RTT", best == "events", f"median round trip: {detail}")


FIRST_FEEDBACK_MAX_S = 1.5
"""One EMAC's first feedback after its process starts, at most, s."""
IDLE_S = 10.0
"""Wall seconds over which an idle EMAC's CPU share is counted."""


def _cpu_s(pid: int) -> float:
    """A process's user and system CPU so far, s (``/proc``)."""
    with open(f"/proc/{pid}/stat", encoding="ascii") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _rss_mb(pid: int) -> float:
    with open(f"/proc/{pid}/status", encoding="ascii") as f:
        return next(int(line.split()[1]) for line in f if line.startswith("VmRSS")) / 1024


def _listener(env: dict[str, str]) -> tuple[Any, Any, Any, list[float]]:
    """A node on ``env``'s domain noting when each ``/ema/emac/feedback`` message arrives (perf_counter)."""
    import rclpy  # noqa: PLC0415 - the listener; the other benchmarks need no ROS in this process
    from rclpy.context import Context  # noqa: PLC0415
    from rclpy.executors import SingleThreadedExecutor  # noqa: PLC0415
    from rclpy.signals import SignalHandlerOptions  # noqa: PLC0415
    from sensor_msgs.msg import JointState  # noqa: PLC0415

    context = Context()
    saved = {key: os.environ.get(key) for key in ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE")}
    os.environ.update({key: env[key] for key in saved})  # the middleware reads them when the context starts
    rclpy.init(context=context, signal_handler_options=SignalHandlerOptions.NO)
    for key, value in saved.items():
        if value is None:
            del os.environ[key]
        else:
            os.environ[key] = value
    node = rclpy.create_node("startup_listener", context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    got: list[float] = []
    node.create_subscription(JointState, "/ema/emac/feedback", lambda _msg: got.append(time.perf_counter()), 10)
    return context, node, executor, got


def emac_startup(starts: int = 3) -> Result:
    """One EMAC channel process (real time, no commands: idle frames at 200 Hz), started ``starts`` times.

    Each start: seconds to its first feedback as the node publishes it (its summary's ``first_feedback_s``, from
    the process's start) and as a listener already on the domain receives it (DDS discovery included); the last
    one's CPU share over :data:`IDLE_S` and its resident memory.
    """
    domain = free_domain_id(os.getpid() + 61)
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", PYTHONUNBUFFERED="1")
    context, node, executor, got = _listener(env)
    cmd = [sys.executable, "-m", "ema_sim.nodes.emac", "--model", MODEL, "--channel", "left_wing"]
    arrived: list[float] = []
    published: list[float | None] = []
    idle = rss = float("nan")
    try:
        for k in range(starts):
            got.clear()
            t0 = time.perf_counter()
            proc = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
            try:
                while not got and time.perf_counter() - t0 < 60 and proc.poll() is None:
                    executor.spin_once(timeout_sec=0.005)
                arrived.append(got[0] - t0 if got else float("nan"))
                if k == starts - 1:
                    time.sleep(2.0)  # settled
                    c0, w0 = _cpu_s(proc.pid), time.monotonic()
                    time.sleep(IDLE_S)
                    idle = (_cpu_s(proc.pid) - c0) / (time.monotonic() - w0)
                    rss = _rss_mb(proc.pid)
            finally:
                proc.send_signal(signal.SIGINT)
                out, _ = proc.communicate(timeout=30)
            line = next((x for x in out.splitlines() if x.startswith("EMA_SUMMARY ")), "")
            published.append(json.loads(line[len("EMA_SUMMARY "):]).get("first_feedback_s") if line else None)
    finally:
        executor.shutdown()
        node.destroy_node()
        context.try_shutdown()
    first = statistics.median(arrived)
    return Result(first, "s first feedback", first <= FIRST_FEEDBACK_MAX_S,
                  f"{MODEL}, one channel, real time, idle: first feedback received "
                  f"{', '.join(f'{x:.2f}' for x in arrived)} s after the process started (published at "
                  f"{', '.join('?' if x is None else f'{x:.2f}' for x in published)} s, the node's own count); "
                  f"idle {idle:.1%} of one core, {rss:.0f} MB resident")


BENCHMARKS = [
    Benchmark(f"nodes_lockstep_single_{MODEL}", "≥ 10× real time", lambda: lockstep("single")),
    Benchmark(f"nodes_lockstep_processes_{MODEL}",
              f"≥ {PROCESSES_RTF_MIN:g}× real time, ≥ {PROCESSES_OF_SINGLE_MIN:g}× the single layout's",
              lambda: lockstep("processes")),
    Benchmark(f"nodes_lockstep_processes_batched_{MODEL}",
              f"≥ {PROCESSES_RTF_MIN:g}× real time, ≥ {PROCESSES_OF_SINGLE_MIN:g}× the single layout's",
              lambda: lockstep("processes", BATCH)),
    Benchmark(f"nodes_realtime_single_fifo_{MODEL}", "p99 ≤ 2 ms, 0 missed", lambda: realtime("single", rt=20)),
    Benchmark(f"nodes_realtime_single_{MODEL}", "p99 ≤ 2 ms, 0 missed", lambda: realtime("single", rt=0)),
    Benchmark(f"nodes_realtime_container_{MODEL}", "p99 ≤ 2 ms, 0 missed", lambda: realtime("container", rt=0)),
    Benchmark(f"nodes_realtime_processes_{MODEL}", "< 0.1 % missed, ≤ 60 % CPU",
              lambda: realtime("processes", rt=0)),
    Benchmark(f"nodes_realtime_processes_fifo_{MODEL}", "< 0.1 % missed, ≤ 60 % CPU",
              lambda: realtime("processes", rt=20)),
    Benchmark("nodes_executor_choice", "EventsExecutor fastest", executor_choice),
    Benchmark(f"nodes_emac_startup_{MODEL}", f"first feedback ≤ {FIRST_FEEDBACK_MAX_S:g} s", emac_startup),
]
