"""Reading a foreign log: its text (plain, gzip, any encoding), its separator and layout, the table
of numbers it holds, read fast or streamed."""
from __future__ import annotations

import codecs
import csv
import difflib
import gzip
import math
import os
import re
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO, Callable, Mapping, Sequence

import numpy as np

from ..errors import DataError
from ..filters import lowpass
from .mapping import ANTI_ALIAS_FRACTION, AUTO, COMMENT_PREFIXES, TARGETS, ColumnMap, ImportMapping
from .runs import MAX_ABS_VALUE, odd_line_breaks, read_csv_blocks


def read_text(path: str | os.PathLike) -> str:
    """Text of a raw log, gunzipped when it is gzip data (by content, not by name).

    Raises
    ------
    DataError
        Missing, unreadable, corrupt gzip, binary (NUL bytes) or empty file.
    """
    p = Path(path)
    if not p.exists():
        raise DataError(f"{path}: no such file")
    if p.is_dir():
        raise DataError(f"{path}: is a directory, not a log file")
    try:
        raw = p.read_bytes()
        if raw[:2] == b"\x1f\x8b":
            raw = gzip.decompress(raw)
    except OSError as exc:
        if isinstance(exc, (gzip.BadGzipFile, EOFError)) or not getattr(exc, "strerror", None):
            raise DataError(f"{path}: corrupt gzip data ({exc})") from None
        raise DataError(f"{path}: cannot read ({exc.strerror})") from None
    except (EOFError, zlib.error) as exc:
        raise DataError(f"{path}: corrupt gzip data ({exc})") from None
    if b"\x00" in raw:
        raise DataError(f"{path}: binary data (NUL bytes), not a text log")
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError:
        # loggers on Windows write cp1252 (degree signs, micro signs) in their headers
        text = raw.decode("latin-1")
    if not text.strip():
        raise DataError(f"{path}: empty file")
    return text.lstrip("\ufeff")


def _readme_lines(path: Path) -> list[str]:
    folder = path.parent
    lines: list[str] = []
    try:
        names = sorted(folder.iterdir())
    except OSError:
        return lines
    for f in names:
        if f.is_file() and f.name.lower().startswith("readme"):
            try:
                lines += f.read_text(encoding="utf-8", errors="replace").splitlines()
            except OSError:
                continue
    return lines


def _split(line: str, sep: str | None) -> list[str]:
    return line.split() if sep is None else line.split(sep)


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


SNIFF_LINES = 20
"""Data lines :func:`sniff_separator` looks at."""


def sniff_separator(lines: Sequence[str]) -> str | None:
    """The field separator of delimited text: comma, tab or semicolon, else None (any whitespace).

    :class:`csv.Sniffer` proposes one of the three from the first :data:`SNIFF_LINES` lines; it
    is kept only when every one of those lines then splits into the same number (> 1) of fields.
    The sniffer cannot tell columns aligned by runs of spaces, which are whitespace-separated.
    """
    sample = [ln for ln in lines[:SNIFF_LINES] if ln.strip()]
    if not sample:
        return None
    try:
        sep = csv.Sniffer().sniff("\n".join(sample), delimiters=",\t;").delimiter
    except csv.Error:
        return None
    counts = {len(ln.split(sep)) for ln in sample}
    return sep if len(counts) == 1 and counts.pop() > 1 else None


def _separator_name(sep: str | None) -> str:
    return {None: "whitespace", ",": "comma", "\t": "tab", ";": "semicolon"}.get(sep, repr(sep))


@dataclass(frozen=True)
class Layout:
    """Delimited text split into its parts (:func:`split_table`); the cells stay text.

    Attributes
    ----------
    header : tuple of str
        The skipped and the comment lines, in order.
    names : tuple of str or None
        The column names of the header row, when the file has one.
    separator : str or None
        The separator used (given or sniffed; None: any whitespace).
    linenos : sequence of int
        1-based line number of every data row (a range when the rows follow each other).
    rows : tuple of list of str
        The fields of every data row, as split (not stripped).
    """

    header: tuple[str, ...]
    names: tuple[str, ...] | None
    separator: str | None
    linenos: Sequence[int]
    rows: tuple[list[str], ...]

    def split(self, line: str) -> list[str]:
        """The fields of one line by this layout's separator."""
        return _split(line.strip() if self.separator is None else line, self.separator)


