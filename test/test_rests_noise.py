"""Rests before noise: a limit cycle at rest, the floor where the output cannot move, a floor that grows with
the excitation, and the resolution of a count coarser than the printing.

Every record is made here, from a plant of its own (a first-order servo, numpy only), logged as a bench logger
does: jittered instants, integer-millisecond stamps, counts printed to the logger's digits.
"""

from __future__ import annotations

import json
import math
from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest

from ema_sim.analysis.estimation import grid, rests
from ema_sim.analysis.estimation.noise import output_noise, with_rests
from ema_sim.analysis.estimation.prepared import output_floors
from ema_sim.cli import main
from ema_sim.config import load_channel
from ema_sim.identify.diagnosis import OutputDiagnosis, _floor_caveat, _hunting_rings
from ema_sim.identify.record import prepare
from ema_sim.io.measured import MeasuredData

LC_HZ = 37.0
LC_AMP_MM = 0.035


def _stamps(rng: np.random.Generator, t_end: float, rate_hz: float = 100.0) -> tuple[np.ndarray, np.ndarray]:
    """True instants (jittering up to 1 ms late) and their integer-millisecond stamps."""
    nominal = np.arange(0.05, t_end, 1.0 / rate_hz)
    true = nominal + rng.uniform(0.0, 1e-3, nominal.size)
    return true, np.round(true, 3)


def _servo(t: np.ndarray, cmd: np.ndarray, tau_s: float = 0.05) -> np.ndarray:
    """A first-order servo's response to a held command (exact between samples)."""
    y = np.zeros_like(cmd)
    for k in range(1, t.size):
        a = math.exp(-(t[k] - t[k - 1]) / tau_s)
        y[k] = a * y[k - 1] + (1.0 - a) * cmd[k - 1]
    return y


