"""Parameters of the second-order family (section 3.1, figures 21, 26, 29), each declared once.

The dataclass fields are the YAML keys of a channel's ``second_order`` section; their metadata
(:mod:`ema_sim.parameters`) gives unit, range, description, switch-off value and kernel slot. The
kernel reads the values unconverted, one slot per field in declaration order: :data:`P`. The ranges
of the fitted parameters are the bounds identification searches in.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, replace

from ema_sim import parameters as pm
from ema_sim.config import ChannelConfig
from ema_sim.models.base import FloatArray

FAMILY = "second-order"
SECTION = "second_order"
INF = math.inf
FIGURE23 = ("figure 23's recommended model bounds for all data sets (its numbers are not in the text): illustrative, "
            "a box holding every channel's configured value and HOAD3's LOES (61.8-64.5 rad/s, ζ 0.73-0.75, "
            "7.7-8.5 ms); `ema montecarlo --analysis` takes the spread of measured records instead")


@pm.documented
@dataclass(frozen=True)
class SecondOrderParams:
    """Every parameter of the figure-26 pipeline, in the units its name carries (config ``second_order``)."""

    wn_rad_s: float = pm.param("rad/s", "natural frequency ωn of the basic second order (figure 21)",
                               min=5.0, max=500.0, kernel="wn_rad_s", uncertainty=(45.0, 75.0),
                               uncertainty_source=FIGURE23)
    zeta: float = pm.param("-", "damping ratio ζ (figure 21)", min=0.05, max=3.0, kernel="zeta",
                           uncertainty=(0.5, 0.8), uncertainty_source=FIGURE23)
    rate_limit_dps: float = pm.linked(
        ChannelConfig, "slew_rate_dps", description="unloaded rate limit rl on the velocity command: the "
        "channel's unloaded slew (3.1.2.1, table 1)", off=INF, kernel="rate_limit_dps")
    k2_dps_per_lb: float = pm.param("deg/s/lbf", "rate-limit slope K2 with the load hm/marm (3.1.2.1)", min=0.0,
                                    max=1.0, off=0.0, kernel="k2_dps_per_lb")
    moment_arm_in: float = pm.linked(ChannelConfig, "crank_arm_in", description="moment arm marm (the servo crank "
                                     "arm) of the rate limit's load term", kernel="moment_arm_in")
    position_min_deg: float = pm.linked(ChannelConfig, "position_min_deg", description="lower position limit on "
                                        "the states (3.1.2.1)", kernel="position_min_deg")
    position_max_deg: float = pm.linked(ChannelConfig, "position_max_deg", description="upper position limit on "
                                        "the states (3.1.2.1)", kernel="position_max_deg")
    kb: float = pm.param("-", "command error slope: (1 + Kb)·u + offset (3.1.2.2)", min=-0.5, max=0.5, off=0.0,
                         kernel="kb")
    offset_deg: float = pm.param("deg", "command error bias (3.1.2.2)", min=-5.0, max=5.0, off=0.0,
                                 kernel="offset_deg")
    quantization_deg: float = pm.param("deg", "command quantization, the D/A resolution (3.1.2.2)", min=0.0,
                                       off=0.0, element="quantization", kernel="quantization_deg")
    free_play_deg: float = pm.linked(
        ChannelConfig, "free_play_deg", description="free play width, ±half in the limited double integrator "
        "(3.1.2.3, figure 29)", off=0.0, kernel="free_play_deg")
    surface_inertia_inlbs2: float = pm.linked(
        ChannelConfig, "surface_inertia_inlbs2", description="surface inertia Is of the free-play subsystem "
        "(table A2)", kernel="surface_inertia_inlbs2")
    kcp_per_kinlb: float = pm.param("1/(1000 in·lb)", "compliance correction K_CP = 1 + kcp·(aiding load)/1000 "
                                    "(3.1.2.4)", off=0.0, kernel="kcp_per_kinlb")
    delay_s: float = pm.param("s", "time delay, command to first motion (2.3)", min=0.0, max=0.2, off=0.0,
                              kernel="delay_s", uncertainty=(0.002, 0.010), uncertainty_source=FIGURE23)
    command_lag_hz: float = pm.param("Hz", "first-order lag on the command", min=0.2, max=2000.0, off=0.0,
                                     kernel="command_lag_hz")
    feedback_lag_hz: float = pm.param("Hz", "first-order lag on the LVDT feedback", min=0.2, max=2000.0, off=0.0,
                                      kernel="feedback_lag_hz")
    threshold_deg: float = pm.param("deg", "dead zone (half width) on the servo error (2.1)", min=0.0, max=2.0,
                                    off=0.0, kernel="threshold_deg")
    compliance_deg_per_kinlb: float = pm.param(
        "deg/(1000 in·lb)", "surface deflection outside the servo loop, linear in hinge moment (2.8)", min=0.0,
        max=10.0, off=0.0, kernel="compliance_deg_per_kinlb")
    lvdt_compliance_deg_per_kinlb: float = pm.param(
        "deg/(1000 in·lb)", "deflection inside the servo loop the LVDT reads and the loop does not remove (2.8)",
        min=0.0, max=10.0, off=0.0, default=0.0, kernel="lvdt_compliance_deg_per_kinlb")
    hysteresis_h_lb_per_in: float = pm.param(
        "lbf/in", "hysteretic damping h of the compliance, viscous equivalent h/ω (3.2.2, figure 36)", min=1.0,
        max=1e7, off=0.0, default=0.0, kernel="hysteresis_h_lb_per_in")
    hysteresis_freq_hz: float = pm.param("Hz", "the frequency ω/2π of h/ω (the load's)", min=0.0,
                                         min_exclusive=True, default=0.0125, kernel="hysteresis_freq_hz")
    # installed-actuator stages (identification vocabulary, docs/effects.md); every one off by default
    feedback_delay_s: float = pm.param("s", "time delay from motion to the LVDT reading, outside the servo loop "
                                       "(HOAD3's 2 ms, 2.3)", min=0.0, max=0.2, off=0.0, default=0.0,
                                       kernel="feedback_delay_s")
    feedback_filter_in_loop: float = pm.param(
        "-", "1: the servo closes on a first-order filtered LVDT (corner 2ζωn): the position is the filter's "
        "output, the actuator and surface lead it by 1/(2ζωn) (2.8, figure 30's stage 15)", min=0.0, max=1.0,
        off=0.0, default=0.0, kernel="feedback_filter_in_loop")
    integral_hz: float = pm.param("Hz", "servo integral action: the position loop's PI corner Ki/Kp/2π; it "
                                  "integrates while the drive is unlimited and the error outside the threshold "
                                  "(figure 30's stage 4)", min=0.001, max=20.0, off=0.0, default=0.0,
                                  kernel="integral_hz")
    servo_compliance_deg_per_kinlb: float = pm.param(
        "deg/(1000 in·lb)", "the droop a proportional servo holds under load: an aiding hinge moment adds "
        "(ωn/2ζ)·droop to the actuator's rate; integral action washes it out (2.8)", min=0.0, max=10.0, off=0.0,
        default=0.0, kernel="servo_compliance_deg_per_kinlb")
    accel_limit_dps2: float = pm.param(
        "deg/s²", "current-limited drive: the actuator's acceleration at the current limit, unloaded (figure 30's "
        "stage 5)", min=100.0, max=1e6, off=INF, default=INF, kernel="accel_limit_dps2")
    velocity_loop_hz: float = pm.param(
        "Hz", "bandwidth of the current-limited drive's velocity loop (with accel_limit_dps2)", min=5.0, max=1000.0,
        default=300.0, kernel="velocity_loop_hz")
    linkage_freq_hz: float = pm.param(
        "Hz", "the surface's own mode outside the servo loop: surface inertia on the linkage stiffness below the "
        "compliance knee (figures 32, 33)", min=1.0, max=500.0, off=0.0, default=0.0, kernel="linkage_freq_hz")
    linkage_zeta: float = pm.param("-", "damping ratio of the linkage mode (at linkage_freq_hz)", min=0.005, max=2.0,
                                   default=0.1, kernel="linkage_zeta")
    compliance_knee_inlb: float = pm.param(
        "in·lb", "nonlinear compliance: the hinge moment where the linkage stiffens (figures 16, 33)", min=1.0,
        max=1e5, off=INF, default=INF, kernel="compliance_knee_inlb")
    compliance_stiff_deg_per_kinlb: float = pm.param(
        "deg/(1000 in·lb)", "nonlinear compliance above the knee (figures 16, 33)", min=0.0, max=10.0, default=0.0,
        kernel="compliance_stiff_deg_per_kinlb")
    lvdt_compliance_knee_inlb: float = pm.param(
        "in·lb", "nonlinear LVDT compliance: the hinge moment where it stiffens (figure 16's LVDT curve)", min=1.0,
        max=1e5, off=INF, default=INF, kernel="lvdt_compliance_knee_inlb")
    lvdt_compliance_stiff_deg_per_kinlb: float = pm.param(
        "deg/(1000 in·lb)", "nonlinear LVDT compliance above the knee", min=0.0, max=10.0, default=0.0,
        kernel="lvdt_compliance_stiff_deg_per_kinlb")

    @classmethod
    def from_channel(cls, channel: ChannelConfig, **overrides: float) -> SecondOrderParams:
        """Defaults of a channel's ``second_order`` section and its physical data, then overrides.

        Parameters
        ----------
        channel : ChannelConfig
            The channel whose section and physical data give the defaults.
        **overrides : float
            Parameter values that replace the channel's.

        Returns
        -------
        SecondOrderParams
            The validated parameters.
        """
        return pm.load(cls, channel.section(SECTION), origin=channel.channel, family=FAMILY, section=SECTION,
                       overrides=overrides, source=channel)

    @classmethod
    def basic(cls, channel: ChannelConfig, **overrides: float) -> SecondOrderParams:
        """The basic second order of figure 21: the channel's ωn and ζ, every switchable stage off.

        Parameters
        ----------
        channel : ChannelConfig
            The channel whose ωn, ζ and physical data are used.
        **overrides : float
            Stages to switch on (or values to change).

        Returns
        -------
        SecondOrderParams
            The validated parameters.
        """
        return cls.from_channel(channel, **{**pm.switched_off(cls), **overrides})

    def validate(self) -> None:
        """Reject values no actuator can have (one message naming the parameter)."""
        pm.validate(self, FAMILY)

    def replace(self, **changes: float) -> SecondOrderParams:
        """A copy with some parameters changed (validated).

        Parameters
        ----------
        **changes : float
            Parameter name → new value.

        Returns
        -------
        SecondOrderParams
            The validated copy.
        """
        out = replace(self, **changes)
        out.validate()
        return out

    def as_dict(self) -> dict[str, float]:
        """Name → value.

        Returns
        -------
        dict
            Every parameter.
        """
        return asdict(self)

    def kernel_vector(self) -> FloatArray:
        """The parameters in kernel order (the :data:`P` slots).

        Returns
        -------
        numpy.ndarray
            One float per slot.
        """
        return pm.kernel_vector(self, P)


P = pm.kernel_layout(SecondOrderParams)
"""Kernel slots, generated from the declared kernel names (``p[P.wn_rad_s]``)."""
N_PARAMS = len(P)
"""Kernel slots in all (a fixed-step kernel holds an instance's as a tuple of this length)."""

X = pm.slots("SecondOrderState", ("position_deg", "rate_dps", "free_play_deg", "free_play_rate_dps",
                                  "command_lag_deg", "feedback_lag_deg", "compliance_deg", "integral_deg_s",
                                  "drive_rate_dps", "linkage_deg", "linkage_rate_dps", "history_head",
                                  "history_last_s"))
"""State columns shared by every implementation."""
N_STATE = len(X)

