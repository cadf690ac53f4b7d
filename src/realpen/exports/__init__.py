"""Exports of a tactile pattern (and its sound loop) to the formats haptic platforms read.

Every format takes a :class:`~realpen.tactile.pattern.TactilePattern`, optionally a sound loop
(:class:`realpen.sound.loop.SoundLoop`, or any object with ``samples`` and ``rate``) and the
coupling constants, so a pattern made in a notebook exports as well as a pen profile::

    from realpen.exports import render, export
    result = render("hjif", pattern)                       # bytes, summary, limits
    export("ahap", "pen.ahap", pattern, sound=loop)        # writes pen.ahap + pen-sound.wav
    export_profile(resolve_profile("pencil"), "wav", "pencil.wav", stereo=True)

:data:`FORMATS` maps a format name to its module. Each module documents its fields, where they
come from, and what the format cannot carry, and defines ``SUFFIX``, ``LIMITS`` and
``export(pattern, sound=None, coupling=None, *, name, tool, version, **options) -> Export``.
Formats that need the sound (``wav`` with ``stereo=True``; ``ahap`` with
``sound_events=True``) refuse to go without it, naming ``sound``.

File names: each format is written to a file with its suffix (:data:`SUFFIXES`: ``.wav``,
``.h``, ``.ahap``, ``.haptic``, ``.json`` or ``.kt`` for ``android``, ``.hjif``; any case).
:func:`export` refuses a path with another suffix — a WAV named ``x.mp3`` would be opened as
MP3 by whoever receives it —, and :func:`format_for_suffix` names the format a path asks for
(the command line infers the format with it).

Looping: the tactile pattern (1500 ms) loops while the pen moves. WAV (its ``smpl`` chunk and
whole periods), C header and Android's ``createWaveform`` carry the loop; AHAP, ``.haptic``,
``.hjif`` and the Android envelopes have no loop flag, so they hold one period (or ``repeats``
periods) and loop at playback.

May import (the ``layers`` contract of ``[tool.importlinter]`` in ``pyproject.toml``, checked by
``lint-imports``): :mod:`realpen.sound`, :mod:`realpen.tactile`, :mod:`realpen.motion`,
:mod:`realpen.datasets`, :mod:`realpen.dsp`, :mod:`realpen.io`, :mod:`realpen.checks` and the
stdlib-only modules (:mod:`realpen.errors`, :mod:`realpen.validation`, :mod:`realpen.defaults`,
``realpen._version``, ``realpen._lazy``, :mod:`realpen.examples`); never :mod:`realpen.profile`
or :mod:`realpen.display`, its siblings (:func:`export_profile` takes a loaded profile).
"""

from __future__ import annotations

import inspect
import os
from dataclasses import dataclass, replace
from pathlib import Path
from types import ModuleType

from realpen.defaults import EXPORT_FORMATS
from realpen.errors import ParameterError, fail
from realpen.exports import ahap, android, c_header, haptic, hjif, wav
from realpen.exports.base import Export
from realpen.exports.snippets import unity_script_name
from realpen.io.files import atomic_path

__all__ = ["FORMATS", "SUFFIXES", "Export", "Written", "format_names", "format_for_suffix",
           "check_suffix", "profile_inputs", "companion_paths", "render", "export",
           "export_profile"]

_MODULES = (wav, c_header, ahap, haptic, android, hjif)
FORMATS: dict[str, ModuleType] = dict(zip(EXPORT_FORMATS, _MODULES))
"""Format name (:data:`realpen.defaults.EXPORT_FORMATS`, in that order) → its module."""
SUFFIXES: dict[str, tuple[str, ...]] = {
    name: (module.SUFFIX, android.KOTLIN_SUFFIX) if module is android else (module.SUFFIX,)
    for name, module in FORMATS.items()}
"""Format name → the file suffixes it is written to (lower case; the first is the usual one)."""


def _ahap_path_options(path: Path) -> dict:
    return {"sound_file": f"{path.stem}-sound.wav", "ahap_file": path.name}


def _c_header_path_options(path: Path) -> dict:
    return {"header_file": path.name}


def _haptic_path_options(path: Path) -> dict:
    return {"haptic_file": path.name}


def _android_path_options(path: Path) -> dict:
    return {"kotlin_only": path.suffix.lower() == android.KOTLIN_SUFFIX}


_PATH_OPTIONS = {"ahap": _ahap_path_options, "android": _android_path_options,
                 "c-header": _c_header_path_options, "haptic": _haptic_path_options}


