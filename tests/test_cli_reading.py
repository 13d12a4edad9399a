"""The reading of a big file shows its progress on a terminal, and only there (`hyst identify`,
`hyst import`). The bar itself is rich's; here what feeds it: the file's name and its MiB read,
growing to the whole, from the readers' blocks. Reading speed and memory are measured in
bench/bench_io.py."""
from __future__ import annotations

import contextlib
import sys

import numpy as np
import pytest
from typer.testing import CliRunner

import hystcli.io.runs as io_mod
from hystcli.cli import app

APP = sys.modules["hystcli.cli.app"]   # the module (hystcli.cli.app is the typer app)
MiB = 2 ** 20


@pytest.fixture
def big(tmp_path, monkeypatch):
    """A 2.2 MiB run (100,000 rows) read in blocks of 10,000 rows, and a progress threshold of 1 MiB."""
    monkeypatch.setattr(io_mod, "READ_CHUNK_ROWS", 10_000)
    monkeypatch.setattr(io_mod, "READ_PROGRESS_BYTES", MiB)
    t = np.arange(100_000) / 1000.0
    q = 40.0 * np.sin(2 * np.pi * 0.5 * t)
    path = tmp_path / "big.csv"
    # no c1 or y1 column: identify refuses the run at once after reading it (its fit is not timed here)
    path.write_text("t,q1,x\n" + "".join(f"{a:.3f},{b:.4f},{c:.2f}\n" for a, b, c in zip(t, q, 2 * q)))
    assert path.stat().st_size > 2 * MiB
    return path


def _updates(monkeypatch, tty: bool) -> list:
    seen: list = []

    @contextlib.contextmanager
    def fake_bar():
        yield lambda message, done=None, total=None: seen.append((message, done, total))

    monkeypatch.setattr(APP, "stderr_is_tty", lambda: tty)
    monkeypatch.setattr(APP, "_rich_progress", fake_bar)
    return seen


@pytest.mark.parametrize("argv", [["identify", "{big}", "-o", "{out}.json"],
                                  ["import", "{big}", "--map", "t=1,q1=2,c1=3", "--skip", "1", "-o", "{out}.csv"]])
def test_a_big_read_shows_its_progress_on_a_terminal(big, monkeypatch, argv):
    seen = _updates(monkeypatch, tty=True)
    args = [a.format(big=big, out=big.parent / "out") for a in argv]
    CliRunner().invoke(app, args)
    reads = [s for s in seen if s[0] == "reading big.csv"]
    assert len(reads) >= 10   # 100,000 rows in blocks of 10,000
    done = [d for _, d, _ in reads]
    assert done == sorted(done) and done[-1] == reads[-1][2] == big.stat().st_size // MiB


def test_no_progress_off_a_terminal_or_quiet(big, monkeypatch):
    seen = _updates(monkeypatch, tty=False)
    res = CliRunner().invoke(app, ["import", str(big), "--map", "t=1,q1=2,c1=3", "--skip", "1",
                                   "-o", str(big.parent / "out.csv")])
    assert res.exit_code == 0, res.output
    assert seen == [] and "reading" not in res.stderr
    seen = _updates(monkeypatch, tty=True)
    res = CliRunner().invoke(app, ["import", str(big), "--map", "t=1,q1=2,c1=3", "--skip", "1",
                                   "-o", str(big.parent / "out2.csv"), "--quiet"])
    assert res.exit_code == 0 and seen == []
