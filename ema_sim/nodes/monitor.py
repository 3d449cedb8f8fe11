"""``ema_monitor``: a lifecycle node watching EMAC channels against their reference model.

A thin adapter over :class:`ema_sim.monitor.online.OnlineMonitor`. It reads the EMAC's input command
(``/ema/emac/command``, V), the hinge moment (``/ema/load/hinge_moment``) and the LVDT feedback and motor current
(``/ema/emac/feedback``, V and A), converts them with each channel's scaling, and steps one monitor per channel at
each feedback frame. It publishes ``/diagnostics`` once a second (OK while watching, WARN while the healthy window
calibrates, ERROR after a detection, with the statistic, threshold and the last detection's key values) and each
detection as JSON on ``/ema/monitor/detections``. After a detection a channel's monitor re-baselines (its
reference adopts the re-estimated fault) and watches on, so a second fault is detected and published too.
Constructed unconfigured: ``configure`` makes its topics, ``activate`` starts watching, ``deactivate`` stops,
``cleanup`` removes them. The reference is a fidelity or an ``ema identify`` report (``model``); a model learned on
the healthy window is the offline command's (``ema monitor``), not the node's.
"""

from __future__ import annotations

import argparse
import json
import math
import time
from collections.abc import Sequence
from typing import Unpack

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import ParameterType
from rclpy.lifecycle import LifecycleNodeMixin, LifecycleState, TransitionCallbackReturn
from rclpy.publisher import Publisher
from rclpy.subscription import Subscription
from std_msgs.msg import String

from ema_msgs_py import contract as ct
from ema_msgs_py.cdr import JointFrame
from ema_msgs_py.contract import scaling_of
from ema_msgs_py.ros import qos
from ema_sim.config import load_channel
from ema_sim.jsontypes import JsonObject
from ema_sim.models import model_names
from ema_sim.monitor import Options, from_name, from_report
from ema_sim.monitor.online import OnlineMonitor
from ema_sim.nodes.common import NodeOptions, SuiteNode, run
from ema_sim.nodes.params import Spec, names_list
from ema_sim.nodes.ports import Ports, PortsFactory


