"""The topic contract of the node suite (pure Python: importable without ROS).

Volts on the wire, as the real EMAC speaks (section 1.4: every command and feedback is scaled to
±10 Vdc); degrees through each channel's third-order calibration curves (section 2.6). The FMU side
and the EMAC side have distinct topics so the test environment can sit between them both ways:

    FMU ──/ema/fmu/command──▶ testenv ──/ema/emac/command──▶ EMAC (model)
    FMU ◀─/ema/fmu/feedback── testenv ◀─/ema/emac/feedback── EMAC
    load rig / vehicle ──/ema/load/hinge_moment──▶ EMAC ──/ema/sensor/surface──▶ instruments

Every per-frame signal is a ``sensor_msgs/JointState`` whose ``name`` lists channels (any subset, as
ROS joint states do); the header stamp is the FMU frame the values belong to. An empty array means
"not measured" (the JointState convention), e.g. ``effort`` on feedback from a model without a motor.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Final, Protocol

CHANNELS: tuple[str, ...] = ("left_wing", "right_wing", "left_rudder", "right_rudder", "cowl_door")
"""The five EMAC channels (section 1.4), in this order: the ``name`` entries of the per-frame JointStates
and the stem of each ``config/<channel>.yaml``."""
FRAME_HZ = 200.0
"""The FMU frame rate: feedback is published once per frame (table 5)."""
FULL_SCALE_V = 10.0
"""Every command and feedback is scaled to ±10 V (section 1.4)."""

JOINT_STATE: Final = "sensor_msgs/msg/JointState"
CLOCK: Final = "rosgraph_msgs/msg/Clock"
STRING: Final = "std_msgs/msg/String"
DIAGNOSTIC_ARRAY = "diagnostic_msgs/msg/DiagnosticArray"


@dataclass(frozen=True)
class QosSpec:
    """A QoS profile as plain data (``rclpy`` and ``rosbags`` forms in :mod:`.ros` / :mod:`.typestore`)."""

    reliability: str = "reliable"
    """``reliable`` or ``best_effort``."""
    durability: str = "volatile"
    """``volatile`` or ``transient_local``."""
    depth: int = 1000
    """History depth (keep last)."""

    def describe(self) -> str:
        """The profile in words, e.g. ``reliable, volatile, keep last 1000``."""
        return f"{self.reliability}, {self.durability}, keep last {self.depth}"


FRAME_QOS = QosSpec("reliable", "volatile", 1000)
"""Per-frame signals: reliable so lockstep never loses a frame; deep so a recorder may lag."""
CLOCK_QOS = QosSpec("reliable", "transient_local", 100)
"""``clock`` from the lockstep clock: the latest frame reaches a late joiner; every subscription matches it
(best effort or reliable, volatile or transient local). Nodes step every frame up to the clock's value,
so only the latest matters, and the clock sends it again while it waits (a best-effort reader may miss one)."""
CLOCK_SUB_QOS = QosSpec("best_effort", "volatile", 10)
"""The nodes' ``clock`` subscriptions: best effort and volatile, so any ordinary ``/clock`` publisher matches
(default QoS, rclcpp's ``ClockQoS``, ``ros2 bag play --clock``, a simulator's bridge). Lockstep does not
rest on the clock's delivery: a node steps a frame only with the inputs stamped for it, and an input
stamped *t* tells it the suite's time has reached *t*."""
LATCHED_QOS = QosSpec("reliable", "transient_local", 10)
"""Test metadata and readiness: late joiners get the last messages."""
EVENT_QOS = QosSpec("reliable", "volatile", 10)
"""Failure injection and diagnostics."""


@dataclass(frozen=True)
class TopicSpec:
    """One topic of the contract."""

    name: str
    """The contract name (in the root namespace)."""
    msgtype: str
    """``pkg/msg/Type``."""
    qos: QosSpec
    """The QoS its publisher offers."""
    publisher: str
    """Who publishes it, in words."""
    subscribers: str
    """Who takes it, in words."""
    fields: dict[str, str] = field(default_factory=dict)
    """Message field → meaning and unit."""
    per_frame: bool = True
    """Published once per FMU frame (False: events and metadata)."""


