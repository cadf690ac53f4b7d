"""Option values read without pydantic, so that a small command starts fast.

Recent typer releases (0.29 here) read every option value through a pydantic ``TypeAdapter``:
importing pydantic and building the adapters costs about 0.17 s of CPU per command, three times
the analysis of a minute of recording by ``realpen analyze``. The values our commands take are plain
(``str``, ``int``, ``float``, ``bool``, :class:`pathlib.Path` and lists of them), so
:class:`FastCoercionGroup` reads the unremarkable ones itself: a decimal integer, a decimal
number, any text, a path. Everything else — a value out of range, ``1_000``, ``0x10``,
``inf``, an error — goes to typer's own reading, which gives its usual value or message:
what a user sees never depends on which path read the value (``tests/test_startup_imports.py``
checks the two agree).

The reader plugs into three private names of typer (``_TyperParameter``,
``build_runtime_param``, ``coerce_cli_path``); where a typer release lacks them, every value
goes through typer as before, only slower.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any, get_args, get_origin

try:  # recent typer releases carry their own copy of click
    from typer.core import TyperGroup
except ImportError:  # pragma: no cover - every supported typer has it
    from typer.main import TyperGroup

__all__ = ["FastCoercionGroup", "install_fast_coercion"]

# Forms whose value Python and pydantic read alike; other spellings go to typer.
_INTEGER = re.compile(r"-?(?:0|[1-9][0-9]{0,17})")
_DECIMAL = re.compile(r"-?(?:0|[1-9][0-9]{0,15})(?:\.[0-9]{1,15})?(?:[eE][-+]?[0-9]{1,2})?")
_EXACT_INT_AS_FLOAT = 2**53  # a larger int default is left to typer


class _Unsure(Exception):
    """The fast reading does not vouch for this value: typer reads it."""


def _typer_hooks():
    """typer's runtime parameter class, its full reader and its path check (None: this typer
    release has no pydantic readers, or names them otherwise)."""
    try:
        from typer._coercion import build_runtime_param
        from typer._param_types import coerce_cli_path
        from typer.core import _TyperParameter
    except ImportError:
        return None
    return _TyperParameter, build_runtime_param, coerce_cli_path


def _within(number, info) -> bool:
    return ((info.min is None or number >= info.min)
            and (info.max is None or number <= info.max))


def _read_scalar(annotation, info, value, param, ctx, coerce_cli_path):
    """``value`` as ``annotation``, exactly as typer would read it; :class:`_Unsure` else."""
    kind = type(value)
    if (annotation is str and kind is str) or (annotation is bool and kind is bool):
        return value
    if annotation is int:
        if kind is str and _INTEGER.fullmatch(value):
            number = int(value)
        elif kind is int:
            number = value
        else:
            raise _Unsure
        if _within(number, info):
            return number
        raise _Unsure
    if annotation is float:
        if kind is str and _DECIMAL.fullmatch(value):
            number = float(value)
        elif kind is float or (kind is int and abs(value) <= _EXACT_INT_AS_FLOAT):
            number = float(value)
        else:
            raise _Unsure
        if _within(number, info):
            return number
        raise _Unsure
    if annotation is Path and kind in (str, type(Path())):
        # typer's own checks (existence, readability) run on the path, as after pydantic's.
        return coerce_cli_path(Path(value), info, path_type=Path, param=param, ctx=ctx)
    raise _Unsure


def _readable(annotation, info) -> bool:
    """Whether the fast reader handles an option of this annotation and settings."""
    if get_origin(annotation) is list:
        (annotation,) = get_args(annotation) or (None,)
    if annotation not in (str, int, float, bool, Path):
        return False
    plain_number = not info.clamp and (annotation in (int, float) or
                                       (info.min is None and info.max is None))
    plain_path = annotation is not Path or info.path_type is None
    return (info.parser is None and getattr(info, "click_type", None) is None
            and plain_number and plain_path)


class _FastParam:
    """A runtime parameter (typer's ``coerce`` interface) that reads plain values itself and
    hands the rest to typer's own, built on first need."""

    def __init__(self, descriptor, build_runtime_param, coerce_cli_path):
        self._descriptor = descriptor
        self._build = build_runtime_param
        self._coerce_cli_path = coerce_cli_path
        self._typer_param = None

    def coerce(self, value: Any, param, ctx) -> Any:
        several = param.multiple or param.nargs == -1
        if value is None:  # as typer: nothing given
            return () if several else None
        try:
            return self._fast(value, several, param, ctx)
        except Exception:  # typer reads it again: its value, or its message
            if self._typer_param is None:
                self._typer_param = self._build(self._descriptor)
            return self._typer_param.coerce(value, param=param, ctx=ctx)

    def _fast(self, value, several: bool, param, ctx):
        annotation, info = self._descriptor.annotation, self._descriptor.parameter_info
        if get_origin(annotation) is list:
            if not several or not isinstance(value, (list, tuple)):
                raise _Unsure
            (item_type,) = get_args(annotation)
            return [_read_scalar(item_type, info, item, param, ctx, self._coerce_cli_path)
                    for item in value]
        if several:
            raise _Unsure
        return _read_scalar(annotation, info, value, param, ctx, self._coerce_cli_path)


def install_fast_coercion(command) -> int:
    """Give every plain option of ``command`` and its subcommands the fast reader (their
    ``-h/--help`` too, made on first use).

    Args:
        command: a click command or group built by typer.

    Returns:
        How many options were given it (0 where this typer release has no pydantic readers).
    """
    hooks = _typer_hooks()
    if hooks is None:
        return 0
    parameter_class, build_runtime_param, coerce_cli_path = hooks

    def make_fast(param) -> bool:
        descriptor = getattr(param, "type_descriptor", None)
        if (isinstance(param, parameter_class) and descriptor is not None
                and getattr(param, "_runtime_param", False) is None
                and descriptor.file_annotation is None
                and _readable(descriptor.annotation, descriptor.parameter_info)):
            param._runtime_param = _FastParam(descriptor, build_runtime_param, coerce_cli_path)
            return True
        return False

    installed = 0
    pending = [command]
    while pending:
        current = pending.pop()
        pending.extend(getattr(current, "commands", {}).values())
        installed += sum(make_fast(param) for param in current.params)
        _fast_help_option(current, make_fast)
    return installed


def _fast_help_option(command, make_fast) -> None:
    """The help option is made (and kept) when a command first parses: read it fast too."""
    made = command.get_help_option

    def get_help_option(ctx):
        option = made(ctx)
        if option is not None:
            make_fast(option)
        return option

    command.get_help_option = get_help_option


class FastCoercionGroup(TyperGroup):
    """The root group: before it runs, its commands' plain options get the fast reader."""

    def main(self, *args, **kwargs):
        try:
            install_fast_coercion(self)
        except (AttributeError, TypeError):  # a typer release built otherwise: typer reads all
            pass
        return super().main(*args, **kwargs)
