"""The pen profiles a live server offers: the bundled pens, the user's, and extra folders."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import numpy as np

from realpen.errors import RealPenError, fail
from realpen.exports.base import resample_loop
from realpen.io.files import wav_bytes
from realpen.pens import BUNDLED_PENS
from realpen.profile.bundle import PenProfile
from realpen.profile.registry import list_profiles, load_profile
from realpen.profile.schema import MAX_WAV_FRAMES

__all__ = ["MIN_WAV_RATE", "playable_rate", "playable_wav", "CatalogEntry", "Catalog"]

MIN_WAV_RATE = 3000  # browsers' decodeAudioData refuses WAVs below 3 kHz (Chrome, the spec's floor)


def playable_rate(frames: int, rate: int, preferred: int) -> int:
    """The rate to serve a looping signal of ``frames`` samples at ``rate`` Hz in a browser.

    ``rate`` itself when it is at least :data:`MIN_WAV_RATE`; else ``preferred`` (the sound's
    rate) when the loop is a whole number of samples there; else the smallest whole multiple of
    ``rate`` that is at least :data:`MIN_WAV_RATE` (always a whole number of samples).
    """
    rate, preferred = int(rate), int(preferred)
    if rate >= MIN_WAV_RATE:
        return rate
    if preferred >= MIN_WAV_RATE and (frames * preferred) % rate == 0:
        return preferred
    return rate * math.ceil(MIN_WAV_RATE / rate)


def playable_wav(samples: np.ndarray, rate: int, preferred: int, what: str) -> bytes:
    """One period of a loop as a 32-bit float WAV a browser decodes (see :func:`playable_rate`).

    Below 3 kHz the period is resampled as a loop (seamless across the wrap) and, should the
    anti-aliasing filter overshoot full scale, scaled back to peak 1.
    """
    new_rate = playable_rate(len(samples), rate, preferred)
    if new_rate == rate:
        return wav_bytes(samples, rate)
    resampled = resample_loop(samples, rate, new_rate, what)
    peak = float(np.max(np.abs(resampled))) if len(resampled) else 0.0
    if peak > 1.0:
        resampled = resampled / peak
    return wav_bytes(resampled, new_rate)


@dataclass
class CatalogEntry:
    """One offered profile and where it was found (``bundled``, ``user`` or ``extra``)."""

    profile: PenProfile
    where: str
    _point_wavs: dict[int, bytes] = field(default_factory=dict, repr=False)

    @property
    def sound_rate(self) -> int:
        """The rate the sound unit is served at (its own, unless below 3 kHz)."""
        meta = self.profile.meta
        return playable_rate(meta.sound.frames, meta.sound.rate, meta.sound.rate)

    @property
    def tactile_rate(self) -> int:
        """The rate the tactile pattern is served at: its own, or, below 3 kHz (which browsers
        cannot decode), the sound's rate or a whole multiple of its own."""
        pattern = self.profile.meta.tactile
        return playable_rate(pattern.frames, pattern.rate, self.profile.meta.sound.rate)

    @cached_property
    def sound_wav(self) -> bytes:
        """The sound unit as a 32-bit float WAV (the page decodes and loops it)."""
        return playable_wav(self.profile.sound, self.profile.meta.sound.rate,
                            self.profile.meta.sound.rate, f"{self.profile.name} sound unit")

    @cached_property
    def tactile_wav(self) -> bytes:
        """The tactile pattern as a 32-bit float WAV at :attr:`tactile_rate` (Web Audio
        resamples it to the context's rate)."""
        return playable_wav(self.profile.tactile, self.profile.meta.tactile.rate,
                            self.profile.meta.sound.rate, f"{self.profile.name} tactile pattern")

    @cached_property
    def grid(self):
        """The profile's :class:`~realpen.tactile.grid.VibrationGrid` when it has more than one
        point (the page then mixes one loop per point), else None (one loop, as ever)."""
        grid = self.profile.grid
        return grid if len(grid.points) > 1 else None

    def point_rate(self, index: int) -> int:
        """The rate grid point ``index``'s loop is served at (as :attr:`tactile_rate`)."""
        pattern = self.grid.points[index].pattern
        return playable_rate(pattern.frames, pattern.rate, self.profile.meta.sound.rate)

    def point_wav(self, index: int) -> bytes:
        """Grid point ``index``'s loop as a 32-bit float WAV at :meth:`point_rate`, rendered
        from its pattern once and kept (the reference point's is :attr:`tactile_wav`).

        Raises:
            IndexError: no such point (or no grid).
        """
        if self.grid is None or not 0 <= index < len(self.grid.points):
            raise IndexError(index)
        if index == self.grid.reference:
            return self.tactile_wav
        cached = self._point_wavs.get(index)
        if cached is None:
            pattern = self.grid.points[index].pattern
            cached = playable_wav(pattern.render(), pattern.rate, self.profile.meta.sound.rate,
                                  f"{self.profile.name} tactile pattern at grid point {index}")
            self._point_wavs[index] = cached  # two threads may both render it: same bytes
        return cached

    def check(self) -> None:
        """Refuse a profile whose loops would be too long to serve.

        Below 3 kHz a loop is served resampled, up to 4,000 times as many frames (100 Hz to
        400 kHz): the served WAV may hold at most
        :data:`~realpen.profile.schema.MAX_WAV_FRAMES` frames, like a bundle's own.

        Raises:
            RealPenError: naming the bundle and the loop.
        """
        meta = self.profile.meta
        loops = [("tactile pattern", meta.tactile.frames, meta.tactile.rate, self.tactile_rate),
                 ("sound unit", meta.sound.frames, meta.sound.rate, self.sound_rate)]
        for index, point in enumerate(self.grid.points if self.grid else ()):
            loops.append((f"tactile pattern at grid point {index}", point.pattern.frames,
                          point.pattern.rate, self.point_rate(index)))
        for what, frames, rate, served in loops:
            length = frames * served // rate
            if length > MAX_WAV_FRAMES:
                raise fail(self.profile.path or self.profile.name,
                           f"its {what} would be {length:,} frames served at {served} Hz; "
                           f"the limit is {MAX_WAV_FRAMES:,}")

    def to_json(self) -> dict:
        """The entry as the page reads it (``GET /api/profiles``): the pen, its version and
        coupling, and where to fetch its sound and tactile loops; ``tactile`` describes the
        :class:`~realpen.tactile.pattern.TactilePattern` (rate, frames, sub-patterns).

        A profile whose grid has more than one point also has ``grid``: its points (speed in
        mm/s, force in N, the rate and URL of the point's loop), the Delaunay ``triangles``
        over them (index triples), ``scale`` (mm/s and N: each axis is divided by it before
        distances are measured, as the triangulation did), ``full_pressure_force_n`` (the force
        at page pressure 1) and ``reference`` (the point whose loop is ``tactile``)."""
        meta = self.profile.meta
        pattern = meta.tactile
        name = self.profile.name
        return {
            "name": name, "tool": meta.tool, "description": meta.description,
            "version": self.profile.version, "where": self.where,
            "coupling": meta.coupling.to_json(),
            "sound": {"rate": meta.sound.rate, "frames": meta.sound.frames,
                      "wav_rate": self.sound_rate, "url": f"api/profiles/{name}/sound.wav"},
            "tactile": {"rate": pattern.rate, "frames": pattern.frames,
                        "subpatterns": len(pattern.subpatterns),
                        "subpattern_ms": pattern.subpattern_ms, "boundary": pattern.boundary,
                        "wav_rate": self.tactile_rate,
                        "url": f"api/profiles/{name}/tactile.wav"},
            **({"grid": self._grid_json()} if self.grid is not None else {}),
        }

    def _grid_json(self) -> dict:
        grid, name = self.grid, self.profile.name
        points = [{"speed_mm_s": p.speed_mm_s, "force_n": p.force_n,
                   "wav_rate": self.point_rate(i),
                   "url": (f"api/profiles/{name}/tactile.wav" if i == grid.reference
                           else f"api/profiles/{name}/grid/{i}.wav")}
                  for i, p in enumerate(grid.points)]
        return {"points": points, "triangles": grid.triangles.tolist(),
                "scale": [float(s) for s in grid.scale],
                "full_pressure_force_n": grid.full_pressure_force_n,
                "reference": grid.reference, "mix_gain": grid.mix_gain}


