"""Dead-link check of the repository's own Markdown: every relative link must resolve.

``mkdocs build --strict`` checks the links between the site's pages; this checks every Markdown
file of the repository (the README, ``docs/``, ``sample_data/``, ...), including links that leave
``docs/`` and anchors into other files. Links to the web (``https://``, ``mailto:``) are not
followed: CI has no general internet. Links inside code (fenced blocks, inline code) are not
links. Run from anywhere; exit 1 and one line per dead link when there is one::

    python docs/check_links.py
"""
from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path
from urllib.parse import unquote

ROOT = Path(__file__).resolve().parents[1]

# folders that are not the repository's documents: VCS, build output, environments, caches
SKIP_DIRS = {".git", "site", "build", "dist", ".venv", "venv", "node_modules", "__pycache__"}

_FENCE = re.compile(r"^(```|~~~).*?^\1", re.M | re.S)
_CODE = re.compile(r"`[^`\n]*`")
_LINK = re.compile(r"!?\[[^\]\n]*\]\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)")
_HEADING = re.compile(r"^#{1,6}\s+(.*?)\s*#*\s*$", re.M)
_EXTERNAL = re.compile(r"^[a-z][a-z0-9+.-]*:", re.I)


def repository_files(root: Path = ROOT, pattern: str = "*") -> list[Path]:
    """The repository's files matching ``pattern``: tracked or new, not ignored (``git ls-files``);
    outside a git checkout, every file outside :data:`SKIP_DIRS`, hidden folders and eggs."""
    try:
        out = subprocess.run(["git", "ls-files", "-z", "--cached", "--others", "--exclude-standard",
                              "--", pattern], cwd=root, capture_output=True, check=True).stdout
        return sorted(root / name for name in set(out.decode().split("\0")) if name
                      and (root / name).is_file())
    except (OSError, subprocess.CalledProcessError):
        return sorted(p for p in root.rglob(pattern) if p.is_file()
                      and not any(part in SKIP_DIRS or part.startswith(".") or part.endswith(".egg-info")
                                  for part in p.relative_to(root).parts[:-1]))


def markdown_files(root: Path = ROOT) -> list[Path]:
    """Every Markdown file of the repository (:func:`repository_files`)."""
    return repository_files(root, "*.md")


def _prose(text: str) -> str:
    """The text without fenced code blocks and inline code spans (their brackets are not links)."""
    return _CODE.sub("", _FENCE.sub("", text))


def slug(heading: str) -> str:
    """The anchor GitHub and mkdocs give a heading: lower case, punctuation dropped, spaces to
    hyphens (``"2. Units and conventions"`` -> ``"2-units-and-conventions"``)."""
    text = re.sub(r"[`*_]", "", heading).strip().lower()
    text = re.sub(r"[^\w\s-]", "", text)
    return re.sub(r"\s+", "-", text)


def anchors(path: Path) -> set[str]:
    """The anchors of a Markdown file's headings."""
    return {slug(h) for h in _HEADING.findall(_FENCE.sub("", path.read_text(encoding="utf-8")))}


def links(path: Path) -> list[str]:
    """The relative link targets of a Markdown file (web links and pure anchors included)."""
    return _LINK.findall(_prose(path.read_text(encoding="utf-8")))


def dead_links(root: Path = ROOT) -> list[str]:
    """One line ``file: target (why)`` per relative link that does not resolve."""
    dead = []
    for md in markdown_files(root):
        for target in links(md):
            if _EXTERNAL.match(target):
                continue
            where, _, anchor = unquote(target).partition("#")
            dest = (md.parent / where).resolve() if where else md
            name = md.relative_to(root)
            if not dest.exists():
                dead.append(f"{name}: {target} (no such file)")
            elif root.resolve() not in dest.parents:
                dead.append(f"{name}: {target} (outside the repository)")
            elif anchor and dest.suffix == ".md" and anchor not in anchors(dest):
                dead.append(f"{name}: {target} (no heading with that anchor)")
    return dead


def main() -> int:
    dead = dead_links()
    for line in dead:
        print(f"Error: dead link in {line}", file=sys.stderr)
    n = len(markdown_files())
    print(f"{n} Markdown files checked, {len(dead)} dead link(s)")
    return 1 if dead else 0


if __name__ == "__main__":
    raise SystemExit(main())
