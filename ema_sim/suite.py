"""Bring the node suite up, run one test, bring it down cleanly (no ``ros2 launch`` here).

The same nodes — the EMAC channels, the test environment, the maneuver node (FMU, load rig and
recorder) and, under lockstep, the clock — hosted three ways (``layout``):

* ``single`` (default): one process composes every node (:mod:`ema_sim.nodes.container`): per-frame
  messages between them are handed over in-process and still published on the contract topics for
  anyone outside. The only layout that meets the lockstep speed target on a 2-core machine.
* ``container``: the EMACs, the test environment and the clock composed; the maneuver node in a process
  of its own, talking to them over DDS as an external flight computer would.
* ``processes``: one process per node.

and the EMACs two ways (``emac``): ``box``, one EMAC node hosting the five channels as the real EMAC is
one box (default), or ``channels``, one EMAC node per channel.

The maneuver node waits for the others on ``/ema/ready`` and then records; under lockstep the clock
waits for all of them. The suite ends when the maneuver node has finished and closed its bag; the
others then get SIGINT, and SIGKILL only if they do not stop within a few seconds. Each process's
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
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

from ema_sim.config import CHANNELS
from ema_sim.errors import EmaError
from ema_sim.signals.plans import build_plan
from ema_sim.switches import element_names, environment_elements

SUMMARY_PREFIX = "EMA_SUMMARY "
STOP_TIMEOUT_S = 8.0
LAYOUTS = ("single", "container", "processes")
DEFAULT_LAYOUT = "single"
EMAC_HOSTING = ("box", "channels")
DEFAULT_EMAC = "box"


def free_domain_id(seed: int | None = None) -> int:
    """A ROS domain id in 1–101 derived from the pid (so parallel runs on one machine do not meet)."""
    return 1 + ((os.getpid() if seed is None else seed) % 101)


@dataclass
class SuiteConfig:
    """One run of the suite."""

    bag: Path
    model: str = "loada"
    profile: str = "none"
    test: str | None = None
    maneuver: str | None = None
    load: str | None = None
    channels: list[str] = field(default_factory=lambda: ["left_wing"])
    """Driven channels."""
    emac_channels: list[str] = field(default_factory=lambda: list(CHANNELS))
    """Channels that get an EMAC node."""
    duration_s: float | None = None
    lockstep: bool = False
    emac_box: bool | None = None
    """Shorthand: True for ``emac="box"``, False for ``emac="channels"``."""
    layout: str = DEFAULT_LAYOUT
    """``single``, ``container`` or ``processes`` (see the module docstring)."""
    emac: str = DEFAULT_EMAC
    """``box``: one EMAC node for every channel; ``channels``: one EMAC node per channel."""
    frame_hz: float = 200.0
    domain_id: int | None = None
    disable: list[str] = field(default_factory=list)
    window: int = 1
    rt_priority: int = 0
    """Real time: every node process at this SCHED_FIFO priority, memory locked, CPUs kept from idle halts
    (0: normal scheduling; see :mod:`ema_sim.nodes.realtime`)."""
    extra_emac_args: list[str] = field(default_factory=list)
    measure_busy: bool = False
    """Composed layouts: account the container thread's time to each node (``busy_s`` in the summaries)."""
    fmu: bool = False
    """Aircraft in the loop: the ``fmu`` node (vehicle and autopilot) drives the suite instead of the maneuver."""
    fmu_args: list[str] = field(default_factory=list)
    """Extra ``fmu`` arguments (``--open-loop``, ``--bungee 100``...)."""
    seed: int | None = None
    """The test environment's noise seed (default: the profile's)."""

    def __post_init__(self) -> None:
        if self.emac_box is not None:
            self.emac = "box" if self.emac_box else "channels"
        if self.layout not in LAYOUTS:
            raise EmaError(f"unknown layout {self.layout!r}; layouts: {', '.join(LAYOUTS)}")
        self.disable = list(element_names(self.disable))  # one clear error before anything starts
        if self.emac not in EMAC_HOSTING:
            raise EmaError(f"unknown EMAC hosting {self.emac!r}; give {' or '.join(EMAC_HOSTING)}")
        self.emac_box = self.emac == "box"


