"""The high-fidelity family of section 3.2: HOAC1, HOAD2 and HOAD3 (tables 4 and 5).

The manufacturer's HOAC1 is proprietary, so this one is built from physics and the published
specifications (table 1, table A2, sections 1.4 and 2.5). One pipeline of named stages in the order of
figure 30, shared by the three implementations; mechanical quantities are in ball-screw coordinates
(in, in/s, lbf), the surface angle is the screw travel over the servo crank arm.

flight/test environment (HOAD2, HOAD3; section 4.2.5)
    1. command delay         command to first motion (HOAD3: 4 ms, section 2.3)
    2. command quantization  5 mV through the channel's command calibration, degrees → volts → degrees
    3. command noise         band-limited, seeded, measured rms in volts
EMAC channel and motor (figure 30; :mod:`ema_sim.models.drive`)
    4. position-loop controller electronics  Kp·(command − filtered LVDT) plus an integral that runs
                             only while the PWM drives; limited at the slew rate
    5. velocity loop         tachometer feedback, current demand limited at the current limit
    6. current loop          proportional, resistive and back-EMF feed-forward
    7. PWM with dead band    no drive for small demands, duty limit on the bus voltage
    8. brushless DC motor    DC equivalent: 0.88 Ω stator (table A2), inductance, Kt = Ke
    9. 150 V bus             supply, source resistance and bus capacitance; regeneration raises it
   10. rotor and screw inertia, ball screw and gear ratio
   11. Coulomb friction and stiction; brake engaged while unpowered (> 4,000 lbf, table 1)
gear train and surface (:mod:`ema_sim.models.gear_train`)
   12. gear train            figure 32 (HOAC1, HOAD2): backlash dead zone, gear and backup stiffness;
                             figure 33 (HOAD3): three-segment total and actuator compliance;
                             figure 36 (option): hysteretic damping h/ω scaled by stiffness
   13. servo crank arm       force ↔ hinge moment, screw travel ↔ surface angle
   14. surface inertia       with the hinge-moment input and spindle (hinge) friction
   15. LVDT with its filter  fed back to stage 4 (inside the servo loop)
flight/test environment, feedback side
   16. feedback delay        motion to feedback (HOAD3: 2 ms, section 2.3)
   17. feedback noise and 5 mV quantization through the feedback calibration

The implementations differ as table 5 says:

* ``hoac1`` continuous: adaptive Dormand–Prince with every regime change (dead band, stiction,
  backlash contact, limits, stops) located as an event (:mod:`ema_sim.models.hybrid`).
* ``hoad2`` the 10,000 Hz discrete implementation with the flight/test elements of stages 1–3, 16, 17.
* ``hoad3`` HOAD2 adjusted to the installed data: the figure-33 gear train, 4 ms + 2 ms delays.

Outputs: position = the (delayed, quantized, noisy) filtered LVDT; surface = the true surface angle,
compliance outside the loop included; rate = the motor-side screw rate; current = motor current;
bus = bus voltage. Power is an input the node layer can drive: :meth:`HighOrderModel.set_power`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass, fields, replace
from typing import Any, ClassVar

import numba as nb
import numpy as np
from numpy.typing import ArrayLike

from ema_sim.config import ChannelConfig
from ema_sim.errors import ConfigError, EmaError, UnknownNameError
from ema_sim.models import drive as dr
from ema_sim.models import gear_train as gt
from ema_sim.models import noise as nz
from ema_sim.models import stages as st
from ema_sim.models.base import (
    N_OUT,
    O_BUS,
    O_CUR,
    O_FLAGS,
    O_POS,
    O_RATE,
    O_SURF,
    ActuatorModel,
    FloatArray,
    batch_params,
)
from ema_sim.models.hybrid import make_hybrid

VARIANTS = ("hoac1", "hoad2", "hoad3")
BOUNDS = {"lower": -1.0, "mean": 0.0, "upper": 1.0}
"""Figure 35's compliance bounds: ``upper`` is the most compliant curve, ``lower`` the stiffest."""
_CURVE_FIELDS = (
    "total_breakpoints_lbf", "total_mean_stiffness_lbf_per_in", "total_upper_stiffness_lbf_per_in",
    "total_lower_stiffness_lbf_per_in", "actuator_breakpoints_lbf", "actuator_mean_stiffness_lbf_per_in",
    "actuator_upper_stiffness_lbf_per_in", "actuator_lower_stiffness_lbf_per_in",
)
_ENVIRONMENT_FIELDS = (
    "command_delay_s", "feedback_delay_s", "quantization_v", "command_noise_v", "feedback_noise_v",
    "noise_bandwidth_hz",
)
_FIG33_SCALARS = (
    "linkage_damping_lbf_s_per_in", "hysteretic_damping_lbf_per_in", "hysteresis_freq_rad_s",
    "hysteresis_reference_load_inlb",
)
OPTIONS = ("bound", "hysteresis", "noise", "seed")
"""Keyword options of the high-order models (not parameters; also accepted as ``--set`` numbers)."""


