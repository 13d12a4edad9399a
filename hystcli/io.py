"""Run CSV files and model JSON files: read, validate at the boundary, write atomically.

Formats are docs/design.md section 6. A run CSV is optional ``# key: value`` metadata lines, a header
row and numeric rows; a model JSON is ``{"format": "hyst-model", "version": 1, "knobs": ...}``.
Every reader raises :class:`~hystcli.errors.DataError` or :class:`~hystcli.errors.ModelError`
with a message that names the file and the problem; every writer writes a temporary file beside
the target and renames it, so a reader never sees a partial file.
"""
from __future__ import annotations

import contextlib
import datetime as _dt
import hashlib
import io as _io
import json
import math
import os
import tempfile
from dataclasses import dataclass, field, replace
from pathlib import Path
from types import MappingProxyType
from typing import BinaryIO, Callable, Iterable, Iterator, Mapping

import numpy as np

from .errors import DataError, HystError, ModelError
from .estimate import Estimate
from .model import PARAM_NAMES, EffectSpec, Geometry, KnobIdentification, KnobModel, Model

MODEL_FORMAT = "hyst-model"
MODEL_VERSION = 1

KNOWN_COLUMNS = ("t", "q1", "q2", "y1", "y2", "c1", "c2", "r1", "r2")
MAX_ABS_VALUE = 1e10
"""Largest magnitude a known column may hold. Far beyond any angle (deg), current (mA) or time (s)
a lab records, yet small enough that squares and sums of a whole run stay finite: a cell like
``1e308`` is a corrupt file, refused when read rather than overflowing deep inside a command."""

KNOWN_META = ("catheter", "controller", "shape", "motion", "trial", "rotation", "offset1", "offset2", "condition",
              "shift_ignored")


# --------------------------------------------------------------------------------------------
# runs
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Run:
    """One recorded or simulated run: named numeric columns of equal length plus metadata.

    Attributes
    ----------
    columns : mapping of str to numpy.ndarray
        ``t`` (s), ``q1``/``q2`` (deg), ``y1``/``y2`` (deg), ``c1``/``c2`` (mA),
        ``r1``/``r2`` (deg), and any other numeric column, in file order.
    meta : mapping of str to str
        The ``# key: value`` lines, in file order.
    source : str or None
        Where the run was read from, for messages.
    """

    columns: Mapping[str, np.ndarray]
    meta: Mapping[str, str] = field(default_factory=dict)
    source: str | None = None

    def __post_init__(self) -> None:
        cols = {}
        n = None
        for name, values in self.columns.items():
            arr = np.asarray(values, dtype=np.float64)
            if arr is values and arr.flags.writeable:
                # the caller's own array: freeze a copy, never the caller's (a read-only array is
                # shared as it is: it came from another Run, or its owner chose to freeze it)
                arr = arr.copy()
            if arr.ndim != 1:
                raise DataError(f"{self._where()}column {name} must be 1-D")
            if n is None:
                n = arr.shape[0]
            elif arr.shape[0] != n:
                raise DataError(f"{self._where()}column {name} has {arr.shape[0]} rows, expected {n}")
            arr.setflags(write=False)
            cols[str(name)] = arr
        object.__setattr__(self, "columns", MappingProxyType(cols))
        object.__setattr__(self, "meta", MappingProxyType({str(k): str(v) for k, v in self.meta.items()}))

    def _where(self) -> str:
        return f"{self.source}: " if self.source else ""

    def __len__(self) -> int:
        return next(iter(self.columns.values())).shape[0] if self.columns else 0

    def __contains__(self, name: str) -> bool:
        return name in self.columns

    def __getitem__(self, name: str) -> np.ndarray:
        try:
            return self.columns[name]
        except KeyError:
            raise DataError(_missing(self.source, name, self.columns)) from None

    @property
    def t(self) -> np.ndarray:
        """Time column (s)."""
        return self["t"]

    def knobs(self, prefix: str = "q") -> list[int]:
        """Knob indices that have a column ``{prefix}{k}`` (e.g. ``q1``, ``q2``)."""
        return [k for k in (1, 2) if f"{prefix}{k}" in self.columns]

    def require(self, *names: str) -> "Run":
        """Raise :class:`DataError` naming the first missing column; return self."""
        for name in names:
            if name not in self.columns:
                self[name]
        return self

    def with_columns(self, **columns: np.ndarray) -> "Run":
        """A copy with columns added or replaced (order kept, new ones appended)."""
        cols = dict(self.columns)
        cols.update(columns)
        return replace(self, columns=cols)

    def with_meta(self, **meta: object) -> "Run":
        """A copy with metadata added or replaced (``None`` removes a key)."""
        m = dict(self.meta)
        for k, v in meta.items():
            if v is None:
                m.pop(k, None)
            else:
                m[k] = _meta_str(v)
        return replace(self, meta=m)

    def unknown_meta(self) -> list[str]:
        """Metadata keys hyst does not interpret (kept and reported, never an error)."""
        return [k for k in self.meta if k not in KNOWN_META]

    @property
    def sample_rate(self) -> float:
        """Median sample rate (Hz) from ``t``."""
        t = self.t
        if len(t) < 2:
            raise DataError(f"{self._where()}needs at least 2 samples to know the sample rate")
        return float(1.0 / np.median(np.diff(t)))


