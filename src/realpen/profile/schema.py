"""``profile.json``: the versioned, validated description of a pen profile (formats 2 and 3).

::

    {"format": 2, "name": "pencil", "tool": "pencil (4B)", "description": "…",
     "tactile":  TactilePattern.to_json()  (rate, subpattern_ms, boundary, crossfade_ms,
                                            subpatterns: [[component, …], …]),
     "grid":     VibrationGrid.to_json()   (format 3 only, when the profile has one:
                                            full_pressure_force_n, reference,
                                            points: [{speed_mm_s, force_n, tactile}, …]),
     "sound":    {rate, frames, mode, unit_ms, crossfade_ms, start_s, rms_dbfs, seam},
     "actuator": Actuator.to_json()        (spec, kind, params[, table_hz, table_response]),
     "coupling": Coupling (realpen.coupling/1, Eq. 1),
     "files":    {"tactile": {file, rate, frames, sha256}, "sound": {…}},
     "provenance": {realpen_version, sources, tactile_parameters, sound_parameters, model, notes}}

The ``tactile`` section is exactly the fields of :class:`realpen.tactile.pattern.TactilePattern`:
its pydantic model is *generated* from that dataclass (:func:`model_of`) and validating it
yields a ``TactilePattern``; likewise ``actuator`` is read by
:meth:`realpen.tactile.actuator.Actuator.from_json`. ``files`` describes the two WAVs (checked
on loading).

Format 1 (RealPen ≤ 0.1: WAV rate, frames and SHA-256 inside the ``tactile`` and ``sound``
sections, the actuator's ``table_*`` always present) is still read: :func:`upgrade` turns it
into format 2.

Format 3 adds what format 2 cannot hold: a tactile pattern with a residual (its ``tactile``
section then has a ``residual`` key), a vibration grid (the ``grid`` section: patterns at
several (speed, force) points, :class:`realpen.tactile.grid.VibrationGrid`; the reference
point's pattern is the ``tactile`` section and ``tactile.wav``, the others are rendered from
their JSON when needed) and a pen made from one recording alone (the ``parts`` key:
``["sound"]`` for a sound-only pen, from a microphone alone; ``["tactile"]`` for a
tactile-only pen, from an accelerometer alone). A profile with none of these is written as
format 2, byte for byte as before, so existing profiles and their versions do not change;
:attr:`ProfileMeta.format` is always the lowest format that holds the profile.

The part a pen lacks is still in the bundle, as silence: a tactile
pattern of one component of amplitude 0, or a sound unit of zeros. Every reader of profiles
(the live page, the pen, the exports' loops) then plays the pen as it is — sound only, or
vibration only — without a case of its own, while ``parts`` says what was recorded (the
summary, ``profile show`` and the exports read it; :attr:`ProfileMeta.has_tactile`,
:attr:`ProfileMeta.has_sound`).

The profile's *version* (:func:`profile_version`) is the SHA-256 of a canonical form of the
document without ``files`` (floats rounded to 9 significant digits, keys sorted, compact
separators), so the same pen has the same version on every machine. ``files`` is left out
because the WAVs follow from the rest (components; the sound's source hash and start), while
their bytes, and so their SHA-256, can differ in the last bits of a float between machines.

Limits. Every number is finite, and the sizes are bounded so that no ``profile.json`` can
make a reader allocate much: each WAV holds at most :data:`MAX_WAV_FRAMES` frames and is at
most :data:`MAX_WAV_BYTES` bytes, rates are :data:`realpen.checks.MIN_RATE_HZ` to
:data:`realpen.checks.MAX_RATE_HZ`, lengths in ms at most :data:`MAX_SECTION_MS`.

Imports pydantic and numpy only (the Coupling type is loaded when a document is validated), so
the WebSocket schema can import :data:`NAME_PATTERN` without scipy or soundfile.
"""

from __future__ import annotations

import copy
import math
import sys
from dataclasses import MISSING
from typing import Annotated, Any, Literal