@dataclass(frozen=True)
class HighOrderParams:
    """Every parameter of the figure-30 pipeline, in the units its name carries (config ``high_order``)."""

    # position-loop controller electronics, velocity and current loops, PWM (EMAC channel)
    position_gain_per_s: float
    position_integral_per_s2: float
    rate_limit_in_s: float
    velocity_gain_a_per_in_s: float
    lvdt_filter_hz: float
    current_limit_a: float
    current_gain_v_per_a: float
    pwm_dead_band_v: float
    pwm_max_duty_ratio: float
    # motor, gears and screw
    stator_resistance_ohm: float
    inductance_mh: float
    back_emf_v_s_per_rad: float
    rotor_inertia_inlbs2: float
    gear_reduction_ratio: float
    screw_lead_in_per_rev: float
    # 150 V bus
    bus_supply_v: float
    bus_source_resistance_ohm: float
    bus_capacitance_uf: float
    # friction and brake
    coulomb_friction_lbf: float
    stiction_lbf: float
    brake_holding_lbf: float
    hinge_friction_inlb: float
    # figure 32 gear train
    gear_backlash_in: float
    gear_stiffness_lbf_per_in: float
    backup_stiffness_lbf_per_in: float
    gear_damping_lbf_s_per_in: float
    # channel geometry (tables 1, A2)
    crank_arm_in: float
    surface_inertia_inlbs2: float
    position_min_deg: float
    position_max_deg: float
    # flight/test environment (zero for HOAC1)
    command_delay_s: float
    feedback_delay_s: float
    quantization_v: float
    command_noise_v: float
    feedback_noise_v: float
    noise_bandwidth_hz: float
    # figure 33 and 36 (HOAD3)
    total_breakpoints_lbf: tuple[float, float]
    total_mean_stiffness_lbf_per_in: tuple[float, float, float]
    total_upper_stiffness_lbf_per_in: tuple[float, float, float]
    total_lower_stiffness_lbf_per_in: tuple[float, float, float]
    actuator_breakpoints_lbf: tuple[float, float]
    actuator_mean_stiffness_lbf_per_in: tuple[float, float, float]
    actuator_upper_stiffness_lbf_per_in: tuple[float, float, float]
    actuator_lower_stiffness_lbf_per_in: tuple[float, float, float]
    linkage_damping_lbf_s_per_in: float
    hysteretic_damping_lbf_per_in: float
    hysteresis_freq_rad_s: float
    hysteresis_reference_load_inlb: float

    @classmethod
    def from_channel(cls, channel: ChannelConfig, variant: str = "hoad3", **overrides: Any) -> HighOrderParams:  # noqa: PLR0912
        """A channel's ``high_order`` section (and its ``hoad2``/``hoad3`` part for ``variant``), then overrides.

        HOAC1 has no flight/test environment: its delays, quantization and noise are zero.
        """
        if variant not in VARIANTS:
            raise UnknownNameError("high-order variant", variant, VARIANTS)
        sec = channel.section("high_order")
        if not sec:
            raise ConfigError(f"{channel.channel}: no high_order section")
        names = {f.name for f in fields(cls)}
        values: dict[str, Any] = {
            "crank_arm_in": channel.crank_arm_in,
            "surface_inertia_inlbs2": channel.surface_inertia_inlbs2,
            "position_min_deg": channel.position_min_deg,
            "position_max_deg": channel.position_max_deg,
        }
        subsections = {"hoad2", "hoad3"}
        for key, value in sec.items():
            if key in subsections:
                continue
            if key not in names:
                raise ConfigError(f"{channel.channel}: unknown high_order parameter {key!r}")
            values[key] = value
        hoad3 = dict(sec.get("hoad3", {}))
        env = dict(sec.get(variant, {})) if variant != "hoac1" else {}
        for part, allowed in ((hoad3, set(_CURVE_FIELDS) | set(_FIG33_SCALARS) | set(_ENVIRONMENT_FIELDS)),
                              (dict(sec.get("hoad2", {})), set(_ENVIRONMENT_FIELDS))):
            for key in part:
                if key not in allowed:
                    raise ConfigError(f"{channel.channel}: unknown high_order parameter {key!r}")
        for key in (*_CURVE_FIELDS, *_FIG33_SCALARS):
            if key in hoad3:
                values[key] = hoad3[key]
        for key in _ENVIRONMENT_FIELDS:
            values[key] = env.get(key, 0.0)
        for key, value in overrides.items():
            if key not in names:
                raise UnknownNameError("high-order parameter", key, names | set(OPTIONS))
            values[key] = value
        missing = names - values.keys()
        if missing:
            raise ConfigError(f"{channel.channel}: high_order is missing {', '.join(sorted(missing))}")
        params = cls(**{k: _as_value(k, v) for k, v in values.items()})
        params.validate()
        return params

    def validate(self) -> None:
        """Reject values no actuator can have (one message naming the parameter)."""
        for f in fields(self):
            value = getattr(self, f.name)
            items = value if isinstance(value, tuple) else (value,)
            if not all(math.isfinite(v) for v in items):
                raise ConfigError(f"high-order parameter {f.name} must be finite")
            if any(v < 0.0 for v in items) and f.name not in ("position_min_deg", "position_max_deg"):
                raise ConfigError(f"high-order parameter {f.name} must not be negative")
        positive = (
            "position_gain_per_s", "rate_limit_in_s", "velocity_gain_a_per_in_s", "lvdt_filter_hz",
            "current_limit_a", "pwm_max_duty_ratio", "stator_resistance_ohm", "inductance_mh",
            "back_emf_v_s_per_rad", "rotor_inertia_inlbs2", "gear_reduction_ratio", "screw_lead_in_per_rev",
            "bus_supply_v", "bus_source_resistance_ohm", "bus_capacitance_uf", "gear_stiffness_lbf_per_in",
            "backup_stiffness_lbf_per_in", "crank_arm_in", "surface_inertia_inlbs2", "hysteresis_freq_rad_s",
            "hysteresis_reference_load_inlb",
        )
        for name in positive:
            if getattr(self, name) <= 0.0:
                raise ConfigError(f"high-order parameter {name} must be positive")
        if self.pwm_max_duty_ratio > 1.0:
            raise ConfigError("pwm_max_duty_ratio must not exceed 1")
        if self.stiction_lbf < self.coulomb_friction_lbf:
            raise ConfigError("stiction_lbf must be at least coulomb_friction_lbf")
        if self.position_min_deg >= self.position_max_deg:
            raise ConfigError("position_min_deg must be below position_max_deg")
        for name in ("total_breakpoints_lbf", "actuator_breakpoints_lbf"):
            f1, f2 = getattr(self, name)
            if not 0.0 < f1 < f2:
                raise ConfigError(f"{name} must be two increasing positive forces")
        for name in _CURVE_FIELDS:
            if "stiffness" in name and min(getattr(self, name)) <= 0.0:
                raise ConfigError(f"{name} must be positive")

    def replace(self, **changes: Any) -> HighOrderParams:
        """A copy with some parameters changed (validated)."""
        out = replace(self, **{k: _as_value(k, v) for k, v in changes.items()})
        out.validate()
        return out

    def as_dict(self) -> dict[str, Any]:
        """Name → value."""
        return asdict(self)

    # ------------------------------------------------------------------ derived quantities
    @property
    def screw_in_per_rad(self) -> float:
        """G: screw travel per motor radian (lead over 2π·gear ratio)."""
        return self.screw_lead_in_per_rev / (2.0 * math.pi * self.gear_reduction_ratio)

    @property
    def torque_constant_inlb_per_a(self) -> float:
        """Kt in in·lbf/A: equal to Ke in SI units (N·m/A = V·s/rad) for an ideal motor."""
        return self.back_emf_v_s_per_rad * dr.INLB_PER_NM

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
        return st.RAD2DEG / self.crank_arm_in

    def curves(self, bound: float = 0.0) -> tuple[tuple[float, ...], tuple[float, ...]]:
        """Figure 33's (total, actuator) curves as ``(F1, F2, k1, k2, k3)`` at ``bound`` ∈ [−1, 1].

        ``bound`` moves each segment's compliance from the mean towards the upper (+1, most compliant)
        or the lower (−1, stiffest) bound, linearly in compliance, for Monte Carlo use.
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

    def kernel_vector(self, *, figure33: bool, bound: float = 0.0, hysteresis: bool = False,
                      noise: bool = True, feedback_cal: tuple[float, float, float, float] = (0.0, 1.0, 0.0, 0.0)
                      ) -> FloatArray:
        """The parameters in kernel order (the ``K_*`` indices), in kernel units (SI electrical, in/lbf)."""
        total, actuator = self.curves(bound)
        total_k = gt.three_segment_breakpoints(*total)
        act = gt.three_segment_breakpoints(*actuator)
        k_avg = gt.hysteresis_average_stiffness(self.hysteresis_reference_load_inlb / self.crank_arm_in, total_k)
        h = self.hysteretic_damping_lbf_per_in if (hysteresis and figure33) else 0.0
        v = np.zeros(N_KERNEL)
        v[K_KP] = self.position_gain_per_s
        v[K_KI] = self.position_integral_per_s2
        v[K_VMAX] = self.rate_limit_in_s
        v[K_KV] = self.velocity_gain_a_per_in_s
        v[K_WLF] = st.TWO_PI * self.lvdt_filter_hz
        v[K_IMAX] = self.current_limit_a
        v[K_KC] = self.current_gain_v_per_a
        v[K_VDB] = self.pwm_dead_band_v
        v[K_DUTY] = self.pwm_max_duty_ratio
        v[K_R] = self.stator_resistance_ohm
        v[K_L] = self.inductance_mh * 1e-3
        v[K_KE] = self.back_emf_v_per_in_s
        v[K_KF] = self.force_per_amp_lbf
        v[K_MM] = self.motor_mass_lbs2_per_in
        v[K_MS] = self.surface_mass_lbs2_per_in
        v[K_ARM] = self.crank_arm_in
        v[K_VSUP] = self.bus_supply_v
        v[K_RSRC] = self.bus_source_resistance_ohm
        v[K_CBUS] = self.bus_capacitance_uf * 1e-6
        v[K_FC] = self.coulomb_friction_lbf
        v[K_FS] = self.stiction_lbf
        v[K_FB] = self.brake_holding_lbf
        v[K_FH] = self.hinge_friction_inlb / self.crank_arm_in
        v[K_HB] = 0.5 * self.gear_backlash_in
        v[K_KSER] = gt.series_stiffness(self.gear_stiffness_lbf_per_in, self.backup_stiffness_lbf_per_in)
        v[K_KB] = self.backup_stiffness_lbf_per_in
        v[K_CG] = self.gear_damping_lbf_s_per_in
        v[K_XMIN] = self.position_min_deg / self.deg_per_in
        v[K_XMAX] = self.position_max_deg / self.deg_per_in
        v[K_CMD_DELAY] = self.command_delay_s
        v[K_FB_DELAY] = self.feedback_delay_s
        v[K_QUANT] = self.quantization_v
        v[K_NCMD] = self.command_noise_v if noise else 0.0
        v[K_NFB] = self.feedback_noise_v if noise else 0.0
        v[K_NBW] = self.noise_bandwidth_hz
        v[K_FIG33] = 1.0 if figure33 else 0.0
        v[K_T_F1:K_T_K3 + 1] = total_k[:7]
        v[K_A_F1:K_A_C3 + 1] = (*act[:4], *act[7:])
        v[K_CLINK] = self.linkage_damping_lbf_s_per_in
        v[K_HC] = gt.hysteresis_coefficient(h, self.hysteresis_freq_rad_s, k_avg)
        v[K_KAVG] = k_avg
        v[K_DPI] = self.deg_per_in
        v[K_FBC0:K_FBC3 + 1] = feedback_cal
        return v


def _as_value(name: str, value: Any) -> Any:
    if name in _CURVE_FIELDS:
        items = tuple(float(x) for x in np.asarray(value, dtype=float).ravel())
        want = 2 if "breakpoints" in name else 3
        if len(items) != want:
            raise ConfigError(f"high-order parameter {name} needs {want} values, got {len(items)}")
        return items
    return float(value)


(
    K_KP, K_VMAX, K_KV, K_WLF, K_IMAX, K_KC, K_VDB, K_DUTY, K_R, K_L, K_KE, K_KF, K_MM, K_MS, K_ARM,
    K_VSUP, K_RSRC, K_CBUS, K_FC, K_FS, K_FB, K_HB, K_KSER, K_KB, K_CG, K_XMIN, K_XMAX, K_CMD_DELAY,
    K_FB_DELAY, K_QUANT, K_NCMD, K_NFB, K_NBW, K_FIG33,
    K_T_F1, K_T_F2, K_T_D1, K_T_D2, K_T_K1, K_T_K2, K_T_K3,  # figure 33 total curve: force form
    K_A_F1, K_A_F2, K_A_G1, K_A_G2, K_A_C1, K_A_C2, K_A_C3,  # figure 33 actuator curve: deflection form
    K_CLINK, K_HC, K_KAVG, K_DPI, K_FBC0, K_FBC1, K_FBC2, K_FBC3, K_FH, K_KI,
) = range(58)
N_KERNEL = 58

# State columns shared by the implementations (the continuous model integrates the first seven).
X_XM, X_VM, X_XS, X_VS, X_I, X_LF, X_VBUS, X_XI, X_NCMD, X_NFB, X_TFB, X_FLAGS, X_HEAD = range(13)
N_STATE = 13
N_CONTINUOUS = 8


# ================================================================================ shared stages
@st.jit
def _total_force(p, d):  # noqa: ANN001, ANN202
    """Figure 33's total gear-train and linkage curve: (force, tangent stiffness, segment)."""
    return gt.three_segment_force(d, p[K_T_F1], p[K_T_F2], p[K_T_D1], p[K_T_D2], p[K_T_K1], p[K_T_K2], p[K_T_K3])


