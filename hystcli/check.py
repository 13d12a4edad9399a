"""`hyst check`: every problem of a run CSV at once, before a command trips on the first.

This module owns the checks; the command line only renders them. :func:`check_file` reads a file
leniently (a bad cell becomes NaN and a problem, never an exception) and returns a
:class:`CheckReport`: a list of :class:`Problem` records, each one line, ``error`` (a command would
refuse the file or read a wrong number from it) or ``warning`` (it would run, on data that likely
cannot give what it is for). :func:`check_run` runs the physical checks on a run already read.

The physical checks and the figures they use:

- time: non-increasing steps (error); sample-rate jitter, the standard deviation of the time
  steps over their median, and gaps longer than :data:`hystcli.importer.IRREGULAR` median steps
  (warning beyond :data:`MAX_JITTER`);
- a tip that never moves: the tip's robust range (1st to 99th percentile) under
  :data:`MIN_SIGNAL_TO_NOISE` times its noise, the noise estimated from second differences
  (:func:`noise`), which a smooth motion hardly enters;
- a knob that never reverses: no turning point (:func:`turning_points`) in its angle;
- a current that never goes below its no-load level: the current's median per knob-angle bin is
  lowest inside the travel and rises toward both ends (:func:`magnitude_only`). A signed motor
  current falls below its no-load level once the knob takes up the other tendon (past the
  negative dead-zone edge); one that rises on both sides is a magnitude ``|I|``;
- a sweep that never passes an edge: on no monotone stretch of the knob does a two-piece line
  (a hinge at the best of the stretch's inner quantiles) beat one line by :data:`MIN_DELTA_BIC`
  in BIC (:func:`slope_change`): the current's slope never changes along the knob, so no
  dead-zone edge can be read from it.

The core never imports typer or rich; nothing here writes.
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from .errors import DataError, HystError
from .io import KNOWN_COLUMNS, MAX_ABS_VALUE, Run
from .io import _parse_meta_line as _meta_line

ERROR = "error"
WARNING = "warning"
LEVELS = (ERROR, WARNING)

CURRENT_SIGNS = ("signed", "magnitude")
"""How a drive reports its motor current: signed (below the no-load level for the other tendon)
or its magnitude only."""

MIN_ROWS = 10
"""Fewer data rows than this is no run."""

MAX_JITTER = 0.05
"""Largest sample-rate jitter (std of the time steps over their median) without a warning: the
filters and the slope estimates assume a uniform rate; 5 % moves a 100 Hz cut-off by 5 Hz."""

MIN_SIGNAL_TO_NOISE = 10.0
"""A signal whose robust range is under this many noise standard deviations does not move: pure
noise spans about 5 of them over a thousand samples, a swept tip hundreds."""

MIN_DELTA_BIC = 10.0
"""BIC gain of the two-piece line over one line that shows a slope change: 10 is "very strong"
evidence on Kass and Raftery's scale, which autocorrelated noise (a filtered current) inflates;
stretches are thinned to :data:`EDGE_TEST_POINTS` samples for that reason."""

EDGE_TEST_POINTS = 200
"""Samples of one monotone stretch the slope-change test uses (evenly spaced): enough to see an
edge, few enough that neighbouring samples' correlated noise does not pass for one."""

MIN_STRETCH_POINTS = 30
"""A monotone stretch with fewer samples is too short to test for a slope change."""

MAGNITUDE_BINS = 20
"""Knob-angle bins of the current's median profile in :func:`magnitude_only`."""

