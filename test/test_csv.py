import re

import numpy as np
import pytest

from ema_sim.cli import main
from ema_sim.commands.identify import load_measured
from ema_sim.errors import DataError
from ema_sim.io.csv import RigFormat, parse_columns, parse_csv, read_csv, write_csv


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
        (lambda ls: [ls[0], "time_s,command_deg,position_in", *ls[2:]],
         r"'position_in' in another unit: map it with --columns, e.g. position_in=position_in\)"),
        (lambda ls: [*ls[:10], "0.0081,abc,1", *ls[11:]], r"line 11, column 'command_deg': not a number"),
        (lambda ls: [*ls[:10], "0.0081,nan,1", *ls[11:]], r"line 11, column 'command_deg'.*not a finite"),
        (lambda ls: [*ls[:10], "0.0001,1,1", *ls[11:]], r"column 'time_s': time does not increase"),
        (lambda ls: ls[:50], "at least 100"),
        (lambda ls: [*ls[:5], "0.1,1", *ls[6:]], r"line 6: 2 cells, header has 3"),
        (lambda ls: ["time_s,command_deg,time_s", *ls[2:]], "appears twice"),
        (lambda ls: [*ls[:10], "0.0081,1_0.0,1", *ls[11:]], r"line 11, column 'command_deg': not a number: '1_0.0'"),
        (lambda ls: [ls[0], "time_s,command_deg,position_deg,command_v",
                     *(f"{x},{10.0 + 0.1 * (k == 40)}" for k, x in enumerate(ls[2:]))], None),
        (lambda ls: [ls[0], "time_s,command_deg,position_deg,command_v",
                     *(f"{x},{-12.5 if k >= 40 else 0.0}" for k, x in enumerate(ls[2:]))],
         r"data row 41, column 'command_v': -12.5 V is beyond the contract's ±10 V signals \(60 rows are\)"),
    ],
)
def test_contract_violations_name_row_and_column(mutate, message):
    if message is None:  # within the converter's overrange: read as it is
        assert parse_csv("\n".join(mutate(good_lines())), "rig.csv").command_v[40] == pytest.approx(10.1)
        return
    with pytest.raises(DataError, match=message):
        parse_csv("\n".join(mutate(good_lines())), "rig.csv")


def test_a_spreadsheets_export_and_a_rigs_banner_are_read_as_they_come():
    """Semicolons with decimal commas (a locale whose decimal mark is the comma), tabs, and ``#`` lines that are
    not ``# key: value``: read, the banner kept as the comment; a cell that is no number stays an error."""
    body = [f"{i * 0.001:.3f};{i * 0.5};{i * 0.25}".replace(".", ",") for i in range(100)]
    text = "\n".join(["# DAU export 12:30, run 7", "# channel: cowl_door", "# operator J. Doe",
                      "time_s;command_deg;position_deg", *body])
    data = parse_csv(text, "export.csv")
    assert data.time_s[3] == pytest.approx(0.003)
    assert data.command_deg[3] == pytest.approx(1.5)
    assert data.position_deg[99] == pytest.approx(24.75)
    assert data.metadata["channel"] == "cowl_door"
    assert data.metadata["comment"] == "DAU export 12:30, run 7 | operator J. Doe"
    tabbed = parse_csv("\n".join(line.replace(",", "\t") for line in good_lines()), "tabs.csv")
    assert tabbed.position_deg[7] == pytest.approx(7.0)
    with pytest.raises(DataError, match=r"line 6, column 'command_deg': not a number: '1,2,3'"):
        parse_csv("\n".join([*text.splitlines()[:5], "0,001;1,2,3;0", *text.splitlines()[6:]]), "export.csv")


def test_unreadable_files_are_one_clear_error(tmp_path):
    with pytest.raises(DataError, match="no such file"):
        read_csv(tmp_path / "missing.csv")
    binary = tmp_path / "b.csv"
    binary.write_bytes(b"\xff\xfe\x00garbage")
    with pytest.raises(DataError, match="not UTF-8"):
        read_csv(binary)
    with pytest.raises(DataError, match=r"cannot read \(Is a directory\)"):
        read_csv(tmp_path)


# ---------------------------------------------------------------------------------------------- rig files
def rig_text(sep="\t", header=("t", "demand", "pos"), rows=150, pos_scale=1.0):
    lines = [sep.join(header)]
    for k in range(rows):
        lines.append(sep.join([str(12 * k + (k % 3)), f"{np.sin(k / 10):.2f}", f"{pos_scale * np.sin(k / 10):.2f}"]))
    return "\n".join(lines) + "\n"


@pytest.mark.parametrize("sep", ["\t", ","])
def test_a_rig_file_as_it_comes_tab_or_comma_time_in_ms_named_columns(sep):
    fmt = RigFormat(parse_columns("time_ms=t,command_deg=demand,position_deg=pos"))
    d = parse_csv(rig_text(sep), "rig.txt", fmt)
    assert d.time_s[:3] == pytest.approx([0.0, 0.013, 0.026])
    assert d.command_deg[10] == pytest.approx(round(np.sin(1.0), 2))
    assert d.unit == "deg"
    assert d.metadata["columns"] == "time_ms=t, command_deg=demand, position_deg=pos"


