"""The README stays a front door and the documentation holds: links resolve, the site builds, examples run.

Every ```` ```python ```` block of README.md and docs/*.md runs here, unless its fence says
``title="sketch"``; every ``ema …`` line of a ```` ```sh ```` block parses with ``ema``'s own parser, and
every ``make …`` target named there exists.
"""

import contextlib
import io
import os
import re
import shlex
import subprocess
import sys
import unicodedata
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
DOCS = sorted((ROOT / "docs").glob("*.md"))
PAGES = [README, ROOT / "CONTRIBUTING.md", *DOCS]
"""Every Markdown file whose links are checked."""

MAX_README_LINES = 250
MAX_README_WIDTH = 120
SKETCH = 'title="sketch"'
"""A ```` ```python ```` fence carrying this is an illustration, not run."""


def _rel(path: Path) -> str:
    return str(path.relative_to(ROOT))


def fenced_blocks(text: str) -> list[tuple[str, int, str]]:
    """Every fenced code block: (info string, line of the opening fence, body)."""
    blocks, info, start, body = [], None, 0, []
    for n, line in enumerate(text.splitlines(), 1):
        stripped = line.strip()
        if info is None:
            if stripped.startswith("```"):
                info, start, body = stripped[3:].strip(), n, []
        elif stripped == "```":
            blocks.append((info, start, "\n".join(body) + "\n"))
            info = None
        else:
            body.append(line)
    assert info is None, f"a code fence opened at line {start} is never closed"
    return blocks


def prose_lines(text: str) -> list[tuple[int, str]]:
    """The lines outside code fences, with inline code spans blanked out."""
    out, fence = [], False
    for n, line in enumerate(text.splitlines(), 1):
        if line.strip().startswith("```"):
            fence = not fence
            continue
        if not fence:
            out.append((n, re.sub(r"(`+)(?:(?!\1).)+?\1", "", line)))
    return out


LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)")


def _heading_text(line: str) -> str:
    """A heading's text as rendered: link targets, code and emphasis marks gone."""
    text = re.sub(r"\[([^\]]*)\]\([^)]*\)", r"\1", line.lstrip("#").strip())
    return text.replace("`", "").replace("*", "")


def mkdocs_slug(text: str) -> str:
    """Python-Markdown's ``toc`` slug (what MkDocs and its anchors use)."""
    text = unicodedata.normalize("NFKD", text).encode("ascii", "ignore").decode("ascii")
    text = re.sub(r"[^\w\s-]", "", text).strip().lower()
    return re.sub(r"[-\s]+", "-", text)


def github_slug(text: str) -> str:
    """GitHub's heading anchor (what a reader of README.md and CONTRIBUTING.md on a forge follows)."""
    return re.sub(r"[^\w\- ]", "", text.strip().lower()).replace(" ", "-")


def anchors(path: Path, slug) -> set[str]:
    """The anchors of a Markdown file's headings under one slug rule (repeats get ``_1``/``-1``...)."""
    seen: dict[str, int] = {}
    found = set()
    fence = False
    for line in path.read_text(encoding="utf-8").splitlines():
        if line.strip().startswith("```"):
            fence = not fence
        if fence or not re.match(r"#{1,6} ", line):
            continue
        base = slug(_heading_text(line))
        n = seen.get(base, 0)
        seen[base] = n + 1
        found.add(base if n == 0 else f"{base}{'_' if slug is mkdocs_slug else '-'}{n}")
    return found


def test_the_readme_is_a_front_door():
    lines = README.read_text(encoding="utf-8").splitlines()
    assert len(lines) <= MAX_README_LINES, f"README.md has {len(lines)} lines: move sections to docs/"
    wide = [n for n, line in enumerate(lines, 1) if len(line) > MAX_README_WIDTH]
    assert wide == [], f"README.md lines over {MAX_README_WIDTH} characters: {wide}"
    text = "\n".join(lines)
    for needed in ("make demo", "make test", "docs/index.md", "docs/contributing.md"):
        assert needed in text, needed
    assert any(info == "python" for info, _, _ in fenced_blocks(text)), "the tour's code example"


