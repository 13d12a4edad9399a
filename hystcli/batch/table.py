"""The batch's results: durable part files while it runs, one sorted table at the end.

Every finished task is written at once as one small JSON file in the parts folder
(``results.parquet.parts/<key>.json``): written to a temporary name, flushed to disk (fsync),
then renamed, so a part is whole or absent, and a Ctrl-C, a killed client or a dead worker loses
nothing already written. A rerun reads the parts folder and skips every task whose key is in it.

The table is assembled from the parts: one row per run, sorted by path, columns in a fixed
order (identity, manifest, metadata, result), types inferred from the values alone. Nothing
in it depends on which engine ran a task, in what order, or how long it took: the seconds each
task took and the worker that ran it go to a separate timing table (``results.timing.parquet``),
so that two runs of the same batch give byte-identical tables.
"""
from __future__ import annotations

import json
import os
import re
import tempfile
from pathlib import Path
from typing import Any, Iterable, Mapping, Sequence

from .. import DataError

IDENTITY = ("path", "sha256", "command", "status", "reason", "warnings", "model", "model_sha256", "key")
"""The first columns of every table, in this order; then ``manifest_*``, ``meta_*``, the result."""

TIMING = ("key", "seconds", "attempts", "worker")
"""The columns of the timing table (one row per task)."""

FORMATS = ("parquet", "csv")


def table_format(path: Path) -> str:
    """``csv`` for a ``.csv`` file, else ``parquet`` (the default)."""
    return "csv" if Path(path).suffix.lower() == ".csv" else "parquet"


def parts_dir(output: Path) -> Path:
    """Where the parts of the table ``output`` are kept (beside it: ``OUTPUT.parts``)."""
    output = Path(output)
    return output.with_name(output.name + ".parts")


def timing_path(output: Path) -> Path:
    """The timing table beside ``output`` (``results.parquet`` -> ``results.timing.parquet``)."""
    output = Path(output)
    return output.with_name(f"{output.stem}.timing{output.suffix or '.parquet'}")


def write_part(folder: Path, key: str, part: Mapping[str, Any]) -> Path:
    """Write one finished task's part durably (temporary file, fsync, rename); return its path."""
    folder.mkdir(parents=True, exist_ok=True)
    target = folder / f"{key}.json"
    fd, tmp = tempfile.mkstemp(prefix=f".{key}.", suffix=".tmp", dir=folder)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            json.dump(part, f, sort_keys=True, allow_nan=True)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, target)
    except BaseException:
        with _quiet():
            os.unlink(tmp)
        raise
    return target


class _quiet:
    def __enter__(self) -> None:
        return None

    def __exit__(self, *exc: object) -> bool:
        return exc[0] is not None and issubclass(exc[0], OSError)  # type: ignore[arg-type]


def read_parts(folder: Path) -> dict[str, dict]:
    """The parts already written, by key (a part that cannot be read is ignored: it is recomputed)."""
    out: dict[str, dict] = {}
    if not folder.is_dir():
        return out
    for p in folder.glob("*.json"):
        try:
            part = json.loads(p.read_text(encoding="utf-8"))
        except (OSError, ValueError):
            continue
        if isinstance(part, dict) and part.get("key") == p.stem:
            out[p.stem] = part
    return out


def _natural(name: str) -> tuple:
    # k2_... before k10_..., and b_neg_lo after b_neg: a stable order a reader can scan
    return tuple(int(t) if t.isdigit() else t for t in re.split(r"(\d+)", name))


def column_order(rows: Iterable[Mapping[str, Any]]) -> list[str]:
    """Identity columns, then ``manifest_*``, ``meta_*`` and result columns, each group sorted."""
    names: set[str] = set()
    for r in rows:
        names.update(r)
    rest = names - set(IDENTITY)
    manifest = sorted((n for n in rest if n.startswith("manifest_")), key=_natural)
    meta = sorted((n for n in rest if n.startswith("meta_")), key=_natural)
    result = sorted((n for n in rest if not n.startswith(("manifest_", "meta_"))), key=_natural)
    return list(IDENTITY) + manifest + meta + result


def _arrow_type(values: Sequence[Any]) -> Any:
    import pyarrow as pa

    seen = {type(v) for v in values if v is not None}
    if not seen:
        return pa.string()
    if seen == {bool}:
        return pa.bool_()
    if seen == {int}:
        return pa.int64()
    if seen <= {int, float}:
        return pa.float64()
    return pa.string()


def _cell(value: Any, typ: Any) -> Any:
    import pyarrow as pa

    if value is None:
        return None
    if typ == pa.float64():
        return float(value)
    if typ == pa.string() and not isinstance(value, str):
        return json.dumps(value) if isinstance(value, (list, dict)) else str(value)
    return value


def arrow_table(rows: Sequence[Mapping[str, Any]], columns: Sequence[str] | None = None) -> Any:
    """The rows as a pyarrow Table, in the order given, columns in :func:`column_order`."""
    import pyarrow as pa

    columns = list(columns) if columns is not None else column_order(rows)
    arrays = {}
    for name in columns:
        values = [r.get(name) for r in rows]
        typ = _arrow_type(values)
        arrays[name] = pa.array([_cell(v, typ) for v in values], type=typ)
    return pa.table(arrays)


def write_table(table: Any, path: Path) -> None:
    """Write a pyarrow Table to ``path`` (Parquet, or CSV for a ``.csv`` name) atomically.

    The same table gives the same bytes: no time stamp, no pandas metadata, one row group.
    """
    import pyarrow.csv as pacsv
    import pyarrow.parquet as pq

    path = Path(path)
    folder = path.parent if str(path.parent) else Path(".")
    if not folder.is_dir():
        raise DataError(f"{path}: the folder {folder} does not exist")
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=folder)
    os.close(fd)
    try:
        if table_format(path) == "csv":
            pacsv.write_csv(table, tmp)
        else:
            pq.write_table(table, tmp, compression="zstd", row_group_size=max(1, table.num_rows))
        with open(tmp, "rb+") as f:
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        with _quiet():
            os.unlink(tmp)
        raise


def read_table(path: Path) -> Any:
    """A results table (Parquet or CSV) as a pandas DataFrame.

    Raises
    ------
    DataError
        No such file, or not a table ``hyst batch`` wrote (no ``path`` and ``status`` columns).
    """
    path = Path(path)
    if not path.is_file():
        raise DataError(f"{path}: no such file")
    try:
        if table_format(path) == "csv":
            import pyarrow.csv as pacsv

            df = pacsv.read_csv(path).to_pandas()
        else:
            import pyarrow.parquet as pq

            df = pq.read_table(path).to_pandas()
    except Exception as exc:  # pyarrow's errors are many kinds; the user needs one line
        raise DataError(f"{path}: not a readable results table ({str(exc).splitlines()[0]})") from None
    missing = [c for c in ("path", "status") if c not in df.columns]
    if missing:
        raise DataError(f"{path}: not a hyst batch table (no column {missing[0]!r})")
    return df