MAGNITUDE_RISE = 0.25
"""Each end of the profile must rise above its lowest bin by this fraction of its span."""


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

    The median absolute deviation of ``x[i+1] - 2 x[i] + x[i-1]`` (variance 6 sigma^2 for white
    noise) over 0.6745: a smooth motion adds little to second differences, outliers nothing.
    """
    d2 = np.diff(np.asarray(x, dtype=float), 2)
    if d2.size == 0:
        return 0.0
    return float(np.median(np.abs(d2 - np.median(d2))) / 0.6745 / math.sqrt(6.0))


def robust_range(x: np.ndarray) -> float:
    """The 1st to 99th percentile span of ``x`` (a spike or two does not make a signal move)."""
    lo, hi = np.percentile(x, [1.0, 99.0])
    return float(hi - lo)


def turning_points(q: np.ndarray, band: float) -> list[int]:
    """Indices where ``q`` turns back by more than ``band`` (a zigzag filter).

    A turn counts once ``q`` has come back ``band`` from its last extreme, so noise and dither
    smaller than ``band`` are no reversal. Returns the indices of the extremes, in order.
    """
    turns: list[int] = []
    lo = hi = float(q[0])
    direction, ext_i, ext = 0, 0, lo
    for i, x in enumerate(map(float, q)):
        if direction == 0:  # no way yet: the first move beyond the band sets it
            lo, hi = min(lo, x), max(hi, x)
            if x - lo > band or hi - x > band:
                direction, ext_i, ext = (1 if x - lo > band else -1), i, x
        elif (x - ext) * direction > 0:
            ext_i, ext = i, x
        elif abs(x - ext) > band:
            turns.append(ext_i)
            direction, ext_i, ext = -direction, i, x
    return turns


def _stride(n: int, most: int) -> int:
    return max(1, int(math.ceil(n / most)))


def slope_change(q: np.ndarray, c: np.ndarray) -> float:
    """BIC gain of a two-piece line (a hinge) over one line for ``c`` against ``q``.

    One line has 2 parameters; the hinge ``a + b q + g max(0, q - k)`` has 4 (its knot ``k`` the
    best of the 10th to 90th percentiles of ``q``). Gain = BIC(one) - BIC(hinge), BIC = n ln(RSS /
    n) + p ln n: positive when the slope change explains more than its two parameters cost.
    """
    q = np.asarray(q, dtype=float)
    c = np.asarray(c, dtype=float)
    n = q.size
    one = np.column_stack([np.ones(n), q])

    def rss(design: np.ndarray) -> float:
        coef, *_ = np.linalg.lstsq(design, c, rcond=None)
        r = c - design @ coef
        return max(float(r @ r), 1e-300)

    rss1 = rss(one)
    best = min(rss(np.column_stack([one, np.maximum(q - k, 0.0)]))
               for k in np.unique(np.percentile(q, np.linspace(10, 90, 33))))
    return (n * math.log(rss1 / n) + 2 * math.log(n)) - (n * math.log(best / n) + 4 * math.log(n))


def magnitude_only(q: np.ndarray, c: np.ndarray) -> dict | None:
    """Signs of a magnitude-only current: its median per knob-angle bin is lowest inside the
    travel and rises toward both ends, each by :data:`MAGNITUDE_RISE` of the profile's span.

    Returns the figures (``level`` and ``q_at`` of the lowest bin, ``left``/``right`` and
    ``q_left``/``q_right`` of the end bins), or None when the current does not look so (or the
    knob covers too little to tell). The span must exceed :data:`MIN_SIGNAL_TO_NOISE` noise
    standard deviations: a flat, noisy current is no V.
    """
    lo, hi = np.percentile(q, [1.0, 99.0])
    if not hi > lo:
        return None
    edges = np.linspace(lo, hi, MAGNITUDE_BINS + 1)
    idx = np.clip(np.searchsorted(edges, q, side="right") - 1, 0, MAGNITUDE_BINS - 1)
    med = np.full(MAGNITUDE_BINS, np.nan)
    for b in range(MAGNITUDE_BINS):
        sel = c[idx == b]
        if sel.size >= 5:
            med[b] = np.median(sel)
    filled = np.flatnonzero(np.isfinite(med))
    if filled.size < MAGNITUDE_BINS // 2:
        return None
    centres = 0.5 * (edges[:-1] + edges[1:])
    first, last = filled[0], filled[-1]
    low = int(filled[np.argmin(med[filled])])
    span = float(np.nanmax(med) - med[low])
    inner = first + 2 < low < last - 2
    rises = min(med[first], med[last]) - med[low]
    if not (inner and span > MIN_SIGNAL_TO_NOISE * noise(c) and rises > MAGNITUDE_RISE * span):
        return None
    return {"level": float(med[low]), "q_at": float(centres[low]), "left": float(med[first]),
            "q_left": float(centres[first]), "right": float(med[last]), "q_right": float(centres[last])}


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
    out: list[Problem] = []
    q_name, y_name, c_name = f"q{k}", f"y{k}", f"c{k}"
    q_all = cols[q_name]
    ok = np.isfinite(q_all)
    q = q_all[ok]
    span = robust_range(q)
    stride = _stride(q.size, 20000)  # reversals are slow events: a thinned angle shows them all
    band = max(MIN_SIGNAL_TO_NOISE * noise(q), 0.01 * span)
    turns = [i * stride for i in turning_points(q[::stride], band)]
    if not turns:
        out.append(Problem(WARNING, q_name, f"knob {k} never reverses (one way, {float(q[0]):+.1f} to "
                                            f"{float(q[-1]):+.1f} deg): identify needs it to go back and forth "
                                            "to see the backlash (a detect-shift replay need not)"))
    if y_name in cols:
        y = cols[y_name][ok & np.isfinite(cols[y_name])]
        if y.size >= MIN_ROWS:
            sigma, rng = noise(y), robust_range(y)
            if not rng > MIN_SIGNAL_TO_NOISE * sigma:
                out.append(Problem(WARNING, y_name, f"the tip never moves: its range {rng:.3g} deg is "
                                                    f"{'no more than its noise' if sigma == 0 else f'{rng / sigma:.1f} x its noise {sigma:.2g} deg'}"
                                                    f" while knob {k} spans {span:.3g} deg (a tip sensor not "
                                                    "connected?); identify --current-only ignores the tip"))
    if c_name not in cols:
        out.append(Problem(WARNING, c_name, f"no motor current {c_name} for knob {k}: detect-shift and identify "
                                            "--current-only read the dead-zone edges from it"))
        return out
    both = ok & np.isfinite(cols[c_name])
    q, c = q_all[both], cols[c_name][both]
    if q.size < MIN_ROWS:
        return out
    if current_sign == "signed":
        v = magnitude_only(q, c)
        if v is not None:
            out.append(Problem(ERROR, c_name, f"the current never goes below its no-load level: lowest "
                                              f"({v['level']:.4g} mA) at q{k} ~ {v['q_at']:+.1f} deg, rising to "
                                              f"{v['left']:.4g} mA at {v['q_left']:+.1f} deg and {v['right']:.4g} mA "
                                              f"at {v['q_right']:+.1f} deg. A signed current falls below it past "
                                              "the negative edge: this drive reports |I|, and --current-sign "
                                              "magnitude is the option for such drives"))
    bounds = [0] + [t for t in turns if 0 < t < q.size] + [q.size]
    gains = []
    for a, b in zip(bounds[:-1], bounds[1:]):
        if b - a >= MIN_STRETCH_POINTS:
            s = _stride(b - a, EDGE_TEST_POINTS)
            gains.append(slope_change(q[a:b:s], c[a:b:s]))
    if gains and max(gains) < MIN_DELTA_BIC:
        out.append(Problem(WARNING, c_name, f"the sweep never passes a dead-zone edge: the current's slope does "
                                            f"not change along knob {k} on any of {len(gains)} one-way stretch(es) "
                                            f"(best BIC gain of a two-piece line {max(gains):.1f} < "
                                            f"{MIN_DELTA_BIC:g}): sweep further, or the current does not follow "
                                            "the tendons"))
    return out


def _meta_problems(meta: Mapping[str, str]) -> list[Problem]:
    from .model import Shape

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


def check_run(run: Run, current_sign: str = "signed") -> tuple[Problem, ...]:
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
        out += _knob_problems(cols, k, current_sign)
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


def check_file(path: str | os.PathLike, columns: object = None, current_sign: str = "signed") -> CheckReport:
    """Every problem of one run CSV, or of a user's own CSV read through ``columns``.

    Parameters
    ----------
    path : path-like
    columns : hystcli.importer.ImportMapping, optional
        A ``--columns`` mapping (:func:`hystcli.importer.columns_mapping`): the file may then use
        any separator and its own column names and units. Without one the file must be a run CSV:
        comma-separated, ``# key: value`` metadata lines, a header row of run column names.
    current_sign : {"signed", "magnitude"}
        ``magnitude``: the drive reports ``|I|`` (the magnitude check is left out).

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


__all__ = ["CURRENT_SIGNS", "CheckReport", "ERROR", "LEVELS", "Problem", "WARNING", "check_file", "check_run",
           "magnitude_only", "noise", "require_shape", "robust_range", "shape_message", "slope_change",
           "turning_points"]
