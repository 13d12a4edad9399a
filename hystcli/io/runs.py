"""Run CSV files and model JSON files: read, validate at the boundary, write atomically.

Formats are docs/design.md section 6. A run CSV is optional ``# key: value`` metadata lines, a header
row and numeric rows; a model JSON is ``{"format": "hyst-model", "version": 1, "knobs": ...}``.
Every reader raises :class:`~hystcli.errors.DataError` or :class:`~hystcli.errors.ModelError`
with a message that names the file and the problem; every writer writes a temporary file beside
the target and renames it, so a reader never sees a partial file.
"""
from __future__ import annotations

import io as _io
import os
from pathlib import Path
from typing import BinaryIO, Callable, Iterable, Iterator

import numpy as np

from ..core.run import Run, missing_column
from ..errors import DataError

MODEL_FORMAT = "hyst-model"
MODEL_VERSION = 1

KNOWN_COLUMNS = ("t", "q1", "q2", "y1", "y2", "c1", "c2", "r1", "r2")
MAX_ABS_VALUE = 1e10
"""Largest magnitude a known column may hold. Far beyond any angle (deg), current (mA) or time (s)
a lab records, yet small enough that squares and sums of a whole run stay finite: a cell like
``1e308`` is a corrupt file, refused when read rather than overflowing deep inside a command."""


def _parse_meta_line(line: str) -> tuple[str, str] | None:
    body = line[1:].strip()
    if ":" not in body:
        return None
    key, _, value = body.partition(":")
    key = key.strip()
    if not key or " " in key:
        return None
    return key, value.strip()


def _meta_of(lines: Iterable[str]) -> dict[str, str]:
    """The ``# key: value`` metadata among a run's head lines (other comments are skipped)."""
    meta: dict[str, str] = {}
    for line in lines:
        if line.startswith("#"):
            kv = _parse_meta_line(line)
            if kv is not None:
                meta[kv[0]] = kv[1]
    return meta


def read_meta(path: str | os.PathLike) -> dict[str, str]:
    """The ``# key: value`` metadata of a run CSV, read from its head only (the rows are not
    read), as :func:`read_run` reads it: what a batch groups runs by before any worker parses them.

    Raises
    ------
    DataError
        The file cannot be read.
    """
    head: list[str] = []
    try:
        # utf-8-sig, as read_run: a byte-order mark is not part of the first metadata line
        with open(path, encoding="utf-8-sig", errors="replace") as f:
            for line in f:
                line = line.rstrip("\r\n")
                if line.strip() and not line.startswith("#"):
                    break  # the header: metadata only comes before it
                head.append(line)
    except OSError as exc:
        raise DataError(f"{path}: cannot read ({exc.strerror or exc})") from None
    return _meta_of(head)


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
    meta = _meta_of(lines[:-1])
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
                raise DataError(f"{source}: the header has {len(fields)} fields separated by {name}, not commas: "
                                f"name its columns with --columns (then any delimiter is read), e.g. "
                                f"--columns t=NAME,q1=NAME,... , or convert it once with `hyst import {source} "
                                f"--sep {option} --skip {i + 1} --map {spec or 't=1,q1=2,...'} -o converted.csv`")
    if any(h == "" for h in header):
        raise DataError(f"{source}: header row has an empty column name")
    if len(set(header)) != len(header):
        dup = next(h for h in header if header.count(h) > 1)
        raise DataError(f"{source}: column {dup!r} appears twice in the header")
    for col in ("t", *require):
        if col not in header:
            raise DataError(missing_column(source, col, header))
    return meta, header


def missing_column(source: str | None, name: str, columns: Iterable[str]) -> str:
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


