"""``emac``: one EMAC channel (or an EMAC box of several) on the topic contract.

Subscribes to ``/ema/emac/command`` (its FMU command, after the test environment) and
``/ema/load/hinge_moment``; publishes ``/ema/emac/feedback`` (LVDT position and motor current, V and A),
``/ema/sensor/surface`` (the external sensor's surface angle) and, for models with a motor,
``/ema/sensor/bus``, once per FMU frame. Two clocks:

* real time: each command message is one frame, stepped and answered at once (the FMU's frame is
  the clock); when no command comes for :data:`IDLE_AFTER_FRAMES` frames the channel steps on with the
  held command and the watchdog brakes it after ``watchdog_timeout_s``. Every frame is stepped once: a
  command that comes after its frame was stepped without it is applied from the next frame and counted
  (``late_commands``), and the feedback stamps increase strictly. The command stamps are judged by
  :class:`ema_sim.emac.stamps.CommandClock`: an out-of-order or implausibly future stamp is dropped and
  counted, and after ``emac.resync_commands`` consecutive commands of a clock that moved (an FMU restart)
  the node follows them (``command_resyncs``, a WARN line);
* lockstep (``use_sim_time``): the model advances exactly one frame per frame of ``/clock``, with the
  inputs stamped for that frame; it waits for them while their publishers are alive, so a run is
  reproducible whatever the machine's load. A ``/clock`` that jumps backwards (a reset, a replay)
  restarts the node's time base there (``clock_resets``, a WARN line), the brake engaged until the new
  time's commands come.

Run-time failures: ``std_msgs/String`` on ``/ema/emac/<channel>/failure`` or the ``emac.failure``
parameter (``stuck``, ``hard_over:direction=-1``, ``zero``, ``power_loss``, ``stall``, ``none``).
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Sequence
from typing import Any, Unpack

from rclpy.impl.implementation_singleton import rclpy_implementation
from rclpy.lifecycle import LifecycleNodeMixin, LifecycleState, TransitionCallbackReturn
from rclpy.publisher import Publisher
from rclpy.subscription import Subscription

from ema_sim.emac.stamps import CommandClock, FrameGate
from ema_sim.errors import EmaError
from ema_sim.models import create
from ema_sim.nodes.common import NodeOptions, command_line, run
from ema_sim.nodes.emac_frames import CATCH_UP, EmacFrames
from ema_sim.nodes.emac_params import channel_specs, default_name, emac_specs, node_specs
from ema_sim.nodes.emac_receive import LOCKSTEP_LEAD_FRAMES
from ema_sim.nodes.emac_state import DROPS, FAULT_HOLD_S, IDLE_AFTER_FRAMES, NS
from ema_sim.nodes.emac_streams import SourceStream, Stream
from ema_sim.nodes.params import file_entries, key_matches, names_list, params_files, remapped
from ema_sim.nodes.ports import Ports, PortsFactory
from ema_sim.signals.plans import channel_list

__all__ = [
    "CATCH_UP",
    "DROPS",
    "FAULT_HOLD_S",
    "IDLE_AFTER_FRAMES",
    "LOCKSTEP_LEAD_FRAMES",
    "NS",
    "EmacNode",
    "ManagedEmacNode",
    "SourceStream",
    "Stream",
    "channel_specs",
    "default_name",
    "emac_specs",
    "main",
    "node",
    "node_specs",
    "parser",
    "warm",
]


class EmacNode(EmacFrames):
    """The node (see the module docstring).

    Parameters
    ----------
    args : argparse.Namespace or None
        The command line's flags (parameter overrides; ``channels`` is resolved here).
    ports : callable
        How per-frame messages travel (:class:`~ema_sim.nodes.ports.Ports`, or a container's).
    name : str or None
        The node's name (None: from the channels, :func:`~ema_sim.nodes.emac_params.default_name`).
    **options : NodeOptions
        rclpy node options (``context``, ``cli_args``...), as a process's ROS arguments give them.

    Raises
    ------
    EmaError
        A configuration error (logged at FATAL through the node's logger, and the node destroyed, first).
    """

    def __init__(self, args: argparse.Namespace | None = None, ports: PortsFactory = Ports, name: str | None = None,
                 **options: Unpack[NodeOptions]) -> None:
        """The node, built from its parameters (see the class docstring for the arguments)."""
        flag = channel_list(getattr(args, "channels", None) or []) or None
        argv = command_line(options)
        if name is None:
            name = default_name(flag, argv, options.get("namespace"))
        super().__init__(name, args, exclude=("channels",), **options)
        try:
            self._build(flag, argv, ports)
        except BaseException as exc:  # a user error (one line, from run) or a bug: the node leaves the graph first
            if isinstance(exc, EmaError):  # through its logger (/rosout) before it goes
                self.fatal(str(exc))
                exc.logged = True  # type: ignore[attr-defined]
            self.destroy_node()
            raise

    def _build(self, flag: list[str] | None, argv: list[str], ports: PortsFactory) -> None:
        """The node's state (:meth:`_build_state`), then its topics and run-time parameters."""
        self._build_state(flag, argv, ports)
        if self.configured:
            self._make_topics()
        self._on_changes()
        self.get_logger().info(
            f"{self.model_name} on {', '.join(self.channels)}; {'lockstep' if self.lockstep else 'real time'} at "
            f"{self.settings.frame_hz:g} Hz; watchdog {self.settings.watchdog_timeout_s * 1e3:g} ms")
        if self.lockstep and self.sources and not self.source_fb.expected:
            self.get_logger().warning(
                f"lockstep: no emac_<channel> peers name the crosstalk sources ({', '.join(self.sources)}); each "
                "frame takes whichever source feedback has come, so the crosstalk may differ from run to run")



RCLError = rclpy_implementation.RCLError
"""What rcl's lifecycle state machine raises on a transition it does not have."""


class ManagedEmacNode(LifecycleNodeMixin, EmacNode):
    """The EMAC node as a managed (lifecycle) node: ``emac --lifecycle``.

    Constructed *unconfigured*: parameters declared and models built (so ``ros2 param`` works and the first
    frame does not compile), but no topic. ``configure`` makes its publishers and subscriptions (*inactive*):
    inputs are dropped, no frame is stepped and nothing is published, so the surface stays where it is, the
    brake held. ``activate`` starts a new time base: the brake stays engaged until a fresh command comes (as at
    start-up), then frames are stepped and published as by :class:`EmacNode`. ``deactivate`` stops them again;
    ``cleanup`` removes the topics; ``shutdown`` ends the process. The transitions are served by the standard
    lifecycle services (``<node>/change_state``, ``<node>/get_state``...), on the node's own executor loop.

    Parameters
    ----------
    args : argparse.Namespace or None
        The command line's flags (parameter overrides).
    ports : callable
        How per-frame messages travel (:class:`~ema_sim.nodes.ports.Ports`).
    name : str or None
        The node's name (None: from the channels, :func:`~ema_sim.nodes.emac_params.default_name`).
    **options : NodeOptions
        rclpy node options (``context``, ``cli_args``).
    """

    managed = True

    def __init__(self, args: argparse.Namespace | None = None, ports: PortsFactory = Ports, name: str | None = None,
                 **options: Unpack[NodeOptions]) -> None:
        EmacNode.__init__(self, args, ports, name, **options)
        LifecycleNodeMixin.__init__(self)
        self._lifecycle_entities: list[Publisher | Subscription] = []
        service = self._service_change_state
        change = service.callback

        def guarded(request: Any, response: Any) -> Any:
            # rclpy's own callback raises on a transition the present state lacks (activate while unconfigured),
            # which would end the process: the request is refused instead, as rclcpp refuses it
            try:
                return change(request, response)
            except RCLError as exc:
                self.get_logger().warning(f"lifecycle transition {request.transition.id} "
                                          f"{request.transition.label!r} refused: {exc}")
                response.success = False
                return response

        service.callback = guarded

    def check_ready(self) -> None:
        """Announce readiness only once active (a managed node's topics come at ``configure``)."""
        if self.active:
            super().check_ready()

    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Make the topics (publishers and subscriptions); inactive: nothing stepped or published.

        Parameters
        ----------
        state : LifecycleState
            The state before the transition.

        Returns
        -------
        TransitionCallbackReturn
            SUCCESS.
        """
        pubs, subs = set(self.publishers), set(self.every_subscription())
        self._make_topics()
        self._lifecycle_entities = [*(p for p in self.publishers if p not in pubs),
                                    *(s for s in self.every_subscription() if s not in subs)]
        self.configured = True
        self._publish_diagnostics()  # inactive: brake held
        self.get_logger().info(f"configured from {state.label}: topics up, inactive (brake held, no feedback)")
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Step and publish from now on, the brake engaged until a fresh command comes.

        Parameters
        ----------
        state : LifecycleState
            The state before the transition.

        Returns
        -------
        TransitionCallbackReturn
            SUCCESS.
        """
        self._new_time_base()
        self.active = True
        self._diagnose_now = True
        self.get_logger().info(f"activated from {state.label}: stepping frames, brake engaged until a command comes")
        return TransitionCallbackReturn.SUCCESS

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Stop stepping and publishing; inputs are dropped until activated again.

        Parameters
        ----------
        state : LifecycleState
            The state before the transition.

        Returns
        -------
        TransitionCallbackReturn
            SUCCESS.
        """
        self.active = False
        self._publish_diagnostics()
        self.get_logger().info(f"deactivated from {state.label}: no frames, brake held")
        return TransitionCallbackReturn.SUCCESS

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Remove the topics made at ``configure`` (unconfigured again; the models keep their state).

        Parameters
        ----------
        state : LifecycleState
            The state before the transition.

        Returns
        -------
        TransitionCallbackReturn
            SUCCESS.
        """
        self._drop_topics()
        self.get_logger().info(f"cleaned up from {state.label}: topics removed")
        return TransitionCallbackReturn.SUCCESS

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Stop: the process ends after this transition's answer (its summary printed and logged).

        Parameters
        ----------
        state : LifecycleState
            The state before the transition.

        Returns
        -------
        TransitionCallbackReturn
            SUCCESS.
        """
        self.active = False
        self.done = True
        self.get_logger().info(f"shut down from {state.label}")
        return TransitionCallbackReturn.SUCCESS

    def close(self) -> None:  # noqa: D102
        super().close()
        self._drop_topics()

    def _drop_topics(self) -> None:
        for entity in self._lifecycle_entities:
            if isinstance(entity, Publisher):
                self.destroy_publisher(entity)
            else:
                self.destroy_subscription(entity)
        self._lifecycle_entities = []
        self.configured = False

    def _new_time_base(self) -> None:
        """Forget the frames and inputs of before: the next command starts the frames; brake until it comes."""
        for s in self._stream_list:
            s.queue.clear()
            s.last_stamp = None
            s.waiting_since = None
            s.gave_up = False
        self.model_ns = None
        self.clock_ns = None
        self.last_clock_topic_ns = None
        self.first_command = True
        self.last_good_ns = dict.fromkeys(self.channels)
        self.last_good_wall = dict.fromkeys(self.channels)
        self.command_clock = CommandClock(self.frame_ns, self.settings.stamp_tolerance_s,
                                          self.settings.resync_commands)
        late, self.gate = self.gate.late, FrameGate(self.frame_ns, self.settings.resync_commands)
        self.gate.late = late
        self.last_step_wall = time.monotonic()
        self.next_idle = self.last_step_wall + IDLE_AFTER_FRAMES * self.frame_s


def parser() -> argparse.ArgumentParser:
    """Command-line flags: shorthands for the node's parameters (ROS arguments go after ``--ros-args``)."""
    p = argparse.ArgumentParser(prog="emac", description="One EMAC channel (or several: an EMAC box).",
                                argument_default=argparse.SUPPRESS)
    p.add_argument("--model", help="parameter model: model name (ema models); default loada")
    p.add_argument("--channel", dest="channels", action="append", type=names_list,
                   help="parameter channels: channel (repeatable, comma-separated, or 'all' for an EMAC box of five)")
    p.add_argument("--rate", dest="rate_hz", type=float, help="parameter rate_hz: integration rate of a discrete "
                   "model, Hz")
    p.add_argument("--frame-hz", dest="emac.frame_hz", type=float, help="parameter emac.frame_hz: FMU frame rate "
                   "(default from config/emac.yaml)")
    p.add_argument("--disable", action="append", type=names_list,
                   help="parameter disable: switch the model's own elements off: dead_band (the PWM's), quantization, "
                        "noise (others, the test environment's, are accepted and left to it)")
    p.add_argument("--lifecycle", action="store_true", help="a managed (lifecycle) node: unconfigured until told "
                   "(configure, activate, deactivate, cleanup, shutdown through <node>/change_state)")
    return p


def node(args: argparse.Namespace) -> EmacNode:
    """The node a command line asks for: an :class:`EmacNode`, or with ``--lifecycle`` a :class:`ManagedEmacNode`.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed flags (``lifecycle`` is taken out; the others are parameter overrides).

    Returns
    -------
    EmacNode
        The node.
    """
    return (ManagedEmacNode if vars(args).pop("lifecycle", False) else EmacNode)(args)


def warm(argv: Sequence[str]) -> None:
    """Load the kernels of the model a command line chooses, ahead of need: a standby's head start.

    Numba's cached kernels take most of an EMAC's construction (1.5 of 2.6 s for HOAD3 on a busy machine), so
    a standby (:mod:`ema_sim.nodes.standby`) builds the model once, and the node it becomes builds its own at
    once. The model and channels are those the flags give, or the parameter files' sections for the node's
    name (``-r __node:=``), as the node would find them; the node itself still checks them when it starts.

    Parameters
    ----------
    argv : sequence of str
        The node's command line (ROS arguments included).
    """
    flags, _ = parser().parse_known_args(list(argv))
    model: object = getattr(flags, "model", None)
    channels: object = [c for group in getattr(flags, "channels", []) for c in group]
    name = remapped(argv, "__node")
    for path in params_files(argv):
        for key, params in file_entries(path):
            if key_matches(key, f"/{name or 'emac'}"):
                model = params.get("model", model)
                channels = params.get("channels", params.get("channel", channels))
    channels = [channels] if isinstance(channels, str) else channels
    step_s = 1.0 / 200.0
    for channel in channels if isinstance(channels, list) and channels else ["left_wing"]:
        create(str(model or "loada"), str(channel)).step_values(0.0, 0.0, step_s)


def main(argv: Sequence[str] | None = None) -> int:
    """Console script ``emac``.

    Parameters
    ----------
    argv : sequence of str or None
        The arguments (None: the process's).

    Returns
    -------
    int
        The exit status.
    """
    return run(node, parser(), argv)


if __name__ == "__main__":
    raise SystemExit(main())
