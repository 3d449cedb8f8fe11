"""Parameters of the high-order family (section 3.2, figures 30, 32, 33, 36), each declared once.

The fields are the YAML keys of a channel's ``high_order`` section (the flight/test elements in its
``hoad2``/``hoad3`` subsections, figure 33's curves in ``hoad3``) or of the channel's physical data;
their metadata (:mod:`ema_sim.parameters`) gives unit, range, description, switch and kernel slot.
The kernel works in ball-screw units (in, in/s, lbf) and SI electrical units: each field declares
its kernel name (unit in the name) and its conversion; slots that no single parameter fills
(options, figure 33's curves at a compliance bound, the feedback calibration) are listed in
:data:`KERNEL_EXTRA`. :data:`P` is the generated layout, :data:`X` the state layout.

Where the report publishes no number the values are illustrative (``config/*.yaml`` says which);
section 3.2 puts the parametric uncertainty of a model built without the manufacturer's data at 10 to
30 percent.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, replace
from typing import Any, ClassVar

from ema_sim import parameters as pm
from ema_sim.config import ChannelConfig
from ema_sim.errors import ConfigError, EmaError, UnknownNameError
from ema_sim.models.arrays import FloatArray
from ema_sim.models.high_order import gear_train as gt
from ema_sim.models.stages import RAD2DEG, TWO_PI

FAMILY = "high-order"
SECTION = "high_order"
VARIANTS = ("hoac1", "hoad2", "hoad3")
ENVIRONMENT = ("hoad2", "hoad3")
"""The variants with the flight/test elements (delays, quantization, noise) in their own subsection."""
BOUNDS = {"lower": -1.0, "mean": 0.0, "upper": 1.0}
"""Figure 35's compliance bounds: ``upper`` is the most compliant curve, ``lower`` the stiffest."""
OPTIONS = ("bound", "hysteresis", "noise", "seed")
"""Keyword options of the high-order models (not parameters; also accepted as ``--set`` numbers)."""
INLB_PER_NM = 8.850745793490558
"""in·lbf per N·m: the motor's torque constant in in·lbf/A is its back-EMF constant (V·s/rad) times this."""
POS = {"min": 0.0, "min_exclusive": True}
"""A positive quantity."""
NONNEG = {"min": 0.0}
"""A quantity that may be zero."""
ILLUSTRATIVE = "illustrative: chosen inside the report's specifications (config)"


def _curve(description: str, size: int, **meta: object) -> Any:
    """A figure-33 curve field (in the ``hoad3`` subsection)."""
    return pm.param("lbf" if "breakpoints" in description else "lbf/in", description, size=size, section="hoad3",
                    **POS, **meta)


def _environment(unit: str, description: str, **meta: object) -> float:
    """A flight/test element of HOAD2/HOAD3 (in the variant's subsection; 0 for HOAC1): a float field."""
    spec: float = pm.param(unit, description, default=0.0, variants=ENVIRONMENT, **NONNEG, **meta)
    return spec


