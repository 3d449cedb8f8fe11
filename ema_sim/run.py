"""One run of the node suite, validated once: which nodes run in which processes, and ONE parameter file.

A :class:`RunDescription` is built once (``ema launch``'s options, a test's keyword arguments) and checked
once when it is made: model, profile, elements switched off, the test or maneuver, the aircraft-in-the-loop
set-up, layout, namespace. Everything a node needs then travels as ROS parameters in one parameter file
(:meth:`RunDescription.parameter_file`), a section per node name, which every process of the run is given
with ``--params-file``; the nodes declare their parameters and take their values from it (nothing is turned
back into command-line options). :meth:`RunDescription.processes` says which processes host which nodes:
``ema launch`` (:mod:`ema_sim.suite`) starts them itself and the launch files under ``launch/``
(:mod:`ema_sim.launching`) hand the same list to ``ros2 launch``.
"""

from __future__ import annotations

import argparse
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from ema_sim.ail.params import load_ail_config
from ema_sim.config import CHANNELS
from ema_sim.environment import load_profile
from ema_sim.errors import EmaError, UnknownNameError
from ema_sim.jsontypes import JsonObject
from ema_sim.models import model_names
from ema_sim.signals.plans import build_plan, channel_list

LAYOUTS = ("single", "container", "processes")
DEFAULT_LAYOUT = "single"
EMAC_HOSTING = ("box", "channels")
DEFAULT_EMAC = "box"
EXECUTABLES: dict[str, str] = {
    "emac": "ema_sim.nodes.emac",
    "testenv": "ema_sim.nodes.testenv",
    "maneuver": "ema_sim.nodes.maneuver",
    "fmu": "ema_sim.nodes.fmu",
    "simclock": "ema_sim.nodes.clock",
    "fmu_bridge": "ema_sim.nodes.bridge",
    "ema_container": "ema_sim.nodes.container",
}
"""Console script (``ros2 run ema_sim …``) → the module it runs (``setup.py`` installs the same names)."""
CONTAINER = "ema_container"


@dataclass(frozen=True)
class Process:
    """One process of a run."""

    name: str
    """Its name in ``ema launch`` (the log file ``<bag>.logs/<name>.log``)."""
    executable: str
    """The console script."""
    nodes: tuple[str, ...]
    """The nodes it hosts (a container composes several)."""
    arguments: tuple[str, ...] = ()
    """Process options (the real-time set-up acts on the process before ROS starts)."""

    @property
    def module(self) -> str:
        """The module ``python -m`` runs."""
        return EXECUTABLES[self.executable]

    @property
    def node_name(self) -> str | None:
        """The node's name when the process hosts one node (``-r __node:=``), else None."""
        return self.nodes[0] if self.executable != CONTAINER else None


def _fmu_options(items: list[str]) -> argparse.Namespace:
    """``fmu_args`` (``--open-loop``, ``--bungee 100``) read once into fields."""
    p = argparse.ArgumentParser(prog="fmu options", add_help=False, exit_on_error=False)
    p.add_argument("--open-loop", action="store_true")
    p.add_argument("--bungee", type=float, default=None)
    try:
        args, rest = p.parse_known_args(items)
    except argparse.ArgumentError as exc:
        raise EmaError(f"fmu options: {exc}") from None
    if rest:
        raise EmaError(f"fmu options: unknown {' '.join(rest)!r} (known: --open-loop, --bungee INLB)")
    return args


class _PlainDumper(yaml.SafeDumper):
    """Every value written out where it is used (rcl's parser knows no YAML anchors or aliases)."""

    def ignore_aliases(self, data: object) -> bool:  # noqa: ARG002
        return True


def _namespace(text: str) -> str:
    """``aircraft2`` or ``/aircraft2/`` → ``/aircraft2`` (empty: none); one error for a name ROS refuses."""
    parts = [p for p in text.strip("/").split("/") if p]
    if not all(p.isidentifier() for p in parts):
        raise EmaError(f"namespace {text!r}: names of letters, digits and underscores, e.g. /aircraft2")
    return "".join(f"/{p}" for p in parts)


