"""The independent zoo's live plant for ``hyst sim-robot --plant bench/plants/live.py:SPEC``.

``SPEC`` is ``SEED[:FAMILY[:OFFSET]]``: the plant of :func:`plants.zoo.plants.live_plant` for that
seed and current-law family, its shaft bent by OFFSET deg (knob 1 only). The test plants are not
installed with hyst, so the command loads them from this file; like the plants, it imports nothing
from hystcli.
"""
from __future__ import annotations

import math
import sys
from pathlib import Path

# sim-robot loads this file by path: the bench folder (which holds the plants package) goes on
# sys.path so that the plants import as they do in the tests and benches
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from plants.zoo import plants  # noqa: E402


def plant(spec: str):  # noqa: ANN201 - plants.zoo.plants.LivePlant
    """The live plant ``SEED[:FAMILY[:OFFSET]]``; ValueError names what is wrong with ``spec``."""
    parts = spec.split(":")
    try:
        seed = int(parts[0])
        family = parts[1] if len(parts) > 1 and parts[1] else None
        offset = float(parts[2]) if len(parts) > 2 else 0.0
        ok = len(parts) <= 3 and seed >= 0 and math.isfinite(offset) and (family is None or family in plants.FAMILIES)
    except ValueError:
        ok = False
    if not ok:
        raise ValueError(f"expected SEED[:FAMILY[:OFFSET]], FAMILY one of {', '.join(plants.FAMILIES)}")
    return plants.live_plant(seed, family, offset=offset)[0]
