"""Figures as file bytes: the formats a figure is written in, and the bytes of a matplotlib Figure.

A figure function builds a ``matplotlib.figure.Figure`` (never pyplot: no global state, no display)
and :func:`figure_bytes` turns it into the same bytes for the same data. matplotlib is imported
inside the functions, so importing this module costs nothing.
"""
from __future__ import annotations

import io as _io

PLOT_FORMATS = ("png", "pdf", "svg")


def figure_bytes(fig: object, fmt: str) -> bytes:
    """A matplotlib ``Figure`` as file bytes in ``fmt``, the same bytes for the same figure."""
    import matplotlib

    buf = _io.BytesIO()
    # no date or version stamps and fixed SVG ids: the same data give the same bytes
    stamp = {"png": {"Software": None}, "pdf": {"CreationDate": None, "Producer": None},
             "svg": {"Date": None}}[fmt]
    with matplotlib.rc_context({"svg.hashsalt": "hyst"}):
        fig.savefig(buf, format=fmt, metadata=stamp)  # type: ignore[attr-defined]
    return buf.getvalue()


__all__ = ["PLOT_FORMATS", "figure_bytes"]