@dataclass
class Written:
    """What :func:`export` wrote: the main file, any companions, and the export."""

    path: Path
    companions: list[Path]
    export: Export


def format_names() -> str:
    """The known formats, comma-separated, for messages."""
    return ", ".join(FORMATS)


def _suffix_list() -> str:
    return ", ".join(f"{name} {' or '.join(suffixes)}" for name, suffixes in SUFFIXES.items())


def format_for_suffix(path: str | os.PathLike) -> str:
    """The format a file name asks for, by its suffix (any case): ``pen.ahap`` → ``"ahap"``,
    ``Pen.kt`` → ``"android"``.

    Raises:
        RealPenError: one line naming the path, when no format is written to its suffix.

    Example:
        >>> format_for_suffix("pencil.WAV"), format_for_suffix("pencil.json")
        ('wav', 'android')
    """
    suffix = Path(path).suffix.lower()
    for name, suffixes in SUFFIXES.items():
        if suffix in suffixes:
            return name
    what = f"the suffix {suffix}" if suffix else "no suffix"
    raise fail(path, f"has {what}; no export format is written to it (name the file for its "
                     f"format: {_suffix_list()})")


def check_suffix(fmt: str, path: str | os.PathLike) -> None:
    """Refuse to write format ``fmt`` to a file whose suffix (any case) is not the format's.

    Raises:
        ParameterError: an unknown ``fmt``.
        RealPenError: one line naming the path, the format and the suffix it is written to.
    """
    _module(fmt)
    suffix = Path(path).suffix.lower()
    if suffix not in SUFFIXES[fmt]:
        expected = " or ".join(SUFFIXES[fmt])
        found = f"not {suffix}" if suffix else "and this name has none"
        article = "an" if fmt[0] in "aeiou" else "a"
        raise fail(path, f"{article} {fmt} export is written to a {expected} file, {found} "
                         f"(name the file {Path(path).stem}{SUFFIXES[fmt][0]}, or choose the "
                         f"format its suffix names)")


def profile_inputs(profile) -> dict:
    """The export inputs of a pen profile: ``pattern``, ``sound`` (its loop), ``coupling``,
    ``name``, ``tool`` and ``version`` (the profile's content version).

    Raises:
        RealPenError: a sound-only pen (no tactile part: every format exports a pattern).
    """
    if not profile.has_tactile:
        raise fail(profile.path or profile.name, "is a sound-only pen (made without "
                                                 "vibration): it has no tactile pattern to "
                                                 "export")
    return {"pattern": profile.pattern, "sound": profile.sound_loop,
            "coupling": profile.coupling, "name": profile.name, "tool": profile.meta.tool,
            "version": profile.version}


def companion_paths(fmt: str, out_path: str | os.PathLike) -> list[Path]:
    """The files :func:`export` writes beside ``out_path`` for a pen profile (which has a
    sound and a coupling): for ``ahap`` the sound it plays, ``<stem>-sound.wav``, and its Swift
    player, ``<stem>.swift``; for ``haptic`` its Unity script
    (:func:`realpen.exports.snippets.unity_script_name`); none for the others.

    Raises:
        ParameterError: an unknown ``fmt``.
    """
    _module(fmt)
    out = Path(out_path)
    if fmt == "ahap":
        return [out.with_name(_ahap_path_options(out)["sound_file"]),
                out.with_name(f"{out.stem}.swift")]
    if fmt == "haptic":
        return [out.with_name(unity_script_name(out.name))]
    return []


def _module(fmt: str) -> ModuleType:
    module = FORMATS.get(fmt)
    if module is None:
        raise ParameterError("fmt", f"unknown format '{fmt}' (known: {format_names()})")
    return module


