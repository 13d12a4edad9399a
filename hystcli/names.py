"""Names the command line offers in its help, in a module that imports nothing.

``hyst --help`` and ``hyst simulate --help`` list these; the modules that own what they name
(:mod:`hystcli.sim.twin` for the motions) are heavy to import, so the names live here and those
modules take them from here: one declaration, no import cost for the help.
"""
from __future__ import annotations

MOTIONS = ("sweep", "periodic", "nonperiodic")
"""Motions the virtual catheter generates (docs/design.md section 7): the identification sweep, the
paper's periodic input, its non-periodic input."""

__all__ = ["MOTIONS"]
