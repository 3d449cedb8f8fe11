"""The package is a correct ament_python package and the models stay free of ROS."""

import ast
import configparser
import xml.etree.ElementTree as ET
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_package_xml_is_format_3_ament_python_with_the_runtime_dependencies():
    root = ET.parse(ROOT / "package.xml").getroot()
    assert root.get("format") == "3"
    assert root.findtext("name") == "ema_sim"
    assert root.find("export/build_type").text == "ament_python"
    deps = {e.text for e in root.findall("exec_depend")}
    assert {"rclpy", "std_msgs", "sensor_msgs", "rosgraph_msgs", "builtin_interfaces"} <= deps


def test_setup_cfg_installs_scripts_where_ros2_run_finds_them():
    cfg = configparser.ConfigParser()
    cfg.read(ROOT / "setup.cfg")
    assert cfg["develop"]["script_dir"] == "$base/lib/ema_sim"
    assert cfg["install"]["install_scripts"] == "$base/lib/ema_sim"
    assert (ROOT / "resource" / "ema_sim").is_file()


def test_setup_py_registers_the_ament_index_marker_and_config():
    tree = ast.parse((ROOT / "setup.py").read_text())
    text = ast.unparse(tree)
    assert "share/ament_index/resource_index/packages" in text
    assert "config/*.yaml" in text
    assert "ema = ema_sim.cli:entry" in text


FORBIDDEN = ("rclpy", "rosbags", "mcap", "std_msgs", "sensor_msgs", "rosgraph_msgs", "builtin_interfaces",
             "ema_msgs_py", "ema_sim.nodes", "ema_sim.io")


def test_models_never_import_ros():
    offenders = []
    for path in (ROOT / "ema_sim" / "models").rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                names = [node.module or ""]
            else:
                continue
            offenders += [f"{path.name}: {n}" for n in names if n.startswith(FORBIDDEN)]
    assert offenders == []


def test_makefile_and_ci_use_the_readme_commands():
    readme = (ROOT / "README.md").read_text()
    assert "make demo" in readme
    assert "make test" in readme
    assert "make test" in (ROOT / ".ci" / "run").read_text()


ROSDEP_KEYS = {
    "rclpy": "rclpy", "std_msgs": "std_msgs", "sensor_msgs": "sensor_msgs", "rosgraph_msgs": "rosgraph_msgs",
    "builtin_interfaces": "builtin_interfaces", "diagnostic_msgs": "diagnostic_msgs",
    "rcl_interfaces": "rcl_interfaces", "ament_index_python": "ament_index_python", "launch": "launch",
    "launch_ros": "launch_ros", "numpy": "python3-numpy", "scipy": "python3-scipy", "yaml": "python3-yaml",
    "matplotlib": "python3-matplotlib", "numba": "python3-numba-pip",
    "llvmlite": "python3-numba-pip", "control": "python3-control-pip",  # llvmlite: numba's own dependency
    "rosbags": "python3-rosbags-pip", "mcap": "python3-mcap-pip", "typing_extensions": "python3-typing-extensions",
    "distributed": "python3-dask-distributed-pip", "dask": "python3-dask-distributed-pip",  # distributed needs dask
    "pyarrow": "python3-pyarrow-pip", "threadpoolctl": "python3-threadpoolctl-pip",
    "fmpy": "python3-fmpy-pip", "jsbsim": "python3-jsbsim-pip", "jsonschema": "python3-jsonschema",
}
"""Top-level import → its rosdep key (a new import without one fails the test below)."""


def _third_party_imports():
    import sys  # noqa: PLC0415

    mods = set()
    for folder in ("ema_sim", "ema_msgs_py", "launch"):
        for path in (ROOT / folder).rglob("*.py"):
            for node in ast.walk(ast.parse(path.read_text())):
                if isinstance(node, ast.Import):
                    mods |= {a.name.split(".")[0] for a in node.names}
                elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                    mods.add(node.module.split(".")[0])
    return {m for m in mods if m not in sys.stdlib_module_names and m not in ("ema_sim", "ema_msgs_py")}


def test_package_xml_has_a_rosdep_key_for_every_import_and_defines_the_pip_ones():
    import yaml  # noqa: PLC0415

    imports = _third_party_imports()
    assert imports >= {"numba", "rosbags", "mcap", "control", "launch", "launch_ros"}
    unmapped = imports - set(ROSDEP_KEYS)
    assert not unmapped, f"give these imports a rosdep key in package.xml: {sorted(unmapped)}"
    deps = {e.text for e in ET.parse(ROOT / "package.xml").getroot().findall("exec_depend")}
    missing = {ROSDEP_KEYS[m] for m in imports} - deps
    assert not missing, missing
    own = yaml.safe_load((ROOT / "rosdep" / "ema_sim.yaml").read_text())
    for key in (d for d in deps if d.endswith("-pip")):
        assert set(own[key]) >= {"ubuntu", "debian"}, key
        assert own[key]["ubuntu"]["pip"]["packages"], key


def test_setup_py_installs_the_launch_files_and_requirements_pin_the_workspace_build():
    text = ast.unparse(ast.parse((ROOT / "setup.py").read_text()))
    assert "launch/*.launch.py" in text
    assert "rosdep/ema_sim.yaml" in text
    pins = dict(line.split("==") for line in (ROOT / "requirements.txt").read_text().splitlines()
                if "==" in line and not line.startswith("#"))
    assert {"colcon-core", "colcon-ros", "ros-jazzy-ament-package"} <= set(pins)