def _meta_str(v: object) -> str:
    if isinstance(v, float):
        return repr(v) if not v.is_integer() else f"{v:.1f}"
    return str(v)


def _parse_meta_line(line: str) -> tuple[str, str] | None:
    body = line[1:].strip()
    if ":" not in body:
        return None
    key, _, value = body.partition(":")
    key = key.strip()
    if not key or " " in key:
        return None
    return key, value.strip()


READ_PROGRESS_BYTES = 16 * 2**20
"""Files at least this big report their reading to a ``progress`` callback (:func:`read_run`): a
smaller one reads in a fraction of a second."""

READ_CHUNK_ROWS = 200_000
"""Rows per block of the big-file readers (:func:`read_run`, ``hyst import``'s): blocks bound the
parser's own buffers and give the progress its steps."""


def read_run(path: str | os.PathLike, require: Iterable[str] = ("t",),
             progress: Callable[[int, int], None] | None = None) -> Run:
    """Read and validate a run CSV.

    Parameters
    ----------
    path : path-like
        The CSV file.
    require : iterable of str
        Columns that must be present (``t`` always is); checked on the header, before the rows
        are read.
    progress : callable, optional
        ``progress(bytes_read, bytes_total)`` after each block of rows, for files of at least
        :data:`READ_PROGRESS_BYTES`.

    Returns
    -------
    Run
        Its columns are read-only float64 arrays.

    Raises
    ------
    DataError
        Missing or empty file, no header, a missing column, a non-numeric cell, NaN or
        infinity, non-increasing ``t``; the message names the file, column and row.

    Notes
    -----
    The rows are parsed from the file in blocks with explicit float64 types (pandas' C
    parser), never held as text: the peak memory is about the columns plus one block. Any
    doubt about a file (a parse error, a NaN, a row the parser would shift) sends it through
    :func:`parse_run`, which finds and names the problem; so both say the same.
    """
    p = Path(path)
    name = str(path)
    if not p.exists():
        raise DataError(f"{name}: no such file")
    if p.is_dir():
        raise DataError(f"{name}: is a directory, not a run CSV")
    try:
        with open(p, "rb") as f:
            run = _read_blocks(f, name, require, p.stat().st_size, progress)
        if run is not None:
            return run
        # utf-8-sig: Excel starts its UTF-8 CSVs with a byte-order mark, which is not part of 't'
        text = p.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError:
        raise DataError(f"{name}: not a text CSV file (not UTF-8)") from None
    except OSError as exc:
        raise DataError(f"{name}: cannot read ({exc.strerror})") from None
    return parse_run(text, source=name, require=require)