@st.jit
def _total_deflection(p, force):  # noqa: ANN001, ANN202
    """Deflection of the total curve under ``force``."""
    return gt.three_segment_deflection(force, p[K_T_F1], p[K_T_F2], p[K_T_D1], p[K_T_D2], 1.0 / p[K_T_K1],
                                       1.0 / p[K_T_K2], 1.0 / p[K_T_K3])


@st.jit
def _actuator_deflection(p, force):  # noqa: ANN001, ANN202
    """Figure 33's actuator (in-loop, LVDT) compliance: deflection under ``force``."""
    return gt.three_segment_deflection(force, p[K_A_F1], p[K_A_F2], p[K_A_G1], p[K_A_G2], p[K_A_C1], p[K_A_C2],
                                       p[K_A_C3])


@nb.njit(cache=True, inline="always", error_model="numpy")
def _gear_train(p, xm, xs):  # noqa: ANN001, ANN202
    """Stage 12 (and 15's LVDT reading): spring force, damping coefficient, LVDT, free-play flag.

    The damper's force ``c·(v_motor − v_surface)`` is left to the integrator, which takes it
    implicitly on each mass.
    """
    d = xm - xs
    if p[K_FIG33] > 0.5:
        fk, ktan, seg = _total_force(p, d)
        c = p[K_CLINK] + gt.hysteretic_damping(p[K_HC], ktan)
        lvdt = gt.lvdt_fig33(xm, fk, p[K_A_F1], p[K_A_F2], p[K_A_G1], p[K_A_G2], p[K_A_C1], p[K_A_C2], p[K_A_C3])
        return fk, c, lvdt, seg == 1
    seg = gt.dead_zone_segment(d, p[K_HB])
    fk, _ = gt.gear_train_fig32(d, 0.0, p[K_HB], p[K_KSER], p[K_CG], seg)
    c = p[K_CG] if seg != 0 else 0.0
    return fk, c, gt.lvdt_fig32(xs, fk, p[K_KB]), seg == 0


@nb.njit(cache=True)
def _cubic(c0, c1, c2, c3, x):  # noqa: ANN001, ANN202
    return c0 + x * (c1 + x * (c2 + x * c3))


@nb.njit(cache=True)
def _cubic_inverse(c0, c1, c2, c3, y):  # noqa: ANN001, ANN202
    """Newton on the calibration cubic from the linear guess (as :meth:`Cubic.inverse`)."""
    x = (y - c0) / c1
    for _ in range(8):
        dx = (c0 + x * (c1 + x * (c2 + x * c3)) - y) / (c1 + x * (2.0 * c2 + 3.0 * c3 * x))
        x -= dx
        if abs(dx) <= 1e-15 * (1.0 + abs(x)):
            break
    return x


@nb.njit(cache=True)
def command_in(P, c0, c1, c2, c3, bp_u, x_out, slope_out):  # noqa: ANN001, ANN201
    """Stage 2 on every breakpoint of every instance: degrees → volts (command curve) → 5 mV → degrees → in.

    ``slope_out`` gets the inches per volt at the quantized command (for the command noise); with
    neither quantization nor command noise the command passes straight through and the slope is 0.
    The operations are those of :class:`~ema_sim.calibration.Cubic` in the same order (``__call__``,
    8 Newton steps of ``inverse``, ``slope``), so the result is the same to the last bit.
    """
    quant_any = False
    noise_any = False
    for i in range(P.shape[0]):
        quant_any = quant_any or P[i, K_QUANT] > 0.0
        noise_any = noise_any or P[i, K_NCMD] > 0.0
    for i in range(P.shape[0]):
        dpi = P[i, K_DPI]
        quant = P[i, K_QUANT]
        for j in range(bp_u.shape[1]):
            u = bp_u[i, j]
            if not quant_any and not noise_any:
                x_out[i, j] = u / dpi
                slope_out[i, j] = 0.0
                continue
            deg = u
            if quant > 0.0:
                volts = c0 + u * (c1 + u * (c2 + u * c3))
                y = quant * math.floor(volts / quant + 0.5)
                deg = (y - c0) / c1
                for _ in range(8):
                    f = (c0 + deg * (c1 + deg * (c2 + deg * c3))) - y
                    deg = deg - f / (c1 + deg * (2.0 * c2 + 3.0 * c3 * deg))
            x_out[i, j] = deg / dpi
            slope_out[i, j] = 1.0 / ((c1 + deg * (2.0 * c2 + 3.0 * c3 * deg)) * dpi)


@nb.njit(cache=True)
def _feedback_deg(p, lf_in, s, x, rng):  # noqa: ANN001, ANN202
    """Stages 16–17 at a sample instant ``s``: LVDT degrees → volts (+ noise) → 5 mV → degrees."""
    deg = lf_in * p[K_DPI]
    if p[K_QUANT] <= 0.0 and p[K_NFB] <= 0.0:
        return deg
    c0, c1, c2, c3 = p[K_FBC0], p[K_FBC1], p[K_FBC2], p[K_FBC3]
    volts = _cubic_inverse(c0, c1, c2, c3, deg)
    if p[K_NFB] > 0.0:
        decay = math.exp(-st.TWO_PI * p[K_NBW] * max(s - x[X_TFB], 0.0)) if p[K_NBW] > 0.0 else 0.0
        x[X_NFB] = nz.band_limited_step(x[X_NFB], decay, p[K_NFB] * math.sqrt(1.0 - decay * decay), rng)
        x[X_TFB] = s
        volts += x[X_NFB]
    volts = st.quantize(volts, p[K_QUANT])
    return _cubic(c0, c1, c2, c3, volts)


