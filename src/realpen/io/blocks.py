"""Recordings read in blocks, so that memory does not grow with their length.

:func:`open_stream` opens a WAV/FLAC/OGG, CSV or NPZ recording and returns a
:class:`RecordingStream`: its rate, axes and (when the file says) frames, the blocks of samples
in order (:meth:`RecordingStream.iter_blocks`, float64 arrays of shape (frames, axes)) and any
stretch of it (:meth:`RecordingStream.read`). What each format does:

- **Audio** (soundfile): read a block at a time; :meth:`~RecordingStream.read` seeks. A WAV
  whose data chunk is shorter than its header says is refused when opened, any other file that
  ends before the frames its header promises when the stream reaches the end.
- **NPZ**: the samples member of an uncompressed archive (``np.savez``) is memory-mapped at its
  data offset (after the zip entry's local header and the ``.npy`` header); pages already read
  are given back to the system, so resident memory stays at one block whatever the length. A
  deflated member (``np.savez_compressed``, :func:`realpen.io.recording.save_npz`) is inflated
  as it streams through :mod:`zipfile`, never read whole; :meth:`~RecordingStream.read` then
  inflates from the start of the member up to the stretch (seeking in deflate data is not
  possible), which costs time, not memory.
- **CSV**: the same rules and messages as :func:`realpen.io.csvtable.read_csv` (a header row,
  a sniffed delimiter, decimal commas, blank lines, every value a finite number, the limits of
  :mod:`realpen.io.limits`), converted a chunk of rows at a time. A time column (``t``, ``time``
  or ``timestamp``, in s) gives the rate from the median step of the first
  :data:`CSV_RATE_ROWS` rows (the in-memory loader takes the median over the whole file);
  steps must be positive and no gap wider than ``GAP_FACTOR`` steps, as in memory. Evenly
  sampled rows (every step within 1 % of the rate's) are taken as they are; from the first
  chunk whose steps jitter more, the rows are interpolated onto the even grid by a cubic spline
  over that chunk and the end of the one before (the in-memory loader fits one spline to the
  whole file; the two agree to far below a sample's precision away from the first jittered
  row). :meth:`~RecordingStream.read` reads a CSV again from its start.

Every block is checked as :func:`realpen.io.recording.load_recording` checks a whole recording
(NaN, infinity, values beyond ``MAX_SAMPLE_MAGNITUDE``), naming the file and the frame. The
in-memory limit on samples (``MAX_FRAMES``) does not apply: a streamed recording may hold up to
:data:`MAX_STREAM_SAMPLES` samples, checked from the header before anything is read where the
header says (audio, NPZ) and as the rows arrive otherwise (CSV, itself limited to
``MAX_CSV_BYTES``).
"""

from __future__ import annotations

import math
import mmap
import os
import struct
import zipfile
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import soundfile as sf

from realpen.checks import MAX_RATE_HZ, MIN_RATE_HZ, count_text, require_rate
from realpen.errors import ParameterError, fail
from realpen.io import csvtable
from realpen.io.files import check_readable_file
from realpen.io.limits import (
    MAX_CSV_BYTES,
    MAX_SAMPLE_MAGNITUDE,
    MAX_STREAM_SAMPLES,
    check_signal,
    check_size,
)
from realpen.io.recording import (
    GAP_FACTOR,
    JITTER_TOLERANCE,
    NPZ_ERRORS,
    NPZ_METADATA,
    TIME_PATTERN,
    audio_rate_units,
    axis_names,
    check_npz_method,
    npz_metadata,
    open_npz,
    read_exactly,
    read_npy_header,
    read_npz_array,
    wav_missing_bytes,
)
from realpen.io.timegrid import gap_refusal

__all__ = ["RecordingStream", "ArrayStream", "open_stream", "MAX_STREAM_SAMPLES",
           "DEFAULT_BLOCK_FRAMES", "CSV_RATE_ROWS"]


DEFAULT_BLOCK_FRAMES = 1 << 16
"""Frames per block when the caller does not say (1.5 MiB for three axes)."""

CSV_RATE_ROWS = 1 << 16
"""Rows of a CSV whose time steps give the rate (their median step)."""

_SPLINE_ROWS = 16  # rows a spline reaches past the grid points it places (jittered CSV)


