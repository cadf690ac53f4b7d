"""From recordings to a :class:`~realpen.profile.bundle.PenProfile`.

The vibration recording goes through the tactile pipeline
(:func:`realpen.tactile.build.build_pattern`), the friction sound through the loop-unit search
(:func:`realpen.sound.loop.find_loop_unit`); both, the actuator, the coupling constants and the
provenance of every input make one profile.

A profile whose feel follows the pen holds a :class:`~realpen.tactile.grid.VibrationGrid`:
one pattern per (speed, force) point, each built by the same pipeline with the same parameters
and actuator, from recordings made at those points
(:func:`~realpen.tactile.grid.grid_from_recordings`, and :func:`read_grid_csv` for the list of
them) or from vibration synthesised at every vertex of a HaTT texture model
(:func:`~realpen.tactile.grid.grid_from_hatt`).

A pen may be made from one recording alone: the friction sound without vibration (a sound-only
pen) or vibration without sound (a tactile-only pen). The part it lacks is bundled as silence
and the profile says which part it has (``parts``; see :mod:`realpen.profile.schema`).
"""

from __future__ import annotations

import csv
import io
import math
import os
import re
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from realpen._version import __version__
from realpen.checks import MAX_FORCE_N, MAX_GRID_POINTS, MAX_SPEED_MM_S
from realpen.defaults import SOUND_RATE_HZ
from realpen.errors import ParameterError, fail
from realpen.io.blocks import RecordingStream
from realpen.io.limits import read_bounded
from realpen.io.recording import Recording
from realpen.profile.bundle import PenProfile, bundle_wavs
from realpen.profile.schema import (
    NAME_PATTERN,
    SILENT_DBFS,
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
from realpen.tactile.grid import FULL_PRESSURE_FORCE_N, VibrationGrid, grid_from_hatt, grid_from_recordings
from realpen.tactile.pattern import Component, TactilePattern

if TYPE_CHECKING:
    from realpen.datasets.hatt import HattModelSet
    from realpen.sound.loop import SoundLoop

__all__ = ["build_profile", "profile_from_parts", "check_name", "read_grid_csv",
           "silent_pattern", "MAX_GRID_CSV_BYTES"]

MAX_GRID_CSV_BYTES = 1024 * 1024
"""The largest grid CSV read (bytes): a grid is at most 64 rows of a path and two numbers."""
GRID_CSV_COLUMNS = ("speed_mm_s", "force_n", "path")


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
                       model: dict | None = None, grid: VibrationGrid | None = None,
                       notes: Sequence[str] = (), parts: Sequence[str] | None = None
                       ) -> PenProfile:
    """Assemble a :class:`PenProfile` from a tactile pattern and a sound unit.

    Args:
        name: profile name (see :func:`check_name`).
        tool: the tool type, free text.
        pattern: the tactile pattern (its actuator and parameters are recorded).
        sound: the sound unit, one loop, full scale ±1.
        sound_rate: its rate in Hz.
        sound_section: ``mode``, ``unit_ms``, ``crossfade_ms``, ``start_s``, ``rms_dbfs``,
            ``seam`` of :class:`~realpen.profile.schema.SoundSection`.
        coupling: the :class:`~realpen.motion.coupling.Coupling` constants.
        sources: the input files.
        sound_parameters: the loop search's parameters and scores.
        model: parameters of the generating model, for modelled pens.
        grid: patterns at (speed, force) points (a format-3 profile); ``pattern`` must be its
            reference point's. A one-point grid is no grid: the profile stays format 2.
        notes: more notes for the provenance, after the pattern's own.
        parts: the parts the pen has, when only one (``["tactile"]`` or ``["sound"]``; the
            other is then silence, see :mod:`realpen.profile.schema`); None: both.

    Raises:
        ParameterError: a bad name, a pattern without an actuator, or a grid whose reference
            pattern is not ``pattern``.
    """
    check_name(name)
    if pattern.actuator is None:
        raise ParameterError("pattern", "needs its actuator (build it with build_pattern, or "
                                        "give TactilePattern(..., actuator=...))")
    if grid is not None and len(grid.points) == 1:
        grid = None  # the profile's one pattern already says all a single point does
    if grid is not None and grid.reference_pattern != pattern:
        raise ParameterError("grid", "the reference point's pattern must be the profile's "
                                     "pattern")
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
        parts=None if parts is None else list(parts),
        tactile=pattern,  # validation keeps the pattern's own fields (to_json), not its origin
        grid=grid,
        sound=SoundSection(rate=sound_rate, frames=len(sound), **sound_section),
        actuator=pattern.actuator,
        coupling=coupling,
        files=files,
        provenance=Provenance(realpen_version=__version__, sources=sources,
                              tactile_parameters=params, sound_parameters=sound_parameters,
                              model=model, notes=[*pattern.notes, *notes]))
    profile = PenProfile(meta, tactile, sound)
    profile.meta = profile._current_meta(bundle_wavs(profile))
    return profile


