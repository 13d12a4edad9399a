"""Live tracking: compensate a reference as it comes and send the commands to the robot
(``hyst track``).

The reference (a run CSV with ``t`` and ``r1``/``r2``: a file, or lines on stdin as they arrive)
goes sample by sample through a :class:`hystcli.stream.Compensator`, and each command goes to the
robot as a ``MOVE`` at the reference's own timing (sample ``i`` at ``t[i] - t[0]`` after the
start). What the robot answers (motor current, the tracker's tip angle) is logged beside the
reference and the commands: the log is a run CSV (docs/design.md section 6) that ``hyst evaluate``
reads as it is.

Safety, as ``hyst play`` (:mod:`hystcli.device.robot`): a whole reference file is compensated and checked
against the limits before the first ``MOVE`` (nothing moves when a command is beyond the travel
limit, or, with ``speed="strict"``, a step beyond the speed limit); a reference on stdin is checked
sample by sample, before each ``MOVE``. With ``speed="limit"`` the compensator rate-limits its
commands as it goes (:class:`hystcli.stream.Compensator`'s ``limits``): the knob crosses the
inverse's jumps at the speed limit and catches up after them. On any fault (a link error, a garbled
or late reply, a bad reference line, a limit, Ctrl-C) every motor is stopped, the knobs go back to
where they began, and the error says where they are; the caller writes nothing.

The core never prints; ``hystcli/cli/track_cmds.py`` renders.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any, Callable, Iterable, Iterator, Mapping

import numpy as np

from ..core.model import Model
from ..core.run import Run
from ..errors import DataError, SafetyStop
from ..safety import DEFAULT_MOVE_SPEED, LimitExceeded, Limits, check_speed_mode


# --------------------------------------------------------------------------------------------
# the reference
# --------------------------------------------------------------------------------------------
@dataclass
class Reference:
    """A desired trajectory read sample by sample.

    Attributes
    ----------
    meta : dict of str to str
        Its ``# key: value`` metadata (shape, offsets, ...).
    knobs : tuple of int
        Knobs with an ``r<k>`` column.
    rows : iterator of (float, tuple of float)
        ``(t, (r<k> ...))`` per sample, in :attr:`knobs` order, validated as they come.
    run : Run or None
        The whole reference when it is known up front (a file): the commands are then checked
        before anything moves.
    source : str
    """

    meta: dict
    knobs: tuple
    rows: Iterator
    run: Run | None = None
    source: str = "reference"


def reference_from_run(run: Run) -> Reference:
    """A :class:`Reference` over a run read whole (a file)."""
    knobs = tuple(run.knobs("r"))
    if not knobs:
        raise DataError(f"{run.source or 'reference'}: no desired tip angle column (r1 or r2)")
    t = np.asarray(run.t, float)
    rs = [np.asarray(run[f"r{k}"], float) for k in knobs]
    if len(t) < 2:
        raise DataError(f"{run.source or 'reference'}: a reference needs at least 2 samples")

    def rows() -> Iterator:
        for i in range(len(t)):
            yield float(t[i]), tuple(float(r[i]) for r in rs)

    return Reference(dict(run.meta), knobs, rows(), run, run.source or "reference")


def reference_from_lines(lines: Iterable[str], source: str = "<stdin>") -> Reference:
    """A :class:`Reference` over the lines of a run CSV as they arrive (stdin).

    Reads the metadata and the header at once, then one row per ``next()``. Each row is checked
    when it comes: numbers, finite, as many fields as the header, ``t`` strictly increasing.

    Raises
    ------
    DataError
        No header, no ``t`` or ``r<k>`` column (at once), or a bad row (when it is read; the
        message names the line).
    """
    it = iter(lines)
    meta: dict[str, str] = {}
    header = None
    lineno = 0
    for line in it:
        lineno += 1
        text = line.strip()
        if lineno == 1:
            text = text.lstrip("\ufeff")
        if not text:
            continue
        if text.startswith("#"):
            key, sep, value = text[1:].partition(":")
            if sep and key.strip():
                meta[key.strip()] = value.strip()
            continue
        header = [h.strip() for h in text.split(",")]
        break
    if header is None:
        raise DataError(f"{source}: no header row (expected t,r1[,r2])")
    if "t" not in header:
        raise DataError(f"{source}: missing column 't' (columns: {', '.join(header)})")
    knobs = tuple(k for k in (1, 2) if f"r{k}" in header)
    if not knobs:
        raise DataError(f"{source}: no desired tip angle column (r1 or r2)")
    it_t = header.index("t")
    idx = [header.index(f"r{k}") for k in knobs]
    width = len(header)

    def rows() -> Iterator:
        nonlocal lineno
        last = -math.inf
        for line in it:
            lineno += 1
            text = line.strip()
            if not text or text.startswith("#"):
                continue
            cells = text.split(",")
            if len(cells) != width:
                raise DataError(f"{source}: line {lineno} has {len(cells)} fields, the header {width}")
            try:
                t = float(cells[it_t])
                rs = tuple(float(cells[j]) for j in idx)
            except ValueError:
                raise DataError(f"{source}: line {lineno} holds a value that is not a number: {text[:60]!r}") from None
            if not (math.isfinite(t) and all(math.isfinite(r) for r in rs)):
                raise DataError(f"{source}: line {lineno} holds NaN or infinity")
            if not t > last:
                raise DataError(f"{source}: t must be strictly increasing (line {lineno}: {t:g} after {last:g})")
            last = t
            yield t, rs

    return Reference(meta, knobs, rows(), None, source)


# --------------------------------------------------------------------------------------------
# tracking
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class TrackResult:
    """What :func:`track` did.

    Attributes
    ----------
    run : Run
        The log: ``t``, ``r<k>``, ``q<k>``, ``y<k>`` (when the robot has a tracker), ``c<k>``,
        with the reference's metadata plus ``controller``, ``offset<k>``, the device's identity and
        ``track_*`` (timing, lookahead, the compensator's cost per step).
    offsets : dict of int to float
        The offset each knob's commands used (detected, or the model's rule for the reference).
    shift : dict
        Per knob, the Algorithm 1 result when the shift was detected first (else empty).
    step_us : float
        Median cost of one :meth:`Compensator.step` during the run (microseconds).
    catch_ups : dict of int to hystcli.safety.CatchUp
        Per knob whose commands were rate-limited (``speed="limit"``), how long it lagged.
    """

    run: Run
    offsets: dict
    shift: dict = field(default_factory=dict)
    step_us: float = 0.0
    catch_ups: dict = field(default_factory=dict)


def _compensator(model: Model, ref: Reference, knobs: tuple, dt: float, latency: str,
                 limits: Limits | None) -> Any:
    from ..stream import Compensator

    for k in knobs:
        model.knob(k)
    return Compensator.for_run(model, ref.meta, knobs=knobs, dt=dt, latency=latency, limits=limits)


def track(device: Any, model: Model, reference: Reference, *, limits: Limits = Limits(),
          speed: str = "strict", paced: bool = True, latency: str = "delay",
          detect_shift_first: bool = False, shift_options: Mapping[str, Any] | None = None,
          return_on_abort: bool = True, move_speed: float | None = None, min_speed: float = 1e-3,
          progress: Callable[[int], None] | None = None, clock: Callable[[], float] = time.monotonic,
          sleep: Callable[[float], None] = time.sleep) -> TrackResult:
    """Compensate ``reference`` live and play the commands on ``device``; log what it reports.

    Parameters
    ----------
    device : hystcli.device.Device
        An open device (handshake done).
    model : Model
        The catheter's model (with its effects). Each knob's offset is docs/design.md section 6's rule
        for the reference's metadata, or the detected one with ``detect_shift_first``.
    reference : Reference
        :func:`reference_from_run` (a file: checked whole first) or :func:`reference_from_lines`.
    limits : Limits
        Tightened by the device's announced limits.
    speed : {"strict", "fast", "limit"}
        A step beyond the speed limit refuses the reference (a file before anything moves, stdin
        at that sample), is sent at the speed limit (``fast``: the knob arrives late), or is
        rate-limited by the compensator (``limit``: the knob catches up after it). Travel is never
        waived.
    paced : bool
        Send sample ``i`` at ``t[i] - t[0]`` after the start (True), or as fast as the robot
        answers.
    latency : {"delay", "ignore"}
        What the compensator does with a ``latency`` effect (:mod:`hystcli.stream.compensator`).
        With ``delay`` the command of sample ``i`` needs the reference up to ``t[i] + delay``:
        read ahead from a file at no cost; on stdin the commands go out that much late.
    detect_shift_first : bool
        Run Algorithm 1 on each knob first (``hyst detect-shift --port``) and use its offsets.
    shift_options : mapping, optional
        Options of :func:`hystcli.shift.detect_shift` and of the device probe (``current_ceiling``,
        ``speed``, ``dwell``, ``mean``).
    return_on_abort : bool
        After a fault, move the knobs back to where they began (True) or hold them.
    move_speed : float, optional
        Speed of the untimed moves (to the first command, back after a fault).
    progress : callable, optional
        ``progress(i)`` after each sample sent.

    Returns
    -------
    TrackResult

    Raises
    ------
    DataError, ModelError, LimitExceeded
        Before anything moved (a bad reference file, a knob the model or robot lacks, a command
        file beyond a limit).
    LinkError, DeviceError, SafetyStop, DataError, ShiftDetectionError
        While moving: the motors were stopped and the knobs returned (or held); the message
        says where they are.
    hystcli.device.robot.Interrupted
        Ctrl-C while moving (likewise).
    """
    from .robot import (_hold_statement, _Pacer, _reraise_with, _return_knobs, _send_row, check_trajectory,
                        effective_limits)

    check_speed_mode(speed)
    info = device.info or device.hello()
    knobs = tuple(reference.knobs)
    for k in knobs:
        model.knob(k)
        if k not in info.knobs:
            raise DataError(f"{reference.source} has r{k} but device {info.name} drives knobs "
                            f"{','.join(map(str, info.knobs))}")
    lim = effective_limits(limits, device)
    v_move = min(DEFAULT_MOVE_SPEED if move_speed is None else float(move_speed), lim.max_speed)

    # the first two samples give the sample period the latency buffer counts in
    rows = reference.rows
    head = []
    for row in rows:
        head.append(row)
        if len(head) == 2:
            break
    if len(head) < 2:
        raise DataError(f"{reference.source}: a reference needs at least 2 samples")
    if reference.run is not None:
        dt = float(np.median(np.diff(reference.run.t)))
    else:
        dt = head[1][0] - head[0][0]
    comp = _compensator(model, reference, knobs, dt, latency, lim if speed == "limit" else None)
    ts: list[float] = []
    rs: list[tuple] = []
    qs: list[tuple] = []
    cs: list[tuple] = []
    ys: list[tuple] = []
    cost: list[float] = []
    shift_results: dict = {}
    starts = {k: device.state(k).angle for k in knobs}
    pacer = _Pacer(paced, clock, sleep)
    capped = 0
    perf = time.perf_counter
    try:
        if detect_shift_first:
            shift_results = _detect(device, model, knobs, dict(shift_options or {}))
            for k, res in shift_results.items():
                comp.set_offset(k, res.offset)
        if reference.run is not None:
            # the whole file, compensated and checked before the first MOVE (as `play` checks)
            run = reference.run
            r_all = np.column_stack([run[f"r{k}"] for k in knobs])
            q_all = comp.steps(r_all[:, 0] if len(knobs) == 1 else r_all, run.t)
            tail = comp.flush()
            q_all = np.asarray(q_all).reshape(len(run), len(knobs))
            if comp.lookahead:
                q_all = np.vstack([q_all[comp.lookahead:], np.asarray(tail).reshape(-1, len(knobs))])
            check_trajectory(device, Run({"t": run.t, **{f"q{k}": q_all[:, j] for j, k in enumerate(knobs)}},
                                         source=reference.source), limits, speed=speed)
            comp.reset()

        def emit(q: tuple) -> None:
            # send the command of sample len(qs) at its time; record the robot's answer
            nonlocal capped
            i = len(qs)
            t_i = ts[i]
            for j, k in enumerate(knobs):
                if not abs(q[j]) <= lim.travel:
                    raise SafetyStop(f"knob {k}: command {q[j]:+.2f} deg at t={t_i:g} s is beyond the "
                                     f"travel limit +-{lim.travel:g} deg")
            if i == 0:
                for j, k in enumerate(knobs):
                    device.move(k, q[j], v_move)   # untimed, to the first command
                pacer.start(t_i)
            else:
                pacer.wait(t_i)
            c_row, y_row, n_capped = _send_row(device, info, knobs, q, qs[-1] if i else None,
                                               t_i - ts[i - 1] if i else dt, lim, fast=speed == "fast",
                                               min_speed=min_speed, i=i, t=t_i)
            capped += n_capped
            qs.append(tuple(q))
            cs.append(tuple(c_row))
            ys.append(tuple(y_row))
            if progress is not None:
                progress(len(qs))

        one = len(knobs) == 1
        for source in (head, rows):
            for t, r in source:
                ts.append(t)
                rs.append(r)
                t0 = perf()
                q = comp.step(r[0] if one else r, t)
                cost.append(perf() - t0)
                if len(ts) > comp.lookahead:
                    emit((q,) if one else q)
        for q in comp.flush():
            emit((q,) if one else q)
    except LimitExceeded:
        # the whole file refused before its first MOVE: nothing of the run moved (a shift search
        # before it has brought its knob back itself)
        device.stop()
        raise
    except BaseException as exc:
        device.stop()
        statement = (_return_knobs(device, starts, v_move) if return_on_abort
                     else _hold_statement(device, knobs))
        _reraise_with(exc, statement)

    cols: dict[str, np.ndarray] = {"t": np.asarray(ts)}
    for j, k in enumerate(knobs):
        cols[f"r{k}"] = np.asarray([r[j] for r in rs])
        cols[f"q{k}"] = np.asarray([q[j] for q in qs])
        if info.tracker:
            cols[f"y{k}"] = np.asarray([y[j] for y in ys])
        cols[f"c{k}"] = np.asarray([c[j] for c in cs])
    offsets = {k: comp.offsets[k] for k in knobs}
    meta = dict(reference.meta)
    meta["controller"] = "comp" if all(o == 0.0 for o in offsets.values()) else "comp+shift"
    for k in knobs:
        meta[f"offset{k}"] = repr(float(offsets[k]))
    meta.pop("shift_ignored", None)
    meta.update(info.as_meta())
    step_us = float(np.median(cost) * 1e6) if cost else 0.0
    meta.update({"track_timing": "paced" if paced else "fast", "track_max_lag_s": f"{pacer.max_lag:.4f}",
                 "track_latency": latency, "track_lookahead": str(comp.lookahead),
                 "track_speed_limit": f"{lim.max_speed:g}", "track_speed_capped": str(capped),
                 "track_speed_mode": speed, "track_step_us": f"{step_us:.2f}"})
    catch_ups = comp.catch_ups
    for k, c in catch_ups.items():
        meta[f"track_catchup{k}"] = c.note
    if shift_results:
        meta["shift_source"] = "live: detected before tracking (Algorithm 1)"
    return TrackResult(Run(cols, meta), offsets, shift_results, step_us, catch_ups)


def _detect(device: Any, model: Model, knobs: tuple, options: dict) -> dict:
    """Algorithm 1 on each knob over the open device (``hyst detect-shift --port``); every knob
    goes back to where it began."""
    from .. import shift as shift_mod
    from . import probe as device_mod

    probe_opts = {name: options.pop(name) for name in ("current_ceiling", "speed", "dwell", "mean")
                  if name in options}
    results = {}
    for k in knobs:
        probe = device_mod.DeviceProbe(device, k, **probe_opts)
        results[k] = shift_mod.detect_shift(model, probe, k, **options)
    return results


__all__ = ["Reference", "TrackResult", "reference_from_lines", "reference_from_run", "track"]