def parse_run(text: str, source: str = "<run>", require: Iterable[str] = ("t",)) -> Run:
    """Parse the text of a run CSV (see :func:`read_run`)."""
    lines = text.removeprefix("\ufeff").splitlines()
    i = 0
    while i < len(lines) and (lines[i].startswith("#") or not lines[i].strip()):
        i += 1
    meta, header = _parse_head(lines[:i + 1], source, require)
    import pandas as pd  # here, not at the top: pandas alone costs `hyst --help` half a second
    body = "\n".join(lines[i + 1:])
    header_line = i + 1  # 1-based line number of the header
    if not body.strip():
        raise DataError(f"{source}: no data rows after the header")
    # pandas would silently shift a row with the wrong number of fields into an index column
    ncomma = len(header) - 1
    for j, line in enumerate(lines[i + 1:]):
        if line.count(",") != ncomma and line.strip():
            raise DataError(f"{source}: line {header_line + 1 + j} has {line.count(',') + 1} fields, "
                            f"the header has {len(header)}")
    try:
        df = pd.read_csv(_io.StringIO(body), header=None, names=header, dtype=np.float64,
                         skip_blank_lines=True, comment=None, engine="c")
        fast_ok = True
    except (ValueError, pd.errors.ParserError):
        fast_ok = False
    if not fast_ok:
        try:
            df = pd.read_csv(_io.StringIO(body), header=None, names=header, dtype=str,
                             keep_default_na=False, skip_blank_lines=True, engine="python")
        except pd.errors.ParserError as exc:
            raise DataError(f"{source}: malformed CSV ({str(exc).splitlines()[0]})") from None
        for col in header:
            conv = pd.to_numeric(df[col].str.strip(), errors="coerce")
            bad = np.flatnonzero(conv.isna().to_numpy() & ~df[col].str.strip().str.lower().isin(["nan"]).to_numpy())
            if bad.size:
                row = int(bad[0])
                raise DataError(f"{source}: column {col!r}, line {header_line + 1 + row}: "
                                f"{df[col].iloc[row]!r} is not a number")
        df = df.apply(lambda s: pd.to_numeric(s.str.strip(), errors="coerce"))
    cols: dict[str, np.ndarray] = {}
    for col in header:
        arr = df[col].to_numpy(dtype=np.float64)
        problem = _bad_value(col, arr)
        if problem is not None:
            row, what = problem
            raise DataError(f"{source}: column {col!r}, line {header_line + 1 + row}: {what}")
        cols[col] = arr
    t = cols["t"]
    dt = np.diff(t)
    if dt.size and not np.all(dt > 0):
        row = int(np.flatnonzero(~(dt > 0))[0]) + 1
        raise DataError(f"{source}: column 't' is not strictly increasing at line {header_line + 1 + row} "
                        f"({float(t[row - 1])!r} then {float(t[row])!r})")
    return Run(cols, meta, source)


def _parse_head(lines: list[str], source: str, require: Iterable[str]) -> tuple[dict[str, str], list[str]]:
    """The metadata and the header of a run CSV from its first lines (metadata and blank lines,
    then the header, the last), the header checked and the ``require``d columns in it."""
    meta: dict[str, str] = {}
    for line in lines[:-1]:
        if line.startswith("#"):
            kv = _parse_meta_line(line)
            if kv is not None:
                meta[kv[0]] = kv[1]
    if not lines or lines[-1].startswith("#") or not lines[-1].strip():
        raise DataError(f"{source}: empty file (no header row)")
    i = len(lines) - 1
    header = [h.strip() for h in lines[i].split(",")]
    if len(header) == 1:
        for sep, name, option in ((";", "semicolons", "';'"), ("\t", "tabs", "tab")):
            fields = [f.strip() for f in lines[i].split(sep)]
            if len(fields) > 1:
                # Excel in many locales writes ';': say exactly how to convert the file
                spec = ",".join(f"{f}={j + 1}" for j, f in enumerate(fields) if f in KNOWN_COLUMNS)
                raise DataError(f"{source}: the header has no commas but {len(fields)} fields separated by "
                                f"{name}; a run CSV is comma-separated: convert it with `hyst import "
                                f"{source} --sep {option} --skip {i + 1} --map {spec or 't=1,q1=2,...'} "
                                f"-o converted.csv`")
    if any(h == "" for h in header):
        raise DataError(f"{source}: header row has an empty column name")
    if len(set(header)) != len(header):
        dup = next(h for h in header if header.count(h) > 1)
        raise DataError(f"{source}: column {dup!r} appears twice in the header")
    for col in ("t", *require):
        if col not in header:
            raise DataError(_missing(source, col, header))
    return meta, header


def _missing(source: str | None, name: str, columns: Iterable[str]) -> str:
    """The message for a column a run lacks."""
    return (f"{source + ': ' if source else ''}missing column {name!r} "
            f"(columns: {', '.join(columns) or 'none'})")


def odd_line_breaks(data: bytes, start: int = 0) -> bool:
    """Whether ``data[start:]`` (whole lines) breaks a line where str.splitlines does and a CSV
    parser does not: a lone carriage return, a vertical tab, a form feed, a file, group or record
    separator, a next-line or a line or paragraph separator. A reader that parses such bytes as
    CSV would count lines differently from one that splits the text (:func:`parse_run`). Byte
    searches, not a regular expression: this runs over every byte of a big file."""
    if data.count(b"\r", start) != data.count(b"\r\n", start):
        return True
    return any(data.find(b, start) >= 0 for b in (b"\x0b", b"\x0c", b"\x1c", b"\x1d", b"\x1e", b"\xc2\x85",
                                                  b"\xe2\x80\xa8", b"\xe2\x80\xa9"))


