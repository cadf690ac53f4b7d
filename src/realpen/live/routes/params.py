"""Integers in URLs: the digits 0–9 and nothing else, within a stated range.

Python's ``int()`` and pydantic's lax mode read ``1_0`` as 10, ``+1``, ``" 1"`` and ``1.0`` as 1,
and digits of other scripts (``١``) as numbers, so a loosely read URL names another session than
the one written. Every integer path and query parameter of the live app is instead of a type
made by :func:`url_int`: only ``[0-9]+`` (leading zeros allowed; no sign, decimal point,
underscore, space or exponent), then the parameter's range. Anything else is refused before the
route runs, with FastAPI's 422 and one line (``path.session_id: Input should be …``), the reply
every invalid request gets (:func:`realpen.live.errors.request_error_reply`).

Ids and numbers that reach a store go up to :data:`~realpen.io.limits.MAX_STORED_INT`
(:data:`STORED_ID`); the largest valid id is a normal id, answered 404 when nothing has it.
"""

from __future__ import annotations

import re
from typing import Annotated, Any

from annotated_types import Ge, Le
from pydantic import BeforeValidator
from pydantic_core import PydanticCustomError

from realpen.io.limits import MAX_STORED_INT

__all__ = ["url_int", "STORED_ID", "STORED_NUMBER"]

_DIGITS = re.compile(r"[0-9]+")


def url_int(minimum: int, maximum: int) -> Any:
    """The type of an integer URL parameter from ``minimum`` to ``maximum`` (both included).

    Use it as the parameter's annotation (``session_id: STORED_ID``, or
    ``limit: url_int(1, 1000) = 200`` for a query parameter with a default).

    Args:
        minimum: the smallest value accepted (≥ 0: a sign is never accepted).
        maximum: the largest value accepted.

    Returns:
        An ``Annotated[int, …]`` type for FastAPI.

    >>> from pydantic import TypeAdapter, ValidationError
    >>> page = TypeAdapter(url_int(1, 1000))
    >>> page.validate_python("007")
    7
    >>> for text in ("1_0", "1.0", "+1", " 1", "1001"):
    ...     try:
    ...         page.validate_python(text)
    ...     except ValidationError as error:
    ...         print(error.errors()[0]["type"])
    int_digits
    int_digits
    int_digits
    int_digits
    less_than_equal
    """
    if not 0 <= minimum <= maximum:
        raise ValueError(f"url_int: need 0 <= minimum <= maximum, got {minimum}, {maximum}")
    longest = len(str(maximum))

    def digits_only(value: object) -> object:
        if not isinstance(value, str):  # a default, or a caller's own int: the range decides
            return value
        if _DIGITS.fullmatch(value) is None:
            raise PydanticCustomError(
                "int_digits", "Input should be a whole number in the digits 0-9 only (no sign, "
                              "decimal point, underscore or space)")
        significant = value.lstrip("0")
        if len(significant) > longest:  # refused before int(): a URL may hold thousands of digits
            raise PydanticCustomError("less_than_equal",
                                      "Input should be less than or equal to {le}",
                                      {"le": maximum})
        return int(significant or "0")

    # annotated_types' bounds, not Field(): FastAPI adds its own Field (with the alias) to a
    # query parameter, and pydantic warns about a second one inside Annotated.
    return Annotated[int, BeforeValidator(digits_only), Ge(minimum), Le(maximum)]


STORED_ID = url_int(1, MAX_STORED_INT)
"""An id of the store in a URL (a study session, a trial's number): 1 to 2,147,483,647."""
STORED_NUMBER = url_int(0, MAX_STORED_INT)
"""A number from 0 that a store could hold (e.g. a grid point's index): 0 to 2,147,483,647."""