from pydantic import (
    AfterValidator,
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Field,
    PlainSerializer,
    PlainValidator,
    SerializerFunctionWrapHandler,
    ValidationError,
    WithJsonSchema,
    create_model,
    model_serializer,
    model_validator,
)

from realpen.checks import MAX_GRID_POINTS, MAX_RATE_HZ, MIN_RATE_HZ
from realpen.tactile.actuator import KINDS, Actuator
from realpen.tactile.grid import GridPoint, VibrationGrid
from realpen.tactile.pattern import Component, TactilePattern, content_version, json_fields
from realpen.validation import validation_line

__all__ = ["FORMAT", "READABLE_FORMATS", "NAME_PATTERN", "PROFILE_JSON", "TACTILE_WAV",
           "SOUND_WAV", "BUNDLE_FILES", "ComponentModel", "TactileModel", "SoundSection",
           "GridPointSection", "GridSection", "needed_format", "WavFile", "BundleFiles",
           "SourceFile", "Provenance", "ProfileMeta", "model_of", "upgrade", "profile_version",
           "MAX_WAV_FRAMES", "MAX_WAV_BYTES", "MAX_SECTION_MS", "PARTS", "SILENT_DBFS"]

FORMAT = 3
"""The newest format written (a profile without residual and grid is still written as 2)."""
READABLE_FORMATS = (1, 2, 3)
NAME_PATTERN = r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,63}$"
PROFILE_JSON, TACTILE_WAV, SOUND_WAV = "profile.json", "tactile.wav", "sound.wav"
BUNDLE_FILES = (PROFILE_JSON, TACTILE_WAV, SOUND_WAV)

MAX_WAV_FRAMES = 2**24
"""The most frames (samples; the WAVs are mono) of a bundle's ``tactile.wav`` or ``sound.wav``:
16,777,216, 64 MiB as 32-bit float — the longest tactile pattern RealPen synthesises
(:data:`realpen.checks.MAX_PATTERN_FRAMES`, the same number), so every pattern and
every sound unit (at most 60 s) it builds can be bundled, while a forged header cannot ask for
gigabytes. A method's pattern is 1.5 s (12,000 frames at 8 kHz) and its sound unit 300 ms."""
MAX_WAV_BYTES = 4 * MAX_WAV_FRAMES + 64 * 1024
"""The largest ``tactile.wav`` or ``sound.wav`` read (bytes): :data:`MAX_WAV_FRAMES` frames of
32-bit float plus 64 KiB for the header and chunks (``fmt``, ``smpl``, ``LIST``)."""
MAX_SECTION_MS = 60_000.0
"""The longest sound unit or crossfade a ``profile.json`` may state (ms); a unit is 300 ms."""
PARTS = ("tactile", "sound")
"""What a pen profile renders: the tactile pattern and the friction sound."""
SILENT_DBFS = -200.0
"""The ``rms_dbfs`` stated for a silent sound unit (a tactile-only pen): the level of zeros is
−∞ dB, which JSON cannot hold; −200 dBFS is far below any recording (24-bit PCM's floor is
−144 dBFS)."""


def _finite_number(value: Any) -> int | float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        shown = repr(value) if isinstance(value, (bool, float)) else type(value).__name__
        raise ValueError(f"must be a finite number, got {shown}")
    return value


# A figure of a free-form table (the seam report): a JSON int or float as it is, never a string,
# a boolean or an overflowed float (1e999 parses as inf).
FiniteNumber = Annotated[Any, PlainValidator(_finite_number), WithJsonSchema({"type": "number"})]


class _Strict(BaseModel):
    # defer_build: a model's validator is built when it is first used, not on import. Reading a
    # profile builds ProfileMeta's alone (its sections are part of it), not one per section.
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False, defer_build=True)


