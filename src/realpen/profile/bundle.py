"""Pen profiles: one bundle per pen, everything needed to reproduce it.

A bundle is a folder (or the same files in a ``.zip``) holding

- ``profile.json`` — versioned (``"format": 1``) and validated by :class:`ProfileMeta`: name,
  tool type, the tactile pattern's components per sub-pattern, rates and lengths, the
  actuator, the coupling constants (Eq. 1), and provenance (source files with SHA-256, every
  parameter, the package version);
- ``tactile.wav`` — the looping tactile pattern (mono, 32-bit float);
- ``sound.wav`` — the looping friction-sound unit (mono, 32-bit float, RMS −20 dBFS).

Loading checks that the WAVs are there and are the ones the JSON describes (rate, length,
SHA-256), so a bundle can be trusted or is refused with one clear line.
"""

from __future__ import annotations

import hashlib
import io
import json
import os
import re
import shutil
import tempfile
import zipfile
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Annotated, Literal

import numpy as np
import soundfile as sf
from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from realpen import __version__
from realpen.tactile.actuator import Actuator
from realpen.sound.coupling import Coupling
from realpen.errors import RealPenError, fail
from realpen.io.files import atomic_path, current_umask, wav_bytes
from realpen.io.recording import Recording
from realpen.sound.loop import find_loop_unit
from realpen.tactile.pattern import Pattern, TactileParams, build_pattern

FORMAT = 1
PROFILE_JSON, TACTILE_WAV, SOUND_WAV = "profile.json", "tactile.wav", "sound.wav"
BUNDLE_FILES = (PROFILE_JSON, TACTILE_WAV, SOUND_WAV)
NAME_PATTERN = r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,63}$"


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)


class ComponentEntry(_Strict):
    """One sinusoid: frequency (Hz), amplitude (full scale), phase (rad), and its origin.

    ``joins_previous`` / ``joins_next``: the component continues a track across that boundary
    (continuous phase), so the crossfade there is linear rather than equal-power.
    """

    frequency_hz: float = Field(gt=0)
    amplitude: float = Field(ge=0)
    phase: float
    power: float | None = None
    weight: float | None = None
    clipped: bool = False
    joins_previous: bool = False
    joins_next: bool = False


class TactileSection(_Strict):
    """The tactile pattern: ``tactile.wav`` and the components it is made of."""

    file: Literal["tactile.wav"] = TACTILE_WAV
    rate: int = Field(gt=0)
    frames: int = Field(gt=0)
    sha256: str
    subpattern_ms: float = Field(gt=0, le=60_000)
    boundary: Literal["crossfade", "hard"]
    crossfade_ms: float = Field(ge=0)
    subpatterns: list[Annotated[list[ComponentEntry], Field(min_length=1)]] = Field(min_length=1)

    @model_validator(mode="after")
    def _lengths_agree(self) -> "TactileSection":
        per_sub = int(round(self.subpattern_ms * self.rate / 1000.0))
        if per_sub * len(self.subpatterns) != self.frames:
            raise ValueError(f"{len(self.subpatterns)} sub-patterns of {self.subpattern_ms:g} ms "
                             f"at {self.rate} Hz are {per_sub * len(self.subpatterns)} frames, "
                             f"not {self.frames}")
        return self


class SoundSection(_Strict):
    """The friction-sound unit: ``sound.wav`` and how it was cut."""

    file: Literal["sound.wav"] = SOUND_WAV
    rate: int = Field(gt=0)
    frames: int = Field(gt=0)
    sha256: str
    mode: Literal["loop", "granular"] = "loop"
    unit_ms: float = Field(gt=0)
    crossfade_ms: float = Field(ge=0)
    start_s: float | None = None
    rms_dbfs: float
    seam: dict


class ActuatorSection(_Strict):
    """The actuator the tactile pattern is equalised for."""

    spec: str
    kind: str
    params: dict = {}
    table_hz: list[float] | None = None
    table_response: list[float] | None = None


class SourceFile(_Strict):
    """A file the profile was built from."""

    role: str
    name: str
    sha256: str | None = None


class Provenance(_Strict):
    """Where a profile came from."""

    realpen_version: str
    sources: list[SourceFile]
    tactile_parameters: dict
    sound_parameters: dict
    model: dict | None = None
    notes: list[str] = []


class ProfileMeta(_Strict):
    """``profile.json``, format 1."""

    format: Literal[1] = FORMAT
    name: str = Field(pattern=NAME_PATTERN)
    tool: str
    description: str = ""
    tactile: TactileSection
    sound: SoundSection
    actuator: ActuatorSection
    coupling: Coupling
    provenance: Provenance


