"""Start-up of the command line (issue 12): what `hyst --help` loads, -V, completion, and Ctrl-C
while the modules load. Timings are in bench/bench_startup.py; here what makes them: the heavy
libraries stay out until a command needs them."""
from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

HEAVY = ("scipy", "pandas", "numba", "matplotlib", "rich", "hystcli.sim.twin", "hystcli.core.effects",
         "hystcli.identification", "hystcli.diagnosis", "hystcli.sim.experiment")


def _python(code: str, *args: str, env: dict | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True, timeout=120,
                          env={**os.environ, **(env or {})})


def _loaded_after(argv: list[str]) -> list[str]:
    code = ("import json, sys\n"
            "from hystcli.__main__ import main\n"
            "sys.argv = ['hyst', *sys.argv[1:]]\n"
            "try:\n    main()\nexcept SystemExit:\n    pass\n"
            f"print(json.dumps([m for m in {HEAVY!r} if m in sys.modules]), file=sys.stderr)\n")
    res = _python(code, *argv)
    return json.loads(res.stderr.strip().splitlines()[-1])


@pytest.mark.parametrize("argv", [["--help"], ["--version"], ["identify", "--help"], ["demo", "--help"],
                                  ["simulate", "--help"], ["diagnose", "--help"], ["import", "--help"]])
def test_help_and_version_load_no_heavy_library(argv):
    assert _loaded_after(argv) == []


def test_import_hystcli_is_light_and_its_names_still_work(tmp_path):
    res = _python("import sys, hystcli\n"
                  "light = [m for m in ('numpy', 'pandas', 'numba', 'hystcli.io') if m in sys.modules]\n"
                  "m = hystcli.KnobModel(9.1, -8.7, 6.2, 5.9, 1.45, -4.0, 4.2)\n"
                  "hystcli.save_model(sys.argv[1], hystcli.Model({1: m}))\n"
                  "print(light, hystcli.load_model(sys.argv[1]).knob(1) == m, 'load_model' in dir(hystcli))",
                  str(tmp_path / "m.json"))
    assert res.returncode == 0, res.stderr
    assert res.stdout.split() == ["[]", "True", "True"]
    assert "no attribute 'nope'" in _python("import hystcli; hystcli.nope").stderr


def test_version_has_a_short_alias():
    for flag in ("-V", "--version"):
        res = subprocess.run([sys.executable, "-m", "hystcli", flag], capture_output=True, text=True, timeout=120)
        assert res.returncode == 0 and res.stdout.startswith("hyst ") and res.stdout.split()[1][0].isdigit()


def test_shell_completion_completes_commands_and_options():
    env = {"_HYST_COMPLETE": "complete_bash", "COMP_WORDS": "hyst ide", "COMP_CWORD": "1"}
    res = _python("from hystcli.__main__ import main; main()", env=env)
    assert res.stdout.split() == ["identify"]
    env.update(COMP_WORDS="hyst simulate --mo", COMP_CWORD="2")
    assert _python("from hystcli.__main__ import main; main()", env=env).stdout.split() == ["--motion"]
    res = _python("from hystcli.__main__ import main; import sys; sys.argv = ['hyst', '--help']; main()")
    assert "--install-completion" in res.stdout and "--show-completion" in res.stdout


def test_ctrl_c_while_the_commands_load_is_no_traceback():
    # Ctrl-C arrives while a command module is being imported (the slowest part of start-up)
    code = ("import sys\n"
            "class Interrupt:\n"
            "    def find_spec(self, name, path=None, target=None):\n"
            "        if name == 'hystcli.cli.model_cmds':\n"
            "            raise KeyboardInterrupt\n"
            "sys.meta_path.insert(0, Interrupt())\n"
            "sys.argv = ['hyst', '--help']\n"
            "from hystcli.__main__ import main\n"
            "main()\n")
    res = _python(code)
    assert res.returncode == 130
    assert res.stderr == "Error: interrupted\n" and res.stdout == ""


def test_usage_lines_name_arguments_not_python_types():
    res = _python("from hystcli.__main__ import main; import sys; sys.argv = ['hyst', *sys.argv[1:]]; main()",
                  "evaluate", "--help")
    usage = res.stdout.splitlines()[0]
    assert usage == "Usage: hyst evaluate [OPTIONS] RUN.csv..."
    assert "<list[Path]>" not in res.stdout and "{" not in usage


