"""Options shared by the commands that talk to a robot or write what it will play.

``play``, ``track``, ``home``, ``jog``, ``status``, ``detect-shift --port`` and ``compensate``
declare their limits, what to do with a step beyond the speed limit and their reply deadline from
here, so that one option means one thing
(and has one default, with its reason) everywhere. Every number is checked when parsed: a
non-finite or non-positive value is a usage error (exit 2), never a traceback or a silently
ignored limit (``nan`` passes a plain ``min=`` bound).
"""
from __future__ import annotations

import math
from typing import Annotated, Optional

import typer

from ..safety import Limits


def positive(value: float | None) -> float | None:
    """Option callback: a positive finite number (None passes: an optional option not given)."""
    if value is not None and not (math.isfinite(value) and value > 0):
        raise typer.BadParameter(f"must be a positive number, got {value}")
    return value


def finite(value: float | None) -> float | None:
    """Option callback: a finite number."""
    if value is not None and not math.isfinite(value):
        raise typer.BadParameter(f"must be a finite number, got {value}")
    return value


TimeoutOpt = Annotated[float, typer.Option(
    "--timeout", callback=positive,
    help="Deadline of each reply from the robot, s, beyond the motion's own duration and any "
         "dwell (a MOVE is answered on arrival).")]
TravelLimitOpt = Annotated[float, typer.Option(
    "--travel-limit", callback=positive,
    help="Largest |knob angle| any command may reach, deg. The default is half a turn each way, "
         "beyond every command of the paper's protocol. A robot that announces a tighter travel "
         "limit gets its own.")]
MaxSpeedOpt = Annotated[float, typer.Option(
    "--max-speed", callback=positive,
    help="Largest knob speed, deg/s. The default is one knob turn a second: the paper's motions "
         "need at most 40 and a geared knob motor does a few hundred. A robot that announces a "
         "lower top speed gets its own.")]
InverseMaxSpeedOpt = Annotated[float, typer.Option(
    "--max-speed", callback=positive,
    help="Largest knob speed between samples, deg/s. The default is one knob turn a second: the "
         "paper's motions need at most 40 and a geared knob motor does a few hundred, while the "
         "inverse model's jump across the dead zone or the backlash asks for up to ~40 deg within "
         "one sample (3942 deg/s at 100 Hz): such a step is crossed at this speed. A robot that "
         "announces a lower top speed gets its own.")]
"""``--max-speed`` of the commands that play the inverse model's commands (compensate, track, play),
whose help says what becomes of a faster step."""
MaxAccelOpt = Annotated[Optional[float], typer.Option(
    "--max-accel", callback=positive,
    help="Largest knob acceleration, deg/s^2 (default: reported, not limited).")]
AllowFastOpt = Annotated[bool, typer.Option(
    "--allow-fast",
    help="Keep steps beyond --max-speed (and --max-accel) as they are: `compensate` writes the "
         "exact inverse, jumps included; `play` and `track` send them at the speed limit (the knob "
         "arrives late). By default such steps are rate-limited: the knob crosses them at the "
         "limit and catches up, and a warning says how long it lags. Travel is never waived.")]
StrictSpeedOpt = Annotated[bool, typer.Option(
    "--strict-speed",
    help="Refuse (write or move nothing) when a step is beyond --max-speed (or --max-accel) "
         "instead of rate-limiting it.")]
NoReturnOpt = Annotated[bool, typer.Option(
    "--no-return", help="On a fault or Ctrl-C, hold the knobs where they stopped instead of "
                        "returning them to where they began.")]
MoveSpeedOpt = Annotated[float, typer.Option(
    "--speed", callback=positive,
    help="Knob speed of the move, deg/s; the default is slow enough to watch and stop by hand.")]


def limits(travel_limit: float, max_speed: float, max_accel: float | None = None) -> Limits:
    """The :class:`~hystcli.safety.Limits` the options give."""
    return Limits(travel_limit, max_speed, max_accel)


def speed_mode(allow_fast: bool, strict_speed: bool) -> str:
    """The :data:`~hystcli.safety.SPEED_MODES` entry the flags ask for (both: a usage error)."""
    if allow_fast and strict_speed:
        raise typer.BadParameter("--allow-fast keeps fast steps, --strict-speed refuses them: give one",
                                 param_hint="--allow-fast / --strict-speed")
    return "fast" if allow_fast else "strict" if strict_speed else "limit"


def limit_hint(exc: Exception) -> str:
    """What to change when a trajectory is refused by a limit (``LimitExceeded``)."""
    check = getattr(exc, "check", None)
    if check is None:
        return ""
    first = check.violations[0].limit if check.violations else ""
    if first == "travel":
        return "; raise --travel-limit only if the robot's knob allows it"
    return ("; without --strict-speed such steps are rate-limited (the knob crosses them at the limit "
            "and catches up), --allow-fast keeps them, or raise --max-speed/--max-accel if the robot "
            "allows it")
