"""A record that changed is said to have changed; the stamps' jitter is measured and absorbed by no effect.

Records come from ``changing_records`` (a second-order servo of its own, integrated on a 0.1 ms grid and
logged at 100 Hz in counts with noise): a bandwidth that falls 25 % over the record, a transport delay that
wanders between 2 and 12 ms, a steady servo, and a steady servo whose integer-ms stamps jitter ±2 ms.
"""

from __future__ import annotations

import json
from dataclasses import astuple, replace

import numpy as np
import pytest
from changing_records import BLOCK_S, record
from scipy.optimize import brentq

from ema_sim.analysis.pipeline import resolve_channel
from ema_sim.analysis.records import stamps
from ema_sim.config import load_channel
from ema_sim.identify import artefacts, changes
from ema_sim.identify.criteria import MAX_DELTA_BIC
from ema_sim.identify.declared import declared
from ema_sim.identify.effects import FREE
from ema_sim.identify.fit import Fit, stretch_covariance
from ema_sim.identify.grid_fit import fit_model
from ema_sim.identify.identification import identify
from ema_sim.identify.outcome import Identification, Step
from ema_sim.identify.parallel import Pool
from ema_sim.identify.problem import Problem
from ema_sim.identify.record import prepare
from ema_sim.identify.report import summary, to_json, write_report
from ema_sim.identify.stepwise import start_point
from ema_sim.identify.trust import bandwidth_hz
from ema_sim.identify.window_sigma import window_sigmas
from ema_sim.models.second_order import SecondOrderParams

DURATION_S = 24.0


def _fitted(data, free_extra=(), start=None, exclude=False):
    """The record prepared, its problem, and the declared second order fitted (with ``free_extra`` free too); with
    ``exclude``, the record's artefacts taken out of the fit first."""
    ch, note = resolve_channel(data, None)
    rec = prepare(data, ch, channel_note=note)
    problem = Problem(rec.data, rec.channel, noise=rec.noise, command_sampled=rec.command_sampled,
                      output_range=rec.sensor_range)
    if exclude:
        artefacts.exclude(problem, artefacts.find(problem))
    base, free = declared("second_order", rec.channel, {}, 0.0)
    params = start_point(problem, base, free, False).replace(**(start or {}))
    fit = fit_model(problem, params, (*free, *free_extra), flip=False)
    return problem, Identification(problem, "second_order", fit, fit, record=rec), base


def _falling():
    return record(DURATION_S, seed=3, wn=lambda t: 40.0 * (1.0 - 0.25 * t / DURATION_S))


def _track(found, name):
    return next(t for t in found.tracks if t.name == name)


def test_stamps_jitter_measured_with_the_floor_it_sets():
    rng = np.random.default_rng(5)
    true = np.arange(3000) / 100.0
    jittery = np.round((true + rng.uniform(-0.002, 0.002, true.size)) * 1e3) / 1e3
    st = stamps.measure(jittery)
    assert st.jitters
    assert st.step_s == pytest.approx(1e-3)
    assert st.interval_s == pytest.approx(0.01, rel=1e-4)
    assert st.scatter_s == pytest.approx(np.sqrt(0.002**2 / 3 + 1e-6 / 12), rel=0.1)
    assert 0.0019 <= st.peak_s <= 0.0026
    rate = np.full(true.size, 100.0)
    assert st.floor(rate)[0] == pytest.approx(100.0 * st.scatter_s)
    assert "rate × jitter" in st.statement(rate)
    assert not stamps.measure(np.round(true * 1e3) / 1e3).jitters


def test_timing_error_from_a_residual_that_only_the_stamps_explain():
    rng = np.random.default_rng(6)
    rate = 80.0 * np.sin(np.linspace(0.0, 60.0, 20000))
    e = rng.normal(0.0, 0.002, rate.size) + rate * rng.normal(0.0, 0.0012, rate.size)
    assert stamps.timing_error(e, 0.002, rate) == pytest.approx(0.0012, rel=0.1)
    assert stamps.timing_error(rng.normal(0.0, 0.002, rate.size), 0.002, rate) < 2e-4


def test_windows_are_the_periods_of_a_repeating_command():
    problem, _, _ = _fitted(record(DURATION_S, seed=1))
    ws, how = changes.windows(problem)
    assert changes.period_s(problem.time_s, problem.data.command_deg) == pytest.approx(BLOCK_S, abs=0.02)
    assert len(ws) >= 3
    assert all(w.end_s - w.start_s == pytest.approx(BLOCK_S, abs=0.05) for w in ws)
    assert "repeats every" in how