@nb.njit(cache=True, error_model="numpy", fastmath={"contract", "arcp", "nsz"})
def run_discrete(P, X, RNG, BUF, POWER, bp_t, cmd_in, cmd_slope, bp_h, t0, dt, n_steps, sample_t, out):  # noqa: ANN001, ANN201, PLR0912, PLR0915
    """HOAD2/HOAD3 fixed-step kernel: every instance through ``n_steps`` steps from ``t0``.

    ``cmd_in`` is the command after stages 2 (in, per input breakpoint), ``cmd_slope`` its inches per
    volt for the command noise. A sample at time s reads the state of the last step at or before s.
    Mechanics are symplectic Euler (stable for the stiff gear train), the motor current and the bus
    voltage exact over each step with the bridge voltage held, as the EMAC's sampled loops would be.
    """
    k_samples = sample_t.shape[0]
    for i in range(P.shape[0]):
        p = P[i]
        x = X[i]
        rng = RNG[i]
        buf = BUF[i]
        nbuf = buf.shape[0]
        kp = p[K_KP]
        ki_dt = p[K_KI] * dt
        vmax = p[K_VMAX]
        kv = p[K_KV]
        imax = p[K_IMAX]
        kc = p[K_KC]
        vdb = p[K_VDB]
        duty = p[K_DUTY]
        r = p[K_R]
        ke = p[K_KE]
        kf = p[K_KF]
        arm = p[K_ARM]
        vsup = p[K_VSUP]
        rsrc = p[K_RSRC]
        xmin = p[K_XMIN]
        xmax = p[K_XMAX]
        delay = p[K_CMD_DELAY]
        dt_m = dt / p[K_MM]
        dt_s = dt / p[K_MS]
        inv_arm = 1.0 / arm
        inv_r = 1.0 / r
        decay_i = math.exp(-r * dt / p[K_L])
        g_lf = 1.0 - math.exp(-p[K_WLF] * dt)
        decay_bus = math.exp(-dt / (rsrc * p[K_CBUS]))
        a_cmd = math.exp(-st.TWO_PI * p[K_NBW] * dt) if p[K_NBW] > 0.0 else 0.0
        w_cmd = p[K_NCMD] * math.sqrt(1.0 - a_cmd * a_cmd)
        n_delay = min(round(p[K_FB_DELAY] / dt), nbuf - 1)
        on = POWER[i] > 0.5
        brake = 0.0 if on else p[K_FB]
        fc = p[K_FC] + brake
        fs = p[K_FS] + brake
        fh = p[K_FH]
        xm = x[X_XM]
        vm = x[X_VM]
        xs = x[X_XS]
        vs = x[X_VS]
        cur = x[X_I]
        lf = x[X_LF]
        vbus = x[X_VBUS]
        ncmd = x[X_NCMD]
        xi = x[X_XI]
        flags = int(x[X_FLAGS])
        head = int(x[X_HEAD])
        jd = st.zoh_index(bp_t, t0 - delay, 0)
        jh = st.zoh_index(bp_t, t0, 0)
        js = 0
        for k in range(n_steps + 1):
            t = t0 + k * dt
            while js < k_samples and (k == n_steps or sample_t[js] < t + dt - st.TIME_EPS_S):
                row = out[i, js]
                lagged = buf[head - n_delay if head >= n_delay else head - n_delay + nbuf]
                row[O_POS] = _feedback_deg(p, lagged, sample_t[js], x, rng)
                row[O_SURF] = xs * p[K_DPI]
                row[O_RATE] = vm * p[K_DPI]
                row[O_CUR] = cur
                row[O_BUS] = vbus if on else 0.0
                row[O_FLAGS] = flags
                js += 1
            if k == n_steps:
                break
            jd = st.zoh_index(bp_t, t - delay, jd)
            jh = st.zoh_index(bp_t, t, jh)
            hm = bp_h[i, jh]
            flags = 0
            # stages 1–3: delayed, quantized command with noise (volts → inches at its calibration slope)
            ncmd = nz.band_limited_step(ncmd, a_cmd, w_cmd, rng)
            xc = cmd_in[i, jd] + ncmd * cmd_slope[i, jd]
            if xc > xmax:
                xc = xmax
                flags |= st.FLAG_POSITION
            elif xc < xmin:
                xc = xmin
                flags |= st.FLAG_POSITION
            # stages 12, 15: gear train, LVDT and its filter
            fk, c, lvdt, free = _gear_train(p, xm, xs)
            if free:
                flags |= st.FLAG_FREE_PLAY
            lf += g_lf * (lvdt - lf)
            head += 1
            if head == nbuf:
                head = 0
            buf[head] = lf
            # stages 4–8: controller electronics, current loop, PWM, motor
            if on:
                err = xc - lf
                vc_raw = dr.position_loop(xc, lf, kp, xi)
                sv = dr.saturation_segment(vc_raw, vmax)
                ic_raw = dr.velocity_loop(dr.saturate(vc_raw, vmax, sv), vm, kv)
                si = dr.saturation_segment(ic_raw, imax)
                vd = dr.current_loop(dr.saturate(ic_raw, imax, si), cur, vm, kc, r, ke)
                vlim = duty * vbus
                sp = dr.pwm_segment(vd, vdb, vlim)
                v = dr.pwm(vd, vdb, vlim, sp)
                cur = dr.motor_current_step(v, cur, vm, inv_r, ke, decay_i)
                if dr.integrating(sv, si, sp):
                    xi += ki_dt * err
                if sv != 0:
                    flags |= st.FLAG_RATE
                if si != 0:
                    flags |= st.FLAG_CURRENT
                if sp == 0:
                    flags |= st.FLAG_PWM_DEAD_BAND
            else:
                v = 0.0
                cur = 0.0
                si = 0
                flags |= st.FLAG_BRAKE
            # stages 10–11, 13–14: motor and screw with friction (symplectic Euler), surface
            vm = dr.friction_step(vm, kf * cur - fk + c * vs, fc, fs, dt_m, c * dt_m)
            xm += vm * dt
            if xm >= xmax:
                xm = xmax
                vm = min(vm, 0.0)
                flags |= st.FLAG_POSITION
            elif xm <= xmin:
                xm = xmin
                vm = max(vm, 0.0)
                flags |= st.FLAG_POSITION
            if si != 0 and vm == 0.0:
                flags |= st.FLAG_STALL
            vs = dr.friction_step(vs, fk + c * vm + hm * inv_arm, fh, fh, dt_s, c * dt_s)
            xs += vs * dt
            # stage 9: the bus
            vbus = dr.bus_voltage_step(vbus, dr.bus_current(v, cur, vbus), vsup, rsrc, decay_bus)
        x[X_XM] = xm
        x[X_VM] = vm
        x[X_XS] = xs
        x[X_VS] = vs
        x[X_I] = cur
        x[X_LF] = lf
        x[X_VBUS] = vbus
        x[X_NCMD] = ncmd
        x[X_XI] = xi
        x[X_FLAGS] = flags
        x[X_HEAD] = head


# ================================================================================ HOAC1 (continuous)
# Inputs and held regimes of the continuous model, in its ``u`` vector.
U_XC, U_HM, U_POWER, U_VC, U_IC, U_PWM, U_MOTOR, U_GEAR, U_SURF = range(9)
N_U = 9
MOTOR_STOP_LOW, MOTOR_SLIP_NEG, MOTOR_STUCK, MOTOR_SLIP_POS, MOTOR_STOP_HIGH = -2, -1, 0, 1, 2
N_GUARDS = 11
INF = math.inf


@nb.njit(cache=True)
def _hoac1_drive(p, y, u):  # noqa: ANN001, ANN202
    """Stages 4–8 with the held regimes: (velocity demand raw, current demand raw, voltage demand, V)."""
    vc_raw = dr.position_loop(u[U_XC], y[X_LF], p[K_KP], y[X_XI])
    vc = dr.saturate(vc_raw, p[K_VMAX], int(u[U_VC]))
    ic_raw = dr.velocity_loop(vc, y[X_VM], p[K_KV])
    ic = dr.saturate(ic_raw, p[K_IMAX], int(u[U_IC]))
    vd = dr.current_loop(ic, y[X_I], y[X_VM], p[K_KC], p[K_R], p[K_KE])
    v = dr.pwm(vd, p[K_VDB], p[K_DUTY] * y[X_VBUS], int(u[U_PWM]))
    return vc_raw, ic_raw, vd, v