def split_table(text: str, separator: str | None = ",", comment: str | None = "#", skip: int = 0,
                names_row: bool | None = False, source: str = "<log>") -> Layout:
    """Split delimited text into header lines, an optional row of column names and data rows.

    Parameters
    ----------
    text : str
    separator : str or None
        A separator, None (any whitespace) or ``"auto"`` (:func:`sniff_separator`).
    comment : str or None
        Prefix of comment lines, None (none) or ``"auto"`` (any of :data:`COMMENT_PREFIXES`).
    skip : int
        Lines skipped at the top.
    names_row : bool or None
        Whether the first line after the skipped and comment lines names the columns; None: it
        does when none of its fields is a number.
    source : str
        Name for messages.

    Raises
    ------
    DataError
        No data rows.
    """
    lines = text.splitlines()
    header = list(lines[:skip])
    prefixes = COMMENT_PREFIXES if comment == AUTO else () if comment is None else (comment,)
    data: list[tuple[int, str]] = []
    for i, line in enumerate(lines[skip:], start=skip + 1):
        if prefixes and line.lstrip().startswith(prefixes):
            header.append(line)
        elif line.strip():
            data.append((i, line))
    if not data:
        raise DataError(f"{source}: no data rows (after {skip} skipped lines and "
                        f"{len(header) - skip} comment lines)")
    sep = sniff_separator([ln for _, ln in data]) if separator == AUTO else separator
    layout = Layout((), None, sep, (), ())
    first = [f.strip() for f in layout.split(data[0][1])]
    if names_row is None:
        names_row = not any(_is_number(f) for f in first)
    names = None
    if names_row:
        names = tuple(f.strip("\"'").strip() for f in first)
        data = data[1:]
        if not data:
            raise DataError(f"{source}: no data rows after the header row")
    return Layout(tuple(header), names, sep, tuple(n for n, _ in data), tuple(layout.split(ln) for _, ln in data))


def resolve_columns(columns: Sequence[ColumnMap], layout: Layout, source: str,
                    as_run: bool = False) -> tuple[tuple[ColumnMap, int], ...]:
    """Each column mapping with the 0-based index of the raw column it reads.

    A name is looked up in the header row (exactly, else ignoring case); with ``as_run``, header
    columns named like a run column that no mapping fills or reads are added as they are.

    Raises
    ------
    DataError
        A name the header row lacks (naming the columns it has), a name it has twice, or a name
        in a file without a header row.
    """
    names = layout.names
    out = []
    for c in columns:
        if isinstance(c.column, int):
            out.append((c, c.column - 1))
            continue
        if names is None:
            raise DataError(f"{source}: {c.target}={c.column}: the file has no header row to find "
                            f"{c.column!r} in (its first data line is numbers): give the column's number, "
                            f"{c.target}=N")
        hits = [j for j, n in enumerate(names) if n == c.column] or \
            [j for j, n in enumerate(names) if n.lower() == c.column.lower()]
        if not hits:
            close = difflib.get_close_matches(c.column, names, 1, 0.6)
            raise DataError(f"{source}: no column {c.column!r} for {c.target} (the file has "
                            f"{', '.join(names)})" + (f"; did you mean {close[0]!r}?" if close else ""))
        if len(hits) > 1:
            raise DataError(f"{source}: column {c.column!r} appears {len(hits)} times in the header row; "
                            f"give its number, {c.target}=N")
        out.append((c, hits[0]))
    if as_run and names is not None:
        filled = {c.target for c in columns}
        read = {j for _, j in out}
        out += [(ColumnMap(n, j + 1), j) for j, n in enumerate(names)
                if n in TARGETS and n not in filled and j not in read]
    return tuple(out)