def test_a_falling_bandwidth_is_reported_with_its_trend():
    problem, result, base = _fitted(_falling())
    found = changes.analyse(problem, result, base)
    wn = _track(found, "wn_rad_s")
    assert wn.kind == "falls"
    assert wn.values[-1] < 0.9 * wn.values[0]  # windows 12 s apart of a 24 s fall by 25 %: 0.87
    assert wn.slope_per_s < -3.0 * wn.slope_sigma
    assert found.changed
    assert found.bandwidth_hz[-1] < found.bandwidth_hz[0]
    text = " ".join(found.statements)
    assert "falls" in text
    assert "bandwidth" in text


def test_a_steady_servo_holds():
    problem, result, base = _fitted(record(DURATION_S, seed=2))
    found = changes.analyse(problem, result, base)
    assert found.tracks
    assert not found.changed
    assert not found.warnings


def test_a_wandering_delay_is_reported_as_changing():
    data = record(30.0, seed=4, delay_s=lambda t: 0.007 + 0.005 * np.sin(2.0 * np.pi * t / 30.0 + 0.5))
    problem, result, base = _fitted(data, ("delay_s",), {"delay_s": 0.006})
    found = changes.analyse(problem, result, base)
    delay = _track(found, "delay_s")
    assert delay.changed
    assert max(delay.values) - min(delay.values) > 0.004
    assert any("delay" in s and "changes over the record" in s for s in found.statements)


def test_an_added_effect_the_windows_do_not_need_is_taken_out():
    # the falling servo fitted with a command delay as if the search had added it: each window, fitted with its own
    # parameters, does not need it, so it is taken out and said to have stood in for the change
    problem, result, base = _fitted(_falling(), ("delay_s",), {"delay_s": 0.004})
    result.steps.append(Step("time_delay", "command", {"delay_s": float(result.final.params.delay_s)}, {}, {}, {},
                             "a stand-in"))
    found = changes.analyse(problem, result, base)
    assert len(found.proxies) == 1
    assert "stood in for a change over the record" in found.proxies[0]
    assert not result.steps
    assert [r.effect for r in result.removed] == ["time_delay"]
    assert "delay_s" not in result.final.free
    assert _track(found, "wn_rad_s").kind == "falls"


def test_a_needed_effect_is_tested_on_as_few_windows_as_decide_it():
    # the wandering delay is needed on every window: the refits without it stop once the windows fitted leave more
    # than the windows with it leave on all of them, and the ΔBIC over every window is no higher than that bound
    data = record(30.0, seed=4, delay_s=lambda t: 0.007 + 0.005 * np.sin(2.0 * np.pi * t / 30.0 + 0.5))
    problem, result, _ = _fitted(data, ("delay_s",), {"delay_s": 0.006})
    ws, _ = changes.windows(problem)
    subs = [changes.window_problem(problem, w) for w in ws]
    final = result.final
    with_ = changes.fit_windows(subs, final.params, final.free, final.flip)
    free = tuple(f for f in final.free if f != "delay_s")
    start = final.params.replace(delay_s=0.0)
    without, bound, fitted = changes.refit_without(subs, start, free, final.flip, with_)
    assert without is None
    assert 1 <= fitted < len(subs)
    every = changes._pays(changes.fit_windows(subs, start, free, final.flip), with_)
    assert every <= bound <= MAX_DELTA_BIC


def test_a_needed_effect_stays_and_the_report_says_after_how_many_windows():
    data = record(30.0, seed=4, delay_s=lambda t: 0.007 + 0.005 * np.sin(2.0 * np.pi * t / 30.0 + 0.5))
    problem, result, base = _fitted(data, ("delay_s",), {"delay_s": 0.006})
    result.steps.append(Step("time_delay", "command", {"delay_s": float(result.final.params.delay_s)}, {}, {}, {},
                             "found"))
    found = changes.analyse(problem, result, base)
    assert not found.proxies
    assert [s.effect for s in result.steps] == ["time_delay"]
    (tested,) = found.tests
    assert tested.needed
    assert tested.fitted < tested.windows
    assert any("stopped once the windows fitted decided it" in s for s in found.statements)
    assert found.as_dict()["proxy_tests"][0]["stopped_early"]