def test_the_figures_page_is_what_bench_recorded():
    """docs/figures.md is bench/baseline.json's entries rendered: one source for every measured figure."""
    from ema_sim.benchmark import figures_page, recorded_entries  # noqa: PLC0415

    page = ROOT / "docs" / "figures.md"
    assert page.read_text(encoding="utf-8") == figures_page(recorded_entries(ROOT / "bench")), (
        "docs/figures.md differs from bench/baseline.json: run `ema bench --only NAME --record`")


def test_every_docs_page_is_in_the_site_nav():
    nav = (ROOT / "mkdocs.yml").read_text(encoding="utf-8")
    assert [p.name for p in DOCS if p.name not in nav] == []


@pytest.mark.parametrize("page", PAGES, ids=_rel)
def test_every_relative_link_resolves(page):
    broken = []
    for n, line in prose_lines(page.read_text(encoding="utf-8")):
        for target in LINK.findall(line):
            if re.match(r"^[a-z][a-z0-9+.-]*:", target):  # http:, https:, mailto:
                continue
            path, _, anchor = target.partition("#")
            dest = (page.parent / path).resolve() if path else page
            if not dest.exists():
                broken.append(f"{_rel(page)}:{n}: {target} (no such file)")
                continue
            if anchor and dest.suffix == ".md":
                # docs pages are read on the site (MkDocs' anchors); README and CONTRIBUTING on a forge
                # too, so an anchor they name must be the same under both rules
                rules = [mkdocs_slug] if page in DOCS else [mkdocs_slug, github_slug]
                if not all(anchor in anchors(dest, rule) for rule in rules):
                    broken.append(f"{_rel(page)}:{n}: {target} (no such heading)")
    assert broken == []


def test_the_site_builds_strict(tmp_path):
    pytest.importorskip("mkdocs")
    site = tmp_path / "site"
    # no --quiet: it hides the warnings from the counter --strict reads, and a broken anchor then passes
    done = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--config-file", str(ROOT / "mkdocs.yml"),
         "--site-dir", str(site)],
        cwd=ROOT, capture_output=True, text=True, timeout=120, check=False,
        env={**os.environ, "NO_MKDOCS_2_WARNING": "1"})
    assert done.returncode == 0, done.stdout + done.stderr
    for page in DOCS:
        html = site / ("index.html" if page.stem == "index" else f"{page.stem}/index.html")
        assert html.is_file(), html


def _python_blocks():
    for page in [README, *DOCS]:
        for info, line, body in fenced_blocks(page.read_text(encoding="utf-8")):
            if info.split(" ")[0] == "python" and SKETCH not in info:
                yield pytest.param(body, id=f"{_rel(page)}:{line}")


@pytest.mark.parametrize("code", _python_blocks())
def test_every_python_block_runs(code, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)  # a block that writes files writes them here
    exec(compile(code, "<docs>", "exec"), {"__name__": "__docs__"})
    capsys.readouterr()


def _shell_lines():
    for page in PAGES:
        for info, start, body in fenced_blocks(page.read_text(encoding="utf-8")):
            if info.split(" ")[0] not in {"sh", "bash", "shell"}:
                continue
            for k, line in enumerate(body.splitlines(), 1):
                words = shlex.split(line, comments=True)
                while words and re.match(r"^[A-Z_][A-Z0-9_]*=", words[0]):  # VAR=value prefixes
                    words.pop(0)
                if words and words[0] in {"ema", "make"}:
                    yield f"{_rel(page)}:{start + k}", words


def test_every_ema_and_make_line_of_a_shell_block_is_a_real_command():
    from ema_sim.cli import build_parser  # noqa: PLC0415  (imports every subcommand: only this test pays)

    parser = build_parser()
    targets = set(re.findall(r"^([\w-]+):", (ROOT / "Makefile").read_text(encoding="utf-8"), re.MULTILINE))
    wrong, seen = [], 0
    for where, words in _shell_lines():
        seen += 1
        if words[0] == "make":
            wrong += [f"{where}: make {t}" for t in words[1:] if t not in targets]
            continue
        err = io.StringIO()
        try:
            with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
                parser.parse_args(words[1:])
        except SystemExit:
            wrong.append(f"{where}: {shlex.join(words)}: {err.getvalue().strip()}")
    assert seen > 50, seen
    assert wrong == []
