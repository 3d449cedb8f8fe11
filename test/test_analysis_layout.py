"""The groups of ``ema_sim.analysis`` import only the groups before them, and the registry lists every test once.

Order, lowest first: ``records`` (reading a record), ``estimation`` (what is measured from signals),
``formatting`` (figures and Markdown), ``section2`` (the tests), the loops of ``ema analyze`` (this
package's own modules: ``registry``, ``recognize``, ``pipeline``, ``report``, ``plots``), ``studies``
(run on the models). Read from the source, imports inside functions included.
"""

import ast
import importlib
import inspect
from pathlib import Path

import pytest

import ema_sim.analysis
from ema_sim.analysis import registry
from ema_sim.analysis.section2.base import Section2Test

ROOT = Path(ema_sim.analysis.__file__).resolve().parent
ORDER = ("records", "estimation", "formatting", "section2", "", "studies")
"""Groups, lowest first; ``""`` is the package's own modules."""


def _group(module: str) -> str:
    rest = module.removeprefix("ema_sim.analysis").lstrip(".").split(".")
    return rest[0] if len(rest) > 1 or rest[0] in ORDER else ""


def _modules() -> dict[str, Path]:
    found = {}
    for path in sorted(ROOT.rglob("*.py")):
        parts = list(path.relative_to(ROOT.parent.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        found[".".join(parts)] = path
    return found


def _imports(path: Path) -> set[str]:
    names: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            names.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.update(f"{node.module}.{a.name}" for a in node.names)
            names.add(node.module)
    return {n for n in names if n.startswith("ema_sim.analysis.")}


def test_every_module_sits_in_a_known_group():
    groups = {_group(m) for m in _modules() if m != "ema_sim.analysis"}
    assert groups <= set(ORDER)
    assert {p.name for p in ROOT.iterdir() if p.is_dir() and (p / "__init__.py").exists()} == set(ORDER) - {""}


def test_no_group_imports_a_later_one():
    known = _modules()
    bad = []
    for module, path in known.items():
        own = ORDER.index(_group(module))
        for name in _imports(path):
            target = name
            while target not in known and "." in target:
                target = target.rsplit(".", 1)[0]
            if target in known and ORDER.index(_group(target)) > own:
                bad.append(f"{module} → {target}")
    assert bad == []


def test_the_check_sees_an_upward_import(tmp_path):
    source = tmp_path / "m.py"
    source.write_text("def f():\n    from ema_sim.analysis.section2 import steps\n", encoding="utf-8")
    assert "ema_sim.analysis.section2.steps" in _imports(source)
    assert _group("ema_sim.analysis.section2.steps") == "section2"
    assert _group("ema_sim.analysis.records.series") == "records"
    assert _group("ema_sim.analysis.pipeline") == ""


def _section2_tests() -> list[Section2Test]:
    found = []
    for path in sorted((ROOT / "section2").glob("*.py")):
        module = importlib.import_module(f"ema_sim.analysis.section2.{path.stem}")
        found += [v for v in vars(module).values() if isinstance(v, Section2Test) and v.__module__ == module.__name__]
    return found


def test_the_registry_lists_every_section2_test_once_with_a_unique_key():
    keys = [t.key for t in registry.TESTS]
    assert len(keys) == len(set(keys))
    assert {id(t) for t in registry.TESTS} == {id(t) for t in _section2_tests()}
    assert all(type(t).__module__.startswith("ema_sim.analysis.section2.") for t in registry.TESTS)
    assert all(t.title and t.key for t in registry.TESTS)


@pytest.mark.parametrize("readers", ["EDGE_READERS", "MOVE_READERS", "MOVING_READERS", "HELD_READERS"])
def test_the_recogniser_asks_only_the_tests_readers(readers):
    funcs = getattr(registry, readers)
    assert funcs
    assert len(funcs) == len(set(funcs))
    assert all(inspect.getmodule(f).__name__.startswith("ema_sim.analysis.section2.") for f in funcs)


def test_every_analysis_module_is_imported_by_a_test_of_its_own():
    """Issue 26: each analysis module has a unit test that imports it, not only the end-to-end runs."""
    import ast  # noqa: PLC0415
    from pathlib import Path  # noqa: PLC0415

    root = Path(__file__).resolve().parents[1]
    modules = {".".join(p.relative_to(root).with_suffix("").parts)
               for p in (root / "ema_sim" / "analysis").rglob("*.py") if p.name != "__init__.py"}
    imported = set()
    for test in (root / "test").glob("test_*.py"):
        for node in ast.walk(ast.parse(test.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ImportFrom) and node.module:
                imported.add(node.module)
                imported.update(f"{node.module}.{a.name}" for a in node.names)
            elif isinstance(node, ast.Import):
                imported.update(a.name for a in node.names)
    assert len(modules) > 40
    assert sorted(modules - imported) == []
