"""Atomic file output (write to a temporary file beside the target, then rename), WAV bytes,
and the loop a WAV file carries in its ``smpl`` chunk.

A failed or interrupted run therefore never leaves a half-written output behind.

Loops in WAV files. The RIFF ``smpl`` (sampler) chunk is where samplers, audio editors and
game engines look for a WAV's loop points. :func:`add_smpl_loop` adds one forward loop to WAV
bytes; :func:`read_smpl_loop` finds the first loop of a file. The chunk written is: manufacturer
0, product 0, sample period in ns (10⁹ / rate, rounded), MIDI unity note 60, pitch fraction 0,
no SMPTE offset, one loop and no sampler data; the loop: cue point id 0, type 0 (forward),
start and end in sample frames (end inclusive: the last frame played before the wrap),
fraction 0, play count 0 (forever).

soundfile and scipy are imported when first needed, so light modules (the WebSocket schema's
neighbours, the help of the ``realpen`` command) do not load them.
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import json
import os
import struct
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import BinaryIO

import numpy as np

from realpen.errors import ParameterError, fail

__all__ = ["atomic_path", "json_text", "check_readable_file", "current_umask", "write_files",
           "write_json", "wav_bytes", "write_wav", "sha256_of", "add_smpl_loop",
           "read_smpl_loop", "riff_chunks", "SMPL_UNITY_NOTE"]

SMPL_UNITY_NOTE = 60  # MIDI note at which the sample plays at its own rate (middle C)
_SMPL_HEADER = struct.Struct("<9I")   # manufacturer … sampler data size: 36 bytes
_SMPL_LOOP = struct.Struct("<6I")     # cue id, type, start, end, fraction, play count: 24 bytes


@contextlib.contextmanager
def atomic_path(target: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path in the target's folder; rename it onto ``target`` on success.

    The temporary file keeps the target's suffix so that format sniffing by suffix still
    works. On any exception the temporary file is removed and the target is left untouched.
    """
    target = Path(target)
    if target.is_dir():
        raise fail(target, "is a folder; give a file name to write")
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp_name = tempfile.mkstemp(prefix=f".{target.name}.", suffix=f".tmp{target.suffix}",
                                        dir=target.parent)
    except OSError as error:
        raise fail(target, f"cannot write here ({error.strerror or error})") from None
    os.close(fd)
    tmp = Path(tmp_name)
    try:
        yield tmp
        os.chmod(tmp, 0o666 & ~current_umask())  # mkstemp makes 0600; outputs are ordinary files
        os.replace(tmp, target)
    except OSError as error:
        raise fail(target, f"cannot write ({error.strerror or error})") from None
    finally:
        if tmp.exists():
            tmp.unlink()


def json_text(data: object, source: object = "JSON") -> str:
    """Indented JSON text of ``data``; NaN or infinity becomes a one-line error, not bad JSON."""
    try:
        return json.dumps(data, indent=2, allow_nan=False) + "\n"
    except ValueError:
        raise fail(source, "result holds NaN or infinite numbers; check the parameters") from None


def check_readable_file(path: str | os.PathLike) -> None:
    """Raise a one-line :class:`RealPenError` unless ``path`` is an existing, non-empty file."""
    path = Path(path)
    if not path.exists():
        raise fail(path, "no such file")
    if path.is_dir():
        raise fail(path, "is a folder, not a file")
    if path.stat().st_size == 0:
        raise fail(path, "file is empty")


def current_umask() -> int:
    """The process's file-creation mask."""
    mask = os.umask(0)
    os.umask(mask)
    return mask


def write_files(files: dict[str | os.PathLike, bytes]) -> None:
    """Write several outputs all-or-nothing: every file is staged first, then all are renamed.

    If any file cannot be staged, none of the targets is touched.
    """
    with contextlib.ExitStack() as stack:
        staged = [(stack.enter_context(atomic_path(target)), data) for target, data in files.items()]
        for tmp, data in staged:
            try:
                tmp.write_bytes(data)
            except OSError as error:
                raise fail(tmp, f"cannot write ({error.strerror or error})") from None


def write_json(target: str | os.PathLike, data: object) -> None:
    """Write ``data`` as indented UTF-8 JSON to ``target`` atomically."""
    text = json_text(data, target)
    with atomic_path(target) as tmp:
        tmp.write_text(text, encoding="utf-8")


def wav_bytes(samples: np.ndarray, rate: int, *, loop: bool = False) -> bytes:
    """A 32-bit float WAV of ``samples`` (frames, or frames × channels) at ``rate`` Hz, as bytes.

    Written by scipy rather than libsndfile, whose float WAVs carry a time-stamped PEAK chunk:
    the same samples must always give the same bytes (bundles are checked by SHA-256).

    Args:
        samples: full scale ±1.
        rate: sample rate in Hz.
        loop: add a ``smpl`` chunk declaring the whole file one forward loop
            (:func:`add_smpl_loop`).
    """
    from scipy.io import wavfile

    buffer = io.BytesIO()
    wavfile.write(buffer, int(rate), np.asarray(samples, dtype=np.float32))
    data = buffer.getvalue()
    return add_smpl_loop(data) if loop else data


def write_wav(target: str | os.PathLike, samples: np.ndarray, rate: int,
              subtype: str = "FLOAT", *, loop: bool = False) -> None:
    """Write ``samples`` (frames, or frames × channels; full scale ±1) at ``rate`` Hz atomically.

    ``subtype`` is a soundfile subtype; the default 32-bit float keeps the samples exactly and
    gives identical bytes for identical samples. ``loop`` declares the whole file one forward
    loop in a ``smpl`` chunk (:func:`add_smpl_loop`).
    """
    if subtype == "FLOAT":
        data = wav_bytes(samples, rate, loop=loop)
    else:
        import soundfile as sf

        buffer = io.BytesIO()
        sf.write(buffer, np.asarray(samples, dtype=np.float32), int(rate), subtype=subtype,
                 format="WAV")
        data = add_smpl_loop(buffer.getvalue()) if loop else buffer.getvalue()
    with atomic_path(target) as tmp:
        tmp.write_bytes(data)


