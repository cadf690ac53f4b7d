"""The pen profiles a live server offers: the bundled pens, the user's, and ``--profiles``."""

from __future__ import annotations

import logging
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

from ..errors import RealPenError, fail
from ..fileio import wav_bytes
from ..pens import BUNDLED_PENS
from ..profile import PenProfile, list_profiles, load_profile

log = logging.getLogger(__name__)


@dataclass
class CatalogEntry:
    """One offered profile and where it was found (``bundled``, ``user`` or ``extra``)."""

    profile: PenProfile
    where: str

    @cached_property
    def sound_wav(self) -> bytes:
        """The sound unit as a 32-bit float WAV (the page decodes and loops it)."""
        return wav_bytes(self.profile.sound, self.profile.meta.sound.rate)

    @cached_property
    def tactile_wav(self) -> bytes:
        """The tactile pattern as a 32-bit float WAV at its own rate (Web Audio resamples)."""
        return wav_bytes(self.profile.tactile, self.profile.meta.tactile.rate)

    def to_json(self) -> dict:
        meta = self.profile.meta
        name = self.profile.name
        return {
            "name": name, "tool": meta.tool, "description": meta.description,
            "version": self.profile.version, "where": self.where,
            "coupling": meta.coupling.to_json(),
            "sound": {"rate": meta.sound.rate, "frames": meta.sound.frames,
                      "url": f"api/profiles/{name}/sound.wav"},
            "tactile": {"rate": meta.tactile.rate, "frames": meta.tactile.frames,
                        "url": f"api/profiles/{name}/tactile.wav"},
        }


class Catalog:
    """Profiles by name: bundled pens first (pencil, ballpoint, marker), then the others.

    A name found twice keeps its first profile. A user or extra profile that does not load is
    skipped with a warning (listed in :attr:`skipped`), so one bad bundle does not stop the app.
    """

    def __init__(self, extra: list[Path] | None = None):
        for folder in extra or []:
            if not Path(folder).is_dir():
                raise fail(folder, "--profiles: no such folder")
        self.entries: dict[str, CatalogEntry] = {}
        self.skipped: list[str] = []
        for where, path in list_profiles([Path(p) for p in extra or []]):
            try:
                profile = load_profile(path)
            except RealPenError as error:
                if where == "bundled":
                    raise
                self.skipped.append(str(error))
                log.warning("skipping profile %s", error)
                continue
            self.entries.setdefault(profile.name, CatalogEntry(profile, where))
        order = {name: i for i, name in enumerate(BUNDLED_PENS)}
        ranked = sorted(self.entries.values(),
                        key=lambda e: (order.get(e.profile.name, len(order)), e.where != "bundled"))
        self.entries = {entry.profile.name: entry for entry in ranked}
        if not self.entries:
            raise RealPenError("no pen profiles found (the bundled pens are missing?)")

    def get(self, name: str) -> CatalogEntry | None:
        return self.entries.get(name)

    @property
    def names(self) -> list[str]:
        return list(self.entries)

    def to_json(self) -> list[dict]:
        return [entry.to_json() for entry in self.entries.values()]
