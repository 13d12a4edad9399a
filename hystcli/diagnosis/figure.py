"""The diagnosis figure as PNG bytes (``hyst diagnose --plot``); the figure itself is
:meth:`Diagnosis.plot <hystcli.diagnosis.result.Diagnosis.plot>`."""
from __future__ import annotations

from typing import Sequence

from ..core.run import Run
from .result import Diagnosis


def diagnosis_figure(diag: Diagnosis, runs: Sequence[Run]) -> bytes:
    """PNG bytes of :func:`diagnosis_axes`' figure."""
    import io as _io

    fig = diagnosis_axes(diag, runs)
    buf = _io.BytesIO()
    fig.savefig(buf, format="png", dpi=100)
    return buf.getvalue()


def diagnosis_axes(diag: Diagnosis, runs: Sequence[Run]):  # noqa: ANN201 - matplotlib.figure.Figure
    """The diagnosis figure, :meth:`Diagnosis.plot` (kept under this name for existing callers)."""
    return diag.plot(runs)
