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
:class:`ImportReport` beside the converted :class:`~hystcli.io.Run`.
"""
from __future__ import annotations

import codecs
import csv
import difflib
import gzip
import json
import math
import os
import re
import zlib
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import BinaryIO, Callable, Iterable, Mapping, Sequence

import numpy as np

from .errors import DataError
from .filters import lowpass
from . import io
from .io import KNOWN_COLUMNS, MAX_ABS_VALUE, Run, odd_line_breaks
from .io import _parse_meta_line as _meta_line

TARGETS = KNOWN_COLUMNS
"""Run columns a mapping may fill (docs/design.md section 6)."""

ZERO_MODES = ("none", "first", "mean")
TIME_REPAIRS = ("error", "drop")
MAPPING_FORMAT = "hyst-import"
MAPPING_VERSION = 1

ANTI_ALIAS_FRACTION = 0.4
"""Anti-alias cut-off of :func:`resample` as a fraction of the new sample rate."""

IRREGULAR = 1.5
"""A time step longer than this many median steps (or shorter than the median over it) makes the
sampling irregular."""

AUTO = "auto"
"""A mapping's ``separator`` or ``comment`` found from the file itself."""

COMMENT_PREFIXES = ("#", "%")
"""Comment prefixes an ``auto`` comment setting recognises."""
_KEY_RE = re.compile(r"^[A-Za-z_][A-Za-z0-9_.-]*$")


# --------------------------------------------------------------------------------------------
# mappings
# --------------------------------------------------------------------------------------------
TIME_UNITS = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "min": 60.0}
"""Time units a mapping may name, with the factor to s (the unit of a run's ``t``)."""

ANGLE_UNITS = {"deg": 1.0, "rad": 180.0 / math.pi, "rev": 360.0}
"""Angle units a mapping may name, with the factor to deg (the unit of ``q``, ``y`` and ``r``)."""

CURRENT_UNIT = "mA"
"""The unit of a run's current columns ``c<k>`` (docs/design.md section 6)."""

CURRENT_UNITS = {"A": 1000.0, "mA": 1.0, "uA": 1e-3}
"""Current units a log may state (metadata ``current_unit``, or a mapping's unit), with the factor to
mA; a log that states none is taken to be in mA."""

_UNITS = {"t": ("time", TIME_UNITS), "q": ("angle", ANGLE_UNITS), "y": ("angle", ANGLE_UNITS),
          "r": ("angle", ANGLE_UNITS), "c": ("current", CURRENT_UNITS)}


def unit_names() -> str:
    """The units of every kind of run column, for messages: ``t: s, ms, ...; q/y/r: deg, ...``."""
    return (f"t: {', '.join(TIME_UNITS)}; q/y/r: {', '.join(ANGLE_UNITS)}; "
            f"c: {', '.join(CURRENT_UNITS)}")


def _unit(target: str, name: str) -> tuple[str, float] | None:
    """The canonical name and the factor of unit ``name`` for ``target``'s kind (case aside: ``a``
    is ``A``), or None when it is no unit of that kind."""
    kind, table = _UNITS[target[0]]
    return next(((u, f) for u, f in table.items() if u.lower() == name.strip().lower()), None)