class RecordingStream:
    """A recording read in blocks. Open one with :func:`open_stream`.

    Nothing is held open between calls: each pass opens the file, and closes it when done.

    Attributes:
        source: the file (or a description of an array).
        rate: sampling rate in Hz.
        axes: one name per column.
        units: physical unit of the samples (``"full scale"`` for audio).
        frames: frames per axis, when known: from the header for audio and NPZ, after a whole
            pass for CSV (None until then).
        frames_hint: frames expected (``frames`` when known; for a CSV, its rows counted from
            its line breaks): for progress bars and first allocations, never for results.
        peak: the largest magnitude of any sample (recording unit), once a pass of
            :meth:`iter_blocks` has reached the end (None until then).
    """

    source: str
    rate: float
    axes: tuple[str, ...]
    units: str
    frames: int | None
    frames_hint: int
    peak: float | None = None

    @property
    def duration_hint(self) -> float:
        """``frames_hint`` in seconds."""
        return self.frames_hint / self.rate

    def __repr__(self) -> str:
        frames = f"{self.frames} frames" if self.frames is not None else \
            f"about {self.frames_hint} frames"
        return (f"{type(self).__name__}({','.join(self.axes)}, {frames} at {self.rate:g} Hz, "
                f"from {Path(self.source).name})")

    def iter_blocks(self, block_frames: int = DEFAULT_BLOCK_FRAMES) -> Iterator[np.ndarray]:
        """The samples in order, as float64 arrays of shape (frames, axes).

        Every block but the last holds ``block_frames`` frames, except a CSV's, whose blocks
        follow its rows. Each call starts again from the beginning.

        Raises:
            ParameterError: ``block_frames`` is not a whole number ≥ 1.
            RealPenError: a damaged or truncated file, a bad value (NaN, infinity, beyond
                ``MAX_SAMPLE_MAGNITUDE``, naming its frame), more than
                :data:`MAX_STREAM_SAMPLES` samples, or no samples at all.
        """
        block_frames = _whole("block_frames", block_frames)
        done, peak = 0, 0.0
        for raw in self._blocks(block_frames):
            block = np.asarray(raw, dtype=np.float64)
            if block.ndim == 1:
                block = block[:, None]
            if not len(block):
                continue
            peak = max(peak, _check_values(self.source, block, done))
            done += len(block)
            if done * len(self.axes) > MAX_STREAM_SAMPLES:
                raise fail(self.source, f"holds more than {MAX_STREAM_SAMPLES:,} samples; "
                                        f"streamed recordings are limited to that many")
            yield block
        if done == 0:
            raise fail(self.source, "holds no samples")
        if self.frames is not None and done < self.frames:
            raise fail(self.source, f"truncated: header promises {self.frames} frames, file "
                                    f"holds {done}")
        self.frames = self.frames_hint = done
        self.peak = peak

    def read(self, start: int, stop: int) -> np.ndarray:
        """Frames ``start`` to ``stop`` (exclusive), float64 of shape (stop - start, axes).

        Raises:
            ParameterError: ``start`` or ``stop`` outside the recording, or ``stop <= start``.
            RealPenError: as :meth:`iter_blocks`.
        """
        start, stop = _whole("start", start, 0), _whole("stop", stop)
        if stop <= start:
            raise ParameterError("stop", f"must be above start ({start}), got {stop}")
        if self.frames is not None and stop > self.frames:
            raise ParameterError("stop", f"{self.source} holds {self.frames} frames, got {stop}")
        data = np.asarray(self._read(start, stop), dtype=np.float64)
        if data.ndim == 1:
            data = data[:, None]
        if len(data) < stop - start:
            if self.frames is None:
                raise ParameterError("stop", f"{self.source} holds {start + len(data)} frames, "
                                             f"got {stop}")
            raise fail(self.source, f"truncated: header promises {self.frames} frames, file "
                                    f"holds {start + len(data)}")
        _check_values(self.source, data, start)
        return data

    def _blocks(self, block_frames: int) -> Iterator[np.ndarray]:
        raise NotImplementedError

    def _read(self, start: int, stop: int) -> np.ndarray:
        # Formats without seeking read up to the stretch and keep only it.
        parts, position = [], 0
        for block in self.iter_blocks(max(DEFAULT_BLOCK_FRAMES, min(stop - start, 1 << 20))):
            end = position + len(block)
            if end > start:
                parts.append(block[max(0, start - position):stop - position])
            position = end
            if position >= stop:
                break
        return np.concatenate(parts) if parts else np.empty((0, len(self.axes)))