def model_of(cls: type, name: str, overrides: dict[str, Any] | None = None) -> type[BaseModel]:
    """A strict pydantic model of the JSON fields of dataclass ``cls``.

    Types come from the dataclass annotations, constraints from each field's ``metadata``
    (``{"schema": {"gt": 0}}``; ``{"choices": (...)}`` becomes a ``Literal``), defaults from the
    dataclass; ``overrides`` replaces the type of some fields (e.g. nested models).
    """
    namespace = vars(sys.modules[cls.__module__])
    definitions = {}
    for item in json_fields(cls):
        if overrides and item.name in overrides:
            kind = overrides[item.name]
        elif "choices" in item.metadata:
            kind = Literal[tuple(item.metadata["choices"])]
        else:
            kind = eval(item.type, namespace) if isinstance(item.type, str) else item.type  # noqa: S307
        if item.default is not MISSING:
            default = item.default
        elif item.default_factory is not MISSING:
            default = item.default_factory()
        else:
            default = ...
        definitions[item.name] = (kind, Field(default, **item.metadata.get("schema", {})))
    return create_model(name, __base__=_Strict, __doc__=(cls.__doc__ or "").split("\n")[0],
                        **definitions)


ComponentModel = model_of(Component, "ComponentModel")
TactileModel = model_of(TactilePattern, "TactileModel", {
    "subpatterns": list[Annotated[list[ComponentModel], Field(min_length=1)]]})


def _pattern(model: BaseModel) -> TactilePattern:
    data = model.model_dump()
    if data.get("residual", 0) is None:  # to_json omits it when there is none
        del data["residual"]
    return TactilePattern.from_json(data)


def _pattern_json(value: Any) -> Any:
    return value.to_json() if isinstance(value, TactilePattern) else value


TactileField = Annotated[TactileModel, BeforeValidator(_pattern_json), AfterValidator(_pattern),
                         PlainSerializer(TactilePattern.to_json)]


ActuatorField = Annotated[Any, PlainValidator(Actuator.from_json), PlainSerializer(Actuator.to_json),
                          WithJsonSchema({
                              "type": "object", "required": ["spec", "kind"],
                              "properties": {"spec": {"type": "string"},
                                             "kind": {"enum": list(KINDS)},
                                             "params": {"type": "object"},
                                             "table_hz": {"type": "array"},
                                             "table_response": {"type": "array"}},
                              "description": "realpen.tactile.actuator.Actuator.to_json()"})]


def _coupling(value: Any):
    from realpen.motion.coupling import Coupling

    if isinstance(value, Coupling):
        return value
    try:
        return Coupling.model_validate(value)
    except ValidationError as error:
        # Without "Value error, ": pydantic adds it again outside.
        raise ValueError(validation_line(error)) from None


CouplingField = Annotated[Any, PlainValidator(_coupling),
                          PlainSerializer(lambda coupling: coupling.model_dump(mode="json")),
                          WithJsonSchema({"type": "object",
                                          "description": "realpen.coupling/1 "
                                                         "(realpen.motion.coupling.Coupling)"})]


class SoundSection(_Strict):
    """The friction-sound unit: its rate (Hz), length (frames) and how it was cut: unit and
    wrap crossfade (ms), where it starts in the recording (s), its RMS level (dBFS) and the seam
    report (:class:`realpen.sound.loop.Seam`'s figures)."""

    rate: int = Field(ge=MIN_RATE_HZ, le=MAX_RATE_HZ)
    frames: int = Field(gt=0, le=MAX_WAV_FRAMES)
    mode: Literal["loop", "granular"] = "loop"
    unit_ms: float = Field(gt=0, le=MAX_SECTION_MS)
    crossfade_ms: float = Field(ge=0, le=MAX_SECTION_MS)
    start_s: float | None = Field(None, ge=0)
    rms_dbfs: float
    # The seam report's figures (dB, percent, a count; {} when not measured): numbers only, as
    # `profile show` and the plots format them.
    seam: dict[str, FiniteNumber]


class GridPointSection(_Strict):
    """One point of the ``grid`` section: speed (mm/s), force (N) and the pattern felt there."""

    speed_mm_s: float = Field(ge=0)
    force_n: float = Field(ge=0)
    tactile: TactileField


