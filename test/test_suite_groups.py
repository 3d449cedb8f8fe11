"""The suite's grouping on pytest-xdist workers applies (``conftest.pytest_collection_modifyitems``).

pytest-xdist reads each test's group into its id in a collection hook of its own: a grouping hook that runs
after it marks nothing, silently, and then two ROS tests of one module run against each other and each worker
builds the shared fixtures again (both happened). This runs the project's conftest on a module of its own.
"""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).parent

MODULE = '''
import pytest

pytestmark = pytest.mark.ros


def test_grouped():
    pass
'''


def test_a_ros_module_runs_as_one_group_on_one_worker(tmp_path: Path) -> None:
    shutil.copy(HERE / "conftest.py", tmp_path / "conftest.py")
    (tmp_path / "test_probe.py").write_text(MODULE)
    (tmp_path / "pytest.ini").write_text("[pytest]\nmarkers =\n    ros: starts real rclpy nodes\n")
    out = subprocess.run([sys.executable, "-m", "pytest", "-v", "-n", "1", "--dist", "loadgroup",
                          "-p", "no:cacheprovider", str(tmp_path)],
                         check=False, capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert out.returncode == 0, out.stdout + out.stderr
    assert "PASSED test_probe.py::test_grouped@test_probe" in out.stdout, out.stdout