def _names_row(mapping: ImportMapping) -> bool | None:
    """Whether the first data line names the columns (None: when none of its fields is a number)."""
    by_name = any(isinstance(c.column, str) for c in mapping.columns)
    return None if by_name or mapping.separator == AUTO or mapping.as_run else False


def _resolve(layout: Layout, mapping: ImportMapping, source: str) -> tuple[tuple[ColumnMap, int], ...]:
    """:func:`resolve_columns` of the mapping, which must give the time or a rate."""
    resolved = resolve_columns(mapping.columns, layout, source, mapping.as_run)
    if not any(c.target == "t" for c, _ in resolved) and mapping.rate is None:
        found = f" (the file has {', '.join(layout.names)})" if layout.names else ""
        raise DataError(f"{source}: no time column: map t=COLUMN{found}")
    return resolved


def _parse_table(text: str, mapping: ImportMapping, source: str
                 ) -> tuple[Layout, dict[str, ColumnMap], dict[str, np.ndarray]]:
    """The layout, the column mappings by target (with any ``as_run`` additions) and the mapped
    columns, converted to the run's units."""
    layout = split_table(text, mapping.separator, mapping.comment, mapping.skip, _names_row(mapping), source)
    resolved = _resolve(layout, mapping, source)
    need = max(j for _, j in resolved) + 1
    for lineno, parts in zip(layout.linenos, layout.rows):
        if len(parts) < need:
            raise DataError(f"{source}: line {lineno} has {len(parts)} fields, the mapping reads column {need} "
                            f"(separator: {_separator_name(layout.separator)})")
    linenos = np.array(layout.linenos)
    cols: dict[str, np.ndarray] = {}
    for c, j in resolved:
        cells = [row[j].strip() for row in layout.rows]
        what = f"column {c.column}" if isinstance(c.column, int) else f"column {c.column!r}"
        try:
            values = np.array(cells, dtype=np.float64)
        except ValueError:
            k = next(k for k, cell in enumerate(cells) if not _is_number(cell))
            hint = " (skip header lines with --skip N)" if k == 0 else ""
            raise DataError(f"{source}: line {linenos[k]}, {what} ({c.target}): "
                            f"{cells[k]!r} is not a number{hint}") from None
        bad = ~np.isfinite(values)
        if bad.any():
            k = int(np.flatnonzero(bad)[0])
            raise DataError(f"{source}: line {linenos[k]}, {what} ({c.target}): "
                            f"{cells[k]!r} is not a finite number")
        values = values * c.factor + c.offset
        # an import shifts time to start at 0, so only a run's own time must be small already
        big = np.abs(values) > MAX_ABS_VALUE if c.target != "t" or mapping.as_run else np.zeros(0, bool)
        if big.any():
            k = int(np.flatnonzero(big)[0])
            raise DataError(f"{source}: line {linenos[k]}, {what} ({c.target}): {cells[k]!r} is beyond "
                            f"+-{MAX_ABS_VALUE:g}, not a plausible angle, current or time")
        cols[c.target] = values
    return layout, {c.target: c for c, _ in resolved}, cols


def _table_fast(path: Path, mapping: ImportMapping, source: str, progress: Callable[[int, int], None] | None = None
                ) -> tuple[Layout, dict[str, ColumnMap], dict[str, np.ndarray]] | None:
    """:func:`_parse_table` of a log file by a CSV parser with float64 columns, streamed from the
    file (gunzipped on the fly): the log is never held whole, as bytes or as text.

    For a log whose rows are plain: after the skipped lines and the comment and blank lines
    above the first row (and a row of names), no comment or blank line, a one-character (or
    whitespace) separator, nothing str.splitlines breaks a line at that the parser does not, no
    NUL byte. None for any other log and for any doubt (a cell that is not a finite number, a
    short or long row, a corrupt gzip stream): :func:`_parse_table` then reads it and names the
    problem. What both read the same way (the column names, the mapping's columns) raises here
    as there.
    """
    prefixes = COMMENT_PREFIXES if mapping.comment == AUTO else () if mapping.comment is None else (mapping.comment,)
    if any(not p.isascii() or not p.strip() or p[0] in "0123456789+-." for p in prefixes):
        return None
    if mapping.separator not in (None, AUTO) and not _plain_separator(mapping.separator):
        return None
    try:
        with _open_log(path) as f:
            return _stream_table(f, mapping, tuple(p.encode() for p in prefixes), source, progress)
    except (OSError, EOFError, zlib.error):
        return None   # the line reader's reading says what is wrong with the file


