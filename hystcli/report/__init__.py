"""Reports: tables, their text formats and figures, for every command and result that shows one.

* :mod:`.table`: :class:`~.table.Table` (plain data) and its formatters (text, Markdown, CSV,
  JSON, LaTeX);
* :mod:`.style`: the one look of every figure (panel size, fonts, the colour of each role) and
  :func:`~.style.new_figure`, which every figure function starts from;
* :mod:`.figures`: the plot formats, the bytes of a matplotlib Figure and
  :func:`~.figures.save_figure`, the one writer of figure files;
* :mod:`.evaluation`: the evaluation's figure (the paper's Figs. 6 and 7).

The estimators (identification, shift detection, diagnosis) import a figure helper from here, not
from the evaluation's metrics. Nothing here prints or imports typer or rich; matplotlib loads only
when a figure is drawn.
"""
