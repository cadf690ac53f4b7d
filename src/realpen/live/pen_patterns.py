"""The pens' tactile patterns as the pen plays them, rendered once per pen and rate.

A page that drives its own link to the pen (Web Serial, Web Bluetooth) uploads the pattern the
pen plays: the profile's tactile pattern at the pen's rate, as int16 little-endian
(:func:`realpen.device.pattern.pen_pattern`). Rendering takes a moment and every page asks
for the same few, so the last :data:`PEN_PATTERNS_KEPT` are kept, by pen, content version
and rate.
"""

from __future__ import annotations

import threading

from realpen.profile.bundle import PenProfile

__all__ = ["PenPatternCache", "PEN_PATTERNS_KEPT"]

PEN_PATTERNS_KEPT = 16  # rendered pen patterns kept (by pen, version and rate)


class PenPatternCache:
    """Rendered pen patterns, the oldest dropped first. Safe to share between threads (the
    routes run on the thread pool).

    Args:
        kept: how many rendered patterns are kept.
    """

    def __init__(self, kept: int = PEN_PATTERNS_KEPT):
        self.kept = kept
        self._rendered: dict[tuple[str, str, int], bytes] = {}
        self._lock = threading.Lock()

    def get(self, profile: PenProfile, rate: int) -> bytes:
        """``profile``'s tactile pattern as the pen plays it at ``rate`` Hz: int16
        little-endian bytes.

        Raises:
            RealPenError: a rate the pattern cannot take.
        """
        from realpen.device.pattern import pattern_bytes, pen_pattern

        key = (profile.name, profile.version, rate)
        with self._lock:
            data = self._rendered.get(key)
        if data is None:
            data = pattern_bytes(pen_pattern(profile, rate))  # outside the lock: it takes a while
            with self._lock:
                if len(self._rendered) >= self.kept:
                    self._rendered.pop(next(iter(self._rendered)))
                self._rendered[key] = data
        return data