def _plain_separator(sep: str | None) -> bool:
    """Whether the CSV parser splits on ``sep`` as str.split does (None: any whitespace)."""
    return sep is None or (len(sep) == 1 and sep not in "\r\n\"+-." and not sep.isalnum())


def _open_log(path: Path) -> BinaryIO:
    """The log's bytes as a stream: gunzipped when it is gzip data (by content, not by name)."""
    f = open(path, "rb")
    if f.read(2) == b"\x1f\x8b":
        f.close()
        return gzip.open(path, "rb")
    f.seek(0)
    return f


class _Utf8:
    """Whether a stream of bytes is UTF-8, fed in pieces of whole lines (:func:`read_text`'s
    choice between UTF-8 and latin-1, without decoding the log)."""

    def __init__(self) -> None:
        self._decoder = codecs.getincrementaldecoder("utf-8")()
        self._ok = True

    def feed(self, data: bytes) -> None:
        if self._ok and not data.isascii():
            try:
                self._decoder.decode(data)
            except UnicodeDecodeError:
                self._ok = False

    def encoding(self) -> str:
        if self._ok:
            try:
                self._decoder.decode(b"", final=True)
            except UnicodeDecodeError:
                self._ok = False
        return "utf-8" if self._ok else "latin-1"


_BOM = b"\xef\xbb\xbf"


def _stream_table(f: BinaryIO, mapping: ImportMapping, prefixes: tuple[bytes, ...], source: str,
                  progress: Callable[[int, int], None] | None
                  ) -> tuple[Layout, dict[str, ColumnMap], dict[str, np.ndarray]] | None:
    utf8 = _Utf8()
    head: list[bytes] = []
    lineno, boms = 0, 0
    while True:  # the head: skipped lines, then comment and blank lines up to the first data line
        start = f.tell()
        line = f.readline()
        if not line or b"\x00" in line or odd_line_breaks(line):
            return None
        utf8.feed(line)
        while lineno == 0 and line.startswith(_BOM):
            line, boms = line[len(_BOM):], boms + 1
        lineno += 1
        body = line.removesuffix(b"\n").removesuffix(b"\r")
        lead = body.lstrip(b" \t")
        if lead[:1] == b"\x1f" or lead[:1] >= b"\x80":
            return None   # whether the line is blank or a comment would depend on its decoding
        if lineno <= mapping.skip or (prefixes and lead.startswith(prefixes)):
            head.append(body)
        elif lead.strip():
            break
    # the data lines once over: anything that would make the parser's rows differ from the line
    # reader's, the first lines (a separator to find, a row of names), and the count of lines,
    # so that the columns are allocated once
    f.seek(start)
    odd = re.compile(rb"\n[ \t\r]*(?:\n" + b"".join(b"|" + re.escape(p) for p in prefixes) + b")")
    lines, size, last, first_lines = 1, start, b"", []
    for block in iter(lambda: f.read(1 << 22) + f.readline(), b""):   # whole lines
        if b"\x00" in block or odd_line_breaks(block) or odd.search(b"\n" + last):
            return None
        utf8.feed(block)
        if len(first_lines) < SNIFF_LINES:
            first_lines += block.split(b"\n", SNIFF_LINES)[:SNIFF_LINES - len(first_lines)]
        lines += block.count(b"\n")
        size += len(block)
        last = block
    if odd.search(b"\n" + last.rstrip(b"\r\n")):   # blank lines that end the file are no row for either
        return None
    encoding = utf8.encoding()
    if boms and encoding != "utf-8":
        return None   # the line reader keeps those bytes, as latin-1 characters
    text = [ln.decode(encoding).removesuffix("\r") for ln in first_lines if ln.strip()]
    sep = sniff_separator(text) if mapping.separator == AUTO else mapping.separator
    if not _plain_separator(sep):
        return None
    layout = Layout((), None, sep, (), ())
    names, first = None, lineno
    fields = [x.strip() for x in layout.split(text[0])]
    names_row = _names_row(mapping)
    if names_row or (names_row is None and not any(_is_number(x) for x in fields)):
        names = tuple(x.strip("\"'").strip() for x in fields)
        f.seek(start)
        start += len(f.readline())
        first += 1
    layout = Layout(tuple(line.decode(encoding) for line in head), names, sep, (), ())
    resolved = _resolve(layout, mapping, source)
    f.seek(start)
    cols = _parse_rows(f, lines, size, resolved, mapping, encoding, sep, progress)
    if cols is None:
        return None
    n = len(next(iter(cols.values())))
    # the rows' line numbers (for _time's messages) as a range: no array of the log's length
    return (Layout(layout.header, names, sep, range(first, first + n), ()), {c.target: c for c, _ in resolved},
            cols)


