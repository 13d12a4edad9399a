"""Thread pools of the numeric libraries: one count for BLAS, OpenMP and numba, set before they load.

hyst's linear algebra is small (a few thousand samples, a handful of parameters), where a BLAS
thread pool only adds threads that, on a busy machine, wait for each other. The command line
(:mod:`hystcli.__main__`) and a batch worker (:mod:`hystcli.batch.tasks`) both call
:func:`pin_threads` before any of the libraries loads.
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