def _square(t: np.ndarray, half_s: float = 2.5) -> np.ndarray:
    return np.where(t < 1.0, 0.0, np.where(((t - 1.0) // half_s) % 2 == 0, 1.0, -1.0))


def hunting_record(seed: int, *, quiet_start: bool, current: str = "swings") -> MeasuredData:
    """1 mm squares; at every rest after the first the output hunts at 37 Hz, ±0.035 mm (a clipped sine).

    ``current``: ``swings`` (the drive's current carries the cycle), ``quiet`` (only its noise), ``none``.
    """
    rng = np.random.default_rng(seed)
    t, stamps = _stamps(rng, 20.0)
    cmd = _square(t)
    y0 = _servo(t, cmd)
    since = t - t[np.maximum.accumulate(np.where(np.r_[True, np.diff(cmd) != 0], np.arange(t.size), 0))]
    on = since > 0.3
    if quiet_start:
        on &= t > 1.0
    wave = np.clip(1.3 * np.sin(2 * np.pi * LC_HZ * t + rng.uniform(0, 6)), -1.0, 1.0)
    y = y0 + LC_AMP_MM * wave * on
    pos = np.round(np.round(y / 0.001) * 0.001, 3)
    cur = 2.0 * (cmd - y0) + rng.normal(0.0, 0.02, t.size)  # the servo's own current, without the cycle
    if current == "swings":
        cur = cur + 0.4 * np.sin(2 * np.pi * LC_HZ * t + 1.0) * on
    return MeasuredData(stamps, np.round(cmd, 3), position_deg=pos,
                        current_a=None if current == "none" else np.round(cur, 2), unit="mm", source="hunting")


def sweep_record(seed: int, *, rolling: bool) -> MeasuredData:
    """A ±2 mm sweep 0.3 → 5 Hz between 3 s rests; sensor noise 0.002 mm; ``rolling``: a disturbance ∝ √speed."""
    rng = np.random.default_rng(seed)
    t, stamps = _stamps(rng, 34.0)
    span = 28.0
    tau = np.clip(t - 3.0, 0.0, span)
    phase = 2 * np.pi * (0.3 * tau + 0.5 * (5.0 - 0.3) / span * tau**2)
    fade = np.clip(np.minimum(tau, span - tau) / 0.5, 0.0, 1.0)
    cmd = np.where((t > 3.0) & (t < 3.0 + span), 2.0 * np.sin(phase) * fade, 0.0)
    y = _servo(t, cmd, 0.01)
    if rolling:
        speed = np.abs(np.gradient(cmd, t))
        y = y + 0.0025 * np.sqrt(speed) * rng.normal(0.0, 1.0, t.size)
    pos = np.round(y + rng.normal(0.0, 0.002, t.size), 3)
    return MeasuredData(stamps, np.round(cmd, 3), position_deg=pos, unit="mm", source="sweep")


# ---------------------------------------------------------------------------------------------- limit cycle
@pytest.mark.parametrize("seed", [0, 1])
def test_a_line_at_rest_with_the_current_swinging_is_a_limit_cycle_with_its_frequency_and_amplitude(seed):
    d = hunting_record(seed, quiet_start=True)
    r = rests.read_rests(d.time_s, d.command_deg, d.position_deg, d.current_a, 0.001)
    lc = r.limit_cycle
    assert lc is not None
    assert lc.current == "swings"
    assert lc.freq_hz == pytest.approx(LC_HZ, rel=0.03)
    assert lc.amplitude == pytest.approx(LC_AMP_MM, rel=0.2)
    assert lc.rests >= lc.of - 1
    said = lc.statement("position", "mm")
    assert "limit cycle" in said
    assert f"{lc.freq_hz:.3g} Hz" in said


def test_a_slow_hunt_in_short_rests_is_read_at_its_own_frequency():
    """3 Hz in rests of 1.2 s (under four cycles each): the periodogram's peak alone read 3.33 Hz."""
    rng = np.random.default_rng(5)
    t = np.arange(0.0, 16.0, 0.001)
    cmd = _square(t, 1.5)
    since = t - t[np.maximum.accumulate(np.where(np.r_[True, np.diff(cmd) != 0], np.arange(t.size), 0))]
    y = _servo(t, cmd, 0.02) + 0.05 * np.sin(2 * np.pi * 3.0 * t) * (since > 0.3) + rng.normal(0.0, 0.003, t.size)
    lc = rests.read_rests(t, cmd, y, None, 0.0).limit_cycle
    assert lc is not None
    assert lc.freq_hz == pytest.approx(3.0, rel=0.02)


def test_without_a_current_column_the_line_is_a_limit_cycle_the_current_could_not_confirm():
    d = hunting_record(2, quiet_start=True, current="none")
    r = rests.read_rests(d.time_s, d.command_deg, d.position_deg, None, 0.001)
    assert r.limit_cycle is not None
    assert r.limit_cycle.current == "not logged"
    assert "current was not logged" in r.limit_cycle.statement("position", "mm")


def test_a_line_the_current_does_not_share_is_no_hunting():
    d = hunting_record(3, quiet_start=True, current="quiet")
    r = rests.read_rests(d.time_s, d.command_deg, d.position_deg, d.current_a, 0.001)
    assert r.line is not None
    assert r.limit_cycle is None
    assert "not hunting" in r.line.statement("position", "mm")


def test_quiet_rests_have_no_line_and_give_the_sensor_floor():
    d = sweep_record(4, rolling=False)
    r = rests.read_rests(d.time_s, d.command_deg, d.position_deg)
    assert len(r.rests) == 2
    assert r.line is None
    assert r.quiet_floor == pytest.approx(0.002, rel=0.3)


# ---------------------------------------------------------------------------------------------- the floor
def test_the_floor_is_read_at_a_quiet_rest_not_in_the_hunting():
    d = hunting_record(5, quiet_start=True)
    nf = output_floors(d.time_s, d.command_deg, {"position_deg": d.position_deg}, d.current_a, None)["position_deg"]
    assert nf.record_white is not None
    assert nf.record_white > 0.003  # the whole record's fourth differences hold the cycle
    assert nf.basis == "rests"
    assert nf.sigma == pytest.approx(0.001 / math.sqrt(12))  # the output reads one count at the quiet rest
    assert not nf.upper_bound


def test_when_every_rest_hunts_the_floor_is_an_upper_bound_and_identify_never_says_nothing_is_left():
    d = hunting_record(6, quiet_start=False)
    nf = output_floors(d.time_s, d.command_deg, {"position_deg": d.position_deg}, d.current_a, None)["position_deg"]
    assert nf.upper_bound
    assert nf.rests is not None
    assert nf.rests.limit_cycle is not None
    said = nf.findings("position_deg", "mm")
    assert any("upper bound" in s for s in said)
    assert any("limit cycle" in s for s in said)
    assert not any("deg" in s for s in said)  # an mm record's channel is named without a unit
    caveat = _floor_caveat(nf, "position_deg", "mm")
    assert "limit cycle" in caveat
    at_floor = OutputDiagnosis("position_deg", 0.98 * nf.sigma, nf.sigma, True, floor_caveat=caveat)
    sentence = at_floor.sentence("mm", 50.0, 5.0)
    assert "nothing left to explain" not in sentence
    assert "limit cycle" in sentence
    plain = OutputDiagnosis("position_deg", 0.98 * nf.sigma, nf.sigma, True)
    assert "nothing left to explain" in plain.sentence("mm", 50.0, 5.0)  # the caveat is what changes it
    ringing = OutputDiagnosis("position_deg", 20 * nf.sigma, nf.sigma, False, line_hz=37.5)
    (said_ring,) = _hunting_rings(SimpleNamespace(noise={"position_deg": nf}), [ringing])
    assert "the limit cycle, not a mode" in said_ring
    assert _hunting_rings(SimpleNamespace(noise={"position_deg": nf}), [replace(ringing, line_hz=12.0)]) == []


def test_identify_warns_of_the_limit_cycle_before_it_fits():
    d = hunting_record(7, quiet_start=True)
    record = prepare(d, load_channel("left_wing"), channel_note="no channel named")
    hunting = [w for w in record.warnings if "limit cycle" in w]
    assert len(hunting) == 1
    assert "Hz" in hunting[0]


def test_analyze_names_the_limit_cycle_and_reads_its_floor_at_rest(tmp_path, capsys):
    d = hunting_record(8, quiet_start=True)
    csv = tmp_path / "hunting.csv"
    rows = zip(d.time_s, d.command_deg, d.position_deg, d.current_a, strict=True)
    csv.write_text("time_s,command_mm,position_mm,current_a\n" + "".join(
        f"{t:.3f},{u:.3f},{y:.3f},{i:.2f}\n" for t, u, y, i in rows), encoding="utf-8")
    out = tmp_path / "analyze.json"
    assert main(["analyze", str(csv), "--columns", "command_mm=command_mm,position_mm=position_mm",
                 "--json", str(out)]) == 0
    console = [line for line in capsys.readouterr().out.splitlines() if "limit cycle" in line]
    assert len(console) == 1
    assert "37 Hz" in console[0]
    (rec,) = json.loads(out.read_text(encoding="utf-8"))["records"]
    assert any("limit cycle" in n for n in rec["notes"])
    noise = rec["noise"]["position_deg"]
    assert noise["basis"] == "rests"
    assert noise["rests"]["line_at_rest"]["current"] == "swings"
    assert noise["sigma"] < 0.001


def test_a_floor_that_grows_with_the_sweep_is_said_not_noise_and_the_floor_is_the_rests():
    d = sweep_record(9, rolling=True)
    nf = output_floors(d.time_s, d.command_deg, {"position_deg": d.position_deg}, d.current_a, None)["position_deg"]
    assert nf.rests is not None
    g = nf.rests.growth
    assert g is not None
    assert g.high > 1.5 * g.low
    assert g.high_hz > 3.0 * g.low_hz
    assert nf.basis == "rests"
    assert nf.sigma == pytest.approx(0.002, rel=0.3)
    assert any("grows with the excitation" in s and "not noise" in s for s in nf.findings("position_deg", "mm"))


def test_a_clean_sweep_sees_no_growth_and_its_floor_at_rest_is_the_sensor():
    """At 100 Hz a 5 Hz sweep leaks into the fourth differences (0.003 mm); its rests say 0.002, the truth."""
    d = sweep_record(10, rolling=False)
    nf = output_floors(d.time_s, d.command_deg, {"position_deg": d.position_deg}, d.current_a, None)["position_deg"]
    assert nf.rests is not None
    assert nf.rests.growth is None
    assert nf.sigma == pytest.approx(0.002, rel=0.3)
    assert not nf.upper_bound


def test_a_record_whose_rests_agree_with_it_keeps_its_own_floor():
    t = np.arange(0.0, 12.0, 0.01)
    cmd = np.where((t > 2.0) & (t < 10.0), np.sin(2 * np.pi * 0.5 * (t - 2.0)), 0.0)
    y = cmd + np.random.default_rng(14).normal(0.0, 0.002, t.size)
    plain = output_noise(y)
    nf = with_rests(plain, t, cmd, y)
    assert nf.basis == "record"
    assert nf.sigma == plain.sigma
    assert not nf.upper_bound


def test_a_record_that_never_rests_reports_its_floor_as_an_upper_bound():
    t = np.arange(0.0, 10.0, 0.01)
    cmd = np.sin(2 * np.pi * 0.5 * t)
    y = cmd + np.random.default_rng(11).normal(0.0, 0.002, t.size)
    nf = with_rests(output_noise(y), t, cmd, y)
    assert nf.upper_bound
    assert nf.sigma == output_noise(y).sigma
    assert "upper bound" in nf.statement


# ---------------------------------------------------------------------------------------------- resolution
@pytest.mark.parametrize("counts_per_rev", [6000, 6600, 7150])
def test_a_count_coarser_than_the_printing_is_found_from_the_values(counts_per_rev):
    """An output encoder of 0.05-0.06° logged to 0.01°: its values step 0.05 or 0.06 apart."""
    q = 360.0 / counts_per_rev
    rng = np.random.default_rng(counts_per_rev)
    t, _ = _stamps(rng, 30.0)
    cmd = np.where(t < 13.0, 2.0 * np.sign(np.sin(2 * np.pi * t / 3.0)), 4.0 * np.sin(2 * np.pi * 0.2 * (t - 13)))
    pos = np.round(np.round(_servo(t, cmd, 0.04) / q) * q, 2)
    g = grid.value_grid(pos)
    assert g is not None
    assert g.q == pytest.approx(q, rel=0.02)
    nf = output_noise(pos)
    assert nf.resolution == pytest.approx(q, rel=0.15)
    assert nf.sigma >= float(nf.resolution) / math.sqrt(12) - 1e-12


def test_a_position_logged_in_hundredths_keeps_a_count_of_a_hundredth():
    rng = np.random.default_rng(12)
    t, _ = _stamps(rng, 30.0)
    cmd = np.where(t < 13.0, np.sign(np.sin(2 * np.pi * t / 3.0)), 1.5 * np.sin(2 * np.pi * 0.5 * (t - 13)))
    pos = np.round(_servo(t, cmd, 0.04), 2)
    assert output_noise(pos).resolution == pytest.approx(0.01)
    assert grid.value_grid(pos).q == pytest.approx(0.01)


def test_values_that_merely_skip_digits_are_not_a_coarse_count():
    """A random walk of 2-3 hundredths: its gaps are 0.02 or 0.03 but its values sit on no coarser grid."""
    rng = np.random.default_rng(13)
    levels = np.round(0.01 * np.cumsum(rng.choice([2, 3], 60)), 2)
    assert grid.coarse_grid(np.unique(levels), 0.01) is None
    y = np.repeat(levels, 10)
    assert grid.value_grid(y).q == pytest.approx(0.01)