@nb.njit(cache=True)
def _hoac1_forces(p, y, u):  # noqa: ANN001, ANN202
    """Spring force, gear force and the force applied to the motor (all but friction)."""
    fk, f = gt.gear_train_fig32(y[X_XM] - y[X_XS], y[X_VM] - y[X_VS], p[K_HB], p[K_KSER], p[K_CG], int(u[U_GEAR]))
    return fk, f, p[K_KF] * y[X_I] - f


@nb.njit(cache=True)
def _friction_levels(p, u):  # noqa: ANN001, ANN202
    brake = 0.0 if u[U_POWER] > 0.5 else p[K_FB]
    return p[K_FC] + brake, p[K_FS] + brake


@nb.njit(cache=True)
def _hoac1_rhs(t, y, p, u, dydt):  # noqa: ANN001, ANN202, ARG001 - the integrator's signature
    """HOAC1 right-hand side with every regime held (see :mod:`ema_sim.models.hybrid`)."""
    fk, f, fapp = _hoac1_forces(p, y, u)
    dydt[X_LF] = p[K_WLF] * (gt.lvdt_fig32(y[X_XS], fk, p[K_KB]) - y[X_LF])
    dydt[X_XI] = 0.0
    if u[U_POWER] > 0.5:
        _, _, _, v = _hoac1_drive(p, y, u)
        dydt[X_I] = dr.motor_current_rate(v, y[X_I], y[X_VM], p[K_R], p[K_L], p[K_KE])
        if dr.integrating(int(u[U_VC]), int(u[U_IC]), int(u[U_PWM])):
            dydt[X_XI] = p[K_KI] * (u[U_XC] - y[X_LF])
    else:
        v = 0.0
        dydt[X_I] = 0.0
    motor = int(u[U_MOTOR])
    if motor in (MOTOR_SLIP_POS, MOTOR_SLIP_NEG):
        fc, _ = _friction_levels(p, u)
        dydt[X_XM] = y[X_VM]
        dydt[X_VM] = (fapp - motor * fc) / p[K_MM]
    else:
        dydt[X_XM] = 0.0
        dydt[X_VM] = 0.0
    surface = int(u[U_SURF])
    if surface != 0:
        dydt[X_XS] = y[X_VS]
        dydt[X_VS] = (f + u[U_HM] / p[K_ARM] - surface * p[K_FH]) / p[K_MS]
    else:
        dydt[X_XS] = 0.0
        dydt[X_VS] = 0.0
    dydt[X_VBUS] = dr.bus_voltage_rate(y[X_VBUS], dr.bus_current(v, y[X_I], y[X_VBUS]), p[K_VSUP], p[K_RSRC],
                                       p[K_CBUS])


@nb.njit(cache=True)
def _pair(raw, limit, seg):  # noqa: ANN001, ANN202
    """Lower and upper guards of a saturation held on ``seg``."""
    if seg > 0:
        return raw - limit, INF
    if seg < 0:
        return INF, -limit - raw
    return raw + limit, limit - raw


@nb.njit(cache=True)
def _hoac1_guards(t, y, p, u, g):  # noqa: ANN001, ANN202, ARG001, PLR0912
    """Distance of every held regime to its boundary (positive inside)."""
    for j in range(N_GUARDS):
        g[j] = INF
    if u[U_POWER] > 0.5:
        vc_raw, ic_raw, vd, _ = _hoac1_drive(p, y, u)
        g[0], g[1] = _pair(vc_raw, p[K_VMAX], int(u[U_VC]))
        g[2], g[3] = _pair(ic_raw, p[K_IMAX], int(u[U_IC]))
        vdb = p[K_VDB]
        vl = p[K_DUTY] * y[X_VBUS]
        seg = int(u[U_PWM])
        b0, b1, b2, b3 = -vdb - vl, -vdb, vdb, vdb + vl
        if seg == -2:
            g[5] = b0 - vd
        elif seg == -1:
            g[4] = vd - b0
            g[5] = b1 - vd
        elif seg == 0:
            g[4] = vd - b1
            g[5] = b2 - vd
        elif seg == 1:
            g[4] = vd - b2
            g[5] = b3 - vd
        else:
            g[4] = vd - b3
    d = y[X_XM] - y[X_XS]
    g[6], g[7] = _pair(d, p[K_HB], int(u[U_GEAR]))
    _, _, fapp = _hoac1_forces(p, y, u)
    _, fs = _friction_levels(p, u)
    motor = int(u[U_MOTOR])
    if motor == MOTOR_STUCK:
        g[8] = fs - abs(fapp)
    elif motor == MOTOR_SLIP_POS:
        g[8] = y[X_VM]
        g[9] = p[K_XMAX] - y[X_XM]
    elif motor == MOTOR_SLIP_NEG:
        g[8] = -y[X_VM]
        g[9] = y[X_XM] - p[K_XMIN]
    elif motor == MOTOR_STOP_HIGH:
        g[8] = fapp + fs
    else:
        g[8] = fs - fapp
    surface = int(u[U_SURF])
    if surface == 0:
        _, f, _ = _hoac1_forces(p, y, u)
        g[10] = p[K_FH] - abs(f + u[U_HM] / p[K_ARM])
    else:
        g[10] = surface * y[X_VS]


@nb.njit(cache=True)
def _surface_stops_or_reverses(p, y, u):  # noqa: ANN001, ANN202
    """The surface at zero speed: held by hinge friction or slipping the way the net force pushes."""
    y[X_VS] = 0.0
    _, f, _ = _hoac1_forces(p, y, u)
    net = f + u[U_HM] / p[K_ARM]
    if abs(net) <= p[K_FH]:
        u[U_SURF] = 0.0
    else:
        u[U_SURF] = 1.0 if net > 0.0 else -1.0


@nb.njit(cache=True)
def _motor_stops_or_reverses(p, y, u):  # noqa: ANN001, ANN202
    """At zero speed: stick when stiction holds, otherwise slip the way the force pushes."""
    y[X_VM] = 0.0
    _, _, fapp = _hoac1_forces(p, y, u)
    _, fs = _friction_levels(p, u)
    if abs(fapp) <= fs:
        u[U_MOTOR] = MOTOR_STUCK
    else:
        u[U_MOTOR] = MOTOR_SLIP_POS if fapp > 0.0 else MOTOR_SLIP_NEG


@nb.njit(cache=True)
def _hoac1_transition(k, t, y, p, u):  # noqa: ANN001, ANN202, ARG001
    """What crossing guard ``k`` does to the regimes."""
    if k < 8:
        slot = (U_VC, U_VC, U_IC, U_IC, U_PWM, U_PWM, U_GEAR, U_GEAR)[k]
        u[slot] += -1.0 if k % 2 == 0 else 1.0
        return
    if k == 10:  # hinge friction
        if int(u[U_SURF]) == 0:
            _, f, _ = _hoac1_forces(p, y, u)
            u[U_SURF] = 1.0 if f + u[U_HM] / p[K_ARM] > 0.0 else -1.0
        else:
            _surface_stops_or_reverses(p, y, u)
        return
    motor = int(u[U_MOTOR])
    if k == 9:  # a mechanical stop
        if motor == MOTOR_SLIP_POS:
            y[X_XM] = p[K_XMAX]
            u[U_MOTOR] = MOTOR_STOP_HIGH
        else:
            y[X_XM] = p[K_XMIN]
            u[U_MOTOR] = MOTOR_STOP_LOW
        y[X_VM] = 0.0
        return
    if motor == MOTOR_STUCK:
        _, _, fapp = _hoac1_forces(p, y, u)
        u[U_MOTOR] = MOTOR_SLIP_POS if fapp > 0.0 else MOTOR_SLIP_NEG
    elif motor in (MOTOR_SLIP_POS, MOTOR_SLIP_NEG):
        _motor_stops_or_reverses(p, y, u)
    elif motor == MOTOR_STOP_HIGH:
        u[U_MOTOR] = MOTOR_SLIP_NEG
    else:
        u[U_MOTOR] = MOTOR_SLIP_POS


