"""Foreign logs to run CSVs: column mappings, presets, and the conditioning real data needs.

This module owns ``hyst import`` and the ``--columns`` option of the other commands
(docs/import.md holds the user's view). A *mapping* (:class:`ImportMapping`) says how to read one
logger's text files: separator, comment prefix, header lines to skip, which column (by its name
in the header row, or its number from 1) becomes which run column (``t``, ``q1`` ... ``r2`` of
docs/design.md section 6) in which unit or with ``value = raw * scale + offset``, and where the
metadata comes from (fixed values, regular expressions over the header lines, and over a
``README`` beside the file). The separator, the comment lines and the header row may be left to
the file itself (``auto``: :func:`split_table`). A *preset* is a named, built-in mapping
(:data:`PRESETS`; ``mrdlab`` for the MRDLab EndoWrist data set,
``sample_data/real/PROVENANCE.md``). ``--columns`` (:func:`columns_mapping`, :func:`read_mapped`)
reads a user's own CSV as a run without writing one.

What real hardware logs need, learnt from that data set and handled here, not by hand-editing:

- incremental encoders, whose zero is arbitrary: ``zero`` = ``none`` (default) / ``first`` /
  ``mean`` subtracts nothing, the first sample, or the mean of each input and output column. The
  default is ``none`` because the offset between runs of one session is information (the hysteresis
  shift of docs/design.md section 3 *is* an offset; on the MRDLab data the flipped jaw angle rises by
  about 1 deg per 10 % of load torque as the cable stretches: the ``stretch`` effect, driven by
  the ``condition`` metadata the preset sets to the load), and the model absorbs any constant
  zero anyway (its ``offset`` and heights). Use ``mean`` when every file was recorded after a
  fresh encoder reset;
- the sign of the gain: the least-squares slope of output on input is reported; a negative gain
  (the model needs the output to rise with the input) is a warning unless ``flip_output`` negates
  the output (and reference) columns;
- non-increasing time stamps: an error naming the line, or with ``time_repair="drop"`` the rows
  whose time is not later than the last kept row are dropped (the first of duplicates kept) and
  counted in the report. Time is shifted to start at 0;
- different sampling rates: ``resample`` interpolates every column linearly onto a uniform grid,
  after a zero-phase Butterworth anti-alias low-pass at 0.4 x the new rate when it is lower;
- drift: the output's drift (deg/s, a least-squares ``y ~ gain*q + b + drift*t``) is reported;
  ``detrend`` removes it. Off by default: slow creep is an effect the diagnosis should see
  (docs/design.md section 8), not something to erase silently.

Everything that was done (rows, rate, ranges, zeroing, flips, drops, drift) comes back in an
:class:`ImportReport` beside the converted :class:`~hystcli.Run`.
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Iterable, Mapping, Sequence

import numpy as np

from ..core.run import Run
from ..errors import DataError
from .mapping import (ANGLE_UNITS, ANTI_ALIAS_FRACTION, AUTO, COMMENT_PREFIXES, CURRENT_UNIT, CURRENT_UNITS,
                      IRREGULAR, MAPPING_FORMAT, MAPPING_VERSION, MAP_SYNTAX, MRDLAB, PRESETS, TARGETS, TIME_REPAIRS,
                      TIME_UNITS, ZERO_MODES, ColumnMap, ImportMapping, MetaPattern, _unit, get_preset, load_mapping,
                      mapping_from_dict, mapping_to_dict, parse_map_spec, parse_meta_option, parse_meta_pattern,
                      parse_number, parse_separator, unit_names)
from .reading import (SNIFF_LINES, Layout, _gain_drift, _parse_table, _readme_lines, _render_meta, _round,
                      _table_fast, _time, read_text, resample, resolve_columns, sniff_separator, split_table)
from .runs import _parse_meta_line as _meta_line


# --------------------------------------------------------------------------------------------
# options and report
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class ImportOptions:
    """Conditioning applied after the mapping (module docstring says why each exists).

    Attributes
    ----------
    zero : {"none", "first", "mean"}
        Subtract nothing, the first sample, or the mean of each ``q`` and ``y`` column (``r``
        moves with its knob's ``y``).
    flip_output : bool or None
        Negate ``y`` and ``r``; None keeps the mapping's choice.
    resample : float or None
        New uniform sample rate (Hz).
    detrend : bool
        Remove the output's linear drift (estimated jointly with a static gain on the input).
    time_repair : {"error", "drop"}
        What to do with non-increasing time stamps.
    decimals : int or None
        Round every value to this many decimals (in the run's units) to keep files small.
    meta : mapping of str to str
        Extra metadata (wins over the mapping's and the header's).
    zero_time : bool
        Shift time to start at 0 (an import); False keeps the file's time (``--columns``).
    """

    zero: str = "none"
    flip_output: bool | None = None
    resample: float | None = None
    detrend: bool = False
    time_repair: str = "error"
    decimals: int | None = None
    meta: Mapping[str, str] = field(default_factory=dict)
    zero_time: bool = True

    def __post_init__(self) -> None:
        if self.zero not in ZERO_MODES:
            raise DataError(f"zero must be one of {', '.join(ZERO_MODES)}, got {self.zero!r}")
        if self.time_repair not in TIME_REPAIRS:
            raise DataError(f"time repair must be one of {', '.join(TIME_REPAIRS)}, got {self.time_repair!r}")
        if self.resample is not None and not (math.isfinite(self.resample) and self.resample > 0):
            raise DataError(f"resample rate must be a positive number of Hz, got {self.resample!r}")
        if self.decimals is not None and not (0 <= self.decimals <= 15):
            raise DataError(f"decimals must be between 0 and 15, got {self.decimals!r}")


@dataclass(frozen=True)
class KnobReport:
    """What the import learnt of one knob's input/output pair.

    Attributes
    ----------
    knob : int
    gain : float or None
        Least-squares slope of ``y`` on ``q`` as read, before any flip (None without ``y``).
    flipped : bool
        Whether ``y`` (and ``r``) were negated.
    drift : float or None
        Drift of the output (deg/s; after the flip), jointly fitted with the static gain.
    detrended : bool
    zero : dict of str to float
        Value subtracted from each zeroed column.
    """

    knob: int
    gain: float | None
    flipped: bool
    drift: float | None
    detrended: bool
    zero: dict[str, float]


@dataclass(frozen=True)
class ImportReport:
    """Everything :func:`convert` did to one file.

    Attributes
    ----------
    source : str
    mapping : str
        Preset or mapping name.
    rows_read, rows_dropped, rows_out : int
    rate_in, rate_out : float
        Median sample rates (Hz) before and after resampling.
    irregular : bool
        Whether the input's steps vary by more than 50 % around the median.
    duration : float
        Length of the output (s).
    t_start : float
        Time of the first raw sample (the output starts at 0).
    ranges : dict of str to (float, float)
        Min and max of every output column.
    knobs : tuple of KnobReport
    resampled, anti_aliased : bool
    warnings : tuple of str
    """

    source: str
    mapping: str
    rows_read: int
    rows_dropped: int
    rows_out: int
    rate_in: float
    rate_out: float
    irregular: bool
    duration: float
    t_start: float
    ranges: dict[str, tuple[float, float]]
    knobs: tuple[KnobReport, ...]
    resampled: bool
    anti_aliased: bool
    warnings: tuple[str, ...]

    def to_dict(self) -> dict:
        """JSON-ready form."""
        return {
            "source": self.source, "mapping": self.mapping, "rows_read": self.rows_read,
            "rows_dropped": self.rows_dropped, "rows_out": self.rows_out, "rate_in": self.rate_in,
            "rate_out": self.rate_out, "irregular": self.irregular, "duration": self.duration,
            "t_start": self.t_start, "ranges": {k: list(v) for k, v in self.ranges.items()},
            "knobs": [{"knob": k.knob, "gain": k.gain, "flipped": k.flipped, "drift": k.drift,
                       "detrended": k.detrended, "zero": k.zero} for k in self.knobs],
            "resampled": self.resampled, "anti_aliased": self.anti_aliased, "warnings": list(self.warnings),
        }


@dataclass(frozen=True)
class Imported:
    """A converted file: the run and the report of what was done."""

    run: Run
    report: ImportReport


# --------------------------------------------------------------------------------------------
# conversion
# --------------------------------------------------------------------------------------------
def convert_text(text: str, mapping: ImportMapping, options: ImportOptions = ImportOptions(),
                 source: str = "<log>", readme: Sequence[str] = ()) -> Imported:
    """Convert the text of one raw log (see :func:`convert`)."""
    return _convert(_parse_table(text, mapping, source), mapping, options, source, readme)


def _convert(table: tuple[Layout, dict[str, ColumnMap], dict[str, np.ndarray]], mapping: ImportMapping,
             options: ImportOptions, source: str, readme: Sequence[str]) -> Imported:
    layout, maps, cols = table
    header, linenos = list(layout.header), layout.linenos
    rows_read = len(linenos)
    cols, dropped = _time(cols, linenos, mapping, options.time_repair, source)
    warnings: list[str] = []
    if dropped:
        warnings.append(f"dropped {dropped} rows whose time did not increase")
    n = cols["t"].size
    if n < 2:
        raise DataError(f"{source}: only {n} data row(s); a run needs at least 2")
    t_start = float(cols["t"][0])
    if options.zero_time:
        cols["t"] = cols["t"] - t_start
    steps = np.diff(cols["t"])
    med = float(np.median(steps))
    rate_in = 1.0 / med
    irregular = bool(steps.max() > IRREGULAR * med or steps.min() < med / IRREGULAR)
    step_range = (float(steps.min()), float(steps.max()))
    del steps  # a big log's columns are the memory: no copy of one kept longer than needed
    if irregular and options.resample is None:
        warnings.append(f"irregular sampling (steps {step_range[0]:.6g} .. {step_range[1]:.6g} s around "
                        f"{med:.6g} s): {'hyst import ' if mapping.as_run else ''}--resample HZ puts it on a "
                        "uniform grid")

    flip = mapping.flip_output if options.flip_output is None else options.flip_output
    knobs = sorted({int(k[1]) for k in cols if k[0] in "qyr" and len(k) == 2})
    gains: dict[int, float | None] = {}
    for k in knobs:
        q, y = cols.get(f"q{k}"), cols.get(f"y{k}")
        gains[k] = None
        if q is not None and y is not None and np.ptp(q) > 0:
            gains[k] = _gain_drift(q, y, cols["t"])[0]
    if flip:
        for name in list(cols):
            if name[0] in "yr":
                cols[name] = -cols[name]

    anti_aliased = False
    if options.resample is not None:
        cols, anti_aliased = resample(cols, float(options.resample))
        if cols["t"].size < 2:
            raise DataError(f"{source}: resampling at {options.resample} Hz leaves fewer than 2 samples")

    knob_reports = []
    for k in knobs:
        q, y = cols.get(f"q{k}"), cols.get(f"y{k}")
        drift = None
        if q is not None and y is not None and np.ptp(q) > 0:
            _, drift = _gain_drift(q, y, cols["t"])
            if options.detrend:
                trend = drift * (cols["t"] - cols["t"][0])
                cols[f"y{k}"] = y - trend
                if f"r{k}" in cols:
                    cols[f"r{k}"] = cols[f"r{k}"] - trend
        zero: dict[str, float] = {}
        if options.zero != "none":
            for name in (f"q{k}", f"y{k}"):
                if name in cols:
                    v = cols[name]
                    zero[name] = float(v[0] if options.zero == "first" else v.mean())
                    cols[name] = v - zero[name]
            if f"r{k}" in cols and f"y{k}" in zero:
                cols[f"r{k}"] = cols[f"r{k}"] - zero[f"y{k}"]
        g = gains[k]
        if g is not None and (-g if flip else g) < 0:
            warnings.append(f"knob {k}: the output falls as the input rises (gain {g:.3g}); the hysteresis "
                            "model needs a rising output: "
                            + (f"negate it, y{k}=NAME:-1" if mapping.as_run else "use --flip-output"))
        knob_reports.append(KnobReport(k, g, bool(flip and (f"y{k}" in cols or f"r{k}" in cols)),
                                       drift, bool(options.detrend and drift is not None), zero))

    found: dict[str, str] = {}
    if mapping.as_run:  # a run CSV's own metadata lines
        found.update(kv for kv in map(_meta_line, header) if kv is not None)
    for pat in mapping.meta_from_header:
        hit = pat.search(header)
        if not hit:
            warnings.append(f"header pattern {pat.regex!r} matched no header line")
        found.update(hit)
    for pat in mapping.meta_from_readme:
        hit = pat.search(readme)
        if not hit and readme:
            warnings.append(f"README pattern {pat.regex!r} matched nothing")
        found.update(hit)
    # precedence: --meta options > what the file says > the mapping's fixed values; the mapping's
    # keys come first in the file (catheter, motion ... before the details)
    meta = _render_meta(dict(mapping.meta), found, source, missing=warnings)
    meta.update(found)
    meta.update(_render_meta({str(k): str(v) for k, v in options.meta.items()}, found, source))
    meta.setdefault("source_file", Path(source).name)

    # motor current in mA, the unit of a run (docs/design.md section 6), from the unit the mapping
    # or else the log states
    currents = [n for n in cols if n[0] == "c"]
    unstated = [n for n in currents if maps.get(n) is None or maps[n].unit is None]
    unit = meta.get("current_unit", CURRENT_UNIT)
    if "current_unit" not in meta and unstated:
        warnings.append(f"the log states no current unit: the current is taken to be in {CURRENT_UNIT} "
                        f"(--meta current_unit=A or {unstated[0]}=COLUMN:A if it is in amperes)")
    if unit not in CURRENT_UNITS:
        raise DataError(f"{source}: current_unit {unit!r} is not one of {', '.join(CURRENT_UNITS)} "
                        "(state the log's current unit with --meta current_unit=A, mA or uA)")
    to_ma = CURRENT_UNITS[unit]
    if currents:
        meta["current_unit"] = CURRENT_UNIT
    for name in unstated:
        # rounded in the log's unit first: --decimals keeps the resolution the log's unit gives
        # (4 decimals of A stay 0.1 mA, not 1e-4 mA), then again so x1000 leaves no float dust
        cols[name] = _round(_round(cols[name], options.decimals) * to_ma, options.decimals)

    # the run's column order of docs/design.md section 6, whatever the mapping's order
    ordered = {name: _round(cols[name], options.decimals) for name in TARGETS if name in cols}
    if options.decimals is not None and not np.all(np.diff(ordered["t"]) > 0):
        raise DataError(f"{source}: {options.decimals} decimals are too few for the time step "
                        f"({1.0 / (options.resample or rate_in):.3g} s)")
    current = (unit, to_ma) if unstated else None
    meta["import"] = _import_note(mapping, flip, options, knob_reports, dropped, anti_aliased, current)
    for values in ordered.values():
        values.setflags(write=False)  # the conversion's own arrays: the run shares them, no copy
    run = Run(ordered, meta, source)

    tt = run["t"]
    report = ImportReport(
        source=source, mapping=mapping.name, rows_read=int(rows_read), rows_dropped=int(dropped),
        rows_out=len(run), rate_in=rate_in, rate_out=float(1.0 / np.median(np.diff(tt))),
        irregular=irregular, duration=float(tt[-1] - tt[0]), t_start=t_start,
        ranges={k: (float(v.min()), float(v.max())) for k, v in run.columns.items()},
        knobs=tuple(knob_reports), resampled=options.resample is not None, anti_aliased=anti_aliased,
        warnings=tuple(warnings),
    )
    return Imported(run, report)


def _import_note(mapping: ImportMapping, flip: bool, options: ImportOptions, knobs: Sequence[KnobReport],
                 dropped: int, anti_aliased: bool, current: tuple[str, float] | None = None) -> str:
    """One metadata line saying how the file was converted, so the run explains itself."""
    parts = [f"mapping {mapping.name} ({' '.join(c.spec() for c in mapping.columns)})"]
    if current is not None and current[1] != 1.0:
        parts.append(f"current in {current[0]} converted to {CURRENT_UNIT} (x{current[1]:g})")
    parts.append("output flipped" if flip else "output as read")
    zeros = [f"{name} {v:.6g}" for k in knobs for name, v in k.zero.items()]
    parts.append(f"zero {options.zero}" + (f" ({', '.join(zeros)} subtracted)" if zeros else ""))
    if options.resample is not None:
        parts.append(f"resampled to {options.resample:g} Hz" + (" after an anti-alias low-pass" if anti_aliased else ""))
    if options.detrend:
        parts.append("output detrended")
    if dropped:
        parts.append(f"{dropped} non-increasing time rows dropped")
    return "; ".join(parts)


def convert(path: str | os.PathLike, mapping: ImportMapping, options: ImportOptions = ImportOptions(),
            source: str | None = None, progress: Callable[[int, int], None] | None = None) -> Imported:
    """Convert one raw log file (plain text or gzip) into a run.

    Parameters
    ----------
    path : path-like
        The raw log.
    mapping : ImportMapping
        How to read it (a preset, :func:`load_mapping` or :func:`parse_map_spec`).
    options : ImportOptions
        Conditioning: zero, flip, resample, detrend, time repair, rounding, extra metadata.
    source : str, optional
        Name used in messages and in ``source_file`` (default: the path).
    progress : callable, optional
        ``progress(bytes_parsed, bytes_total)`` after each block of rows of a log of at least
        :data:`hystcli.io.runs.READ_PROGRESS_BYTES` read by the CSV parser.

    Returns
    -------
    Imported
        The run (columns in the order of docs/design.md section 6, metadata including
        ``import``: how it was made) and the :class:`ImportReport`.

    Raises
    ------
    DataError
        Unreadable, empty, binary or corrupt gzip file; a mapped column beyond a row's fields; a
        non-numeric or non-finite cell; non-increasing time (unless repaired); a metadata template
        naming a key nothing provided. The message names the file and the line.
    """
    p = Path(path)
    name = str(path) if source is None else source
    readme = _readme_lines(p) if mapping.meta_from_readme else []
    table = _table_fast(p, mapping, name, progress) if p.is_file() else None
    if table is None:   # the line reader: the whole text, every line judged and named
        table = _parse_table(read_text(p), mapping, name)
    return _convert(table, mapping, options, name, readme)


def columns_mapping(spec: str | Sequence[ColumnMap]) -> ImportMapping:
    """The mapping of ``--columns``: a user's own CSV read as a run (:func:`read_mapped`).

    Any separator and a header row are found from the file, ``#`` and ``%`` lines are comments
    (``# key: value`` ones metadata), a column the spec does not name keeps its name when it is
    already a run column's, and a current without a unit is in mA (the run's unit).

    Raises
    ------
    DataError
        A malformed spec or a target given twice.
    """
    columns = parse_map_spec(spec) if isinstance(spec, str) else tuple(spec)
    return ImportMapping(columns=columns, separator=AUTO, comment=AUTO, name="--columns",
                         meta={"current_unit": CURRENT_UNIT}, as_run=True)


def read_mapped(path: str | os.PathLike, mapping: ImportMapping, require: Iterable[str] = ("t",),
                progress: Callable[[int, int], None] | None = None) -> Imported:
    """Read a user's own CSV as a run through a one-off mapping (:func:`columns_mapping`).

    Unlike an import, time keeps its values; what an import would warn about (irregular
    sampling, a falling output) is in the report's warnings.

    Raises
    ------
    DataError
        What :func:`convert` raises, and a column in ``require`` the mapped run lacks.
    """
    imported = convert(path, mapping, ImportOptions(zero_time=False), progress=progress)
    imported.run.require(*require)
    return imported


_GUESSES = (("t", ("t", "time", "timestamp", "time_s", "t_s", "sec", "seconds")),
            ("q", ("q", "knob", "knob_deg", "knob_angle", "motor", "motor_angle", "input", "encoder")),
            ("y", ("y", "tip", "tip_deg", "tip_angle", "bend", "bending", "output")),
            ("c", ("c", "current", "current_ma", "i", "motor_current", "amps")),
            ("r", ("r", "ref", "reference", "target", "desired")))
_SUFFIX_UNITS = {"ms": "ms", "us": "us", "rad": "rad", "a": "A", "amps": "A"}


def suggest_columns(names: Sequence[str]) -> str | None:
    """A ``--columns`` spec guessed from a header row's names (``time_s`` -> ``t``, ``knob_deg`` ->
    ``q1``, ``current_A`` -> ``c1=current_A:A``), or None when no time column can be guessed.

    A guess for a message, never applied: the user reads it and types it.
    """
    found: dict[str, str] = {}
    for name in names:
        low = name.strip().lower().replace(" ", "_").replace("-", "_")
        stem, _, suffix = low.rpartition("_")
        for kind, words in _GUESSES:
            if (low in words or stem in words) and kind not in found:
                unit = _SUFFIX_UNITS.get(suffix) if stem in words else None
                if unit is not None and _unit(kind if kind == "t" else kind + "1", unit) is None:
                    unit = None
                found[kind] = f"{name}:{unit}" if unit else name
                break
    if "t" not in found:
        return None
    return ",".join(f"{k if k == 't' else k + '1'}={v}" for k, v in found.items())


def output_name(path: str | os.PathLike) -> str:
    """Run CSV name for a raw file: ``00.TXT.gz`` -> ``00.csv``."""
    name = Path(path).name
    if name.lower().endswith(".gz"):
        name = name[:-3]
    stem = name.rsplit(".", 1)[0] if "." in name.lstrip(".") else name
    return stem + ".csv"


# the import feature's surface: its own names and those of its mapping and reading modules
__all__ = ["ANGLE_UNITS", "ANTI_ALIAS_FRACTION", "AUTO", "COMMENT_PREFIXES", "CURRENT_UNIT", "CURRENT_UNITS",
           "IRREGULAR", "MAPPING_FORMAT", "MAPPING_VERSION", "MAP_SYNTAX", "MRDLAB", "PRESETS", "SNIFF_LINES", "TARGETS",
           "TIME_REPAIRS", "TIME_UNITS", "ZERO_MODES", "ColumnMap", "ImportMapping", "ImportOptions", "ImportReport",
           "Imported", "KnobReport", "Layout", "MetaPattern", "columns_mapping", "convert", "convert_text",
           "get_preset", "load_mapping", "mapping_from_dict", "mapping_to_dict", "output_name", "parse_map_spec",
           "parse_meta_option", "parse_meta_pattern", "parse_number", "parse_separator", "read_mapped", "read_text",
           "resample", "resolve_columns", "sniff_separator", "split_table", "suggest_columns", "unit_names"]