class GridSection(_Strict):
    """The ``grid`` section (format 3): tactile patterns at (speed, force) points
    (:class:`realpen.tactile.grid.VibrationGrid`); validating it yields a ``VibrationGrid``."""

    full_pressure_force_n: float = Field(gt=0)
    reference: int = Field(ge=0)
    points: list[GridPointSection] = Field(min_length=1, max_length=MAX_GRID_POINTS)


def _grid(model: GridSection) -> VibrationGrid:
    for index, point in enumerate(model.points):
        pattern = point.tactile
        if pattern.max_frequency_hz >= pattern.rate / 2:  # it could never be rendered
            raise ValueError(f"points.{index}: components up to "
                             f"{pattern.max_frequency_hz:.0f} Hz do not fit a pattern at "
                             f"{pattern.rate} Hz")
    points = tuple(GridPoint(p.speed_mm_s, p.force_n, p.tactile) for p in model.points)
    return VibrationGrid(points, model.full_pressure_force_n, model.reference)


def _grid_json(value: Any) -> Any:
    return value.to_json() if isinstance(value, VibrationGrid) else value


GridField = Annotated[GridSection, BeforeValidator(_grid_json), AfterValidator(_grid),
                      PlainSerializer(VibrationGrid.to_json)]


def needed_format(pattern: TactilePattern, grid: VibrationGrid | None,
                  parts: list[str] | None = None) -> int:
    """The lowest format that holds a profile: 3 with a residual, a grid or only one of the
    two parts (``parts``), else 2."""
    residual = any(getattr(p, "residual", None) is not None
                   for p in (pattern, *(grid.patterns if grid is not None else ())))
    return 3 if residual or grid is not None or parts is not None else 2


class WavFile(_Strict):
    """One WAV of the bundle: its name, rate (Hz), length (frames) and SHA-256."""

    file: str
    rate: int = Field(ge=MIN_RATE_HZ, le=MAX_RATE_HZ)
    frames: int = Field(gt=0, le=MAX_WAV_FRAMES)
    sha256: str = Field(pattern=r"^[0-9a-f]{64}$")


