"""Bring the node suite up, run one test, bring it down cleanly (``ema launch``; ``launch/`` for ``ros2 launch``).

The same nodes — the EMAC channels, the test environment, the maneuver node (FMU, load rig and
recorder) and, under lockstep, the clock — hosted three ways (``layout``):

* ``single`` (default): one process composes every node (:mod:`ema_sim.nodes.container`): per-frame
  messages between them are handed over in-process and still published on the contract topics for
  anyone outside. The fastest in lockstep on a 2-core machine.
* ``container``: the EMACs, the test environment and the clock composed; the maneuver node in a process
  of its own, talking to them over DDS as an external flight computer would.
* ``processes``: one process per node; in lockstep fast only with several frames a message
  (``frames_per_message``, :mod:`ema_msgs_py.batch`).

and the EMACs two ways (``emac``): ``box``, one EMAC node hosting the five channels as the real EMAC is
one box (default), or ``channels``, one EMAC node per channel.

What runs where, and the one parameter file every process reads, is the run's
:class:`~ema_sim.run.RunDescription` (the launch files under ``launch/`` start the same processes).
Before it starts anything, the suite looks on its domain for live nodes with its run's names (each suite node
claims its name, :mod:`ema_sim.nodes.names`) and refuses, naming them, when there are any.
The maneuver node waits for the others on ``/ema/ready`` and then records; under lockstep the clock
waits for all of them. A process named in the run's ``respawn`` that ends before the driver is started again
at once, with the same command (at most :data:`RESPAWN_LIMIT` times; each restart is a line on stderr and in
its log): a restarted EMAC rejoins the run, in lockstep on the clock's present frame. Each respawned process
has a standby (:mod:`ema_sim.nodes.standby`): its interpreter started and its node's module imported ahead of
need, it stands in at once, and a new standby is started :data:`STANDBY_AFTER_S` later (not to take the CPU
from the node rejoining). Any other node that
ends with an error stops the run. The suite ends when the maneuver node has finished and closed its bag; the
others then get SIGTERM (which a node takes as SIGINT once running, and which ends one still starting
without a traceback), and SIGKILL only if they do not stop within a few seconds; if the launcher itself
dies, each node gets SIGTERM from the kernel (:mod:`ema_sim.nodes.lifetime`). Each process's
output goes to ``<bag>.logs/<process>.log``; each node prints a JSON summary line that :class:`Suite`
collects by node name.
"""

from __future__ import annotations

import contextlib
import json
import os
import shlex
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import IO, Any

from ema_sim.errors import EmaError
from ema_sim.jsontypes import JsonObject
from ema_sim.nodes.lifetime import PARENT_ENV
from ema_sim.run import DEFAULT_EMAC, DEFAULT_LAYOUT, EMAC_HOSTING, LAYOUTS, RunDescription

SUMMARY_PREFIX = "EMA_SUMMARY "
STOP_TIMEOUT_S = 8.0
RESPAWN_LIMIT = 5
"""Restarts of one process in a run: a process that keeps ending is a fault to report, not to hide."""
STANDBY_AFTER_S = 5.0
"""After a standby stood in, wall seconds before the next standby of that process starts."""
STANDBY = "ema_sim.nodes.standby"
NAMES_LOOK_S = 1.5
"""Before a run starts, how long the launcher looks on its domain for live nodes with the run's names (discovery
on a busy two-core machine; each node's own refusal remains for a node found later)."""
SuiteConfig = RunDescription
"""One run of the suite (the name the tests and benchmarks use)."""
__all__ = ["DEFAULT_EMAC", "DEFAULT_LAYOUT", "DOMAIN_RANGE_ENV", "EMAC_HOSTING", "LAYOUTS", "Suite", "SuiteConfig",
           "domain_range", "free_domain_id", "run_suite"]


DOMAIN_RANGE_ENV = "EMA_DOMAIN_RANGE"
"""``lo-hi``: the ROS domain ids :func:`free_domain_id` may pick (default 1-101). Processes sharing a machine give
each other disjoint ranges (the test suite gives each pytest-xdist worker its own), so their runs never meet."""