def _parse_rows(f: BinaryIO, lines: int, size: int, resolved: tuple[tuple[ColumnMap, int], ...],
                mapping: ImportMapping, encoding: str, sep: str | None,
                progress: Callable[[int, int], None] | None) -> dict[str, np.ndarray] | None:
    """The mapped columns of the rows from where ``f`` is, parsed in blocks into preallocated
    float64 arrays (:func:`hystcli.read_csv_blocks`) and scaled in place; None at any doubt."""
    import pandas as pd  # here: the command line's start-up must not pay for pandas

    use = sorted({j for _, j in resolved})
    # the numbers float() reads (_parse_table's): pandas 3's parser rounds correctly, 2's only so asked
    exact = {} if int(pd.__version__.split(".")[0]) >= 3 else {"float_precision": "round_trip"}
    values = read_csv_blocks(f, use, lines, size, progress, usecols=use, encoding=encoding,
                                sep=r"\s+" if sep is None else sep, quoting=csv.QUOTE_NONE, **exact)
    if values is None or not all(np.isfinite(v).all() for v in values.values()):
        return None
    uses = [j for _, j in resolved]
    cols: dict[str, np.ndarray] = {}
    for c, j in resolved:
        v = values[j]
        if uses.count(j) > 1:
            v = v * c.factor + c.offset
        else:  # in place: the array is this reader's and nothing else reads it
            v *= c.factor
            v += c.offset
        # an import shifts time to start at 0, so only a run's own time must be small already
        if (c.target != "t" or mapping.as_run) and np.any(np.abs(v) > MAX_ABS_VALUE):
            return None
        cols[c.target] = v
    return cols


def _time(cols: dict[str, np.ndarray], linenos: Sequence[int], mapping: ImportMapping, repair: str,
          source: str) -> tuple[dict[str, np.ndarray], int]:
    n = len(linenos)
    if "t" not in cols:
        cols = dict(cols, t=np.arange(n) / float(mapping.rate))
        return cols, 0
    t = cols["t"]
    dt = np.diff(t)
    bad = np.flatnonzero(~(dt > 0))
    if bad.size == 0:
        return cols, 0
    if repair == "error":
        j = int(bad[0]) + 1
        what = "repeats" if t[j] == t[j - 1] else "goes back"
        hint = "hyst check lists every problem" if mapping.as_run else "use --time-repair drop to drop such rows"
        raise DataError(f"{source}: time {what} at line {linenos[j]} ({float(t[j - 1])!r} then {float(t[j])!r}; "
                        f"{bad.size} non-increasing steps in all): {hint}")
    # keep a row only when it is later than every row kept before it
    keep = t > np.concatenate(([-np.inf], np.maximum.accumulate(t)[:-1]))
    return {k: v[keep] for k, v in cols.items()}, int(n - keep.sum())


