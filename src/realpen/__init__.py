"""RealPen: the feel and sound of a real pen on paper, for touch screens.

The library is numpy in, numpy out; the ``realpen`` command and the live app are thin shells
over it. ``import realpen as rp`` gives the curated API below; every name is imported on first
use, so ``import realpen`` itself is light (no numpy, scipy or matplotlib until they are needed).

- Recordings: :func:`load_recording`, :class:`Recording`, :func:`load_hatt` (HaTT texture models).
- Tactile: :func:`analyze`, :func:`tactile_pattern`, :class:`TactilePattern`, :class:`Actuator`,
  :func:`parse_actuator`.
- Sound: :func:`find_loop`, :class:`SoundLoop`, :class:`Coupling` (Eq. 1).
- Pen profiles and exports: :func:`load_profile`, :func:`save_profile`, :func:`list_profiles`,
  :func:`export`, :func:`load_haptic` (read an exported haptic file back and render it).
- Figures: :mod:`realpen.display` (every function draws into a given ``ax``).
- Errors: :class:`RealPenError` (bad data), :class:`ParameterError` (bad arguments).

Options are keyword-only everywhere. Example:

>>> import realpen as rp
>>> from realpen.examples import example_recording_path
>>> recording = rp.load_recording(example_recording_path())
>>> pattern = rp.tactile_pattern(recording, actuator="lra:f0=175,q=8", condition="B")
>>> pattern
TactilePattern(15 sub-patterns × 100 ms, 10 components each, 8000 Hz, lra:f0=175,q=8)
"""

from __future__ import annotations

from realpen._lazy import lazy_attributes

__all__ = [
    "__version__",
    # recordings and analysis
    "load_recording", "Recording", "analyze", "load_hatt",
    # tactile patterns
    "tactile_pattern", "TactilePattern", "Actuator", "parse_actuator",
    # sound
    "find_loop", "SoundLoop", "Coupling",
    # profiles and exports
    "load_profile", "save_profile", "list_profiles", "export", "load_haptic",
    # errors
    "RealPenError", "ParameterError",
    # figures (a subpackage, imported on first use: it needs matplotlib)
    "display",
]

# Names re-exported from the library, imported on first access (PEP 562). The version too:
# importlib.metadata is slower to import than the rest of `import realpen`.
_HOMES: dict[str, str] = {
    "__version__": "_version",
    "Recording": "io.recording",
    "load_hatt": "datasets.hatt",
    "TactilePattern": "tactile.pattern",
    "Actuator": "tactile.actuator",
    "parse_actuator": "tactile.actuator",
    "find_loop": "sound.loop",
    "SoundLoop": "sound.loop",
    "Coupling": "motion.coupling",
    "load_profile": "profile.registry",
    "save_profile": "profile.bundle",
    "list_profiles": "profile.registry",
    "load_haptic": "exports.reading",
    "RealPenError": "errors",
    "ParameterError": "errors",
}
_SUBPACKAGES = ("display", "io", "dsp", "motion", "tactile", "sound", "profile", "exports",
                "datasets", "examples", "errors", "checks", "defaults", "pens", "live", "cli")

__getattr__, __dir__ = lazy_attributes(__name__, _HOMES, __all__, _SUBPACKAGES)


def analyze(data, *, rate: float | None = None, unit_ms: float = 100.0, top: int = 10,
            count: int = 15, selection: str = "stationary", highpass_hz: float = 30.0,
            fmin: float | None = None, fmax: float | None = None, axis: str | None = None,
            analysis_rate: float | None = None, min_separation_hz: float | None = None,
            progress=None):
    """Principal frequencies of every unit sequence of a recording or an array.

    The input is prepared as the tactile pipeline prepares it — axes to one by DFT321, an
    optional resampling, a zero-phase high-pass — then split into ``unit_ms`` units whose top
    ``top`` spectral peaks are kept, and ``count`` consecutive units are selected.

    Args:
        data: a :class:`Recording`, or an array of shape (frames,) or (frames, axes).
        rate: the array's sampling rate in Hz (required for an array; a recording has its own).
        unit_ms: unit sequence length in ms.
        top: principal frequencies kept per unit.
        count: consecutive units to select (never the first or the last unit).
        selection: ``"stationary"`` (the steadiest run) or ``"middle"``.
        highpass_hz: high-pass cutoff in Hz (0: none).
        fmin, fmax: band in Hz where peaks count (default: ``highpass_hz`` to Nyquist).
        axis: how axes become one: ``"dft321"`` (default for several), ``"magnitude"`` or an
            axis name.
        analysis_rate: resample to this rate in Hz first (default: keep the rate).
        min_separation_hz: two peaks closer than this are one (default 1000 / unit_ms Hz).
        progress: called as ``progress(units_done, units_total)``.

    Returns:
        A :class:`realpen.dsp.spectrum.Analysis`.

    Raises:
        ParameterError: a bad option, or an array without ``rate``.
        RealPenError: silent, constant or too short input.

    Example:
        >>> import numpy as np, realpen as rp
        >>> t = np.arange(4 * 1344) / 1344
        >>> analysis = rp.analyze(np.sin(2 * np.pi * 180 * t), rate=1344, top=1)
        >>> round(float(analysis.frequencies_hz[5, 0]))
        180
    """
    from realpen.dsp.filters import prepare
    from realpen.dsp.spectrum import analyze as analyze_signal
    from realpen.dsp.stream import streamed_selection
    from realpen.io.recording import as_recording

    recording = as_recording(data, rate)
    prepared = prepare(recording, axis, analysis_rate, highpass_hz)
    fmin = highpass_hz if fmin is None else fmin
    analysis = analyze_signal(prepared.mono, prepared.rate, unit_ms, top, count, selection,
                              fmin=fmin, fmax=fmax, min_separation_hz=min_separation_hz,
                              source=recording.source, progress=progress)
    # The units `realpen analyze` and `realpen tactile` select from the same file.
    return streamed_selection(recording, analysis, axis=axis, analysis_rate=analysis_rate,
                              highpass_hz=highpass_hz, fmin=fmin, fmax=fmax)


