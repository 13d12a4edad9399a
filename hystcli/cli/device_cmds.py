"""Commands of the live robot link: ``sim-robot`` (the twin behind a pseudo-terminal), ``sweep``,
``play``, and the manual ones: ``status``, ``home``, ``jog``.

Each parses, calls one core function of :mod:`hystcli.device.robot` (or the emulator), renders. Every
command that moves a knob checks the whole request against the limits of
:mod:`hystcli.cli.robot_opts` (tightened by what the robot announces) before the first MOVE.
"""
from __future__ import annotations

import signal
import sys
from pathlib import Path
from typing import Annotated, Any, List, Optional

import typer

from .. import io
from ..core.params import Shape
from ..errors import DataError, HystError
from ..safety import DEFAULT_MAX_SPEED, DEFAULT_MOVE_SPEED, DEFAULT_TRAVEL
from ..sim.calibration import CALIBRATED_NAMES, calibrated_catheter
from .app import (BaudOpt, ColumnsOpt, EffectOpt, FormatOpt, KnobsAliasOpt, OutOpt, OutputFormat, QuietOpt,
                  columns_mapping, command, echo_json, echo_table, effects_option, fail, info, load_run, one_of,
                  parse_knobs, stderr_is_tty, warn)
from .robot_opts import (AllowFastOpt, InverseMaxSpeedOpt, NoReturnOpt, MaxSpeedOpt, MoveSpeedOpt, StrictSpeedOpt,
                         TimeoutOpt, TravelLimitOpt, finite, limit_hint, limits, positive, speed_mode)

PortArg = Annotated[str, typer.Option("--port", help="Serial port of the robot (name or pyserial URL).",
                                      show_default=False)]
MAX_KNOB = 9
"""Highest knob number a robot may announce (the line protocol's knobs are 1 to 9)."""
DEVICE_TIMEOUT = 1.0
"""Default reply deadline (s) of the device commands: a robot controller answers in
milliseconds; the motion's own duration and any dwell are added to it per MOVE."""


def _usage(param: str, exc: Exception) -> typer.BadParameter:
    """An option value the core refused, as a usage error (exit 2) naming the option."""
    return typer.BadParameter(str(exc), param_hint=param)


@command("sim-robot", "Serve the virtual catheter as a robot on a pseudo-terminal",
         epilog="Example: hyst sim-robot --catheter ice-a --shape 'alpha=90,theta=0' "
                "--latency-ms 2   (then: hyst status --port /dev/pts/N)")
