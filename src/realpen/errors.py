"""RealPen's two exception types; the command line turns either into one line and exit code 2.

- :class:`RealPenError` — bad *data*: a file or a recording that cannot be used. The message
  names the source and the problem, e.g. ``"take1.wav: file is empty"``.
- :class:`ParameterError` — a bad *argument* to a library function. The message names the
  Python parameter, e.g. ``"unit_ms: must be > 0, got -1"``; the command line maps parameter
  names to its flags in one place (:mod:`realpen.cli.flags`). It is also a :class:`ValueError`,
  so code that catches ``ValueError`` keeps working.

Programming errors are never wrapped in either. The range checks that raise
:class:`ParameterError` live in :mod:`realpen.checks`.

May import: the standard library only.
"""

from __future__ import annotations

__all__ = ["RealPenError", "ParameterError", "fail"]


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
