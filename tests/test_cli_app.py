"""The shared pieces of the command line (hystcli/cli/app.py): progress, usage errors, file names
in messages."""
from __future__ import annotations

import importlib
import io
import sys
from pathlib import Path

import pytest
import typer

from hystcli.errors import DataError

# the module, not the Typer object the package exports under the same name
app_module = importlib.import_module("hystcli.cli.app")


def _run(monkeypatch, tty: bool, steps, quiet: bool = False, interval: float = 1.0) -> str:
    buf = io.StringIO()
    monkeypatch.setattr(sys, "stderr", buf)
    monkeypatch.setattr(app_module, "stderr_is_tty", lambda: tty)
    with app_module.progress(quiet, interval=interval) as update:
        for step in steps:
            update(*step)
    return buf.getvalue()


def test_progress_on_a_pipe_is_plain_lines_first_and_last_always(monkeypatch):
    steps = [(f"step {i}", i, 50) for i in range(1, 51)]
    out = _run(monkeypatch, False, steps, interval=3600.0)
    # within one interval only the first and the last step are shown; no bar, no control codes
    assert out == "[1/50] step 1\n[50/50] step 50\n"
    out = _run(monkeypatch, False, steps[:3], interval=0.0)
    assert out.splitlines() == ["[1/50] step 1", "[2/50] step 2", "[3/50] step 3"]
    # a message without counts (e.g. a stage name) is always shown, and an unknown total never is
    assert _run(monkeypatch, False, [("where",), ("which", 1, None)], interval=3600.0) == "where\n[1] which\n"
    assert _run(monkeypatch, False, steps, quiet=True) == ""


def test_progress_on_a_terminal_is_a_bar_that_never_shows_an_unknown_total(monkeypatch):
    monkeypatch.setenv("TTY_COMPATIBLE", "1")  # rich draws as on a terminal
    monkeypatch.setenv("TTY_INTERACTIVE", "1")
    out = _run(monkeypatch, True, [("reading", 1, 10), ("more", 5, 10)])
    assert "\x1b[" in out and "1/10" in out and "None" not in out and "[1/10]" not in out
    assert _run(monkeypatch, True, [("x", 1, 10)], quiet=True) == ""


def test_usage_errors_and_option_errors_exit_2():
    with pytest.raises(typer.BadParameter, match="bad"):
        app_module.usage_error("bad", "--x")
    with pytest.raises(typer.BadParameter) as err:
        with app_module.option_errors("--shape"):
            raise DataError("bad shape segment 'alpha=x'\nsecond line")
    assert err.value.message == "bad shape segment 'alpha=x'" and err.value.param_hint == "--shape"
    with pytest.raises(typer.BadParameter, match="--output and --plot name the same file"):
        app_module.distinct_outputs(**{"--output": Path("a/../x.png"), "--plot": Path("x.png")})
    app_module.distinct_outputs(**{"--output": Path("x.json"), "--plot": None})
    with pytest.raises(typer.BadParameter, match="are the same file"):
        app_module.distinct_inputs([Path("r.csv"), Path("./r.csv")])


def test_about_names_the_file_once():
    with pytest.raises(DataError, match=r"^run\.csv: sample rate too high$"):
        with app_module.about(Path("run.csv")):
            raise DataError("sample rate too high")
    with pytest.raises(DataError, match=r"^run\.csv: column 't'$"):  # already named: left as it is
        with app_module.about(Path("run.csv")):
            raise DataError("run.csv: column 't'")
