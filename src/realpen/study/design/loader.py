"""Reading a design: the built-in designs, YAML and JSON files, each bounded and checked.

:func:`load_design` reads a built-in design by name (``study1``, ``study2``) or a ``.yaml``,
``.yml`` or ``.json`` file — bounded in bytes and in values (YAML aliases included), YAML read
safely with duplicate keys refused and numbers of at most
:data:`~realpen.io.limits.MAX_NUMBER_CHARS` characters, as in JSON (Python will not turn a
5,000-digit integer into text, and its arithmetic on such numbers is slow) — and validates it
(:func:`realpen.study.design.schema.validate_design`).

May import: :mod:`realpen.errors`, :mod:`realpen.io`, the other modules of
:mod:`realpen.study.design` (and PyYAML, when a YAML file is read).
"""

from __future__ import annotations

import os
from importlib.resources import files
from pathlib import Path
from typing import Any

from realpen.errors import ParameterError, fail
from realpen.io.limits import (
    MAX_NUMBER_CHARS,
    check_size,
    count_values,
    load_json,
    read_bounded,
)
from realpen.study.design.constants import MAX_DESIGN_BYTES, MAX_DESIGN_VALUES
from realpen.study.design.messages import field_path
from realpen.study.design.schema import Design, validate_design

__all__ = ["builtin_designs", "builtin_path", "load_design"]

_BUILTIN = ("study1", "study2")
_NUMBER_TAGS = ("tag:yaml.org,2002:int", "tag:yaml.org,2002:float")


def builtin_designs() -> list[str]:
    """The names of the built-in designs (``["study1", "study2"]``)."""
    return list(_BUILTIN)


def builtin_path(name: str) -> Path:
    """The file of built-in design ``name``.

    Raises:
        ParameterError: not a built-in design.
    """
    if name not in _BUILTIN:
        raise ParameterError("design", f"unknown built-in design {name!r} (choose from "
                                       f"{', '.join(_BUILTIN)})")
    return Path(str(files("realpen.study") / "designs" / f"{name}.yaml"))


def load_design(source: str | os.PathLike) -> Design:
    """Read a design: a built-in name (``"study1"``, ``"study2"``) or a ``.yaml``/``.yml``/
    ``.json`` file.

    Raises:
        RealPenError: one line naming the file, the field path and the problem: a YAML or
            JSON syntax error (with its line), an unknown field, a wrong type, an unknown or
            duplicate id, likert anchors outside the scale, an unplannable structure, …
    """
    if isinstance(source, str) and source in _BUILTIN:
        path = builtin_path(source)
    else:
        path = Path(source)
    suffix = path.suffix.lower()
    if isinstance(source, str) and not suffix and os.sep not in source and "/" not in source \
            and not path.exists():
        raise fail(source, f"unknown design: give a built-in design ({', '.join(_BUILTIN)}) or "
                           f"a .yaml, .yml or .json file")
    if suffix not in (".yaml", ".yml", ".json"):
        raise fail(path, f"is not a design: give a .yaml, .yml or .json file, or a built-in "
                         f"design ({', '.join(_BUILTIN)})")
    if not path.is_file():
        raise fail(path, "no such design file" if not path.exists() else "is not a file")
    if suffix == ".json":
        check_size(path, MAX_DESIGN_BYTES, "design files")
        document = load_json(path)
    else:
        document = _load_yaml(path)
    if count_values(document, MAX_DESIGN_VALUES, keys=True) > MAX_DESIGN_VALUES:
        raise fail(path, f"holds more than {MAX_DESIGN_VALUES:,} values (YAML aliases "
                         f"included); the limit is {MAX_DESIGN_VALUES:,}")
    return validate_design(document, path)


def _load_yaml(path: Path) -> Any:
    import yaml  # only when a YAML design is read

    data = read_bounded(path, MAX_DESIGN_BYTES, "design files")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as error:
        raise fail(path, f"is not UTF-8 text ({error.reason} at byte {error.start})") from None
    loader = _loader()(text)
    try:
        # Composed, checked, then built: a number is refused before Python converts it.
        root = loader.get_single_node()
        if root is None:
            return None
        long_number = _long_number(root)
        if long_number is not None:
            loc, node = long_number
            what = "a key that is a number" if loc and loc[-1] == "[key]" else "a number"
            where = field_path(loc)
            raise fail(path, f"{where + ': ' if where else ''}{what} of {len(node.value):,} "
                             f"characters (line {node.start_mark.line + 1}); numbers are "
                             f"limited to {MAX_NUMBER_CHARS}")
        return loader.construct_document(root)
    except yaml.MarkedYAMLError as error:
        mark = error.problem_mark or error.context_mark
        where = f"line {mark.line + 1}, column {mark.column + 1}: " if mark else ""
        problem = " ".join(str(error.problem or error.context or "invalid YAML").split())
        if error.problem and error.context and error.context_mark:
            problem += (f" ({error.context} at line {error.context_mark.line + 1}, column "
                        f"{error.context_mark.column + 1})")
        kind = "YAML" if isinstance(error, yaml.constructor.ConstructorError) else \
            "YAML syntax error at"
        raise fail(path, f"{kind} {where}{problem}") from None
    except yaml.YAMLError as error:
        raise fail(path, f"YAML syntax error: {' '.join(str(error).split())}") from None
    except RecursionError:
        raise fail(path, "is nested too deeply") from None
    finally:
        loader.dispose()


def _long_number(root) -> tuple[tuple, Any] | None:
    """The first number (in document order) written with more than :data:`MAX_NUMBER_CHARS`
    characters, as (its location, its node), or None. A mapping's key has the location of its
    value with ``"[key]"`` in place of the key's name. Each node is seen once, however many
    aliases name it."""
    import yaml

    seen: set[int] = set()
    stack = [(root, ())]
    while stack:
        node, loc = stack.pop()
        if id(node) in seen:
            continue
        seen.add(id(node))
        if isinstance(node, yaml.ScalarNode):
            if node.tag in _NUMBER_TAGS and len(node.value) > MAX_NUMBER_CHARS:
                return loc, node
        elif isinstance(node, yaml.SequenceNode):
            stack.extend((item, (*loc, i)) for i, item in reversed(list(enumerate(node.value))))
        elif isinstance(node, yaml.MappingNode):
            for key, value in reversed(node.value):
                name = key.value if isinstance(key, yaml.ScalarNode) else "?"
                stack.append((value, (*loc, name)))
                stack.append((key, (*loc, "[key]")))
    return None


_LOADER = None


def _loader():
    """A safe YAML loader (the C one when PyYAML has it) that refuses duplicate keys."""
    global _LOADER
    if _LOADER is None:
        import yaml

        base = getattr(yaml, "CSafeLoader", yaml.SafeLoader)

        class DesignLoader(base):  # type: ignore[misc, valid-type]
            def construct_mapping(self, node, deep=False):
                seen = set()
                for key_node, _ in node.value:
                    key = self.construct_object(key_node, deep=deep)
                    try:
                        duplicate = key in seen
                    except TypeError:  # an unhashable key: the base class says so
                        break
                    if duplicate:
                        raise yaml.constructor.ConstructorError(
                            None, None, f"duplicate key {key!r}", key_node.start_mark)
                    seen.add(key)
                return super().construct_mapping(node, deep=deep)

        _LOADER = DesignLoader
    return _LOADER
