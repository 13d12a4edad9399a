"""Puts the repository's bench/ folder on sys.path so tests can import the bench modules."""
import sys, pathlib; sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "bench"))
