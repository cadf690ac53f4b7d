"""Recordings of pen vibration: loading, saving, DFT321, resampling and the high-pass filter.

A :class:`Recording` is a block of samples (frames × axes) with its rate, axis names, units and
provenance. Loaders accept WAV/FLAC/OGG (any PCM or float subtype, any channel count), CSV (a
header row, an optional time column) and NPZ.
"""

from __future__ import annotations

import os
import re
import zipfile
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import soundfile as sf
from scipy.interpolate import CubicSpline

from realpen.errors import ParameterError, fail, require_number
from realpen.io.csvtable import read_csv
from realpen.io.files import atomic_path, check_readable_file, riff_chunks, sha256_of

__all__ = ["Recording", "load_recording", "as_recording", "save_npz", "AXIS_CHOICES"]

AXIS_CHOICES = ("dft321", "x", "y", "z", "magnitude")


@dataclass(frozen=True)
class Recording:
    """Samples of one recording.

    Attributes:
        samples: float64 array, shape (frames, axes).
        rate: sampling rate in Hz.
        axes: one name per column of ``samples`` (e.g. ``("x", "y", "z")``).
        units: physical unit of the samples (``"m/s^2"``, ``"g"``, ``"full scale"``...).
        source: where the samples came from (a file path, or a description).
        sha256: SHA-256 of the source file's bytes, when there is one.
        history: processing steps applied since loading, oldest first.
    """

    samples: np.ndarray
    rate: float
    axes: tuple[str, ...]
    units: str = "arbitrary"
    source: str = "memory"
    sha256: str | None = None
    history: tuple[str, ...] = field(default_factory=tuple)

    def __post_init__(self) -> None:
        samples = np.asarray(self.samples, dtype=np.float64)
        if samples.ndim == 1:
            samples = samples[:, None]
        object.__setattr__(self, "samples", samples)
        if samples.ndim != 2 or samples.shape[1] != len(self.axes):
            raise ValueError(f"samples of shape {samples.shape} do not match axes {self.axes}")

    def __repr__(self) -> str:
        axes = ",".join(self.axes) if len(self.axes) <= 4 else f"{len(self.axes)} axes"
        source = Path(self.source).name if self.source else "memory"
        source = source if len(source) <= 60 else source[:57] + "..."
        return (f"Recording({axes}, {self.samples.shape[0]} frames at {self.rate:g} Hz "
                f"({self.duration:.3f} s), {self.units}, from {source})")

    @property
    def duration(self) -> float:
        """Length in seconds."""
        return self.samples.shape[0] / self.rate

    @property
    def mono(self) -> np.ndarray:
        """The single axis of a one-axis recording, shape (frames,)."""
        if self.samples.shape[1] != 1:
            raise ValueError("recording has more than one axis; combine them first")
        return self.samples[:, 0]

    def with_samples(self, samples: np.ndarray, step: str, **changes) -> Recording:
        """A copy with new samples and one more entry in ``history``."""
        return replace(self, samples=samples, history=self.history + (step,), **changes)


def _check_finite(samples: np.ndarray, source: str) -> None:
    bad = ~np.isfinite(samples)
    if bad.any():
        first = int(np.argwhere(bad)[0][0])
        raise fail(source, f"contains NaN or infinite values (first at frame {first})")


def _axis_names(count: int) -> tuple[str, ...]:
    """Default names of ``count`` columns: x, y, z for up to three, else ch0, ch1, ..."""
    return ("x", "y", "z")[:count] if count <= 3 else tuple(f"ch{i}" for i in range(count))