@nb.njit(cache=True)
def _hoac1_settle(t, y, p, u):  # noqa: ANN001, ANN202, ARG001
    """Classify every regime from the state (after an input change, or several events at once)."""
    if u[U_POWER] > 0.5:
        vc_raw = dr.position_loop(u[U_XC], y[X_LF], p[K_KP], y[X_XI])
        u[U_VC] = dr.saturation_segment(vc_raw, p[K_VMAX])
        vc = dr.saturate(vc_raw, p[K_VMAX], int(u[U_VC]))
        ic_raw = dr.velocity_loop(vc, y[X_VM], p[K_KV])
        u[U_IC] = dr.saturation_segment(ic_raw, p[K_IMAX])
        _, _, vd, _ = _hoac1_drive(p, y, u)
        u[U_PWM] = dr.pwm_segment(vd, p[K_VDB], p[K_DUTY] * y[X_VBUS])
    u[U_GEAR] = gt.dead_zone_segment(y[X_XM] - y[X_XS], p[K_HB])
    motor = int(u[U_MOTOR])
    _, _, fapp = _hoac1_forces(p, y, u)
    fc, fs = _friction_levels(p, u)
    if motor == MOTOR_STUCK:
        if abs(fapp) > fs:
            u[U_MOTOR] = MOTOR_SLIP_POS if fapp > 0.0 else MOTOR_SLIP_NEG
    elif motor in (MOTOR_SLIP_POS, MOTOR_SLIP_NEG):
        if motor * y[X_VM] < 0.0 or (y[X_VM] == 0.0 and motor * (fapp - motor * fc) < 0.0):
            _motor_stops_or_reverses(p, y, u)
        elif motor == MOTOR_SLIP_POS and y[X_XM] >= p[K_XMAX]:
            y[X_XM] = p[K_XMAX]
            y[X_VM] = 0.0
            u[U_MOTOR] = MOTOR_STOP_HIGH
        elif motor == MOTOR_SLIP_NEG and y[X_XM] <= p[K_XMIN]:
            y[X_XM] = p[K_XMIN]
            y[X_VM] = 0.0
            u[U_MOTOR] = MOTOR_STOP_LOW
    elif motor == MOTOR_STOP_HIGH and fapp < -fs:
        u[U_MOTOR] = MOTOR_SLIP_NEG
    elif motor == MOTOR_STOP_LOW and fapp > fs:
        u[U_MOTOR] = MOTOR_SLIP_POS
    surface = int(u[U_SURF])
    _, f, _ = _hoac1_forces(p, y, u)
    net = f + u[U_HM] / p[K_ARM]
    if surface == 0:
        if abs(net) > p[K_FH]:
            u[U_SURF] = 1.0 if net > 0.0 else -1.0
    elif surface * y[X_VS] < 0.0 or (y[X_VS] == 0.0 and surface * (net - surface * p[K_FH]) < 0.0):
        _surface_stops_or_reverses(p, y, u)


_hoac1_advance = make_hybrid(_hoac1_rhs, _hoac1_guards, _hoac1_transition, _hoac1_settle, N_GUARDS)


@nb.njit(cache=True)
def _hoac1_flags(p, y, u):  # noqa: ANN001, ANN202
    flags = 0
    if u[U_POWER] > 0.5:
        vc_raw, ic_raw, vd, _ = _hoac1_drive(p, y, u)
        if abs(vc_raw) > p[K_VMAX]:
            flags |= st.FLAG_RATE
        if abs(ic_raw) > p[K_IMAX]:
            flags |= st.FLAG_CURRENT
            if y[X_VM] == 0.0:
                flags |= st.FLAG_STALL
        if abs(vd) <= p[K_VDB]:
            flags |= st.FLAG_PWM_DEAD_BAND
        if u[U_XC] >= p[K_XMAX] or u[U_XC] <= p[K_XMIN]:
            flags |= st.FLAG_POSITION
    else:
        flags |= st.FLAG_BRAKE
    if abs(u[U_MOTOR]) == 2.0:
        flags |= st.FLAG_POSITION
    if gt.dead_zone_segment(y[X_XM] - y[X_XS], p[K_HB]) == 0:
        flags |= st.FLAG_FREE_PLAY
    return flags


@nb.njit(cache=True)
def run_continuous(P, Y, U, H, POWER, bp_t, cmd_in, bp_h, t0, t_end, sample_t, rtol, atol, out):  # noqa: ANN001, ANN201
    """HOAC1 kernel: integrate every instance from ``t0`` to ``t_end``, breaking at each input change.

    ``Y`` holds the continuous states, ``U`` the inputs and held regimes, ``H`` the step sizes.
    """
    k_samples = sample_t.shape[0]
    m = bp_t.shape[0]
    events = 0
    for i in range(P.shape[0]):
        p = P[i]
        y = Y[i]
        u = U[i]
        u[U_POWER] = POWER[i]
        h_max = 0.05 / p[K_WLF]
        t = t0
        jh = st.zoh_index(bp_t, t, 0)
        js = 0
        while True:
            u[U_XC] = min(max(cmd_in[i, jh], p[K_XMIN]), p[K_XMAX])
            u[U_HM] = bp_h[i, jh]
            _hoac1_settle(t, y, p, u)
            while js < k_samples and sample_t[js] <= t + st.TIME_EPS_S:
                row = out[i, js]
                row[O_POS] = y[X_LF] * p[K_DPI]
                row[O_SURF] = y[X_XS] * p[K_DPI]
                row[O_RATE] = y[X_VM] * p[K_DPI]
                row[O_CUR] = y[X_I]
                row[O_BUS] = y[X_VBUS] if u[U_POWER] > 0.5 else 0.0
                flags = _hoac1_flags(p, y, u)
                if cmd_in[i, jh] > p[K_XMAX] or cmd_in[i, jh] < p[K_XMIN]:
                    flags |= st.FLAG_POSITION
                row[O_FLAGS] = flags
                js += 1
            if t >= t_end - st.TIME_EPS_S:
                break
            t_next = t_end
            if jh + 1 < m:
                t_next = min(t_next, bp_t[jh + 1])
            if js < k_samples:
                t_next = min(t_next, sample_t[js])
            if t_next > t + st.TIME_EPS_S:
                H[i], ev = _hoac1_advance(p, u, y, t, t_next, H[i], rtol, atol, h_max)
                events += ev
            t = t_next
            jh = st.zoh_index(bp_t, t, jh)
    return events


# ================================================================================ equilibrium
def equilibrium(p: FloatArray, x_command_in: float, hinge_moment_inlb: float, powered: bool) -> dict[str, float]:
    """The state in which a held command and load leave every stage at rest (trim).

    The gear train carries the load (``F = −hm/r``) and the motor current holds it with friction
    carrying nothing. The current demand is what the current loop and the PWM dead band need for that
    current; the position integral supplies it with no servo error (without the integral, a servo
    error does). Unloaded, the PWM rests in its dead band with the integral at zero. A load the motor
    cannot hold (beyond stall plus stiction) leaves the motor on the stop the load pushes it to, with
    the current demand limited.
    """
    xc = min(max(x_command_in, p[K_XMIN]), p[K_XMAX])
    force = -hinge_moment_inlb / p[K_ARM]
    kf, kp, kv, kc, r, vdb = p[K_KF], p[K_KP], p[K_KV], p[K_KC], p[K_R], p[K_VDB]
    i_db = vdb / (kc + r)
    motor = MOTOR_STUCK
    cur = 0.0
    lf = xc
    xi = 0.0
    if powered:
        cur = force / kf
        if abs(cur) > p[K_IMAX] - i_db + p[K_FS] / kf:
            motor = MOTOR_STOP_HIGH if hinge_moment_inlb > 0.0 else MOTOR_STOP_LOW
            cur = 0.0
        elif cur != 0.0:
            ic = cur + math.copysign(i_db, cur)
            if p[K_KI] > 0.0:
                xi = ic / kv
            else:
                lf = xc - ic / (kv * kp)
    if motor == MOTOR_STUCK:
        xm, xs = _positions_from_lvdt(p, lf, force)
    else:
        xm = p[K_XMAX] if motor == MOTOR_STOP_HIGH else p[K_XMIN]
        lf, xs, cur = _at_stop(p, xm, xc, force)
    volts = r * cur
    power = volts * cur
    vbus = dr.steady_bus_voltage(p[K_VSUP], p[K_RSRC], power) if powered else p[K_VSUP]
    flags = 0 if powered else st.FLAG_BRAKE
    if powered and cur == 0.0:
        flags |= st.FLAG_PWM_DEAD_BAND
    if motor != MOTOR_STUCK or x_command_in != xc:
        flags |= st.FLAG_POSITION
    free = abs(force) <= p[K_T_F1] if p[K_FIG33] > 0.5 else gt.dead_zone_segment(xm - xs, p[K_HB]) == 0
    if free:
        flags |= st.FLAG_FREE_PLAY
    return {"xm": xm, "xs": xs, "cur": cur, "lf": lf, "vbus": vbus, "xi": xi, "motor": motor, "flags": flags}


