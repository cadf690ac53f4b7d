"""Pen profile bundles: the in-memory :class:`PenProfile`, and reading and writing bundles.

A bundle is a folder (or the same files in a ``.zip``) holding

- ``profile.json`` — versioned and validated (:mod:`realpen.profile.schema`): name, tool, the
  tactile pattern's fields, the vibration grid's points when there are several (format 3: their
  loops are rendered from this JSON when needed, no more WAVs), the sound unit, the actuator,
  the coupling constants (Eq. 1), the two WAVs' rates, lengths and SHA-256, and provenance;
- ``tactile.wav`` — the looping tactile pattern (mono, 32-bit float, ``smpl`` loop chunk);
- ``sound.wav`` — the looping friction-sound unit (mono, 32-bit float, RMS −20 dBFS, ``smpl``).

Loading checks that the WAVs are there and are the ones the JSON describes (rate, length,
SHA-256), so a bundle can be trusted or is refused with one clear line. Bundles of format 1 are
read too (:func:`realpen.profile.schema.upgrade`).

Whatever its bytes, loading a bundle either succeeds or raises :class:`RealPenError` with one
line naming the bundle, and never reads more than its limits: ``profile.json`` at most
:data:`realpen.io.limits.MAX_JSON_BYTES` (read by :func:`realpen.io.limits.load_json`, which
also bounds nesting and number length), each WAV at most
:data:`realpen.profile.schema.MAX_WAV_BYTES`; sizes are checked before reading (a folder's
``stat``, a zip entry's declared size) and the read itself is bounded, so a lying zip header
cannot inflate more. A ``.zip`` is at most :data:`MAX_ZIP_BYTES` with at most
:data:`MAX_ZIP_ENTRIES` entries, none encrypted, each stored or deflated. A folder's files must
be regular files, not symbolic links, FIFOs or devices.
"""

from __future__ import annotations

import hashlib
import io
import json
import os
import shutil
import stat
import struct
import tempfile
import zipfile
import zlib
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from pydantic import ValidationError

