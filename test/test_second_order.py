import itertools
import math

import numpy as np
import pytest
from conftest import FRAME_S, frames

from ema_sim.analysis.studies.model_error import table6
from ema_sim.config import load_channel
from ema_sim.errors import EmaError, UnknownNameError
from ema_sim.models import Flags, create, model_names
from ema_sim.models.second_order import Loac, Loada, SecondOrder, SecondOrderParams

SECOND_ORDER = ("loac", "loadf", "loada")
# Every nonlinear element off: the plain figure-21 second order with its delay.
PLAIN = {"kb": 0.0, "offset_deg": 0.0, "quantization_deg": 0.0, "free_play_deg": 0.0, "k2_dps_per_lb": 0.0}


def run(model, t, cmd, hm=None, end=None, samples=None):
    model.trim(cmd[0], 0.0 if hm is None else hm[0])
    end = t[-1] + FRAME_S if end is None else end
    samples = t if samples is None else samples
    return model.run(t, cmd, hm, sample_times=samples, end_s=end)


@pytest.mark.parametrize("name", SECOND_ORDER)
@pytest.mark.parametrize(("position", "load"), [(0.0, 0.0), (12.3, 900.0), (-30.0, -1780.0), (43.0, 200.0)])
def test_trim_starts_without_a_transient(name, position, load):
    model = create(name)
    start = model.trim(position_deg=position, hinge_moment_inlb=load)
    assert abs(start.position_deg[0] - position) <= 0.5 * 0.02 * 1.01 + 1e-12  # within half a D/A step
    u = model.trim_command(np.array([position]), np.array([load]))
    t = frames(1.0)
    rec = model.run(t, np.full_like(t, u[0]), np.full_like(t, load), end_s=1.0)
    assert np.ptp(rec.position_deg) < 1e-12
    assert np.ptp(rec.surface_deg) < 1e-12
    assert np.max(np.abs(rec.rate_dps)) < 1e-12


def test_table6_trend_error_falls_with_step_size_and_loadf_is_clearly_worse():
    rows = {(r.model, r.rate_hz): r for r in table6()}
    rates = [200.0, 400.0, 800.0, 1000.0, 2000.0]
    means = [rows[("loada", r)].mean_abs_deg for r in rates]
    maxes = [rows[("loada", r)].max_abs_deg for r in rates]
    assert all(a > b for a, b in itertools.pairwise(means))
    # First order: error ∝ step size (table 6 halves from 200 to 400 Hz and again to 800 Hz).
    for (r1, m1), (r2, m2) in itertools.pairwise(zip(rates, means, strict=True)):
        assert m1 / m2 == pytest.approx(r2 / r1, rel=0.3)
    assert maxes[0] / maxes[2] == pytest.approx(4.0, rel=0.3)
    loadf = rows[("loadf", 200.0)]
    assert loadf.mean_abs_deg > 3.0 * rows[("loada", 200.0)].mean_abs_deg
    assert loadf.max_abs_deg > 3.0 * rows[("loada", 200.0)].max_abs_deg
    # LOADF's maximum is about two frames of full slew (table 6: 1.1627°).
    assert loadf.max_abs_deg == pytest.approx(115.8 * 0.010, rel=0.05)


def test_loac_converged_halving_the_tolerance_changes_it_by_less_than_1e5_deg(rich_inputs):
    t, cmd, hm = rich_inputs
    samples = np.arange(0, 6000) / 1000.0
    a = run(Loac(), t, cmd, hm, end=6.0, samples=samples)
    b = run(Loac(rtol=Loac.default_rtol / 2, atol=Loac.default_atol / 2), t, cmd, hm, end=6.0, samples=samples)
    assert np.max(np.abs(a.position_deg - b.position_deg)) < 1e-5
    assert np.max(np.abs(a.surface_deg - b.surface_deg)) < 1e-5


def test_loadf_leads_loac_the_flight_1_mistake():
    """LOADF answers a step sooner and lags less in phase, so margins computed with it are too high."""
    t = frames(3.0)
    step = np.where(t >= 0.5, 1.0, 0.0)
    loac = run(Loac(**PLAIN), t, step)
    loadf = run(create("loadf", **PLAIN), t, step)
    k = int(np.searchsorted(t, 0.5)) + 4  # 20 ms after the step
    assert loadf.position_deg[0, k] > loac.position_deg[0, k] + 0.05
    f = 8.0  # near a flight control crossover
    sine = 0.5 * np.sin(2 * np.pi * f * t)

    def phase(model):
        rec = run(model, t, sine)
        keep = t >= 1.0
        ref = np.exp(-2j * np.pi * f * t[keep])
        return np.degrees(np.angle(np.sum(rec.position_deg[0, keep] * ref) / np.sum(sine[keep] * ref)))

    loac_phase = phase(Loac(**PLAIN))
    assert phase(create("loadf", **PLAIN)) - loac_phase > 15.0  # phase LOADF wrongly gains (report: ≤ 20°)
    assert abs(phase(create("loada", **PLAIN)) - loac_phase) < 3.0