@dataclass
class RunDescription:
    """One run of the suite (validated when made: one clear error before anything starts)."""

    bag: Path | None
    """The bag directory to create (None: ``bags/<test>_<UTC time>``)."""
    model: str = "loada"
    """The model in every EMAC (``ema models``)."""
    profile: str = "none"
    """The test environment: ``ail``, ``flight`` or ``none``."""
    test: str | None = None
    """A section-2 test spec (``ema tests``)."""
    maneuver: str | None = None
    """A maneuver spec of the driven channels (``ema maneuvers``)."""
    load: str | None = None
    """A hinge-moment spec of the driven channels."""
    channels: list[str] = field(default_factory=lambda: ["left_wing"])
    """Driven channels."""
    emac_channels: list[str] = field(default_factory=lambda: list(CHANNELS))
    """Channels that get an EMAC."""
    duration_s: float | None = None
    """Seconds (None: the test's length)."""
    lockstep: bool = False
    """Every node on the suite's clock, frame by frame (``use_sim_time``)."""
    emac_box: bool | None = None
    """Shorthand: True for ``emac="box"``, False for ``emac="channels"``."""
    layout: str = DEFAULT_LAYOUT
    """``single``: every node composed in one process; ``container``: the EMACs, test environment and clock
    composed, the driver in a process of its own; ``processes``: one process per node."""
    emac: str = DEFAULT_EMAC
    """``box``: one EMAC node for every channel; ``channels``: one EMAC node per channel."""
    frame_hz: float = 200.0
    """The FMU frame rate, Hz."""
    domain_id: int | None = None
    """``ROS_DOMAIN_ID`` of the run (None: a free one, :func:`ema_sim.suite.free_domain_id`)."""
    disable: list[str] = field(default_factory=list)
    """Elements switched off (the test environment's and the model's, :mod:`ema_sim.switches`)."""
    window: int = 1
    """Lockstep: frames the clock may run ahead of the slowest EMAC."""
    frames_per_message: int = 1
    """Lockstep, ``processes`` layout: frames the clock grants at once, each node sending them as one message per
    topic (:mod:`ema_msgs_py.batch`; 1: frame by frame, the contract's default)."""
    rt_priority: int = 0
    """Real time: every process at this SCHED_FIFO priority, memory locked, CPUs kept from idle halts."""
    measure_busy: bool = False
    """Composed layouts: account the container thread's time to each node (``busy_s`` in the summaries)."""
    fmu: bool = False
    """Aircraft in the loop: the ``fmu`` node (vehicle and autopilot) drives the suite instead of the maneuver."""
    fmu_args: list[str] = field(default_factory=list)
    """``--open-loop``, ``--bungee INLB``: read once into :attr:`open_loop` and :attr:`bungee_inlb`."""
    open_loop: bool = False
    """Aircraft in the loop: the simulation flies its own model actuators."""
    bungee_inlb: float | None = None
    """Aircraft in the loop: a bungee on the wings, in·lb."""
    seed: int | None = None
    """The test environment's noise seed (default: the profile's)."""
    namespace: str = ""
    """ROS namespace of every node (``/aircraft2``): every topic of the run moves with it."""
    faults: list[str] = field(default_factory=list)
    """Faults the EMACs inject on a schedule (``emac.faults`` specs, times from the channel's start)."""
    respawn: list[str] = field(default_factory=list)
    """Processes restarted when they end before the driver (names of :meth:`processes`, comma lists, ``emacs``
    for every EMAC process of the ``processes`` layout); never the driver's (its end is the run's)."""
    stall_timeout_s: float = 5.0
    """Lockstep: wall seconds the clock waits for a silent EMAC before going on without it (it rejoins when its
    feedback reaches the clock again, :mod:`ema_sim.nodes.clock`)."""

    def __post_init__(self) -> None:
        # `ema` imports this module at every start (commands/launch.py); the switches import python-control
        from ema_sim.faults import parse_fault  # noqa: PLC0415 - loaded when a run is described
        from ema_sim.switches import element_names, environment_elements, model_overrides  # noqa: PLC0415 - 1.2 s

        for spec in self.faults:
            parse_fault(spec)  # a bad spec is one clear error before any node starts

        if self.emac_box is not None:
            self.emac = "box" if self.emac_box else "channels"
        if self.layout not in LAYOUTS:
            raise EmaError(f"unknown layout {self.layout!r}; layouts: {', '.join(LAYOUTS)}")
        if self.emac not in EMAC_HOSTING:
            raise EmaError(f"unknown EMAC hosting {self.emac!r}; give {' or '.join(EMAC_HOSTING)}")
        self.emac_box = self.emac == "box"
        if self.model not in model_names():
            raise UnknownNameError("model", self.model, model_names())
        if not (math.isfinite(self.frame_hz) and self.frame_hz > 0.0):
            raise EmaError(f"the frame rate must be a positive number of Hz, got {self.frame_hz!r}")
        if self.window < 1:
            raise EmaError(f"the lockstep window must be at least one frame, got {self.window}")
        self._check_batches()
        self.disable = list(element_names(self.disable))
        model_overrides(self.model, self.disable)  # dead_band on a model without one: one error
        load_profile(self.profile, disable=environment_elements(self.disable))
        self.channels = channel_list(self.channels or ["left_wing"])
        self.emac_channels = channel_list(self.emac_channels or list(CHANNELS))
        opts = _fmu_options(self.fmu_args)
        self.open_loop = self.open_loop or opts.open_loop
        self.bungee_inlb = self.bungee_inlb if opts.bungee is None else opts.bungee
        self.fmu_args = []
        self.namespace = _namespace(self.namespace)
        self._check_driver()
        if not (math.isfinite(self.stall_timeout_s) and self.stall_timeout_s >= 0.0):
            raise EmaError(f"the stall timeout must be a number of seconds ≥ 0, got {self.stall_timeout_s!r}")
        self.respawn = self._respawned(self.respawn)
        if self.bag is None:
            from ema_sim.nodes.driver import stamped_bag  # noqa: PLC0415 - imports rclpy: only when a bag is named here

            self.bag = stamped_bag(f"ail_{self.profile}" if self.fmu else self.test_name)
        self.bag = Path(self.bag)

    def _check_driver(self) -> None:
        """The driver's part: the aircraft-in-the-loop set-up, or the test and its length."""
        if self.fmu:
            if self.maneuver or self.test:
                raise EmaError("--fmu drives the suite with the vehicle and autopilot: no --maneuver or --test with it")
            if self.duration_s is None or not (math.isfinite(self.duration_s) and self.duration_s > 0.0):
                raise EmaError("the aircraft-in-the-loop run needs a positive duration")
            load_ail_config().setup(self.profile, bungee_inlb=self.bungee_inlb)
            self.emac_channels = list(CHANNELS)
            self.run_s = float(self.duration_s)
            self.test_name = "ail"
        else:
            if self.open_loop or self.bungee_inlb is not None:
                raise EmaError("--open-loop and --bungee belong to the aircraft-in-the-loop run: add --fmu")
            if not (self.maneuver or self.test):
                raise EmaError("give --maneuver SPEC, --test SPEC (ema maneuvers, ema tests) or --fmu "
                               "(aircraft in the loop)")
            plan = build_plan(self.test, maneuver=self.maneuver, load=self.load, channels=self.channels,
                              duration_s=self.duration_s)
            self.run_s = plan.duration_s
            self.test_name = plan.test

    def _check_batches(self) -> None:
        """Several frames a message: lockstep, one process per node, an open-loop driver (one clear error)."""
        k = self.frames_per_message
        if k == 1:
            return
        if not 1 <= k <= 1000:
            why = "a number of frames from 1 to 1000"
        elif not self.lockstep:
            why = "lockstep (--lockstep): in real time each frame is answered as it comes"
        elif self.layout != "processes":
            why = "--layout processes: the composed layouts hand frames over in-process, with nothing to batch"
        elif self.fmu:
            why = "an open-loop driver (a maneuver or test): the aircraft-in-the-loop FMU closes its loop every frame"
        else:
            return
        raise EmaError(f"--frames-per-message {k} needs {why}")

    def _respawned(self, names: list[str]) -> list[str]:
        """The processes to restart, ``emacs`` expanded and each checked (one clear error naming the choices)."""
        procs = [p.name for p in self.processes()]
        choices = [p for p in procs if p != self.driver_process]
        out: list[str] = []
        for name in (n.strip() for item in names for n in item.split(",") if n.strip()):
            if name == "emacs":
                if self.layout != "processes":
                    raise EmaError(f"--respawn emacs needs --layout processes (the {self.layout} layout composes the "
                                   f"EMACs in {procs[0]}); give --respawn {procs[0]} to restart that process")
                picked = [n for n in self.emac_nodes() if n in procs]
            elif name in choices:
                picked = [name]
            else:
                raise EmaError(f"--respawn {name}: no process of this run to restart by that name; give emacs or one "
                               f"of {', '.join(choices)} (the driver, {self.driver_process}, ends the run)")
            out += [n for n in picked if n not in out]
        return out

    # ----------------------------------------------------------------- nodes and processes
    @property
    def bag_dir(self) -> Path:
        """The bag directory: :attr:`bag`, named when the run was made if none was given."""
        if self.bag is None:  # __post_init__ names it: only a caller that set it back to None gets here
            raise EmaError("the run has no bag directory")
        return self.bag

    @property
    def driver(self) -> str:
        """The node that drives the test and records the bag: ``maneuver``, or ``fmu`` in the loop."""
        return "fmu" if self.fmu else "maneuver"

    def emac_nodes(self) -> list[str]:
        """Node names of the EMACs."""
        return ["emac"] if self.emac_box else [f"emac_{c}" for c in self.emac_channels]

    def node_names(self) -> list[str]:
        """Every node of the run (a container's own node aside: it only carries the others' messages)."""
        return [*self.emac_nodes(), "testenv", self.driver, *(["simclock"] if self.lockstep else [])]

    def processes(self) -> list[Process]:
        """The processes of the run's layout, the driver's last (its end is the end of the run)."""
        rt = ("--rt-priority", str(self.rt_priority)) if self.rt_priority > 0 else ()
        clock = ["simclock"] if self.lockstep else []
        if self.layout == "processes":
            out = [Process(n, "emac", (n,), rt) for n in self.emac_nodes()]
            out += [Process("testenv", "testenv", ("testenv",), rt)]
            out += [Process("simclock", "simclock", ("simclock",), rt)] if self.lockstep else []
            return [*out, Process(self.driver, self.driver, (self.driver,), rt)]
        composed = ("testenv", *self.emac_nodes(), *clock)
        if self.layout == "single":
            return [Process("suite", CONTAINER, (*composed, self.driver), rt)]
        return [Process("container", CONTAINER, composed, rt), Process(self.driver, self.driver, (self.driver,), rt)]

    @property
    def driver_process(self) -> str:
        """The process whose end is the end of the test: the driver's (it closes the bag)."""
        return self.processes()[-1].name

    # ----------------------------------------------------------------- parameters
    def parameters(self) -> dict[str, JsonObject]:
        """Node name → its parameters (``ros__parameters``) for this run."""
        from ema_sim.switches import environment_elements  # noqa: PLC0415 - python-control, see __post_init__

        peers = self.node_names()
        common: dict[str, Any] = {"peers": peers}
        if self.frames_per_message > 1:
            common["frames_per_message"] = self.frames_per_message
        sim = {"use_sim_time": True} if self.lockstep else {}
        waited = [*self.emac_nodes(), "testenv"]
        out: dict[str, dict[str, Any]] = {}
        for name in self.emac_nodes():
            chans = self.emac_channels if name == "emac" else [name[len("emac_"):]]
            out[name] = {**common, **sim, "model": self.model, "channels": chans, "disable": self.disable,
                         "emac": {"frame_hz": self.frame_hz,
                                  # a peer's feedback is waited for at most half the clock's stall timeout: a
                                  # live channel waiting on a dead peer steps on and is not left out with it
                                  **({"lockstep_source_wait_s": self.stall_timeout_s / 2} if self.lockstep else {}),
                                  **({"faults": ";".join(self.faults)} if self.faults else {})}}
        out["testenv"] = {**common, **sim, "profile": self.profile, "frame_hz": self.frame_hz,
                          "disable": list(environment_elements(self.disable)),
                          **({"seed": self.seed} if self.seed is not None else {})}
        driver = {**common, **sim, "bag": str(self.bag), "model": self.model, "profile": self.profile,
                  "frame_hz": self.frame_hz, "wait_for": waited}
        if self.fmu:
            out["fmu"] = {**driver, "duration_s": self.run_s,
                          "mode": "open_loop" if self.open_loop else "closed_loop", "disable": self.disable,
                          **({"bungee_inlb": self.bungee_inlb} if self.bungee_inlb is not None else {}),
                          **({"seed": self.seed} if self.seed is not None else {})}
        else:
            out["maneuver"] = {**driver, "channels": self.channels, "command_channels": self.emac_channels,
                               "expect_feedback": [c for c in self.channels if c in self.emac_channels],
                               **{k: v for k, v in (("test", self.test), ("maneuver", self.maneuver),
                                                    ("load", self.load), ("duration_s", self.duration_s))
                                  if v is not None}}
        if self.lockstep:
            out["simclock"] = {**common, "wait_for": [*waited, self.driver], "channels": self.emac_channels,
                               "window": self.window, "duration_s": self.run_s, "frame_hz": self.frame_hz,
                               "stall_timeout_s": self.stall_timeout_s}
        for proc in self.processes():
            if proc.executable == CONTAINER:
                out[CONTAINER] = {**sim, "nodes": list(proc.nodes), "measure_busy": self.measure_busy}
        return {name: {k: v for k, v in params.items() if v != []} for name, params in out.items()}

    def parameter_file(self) -> str:
        """The run's ROS 2 parameter file: a section per node (under the run's namespace)."""
        ns = self.namespace
        doc = {f"{ns}/{name}" if ns else name: {"ros__parameters": params}
               for name, params in self.parameters().items()}
        head = (f"# ema_sim run: {self.test_name} on {', '.join(self.channels)}, {self.model}, profile "
                f"{self.profile}, {'lockstep' if self.lockstep else 'real time'}, layout {self.layout}\n")
        return head + yaml.dump(doc, Dumper=_PlainDumper, sort_keys=False, default_flow_style=None, width=120)

    def write(self, path: str | Path) -> Path:
        """Write :meth:`parameter_file` to ``path``.

        Parameters
        ----------
        path : str or Path
            The file (its directory is created).

        Returns
        -------
        Path
            The file written.
        """
        p = Path(path)
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(self.parameter_file(), encoding="utf-8")
        return p

    def ros_arguments(self, proc: Process, params_file: str | Path) -> list[str]:
        """``--ros-args …`` of one process: the run's parameter file, its node name, the namespace.

        Parameters
        ----------
        proc : Process
            One of :meth:`processes`.
        params_file : str or Path
            Where :meth:`write` put the run's parameter file.

        Returns
        -------
        list[str]
            The arguments, ``--ros-args`` first.
        """
        out = ["--ros-args", "--params-file", str(params_file)]
        if proc.node_name is not None:
            out += ["-r", f"__node:={proc.node_name}"]
        if self.namespace:
            out += ["-r", f"__ns:={self.namespace}"]
        return out