def _positions_from_lvdt(p: FloatArray, lvdt: float, force: float) -> tuple[float, float]:
    """Motor-side and surface positions whose LVDT reading is ``lvdt`` under gear force ``force``."""
    if p[K_FIG33] > 0.5:
        xm = lvdt + _actuator_deflection(p, force)
        d = _total_deflection(p, force)
        return xm, xm - d
    xs = lvdt - force / p[K_KB]
    d = 0.0 if force == 0.0 else force / p[K_KSER] + math.copysign(p[K_HB], force)
    return xs + d, xs


def _at_stop(p: FloatArray, xm: float, xc: float, force: float) -> tuple[float, float, float]:
    """LVDT, surface position and current of a motor held on a stop (the stop takes the difference)."""
    if p[K_FIG33] > 0.5:
        lvdt = xm - _actuator_deflection(p, force)
        xs = xm - _total_deflection(p, force)
    else:
        d = 0.0 if force == 0.0 else force / p[K_KSER] + math.copysign(p[K_HB], force)
        xs = xm - d
        lvdt = xs + force / p[K_KB]
    toward = math.copysign(1.0, xc - lvdt) if xc != lvdt else 0.0
    cur = toward * (p[K_IMAX] - p[K_VDB] / (p[K_KC] + p[K_R]))
    return lvdt, xs, cur


# ================================================================================ linearization
@dataclass(frozen=True)
class LinearizedActuator:
    """HOAD3 linearized about a load, for HOALM (section 4.2.7): matrices of ``ẋ = A·x + B·u``, ``y = C·x``.

    States: motor-side screw position and rate, surface position and rate (in, in/s), motor current (A),
    filtered LVDT (in), position integral (in/s). Inputs: command (deg), hinge moment (in·lb). Outputs:
    position and surface (deg).
    """

    a: FloatArray
    b: FloatArray
    c: FloatArray
    command_delay_s: float
    feedback_delay_s: float
    total_stiffness_lbf_per_in: float
    actuator_compliance_in_per_lbf: float
    states: tuple[str, ...] = ("x_motor_in", "v_motor_in_s", "x_surface_in", "v_surface_in_s", "current_a",
                               "lvdt_filtered_in", "integral_in_s")


def linearize(params: HighOrderParams, hinge_moment_inlb: float = 0.0, *, bound: float = 0.0,
              figure33: bool = True) -> LinearizedActuator:
    """The figure-30 pipeline about the equilibrium under ``hinge_moment_inlb``, nonlinear elements removed.

    As section 4.2.7 describes for HOALM: the PWM dead band, stiction and Coulomb friction, the current,
    rate and voltage limits and the switching are taken out; the piecewise-linear compliance curves
    are replaced by their slopes at the operating force; quantization and noise are dropped; the
    command and feedback delays stay (exactly, as delays). The position integral is linear and stays
    (it integrates whenever the PWM is out of its dead band, which without a dead band is always).
    Hysteretic damping is frequency dependent and is left out.
    """
    v = params.kernel_vector(figure33=figure33, bound=bound, hysteresis=False, noise=False)
    force = -hinge_moment_inlb / v[K_ARM]
    if figure33:
        _, kt, _ = _total_force(v, _total_deflection(v, force))
        seg_c = (v[K_A_C1], v[K_A_C2], v[K_A_C3])
        ca = seg_c[0] if abs(force) < v[K_A_F1] else (seg_c[1] if abs(force) < v[K_A_F2] else seg_c[2])
        damping = v[K_CLINK]
    else:
        kt = v[K_KSER]
        ca = 1.0 / v[K_KSER] - 1.0 / v[K_KB]  # figure 32: LVDT = x_surface + F/K_backup, beyond the backlash
        damping = v[K_CG]
    kp, kv, kc, r, ll, kf = v[K_KP], v[K_KV], v[K_KC], v[K_R], v[K_L], v[K_KF]
    mm, ms, wf, dpi = v[K_MM], v[K_MS], v[K_WLF], v[K_DPI]
    a = np.zeros((7, 7))
    b = np.zeros((7, 2))
    xm, vm, xs, vs, cur, lf, xi = range(7)
    # current loop without the dead band: L·di/dt = (Kc + R)·(i_c − i), i_c = Kv·(Kp·(x_c − lf) + ∫ − v_m)
    g = (kc + r) / ll
    a[cur, cur] = -g
    a[cur, vm] = -g * kv
    a[cur, lf] = -g * kv * kp
    a[cur, xi] = g * kv
    b[cur, 0] = g * kv * kp / dpi
    a[xi, lf] = -v[K_KI]
    b[xi, 0] = v[K_KI] / dpi
    # motor and surface through the linearized gear train
    a[xm, vm] = 1.0
    a[vm, cur] = kf / mm
    a[vm, xm] = -kt / mm
    a[vm, xs] = kt / mm
    a[vm, vm] = -damping / mm
    a[vm, vs] = damping / mm
    a[xs, vs] = 1.0
    a[vs, xm] = kt / ms
    a[vs, xs] = -kt / ms
    a[vs, vm] = damping / ms
    a[vs, vs] = -damping / ms
    b[vs, 1] = 1.0 / (v[K_ARM] * ms)
    # LVDT (motor-side position less the in-loop compliance) and its filter
    a[lf, xm] = wf * (1.0 - ca * kt)
    a[lf, xs] = wf * ca * kt
    a[lf, lf] = -wf
    c = np.zeros((2, 7))
    c[0, lf] = dpi
    c[1, xs] = dpi
    return LinearizedActuator(a, b, c, params.command_delay_s, params.feedback_delay_s, float(kt), float(ca))