@pm.documented
@dataclass(frozen=True, kw_only=True)
class HighOrderParams:
    """Every parameter of the figure-30 pipeline, in the units its name carries (config ``high_order``)."""

    # position-loop controller electronics, velocity and current loops, PWM (EMAC channel)
    position_gain_per_s: float = pm.param("1/s", "position-loop gain Kp (stage 4)", kernel="position_gain_per_s",
                                          **POS)
    position_integral_per_s2: float = pm.param(
        "1/s²", "position-loop integral gain Ki, integrating only while the PWM drives (stage 4)",
        kernel="position_integral_per_s2", **NONNEG)
    rate_limit_in_s: float = pm.param("in/s", "slew limit on the velocity demand (stage 4)",
                                      kernel="rate_limit_in_s", **POS)
    velocity_gain_a_per_in_s: float = pm.param("A/(in/s)", "tachometer velocity-loop gain Kv (stage 5)",
                                               kernel="velocity_gain_a_per_in_s", **POS)
    lvdt_filter_hz: float = pm.param("Hz", "LVDT demodulator filter corner (stage 15)", kernel="lvdt_filter_rad_s",
                                     to_kernel=lambda p: TWO_PI * p.lvdt_filter_hz, **POS)
    current_limit_a: float = pm.param("A", "current limit on the current demand (stage 5)",
                                      kernel="current_limit_a", **POS)
    current_gain_v_per_a: float = pm.param("V/A", "current-loop gain Kc (stage 6)", kernel="current_gain_v_per_a",
                                           **NONNEG)
    pwm_dead_band_v: float = pm.param("V", "PWM dead band (stage 7; the dither mechanism of 4.3)",
                                      kernel="pwm_dead_band_v", off=0.0, element="dead_band", **NONNEG)
    pwm_max_duty_ratio: float = pm.param("-", "PWM duty limit on the bus voltage (stage 7)", max=1.0,
                                         kernel="pwm_max_duty_ratio", **POS)
    # motor, gears and screw
    stator_resistance_ohm: float = pm.param(
        "Ω", "stator resistance of the DC-equivalent motor (stage 8)", kernel="stator_resistance_ohm",
        uncertainty=(0.78, 0.98), uncertainty_source="table A2: 0.88 ± 0.10 Ω", **POS)
    inductance_mh: float = pm.param("mH", "winding inductance (stage 8)", kernel="inductance_h", to_kernel=1e-3,
                                    **POS)
    back_emf_v_s_per_rad: float = pm.param(
        "V·s/rad", "back-EMF constant Ke, equal to the torque constant Kt in SI units (stage 8)",
        kernel="back_emf_v_per_in_s", to_kernel=lambda p: p.back_emf_v_per_in_s, **POS)
    rotor_inertia_inlbs2: float = pm.param(
        "in·lb·s²", "rotor, gear and screw inertia at the motor shaft (stage 10)", kernel="motor_mass_lbs2_per_in",
        to_kernel=lambda p: p.motor_mass_lbs2_per_in, **POS)
    gear_reduction_ratio: float = pm.param("-", "gear reduction N, motor to screw (stage 10)", **POS)
    screw_lead_in_per_rev: float = pm.param("in/rev", "ball-screw lead (stage 10)", **POS)
    # 150 V bus
    bus_supply_v: float = pm.param(
        "V", "bus supply (stage 9)", kernel="bus_supply_v", uncertainty=(125.0, 150.0),
        uncertainty_source="section 1.4 and table 1: 150 Vdc, minimum 125 Vdc", **POS)
    bus_source_resistance_ohm: float = pm.param("Ω", "bus source and wiring resistance (stage 9)",
                                                kernel="bus_source_resistance_ohm", **POS)
    bus_capacitance_uf: float = pm.param("µF", "bus capacitance; regeneration charges it (stage 9, 2.5)",
                                         kernel="bus_capacitance_f", to_kernel=1e-6, **POS)
    # friction and brake
    coulomb_friction_lbf: float = pm.param("lbf", "Coulomb friction on the motor and screw (stage 11)",
                                           kernel="coulomb_friction_lbf", **NONNEG)
    stiction_lbf: float = pm.param("lbf", "stiction on the motor and screw (stage 11, 2.2.2)", kernel="stiction_lbf",
                                   **NONNEG)
    brake_holding_lbf: float = pm.param("lbf", "brake holding force while unpowered (stage 11; > 4,000 lbf, table 1)",
                                        kernel="brake_holding_lbf", **NONNEG)
    hinge_friction_inlb: float = pm.param(
        "in·lb", "surface spindle friction (stage 14)", kernel="hinge_friction_lbf",
        to_kernel=lambda p: p.hinge_friction_inlb / p.crank_arm_in, **NONNEG)
    # figure 32 gear train
    gear_backlash_in: float = pm.param(
        "in", "gear backlash, the figure-32 dead zone's full width (stage 12)", kernel="half_backlash_in",
        to_kernel=0.5, uncertainty=(0.0, 0.005), uncertainty_source="table 1: backlash ≤ 0.005 in", **NONNEG)
    gear_stiffness_lbf_per_in: float = pm.param(
        "lbf/in", "gear-train stiffness, in series with the backup structure (figure 32)",
        kernel="series_stiffness_lbf_per_in",
        to_kernel=lambda p: gt.series_stiffness(p.gear_stiffness_lbf_per_in, p.backup_stiffness_lbf_per_in), **POS)
    backup_stiffness_lbf_per_in: float = pm.param("lbf/in", "backup-structure stiffness (figure 32)",
                                                  kernel="backup_stiffness_lbf_per_in", **POS)
    gear_damping_lbf_s_per_in: float = pm.param("lbf·s/in", "gear-train damping in contact (figure 32)",
                                                kernel="gear_damping_lbf_s_per_in", **NONNEG)
    # channel geometry (tables 1, A2)
    crank_arm_in: float = pm.linked(ChannelConfig, "crank_arm_in", description="servo crank arm: force ↔ hinge "
                                    "moment, travel ↔ angle (stage 13)", kernel="crank_arm_in")
    surface_inertia_inlbs2: float = pm.linked(
        ChannelConfig, "surface_inertia_inlbs2", description="surface inertia (stage 14, table A2)",
        kernel="surface_mass_lbs2_per_in", to_kernel=lambda p: p.surface_mass_lbs2_per_in)
    position_min_deg: float = pm.linked(ChannelConfig, "position_min_deg", description="lower mechanical stop",
                                        kernel="position_min_in", to_kernel=lambda p: p.position_min_deg / p.deg_per_in)
    position_max_deg: float = pm.linked(ChannelConfig, "position_max_deg", description="upper mechanical stop",
                                        kernel="position_max_in", to_kernel=lambda p: p.position_max_deg / p.deg_per_in)
    # flight/test environment (zero for HOAC1)
    command_delay_s: float = _environment("s", "command to first motion (stage 1; HOAD3: 4 ms, 2.3)",
                                          kernel="command_delay_s")
    feedback_delay_s: float = _environment("s", "motion to feedback (stage 16; HOAD3: 2 ms, 2.3)",
                                           kernel="feedback_delay_s")
    quantization_v: float = _environment("V", "command and feedback quantization through the calibrations "
                                         "(stages 2, 17; 5 mV, 4.3)", kernel="quantization_v", off=0.0,
                                         element="quantization")
    command_noise_v: float = _environment("V", "command noise rms (stage 3)", kernel="command_noise_v", off=0.0,
                                          element="noise")
    feedback_noise_v: float = _environment("V", "feedback noise rms (stage 17)", kernel="feedback_noise_v", off=0.0,
                                           element="noise")
    noise_bandwidth_hz: float = _environment("Hz", "bandwidth of the first-order noise (stages 3, 17)",
                                             kernel="noise_bandwidth_hz")
    # figure 33 and 36 (HOAD3)
    total_breakpoints_lbf: tuple[float, float] = _curve(
        "figure 33 total curve: breakpoints F1 < F2", 2, increasing=True)
    total_mean_stiffness_lbf_per_in: tuple[float, float, float] = _curve(
        "figure 33 total curve: mean segment stiffnesses", 3)
    total_upper_stiffness_lbf_per_in: tuple[float, float, float] = _curve(
        "figure 33 total curve: upper bound (most compliant) segment stiffnesses (figure 35)", 3)
    total_lower_stiffness_lbf_per_in: tuple[float, float, float] = _curve(
        "figure 33 total curve: lower bound (stiffest) segment stiffnesses (figure 35)", 3)
    actuator_breakpoints_lbf: tuple[float, float] = _curve(
        "figure 33 actuator (LVDT) curve: breakpoints F1 < F2", 2, increasing=True)
    actuator_mean_stiffness_lbf_per_in: tuple[float, float, float] = _curve(
        "figure 33 actuator curve: mean segment stiffnesses", 3)
    actuator_upper_stiffness_lbf_per_in: tuple[float, float, float] = _curve(
        "figure 33 actuator curve: upper bound segment stiffnesses", 3)
    actuator_lower_stiffness_lbf_per_in: tuple[float, float, float] = _curve(
        "figure 33 actuator curve: lower bound segment stiffnesses", 3)
    linkage_damping_lbf_s_per_in: float = pm.param("lbf·s/in", "structural damping of the figure-33 gear train",
                                                   section="hoad3", kernel="linkage_damping_lbf_s_per_in", **NONNEG)
    hysteretic_damping_lbf_per_in: float = pm.param(
        "lbf/in", "hysteretic damping h (figure 36; h = A/(π·Pk²) of test rw13, 3.2.2)", section="hoad3", off=0.0,
        **NONNEG)
    hysteresis_freq_rad_s: float = pm.param("rad/s", "ω of the viscous equivalent h/ω (3.2.2)", section="hoad3",
                                            **POS)
    hysteresis_reference_load_inlb: float = pm.param(
        "in·lb", "load amplitude of the anticipated motion that sets the average stiffness (figure 36)",
        section="hoad3", **POS)

    RELATIONS: ClassVar[tuple[pm.Relation, ...]] = (("coulomb_friction_lbf", "<=", "stiction_lbf"),)

    @classmethod
    def from_channel(cls, channel: ChannelConfig, variant: str = "hoad3", **overrides: pm.Value) -> HighOrderParams:
        """A channel's ``high_order`` section (and its ``hoad2``/``hoad3`` part for ``variant``), then overrides.

        HOAC1 has no flight/test environment: its delays, quantization and noise are zero.

        Parameters
        ----------
        channel : ChannelConfig
            The channel whose section and physical data give the defaults.
        variant : str
            ``hoac1``, ``hoad2`` or ``hoad3``.
        **overrides : float
            Parameter values that replace the channel's.

        Returns
        -------
        HighOrderParams
            The validated parameters.
        """
        if variant not in VARIANTS:
            raise UnknownNameError("high-order variant", variant, VARIANTS)
        section = channel.section(SECTION)
        if not section:
            raise ConfigError(f"{channel.channel}: no {SECTION} section")
        return pm.load(cls, section, origin=channel.channel, family=FAMILY, section=SECTION, overrides=overrides,
                       options=OPTIONS, variant=variant, source=channel)

    def validate(self) -> None:
        """Reject values no actuator can have (one message naming the parameter)."""
        pm.validate(self, FAMILY)

    def replace(self, **changes: pm.Value) -> HighOrderParams:
        """A copy with some parameters changed (validated).

        Parameters
        ----------
        **changes : float or tuple of float
            Parameter name → new value.

        Returns
        -------
        HighOrderParams
            The validated copy.
        """
        info = pm.metas(self)
        coerced: dict[str, Any] = {k: pm.coerce(k, info[k], v, "replace", FAMILY) for k, v in changes.items()}
        out = replace(self, **coerced)
        out.validate()
        return out

    def as_dict(self) -> dict[str, float | tuple[float, ...]]:
        """Name → value.

        Returns
        -------
        dict
            Every parameter.
        """
        return asdict(self)

    # ------------------------------------------------------------------ derived quantities
    @property
    def screw_in_per_rad(self) -> float:
        """G: screw travel per motor radian (lead over 2π·gear ratio)."""
        return self.screw_lead_in_per_rev / (2.0 * math.pi * self.gear_reduction_ratio)

    @property
    def torque_constant_inlb_per_a(self) -> float:
        """Kt in in·lbf/A: equal to Ke in SI units (N·m/A = V·s/rad) for an ideal motor."""
        return self.back_emf_v_s_per_rad * INLB_PER_NM

    @property
    def force_per_amp_lbf(self) -> float:
        """Screw force per motor amp, lbf/A (Kt/G)."""
        return self.torque_constant_inlb_per_a / self.screw_in_per_rad

    @property
    def back_emf_v_per_in_s(self) -> float:
        """Back-EMF per unit screw rate, V per in/s (Ke/G)."""
        return self.back_emf_v_s_per_rad / self.screw_in_per_rad

    @property
    def motor_mass_lbs2_per_in(self) -> float:
        """Rotor, gear and screw inertia seen at the screw, lbf·s²/in (J/G²)."""
        return self.rotor_inertia_inlbs2 / self.screw_in_per_rad**2

    @property
    def surface_mass_lbs2_per_in(self) -> float:
        """Surface inertia seen at the screw through the crank arm, lbf·s²/in (I/r²)."""
        return self.surface_inertia_inlbs2 / self.crank_arm_in**2

    @property
    def deg_per_in(self) -> float:
        """Surface degrees per inch of screw travel (small-angle crank arm)."""
        return RAD2DEG / self.crank_arm_in

    def curves(self, bound: float = 0.0) -> tuple[tuple[float, ...], tuple[float, ...]]:
        """Figure 33's (total, actuator) curves as ``(F1, F2, k1, k2, k3)`` at ``bound`` ∈ [−1, 1].

        ``bound`` moves each segment's compliance from the mean towards the upper (+1, most compliant)
        or the lower (−1, stiffest) bound, linearly in compliance, for Monte Carlo use.

        Parameters
        ----------
        bound : float
            −1 (lower), 0 (mean), +1 (upper), or between.

        Returns
        -------
        total : tuple of float
            The total curve ``(F1, F2, k1, k2, k3)``.
        actuator : tuple of float
            The actuator (LVDT) curve.
        """
        if not -1.0 <= bound <= 1.0:
            raise EmaError(f"compliance bound must be in [-1, 1] (lower, mean, upper), got {bound}")

        def pick(mean: tuple[float, ...], upper: tuple[float, ...], lower: tuple[float, ...]) -> tuple[float, ...]:
            edge = upper if bound >= 0.0 else lower
            w = abs(bound)
            return tuple(1.0 / ((1.0 - w) / m + w / e) for m, e in zip(mean, edge, strict=True))

        total = (*self.total_breakpoints_lbf, *pick(self.total_mean_stiffness_lbf_per_in,
                                                    self.total_upper_stiffness_lbf_per_in,
                                                    self.total_lower_stiffness_lbf_per_in))
        actuator = (*self.actuator_breakpoints_lbf, *pick(self.actuator_mean_stiffness_lbf_per_in,
                                                          self.actuator_upper_stiffness_lbf_per_in,
                                                          self.actuator_lower_stiffness_lbf_per_in))
        return total, actuator

    def kernel_vector(self, *, figure33: bool, bound: float = 0.0, hysteresis: bool = False, noise: bool = True,
                      feedback_cal: tuple[float, float, float, float] = (0.0, 1.0, 0.0, 0.0)) -> FloatArray:
        """The parameters in kernel order (the :data:`P` slots), in kernel units (SI electrical, in, lbf).

        Parameters
        ----------
        figure33 : bool
            The figure-33 gear train (HOAD3) rather than figure 32's.
        bound : float
            Figure 35's compliance bound (see :meth:`curves`).
        hysteresis : bool
            Figure 36's hysteretic damping on (figure 33 only).
        noise : bool
            The measured noise on (off: zero noise slots).
        feedback_cal : tuple of float
            The channel's feedback calibration ``(c0, c1, c2, c3)``, volts → degrees.

        Returns
        -------
        numpy.ndarray
            One float per slot of :data:`P`.
        """
        total, actuator = self.curves(bound)
        total_k = gt.three_segment_breakpoints(*total)
        act = gt.three_segment_breakpoints(*actuator)
        h = self.hysteretic_damping_lbf_per_in if (hysteresis and figure33) else 0.0
        source = self if noise else replace(self, command_noise_v=0.0, feedback_noise_v=0.0)
        extra: dict[str, float] = {
            "force_per_amp_lbf_per_a": self.force_per_amp_lbf,
            "deg_per_in": self.deg_per_in,
            "figure33": 1.0 if figure33 else 0.0,
            "hysteresis_coefficient_s": 0.0,
        }
        extra.update(zip(TOTAL_CURVE, total_k[:7], strict=True))
        extra.update(zip(ACTUATOR_CURVE, (*act[:4], *act[7:]), strict=True))
        extra.update(zip(FEEDBACK_CAL, feedback_cal, strict=True))
        if h > 0.0:
            k_avg = gt.hysteresis_average_stiffness(self.hysteresis_reference_load_inlb / self.crank_arm_in, total_k)
            extra["hysteresis_coefficient_s"] = gt.hysteresis_coefficient(h, self.hysteresis_freq_rad_s, k_avg)
        return pm.kernel_vector(source, P, extra)