class MonitorNode(LifecycleNodeMixin, SuiteNode):
    """The node (see the module docstring).

    Parameters
    ----------
    args : argparse.Namespace or None
        The flags given on the node's command line (parameter overrides).
    ports : callable
        Builds the node's topic ports (:class:`~ema_sim.nodes.ports.Ports`).
    name : str
        The node's name.
    options : NodeOptions
        Passed on to :class:`~ema_sim.nodes.common.SuiteNode` (its hosting options).
    """

    def __init__(self, args: argparse.Namespace | None = None, ports: PortsFactory = Ports, name: str = "ema_monitor",
                 **options: Unpack[NodeOptions]) -> None:
        SuiteNode.__init__(self, name, args, **options)
        LifecycleNodeMixin.__init__(self)
        p = self.params.declare([
            Spec("channels", ["left_wing"], "channels watched", kind=ParameterType.PARAMETER_STRING_ARRAY),
            Spec("model", "loada", "reference: a fidelity (ema models) or an ema identify report"),
            Spec("healthy_s", 30.0, "first seconds stated healthy (residual spread)", "s", 1.0, 3600.0),
            Spec("false_alarms_per_hour", 0.1, "detector design rate", "1/h", 1e-6, 1e4),
            Spec("block_s", 0.02, "residual block", "s", 0.001, 1.0),
            Spec("window_s", 5.0, "isolation window after an alarm", "s", 0.5, 60.0),
            Spec("frame_hz", ct.FRAME_HZ, "FMU frame rate", "Hz", 1.0, 1e5),
        ], name)
        self.ports_factory = ports
        self.frame_s = 1.0 / p["frame_hz"]
        opts = Options(healthy_s=p["healthy_s"], false_alarms_per_hour=p["false_alarms_per_hour"],
                       block_s=p["block_s"], window_s=p["window_s"])
        self.monitors: dict[str, OnlineMonitor] = {}
        self.scalings = {}
        for ch in p["channels"]:
            cfg = load_channel(ch)
            ref = from_name(p["model"], cfg) if p["model"] in model_names() else from_report(p["model"], cfg)
            self.monitors[ch] = OnlineMonitor(ref, opts, self.frame_s)
            self.scalings[ch] = scaling_of(cfg)
        self.command: dict[str, float] = {}
        self.load: dict[str, float] = {}
        self.active = False
        self.cpu_s = 0.0
        self.frames = 0
        self._next_diag = 0.0
        self._entities: list[Publisher | Subscription] = []

    # ----------------------------------------------------------------- lifecycle
    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:  # noqa: ARG002
        """Make the topics; inactive: frames are dropped.

        Parameters
        ----------
        state : LifecycleState
            The lifecycle state the transition starts from.
        """
        pubs, subs = set(self.publishers), set(self.every_subscription())
        self.ports = self.ports_factory(self)
        self.diag_pub = self.create_publisher(DiagnosticArray, ct.endpoint(ct.DIAGNOSTICS), qos(ct.EVENT_QOS))
        self.det_pub = self.create_publisher(String, ct.endpoint(ct.MONITOR_DETECTIONS), qos(ct.EVENT_QOS))
        self.ports.frame_subscription(ct.EMAC_COMMAND, self._on_command, self._bad)
        self.ports.frame_subscription(ct.HINGE_MOMENT, self._on_load, self._bad)
        self.ports.frame_subscription(ct.EMAC_FEEDBACK, self._on_feedback, self._bad)
        self._entities = [*(x for x in self.publishers if x not in pubs),
                          *(x for x in self.every_subscription() if x not in subs)]
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:  # noqa: ARG002
        """Start watching.

        Parameters
        ----------
        state : LifecycleState
            The lifecycle state the transition starts from.
        """
        self.active = True
        return TransitionCallbackReturn.SUCCESS

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:  # noqa: ARG002
        """Stop watching (frames dropped).

        Parameters
        ----------
        state : LifecycleState
            The lifecycle state the transition starts from.
        """
        self.active = False
        return TransitionCallbackReturn.SUCCESS

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:  # noqa: ARG002
        """Remove the topics.

        Parameters
        ----------
        state : LifecycleState
            The lifecycle state the transition starts from.
        """
        for e in self._entities:
            if isinstance(e, Publisher):
                self.destroy_publisher(e)
            else:
                self.destroy_subscription(e)
        self._entities = []
        return TransitionCallbackReturn.SUCCESS

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:  # noqa: ARG002
        """End the process.

        Parameters
        ----------
        state : LifecycleState
            The lifecycle state the transition starts from.
        """
        self.done = True
        return TransitionCallbackReturn.SUCCESS

    # ----------------------------------------------------------------- frames
    def _bad(self, text: str) -> None:
        self.throttled("drop", f"message dropped: {text}")

    def _on_command(self, msg: JointFrame) -> None:
        for i, ch in enumerate(msg.name):
            if ch in self.monitors and i < len(msg.position):
                self.command[ch] = self.scalings[ch].command_v_to_deg(float(msg.position[i]))

    def _on_load(self, msg: JointFrame) -> None:
        for i, ch in enumerate(msg.name):
            if ch in self.monitors and i < len(msg.effort):
                self.load[ch] = float(msg.effort[i])

    def _on_feedback(self, msg: JointFrame) -> None:
        if not self.active:
            return
        t0 = time.process_time()
        for i, ch in enumerate(msg.name):
            mon = self.monitors.get(ch)
            if mon is None or i >= len(msg.position) or ch not in self.command:
                continue
            pos = self.scalings[ch].feedback_v_to_deg(float(msg.position[i]))
            if not (math.isfinite(pos) and math.isfinite(self.command[ch])):
                continue
            cur = float(msg.effort[i]) if i < len(msg.effort) else math.nan
            d = mon.step(self.command[ch], self.load.get(ch, 0.0), pos, current_a=cur)
            if d is not None:
                out = String()
                out.data = json.dumps({"channel": ch, **d.as_dict()}, allow_nan=False)
                self.det_pub.publish(out)
                self.get_logger().warning(f"{ch}: {d.kind} at {d.time_s:.3f} s ({d.parameter} = {d.estimate:.4g})")
        self.frames += 1
        self.mark_running()
        self.cpu_s += time.process_time() - t0
        now = time.monotonic()
        if now >= self._next_diag:
            self._next_diag = now + 1.0
            self.diag_pub.publish(self.diagnostics())

    def diagnostics(self) -> DiagnosticArray:
        """One status per channel: WARN calibrating, OK watching, ERROR after a detection."""
        msg = DiagnosticArray()
        msg.header.stamp = self.get_clock().now().to_msg()
        for ch, mon in self.monitors.items():
            d = mon.detection
            level = DiagnosticStatus.ERROR if d is not None else (
                DiagnosticStatus.OK if mon.calibrated else DiagnosticStatus.WARN)
            text = ("alarm: isolating" if mon.alarm is not None and d is None else
                    f"{d.kind}: {d.parameter} = {d.estimate:.4g}" if d is not None else
                    "watching" if mon.calibrated else "calibrating on the healthy window")
            values = {"reference": mon.reference.origin, "statistic": f"{mon.statistic:.3f}",
                      "threshold": f"{mon.h:.3f}", "time_s": f"{mon.t:.3f}",
                      "cpu_share": f"{self.cpu_s / max(self.frames * self.frame_s, 1e-9) / len(self.monitors):.4f}"}
            if d is not None:
                values.update({k: str(v) for k, v in d.as_dict().items() if k not in ("ranking", "signature")})
                values["detections"] = str(len(mon.detections))
            msg.status.append(DiagnosticStatus(level=level, name=f"{self.get_fully_qualified_name()}: {ch}",
                                               message=text, hardware_id=mon.reference.model,
                                               values=[KeyValue(key=k, value=v) for k, v in values.items()]))
        return msg

    def summary(self) -> JsonObject:  # noqa: D102
        return {"frames": self.frames, "cpu_s": self.cpu_s,
                "detections": {ch: [d.as_dict() for d in m.detections] for ch, m in self.monitors.items()
                               if m.detections}}


def parser() -> argparse.ArgumentParser:
    """Command-line flags: shorthands for the node's parameters."""
    p = argparse.ArgumentParser(prog="ema_monitor", description="Watch EMAC channels against their reference model.",
                                argument_default=argparse.SUPPRESS)
    p.add_argument("--channel", dest="channels", action="append", type=names_list, help="parameter channels")
    p.add_argument("--model", help="parameter model: a fidelity or an ema identify report (default loada)")
    p.add_argument("--healthy-s", dest="healthy_s", type=float, help="parameter healthy_s (30)")
    return p


def main(argv: Sequence[str] | None = None) -> int:
    """Console script ``ema_monitor``.

    Parameters
    ----------
    argv : sequence of str or None
        The command line, ROS arguments included (None: ``sys.argv[1:]``).

    Returns
    -------
    int
        The process's exit status.
    """
    return run(MonitorNode, parser(), argv)


if __name__ == "__main__":
    raise SystemExit(main())
