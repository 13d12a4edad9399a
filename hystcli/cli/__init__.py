"""Command-line layer of hyst: parse, call one core function, render.

``app.py`` holds the typer app, the shared options and the error rendering; each ``*_cmds.py``
module registers the commands of one area of the core (model, twin, shift, metrics, device,
diagnosis). They are imported here, in name order, so that a new command module needs no edit
elsewhere.

Start-up time is part of the interface: ``hyst --help`` must cost about as much as importing
numpy. So no command module imports scipy, pandas, numba, matplotlib or a heavy core module at
its top: each command imports what it needs when it runs (``tests/test_cli_startup.py`` checks).
The console script enters through :func:`hystcli.__main__.main`, which imports this package
inside its Ctrl-C handler.
"""
from __future__ import annotations

import importlib
import pkgutil

from .app import app

# the workflow's order first (as `hyst --help` lists them), then any other command module
_ORDER = ("model_cmds", "inspect_cmds", "shift_cmds", "metrics_cmds", "diagnose_cmds", "twin_cmds",
          "device_cmds", "demo_cmds", "import_cmds")
_found = sorted(m.name for m in pkgutil.iter_modules(__path__) if m.name.endswith("_cmds"))
for _mod in [m for m in _ORDER if m in _found] + [m for m in _found if m not in _ORDER]:
    importlib.import_module(f"{__name__}.{_mod}")


def main() -> None:
    """Run the ``hyst`` command line (the same as the console script, :func:`hystcli.__main__.main`)."""
    from ..__main__ import main as entry

    entry()


__all__ = ["app", "main"]