def _whole(parameter: str, value: int, minimum: int = 1) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < minimum:
        raise ParameterError(parameter, f"must be a whole number >= {minimum}, got {value!r}")
    return int(value)


def _check_values(source: object, block: np.ndarray, first_frame: int) -> float:
    """The block's largest magnitude, after refusing NaN, infinity or a magnitude beyond
    ``MAX_SAMPLE_MAGNITUDE``, naming the frame (counted from the start of the recording),
    worded as the in-memory loader words it."""
    peak = max(float(np.max(block)), -float(np.min(block)))  # NaN propagates
    if math.isfinite(peak) and peak <= MAX_SAMPLE_MAGNITUDE:
        return peak
    bad = ~np.isfinite(block)
    if bad.any():
        frame = first_frame + int(np.argwhere(bad)[0][0])
        raise fail(source, f"contains NaN or infinite values (first at frame {frame})")
    frame, axis = (int(i) for i in np.argwhere(np.abs(block) > MAX_SAMPLE_MAGNITUDE)[0])
    raise fail(source, f"holds the value {block[frame, axis]:.3g} at frame {first_frame + frame}; "
                       f"samples beyond ±{MAX_SAMPLE_MAGNITUDE:g} are not a measurement in any "
                       f"unit (an overflow or a damaged file)")


def _check_samples(source: object, frames: int, channels: int) -> None:
    """Refuse a declared length over :data:`MAX_STREAM_SAMPLES` before anything is read."""
    if frames * channels > MAX_STREAM_SAMPLES:
        raise fail(source, f"holds {count_text(frames)} frames × {channels} channel(s); "
                           f"streamed recordings are limited to {MAX_STREAM_SAMPLES:,} samples "
                           f"in all")


def open_stream(path: str | os.PathLike, rate: float | None = None,
                units: str | None = None) -> RecordingStream:
    """Open a WAV/FLAC/OGG, CSV or NPZ recording to read in blocks (see the module doc).

    Args:
        path: the file; the suffix picks the reader (``.csv``, ``.npz``; anything else is read
            as audio by soundfile), as :func:`realpen.io.recording.load_recording` does.
        rate: sampling rate in Hz for a CSV with no time column or an NPZ with no ``rate``
            (always checked: ``MIN_RATE_HZ`` to ``MAX_RATE_HZ``).
        units: override the unit of the samples.

    Returns:
        A :class:`RecordingStream`. Only the header (and, for a CSV, the rows that give its
        rate) is read here.

    Raises:
        RealPenError: a missing, empty, damaged or truncated file, or one over a limit, named.
        ParameterError: ``rate`` out of range, or needed and not given.

    Example:
        >>> from realpen.examples import example_recording_path
        >>> stream = open_stream(example_recording_path())
        >>> stream.rate, stream.axes, stream.frames
        (1344.0, ('x', 'y', 'z'), 16128)
        >>> sum(len(block) for block in stream.iter_blocks(5000))
        16128
    """
    path = Path(path)
    check_readable_file(path)
    if rate is not None:
        require_rate("rate", rate)
    suffix = path.suffix.lower()
    if suffix == ".csv":
        stream: RecordingStream = _CsvStream(path, rate)
    elif suffix == ".npz":
        stream = _NpzStream(path, rate)
    else:
        stream = _AudioStream(path)
    if units is not None:
        stream.units = units
    return stream


class ArrayStream(RecordingStream):
    """An array in memory seen as a stream (for the same analysis as a file's).

    Args:
        samples: shape (frames,) or (frames, axes); converted to float64.
        rate: its rate in Hz.
        axes: names of the columns (default x, y, z for up to three).
        source: how messages name it.
    """

    def __init__(self, samples: np.ndarray, rate: float, axes: tuple[str, ...] | None = None,
                 source: str = "array", units: str = "arbitrary"):
        data = np.asarray(samples, dtype=np.float64)
        self.samples = data[:, None] if data.ndim == 1 else data
        if self.samples.ndim != 2:
            raise ParameterError("samples", f"must have shape (frames,) or (frames, axes), "
                                            f"got {data.shape}")
        self.rate = float(rate)
        self.axes = tuple(axes) if axes is not None else axis_names(self.samples.shape[1])
        if len(self.axes) != self.samples.shape[1]:
            raise ParameterError("axes", f"names {len(self.axes)} axes for "
                                         f"{self.samples.shape[1]} columns")
        self.source, self.units = source, units
        self.frames = self.frames_hint = len(self.samples)

    def _blocks(self, block_frames: int) -> Iterator[np.ndarray]:
        for start in range(0, len(self.samples), block_frames):
            yield self.samples[start:start + block_frames]

    def _read(self, start: int, stop: int) -> np.ndarray:
        return self.samples[start:stop]


