"""From recordings to a :class:`~realpen.profile.bundle.PenProfile`.

The vibration recording goes through the tactile pipeline
(:func:`realpen.tactile.build.build_pattern`), the friction sound through the loop-unit search
(:func:`realpen.sound.loop.find_loop_unit`); both, the actuator, the coupling constants and the
provenance of every input make one profile.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from realpen import __version__
from realpen.errors import ParameterError
from realpen.io.recording import Recording
from realpen.profile.bundle import PenProfile, bundle_wavs
from realpen.profile.schema import (
    NAME_PATTERN,
    SOUND_WAV,
    TACTILE_WAV,
    BundleFiles,
    ProfileMeta,
    Provenance,
    SoundSection,
    SourceFile,
    WavFile,
)
from realpen.tactile.actuator import Actuator
from realpen.tactile.build import build_pattern
from realpen.tactile.conditions import TactileParams
from realpen.tactile.pattern import TactilePattern

if TYPE_CHECKING:
    from realpen.sound.loop import SoundLoop

__all__ = ["build_profile", "profile_from_parts", "check_name"]


def check_name(name: str) -> str:
    """``name`` if it is a valid profile name (letters, digits, ``-_.``; up to 64 characters).

    Raises:
        ParameterError: (parameter ``name``) otherwise.
    """
    if not isinstance(name, str) or not re.match(NAME_PATTERN, name):
        raise ParameterError("name", f"'{name}' is not a valid profile name (letters, digits, "
                                     f"'-', '_', '.'; up to 64 characters)")
    return name


def profile_from_parts(name: str, tool: str, pattern: TactilePattern, sound: np.ndarray,
                       sound_rate: int, sound_section: dict, coupling, sources: list[SourceFile],
                       sound_parameters: dict, description: str = "",
                       model: dict | None = None) -> PenProfile:
    """Assemble a :class:`PenProfile` from a tactile pattern and a sound unit.

    Args:
        name: profile name (see :func:`check_name`).
        tool: the tool type, free text.
        pattern: the tactile pattern (its actuator and parameters are recorded).
        sound: the sound unit, one loop, full scale ±1.
        sound_rate: its rate in Hz.
        sound_section: ``mode``, ``unit_ms``, ``crossfade_ms``, ``start_s``, ``rms_dbfs``,
            ``seam`` of :class:`~realpen.profile.schema.SoundSection`.
        coupling: the :class:`~realpen.sound.coupling.Coupling` constants.
        sources: the input files.
        sound_parameters: the loop search's parameters and scores.
        model: parameters of the generating model, for modelled pens.

    Raises:
        ParameterError: a bad name, or a pattern without an actuator.
    """
    check_name(name)
    if pattern.actuator is None:
        raise ParameterError("pattern", "needs its actuator (build it with build_pattern, or "
                                        "give TactilePattern(..., actuator=...))")
    tactile = np.asarray(pattern.samples, dtype=np.float32)
    sound = np.asarray(sound, dtype=np.float32)
    sound_rate = int(sound_rate)
    files = BundleFiles(  # completed with the real SHA-256 when saved
        tactile=WavFile(file=TACTILE_WAV, rate=pattern.rate, frames=len(tactile),
                        sha256="0" * 64),
        sound=WavFile(file=SOUND_WAV, rate=sound_rate, frames=len(sound), sha256="0" * 64))
    params = pattern.params.to_json() if pattern.params is not None else {}
    meta = ProfileMeta(
        name=name, tool=tool, description=description,
        tactile=pattern,  # validation keeps the pattern's own fields (to_json), not its origin
        sound=SoundSection(rate=sound_rate, frames=len(sound), **sound_section),
        actuator=pattern.actuator,
        coupling=coupling,
        files=files,
        provenance=Provenance(realpen_version=__version__, sources=sources,
                              tactile_parameters=params, sound_parameters=sound_parameters,
                              model=model, notes=list(pattern.notes)))
    profile = PenProfile(meta, tactile, sound)
    profile.meta = profile._current_meta(bundle_wavs(profile))
    return profile


def build_profile(name: str, tool: str, vibration: Recording, sound: Recording | SoundLoop,
                  actuator: Actuator | str, tactile_params: TactileParams | None = None,
                  unit_ms: float = 300.0, crossfade_ms: float = 10.0, coupling=None,
                  description: str = "", model: dict | None = None, progress=None) -> PenProfile:
    """Run the tactile and the auditory pipelines and bundle the result.

    Args:
        name: profile name (letters, digits, ``-_.``; up to 64 characters).
        tool: the tool type (pencil, ballpoint, …).
        vibration: the pen's vibration recording (any axes and rate).
        sound: the pen's friction sound, mono, already at the profile's sound rate (Hz); or a
            ready :class:`~realpen.sound.loop.SoundLoop` (e.g. a WAV whose ``smpl`` chunk
            declares its loop, from :func:`~realpen.sound.loop.load_sound`), used as it is.
        actuator: an :class:`~realpen.tactile.actuator.Actuator` or a spec string.
        tactile_params: the tactile pipeline's parameters (default: condition B's).
        unit_ms, crossfade_ms: loop-unit length and wrap crossfade in ms.
        coupling: the Eq. 1 constants (default: :class:`realpen.sound.coupling.Coupling()`).
        model: parameters of the generating model, for modelled pens.
        progress: called as ``progress(done, total)`` during the vibration's analysis.

    Raises:
        ParameterError: a bad name or parameter, named by its Python name.
        RealPenError: a problem with a recording, naming it.
    """
    from realpen.sound.coupling import Coupling
    from realpen.sound.loop import SoundLoop, find_loop_unit

    check_name(name)
    coupling = Coupling() if coupling is None else coupling
    pattern = build_pattern(vibration, actuator, tactile_params or TactileParams(), progress)
    if isinstance(sound, SoundLoop):  # a ready loop: used as it is
        unit = sound.normalised()
        sound_sha256 = sound.source_sha256
    else:
        unit = find_loop_unit(sound.mono, sound.rate, unit_ms, crossfade_ms, source=sound.source,
                              recording=sound).normalised()
        sound_sha256 = sound.sha256
    report = unit.to_json()
    section = {"mode": unit.mode, "unit_ms": report.get("unit_ms") or report["length_ms"],
               "crossfade_ms": unit.crossfade_ms or 0.0,
               "start_s": report["start_s"], "rms_dbfs": report["rms_dbfs"],
               "seam": report["seam"] or {}}
    sources = [SourceFile(role="vibration", name=Path(vibration.source).name,
                          sha256=vibration.sha256),
               SourceFile(role="sound", name=Path(sound.source or "sound").name,
                          sha256=sound_sha256)]
    return profile_from_parts(name, tool, pattern, unit.samples, int(round(sound.rate)), section,
                              coupling, sources,
                              {"unit_ms": unit_ms, "crossfade_ms": crossfade_ms,
                               "scores": report.get("scores"), "rate": sound.rate},
                              description, model)