class BundleFiles(_Strict):
    """The bundle's two WAVs."""

    tactile: WavFile
    sound: WavFile


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
    """``profile.json``, format 2 or 3 (see the module docstring).

    ``tactile`` is a :class:`~realpen.tactile.pattern.TactilePattern` (without samples),
    ``grid`` a :class:`~realpen.tactile.grid.VibrationGrid` or None (then left out of the
    JSON), ``actuator`` an :class:`~realpen.tactile.actuator.Actuator`, ``coupling`` a
    :class:`~realpen.motion.coupling.Coupling`. ``format`` is set to the lowest format that
    holds the profile (:func:`needed_format`); a format-2 document with a residual, a grid or
    ``parts`` is refused. ``parts`` is None for a pen with both parts (``["tactile",
    "sound"]`` is read as None), else the one part it has; the other is silence (see the
    module docstring).
    """

    format: Literal[2, 3] | None = None
    name: str = Field(pattern=NAME_PATTERN)
    tool: str
    description: str = ""
    # The parts recorded, when the pen lacks one (left out of the JSON when it has both).
    parts: list[Literal["tactile", "sound"]] | None = Field(None, min_length=1, max_length=2)
    tactile: TactileField
    grid: GridField | None = None
    sound: SoundSection
    actuator: ActuatorField
    coupling: CouplingField
    files: BundleFiles
    provenance: Provenance

    @property
    def has_tactile(self) -> bool:
        """Whether the pen's tactile pattern was built from a vibration source (False: a
        sound-only pen, whose ``tactile`` section is silence)."""
        return self.parts is None or "tactile" in self.parts

    @property
    def has_sound(self) -> bool:
        """Whether the pen's sound unit was cut from a recording (False: a tactile-only pen,
        whose sound unit is silence)."""
        return self.parts is None or "sound" in self.parts

    @model_validator(mode="after")
    def _format_and_grid(self) -> ProfileMeta:
        if self.parts is not None:
            parts = [part for part in PARTS if part in self.parts]
            self.parts = None if len(parts) == len(PARTS) else parts
        needed = needed_format(self.tactile, self.grid, self.parts)
        if self.format is not None and self.format < needed:
            what = ("a grid" if self.grid is not None else "only one part" if self.parts
                    else "a residual")
            raise ValueError(f"format: a profile with {what} is format {needed}, not "
                             f"{self.format}")
        self.format = needed
        if self.grid is not None and self.grid.reference_pattern != self.tactile:
            raise ValueError(f"grid: the pattern of the reference point "
                             f"({self.grid.reference}) is not the tactile section")
        return self

    @model_serializer(mode="wrap")
    def _without_empty_grid(self, handler: SerializerFunctionWrapHandler) -> dict:
        data = handler(self)
        for key in ("grid", "parts"):
            if data.get(key, 0) is None:  # format 2 has neither key: its bytes stay as they were
                del data[key]
        return data

    @model_validator(mode="after")
    def _files_agree(self) -> ProfileMeta:
        pattern, wav = self.tactile, self.files.tactile
        if wav.file != TACTILE_WAV or self.files.sound.file != SOUND_WAV:
            raise ValueError(f"files: the WAVs are {TACTILE_WAV} and {SOUND_WAV}")
        if pattern.rate != wav.rate or pattern.frames != wav.frames:
            raise ValueError(f"tactile: {len(pattern.subpatterns)} sub-patterns of "
                             f"{pattern.subpattern_ms:g} ms at {pattern.rate} Hz are "
                             f"{pattern.frames} frames, not {wav.frames} at {wav.rate} Hz "
                             f"({TACTILE_WAV})")
        sound = self.sound
        if (sound.rate, sound.frames) != (self.files.sound.rate, self.files.sound.frames):
            raise ValueError(f"sound: {sound.frames} frames at {sound.rate} Hz, but "
                             f"{SOUND_WAV} is {self.files.sound.frames} at "
                             f"{self.files.sound.rate} Hz")
        return self


def upgrade(document: dict) -> dict:
    """A format-1 ``profile.json`` document in format 2 (a copy; format 2 is returned as is).

    Format 1 kept each WAV's ``file``, ``rate``, ``frames`` and ``sha256`` in the ``tactile``
    and ``sound`` sections; format 2 keeps them in ``files``, and the ``tactile`` section is
    exactly the pattern. A document too broken to move is returned for validation to refuse.
    """
    if document.get("format") != 1:
        return document
    upgraded = copy.deepcopy(document)
    upgraded["format"] = 2
    tactile, sound = upgraded.get("tactile"), upgraded.get("sound")
    if not isinstance(tactile, dict) or not isinstance(sound, dict):
        return upgraded
    files = {}
    for key, section, wav in (("tactile", tactile, TACTILE_WAV), ("sound", sound, SOUND_WAV)):
        files[key] = {"file": section.pop("file", wav), "rate": section.get("rate"),
                      "frames": section.get("frames"), "sha256": section.pop("sha256", None)}
    tactile.pop("frames", None)
    actuator = upgraded.get("actuator")
    if isinstance(actuator, dict):
        for key in ("table_hz", "table_response"):
            if key in actuator and actuator[key] is None:
                del actuator[key]
    ordered = {}
    for key, value in upgraded.items():
        ordered[key] = value
        if key == "coupling":
            ordered["files"] = files
    ordered.setdefault("files", files)
    return ordered


def profile_version(meta: ProfileMeta | dict) -> str:
    """The content version of a profile: 12 hex digits of the SHA-256 of the canonical form
    (floats to 9 significant digits, sorted keys, compact) of ``profile.json`` without
    ``files``."""
    document = meta.model_dump(mode="json") if isinstance(meta, BaseModel) else dict(meta)
    document.pop("files", None)
    return content_version(document)