def silent_pattern(actuator: Actuator | str, params: TactileParams | None = None
                   ) -> TactilePattern:
    """The tactile pattern of a sound-only pen: silence as long as a pattern built with
    ``params`` (one sub-pattern of one component of amplitude 0), equalised for ``actuator``.

    Example:
        >>> float(abs(silent_pattern("lra:f0=175,q=8").render()).max())
        0.0
    """
    from realpen.tactile.actuator import parse_actuator

    params = params or TactileParams()
    actuator = parse_actuator(actuator) if isinstance(actuator, str) else actuator
    length_ms = params.subpatterns * params.unit_ms
    # Any frequency would do at amplitude 0; the actuator's own keeps the JSON meaningful.
    frequency = float(actuator.params.get("f0", 175.0)) if actuator.params else 175.0
    return TactilePattern([[Component(min(frequency, params.rate / 4), 0.0)]], params.rate,
                          length_ms, params.boundary, params.crossfade_ms, actuator=actuator)


def _silent_sound(unit_ms: float) -> tuple[np.ndarray, int, dict]:
    """(samples, rate in Hz, sound section) of a tactile-only pen: ``unit_ms`` of zeros."""
    frames = max(1, int(round(SOUND_RATE_HZ * unit_ms / 1000.0)))
    section = {"mode": "loop", "unit_ms": unit_ms, "crossfade_ms": 0.0, "start_s": None,
               "rms_dbfs": SILENT_DBFS, "seam": {}}
    return np.zeros(frames, dtype=np.float32), SOUND_RATE_HZ, section


