"""RealPen's two exception types; the command line turns either into one line and exit code 2.

- :class:`RealPenError` — bad *data*: a file or a recording that cannot be used. The message
  names the source and the problem, e.g. ``"take1.wav: file is empty"``.
- :class:`ParameterError` — a bad *argument* to a library function. The message names the
  Python parameter, e.g. ``"unit_ms: must be > 0, got -1"``; the command line maps parameter
  names to its flags in one place (:mod:`realpen.cli.flags`). It is also a :class:`ValueError`,
  so code that catches ``ValueError`` keeps working.

Programming errors are never wrapped in either.
"""

from __future__ import annotations

import math

__all__ = ["RealPenError", "ParameterError", "fail", "require_number", "require_choice"]


class RealPenError(Exception):
    """A problem with the user's input (a file, a recording) that can be said in one line."""


class ParameterError(RealPenError, ValueError):
    """A bad argument, worded with the Python parameter's name.

    Attributes:
        parameter: the parameter's Python name (``"unit_ms"``).
        problem: what is wrong with it, without the name (``"must be > 0, got -1"``).
    """

    def __init__(self, parameter: str, problem: str):
        super().__init__(f"{parameter}: {problem}")
        self.parameter = parameter
        self.problem = problem


def fail(source: object, problem: str) -> RealPenError:
    """Build a :class:`RealPenError` that reads ``"<source>: <problem>"``."""
    return RealPenError(f"{source}: {problem}")


def require_number(parameter: str, value: float, minimum: float | None = None,
                   maximum: float | None = None, inclusive: bool = True) -> None:
    """Raise a :class:`ParameterError` unless ``value`` is a finite number within bounds.

    ``minimum`` is inclusive unless ``inclusive`` is false; ``maximum`` is always inclusive.
    Booleans are refused (``True`` is not a count).

    >>> require_number("top", 0, minimum=1)
    Traceback (most recent call last):
    ...
    realpen.errors.ParameterError: top: must be >= 1, got 0
    """
    if isinstance(value, bool) or not isinstance(value, (int, float)) or \
            (isinstance(value, float) and not math.isfinite(value)):
        raise ParameterError(parameter, f"must be a finite number, got {_shown(value)}")
    if minimum is not None and (value < minimum or (not inclusive and value == minimum)):
        relation = ">=" if inclusive else ">"
        raise ParameterError(parameter, f"must be {relation} {minimum:g}, got {_shown(value)}")
    if maximum is not None and value > maximum:
        raise ParameterError(parameter, f"must be <= {maximum:g}, got {_shown(value)}")


def _shown(value: object) -> str:
    """A value for a message: floats as ``:g``, integers exactly; an integer of more than 30
    digits (too large for a float, or for ``str`` past 4300 digits) by its size."""
    if isinstance(value, int) and not isinstance(value, bool):
        if abs(value) < 10**30:
            return str(value)
        digits = math.floor(value.bit_length() * math.log10(2)) + 1
        return f"an integer of about {digits} digits"
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        return f"{value:g}"
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def require_choice(parameter: str, value: object, choices: tuple[str, ...]) -> None:
    """Raise a :class:`ParameterError` unless ``value`` is one of ``choices``."""
    if value not in choices:
        raise ParameterError(parameter, f"unknown value {value!r} (choose from {', '.join(choices)})")
