"""The package's import graph: no module imports a layer above its own (hystcli.LAYERS), no circle,
the core free of the command line's and the figures' libraries. Read with ``ast``, so an import
inside a function counts as much as one at the top of a file."""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

import hystcli

PACKAGE = Path(hystcli.__file__).resolve().parent
CORE = ("core",)


def _modules() -> dict[str, Path]:
    """Dotted name -> file of every module of the package (a package by its ``__init__``)."""
    mods = {}
    for f in PACKAGE.rglob("*.py"):
        parts = ["hystcli", *f.relative_to(PACKAGE).with_suffix("").parts]
        if parts[-1] == "__init__":
            parts.pop()
        mods[".".join(parts)] = f
    return mods


def _imports(name: str, path: Path, mods: dict[str, Path]) -> list[tuple[str, bool]]:
    """(imported name, inside a function) for every import of the module; names of the package
    resolved to the module they load (``from . import io`` is ``hystcli.io``), others left whole."""
    found = []

    def visit(node: ast.AST, in_function: bool) -> None:
        for child in ast.iter_child_nodes(node):
            inner = in_function or isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda))
            if isinstance(child, ast.Import):
                found.extend((a.name, in_function) for a in child.names)
            elif isinstance(child, ast.ImportFrom):
                if child.level:
                    base = name.split(".") if path.name == "__init__.py" else name.split(".")[:-1]
                    base = base[:len(base) - (child.level - 1)]
                    module = ".".join(base + ([child.module] if child.module else []))
                else:
                    module = child.module or ""
                for a in child.names:
                    full = f"{module}.{a.name}"
                    found.append((full if full in mods else module, in_function))
            visit(child, inner)

    visit(ast.parse(path.read_text(), str(path)), False)
    return found


def _graph() -> dict[str, set[tuple[str, bool]]]:
    mods = _modules()
    graph = {}
    for name, path in mods.items():
        edges = set()
        for target, late in _imports(name, path, mods):
            while target and target not in mods and target.startswith("hystcli."):
                target = target.rpartition(".")[0]
            if target in mods and target != name:
                edges.add((target, late))
        graph[name] = edges
    return graph


def _top(module: str) -> str:
    """The name directly under hystcli a module belongs to ('' for the package itself)."""
    return module.split(".")[1] if module.count(".") else ""


def _layer(module: str) -> int:
    top = _top(module)
    for i, names in enumerate(hystcli.LAYERS):
        if top in names:
            return i
    raise AssertionError(f"{module} is in no layer: add {top!r} to hystcli.LAYERS")


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan's algorithm)."""
    index, low, stack, on, out = {}, {}, [], set(), []

    def strong(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                strong(w)
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
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            strong(v)
    return out


def test_every_module_is_in_one_layer():
    tops = {_top(m) for m in _modules()} - {""}
    listed = [n for layer in hystcli.LAYERS for n in layer]
    assert len(listed) == len(set(listed)), "a name is in two layers"
    assert tops <= set(listed), f"in no layer: {sorted(tops - set(listed))}"


def test_no_module_imports_a_layer_above_its_own():
    upward = sorted(f"{src} -> {dst}{' (in a function)' if late else ''}"
                    for src, edges in _graph().items() if _top(src)
                    for dst, late in edges if _top(dst) and _layer(dst) > _layer(src))
    assert not upward, "imports against the layers of hystcli.LAYERS:\n" + "\n".join(upward)


def test_the_import_graph_has_no_circle():
    graph = {src: {dst for dst, _ in edges} for src, edges in _graph().items()}
    assert not _cycles(graph), _cycles(graph)


def test_the_package_itself_imports_only_the_errors():
    # `import hystcli` stays light: every other public name is imported by name on first use
    assert {dst for dst, _ in _graph()["hystcli"]} == {"hystcli.errors"}


def test_the_core_imports_no_command_line_or_figure_library():
    mods = _modules()
    heavy = sorted(f"{name} imports {target}" for name, path in mods.items() if _top(name) in CORE
                   for target, _ in _imports(name, path, mods)
                   if target.split(".")[0] in ("typer", "rich", "matplotlib", "click"))
    assert not heavy, heavy


@pytest.mark.parametrize("source, message", [
    ({"hystcli.a": {"hystcli.b"}, "hystcli.b": {"hystcli.c"}, "hystcli.c": {"hystcli.a"}}, "circle"),
    ({"hystcli.a": {"hystcli.b"}, "hystcli.b": set()}, None)])
def test_the_circle_finder_finds_a_circle_and_only_a_circle(source, message):
    found = _cycles(source)
    assert (found == [["hystcli.a", "hystcli.b", "hystcli.c"]]) if message else found == []


def test_the_reading_resolves_relative_and_late_imports(tmp_path):
    # the checks above can fail: a function-level relative import is read, resolved and marked late
    f = tmp_path / "m.py"
    f.write_text("from .errors import DataError\n\ndef g():\n    from . import io\n    import typer\n")
    mods = {"hystcli.m": f, "hystcli.io": f, "hystcli.errors": f}
    assert set(_imports("hystcli.m", f, mods)) == {("hystcli.errors", False), ("hystcli.io", True),
                                                    ("typer", True)}
