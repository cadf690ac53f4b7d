"""Atomic file output: write to a temporary file beside the target, then rename.

A failed or interrupted run therefore never leaves a half-written output behind.
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import json
import os
import tempfile
from pathlib import Path
from typing import Iterator

import numpy as np
import soundfile as sf
from scipy.io import wavfile

from realpen.errors import fail


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


def wav_bytes(samples: np.ndarray, rate: int) -> bytes:
    """A 32-bit float WAV of ``samples`` (frames, or frames × channels) at ``rate`` Hz, as bytes.

    Written by scipy rather than libsndfile, whose float WAVs carry a time-stamped PEAK chunk:
    the same samples must always give the same bytes (bundles are checked by SHA-256).
    """
    buffer = io.BytesIO()
    wavfile.write(buffer, int(rate), np.asarray(samples, dtype=np.float32))
    return buffer.getvalue()


def write_wav(target: str | os.PathLike, samples: np.ndarray, rate: int,
              subtype: str = "FLOAT") -> None:
    """Write ``samples`` (frames, or frames × channels; full scale ±1) at ``rate`` Hz atomically.

    ``subtype`` is a soundfile subtype; the default 32-bit float keeps the samples exactly and
    gives identical bytes for identical samples.
    """
    with atomic_path(target) as tmp:
        if subtype == "FLOAT":
            tmp.write_bytes(wav_bytes(samples, rate))
        else:
            sf.write(tmp, np.asarray(samples, dtype=np.float32), int(rate), subtype=subtype,
                     format="WAV")


def sha256_of(path: str | os.PathLike) -> str:
    """SHA-256 hex digest of a file's bytes."""
    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()
