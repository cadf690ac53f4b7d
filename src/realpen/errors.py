"""The one exception type that the command line turns into a one-line message and exit code 2."""


class RealPenError(Exception):
    """A problem with the user's input (a file, a parameter) that can be said in one line.

    The message names the file or the parameter and the problem, e.g.
    ``"take1.wav: file is empty"``. Programming errors are never wrapped in it.
    """


def fail(source: object, problem: str) -> RealPenError:
    """Build a :class:`RealPenError` that reads ``"<source>: <problem>"``."""
    return RealPenError(f"{source}: {problem}")


def require_number(option: str, value: float, minimum: float | None = None,
                   maximum: float | None = None, inclusive: bool = True) -> None:
    """Raise a one-line :class:`RealPenError` unless ``value`` is finite and within bounds.

    ``minimum`` is inclusive unless ``inclusive`` is false; ``maximum`` is always inclusive.
    """
    import math

    if not isinstance(value, (int, float)) or not math.isfinite(value):
        raise RealPenError(f"{option} must be a finite number, got {value}")
    if minimum is not None and (value < minimum or (not inclusive and value == minimum)):
        relation = ">=" if inclusive else ">"
        raise RealPenError(f"{option} must be {relation} {minimum:g}, got {value:g}")
    if maximum is not None and value > maximum:
        raise RealPenError(f"{option} must be <= {maximum:g}, got {value:g}")