TOPICS: dict[str, TopicSpec] = {t.name: t for t in (
    TopicSpec("/ema/fmu/command", JOINT_STATE, FRAME_QOS, "FMU (maneuver, fmu, fmu_bridge, a flight computer)",
              "testenv", {"position": "command, V (±10 V)"}),
    TopicSpec("/ema/emac/command", JOINT_STATE, FRAME_QOS, "testenv", "emac",
              {"position": "command at the EMAC input, V (±10 V)"}),
    TopicSpec("/ema/emac/feedback", JOINT_STATE, FRAME_QOS, "emac", "testenv, simclock",
              {"position": "LVDT position feedback, V (±10 V)",
               "effort": "motor current feedback, A (empty: the model has no motor)"}),
    TopicSpec("/ema/fmu/feedback", JOINT_STATE, FRAME_QOS, "testenv", "FMU",
              {"position": "LVDT position feedback as the FMU reads it, V",
               "effort": "motor current feedback, A (empty when unknown)"}),
    TopicSpec("/ema/load/hinge_moment", JOINT_STATE, FRAME_QOS, "load rig or vehicle (maneuver, fmu)", "emac",
              {"effort": "hinge moment, in·lb, positive aids positive deflection; held over the frame"}),
    TopicSpec("/ema/sensor/surface", JOINT_STATE, FRAME_QOS, "emac", "instruments, recorder",
              {"position": "true surface angle (external sensor: free play and compliance included), deg",
               "velocity": "actuator rate, deg/s",
               "effort": "hinge moment applied over the frame that ends at the stamp, in·lb"}),
    TopicSpec("/ema/sensor/bus", JOINT_STATE, FRAME_QOS, "emac (models with a motor)", "instruments, recorder",
              {"position": "150 V bus voltage seen by the channel, V"}),
    TopicSpec("/ema/fmu/vehicle", JOINT_STATE, FRAME_QOS, "fmu (aircraft-in-the-loop vehicle simulation)",
              "recorder, monitors", {"name": "state names: alpha_deg, q_dps, theta_deg, p_dps, phi_deg",
                                     "position": "vehicle state at the frame, deg and deg/s"}),
    TopicSpec("/ema/joint_commands", JOINT_STATE, FRAME_QOS, "ros2_control (topic_based_ros2_control)",
              "fmu_bridge", {"position": "surface command, rad"}),
    TopicSpec("/ema/joint_states", JOINT_STATE, FRAME_QOS, "fmu_bridge", "ros2_control",
              {"position": "surface position from LVDT feedback through the feedback curve, rad",
               "velocity": "its frame-to-frame rate, rad/s"}),
    TopicSpec("/clock", CLOCK, CLOCK_QOS, "simclock (lockstep only)", "every node with use_sim_time",
              {"clock": "simulation time, advanced one FMU frame at a time"}),
    TopicSpec("/ema/test", STRING, LATCHED_QOS, "maneuver, fmu", "recorder",
              {"data": "the test's parameters as JSON (also in the bag's metadata)"}, per_frame=False),
    TopicSpec("/ema/ready", STRING, LATCHED_QOS, "every suite node", "simclock, maneuver, fmu",
              {"data": "name of a node that is up and subscribed"}, per_frame=False),
    TopicSpec("/ema/nodes", STRING, LATCHED_QOS, "every suite node", "every suite node, ema launch",
              {"data": "JSON: a node's full name, pid, host and start time; the younger of two nodes of one name "
                       "refuses to run"}, per_frame=False),
    TopicSpec("/diagnostics", DIAGNOSTIC_ARRAY, EVENT_QOS, "emac, testenv, simclock", "monitors",
              {"status": "one status per channel: brake, failure, counters of rejected inputs; simclock: each "
                         "channel in lockstep, silent or left out"}, per_frame=False),
    TopicSpec("/ema/faults/truth", STRING, EVENT_QOS, "emac (faults injected: emac.faults)", "recorder, scoring",
              {"data": "JSON {channel, time_s, faults: {fault_<kind>: size in}}, at each change of an injected "
                       "fault's size"}, per_frame=False),
    TopicSpec("/ema/monitor/detections", STRING, EVENT_QOS, "ema_monitor", "operators, recorder",
              {"data": "JSON of a detection: channel, time_s, output, kind, parameter, estimate, uncertainty, "
                       "statistic"}, per_frame=False),
)}
FAULT_TRUTH = "/ema/faults/truth"
MONITOR_DETECTIONS = "/ema/monitor/detections"


