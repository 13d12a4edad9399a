"""`hyst check`: every problem of a run CSV at once, before a command trips on the first.

This module owns the checks; the command line only renders them. :func:`check_file` reads a file
leniently (a bad cell becomes NaN and a problem, never an exception) and returns a
:class:`CheckReport`: a list of :class:`Problem` records, each one line, ``error`` (a command would
refuse the file or read a wrong number from it) or ``warning`` (it would run, on data that likely
cannot give what it is for). :func:`check_run` runs the physical checks on a run already read.

The physical checks read the data as identify does (:mod:`hystcli.signal`):

- time: non-increasing steps (error); sample-rate jitter, the standard deviation of the time
  steps over their median, and gaps longer than :data:`hystcli.io.importer.IRREGULAR` median steps
  (warning beyond :data:`MAX_JITTER`);
- a tip that never moves: the tip's robust range (1st to 99th percentile) under
  :data:`MIN_SIGNAL_TO_NOISE` times its noise, the noise estimated from second differences
  (:func:`noise`), which a smooth motion hardly enters;
- a knob that never reverses: no reversal (:func:`hystcli.signal.stretches.find_reversals`);
- a current that never goes below its no-load level: it dips inside the swept range and rises
  from there both ways (:func:`hystcli.signal.reading.detect_sign`). A signed motor current falls
  below its no-load level once the knob takes up the other tendon (past the negative dead-zone
  edge); one that rises on both sides is a magnitude ``|I|``. A warning when the sign is left to
  identify (``auto``, which reads it so), an error when the user says the current is signed;
- a sweep that never passes an edge: on no monotone stretch of the knob does a continuous broken
  line of two pieces beat one line by BIC (:func:`hystcli.signal.pwl.fit_piecewise`, which counts
  the residuals' autocorrelation): the current's slope never changes along the knob, so no
  dead-zone edge can be read from it;
- units that look wrong: a knob whose moving speed is under :data:`MIN_KNOB_SPEED` deg/s (a time
  column in milliseconds read as seconds turns a 40 deg/s sweep into 0.04 deg/s), or a motor current
  whose whole range is under :data:`MIN_CURRENT_RANGE` mA (a current in amperes read as mA).

The core never imports typer or rich; nothing here writes.
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from ..core.run import Run
from ..errors import DataError, HystError
from ..settings import CURRENT_SIGNS
from .runs import KNOWN_COLUMNS, MAX_ABS_VALUE, _parse_meta_line as _meta_line

ERROR = "error"
WARNING = "warning"
LEVELS = (ERROR, WARNING)

MIN_ROWS = 10
"""Fewer data rows than this is no run."""

MAX_JITTER = 0.05
"""Largest sample-rate jitter (std of the time steps over their median) without a warning: the
filters and the slope estimates assume a uniform rate; 5 % moves a 100 Hz cut-off by 5 Hz."""

MIN_SIGNAL_TO_NOISE = 10.0
"""A signal whose robust range is under this many noise standard deviations does not move: pure
noise spans about 5 of them over a thousand samples, a swept tip hundreds."""

MIN_STRETCH_POINTS = 30
"""A monotone stretch with fewer samples is too short to test for a slope change."""

EDGE_TEST_POINTS = 2000
"""Most samples of one monotone stretch the slope-change fit reads (evenly spaced; the fit counts
the residuals' autocorrelation, so thinning costs precision, not honesty)."""


#: deg/s. The slowest knob speed taken at face value: catheter sweeps run at 1-360 deg/s (the
#: paper's at 40 deg/s); a knob that moves slower than this is most likely timed in ms, not s.
MIN_KNOB_SPEED = 0.5
#: mA. The smallest range of a motor current taken at face value: a tendon drive's current moves
#: by tens of mA between slack and loaded; a smaller range is most likely a current in A.
MIN_CURRENT_RANGE = 1.0


@dataclass(frozen=True)
class Problem:
    """One problem of one file, as one line.

    Attributes
    ----------
    level : {"error", "warning"}
        ``error``: a command would refuse the file or read a wrong number from it; ``warning``:
        it would run, on data that likely cannot give what it is for.
    where : str
        The column (``t``, ``q1`` ...), ``file``, ``header`` or ``meta:KEY``.
    message : str
        What is wrong, with the figures and what to do.
    """

    level: str
    where: str
    message: str

    def __post_init__(self) -> None:
        if self.level not in LEVELS:
            raise ValueError(f"level must be one of {', '.join(LEVELS)}, got {self.level!r}")

    def to_dict(self) -> dict:
        """JSON-ready form."""
        return {"level": self.level, "where": self.where, "message": self.message}


@dataclass(frozen=True)
class CheckReport:
    """What :func:`check_file` found in one file.

    Attributes
    ----------
    source : str
        The file as given.
    problems : tuple of Problem
        Errors and warnings, in the order the checks ran (file, header, cells, time, knobs).
    rows : int
        Data rows read (0 when the file could not be split into rows).
    columns : tuple of str
        The run columns found (after any mapping).
    rate : float or None
        Median sample rate, Hz.
    jitter : float or None
        Standard deviation of the time steps over their median.
    """

    source: str
    problems: tuple[Problem, ...]
    rows: int = 0
    columns: tuple[str, ...] = ()
    rate: float | None = None
    jitter: float | None = None

    @property
    def errors(self) -> tuple[Problem, ...]:
        """The error-level problems."""
        return tuple(p for p in self.problems if p.level == ERROR)

    @property
    def ok(self) -> bool:
        """No error-level problem (warnings allowed)."""
        return not self.errors

    def to_dict(self) -> dict:
        """JSON-ready form."""
        return {"file": self.source, "ok": self.ok, "rows": self.rows, "columns": list(self.columns),
                "rate_hz": self.rate, "jitter": self.jitter,
                "problems": [p.to_dict() for p in self.problems]}


# --------------------------------------------------------------------------------------------
# statistics the checks use
# --------------------------------------------------------------------------------------------
def noise(x: np.ndarray) -> float:
    """Standard deviation of white noise on ``x``, from its second differences.

    The robust scale (:func:`hystcli.signal.pwl.robust_scale`) of ``x[i+1] - 2 x[i] + x[i-1]``,
    whose variance is 6 sigma^2 for white noise: a smooth motion adds little to second
    differences, outliers nothing.
    """
    from ..signal.pwl import robust_scale

    return robust_scale(np.diff(np.asarray(x, dtype=float), 2)) / math.sqrt(6.0)


def robust_range(x: np.ndarray) -> float:
    """The 1st to 99th percentile span of ``x`` (a spike or two does not make a signal move)."""
    lo, hi = np.percentile(x, [1.0, 99.0])
    return float(hi - lo)


def _stride(n: int, most: int) -> int:
    return max(1, int(math.ceil(n / most)))


def passes_an_edge(q: np.ndarray, c: np.ndarray) -> tuple[bool, int]:
    """Whether the current's slope changes along the knob on some monotone stretch, and how many
    stretches were long enough to tell (:data:`MIN_STRETCH_POINTS`).

    Each stretch is read as identify reads it: against the knob angle along the motion, a
    continuous broken line of one or two pieces, chosen by BIC.
    """
    from ..signal.pwl import fit_piecewise
    from ..signal.stretches import monotone_stretches

    tested = 0
    for a, b, direction in monotone_stretches(q):
        if b - a < MIN_STRETCH_POINTS:
            continue
        tested += 1
        x, y = direction * q[a:b + 1], c[a:b + 1]
        order = np.argsort(x, kind="stable")[::_stride(b + 1 - a, EDGE_TEST_POINTS)]
        if fit_piecewise(x[order], y[order], max_pieces=2).knots:
            return True, tested
    return False, tested


# --------------------------------------------------------------------------------------------
# the checks
# --------------------------------------------------------------------------------------------
def _time_problems(t: np.ndarray, linenos: np.ndarray) -> tuple[list[Problem], float | None, float | None]:
    """Non-increasing steps, jitter and gaps of a time column (finite values only)."""
    from .importer import IRREGULAR

    out: list[Problem] = []
    ok = np.isfinite(t)
    t, lines = t[ok], linenos[ok]
    if t.size < 2:
        return out, None, None
    dt = np.diff(t)
    back = np.flatnonzero(~(dt > 0))
    if back.size:
        j = int(back[0]) + 1
        out.append(Problem(ERROR, "t", f"{back.size} time step(s) do not increase, the first at line {lines[j]} "
                                       f"({float(t[j - 1])!r} then {float(t[j])!r})"))
    steps = dt[dt > 0]
    if steps.size < 2:
        return out, None, None
    med = float(np.median(steps))
    jitter = float(np.std(steps) / med)
    gaps = int(np.count_nonzero(steps > IRREGULAR * med))
    if jitter > MAX_JITTER or gaps:
        out.append(Problem(WARNING, "t", f"sample rate {1 / med:.4g} Hz with {100 * jitter:.1f} % jitter (std of the "
                                         f"time steps over their median; steps {steps.min():.4g} .. "
                                         f"{steps.max():.4g} s" + (f", {gaps} gap(s) over {IRREGULAR:g} steps"
                                                                     if gaps else "")
                                         + "): hyst import --resample HZ puts it on a uniform grid"))
    return out, 1.0 / med, jitter


def _knob_problems(cols: Mapping[str, np.ndarray], k: int, current_sign: str) -> list[Problem]:
    """The physical checks of knob ``k`` (its angle moves)."""
    from ..signal.reading import detect_sign
    from ..signal.stretches import find_reversals

    out: list[Problem] = []
    q_name, y_name, c_name = f"q{k}", f"y{k}", f"c{k}"
    q_all = cols[q_name]
    ok = np.isfinite(q_all)
    q = q_all[ok]
    span = robust_range(q)
    if find_reversals(q)[0].size == 0:
        out.append(Problem(WARNING, q_name, f"knob {k} never reverses (one way, {float(q[0]):+.1f} to "
                                            f"{float(q[-1]):+.1f} deg): identify needs it to go back and forth "
                                            "to see the backlash (a detect-shift replay need not)"))
    if y_name in cols:
        y = cols[y_name][ok & np.isfinite(cols[y_name])]
        if y.size >= MIN_ROWS:
            sigma, rng = noise(y), robust_range(y)
            if not rng > MIN_SIGNAL_TO_NOISE * sigma:
                versus = "no more than its noise" if sigma == 0 else f"{rng / sigma:.1f} x its noise {sigma:.2g} deg"
                out.append(Problem(WARNING, y_name, f"the tip never moves: its range {rng:.3g} deg is {versus} "
                                                    f"while knob {k} spans {span:.3g} deg (a tip sensor not "
                                                    "connected?); identify --current-only ignores the tip"))
    if c_name not in cols:
        out.append(Problem(WARNING, c_name, f"no motor current {c_name} for knob {k}: detect-shift and identify "
                                            "--current-only read the dead-zone edges from it"))
        return out
    both = ok & np.isfinite(cols[c_name])
    q, c = q_all[both], cols[c_name][both]
    if q.size < MIN_ROWS:
        return out
    if current_sign != "magnitude" and detect_sign(q, c, np.sign(np.gradient(q)))[0] == "magnitude":
        said = ("you said it is signed: it is not, and identify --current-sign signed would read the "
                "negative tendon's take-up as the positive one's" if current_sign == "signed" else
                "identify reads it so (--current-sign auto); --current-sign magnitude is the option for such "
                "drives")
        out.append(Problem(ERROR if current_sign == "signed" else WARNING, c_name,
                           "the current never goes below its no-load level: it dips inside the swept range and "
                           "rises from there both ways, as a magnitude |I| does (a signed current falls below "
                           f"it past the negative edge); {said}"))
    passes, tested = passes_an_edge(q, c)
    if tested and not passes:
        out.append(Problem(WARNING, c_name, f"the sweep never passes a dead-zone edge: the current's slope does "
                                            f"not change along knob {k} on any of {tested} one-way stretch(es) "
                                            "(a broken line of two pieces never beats one line by BIC): sweep "
                                            "further, or the current does not follow the tendons"))
    return out


def _meta_problems(meta: Mapping[str, str]) -> list[Problem]:
    from ..core.params import Shape

    shape = meta.get("shape")
    if shape is None or not str(shape).strip():
        return []
    try:
        Shape.parse(shape)
    except HystError as exc:
        return [Problem(ERROR, "meta:shape", shape_message(shape, exc))]
    return []


def shape_message(shape: str, exc: BaseException) -> str:
    """The message for a ``shape`` metadata value that is no shape (one for every command)."""
    return (f"metadata shape {shape!r} is not a shape ({str(exc).splitlines()[0]}): write 'straight' or "
            "alpha=DEG,theta=DEG segments separated by ';'")


def require_shape(run: Run) -> Run:
    """Raise :class:`DataError` naming the run's file when its ``shape`` metadata is no shape.

    Commands that only group by the shape (evaluate) and those that compute with it (diagnose)
    refuse the same value with the same message.
    """
    problems = _meta_problems(run.meta)
    if problems:
        raise DataError(f"{run.source or '<run>'}: {problems[0].message}")
    return run


def check_run(run: Run, current_sign: str = "auto") -> tuple[Problem, ...]:
    """The metadata, time and physical checks of a run already read (see the module docstring);
    a line number in a message counts data rows from 1."""
    time = _time_problems(run.t, np.arange(1, len(run) + 1))[0] if "t" in run else []
    return tuple(_ordered(_meta_problems(run.meta) + time + _physical(run.columns, current_sign)))


def _physical(cols: Mapping[str, np.ndarray], current_sign: str) -> list[Problem]:
    """The knobs' checks: whether one moves, then each moving one's (:func:`_knob_problems`)."""
    if current_sign not in CURRENT_SIGNS:
        raise DataError(f"current sign must be one of {', '.join(CURRENT_SIGNS)}, got {current_sign!r}")
    out = []
    knobs = [k for k in (1, 2) if f"q{k}" in cols]
    moving = [k for k in knobs if np.isfinite(cols[f"q{k}"]).sum() >= MIN_ROWS
              and robust_range(cols[f"q{k}"][np.isfinite(cols[f"q{k}"])]) > 0]
    if knobs and not moving:
        out.append(Problem(ERROR, "/".join(f"q{k}" for k in knobs),
                           "no knob moves: there is nothing to identify or detect"))
    for k in moving:
        out += _knob_problems(cols, k, current_sign) + _unit_problems(cols, k)
    return out


def _unit_problems(cols: Mapping[str, np.ndarray], k: int) -> list[Problem]:
    """A knob speed or a current range too small for the units a run CSV uses (s, mA)."""
    out = []
    q = cols[f"q{k}"]
    if "t" in cols:
        ok = np.isfinite(q) & np.isfinite(cols["t"])
        if ok.sum() >= MIN_ROWS:
            t, qk = cols["t"][ok], q[ok]
            dt = np.diff(t)
            good = dt > 0
            speed = np.abs(np.diff(qk)[good] / dt[good])
            moving = speed[speed > 0]
            if moving.size and float(np.median(moving)) < MIN_KNOB_SPEED:
                out.append(Problem(WARNING, "t", f"knob {k} moves at {float(np.median(moving)):.3g} deg/s (median "
                                                 f"while moving), slower than any sweep: is t in milliseconds? "
                                                 "name its unit, e.g. --columns t=time_ms:ms"))
    c_name = f"c{k}"
    if c_name in cols:
        c = cols[c_name][np.isfinite(cols[c_name])]
        if c.size >= MIN_ROWS and float(np.ptp(c)) < MIN_CURRENT_RANGE:
            out.append(Problem(WARNING, c_name, f"the motor current spans only {float(np.ptp(c)):.3g} mA: is it in "
                                                f"amperes? name its unit, e.g. --columns {c_name}=current:A"))
    return out


def _cells(cells: Sequence[str]) -> tuple[np.ndarray, np.ndarray]:
    """Values (NaN where a cell is no number) and where a cell is text rather than a number or an
    empty/NaN cell."""
    try:
        values = np.array(cells, dtype=np.float64)
        return values, np.zeros(values.size, bool)
    except ValueError:
        pass
    values = np.full(len(cells), np.nan)
    text = np.zeros(len(cells), bool)
    for j, cell in enumerate(cells):
        try:
            values[j] = float(cell)
        except ValueError:
            text[j] = bool(cell.strip())
    return values, text


def _cell_problems(name: str, cells: Sequence[str], values: np.ndarray, text: np.ndarray,
                   linenos: np.ndarray) -> list[Problem]:
    out = []
    checks = ((text, "cell(s) are not numbers", True),
              (np.isnan(values) & ~text, "missing value(s) (empty or NaN)", False),
              (np.isinf(values), "infinite value(s)", True),
              (np.isfinite(values) & (np.abs(values) > MAX_ABS_VALUE),
               f"value(s) beyond +-{MAX_ABS_VALUE:g}, not a plausible angle, current or time", True))
    for mask, what, quote in checks:
        if mask.any():
            j = int(np.flatnonzero(mask)[0])
            shown = f" ({cells[j].strip()!r})" if quote else ""
            out.append(Problem(ERROR, name, f"{int(mask.sum())} {what}, the first at line {linenos[j]}{shown}"))
    return out


def _read_text(path: Path) -> tuple[str | None, list[Problem]]:
    if not path.exists():
        return None, [Problem(ERROR, "file", "no such file")]
    if path.is_dir():
        return None, [Problem(ERROR, "file", "is a directory, not a run CSV")]
    try:
        raw = path.read_bytes()
    except OSError as exc:
        return None, [Problem(ERROR, "file", f"cannot read ({exc.strerror})")]
    out = []
    if raw.startswith(b"\xef\xbb\xbf"):
        out.append(Problem(WARNING, "file", "the file starts with a byte-order mark (Excel's UTF-8): hyst "
                                            "reads it, some other tools take it for part of the first name"))
    if b"\x00" in raw:
        return None, out + [Problem(ERROR, "file", "binary data (NUL bytes), not a text CSV")]
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        return None, out + [Problem(ERROR, "file", "not a text CSV file (not UTF-8)")]
    if not text.strip():
        return None, out + [Problem(ERROR, "file", "empty file")]
    return text, out


def check_file(path: str | os.PathLike, columns: object = None, current_sign: str = "auto") -> CheckReport:
    """Every problem of one run CSV, or of a user's own CSV read through ``columns``.

    Parameters
    ----------
    path : path-like
    columns : hystcli.io.importer.ImportMapping, optional
        A ``--columns`` mapping (:func:`hystcli.io.importer.columns_mapping`): the file may then use
        any separator and its own column names and units. Without one the file must be a run CSV:
        comma-separated, ``# key: value`` metadata lines, a header row of run column names.
    current_sign : {"auto", "signed", "magnitude"}
        What the user says of the current (:data:`hystcli.settings.CURRENT_SIGNS`): a magnitude
        found is a warning under ``auto``, an error under ``signed``, and not looked for under
        ``magnitude``.

    Returns
    -------
    CheckReport
        Never raises for a bad file: everything wrong is a :class:`Problem`.
    """
    from . import importer

    source = str(path)
    text, problems = _read_text(Path(path))
    if text is None:
        return CheckReport(source, tuple(problems))
    mapping = columns
    try:
        layout = importer.split_table(text, importer.AUTO, "#" if mapping is None else importer.AUTO,
                                      0, None, source)
    except DataError as exc:
        return CheckReport(source, tuple(problems + [Problem(ERROR, "file", _strip(str(exc), source))]))
    meta = dict(kv for kv in map(_meta_line, layout.header) if kv is not None)
    names = list(layout.names or ())
    if mapping is None and layout.names is None:
        problems.append(Problem(ERROR, "header", f"no header row: line {layout.linenos[0]} is numbers; a run CSV "
                                                 "names its columns first (t,q1,y1,c1), or read it with --columns "
                                                 "t=1,q1=2,... (numbers count from 1)"))
        return CheckReport(source, tuple(problems), len(layout.rows))
    if mapping is None:
        if layout.separator != ",":
            problems.append(Problem(ERROR, "file", f"the columns are separated by {_sep_words(layout.separator)}, "
                                                   "not commas: read it with --columns (any separator), or "
                                                   "convert it with hyst import"))
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup:
            problems.append(Problem(ERROR, "header", f"column {dup[0]!r} appears twice in the header"))
        if "" in names:
            problems.append(Problem(ERROR, "header", "the header row has an empty column name"))
        wanted = [(n, j) for j, n in enumerate(names) if n in KNOWN_COLUMNS]
        targets = [n for n, _ in wanted]
    else:
        try:
            resolved = importer.resolve_columns(mapping.columns, layout, source, as_run=True)
        except DataError as exc:
            return CheckReport(source, tuple(problems + [Problem(ERROR, "header", _strip(str(exc), source))]),
                               len(layout.rows))
        wanted = [(c.target, j) for c, j in resolved]
        targets = [c.target for c, _ in resolved]
        factors = {c.target: (c.factor, c.offset) for c, _ in resolved}
    problems += _missing_columns(targets, names, mapping is not None)
    linenos = np.array(layout.linenos)
    width = len(names) if mapping is None else max([j for _, j in wanted], default=-1) + 1
    short = [i for i, row in enumerate(layout.rows) if len(row) != width and (mapping is None or len(row) < width)]
    if short:
        problems.append(Problem(ERROR, "file", f"{len(short)} line(s) have a number of fields other than the "
                                               f"header's {width}, the first line {linenos[short[0]]} "
                                               f"({len(layout.rows[short[0]])} fields)"))
    keep = np.ones(len(layout.rows), bool)
    keep[short] = False
    rows = [row for row, k in zip(layout.rows, keep) if k]
    linenos = linenos[keep]
    cols: dict[str, np.ndarray] = {}
    for name, j in wanted:
        cells = [row[j] for row in rows]
        values, text_cells = _cells(cells)
        problems += _cell_problems(name, cells, values, text_cells, linenos)
        if mapping is not None:
            factor, offset = factors[name]
            values = values * factor + offset
        cols[name] = values
    if len(rows) < MIN_ROWS:
        problems.append(Problem(ERROR, "file", f"only {len(rows)} data row(s): a run needs at least {MIN_ROWS}"))
        return CheckReport(source, tuple(problems), len(rows), tuple(cols))
    time_problems, rate, jitter = (_time_problems(cols["t"], linenos) if "t" in cols else ([], None, None))
    problems += _meta_problems(meta) + time_problems + _physical(cols, current_sign)
    return CheckReport(source, tuple(_ordered(problems)), len(rows), tuple(cols), rate, jitter)


def _ordered(problems: list[Problem]) -> list[Problem]:
    """File and header problems first, then per column in the run's order (stable)."""
    order = {name: i for i, name in enumerate(("file", "header", "meta:shape") + KNOWN_COLUMNS)}
    return sorted(problems, key=lambda p: order.get(p.where, len(order)))


def _missing_columns(targets: Sequence[str], names: Sequence[str], mapped: bool) -> list[Problem]:
    from .importer import suggest_columns

    out = []
    if "t" not in targets:
        guess = suggest_columns(names) if not mapped else None
        hint = (f"; name yours with --columns {guess}" if guess else
                "; map it with --columns t=NAME" if mapped else
                "; name yours with --columns t=NAME,q1=NAME,y1=NAME,c1=NAME")
        out.append(Problem(ERROR, "header", f"no time column t (the file has {', '.join(names) or 'no header row'})"
                                            + hint))
    if not any(n in targets for n in ("q1", "q2", "r1", "r2")):
        out.append(Problem(ERROR, "header", f"no knob angle q1 or q2, nor a reference r1 or r2 (columns found: "
                                            f"{', '.join(targets) or 'none'})"))
    for k in (1, 2):
        if f"q{k}" in targets and f"y{k}" not in targets and f"c{k}" not in targets:
            out.append(Problem(ERROR, "header", f"knob {k} has neither a tip angle y{k} nor a current c{k}: "
                                                "nothing to identify it from"))
    return out


def _sep_words(sep: str | None) -> str:
    return {None: "spaces", "\t": "tabs", ";": "semicolons"}.get(sep, repr(sep))


def _strip(message: str, source: str) -> str:
    """A core error's message without the file name the report already carries."""
    prefix = f"{source}: "
    return message[len(prefix):] if message.startswith(prefix) else message


__all__ = ["CheckReport", "ERROR", "LEVELS", "Problem", "WARNING", "check_file", "check_run", "noise",
           "passes_an_edge", "require_shape", "robust_range", "shape_message"]