def sim_robot_cmd(
    catheter: Annotated[str, typer.Option(
        help=f"Virtual catheter ({', '.join(CALIBRATED_NAMES)}): the calibrated one `hyst simulate` "
             "and the sample data use.")] = "ice-a",
    shape: Annotated[str, typer.Option(help="Shaft shape: 'straight' or 'alpha=90,theta=0;...' (deg).")] = "straight",
    rotation: Annotated[float, typer.Option(callback=finite, help="Bulk rotation of the catheter body (deg).")] = 0.0,
    effect: EffectOpt = None,
    seed: Annotated[int, typer.Option("--seed", min=0, help="Seed of every random draw (same seed, same bytes).")] = 0,
    latency_ms: Annotated[float, typer.Option(min=0.0, callback=finite, help="Answer latency per frame (ms).")] = 0.0,
    knob: Annotated[Optional[List[str]], typer.Option(
        "--knob", metavar="K", help="Knobs the robot drives: 1, 2 or 1,2 (repeatable; default 1,2).",
        show_default=False)] = None,
    knobs_alias: KnobsAliasOpt = None,
    travel_limit: Annotated[float, typer.Option(
        min=1.0, callback=finite, help="Largest |knob angle| accepted (deg); announced in the handshake.")] = 170.0,
    max_speed: Annotated[float, typer.Option(
        "--max-speed", min=1.0, callback=finite,
        help="Fastest knob speed its motors do (deg/s); a faster MOVE is refused (E_ARG). "
             "Announced in the handshake.")] = 1000.0,
    name: Annotated[str, typer.Option(help="Device name sent in the handshake.")] = "hyst-sim",
    fault: Annotated[Optional[List[str]], typer.Option(
        "--fault", help="Inject a fault (tests): KIND@N[xCOUNT][=VALUE], KIND one of silent, garble, "
                        "close, error, spike, delay; N counts MOVE frames.")] = None,
    plant: Annotated[Optional[str], typer.Option(
        "--plant", metavar="FILE.py[:ARGS]",
        help="Serve a plant built by a Python file instead of the catheter (tests of the live path on "
             "a plant our code did not make): FILE.py defines plant(args) returning the plant, ARGS "
             "(the text after the first ':' following .py) passed as one string. The independent test "
             "plants are not installed with hyst; the repository's bench/plants/live.py serves them: "
             "--plant bench/plants/live.py:SEED[:FAMILY[:OFFSET]].")] = None,
    quiet: QuietOpt = False,
) -> None:
    """Serve the virtual catheter as a robot on a pseudo-terminal until Ctrl-C or SIGTERM.

    Prints the device path (one line on stdout) to pass as --port to `hyst play`, `status`,
    `home`, `jog` or `detect-shift`, once the device is ready to answer (its twin warmed up).
    The device speaks the hyst line protocol (docs/protocol.md) with the optional features dwell
    and mean. The catheter and its effects are those of `hyst simulate` given the same
    --catheter and --effect.
    """
    from ..core.effects import format_effects
    from ..device.emulator import Fault, serve
    from ..sim.live import LiveTwin

    knob_list = parse_knobs(one_of(knob, knobs_alias, "--knob", "--knobs")) or (1, 2)
    if not name or len(name) > 32 or any(not (0x21 <= ord(ch) <= 0x7E) or ch in "*=" for ch in name):
        raise typer.BadParameter("at most 32 printable characters without spaces, '*' or '='",
                                 param_hint="--name")
    # every option value the core parses is a usage error when refused (exit 2)
    try:
        cath = calibrated_catheter(catheter)
    except HystError as exc:
        raise _usage("--catheter", exc) from None
    try:
        shp = Shape.parse(shape)
    except HystError as exc:
        raise _usage("--shape", exc) from None
    try:
        effs = effects_option(effect)
    except HystError as exc:
        raise _usage("--effect", exc) from None
    try:
        faults = [Fault.parse(f) for f in fault or ()]
    except HystError as exc:
        raise _usage("--fault", exc) from None
    if plant is not None:
        twin = _file_plant(plant)
    else:
        twin = LiveTwin(cath, shape=shp, rotation=rotation, effects=effs, seed=seed, knobs=knob_list)
    server = serve(twin, latency=latency_ms / 1000.0, faults=faults, name=name,
                   travel_limit=travel_limit, max_speed=max_speed, background=False)

    def _terminate(signum, frame):  # SIGTERM ends the server like Ctrl-C
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGTERM, _terminate)
    try:
        # the path is printed once the device can answer at full speed (serve warmed it up):
        # a client may connect and start moving at once
        sys.stdout.write(server.path + "\n")
        sys.stdout.flush()
        what = (f"plant {plant}" if plant is not None else
                f"{catheter} ({shp}, rotation {rotation:g} deg, effects {format_effects(twin.effects)})")
        info(f"serving {what} on {server.path}; Ctrl-C to stop", quiet)
        server.serve_forever()
        if server.closed:
            info("the device port was closed (fault injected)", quiet)
    except KeyboardInterrupt:
        info("stopped", quiet)
    finally:
        signal.signal(signal.SIGTERM, previous)
        server.shutdown()


def _file_plant(text: str) -> Any:
    """The plant ``plant(ARGS)`` of the Python file in ``FILE.py[:ARGS]`` builds."""
    import importlib.util

    path, sep, args = text.partition(".py:")
    path = path + ".py" if sep else text
    spec = importlib.util.spec_from_file_location("hyst_sim_plant", path) if Path(path).is_file() else None
    if spec is None or not path.endswith(".py"):
        raise typer.BadParameter(f"{path!r} is not a Python file (FILE.py[:ARGS])", param_hint="--plant")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    build = getattr(module, "plant", None)
    if not callable(build):
        raise typer.BadParameter(f"{path} defines no function plant(args)", param_hint="--plant")
    try:
        return build(args)
    except ValueError as exc:
        # the file's own refusal of its arguments is a usage error, as any option value's
        raise typer.BadParameter(f"{args!r}: {exc}", param_hint="--plant") from None


@command("sweep", "Write the identification sweep as commands for `play`",
         epilog="Example: hyst sweep --knob 1 -o sweep_cmd.csv && hyst play sweep_cmd.csv "
                "--port /dev/ttyUSB0 -o sweep_knob1.csv && hyst identify sweep_knob1.csv -o model.json")
