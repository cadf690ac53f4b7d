"""One line from a pydantic validation error: the one formatter every layer uses.

A profile, a study design, a WebSocket message and an HTTP request body are all checked by
pydantic; each problem reaches the user as ``where: what`` on one line. The wording of *what*
may be refined by the caller (a design explains an unknown field by listing the allowed ones),
but the location, the one-lining, the cut of long texts and the "(and N more)" tail are made
here, once.

May import: the standard library only (pydantic's errors arrive as plain dicts), so that the
lightest modules can use it.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping, Sequence
from typing import Any

__all__ = ["one_line", "error_location", "problem_text", "validation_line"]

#: Parts of a location that say nothing to a user (pydantic's wrappers).
_SILENT_PARTS = frozenset({"__root__"})


def one_line(text: object, limit: int = 200) -> str:
    """``text`` on one line (runs of whitespace made one space), cut to ``limit`` characters.

    Messages quote the user's own text, which may hold newlines or run to megabytes.

    >>> one_line("a\\n  b")
    'a b'
    >>> one_line("x" * 10, limit=5)
    'xxxx…'
    """
    line = " ".join(str(text).split())
    return line if len(line) <= limit else line[:limit - 1] + "…"


def error_location(loc: Iterable[object], part_limit: int = 40) -> str:
    """A pydantic location as a dotted path (``pens.0.profile``); each part on one line and cut
    to ``part_limit`` characters (a location can hold the document's own keys).

    >>> error_location(("body", "answers", "Q1"))
    'body.answers.Q1'
    """
    return ".".join(one_line(part, part_limit) for part in loc if part not in _SILENT_PARTS)


def problem_text(error: Mapping[str, Any]) -> str:
    """A pydantic error's message without pydantic's ``"Value error, "`` prefix, on one line.

    >>> problem_text({"msg": "Value error, must be > 0"})
    'must be > 0'
    """
    return one_line(str(error.get("msg", "invalid")).removeprefix("Value error, "))


def validation_line(errors: Sequence[Mapping[str, Any]] | Any, *,
                    explain: Callable[[Mapping[str, Any]], str] | None = None,
                    count_others: bool = False, default: str = "invalid") -> str:
    """The first problem of a validation error as ``where: what`` on one line.

    Args:
        errors: a :class:`pydantic.ValidationError` (or FastAPI's ``RequestValidationError``),
            or the list its ``errors()`` gives.
        explain: turns one error into the whole line (``where: what``) when a caller words
            problems itself; the default joins :func:`error_location` and :func:`problem_text`.
        count_others: add ``" (and N more problems)"`` when there are several.
        default: the line when there is no problem listed at all.

    Returns:
        One line; never a traceback, never the offending input in full.

    >>> validation_line([{"loc": ("a", 0), "msg": "Value error, too big"}])
    'a.0: too big'
    >>> validation_line([{"loc": (), "msg": "x"}, {"loc": ("b",), "msg": "y"}], count_others=True)
    'x (and 1 more problem)'
    """
    if hasattr(errors, "errors"):
        try:
            # Without inputs and context: each error's copy of its input could take gigabytes.
            errors = errors.errors(include_url=False, include_input=False, include_context=False)
        except TypeError:  # FastAPI's RequestValidationError.errors() takes no arguments
            errors = errors.errors()
    problems = list(errors)
    if not problems:
        return default
    first = problems[0]
    if explain is not None:
        line = explain(first)
    else:
        where = error_location(first.get("loc", ()))
        message = problem_text(first)
        line = f"{where}: {message}" if where else message
    others = len(problems) - 1
    if count_others and others:
        line += f" (and {others} more problem{'s' if others > 1 else ''})"
    return line