def test_help_examples_name_files_that_exist():
    # run from the repository root, every example's input path is a file there (the others, like
    # model.json, are what the README's walk-through writes)
    from pathlib import Path

    from typer.testing import CliRunner

    from hystcli.cli import app

    root = Path(__file__).resolve().parents[1]
    named = 0
    for name in ("identify", "predict", "rotate-shift", "evaluate", "diagnose", "simulate", "demo", "import"):
        text = CliRunner().invoke(app, [name, "--help"], terminal_width=400).stdout
        for line in (ln for ln in text.splitlines() if "hyst " in ln):
            for token in line.replace('"', " ").split():
                if "/" in token and token.rstrip("/").endswith((".csv", ".json", ".gz")):
                    named += 1
                    assert list(root.glob(token)), (name, token)
    assert named >= 4


def test_ctrl_c_while_typer_builds_the_commands_is_no_traceback():
    code = ("import sys, typer.main\n"
            "def interrupted(*a, **k):\n"
            "    raise KeyboardInterrupt\n"
            "typer.main.get_command = interrupted\n"
            "sys.argv = ['hyst', '--help']\n"
            "from hystcli.__main__ import main\n"
            "main()\n")
    res = _python(code)
    assert res.returncode == 130 and res.stderr == "Error: interrupted\n"


# ------------------------------------------------------------------------------------------
# threads: the command line pins BLAS, OpenMP and numba before they load
# ------------------------------------------------------------------------------------------
_THREAD_VARS = ("HYST_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS",
                "BLIS_NUM_THREADS", "VECLIB_MAXIMUM_THREADS", "NUMEXPR_NUM_THREADS", "NUMBA_NUM_THREADS")


def _threads(**env: str) -> tuple[set, int]:
    """BLAS thread counts (threadpoolctl's, numpy loaded after the entry point's pinning) and the
    thread count numba will read when it loads, in a process whose environment sets only ``env``
    of the thread variables."""
    code = ("import json, os\n"
            "from hystcli.__main__ import pin_threads\n"
            "pin_threads()\n"
            "import numpy\n"
            "from threadpoolctl import threadpool_info\n"
            "print(json.dumps([sorted({p['num_threads'] for p in threadpool_info() if p['user_api'] == 'blas'}),"
            " int(os.environ['NUMBA_NUM_THREADS'])]))\n")
    base = {k: v for k, v in os.environ.items() if k not in _THREAD_VARS}
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                         env={**base, **env})
    assert res.returncode == 0, res.stderr
    blas, numba_threads = json.loads(res.stdout)
    return set(blas), numba_threads


def test_the_command_line_pins_threads_to_one_unless_told():
    if (os.cpu_count() or 1) < 2:
        pytest.skip("one processor: every thread count is 1")
    assert _threads() == ({1}, 1)
    assert _threads(HYST_THREADS="2") == ({2}, 2)
    # a library's own variable the user set is kept, the others follow HYST_THREADS (or 1)
    assert _threads(OPENBLAS_NUM_THREADS="2") == ({2}, 1)
    assert _threads(NUMBA_NUM_THREADS="2", HYST_THREADS="1") == ({1}, 2)


def test_a_bad_thread_count_is_a_usage_error_and_help_says_how_to_set_it():
    res = _python("from hystcli.__main__ import main; import sys; sys.argv = ['hyst', '--help']; main()",
                  env={"HYST_THREADS": "many"})
    assert res.returncode == 2 and res.stderr == "Error: HYST_THREADS must be a positive whole number, got 'many'\n"
    res = _python("from hystcli.__main__ import main; import sys; sys.argv = ['hyst', '--help']; main()")
    assert "HYST_THREADS" in res.stdout and "OPENBLAS_NUM_THREADS" in res.stdout


def test_a_bad_input_file_is_refused_before_anything_heavy_loads(tmp_path):
    """The error line of a missing or malformed run comes in the command line's own start-up
    time: scipy, numba, pandas and the fit load only for a file that can be read."""
    bad = tmp_path / "bad.csv"
    bad.write_text("time,knob,tip\n0,1,2\n")
    for path in (tmp_path / "missing.csv", bad):
        assert _loaded_after(["identify", str(path), "-o", str(tmp_path / "m.json")]) == []
    # the check sees a heavy library when one loads: pandas reads a readable run
    good = tmp_path / "good.csv"
    good.write_text("t,q1\n0,0\n0.1,1\n")
    assert "pandas" in _loaded_after(["evaluate", str(good)])
