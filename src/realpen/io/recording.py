"""Recordings of pen vibration: loading, saving, DFT321, resampling and the high-pass filter.

A :class:`Recording` is a block of samples (frames × axes) with its rate, axis names, units and
provenance. Loaders accept WAV/FLAC/OGG (any PCM or float subtype, any channel count), CSV (a
header row, an optional time column) and NPZ.

A WAV header holds a whole number of Hz; a capture from the pen's accelerometer
(:func:`realpen.device.capture.write_capture`) runs at the sensor's own rate (1344 Hz ± a few per
cent, estimated from the pen's clock), which it writes exactly in the JSON of the file's comment
(``"format": "realpen-capture/1"``, ``rate_hz``, ``units``): the loaders take the rate and units
from there (:func:`audio_rate_units`).

Every loader checks what the file declares against :mod:`realpen.io.limits` (rate, channels,
samples in all) before it allocates the samples, so a forged header or a compressed NPZ of
zeros is refused in one line instead of exhausting memory.
"""

from __future__ import annotations

import io
import math
import os
import re
import zipfile
import zlib
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import soundfile as sf

from realpen.checks import MAX_RATE_HZ, MIN_RATE_HZ, require_rate
from realpen.errors import ParameterError, fail
from realpen.io.csvtable import read_csv
from realpen.io.files import atomic_path, check_readable_file, riff_chunks, sha256_of
from realpen.io.limits import (
    MAX_CHANNELS,
    MAX_FRAMES,
    MAX_NPY_HEADER_BYTES,
    MAX_NPZ_ARRAY_BYTES,
    MAX_NPZ_DIRECTORY_BYTES,
    MAX_SAMPLE_MAGNITUDE,
    check_signal,
)
from realpen.io.timegrid import (
    DEFAULT_MAX_INTERPOLATED_PCT,
    gap_refusal,
    grid_rate_choice,
    place_on_grid,
)

__all__ = ["Recording", "load_recording", "as_recording", "save_npz", "AXIS_CHOICES",
           "CAPTURE_FORMAT", "capture_metadata", "audio_rate_units",
           # the readers' parts that the block reader (realpen.io.blocks) shares
           "GAP_FACTOR", "JITTER_TOLERANCE", "TIME_PATTERN", "NPZ_METADATA", "NPZ_ERRORS",
           "axis_names", "wav_missing_bytes", "open_npz", "npz_metadata", "check_npz_method",
           "read_npz_array", "read_exactly", "read_npy_header"]

AXIS_CHOICES = ("dft321", "x", "y", "z", "magnitude")
CAPTURE_FORMAT = "realpen-capture/1"  # the "format" of a capture's JSON in its WAV comment
_MAX_UNITS_CHARS = 32


def capture_metadata(comment: str | None, header_rate: float) -> dict | None:
    """The provenance a capture wrote into an audio file's comment, or None when the comment
    is not one (any other text, or a ``rate_hz`` that is not the header's rate to within 1 Hz).

    Args:
        comment: the file's comment text.
        header_rate: the rate in the file's header, in Hz (the capture's, rounded).

    >>> capture_metadata('{"format": "realpen-capture/1", "rate_hz": 1366.85}', 1367)["rate_hz"]
    1366.85
    >>> capture_metadata("recorded on Tuesday", 1367) is None
    True
    """
    if not comment or not comment.lstrip().startswith("{"):
        return None
    import json

    try:
        data = json.loads(comment)
    except ValueError:
        return None
    if not isinstance(data, dict) or data.get("format") != CAPTURE_FORMAT:
        return None
    rate = data.get("rate_hz")
    if isinstance(rate, bool) or not isinstance(rate, (int, float)) or \
            not math.isfinite(rate) or abs(rate - header_rate) > 1.0:
        return None
    units = data.get("units")
    if not isinstance(units, str) or not 0 < len(units) <= _MAX_UNITS_CHARS:
        data["units"] = "m/s^2"
    return data


