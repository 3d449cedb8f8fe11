"""One node per name: a second node of a running node's name refuses to run and names the first."""

import os
import signal
import subprocess
import sys
import time

import pytest

from ema_sim.suite import free_domain_id

pytestmark = pytest.mark.ros


def test_a_second_node_of_a_running_nodes_name_refuses_with_one_error_naming_it(tmp_path):
    env = dict(os.environ, ROS_DOMAIN_ID=str(free_domain_id(os.getpid() + 131)),
               ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", PYTHONUNBUFFERED="1")
    cmd = [sys.executable, "-m", "ema_sim.nodes.emac", "--channel", "right_rudder"]
    first_log = tmp_path / "first.log"
    with first_log.open("w") as out:
        first = subprocess.Popen(cmd, env=env, stdout=out, stderr=subprocess.STDOUT, text=True)
    try:
        # the second starts once the first has claimed its name (its claim is made before it logs its setup):
        # started together on a busy machine, either may claim first, and the younger claim is the one refused
        deadline = time.monotonic() + 60.0
        while "on right_rudder" not in first_log.read_text() and first.poll() is None and time.monotonic() < deadline:
            time.sleep(0.05)
        assert "on right_rudder" in first_log.read_text(), first_log.read_text()
        second = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=45, check=False)
        assert second.returncode == 2
        (line,) = [x for x in second.stderr.splitlines() if x.startswith("emac: error:")]
        assert f"another node named /emac_right_rudder is running on this ROS domain (pid {first.pid}" in line
        assert first.poll() is None  # the older one goes on
    finally:
        first.send_signal(signal.SIGINT)
        first.wait(timeout=20)
    assert "started after this one: it refuses to run" in first_log.read_text()