def sweep_cmd(
    output: OutOpt,
    knob: Annotated[int, typer.Option("--knob", min=1, max=2, help="Knob to sweep.")] = 1,
    amplitude: Annotated[float, typer.Option(
        "--amplitude", min=1.0, max=180.0, help="Sweep amplitude +-A, deg (paper: 40).")] = 40.0,
    peak_speed: Annotated[float, typer.Option(
        "--peak-speed", min=0.1, max=1000.0, help="Peak knob speed, deg/s (paper: 40).")] = 40.0,
    cycles: Annotated[float, typer.Option("--cycles", min=0.5, max=100.0, help="Sine cycles (paper: 2).")] = 2.0,
    fs: Annotated[float, typer.Option("--fs", min=1.0, max=10000.0, help="Sample rate, Hz.")] = 1000.0,
    quiet: QuietOpt = False,
) -> None:
    """Write the identification sweep (paper section II-C-2) as a command trajectory for `hyst play`.

    A sine of +-AMPLITUDE deg on one knob with the given peak speed, the other knob at rest, on
    a straight shaft: play it on the robot with `hyst play` and identify the model from the
    recording with `hyst identify`.
    """
    from ..core.run import Run
    from ..sim.twin import sweep

    t, q = sweep(amplitude=amplitude, cycles=cycles, peak_speed=peak_speed, fs=fs)
    run = Run({"t": t, f"q{knob}": q}, {"motion": "sweep", "controller": "none", "knob": str(knob),
                                         "shape": "straight"})
    io.write_run(output, run)
    info(f"wrote {output}: knob {knob}, +-{amplitude:g} deg, {cycles:g} cycles at up to "
         f"{peak_speed:g} deg/s, {len(run)} samples ({t[-1]:.1f} s)", quiet)


def _interrupted(exc: KeyboardInterrupt) -> None:
    """Ctrl-C while knobs moved: exit 130 with where they are (the core's statement)."""
    fail(f"interrupted; {exc}" if str(exc) else "interrupted", 130)


@command("play", "Play knob commands on the robot and record the run",
         epilog="Example: hyst sweep --knob 1 -o sweep_cmd.csv && hyst play sweep_cmd.csv "
                "--port /dev/ttyUSB0 -o sweep_knob1.csv")