from realpen.errors import ParameterError, RealPenError, fail
from realpen.io.files import atomic_path, current_umask, wav_bytes
from realpen.io.limits import MAX_JSON_BYTES, load_json
from realpen.profile.schema import (
    BUNDLE_FILES,
    FORMAT,
    MAX_WAV_BYTES,
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
from realpen.tactile.grid import VibrationGrid
from realpen.tactile.pattern import TactilePattern
from realpen.validation import one_line, validation_line

__all__ = ["PenProfile", "save_profile", "read_bundle", "bundle_wavs", "MAX_ZIP_ENTRIES",
           "MAX_ZIP_BYTES", "MAX_FILE_BYTES"]

MAX_FILE_BYTES = {PROFILE_JSON: MAX_JSON_BYTES, TACTILE_WAV: MAX_WAV_BYTES, SOUND_WAV: MAX_WAV_BYTES}
"""The largest size (bytes) of each file of a bundle, checked before it is read."""
MAX_ZIP_ENTRIES = 64
"""The most entries a bundle ``.zip`` may hold. A bundle is three files; folder entries and an
archiver's leftovers (``__MACOSX/``) fit, while the central directory of a zip of thousands of
entries is refused before any entry is read."""
MAX_ZIP_BYTES = sum(MAX_FILE_BYTES.values()) + 1024 * 1024
"""The largest bundle ``.zip`` read (bytes): its three files stored uncompressed at their limits,
plus 1 MiB for headers and leftovers (about 133 MiB)."""

# Entries RealPen inflates: what save_profile writes and every archiver's default. Others
# (bzip2, lzma — whose header may ask for a huge dictionary —, deflate64, …) are refused.
_ZIP_METHODS = (zipfile.ZIP_STORED, zipfile.ZIP_DEFLATED)
# What zipfile and zlib raise on damaged archives: truncated or inconsistent headers and
# streams, bad CRCs, sizes that do not fit. Caught only around reading the archive.
_ZIP_ERRORS = (zipfile.BadZipFile, zipfile.LargeZipFile, OSError, EOFError, ValueError,
               RuntimeError, NotImplementedError, OverflowError, struct.error, zlib.error)


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
        """The coupling constants of Eq. 1 (:class:`realpen.motion.coupling.Coupling`)."""
        return self.meta.coupling

    @property
    def pattern(self) -> TactilePattern:
        """The tactile pattern, its samples those of ``tactile.wav``, with its actuator and
        (when the provenance holds them) its parameters."""
        base = self.meta.tactile
        try:
            params = TactileParams(**self.meta.provenance.tactile_parameters)
        # Provenance of another version or shape, or numbers that overflow: not needed.
        except (TypeError, ValueError, ArithmeticError):
            params = None
        pattern = replace(base, actuator=self.meta.actuator, params=params,
                          notes=tuple(self.meta.provenance.notes))
        return pattern.with_samples(self.tactile)

    @property
    def grid(self) -> VibrationGrid:
        """The tactile patterns at (speed, force) points that the feel follows
        (:class:`~realpen.tactile.grid.VibrationGrid`): the profile's own grid, or a grid of one
        point, :attr:`pattern`, when it has none (which plays exactly as that one pattern).

        Every point's pattern carries the profile's actuator and parameters; the reference
        point's is :attr:`pattern` (the samples of ``tactile.wav``), the others are rendered from
        their JSON when their samples are first asked for. Kept for the ``meta`` it was made from.
        """
        cached = self.__dict__.get("_grid")
        if cached is not None and cached[0] is self.meta and cached[1] is self.tactile:
            return cached[2]
        pattern = self.pattern
        own = self.meta.grid
        if own is None:
            grid = VibrationGrid.single(pattern)
        else:
            points = tuple(
                replace(point, pattern=pattern if index == own.reference else
                        replace(point.pattern, actuator=pattern.actuator, params=pattern.params))
                for index, point in enumerate(own.points))
            grid = replace(own, points=points, notes=pattern.notes)
        self.__dict__["_grid"] = (self.meta, self.tactile, grid)
        return grid

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
        has the same version on every machine.

        Kept for the ``meta`` object it was computed from (hashing takes milliseconds, and the
        live server asks on every pen-down); a new ``meta`` is hashed again.
        """
        cached = self.__dict__.get("_version")
        if cached is None or cached[0] is not self.meta:
            cached = (self.meta, profile_version(self.meta))
            self.__dict__["_version"] = cached
        return cached[1]

    @property
    def has_tactile(self) -> bool:
        """Whether the pen has a tactile pattern (False: a sound-only pen, whose
        ``tactile.wav`` is silence; see :mod:`realpen.profile.schema`)."""
        return self.meta.has_tactile

    @property
    def has_sound(self) -> bool:
        """Whether the pen has a friction sound (False: a tactile-only pen, whose
        ``sound.wav`` is silence)."""
        return self.meta.has_sound

    def summary(self) -> str:
        """One line: name, tool, components, lengths, grid points (if any), actuator; a part the
        pen lacks is said to be so."""
        t, s = self.meta.tactile, self.meta.sound
        counts = {len(sub) for sub in t.subpatterns}
        grid = "" if self.meta.grid is None else f" at {len(self.meta.grid.points)} points"
        tactile = (f"tactile {len(t.subpatterns)}×{t.subpattern_ms:g} ms, "
                   f"{'/'.join(map(str, sorted(counts)))} components, {t.rate} Hz{grid}"
                   if self.has_tactile else "no tactile part (a sound-only pen)")
        sound = (f"sound {s.unit_ms:g} ms {s.mode} at {s.rate} Hz" if self.has_sound
                 else "no sound part (a tactile-only pen)")
        return f"{self.name}: {self.meta.tool}; {tactile}; {sound}; actuator {self.meta.actuator.spec}"

    def __repr__(self) -> str:
        t, s = self.meta.tactile, self.meta.sound
        tool = self.meta.tool if len(self.meta.tool) <= 40 else self.meta.tool[:37] + "..."
        tactile = (f"tactile {len(t.subpatterns)}×{t.subpattern_ms:g} ms at {t.rate} Hz"
                   if self.has_tactile else "no tactile")
        sound = f"sound {s.unit_ms:g} ms at {s.rate} Hz" if self.has_sound else "no sound"
        return f"PenProfile({self.name!r}, {tool!r}, {tactile}, {sound}, version {self.version})"

    def _current_meta(self, wavs: dict[str, bytes]) -> ProfileMeta:
        """``meta`` with ``files`` describing ``wavs``, checked against the samples."""
        pattern, sound = self.meta.tactile, self.meta.sound
        if len(self.tactile) != pattern.frames:
            raise ParameterError("tactile", f"{len(self.tactile)} samples, but the pattern is "
                                            f"{pattern.frames} at {pattern.rate} Hz")
        if len(self.sound) != sound.frames:
            raise ParameterError("sound", f"{len(self.sound)} samples, but the sound section "
                                          f"says {sound.frames}")
        try:
            files = BundleFiles.model_validate({
                "tactile": {"file": TACTILE_WAV, "rate": pattern.rate, "frames": len(self.tactile),
                            "sha256": _sha(wavs[TACTILE_WAV])},
                "sound": {"file": SOUND_WAV, "rate": sound.rate, "frames": len(self.sound),
                          "sha256": _sha(wavs[SOUND_WAV])}})
        except ValidationError as error:  # a WAV loading would refuse: too long, odd rate
            raise ParameterError("profile", f"files.{validation_line(error)}") from None
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


def _read_wav(data: bytes, name: str, source: object, wav: WavFile) -> np.ndarray:
    """The samples of a bundle WAV, float32, shape (frames,), once its header says it is mono
    and exactly ``wav.frames`` frames at ``wav.rate`` Hz: a header that claims more frames than
    the profile needs is refused before anything is decoded."""
    import soundfile as sf

    def refuse(frames: int, rate: int):
        return fail(source, f"{name} is {frames} frames at {rate} Hz; {PROFILE_JSON} says "
                            f"{wav.frames} frames at {wav.rate} Hz")

    try:
        with sf.SoundFile(io.BytesIO(data)) as handle:
            if handle.channels != 1:
                raise fail(source, f"{name} has {handle.channels} channels; a profile WAV is mono")
            if handle.samplerate != wav.rate or handle.frames != wav.frames:
                raise refuse(handle.frames, handle.samplerate)
            samples = handle.read(wav.frames, dtype="float32")
    except (sf.LibsndfileError, RuntimeError, ValueError, TypeError) as error:
        raise fail(source, f"{name} is not a readable WAV ({one_line(error)})") from None
    if len(samples) != wav.frames:  # the data ended before the header's count
        raise refuse(len(samples), wav.rate)
    return samples


def save_profile(profile: PenProfile, target: str | os.PathLike) -> Path:
    """Write a bundle atomically: a folder, or a ``.zip`` when ``target`` ends in ``.zip``.

    ``profile.json``'s ``files`` section is made from the samples written. An existing bundle
    at ``target`` is replaced only once the new one is complete; a folder holding anything but
    a bundle is never replaced.

    Returns:
        The bundle's path (a folder's resolved path).

    Raises:
        ParameterError: the samples do not match the pattern or the sound section, or
            ``profile.json`` would be larger than a bundle may hold.
        RealPenError: the target cannot be written (naming it).
    """
    target = Path(target)
    wavs = bundle_wavs(profile)
    files = {PROFILE_JSON: _document_bytes(profile._current_meta(wavs)), **wavs}
    if len(files[PROFILE_JSON]) > MAX_JSON_BYTES:  # loading would refuse it: never written
        raise ParameterError("profile", f"{PROFILE_JSON} would be {len(files[PROFILE_JSON]):,} "
                                        f"bytes, over the {MAX_JSON_BYTES:,} a profile may "
                                        f"hold; use fewer grid points or components")
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




def _check_size(bundle: Path, name: str, size: int, what: str = "is") -> None:
    """Refuse a size in bytes over the limit of the bundle file ``name``, before reading it."""
    limit = MAX_FILE_BYTES[name]
    if size > limit:
        raise fail(bundle, f"{name} {what} {size:,} bytes; the limit is {limit:,}")


def _check_read(bundle: Path, name: str, data: bytes, how: str) -> bytes:
    """Refuse what a bounded read (at most limit + 1 bytes) found to be over the limit."""
    limit = MAX_FILE_BYTES[name]
    if len(data) > limit:
        raise fail(bundle, f"{name} {how} more than its limit of {limit:,} bytes")
    return data


def _open_nonblocking(path: Path, flags: int = 0):
    """``path`` opened for binary reading without following a last symlink when ``flags`` holds
    O_NOFOLLOW, and without blocking: opening a FIFO waits for a writer unless O_NONBLOCK."""
    flags |= os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_BINARY", 0)
    return open(os.open(path, flags), "rb")


def _read_folder_file(folder: Path, name: str) -> bytes | None:
    """The bytes of the bundle folder's ``name`` (None when there is none), refusing symlinks,
    special files and files over their limit before reading, and reading at most limit + 1."""
    member = folder / name
    try:
        info = os.lstat(member)
    except FileNotFoundError:
        return None
    except OSError as error:
        raise fail(folder, f"{name}: cannot read ({error.strerror or error})") from None
    if stat.S_ISLNK(info.st_mode):
        raise fail(folder, f"{name} is a symbolic link; a bundle holds its files itself")
    if not stat.S_ISREG(info.st_mode):
        raise fail(folder, f"{name} is not a regular file")
    _check_size(folder, name, info.st_size)
    try:
        with _open_nonblocking(member, getattr(os, "O_NOFOLLOW", 0)) as handle:
            # What was opened may not be what lstat saw (replaced meanwhile): check it again.
            if not stat.S_ISREG(os.fstat(handle.fileno()).st_mode):
                raise fail(folder, f"{name} is not a regular file")
            data = handle.read(MAX_FILE_BYTES[name] + 1)
    except OSError as error:
        raise fail(folder, f"{name}: cannot read ({error.strerror or error})") from None
    return _check_read(folder, name, data, "grew, while it was read, to")


def _read_zip_entry(path: Path, archive: zipfile.ZipFile, entry: zipfile.ZipInfo,
                    name: str) -> bytes:
    if entry.flag_bits & 0x1:
        raise fail(path, f"{name} is encrypted; a bundle's entries are not")
    if entry.compress_type not in _ZIP_METHODS:
        raise fail(path, f"{name} uses zip compression method {entry.compress_type}; "
                         f"RealPen reads stored or deflated entries")
    _check_size(path, name, entry.file_size, "is declared")
    with archive.open(entry) as stream:
        # Bounded: whatever the headers say, no more than the limit + 1 bytes are inflated.
        data = stream.read(MAX_FILE_BYTES[name] + 1)
    return _check_read(path, name, data, "inflates to")


def _read_zip(path: Path) -> dict[str, bytes]:
    try:
        handle = _open_nonblocking(path)
    except OSError as error:
        raise fail(path, f"cannot read ({error.strerror or error})") from None
    with handle:
        info = os.fstat(handle.fileno())
        if not stat.S_ISREG(info.st_mode):
            raise fail(path, "is not a regular file (a profile is a folder or a .zip)")
        if info.st_size > MAX_ZIP_BYTES:
            raise fail(path, f"is {info.st_size:,} bytes; a profile .zip is limited to "
                             f"{MAX_ZIP_BYTES:,}")
        try:
            with zipfile.ZipFile(handle) as archive:
                entries = archive.infolist()
                if len(entries) > MAX_ZIP_ENTRIES:
                    raise fail(path, f"holds {len(entries):,} entries; a profile .zip holds at "
                                     f"most {MAX_ZIP_ENTRIES}")
                members = [entry for entry in entries if not entry.is_dir()
                           and Path(entry.filename).name in BUNDLE_FILES]
                named = {Path(entry.filename).name: entry for entry in members}
                if len(named) != len(members):
                    raise fail(path, "holds more than one profile (repeated profile.json or WAVs)")
                return {name: _read_zip_entry(path, archive, entry, name)
                        for name, entry in named.items()}
        except _ZIP_ERRORS as error:
            raise fail(path, f"not a profile folder or a readable .zip "
                             f"({one_line(error)})") from None


def _read_bundle_files(path: Path) -> dict[str, bytes]:
    try:
        info = os.stat(path)
    except (FileNotFoundError, NotADirectoryError):
        raise fail(path, "no such profile (folder or .zip)") from None
    except OSError as error:  # e.g. a folder on the way that may not be searched
        raise fail(path, f"cannot read ({error.strerror or error})") from None
    if stat.S_ISDIR(info.st_mode):
        files = {name: _read_folder_file(path, name) for name in BUNDLE_FILES}
        return {name: data for name, data in files.items() if data is not None}
    return _read_zip(path)




def read_bundle(path: str | os.PathLike) -> PenProfile:
    """Read and check the bundle (folder or ``.zip``) of format 1, 2 or 3 at ``path``.

    Finding a profile by name is :func:`realpen.profile.registry.resolve_profile`'s (and
    :func:`~realpen.profile.registry.load_profile`'s): the one place a name or a path is told
    apart. This reads a path only.

    Raises:
        RealPenError: a missing file, an unknown format version, a schema violation, WAVs
            that do not match the JSON, a file over its limit, a damaged, encrypted or
            oversized zip — each as one line naming the bundle (no other exception, whatever
            the bundle's bytes).
    """
    try:
        return _load_bundle(Path(path))
    except RealPenError as error:
        # One line even when the bundle's own name holds a newline.
        if len(str(error).splitlines()) > 1:
            raise RealPenError(" ".join(str(error).split())) from None
        raise


def _load_bundle(path: Path) -> PenProfile:
    files = _read_bundle_files(path)
    missing = [name for name in BUNDLE_FILES if name not in files]
    if missing:
        raise fail(path, f"incomplete profile: missing {', '.join(missing)}")
    # Bounded in size, nesting depth and digits per number; NaN/Infinity refused.
    document = load_json(files[PROFILE_JSON], what=f"{path}: {PROFILE_JSON}")
    if not isinstance(document, dict):
        raise fail(path, f"{PROFILE_JSON} must hold a JSON object")
    if type(document.get("format")) is not int or document["format"] not in READABLE_FORMATS:
        raise fail(path, f"unknown profile format {one_line(repr(document.get('format')), 40)} "
                         f"(this RealPen reads formats {', '.join(map(str, READABLE_FORMATS))}; "
                         f"it writes {FORMAT})")
    try:
        meta = ProfileMeta.model_validate(upgrade(document))
    except ValidationError as error:
        raise fail(path, f"{PROFILE_JSON}: {validation_line(error)}") from None
    arrays = {}
    for name, wav in ((TACTILE_WAV, meta.files.tactile), (SOUND_WAV, meta.files.sound)):
        data = files[name]
        if _sha(data) != wav.sha256:
            raise fail(path, f"{name} does not match {PROFILE_JSON} (SHA-256 differs)")
        samples = _read_wav(data, name, path, wav)
        if not np.all(np.isfinite(samples)):
            raise fail(path, f"{name} holds NaN or infinite samples")
        arrays[name] = samples
    return PenProfile(meta, arrays[TACTILE_WAV], arrays[SOUND_WAV], path)