LAUNCH_ARGUMENTS: dict[str, tuple[str, str]] = {
    "model": ("loada", "model of every channel (ema models)"),
    "profile": ("none", "test environment: ail, flight or none"),
    "test": ("", "section-2 test spec (ema tests)"),
    "maneuver": ("", "maneuver spec of the driven channels (ema maneuvers)"),
    "load": ("", "hinge-moment spec of the driven channels"),
    "channels": ("left_wing", "driven channels, comma-separated (all: the five)"),
    "emacs": ("all", "channels that get an EMAC, comma-separated"),
    "emac": (DEFAULT_EMAC, "box: one EMAC node for every channel; channels: one EMAC node per channel"),
    "duration": ("", "seconds (empty: the test's length; 24 with fmu)"),
    "lockstep": ("false", "run on the clock, frame by frame (true/false): the nodes' use_sim_time"),
    "use_sim_time": ("", "ROS's name for lockstep (true/false; empty: lockstep decides)"),
    "window": ("1", "lockstep: frames the clock may run ahead of the slowest EMAC"),
    "frames_per_message": ("1", "lockstep, processes layout: frames granted at once and sent as one message"),
    "bag": ("", "bag directory to create (empty: bags/<test>_<UTC time>)"),
    "disable": ("", "elements switched off, comma-separated (delay, lag, quantization, noise, dead_band...)"),
    "seed": ("", "test-environment noise seed (empty: the profile's)"),
    "rt_priority": ("0", "real time: SCHED_FIFO priority of every process (0: off)"),
    "fmu": ("false", "aircraft in the loop: the fmu node drives the suite (true/false)"),
    "open_loop": ("false", "with fmu: open-loop AIL"),
    "bungee": ("", "with fmu: bungee on the wings, in·lb"),
    "namespace": ("", "ROS namespace of every node, e.g. /aircraft2"),
    "respawn": ("", "processes restarted when they end before the driver, comma-separated (emacs: every EMAC's)"),
    "stall_timeout": ("5", "lockstep: wall seconds the clock waits for a silent EMAC before going on without it"),
    "clock_topic": ("/clock", "the topic the nodes take the lockstep clock from (/clock, ROS's; a relative name such "
                              "as clock: one clock per namespace, for two vehicles in lockstep on one graph)"),
}
"""The launch files' arguments (``ros2 launch ema_sim single.launch.py maneuver:=step``): ``ema launch``'s options."""


