import argparse
import json
import os
import signal
import subprocess
import sys
import time
from importlib import import_module

import numpy as np
import pytest

from ema_sim import cli
from ema_sim.cli import main
from ema_sim.commands import COMMANDS, SUBCOMMANDS
from ema_sim.io.csv import read_csv


def test_simulate_writes_a_contract_csv_sampled_like_a_dau(tmp_path, capsys):
    out = tmp_path / "sweep.csv"
    rc = main(["simulate", "--model", "loada", "--channel", "right_rudder", "--maneuver",
               "sweep:f0_hz=0.5,f1_hz=5,amp_deg=1,sweep_s=4", "--load", "const:inlb=100",
               "--sample-hz", "500", "--csv", str(out)])
    assert rc == 0
    data = read_csv(out)
    assert data.metadata["model"] == "loada"
    assert data.metadata["channel"] == "right_rudder"
    assert data.sample_hz == pytest.approx(500.0)
    assert data.time_s[-1] == pytest.approx(5.0)
    assert data.outputs == ["position_deg", "surface_deg"]
    assert np.allclose(data.hinge_moment_inlb, 100.0)
    assert data.command_v is not None
    assert data.position_v is not None
    # right rudder: direct degrees-to-volts relation, ≈ 0.235 V per degree.
    assert np.corrcoef(data.command_deg, data.command_v)[0, 1] > 0.999
    assert "wrote" in capsys.readouterr().out


def test_simulate_inverse_channels_have_negative_volts(tmp_path):
    out = tmp_path / "lw.csv"
    assert main(["simulate", "--model", "loac", "--maneuver", "step:amp_deg=5", "--csv", str(out)]) == 0
    data = read_csv(out)
    held = data.command_deg == 5.0
    assert np.all(data.command_v[held] < -1.0)


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--model", "hoad9", "--maneuver", "step"], "unknown model 'hoad9'; known: "),
        (["--model", "loada", "--maneuver", "step:amp=1"], "unknown field 'amp'"),
        (["--model", "loada", "--maneuver", "step", "--channel", "tail"], "unknown channel 'tail'"),
        (["--model", "loada", "--maneuver", "step", "--rate", "-5"], "rate must be a positive"),
        (["--model", "loada", "--maneuver", "step", "--set", "wn=3"], "unknown second-order parameter 'wn'"),
        (["--model", "loada", "--maneuver", "step", "--set", "zeta=-1"], "zeta must be positive"),
    ],
)
def test_bad_input_is_one_line_and_exit_status_2(tmp_path, capsys, args, message):
    rc = main(["simulate", *args, "--csv", str(tmp_path / "x.csv")])
    err = capsys.readouterr().err
    assert rc == 2
    assert message in err
    assert len(err.strip().splitlines()) == 1
    assert not (tmp_path / "x.csv").exists()


def test_compare_prints_table6_and_writes_json(tmp_path, capsys):
    out = tmp_path / "t6.json"
    assert main(["compare", "--models", "loadf@200,loada@800", "--json", str(out)]) == 0
    rows = json.loads(out.read_text())
    assert [r["model"] for r in rows] == ["loadf", "loada"]
    assert rows[0]["max_abs_deg"] > 5 * rows[1]["max_abs_deg"]
    assert "| LOADF | 200 Hz |" in capsys.readouterr().out


def test_console_script_is_installed():
    res = subprocess.run([sys.executable, "-m", "ema_sim.cli", "models"], capture_output=True, text=True, check=True)
    assert "loada" in res.stdout


def test_every_subcommand_is_mapped_to_the_module_that_registers_it():
    registered = {}
    for name in COMMANDS:
        sub = argparse.ArgumentParser().add_subparsers()
        import_module(f"ema_sim.commands.{name}").register(sub)
        registered.update(dict.fromkeys(sub.choices, name))
    assert registered == SUBCOMMANDS


def test_a_command_imports_its_own_module_and_no_other_command():
    code = ("import sys; from ema_sim.cli import main; main(['schema', 'analyze']); "
            "print(sorted(m for m in sys.modules if m.startswith('ema_sim.commands.')), file=sys.stderr)")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=False)
    assert done.returncode == 0, done.stderr
    assert done.stderr.strip().splitlines()[-1] == "['ema_sim.commands.common', 'ema_sim.commands.schema']"


def test_ema_help_lists_every_subcommand():
    done = subprocess.run([sys.executable, "-m", "ema_sim.cli", "--help"], capture_output=True, text=True,
                          check=False)
    assert done.returncode == 0, done.stderr
    assert all(name in done.stdout for name in SUBCOMMANDS)


def test_ctrl_c_swallowed_by_a_library_while_importing_is_still_an_interruption(monkeypatch, capsys):
    """A library that imports under a bare ``except:`` (ruamel.yaml does) swallows the KeyboardInterrupt of a
    Ctrl-C that lands there; ``ema`` still stops with status 130, one line, before running anything."""
    real = cli.build_parser

    def build(argv):
        try:  # what the library does: the interrupt lands inside its guarded import and is dropped
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(5.0)  # the handler runs (and raises) at once; never slept through
        except:  # noqa: E722
            pass
        return real(argv)

    monkeypatch.setattr(cli, "build_parser", build)
    before = signal.signal(signal.SIGINT, signal.default_int_handler)  # as Python sets it (a test worker may not)
    try:
        assert cli.main(["models"]) == 130
    finally:
        put_back = signal.signal(signal.SIGINT, before)
    out = capsys.readouterr()
    assert (out.out, out.err.strip()) == ("", "ema: interrupted")  # the command never ran
    assert put_back is signal.default_int_handler  # the handler put back
