"""Figures as files: the formats a figure is written in, its bytes, and the one function that
writes it.

A figure function builds a ``matplotlib.figure.Figure`` in the style of :mod:`.style` (never
pyplot: no global state, no display); :func:`figure_bytes` turns it into the same bytes for the same
data and :func:`save_figure` writes those bytes atomically. matplotlib is imported inside the
functions, so importing this module costs nothing.
"""
from __future__ import annotations

import io as _io
import os
from pathlib import Path
from typing import Iterable

from ..errors import DataError

PLOT_FORMATS = ("png", "pdf", "svg")


def figure_bytes(fig: object, fmt: str) -> bytes:
    """A matplotlib ``Figure`` as file bytes in ``fmt``, the same bytes for the same figure."""
    import matplotlib

    if fmt not in PLOT_FORMATS:
        raise DataError(f"cannot draw a {fmt!r} figure: choose among {', '.join(PLOT_FORMATS)}")
    buf = _io.BytesIO()
    # no date or version stamps and fixed SVG ids: the same data give the same bytes
    stamp = {"png": {"Software": None}, "pdf": {"CreationDate": None, "Producer": None},
             "svg": {"Date": None}}[fmt]
    with matplotlib.rc_context({"svg.hashsalt": "hyst"}):
        fig.savefig(buf, format=fmt, metadata=stamp)  # type: ignore[attr-defined]
    return buf.getvalue()


def save_figure(fig: object, path: str | os.PathLike, inputs: Iterable[str | os.PathLike] = (),
                fmt: str | None = None) -> None:
    """Write ``fig`` to ``path`` in ``fmt``, by default the format its suffix names (``.png``,
    ``.pdf``, ``.svg``).

    The bytes are made first (:func:`figure_bytes`) and then written through a temporary file and
    a rename, so ``path`` holds the whole figure or what it held before, never part of one.

    Raises
    ------
    DataError
        Another format; ``path`` is one of ``inputs``; the file cannot be written.
    """
    from ..io import atomic_write

    data = figure_bytes(fig, fmt or Path(path).suffix.lower().lstrip("."))
    atomic_write(path, lambda f: f.write(data), inputs=inputs)


__all__ = ["PLOT_FORMATS", "figure_bytes", "save_figure"]