TOTAL_CURVE = ("total_f1_lbf", "total_f2_lbf", "total_d1_in", "total_d2_in", "total_k1_lbf_per_in",
               "total_k2_lbf_per_in", "total_k3_lbf_per_in")
"""Figure 33's total curve in its force form (:func:`gear_train.three_segment_force`)."""
ACTUATOR_CURVE = ("actuator_f1_lbf", "actuator_f2_lbf", "actuator_d1_in", "actuator_d2_in",
                  "actuator_c1_in_per_lbf", "actuator_c2_in_per_lbf", "actuator_c3_in_per_lbf")
"""Figure 33's actuator curve in its deflection form (:func:`gear_train.three_segment_deflection`)."""
FEEDBACK_CAL = ("feedback_cal_c0_deg", "feedback_cal_c1_deg_per_v", "feedback_cal_c2_deg_per_v2",
                "feedback_cal_c3_deg_per_v3")
"""The channel's feedback calibration (stage 17's volts → degrees)."""
KERNEL_EXTRA = ("force_per_amp_lbf_per_a", "deg_per_in", "figure33", *TOTAL_CURVE, *ACTUATOR_CURVE,
                "hysteresis_coefficient_s", *FEEDBACK_CAL)
"""Kernel slots no single parameter fills: derived from several, options, the channel's calibration."""

P = pm.kernel_layout(HighOrderParams, KERNEL_EXTRA)
"""Kernel slots, generated from the declared kernel names (``p[P.position_gain_per_s]``)."""

X = pm.slots("HighOrderState", (
    "x_motor_in", "v_motor_in_s", "x_surface_in", "v_surface_in_s", "current_a", "lvdt_filtered_in", "bus_v",
    "integral_in_s", "command_noise_v", "feedback_noise_v", "flags", "delay_head",
))
"""State columns shared by the implementations; the continuous model integrates the first :data:`N_CONTINUOUS`."""
N_STATE = len(X)
N_CONTINUOUS = 8
