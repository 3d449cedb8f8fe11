"""``ema launch``: the node suite from one command (five EMACs, test environment, clock, maneuver or fmu)."""

from __future__ import annotations

import argparse
import signal
import sys
from collections.abc import Callable
from pathlib import Path
from types import FrameType
from typing import TYPE_CHECKING

from ema_sim.ail.bag import run_from_bag
from ema_sim.ail.measure import DITHER_MIN_PP_DEG, measure
from ema_sim.ail.params import load_ail_config
from ema_sim.commands.common import Subparsers
from ema_sim.emac.failures import failure_help
from ema_sim.io.bag import bag_info
from ema_sim.run import DEFAULT_EMAC, DEFAULT_LAYOUT, EMAC_HOSTING, LAYOUTS, RunDescription
from ema_sim.signals.plans import test_help
from ema_sim.suite import Suite

if TYPE_CHECKING:
    from ema_sim.io.bag.reader import BagInfo


def _config(args: argparse.Namespace) -> tuple[RunDescription, str, str, float]:
    """The run's description (validated once, as it is made), what it is, on what, for how long."""
    cfg = RunDescription(
        bag=Path(args.bag) if args.bag else None, model=args.model, profile=args.profile, test=args.test,
        maneuver=args.maneuver, load=args.load, channels=args.channels, emac_channels=args.emacs,
        duration_s=24.0 if args.fmu and args.duration is None else args.duration, lockstep=args.lockstep,
        layout=args.layout, emac="box" if args.emac_box else args.emac, domain_id=args.domain_id,
        disable=args.disable, rt_priority=args.rt_priority, window=args.window, fmu=args.fmu,
        frames_per_message=args.frames_per_message,
        open_loop=args.open_loop, bungee_inlb=args.bungee, seed=args.seed, namespace=args.namespace,
        faults=args.fault, respawn=args.respawn, stall_timeout_s=args.stall_timeout,
    )
    what = "every channel, with the vehicle and autopilot in the loop" if args.fmu else ", ".join(cfg.channels)
    return cfg, cfg.test_name, what, cfg.run_s


def run(args: argparse.Namespace) -> int:
    """Bring the suite up, run the test, bring it down; print where the bag is and what it holds.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line (the options :func:`register` adds).

    Returns
    -------
    int
        The exit status: 0, or 130 when interrupted (the bag is closed either way).
    """
    cfg, test, what, duration = _config(args)
    bag = cfg.bag_dir
    suite = Suite(cfg)
    mode = "lockstep" if args.lockstep else "real time"
    try:  # from the handlers on, a signal anywhere here (its first line printed or not) stops the suite
        for signum in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):  # each stops the suite the same way, the
            signal.signal(signum, _interrupt)  # bag closed (SIGHUP: the terminal closed; SIGKILL: nodes.lifetime)
        suite.check_names()  # nodes of the run's names already running: one error before anything is started
        print(f"ema launch: {test} on {what} for {duration:g} s, {args.model}, profile {args.profile}, {mode}, "
              f"ROS_DOMAIN_ID {suite.domain_id}; logs and the run's parameters ({suite.params_file.name}) in "
              f"{suite.log_dir}", flush=True)
        suite.run(args.timeout)
    except KeyboardInterrupt:  # the suite is stopped: the bag is closed
        print("ema launch: interrupted; closing the bag", file=sys.stderr)
        _report(suite, bag, bag_info)
        return 130
    _report(suite, bag, bag_info)
    if args.fmu:
        _report_dither(bag)
    return 0


def _interrupt(signum: int, frame: FrameType | None) -> None:  # noqa: ARG001
    raise KeyboardInterrupt


def _report(suite: Suite, bag: Path, bag_info: Callable[[Path], BagInfo]) -> None:
    sums = suite.summaries()
    if bag.exists():
        info = bag_info(bag)
        print(f"bag {bag}: {info.message_count} messages over {info.duration_s:.2f} s; "
              f"channels {', '.join(info.channels) or 'none'}")
    clock = sums.get("simclock")
    if clock and clock.get("wall_s"):
        print(f"lockstep: {clock['sim_s']:.2f} s simulated in {clock['wall_s']:.2f} s "
              f"({clock['realtime_factor']:.2f}× real time, {clock['stalls']} stalls)")
        if clock.get("left_out"):
            print(f"lockstep: {clock['left_out']} channel(s) left out after stall_timeout_s, {clock['rejoined']} "
                  f"rejoined (after {', '.join(f'{s:.2f}' for s in clock['rejoin_s']) or '-'} s); out at the end: "
                  f"{', '.join(clock['out_of_lockstep']) or 'none'}")
    for name, count in suite.restarts.items():
        print(f"{name}: restarted {count} time(s) (--respawn)")
    man = sums.get(suite.driver, {})
    if "latency_p99_ms" in man:
        print(f"real time: command-to-feedback latency p50 {man['latency_p50_ms']:.2f} ms, "
              f"p99 {man['latency_p99_ms']:.2f} ms, max {man['latency_max_ms']:.2f} ms; "
              f"{man['missed_frames']} missed frames of {man['frames']}")