@dataclass(frozen=True)
class ColumnMap:
    """One run column from one raw column: ``value = raw * scale + offset``, or with a unit
    ``value = raw * (the unit's factor) + offset``.

    Attributes
    ----------
    target : str
        Run column name (one of :data:`TARGETS`).
    column : int or str
        1-based column number in the raw file, or the column's name in its header row.
    scale, offset : float
        Linear conversion to the run's units (deg, s, mA).
    unit : str or None
        The raw column's unit (:func:`unit_names`), converted to the run's unit: ``ms`` to s,
        ``rad`` to deg, ``A`` to mA. None: the column is in the run's unit, or (a current) in the
        unit the log's ``current_unit`` metadata states.
    """

    target: str
    column: int | str
    scale: float = 1.0
    offset: float = 0.0
    unit: str | None = None

    def __post_init__(self) -> None:
        if self.target not in TARGETS:
            raise DataError(f"mapping: unknown target column {self.target!r} "
                            f"(targets: {', '.join(TARGETS)})")
        if isinstance(self.column, str):
            if not self.column.strip():
                raise DataError(f"mapping: {self.target}: empty column name")
            object.__setattr__(self, "column", self.column.strip())
        elif isinstance(self.column, bool) or not isinstance(self.column, int) or self.column < 1:
            raise DataError(f"mapping: {self.target}: column must be a number >= 1 (columns count from 1) "
                            f"or a name, got {self.column!r}")
        for name in ("scale", "offset"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise DataError(f"mapping: {self.target}: {name} must be a finite number, got {v!r}")
        if self.scale == 0:
            raise DataError(f"mapping: {self.target}: scale 0 would erase the column")
        if self.unit is not None:
            if self.scale != 1:
                raise DataError(f"mapping: {self.target}: give a unit or a scale, not both")
            unit = _unit(self.target, str(self.unit))
            if unit is None:
                kind, table = _UNITS[self.target[0]]
                raise DataError(f"mapping: {self.target}: {self.unit!r} is not a {kind} unit "
                                f"({', '.join(table)})")
            object.__setattr__(self, "unit", unit[0])

    @property
    def factor(self) -> float:
        """What a raw value is multiplied by: the scale times the unit's factor."""
        return self.scale * (1.0 if self.unit is None else _unit(self.target, self.unit)[1])

    def spec(self) -> str:
        """The ``target=column:scale[:offset]`` (or ``target=column:unit[:offset]``) form of
        :func:`parse_map_spec`."""
        s = f"{self.target}={self.column}:{self.unit if self.unit is not None else repr(self.scale)}"
        return s + (f":{self.offset!r}" if self.offset else "")


@dataclass(frozen=True)
class MetaPattern:
    """Metadata read from text by a regular expression.

    With ``key`` set, the value is the first group of the match (the whole match when the pattern
    has no group); with ``key`` None, every named group ``(?P<name>...)`` gives one key.
    """

    regex: str
    key: str | None = None

    def __post_init__(self) -> None:
        try:
            compiled = re.compile(self.regex)
        except re.error as exc:
            raise DataError(f"metadata pattern {self.regex!r} is not a valid regular expression ({exc})") from None
        if self.key is None and not compiled.groupindex:
            raise DataError(f"metadata pattern {self.regex!r} needs named groups (?P<key>...) "
                            "or the form key=REGEX")
        if self.key is not None and not _KEY_RE.match(self.key):
            raise DataError(f"metadata pattern: {self.key!r} is not a valid metadata key")

    @property
    def keys(self) -> tuple[str, ...]:
        """The metadata keys this pattern can fill."""
        return (self.key,) if self.key else tuple(re.compile(self.regex).groupindex)

    def search(self, lines: Sequence[str]) -> dict[str, str]:
        """Metadata from the first line that matches (empty when none does)."""
        rx = re.compile(self.regex)
        for line in lines:
            m = rx.search(line)
            if m is None:
                continue
            if self.key is not None:
                return {self.key: (m.group(1) if rx.groups else m.group(0)).strip()}
            return {k: v.strip() for k, v in m.groupdict().items() if v is not None}
        return {}


@dataclass(frozen=True)
class ImportMapping:
    """How to read one logger's files and turn them into runs.

    Attributes
    ----------
    columns : tuple of ColumnMap
        At most one per target; ``t`` may be absent when ``rate`` is given.
    separator : str or None
        Field separator; None splits on any whitespace; ``"auto"`` (:data:`AUTO`) finds comma,
        tab, semicolon or whitespace from the data (:func:`sniff_separator`).
    comment : str or None
        Lines starting with this prefix are header lines (searched by ``meta_from_header``);
        ``"auto"``: lines starting with any of :data:`COMMENT_PREFIXES`.
    skip : int
        Lines at the top of the file skipped before anything else (also searched for metadata).
    rate : float or None
        Sample rate (Hz) for logs without a time column: ``t = i / rate``.
    meta : mapping of str to str
        Fixed metadata; ``{key}`` in a value is replaced by metadata found in the header.
    meta_from_header : tuple of MetaPattern
        Patterns searched in the skipped and comment lines.
    meta_from_readme : tuple of MetaPattern
        Patterns searched in a ``README*`` file in the raw file's folder (case-insensitive name).
    flip_output : bool
        Negate the output (``y``) and reference (``r``) columns.
    name : str
        Preset name or where the mapping came from, for the report.
    as_run : bool
        Read the file as a run CSV in other clothes (``--columns``): its ``# key: value`` comment
        lines are metadata, and a header column already named like a run column (``t``, ``q1``
        ...) that the mapping neither fills nor reads is kept as it is. Whether there is a time
        column is then known only once the header is read.
    """

    columns: tuple[ColumnMap, ...]
    separator: str | None = ","
    comment: str | None = "#"
    skip: int = 0
    rate: float | None = None
    meta: Mapping[str, str] = field(default_factory=dict)
    meta_from_header: tuple[MetaPattern, ...] = ()
    meta_from_readme: tuple[MetaPattern, ...] = ()
    flip_output: bool = False
    name: str = "custom"
    as_run: bool = False

    def __post_init__(self) -> None:
        seen: set[str] = set()
        for c in self.columns:
            if c.target in seen:
                raise DataError(f"mapping: column {c.target} is mapped twice")
            seen.add(c.target)
        if not self.columns:
            raise DataError("mapping: no column is mapped (give --preset, --map or --mapping)")
        if "t" not in seen and self.rate is None and not self.as_run:
            raise DataError("mapping: no time column: map t=COLUMN or give the sample rate (--rate HZ)")
        if self.rate is not None and not (math.isfinite(self.rate) and self.rate > 0):
            raise DataError(f"mapping: rate must be a positive number of Hz, got {self.rate!r}")
        if isinstance(self.skip, bool) or not isinstance(self.skip, int) or self.skip < 0:
            raise DataError(f"mapping: skip must be a whole number >= 0, got {self.skip!r}")
        if self.separator is not None and (self.separator == "" or "\n" in self.separator):
            raise DataError("mapping: the separator must be a non-empty string (or whitespace)")
        if self.comment is not None and self.comment == "":
            raise DataError("mapping: the comment prefix must not be empty")
        for k in self.meta:
            if not _KEY_RE.match(str(k)):
                raise DataError(f"mapping: {k!r} is not a valid metadata key")
        object.__setattr__(self, "meta", {str(k): str(v) for k, v in self.meta.items()})

    def column(self, target: str) -> ColumnMap | None:
        """The mapping of one target, if any."""
        return next((c for c in self.columns if c.target == target), None)

    def with_columns(self, extra: Iterable[ColumnMap]) -> "ImportMapping":
        """A copy where ``extra`` replaces (per target) or adds column mappings."""
        cols = {c.target: c for c in self.columns}
        for c in extra:
            cols[c.target] = c
        return replace(self, columns=tuple(cols.values()))


def parse_number(text: str, what: str) -> float:
    """A finite number, written as a decimal or a fraction ``a/b`` (e.g. ``360/8192``)."""
    s = str(text).strip()
    try:
        if "/" in s:
            num, den = s.split("/", 1)
            v = float(num) / float(den)
        else:
            v = float(s)
    except (ValueError, ZeroDivisionError):
        raise DataError(f"{what}: {text!r} is not a number") from None
    if not math.isfinite(v):
        raise DataError(f"{what}: {text!r} is not a finite number")
    return v


MAP_SYNTAX = "target=column[:scale|unit[:offset]]"
"""The form of one ``--map`` / ``--columns`` item (:func:`parse_map_spec`)."""


def parse_map_spec(spec: str) -> tuple[ColumnMap, ...]:
    """Parse ``t=time_ms:ms,q1=knob:rad,y1=tip_deg,c1=I:A`` or ``t=1:0.001,q1=2:360/8192,c1=4``.

    Each item is ``target=column[:scale|unit[:offset]]``. ``column`` is the column's name in the
    file's header row, or its number counting from 1. The second part is a unit (``ms`` ->
    s, ``rad`` -> deg, ``A`` -> mA; :func:`unit_names`) or a scale (default 1; a fraction such as
    ``360/8192`` is fine), and the third an offset in the run's unit (default 0): ``value = raw
    * scale + offset``. A name cannot contain ``,``, ``=`` or ``:``.
    """
    out = []
    for item in (s.strip() for s in str(spec).split(",")):
        if not item:
            continue
        if "=" not in item:
            raise DataError(f"mapping {item!r}: expected {MAP_SYNTAX}")
        target, _, rhs = item.partition("=")
        target = target.strip()
        parts = [p.strip() for p in rhs.split(":")]
        if len(parts) > 3 or not parts[0]:
            raise DataError(f"mapping {item!r}: expected {MAP_SYNTAX}")
        col: int | str = int(parts[0]) if parts[0].lstrip("+-").isdigit() else parts[0]
        scale, unit = 1.0, None
        if len(parts) > 1 and parts[1]:
            if target in TARGETS and _unit(target, parts[1]) is not None:
                unit = parts[1]
            else:
                try:
                    scale = parse_number(parts[1], f"mapping {item!r} scale")
                except DataError:
                    if not parts[1].isalpha() or parts[1].lower() in ("inf", "infinity", "nan"):
                        raise
                    kind = _UNITS[target[0]][0] if target in TARGETS else None
                    what = "a unit" if kind is None else f"{'an' if kind == 'angle' else 'a'} {kind} unit"
                    raise DataError(f"mapping {item!r}: {parts[1]!r} is not a number or {what} "
                                    f"({unit_names()})") from None
        offset = parse_number(parts[2], f"mapping {item!r} offset") if len(parts) > 2 and parts[2] else 0.0
        out.append(ColumnMap(target, col, scale, offset, unit))
    if not out:
        raise DataError(f"mapping {spec!r}: no column given")
    return tuple(out)


def parse_meta_pattern(text: str) -> MetaPattern:
    """``key=REGEX`` (value = first group) or a bare REGEX with named groups."""
    m = re.match(r"^([A-Za-z_][A-Za-z0-9_.-]*)=(.+)$", str(text), re.S)
    if m and not str(text).startswith("(?"):
        return MetaPattern(m.group(2), m.group(1))
    return MetaPattern(str(text))


def parse_meta_option(text: str) -> tuple[str, str]:
    """``key=value`` of ``--meta``."""
    key, sep, value = str(text).partition("=")
    key = key.strip()
    if not sep or not _KEY_RE.match(key):
        raise DataError(f"metadata {text!r}: expected key=value (key of letters, digits, _ . -)")
    return key, value.strip()


def parse_separator(value: object) -> str | None:
    """A separator option: a string, or 'tab', 'comma', 'semicolon', 'whitespace' (None: any
    whitespace), or 'auto' (found from the data)."""
    if value is None:
        return None
    s = str(value)
    named = {"whitespace": None, "space": None, " ": None, "tab": "\t", "\\t": "\t",
             "comma": ",", "semicolon": ";", AUTO: AUTO}
    return named.get(s.lower() if s.strip() else s, s)


def _patterns(value: object, where: str) -> tuple[MetaPattern, ...]:
    if value is None:
        return ()
    if isinstance(value, dict):
        out = []
        for k, v in value.items():
            if not isinstance(v, str):
                raise DataError(f"{where}: the pattern of {k!r} must be a string")
            out.append(MetaPattern(v, str(k)))
        return tuple(out)
    if isinstance(value, list) and all(isinstance(v, str) for v in value):
        return tuple(parse_meta_pattern(v) for v in value)
    raise DataError(f"{where}: expected an object {{key: regex}} or a list of regex strings")


_MAPPING_KEYS = {"format", "version", "name", "columns", "separator", "comment", "skip", "rate", "meta",
                 "meta_from_header", "meta_from_readme", "flip_output"}


def mapping_from_dict(data: object, source: str = "<mapping>") -> ImportMapping:
    """Build an :class:`ImportMapping` from the JSON form documented in docs/import.md."""
    if not isinstance(data, dict):
        raise DataError(f"{source}: a mapping must be a JSON object")
    unknown = sorted(set(data) - _MAPPING_KEYS)
    if unknown:
        raise DataError(f"{source}: unknown key {unknown[0]!r} (keys: {', '.join(sorted(_MAPPING_KEYS))})")
    if data.get("format", MAPPING_FORMAT) != MAPPING_FORMAT:
        raise DataError(f"{source}: \"format\" must be {MAPPING_FORMAT!r}, got {data.get('format')!r}")
    if data.get("version", MAPPING_VERSION) != MAPPING_VERSION:
        raise DataError(f"{source}: unknown mapping version {data.get('version')!r} "
                        f"(this hyst reads version {MAPPING_VERSION})")
    cols_raw = data.get("columns")
    if not isinstance(cols_raw, dict) or not cols_raw:
        raise DataError(f"{source}: \"columns\" must be an object such as {{\"t\": 1, \"q1\": {{\"column\": 2, "
                        f"\"scale\": \"360/8192\"}}}}")
    cols = []
    try:
        for target, v in cols_raw.items():
            if isinstance(v, (int, str)) and not isinstance(v, bool):
                cols.append(ColumnMap(target, v))
                continue
            if not isinstance(v, dict) or "column" not in v:
                raise DataError(f"mapping: {target}: expected a column number or name, or {{\"column\": N, "
                                f"\"scale\": S, \"offset\": O}} or {{\"column\": N, \"unit\": U}}")
            bad = sorted(set(v) - {"column", "scale", "offset", "unit"})
            if bad:
                raise DataError(f"mapping: {target}: unknown key {bad[0]!r}")
            num = {}
            for name in ("scale", "offset"):
                if name in v:
                    x = v[name]
                    num[name] = (parse_number(x, f"mapping: {target}: {name}") if isinstance(x, str) else x)
            cols.append(ColumnMap(target, v["column"], unit=v.get("unit"), **num))
        meta = data.get("meta") or {}
        if not isinstance(meta, dict) or not all(isinstance(x, (str, int, float)) for x in meta.values()):
            raise DataError("mapping: \"meta\" must be an object of strings")
        rate = data.get("rate")
        if rate is not None and (isinstance(rate, bool) or not isinstance(rate, (int, float))):
            raise DataError(f"mapping: rate must be a number of Hz, got {rate!r}")
        flip = data.get("flip_output", False)
        if not isinstance(flip, bool):
            raise DataError(f"mapping: flip_output must be true or false, got {flip!r}")
        return ImportMapping(
            columns=tuple(cols),
            separator=parse_separator(data.get("separator", ",")),
            comment=data.get("comment", "#"),
            skip=data.get("skip", 0),
            rate=None if rate is None else float(rate),
            meta={str(k): str(v) for k, v in meta.items()},
            meta_from_header=_patterns(data.get("meta_from_header"), "mapping: meta_from_header"),
            meta_from_readme=_patterns(data.get("meta_from_readme"), "mapping: meta_from_readme"),
            flip_output=flip,
            name=str(data.get("name", Path(source).name)),
        )
    except DataError as exc:
        msg = str(exc)
        raise DataError(f"{source}: {msg[len('mapping: '):] if msg.startswith('mapping: ') else msg}") from None


def mapping_to_dict(mapping: ImportMapping) -> dict:
    """The JSON form of a mapping (``hyst import --preset mrdlab --show-mapping`` prints it)."""
    return {
        "format": MAPPING_FORMAT, "version": MAPPING_VERSION, "name": mapping.name,
        "columns": {c.target: {"column": c.column, "scale": c.scale, "offset": c.offset,
                               **({"unit": c.unit} if c.unit is not None else {})} for c in mapping.columns},
        "separator": "whitespace" if mapping.separator is None else mapping.separator,
        "comment": mapping.comment, "skip": mapping.skip, "rate": mapping.rate, "meta": dict(mapping.meta),
        "meta_from_header": [p.regex if p.key is None else f"{p.key}={p.regex}" for p in mapping.meta_from_header],
        "meta_from_readme": [p.regex if p.key is None else f"{p.key}={p.regex}" for p in mapping.meta_from_readme],
        "flip_output": mapping.flip_output,
    }


def load_mapping(path: str | os.PathLike) -> ImportMapping:
    """Read a mapping JSON file (docs/import.md)."""
    p = Path(path)
    if not p.is_file():
        raise DataError(f"{path}: no such mapping file")
    try:
        data = json.loads(p.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError) as exc:
        raise DataError(f"{path}: cannot read the mapping ({exc})") from None
    except json.JSONDecodeError as exc:
        raise DataError(f"{path}: not valid JSON ({exc.msg} at line {exc.lineno})") from None
    return mapping_from_dict(data, source=str(path))


# --------------------------------------------------------------------------------------------
# presets
# --------------------------------------------------------------------------------------------
MRDLAB = ImportMapping(
    name="mrdlab",
    columns=(
        # column 1 is labelled [ms] but steps by 0.001 per 1 kHz row: it is seconds
        ColumnMap("t", 1, 1.0),
        ColumnMap("q1", 2, 360.0 / 8192.0),   # back-end (input spindle) encoder, 8192 counts/rev
        ColumnMap("y1", 5, 360.0 / 4000.0),   # front-end (jaw) encoder, 4000 counts/rev
        ColumnMap("c1", 4, 1.0),              # back-end motor current in A (current_unit): written in mA
    ),
    separator=",",
    comment="%",
    meta={"catheter": "endowrist-tool{tool}", "motion": "periodic", "current_unit": "A",
          "dataset": "mrdlab"},
    meta_from_header=(
        MetaPattern(r"tool number (\d+)", "tool"),
        MetaPattern(r"Used (\w+) spindle", "spindle"),
        MetaPattern(r"with a ([0-9.]+) Hz", "frequency_hz"),
        MetaPattern(r"amplitude of ([0-9.]+) degrees", "amplitude_deg"),
        MetaPattern(r"reaction torque of ([0-9.]+) percent", "load_pct"),
        # the load is the run's condition: it drives the condition effects (stretch: the cable
        # yields to the resistive torque; docs/design.md section 8), as the shape does for a catheter
        MetaPattern(r"reaction torque of ([0-9.]+) percent", "condition"),
    ),
    meta_from_readme=(
        MetaPattern(r"pitch of ([+-]?[0-9.]+) degrees", "pitch_deg"),
        MetaPattern(r"roll of ([+-]?[0-9.]+) degrees", "roll_deg"),
    ),
    # the jaw encoder counts against the spindle (gain -0.85 .. -0.91 on all 32 files); the model
    # needs an output that rises with the input
    flip_output=True,
)

PRESETS: dict[str, ImportMapping] = {"mrdlab": MRDLAB}
"""Built-in mappings by name."""


def get_preset(name: str) -> ImportMapping:
    """A built-in mapping by name (:data:`PRESETS`)."""
    try:
        return PRESETS[name]
    except KeyError:
        raise DataError(f"unknown preset {name!r} (presets: {', '.join(PRESETS)})") from None


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
# reading
# --------------------------------------------------------------------------------------------
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
    float64 arrays (:func:`hystcli.io.read_csv_blocks`) and scaled in place; None at any doubt."""
    import pandas as pd  # here: the command line's start-up must not pay for pandas

    use = sorted({j for _, j in resolved})
    # the numbers float() reads (_parse_table's): pandas 3's parser rounds correctly, 2's only so asked
    exact = {} if int(pd.__version__.split(".")[0]) >= 3 else {"float_precision": "round_trip"}
    values = io.read_csv_blocks(f, use, lines, size, progress, usecols=use, encoding=encoding,
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
        :data:`hystcli.io.READ_PROGRESS_BYTES` read by the CSV parser.

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