def load_recording(path, *, rate: float | None = None, units: str | None = None,
                   even_grid=None, max_interpolated_pct: float = 5.0):
    """Load a vibration recording from WAV/FLAC/OGG, CSV or NPZ.

    Args:
        path: the file; its suffix picks the reader (``.csv``, ``.npz``, else audio).
        rate: sampling rate in Hz for a CSV with no time column or an NPZ with no ``rate``.
        units: the unit of the samples, overriding the file's (``"m/s^2"``, ``"g"``, ...).
        even_grid: a CSV whose time column has gaps (a phone's sensor drops samples) is put
            on an even grid: True or ``"median"`` at its median rate, a number at that rate in
            Hz; the missing samples are interpolated and the report (share interpolated,
            longest gap) is the last entry of ``history``. None: such a file is refused.
        max_interpolated_pct: with ``even_grid``, refuse the file when more than this share
            of its samples (per cent) is missing.

    Returns:
        A :class:`Recording` (samples of shape (frames, axes), rate, axes, units, provenance).

    Raises:
        RealPenError: a missing, empty, truncated or unreadable file, NaN/inf samples.
        ParameterError: a bad ``rate``, or none where the file does not carry one.

    Example:
        >>> import realpen as rp
        >>> from realpen.examples import example_recording_path
        >>> recording = rp.load_recording(example_recording_path())
        >>> recording.rate, recording.axes, recording.samples.shape
        (1344.0, ('x', 'y', 'z'), (16128, 3))
    """
    from realpen.io.recording import load_recording as load

    return load(path, rate=rate, units=units, even_grid=even_grid,
                max_interpolated_pct=max_interpolated_pct)


def tactile_pattern(recording, *, actuator="lra:f0=175,q=8", condition: str | None = None,
                    **options):
    """Build the looping, actuator-equalised tactile pattern of a vibration recording.

    Runs the whole tactile pipeline: axes to one, high-pass, unit spectra, the top-N principal
    frequencies of K consecutive units, the weighting 1/|H(f)| of the actuator, and the
    superposed, crossfaded sub-patterns (:func:`realpen.tactile.build.tactile_pattern`).

    Args:
        recording: a :class:`Recording` (see :func:`load_recording`), analysed whole, or the
            path of one, streamed so that memory does not grow with its length (see
            :func:`realpen.tactile.build.build_pattern`).
        actuator: an :class:`Actuator` or a spec string (``"lra:f0=175,q=8"``,
            ``"piezo:f0=300,q=2"``, ``"flat"`` or the path of a measured-response CSV).
        condition: study condition ``"A"``–``"F"``. None gives condition B (the method's
            choice: 10 frequencies × 15 sub-patterns of 100 ms) unless ``top``,
            ``subpatterns`` or ``unit_ms`` are given; a condition and counts that disagree
            are refused.
        options: any other parameter of the pipeline by keyword (``top``, ``subpatterns``,
            ``unit_ms``, ``rate`` in Hz, ``seed``, ``boundary``, ``cap_db``, ``selection``,
            ...; see :class:`realpen.tactile.conditions.TactileParams`).

    Returns:
        The :class:`TactilePattern`.

    Example:
        >>> import realpen as rp
        >>> from realpen.examples import example_recording_path
        >>> recording = rp.load_recording(example_recording_path())
        >>> rp.tactile_pattern(recording, actuator="lra:f0=175,q=8", condition="E")
        TactilePattern(1 sub-pattern × 1500 ms, 10 components each, 8000 Hz, lra:f0=175,q=8)
    """
    from realpen.tactile.build import tactile_pattern as build

    return build(recording, actuator, condition=condition, **options)


def export(fmt: str, path, item, *, sound=None, coupling=None, **options):
    """Write a tactile pattern (or a whole pen profile) in one of the export formats.

    Args:
        fmt: ``"wav"``, ``"c-header"``, ``"ahap"``, ``"haptic"``, ``"android"`` or ``"hjif"``.
        path: the file to write; companion files (an AHAP's sound) are written beside it.
        item: a :class:`TactilePattern`, or a pen profile (:func:`load_profile`), which brings
            its own sound loop and coupling.
        sound: a :class:`SoundLoop` to go with a pattern (``wav`` with ``stereo=True`` and the
            ``ahap`` sound events need one).
        coupling: the :class:`Coupling` constants (the Android export carries them).
        options: the format's own options (``stereo=True``, ``rate=44100``, ``repeats=2``, ...;
            see :mod:`realpen.exports`).

    Returns:
        What was written: ``path``, ``companions`` and the rendered ``export``.

    Example:
        >>> import tempfile, pathlib, realpen as rp
        >>> folder = pathlib.Path(tempfile.mkdtemp())
        >>> written = rp.export("ahap", folder / "pencil.ahap", rp.load_profile("pencil"))
        >>> sorted(p.name for p in folder.iterdir())
        ['pencil-sound.wav', 'pencil.ahap', 'pencil.swift']
    """
    from realpen.exports import export as write

    return write(fmt, path, item, sound=sound, coupling=coupling, **options)