def _report_dither(bag: Path) -> None:
    """Each surface's limit cycle in the recorded run, as ``ema ail`` prints it."""
    run = run_from_bag(bag)
    settle = load_ail_config().settle_s
    if run.time_s[-1] < settle + 4.0:
        print(f"dither: not measured (needs {settle + 4.0:g} s of run; the bag has {run.time_s[-1]:.2f} s)")
        return
    print(f"LVDT position after {settle:g} s (dither: a peak ≥ 15 dB above the floor and ≥ {DITHER_MIN_PP_DEG:g}° "
          "peak to peak):")
    for ch, d in measure(run, settle).items():
        print(f"  {ch:13s} {d.statement}")


def register(sub: Subparsers) -> None:
    """Add ``launch`` (and ``tests``, the list of section-2 tests) to the ``ema`` parser.

    Parameters
    ----------
    sub : Subparsers
        ``ema``'s subcommands (:func:`ema_sim.cli.build_parser`).
    """
    p = sub.add_parser("launch", help="run the ROS 2 node suite: five EMACs, test environment, clock, maneuver",
                       description="Bring up the five EMAC channels, the test environment, (lockstep) the clock "
                                   "and the maneuver node, run one test, record the bag, stop.")
    p.add_argument("--model", default="loada", help="model of every channel (ema models)")
    p.add_argument("--profile", default="none", help="test environment: ail, flight or none")
    p.add_argument("--maneuver", default=None, help="maneuver spec of the driven channels (ema maneuvers)")
    p.add_argument("--test", default=None, help="section-2 test spec (ema tests), e.g. static_crosstalk")
    p.add_argument("--load", default=None, help="hinge-moment spec of the driven channels")
    p.add_argument("--channels", action="append", default=[], help="driven channels (default left_wing; all)")
    p.add_argument("--emacs", action="append", default=[], help="channels that get an EMAC (default all five)")
    p.add_argument("--duration", type=float, default=None, help="seconds (default: the test's length)")
    p.add_argument("--lockstep", action="store_true", help="run on /clock, frame by frame, as fast as possible")
    p.add_argument("--bag", default=None, help="bag directory to create (default bags/<test>_<time>)")
    p.add_argument("--layout", choices=LAYOUTS, default=DEFAULT_LAYOUT,
                   help="single (default): every node composed in one process; container: EMACs, test "
                        "environment and clock composed, the maneuver in its own process; processes: one process "
                        "per node")
    p.add_argument("--emac", choices=EMAC_HOSTING, default=DEFAULT_EMAC,
                   help="box (default): one EMAC node hosting the five channels, as the real EMAC is one box; "
                        "channels: one EMAC node per channel")
    p.add_argument("--emac-box", action="store_true", help="shorthand for --emac box")
    p.add_argument("--window", type=int, default=1,
                   help="lockstep: frames the clock may run ahead of the slowest EMAC (1: strictly frame by frame)")
    p.add_argument("--frames-per-message", type=int, default=1, metavar="K",
                   help="lockstep, --layout processes: the clock grants K frames at once and each node sends them as "
                        "one message per topic (fewer messages, the same frames in the bag; 1: frame by frame)")
    p.add_argument("--respawn", action="append", default=[], metavar="PROCESS",
                   help="restart this process when it ends before the driver (repeatable, comma-separated; emacs: "
                        "every EMAC process of --layout processes)")
    p.add_argument("--stall-timeout", type=float, default=5.0, metavar="S",
                   help="lockstep: wall seconds the clock waits for a silent EMAC before going on without it "
                        "(it rejoins when its feedback reaches the clock again; default 5)")
    p.add_argument("--fault", action="append", default=[], metavar="KIND:FIELD=VALUE,...",
                   help="a fault the EMACs inject on a schedule (repeatable; docs/monitor.md); its truth is "
                        "recorded on /ema/faults/truth")
    p.add_argument("--disable", action="append", default=[],
                   help="switch an element off: the test environment's delay, lag, quantization, noise (or one "
                        "path's, command.delay...) and the model's dead_band")
    p.add_argument("--domain-id", type=int, default=None, help="ROS_DOMAIN_ID (default: the environment's, "
                   "else one derived from the pid)")
    p.add_argument("--rt-priority", type=int, default=0,
                   help="real time: every node at this SCHED_FIFO priority, memory locked, "
                        "idle CPUs polling instead of halting (0: off)")
    p.add_argument("--namespace", default="", help="ROS namespace of every node, e.g. /aircraft2 (every topic of "
                   "the run moves with it; default: none)")
    p.add_argument("--timeout", type=float, default=None, help="give up after this many wall seconds")
    p.add_argument("--fmu", action="store_true",
                   help="aircraft in the loop: the fmu node (vehicle, autopilot, hinge moments) drives the suite "
                        "instead of a maneuver (config/ail_vehicle.yaml; default 24 s)")
    p.add_argument("--open-loop", action="store_true", help="with --fmu: open-loop AIL (a model actuator flies)")
    p.add_argument("--bungee", type=float, default=None, metavar="INLB", help="with --fmu: bungee on the wings")
    p.add_argument("--seed", type=int, default=None, help="test-environment noise seed (default: the profile's)")
    p.set_defaults(func=run)
    t = sub.add_parser("tests", help="list the section-2 tests the maneuver node drives")
    t.set_defaults(func=_tests)


def _tests(args: argparse.Namespace) -> int:  # noqa: ARG001
    print("tests (--test name[:field=value,...]):")
    print(test_help())
    print("\nfailures (std_msgs/String on /ema/emac/<channel>/failure, or the emac.failure parameter):")
    print(failure_help())
    return 0
