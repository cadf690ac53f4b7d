"""The limits RealPen enforces on what it reads, stated in one place.

Every reader checks its input against these *before* any large allocation, and refuses what
exceeds them with one line naming the file and the limit. They are far above anything a real pen
recording, profile or trajectory needs, and low enough that no input — a forged header, a zip or
NPZ bomb, a deeply nested JSON document — can make a call allocate more than a few GB.

The JSON reader here (:func:`load_json`) is the one every RealPen JSON input goes through
(profile.json, coupling files): it bounds the document's size, nesting depth and the number of
digits of any number, and refuses ``NaN``/``Infinity``.
"""

from __future__ import annotations

import json
import os
import re
from pathlib import Path

from realpen.errors import fail

__all__ = ["MIN_RATE_HZ", "MAX_RATE_HZ", "MAX_CHANNELS", "MAX_FRAMES", "MAX_JSON_BYTES", "MAX_JSON_DEPTH", "MAX_NUMBER_CHARS", "MAX_CSV_FIELD_CHARS",
           "load_json", "json_depth"]

MIN_RATE_HZ = 100
"""The lowest sampling rate (Hz) of a signal read or written: an accelerometer for a pen runs at
1 kHz or more; a header that says 1 Hz is damaged."""
MAX_RATE_HZ = 400_000
"""The highest sampling rate (Hz) of a signal read or written (384 kHz is audio's highest)."""
MAX_CHANNELS = 32
"""The most channels a recording may have (a pen's accelerometer has 3, a microphone 1–2)."""
MAX_FRAMES = 2**27
"""The most samples a signal may hold, over all its channels (134 M: 1 GiB as float64; 27 h of
a 1.344 kHz accelerometer, 46 min of 48 kHz sound)."""
MAX_JSON_BYTES = 4 * 1024 * 1024
"""The largest JSON document read (bytes): a profile.json is a few kB."""
MAX_JSON_DEPTH = 32
"""The deepest nesting of arrays and objects in a JSON document read."""
MAX_NUMBER_CHARS = 64
"""The longest number (characters) in a JSON document; 17 significant digits are all a float
holds, and Python's int() on thousands of digits is quadratic."""
MAX_CSV_FIELD_CHARS = 1024
"""The longest CSV field read (characters); a number needs under 30."""

# Strings are removed before brackets are counted: a "[" inside a string is not nesting.
_JSON_STRING = re.compile(rb'"(?:[^"\\]|\\.)*"', re.DOTALL)
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


def load_json(source: bytes | str | os.PathLike, what: object | None = None):
    """Parse a JSON document within the limits above.

    Args:
        source: the document's bytes, or a path to read it from.
        what: how to name the document in errors (default: the path, or ``"JSON"``).

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
        try:
            size = path.stat().st_size
            if size > MAX_JSON_BYTES:
                raise fail(name, f"is {size:,} bytes; JSON documents are limited to "
                                 f"{MAX_JSON_BYTES:,}")
            data = path.read_bytes()
        except OSError as error:
            raise fail(name, f"cannot read ({error.strerror or error})") from None
    if len(data) > MAX_JSON_BYTES:
        raise fail(name, f"is {len(data):,} bytes; JSON documents are limited to "
                         f"{MAX_JSON_BYTES:,}")
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
        return json.loads(text, parse_constant=_refuse_constant)
    except ValueError as error:  # JSONDecodeError, and NaN/Infinity refused above
        raise fail(name, f"is not valid JSON ({error})") from None
