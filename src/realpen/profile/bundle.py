"""Pen profile bundles: the in-memory :class:`PenProfile`, and reading and writing bundles.

A bundle is a folder (or the same files in a ``.zip``) holding

- ``profile.json`` — versioned and validated (:mod:`realpen.profile.schema`): name, tool, the
  tactile pattern's fields, the sound unit, the actuator, the coupling constants (Eq. 1), the
  two WAVs' rates, lengths and SHA-256, and provenance;
- ``tactile.wav`` — the looping tactile pattern (mono, 32-bit float, ``smpl`` loop chunk);
- ``sound.wav`` — the looping friction-sound unit (mono, 32-bit float, RMS −20 dBFS, ``smpl``).

Loading checks that the WAVs are there and are the ones the JSON describes (rate, length,
SHA-256), so a bundle can be trusted or is refused with one clear line. Bundles of format 1 are
read too (:func:`realpen.profile.schema.upgrade`).
"""

from __future__ import annotations

import hashlib
import io
import json
import os
import shutil
import tempfile
import zipfile
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from pydantic import ValidationError

from realpen.errors import ParameterError, fail
from realpen.io.files import atomic_path, current_umask, wav_bytes
from realpen.profile.schema import (
    BUNDLE_FILES,
    FORMAT,
    PROFILE_JSON,
    READABLE_FORMATS,
    SOUND_WAV,
    TACTILE_WAV,
    BundleFiles,
    ProfileMeta,
    WavFile,
    profile_version,
    upgrade,
)
from realpen.tactile.actuator import Actuator
from realpen.tactile.conditions import TactileParams
from realpen.tactile.pattern import TactilePattern

__all__ = ["PenProfile", "save_profile", "load_profile", "bundle_wavs"]


@dataclass
class PenProfile:
    """A loaded or freshly built pen profile.

    Attributes:
        meta: the validated ``profile.json`` (``meta.tactile`` is the
            :class:`~realpen.tactile.pattern.TactilePattern`, ``meta.actuator`` the
            :class:`~realpen.tactile.actuator.Actuator`, ``meta.coupling`` the coupling).
        tactile: the tactile pattern's samples, float32, shape (frames,), full scale ±1.
        sound: the sound unit, float32, shape (frames,), full scale ±1.
        path: where it was loaded from (None when built in memory).
    """

    meta: ProfileMeta
    tactile: np.ndarray
    sound: np.ndarray
    path: Path | None = None

    @property
    def name(self) -> str:
        """The profile's name."""
        return self.meta.name

    @property
    def actuator(self) -> Actuator:
        """The actuator the tactile pattern is equalised for."""
        return self.meta.actuator

    @property
    def coupling(self):
        """The coupling constants of Eq. 1 (:class:`realpen.sound.coupling.Coupling`)."""
        return self.meta.coupling

    @property
    def pattern(self) -> TactilePattern:
        """The tactile pattern, its samples those of ``tactile.wav``, with its actuator and
        (when the provenance holds them) its parameters."""
        base = self.meta.tactile
        try:
            params = TactileParams(**self.meta.provenance.tactile_parameters)
        except (TypeError, ParameterError):
            params = None
        pattern = replace(base, actuator=self.meta.actuator, params=params,
                          notes=tuple(self.meta.provenance.notes))
        return pattern.with_samples(self.tactile)

    @property
    def sound_loop(self):
        """The sound unit as a :class:`realpen.sound.loop.SoundLoop` (the one sound-loop type:
        samples, rate in Hz, how it was cut, its seam), for the exports and the display."""
        from realpen.sound.loop import Seam, SoundLoop

        section = self.meta.sound
        try:
            seam = Seam(**section.seam)
        except TypeError:  # a seam report of another shape (or none)
            seam = None
        return SoundLoop(samples=self.sound, rate=section.rate, mode=section.mode,
                         start_s=section.start_s, unit_ms=section.unit_ms,
                         crossfade_ms=section.crossfade_ms or None, seam=seam,
                         source=str(self.path) if self.path is not None else self.name)

    @property
    def version(self) -> str:
        """Content version: 12 hex digits of the SHA-256 of the canonical form of
        ``profile.json`` (see :func:`realpen.profile.schema.profile_version`); the same pen
        has the same version on every machine."""
        return profile_version(self.meta)

    def summary(self) -> str:
        """One line: name, tool, components, lengths, actuator."""
        t, s = self.meta.tactile, self.meta.sound
        counts = {len(sub) for sub in t.subpatterns}
        return (f"{self.name}: {self.meta.tool}; tactile {len(t.subpatterns)}×{t.subpattern_ms:g} ms, "
                f"{'/'.join(map(str, sorted(counts)))} components, {t.rate} Hz; sound "
                f"{s.unit_ms:g} ms {s.mode} at {s.rate} Hz; actuator {self.meta.actuator.spec}")

    def __repr__(self) -> str:
        t, s = self.meta.tactile, self.meta.sound
        tool = self.meta.tool if len(self.meta.tool) <= 40 else self.meta.tool[:37] + "..."
        return (f"PenProfile({self.name!r}, {tool!r}, tactile {len(t.subpatterns)}×"
                f"{t.subpattern_ms:g} ms at {t.rate} Hz, sound {s.unit_ms:g} ms at {s.rate} Hz, "
                f"version {self.version})")

    def _current_meta(self, wavs: dict[str, bytes]) -> ProfileMeta:
        """``meta`` with ``files`` describing ``wavs``, checked against the samples."""
        pattern, sound = self.meta.tactile, self.meta.sound
        if len(self.tactile) != pattern.frames:
            raise ParameterError("tactile", f"{len(self.tactile)} samples, but the pattern is "
                                            f"{pattern.frames} at {pattern.rate} Hz")
        if len(self.sound) != sound.frames:
            raise ParameterError("sound", f"{len(self.sound)} samples, but the sound section "
                                          f"says {sound.frames}")
        files = BundleFiles(
            tactile=WavFile(file=TACTILE_WAV, rate=pattern.rate, frames=len(self.tactile),
                            sha256=_sha(wavs[TACTILE_WAV])),
            sound=WavFile(file=SOUND_WAV, rate=sound.rate, frames=len(self.sound),
                          sha256=_sha(wavs[SOUND_WAV])))
        return self.meta.model_copy(update={"files": files})