def from_launch_arguments(values: dict[str, str], layout: str) -> RunDescription:
    """A run from launch arguments (strings, as ``ros2 launch`` gives them); the same checks as ``ema launch``.

    Parameters
    ----------
    values : dict[str, str]
        Launch argument → its value (:data:`LAUNCH_ARGUMENTS`; a missing one takes its default).
    layout : str
        One of :data:`LAYOUTS` (the launch file's).

    Returns
    -------
    RunDescription
        The run, validated.

    Raises
    ------
    EmaError
        A flag that is not true or false, a number that is not one, or any check of :class:`RunDescription`.
    """
    def text(name: str) -> str:
        return str(values.get(name, LAUNCH_ARGUMENTS[name][0])).strip()

    def flag(name: str) -> bool:
        value = text(name).lower()
        if value not in ("true", "false"):
            raise EmaError(f"launch argument {name}: true or false, got {value!r}")
        return value == "true"

    def number(name: str) -> float | None:
        value = text(name)
        try:
            return float(value) if value else None
        except ValueError:
            raise EmaError(f"launch argument {name}: a number, got {value!r}") from None

    fmu = flag("fmu")
    lockstep = flag("lockstep")
    if text("use_sim_time"):
        sim = flag("use_sim_time")
        if lockstep and not sim:
            raise EmaError("launch arguments lockstep:=true and use_sim_time:=false disagree (use_sim_time is "
                           "lockstep's ROS name: give one)")
        lockstep = sim
    duration = number("duration")
    seed = number("seed")
    stall = number("stall_timeout")
    return RunDescription(
        bag=Path(text("bag")) if text("bag") else None, model=text("model"), profile=text("profile"),
        test=text("test") or None, maneuver=text("maneuver") or None, load=text("load") or None,
        channels=[text("channels")], emac_channels=[text("emacs")], emac=text("emac"),
        duration_s=24.0 if fmu and duration is None else duration, lockstep=lockstep,
        window=int(number("window") or 1), frames_per_message=int(number("frames_per_message") or 1),
        layout=layout, disable=[text("disable")],
        seed=None if seed is None else int(seed), rt_priority=int(number("rt_priority") or 0), fmu=fmu,
        open_loop=flag("open_loop"), bungee_inlb=number("bungee"), namespace=text("namespace"),
        respawn=[text("respawn")] if text("respawn") else [], stall_timeout_s=5.0 if stall is None else stall,
    )

