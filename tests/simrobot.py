"""`hyst sim-robot` in a subprocess, for the tests that talk to a robot as a user does.

Readiness is the device path on the robot's stdout: sim-robot prints it only once its twin is
warmed up (the emulator answers its first MOVE as fast as the others), so a test never waits a
fixed time. Deadlines are generous (:data:`TIMEOUT`), because a loaded machine (two CPU hogs
beside ``pytest -n 2``) delays any process by a second now and then; a test that needs a reply
deadline to *fire* passes a short one of its own, against a fault that cannot answer in time.
"""
from __future__ import annotations

import contextlib
import select
import signal
import subprocess
import sys
from typing import Iterator

TIMEOUT = "10"
"""Reply deadline (s) the tests give every host command that must succeed."""
START_TIMEOUT = 120.0
"""How long a robot may take to print its path (a cold numba cache compiles first)."""


def start_sim_robot(*args: str) -> tuple[subprocess.Popen, str]:
    """Start `hyst sim-robot --quiet ARGS` and return (process, pty path) once it is ready;
    the caller must :func:`stop` it."""
    proc = subprocess.Popen([sys.executable, "-m", "hystcli", "sim-robot", "--quiet", *args],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        ready, _, _ = select.select([proc.stdout], [], [], START_TIMEOUT)
        if not ready:
            raise AssertionError(f"sim-robot printed no device path within {START_TIMEOUT:g} s")
        path = proc.stdout.readline().strip()
        if not path.startswith("/dev/"):
            raise AssertionError(f"sim-robot printed {path!r}; stderr: "
                                 f"{proc.stderr.read() if proc.poll() is not None else ''}")
    except BaseException:
        stop(proc)
        raise
    return proc, path


def stop(proc: subprocess.Popen) -> int | None:
    """SIGTERM, then kill after 20 s; never leaves the process behind. Returns its exit code."""
    try:
        if proc.poll() is None:
            proc.send_signal(signal.SIGTERM)
        proc.wait(timeout=20)
    except subprocess.TimeoutExpired:
        pass
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(timeout=10)
        for f in (proc.stdout, proc.stderr):
            if f is not None:
                f.close()
    return proc.returncode


@contextlib.contextmanager
def sim_robot(*args: str) -> Iterator[str]:
    """``with sim_robot("--shape", "alpha=45") as path:`` a running robot, stopped afterwards."""
    proc, path = start_sim_robot(*args)
    try:
        yield path
    finally:
        stop(proc)


def interrupt_after(argv: list[str], ready: str, timeout: float = 120.0) -> tuple[int, str]:
    """Run ``python -m hystcli *argv``, and a second after it prints a stderr line starting with
    ``ready`` send it SIGINT, as a user's Ctrl-C: (exit code, stderr).

    SIGINT gets its default action in the child, as a terminal gives it: a test run started in the
    background of a non-interactive shell ignores SIGINT, and a child would inherit that.
    """
    import time

    proc = subprocess.Popen([sys.executable, "-m", "hystcli", *argv], stderr=subprocess.PIPE,
                            stdout=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        line = proc.stderr.readline()
        while line and not line.startswith(ready):
            line = proc.stderr.readline()
        assert line.startswith(ready), proc.stderr.read()
        time.sleep(1.0)  # a second into the motion: the knob is away from where it began
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=timeout)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    return proc.returncode, err