def as_recording(data, rate: float | None = None, *, rate_parameter: str = "rate",
                 data_parameter: str = "data") -> Recording:
    """A :class:`Recording` from a Recording (as it is), a file path, or an array of samples.

    Args:
        data: a Recording; a path to a WAV/FLAC/OGG, CSV or NPZ file (see
            :func:`load_recording`); or an array of shape (frames,) or (frames, axes).
        rate: sampling rate in Hz: required with an array, refused with a Recording, and with
            a path only for files that carry no rate.
        rate_parameter, data_parameter: how the caller names ``rate`` and ``data`` in messages.

    Raises:
        ParameterError: a missing or superfluous rate, an array that is not (frames, axes) of
            finite numbers, or a ``data`` of another type.

    >>> as_recording([0.0, 1.0, 0.0, -1.0], rate=1344)
    Recording(x, 4 frames at 1344 Hz (0.003 s), arbitrary, from array)
    """
    if isinstance(data, Recording):
        if rate is not None and rate != data.rate:
            raise ParameterError(rate_parameter, f"a Recording carries its own rate "
                                                 f"({data.rate:g} Hz); give it only with an array")
        return data
    if isinstance(data, (str, os.PathLike)):
        return load_recording(data, rate=rate)
    if rate is None:
        raise ParameterError(rate_parameter, "needed in Hz when the data is an array")
    require_number(rate_parameter, rate, minimum=0.0, inclusive=False)
    try:
        samples = np.asarray(data, dtype=np.float64)
    except (TypeError, ValueError):
        raise ParameterError(data_parameter, f"must be a Recording, a path or an array of "
                                             f"numbers, not {type(data).__name__}") from None
    if samples.ndim == 1:
        samples = samples[:, None]
    if samples.ndim != 2 or samples.shape[0] == 0:
        raise ParameterError(data_parameter, f"must have shape (frames,) or (frames, axes), "
                                             f"got {samples.shape}")
    if samples.shape[1] > samples.shape[0]:
        raise ParameterError(data_parameter, f"shape {samples.shape} has more axes than "
                                             f"frames; pass (frames, axes), e.g. data.T")
    if not np.all(np.isfinite(samples)):
        raise ParameterError(data_parameter, "contains NaN or infinite values")
    return Recording(samples, float(rate), _axis_names(samples.shape[1]), source="array")


def load_recording(path: str | os.PathLike, rate: float | None = None,
                   units: str | None = None) -> Recording:
    """Load a vibration recording from WAV/FLAC/OGG, CSV or NPZ.

    Args:
        path: the file. The suffix picks the reader (``.csv``, ``.npz``; anything else is read
            as audio by soundfile).
        rate: sampling rate in Hz for a CSV with no time column or an NPZ with no ``rate``
            (ignored when the file carries its own rate).
        units: override the unit of the samples.

    Returns:
        A :class:`Recording` with ``source`` and ``sha256`` set.

    Raises:
        RealPenError: missing, empty, truncated or unreadable files, NaN/inf samples.
        ParameterError: ``rate`` is not a positive number, or is needed (a CSV with no time
            column, an NPZ with no ``rate``) and not given.
    """
    path = Path(path)
    check_readable_file(path)
    if rate is not None:
        require_number("rate", rate, minimum=0.0, inclusive=False)
    suffix = path.suffix.lower()
    if suffix == ".csv":
        recording = _load_csv(path, rate)
    elif suffix == ".npz":
        recording = _load_npz(path, rate)
    else:
        recording = _load_audio(path)
    if recording.samples.shape[0] == 0:
        raise fail(path, "holds no samples")
    if not (np.isfinite(recording.rate) and recording.rate > 0):
        raise fail(path, f"sampling rate must be a positive number, got {recording.rate}")
    _check_finite(recording.samples, str(path))
    return replace(recording, source=str(path), sha256=sha256_of(path),
                   units=units or recording.units)


def _load_audio(path: Path) -> Recording:
    try:
        with sf.SoundFile(path) as handle:
            expected = handle.frames
            data = handle.read(dtype="float64", always_2d=True)
            rate = handle.samplerate
    except (sf.LibsndfileError, RuntimeError, TypeError, ValueError) as error:
        reason = str(error).split("\n")[0]
        raise fail(path, f"not a readable audio file ({reason})") from None
    if data.shape[0] < expected:
        raise fail(path, f"truncated: header promises {expected} frames, file holds {data.shape[0]}")
    missing = _wav_missing_bytes(path)
    if missing:
        raise fail(path, f"truncated: the WAV data chunk is {missing} bytes shorter than its header says")
    channels = data.shape[1]
    axes = _axis_names(channels)
    return Recording(data, float(rate), axes, units="full scale")


def _wav_missing_bytes(path: Path) -> int:
    """Bytes missing from a RIFF/WAVE data chunk (0 when complete or not a RIFF file).

    libsndfile quietly reads what is there, so a cut-off WAV must be caught from its header.
    """
    with open(path, "rb") as handle:
        for name, offset, length in riff_chunks(handle):
            if name == b"data":
                if length in (0, 0xFFFFFFFF):  # streamed WAVs leave the size unset
                    return 0
                return max(0, length - (path.stat().st_size - offset))
    return 0


TIME_PATTERN = re.compile(r"^(t|time|timestamp)([^a-z0-9].*)?$", re.IGNORECASE)
JITTER_TOLERANCE = 0.01  # steps within 1 % of the median count as even sampling
GAP_FACTOR = 2.0  # a step this many times the median is a gap: samples are missing