def test_linear_positions_are_kept_and_named_or_turned_into_degrees_through_the_crank_arm():
    cols = parse_columns("time_ms=t,command_mm=demand,position_mm=pos")
    kept = parse_csv(rig_text(), "rig.txt", RigFormat(cols))
    assert kept.unit == "mm"
    assert kept.position_deg[10] == pytest.approx(round(np.sin(1.0), 2))
    deg = parse_csv(rig_text(), "rig.txt", RigFormat(cols, crank_arm_in=2.0))
    assert deg.unit == "deg"
    assert deg.position_deg[10] == pytest.approx(np.degrees(round(np.sin(1.0), 2) / 25.4 / 2.0))
    assert deg.metadata["crank_arm_in"] == "2"


@pytest.mark.parametrize(("text", "fmt", "message"), [
    (rig_text(), "time_ms=t,command_deg=demand,position_deg=actual", "line 1: no column 'actual' for position_deg"),
    (rig_text().replace("\n13\t", "\n13\tx", 1), "time_ms=t,command_deg=demand,position_deg=pos",
     "line 3, column 'demand' (command_deg): not a number"),
    (rig_text().replace("\n26\t", "\n0\t", 1), "time_ms=t,command_deg=demand,position_deg=pos",
     "data row 3, column 't': time does not increase (13 then 0)"),
    (rig_text(), "time_ms=t,command_deg=demand,position_mm=pos", "positions in deg and mm at once"),
])
def test_rig_file_errors_name_the_line_and_the_rigs_own_column(text, fmt, message):
    with pytest.raises(DataError, match=re.escape(message)):
        parse_csv(text, "rig.txt", RigFormat(parse_columns(fmt)))


@pytest.mark.parametrize(("option", "message"), [
    ("time_ms=t,speed=v", "unknown column 'speed'"),
    ("time_ms", "expected name=column pairs"),
    ("time_ms=t,time_ms=u", "'time_ms' given twice"),
])
def test_a_bad_columns_option_is_one_clear_error(option, message):
    with pytest.raises(DataError, match=re.escape(message)):
        parse_columns(option)


@pytest.mark.parametrize("command", ["analyze", "identify"])
def test_rig_options_and_an_unknown_channel_are_one_line_and_status_2_on_both_commands(tmp_path, capsys, command):
    path = tmp_path / "rig.txt"
    path.write_text(rig_text())
    assert main([command, str(path), "--channel", "bogus"]) == 2
    err = capsys.readouterr().err.strip()
    assert err == (f"ema {command}: error: unknown channel 'bogus'; known: cowl_door, left_rudder, left_wing, "
                   "right_rudder, right_wing")
    assert main([command, str(path), "--columns", "time_ms=t,speed=pos"]) == 2
    assert len(capsys.readouterr().err.strip().splitlines()) == 1
    assert main([command, str(path), "--columns", "time_ms=t,command_deg=demand,position_deg=nope"]) == 2
    assert "no column 'nope' for position_deg" in capsys.readouterr().err


def test_identify_reads_the_rig_file_through_the_same_loader(tmp_path):
    path = tmp_path / "rig.txt"
    path.write_text(rig_text(",", pos_scale=1.0))
    data = load_measured(path, None, RigFormat(parse_columns("time_ms=t,command_mm=demand,position_mm=pos"),
                                              crank_arm_in=1.7317))
    assert data.unit == "deg"
    assert data.time_s[1] == pytest.approx(0.013)


def _logged(rows: int = 200) -> str:
    """A contract CSV of ``rows`` rows with six decimals, no line end after the last."""
    t = np.arange(rows) / 1000.0
    return "\n".join(["time_s,command_deg,position_deg",
                      *(f"{a:.6f},{np.sin(a):.6f},{0.9 * np.sin(a):.6f}" for a in t)])


def test_a_last_line_cut_mid_number_is_left_out_and_said():
    """A logger stopped while writing: the last number lost its last digits. It read as 0.177 before; now the row
    is left out and the record says why."""
    whole = _logged()
    data = parse_csv(whole[:-3], "cut.csv")
    assert data.time_s.size == 199
    assert data.position_deg[-1] == pytest.approx(0.9 * np.sin(0.198), abs=1e-6)
    assert "line 201, the last, has no line end" in data.metadata["truncated"]
    assert "'0.177' in 'position_deg'" in data.metadata["truncated"]


def test_a_last_line_cut_mid_row_is_left_out_not_an_error():
    data = parse_csv(_logged() + "\n0.2000", "cut.csv")
    assert data.time_s.size == 200
    assert "1 of the header's 3 cells" in data.metadata["truncated"]
    with pytest.raises(DataError, match="line 2: 1 cells"):  # a short row inside the file is still an error
        parse_csv(_logged().replace("\n", "\n0.5\n", 1) + "\n", "short.csv")


def test_a_whole_last_line_without_a_line_end_is_kept():
    data = parse_csv(_logged(), "whole.csv")
    assert data.time_s.size == 200
    assert "truncated" not in data.metadata
    ends_short = _logged().rsplit(",", 1)[0] + ",0.5"  # fewer decimals, but a line end follows: a whole number
    assert parse_csv(ends_short + "\n", "d.csv").position_deg[-1] == 0.5


def test_both_tools_print_a_cut_last_line(tmp_path, capsys):
    path = tmp_path / "cut.csv"
    path.write_text(_logged(5000)[:-3], encoding="utf-8")
    assert main(["analyze", str(path), "--channel", "left_wing"]) == 0
    assert "truncated: line 5001" in capsys.readouterr().out
    assert main(["identify", str(path), "--channel", "left_wing", "--max-effects", "0"]) == 0
    assert "truncated: line 5001" in capsys.readouterr().out
