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
    assert "ema = ema_sim.cli:main" in text


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
