"""The limits RealPen enforces on what it reads, stated in one place.

Every reader checks its input against these *before* any large allocation, and refuses what
exceeds them with one line naming the file and the limit. They are far above anything a real pen
recording, profile or trajectory needs, and low enough that no input — a forged header, a zip or
NPZ bomb, a deeply nested JSON document — can make a call allocate more than a few GB.

The JSON reader here (:func:`load_json`) is the one every RealPen JSON input goes through
(profile.json, coupling files): it bounds the document's size, nesting depth and the number of
digits of any number, and refuses ``NaN``/``Infinity``.

The integer ranges (:data:`MAX_STORED_INT`, :data:`MAX_JSON_INT`) are the one rule for numbers
that every interface shares: the WebSocket schema, the HTTP API and both stores.

The limits of *arguments* (rates, lengths, counts) and the helpers that check them are
:mod:`realpen.checks`; :func:`check_signal` refuses a header's rate by the same
:data:`~realpen.checks.MIN_RATE_HZ` and :data:`~realpen.checks.MAX_RATE_HZ`.
"""

from __future__ import annotations

import json
import numbers
import os
import re
from pathlib import Path

from realpen.checks import MAX_RATE_HZ, MIN_RATE_HZ, count_text, rate_text
from realpen.errors import fail

__all__ = ["MAX_STORED_INT", "MAX_JSON_INT", "MAX_CHANNELS", "MAX_FRAMES", "MAX_STREAM_SAMPLES",
           "MAX_JSON_BYTES",
           "MAX_JSON_DEPTH", "MAX_NUMBER_CHARS", "MAX_CSV_FIELD_CHARS", "MAX_CSV_LINE_CHARS",
           "MAX_CSV_BYTES", "MAX_NPZ_DIRECTORY_BYTES", "MAX_NPZ_ARRAY_BYTES",
           "MAX_SAMPLE_MAGNITUDE", "MAX_XML_BYTES", "MAX_MODEL_ORDER",
           "load_json", "json_depth", "count_values", "read_bounded", "check_size", "check_signal"]

MAX_STORED_INT = 2**31 - 1
"""The largest integer a store holds: 2,147,483,647, PostgreSQL's INTEGER (32-bit signed), the
type of every id, number and count of the store (:mod:`realpen.study.tables`). SQLite holds 64
bits, but the rule is one for both, so that what one store accepts the other accepts too. The
WebSocket schema (stroke and sample numbers, study session and trial), the HTTP API's ids and
bodies, and the stores themselves refuse a larger value as bad data, never as a store failure
to retry."""
MAX_JSON_INT = 2**53
"""The largest integer taken where a number is echoed or counted but never stored (a WebSocket
message's ``seq``, a position in the device's command log): 2**53, the end of the range in
which a JSON number is exact in every reader (a double, so JavaScript's too)."""
MAX_CHANNELS = 32
"""The most channels a recording may have (a pen's accelerometer has 3, a microphone 1–2)."""
MAX_FRAMES = 2**26
"""The most samples a signal may hold, over all its channels (67 M: 512 MiB as float64; 13.9 h
of one 1.344 kHz accelerometer axis, 4.6 h of three, 23 min of 48 kHz mono sound, 11.6 min of
stereo). The analysis holds 50–100 bytes per sample at its peak, so no recording makes it use
more than about 3–6 GB."""
MAX_STREAM_SAMPLES = 2**30
"""The most samples (frames × axes) a streamed recording may hold: 1,073,741,824, i.e. 74 h of a
three-axis 1.344 kHz accelerometer (a day is 348 M) or 6.2 h of 48 kHz mono. Streaming keeps
one block in memory, so this bounds the time a forged header can cost, not memory; an analysis
also refuses more than :data:`realpen.checks.MAX_UNITS` units."""
MAX_JSON_BYTES = 4 * 1024 * 1024
"""The largest JSON document read (bytes): a profile.json is a few kB."""
MAX_JSON_DEPTH = 32
"""The deepest nesting of arrays and objects in a JSON document read."""
MAX_JSON_VALUES = 2**19
"""The most values (objects, arrays, numbers, strings) in a JSON document read: 524,288, more
than the largest pattern RealPen writes holds (:data:`realpen.checks.MAX_COMPONENTS`
components of 8 fields); a profile of the method's is about 1,500."""
MAX_NUMBER_CHARS = 64
"""The longest number (characters) in a JSON document; 17 significant digits are all a float
holds, and Python's int() on thousands of digits is quadratic."""
MAX_CSV_FIELD_CHARS = 1024
"""The longest CSV field read (characters); a number needs under 30."""
MAX_CSV_LINE_CHARS = 65_536
"""The longest CSV line read (characters): hundreds of numeric columns. A longer line is refused
before it is split, so one line never costs more than this; it is also below the ``csv``
module's own field limit (131,072), so every over-long field gets RealPen's message."""
MAX_CSV_BYTES = 256 * 1024 * 1024
"""The largest CSV file read (bytes): about an hour of a 1.344 kHz three-axis recording with a
time column. Longer recordings belong in WAV or NPZ. Values are read into arrays as the file
streams past, and at most :data:`MAX_FRAMES` numbers (row numbers included) are kept."""
MAX_NPZ_DIRECTORY_BYTES = 65_536
"""The largest zip directory of an NPZ file (bytes): a recording's NPZ holds a few arrays, and
``zipfile`` loads the whole directory (about 1 kB of memory an entry) when the file is opened."""
MAX_NPY_HEADER_BYTES = 65_536
"""The longest ``.npy`` header read (bytes) in an NPZ; numpy writes about 128."""
MAX_NPZ_ARRAY_BYTES = 65_536
"""The largest array of an NPZ file other than its samples (bytes, as declared in its header):
``rate``, ``axes`` and ``units`` need a few dozen."""
MAX_SAMPLE_MAGNITUDE = 1e12
"""The largest magnitude of a sample read (in the recording's own units). No unit a recording
comes in gets near it (a 32-bit ADC count stays below 2.2e9); values beyond it are an overflow or
a damaged file, and their squares would overflow the spectra."""
MAX_XML_BYTES = 4 * 1024 * 1024
"""The largest XML file read (bytes): a HaTT model file is about 130 kB. ElementTree keeps about
25 bytes of memory for each byte of dense markup, so this bounds a parse near 100 MB."""
MAX_MODEL_ORDER = 128
"""The highest AR or MA order of a texture model (HaTT's published models go to 20); the
polynomial roots cost the cube of the order."""

