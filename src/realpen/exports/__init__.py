"""Exports of a pen profile to the formats haptic platforms read, one module per format.

:data:`FORMATS` maps a format name to its module. Each module documents its fields, where they
come from, and what the format cannot carry, and defines ``SUFFIX``, ``LIMITS`` and
``export(profile, **options) -> Export``; a module may define ``path_options(path)`` for
options that follow from the output path. :func:`export_profile` renders and writes atomically.

Looping: the tactile pattern (1500 ms) loops while the pen moves. WAV, C header and Android's
``createWaveform`` carry the loop; AHAP, ``.haptic``, ``.hjif`` and the Android envelopes have
no loop flag, so they hold one period (or ``repeats`` periods) and loop at playback.
"""

from __future__ import annotations

import inspect
import os
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType

from realpen.errors import RealPenError, fail
from realpen.io.files import atomic_path
from realpen.profile.bundle import PenProfile
from realpen.exports import ahap, android, c_header, haptic, hjif, wav
from realpen.exports.base import Export

FORMATS: dict[str, ModuleType] = {
    "wav": wav,
    "c-header": c_header,
    "ahap": ahap,
    "haptic": haptic,
    "android": android,
    "hjif": hjif,
}


def _ahap_path_options(path: Path) -> dict:
    return {"sound_file": f"{path.stem}-sound.wav"}


def _android_path_options(path: Path) -> dict:
    return {"kotlin_only": path.suffix.lower() == android.KOTLIN_SUFFIX}


_PATH_OPTIONS = {"ahap": _ahap_path_options, "android": _android_path_options}


@dataclass
class Written:
    """What :func:`export_profile` wrote: the main file, any companions, and the export."""

    path: Path
    companions: list[Path]
    export: Export


def format_names() -> str:
    """The known formats, comma-separated, for messages."""
    return ", ".join(FORMATS)


def render(profile: PenProfile, fmt: str, **options) -> Export:
    """Render ``profile`` in format ``fmt`` without writing anything.

    Options the format does not take are refused (``None`` means "not given").

    Raises:
        RealPenError: an unknown format or an option the format does not take, named as the
            command line names it (``--stereo``), or a problem found while rendering.
    """
    module = FORMATS.get(fmt)
    if module is None:
        raise RealPenError(f"--format: unknown format '{fmt}' (known: {format_names()})")
    accepted = inspect.signature(module.export).parameters
    given = {name: value for name, value in options.items() if value is not None}
    for name, value in given.items():
        if name not in accepted:
            raise RealPenError(f"--{name.replace('_', '-')}: not used by --format {fmt}")
    return module.export(profile, **given)


def export_profile(profile: PenProfile, fmt: str, out_path: str | os.PathLike,
                   **options) -> Written:
    """Export ``profile`` in format ``fmt`` to ``out_path``, atomically.

    Companion files (e.g. the sound an AHAP plays) are written beside ``out_path``. Nothing is
    written unless rendering succeeds; each file appears whole or not at all.

    Args:
        profile: a loaded profile (see :func:`realpen.profile.resolve_profile`).
        fmt: one of :data:`FORMATS`.
        out_path: the file to write.
        options: format options, e.g. ``stereo=True``, ``rate=44100``, ``repeats=2``.

    Raises:
        RealPenError: unknown format, unsupported option, bad option value, or an output path
            that cannot be written — one line each.
    """
    out = Path(out_path)
    if out.is_dir():
        raise fail(out, "is a folder; give the file to write")
    if fmt in _PATH_OPTIONS:
        for name, value in _PATH_OPTIONS[fmt](out).items():
            options.setdefault(name, value)
    result = render(profile, fmt, **options)
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
