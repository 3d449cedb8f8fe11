"""Every public function, method and constructor of the listed packages documents every argument (numpydoc).

After python-control's ``control/tests/docstrings_test.py``: each argument must appear as a numpydoc
entry (``name : type``, several names may share one: ``c0, c1 : float``) in the docstring, which
methods may inherit from the method they override. Compiled (numba) functions are checked through the
Python function they compile. Names starting with ``_`` are private and not checked; a dataclass's
generated ``__init__`` is documented by its fields (attribute docstrings or, for parameter sets, the
section :func:`ema_sim.parameters.documented` generates from their metadata), and a ``typing.Protocol`` has
no constructor of its own to document.
"""

import importlib
import inspect
import pkgutil
import re

import pytest

PACKAGES = ["ema_sim.models", "ema_sim.signals", "ema_sim.environment", "ema_sim.io", "ema_sim.analysis",
            "ema_sim.identify", "ema_sim.montecarlo", "ema_sim.export", "ema_msgs_py", "ema_sim.ail",
            "ema_sim.commands", "ema_sim.run", "ema_sim.suite", "ema_sim.launching", "ema_sim.demo", "ema_sim.cli",
            "ema_sim.nodes", "ema_sim.emac"]
"""The packages (and single modules) kept documented (add one here once its docstrings are complete)."""


def _modules(package):
    pkg = importlib.import_module(package)
    yield pkg
    for info in pkgutil.walk_packages(getattr(pkg, "__path__", []), f"{package}."):  # a module has no __path__
        yield importlib.import_module(info.name)


def _python(obj):
    """The Python function behind a numba dispatcher (the object itself otherwise)."""
    return getattr(obj, "py_func", obj)


def _documented(argname, docstring):
    entry = rf"\*{{0,2}}{re.escape(argname)}"
    other = r"\*{0,2}\w+"
    return re.search(rf"(?m)^\s*(?:{other}, )*{entry}(?:, {other})* :", docstring) is not None


def _undocumented(func, doc_owner):
    """Arguments of ``func`` its docstring (or the one it inherits) does not document."""
    doc = inspect.getdoc(doc_owner) or ""
    missing = []
    for name, par in inspect.signature(func).parameters.items():
        if name in ("self", "cls") or name.startswith("_"):
            continue
        if par.kind is inspect.Parameter.VAR_POSITIONAL and not _documented(name, doc):
            missing.append(f"*{name}")
        elif not _documented(name, doc):
            missing.append(name)
    return missing


def _targets(module):
    """(qualified name, function, object whose docstring documents it) for every public callable defined here."""
    for name, obj in vars(module).items():
        if name.startswith("_"):
            continue
        func = _python(obj)
        if getattr(func, "__module__", None) != module.__name__:
            continue  # defined elsewhere (checked there), or an alias
        if inspect.isfunction(func):
            yield f"{module.__name__}.{name}", func, func
        elif inspect.isclass(obj):
            init = obj.__dict__.get("__init__")
            if init is not None and not getattr(obj, "__dataclass_fields__", None) \
                    and not getattr(obj, "_is_protocol", False):  # a Protocol is never built: no __init__ to document
                yield f"{module.__name__}.{name}", init, obj
            for attr, member in obj.__dict__.items():
                target = member.__func__ if isinstance(member, classmethod | staticmethod) else member
                if attr.startswith("_") or not inspect.isfunction(_python(target)):
                    continue
                method = getattr(obj, attr)
                yield f"{module.__name__}.{name}.{attr}", _python(target), method


def _all_targets():
    for package in PACKAGES:
        for module in _modules(package):
            yield from _targets(module)


@pytest.mark.parametrize("package", PACKAGES)
def test_every_argument_is_documented(package):
    problems = []
    for module in _modules(package):
        for qualname, func, owner in _targets(module):
            if not inspect.getdoc(owner):
                problems.append(f"{qualname}: no docstring")
                continue
            missing = _undocumented(func, owner)
            if missing:
                problems.append(f"{qualname}: {', '.join(missing)} not documented")
    assert problems == [], "\n".join(problems)


def test_the_check_finds_an_undocumented_argument():
    def documented(a, b, *args, **kwargs):
        """Something.

        Parameters
        ----------
        a, b : float
            Two numbers.
        *args : float
            More.
        **kwargs : float
            Named.
        """

    def undocumented(a, width):
        """Something.

        Parameters
        ----------
        a : float
            A number; ``width`` is mentioned but not an entry.
        """

    assert _undocumented(documented, documented) == []
    assert _undocumented(undocumented, undocumented) == ["width"]
    assert sum(1 for _ in _all_targets()) > 150  # the walk reaches the packages' functions
