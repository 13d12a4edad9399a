"""Commands of the live robot link: ``sim-robot`` (the twin behind a pseudo-terminal) and ``play``."""
from __future__ import annotations

import signal
import sys
from pathlib import Path
from typing import Annotated, List, Optional

import typer

from .. import io
from ..calibration import CALIBRATED_NAMES, calibrated_catheter
from ..errors import DataError
from ..model import Shape
from .app import BaudOpt, EffectOpt, OutOpt, QuietOpt, SeedOpt, command, effects_option, info, stderr_is_tty


@command("sim-robot", epilog="Example: hyst sim-robot --catheter ice-a --shape 'alpha=90,theta=0' "
                             "--latency-ms 2   (then: hyst play cmds.csv --port /dev/pts/N -o run.csv)")
def sim_robot_cmd(
    catheter: Annotated[str, typer.Option(
        help=f"Virtual catheter ({', '.join(CALIBRATED_NAMES)}): the calibrated one `hyst simulate` "
             "and the sample data use.")] = "ice-a",
    shape: Annotated[str, typer.Option(help="Shaft shape: 'straight' or 'alpha=90,theta=0;...' (deg).")] = "straight",
    rotation: Annotated[float, typer.Option(help="Bulk rotation of the catheter body (deg).")] = 0.0,
    effect: EffectOpt = None,
    seed: SeedOpt = 0,
    latency_ms: Annotated[float, typer.Option(min=0.0, help="Answer latency per frame (ms).")] = 0.0,
    knobs: Annotated[str, typer.Option(help="Knobs the robot drives, e.g. '1,2' or '1'.")] = "1,2",
    travel_limit: Annotated[float, typer.Option(min=1.0, help="Largest |knob angle| accepted (deg).")] = 170.0,
    name: Annotated[str, typer.Option(help="Device name sent in the handshake.")] = "hyst-sim",
    fault: Annotated[Optional[List[str]], typer.Option(
        "--fault", help="Inject a fault (tests): KIND@N[xCOUNT][=VALUE], KIND one of silent, garble, "
                        "close, error, spike, delay; N counts MOVE frames.")] = None,
    quiet: QuietOpt = False,
) -> None:
    """Serve the virtual catheter as a robot on a pseudo-terminal until Ctrl-C or SIGTERM.

    Prints the device path (one line on stdout) to pass as --port to `hyst play` or
    `hyst detect-shift`. The device speaks the hyst line protocol (docs/protocol.md) with the
    optional features dwell and mean. The catheter and its effects are those of
    `hyst simulate` given the same --catheter and --effect.
    """
    from ..effects import format_effects
    from ..emulator import Fault, serve
    from ..twin import LiveTwin

    try:
        knob_list = tuple(int(k) for k in knobs.split(","))
    except ValueError:
        raise typer.BadParameter(f"{knobs!r} is not a comma-separated list of knobs", param_hint="--knobs")
    if not knob_list or any(k not in (1, 2) for k in knob_list):
        raise typer.BadParameter("knobs are 1 and/or 2", param_hint="--knobs")
    if not name or any(not (0x21 <= ord(ch) <= 0x7E) or ch in "*=" for ch in name):
        raise typer.BadParameter("a printable name without spaces, '*' or '='", param_hint="--name")
    # the user-facing catheters are the calibrated ones: the same lookup as `hyst simulate`
    twin = LiveTwin(calibrated_catheter(catheter), shape=Shape.parse(shape), rotation=rotation,
                    effects=effects_option(effect), seed=seed, knobs=knob_list)
    faults = [Fault.parse(f) for f in fault or ()]
    server = serve(twin, latency=latency_ms / 1000.0, faults=faults, name=name,
                   travel_limit=travel_limit, background=False)

    def _terminate(signum, frame):  # SIGTERM ends the server like Ctrl-C
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGTERM, _terminate)
    try:
        sys.stdout.write(server.path + "\n")
        sys.stdout.flush()
        info(f"serving {catheter} ({Shape.parse(shape)}, rotation {rotation:g} deg, effects "
             f"{format_effects(twin.effects)}) on {server.path}; "
             "Ctrl-C to stop", quiet)
        server.serve_forever()
        if server.closed:
            info("the device port was closed (fault injected)", quiet)
    except KeyboardInterrupt:
        info("stopped", quiet)
    finally:
        signal.signal(signal.SIGTERM, previous)
        server.shutdown()


@command("sweep", epilog="Example: hyst sweep --knob 1 -o sweep_cmd.csv && hyst play sweep_cmd.csv "
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
    from ..twin import sweep

    t, q = sweep(amplitude=amplitude, cycles=cycles, peak_speed=peak_speed, fs=fs)
    run = io.Run({"t": t, f"q{knob}": q}, {"motion": "sweep", "controller": "none", "knob": str(knob),
                                            "shape": "straight"})
    io.write_run(output, run)
    info(f"wrote {output}: knob {knob}, +-{amplitude:g} deg, {cycles:g} cycles at up to "
         f"{peak_speed:g} deg/s, {len(run)} samples ({t[-1]:.1f} s)", quiet)


@command("play", epilog="Example: hyst play cmds.csv --port /dev/ttyUSB0 -o run.csv")
def play_cmd(
    trajectory: Annotated[Path, typer.Argument(help="Command trajectory CSV with t and q1/q2 "
                                               "(e.g. from `hyst compensate`).", show_default=False)],
    port: Annotated[str, typer.Option("--port", help="Serial port of the robot (name or pyserial URL).")],
    output: OutOpt,
    baud: BaudOpt = 115200,
    fast: Annotated[bool, typer.Option("--fast", help="Send each command as soon as the previous one "
                                       "is answered instead of at the file's timing.")] = False,
    timeout: Annotated[float, typer.Option(min=0.001, help="Deadline of each reply (s).")] = 1.0,
    quiet: QuietOpt = False,
) -> None:
    """Play the knob commands of TRAJECTORY on the robot and record t, q, c (and y) to a run CSV.

    The trajectory's metadata is kept, the device identity added. On any fault or Ctrl-C every
    motor is stopped, nothing is written, and the exit code is non-zero.
    """
    from ..device import Device, play_trajectory

    io.check_not_input(output, [trajectory])
    folder = output.parent if str(output.parent) else Path(".")
    if not folder.is_dir():
        raise DataError(f"{output}: the folder {folder} does not exist")
    run = io.read_run(trajectory, require=("t",))
    with Device(port, baud, timeout) as device:
        info(f"connected to {device.info.name} ({device.info.catheter}, knobs "
             f"{','.join(map(str, device.info.knobs))}, tracker {'yes' if device.info.tracker else 'no'})",
             quiet)
        progress = None
        if not quiet and stderr_is_tty():
            step = max(1, len(run) // 20)

            def progress(i: int, n: int) -> None:
                if i % step == 0 or i == n:
                    typer.echo(f"\rplaying {i}/{n}", err=True, nl=i == n)
        result = play_trajectory(device, run, paced=not fast, progress=progress)
    result = result.with_meta(trajectory=trajectory.name, port=port)
    io.write_run(output, result, inputs=[trajectory])
    info(f"wrote {output} ({len(result)} samples, max lag {result.meta['play_max_lag_s']} s)", quiet)
