"""One node per name: a second node of a running node's name refuses to run and names the first; ``ema launch``
refuses before it starts anything when nodes of its run's names are running, and says which."""

import os
import signal
import subprocess
import sys
import time

import pytest

from ema_sim.errors import EmaError
from ema_sim.launching import check_names
from ema_sim.suite import Suite, SuiteConfig, free_domain_id

pytestmark = pytest.mark.ros


def _start_right_rudder(tmp_path, offset):
    """An EMAC node of the right rudder on a domain of its own, once it has claimed its name: (process, env, log)."""
    env = dict(os.environ, ROS_DOMAIN_ID=str(free_domain_id(os.getpid() + offset)),
               ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", PYTHONUNBUFFERED="1")
    first_log = tmp_path / "first.log"
    with first_log.open("w") as out:
        first = subprocess.Popen(CMD, env=env, stdout=out, stderr=subprocess.STDOUT, text=True)
    # what follows starts once the first has claimed its name (its claim is made before it logs its setup):
    # started together on a busy machine, either may claim first, and the younger claim is the one refused
    deadline = time.monotonic() + 60.0
    while "on right_rudder" not in first_log.read_text() and first.poll() is None and time.monotonic() < deadline:
        time.sleep(0.05)
    assert "on right_rudder" in first_log.read_text(), first_log.read_text()
    return first, env, first_log


CMD = [sys.executable, "-m", "ema_sim.nodes.emac", "--channel", "right_rudder"]


def test_a_second_node_of_a_running_nodes_name_refuses_with_one_error_naming_it(tmp_path):
    first, env, first_log = _start_right_rudder(tmp_path, 131)
    cmd = CMD
    try:
        second = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=45, check=False)
        assert second.returncode == 2
        (line,) = [x for x in second.stderr.splitlines() if x.startswith("emac: error:")]
        assert f"another node named /emac_right_rudder is running on this ROS domain (pid {first.pid}" in line
        assert first.poll() is None  # the older one goes on
    finally:
        first.send_signal(signal.SIGINT)
        first.wait(timeout=20)
    assert "started after this one: it refuses to run" in first_log.read_text()


def test_a_run_refuses_before_starting_anything_when_its_names_are_running(tmp_path):
    first, env, _ = _start_right_rudder(tmp_path, 137)
    try:
        # the look is a bound on discovery (a generous one on a busy machine): it ends soon after the claim comes
        suite = Suite(SuiteConfig(bag=tmp_path / "bag", domain_id=int(env["ROS_DOMAIN_ID"]), maneuver="step",
                                  emac="channels"),
                      names_look_s=30.0)
        with pytest.raises(EmaError) as err:
            suite.start()
        message = str(err.value)
        assert f"running on ROS domain {env['ROS_DOMAIN_ID']}: /emac_right_rudder (pid {first.pid} on host" in message
        assert "/emac_left_wing" not in message  # only the names taken
        assert not suite.procs  # nothing started...
        assert not (tmp_path / "bag.logs").exists()  # ... nothing written
        assert first.poll() is None
    finally:
        first.send_signal(signal.SIGINT)
        first.wait(timeout=20)


def test_ros2_launch_refuses_before_making_its_nodes_when_its_names_are_running(tmp_path, monkeypatch):
    first, env, _ = _start_right_rudder(tmp_path, 139)
    try:
        monkeypatch.setenv("ROS_DOMAIN_ID", env["ROS_DOMAIN_ID"])
        monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
        with pytest.raises(EmaError) as err:  # the launch files' check, with a look generous for a busy machine
            check_names(["/emac_left_wing", "/emac_right_rudder"], look_s=30.0)
        message = str(err.value)
        assert f"running on ROS domain {env['ROS_DOMAIN_ID']}: /emac_right_rudder (pid {first.pid} on host" in message
        assert "/emac_left_wing" not in message
        check_names(["/aircraft2/emac_right_rudder"], look_s=2.0)  # another namespace: free
    finally:
        first.send_signal(signal.SIGINT)
        first.wait(timeout=20)