def _read_blocks(f: BinaryIO, source: str, require: Iterable[str], size: int,
                 progress: Callable[[int, int], None] | None) -> Run | None:
    """:func:`read_run`'s reader: the head line by line, then the rows in blocks straight into
    preallocated float64 columns. None when the file needs :func:`parse_run` to judge it."""
    head: list[str] = []
    while True:
        raw = f.readline()
        if not raw:
            return None          # no header: parse_run says so
        if not head:
            raw = raw.removeprefix(b"\xef\xbb\xbf")
            if raw.startswith(b"\xef\xbb\xbf"):
                return None      # a second mark: parse_run takes it off too
        if odd_line_breaks(raw):
            return None
        line = raw.decode("utf-8").removesuffix("\n").removesuffix("\r")
        head.append(line)
        if line.strip() and not line.startswith("#"):
            break
    meta, header = _parse_head(head, source, require)
    start = f.tell()
    rows = _count_lines(f, start)
    if rows is None:
        return None
    f.seek(start)
    cols = read_csv_blocks(f, header, rows, size, progress, names=header, encoding="utf-8")
    if cols is None:
        return None
    for name, arr in cols.items():
        if _bad_value(name, arr) is not None:
            return None
        arr.setflags(write=False)  # shared by the Run as it is (no copy)
    t = cols["t"]
    if t.size > 1 and not np.all(np.diff(t) > 0):
        return None
    return Run(cols, meta, source)


def read_csv_blocks(f: BinaryIO, keys: list, lines: int, size: int,
                    progress: Callable[[int, int], None] | None, **options: object) -> dict | None:
    """The columns ``keys`` of the rows pandas' C parser reads from ``f`` (from where it is), a
    block of :data:`READ_CHUNK_ROWS` rows at a time, into float64 arrays allocated once for
    ``lines`` rows: the rows are never held as text, nor twice as numbers.

    ``options`` go to :func:`pandas.read_csv` (``names``, ``usecols``, ``sep`` ...).
    ``progress(position, size)`` follows each block, for a file of at least
    :data:`READ_PROGRESS_BYTES`. None at any doubt, for the caller's own reader to judge: a parse
    error, no row, more rows than ``lines``, or a first row with more fields than asked for
    (pandas would take the surplus as the index and shift the rows).
    """
    import pandas as pd  # here, not at the top: pandas alone costs `hyst --help` half a second

    cols = {k: np.empty(lines) for k in keys}
    n = 0
    show = progress if progress is not None and size >= READ_PROGRESS_BYTES else None
    try:
        with pd.read_csv(f, header=None, dtype=np.float64, engine="c", comment=None, skip_blank_lines=True,
                         chunksize=READ_CHUNK_ROWS, **options) as blocks:
            for block in blocks:
                if not isinstance(block.index, pd.RangeIndex) or n + len(block) > lines:
                    return None
                for k in keys:
                    cols[k][n:n + len(block)] = block[k].to_numpy()
                n += len(block)
                if show is not None:
                    show(min(f.tell(), size), size)
    except (ValueError, UnicodeDecodeError, pd.errors.ParserError):
        return None
    return {k: v[:n] for k, v in cols.items()} if n else None


def _count_lines(f: BinaryIO, start: int) -> int | None:
    """Lines from ``start`` to the end of ``f`` (at least as many as the rows there), or None
    when one breaks where the CSV parser would not (:func:`odd_line_breaks`)."""
    f.seek(start)
    count = 1
    # blocks of whole lines: no line break is cut in two
    for block in iter(lambda: f.read(1 << 22) + f.readline(), b""):
        if odd_line_breaks(block):
            return None
        count += block.count(b"\n")
    return count


def _bad_value(column: str, values: np.ndarray) -> tuple[int, str] | None:
    """The first value :func:`read_run` refuses in a column, as (row, what is wrong), or None."""
    finite = np.isfinite(values)
    if not finite.all():
        row = int(np.flatnonzero(~finite)[0])
        return row, "NaN (missing value)" if np.isnan(values[row]) else "an infinite value"
    if column in KNOWN_COLUMNS and values.size and np.max(np.abs(values)) > MAX_ABS_VALUE:
        row = int(np.argmax(np.abs(values) > MAX_ABS_VALUE))
        return row, (f"{float(values[row]):g} is beyond +-{MAX_ABS_VALUE:g}, not a plausible angle, "
                     "current or time")
    return None


