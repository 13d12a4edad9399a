"""Files in and out: run CSVs, model JSONs, atomic writes, the import of foreign logs and the checks
of a run file.

* :mod:`.runs`: the run CSV format (docs/design.md section 6) of a :class:`~hystcli.core.run.Run`:
  read, parse, validate at the boundary, format;
* :mod:`.files`: writes that are whole or absent (a temporary file renamed over the target),
  several outputs all or none, and :func:`write_run`;
* :mod:`.models`: model JSON files, read and validated, written atomically; a file's hash and
  provenance;
* :mod:`.importer` (with :mod:`.mapping` and :mod:`.reading`): ``hyst import``, foreign logs
  turned into runs through a column mapping;
* :mod:`.check`: ``hyst check``, every problem of a run CSV at once (the format's and the data's).

Every reader raises :class:`~hystcli.errors.DataError` or :class:`~hystcli.errors.ModelError`
naming the file and the problem. The names below are the package's surface
(``from hystcli.io import read_run, write_run``); the importer and the checks are imported on
their own, as ``hystcli.io.importer`` and ``hystcli.io.check``.
"""
from __future__ import annotations

from .files import PendingOutputs, all_or_none, atomic_write, atomic_write_text, check_not_input, write_run
from .models import dumps_model, file_sha256, load_model, model_from_dict, model_to_dict, provenance, save_model
from .runs import (KNOWN_COLUMNS, MAX_ABS_VALUE, MODEL_FORMAT, MODEL_VERSION, READ_CHUNK_ROWS, READ_PROGRESS_BYTES,
                   format_run, odd_line_breaks, parse_run, read_csv_blocks, read_run)

__all__ = ["KNOWN_COLUMNS", "MAX_ABS_VALUE", "MODEL_FORMAT", "MODEL_VERSION", "READ_CHUNK_ROWS",
           "READ_PROGRESS_BYTES", "PendingOutputs", "all_or_none", "atomic_write", "atomic_write_text",
           "check_not_input", "dumps_model", "file_sha256", "format_run", "load_model", "model_from_dict",
           "model_to_dict", "odd_line_breaks", "parse_run", "provenance", "read_csv_blocks", "read_run",
           "save_model", "write_run"]