# Strings are removed before brackets are counted: a "[" inside a string is not nesting.
# Possessive (*+), and an unterminated string matches too: otherwise every escaped quote of a
# long unterminated string would start a rescan to its end (quadratic time).
_JSON_STRING = re.compile(rb'"(?:[^"\\]|\\.)*+"?', re.DOTALL)
_LONG_NUMBER = re.compile(rb"-?[0-9][0-9.eE+-]{%d,}" % MAX_NUMBER_CHARS)


def json_depth(data: bytes) -> int:
    """The deepest nesting of ``[``/``{`` in a JSON document (0 for a bare value).

    Counted without parsing (strings stripped first), so it is safe on any input.
    """
    depth = deepest = 0
    for char in _JSON_STRING.sub(b'""', data):
        if char in b"[{":
            depth += 1
            deepest = max(deepest, depth)
        elif char in b"]}":
            depth -= 1
    return deepest


def _refuse_constant(name: str):
    raise ValueError(f"{name} is not a number RealPen accepts")


def load_json(source: bytes | str | os.PathLike, what: object | None = None, *,
              max_bytes: int = MAX_JSON_BYTES, max_values: int = MAX_JSON_VALUES):
    """Parse a JSON document within the limits above.

    Args:
        source: the document's bytes, or a path to read it from.
        what: how to name the document in errors (default: the path, or ``"JSON"``).
        max_bytes: the largest document read (bytes; default :data:`MAX_JSON_BYTES`).
        max_values: the most values it may hold (default :data:`MAX_JSON_VALUES`).

    Raises:
        RealPenError: one line naming the document: too large, not UTF-8, not valid JSON,
            nested deeper than :data:`MAX_JSON_DEPTH`, a number longer than
            :data:`MAX_NUMBER_CHARS` characters, or ``NaN``/``Infinity``.
    """
    if isinstance(source, (bytes, bytearray)):
        data, name = bytes(source), what or "JSON"
    else:
        path = Path(source)
        name = what or path
        data = read_bounded(path, max_bytes, "JSON documents", name)
    if len(data) > max_bytes:
        raise fail(name, f"is {len(data):,} bytes; JSON documents are limited to "
                         f"{max_bytes:,}")
    depth = json_depth(data)
    if depth > MAX_JSON_DEPTH:
        raise fail(name, f"is nested {depth} levels deep; the limit is {MAX_JSON_DEPTH}")
    stripped = _JSON_STRING.sub(b'""', data)
    if _LONG_NUMBER.search(stripped):
        raise fail(name, f"holds a number longer than {MAX_NUMBER_CHARS} characters")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as error:
        raise fail(name, f"is not UTF-8 text ({error.reason} at byte {error.start})") from None
    try:
        document = json.loads(text, parse_constant=_refuse_constant)
    except ValueError as error:  # JSONDecodeError, and NaN/Infinity refused above
        raise fail(name, f"is not valid JSON ({error})") from None
    values = count_values(document, max_values)
    if values > max_values:
        # Validating that many values (each a possible error) would take gigabytes.
        raise fail(name, f"holds more than {max_values:,} values; the limit is "
                         f"{max_values:,}")
    try:  # a lone surrogate ("\ud800") parses, but is no text: it cannot be written back
        json.dumps(document, ensure_ascii=False).encode("utf-8")
    except UnicodeEncodeError:
        raise fail(name, "holds text that is not valid Unicode (a lone surrogate escape)") \
            from None
    return document


