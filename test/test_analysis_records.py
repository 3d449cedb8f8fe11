"""Unit tests of ``ema_sim.analysis.records.periodic`` and ``ema_sim.analysis.formatting`` on known inputs.

A square wave carries its odd harmonics only, as 1/k; a triangle its odd ones as 1/k² (8/π²·1/k²); a sine
its fundamental alone. The Markdown helpers format numbers, tables and quality words as the report does.
"""

import numpy as np
import pytest

from ema_sim.analysis.formatting import figure, markdown
from ema_sim.analysis.records.periodic import dwell_runs, find_periodic

FS = 200.0


def _record(wave, period_s=2.0, cycles=6, lead_s=1.0):
    """``cycles`` periods of ``wave`` (a function of the phase 0..1) after ``lead_s`` at rest, then a rest."""
    t = np.arange(0.0, lead_s + cycles * period_s + 1.0, 1.0 / FS)
    phase = ((t - lead_s) / period_s) % 1.0
    active = (t >= lead_s) & (t < lead_s + cycles * period_s)
    return t, np.where(active, wave(phase), 0.0)


def _square(phase):
    return np.where(phase < 0.5, 2.0, -2.0)


def _triangle(phase):
    return 2.0 * (1.0 - 4.0 * np.abs(phase - 0.5)) * -1.0


def test_a_square_wave_is_recognised_with_its_period_and_odd_harmonics():
    t, u = _record(_square)
    (p,) = find_periodic(t, u, tol=1e-3)
    assert p.shape == "square"
    assert p.period_s == pytest.approx(2.0, rel=1e-3)
    assert p.freq_hz == pytest.approx(0.5, rel=1e-3)
    assert p.cycles >= 5
    assert p.amplitude == pytest.approx(2.0)
    assert p.centre == pytest.approx(0.0, abs=1e-9)
    a = p.harmonic_amplitudes
    assert a[0] == pytest.approx(4 * 2.0 / np.pi, rel=0.01)  # a square of amplitude A: 4A/π
    assert a[2] / a[0] == pytest.approx(1 / 3, rel=0.02)
    assert a[4] / a[0] == pytest.approx(1 / 5, rel=0.03)
    assert max(a[1], a[3]) < 0.01 * a[0]
    assert set(p.harmonics) >= {1, 3, 5}
    assert all(k % 2 == 1 for k in p.harmonics)
    assert t[p.start] >= 1.0 - 1e-9
    assert p.stop - p.start == pytest.approx(p.cycles * p.period_samples, abs=1.0)


def test_a_triangle_falls_as_one_over_k_squared():
    t, u = _record(_triangle)
    (p,) = find_periodic(t, u, tol=1e-3)
    assert p.shape == "triangle"
    a = p.harmonic_amplitudes
    assert a[0] == pytest.approx(8 * 2.0 / np.pi**2, rel=0.01)
    assert a[2] / a[0] == pytest.approx(1 / 9, rel=0.03)


def test_a_sine_and_a_held_command():
    t, u = _record(lambda ph: np.sin(2 * np.pi * ph), period_s=0.5, cycles=8)
    (p,) = find_periodic(t, u, tol=1e-3)
    assert p.shape == "sine"
    assert p.period_s == pytest.approx(0.5, rel=1e-3)
    assert p.harmonics == (1,)
    assert find_periodic(t, np.full(t.size, 0.3), tol=1e-3) == []


def test_two_cycles_are_not_a_periodic_test():
    t, u = _record(_square, cycles=2)
    assert find_periodic(t, u, tol=1e-3) == []


def test_dwell_runs_of_a_square_template():
    template = np.concatenate([np.full(50, 1.0), np.full(50, -1.0)])
    def circular(runs):
        return [(a % 100, b - a) for a, b in runs]

    top, bottom = dwell_runs(template, 1e-3)
    assert circular(top) == [(0, 50)]
    assert circular(bottom) == [(50, 50)]
    # a run across the cycle's end stays one run
    top, bottom = dwell_runs(np.roll(template, 25), 1e-3)
    assert circular(top) == [(25, 50)]
    assert circular(bottom) == [(75, 50)]


# --------------------------------------------------------------------------- formatting


def test_markdown_numbers_and_units():
    assert markdown.num(None) == "—"
    assert markdown.num(float("nan")) == "—"
    assert markdown.num(1.23456, ".3g", "°") == "1.23°"
    assert markdown.ms(0.0042) == "4.20"
    assert markdown.ms(None) == "—"
    assert markdown.pm(40.0, 0.25) == "40 ± 0.25"


def test_markdown_tables_bullets_images_and_quality():
    assert markdown.table(["a", "b"], [["1", "2"]]) == ["| a | b |", "| --- | --- |", "| 1 | 2 |", ""]
    assert markdown.bullets([]) == []
    assert markdown.bullets(["x"]) == ["- x", ""]
    assert markdown.image(None, "alt") == []
    assert markdown.image("p.png", "alt") == ["![alt](p.png)", ""]
    assert markdown.quality("ok", "ignored") == "ok"
    assert markdown.quality("on_bound", "ζ at its upper bound 3") == "**on a bound**: ζ at its upper bound 3"
    assert markdown.quality("not_determined") == "**not determined**"


def test_zoom_window_finds_the_largest_residual():
    t = np.arange(0.0, 10.0, 0.01)
    residual = np.where((t > 6.0) & (t < 6.5), 1.0, 0.01)
    zoom = figure.zoom_window(t, residual, 0.5)
    assert zoom.stop - zoom.start == 50
    assert 6.0 - 0.02 <= t[zoom.start] <= 6.02
    whole = figure.zoom_window(t, residual, 100.0)
    assert (whole.start, whole.stop) == (0, t.size)


def test_save_writes_a_png_and_closes_the_figure(tmp_path):
    plt = figure.pyplot()
    fig, ax = plt.subplots()
    ax.plot([0, 1], [0, 1], color=figure.COLORS["position_deg"])
    path = tmp_path / "x.png"
    figure.save(fig, path)
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert not plt.fignum_exists(fig.number)