@dataclass
class PenProfile:
    """A loaded or freshly built pen profile.

    Attributes:
        meta: the validated ``profile.json``.
        tactile: the tactile pattern, float32, shape (frames,), full scale ±1.
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
    def version(self) -> str:
        """Content version: the first 12 hex digits of the SHA-256 of ``profile.json``."""
        return hashlib.sha256(self.json_bytes()).hexdigest()[:12]

    def json_bytes(self) -> bytes:
        """``profile.json`` exactly as saved."""
        return (json.dumps(self.meta.model_dump(mode="json"), indent=2) + "\n").encode("utf-8")

    def summary(self) -> str:
        """One line: name, tool, components, lengths, actuator."""
        t, s = self.meta.tactile, self.meta.sound
        counts = {len(sub) for sub in t.subpatterns}
        return (f"{self.name}: {self.meta.tool}; tactile {len(t.subpatterns)}×{t.subpattern_ms:g} ms, "
                f"{'/'.join(map(str, sorted(counts)))} components, {t.rate} Hz; sound "
                f"{s.unit_ms:g} ms {s.mode} at {s.rate} Hz; actuator {self.meta.actuator.spec}")


def _sha(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def _read_wav(data: bytes, name: str, source: object) -> tuple[np.ndarray, int]:
    try:
        samples, rate = sf.read(io.BytesIO(data), dtype="float32", always_2d=True)
    except (sf.LibsndfileError, RuntimeError, ValueError) as error:
        raise fail(source, f"{name} is not a readable WAV ({str(error).splitlines()[0]})") from None
    if samples.shape[1] != 1:
        raise fail(source, f"{name} has {samples.shape[1]} channels; a profile WAV is mono")
    return samples[:, 0], rate


def profile_from_parts(name: str, tool: str, pattern: Pattern, sound: np.ndarray, sound_rate: int,
                       sound_section: dict, coupling: Coupling, sources: list[SourceFile],
                       sound_parameters: dict, description: str = "",
                       model: dict | None = None) -> PenProfile:
    """Assemble a :class:`PenProfile` from a tactile pattern and a sound unit."""
    tactile = np.asarray(pattern.samples, dtype=np.float32)
    sound = np.asarray(sound, dtype=np.float32)
    params = pattern.params
    meta = ProfileMeta(
        name=name, tool=tool, description=description,
        tactile=TactileSection(
            rate=pattern.rate, frames=len(tactile), sha256=_sha(wav_bytes(tactile, pattern.rate)),
            subpattern_ms=params.unit_ms, boundary=params.boundary,
            crossfade_ms=params.crossfade_ms,
            subpatterns=[[ComponentEntry(**asdict(c)) for c in sub] for sub in pattern.subpatterns]),
        sound=SoundSection(rate=sound_rate, frames=len(sound),
                           sha256=_sha(wav_bytes(sound, sound_rate)), **sound_section),
        actuator=ActuatorSection(**pattern.actuator.to_json()),
        coupling=coupling,
        provenance=Provenance(realpen_version=__version__, sources=sources,
                              tactile_parameters=asdict(params), sound_parameters=sound_parameters,
                              model=model, notes=list(pattern.notes)))
    return PenProfile(meta, tactile, sound)


def build_profile(name: str, tool: str, vibration: Recording, sound: Recording, actuator: Actuator,
                  tactile_params: TactileParams = TactileParams(), unit_ms: float = 300.0,
                  crossfade_ms: float = 10.0, coupling: Coupling = Coupling(),
                  description: str = "", model: dict | None = None, progress=None) -> PenProfile:
    """Run the tactile and the auditory pipelines and bundle the result.

    Args:
        vibration: the pen's vibration recording (any axes and rate).
        sound: the pen's friction sound, mono, already at the profile's sound rate.
        unit_ms, crossfade_ms: loop-unit length and wrap crossfade in ms.
        model: parameters of the generating model, for modelled pens.
    """
    if not re.match(NAME_PATTERN, name):
        raise RealPenError(f"--name: '{name}' is not a valid profile name (letters, digits, "
                           f"'-', '_', '.'; up to 64 characters)")
    pattern = build_pattern(vibration, actuator, tactile_params, progress)
    unit = find_loop_unit(sound.mono, sound.rate, unit_ms, crossfade_ms, source=sound.source,
                          recording=sound).normalised()
    report = unit.to_json()
    section = {"mode": "loop", "unit_ms": unit.unit_ms, "crossfade_ms": unit.crossfade_ms,
               "start_s": report["start_s"], "rms_dbfs": report["rms_dbfs"],
               "seam": report["seam"]}
    sources = [SourceFile(role="vibration", name=Path(vibration.source).name,
                          sha256=vibration.sha256),
               SourceFile(role="sound", name=Path(sound.source).name, sha256=sound.sha256)]
    return profile_from_parts(name, tool, pattern, unit.samples, int(round(sound.rate)), section,
                              coupling, sources,
                              {"unit_ms": unit_ms, "crossfade_ms": crossfade_ms,
                               "scores": report["scores"], "rate": sound.rate},
                              description, model)


def save_profile(profile: PenProfile, target: str | os.PathLike) -> Path:
    """Write a bundle atomically: a folder, or a ``.zip`` when ``target`` ends in ``.zip``.

    An existing bundle at ``target`` is replaced only once the new one is complete; a folder
    holding anything but a bundle is never replaced.
    """
    target = Path(target)
    files = {PROFILE_JSON: profile.json_bytes(),
             TACTILE_WAV: wav_bytes(profile.tactile, profile.meta.tactile.rate),
             SOUND_WAV: wav_bytes(profile.sound, profile.meta.sound.rate)}
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


def load_profile(path: str | os.PathLike) -> PenProfile:
    """Load and check a bundle (folder or ``.zip``).

    Raises:
        RealPenError: a missing file, an unknown format version, a schema violation, or WAVs
            that do not match the JSON — each as one line naming the bundle.
    """
    path = Path(path)
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
    if type(document.get("format")) is not int or document["format"] != FORMAT:
        raise fail(path, f"unknown profile format {document.get('format')!r} "
                         f"(this RealPen reads format {FORMAT})")
    try:
        meta = ProfileMeta.model_validate(document)
    except ValidationError as error:
        first = error.errors()[0]
        where = ".".join(str(part) for part in first["loc"])
        raise fail(path, f"{PROFILE_JSON}: {where}: {first['msg']}") from None
    arrays = {}
    for name, section in ((TACTILE_WAV, meta.tactile), (SOUND_WAV, meta.sound)):
        data = files[name]
        if _sha(data) != section.sha256:
            raise fail(path, f"{name} does not match {PROFILE_JSON} (SHA-256 differs)")
        samples, rate = _read_wav(data, name, path)
        if rate != section.rate or len(samples) != section.frames:
            raise fail(path, f"{name} is {len(samples)} frames at {rate} Hz; {PROFILE_JSON} says "
                             f"{section.frames} frames at {section.rate} Hz")
        arrays[name] = samples
    return PenProfile(meta, arrays[TACTILE_WAV], arrays[SOUND_WAV], path)


def profile_locations(extra: list[Path] | None = None) -> list[tuple[str, Path]]:
    """Where profiles are looked for, in order: ("bundled", folder), ("user", folder), extras."""
    from realpen.io.paths import user_profiles_dir
    from realpen.pens import bundled_dir

    places = [("bundled", bundled_dir()), ("user", user_profiles_dir())]
    places += [("extra", Path(p)) for p in (extra or [])]
    return places


def list_profiles(extra: list[Path] | None = None) -> list[tuple[str, Path]]:
    """Every profile found: (where, bundle path), bundled first; later names do not hide earlier.

    A bundle is a sub-folder holding ``profile.json`` or a ``.zip`` file.
    """
    found = []
    for where, folder in profile_locations(extra):
        if not folder.is_dir():
            continue
        for entry in sorted(folder.iterdir()):
            if (entry.is_dir() and (entry / PROFILE_JSON).is_file()) or entry.suffix == ".zip":
                found.append((where, entry))
    return found


def resolve_profile(name_or_path: str, extra: list[Path] | None = None) -> PenProfile:
    """Load a profile by path (folder or ``.zip``) or by name (bundled, user, extra folders)."""
    candidate = Path(name_or_path)
    if candidate.exists() or candidate.suffix == ".zip" or os.sep in name_or_path:
        return load_profile(candidate)
    for _, path in list_profiles(extra):
        if path.name == name_or_path or path.stem == name_or_path:
            return load_profile(path)
    names = sorted({path.stem for _, path in list_profiles(extra)})
    raise RealPenError(f"{name_or_path}: no such profile (known: {', '.join(names) or 'none'})")