def topic(name: str) -> TopicSpec:
    """A contract topic by name.

    Parameters
    ----------
    name : str
        The topic's contract name, e.g. ``/ema/fmu/command``.

    Returns
    -------
    TopicSpec
        Its type, QoS, publisher, subscribers and fields.
    """
    return TOPICS[name]


GLOBAL = frozenset({"/clock", "/diagnostics"})
"""Topics ROS names absolutely: every node's ``/clock`` (what rclpy's and rclcpp's time sources take, a
simulator or ``ros2 bag play --clock`` publishes) and the graph's one ``/diagnostics`` (a diagnostic aggregator
reads it; each status is named after its node's full name, so vehicles do not collide)."""


def endpoint(name: str) -> str:
    """The name a node gives its publisher or subscription: relative (``ema/fmu/command``), or :data:`GLOBAL`.

    A relative name resolves in the node's namespace: ``-r __ns:=/aircraft2`` moves every topic of the suite
    to ``/aircraft2/ema/...``; ``/clock`` and ``/diagnostics`` stay where ROS has them (a run that wants a
    clock of its own per namespace remaps ``/clock``, e.g. ``-r /clock:=/aircraft2/clock``).

    Parameters
    ----------
    name : str
        The topic's contract name.

    Returns
    -------
    str
        The name to create the endpoint with.
    """
    return name if name in GLOBAL else name.lstrip("/")


def canonical(resolved: str, namespace: str = "/") -> str | None:
    """A resolved topic name as the contract (and a bag) names it: the node's namespace taken off.

    ``/aircraft2/ema/fmu/command`` in ``/aircraft2`` → ``/ema/fmu/command``.

    Parameters
    ----------
    resolved : str
        The fully resolved topic name.
    namespace : str, optional
        The node's namespace.

    Returns
    -------
    str or None
        The contract name; None for a topic outside the namespace (another vehicle's).
    """
    ns = namespace.rstrip("/")
    if not ns:
        return resolved
    return resolved[len(ns):] if resolved.startswith(ns + "/") else None


FMU_COMMAND = "/ema/fmu/command"
EMAC_COMMAND = "/ema/emac/command"
EMAC_FEEDBACK = "/ema/emac/feedback"
FMU_FEEDBACK = "/ema/fmu/feedback"
HINGE_MOMENT = "/ema/load/hinge_moment"
SURFACE = "/ema/sensor/surface"
VEHICLE = "/ema/fmu/vehicle"
BUS = "/ema/sensor/bus"
JOINT_COMMANDS = "/ema/joint_commands"
JOINT_STATES = "/ema/joint_states"
CLOCK_TOPIC = "/clock"
TEST = "/ema/test"
READY = "/ema/ready"
NODES = "/ema/nodes"
DIAGNOSTICS = "/diagnostics"


def failure_topic(channel: str) -> str:
    """The topic of one channel's run-time failure injection.

    Parameters
    ----------
    channel : str
        One of :data:`CHANNELS`.

    Returns
    -------
    str
        ``/ema/emac/<channel>/failure`` (``std_msgs/String``, a failure spec such as ``stuck``).
    """
    return f"/ema/emac/{channel}/failure"


FAILURE_QOS = EVENT_QOS


