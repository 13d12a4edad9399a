"""The command line as a newcomer meets it: a CSV of their own columns (check, identify --columns,
import --map by name), the grouped help at 80 columns, the data file positional everywhere, one
--knob and one --format, identify without -o, and the same error for a bad shape everywhere."""
from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from hystcli.cli import app
from hystcli.cli.app import HELP_PANELS, SUMMARY_WIDTH
from hystcli.core.run import Run
from hystcli.io import load_model, read_run, write_run

ROOT = Path(__file__).resolve().parents[1]
SWEEP = ROOT / "sample_data" / "ice-a" / "sweep_knob1.csv"
REPLAY = ROOT / "sample_data" / "ice-a" / "replay_alpha90_knob1.csv"
COLUMNS = "t=time_s,q1=knob_deg,y1=tip_deg,c1=current_mA"

runner = CliRunner()


def invoke(*args, **kw):
    return runner.invoke(app, [str(a) for a in args], **kw)


def one_error(res, code: int = 1) -> str:
    assert res.exit_code == code, res.output
    lines = [ln for ln in res.stderr.splitlines() if ln.startswith("Error")]
    assert len(lines) == 1 and "Traceback" not in res.output, res.output
    return lines[0]


@pytest.fixture(scope="module")
def mine(tmp_path_factory):
    """The sample sweep as a user's own log: tab-separated, a comment line, their own names."""
    d = tmp_path_factory.mktemp("mine")
    run = read_run(SWEEP)
    body = "\n".join("\t".join(repr(v) for v in row)
                     for row in zip(*(run[n].tolist() for n in ("t", "q1", "y1", "c1"))))
    (d / "mine.tsv").write_text("# knob 1 sweep, bench 2\ntime_s\tknob_deg\ttip_deg\tcurrent_mA\n" + body + "\n")
    return d


# --------------------------------------------------------------------------------------------
# your own CSV
# --------------------------------------------------------------------------------------------
def test_check_tells_a_users_csv_what_to_type_and_then_passes_it(mine):
    res = invoke("check", mine / "mine.tsv")
    assert res.exit_code == 1
    lines = res.stdout.splitlines()
    # every problem at once, one line each, then the count
    assert lines == [
        f"{mine / 'mine.tsv'}: error: file: the columns are separated by tabs, not commas: read it with --columns "
        "(any separator), or convert it with hyst import",
        f"{mine / 'mine.tsv'}: error: header: no time column t (the file has time_s, knob_deg, tip_deg, "
        f"current_mA); name yours with --columns {COLUMNS}",
        f"{mine / 'mine.tsv'}: error: header: no knob angle q1 or q2, nor a reference r1 or r2 (columns found: "
        "none)",
        "3 error(s), 0 warning(s) in 1 file(s)"]
    res = invoke("check", mine / "mine.tsv", "--columns", COLUMNS)
    assert res.exit_code == 0, res.output
    assert res.stdout.splitlines()[0] == (f"{mine / 'mine.tsv'}: ok: 12567 rows; 1000 Hz (jitter 0.0 %); "
                                          "columns t, q1, y1, c1")


def test_check_exits_0_with_warnings_only_and_quiet_prints_the_errors(tmp_path):
    run = read_run(SWEEP)
    flat = Run({**run.columns, "y1": np.zeros(len(run))}, run.meta)  # a tip sensor not connected
    write_run(tmp_path / "flat.csv", flat)
    write_run(tmp_path / "nan.csv", run)
    text = (tmp_path / "nan.csv").read_text().splitlines()
    text[20] = text[20].rsplit(",", 1)[0] + ",nan"  # line 21: one missing current
    (tmp_path / "nan.csv").write_text("\n".join(text) + "\n")
    res = invoke("check", tmp_path / "flat.csv")
    assert res.exit_code == 0, res.output
    assert res.stdout.splitlines()[0].startswith(f"{tmp_path / 'flat.csv'}: warning: y1: the tip never moves")
    res = invoke("check", tmp_path / "flat.csv", tmp_path / "nan.csv")
    assert res.exit_code == 1
    assert res.stdout.splitlines()[-1] == "1 error(s), 1 warning(s) in 2 file(s)"
    res = invoke("check", tmp_path / "flat.csv", tmp_path / "nan.csv", "-q")
    assert res.exit_code == 1 and res.stdout.splitlines() == [
        f"{tmp_path / 'nan.csv'}: error: c1: 1 missing value(s) (empty or NaN), the first at line 21"]


