"""The library first: the public names of `import hystcli`, the session script of docs/library.md
run as a user runs it, the docstrings' examples, and the type marker."""
from __future__ import annotations

import doctest
import importlib
import re
import sys
from pathlib import Path

import pytest

import hystcli

ROOT = Path(__file__).resolve().parents[1]
FUNCTIONS = {"identify": "hystcli.identification", "detect_shift": "hystcli.shift.search",
             "compensate": "hystcli.compensation", "predict": "hystcli.core.model",
             "evaluate": "hystcli.report.metrics", "diagnose": "hystcli.diagnosis"}


def test_the_library_functions_are_top_level_names():
    for name, module in FUNCTIONS.items():
        fn = getattr(hystcli, name)
        assert callable(fn) and fn is getattr(importlib.import_module(module), name), name
        assert name in hystcli.__all__
    # importing every subpackage does not put a module where a function was (no name is shared)
    for module in ("hystcli.identification", "hystcli.shift", "hystcli.diagnosis", "hystcli.report.metrics"):
        importlib.import_module(module)
    for name, module in FUNCTIONS.items():
        assert getattr(hystcli, name) is getattr(importlib.import_module(module), name), name


def _page_code() -> list[str]:
    text = (ROOT / "docs" / "library.md").read_text()
    blocks = re.findall(r"```python\n(.*?)```", text, re.S)
    assert len(blocks) == 2, "docs/library.md holds the session and the estimators' example"
    return blocks


def _session_code() -> str:
    return _page_code()[0]


def test_the_session_of_the_docs_runs_and_finds_the_shift(monkeypatch, capsys):
    code = _session_code()
    assert code.startswith("import hystcli\n") and len(code.strip().splitlines()) <= 20
    monkeypatch.chdir(ROOT)
    ns: dict = {}
    exec(compile(code, "docs/library.md", "exec"), ns)  # noqa: S102 - the page's own script
    out = capsys.readouterr().out
    # every result printed its summary
    for value in (ns["ident"], ns["shift"], ns["comps"][1], ns["report"]):
        assert value.summary() in out
    # the shift the replay's twin carried, found within its interval's reach
    truth = float(ns["replay"].meta["true_offset1"])
    assert abs(ns["shift"].offset - truth) < 1.0, (ns["shift"].offset, truth)
    # on the shifted model, ignoring the shift costs accuracy and using it costs none
    report = ns["report"]
    comp, both = report.group(controller="comp"), report.group(controller="comp+shift")
    assert both.rmse_mean < 1e-6 < comp.rmse_mean


def test_the_estimators_example_of_the_docs_runs(monkeypatch, capsys):
    from matplotlib.figure import Figure

    code = _page_code()[1]
    monkeypatch.chdir(ROOT)
    ns: dict = {}
    exec(compile(code, "docs/library.md", "exec"), ns)  # noqa: S102 - the page's own script
    out = capsys.readouterr().out
    assert "0.9 Identifier(level=0.9)" in out and ns["ident"].summary() in out
    assert ns["est"].get_params() == {**hystcli.Identifier().get_params(), "level": 0.9}
    want = hystcli.identify(ns["sweep"], settings=hystcli.Settings(level=0.9))
    assert ns["ident"].intervals == want.intervals
    assert isinstance(ns["fig"], Figure) and ns["fig"].axes


def _module_examples(name: str) -> doctest.TestResults:
    module = sys.modules.get(name) or importlib.import_module(name)
    return doctest.testmod(module, optionflags=doctest.ELLIPSIS, report=False)


@pytest.mark.parametrize("name", ["hystcli.stream.compensator", "hystcli.io.files", "hystcli.cli.app", "hystcli.shift.request",
                                  "hystcli.estimators"])
def test_the_docstring_examples_run(name):
    importlib.import_module(name)
    res = _module_examples(name)
    assert res.attempted > 0 and res.failed == 0, res


def test_no_docstring_example_is_skipped():
    skipped = [f.relative_to(ROOT).as_posix() for f in (ROOT / "hystcli").rglob("*.py")
               if "doctest: +SKIP" in f.read_text()]
    assert not skipped, skipped


def test_the_package_ships_its_type_marker():
    assert (ROOT / "hystcli" / "py.typed").is_file()
    assert re.search(r'\[tool\.setuptools\.package-data\]\s*\nhystcli\s*=\s*\[[^\]]*"py\.typed"',
                     (ROOT / "pyproject.toml").read_text())
