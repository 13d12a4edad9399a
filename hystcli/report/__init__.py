"""Reports: tables, their text formats and figures, for every command and result that shows one.

* :mod:`.table`: :class:`~.table.Table` (plain data) and its formatters (text, Markdown, CSV,
  JSON, LaTeX);
* :mod:`.style`: the one look of every figure (panel size, fonts, the colour of each role) and
  :func:`~.style.new_figure`, which every figure function starts from;
* :mod:`.figures`: the plot formats, the bytes of a matplotlib Figure and
  :func:`~.figures.save_figure`, the one writer of figure files;
* :mod:`.metrics`: the evaluation: PTPE and RMSE, their grouping over run metadata, improvement
  rates and the paper's Tables I and II (``hyst evaluate``, ``hystcli.evaluate``);
* :mod:`.evaluation`: the evaluation's figure (the paper's Figs. 6 and 7);
* :mod:`.inspection`: what ``hyst show`` and ``hyst diff`` print of models, and the envelope
  figure.

The estimators (identification, shift detection, diagnosis) import a figure helper from
:mod:`.style` and :mod:`.figures`; diagnosis scores a fit with :func:`~.metrics.ptpe`. Nothing here
prints or imports typer or rich; matplotlib loads only when a figure is drawn. This ``__init__``
imports nothing: each module is imported by name.
"""
