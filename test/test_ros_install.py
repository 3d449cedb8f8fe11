"""The package as a ROS 2 workspace builds it: ``colcon build`` into a temporary directory, then what it installs.

``launch`` and ``launch_ros`` are not on the package index, so the launch files run here against a stand-in
of the few Jazzy classes they use (same names and keyword arguments, each recording what it is given); every
executable, parameter file and remapping they name must then exist in the install tree, and the processes
must be the ones ``ema launch`` starts for the same run (one description of the suite).
"""
# ruff: noqa: ARG002  (the stand-ins keep launch's signatures, arguments they do not use included)

import os
import shutil
import subprocess
import sys
import types
from pathlib import Path

import pytest
import rclpy
import yaml

from ema_msgs_py.contract import TOPICS, endpoint
from ema_sim.run import EXECUTABLES, LAYOUTS, from_launch_arguments

ROOT = Path(__file__).resolve().parents[1]
pytestmark = pytest.mark.ros


@pytest.fixture(scope="module")
def install(tmp_path_factory):
    """``colcon build`` of this package (colcon-core, colcon-ros and ament_package from requirements.txt)."""
    base = tmp_path_factory.mktemp("ws")
    colcon = shutil.which("colcon", path=str(Path(sys.executable).parent)) or shutil.which("colcon")
    assert colcon, "colcon is pinned in requirements.txt"
    env = dict(os.environ, COLCON_HOME=str(base / "colcon_home"), PATH=f"{Path(sys.executable).parent}:"
               f"{os.environ.get('PATH', '')}")
    done = subprocess.run([colcon, "--log-base", str(base / "log"), "build", "--base-paths", str(ROOT),
                           "--build-base", str(base / "build"), "--install-base", str(base / "install")],
                          cwd=base, env=env, capture_output=True, text=True,
                          timeout=300, check=False)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    prefix = base / "install" / "ema_sim"
    site = next(prefix.glob("lib/python3*/site-packages"))
    # numba's cache of this checkout, beside the installed sources: numba takes it when a source's size and time
    # are its own, which the install keeps, so the nodes load the kernels the set-up compiled (as a second start
    # would), not compile them again (21 s of the test), and recompile any kernel whose source differs
    for cached in ROOT.glob("ema_sim/**/__pycache__/*.nb[ic]"):
        target = site / cached.relative_to(ROOT)
        target.parent.mkdir(exist_ok=True)
        shutil.copy2(cached, target)
    return types.SimpleNamespace(prefix=prefix, site=site, share=prefix / "share" / "ema_sim",
                                 bin=prefix / "lib" / "ema_sim", base=base)


def test_the_install_tree_has_every_executable_config_and_launch_file(install):
    for exe in EXECUTABLES:
        path = install.bin / exe
        assert path.is_file(), exe
        assert os.access(path, os.X_OK), exe
    assert sorted(p.name for p in (install.share / "config").glob("*.yaml")) == \
        sorted(p.name for p in (ROOT / "config").glob("*.yaml"))
    for layout in LAYOUTS:
        assert (install.share / "launch" / f"{layout}.launch.py").is_file()
    assert (install.share / "package.xml").is_file()
    assert (install.prefix / "share" / "ament_index" / "resource_index" / "packages" / "ema_sim").is_file()
    for module in ("ema_sim/launching.py", "ema_sim/run.py"):  # what the launch files run (ema_sim imported here)
        assert (install.site / module).read_text() == (ROOT / module).read_text()


# --------------------------------------------------------------------------- the launch files
class _Recorder:
    """Jazzy's launch classes as far as the launch files use them: the keyword arguments they accept."""

    def __init__(self):
        self.nodes = []
        self.arguments = {}
        rec = self

        class LaunchDescription:
            def __init__(self, initial_entities=None, *, deprecated_reason=None):
                self.entities = list(initial_entities or [])

        class DeclareLaunchArgument:
            def __init__(self, name, *, default_value=None, description=None, choices=None, **kwargs):
                rec.arguments[name] = default_value

        class OpaqueFunction:
            def __init__(self, *, function, args=None, kwargs=None, **left_over_kwargs):
                self.function, self.args, self.kwargs = function, args or [], kwargs or {}

        class LaunchConfiguration:
            def __init__(self, variable_name, *, default=None):
                self.name = variable_name

            def perform(self, context):
                return context.launch_configurations[self.name]

        class Shutdown:
            def __init__(self, *, reason="reason not given", **kwargs):
                self.reason = reason

        class Node:
            def __init__(self, *, executable, package=None, name=None, namespace=None, exec_name=None,
                         parameters=None, remappings=None, ros_arguments=None, arguments=None, **kwargs):
                rec.nodes.append({"executable": executable, "package": package, "name": name,
                                  "namespace": namespace, "parameters": parameters or [],
                                  "remappings": remappings or [], "arguments": arguments or [], **kwargs})

        self.modules = {
            "launch": types.SimpleNamespace(LaunchDescription=LaunchDescription),
            "launch.actions": types.SimpleNamespace(DeclareLaunchArgument=DeclareLaunchArgument,
                                                    OpaqueFunction=OpaqueFunction, Shutdown=Shutdown),
            "launch.substitutions": types.SimpleNamespace(LaunchConfiguration=LaunchConfiguration),
            "launch_ros": types.SimpleNamespace(),
            "launch_ros.actions": types.SimpleNamespace(Node=Node),
        }


