"""The package layers: every package imports only from layers below it, and no module import makes a circle;
and the modules' size: one of more than 700 lines says in its docstring why one concept needs them.

Read from the source, imports inside functions and under ``TYPE_CHECKING`` included, so a lazy import
cannot hide an upward edge or a loop from the check. Layers, lowest first (a package may import its own
modules and any package of a lower layer, never a sibling of its own layer):

0  errors, jsontypes, ema_msgs_py                 the one exception tree; the JSON document type; the topic contract
                                                   (stands on its own)
1  ema_sim (its version), calibration, progress,  the data every layer reads
   benchmark
2  parameters                                     one declaration of every parameter
3  config                                         channel files
4  models, signals                                pure models; test signals (no ROS, no io)
5  environment, simulation, io                    the test environment; running models on signals; CSV and bags
6  switches, analysis, emac                       elements switched off by name; section-2 analysis; one channel
7  identify, ail                                  closing the loop; the aircraft in the loop
8  montecarlo, nodes, export                      campaigns; ROS adapters; models into other simulators
9  run                                            the suite's processes
10 suite, launching                               layouts; ``ema launch``
11 commands, warmup                               ``ema`` subcommands; the kernels compiled ahead
12 cli                                            the ``ema`` entry point
13 demo                                           ``make demo``
"""

import ast
import re
import subprocess
import sys
from pathlib import Path

import pytest

import ema_sim

ROOT = Path(ema_sim.__file__).resolve().parent.parent
LAYERS: list[tuple[str, ...]] = [
    ("ema_sim.errors", "ema_sim.jsontypes", "ema_msgs_py"),
    ("ema_sim", "ema_sim.calibration", "ema_sim.progress", "ema_sim.benchmark"),
    ("ema_sim.parameters",),
    ("ema_sim.config",),
    ("ema_sim.models", "ema_sim.signals"),
    ("ema_sim.faults",),
    ("ema_sim.environment", "ema_sim.simulation", "ema_sim.io"),
    ("ema_sim.switches", "ema_sim.analysis", "ema_sim.emac"),
    ("ema_sim.identify", "ema_sim.ail"),
    ("ema_sim.monitor",),
    ("ema_sim.montecarlo", "ema_sim.nodes", "ema_sim.export"),
    ("ema_sim.run",),
    ("ema_sim.suite", "ema_sim.launching"),
    ("ema_sim.commands", "ema_sim.warmup"),
    ("ema_sim.cli",),
    ("ema_sim.demo",),
]
LAYER = {package: k for k, packages in enumerate(LAYERS) for package in packages}
PURE = ("ema_sim.models", "ema_sim.signals", "ema_sim.faults", "ema_sim.environment", "ema_sim.switches",
        "ema_sim.parameters", "ema_sim.config", "ema_sim.calibration", "ema_sim.errors")
FOREIGN = ("rclpy", "rosbags", "mcap", "ema_msgs_py.ros", "ema_msgs_py.typestore")
"""What no module of the pure layers may import (the models are pure: no ROS, no bag I/O). The contract's pure
modules (``ema_msgs_py.contract``: the channel names, the scaling) are allowed: they import nothing but the
standard library."""


def modules() -> dict[str, Path]:
    """Every module of ``ema_sim`` and ``ema_msgs_py``, by dotted name."""
    found = {}
    for top in ("ema_sim", "ema_msgs_py"):
        for path in sorted((ROOT / top).rglob("*.py")):
            parts = list(path.relative_to(ROOT).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            found[".".join(parts)] = path
    return found


def imports(path: Path, known: dict[str, Path]) -> set[str]:
    """The modules ``path`` imports (anywhere in it): ``from pkg import sub`` names the submodule, not ``pkg``."""
    names: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            subs = [f"{node.module}.{a.name}" for a in node.names if f"{node.module}.{a.name}" in known]
            names.update(subs)
            if len(subs) < len(node.names):
                names.add(node.module)
    return names


def package(module: str) -> str:
    """The layer entry a module belongs to (``ema_sim.models.high_order.hoad`` → ``ema_sim.models``)."""
    if module == "ema_sim":
        return module
    parts = module.split(".")
    return parts[0] if parts[0] != "ema_sim" else ".".join(parts[:2])


def upward(module: str, target: str) -> bool:
    """``module`` importing ``target`` breaks the layers (``target`` an ``ema_sim``/``ema_msgs_py`` module)."""
    own, other = package(module), package(target)
    return own != other and LAYER[other] >= LAYER[own]


def circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The import graph's strongly connected components of more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                found.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


@pytest.fixture(scope="module")
def graph() -> dict[str, set[str]]:
    known = modules()
    return {m: {n for n in imports(p, known) if n in known and n != m} for m, p in known.items()}


def test_every_package_has_a_layer():
    assert sorted({package(m) for m in modules()} - set(LAYER)) == []


def test_no_module_imports_a_package_of_its_own_layer_or_above(graph):
    bad = sorted(f"{m} → {n}" for m, targets in graph.items() for n in targets if upward(m, n))
    assert bad == []


def test_no_import_circle(graph):
    assert circles(graph) == []


@pytest.mark.parametrize("pure", PURE)
def test_the_pure_layers_import_no_ros_and_no_bag_io(pure):
    known = modules()
    bad = sorted(f"{m} → {n}" for m, p in known.items() if package(m) == pure
                 for n in imports(p, known) if any(n == f or n.startswith(f"{f}.") for f in FOREIGN))
    assert bad == []


def test_the_topic_contract_imports_nothing_from_ema_sim():
    """``ema_msgs_py`` stands on its own: no import of ``ema_sim`` anywhere in it (inside functions included),
    and importing every one of its modules loads no ``ema_sim`` module (nor ROS for the pure ones)."""
    known = modules()
    bad = sorted(f"{m} → {n}" for m, p in known.items() if package(m) == "ema_msgs_py"
                 for n in imports(p, known) if n.split(".")[0] == "ema_sim")
    assert bad == []
    ours = sorted(m for m in known if package(m) == "ema_msgs_py")
    assert {"ema_msgs_py.contract", "ema_msgs_py.cdr", "ema_msgs_py.ros", "ema_msgs_py.typestore"} <= set(ours)
    probe = (
        "import importlib, sys\n"
        "importlib.import_module('ema_msgs_py.contract'); importlib.import_module('ema_msgs_py.cdr')\n"
        "ros = sorted(m for m in sys.modules if m.split('.')[0] in ('rclpy', 'rosbags', 'numpy'))\n"
        f"for m in {ours!r}: importlib.import_module(m)\n"
        "print(ros, sorted(m for m in sys.modules if m.split('.')[0] == 'ema_sim'))\n"
    )
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True, cwd=ROOT)
    assert out.stdout.split() == ["[]", "[]"]


