"""The repository's documents: a README that fits a screenful or two, links that resolve, and no
citation of a document the repository does not hold.

The dead-link check is ``docs/check_links.py`` (CI also runs it beside ``mkdocs build --strict``);
these tests hold it to its job on a planted broken link, then run it on the repository.
"""
from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

# Documents outside the repository that files must not send a reader to. Spelt in pieces so that
# this file does not cite them itself.
OUTSIDE = ("DESIGN" + ".md", ".." + "/shared")

# Files other work is rewriting now, whose citations the lead updates when it lands (path
# prefixes). Each must still hold a citation: remove an entry once its files are clean.
PENDING: tuple[str, ...] = ()


def _check_links():
    spec = importlib.util.spec_from_file_location("check_links", ROOT / "docs" / "check_links.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_readme_is_under_150_lines():
    lines = (ROOT / "README.md").read_text(encoding="utf-8").splitlines()
    assert len(lines) < 150, f"README.md has {len(lines)} lines"


def test_the_link_checker_finds_dead_links(tmp_path):
    cl = _check_links()
    repo = tmp_path / "repo"
    (repo / "docs").mkdir(parents=True)
    (repo / "docs" / "page.md").write_text("# A page\n\n## Second part\n", encoding="utf-8")
    (repo / "README.md").write_text(
        "See [the page](docs/page.md), [its part](docs/page.md#second-part), [web](https://example.org),\n"
        "[gone](docs/gone.md), [no part](docs/page.md#third-part), [above](../outside.md) and\n"
        "`[code](not/a/link.md)`.\n\n```\n[fenced](also/not.md)\n```\n", encoding="utf-8")
    (tmp_path / "outside.md").write_text("# out\n", encoding="utf-8")
    dead = cl.dead_links(repo)
    assert sorted(dead) == ["README.md: ../outside.md (outside the repository)",
                            "README.md: docs/gone.md (no such file)",
                            "README.md: docs/page.md#third-part (no heading with that anchor)"]


@pytest.mark.parametrize("heading, anchor", [
    ("2. Units and conventions", "2-units-and-conventions"),
    ("The current's sign", "the-currents-sign"),
    ("Algorithm 1: detecting the shift", "algorithm-1-detecting-the-shift"),
    ("Run CSV", "run-csv"),
    ("`hyst track`", "hyst-track"),
])
def test_anchors_are_the_ones_github_and_mkdocs_make(heading, anchor):
    assert _check_links().slug(heading) == anchor


def test_every_relative_link_in_the_repository_resolves():
    cl = _check_links()
    files = {p.relative_to(ROOT).as_posix() for p in cl.markdown_files(ROOT)}
    assert "README.md" in files and "docs/method.md" in files
    assert cl.dead_links(ROOT) == []


def _citing(text: bytes) -> list[str]:
    return [name for name in OUTSIDE if name.encode() in text]


def test_no_file_cites_a_document_outside_the_repository():
    cl = _check_links()
    found = {}
    for path in cl.repository_files(ROOT):
        cited = _citing(path.read_bytes())
        if cited:
            found[path.relative_to(ROOT).as_posix()] = cited
    stray = {name: cited for name, cited in found.items() if not name.startswith(PENDING)}
    assert not stray, f"files cite documents the repository does not hold: {stray}"
    stale = [prefix for prefix in PENDING if not any(name.startswith(prefix) for name in found)]
    assert not stale, f"no citation left under {stale}: remove them from PENDING"