def build_profile(name: str, tool: str,
                  vibration: Recording | RecordingStream | str | os.PathLike
                  | Sequence[tuple[float, float, Recording]] | HattModelSet | VibrationGrid
                  | None,
                  sound: Recording | SoundLoop | None, actuator: Actuator | str,
                  tactile_params: TactileParams | None = None, unit_ms: float = 300.0,
                  crossfade_ms: float = 10.0, coupling=None, description: str = "",
                  model: dict | None = None, progress=None, *,
                  reference: int | None = None,
                  full_pressure_force_n: float = FULL_PRESSURE_FORCE_N) -> PenProfile:
    """Run the tactile and the auditory pipelines and bundle the result.

    Args:
        name: profile name (letters, digits, ``-_.``; up to 64 characters).
        tool: the tool type (pencil, ballpoint, …).
        vibration: the pen's vibration recording (any axes and rate): a
            :class:`~realpen.io.recording.Recording` (analysed in memory) or a path or
            :class:`~realpen.io.blocks.RecordingStream` (streamed, in flat memory at any length;
            see :func:`~realpen.tactile.build.build_pattern`) — or, for a feel that
            follows the pen, recordings at several points as ``(speed_mm_s, force_n,
            recording)`` tuples (:func:`~realpen.tactile.grid.grid_from_recordings`), a HaTT
            texture model (:class:`~realpen.datasets.hatt.HattModelSet`,
            :func:`~realpen.tactile.grid.grid_from_hatt`), or a
            ready :class:`~realpen.tactile.grid.VibrationGrid` (its patterns are used as they
            are; ``actuator`` and ``tactile_params`` are then ignored). None: a sound-only pen
            (its tactile pattern is silence, :func:`silent_pattern`).
        sound: the pen's friction sound, mono, already at the profile's sound rate (Hz); or a
            ready :class:`~realpen.sound.loop.SoundLoop` (e.g. a WAV whose ``smpl`` chunk
            declares its loop, from :func:`~realpen.sound.loop.load_sound`), used as it is.
            None: a tactile-only pen (its sound unit is ``unit_ms`` of silence at
            :data:`~realpen.defaults.SOUND_RATE_HZ`). ``vibration`` and ``sound`` may not both
            be None.
        actuator: an :class:`~realpen.tactile.actuator.Actuator` or a spec string (a sound-only
            pen keeps it too: the pen's actuator, for when a vibration is added).
        tactile_params: the tactile pipeline's parameters (default: condition B's).
        unit_ms, crossfade_ms: loop-unit length and wrap crossfade in ms.
        coupling: the Eq. 1 constants (default: ``Coupling()``, :class:`realpen.motion.coupling.Coupling`).
        model: parameters of the generating model, for modelled pens.
        progress: called as ``progress(done, total)`` during the vibration's analysis (for a
            grid: points done of all points).
        reference: for a grid, the point whose pattern is the profile's ``tactile`` section
            (default: the point nearest the middle of the grid,
            :func:`~realpen.tactile.grid.central_point`).
        full_pressure_force_n: for points or a HaTT model, the force in N at page pressure 1
            (a ready grid keeps its own).

    Raises:
        ParameterError: a bad name or parameter, named by its Python name; ``vibration`` and
            ``sound`` both None.
        RealPenError: a problem with a recording, naming it.
    """
    from realpen.datasets.hatt import HattModelSet
    from realpen.motion.coupling import Coupling
    from realpen.sound.loop import SoundLoop, find_loop_unit

    check_name(name)
    if vibration is None and sound is None:
        raise ParameterError("vibration", "and sound are both None; a pen needs a vibration "
                                          "source, a sound recording, or both")
    coupling = Coupling() if coupling is None else coupling
    params = tactile_params or TactileParams()
    grid, notes = None, ()
    if vibration is None:
        pattern, sources = silent_pattern(actuator, params), []
    elif isinstance(vibration, (Recording, RecordingStream, str, os.PathLike)):
        pattern = build_pattern(vibration, actuator, params, progress)
        source = vibration.source if isinstance(vibration, (Recording, RecordingStream)) \
            else vibration
        sources = [SourceFile(role="vibration", name=Path(source).name,
                              sha256=pattern.provenance.get("sha256"))]
    else:
        if isinstance(vibration, VibrationGrid):
            grid = vibration if reference is None else _with_reference(vibration, reference)
        elif isinstance(vibration, HattModelSet):
            grid = grid_from_hatt(vibration, actuator, params, reference=reference,
                                  full_pressure_force_n=full_pressure_force_n, progress=progress)
        elif isinstance(vibration, Sequence) and not isinstance(vibration, (str, bytes)):
            grid = grid_from_recordings(vibration, actuator, params, reference=reference,
                                        full_pressure_force_n=full_pressure_force_n,
                                        progress=progress)
        else:
            raise ParameterError("vibration", f"must be a Recording, (speed, force, recording) "
                                              f"points, a HaTT model set or a VibrationGrid, "
                                              f"got {type(vibration).__name__}")
        pattern, notes = grid.reference_pattern, grid.notes
        sources = [SourceFile(**source) for source in grid.provenance.get("sources", [])]
        if grid.provenance.get("model") is not None:
            model = {**grid.provenance["model"], **(model or {})}
    if sound is None:
        samples, sound_rate, section = _silent_sound(unit_ms)
        return profile_from_parts(name, tool, pattern, samples, sound_rate, section, coupling,
                                  sources, {}, description, model, grid, notes, parts=["tactile"])
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
    sources.append(SourceFile(role="sound", name=Path(sound.source or "sound").name,
                              sha256=sound_sha256))
    return profile_from_parts(name, tool, pattern, unit.samples, int(round(sound.rate)), section,
                              coupling, sources,
                              {"unit_ms": unit_ms, "crossfade_ms": crossfade_ms,
                               "scores": report.get("scores"), "rate": sound.rate},
                              description, model, grid, notes,
                              parts=["sound"] if vibration is None else None)


