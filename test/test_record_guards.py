"""Records neither tool can read an actuator from, and outputs neither can write: one line, exit 2, before the work.

Each case was a crash of ``ema analyze`` or ``ema identify`` (a traceback, or a segmentation fault inside scipy's
Savitzky-Golay filter on stamps a nanosecond apart) before the two tools shared these checks.
"""

from __future__ import annotations

import numpy as np
import pytest
from servo_records import servo

from ema_sim.cli import main
from ema_sim.config import load_channel
from ema_sim.identify import artefacts
from ema_sim.identify.identification import identify
from ema_sim.identify.record import prepare
from ema_sim.io.measured import MeasuredData


def _servo_csv(t: np.ndarray, huge_at: int | None = None) -> str:
    """Steps of ±1° every 50 rows through a first-order lag of 10 rows: a plausible record on any stamps.

    ``huge_at``: that row's command is 1e12 (a logger's garbage cell).
    """
    n = t.size
    u = np.where((np.arange(n) // 50) % 2 == 1, 1.0, -1.0)
    y = np.zeros(n)
    for k in range(1, n):
        y[k] = y[k - 1] + 0.1 * (u[k - 1] - y[k - 1])
    if huge_at is not None:
        u[huge_at] = 1e12
    rows = "\n".join(f"{a:.12g},{b:.6f},{c:.6f}" for a, b, c in zip(t, u, y, strict=True))
    return "time_s,command_deg,position_deg\n" + rows + "\n"


CASES = [
    ("ms_as_s", _servo_csv(np.arange(3000.0)), "slower than the 5 Hz needed to see an actuator move; "
     "whole-number stamps 1 apart look like milliseconds"),
    ("half_hertz", _servo_csv(np.arange(400) * 2.0), "sampled every 2 s over 798 s, slower than the 5 Hz"),
    ("ns_as_s", _servo_csv(np.arange(9000) * 1e-9), "9000 samples over 8.999e-06 s, shorter than the 0.1 s"),
    ("huge_cell", _servo_csv(np.arange(3000) / 1000.0, huge_at=1500), "command_deg reaches 1e+12 deg at data row 1501"),
]


@pytest.mark.parametrize("tool", ["analyze", "identify"])
@pytest.mark.parametrize(("name", "text", "message"), CASES, ids=[c[0] for c in CASES])
def test_a_record_no_actuator_move_fits_in_is_one_line_from_either_tool(tmp_path, capsys, tool, name, text, message):
    path = tmp_path / f"{name}.csv"
    path.write_text(text)
    assert main([tool, str(path), *(["-q"] if tool == "identify" else [])]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    errors = [line for line in err if line.startswith(f"ema {tool}: error: ")]
    assert len(errors) == 1, err  # analyze's "analysing ..." progress line may come first; nothing else
    assert err[-1] == errors[0]
    assert not any("Traceback" in line for line in err)
    assert message in errors[0]


@pytest.mark.parametrize("tool", ["analyze", "identify"])
def test_an_output_that_cannot_be_written_is_one_line_before_the_work(tmp_path, capsys, tool):
    path = tmp_path / "steps.csv"
    path.write_text(_servo_csv(np.arange(3000) / 1000.0))
    blocker = tmp_path / "a_file"
    blocker.write_text("")
    assert main([tool, str(path), "--json", str(blocker / "out.json"), *(["-q"] if tool == "identify" else [])]) == 2
    captured = capsys.readouterr()
    assert captured.err.strip().splitlines() == [f"ema {tool}: error: cannot write {blocker / 'out.json'}: {blocker} "
                                                 "is a file, not a folder"]
    assert captured.out == ""  # nothing was analysed or fitted first
    assert main([tool, str(path), "--json", str(tmp_path), *(["-q"] if tool == "identify" else [])]) == 2
    assert capsys.readouterr().err.strip() == f"ema {tool}: error: cannot write {tmp_path}: it is a folder"


def test_a_glitch_of_ten_thousand_degrees_starts_no_rate_limit_beyond_its_range():
    """One 10⁴° sample in a damped servo's record: taken out as a spike, and the effects search still runs (the
    glitch read as a 10⁵ °/s move had started a rate limit beyond its 2,000 °/s range, and the search failed)."""
    t = np.arange(0.0, 8.0, 1e-3)
    u, y = servo(t, [(0.0, 0.0), (1.0, 2.0), (2.5, -2.0), (4.0, 5.0), (5.5, -5.0), (7.0, 0.0)], seed=3)
    delayed = np.interp(t - 0.008, t, y)  # the servo answers 8 ms late
    delayed[5000] = 1e4
    data = MeasuredData(time_s=t, command_deg=u, position_deg=delayed, metadata={"channel": "generic"},
                        source="glitch")
    result = identify(prepare(data, load_channel("left_wing"), channel_note="a generic servo"))
    assert [a.kind for a in artefacts.find(result.problem)] == ["spike"]
    assert result.failures == []
    assert [s.effect for s in result.steps] == ["time_delay"]
    assert result.final.params.delay_s == pytest.approx(0.008, abs=0.001)