def format_run(run: Run) -> str:
    """Text of a run CSV: metadata lines, header, rows (floats in shortest round-trip form).

    Raises
    ------
    DataError
        A value :func:`read_run` would refuse (NaN, infinity, beyond :data:`MAX_ABS_VALUE`):
        hyst never writes a run it cannot read back (NaN would be an empty cell).
    """
    return "".join(_run_text(run))


_WRITE_ROWS = 50_000
"""Rows per piece of text :func:`write_run` writes: the file is written piece by piece, never held
whole."""


def _run_text(run: Run) -> Iterator[str]:
    """The text of a run CSV in pieces (checked first: see :func:`format_run`)."""
    for name, values in run.columns.items():
        problem = _bad_value(name, np.asarray(values))
        if problem is not None:
            row, what = problem
            raise DataError(f"{run._where()}refusing to write column {name!r}, sample {row}: {what} "
                            "(the file could not be read back)")
    head = "".join(f"# {k}: {str(v).replace(chr(10), ' ')}\n" for k, v in run.meta.items())
    names = list(run.columns)
    if not names or any(set(n) & set(',"\r\n') for n in names):
        # a name the CSV writer quotes (never one read_run reads): pandas writes the whole file
        import pandas as pd

        buf = _io.StringIO()
        pd.DataFrame({k: np.asarray(v) for k, v in run.columns.items()}).to_csv(buf, index=False, lineterminator="\n")
        yield head + buf.getvalue()
        return
    yield head + ",".join(names) + "\n"
    cols = [np.asarray(v, dtype=np.float64) for v in run.columns.values()]
    # repr: the shortest string that reads back to the same double (what pandas' to_csv writes)
    for i in range(0, len(run), _WRITE_ROWS):
        rows = zip(*[map(float.__repr__, c[i:i + _WRITE_ROWS].tolist()) for c in cols])
        yield "\n".join(map(",".join, rows)) + "\n"


def write_run(path: str | os.PathLike, run: Run, inputs: Iterable[str | os.PathLike] = ()) -> None:
    """Write a run CSV atomically (temporary file + rename), piece by piece.

    Parameters
    ----------
    path : path-like
        Target file.
    run : Run
    inputs : iterable of path-like
        Input files of the command: writing over one of them is refused.
    """
    atomic_write(path, _run_writer(run), inputs=inputs)


def _run_writer(run: Run) -> Callable[[BinaryIO], None]:
    """A writer of ``run``'s CSV text to a binary file, piece by piece; the run is checked when
    this is called, before any file is made."""
    pieces = _run_text(run)
    first = next(pieces)

    def write(f: BinaryIO) -> None:
        f.write(first.encode("utf-8"))
        for piece in pieces:
            f.write(piece.encode("utf-8"))

    return write


# --------------------------------------------------------------------------------------------
# atomic writes
# --------------------------------------------------------------------------------------------
def check_not_input(path: str | os.PathLike, inputs: Iterable[str | os.PathLike]) -> None:
    """Refuse to write ``path`` when it is one of the command's input files."""
    target = Path(path).resolve()
    for inp in inputs:
        if inp is None:
            continue
        if Path(inp).resolve() == target:
            raise DataError(f"{path}: refusing to overwrite an input file; choose another output path")


def atomic_write_text(path: str | os.PathLike, text: str,
                      inputs: Iterable[str | os.PathLike] = ()) -> None:
    """Write ``text`` to ``path`` through a temporary file in the same folder and a rename."""
    atomic_write(path, lambda f: f.write(text.encode("utf-8")), inputs=inputs)


def _file_mode() -> int:
    """Mode of a new file under the process's umask (what ``open(path, "w")`` would give)."""
    # mkstemp makes its file 0600 whatever the umask; reading the umask means setting it, so it is
    # put back at once (read each time: a caller may change its umask between two writes)
    mask = os.umask(0o022)
    os.umask(mask)
    return 0o666 & ~mask


def _stage(target: Path) -> str:
    """An empty temporary file beside ``target``, with the mode a new file would get; its name
    keeps the target's suffix, since some writers (matplotlib) choose the format by it."""
    fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=f".tmp{target.suffix}", dir=target.parent)
    try:
        os.fchmod(fd, _file_mode())
    finally:
        os.close(fd)
    return tmp


def _check_target(path: str | os.PathLike, inputs: Iterable[str | os.PathLike]) -> Path:
    check_not_input(path, inputs)
    target = Path(path)
    folder = target.parent if str(target.parent) else Path(".")
    if not folder.is_dir():
        raise DataError(f"{path}: the folder {folder} does not exist")
    if target.is_dir():
        raise DataError(f"{path}: is a directory; give a file name")
    return target


