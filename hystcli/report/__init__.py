"""Reports: tables, their text formats and figures, for every command and result that shows one.

* :mod:`.table`: :class:`~.table.Table` (plain data) and its formatters (text, Markdown, CSV,
  JSON, LaTeX);
* :mod:`.figures`: the plot formats and the bytes of a matplotlib Figure.

The estimators (identification, shift detection, diagnosis) import a figure helper from here, not
from the evaluation's metrics. Nothing here prints or imports typer or rich; matplotlib loads only
when a figure is drawn.
"""
