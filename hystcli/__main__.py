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

import os
import sys

THREADS_ENV = "HYST_THREADS"
"""Environment variable: how many threads hyst's numeric libraries may use (default 1)."""

BLAS_THREAD_VARS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "BLIS_NUM_THREADS",
                    "VECLIB_MAXIMUM_THREADS", "NUMEXPR_NUM_THREADS")
"""What BLAS/OpenMP builds read for their thread count when they load."""


def pin_threads(environ: dict | None = None) -> int:
    """Set the thread count of BLAS, OpenMP and numba before they load; return it.

    The count is ``HYST_THREADS`` when set, else 1. A thread variable of a library that the user
    set is kept: when any of :data:`BLAS_THREAD_VARS` is set, the BLAS variables are left as
    they are (OpenBLAS reads ``OMP_NUM_THREADS`` when ``OPENBLAS_NUM_THREADS`` is unset), and a
    set ``NUMBA_NUM_THREADS`` is kept. A BLAS already loaded in this process (hyst used as a
    library before the command line) is limited through threadpoolctl instead.

    Raises
    ------
    ValueError
        ``HYST_THREADS`` is not a positive whole number.
    """
    env = os.environ if environ is None else environ
    text = env.get(THREADS_ENV, "").strip()
    n = 1
    if text:
        if not text.isdigit() or int(text) < 1:
            raise ValueError(f"{THREADS_ENV} must be a positive whole number, got {text!r}")
        n = int(text)
    env.setdefault("NUMBA_NUM_THREADS", str(n))
    if any(env.get(var) for var in BLAS_THREAD_VARS):
        return n
    for var in BLAS_THREAD_VARS:
        env[var] = str(n)
    if environ is None and "numpy" in sys.modules:
        from threadpoolctl import threadpool_limits

        threadpool_limits(limits=n)
    return n


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
