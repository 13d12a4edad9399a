"""One run: named numeric columns of equal length plus metadata, as every layer passes it.

The container only; reading and writing the run CSV format (docs/design.md section 6) is
:mod:`hystcli.io.runs`'s. It sits in the core because prediction and compensation
(:mod:`hystcli.core.model`, the effect chain) take runs and make them.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from types import MappingProxyType
from typing import Iterable, Mapping

import numpy as np

from ..errors import DataError

KNOWN_META = ("catheter", "controller", "shape", "motion", "trial", "rotation", "offset1", "offset2", "condition",
              "shift_ignored")
"""Metadata keys hyst interprets (docs/design.md section 6); others are kept and reported."""


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
            raise DataError(missing_column(self.source, name, self.columns)) from None

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


def missing_column(source: str | None, name: str, columns: Iterable[str]) -> str:
    """The message for a column a run lacks."""
    return (f"{source + ': ' if source else ''}missing column {name!r} "
            f"(columns: {', '.join(columns) or 'none'})")