def domain_range() -> tuple[int, int]:
    """The domain ids :func:`free_domain_id` picks from: :data:`DOMAIN_RANGE_ENV`, or 1-101.

    Returns
    -------
    tuple of int
        The lowest and highest id.

    Raises
    ------
    EmaError
        The variable is not ``lo-hi`` with 0 ≤ lo ≤ hi ≤ 232.
    """
    text = os.environ.get(DOMAIN_RANGE_ENV, "").strip()
    if not text:
        return 1, 101
    lo_s, _, hi_s = text.partition("-")
    try:
        lo, hi = int(lo_s), int(hi_s)
    except ValueError:
        lo, hi = -1, -1
    if not 0 <= lo <= hi <= 232:
        raise EmaError(f"{DOMAIN_RANGE_ENV}={text!r}: give lo-hi with 0 <= lo <= hi <= 232")
    return lo, hi


def free_domain_id(seed: int | None = None) -> int:
    """A ROS domain id in :func:`domain_range` derived from the pid (so parallel runs on one machine do not meet).

    Parameters
    ----------
    seed : int, optional
        Derive it from this number instead of the pid.

    Returns
    -------
    int
        The domain id.
    """
    lo, hi = domain_range()
    return lo + ((os.getpid() if seed is None else seed) % (hi - lo + 1))