def _cannot_write(path: str | os.PathLike, exc: OSError) -> DataError:
    # the message names the file the user asked for, never the temporary file beside it
    return DataError(f"{path}: cannot write ({exc.strerror or exc})")


def atomic_write(path: str | os.PathLike, writer: Callable, inputs: Iterable[str | os.PathLike] = ()) -> None:
    """Call ``writer(binary_file)`` on a temporary file, then rename it onto ``path``.

    On any error the temporary file is removed and ``path`` is left as it was. The file gets
    the mode the umask gives a new file.
    """
    target = _check_target(path, inputs)
    try:
        tmp = _stage(target)
    except OSError as exc:
        raise _cannot_write(path, exc) from None
    try:
        with open(tmp, "wb") as f:
            writer(f)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, target)
    except BaseException as exc:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        if isinstance(exc, OSError):
            raise _cannot_write(path, exc) from None
        raise


class PendingOutputs:
    """The output files of one command, staged beside their targets until all are written.

    Made by :func:`all_or_none`; each ``write_*`` (or a writer given :meth:`path`) fills a
    temporary file, and only when every one succeeded are they renamed onto their targets.
    """

    def __init__(self) -> None:
        self._staged: list[tuple[str, Path]] = []

    def path(self, target: str | os.PathLike, inputs: Iterable[str | os.PathLike] = ()) -> str:
        """A temporary path (same folder and suffix) for a writer that wants a file name."""
        checked = _check_target(target, inputs)
        if any(t.resolve() == checked.resolve() for _, t in self._staged):
            raise DataError(f"{target}: given as two of the outputs; choose different files")
        try:
            tmp = _stage(checked)
        except OSError as exc:
            raise _cannot_write(target, exc) from None
        self._staged.append((tmp, checked))
        return tmp

    def write_bytes(self, target: str | os.PathLike, data: bytes,
                    inputs: Iterable[str | os.PathLike] = ()) -> None:
        """Stage ``data`` for ``target``."""
        self._write(target, lambda f: f.write(data), inputs)

    def write_text(self, target: str | os.PathLike, text: str, inputs: Iterable[str | os.PathLike] = ()) -> None:
        """Stage ``text`` (UTF-8) for ``target``."""
        self.write_bytes(target, text.encode("utf-8"), inputs)

    def write_run(self, target: str | os.PathLike, run: Run, inputs: Iterable[str | os.PathLike] = ()) -> None:
        """Stage ``run`` as a run CSV for ``target``, piece by piece (:func:`write_run`)."""
        self._write(target, _run_writer(run), inputs)

    def _write(self, target: str | os.PathLike, writer: Callable[[BinaryIO], object],
               inputs: Iterable[str | os.PathLike]) -> None:
        tmp = self.path(target, inputs)
        try:
            with open(tmp, "wb") as f:
                writer(f)
                f.flush()
                os.fsync(f.fileno())
        except OSError as exc:
            raise _cannot_write(target, exc) from None

    def discard(self) -> None:
        """Remove every staged file; no target is touched."""
        for tmp, _ in self._staged:
            with contextlib.suppress(OSError):
                os.unlink(tmp)
        self._staged.clear()

    def commit(self) -> list[Path]:
        """Rename every staged file onto its target; returns the targets."""
        done: list[Path] = []
        try:
            for tmp, target in self._staged:
                os.replace(tmp, target)
                done.append(target)
        except OSError as exc:
            # a rename in the same folder fails only if the folder changed under us: say what
            # was written rather than pretend nothing was
            self._staged = self._staged[len(done):]
            self.discard()
            written = f" ({', '.join(map(str, done))} already written)" if done else ""
            raise DataError(f"{target}: cannot write ({exc.strerror or exc}){written}") from None
        self._staged.clear()
        return done


@contextlib.contextmanager
def all_or_none() -> Iterator[PendingOutputs]:
    """Write several output files all or none.

    Examples
    --------
    >>> import pathlib, tempfile
    >>> folder = pathlib.Path(tempfile.mkdtemp())
    >>> with all_or_none() as out:
    ...     out.write_text(folder / "report.json", "{}")
    ...     out.write_text(folder / "model.json", "{}")  # an error here would leave neither file
    >>> sorted(p.name for p in folder.iterdir())
    ['model.json', 'report.json']
    >>> import shutil; shutil.rmtree(folder)
    """
    pending = PendingOutputs()
    try:
        yield pending
    except HystError as exc:
        # a writer that was given a temporary path names it in its error: name the target instead
        message = str(exc)
        for tmp, target in pending._staged:
            message = message.replace(tmp, str(target))
        pending.discard()
        if message != str(exc):
            raise type(exc)(message) from None
        raise
    except BaseException:
        pending.discard()
        raise
    pending.commit()


