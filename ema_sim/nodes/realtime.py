"""Real-time set-up of a node process: SCHED_FIFO, memory locked, the CPUs kept out of idle halts.

What a real-time Linux test rig does before its first frame (cyclictest does the same three things):

* ``SCHED_FIFO`` at the given priority, for the process's thread and every thread it starts later
  (rclpy's middleware threads), so no normal-priority task can take the CPU in the middle of a frame;
* ``mlockall``, so no page of the process is reclaimed and faulted back in during a frame (only where
  the whole address space may be locked: as root or with an unlimited ``RLIMIT_MEMLOCK``; locking the
  future mappings under a finite limit would make later allocations fail);
* a 0 µs request on ``/dev/cpu_dma_latency`` (the kernel's PM QoS), held for the process's life, so an
  idle CPU polls instead of halting. Measured on this project's 2-vCPU virtual machine (a C loop with
  the suite's 5 ms frames and 0.5 ms of work at SCHED_FIFO 20): a halted vCPU waits for the hypervisor
  to run it again, and the request cut frames whose work took over 5 ms from 83 in 600 s to 2 in 300 s.
  The price: idle CPUs spin for as long as the process runs.

Each step is tried on its own; what could not be done is said in :attr:`Setup.notes` and the node runs
on without it (a node never dies on a setting it is not allowed).
"""

from __future__ import annotations

import ctypes
import os
import resource
import struct
from dataclasses import dataclass, field

from ema_sim.jsontypes import JsonObject, JsonValue

MCL_CURRENT = 1
MCL_FUTURE = 2
CPU_LATENCY = "/dev/cpu_dma_latency"


@dataclass
class Setup:
    """What :func:`apply` did (the node's summary reports it)."""

    priority: int = 0
    """The SCHED_FIFO priority in force (0: normal scheduling)."""
    memory_locked: bool = False
    cpu_latency_us: int | None = None
    """The held PM QoS CPU latency request (None: none held)."""
    notes: list[str] = field(default_factory=list)

    def summary(self) -> JsonObject:
        """For the node's summary line."""
        out: JsonObject = {"sched_fifo": self.priority, "memory_locked": self.memory_locked,
                         "cpu_latency_us": self.cpu_latency_us}
        if self.notes:
            out["notes"] = list[JsonValue](self.notes)
        return out


_held: list[int] = []
"""File descriptors of held PM QoS requests: the request lasts while the descriptor is open."""


def apply(priority: int, *, lock_memory: bool = True, cpu_latency_us: int | None = 0) -> Setup:
    """Set this process up for real time (see the module docstring); nothing at all when ``priority`` is 0.

    Parameters
    ----------
    priority : int
        The SCHED_FIFO priority (1–99) of every thread of the process; 0: normal scheduling, nothing done.
    lock_memory : bool
        Lock the process's memory (``mlockall``, where the whole address space may be locked).
    cpu_latency_us : int or None
        Hold a PM QoS CPU latency request of this many µs on ``/dev/cpu_dma_latency`` (None: none).

    Returns
    -------
    Setup
        What was done, and notes on what could not be.
    """
    setup = Setup()
    if priority <= 0:
        return setup
    try:
        for tid in _threads():  # the threads already running (numpy's pool) as well as those to come
            os.sched_setscheduler(tid, os.SCHED_FIFO, os.sched_param(priority))
        setup.priority = priority
    except (OSError, ValueError) as exc:
        setup.notes.append(f"SCHED_FIFO {priority}: {exc}")
    if lock_memory:
        _lock_memory(setup)
    if cpu_latency_us is not None:
        _hold_cpu_latency(setup, cpu_latency_us)
    return setup


def _threads() -> list[int]:
    try:
        return [int(t) for t in os.listdir("/proc/self/task")]
    except OSError:
        return [0]


def _lock_memory(setup: Setup) -> None:
    soft, _ = resource.getrlimit(resource.RLIMIT_MEMLOCK)
    if soft != resource.RLIM_INFINITY and os.geteuid() != 0:
        setup.notes.append(f"mlockall: RLIMIT_MEMLOCK is {soft} bytes, not unlimited; memory not locked")
        return
    libc = ctypes.CDLL(None, use_errno=True)
    if libc.mlockall(MCL_CURRENT | MCL_FUTURE) != 0:
        setup.notes.append(f"mlockall: {os.strerror(ctypes.get_errno())}")
        return
    setup.memory_locked = True


def _hold_cpu_latency(setup: Setup, us: int) -> None:
    try:
        fd = os.open(CPU_LATENCY, os.O_WRONLY | os.O_CLOEXEC)
    except OSError as exc:
        setup.notes.append(f"{CPU_LATENCY}: {exc.strerror}")
        return
    try:
        os.write(fd, struct.pack("i", us))
    except OSError as exc:
        os.close(fd)
        setup.notes.append(f"{CPU_LATENCY}: {exc.strerror}")
        return
    _held.append(fd)
    setup.cpu_latency_us = us


def cpu_latency_request_us() -> int | None:
    """The system's PM QoS CPU latency in force, µs (None where it cannot be read)."""
    try:
        with open(CPU_LATENCY, "rb") as f:
            return int(struct.unpack("i", f.read(4))[0])
    except (OSError, struct.error):
        return None


def steal_s() -> float | None:
    """CPU time the hypervisor took from this machine's CPUs since boot, s (all CPUs; None off Linux)."""
    try:
        with open("/proc/stat") as f:
            fields = f.readline().split()
        return int(fields[8]) / os.sysconf("SC_CLK_TCK")
    except (OSError, IndexError, ValueError):
        return None
