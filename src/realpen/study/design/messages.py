"""The wording of a design's problems: pydantic's errors as the design file's field paths.

A design is validated by pydantic; :func:`problem_line` turns its errors into the one line the
user reads (``blocks[1].trials[0].questions[2]: unknown question 'Q9' (…)``) through the one
formatter of :mod:`realpen.validation`, with :func:`explain` as the design's own wording.

May import: :mod:`realpen.validation` (and pydantic).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any, get_args

from pydantic import BaseModel

from realpen.validation import error_location, problem_text, validation_line

__all__ = ["shown", "field_path", "explain", "problem_line"]


def shown(value: object) -> str:
    """A value as a message quotes it: its ``repr``, cut to 40 characters.

    >>> shown("x" * 50)
    "'xxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxx..."
    """
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


def field_path(loc: Sequence[object]) -> str:
    """A pydantic location as the design file's field path: ``blocks[1].trials[0].questions``
    (list positions in brackets, a mapping's ``[key]`` marker left out, each name on one line
    and cut as :func:`realpen.validation.error_location` cuts it).

    >>> field_path(("blocks", 1, "trials", 0, "questions"))
    'blocks[1].trials[0].questions'
    """
    text = ""
    for part in loc:
        if isinstance(part, int):
            text += f"[{part}]"
        elif part == "[key]":
            continue
        else:
            name = error_location((part,))
            text += f".{name}" if text else name
    return text


def _model_at(root: type[BaseModel], loc: tuple) -> type[BaseModel] | None:
    """The model whose field ``loc`` (from ``root``) ends in (for naming the fields allowed there)."""
    model: Any = root
    for part in loc:
        if isinstance(part, int):
            continue
        if not (isinstance(model, type) and issubclass(model, BaseModel)) or \
                part not in model.model_fields:
            return None
        model = _inner_model(model.model_fields[part].annotation)
    return model if isinstance(model, type) and issubclass(model, BaseModel) else None


def _inner_model(annotation: Any) -> type[BaseModel] | None:
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return annotation
    for argument in get_args(annotation):
        found = _inner_model(argument)
        if found is not None:
            return found
    return None


def explain(error: Mapping[str, Any], root: type[BaseModel]) -> str:
    """One pydantic error of validating ``root`` (a design) as ``path: problem``, worded for
    the person who wrote the file: an unknown field lists the fields allowed there, a pattern
    names the id rule, a wrong type says what is expected and what was given.

    >>> from pydantic import BaseModel
    >>> class Pen(BaseModel):
    ...     id: str
    >>> explain({"loc": ("pens", 2, "colour"), "type": "extra_forbidden", "msg": ""}, Pen)
    'pens[2].colour: unknown field'
    """
    loc = tuple(error["loc"])
    kind = error["type"]
    if kind == "extra_forbidden":
        model = _model_at(root, loc[:-1])
        allowed = f" (allowed here: {', '.join(model.model_fields)})" if model else ""
        return f"{field_path(loc)}: unknown field{allowed}"
    if kind == "missing":
        return f"{field_path(loc)}: missing (required)"
    message = problem_text(error)
    message = message[0].lower() + message[1:] if message else message
    if kind == "string_pattern_mismatch":
        message = "must be an id: a letter or digit, then letters, digits, - _ . (≤ 64)"
    elif kind in ("model_type", "model_attributes_type", "dict_type"):
        message = "must be a mapping (field: value)"
    elif kind == "list_type":
        message = "must be a list"
    if "input" in error and not isinstance(error["input"], (dict, list)):
        message += f", got {shown(error['input'])}"
    if loc and loc[-1] == "[key]":  # a mapping's key: {1: "no"} has the key 1
        loc, message = loc[:-2], f"key {loc[-2]!r}: {message}"
    where = field_path(loc)
    return f"{where}: {message}" if where else message


def problem_line(problems: Sequence[Mapping[str, Any]], root: type[BaseModel]) -> str:
    """The first of pydantic's ``problems`` in validating ``root`` as one line (:func:`explain`),
    with ``" (and N more problems)"`` when there are several.

    An unknown field comes first: a misspelt field is also a missing one, and the unknown name
    says what went wrong.
    """
    ordered = sorted(problems, key=lambda problem: problem["type"] != "extra_forbidden")
    return validation_line(ordered, explain=lambda error: explain(error, root), count_others=True)