class Suite:
    """The processes of one run."""

    def __init__(self, cfg: SuiteConfig) -> None:
        self.cfg = cfg
        self.domain_id = cfg.domain_id if cfg.domain_id is not None else int(
            os.environ.get("ROS_DOMAIN_ID") or free_domain_id())
        self.log_dir = Path(f"{cfg.bag}.logs")
        self.procs: dict[str, subprocess.Popen[bytes]] = {}
        self._logs: dict[str, IO[bytes]] = {}
        self.started = 0.0

    # ----------------------------------------------------------------- processes
    def _env(self) -> dict[str, str]:
        env = dict(os.environ)
        env["ROS_DOMAIN_ID"] = str(self.domain_id)
        env.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
        env["PYTHONUNBUFFERED"] = "1"
        env.setdefault("RCUTILS_COLORIZED_OUTPUT", "0")
        return env

    def _spawn(self, name: str, module: str, args: list[str], *, sim_time: bool | None = None) -> None:
        cmd = [sys.executable, "-m", f"ema_sim.nodes.{module}", *args, "--peers", ",".join(self.node_names())]
        if self.cfg.rt_priority > 0:
            cmd += ["--rt-priority", str(self.cfg.rt_priority)]
        if self.cfg.lockstep and (module != "clock" if sim_time is None else sim_time):
            cmd += ["--ros-args", "-p", "use_sim_time:=true"]
        log = (self.log_dir / f"{name}.log").open("wb")
        self._logs[name] = log
        log.write((" ".join(cmd) + "\n").encode())
        log.flush()
        self.procs[name] = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, env=self._env(),
                                            start_new_session=True)

    @property
    def driver(self) -> str:
        """The node that drives the test and records the bag: ``maneuver``, or ``fmu`` in the loop."""
        return "fmu" if self.cfg.fmu else "maneuver"

    @property
    def fmu_process(self) -> str:
        """The process whose end is the end of the test: the driver's (it closes the bag)."""
        return "suite" if self.cfg.layout == "single" else self.driver

    def node_names(self) -> list[str]:
        """Every node of the run (the container's own node aside: it only carries the others' messages)."""
        return [*self.emac_nodes(), "testenv", self.driver, *(["simclock"] if self.cfg.lockstep else [])]

    def emac_nodes(self) -> list[str]:
        """Node names of the EMACs."""
        return ["emac"] if self.cfg.emac_box else [f"emac_{c}" for c in self.cfg.emac_channels]

    def node_args(self, duration_s: float) -> dict[str, list[str]]:
        """Command-line arguments of each node (``emac``, ``testenv``, ``maneuver``, ``simclock``)."""
        cfg = self.cfg
        fh = ["--frame-hz", f"{cfg.frame_hz:g}"]
        env_args = ["--profile", cfg.profile, *fh]
        for item in environment_elements(cfg.disable):
            env_args += ["--disable", item]
        if cfg.seed is not None:
            env_args += ["--seed", str(cfg.seed)]
        wait_for = [*self.emac_nodes(), "testenv"]
        man = ["--bag", str(cfg.bag), "--model", cfg.model, "--profile", cfg.profile, *fh,
               "--wait-for", ",".join(wait_for), "--channels", ",".join(cfg.channels),
               "--command-channels", ",".join(cfg.emac_channels),
               "--expect-feedback", ",".join(c for c in cfg.channels if c in cfg.emac_channels)]
        for flag, value in (("--test", cfg.test), ("--maneuver", cfg.maneuver), ("--load", cfg.load)):
            if value:
                man += [flag, value]
        if cfg.duration_s is not None:
            man += ["--duration", f"{cfg.duration_s:g}"]
        fmu = ["--bag", str(cfg.bag), "--model", cfg.model, "--profile", cfg.profile, *fh,
               "--wait-for", ",".join(wait_for), "--duration", f"{duration_s:g}", *cfg.fmu_args]
        if cfg.seed is not None:
            fmu += ["--seed", str(cfg.seed)]
        for item in cfg.disable:
            fmu += ["--disable", item]
        return {
            "emac": ["--model", cfg.model, *fh, *(a for name in cfg.disable for a in ("--disable", name)),
                     *cfg.extra_emac_args],
            "testenv": env_args,
            "maneuver": man,
            "fmu": fmu,
            "simclock": ["--wait-for", ",".join([*wait_for, self.driver]), "--channels", ",".join(cfg.emac_channels),
                         "--window", str(cfg.window), "--duration", f"{duration_s:.9g}", *fh],
        }

    def start(self) -> None:
        """Start every process (returns at once; the nodes find each other on their own)."""
        cfg = self.cfg
        if cfg.fmu:
            if cfg.duration_s is None or not cfg.duration_s > 0.0:
                raise EmaError("the aircraft-in-the-loop run needs a positive duration")
            self.duration_s = cfg.duration_s
        else:
            plan = build_plan(cfg.test, maneuver=cfg.maneuver, load=cfg.load, channels=cfg.channels,
                              duration_s=cfg.duration_s)  # a bad spec is one clear error before anything starts
            self.duration_s = plan.duration_s
        if cfg.bag.exists():
            raise EmaError(f"{cfg.bag} exists already; give a new bag directory")
        self.log_dir.mkdir(parents=True, exist_ok=True)
        self.started = time.monotonic()
        args = self.node_args(self.duration_s)
        driver = self.driver
        if cfg.layout == "processes":
            if cfg.emac_box:
                self._spawn("emac", "emac", ["--channel", ",".join(cfg.emac_channels), *args["emac"]])
            else:
                for ch in cfg.emac_channels:
                    self._spawn(f"emac_{ch}", "emac", ["--channel", ch, *args["emac"]])
            self._spawn("testenv", "testenv", args["testenv"])
            self._spawn(driver, driver, args[driver])
            if cfg.lockstep:
                self._spawn("simclock", "clock", args["simclock"])
            return
        host = ["--channels", ",".join(cfg.emac_channels), "--emac-args", shlex.join(args["emac"]),
                "--testenv-args", shlex.join(args["testenv"])]
        host += ["--emac-box"] if cfg.emac_box else []
        host += ["--measure-busy"] if cfg.measure_busy else []
        host += ["--clock-args", shlex.join(args["simclock"])] if cfg.lockstep else []
        if cfg.layout == "single":
            self._spawn("suite", "container", [*host, f"--{driver}-args", shlex.join(args[driver])], sim_time=True)
        else:
            self._spawn("container", "container", host, sim_time=True)
            self._spawn(driver, driver, args[driver])

    def wait(self, timeout_s: float | None = None) -> int:
        """Wait for the maneuver node to finish (its bag closed); returns its exit status."""
        deadline = None if timeout_s is None else time.monotonic() + timeout_s
        man = self.procs[self.fmu_process]
        while man.poll() is None:
            for name, proc in self.procs.items():
                if name != self.fmu_process and proc.poll() not in (None, 0):
                    self.stop()
                    raise EmaError(f"node {name} exited with status {proc.returncode}; see {self.log_dir / name}.log")
            if deadline is not None and time.monotonic() > deadline:
                self.stop()
                raise EmaError(f"the test did not finish within {timeout_s:g} s; see {self.log_dir}")
            time.sleep(0.05)
        return int(man.returncode)

    def stop(self) -> dict[str, int | None]:
        """SIGINT to every process still running (the maneuver first: it closes the bag), then SIGKILL."""
        first = ("simclock", "maneuver", "fmu", "suite", "container")
        order = [*first, *[n for n in self.procs if n not in first]]
        for name in order:
            proc = self.procs.get(name)
            if proc is not None and proc.poll() is None:
                with contextlib.suppress(ProcessLookupError):
                    os.kill(proc.pid, signal.SIGINT)
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
        out: dict[str, dict[str, Any]] = {}
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
        """Start, wait for the test, stop (also when interrupted); one error when the driver failed."""
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


def run_suite(cfg: SuiteConfig, timeout_s: float | None = None) -> dict[str, dict[str, Any]]:
    """Start, wait for the test, stop; the nodes' summaries."""
    suite = Suite(cfg)
    suite.run(timeout_s)
    return suite.summaries()