def _launch(install, layout, given, monkeypatch):
    """Run an installed launch file as ``ros2 launch ema_sim <layout>.launch.py k:=v ...`` would."""
    rec = _Recorder()
    for name, module in rec.modules.items():
        monkeypatch.setitem(sys.modules, name, module)
    path = install.share / "launch" / f"{layout}.launch.py"
    scope = {"__file__": str(path), "__name__": "launch_file"}
    exec(compile(path.read_text(), str(path), "exec"), scope)  # how launch loads a Python launch file
    description = scope["generate_launch_description"]()
    context = types.SimpleNamespace(launch_configurations={**rec.arguments, **given})
    for entity in description.entities:
        if hasattr(entity, "function"):
            entity.function(context, *entity.args, **entity.kwargs)
    return rec


RUNS = [
    {"maneuver": "step"},
    {"test": "steps", "use_sim_time": "true", "emac": "channels", "profile": "ail", "namespace": "/aircraft2",
     "clock_topic": "clock"},
    {"fmu": "true", "lockstep": "true", "duration": "3", "open_loop": "true"},
]


@pytest.mark.parametrize("layout", LAYOUTS)
@pytest.mark.parametrize("given", RUNS, ids=["maneuver", "namespaced_lockstep", "fmu"])
def test_launch_files_name_only_what_the_install_has_and_start_what_ema_launch_starts(install, monkeypatch,
                                                                                       tmp_path, layout, given):
    given = {**given, "bag": str(tmp_path / "bag")}
    rec = _launch(install, layout, given, monkeypatch)
    run = from_launch_arguments(given, layout)
    procs = run.processes()
    assert [(n["executable"], n["name"]) for n in rec.nodes] == [(p.executable, p.node_name) for p in procs]
    assert [n["namespace"] for n in rec.nodes] == [run.namespace or None] * len(procs)
    assert rec.nodes[-1]["on_exit"] is not None  # the driver's end ends the launch
    endpoints = {endpoint(t) for t in TOPICS}
    for node in rec.nodes:
        assert node["package"] == "ema_sim"
        assert os.access(install.bin / node["executable"], os.X_OK), node["executable"]
        for frm, _ in node["remappings"]:
            assert frm in endpoints, frm
        for params in node["parameters"]:
            doc = yaml.safe_load(Path(params).read_text())
            wanted = {f"{run.namespace}/{n}" if run.namespace else n for n in procs[-1].nodes}
            assert wanted <= set(doc), (wanted, set(doc))
            ctx = rclpy.Context()  # rcl itself parses it
            rclpy.init(context=ctx, args=["launch", "--ros-args", "--params-file", params])
            rclpy.shutdown(context=ctx)
    assert run.lockstep == (given.get("use_sim_time", given.get("lockstep")) == "true")
    if given.get("clock_topic") == "clock":  # one clock per namespace: /clock remapped into it
        assert all(n["remappings"] == [("/clock", "clock")] for n in rec.nodes)
    else:  # ROS's /clock
        assert all(not n["remappings"] for n in rec.nodes)


# --------------------------------------------------------------------------- installed nodes, installed files
def test_installed_nodes_start_with_the_installed_parameter_files(install, tmp_path):
    """The installed executables, on the installed package alone, take every installed parameter file."""
    from test_ros_integration import Client, get_params, start, stop, wait_for_node  # noqa: PLC0415

    env = {"PYTHONPATH": f"{install.site}:{os.environ.get('PYTHONPATH', '')}".rstrip(":"),
           "AMENT_PREFIX_PATH": str(install.prefix)}
    files = [a for f in sorted((install.share / "config").glob("*.yaml")) for a in ("--params-file", str(f))]
    did = 1 + (os.getpid() + 71) % 101
    client = Client(did)
    procs = [start(did, "--channels", "all", "--ros-args", *files, exe=[str(install.bin / "ema_container")],
                   env=env, log=tmp_path / "container.log", cwd=tmp_path),
             start(did, "--bag", str(tmp_path / "f"), "--ros-args", *files, exe=[str(install.bin / "fmu")],
                   env=env, log=tmp_path / "fmu.log", cwd=tmp_path)]
    try:
        for node in ("emac_left_wing", "emac_right_rudder", "testenv", "fmu"):
            wait_for_node(client, node, 60)
        got = get_params(client, "/emac_right_rudder", ["high_order.hoad3.actuator_breakpoints_lbf",
                                                        "high_order.backup_stiffness_lbf_per_in"])
        assert got == {"high_order.hoad3.actuator_breakpoints_lbf": [10.0, 90.5],
                       "high_order.backup_stiffness_lbf_per_in": 5.0e6}
        assert get_params(client, "/fmu", ["autopilot.roll_rate_gain_s"])["autopilot.roll_rate_gain_s"] == 0.078
        assert all(p.poll() is None for p in procs)
    finally:
        stop(*procs)
        client.close()
    for name in ("container", "fmu"):
        text = (tmp_path / f"{name}.log").read_text()
        assert "Traceback" not in text, text[-2000:]