def bundle_wavs(profile: PenProfile) -> dict[str, bytes]:
    """The two WAV files of a bundle, by name (32-bit float, each one loop with a ``smpl``
    loop chunk)."""
    return {TACTILE_WAV: wav_bytes(np.asarray(profile.tactile, dtype=np.float32),
                                   profile.meta.tactile.rate, loop=True),
            SOUND_WAV: wav_bytes(np.asarray(profile.sound, dtype=np.float32),
                                 profile.meta.sound.rate, loop=True)}


def _document_bytes(meta: ProfileMeta) -> bytes:
    return (json.dumps(meta.model_dump(mode="json"), indent=2, allow_nan=False)
            + "\n").encode("utf-8")


def _sha(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def _read_wav(data: bytes, name: str, source: object) -> tuple[np.ndarray, int]:
    import soundfile as sf

    try:
        samples, rate = sf.read(io.BytesIO(data), dtype="float32", always_2d=True)
    except (sf.LibsndfileError, RuntimeError, ValueError) as error:
        raise fail(source, f"{name} is not a readable WAV ({str(error).splitlines()[0]})") from None
    if samples.shape[1] != 1:
        raise fail(source, f"{name} has {samples.shape[1]} channels; a profile WAV is mono")
    return samples[:, 0], rate


def save_profile(profile: PenProfile, target: str | os.PathLike) -> Path:
    """Write a bundle atomically: a folder, or a ``.zip`` when ``target`` ends in ``.zip``.

    ``profile.json``'s ``files`` section is made from the samples written. An existing bundle
    at ``target`` is replaced only once the new one is complete; a folder holding anything but
    a bundle is never replaced.

    Returns:
        The bundle's path (a folder's resolved path).

    Raises:
        ParameterError: the samples do not match the pattern or the sound section.
        RealPenError: the target cannot be written (naming it).
    """
    target = Path(target)
    wavs = bundle_wavs(profile)
    files = {PROFILE_JSON: _document_bytes(profile._current_meta(wavs)), **wavs}
    if target.suffix.lower() == ".zip":
        with atomic_path(target) as tmp:
            with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as archive:
                for name, data in files.items():
                    # A fixed date keeps the archive byte-identical when rebuilt.
                    info = zipfile.ZipInfo(name, date_time=(2016, 10, 16, 0, 0, 0))
                    info.compress_type = zipfile.ZIP_DEFLATED
                    archive.writestr(info, data)
        return target
    target = target.resolve()
    if target.exists() and not target.is_dir():
        raise fail(target, "exists and is not a folder")
    if target == Path.cwd().resolve() or target in Path.cwd().resolve().parents:
        raise fail(target, "is the current folder; give the bundle a folder of its own")
    if target.is_dir():
        others = sorted(p.name for p in target.iterdir() if p.name not in BUNDLE_FILES)
        if others:
            raise fail(target, f"is a folder holding other files ({', '.join(others[:3])}); "
                               f"a bundle replaces only a folder that holds a bundle")
    target.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=f".{target.name}.", dir=target.parent))
    os.chmod(staging, 0o777 & ~current_umask())  # mkdtemp makes 0700; a bundle is shared
    try:
        for name, data in files.items():
            (staging / name).write_bytes(data)
        if target.exists():
            retired = Path(tempfile.mkdtemp(prefix=f".{target.name}.old.", dir=target.parent))
            os.replace(target, retired / "bundle")
            os.replace(staging, target)
            shutil.rmtree(retired, ignore_errors=True)
        else:
            os.replace(staging, target)
    finally:
        if staging.exists():
            shutil.rmtree(staging, ignore_errors=True)
    return target


