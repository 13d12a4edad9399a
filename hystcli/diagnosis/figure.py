"""The diagnosis figure as PNG bytes (``hyst diagnose --plot``); the figure itself is
:meth:`Diagnosis.plot <hystcli.diagnosis.result.Diagnosis.plot>`."""
from __future__ import annotations

from typing import Sequence

from ..core.run import Run
from .result import Diagnosis


def diagnosis_figure(diag: Diagnosis, runs: Sequence[Run]) -> bytes:
    """PNG bytes of :func:`diagnosis_axes`' figure, the same bytes for the same diagnosis."""
    from ..report.figures import figure_bytes

    return figure_bytes(diagnosis_axes(diag, runs), "png")


def diagnosis_axes(diag: Diagnosis, runs: Sequence[Run]):  # noqa: ANN201 - matplotlib.figure.Figure
    """The diagnosis figure, :meth:`Diagnosis.plot` (kept under this name for existing callers)."""
    return diag.plot(runs)
