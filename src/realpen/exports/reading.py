"""Read a haptic file back — ``.hjif``, ``.haptic``, ``.ahap`` or RealPen's Android JSON — and
render what a player would play.

Every export is proven by reading it back: :func:`load_haptic` checks the file against its
format's rules (each refusal one line naming the file, the field and the rule) and returns a
:class:`HapticFile` whose :meth:`HapticFile.render` gives the vibration as samples. How each
format is played is documented in its reader (:mod:`realpen.exports.readers`); where a format
leaves the player a choice (the envelope formats' carrier), the model used is stated there and
in :attr:`HapticFile.notes`.

    import realpen as rp
    clip = rp.load_haptic("pencil.hjif")
    samples = clip.render(8000)          # float64, full scale ±1
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from realpen.checks import MAX_RATE_HZ, MIN_RATE_HZ
from realpen.errors import ParameterError, fail
from realpen.exports.base import MAX_EXPORT_FRAMES
from realpen.exports.readers.fields import Playback
from realpen.io.limits import load_json

__all__ = ["READ_FORMATS", "DEFAULT_RENDER_RATE", "MAX_HAPTIC_FILE_BYTES", "MAX_HAPTIC_VALUES",
           "HapticFile", "format_of_file", "load_haptic", "frame_rms"]

READ_FORMATS = {".hjif": "hjif", ".haptic": "haptic", ".ahap": "ahap", ".json": "android",
                ".vij": "haptic"}
"""File suffix → the format read from it (RealPen's Android export is ``.json``; a Lofelt v0
``.vij`` is refused by the ``.haptic`` reader, saying so)."""
DEFAULT_RENDER_RATE = 8000
"""The rate (Hz) :meth:`HapticFile.render` uses by default: the bundled pens' own."""
MAX_HAPTIC_FILE_BYTES = {"hjif": 256 * 1024 * 1024, "haptic": 16 * 1024 * 1024,
                         "ahap": 16 * 1024 * 1024, "android": 16 * 1024 * 1024}
"""The largest haptic file read, by format (bytes): the largest ``.hjif`` RealPen writes
(:data:`realpen.exports.hjif.MAX_EFFECTS` effects) is under 256 MB; the largest envelope file
(600 s at a point every 10 ms) under 10 MB."""
MAX_HAPTIC_VALUES = {"hjif": 2**24, "haptic": 2**20, "ahap": 2**20, "android": 2**20}
"""The most JSON values (objects, arrays, numbers, strings) in a haptic file read, by format;
checking each costs time."""


@dataclass(frozen=True)
class HapticFile:
    """A haptic file read back.

    Attributes:
        path: the file.
        format: ``"hjif"``, ``"haptic"``, ``"ahap"`` or ``"android"``.
        document: the parsed JSON.
        duration_s: how long a player plays it once, in s.
        summary: one line saying what it holds.
        notes: how it was read where the format leaves a choice.
    """

    path: Path
    format: str
    document: dict
    duration_s: float
    summary: str
    notes: tuple[str, ...]
    playback: Playback

    def __repr__(self) -> str:
        return f"HapticFile({self.path.name}, {self.format}, {self.duration_s:g} s: {self.summary})"

    def render(self, rate: int = DEFAULT_RENDER_RATE) -> np.ndarray:
        """The vibration a player would drive, as float64 mono samples at ``rate`` Hz.

        Args:
            rate: whole Hz, from :data:`~realpen.checks.MIN_RATE_HZ` to
                :data:`~realpen.checks.MAX_RATE_HZ`.

        Raises:
            ParameterError: (parameter ``rate``) a bad rate, or more samples than an export
                holds (:data:`~realpen.exports.base.MAX_EXPORT_FRAMES`).
        """
        if isinstance(rate, bool) or not isinstance(rate, (int, float, np.integer)) \
                or not math.isfinite(rate) or int(rate) != rate \
                or not MIN_RATE_HZ <= rate <= MAX_RATE_HZ:
            raise ParameterError("rate", f"must be a whole number of Hz from {MIN_RATE_HZ:g} "
                                         f"to {MAX_RATE_HZ:g}, got {rate}")
        frames = self.duration_s * int(rate)
        if frames > MAX_EXPORT_FRAMES:
            raise ParameterError("rate", f"{self.path.name} lasts {self.duration_s:g} s: "
                                         f"{frames:,.0f} samples at {int(rate)} Hz; at most "
                                         f"{MAX_EXPORT_FRAMES:,} are rendered")
        return np.asarray(self.playback.render(int(rate)), dtype=np.float64)

    def envelope(self, rate: int = DEFAULT_RENDER_RATE, frame_ms: float = 10.0) -> np.ndarray:
        """The RMS of the rendered vibration in ``frame_ms`` frames (full scale)."""
        return frame_rms(self.render(rate), rate, frame_ms)


def frame_rms(samples: np.ndarray, rate: float, frame_ms: float = 10.0) -> np.ndarray:
    """RMS of consecutive ``frame_ms`` frames of ``samples`` (a last partial frame is dropped).

    Args:
        samples: mono samples.
        rate: their rate in Hz.
        frame_ms: frame length in ms.
    """
    x = np.asarray(samples, dtype=np.float64)
    size = max(1, int(round(frame_ms * rate / 1000)))
    count = len(x) // size
    return np.sqrt(np.mean(x[:count * size].reshape(count, size) ** 2, axis=1))


def format_of_file(path: str | os.PathLike) -> str:
    """The format :func:`load_haptic` reads from ``path``, by its suffix.

    Raises:
        RealPenError: a suffix no reader takes, naming the known ones.
    """
    suffix = Path(path).suffix.lower()
    if suffix not in READ_FORMATS:
        known = ", ".join(f"{s} ({f})" for s, f in READ_FORMATS.items())
        raise fail(path, f"cannot be read: unknown suffix '{suffix}' (known: {known})")
    return READ_FORMATS[suffix]


def _reader(fmt: str):
    import importlib

    return importlib.import_module(f"realpen.exports.readers.{fmt}")


def load_haptic(path: str | os.PathLike) -> HapticFile:
    """Read a haptic file: ``.hjif`` (MPEG-I haptics), ``.haptic`` (Lofelt / Meta v1),
    ``.ahap`` (Apple Core Haptics) or ``.json`` (RealPen's Android export).

    Args:
        path: the file; its suffix says the format.

    Returns:
        The :class:`HapticFile`; :meth:`HapticFile.render` plays it.

    Raises:
        RealPenError: one line naming the file: unreadable, too large, not JSON, or a field
            that breaks the format's rules (naming the field and the rule).

    Example:
        >>> import realpen as rp, tempfile, pathlib
        >>> folder = pathlib.Path(tempfile.mkdtemp())
        >>> _ = rp.export("haptic", folder / "pencil.haptic", rp.load_profile("pencil"))
        >>> clip = rp.load_haptic(folder / "pencil.haptic")
        >>> clip.format, round(clip.duration_s, 3), len(clip.render(8000))
        ('haptic', 1.5, 12000)
    """
    path = Path(path)
    fmt = format_of_file(path)
    if not path.is_file():
        raise fail(path, "no such file" if not path.exists() else "is not a file")
    document = load_json(path, max_bytes=MAX_HAPTIC_FILE_BYTES[fmt],
                         max_values=MAX_HAPTIC_VALUES[fmt])
    if not isinstance(document, dict):
        raise fail(path, f"must hold a JSON object, got {type(document).__name__}")
    playback = _reader(fmt).read(document, path)
    return HapticFile(path, fmt, document, playback.duration_s, playback.summary,
                      playback.notes, playback)