def test_the_channel_files_load_without_ros_or_bag_io():
    """The pure layers import the contract's pure modules only: loading a channel file loads no ROS."""
    probe = ("import sys\nfrom ema_sim.config import load_channel, scaling\nload_channel('left_wing')\n"
             "scaling('cowl_door')\nprint(sorted(m for m in sys.modules if m.split('.')[0] in ('rclpy', 'rosbags')))\n")
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True, cwd=ROOT)
    assert out.stdout.split() == ["[]"]


def test_the_node_processes_import_neither_python_control_nor_plotting():
    """Every ROS process imports its node module at start: python-control (1.07 s, with scipy.signal and
    matplotlib) is imported where a linear system is built, not by a module every node imports."""
    probe = ("import sys\nimport ema_sim.nodes.emac, ema_sim.nodes.testenv, ema_sim.nodes.maneuver\n"
             "print(sorted({m.split('.')[0] for m in sys.modules} & {'control', 'matplotlib'}))\n")
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True, cwd=ROOT)
    assert out.stdout.split() == ["[]"]


def test_the_check_sees_lazy_imports_upward_and_circles(tmp_path):
    source = tmp_path / "a.py"
    source.write_text("from ema_sim.models import b\nimport numpy\n\n\ndef f():\n    from ema_sim.io import bag\n",
                      encoding="utf-8")
    known = {"ema_sim.models.a": source, "ema_sim.models.b": source, "ema_sim.io": source, "ema_sim.io.bag": source}
    assert imports(source, known) == {"ema_sim.models.b", "ema_sim.io.bag", "numpy"}
    assert upward("ema_sim.models.a", "ema_sim.io.bag")
    assert not upward("ema_sim.io.bag", "ema_sim.models.a")
    assert upward("ema_sim.models.a", "ema_sim.signals")  # a sibling of its own layer
    assert circles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert circles({"a": {"b"}, "b": set()}) == []


LONG_MODULE_LINES = 700
"""A module longer than this says in its docstring why one concept needs more (:func:`long_module_reason`)."""


def long_module_reason(path: Path) -> str | None:
    """Why a module of more than :data:`LONG_MODULE_LINES` lines is one, or None when it is short or says nothing.

    The docstring must say "in one module of about N lines" (across line breaks), N within 10 % of its length:
    the sentence is the reason, and a figure gone stale means the module grew past what was argued for.
    """
    text = path.read_text(encoding="utf-8")
    lines = text.count("\n")
    if lines <= LONG_MODULE_LINES:
        return ""
    doc = " ".join((ast.get_docstring(ast.parse(text)) or "").split())
    said = re.search(r"in one module of about (\d+) lines", doc)
    if said is None or abs(int(said.group(1)) - lines) > 0.1 * lines:
        return None
    return doc


def test_every_long_module_says_why_it_is_one():
    bad = sorted(f"{m} ({p.read_text(encoding='utf-8').count(chr(10))} lines)" for m, p in modules().items()
                 if long_module_reason(p) is None)
    assert bad == []


def test_the_length_check_sees_a_long_module_without_its_reason(tmp_path):
    body = "x = 1\n" * 720
    silent = tmp_path / "silent.py"
    silent.write_text(f'"""A module."""\n{body}', encoding="utf-8")
    argued = tmp_path / "argued.py"
    argued.write_text(f'"""One concept in one module\nof about 720 lines: its parts belong together."""\n{body}',
                      encoding="utf-8")
    stale = tmp_path / "stale.py"
    stale.write_text(f'"""One concept in one module of about 500 lines."""\n{body}', encoding="utf-8")
    short = tmp_path / "short.py"
    short.write_text('"""A module."""\nx = 1\n', encoding="utf-8")
    assert long_module_reason(silent) is None
    assert long_module_reason(stale) is None
    assert long_module_reason(argued)
    assert long_module_reason(short) == ""