def _read_bundle_files(path: Path) -> dict[str, bytes]:
    if not path.exists():
        raise fail(path, "no such profile (folder or .zip)")
    if path.is_dir():
        return {name: (path / name).read_bytes() for name in BUNDLE_FILES if (path / name).is_file()}
    try:
        with zipfile.ZipFile(path) as archive:
            members = [n for n in archive.namelist() if Path(n).name in BUNDLE_FILES]
            names = {Path(n).name: n for n in members}
            if len(names) != len(members):
                raise fail(path, "holds more than one profile (repeated profile.json or WAVs)")
            return {short: archive.read(full) for short, full in names.items()}
    except (zipfile.BadZipFile, OSError) as error:
        raise fail(path, f"not a profile folder or a readable .zip ({error})") from None


def _first_error(error: ValidationError) -> str:
    first = error.errors()[0]
    where = ".".join(str(part) for part in first["loc"])
    message = first["msg"].removeprefix("Value error, ")
    return f"{where}: {message}" if where else message


def load_profile(path: str | os.PathLike) -> PenProfile:
    """Load and check a bundle (folder or ``.zip``) of format 1 or 2.

    Args:
        path: the bundle's folder or ``.zip``; a bare name that is no file here (``"pencil"``)
            is looked up among the installed profiles
            (:func:`realpen.profile.registry.resolve_profile`).

    Example:
        >>> load_profile("pencil").meta.tactile
        TactilePattern(15 sub-patterns × 100 ms, 10 components each, 8000 Hz)

    Raises:
        RealPenError: a missing file, an unknown format version, a schema violation, or WAVs
            that do not match the JSON — each as one line naming the bundle.
    """
    text = os.fspath(path)
    path = Path(path)
    if not path.exists() and os.sep not in text and (os.altsep or os.sep) not in text \
            and path.suffix.lower() != ".zip":
        from realpen.profile.registry import resolve_profile

        return resolve_profile(text)
    files = _read_bundle_files(path)
    missing = [name for name in BUNDLE_FILES if name not in files]
    if missing:
        raise fail(path, f"incomplete profile: missing {', '.join(missing)}")
    try:
        document = json.loads(files[PROFILE_JSON].decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as error:
        raise fail(path, f"{PROFILE_JSON} is not valid JSON ({error})") from None
    if not isinstance(document, dict):
        raise fail(path, f"{PROFILE_JSON} must hold a JSON object")
    if type(document.get("format")) is not int or document["format"] not in READABLE_FORMATS:
        raise fail(path, f"unknown profile format {document.get('format')!r} (this RealPen "
                         f"reads formats {', '.join(map(str, READABLE_FORMATS))}; it writes "
                         f"{FORMAT})")
    try:
        meta = ProfileMeta.model_validate(upgrade(document))
    except ValidationError as error:
        raise fail(path, f"{PROFILE_JSON}: {_first_error(error)}") from None
    arrays = {}
    for name, wav in ((TACTILE_WAV, meta.files.tactile), (SOUND_WAV, meta.files.sound)):
        data = files[name]
        if _sha(data) != wav.sha256:
            raise fail(path, f"{name} does not match {PROFILE_JSON} (SHA-256 differs)")
        samples, rate = _read_wav(data, name, path)
        if rate != wav.rate or len(samples) != wav.frames:
            raise fail(path, f"{name} is {len(samples)} frames at {rate} Hz; {PROFILE_JSON} says "
                             f"{wav.frames} frames at {wav.rate} Hz")
        if not np.all(np.isfinite(samples)):
            raise fail(path, f"{name} holds NaN or infinite samples")
        arrays[name] = samples
    return PenProfile(meta, arrays[TACTILE_WAV], arrays[SOUND_WAV], path)