# --- audio -----------------------------------------------------------------------------------

_AUDIO_ERRORS = (sf.LibsndfileError, RuntimeError, TypeError, ValueError)


class _AudioStream(RecordingStream):
    def __init__(self, path: Path):
        self.source = str(path)
        self.path = path
        try:
            with sf.SoundFile(path) as handle:
                rate, frames, channels = handle.samplerate, handle.frames, handle.channels
                exact_rate, units = audio_rate_units(handle)  # a capture's rate is not whole
        except _AUDIO_ERRORS as error:
            raise self._unreadable(error) from None
        check_signal(path, rate, 0, channels)  # rate and channels; the length is ours
        _check_samples(path, frames, channels)
        missing = wav_missing_bytes(path)
        if missing:
            raise fail(path, f"truncated: the WAV data chunk is {missing} bytes shorter than its "
                             f"header says")
        self.rate, self.axes, self.units = exact_rate, axis_names(channels), units
        self.frames = self.frames_hint = frames

    def _unreadable(self, error: Exception):
        return fail(self.path, f"not a readable audio file ({str(error).splitlines()[0]})")

    def _blocks(self, block_frames: int) -> Iterator[np.ndarray]:
        try:
            with sf.SoundFile(self.path) as handle:
                while True:
                    block = _read_audio(handle, block_frames)
                    if not len(block):
                        return
                    yield block
        except _AUDIO_ERRORS as error:
            raise self._unreadable(error) from None

    def _read(self, start: int, stop: int) -> np.ndarray:
        try:
            with sf.SoundFile(self.path) as handle:
                handle.seek(start)
                return _read_audio(handle, stop - start)
        except _AUDIO_ERRORS as error:
            raise self._unreadable(error) from None


def _read_audio(handle: sf.SoundFile, frames: int) -> np.ndarray:
    """Up to ``frames`` frames as float64 in full scale, as soundfile reads them.

    16-bit samples are read as integers and scaled here: libsndfile's own conversion to float64
    takes three times as long, and its result is the same to the bit (it divides by 2¹⁵ too,
    which is exact).
    """
    if handle.subtype == "PCM_16":
        codes = handle.read(frames, dtype="int16", always_2d=True)
        return np.multiply(codes, 1.0 / 32768, dtype=np.float64)
    return handle.read(frames, dtype="float64", always_2d=True)


# --- NPZ -------------------------------------------------------------------------------------

_LOCAL_HEADER = struct.Struct("<4s22xHH")  # signature ... file name length, extra field length