def audio_rate_units(handle: sf.SoundFile) -> tuple[float, str]:
    """(rate in Hz, units) of an open audio file: a capture's exact rate and units from its
    comment (:func:`capture_metadata`), else the header's rate in "full scale"."""
    try:
        comment = handle.comment
    except (sf.LibsndfileError, RuntimeError, UnicodeError, AttributeError):
        comment = None
    metadata = capture_metadata(comment, handle.samplerate)
    if metadata is None:
        return float(handle.samplerate), "full scale"
    return float(metadata["rate_hz"]), metadata["units"]


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


_SCAN_FRAMES = 1 << 20  # frames looked at a time when searching for a bad value


def _value_problem(samples: np.ndarray) -> str | None:
    """What is wrong with the values of ``samples`` (frames × axes), or None when nothing is.

    NaN, infinity, or a magnitude beyond :data:`MAX_SAMPLE_MAGNITUDE`: such a value is an
    overflow or damage, and judged later it would pass for silence or break the spectra. Only
    the failing case scans for the first bad frame, in blocks, so a valid recording costs no
    copy of its samples.
    """
    if samples.size == 0:
        return None
    peak = max(float(np.max(samples)), -float(np.min(samples)))  # NaN propagates
    if math.isfinite(peak) and peak <= MAX_SAMPLE_MAGNITUDE:
        return None
    for start in range(0, samples.shape[0], _SCAN_FRAMES):
        block = samples[start:start + _SCAN_FRAMES]
        bad = ~np.isfinite(block)
        if bad.any():
            frame = start + int(np.argwhere(bad)[0][0])
            return f"contains NaN or infinite values (first at frame {frame})"
        large = np.abs(block) > MAX_SAMPLE_MAGNITUDE
        if large.any():
            frame, axis = (int(i) for i in np.argwhere(large)[0])
            return (f"holds the value {block[frame - start, axis]:.3g} at frame {frame}; samples "
                    f"beyond ±{MAX_SAMPLE_MAGNITUDE:g} are not a measurement in any unit (an "
                    f"overflow or a damaged file)")
    return None


def axis_names(count: int) -> tuple[str, ...]:
    """Default names of ``count`` columns: x, y, z for up to three, else ch0, ch1, ..."""
    return ("x", "y", "z")[:count] if count <= 3 else tuple(f"ch{i}" for i in range(count))