def count_values(document, limit: int, keys: bool = False) -> int:
    """How many values (objects, arrays, scalars) ``document`` holds, counting up to
    ``limit + 1`` (so a bomb costs no more than the limit); ``keys``: mapping keys count too
    (YAML's may be values of any kind)."""
    count, stack = 0, [document]
    while stack and count <= limit:
        value = stack.pop()
        count += 1
        if isinstance(value, dict):
            if keys:
                stack.extend(value.keys())
            stack.extend(value.values())
        elif isinstance(value, list):
            stack.extend(value)
    return count


def read_bounded(path: str | os.PathLike, limit: int, kind: str, name: object = None) -> bytes:
    """The bytes of the file at ``path``, refused when over ``limit`` bytes (by its size before
    reading, and by what was read: a file may grow meanwhile).

    Args:
        path: the file.
        limit: the most bytes accepted.
        kind: what the file is, for the message (``"design files"``).
        name: how messages name the file (default: ``path``).

    Raises:
        RealPenError: ``"<name>: is N bytes; <kind> are limited to <limit>"``, or a file that
            cannot be read.
    """
    name = path if name is None else name
    try:
        size = Path(path).stat().st_size
        if size > limit:
            raise fail(name, f"is {size:,} bytes; {kind} are limited to {limit:,}")
        data = Path(path).read_bytes()
    except OSError as error:
        raise fail(name, f"cannot read ({error.strerror or error})") from None
    if len(data) > limit:
        raise fail(name, f"is {len(data):,} bytes; {kind} are limited to {limit:,}")
    return data


def check_size(path: str | os.PathLike, limit: int, kind: str) -> int:
    """The size of the file at ``path`` in bytes, refused when over ``limit`` bytes.

    Args:
        path: the file (its existence is the caller's to check first).
        limit: the most bytes accepted.
        kind: what the file is, for the message (``"CSV files"``).

    Raises:
        RealPenError: ``"<path>: is N bytes; <kind> are limited to <limit>"``, or a file that
            cannot be read.
    """
    try:
        size = Path(path).stat().st_size
    except OSError as error:
        raise fail(path, f"cannot read ({error.strerror or error})") from None
    if size > limit:
        raise fail(path, f"is {size:,} bytes; {kind} are limited to {limit:,}")
    return size




def check_signal(source: object, rate: float | None, frames: int, channels: int) -> None:
    """Refuse a signal whose header is out of the limits, before its samples are read.

    Args:
        source: names the file in messages.
        rate: sampling rate in Hz, between :data:`MIN_RATE_HZ` and :data:`MAX_RATE_HZ` (None:
            not known yet, not checked).
        frames: frames the file declares (samples per channel).
        channels: channels it declares, 1 to :data:`MAX_CHANNELS`; ``frames × channels`` may
            not exceed :data:`MAX_FRAMES`.

    Raises:
        RealPenError: one line naming ``source`` and the limit.
    """
    # NaN and infinity fail the comparison; an integer compares exactly, however large.
    if rate is not None and not (isinstance(rate, numbers.Real)
                                 and MIN_RATE_HZ <= rate <= MAX_RATE_HZ):
        raise fail(source, f"sampling rate {rate_text(rate)} Hz is outside the "
                           f"{MIN_RATE_HZ:,}–{MAX_RATE_HZ:,} Hz RealPen reads (a damaged header?)")
    if not 1 <= channels <= MAX_CHANNELS:
        raise fail(source, f"has {count_text(channels)} channels; recordings are limited to "
                           f"1–{MAX_CHANNELS}")
    if frames * channels > MAX_FRAMES:
        raise fail(source, f"holds {count_text(frames)} frames × {channels} channel(s); "
                           f"recordings are limited to {MAX_FRAMES:,} samples in all")
