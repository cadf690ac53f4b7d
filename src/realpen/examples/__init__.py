"""Example data that ships with RealPen (synthetic; see ``scripts/make_example_recording.py``).

May import: the standard library only (it hands out paths; the readers live in :mod:`realpen.io`).
"""

from importlib.resources import files
from pathlib import Path


def example_recording_path() -> Path:
    """Path of the bundled synthetic 3-axis pen-on-paper recording (1344 Hz, m/s², 12 s)."""
    return Path(str(files(__name__) / "synthetic_pen_3axis.npz"))