def _load_csv(path: Path, rate: float | None) -> Recording:
    # The one CSV reader: a header row, a sniffed delimiter (a decimal comma with ';'), blank
    # lines skipped, every value a finite number, messages naming the line.
    table = read_csv(path)
    header = list(table.names)
    values = table.values
    time_index = next((i for i, name in enumerate(header) if TIME_PATTERN.match(name)), None)
    if time_index is not None:
        times = values[:, time_index]
        values = np.delete(values, time_index, axis=1)
        time_name = header.pop(time_index)
        rate, values = _even_sampling(path, time_name, times, values)
    elif rate is None:
        # A missing argument, not bad data: the caller names its own way of giving ``rate``.
        raise ParameterError("rate", f"needed in Hz: {path} is a CSV with no time column "
                                     f"(t, time or timestamp)")
    if values.shape[1] == 0:
        raise fail(path, "CSV has no signal columns")
    return Recording(values, float(rate), tuple(header))


def _even_sampling(path: Path, name: str, times: np.ndarray, values: np.ndarray
                   ) -> tuple[float, np.ndarray]:
    """Rate from a time column (s); jittered timestamps are interpolated onto an even grid.

    The interpolation is a cubic spline, which keeps tones up to a third of the rate within a
    few per cent; larger gaps than ``GAP_FACTOR`` steps are refused rather than invented.
    """
    steps = np.diff(times)
    if len(steps) == 0 or not np.all(steps > 0):
        raise fail(path, f"time column '{name}' is not strictly increasing")
    step = float(np.median(steps))
    widest = int(np.argmax(steps))
    if steps[widest] > GAP_FACTOR * step:
        raise fail(path, f"time column '{name}' has a gap of {steps[widest]:.4g} s after "
                         f"{times[widest]:.4g} s (samples are {step:.4g} s apart); analyse the "
                         f"parts on either side separately")
    if np.max(np.abs(steps - step)) <= JITTER_TOLERANCE * step:
        return 1.0 / step, values
    grid = times[0] + np.arange(int(np.floor((times[-1] - times[0]) / step)) + 1) * step
    return 1.0 / step, CubicSpline(times, values, axis=0)(grid)


def _load_npz(path: Path, rate: float | None) -> Recording:
    try:
        archive = np.load(path, allow_pickle=False)
        if not hasattr(archive, "files"):
            raise fail(path, "is a single .npy array, not an NPZ archive")
        with archive:
            contents = {key: archive[key] for key in archive.files}
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as error:
        raise fail(path, f"not a readable NPZ archive ({error})") from None
    key = next((k for k in ("samples", "data", "acc", "acceleration") if k in contents), None)
    if key is None:
        raise fail(path, "NPZ has no 'samples' array")
    samples = contents[key]
    if samples.dtype.kind not in "iuf":
        raise fail(path, f"'{key}' must hold real numbers, not {samples.dtype}")
    samples = samples.astype(np.float64)
    if samples.ndim == 1:
        samples = samples[:, None]
    if samples.ndim != 2:
        raise fail(path, f"'{key}' must be 1-D or 2-D, got shape {samples.shape}")
    if "rate" in contents:
        stored = contents["rate"]
        if stored.size != 1 or stored.dtype.kind not in "iuf":
            raise fail(path, "'rate' must be one number in Hz")
        rate = float(stored.reshape(()))
    elif rate is None:
        raise ParameterError("rate", f"needed in Hz: {path} is an NPZ with no 'rate' array")
    if "axes" in contents:
        names = np.atleast_1d(contents["axes"])
        if names.dtype.kind not in "US" or names.ndim != 1:
            raise fail(path, "'axes' must be an array of axis names")
        axes = tuple(str(a) for a in names)
    else:
        axes = _axis_names(samples.shape[1])
    if len(axes) != samples.shape[1]:
        raise fail(path, f"NPZ names {len(axes)} axes for {samples.shape[1]} columns")
    units = str(contents["units"]) if "units" in contents else "arbitrary"
    return Recording(samples, rate, axes, units=units)


def save_npz(recording: Recording, path: str | os.PathLike) -> None:
    """Save a recording as NPZ (``samples``, ``rate``, ``axes``, ``units``) atomically."""
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as handle:
            np.savez_compressed(handle, samples=recording.samples.astype(np.float32),
                                rate=recording.rate, axes=np.array(recording.axes),
                                units=recording.units)
