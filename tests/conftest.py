"""Puts the repository's bench/ folder on sys.path, so tests can import the bench's plants."""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