class _NpzStream(RecordingStream):
    """The samples member of an NPZ, memory-mapped when stored, inflated in order when
    deflated; metadata and checks as :func:`realpen.io.recording.load_recording`."""

    def __init__(self, path: Path, rate: float | None):
        self.source, self.path = str(path), path
        try:
            with open_npz(path) as (archive, members, key):
                self.info, self.key = members[key], key
                self._layout(archive)
                contents = {name: read_npz_array(path, archive, members[name], name)
                            for name in NPZ_METADATA if name in members}
        except NPZ_ERRORS as error:
            raise fail(path, f"not a readable NPZ archive ({error})") from None
        frames, channels = self.shape
        # Frames are checked against the streaming limit (_layout), not the in-memory one.
        self.rate, self.axes, self.units = npz_metadata(path, contents, rate, 0, channels)
        self.frames = self.frames_hint = frames
        if frames == 0:
            raise fail(path, "holds no samples")

    def _layout(self, archive: zipfile.ZipFile) -> None:
        """The samples' .npy header, checked as the in-memory reader checks it, and where
        their data starts (in the member, and in the file when the member is stored)."""
        path, info, key = self.path, self.info, self.key
        check_npz_method(path, info, key)
        with archive.open(info) as handle:
            shape, fortran, dtype = read_npy_header(handle, path, key)
            data_start = handle.tell()  # in the member: magic, header length, header
        if dtype.hasobject or dtype.fields is not None or dtype.subdtype is not None or \
                dtype.kind not in "iuf" or dtype.itemsize == 0:
            raise fail(path, f"'{key}' must hold real numbers, not {dtype}")
        if len(shape) not in (1, 2):
            raise fail(path, f"'{key}' must be 1-D or 2-D, got {len(shape)}-D")
        if any(size < 0 for size in shape):
            raise fail(path, f"'{key}' declares an impossible shape (a negative size)")
        frames, channels = shape[0], shape[1] if len(shape) == 2 else 1
        check_signal(path, None, 0, channels)
        _check_samples(path, frames, channels)
        self.shape, self.dtype = (frames, channels), dtype
        # Fortran order keeps each axis together: it is read axis by axis, side by side.
        self.fortran = bool(fortran) and channels > 1
        self.data_start = data_start
        nbytes = frames * channels * dtype.itemsize
        if info.file_size < self.data_start + nbytes:
            raise fail(path, f"'{key}' is truncated: its header declares more data than the "
                             f"archive holds")
        self.offset = None
        if info.compress_type == zipfile.ZIP_STORED:
            with open(path, "rb") as raw:
                raw.seek(info.header_offset)
                signature, name_length, extra_length = _LOCAL_HEADER.unpack(
                    read_exactly(raw, _LOCAL_HEADER.size, path, key))
                if signature != b"PK\x03\x04":
                    raise zipfile.BadZipFile(f"bad local header of '{info.filename}'")
            self.offset = (info.header_offset + _LOCAL_HEADER.size + name_length + extra_length
                           + self.data_start)
            if self.offset + nbytes > path.stat().st_size:
                raise fail(path, f"'{key}' is truncated: its header declares more data than "
                                 f"the archive holds")

    def _column_spans(self, start: int, stop: int) -> list[tuple[int, int]]:
        """Byte ranges (from the samples' first byte) of frames [start, stop): one range in C
        order, one per axis in Fortran order."""
        frames, channels = self.shape
        size = self.dtype.itemsize
        if not self.fortran:
            return [(start * channels * size, stop * channels * size)]
        return [((axis * frames + start) * size, (axis * frames + stop) * size)
                for axis in range(channels)]

    def _assemble(self, parts: list[bytes | memoryview], count: int) -> np.ndarray:
        channels = self.shape[1]
        if not self.fortran:
            return np.frombuffer(parts[0], dtype=self.dtype).astype(np.float64).reshape(
                count, channels)
        out = np.empty((count, channels))
        for axis, part in enumerate(parts):
            out[:, axis] = np.frombuffer(part, dtype=self.dtype)
        return out

    def _blocks(self, block_frames: int) -> Iterator[np.ndarray]:
        frames = self.shape[0]
        try:
            if self.offset is not None:
                yield from self._mapped_blocks(block_frames)
                return
            with zipfile.ZipFile(self.path) as archive:
                handles = [archive.open(self.info) for _ in self._column_spans(0, 1)]
                try:
                    for handle, (first, _) in zip(handles, self._column_spans(0, 1)):
                        handle.seek(self.data_start + first)
                    for start in range(0, frames, block_frames):
                        stop = min(start + block_frames, frames)
                        parts = [read_exactly(handle, last - first, self.path, self.key)
                                 for handle, (first, last) in
                                 zip(handles, self._column_spans(start, stop))]
                        yield self._assemble(parts, stop - start)
                finally:
                    for handle in handles:
                        handle.close()
        except NPZ_ERRORS as error:
            raise fail(self.path, f"not a readable NPZ archive ({error})") from None

    def _mapped_blocks(self, block_frames: int) -> Iterator[np.ndarray]:
        frames = self.shape[0]
        page = mmap.ALLOCATIONGRANULARITY
        base = self.offset - self.offset % page  # a mapping starts on a page boundary
        end = self.offset + frames * self.shape[1] * self.dtype.itemsize
        with open(self.path, "rb") as raw, \
                mmap.mmap(raw.fileno(), end - base, access=mmap.ACCESS_READ, offset=base) as view:
            skip = self.offset - base
            # Per axis, the page up to which the pages have been given back (a page that is
            # needed again, as where two axes meet in Fortran order, is read in again).
            released = [(skip + first) // page * page for first, _ in self._column_spans(0, 1)]
            for start in range(0, frames, block_frames):
                stop = min(start + block_frames, frames)
                spans = self._column_spans(start, stop)
                buffer = memoryview(view)
                try:
                    block = self._assemble([buffer[skip + a:skip + b] for a, b in spans],
                                           stop - start)
                finally:
                    buffer.release()
                # Pages already converted go back to the system: a mapped file's pages count
                # as resident memory for as long as they stay mapped in.
                if hasattr(view, "madvise"):
                    for index, (_, last) in enumerate(spans):
                        done = (skip + last) // page * page
                        if done > released[index]:
                            view.madvise(mmap.MADV_DONTNEED, released[index],
                                         done - released[index])
                            released[index] = done
                yield block

    def _read(self, start: int, stop: int) -> np.ndarray:
        spans = self._column_spans(start, stop)
        try:
            if self.offset is not None:
                with open(self.path, "rb") as raw:
                    parts = []
                    for first, last in spans:
                        raw.seek(self.offset + first)
                        parts.append(read_exactly(raw, last - first, self.path, self.key))
                return self._assemble(parts, stop - start)
            with zipfile.ZipFile(self.path) as archive, archive.open(self.info) as handle:
                parts = []
                for first, last in spans:  # ascending: each seek moves forward
                    handle.seek(self.data_start + first)
                    parts.append(read_exactly(handle, last - first, self.path, self.key))
                return self._assemble(parts, stop - start)
        except NPZ_ERRORS as error:
            raise fail(self.path, f"not a readable NPZ archive ({error})") from None


# --- CSV -------------------------------------------------------------------------------------

class _CsvStream(RecordingStream):
    """A recording CSV (a header row, numeric columns, an optional time column in s)."""

    def __init__(self, path: Path, rate: float | None):
        self.source, self.path = str(path), path
        check_size(path, MAX_CSV_BYTES, "CSV files")
        self.frames = None
        self.frames_hint = max(1, csvtable.line_breaks(path))
        rows = self._rows()
        names = next(rows)
        self.time_index = next((i for i, name in enumerate(names) if TIME_PATTERN.match(name)),
                               None)
        self.units = "arbitrary"
        if self.time_index is None:
            if rate is None:
                raise ParameterError("rate", f"needed in Hz: {path} is a CSV with no time column "
                                             f"(t, time or timestamp)")
            self.rate, self.step = float(rate), 1.0 / rate
        else:
            self.time_name = names[self.time_index]
            first = next(rows, None)
            times = first[:, self.time_index] if first is not None else np.empty(0)
            self.step = self._rate_step(times)
            self.rate = 1.0 / self.step
        rows.close()
        self.axes = tuple(name for i, name in enumerate(names) if i != self.time_index)
        if not self.axes:
            raise fail(path, "CSV has no signal columns")

    def _rows(self, block_rows: int = CSV_RATE_ROWS) -> Iterator:
        """The header's names, then the values as float64 arrays of ``block_rows`` rows."""
        path = self.path
        try:
            with open(path, encoding="utf-8-sig") as handle:
                rows, delimiter = csvtable.numbered_rows(path, handle)
                first_line, names = next(rows)
                if all(csvtable.is_number(cell, delimiter != ",") for cell in names):
                    raise fail(path, f"line {first_line}: CSV needs a header row naming its "
                                     f"columns (the first row is numbers)")
                yield tuple(names)
                width = len(names)
                pending: list[tuple[int, list[str]]] = []
                for line_no, row in rows:
                    if len(row) != width:
                        raise fail(path, f"line {line_no}: {len(row)} values for the {width} "
                                         f"columns of the header")
                    pending.append((line_no, row))
                    if len(pending) >= block_rows:
                        yield self._values(pending, names, delimiter)
                        pending = []
                if pending:
                    yield self._values(pending, names, delimiter)
        except UnicodeDecodeError:
            raise fail(path, "not a text CSV file") from None
        except OSError as error:
            raise fail(path, f"cannot read ({error.strerror or error})") from None

    def _values(self, pending: list, names, delimiter: str) -> np.ndarray:
        values = np.empty((len(pending), len(names)))
        for index, name in enumerate(names):
            values[:, index], _ = csvtable.column_numbers(
                self.path, [cells[index] for _, cells in pending], pending, name, delimiter, "")
        return values

    def _rate_step(self, times: np.ndarray) -> float:
        """The sampling step (s) from the first rows' times, checked as in memory."""
        steps = np.diff(times)
        if len(steps) == 0 or not np.all(steps > 0):
            raise fail(self.path, f"time column '{self.time_name}' is not strictly increasing")
        step = float(np.median(steps))
        rate = 1.0 / step
        if not MIN_RATE_HZ <= rate <= MAX_RATE_HZ:
            raise fail(self.path, f"time column '{self.time_name}' gives a sampling rate of "
                                  f"{rate:.4g} Hz, outside the {MIN_RATE_HZ:,}–{MAX_RATE_HZ:,} Hz "
                                  f"RealPen reads (are the times in seconds?)")
        return step

    def _blocks(self, block_frames: int) -> Iterator[np.ndarray]:
        rows = self._rows(block_frames)
        next(rows)  # the header, read when the stream was opened
        if self.time_index is None:
            yield from rows
            return
        grid = _EvenGrid(self.path, self.time_name, self.step)
        for values in rows:
            times = values[:, self.time_index]
            signal = np.delete(values, self.time_index, axis=1)
            yield grid.place(times, signal)
        yield grid.finish()


class _EvenGrid:
    """Rows of a time column placed on an even grid, a chunk at a time (see the module doc)."""

    def __init__(self, path: Path, name: str, step: float):
        self.path, self.name, self.step = path, name, step
        self.last_time: float | None = None
        self.even = True
        self.next_time = 0.0  # the time of the next grid point, once interpolating
        self.tail_t = np.empty(0)
        self.tail_x: np.ndarray | None = None

    def place(self, times: np.ndarray, values: np.ndarray) -> np.ndarray:
        """The rows of one chunk on the grid (the rows themselves while every step is even)."""
        if self.last_time is None:
            self.next_time = float(times[0])
        joined = times if self.last_time is None else np.concatenate([[self.last_time], times])
        steps = np.diff(joined)
        if len(steps) and not np.all(steps > 0):
            raise fail(self.path, f"time column '{self.name}' is not strictly increasing")
        if len(steps):
            widest = int(np.argmax(steps))
            if steps[widest] > GAP_FACTOR * self.step:
                raise gap_refusal(self.path, self.name, steps[widest], joined[widest], self.step)
        if self.even and np.all(np.abs(steps - self.step) <= JITTER_TOLERANCE * self.step):
            self._keep(times, values)
            self.next_time = times[-1] + self.step
            return values
        self.even = False
        all_t = np.concatenate([self.tail_t, times])
        all_x = values if self.tail_x is None else np.concatenate([self.tail_x, values])
        # Grid points well inside the spline's rows now; the last few wait for the next chunk,
        # where they are inside too.
        limit = all_t[-_SPLINE_ROWS] if len(all_t) > 2 * _SPLINE_ROWS else None
        placed = self._interpolate(all_t, all_x, limit)
        self._keep(all_t, all_x)
        return placed

    def finish(self) -> np.ndarray:
        """Grid points left for the end of the last chunk."""
        if self.even or self.tail_x is None:
            return np.empty((0, 0 if self.tail_x is None else self.tail_x.shape[1]))
        return self._interpolate(self.tail_t, self.tail_x, None)

    def _interpolate(self, all_t: np.ndarray, all_x: np.ndarray, limit: float | None
                     ) -> np.ndarray:
        end = all_t[-1] if limit is None else limit
        count = int(np.floor((end - self.next_time) / self.step + 1e-9)) + 1
        if count <= 0 or len(all_t) < 2:
            return np.empty((0, all_x.shape[1]))
        grid = self.next_time + np.arange(count) * self.step
        self.next_time = grid[-1] + self.step
        # Here, not at the top: only a jittered CSV needs it, and scipy.interpolate is heavy.
        from scipy.interpolate import CubicSpline

        return CubicSpline(all_t, all_x, axis=0)(grid)

    def _keep(self, times: np.ndarray, values: np.ndarray) -> None:
        self.last_time = float(times[-1])
        self.tail_t = times[-2 * _SPLINE_ROWS:].copy()
        self.tail_x = values[-2 * _SPLINE_ROWS:].copy()