class Catalog:
    """Profiles by name: bundled pens first (pencil, ballpoint, marker), then the others.

    A name found twice keeps its first profile. A user or extra profile that does not load is
    skipped and listed in :attr:`skipped`, one line per bundle naming it and the problem
    (``realpen serve`` prints the list once, on stdout, in its startup summary), so one bad
    bundle does not stop the app. Loading a bundle raises nothing but
    :class:`~realpen.errors.RealPenError` whatever its bytes, within bounded memory
    (:func:`~realpen.profile.registry.load_profile`).
    """

    def __init__(self, extra: list[Path] | None = None):
        for folder in extra or []:
            if not Path(folder).is_dir():
                raise fail(folder, "no such folder of profiles")
        self.entries: dict[str, CatalogEntry] = {}
        self.skipped: list[str] = []
        for where, path in list_profiles([Path(p) for p in extra or []]):
            try:
                entry = CatalogEntry(load_profile(path), where)
                entry.check()
            except RealPenError as error:
                if where == "bundled":
                    raise
                self.skipped.append(" ".join(str(error).split()))  # one line, always
                continue
            self.entries.setdefault(entry.profile.name, entry)
        order = {name: i for i, name in enumerate(BUNDLED_PENS)}
        ranked = sorted(self.entries.values(),
                        key=lambda e: (order.get(e.profile.name, len(order)), e.where != "bundled"))
        self.entries = {entry.profile.name: entry for entry in ranked}
        if not self.entries:
            raise RealPenError("no pen profiles found (the bundled pens are missing?)")

    def get(self, name: str) -> CatalogEntry | None:
        """The entry of a pen by name, or None."""
        return self.entries.get(name)

    def add(self, path: Path, where: str = "user") -> CatalogEntry:
        """Offer the profile at ``path`` from now on (one installed while the server runs),
        after the others; one of the same name that is not bundled is replaced.

        Raises:
            RealPenError: the bundle does not load or its loops are too long to serve, or a
                bundled pen has that name.
        """
        entry = CatalogEntry(load_profile(path), where)
        entry.check()
        name = entry.profile.name
        held = self.entries.get(name)
        if held is not None and held.where == "bundled":
            raise fail(path, f"'{name}' is a bundled pen's name")
        # A new dict, swapped in whole: routes iterate the entries on other threads.
        self.entries = {**{key: e for key, e in self.entries.items() if key != name},
                        name: entry}
        return entry

    @property
    def names(self) -> list[str]:
        """The offered pens' names, bundled pens first."""
        return list(self.entries)

    def to_json(self) -> list[dict]:
        """Every entry's :meth:`CatalogEntry.to_json`, in order."""
        return [entry.to_json() for entry in self.entries.values()]
