"""What every format reader shares: the :class:`Playback` it returns and one-line field checks.

Every check raises :class:`~realpen.errors.RealPenError` reading ``"<file>: <where>: <problem>"``,
e.g. ``"pen.ahap: Pattern[3].Event.Time: must be a number ≥ 0, got 'soon'"``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from realpen.errors import RealPenError, fail

__all__ = ["MAX_PLAY_S", "MAX_PARTS", "Playback", "where", "member", "number", "integer",
           "seconds", "text", "array", "problem", "check_parts", "check_play_time"]

MAX_PLAY_S = 3600.0
"""The longest a haptic file read may play, in s: an hour (RealPen's exports hold at most
600 s); times beyond it are refused before anything is built."""
MAX_PARTS = 100_000
"""The most effects, events, breakpoints or steps a haptic file read may hold: as many as the
largest ``.hjif`` RealPen writes (:data:`realpen.exports.hjif.MAX_EFFECTS`); rendering costs
time in proportion to them."""


@dataclass(frozen=True)
class Playback:
    """What a format reader found in a file: how long it plays and how to render it.

    Attributes:
        duration_s: how long a player plays the file once, in s.
        summary: one line saying what the file holds.
        render: ``render(rate)`` → the vibration a player would drive, float64 mono samples
            at ``rate`` Hz over ``duration_s`` (full scale ±1).
        notes: how the file was read where the format leaves a choice (one sentence each).
    """

    duration_s: float
    summary: str
    render: Callable[[int], np.ndarray]
    notes: tuple[str, ...] = ()


def where(parent: str, key: str | int) -> str:
    """The path of a member for messages: ``where("Pattern", 3)`` → ``"Pattern[3]"``."""
    if isinstance(key, int):
        return f"{parent}[{key}]"
    return f"{parent}.{key}" if parent else key


def problem(source: object, at: str, what: str) -> RealPenError:
    """The error for a field: ``"<source>: <at>: <what>"`` (or ``"<source>: <what>"``)."""
    return fail(source, f"{at}: {what}" if at else what)


def _shown(value: object) -> str:
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


def member(obj: object, key: str, source: object, at: str, *, required: bool = True,
           default: object = None) -> object:
    """``obj[key]`` of a JSON object ``obj`` found at ``at``.

    Raises:
        RealPenError: ``obj`` is not an object, or ``key`` is missing and ``required``.
    """
    if not isinstance(obj, dict):
        raise problem(source, at, f"must be an object, got {_shown(obj)}")
    if key not in obj:
        if required:
            raise problem(source, where(at, key), "is missing")
        return default
    return obj[key]


def number(value: object, source: object, at: str, *, low: float | None = None,
           high: float | None = None) -> float:
    """``value`` as a finite float, checked against ``low`` … ``high`` (inclusive).

    Raises:
        RealPenError: not a number (booleans are not), or out of range, naming the range.
    """
    # math.isfinite: np.isfinite refuses Python ints beyond 64 bits, which JSON may hold.
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise problem(source, at, f"must be a number, got {_shown(value)}")
    if (low is not None and value < low) or (high is not None and value > high):
        span = (f"from {low:g} to {high:g}" if low is not None and high is not None
                else f"≥ {low:g}" if low is not None else f"≤ {high:g}")
        raise problem(source, at, f"must be {span}, got {value:g}")
    return float(value)


def integer(value: object, source: object, at: str, *, low: int | None = None,
            high: int | None = None) -> int:
    """``value`` as an int (a JSON number without a fraction), checked against the range.

    Raises:
        RealPenError: not a whole number, or out of range.
    """
    if isinstance(value, bool) or not isinstance(value, (int, float)) \
            or not math.isfinite(value) or int(value) != value:
        raise problem(source, at, f"must be a whole number, got {_shown(value)}")
    number(value, source, at, low=low, high=high)
    return int(value)


def seconds(value: object, source: object, at: str) -> float:
    """A time in s: a number from 0 to :data:`MAX_PLAY_S`.

    Raises:
        RealPenError: not a number, negative, or beyond :data:`MAX_PLAY_S`.
    """
    return number(value, source, at, low=0.0, high=MAX_PLAY_S)


def check_play_time(duration_s: float, source: object) -> float:
    """``duration_s`` if it is at most :data:`MAX_PLAY_S`.

    Raises:
        RealPenError: naming the file and the limit.
    """
    if not duration_s <= MAX_PLAY_S:
        raise problem(source, "", f"plays {duration_s:g} s; RealPen reads haptic files of at "
                                  f"most {MAX_PLAY_S:g} s")
    return duration_s


def check_parts(count: int, what: str, source: object) -> int:
    """``count`` if it is at most :data:`MAX_PARTS`.

    Raises:
        RealPenError: naming the file, what was counted and the limit.
    """
    if count > MAX_PARTS:
        raise problem(source, "", f"holds {count:,} {what}; RealPen reads at most "
                                  f"{MAX_PARTS:,}")
    return count


def text(value: object, source: object, at: str, *, choices: tuple[str, ...] = ()) -> str:
    """``value`` as a string, one of ``choices`` when given.

    Raises:
        RealPenError: not a string, or not one of ``choices``.
    """
    if not isinstance(value, str):
        raise problem(source, at, f"must be text, got {_shown(value)}")
    if choices and value not in choices:
        raise problem(source, at, f"must be one of {', '.join(choices)}, got {_shown(value)}")
    return value


def array(value: object, source: object, at: str, *, min_items: int = 0) -> list:
    """``value`` as a JSON array of at least ``min_items`` items.

    Raises:
        RealPenError: not an array, or too short.
    """
    if not isinstance(value, list):
        raise problem(source, at, f"must be an array, got {_shown(value)}")
    if len(value) < min_items:
        raise problem(source, at, "must not be empty" if min_items == 1
                      else f"must hold at least {min_items} items, got {len(value)}")
    return value