@pytest.mark.parametrize("name", SECOND_ORDER)
def test_rate_limit_with_load_in_velocity_command_form(name):
    cfg = load_channel("left_wing")
    t = frames(1.5)
    step = np.where(t >= 0.2, 20.0, 0.0)
    for hm in (0.0, 1000.0, -1000.0):
        model = create(name, free_play_deg=0.0, quantization_deg=0.0, kb=0.0, offset_deg=0.0)
        rec = run(model, t, step, np.full_like(t, hm))
        so = model.params[0]
        expected = so.rate_limit_dps + so.k2_dps_per_lb * hm / cfg.crank_arm_in
        slewing = (rec.flags[0] & Flags.RATE_LIMIT) != 0
        assert slewing.sum() > 10
        assert np.max(rec.rate_dps) == pytest.approx(expected, rel=0.01)
        assert np.median(np.diff(rec.position_deg[0])[slewing[1:]]) / FRAME_S == pytest.approx(expected, rel=0.02)


@pytest.mark.parametrize("name", SECOND_ORDER)
def test_position_limit_acts_on_the_state_without_windup(name):
    t = frames(2.0)
    cmd = np.where(t < 1.0, 80.0, 30.0)
    rec = run(create(name), t, cmd)
    pos = rec.position_deg[0]
    assert np.max(pos) <= 43.0 + 1e-9
    held = (t > 0.6) & (t < 1.0)
    assert np.all(np.abs(pos[held] - 43.0) < 1e-9)
    assert np.all(rec.flags[0][held] & Flags.POSITION_LIMIT)
    # Leaves the stop as soon as the delayed command comes back inside: nothing wound up.
    k = int(np.searchsorted(t, 1.0))
    assert pos[k + 2] < 43.0 - 0.05  # moving 10 ms after the change (4 ms of it is delay)
    assert pos[k + 10] < 43.0 - 3.0


def test_free_play_crossing_matches_the_limited_double_integrator():
    cfg = load_channel("left_wing")
    hm = 20.0
    t = frames(2.0)
    load = np.where(t < 1.0, -hm, hm)
    model = Loac()
    model.trim(0.0, -hm)
    rec = model.run(t, np.zeros_like(t), load, sample_times=np.arange(0, 2000) / 1000.0, end_s=2.0)
    gap = rec.surface_deg[0] - rec.position_deg[0]
    assert gap[0] == pytest.approx(-0.1)
    assert gap[-1] == pytest.approx(0.1)
    accel = hm / cfg.surface_inertia_inlbs2 * 180 / math.pi
    crossing = math.sqrt(2 * 0.2 / accel)
    moving = (gap > -0.1 + 1e-9) & (gap < 0.1 - 1e-9)
    assert moving.sum() / 1000.0 == pytest.approx(crossing, abs=0.002)
    assert np.all(rec.flags[0][~moving] & Flags.FREE_PLAY_STOP)


@pytest.mark.parametrize("name", SECOND_ORDER)
def test_command_error_and_quantization_set_the_steady_state(name):
    model = create(name)
    so = model.params[0]
    t = frames(1.5)
    for cmd in (0.013, 5.0, -17.234):
        rec = run(model, t, np.full_like(t, cmd))
        expected = so.quantization_deg * round(((1 + so.kb) * cmd + so.offset_deg) / so.quantization_deg)
        assert rec.position_deg[0, -1] == pytest.approx(expected, abs=1e-9)


def test_quantization_makes_a_slow_ramp_a_staircase():
    t = frames(30.0)
    rec = run(create("loada"), t, 0.01 * t)
    settled = (t > 5) & (np.abs(rec.rate_dps[0]) < 1e-6)
    levels = np.unique(np.round(rec.position_deg[0, settled] / 0.02, 3))
    assert np.allclose(levels, np.round(levels))
    assert 10 <= levels.size <= 17


