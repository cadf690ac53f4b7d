"""The one exception type that the command line turns into a one-line message and exit code 2."""


class RealPenError(Exception):
    """A problem with the user's input (a file, a parameter) that can be said in one line.

    The message names the file or the parameter and the problem, e.g.
    ``"take1.wav: file is empty"``. Programming errors are never wrapped in it.
    """


def fail(source: object, problem: str) -> RealPenError:
    """Build a :class:`RealPenError` that reads ``"<source>: <problem>"``."""
    return RealPenError(f"{source}: {problem}")