def as_recording(data, rate: float | None = None, *, rate_parameter: str = "rate",
                 data_parameter: str = "data") -> Recording:
    """A :class:`Recording` from a Recording (as it is), a file path, or an array of samples.

    Args:
        data: a Recording; a path to a WAV/FLAC/OGG, CSV or NPZ file (see
            :func:`load_recording`); or an array of shape (frames,) or (frames, axes).
        rate: sampling rate in Hz (``MIN_RATE_HZ`` to ``MAX_RATE_HZ``): required with an array,
            refused with a Recording, and with a path only for files that carry no rate.
        rate_parameter, data_parameter: how the caller names ``rate`` and ``data`` in messages.

    Raises:
        ParameterError: a missing, superfluous or out-of-range rate, an array that is not
            (frames, axes) of finite numbers within ``MAX_SAMPLE_MAGNITUDE``, more axes or
            samples than :mod:`realpen.io.limits` allows, or a ``data`` of another type.

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
    require_rate(rate_parameter, rate)
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
    if samples.shape[1] > MAX_CHANNELS or samples.size > MAX_FRAMES:
        raise ParameterError(data_parameter, f"shape {samples.shape} is over the limits of "
                                             f"{MAX_CHANNELS} axes and {MAX_FRAMES:,} samples")
    problem = _value_problem(samples)
    if problem:
        raise ParameterError(data_parameter, problem)
    return Recording(samples, float(rate), axis_names(samples.shape[1]), source="array")


def load_recording(path: str | os.PathLike, rate: float | None = None,
                   units: str | None = None, *, even_grid: bool | str | float | None = None,
                   max_interpolated_pct: float = DEFAULT_MAX_INTERPOLATED_PCT) -> Recording:
    """Load a vibration recording from WAV/FLAC/OGG, CSV or NPZ.

    Args:
        path: the file. The suffix picks the reader (``.csv``, ``.npz``; anything else is read
            as audio by soundfile).
        rate: sampling rate in Hz for a CSV with no time column or an NPZ with no ``rate``
            (ignored when the file carries its own rate, but always checked): ``MIN_RATE_HZ``
            to ``MAX_RATE_HZ`` (100 Hz to 400 kHz).
        units: override the unit of the samples.
        even_grid: for a CSV with a time column whose samples have gaps (a phone's sensor
            drops samples): True or ``"median"`` puts the samples on an even grid at the
            median rate of the time column, a number in Hz at that rate (see
            :func:`realpen.io.timegrid.place_on_grid`); the missing samples are interpolated
            and the :class:`~realpen.io.timegrid.GridReport` is the last entry of the
            recording's ``history``. None (default): a gap is refused, naming this option.
        max_interpolated_pct: with ``even_grid``, refuse the file when more than this share
            of its samples (per cent) is missing.

    Returns:
        A :class:`Recording` with ``source`` and ``sha256`` set.

    Raises:
        RealPenError: missing, empty, truncated or unreadable files; NaN/inf samples or samples
            beyond ``MAX_SAMPLE_MAGNITUDE``; a file over a limit of :mod:`realpen.io.limits`
            (its rate, channels or samples, checked before they are read; a CSV's bytes, lines
            and fields; an NPZ's directory and arrays), naming the file and the limit.
        ParameterError: ``rate`` is not a number from ``MIN_RATE_HZ`` to ``MAX_RATE_HZ``, or is
            needed (a CSV with no time column, an NPZ with no ``rate``) and not given;
            ``even_grid`` is needed (a CSV whose time column has gaps) or given for a file
            that has no time column.

    Example:
        >>> import tempfile, numpy as np
        >>> t = np.delete(np.arange(800) / 400, [300, 301])  # a phone dropped two samples
        >>> path = tempfile.mkdtemp() + "/phone.csv"
        >>> np.savetxt(path, np.column_stack([t, np.sin(300 * t)]), fmt="%.6f", delimiter=",",
        ...            header="time,z", comments="")
        >>> recording = load_recording(path, even_grid=True)
        >>> recording.samples.shape, round(recording.rate, 6)
        ((800, 1), 400.0)
        >>> print(recording.history[-1])  # doctest: +ELLIPSIS
        put on an even grid at 400 Hz ...: 2 missing sample(s) interpolated, 0.25 % of 800; ...
    """
    path = Path(path)
    check_readable_file(path)
    if rate is not None:
        require_rate("rate", rate)
    grid_rate = grid_rate_choice(even_grid)
    suffix = path.suffix.lower()
    if grid_rate is not None and suffix != ".csv":
        raise ParameterError("even_grid", f"applies to a CSV with a time column; {path} is "
                                          f"not a CSV (its samples are evenly spaced)")
    if suffix == ".csv":
        recording = _load_csv(path, rate, grid_rate, max_interpolated_pct)
    elif suffix == ".npz":
        recording = _load_npz(path, rate)
    else:
        recording = _load_audio(path)
    if recording.samples.shape[0] == 0:
        raise fail(path, "holds no samples")
    # Every reader checked what it could before reading; this covers a rate given by the caller
    # for a CSV and the frames a CSV time column's interpolation made.
    check_signal(path, recording.rate, *recording.samples.shape)
    problem = _value_problem(recording.samples)
    if problem:
        raise fail(path, problem)
    return replace(recording, source=str(path), sha256=sha256_of(path),
                   units=units or recording.units)


def _load_audio(path: Path) -> Recording:
    try:
        with sf.SoundFile(path) as handle:
            expected = handle.frames
            # The header alone, before the samples are allocated (frames × channels float64).
            check_signal(path, handle.samplerate, expected, handle.channels)
            data = handle.read(dtype="float64", always_2d=True)
            rate, units = audio_rate_units(handle)
    except (sf.LibsndfileError, RuntimeError, TypeError, ValueError) as error:
        reason = str(error).split("\n")[0]
        raise fail(path, f"not a readable audio file ({reason})") from None
    if data.shape[0] < expected:
        raise fail(path, f"truncated: header promises {expected} frames, file holds {data.shape[0]}")
    missing = wav_missing_bytes(path)
    if missing:
        raise fail(path, f"truncated: the WAV data chunk is {missing} bytes shorter than its header says")
    channels = data.shape[1]
    axes = axis_names(channels)
    return Recording(data, float(rate), axes, units=units)


def wav_missing_bytes(path: Path) -> int:
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


def _load_csv(path: Path, rate: float | None, grid_rate: bool | float | None = None,
              max_interpolated_pct: float = DEFAULT_MAX_INTERPOLATED_PCT) -> Recording:
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
        if grid_rate is not None:
            values, report = place_on_grid(times, values, rate=grid_rate, source=path,
                                           time_name=time_name,
                                           max_interpolated_pct=max_interpolated_pct)
            if values.shape[1] == 0:
                raise fail(path, "CSV has no signal columns")
            return Recording(values, report.rate, tuple(header), history=(str(report),))
        rate, values = _even_sampling(path, time_name, times, values)
    elif grid_rate is not None:
        raise ParameterError("even_grid", f"applies to a CSV with a time column (t, time or "
                                          f"timestamp); {path} has none")
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
        raise gap_refusal(path, name, steps[widest], times[widest], step)
    rate = 1.0 / step
    if not MIN_RATE_HZ <= rate <= MAX_RATE_HZ:  # before the interpolation allocates its grid
        raise fail(path, f"time column '{name}' gives a sampling rate of {rate:.4g} Hz, outside "
                         f"the {MIN_RATE_HZ:,}–{MAX_RATE_HZ:,} Hz RealPen reads (are the times "
                         f"in seconds?)")
    if np.max(np.abs(steps - step)) <= JITTER_TOLERANCE * step:
        return rate, values
    grid = times[0] + np.arange(int(np.floor((times[-1] - times[0]) / step)) + 1) * step
    from scipy.interpolate import CubicSpline  # only for uneven sampling: heavy to import

    return rate, CubicSpline(times, values, axis=0)(grid)


NPZ_SAMPLE_KEYS = ("samples", "data", "acc", "acceleration")  # the first one present is read
NPZ_METADATA = ("rate", "axes", "units")
_READ_BYTES = 1 << 22  # bytes inflated at a time from an NPZ member
# What a damaged archive or member can raise from zipfile (RuntimeError: encrypted), zlib and
# numpy's header reader.
NPZ_ERRORS = (OSError, ValueError, EOFError, zipfile.BadZipFile, zlib.error, NotImplementedError,
               RuntimeError, OverflowError)


def _load_npz(path: Path, rate: float | None) -> Recording:
    """An NPZ recording, read member by member within the limits, never with ``np.load``.

    ``np.load`` allocates whatever shape a member's header declares and ``zipfile`` loads the
    whole directory; here the directory's size and each header are checked first, and a
    member is inflated only up to the size its header declares.
    """
    try:
        with open_npz(path) as (archive, members, key):
            samples = read_npz_array(path, archive, members[key], key, samples=True)
            contents = {name: read_npz_array(path, archive, members[name], name)
                        for name in NPZ_METADATA if name in members}
    except NPZ_ERRORS as error:
        raise fail(path, f"not a readable NPZ archive ({error})") from None
    if samples.ndim == 1:
        samples = samples[:, None]
    rate, axes, units = npz_metadata(path, contents, rate, *samples.shape)
    return Recording(samples, rate, axes, units=units)


def npz_metadata(path: Path, contents: dict, rate: float | None, frames: int, channels: int
                 ) -> tuple[float, tuple[str, ...], str]:
    """(rate in Hz, axis names, units) of an NPZ recording from its small arrays ``contents``
    (``rate``, ``axes``, ``units``; ``rate`` given here when the file has none), checked
    against its samples' ``frames`` × ``channels``."""
    if "rate" in contents:
        stored = contents["rate"]
        if stored.size != 1 or stored.dtype.kind not in "iuf":
            raise fail(path, "'rate' must be one number in Hz")
        rate = float(stored.reshape(()))
        check_signal(path, rate, frames, channels)
    elif rate is None:
        raise ParameterError("rate", f"needed in Hz: {path} is an NPZ with no 'rate' array")
    if "axes" in contents:
        names = np.atleast_1d(contents["axes"])
        if names.dtype.kind not in "US" or names.ndim != 1:
            raise fail(path, "'axes' must be an array of axis names")
        axes = tuple(str(a) for a in names)
    else:
        axes = axis_names(channels)
    if len(axes) != channels:
        raise fail(path, f"NPZ names {len(axes)} axes for {channels} columns")
    units = str(contents["units"]) if "units" in contents else "arbitrary"
    return float(rate), axes, units


def _check_zip_directory(path: Path, handle) -> None:
    """Refuse an NPZ whose zip directory is larger than :data:`MAX_NPZ_DIRECTORY_BYTES`.

    ``zipfile.ZipFile`` reads and parses the whole directory when it opens a file, with no
    limit and no public way to see its size first. ``_EndRecData`` is the function it uses to
    find the directory (the zip64 record included), so the size checked is the size it reads.
    """
    find_end = getattr(zipfile, "_EndRecData", None)
    if find_end is None:  # a Python whose zipfile has changed: its own limits must do
        return
    end = find_end(handle)
    if end is None:
        raise zipfile.BadZipFile("File is not a zip file")
    size = end[zipfile._ECD_SIZE]
    if size > MAX_NPZ_DIRECTORY_BYTES:
        raise fail(path, f"its zip directory is {size:,} bytes; NPZ files are limited to "
                         f"{MAX_NPZ_DIRECTORY_BYTES:,} (a recording needs a few arrays)")


@contextmanager
def open_npz(path: Path) -> Iterator[tuple[zipfile.ZipFile, dict[str, zipfile.ZipInfo], str]]:
    """The open NPZ archive, its members by array name and the samples' key, once the file is
    known to be an archive (not a bare .npy) with a bounded zip directory and a samples array.
    Zip errors propagate (callers turn them into one line naming the file)."""
    with open(path, "rb") as handle:
        if handle.read(6) == b"\x93NUMPY":
            raise fail(path, "is a single .npy array, not an NPZ archive")
        _check_zip_directory(path, handle)
    with zipfile.ZipFile(path) as archive:
        members: dict[str, zipfile.ZipInfo] = {}
        for info in archive.infolist():  # np.savez names the member of array "x" x.npy
            name = info.filename[:-4] if info.filename.endswith(".npy") else info.filename
            members.setdefault(name, info)
        key = next((k for k in NPZ_SAMPLE_KEYS if k in members), None)
        if key is None:
            raise fail(path, "NPZ has no 'samples' array")
        yield archive, members, key


def check_npz_method(path: Path, info: zipfile.ZipInfo, key: str) -> None:
    """Refuse an NPZ member that is neither stored nor deflated (zipfile inflates bzip2 and
    LZMA members without an output bound; numpy never writes them)."""
    if info.compress_type not in (zipfile.ZIP_STORED, zipfile.ZIP_DEFLATED):
        raise fail(path, f"'{key}' is compressed with zip method {info.compress_type}; NPZ "
                         f"arrays must be stored or deflated, as numpy writes them")


def read_npy_header(handle, path: Path, key: str) -> tuple[tuple[int, ...], bool, np.dtype]:
    """(shape, Fortran order, dtype) from the .npy header at the start of ``handle`` (an open
    NPZ member), leaving ``handle`` at the data: versions 1.0 and 2.0, the header at most
    :data:`~realpen.io.limits.MAX_NPY_HEADER_BYTES`."""
    version = np.lib.format.read_magic(handle)
    if version not in ((1, 0), (2, 0)):
        raise fail(path, f"'{key}' is a .npy version {version[0]}.{version[1]} array; "
                         f"RealPen reads versions 1.0 and 2.0")
    # numpy reads the whole declared header (up to 4 GiB) before checking its size: the
    # length is read and bounded here, and numpy parses a copy of the bounded bytes.
    width = 2 if version == (1, 0) else 4
    length_bytes = read_exactly(handle, width, path, key)
    length = int.from_bytes(length_bytes, "little")
    if length > MAX_NPY_HEADER_BYTES:
        raise fail(path, f"'{key}' declares a {length:,}-byte .npy header; headers are "
                         f"limited to {MAX_NPY_HEADER_BYTES:,} bytes")
    header = io.BytesIO(length_bytes + read_exactly(handle, length, path, key))
    read_header = np.lib.format.read_array_header_1_0 if version == (1, 0) else \
        np.lib.format.read_array_header_2_0
    return read_header(header)


def read_npz_array(path: Path, archive: zipfile.ZipFile, info: zipfile.ZipInfo, key: str,
                   samples: bool = False) -> np.ndarray:
    """One member of an NPZ, checked from its .npy header before any of its data is read.

    The samples (``samples=True``) must be 1-D or 2-D real numbers within ``MAX_CHANNELS`` and
    ``MAX_FRAMES``, and come back as float64, converted block by block so that no second copy
    in the stored type is made; any other member may declare at most
    ``MAX_NPZ_ARRAY_BYTES``. Object dtypes (pickles) and records are refused.
    """
    check_npz_method(path, info, key)
    with archive.open(info) as handle:
        shape, fortran, dtype = read_npy_header(handle, path, key)
        if dtype.itemsize == 0:
            raise fail(path, f"'{key}' holds {dtype} values, which take no bytes")
        if dtype.hasobject or dtype.fields is not None or dtype.subdtype is not None:
            raise fail(path, f"'{key}' holds {dtype} values; NPZ arrays must hold numbers or "
                             f"text (objects, which need pickles, and records are refused)")
        # A forged header's numbers may have thousands of digits: messages do not quote them.
        if any(size < 0 for size in shape):
            raise fail(path, f"'{key}' declares an impossible shape (a negative size)")
        count = math.prod(shape)  # exact: Python integers, however large the header's numbers
        if samples:
            if dtype.kind not in "iuf":
                raise fail(path, f"'{key}' must hold real numbers, not {dtype}")
            if len(shape) not in (1, 2):
                raise fail(path, f"'{key}' must be 1-D or 2-D, got {len(shape)}-D")
            check_signal(path, None, shape[0], shape[1] if len(shape) == 2 else 1)
            flat = np.empty(count, dtype=np.float64)
            step = max(1, _READ_BYTES // max(dtype.itemsize, 1))
            for start in range(0, count, step):
                stop = min(start + step, count)
                data = read_exactly(handle, (stop - start) * dtype.itemsize, path, key)
                flat[start:stop] = np.frombuffer(data, dtype=dtype)
        else:
            size = count * dtype.itemsize
            if size > MAX_NPZ_ARRAY_BYTES:
                raise fail(path, f"'{key}' declares more than {MAX_NPZ_ARRAY_BYTES:,} bytes; "
                                 f"NPZ arrays other than the samples are limited to "
                                 f"{MAX_NPZ_ARRAY_BYTES:,}")
            flat = np.frombuffer(read_exactly(handle, size, path, key), dtype=dtype,
                                 count=count)
    return flat.reshape(shape[::-1]).T if fortran else flat.reshape(shape)


def read_exactly(handle, size: int, path: Path, key: str) -> bytes:
    """``size`` bytes of an NPZ member; ``read(size)`` inflates no more than it returns."""
    data = handle.read(size)
    if len(data) < size:
        raise fail(path, f"'{key}' is truncated: its header declares more data than the "
                         f"archive holds")
    return data


def save_npz(recording: Recording, path: str | os.PathLike) -> None:
    """Save a recording as NPZ (``samples``, ``rate``, ``axes``, ``units``) atomically."""
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as handle:
            np.savez_compressed(handle, samples=recording.samples.astype(np.float32),
                                rate=recording.rate, axes=np.array(recording.axes),
                                units=recording.units)