def resample(run_cols: Mapping[str, np.ndarray], rate: float) -> tuple[dict[str, np.ndarray], bool]:
    """Columns on a uniform grid of ``rate`` Hz from the first to the last time stamp.

    Linear interpolation; when ``rate`` is below the source's median rate, every column is first
    low-passed (zero-phase 3rd-order Butterworth, cut-off :data:`ANTI_ALIAS_FRACTION` x ``rate``)
    so that noise above the new Nyquist frequency does not fold into the band.

    Returns
    -------
    columns : dict of str to numpy.ndarray
    anti_aliased : bool
    """
    t = np.asarray(run_cols["t"], dtype=float)
    if t.size < 2:
        raise DataError("cannot resample fewer than 2 samples")
    fs = 1.0 / float(np.median(np.diff(t)))
    n = int(math.floor((t[-1] - t[0]) * rate + 1e-9)) + 1
    grid = t[0] + np.arange(n) / rate
    aa = rate < fs * (1 - 1e-9)
    out = {"t": grid}
    for k, v in run_cols.items():
        if k == "t":
            continue
        x = np.asarray(v, dtype=float)
        if aa:
            x = lowpass(x, fs, cutoff=ANTI_ALIAS_FRACTION * rate)
        out[k] = np.interp(grid, t, x)
    return out, aa


def _gain_drift(q: np.ndarray, y: np.ndarray, t: np.ndarray) -> tuple[float, float]:
    """Least squares ``y ~ gain*q + b + drift*(t - t0)``: (gain, drift).

    Through the centred 2x2 normal equations, summed a block at a time: no copy of a column of
    the log's length, where lstsq's n x 3 matrix and its copies held 150 MB more at the peak of
    a 2M-row import. The
    normal equations square the problem's condition: they are used while the centred knob angle
    and time are far from collinear (1 - correlation^2 above 1e-4, where they agree with lstsq to
    about 1e-12; a sweep's sine against time is near 1), lstsq beyond (a knob that moves almost
    in step with time)."""
    means = (q.mean(), t.mean(), y.mean())
    sums = np.zeros(5)   # qq, qt, tt, qy, ty of the centred columns, a block at a time
    for i in range(0, q.size, 1 << 20):
        qc, tc, yc = (x[i:i + (1 << 20)] - m for x, m in zip((q, t, y), means))
        sums += (qc @ qc, qc @ tc, tc @ tc, qc @ yc, tc @ yc)
    qq, qt, tt, qy, ty = sums
    if qq * tt - qt ** 2 <= 1e-4 * qq * tt:
        a = np.column_stack([q, np.ones_like(q), t - t[0]])
        coef, *_ = np.linalg.lstsq(a, y, rcond=None)
        return float(coef[0]), float(coef[2])
    gain, drift = np.linalg.solve([[qq, qt], [qt, tt]], [qy, ty])
    return float(gain), float(drift)


def _render_meta(meta: dict[str, str], found: Mapping[str, str], source: str,
                 missing: list[str] | None = None) -> dict[str, str]:
    """Fill ``{key}`` templates from ``found``; an unknown key is an error, or, with ``missing``
    given, a note in it and the key left out (a mapping's defaults must not stop an import)."""
    out = {}
    for k, v in meta.items():
        if "{" in v:
            try:
                v = v.format_map(dict(found))
            except KeyError as exc:
                msg = f"metadata {k}={v!r} refers to {{{exc.args[0]}}}, which no header pattern found"
                if missing is not None:
                    missing.append(msg + f"; {k} left out")
                    continue
                raise DataError(f"{source}: {msg}") from None
            except (ValueError, IndexError):
                raise DataError(f"{source}: metadata {k}={v!r}: bad {{}} template (write {{{{ for a brace)") from None
        out[k] = v
    return out


def _round(x: np.ndarray, decimals: int | None) -> np.ndarray:
    if decimals is None:
        return x
    r = np.round(x, decimals)
    return r + 0.0  # no "-0.0" in the file