def riff_chunks(handle: BinaryIO) -> Iterator[tuple[bytes, int, int]]:
    """(name, offset of the chunk's body, body length) of each chunk of a RIFF/WAVE file.

    Only the chunk headers are read. ``handle`` is a binary file (or :class:`io.BytesIO`) at
    its start; the caller may read a chunk's body before asking for the next chunk. A file that
    is not RIFF/WAVE has no chunks.
    """
    head = handle.read(12)
    if len(head) < 12 or head[:4] != b"RIFF" or head[8:12] != b"WAVE":
        return
    position = 12
    while True:
        handle.seek(position)
        chunk = handle.read(8)
        if len(chunk) < 8:
            return
        name, length = struct.unpack("<4sI", chunk)
        yield name, position + 8, length
        position += 8 + length + (length & 1)


def _chunks(data: bytes, source: object) -> list[tuple[bytes, int, int]]:
    """:func:`riff_chunks` of RIFF/WAVE bytes; :class:`RealPenError` for other bytes."""
    if len(data) < 12 or data[:4] != b"RIFF" or data[8:12] != b"WAVE":
        raise fail(source, "not a RIFF/WAVE file")
    return list(riff_chunks(io.BytesIO(data)))


def add_smpl_loop(wav: bytes, start: int = 0, end: int | None = None) -> bytes:
    """WAV bytes with a ``smpl`` chunk declaring one forward loop (see the module doc).

    Any ``smpl`` chunk already there is replaced; the RIFF size is updated. The same input
    always gives the same bytes.

    Args:
        wav: a RIFF/WAVE file's bytes (PCM or float, any channel count).
        start: first frame of the loop (0: the start of the file).
        end: last frame of the loop, inclusive (None: the last frame of the file).

    Returns:
        The WAV's bytes with the ``smpl`` chunk after its other chunks.

    Raises:
        RealPenError: bytes that are not a WAV with ``fmt`` and ``data`` chunks.
        ParameterError: ``start`` or ``end`` outside the file's frames, or ``end < start``.

    Example:
        >>> data = add_smpl_loop(wav_bytes(np.zeros(480), 48000))
        >>> read_smpl_loop(data)
        (0, 479)
    """
    chunks = list(_chunks(wav, "WAV bytes"))
    fmt = next(((offset, length) for name, offset, length in chunks if name == b"fmt "), None)
    body = next(((offset, length) for name, offset, length in chunks if name == b"data"), None)
    if fmt is None or body is None or fmt[1] < 16:
        raise fail("WAV bytes", "no fmt and data chunks")
    _, channels, rate, _, block_align = struct.unpack_from("<HHIIH", wav, fmt[0])
    frames = min(body[1], len(wav) - body[0]) // max(block_align, 1)
    end = frames - 1 if end is None else end
    for name, value in (("start", start), ("end", end)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) \
                or not 0 <= value < max(frames, 1):
            raise ParameterError(name, f"must be a frame from 0 to {frames - 1}, got {value!r}")
    if end < start:
        raise ParameterError("end", f"must not come before start ({start}), got {end}")
    period_ns = int(round(1e9 / rate)) if rate else 0
    chunk = (_SMPL_HEADER.pack(0, 0, period_ns, SMPL_UNITY_NOTE, 0, 0, 0, 1, 0)
             + _SMPL_LOOP.pack(0, 0, int(start), int(end), 0, 0))
    kept = b"".join(wav[offset - 8:offset + length + (length & 1)]
                    for name, offset, length in chunks if name != b"smpl")
    riff = b"WAVE" + kept + b"smpl" + struct.pack("<I", len(chunk)) + chunk
    return b"RIFF" + struct.pack("<I", len(riff)) + riff


def read_smpl_loop(source: str | os.PathLike | bytes) -> tuple[int, int] | None:
    """The first loop of a WAV's ``smpl`` chunk as (start, end) frames, end inclusive.

    Only the chunk headers are read (a long file is not loaded).

    Args:
        source: a WAV file's path, or its bytes.

    Returns:
        (start, end), or None when the file is not a RIFF/WAVE file, has no ``smpl`` chunk, or
        its chunk declares no loop (or a loop that ends before it starts).

    Raises:
        RealPenError: a path that cannot be read.
    """
    try:
        with (io.BytesIO(bytes(source)) if isinstance(source, (bytes, bytearray))
              else open(source, "rb")) as handle:
            return _first_smpl_loop(handle)
    except OSError as error:
        raise fail(source, f"cannot read ({error.strerror or error})") from None


def _first_smpl_loop(handle: BinaryIO) -> tuple[int, int] | None:
    wanted = _SMPL_HEADER.size + _SMPL_LOOP.size
    for name, _, length in riff_chunks(handle):
        if name == b"smpl" and length >= wanted:
            body = handle.read(wanted)
            if len(body) < wanted:
                return None
            if _SMPL_HEADER.unpack_from(body)[7] < 1:
                return None
            _, _, start, end, _, _ = _SMPL_LOOP.unpack_from(body, _SMPL_HEADER.size)
            return (int(start), int(end)) if end >= start else None
    return None


def sha256_of(path: str | os.PathLike) -> str:
    """SHA-256 hex digest of a file's bytes."""
    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()