@dataclass(frozen=True)
class Scaling:
    """Degree↔volt conversions of one channel, fast on scalars (the FMU's calibration curves).

    ``command``: surface degrees → command volts (third order); ``feedback``: LVDT volts → surface
    degrees (third order). ``sign`` is −1 for the inverse relation of both wings and the left rudder
    (section 4.4.1): there, a positive deflection is a negative voltage.
    """

    channel: str
    """One of :data:`CHANNELS`."""
    command: tuple[float, float, float, float]
    """Command curve ``c0..c3``: surface degrees → volts."""
    feedback: tuple[float, float, float, float]
    """Feedback curve ``c0..c3``: LVDT volts → surface degrees."""
    full_scale_v: float = FULL_SCALE_V
    """Commands and feedback span ±this, V."""

    @property
    def sign(self) -> int:
        """+1 direct, −1 inverse degrees-to-volts relation."""
        return 1 if self.command[1] >= 0.0 else -1

    def command_deg_to_v(self, deg: float) -> float:
        """Volts the FMU sends for a surface command.

        Parameters
        ----------
        deg : float
            The surface command, deg.

        Returns
        -------
        float
            The command, V.
        """
        return _cubic(self.command, deg)

    def command_v_to_deg(self, volts: float) -> float:
        """The surface command a command voltage stands for (inverse command curve).

        Parameters
        ----------
        volts : float
            The command, V.

        Returns
        -------
        float
            The surface command, deg.
        """
        return _inverse(self.command, volts)

    def feedback_v_to_deg(self, volts: float) -> float:
        """Surface degrees the FMU reads from LVDT volts.

        Parameters
        ----------
        volts : float
            The LVDT feedback, V.

        Returns
        -------
        float
            The surface position, deg.
        """
        return _cubic(self.feedback, volts)

    def feedback_deg_to_v(self, deg: float) -> float:
        """LVDT volts that read back as ``deg`` (inverse feedback curve).

        Parameters
        ----------
        deg : float
            The surface position, deg.

        Returns
        -------
        float
            The LVDT feedback, V.
        """
        return _inverse(self.feedback, deg)

    @property
    def volts_per_deg(self) -> float:
        """Magnitude of the feedback scale at zero, V per degree (≈ 0.235)."""
        return 1.0 / abs(self.feedback[1])


def _cubic(c: tuple[float, float, float, float], x: float) -> float:
    return c[0] + x * (c[1] + x * (c[2] + x * c[3]))


def _inverse(c: tuple[float, float, float, float], y: float) -> float:
    x = (y - c[0]) / c[1]
    for _ in range(8):
        f = _cubic(c, x) - y
        step = f / (c[1] + x * (2.0 * c[2] + 3.0 * c[3] * x))
        x -= step
        if abs(step) < 1e-13 * (1.0 + abs(x)):
            break
    return x


class Curve(Protocol):
    """A third-order calibration curve that lists its coefficients (``ema_sim.calibration.Cubic``)."""

    def coefficients(self) -> Sequence[float]:
        """``[c0, c1, c2, c3]`` of ``y = c0 + c1·x + c2·x² + c3·x³``."""
        ...


class Calibrated(Protocol):
    """What :func:`scaling_of` reads from a channel's configuration (``ema_sim.config.ChannelConfig``)."""

    @property
    def channel(self) -> str:
        """The channel's name (one of :data:`CHANNELS`)."""
        ...

    @property
    def command_cal(self) -> Curve:
        """Surface degrees → command volts."""
        ...

    @property
    def feedback_cal(self) -> Curve:
        """LVDT volts → surface degrees."""
        ...

    @property
    def full_scale_v(self) -> float:
        """The ±full scale of commands and feedback, V."""
        ...


def _four(curve: Curve) -> tuple[float, float, float, float]:
    c0, c1, c2, c3 = (float(c) for c in curve.coefficients())
    return c0, c1, c2, c3


def scaling_of(cfg: Calibrated) -> Scaling:
    """The scaling of a channel's configuration.

    The contract reads no file: ``ema_sim.config.scaling`` gives a channel's scaling from its
    ``config/<channel>.yaml``, and a node builds one from its ROS parameters. The configuration's loader
    has checked the curves (four finite coefficients each).

    Parameters
    ----------
    cfg : Calibrated
        The channel's configuration: its name, both calibration curves and the full scale
        (an ``ema_sim.config.ChannelConfig``).

    Returns
    -------
    Scaling
        The channel's degree↔volt conversions on scalars.
    """
    return Scaling(cfg.channel, _four(cfg.command_cal), _four(cfg.feedback_cal), float(cfg.full_scale_v))


__all__ = [
    "CHANNELS", "CLOCK_QOS", "FRAME_HZ", "FRAME_QOS", "FULL_SCALE_V", "GLOBAL", "LATCHED_QOS", "TOPICS", "QosSpec",
    "Scaling", "TopicSpec", "canonical", "endpoint", "failure_topic", "scaling_of", "topic",
]
