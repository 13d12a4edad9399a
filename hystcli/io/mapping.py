"""Import mappings: which columns of a foreign log fill which run columns, in which units, with
which metadata; load and save them, and the presets for known logs."""
from __future__ import annotations

import json
import math
import os
import re
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Iterable, Mapping, Sequence

from ..errors import DataError
from .runs import KNOWN_COLUMNS

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