# --------------------------------------------------------------------------------------------
# models
# --------------------------------------------------------------------------------------------
def _num(value: object, what: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ModelError(f"{what} must be a number, got {value!r}")
    v = float(value)
    if not math.isfinite(v):
        raise ModelError(f"{what} must be finite, got {value!r}")
    return v


def model_from_dict(data: object, source: str = "<model>") -> Model:
    """Build a :class:`Model` from the parsed JSON of a model file, validating everything."""
    if not isinstance(data, dict):
        raise ModelError(f"{source}: not a hyst model (the top level must be a JSON object)")
    if data.get("format") != MODEL_FORMAT:
        raise ModelError(f"{source}: not a hyst model (\"format\" must be {MODEL_FORMAT!r}, "
                         f"got {data.get('format')!r})")
    version = data.get("version")
    if version != MODEL_VERSION:
        raise ModelError(f"{source}: unknown model version {version!r} (this hyst reads version {MODEL_VERSION})")
    knobs_raw = data.get("knobs")
    if not isinstance(knobs_raw, dict) or not knobs_raw:
        raise ModelError(f"{source}: \"knobs\" must be an object with knob \"1\" and/or \"2\"")
    knobs: dict[int, KnobModel] = {}
    for key, params in knobs_raw.items():
        if key not in ("1", "2"):
            raise ModelError(f"{source}: unknown knob {key!r} (knobs are \"1\" and \"2\")")
        if not isinstance(params, dict):
            raise ModelError(f"{source}: knob {key} must be an object of parameters")
        missing = [p for p in PARAM_NAMES if p != "offset" and p not in params]
        if missing:
            raise ModelError(f"{source}: knob {key} is missing parameter {missing[0]}")
        unknown = [p for p in params if p not in PARAM_NAMES]
        if unknown:
            raise ModelError(f"{source}: knob {key} has unknown parameter {unknown[0]!r}")
        values = {p: _num(params[p], f"knob {key} parameter {p}") for p in params}
        try:
            knobs[int(key)] = KnobModel(**values)
        except ModelError as exc:
            raise ModelError(f"{source}: knob {key}: {exc}") from None
    geometry = None
    if data.get("geometry") is not None:
        g = data["geometry"]
        if not isinstance(g, dict) or "beta_catheter_mm" not in g or "beta_knob_mm" not in g:
            raise ModelError(f"{source}: \"geometry\" needs beta_catheter_mm and beta_knob_mm")
        try:
            geometry = Geometry(_num(g["beta_catheter_mm"], "geometry beta_catheter_mm"),
                                _num(g["beta_knob_mm"], "geometry beta_knob_mm"))
        except ModelError as exc:
            raise ModelError(f"{source}: {exc}") from None
    effects = []
    for i, e in enumerate(data.get("effects") or []):
        if not isinstance(e, dict) or not isinstance(e.get("name"), str):
            raise ModelError(f"{source}: effect #{i + 1} needs a \"name\"")
        params = e.get("params") or {}
        if not isinstance(params, dict):
            raise ModelError(f"{source}: effect {e['name']!r}: \"params\" must be an object")
        form = e.get("form") or ""
        if not isinstance(form, str):
            raise ModelError(f"{source}: effect {e['name']!r}: \"form\" must be a string")
        effects.append(EffectSpec(e["name"], {k: _num(v, f"effect {e['name']} parameter {k}")
                                              for k, v in params.items()}, form))
    meta = data.get("meta") or {}
    if not isinstance(meta, dict):
        raise ModelError(f"{source}: \"meta\" must be an object")
    ident: dict[int, KnobIdentification] = {}
    for key, d in (data.get("identification") or {}).items():
        if key not in ("1", "2") or not isinstance(d, dict):
            raise ModelError(f"{source}: bad \"identification\" entry {key!r}")
        try:
            ident[int(key)] = _identification_of(d, source, key)
        except KeyError as exc:
            raise ModelError(f"{source}: identification of knob {key} is missing {exc.args[0]}") from None
        except ModelError as exc:
            if str(exc).startswith(str(source)):
                raise
            raise ModelError(f"{source}: knob {key}'s {exc}") from None
    return Model(knobs, geometry, tuple(effects), meta, ident)


def _identification_of(d: dict, source: str, key: str) -> KnobIdentification:
    """A knob's identification from its model-file entry."""
    where = f"{source}: knob {key} identification"

    def estimates(value: object, what: str) -> dict:
        if value is None:
            return {}
        if not isinstance(value, dict) or not all(isinstance(v, dict) for v in value.values()):
            raise ModelError(f"{where}: \"{what}\" must map names to intervals")
        return {str(n): Estimate.from_dict(v, f"{where} {what} {n}") for n, v in value.items()}

    sign = d.get("current_sign")
    return KnobIdentification(
        q_min=_num(d["q_min"], "identification q_min"), q_max=_num(d["q_max"], "identification q_max"),
        method=str(d.get("method", "tip")),
        rmse=None if d.get("rmse") is None else _num(d["rmse"], "identification rmse"),
        estimates=estimates(d.get("estimates"), "estimates"),
        current_sign=None if sign is None else str(sign),
        current_edges=estimates(d.get("current_edges"), "current_edges"),
        slope_dead_zone=_num(d.get("slope_dead_zone", 0.0), "identification slope_dead_zone"),
        **{name: None if d.get(name) is None else _num(d[name], f"identification {name}")
           for name in KnobIdentification.OPTIONAL})


def model_to_dict(model: Model) -> dict:
    """The JSON-ready dict of a model (docs/design.md section 6)."""
    out: dict = {"format": MODEL_FORMAT, "version": MODEL_VERSION,
                 "knobs": {str(k): v.params() for k, v in model.knobs.items()}}
    if model.geometry is not None:
        out["geometry"] = {"beta_catheter_mm": model.geometry.beta_catheter_mm,
                           "beta_knob_mm": model.geometry.beta_knob_mm}
    if model.effects:
        out["effects"] = [{"name": e.name, **({"form": e.form} if e.form else {}), "params": dict(e.params)}
                          for e in model.effects]
    if model.meta:
        out["meta"] = dict(model.meta)
    if model.identification:
        out["identification"] = {str(k): _identification_dict(v) for k, v in model.identification.items()}
    return out


def _identification_dict(v: KnobIdentification) -> dict:
    out: dict = {"q_min": v.q_min, "q_max": v.q_max, "method": v.method, "rmse": v.rmse,
                 "estimates": {n: e.to_dict() for n, e in v.estimates.items()}}
    if v.current_sign is not None:
        out["current_sign"] = v.current_sign
        out["current_edges"] = {n: e.to_dict() for n, e in v.current_edges.items()}
        out["slope_dead_zone"] = v.slope_dead_zone
    out.update({name: getattr(v, name) for name in KnobIdentification.OPTIONAL if getattr(v, name) is not None})
    return out


def load_model(path: str | os.PathLike) -> Model:
    """Read and validate a model JSON file.

    Raises
    ------
    ModelError
        Missing file, invalid JSON, wrong format or version, invalid parameters.
    """
    p = Path(path)
    if not p.exists():
        raise ModelError(f"{path}: no such model file")
    try:
        text = p.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise ModelError(f"{path}: cannot read the model ({exc})") from None
    if not text.strip():
        raise ModelError(f"{path}: empty model file")
    try:
        data = json.loads(text, parse_constant=lambda c: float(c))
    except json.JSONDecodeError as exc:
        raise ModelError(f"{path}: not valid JSON ({exc.msg} at line {exc.lineno})") from None
    return model_from_dict(data, source=str(path))


def dumps_model(model: Model) -> str:
    """JSON text of a model (stable key order, so the same model gives the same bytes)."""
    return json.dumps(model_to_dict(model), indent=2, allow_nan=False) + "\n"


def save_model(path: str | os.PathLike, model: Model, inputs: Iterable[str | os.PathLike] = ()) -> None:
    """Write a model JSON file atomically."""
    atomic_write_text(path, dumps_model(model), inputs=inputs)


def file_sha256(path: str | os.PathLike) -> str:
    """SHA-256 of a file, for the provenance in model metadata."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def provenance(source: str | os.PathLike | None, **extra: object) -> dict:
    """Model metadata: the source file, its hash, its modification time and no wall-clock time.

    ``source_modified`` is when the source file was last written (UTC); the model records no time
    of its own making, so that the same command on the same input gives the same bytes.
    """
    meta: dict = {}
    if source is not None:
        meta["source"] = Path(source).name
        meta["sha256"] = file_sha256(source)
        mtime = os.stat(source).st_mtime
        meta["source_modified"] = _dt.datetime.fromtimestamp(mtime, _dt.timezone.utc).replace(
            microsecond=0).isoformat()
    meta.update({k: v for k, v in extra.items() if v is not None})
    return meta