@pytest.mark.slow
def test_identify_with_columns_reads_a_users_csv_as_the_run(mine):
    ours = invoke("identify", mine / "mine.tsv", "--columns", COLUMNS, "--format", "json")
    assert ours.exit_code == 0, ours.output
    theirs = invoke("identify", SWEEP, "--format", "json")
    assert theirs.exit_code == 0, theirs.output
    # the same numbers, read either way (the warnings name each its own file)
    assert json.loads(ours.stdout.replace(str(mine / "mine.tsv"), "RUN")) == \
        json.loads(theirs.stdout.replace(str(SWEEP), "RUN"))
    res = invoke("identify", mine / "mine.tsv", "--columns", "t=time,q1=knob_deg")
    assert one_error(res) == (f"Error: {mine / 'mine.tsv'}: no column 'time' for t (the file has time_s, knob_deg, "
                              "tip_deg, current_mA); did you mean 'time_s'?")
    assert "--columns" in one_error(invoke("identify", mine / "mine.tsv", "--columns", "t"), 2)


def test_columns_with_units_convert_to_the_runs_units(tmp_path):
    run = read_run(SWEEP)
    n = 3000
    text = "time_ms;knob_rad;tip;I_A\n" + "\n".join(
        f"{1000 * t!r};{float(np.radians(q))!r};{y!r};{c / 1000!r}"
        for t, q, y, c in zip(*(run[k][:n].tolist() for k in ("t", "q1", "y1", "c1"))))
    (tmp_path / "log.csv").write_text(text + "\n")
    out = tmp_path / "pred.csv"
    model = tmp_path / "m.json"
    write_run(tmp_path / "sweep.csv", run)
    assert invoke("identify", tmp_path / "sweep.csv", "-o", model, "-q").exit_code == 0
    res = invoke("predict", tmp_path / "log.csv", "--model", model, "-o", out,
                 "--columns", "t=time_ms:ms,q1=knob_rad:rad,y1=tip,c1=I_A:A", "-q")
    assert res.exit_code == 0, res.output
    pred = read_run(out)
    np.testing.assert_allclose(pred["t"], run["t"][:n], rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(pred["c1"], run["c1"][:n], rtol=1e-12)
    np.testing.assert_allclose(pred["y1_measured"], run["y1"][:n])


def test_import_maps_columns_by_name_and_sniffs_the_layout(mine, tmp_path):
    out = tmp_path / "run.csv"
    res = invoke("import", mine / "mine.tsv", "--map", COLUMNS, "-o", out)
    assert res.exit_code == 0, res.output
    run, sweep = read_run(out), read_run(SWEEP)
    for name in ("q1", "y1", "c1"):
        np.testing.assert_array_equal(run[name], sweep[name])
    assert "states no current unit" in res.stderr  # an import is told the current's unit, or warns
    res = invoke("import", mine / "mine.tsv", "--map", "t=time_s,q1=knob", "-o", tmp_path / "x.csv")
    assert "no column 'knob' for q1 (the file has time_s, knob_deg, tip_deg, current_mA)" in one_error(res)
    assert not (tmp_path / "x.csv").exists()


def test_every_command_that_reads_runs_takes_columns():
    for name in ("identify", "check", "detect-shift", "evaluate", "diagnose", "predict", "compensate", "simulate",
                 "play", "track"):
        assert "--columns" in invoke(name, "--help", terminal_width=200).stdout, name


# --------------------------------------------------------------------------------------------
# help
# --------------------------------------------------------------------------------------------
@pytest.mark.parametrize("width", [80, 200])
def test_help_groups_the_commands_with_whole_summaries(width, monkeypatch):
    monkeypatch.setenv("COLUMNS", str(width))
    text = invoke("--help", terminal_width=width).stdout
    assert "..." not in text.split("\n", 1)[1] and max(map(len, text.splitlines())) <= width
    titles = [ln[:-1] for ln in text.splitlines() if ln.endswith(":") and not ln.startswith(" ")]
    assert titles == ["Options", *HELP_PANELS]
    commands = {c.name: c for c in [*app.registered_commands, *app.registered_groups]}  # groups: hyst batch
    for title, names in HELP_PANELS.items():
        block = text.split(f"\n{title}:\n", 1)[1].split("\n\n", 1)[0].splitlines()
        assert [ln.split()[0] for ln in block] == list(names)
        for ln, name in zip(block, names):
            summary = commands[name].short_help
            assert len(summary) <= SUMMARY_WIDTH and ln.rstrip().endswith(summary), ln
    assert sorted(commands) == sorted(n for names in HELP_PANELS.values() for n in names)


def test_every_commands_help_fits_80_columns():
    for c in app.registered_commands:
        text = invoke(c.name, "--help", terminal_width=80).stdout
        assert max(map(len, text.splitlines())) <= 80, c.name
        assert "--knobs" not in text and "--replay" not in text, c.name  # old spellings work, unlisted


def test_home_and_jog_help_does_not_explain_the_inverse_models_jump():
    for name in ("home", "jog"):
        assert "dead zone" not in invoke(name, "--help", terminal_width=200).stdout
    assert "dead zone" in invoke("compensate", "--help", terminal_width=200).stdout


def test_format_choices_are_one_set():
    choices = set()
    for c in app.registered_commands:
        text = invoke(c.name, "--help", terminal_width=400).stdout
        m = re.search(r"--format <(table\|[a-z|]+)>", text)
        if m:
            choices.add(m.group(1))
    assert choices == {"table|json|csv|markdown|latex"}


# --------------------------------------------------------------------------------------------
# the data file positional, one --knob
# --------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def model(tmp_path_factory):
    d = tmp_path_factory.mktemp("model")
    assert invoke("identify", SWEEP, "-o", d / "model.json", "-q").exit_code == 0
    return d / "model.json"


def test_detect_shift_takes_the_replay_positionally_and_as_the_old_option(model, tmp_path):
    a, b = tmp_path / "a.json", tmp_path / "b.json"
    res = invoke("detect-shift", REPLAY, "--model", model, "-o", a, "-q")
    assert res.exit_code == 0, res.output
    res = invoke("detect-shift", "--model", model, "--replay", REPLAY, "-o", b, "-q")
    assert res.exit_code == 0, res.output
    assert a.read_bytes() == b.read_bytes()
    assert load_model(a).knob(1).offset == pytest.approx(26.5, abs=1.5)  # alpha = 90 on ice-a: 27.45 true
    assert "once" in one_error(invoke("detect-shift", REPLAY, "--replay", REPLAY, "--model", model, "-o",
                                      tmp_path / "c.json"), 2)
    assert "REPLAY.csv or --port" in one_error(invoke("detect-shift", "--model", model, "-o", tmp_path / "d.json"), 2)
    assert not (tmp_path / "c.json").exists()


def test_rotate_shift_and_simulate_take_their_file_positionally(model, tmp_path):
    a, b = tmp_path / "a.json", tmp_path / "b.json"
    assert invoke("rotate-shift", model, "--degrees", "30", "-o", a, "-q").exit_code == 0
    assert invoke("rotate-shift", "--model", model, "--degrees", "30", "-o", b, "-q").exit_code == 0
    assert a.read_bytes() == b.read_bytes()
    ref = tmp_path / "cmd.csv"
    write_run(ref, Run({"t": np.arange(0, 2, 0.01), "q1": 10 * np.sin(np.arange(0, 2, 0.01))}))
    ra, rb = tmp_path / "ra.csv", tmp_path / "rb.csv"
    assert invoke("simulate", ref, "-o", ra, "-q").exit_code == 0
    assert invoke("simulate", "--commands", ref, "-o", rb, "-q").exit_code == 0
    assert ra.read_bytes() == rb.read_bytes()


def test_knob_is_the_one_spelling_and_knobs_still_works(tmp_path):
    a, b = tmp_path / "a.csv", tmp_path / "b.csv"
    assert invoke("simulate", "--motion", "sweep", "--knob", "1,2", "--seed", "3", "-o", a, "-q").exit_code == 0
    assert invoke("simulate", "--motion", "sweep", "--knobs", "1,2", "--seed", "3", "-o", b, "-q").exit_code == 0
    assert a.read_bytes() == b.read_bytes() and read_run(a).knobs() == [1, 2]
    c = tmp_path / "c.csv"
    assert invoke("simulate", "--motion", "sweep", "--knob", "1", "--knob", "2", "--seed", "3", "-o", c,
                  "-q").exit_code == 0
    assert c.read_bytes() == a.read_bytes()
    assert "--knob" in one_error(invoke("simulate", "--knob", "3", "-o", tmp_path / "d.csv"), 2)


# --------------------------------------------------------------------------------------------
# identify without -o; the formats
# --------------------------------------------------------------------------------------------
def test_identify_without_output_prints_the_parameters_and_writes_nothing(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    res = invoke("identify", SWEEP)
    assert res.exit_code == 0, res.output
    lines = res.stdout.splitlines()
    assert lines[0].startswith("knob 1 (")
    assert [ln.split()[0] for ln in lines[1:8]] == ["d_pos", "d_neg", "b_pos", "b_neg", "omega", "h_pos", "h_neg"]
    assert "no model written: -o model.json keeps it" in res.stderr
    assert list(tmp_path.iterdir()) == []


def test_compensate_prints_any_table_format(model, tmp_path):
    out = tmp_path / "cmd.csv"
    ref = ROOT / "sample_data" / "reference_periodic.csv"
    res = invoke("compensate", ref, "--model", model, "-o", out, "--allow-fast", "--format", "csv")
    assert res.exit_code == 0, res.output
    header, row = res.stdout.splitlines()[:2]
    assert header == "knob,offset,q_min,q_max,peak_speed,peak_speed_t,peak_accel,peak_accel_t"
    commands = read_run(out)
    assert float(row.split(",")[2]) == pytest.approx(commands["q1"].min())
    assert "demo prints table, json, markdown, not latex" in one_error(
        invoke("demo", "--format", "latex", "--out", tmp_path / "o"), 2)


# --------------------------------------------------------------------------------------------
# smaller things
# --------------------------------------------------------------------------------------------
def _bent(tmp_path, name, seed):
    t = np.arange(0, 20, 0.02)
    rng = np.random.default_rng(seed)
    r = 30 * np.sin(2 * np.pi * 0.1 * t)
    run = Run({"t": t, "q1": r, "y1": r + rng.normal(0, 1, t.size), "r1": r},
              {"shape": "bent", "controller": "none", "motion": "periodic", "catheter": "mine"})
    write_run(tmp_path / name, run)
    return tmp_path / name


def test_a_shape_that_is_no_shape_is_the_same_error_naming_the_file(model, tmp_path):
    a, b = _bent(tmp_path, "a.csv", 1), _bent(tmp_path, "b.csv", 2)
    evaluate = one_error(invoke("evaluate", a, b))
    diagnose = one_error(invoke("diagnose", a, b, "--model", model, "-o", tmp_path / "r.json"))
    expected = (f"Error: {a}: metadata shape 'bent' is not a shape (bad shape segment 'bent': expected "
                "alpha=DEG[,theta=DEG]): write 'straight' or alpha=DEG,theta=DEG segments separated by ';'")
    assert evaluate == diagnose == expected
    assert not (tmp_path / "r.json").exists()


def test_show_gives_the_models_own_record_not_a_file_time(model):
    text = invoke("show", model).stdout.splitlines()[0]
    assert "source sweep_knob1.csv" in text and "source modified " in text and "created" not in text
    assert "source_modified" in load_model(model).meta and "created" not in load_model(model).meta


def test_user_facing_text_names_no_issue():
    texts = [invoke(c.name, "--help", terminal_width=400).stdout for c in app.registered_commands]
    assert not any(re.search(r"\(issue \d+\)", t) for t in texts)
    src = "\n".join(p.read_text() for p in (ROOT / "hystcli").rglob("*.py"))
    strings = re.findall(r"[\"'][^\"'\n]*issue \d+[^\"'\n]*[\"']", src)
    assert strings == []


@pytest.mark.slow
def test_demo_counts_its_steps_as_its_progress_does(tmp_path):
    res = invoke("demo", "--simulate", "--trials", "1", "--no-diagnose", "--no-figures", "--out", tmp_path / "o")
    assert res.exit_code == 0, res.output
    last = [ln for ln in res.stderr.splitlines() if ln.startswith("[")][-1]
    done, total = map(int, re.match(r"\[(\d+)/(\d+)\]", last).groups())
    steps = re.search(r"demo took [0-9.]+ s \((\d+) steps: (.*)\)", res.stderr)
    assert done == total == int(steps.group(1))
    kinds = dict((w, int(n)) for n, w in (part.split(" ", 1) for part in steps.group(2).split(", ")))
    assert sum(kinds.values()) == total and kinds["identifications"] == 2


def test_tables_fit_100_columns(tmp_path):
    runs = []
    for i, (ctrl, shape) in enumerate([("none", "alpha=45,theta=0;alpha=45,theta=90"), ("comp", "alpha=90"),
                                       ("comp+shift", "alpha=90")]):
        t = np.arange(0, 10, 0.02)
        r = 30 * np.sin(t)
        run = Run({"t": t, "q1": r, "y1": r + 0.1 * i * np.cos(t), "r1": r},
                  {"controller": ctrl, "shape": shape, "motion": "periodic"})
        runs.append(tmp_path / f"r{i}.csv")
        write_run(runs[-1], run)
    res = invoke("evaluate", *runs)
    assert res.exit_code == 0, res.output
    assert max(map(len, res.stdout.splitlines())) <= 100
    assert "RMSE vs comp %" in res.stdout  # nothing cut: the wide table comes in slices
    header_lines = [ln for ln in res.stdout.splitlines() if ln.startswith("controller")]
    assert len(header_lines) >= 2 and all("shape" in ln and "motion" in ln for ln in header_lines)
