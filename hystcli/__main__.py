"""``python -m hystcli`` and the ``hyst`` console script: the command line.

The entry point is this small module rather than :mod:`hystcli.cli` so that Ctrl-C while the
command modules load (a few tenths of a second on a busy machine) is caught like Ctrl-C in a
command: ``Error: interrupted``, exit 130, no traceback.
"""
from __future__ import annotations

import sys


def main() -> None:
    """Entry point of the ``hyst`` console script."""
    try:
        from .cli import app

        # typer builds the click commands before its own Ctrl-C handling starts: covered here too
        app(prog_name="hyst")
    except KeyboardInterrupt:
        sys.stderr.write("Error: interrupted\n")
        raise SystemExit(130) from None


if __name__ == "__main__":
    main()
