"""What the two nodes that drive a run share: the maneuver node and the ``fmu`` (aircraft in the loop).

Each records the bag it names (``bags/<stem>_<UTC time>`` by default, the channels' calibration in its
metadata) and goes through the same phases: *waiting* for the suite on ``/ema/ready`` and for its
recorder to be matched; *running* its frames; *finishing*, until the last frame's feedback is back or a
deadline passes; *draining* what is still queued; done. Only what differs is left to each node: its
frames, and when its last frame counts as answered.
"""

from __future__ import annotations

import abc
import datetime as dt
import json
import time
from collections.abc import Iterable, Mapping
from pathlib import Path

from rcl_interfaces.msg import ParameterType
from std_msgs.msg import String

from ema_msgs_py import contract as ct
from ema_msgs_py.ros import qos
from ema_sim.config import load_channel
from ema_sim.io.bag import BagWriter
from ema_sim.nodes.common import SuiteNode
from ema_sim.nodes.params import Spec
from ema_sim.nodes.recorder import Recorder

NS = 1_000_000_000
START_DELAY_S = 0.05
"""From the suite being ready to the first frame (real time)."""


def stamped_bag(stem: str) -> Path:
    """``bags/<stem>_<UTC time>``.

    Parameters
    ----------
    stem : str
        The bag's name before its time.

    Returns
    -------
    pathlib.Path
        The bag directory to create (relative to the working directory).
    """
    return Path("bags") / f"{stem}_{dt.datetime.now(dt.UTC).strftime('%Y%m%d_%H%M%S')}"


def calibration_metadata(channels: Iterable[str]) -> dict[str, str]:
    """Each channel's command and feedback curves, as the bag reader converts volts with them.

    Parameters
    ----------
    channels : iterable of str
        The channels.

    Returns
    -------
    dict of str to str
        ``calibration.<channel>``: the JSON of its curves' coefficients.
    """
    out = {}
    for ch in channels:
        cfg = load_channel(ch)
        out[f"calibration.{ch}"] = json.dumps({"command_cal_v": cfg.command_cal.coefficients(),
                                               "feedback_cal_deg": cfg.feedback_cal.coefficients()})
    return out


def driver_specs(duration_s: float, duration_text: str, *, profile: str = "", frame_hz: float = ct.FRAME_HZ,
                 profile_text: str = "the test environment's profile, for the bag's metadata") -> list[Spec]:
    """The parameters both drivers have (read-only: a run is set up once).

    Parameters
    ----------
    duration_s : float
        The default run length (s).
    duration_text : str
        Its description (what 0 means to this driver).
    profile : str
        The default test-environment profile named in the bag's metadata.
    frame_hz : float
        The default frame rate (Hz).
    profile_text : str
        The profile parameter's description.

    Returns
    -------
    list of Spec
        The shared parameter declarations.
    """
    return [
        Spec("bag", "", "bag directory to create (empty: bags/<test>_<UTC time>)"),
        Spec("model", "", "the EMACs' model, for the bag's metadata"),
        Spec("profile", profile, profile_text),
        Spec("frame_hz", frame_hz, "FMU frame rate", "Hz", 1.0, 1e5),
        Spec("duration_s", duration_s, duration_text, "s", 0.0, 1e7),
        Spec("wait_for", [], "nodes to wait for on ready before the first frame",
             kind=ParameterType.PARAMETER_STRING_ARRAY),
    ]


class DriverNode(SuiteNode, abc.ABC):
    """A node that drives a run and records its bag (see the module docstring)."""

    lockstep: bool
    """Frames follow ``/clock`` (``use_sim_time``): set by each driver before :meth:`_open_run`."""
    recorder: Recorder
    """Its bag's recorder: each driver makes it after :meth:`_open_run`, and calls :meth:`_take_recorded`."""

    def _open_run(self, bag: Path, metadata: dict[str, str], wait_for: Iterable[str]) -> None:
        """Create the bag, publish the run's parameters on ``/ema/test``, listen on ``/ema/ready``."""
        self.bag_path = bag
        bag.parent.mkdir(parents=True, exist_ok=True)
        self.writer = BagWriter(bag, metadata)
        self.wait_for = {n for item in wait_for for n in item.split(",") if n}
        self.test_pub = self.create_publisher(String, ct.endpoint(ct.TEST), qos(ct.LATCHED_QOS))
        self.test_pub.publish(String(data=json.dumps(metadata)))
        self.ready: set[str] = set()
        self.create_subscription(String, ct.endpoint(ct.READY), self._on_ready, qos(ct.LATCHED_QOS))
        self.phase = "waiting"
        self.k = 0
        self.start_wall = 0.0
        self.late_publish = 0
        self.finish_deadline = 0.0
        self.drain_until = 0.0

    def _on_ready(self, msg: String) -> None:
        self.ready.add(msg.data)

    def _wait_ready(self) -> float:
        """Waiting: start once every awaited node is ready and the recorder is matched."""
        if not (self.wait_for <= self.ready and self.matched()):
            return 0.01
        self.phase = "running"
        self.mark_running()
        self.get_logger().info("running")
        self.announce_ready()
        self.start_wall = time.monotonic() + START_DELAY_S
        self._started()
        return START_DELAY_S

    def _started(self) -> None:
        """The run has just started (the first frame is due at ``start_wall``)."""

    def _finish(self, now: float, wait_s: float) -> None:
        """The last frame is out: wait at most ``wait_s`` for its feedback."""
        self.phase = "finishing"
        self.finish_deadline = now + wait_s

    @abc.abstractmethod
    def _answered(self) -> bool:
        """The last frame's feedback is back (each driver knows what its last frame's feedback is)."""

    def _finish_up(self, now: float) -> float:
        """Finishing, then draining what is still queued, then done."""
        if self.phase == "finishing":
            if self._answered() or now > self.finish_deadline:
                self.phase = "draining"
                self.drain_until = now + (0.25 if self.lockstep else 0.1)
            return 0.005
        # in real time the EMACs report on while braked: stop anyway
        if now >= self.drain_until:
            self.done = True
        return max(self.drain_until - now, 0.0)

    def _take_recorded(self) -> None:
        """Record what waits on the topics taken at the frame: once a frame while running, each poll otherwise."""
        self.recorder.take()

    def _close_bag(self, frames: int, extra: Mapping[str, object] | None = None) -> None:
        """Note how far the run got (and ``extra``) in the bag's metadata, and close it."""
        self._take_recorded()
        self.writer.set_metadata("frames_commanded", str(self.k))
        self.writer.set_metadata("completed", str(self.k >= frames).lower())
        for key, value in (extra or {}).items():
            self.writer.set_metadata(key, value)
        self.writer.close()