# --- grids ---------------------------------------------------------------------------------------

def _with_reference(grid: VibrationGrid, reference: int) -> VibrationGrid:
    from dataclasses import replace

    return replace(grid, reference=reference)


def read_grid_csv(path: str | os.PathLike) -> list[tuple[float, float, Path]]:
    """The points of a grid CSV: a header naming ``speed_mm_s``, ``force_n`` and ``path``
    (any order, other columns ignored), then one row per point: speed in mm/s, force in N,
    and the recording's path, relative to the CSV's folder unless absolute.

    Returns:
        ``(speed_mm_s, force_n, recording path)`` per row, in file order.

    Raises:
        RealPenError: naming the CSV (and the line, counted as an editor does): a missing or
            unreadable file, a missing header or column, a value that is not a finite number
            from 0 up, a recording that is not there, a (speed, force) given twice, no rows,
            more than :data:`~realpen.checks.MAX_GRID_POINTS` rows.
    """
    path = Path(path)
    from realpen.io.files import check_readable_file

    check_readable_file(path)
    data = read_bounded(path, MAX_GRID_CSV_BYTES, "grid CSV files")
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError:
        raise fail(path, "not a text CSV file") from None
    lines = [(number, line) for number, line in enumerate(io.StringIO(text), start=1)
             if line.strip()]
    if not lines:
        raise fail(path, f"is empty; it needs a header {','.join(GRID_CSV_COLUMNS)} and a row "
                         f"per point")
    header_line, header = lines[0][0], _cells(lines[0][1])
    names = [cell.strip().lower() for cell in header]
    missing = [name for name in GRID_CSV_COLUMNS if name not in names]
    if missing:
        raise fail(path, f"line {header_line}: the header needs the columns "
                         f"{', '.join(GRID_CSV_COLUMNS)} (missing {', '.join(missing)})")
    where = {name: names.index(name) for name in GRID_CSV_COLUMNS}
    if len(lines) - 1 > MAX_GRID_POINTS:
        raise fail(path, f"has {len(lines) - 1} rows; a grid holds at most {MAX_GRID_POINTS} "
                         f"points")
    rows, seen = [], {}
    for number, line in lines[1:]:
        cells = _cells(line)
        if len(cells) != len(header):
            raise fail(path, f"line {number}: {len(cells)} fields, the header has "
                             f"{len(header)}")
        values = []
        for name, limit in (("speed_mm_s", MAX_SPEED_MM_S), ("force_n", MAX_FORCE_N)):
            cell = cells[where[name]].strip()
            try:
                value = float(cell) if len(cell) <= 64 else math.nan
            except ValueError:
                value = math.nan
            if not math.isfinite(value) or not 0 <= value <= limit:
                raise fail(path, f"line {number}: {name} {cell[:40]!r} must be a number from "
                                 f"0 to {limit:g}")
            values.append(value)
        key = tuple(values)
        if key in seen:
            raise fail(path, f"line {number}: {key[0]:g} mm/s, {key[1]:g} N is on line "
                             f"{seen[key]} too")
        seen[key] = number
        given = cells[where["path"]].strip()
        if not given:
            raise fail(path, f"line {number}: the path is empty")
        recording = Path(given) if os.path.isabs(given) else path.parent / given
        if not recording.is_file():
            raise fail(path, f"line {number}: {given}: no such file")
        if recording.resolve() == path.resolve():
            raise fail(path, f"line {number}: the grid lists itself as a recording")
        rows.append((values[0], values[1], recording))
    if not rows:
        raise fail(path, "has a header but no points")
    return rows


def _cells(line: str) -> list[str]:
    return next(csv.reader([line.rstrip("\r\n")]), [])