@pytest.mark.parametrize("name", SECOND_ORDER)
def test_delay_holds_the_surface_still_for_4_ms(name):
    model = create(name, free_play_deg=0.0)
    t = frames(1.0)
    step = np.where(t >= 0.5, 1.0, 0.0)
    samples = np.arange(0, 1000) / 10_000.0 + 0.49
    model.trim(0.0)
    rec = model.run(t, step, sample_times=samples, end_s=0.6)
    start = rec.position_deg[0, 0]
    moved = np.abs(rec.position_deg[0] - start) > 1e-9
    first = samples[np.argmax(moved)]
    if name == "loac":
        assert first == pytest.approx(0.5041, abs=1.5e-4)  # first sample after 4 ms
    elif name == "loada":
        assert 0.504 <= first <= 0.5075  # a 1.25 ms step after the delay
    else:
        assert 0.5 <= first <= 0.5151  # LOADF's lead eats into the delay


def test_compliance_correction_scales_the_command_with_aiding_load():
    model = create("loac", kcp_per_kinlb=0.05, quantization_deg=0.0, kb=0.0, offset_deg=0.0)
    t = frames(1.0)
    for hm, cmd in ((1000.0, 10.0), (-1000.0, 10.0), (1000.0, -10.0)):
        rec = run(model, t, np.full_like(t, cmd), np.full_like(t, hm))
        aiding = hm if cmd > 0 else -hm
        assert rec.position_deg[0, -1] == pytest.approx(cmd * (1 + 0.05 * aiding / 1000), abs=1e-9)


def test_threshold_dead_zone_ignores_small_command_changes():
    model = create("loada", threshold_deg=0.1, quantization_deg=0.0, kb=0.0, offset_deg=0.0)
    t = frames(1.0)
    small = np.where(t >= 0.2, 0.05, 0.0)
    rec = run(model, t, small)
    assert np.ptp(rec.position_deg) < 1e-12
    assert np.all(rec.flags[0] & Flags.THRESHOLD)
    big = np.where(t >= 0.2, 0.5, 0.0)
    rec = run(model, t, big)
    assert 0.5 - 0.1 - 1e-6 <= rec.position_deg[0, -1] <= 0.5 + 0.1  # stops somewhere inside the dead zone
    assert rec.position_deg[0, -1] > 0.3


@pytest.mark.parametrize("name", SECOND_ORDER)
def test_frame_stepping_equals_one_run(name, rich_inputs):
    t, cmd, hm = rich_inputs
    a = create(name)
    a.trim(cmd[0], hm[0])
    stepped = np.array([a.step(c, h, FRAME_S).position_deg[0] for c, h in zip(cmd, hm, strict=True)])
    b = create(name)
    b.trim(cmd[0], hm[0])
    ran = b.run(t, cmd, hm, sample_times=t + FRAME_S, end_s=t[-1] + FRAME_S).position_deg[0]
    assert np.max(np.abs(stepped - ran)) < 1e-9


def test_identification_simulator_takes_no_stop_where_a_breakpoint_holds_its_value():
    """A record logged at 1 kHz and the same inputs given only where they change: the same run, bit for bit.

    The RK4 simulator stops where the delayed command or the hinge moment changes, not at every logged sample of
    a held value (the stops it saves are most of a step record's). The samples fall between the breakpoints.
    """
    t = np.arange(2000) / 1000.0
    cmd = np.where(t < 0.3, 0.0, np.where(t < 0.9, 2.0, -1.5))
    hm = np.where(t < 0.5, 0.0, 400.0)
    samples = t + 0.0005

    def simulate(tt, cc, hh):
        model = SecondOrder("left_wing", delay_s=0.0045, free_play_deg=0.05, compliance_deg_per_kinlb=0.2)
        model.trim(0.0, 0.0)
        return model.run(tt, cc, hh, sample_times=samples, end_s=2.0)

    logged = simulate(t, cmd, hm)
    changes = np.r_[True, (np.diff(cmd) != 0.0) | (np.diff(hm) != 0.0)]
    assert changes.sum() == 4
    given = simulate(t[changes], cmd[changes], hm[changes])
    assert np.abs(logged.position_deg).max() > 1.0  # it moved through every change
    for name in ("position_deg", "surface_deg", "rate_dps"):
        assert np.array_equal(getattr(logged, name), getattr(given, name)), name