# ================================================================================ the models
class HighOrderModel(ActuatorModel):
    """Common part of HOAC1, HOAD2 and HOAD3: parameters, power, command path and trim."""

    has_current = True
    variant: ClassVar[str] = "hoac1"
    figure33: ClassVar[bool] = False

    def __init__(
        self,
        channel: str | ChannelConfig = "left_wing",
        *,
        n: int = 1,
        rate_hz: float | None = None,
        params: HighOrderParams | list[HighOrderParams] | None = None,
        bound: str | float | Sequence[str | float] = "mean",
        hysteresis: bool | float = False,
        noise: bool | float = True,
        seed: int | float | Sequence[int] = 0,
        **overrides: Any,
    ) -> None:
        super().__init__(channel, n=n, rate_hz=rate_hz)
        if params is not None and overrides:
            raise ValueError("give either params or keyword overrides, not both")
        bounds = list(bound) if isinstance(bound, Sequence) and not isinstance(bound, str) else [bound] * self.n
        if len(bounds) != self.n:
            raise EmaError(f"got {len(bounds)} compliance bounds for {self.n} instances")
        self.bounds = [_bound_value(b) for b in bounds]
        self.hysteresis = bool(hysteresis)
        if not self.figure33 and (any(self.bounds) or self.hysteresis):
            raise EmaError(f"{self.name}: compliance bounds and hysteretic damping belong to HOAD3's figure-33 "
                           "gear train")
        self.noise = bool(noise)
        self.seed = seed if isinstance(seed, Sequence) else int(seed)
        self.params: list[HighOrderParams] = batch_params(
            params, self.n, lambda: HighOrderParams.from_channel(self.channel, self.variant, **overrides)
        )
        if self.continuous and any(getattr(prm, f) > 0.0 for prm in self.params for f in _ENVIRONMENT_FIELDS[:5]):
            raise EmaError(f"{self.name} has no flight/test environment (delay, quantization, noise): use hoad2/hoad3")
        fb = self.channel.feedback_cal
        self._P = np.stack([
            prm.kernel_vector(figure33=self.figure33, bound=b, hysteresis=self.hysteresis, noise=self.noise,
                              feedback_cal=(fb.c0, fb.c1, fb.c2, fb.c3))
            for prm, b in zip(self.params, self.bounds, strict=True)
        ])
        self._max_delay_s = float(self._P[:, K_CMD_DELAY].max())
        self._power = np.ones(self.n)
        self.trim()

    # ------------------------------------------------------------------ power and brake
    @property
    def power(self) -> FloatArray:
        """Motor power of each instance (1 on, 0 off: brake engaged, no drive)."""
        return self._power.copy()

    def set_power(self, on: bool | ArrayLike) -> None:
        """Switch the 150 V motor power of every (or each) instance from the current model time.

        Off: the bridge is open (no current), the brake holds the motor (> 4,000 lbf, table 1) and
        the bus reads 0 V. On: the brake releases and the servo loop resumes from where it is.
        """
        value = np.broadcast_to(np.asarray(on, dtype=float), (self.n,)).copy()
        if not np.all((value == 0.0) | (value == 1.0)):
            raise EmaError("power must be on or off (true/false or 1/0)")
        self._power = value

    # ------------------------------------------------------------------ command path
    def _command_in(self, bp_u: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Stage 2 on every breakpoint: command degrees → (quantized command in inches, inches per volt)."""
        bp_u = np.ascontiguousarray(bp_u, dtype=float)
        x_in = np.empty_like(bp_u)
        slope = np.empty_like(bp_u)
        cal = self.channel.command_cal
        command_in(self._P, cal.c0, cal.c1, cal.c2, cal.c3, bp_u, x_in, slope)
        return x_in, slope

    # ------------------------------------------------------------------ base interface
    @property
    def max_delay_s(self) -> float:  # noqa: D102
        return self._max_delay_s

    def trim_command(self, position_deg: FloatArray, hinge_moment_inlb: FloatArray) -> FloatArray:
        """The command whose equilibrium LVDT reading is ``position_deg`` under the load."""
        out = np.empty(self.n)
        for i in range(self.n):
            p = self._P[i]
            target = position_deg[i] / p[K_DPI]
            eq = equilibrium(p, target, float(hinge_moment_inlb[i]), self._power[i] > 0.5)
            out[i] = (2.0 * target - eq["lf"]) * p[K_DPI] if eq["motor"] == MOTOR_STUCK else position_deg[i]
        return out

    def stream_seeds(self) -> list[int]:
        """The noise stream of each instance: ``seed`` and the instance number, or one seed per instance.

        A batch given the seeds ``[a, b, …]`` reproduces single models seeded ``a``, ``b``, ….
        """
        if isinstance(self.seed, Sequence):
            if len(self.seed) != self.n:
                raise EmaError(f"got {len(self.seed)} seeds for {self.n} instances")
            return [(int(s) * 1_000_003) % 2**63 for s in self.seed]
        return [(self.seed * 1_000_003 + i) % 2**63 for i in range(self.n)]

    def _equilibria(self, command_deg: FloatArray, hinge_moment_inlb: FloatArray) -> list[dict[str, float]]:
        x_in, _ = self._command_in(command_deg[:, None])
        return [equilibrium(self._P[i], float(x_in[i, 0]), float(hinge_moment_inlb[i]), self._power[i] > 0.5)
                for i in range(self.n)]

    def describe(self) -> dict[str, Any]:  # noqa: D102
        info = super().describe()
        info.update(bounds=self.bounds, hysteresis=self.hysteresis, noise=self.noise, seed=self.seed)
        return info


def _bound_value(bound: str | float) -> float:
    if isinstance(bound, str):
        if bound not in BOUNDS:
            raise UnknownNameError("compliance bound", bound, BOUNDS)
        return BOUNDS[bound]
    value = float(bound)
    if not -1.0 <= value <= 1.0:
        raise EmaError(f"compliance bound must be in [-1, 1] (lower, mean, upper), got {bound}")
    return value


class Hoac1(HighOrderModel):
    """HOAC1: the continuous physics model of figure 30, the reference the discrete ones are judged by."""

    name = "hoac1"
    title = "High-order actuator continuous model version 1.0 (HOAC1)"
    continuous = True
    variant = "hoac1"
    default_rtol: ClassVar[float] = 1e-9
    default_atol: ClassVar[float] = 1e-11

    def __init__(self, *args: Any, rtol: float | None = None, atol: float | None = None, **kwargs: Any) -> None:
        self.rtol = self.default_rtol if rtol is None else float(rtol)
        self.atol = self.default_atol if atol is None else float(atol)
        self.events = 0
        """Regime changes located so far (a measure of how hard the record was)."""
        super().__init__(*args, **kwargs)

    def _trim_states(self, command_deg: FloatArray, hinge_moment_inlb: FloatArray) -> None:
        self._Y = np.zeros((self.n, N_CONTINUOUS))
        self._U = np.zeros((self.n, N_U))
        for i, eq in enumerate(self._equilibria(command_deg, hinge_moment_inlb)):
            self._Y[i, [X_XM, X_XS, X_I, X_LF, X_VBUS, X_XI]] = (eq["xm"], eq["xs"], eq["cur"], eq["lf"], eq["vbus"],
                                                                  eq["xi"])
            self._U[i, U_MOTOR] = eq["motor"]
        self._h = np.full(self.n, 1e-5)
        self.events = 0

    def set_power(self, on: bool | ArrayLike) -> None:  # noqa: D102
        super().set_power(on)
        self._Y[self._power < 0.5, X_I] = 0.0  # the open bridge: no winding current

    def _integrate(self, bp_t, bp_u, bp_h, t_end, sample_t):  # noqa: ANN001, ANN202
        out = np.empty((self.n, sample_t.size, N_OUT))
        x_in, _ = self._command_in(bp_u)
        self.events += run_continuous(
            self._P, self._Y, self._U, self._h, self._power, bp_t, np.ascontiguousarray(x_in),
            np.ascontiguousarray(bp_h), self._t, t_end, sample_t, self.rtol, self.atol, out,
        )
        return out


class Hoad2(HighOrderModel):
    """HOAD2: HOAC1 discretized at 10,000 Hz with time delay, 5 mV quantization and noise (4.2.5)."""

    name = "hoad2"
    title = "High-order actuator discrete model version 2.0 (HOAD2)"
    default_rate_hz = 10_000.0
    variant = "hoad2"

    def _trim_states(self, command_deg: FloatArray, hinge_moment_inlb: FloatArray) -> None:
        dt = 1.0 / self.rate_hz
        nbuf = round(float(self._P[:, K_FB_DELAY].max()) / dt) + 1
        self._X = np.zeros((self.n, N_STATE))
        self._buf = np.zeros((self.n, nbuf))
        for i, eq in enumerate(self._equilibria(command_deg, hinge_moment_inlb)):
            self._X[i, [X_XM, X_XS, X_I, X_LF, X_VBUS, X_XI]] = (eq["xm"], eq["xs"], eq["cur"], eq["lf"], eq["vbus"],
                                                                  eq["xi"])
            self._X[i, X_FLAGS] = eq["flags"]
            self._buf[i] = eq["lf"]
        self._rng = np.array([[nz.splitmix64(s)] for s in self.stream_seeds()], dtype=np.uint64)
        self._steps = 0

    def set_power(self, on: bool | ArrayLike) -> None:  # noqa: D102
        super().set_power(on)
        self._X[self._power < 0.5, X_I] = 0.0

    def _integrate(self, bp_t, bp_u, bp_h, t_end, sample_t):  # noqa: ANN001, ANN202
        dt = 1.0 / self.rate_hz
        t0 = self._steps * dt
        n_steps = max(math.floor((t_end - t0) / dt + 1e-6), 0)
        x_in, slope = self._command_in(bp_u)
        out = np.empty((self.n, sample_t.size, N_OUT))
        run_discrete(
            self._P, self._X, self._rng, self._buf, self._power, bp_t, np.ascontiguousarray(x_in),
            np.ascontiguousarray(slope), np.ascontiguousarray(bp_h), t0, dt, n_steps, sample_t, out,
        )
        self._steps += n_steps
        return out


class Hoad3(Hoad2):
    """HOAD3: HOAD2 adjusted to the installed data: figure-33 gear train, 4 ms + 2 ms delays (2.3)."""

    name = "hoad3"
    title = "High-order actuator discrete model version 3.0 (HOAD3)"
    variant = "hoad3"
    figure33 = True