def test_windows_fitted_on_two_workers_give_the_serial_fits_and_stop():
    data = record(30.0, seed=4, delay_s=lambda t: 0.007 + 0.005 * np.sin(2.0 * np.pi * t / 30.0 + 0.5))
    problem, result, _ = _fitted(data, ("delay_s",), {"delay_s": 0.006})
    ws, _ = changes.windows(problem)
    subs = [changes.window_problem(problem, w) for w in ws]
    final = result.final
    start = final.params.replace(delay_s=0.0)
    free = tuple(f for f in final.free if f != "delay_s")
    serial = changes.fit_windows(subs, final.params, final.free, final.flip)
    alone = changes.refit_without(subs, start, free, final.flip, serial)
    pool = Pool(workers=2)
    try:
        spread = changes.fit_windows(subs, final.params, final.free, final.flip, pool)
        together = changes.refit_without(subs, start, free, final.flip, spread, pool)
    finally:
        pool.close()
    assert not pool.failed  # the cluster started: the fits ran on its two threads
    assert pool.workers == 2
    assert [astuple(f.params) for f in spread.fits] == [astuple(f.params) for f in serial.fits]
    assert spread.rss == serial.rss
    assert together[1:] == alone[1:]
    assert together[0] is None


def test_an_effect_not_needed_is_refitted_on_every_window():
    problem, result, _ = _fitted(_falling(), ("delay_s",), {"delay_s": 0.004})
    ws, _ = changes.windows(problem)
    subs = [changes.window_problem(problem, w) for w in ws]
    final = result.final
    with_ = changes.fit_windows(subs, final.params, final.free, final.flip)
    free = tuple(f for f in final.free if f != "delay_s")
    without, d, fitted = changes.refit_without(subs, final.params.replace(delay_s=0.0), free, final.flip, with_)
    assert without is not None
    assert fitted == len(subs)
    assert d == changes._pays(changes.fit_windows(subs, final.params.replace(delay_s=0.0), free, final.flip), with_)
    assert d > MAX_DELTA_BIC


def test_jitter_only_adds_nothing_and_names_the_jitter():
    data = record(DURATION_S, seed=7, stamp_error_s=0.002)
    ch, note = resolve_channel(data, None)
    rec = prepare(data, ch, channel_note=note)
    result = identify(rec)
    assert not result.steps
    assert not result.discovered
    assert result.problem.timing_s == pytest.approx(rec.stamps.scatter_s)
    report = to_json(result, "jitter")
    assert report["stamps"]["jitters"]
    assert any("rate × jitter" in n for n in report["notes"])


@pytest.mark.slow
def test_identify_reports_the_trend_in_console_json_and_report(tmp_path):
    data = _falling()
    ch, note = resolve_channel(data, None)
    rec = prepare(data, ch, channel_note=note)
    result = identify(rec)
    report = json.loads(json.dumps(to_json(result, "drift"), allow_nan=False))
    assert report["changes"]["changed"]
    wn = next(p for p in report["changes"]["parameters"] if p["parameter"] == "wn_rad_s")
    assert wn["trend"] == "falls"
    assert "falls" in summary(report)
    md = write_report(result, report, tmp_path).read_text(encoding="utf-8")
    assert "## Over the record: the parameters per window" in md
    assert any(s["stage"] == "changes" for s in report["stages"])


def test_wn_and_zeta_that_trade_while_the_bandwidth_holds_are_no_change_of_the_record():
    """Windows of an unchanged overdamped servo land at different (ωn, ζ) of one ridge: not reported as a change;
    a bandwidth that moves is still a change."""
    base = SecondOrderParams.basic(load_channel("left_wing"))
    first = base.replace(wn_rad_s=175.0, zeta=2.35)
    target = bandwidth_hz(first)
    second = base.replace(wn_rad_s=brentq(lambda w: bandwidth_hz(base.replace(wn_rad_s=w, zeta=2.0)) - target,
                                          50.0, 400.0), zeta=2.0)

    def fits(*params):
        return changes.WindowFit(("wn_rad_s", "zeta"), [Fit(p, False, ("wn_rad_s", "zeta"), np.zeros((1, 3)),
                                                            np.zeros(1), np.zeros((1, 2)), {}) for p in params], 2)

    def moving(name, a, b):
        return changes.Track((a, b), (0.01, 0.01), (3.0, 9.0), 1e4, 1, 0.0, (b - a) / 6.0, 0.01, "wanders", name=name)

    tracks = [moving("wn_rad_s", first.wn_rad_s, second.wn_rad_s), moving("zeta", 2.35, 2.0)]
    kept, why = changes._on_the_ridge(tracks, fits(first, second))
    assert [t.kind for t in kept] == ["steady", "steady"]
    assert "bandwidth holds" in why[0]
    slower = base.replace(wn_rad_s=120.0, zeta=2.0)
    kept, why = changes._on_the_ridge([moving("wn_rad_s", 175.0, 120.0), moving("zeta", 2.35, 2.0)],
                                      fits(first, slower))
    assert [t.kind for t in kept] == ["wanders", "wanders"]
    assert why == []


