from pathlib import Path

import numpy as np
import pytest

from ema_sim.errors import DataError
from ema_sim.io.csv import parse_csv, read_csv, write_csv


def contract_rows(n=120):
    t = np.arange(n) / 1000.0
    return {"time_s": t, "command_deg": np.sin(t), "position_deg": 0.9 * np.sin(t), "hinge_moment_inlb": 10 * t}


def test_round_trip_keeps_columns_and_metadata(tmp_path):
    cols = contract_rows()
    path = tmp_path / "d.csv"
    write_csv(path, cols, {"channel": "right_wing", "model": "loada"})
    data = read_csv(path)
    assert data.metadata == {"channel": "right_wing", "model": "loada"}
    assert data.outputs == ["position_deg"]
    assert data.surface_deg is None
    for name, values in cols.items():
        assert np.allclose(getattr(data, name), values, rtol=1e-8)
    assert data.sample_hz == pytest.approx(1000.0)


def test_unknown_columns_are_ignored_and_order_is_free():
    lines = ["extra,surface_deg,command_deg,time_s"] + [f"x,{i * 0.1},{i * 0.2},{i * 0.001}" for i in range(100)]
    data = parse_csv("\n".join(lines))
    assert data.outputs == ["surface_deg"]
    assert data.command_deg[3] == pytest.approx(0.6)


def good_lines(n=100):
    return ["# channel: left_wing", "time_s,command_deg,position_deg"] + [f"{i * 0.001},{i},{i}" for i in range(n)]


@pytest.mark.parametrize(
    ("mutate", "message"),
    [
        (lambda ls: [ls[0], "time_s,position_deg", *ls[2:]], "missing required column 'command_deg'"),
        (lambda ls: [ls[0], "time_s,command_deg", *ls[2:]], "needs a 'position_deg' or 'surface_deg'"),
        (lambda ls: [*ls[:10], "0.0081,abc,1", *ls[11:]], r"line 11, column 'command_deg': not a number"),
        (lambda ls: [*ls[:10], "0.0081,nan,1", *ls[11:]], r"line 11, column 'command_deg'.*not a finite"),
        (lambda ls: [*ls[:10], "0.0001,1,1", *ls[11:]], r"column 'time_s': time does not increase"),
        (lambda ls: ls[:50], "at least 100"),
        (lambda ls: [*ls[:5], "0.1,1", *ls[6:]], r"line 6: 2 cells, header has 3"),
        (lambda ls: ["# no colon here", *ls[1:]], "line 1: metadata must be"),
        (lambda ls: ["time_s,command_deg,time_s", *ls[2:]], "appears twice"),
    ],
)
def test_contract_violations_name_row_and_column(mutate, message):
    with pytest.raises(DataError, match=message):
        parse_csv("\n".join(mutate(good_lines())), "rig.csv")


def test_unreadable_files_are_one_clear_error(tmp_path):
    with pytest.raises(DataError, match="no such file"):
        read_csv(tmp_path / "missing.csv")
    binary = tmp_path / "b.csv"
    binary.write_bytes(b"\xff\xfe\x00garbage")
    with pytest.raises(DataError, match="not UTF-8"):
        read_csv(binary)
    assert isinstance(Path(tmp_path), Path)