class Suite:
    """The processes of one run.

    Parameters
    ----------
    cfg : RunDescription
        The run: what runs in which process, and its parameters.
    names_look_s : float
        How long :meth:`start` looks for live nodes with the run's names before starting any, s (0: no look).
    """

    def __init__(self, cfg: RunDescription, names_look_s: float = NAMES_LOOK_S) -> None:
        self.cfg = cfg
        self.names_look_s = names_look_s
        self.names_checked = False
        """:meth:`check_names` found the run's names free (:meth:`start` then does not look again)."""
        self.domain_id = cfg.domain_id if cfg.domain_id is not None else int(
            os.environ.get("ROS_DOMAIN_ID") or free_domain_id())
        self.bag = cfg.bag_dir
        """The bag the driver records."""
        self.log_dir = Path(f"{self.bag}.logs")
        self.params_file = self.log_dir / "run.yaml"
        """The run's one parameter file (:meth:`~ema_sim.run.RunDescription.parameter_file`)."""
        self.procs: dict[str, subprocess.Popen[bytes]] = {}
        self._logs: dict[str, IO[bytes]] = {}
        self._commands: dict[str, list[str]] = {}
        self.restarts: dict[str, int] = {}
        """Times each respawned process was started again."""
        self._standby: dict[str, subprocess.Popen[bytes]] = {}
        self._stopping = False
        self._standby_due: dict[str, float] = {}
        """Respawned processes without a standby: when the next is started (monotonic)."""
        self.started = 0.0
        self.duration_s = cfg.run_s

    # ----------------------------------------------------------------- processes
    def _env(self) -> dict[str, str]:
        env = dict(os.environ)
        env["ROS_DOMAIN_ID"] = str(self.domain_id)
        env.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
        env["PYTHONUNBUFFERED"] = "1"
        env.setdefault("RCUTILS_COLORIZED_OUTPUT", "0")
        env[PARENT_ENV] = str(os.getpid())
        return env

    @property
    def driver(self) -> str:
        """The node that drives the test and records the bag: ``maneuver``, or ``fmu`` in the loop."""
        return self.cfg.driver

    @property
    def fmu_process(self) -> str:
        """The process whose end is the end of the test: the driver's (it closes the bag)."""
        return self.cfg.driver_process

    def node_names(self) -> list[str]:
        """Every node of the run (the container's own node aside: it only carries the others' messages)."""
        return self.cfg.node_names()

    def emac_nodes(self) -> list[str]:
        """Node names of the EMACs."""
        return self.cfg.emac_nodes()

    def start(self) -> None:
        """Write the run's parameter file and start every process (returns at once; the nodes find each other)."""
        cfg = self.cfg
        self._stopping = False
        if self.bag.exists():
            raise EmaError(f"{self.bag} exists already; give a new bag directory")
        if not self.names_checked:
            self.check_names()
        self.log_dir.mkdir(parents=True, exist_ok=True)
        cfg.write(self.params_file)
        self.started = time.monotonic()
        for proc in cfg.processes():
            cmd = [sys.executable, "-m", proc.module, *proc.arguments, *cfg.ros_arguments(proc, self.params_file)]
            log = (self.log_dir / f"{proc.name}.log").open("wb")
            self._logs[proc.name] = log
            log.write((shlex.join(cmd) + "\n").encode())
            log.flush()
            self._commands[proc.name] = cmd
            self._spawn(proc.name)
        self._standby_due = dict.fromkeys(self.cfg.respawn, self.started)
        self._start_standbys()

    def full_names(self) -> list[str]:
        """The run's nodes by full name (its namespace included), as they claim them."""
        return [f"{self.cfg.namespace}/{name}" for name in self.node_names()]

    def check_names(self) -> None:
        """Refuse to start when live nodes with the run's names are on its domain (they would merge with its own).

        Raises
        ------
        EmaError
            One line naming each such node (pid, host, how long it has been up).
        """
        if self.names_look_s <= 0:
            return
        from ema_sim.nodes.names import refuse_taken  # noqa: PLC0415 - rclpy only where a run starts

        taken = refuse_taken(self.full_names(), self.domain_id, self.names_look_s,
                             self._env()["ROS_AUTOMATIC_DISCOVERY_RANGE"])  # looked at as the nodes will look
        self.names_checked = True
        if taken.graph_only:
            print(f"ema launch: {', '.join(taken.graph_only)} in the graph of ROS domain {self.domain_id} without a "
                  "live claim (a node that just ended, or not the suite's): starting anyway", file=sys.stderr,
                  flush=True)

    def _spawn(self, name: str) -> None:
        # A session of its own: the terminal's Ctrl-C reaches the launcher, which stops the nodes in order
        # (the driver first: it closes the bag); the nodes end with it however it ends (PARENT_ENV).
        self.procs[name] = subprocess.Popen(self._commands[name], stdout=self._logs[name], stderr=subprocess.STDOUT,
                                            env=self._env(), start_new_session=True)

    def _start_standbys(self) -> None:
        """Start the standbys that are due (:data:`STANDBY_AFTER_S` after the last stood in)."""
        now = time.monotonic()
        for name, due in list(self._standby_due.items()):
            if now >= due:
                del self._standby_due[name]
                cmd = self._commands[name]
                at = cmd.index("-m") + 1
                self._standby[name] = subprocess.Popen([*cmd[:at], STANDBY, *cmd[at:]], stdin=subprocess.PIPE,
                                                       stdout=self._logs[name], stderr=subprocess.STDOUT,
                                                       env=self._env(), start_new_session=True)

    def _respawn(self, name: str, status: int) -> None:
        """Start a respawned process again after it ended with ``status`` (a line on stderr and in its log)."""
        count = self.restarts[name] = self.restarts.get(name, 0) + 1
        standby = self._standby.pop(name, None)
        warm = False
        if standby is not None and standby.poll() is None and standby.stdin is not None:
            try:
                standby.stdin.write(b"run\n")
                standby.stdin.close()
                self.procs[name] = standby
                warm = True
            except OSError:  # it ended between the look and the word: start one cold
                pass
        if not warm:
            self._spawn(name)
        line = (f"ema launch: {name} ended (status {status}) before the {self.driver}; started again "
                f"({'its standby' if warm else 'cold'}; {count} of at most {RESPAWN_LIMIT} restarts)")
        self._logs[name].write(f"{line}\n".encode())
        self._logs[name].flush()
        print(line, file=sys.stderr, flush=True)
        self._standby_due[name] = time.monotonic() + STANDBY_AFTER_S

    def _stop_standbys(self) -> None:
        """End the standbys (end of input: each ends at once, or is killed if it is still importing)."""
        self._standby_due.clear()
        for proc in self._standby.values():
            if proc.stdin is not None:
                with contextlib.suppress(OSError):
                    proc.stdin.close()
            try:
                proc.wait(timeout=2.0)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
        self._standby.clear()

    def wait(self, timeout_s: float | None = None) -> int:
        """Wait for the driver to finish (its bag closed).

        Parameters
        ----------
        timeout_s : float, optional
            Give up (and stop every process) after this long, s; None waits as long as it takes.

        Returns
        -------
        int
            The driver's exit status.

        Raises
        ------
        EmaError
            Another node exited with an error, or the timeout passed (the suite is stopped either way).
        """
        deadline = None if timeout_s is None else time.monotonic() + timeout_s
        man = self.procs[self.fmu_process]
        while man.poll() is None:
            for name, proc in list(self.procs.items()):
                status = proc.poll()
                if name == self.fmu_process or status is None:
                    continue
                if self._stopping:  # ending because the suite is being stopped (another thread): no restart
                    continue
                if name in self.cfg.respawn and self.restarts.get(name, 0) < RESPAWN_LIMIT:
                    self._respawn(name, status)
                elif status != 0:
                    self.stop()
                    raise EmaError(f"node {name} exited with status {status}; see {self.log_dir / name}.log"
                                   + (f" (restarted {RESPAWN_LIMIT} times already)" if name in self.cfg.respawn
                                      else ""))
            if self._standby_due:
                self._start_standbys()
            if deadline is not None and time.monotonic() > deadline:
                self.stop()
                raise EmaError(f"the test did not finish within {timeout_s:g} s; see {self.log_dir}")
            time.sleep(0.05)
        return int(man.returncode)

    def stop(self) -> dict[str, int | None]:
        """SIGTERM to every process still running (the maneuver first: it closes the bag), then SIGKILL."""
        self._stopping = True
        self._stop_standbys()
        first = ("simclock", "maneuver", "fmu", "suite", "container")
        order = [*first, *[n for n in self.procs if n not in first]]
        for name in order:
            proc = self.procs.get(name)
            if proc is not None and proc.poll() is None:
                with contextlib.suppress(ProcessLookupError):
                    os.kill(proc.pid, signal.SIGTERM)
        deadline = time.monotonic() + STOP_TIMEOUT_S
        for proc in self.procs.values():
            try:
                proc.wait(timeout=max(deadline - time.monotonic(), 0.1))
            except subprocess.TimeoutExpired:
                with contextlib.suppress(ProcessLookupError):
                    os.kill(proc.pid, signal.SIGKILL)
                proc.wait()
        for log in self._logs.values():
            log.close()
        return {name: proc.returncode for name, proc in self.procs.items()}

    def summaries(self) -> dict[str, dict[str, Any]]:
        """The JSON summary each node printed when it stopped, by node name."""
        out: dict[str, JsonObject] = {}
        for name in self.procs:
            path = self.log_dir / f"{name}.log"
            if not path.is_file():
                continue
            for line in path.read_text(encoding="utf-8", errors="replace").splitlines():
                if line.startswith(SUMMARY_PREFIX):
                    with contextlib.suppress(ValueError):
                        summary = json.loads(line[len(SUMMARY_PREFIX):])
                        out[str(summary.get("node", name))] = {**summary, "process": name}
        return out

    def run(self, timeout_s: float | None = None) -> None:
        """Start, wait for the test, stop (also when interrupted).

        Parameters
        ----------
        timeout_s : float, optional
            As in :meth:`wait`.

        Raises
        ------
        EmaError
            The bag exists already, a node failed, the timeout passed, or the driver exited with an error.
        """
        try:
            self.start()
            status = self.wait(timeout_s)
        except BaseException:
            self.stop()
            raise
        self.stop()
        if status != 0:
            raise EmaError(f"the {self.driver} node exited with status {status}; see "
                           f"{self.log_dir / (self.fmu_process + '.log')}")

    def __enter__(self) -> Suite:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()


def run_suite(cfg: SuiteConfig, timeout_s: float | None = None) -> dict[str, JsonObject]:
    """Start, wait for the test, stop.

    Parameters
    ----------
    cfg : SuiteConfig
        The run.
    timeout_s : float, optional
        As in :meth:`Suite.wait`.

    Returns
    -------
    dict[str, JsonObject]
        The nodes' summaries, by node name.
    """
    suite = Suite(cfg)
    suite.run(timeout_s)
    return suite.summaries()
