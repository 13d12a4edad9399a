"""``python -m hystcli`` and the ``hyst`` console script: the command line.

The entry point is this small module rather than :mod:`hystcli.cli` so that Ctrl-C while the
command modules load (a few tenths of a second on a busy machine) is caught like Ctrl-C in a
command: ``Error: interrupted``, exit 130, no traceback.

It also pins the numeric libraries' thread pools before any of them loads (:func:`pin_threads`):
hyst's linear algebra is small (a few thousand samples, a handful of parameters), where a BLAS
thread pool only adds threads that, on a busy machine, wait for each other. The core's own
fits limit BLAS around their loops (threadpoolctl); this covers every other call, and any
command to come, once.
"""
from __future__ import annotations

import sys

from .threads import BLAS_THREAD_VARS, THREADS_ENV, pin_threads  # noqa: F401 (the entry point's names)


def main() -> None:
    """Entry point of the ``hyst`` console script."""
    try:
        pin_threads()
    except ValueError as exc:
        sys.stderr.write(f"Error: {exc}\n")
        raise SystemExit(2) from None
    try:
        from .cli import app

        # typer builds the click commands before its own Ctrl-C handling starts: covered here too
        app(prog_name="hyst")
    except KeyboardInterrupt:
        sys.stderr.write("Error: interrupted\n")
        raise SystemExit(130) from None


if __name__ == "__main__":
    main()