def test_a_dropout_the_record_leaves_out_is_left_out_of_every_window():
    """A 200 ms stale stretch of a steady servo is taken out of the fit: the windows leave it out too, so it moves no
    window's parameters and the windows fit at the noise floor."""
    data = record(DURATION_S, seed=2)
    y = data.position_deg.copy()
    a, b = np.searchsorted(data.time_s, [9.0, 9.2])
    y[a:b] = y[a - 1]
    problem, result, base = _fitted(replace(data, position_deg=y), exclude=True)
    assert not problem.mask[a + 2:b].any()
    ws, _ = changes.windows(problem)
    for w in ws:
        sub = changes.window_problem(problem, w)
        assert not (sub.mask & ~problem.mask[w.lead:w.end]).any()
    found = changes.analyse(problem, result, base)
    assert not found.changed
    assert found.rms_over_noise["position_deg"] < 1.2  # 6× with the dropout fitted in its window


def test_a_grid_searched_parameter_is_not_tested_for_a_change():
    """Kb behind a quantizer is found by a grid search: its ± is the grid's spacing, no σ a change is tested on."""
    problem, _, _ = _fitted(record(DURATION_S, seed=2))
    ws, _ = changes.windows(problem)
    subs = [changes.window_problem(problem, w) for w in ws]
    params = SecondOrderParams.basic(load_channel("left_wing"), quantization_deg=0.02)
    fits = [Fit(params.replace(kb=-0.0002 - 0.001 * k), False, ("kb",), np.zeros((1, 3)), np.zeros(1),
                np.zeros((1, 0)), {"kb": 2e-5}) for k in range(len(ws))]
    kb = changes.track("kb", changes.WindowFit(("kb",), fits, 2), ws, subs)
    assert kb.kind == "not determined"
    assert kb.sigma == (2e-5,) * len(ws)
    smooth = [replace(f, params=f.params.replace(quantization_deg=0.0)) for f in fits]
    assert changes.track("kb", changes.WindowFit(("kb",), smooth, 2), ws, subs).changed  # a σ: tested


def test_a_window_sigma_covers_the_misfit_not_only_the_noise():
    """A misfit that pulls the estimate one way on one stretch and the other way on the next widens the σ beyond the
    coloured-residual one; between windows of unlike excitation, the largest misfit a window shows widens them all."""
    problem, _, _ = _fitted(record(DURATION_S, seed=2))
    subs = [changes.window_problem(problem, w) for w in changes.windows(problem)[0][:2]]
    rng = np.random.default_rng(1)
    base = SecondOrderParams.basic(load_channel("left_wing"))

    def fit(sub, pull, scale=1.0):
        n = int(sub.mask.sum())
        jac = rng.normal(0.0, 0.1, (n, 1))
        noise = rng.normal(0.0, 1.0, n)
        noise -= jac[:, 0] * (jac[:, 0] @ noise) / (jac[:, 0] @ jac[:, 0])  # the optimum: no score left
        residual = scale * noise + pull * np.where(np.arange(n) < n // 2, 1.0, -1.0) * jac[:, 0]
        coloured = abs(FREE["wn_rad_s"].derivative(base.wn_rad_s)) / float(np.linalg.norm(jac))  # white noise
        return Fit(base, False, ("wn_rad_s",), np.zeros((n, 3)), residual, jac, {"wn_rad_s": coloured}, ("wn_rad_s",))

    quiet = [fit(sub, 0.0) for sub in subs]
    coloured = [f.sigma["wn_rad_s"] for f in quiet]
    for alike in (True, False):  # noise alone: about the coloured σ
        assert window_sigmas(subs, quiet, "wn_rad_s", alike) == pytest.approx(coloured, rel=0.5)
    pulled = [fit(subs[0], 0.0), fit(subs[1], 5.0)]
    alike = window_sigmas(subs, pulled, "wn_rad_s", True)
    unlike = window_sigmas(subs, pulled, "wn_rad_s", False)
    assert alike[0] == pytest.approx(pulled[0].sigma["wn_rad_s"], rel=0.5)
    assert alike[1] > 3.0 * pulled[1].sigma["wn_rad_s"]
    assert unlike[0] > 3.0 * pulled[0].sigma["wn_rad_s"]  # the other window's misfit, on this one too
    assert unlike[1] >= alike[1]


def test_a_parameter_the_record_cannot_move_leaves_the_others_their_stretch_covariance():
    """A zero Jacobian column is infinitely uncertain on its own; the others keep a finite stretch covariance."""
    rng = np.random.default_rng(2)
    jac = np.column_stack([rng.normal(0.0, 1.0, 800), np.zeros(800)])
    cov = stretch_covariance(rng.normal(0.0, 1.0, 800), jac, 800, 1)
    assert 0.0 < cov[0, 0] < 10.0 / 800  # finite, of the order white unit noise gives over 800 samples (1/800)
    assert cov[1, 1] == np.inf
