"""``hyst batch`` and ``hyst report``: many runs through one command, one results table.

- :mod:`~hystcli.batch.core`: :func:`plan` the tasks, :func:`run_batch` them;
- :mod:`~hystcli.batch.engine`: local processes or a dask.distributed cluster;
- :mod:`~hystcli.batch.tasks`: the task function (the only module that imports the rest of hyst);
- :mod:`~hystcli.batch.table`: durable parts, the deterministic table;
- :mod:`~hystcli.batch.report`: summaries, drift and outliers over a table.

Needs the ``batch`` extra (``pip install 'hystcli[batch]'``: pyarrow, dask.distributed).
"""
from __future__ import annotations

from .. import HystError

EXTRA = "batch"


class MissingExtra(HystError):
    """A package of the ``batch`` extra is not installed."""


def require(*modules: str) -> None:
    """Raise :class:`MissingExtra` naming the extra when one of ``modules`` cannot be imported."""
    import importlib.util

    for m in modules:
        if importlib.util.find_spec(m) is None:
            raise MissingExtra(f"hyst batch needs {m}: pip install 'hystcli[{EXTRA}]'")