@pytest.mark.parametrize(("name", "n"), [("loada", 1), ("loadf", 1), ("loada", 3), ("hoad3", 1), ("hoad3", 2)])
def test_step_is_run_one_frame_at_a_time_bit_for_bit(name, n, rich_inputs):
    """``step`` writes its breakpoint into the kept history in place; ``run`` concatenates: same inputs, same bits.

    1,200 frames wrap the history buffers several times; NaN inputs are held at their last value by both.
    """
    t, cmd, hm = rich_inputs
    cmd, hm = cmd.copy(), hm.copy()
    cmd[300], hm[301] = math.nan, math.inf
    a, b, v = create(name, n=n), create(name, n=n), create(name, n=n)
    for model in (a, b, v):
        model.trim(cmd[0], hm[0])
    for k, (tk, c, h) in enumerate(zip(t, cmd, hm, strict=True)):
        s = a.step(c if n == 1 else np.full(n, c), h, FRAME_S)
        if n == 1:  # the node layer's scalar path: the same frame as floats
            values = v.step_values(float(c), float(h), FRAME_S)
            assert all(isinstance(x, float) for x in values)
            assert np.array_equal(values, [x[0] for x in (s.position_deg, s.surface_deg, s.rate_dps, s.current_a,
                                                          s.bus_v, s.flags)], equal_nan=True), k
        held_c = c if math.isfinite(c) else cmd[k - 1]
        held_h = h if math.isfinite(h) else hm[k - 1]
        r = b.run([tk], [held_c], [held_h], sample_times=[tk + FRAME_S], end_s=tk + FRAME_S)
        assert np.array_equal(s.position_deg, r.position_deg[:, 0]), k
        assert np.array_equal(s.surface_deg, r.surface_deg[:, 0]), k
    assert a.rejected_inputs == 2 * n
    assert a.time_s == pytest.approx(b.time_s, abs=1e-9)


def test_batch_instances_are_independent_and_equal_single_runs(rich_inputs):
    t, cmd, hm = rich_inputs
    base = SecondOrderParams.from_channel(load_channel("left_wing"))
    params = [base.replace(wn_rad_s=w, delay_s=d) for w, d in ((40.0, 0.0), (56.5, 0.004), (80.0, 0.02))]
    batch = Loada(n=3, params=params)
    batch.trim(cmd[0], hm[0])
    rec = batch.run(t, cmd, hm, end_s=6.0)
    for i, p in enumerate(params):
        single = Loada(params=p)
        single.trim(cmd[0], hm[0])
        assert np.array_equal(single.run(t, cmd, hm, end_s=6.0).position_deg[0], rec.position_deg[i])
    assert np.ptp(rec.position_deg[:, -200], axis=0) > 0


@pytest.mark.parametrize("name", [*SECOND_ORDER, "sloac"])
def test_non_finite_commands_are_held_and_counted_never_propagated(name, caplog):
    model = create(name)
    model.trim(1.0)
    for _ in range(10):
        model.step(1.0)
    before = model.step(1.0)
    after = model.step(float("nan"), float("inf"))
    assert np.isfinite(after.position_deg).all()
    assert after.position_deg[0] == pytest.approx(before.position_deg[0], abs=1e-6)
    assert model.rejected_inputs == 2
    assert "non-finite input held" in caplog.text
    t = frames(0.1)
    bad = np.ones_like(t)
    bad[7] = np.nan
    with pytest.raises(EmaError, match="command_deg: non-finite value at index"):
        model.run(t + 1.0, bad)


def test_unknown_model_and_parameter_names_list_the_known_ones():
    with pytest.raises(UnknownNameError, match=r"known: .*loac, loada, loadf, .*second_order, sloac"):
        create("hoad9")
    with pytest.raises(UnknownNameError, match="second-order parameter 'wn_hz'"):
        create("loada", wn_hz=3.0)
    assert {"loac", "loadf", "loada", "sloac", "second_order"} <= set(model_names())


@pytest.mark.parametrize("channel", ["left_wing", "right_wing", "left_rudder", "right_rudder"])
def test_sloac_matches_the_second_order_and_meets_the_bandwidth_spec(channel):
    model = create("sloac", channel)
    so = model.params
    f = np.linspace(0.1, 30, 3000)
    gain, phase = model.frequency_response(f)
    s = 2j * np.pi * f
    h = so.wn_rad_s**2 / (s**2 + 2 * so.zeta * so.wn_rad_s * s + so.wn_rad_s**2) * np.exp(-s * so.delay_s)
    assert np.allclose(gain, 20 * np.log10(np.abs(h)), atol=1e-9)
    assert np.allclose(phase, np.degrees(np.unwrap(np.angle(h))), atol=1e-6)
    bandwidth = f[np.argmax(gain < -3.0)]
    assert bandwidth >= 7.5  # table 1


def test_sloac_time_response_equals_loac_with_its_nonlinear_elements_off():
    t = frames(3.0)
    cmd = np.where(t >= 0.5, 0.5, 0.0) + 0.2 * np.sin(2 * np.pi * 2.0 * t)
    loac = run(Loac(**PLAIN), t, cmd)
    sloac = run(create("sloac"), t, cmd)
    assert np.max(np.abs(loac.position_deg - sloac.position_deg)) < 1e-6