def play_cmd(
    trajectory: Annotated[Path, typer.Argument(help="Command trajectory CSV with t and q1/q2 "
                                               "(e.g. from `hyst compensate`).", show_default=False)],
    port: PortArg,
    output: OutOpt,
    baud: BaudOpt = 115200,
    fast: Annotated[bool, typer.Option("--fast", help="Send each command as soon as the previous one "
                                       "is answered instead of at the file's timing.")] = False,
    timeout: TimeoutOpt = DEVICE_TIMEOUT,
    travel_limit: TravelLimitOpt = DEFAULT_TRAVEL,
    max_speed: InverseMaxSpeedOpt = DEFAULT_MAX_SPEED,
    allow_fast: AllowFastOpt = False,
    strict_speed: StrictSpeedOpt = False,
    no_return: NoReturnOpt = False,
    columns: ColumnsOpt = None,
    quiet: QuietOpt = False,
) -> None:
    """Play the knob commands of TRAJECTORY on the robot and record t, q, c (and y) to a run CSV.

    The whole file is checked before the first MOVE: finite values, increasing t, knobs the
    robot has, every command within --travel-limit and every step within --max-speed (the
    robot's own announced limits when tighter). A faster step is rate-limited (the knob crosses
    it at the limit and catches up; a warning says how long it lags; q in the output is what was
    sent), sent at the limit with --allow-fast, or refused with --strict-speed. On any fault or
    Ctrl-C every motor is stopped,
    the knobs go back to where they began (--no-return: they hold), the error says where each
    knob is, nothing is written, and the exit code is non-zero.
    """
    from ..device.robot import Interrupted, check_trajectory, play_trajectory
    from ..safety import LimitExceeded

    mode = speed_mode(allow_fast, strict_speed)
    io.check_not_input(output, [trajectory])
    folder = output.parent if str(output.parent) else Path(".")
    if not folder.is_dir():
        raise DataError(f"{output}: the folder {folder} does not exist")
    run = load_run(trajectory, columns_mapping(columns), quiet=quiet)
    lim = limits(travel_limit, max_speed)
    with _open(port, baud, timeout) as device:
        info(f"connected to {device.info.name} ({device.info.catheter}, knobs "
             f"{','.join(map(str, device.info.knobs))}, tracker {'yes' if device.info.tracker else 'no'})",
             quiet)
        try:
            plan = check_trajectory(device, run, lim, speed=mode)
        except LimitExceeded as exc:
            raise type(exc)(f"{exc}{limit_hint(exc)}", exc.check) from None
        for c in plan.catch_ups.values():
            warn(c.message)
        check = plan.check
        info("checked: " + "; ".join(
            f"knob {k} {m.q_min:+.1f}..{m.q_max:+.1f} deg, peak {m.peak_speed:.1f} deg/s"
            for k, m in check.knobs.items()) + f" (limits +-{check.limits.travel:g} deg, "
            f"{check.limits.max_speed:g} deg/s)", quiet)
        progress = None
        if not quiet and stderr_is_tty():
            step = max(1, len(run) // 20)

            def progress(i: int, n: int) -> None:
                if i % step == 0 or i == n:
                    typer.echo(f"\rplaying {i}/{n}", err=True, nl=i == n)
        try:
            result = play_trajectory(device, run, paced=not fast, limits=lim, speed=mode,
                                     return_on_abort=not no_return, progress=progress)
        except Interrupted as exc:
            _interrupted(exc)
    result = result.with_meta(trajectory=trajectory.name, port=port)
    io.write_run(output, result, inputs=[trajectory])
    capped = int(result.meta["play_speed_capped"])
    info(f"wrote {output} ({len(result)} samples, max lag {result.meta['play_max_lag_s']} s"
         + (f", {capped} steps sent at the {result.meta['play_speed_limit']} deg/s limit" if capped else "")
         + ")", quiet)


# --------------------------------------------------------------------------------------------
# status, home, jog
# --------------------------------------------------------------------------------------------
def _open(port: str, baud: int, timeout: float) -> Any:
    from ..device import Device

    if baud <= 0:  # pyserial's own refusal would come out as a link error (exit 1)
        raise typer.BadParameter(f"must be a positive number, got {baud}", param_hint="--baud")
    return Device(port, baud, timeout)


def _fmt_tip(tip: float | None) -> str:
    return "-" if tip is None else f"{tip:+.3f}"


@command("status", "Show the robot's handshake and each knob's state",
         epilog="Example: hyst status --port /dev/ttyUSB0 --format json")
def status_cmd(
    port: PortArg,
    baud: BaudOpt = 115200,
    timeout: TimeoutOpt = DEVICE_TIMEOUT,
    fmt: FormatOpt = OutputFormat.table,
) -> None:
    """Show who the robot is (handshake) and each knob's angle, motor current and tip angle.

    Reads only (HELLO and one STATE per knob): nothing moves, no STOP is sent.
    """
    from ..device.robot import status

    device = _open(port, baud, timeout)
    try:
        st = status(device)
    finally:
        device.close()  # not the context manager: it would send STOP, and status only reads
    if fmt == OutputFormat.json:
        echo_json(st.to_dict())
        return
    if fmt != OutputFormat.table:
        from ..report.table import Table

        echo_table(Table(("knob", "angle", "current", "tip"), ("knob", "angle (deg)", "current (mA)", "tip (deg)"),
                         tuple((s.knob, s.angle, s.current, s.tip) for s in st.knobs)), fmt, digits=3)
        return
    i = st.info
    typer.echo(f"device {i.name} (protocol {i.protocol}), catheter {i.catheter}, knobs "
               f"{','.join(map(str, i.knobs))}, tracker {'yes' if i.tracker else 'no'}, features "
               f"{','.join(i.features) or 'none'}")
    if st.limits:
        typer.echo("limits: " + ", ".join(
            f"travel +-{v:g} deg" if k == "travel" else f"max speed {v:g} deg/s"
            for k, v in st.limits.items()))
    other = {k: v for k, v in i.extra.items() if k not in st.limits}
    if other:
        typer.echo("other: " + " ".join(f"{k}={v}" for k, v in other.items()))
    typer.echo(f"{'knob':>4}  {'angle (deg)':>11}  {'current (mA)':>12}  {'tip (deg)':>9}")
    for s in st.knobs:
        typer.echo(f"{s.knob:>4}  {s.angle:>+11.3f}  {s.current:>12.2f}  {_fmt_tip(s.tip):>9}")


def _render_moves(moves: dict, fmt: OutputFormat, quiet: bool) -> None:
    if fmt == OutputFormat.json:
        echo_json({"knobs": {str(k): {"from": b.angle, "to": a.angle, "current": a.current, "tip": a.tip}
                             for k, (b, a) in moves.items()}})
    elif fmt != OutputFormat.table:
        from ..report.table import Table

        echo_table(Table(("knob", "from", "to", "current", "tip"),
                         ("knob", "from (deg)", "to (deg)", "current (mA)", "tip (deg)"),
                         tuple((k, b.angle, a.angle, a.current, a.tip) for k, (b, a) in moves.items())), fmt, digits=3)
    elif not quiet:
        for k, (b, a) in moves.items():
            typer.echo(f"knob {k}: {b.angle:+.3f} -> {a.angle:+.3f} deg (current {a.current:.1f} mA, "
                       f"tip {_fmt_tip(a.tip)} deg)")


@command("home", "Move the knobs back to 0 deg (or --angle)",
         epilog="Example: hyst home --port /dev/ttyUSB0            (every knob to 0 deg)\n\n"
                "         hyst home --port /dev/ttyUSB0 --knob 2 --angle 10")
def home_cmd(
    port: PortArg,
    knob: Annotated[Optional[List[str]], typer.Option(
        "--knob", metavar="K", help="Knob(s) to move: 1, 2 or 1,2 (repeatable; default: every knob of the "
                                    "robot).", show_default=False)] = None,
    angle: Annotated[float, typer.Option(
        "--angle", callback=finite, help="Target angle, deg (0: the knobs' zero, the straight-shaft rest).")] = 0.0,
    speed: MoveSpeedOpt = DEFAULT_MOVE_SPEED,
    travel_limit: TravelLimitOpt = DEFAULT_TRAVEL,
    max_speed: MaxSpeedOpt = DEFAULT_MAX_SPEED,
    baud: BaudOpt = 115200,
    timeout: TimeoutOpt = DEVICE_TIMEOUT,
    fmt: FormatOpt = OutputFormat.table,
    quiet: QuietOpt = False,
) -> None:
    """Move the knobs back to 0 deg (or --angle), one after the other, at --speed.

    Every target is checked against the travel limit first. On a fault or Ctrl-C the motors
    stop and the error says where each knob is.
    """
    from ..device.robot import Interrupted, home

    knobs = parse_knobs(knob, most=MAX_KNOB)
    _check_speed(speed, max_speed, travel_limit, abs(angle))
    with _open(port, baud, timeout) as device:
        try:
            moves = home(device, list(knobs) if knobs else None, angle, speed=speed,
                         limits=limits(travel_limit, max_speed))
        except Interrupted as exc:
            _interrupted(exc)
    _render_moves(moves, fmt, quiet)


JOG_MAX_STEP = 10.0
"""Default largest jog (deg): a nudge to see a knob respond or to free it, not a move anywhere
(`home --angle` moves anywhere); 10 deg is a quarter of the dead zone's width on the calibrated
catheters, so one jog from rest does not bend the tip far."""


@command("jog", "Move one knob by a small relative angle",
         epilog="Example: hyst jog --port /dev/ttyUSB0 --knob 1 --by -2.5")
def jog_cmd(
    port: PortArg,
    knob: Annotated[int, typer.Option("--knob", min=1, max=MAX_KNOB, help="Knob to move.", show_default=False)],
    by: Annotated[float, typer.Option(
        "--by", callback=finite, help="Relative angle, deg (signed).", show_default=False)],
    max_step: Annotated[float, typer.Option(
        "--max-step", callback=positive,
        help="Largest |--by|, deg: a jog is a nudge, not a move anywhere.")] = JOG_MAX_STEP,
    speed: MoveSpeedOpt = DEFAULT_MOVE_SPEED,
    travel_limit: TravelLimitOpt = DEFAULT_TRAVEL,
    max_speed: MaxSpeedOpt = DEFAULT_MAX_SPEED,
    baud: BaudOpt = 115200,
    timeout: TimeoutOpt = DEVICE_TIMEOUT,
    fmt: FormatOpt = OutputFormat.table,
    quiet: QuietOpt = False,
) -> None:
    """Move one knob by a small relative angle from where it is.

    Refused before anything moves when |--by| exceeds --max-step, the target the travel limit,
    or --speed the speed limit.
    """
    from ..device.robot import Interrupted, jog

    if abs(by) > max_step:
        raise typer.BadParameter(f"|{by:g}| deg is beyond --max-step {max_step:g} deg", param_hint="--by")
    _check_speed(speed, max_speed, travel_limit, 0.0)
    with _open(port, baud, timeout) as device:
        try:
            moves = {knob: jog(device, knob, by, max_step=max_step, speed=speed,
                               limits=limits(travel_limit, max_speed))}
        except Interrupted as exc:
            _interrupted(exc)
    _render_moves(moves, fmt, quiet)


def _check_speed(speed: float, max_speed: float, travel_limit: float, target: float) -> None:
    """Options that contradict each other are usage errors, found before connecting."""
    if speed > max_speed:
        raise typer.BadParameter(f"{speed:g} deg/s is beyond --max-speed {max_speed:g}", param_hint="--speed")
    if target > travel_limit:
        raise typer.BadParameter(f"{target:g} deg is beyond --travel-limit {travel_limit:g}",
                                 param_hint="--angle")
