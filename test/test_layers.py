"""The package layers: a module imports only from its own layer or below (read from the source, lazy imports too).

0  errors, calibration, config, parameters       the data every layer reads
1  models, signals                              pure models and test signals (no ROS, no io)
2  environment                                  the test environment (steps the models' elements)
3  switches                                     elements switched off by name: environment + models
"""

import ast
from pathlib import Path

import pytest

import ema_sim

ROOT = Path(ema_sim.__file__).resolve().parent
BASE = {"ema_sim.errors", "ema_sim.calibration", "ema_sim.config", "ema_sim.parameters"}
ALLOWED = {
    "ema_sim.errors": set(),
    "ema_sim.calibration": set(),
    "ema_sim.config": {"ema_sim.calibration", "ema_sim.errors"},
    "ema_sim.parameters": {"ema_sim.errors"},
    "ema_sim.models": BASE | {"ema_sim.models"},
    "ema_sim.signals": BASE | {"ema_sim.signals"},
    "ema_sim.environment": BASE | {"ema_sim.environment", "ema_sim.models"},
    "ema_sim.switches": BASE | {"ema_sim.environment", "ema_sim.models"},
}
FOREIGN = ("rclpy", "rosbags", "mcap", "ema_msgs_py")
"""What no module of these layers may import (the models are pure: no ROS, no bag I/O)."""


def _modules(package: str) -> list[Path]:
    path = ROOT.joinpath(*package.split(".")[1:])
    return sorted(path.rglob("*.py")) if path.is_dir() else [path.with_suffix(".py")]


def _imports(path: Path) -> set[str]:
    names = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module)
    return names


def _owner(module: str) -> str:
    """The layer entry an ``ema_sim`` module belongs to (``ema_sim.models.high_order.hoad`` → ``ema_sim.models``)."""
    parts = module.split(".")
    return ".".join(parts[:2])


def _violations(package: str, path: Path) -> list[str]:
    def above(name: str) -> bool:
        return name.startswith("ema_sim.") and _owner(name) not in {package, *ALLOWED[package]}

    return [name for name in sorted(_imports(path)) if name.split(".")[0] in FOREIGN or above(name)]


@pytest.mark.parametrize("package", sorted(ALLOWED))
def test_a_package_imports_only_its_own_layer_and_below(package):
    files = _modules(package)
    assert files, package
    for path in files:
        assert _violations(package, path) == [], f"{path.relative_to(ROOT.parent)} imports above its layer"


def test_the_check_sees_a_lazy_import_above_the_layer(tmp_path):
    module = tmp_path / "bad.py"
    module.write_text("from ema_sim.environment import ELEMENTS\nimport numpy\n\n\ndef f():\n"
                      "    import rclpy\n    from ema_sim.io import bag\n", encoding="utf-8")
    assert _violations("ema_sim.models", module) == ["ema_sim.environment", "ema_sim.io", "rclpy"]