def render(fmt: str, pattern, sound=None, coupling=None, **options) -> Export:
    """Render a tactile pattern (and its sound loop) in format ``fmt`` without writing.

    Args:
        fmt: one of :data:`FORMATS` (``wav``, ``c-header``, ``ahap``, ``haptic``, ``android``,
            ``hjif``).
        pattern: a :class:`~realpen.tactile.pattern.TactilePattern`, or a
            :class:`~realpen.profile.bundle.PenProfile` (which brings its sound loop, coupling,
            name, tool and version; ``sound``/``coupling`` given here take precedence).
        sound: the sound loop (``samples``, ``rate`` in Hz); ``wav`` with ``stereo=True`` and
            the ``ahap`` sound events need it.
        coupling: the Eq. 1 constants (:class:`realpen.motion.coupling.Coupling`); the Android
            JSON copies them, the other formats cannot carry them.
        options: ``name``, ``tool``, ``version`` (labels; default ``"pattern"``, none, the
            pattern's version) and the format's own options, e.g. ``stereo=True``,
            ``rate=44100`` (Hz), ``repeats=2``, ``subtype="float"``. ``None`` means "not
            given".

    Returns:
        The :class:`~realpen.exports.base.Export`: bytes, summary, companion files, limits.

    Raises:
        ParameterError: an unknown ``fmt``, an option the format does not take (named by the
            option), a bad option value, or a missing sound where it is needed.
        RealPenError: a problem found while rendering (e.g. a silent pattern).

    Example:
        >>> from realpen.tactile.pattern import Component, TactilePattern
        >>> pattern = TactilePattern([[Component(175.0, 0.5)], [Component(200.0, 0.5)]])
        >>> render("c-header", pattern, name="demo").summary
        'realpen_demo_tactile[1600], 12-bit codes 708–3356 at 8000 Hz, loop'
    """
    module = _module(fmt)
    given = {name: value for name, value in options.items() if value is not None}
    grid_limits: tuple[str, ...] = ()
    if not hasattr(pattern, "subpatterns") and hasattr(pattern, "pattern") \
            and hasattr(pattern, "sound_loop"):  # a PenProfile
        grid_limits = _grid_limits(pattern)
        inputs = profile_inputs(pattern)
        pattern = inputs.pop("pattern")
        own_sound, own_coupling = inputs.pop("sound"), inputs.pop("coupling")
        sound = own_sound if sound is None else sound
        coupling = own_coupling if coupling is None else coupling
        given = {**inputs, **given}
    accepted = inspect.signature(module.export).parameters
    for name in given:
        if name not in accepted or name in ("pattern", "sound", "coupling"):
            raise ParameterError(name, f"not used by format '{fmt}'")
    result = module.export(pattern, sound, coupling, **given)
    return replace(result, limits=(*result.limits, *grid_limits)) if grid_limits else result


def _grid_limits(profile) -> tuple[str, ...]:
    """What every format says of a profile's vibration grid: only its reference pattern goes."""
    grid = profile.meta.grid
    if grid is None or len(grid.points) < 2:
        return ()
    point = grid.points[grid.reference]
    return (f"the vibration grid ({len(grid.points)} points that the feel follows with speed and "
            f"force); only the reference point's pattern ({point.speed_mm_s:g} mm/s, "
            f"{point.force_n:g} N) is exported",)


def export(fmt: str, out_path: str | os.PathLike, pattern, sound=None, coupling=None,
           **options) -> Written:
    """Render (see :func:`render`) and write ``out_path`` atomically.

    Companion files (e.g. the sound an AHAP plays, ``<stem>-sound.wav``) are written beside
    ``out_path``. Nothing is written unless rendering succeeds; each file appears whole or not
    at all. For ``android``, a ``.kt`` path writes the Kotlin source alone.

    Raises:
        ParameterError: as :func:`render`.
        RealPenError: an output path that cannot be written, or whose suffix is not the
            format's (:func:`check_suffix`), naming it.
    """
    out = Path(out_path)
    if out.is_dir():
        raise fail(out, "is a folder; give the file to write")
    check_suffix(fmt, out)
    if fmt in _PATH_OPTIONS:
        for name, value in _PATH_OPTIONS[fmt](out).items():
            if options.get(name) is None:
                options[name] = value
    result = render(fmt, pattern, sound, coupling, **options)
    companions = [out.with_name(name) for name in result.companions]
    try:
        with atomic_path(out) as tmp:
            tmp.write_bytes(result.data)
            for target, data in zip(companions, result.companions.values()):
                with atomic_path(target) as companion_tmp:
                    companion_tmp.write_bytes(data)
    except OSError as error:
        raise fail(out, f"cannot write ({error.strerror or error})") from None
    return Written(out, companions, result)


def export_profile(profile, fmt: str, out_path: str | os.PathLike, **options) -> Written:
    """Export a pen profile in format ``fmt`` to ``out_path`` (see :func:`export`).

    Args:
        profile: a loaded profile (see :func:`realpen.profile.registry.resolve_profile`).
        fmt: one of :data:`FORMATS`.
        out_path: the file to write, with the format's suffix (:data:`SUFFIXES`).
        options: format options, e.g. ``stereo=True``, ``rate=44100`` (Hz), ``repeats=2``,
            ``subtype="float"``.
    """
    return export(fmt, out_path, profile, **options)
