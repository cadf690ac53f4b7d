"""Shared pieces of the command line: console output, progress bars, and the output check."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator, Mapping
from pathlib import Path

import typer
from rich.console import Console

from realpen.errors import RealPenError, fail

__all__ = ["console", "err_console", "PROGRESS_AFTER_S", "progress_bar", "force_option",
           "check_outputs"]

# Markup off: paths, tool names and descriptions are the user's text, not rich markup.
console = Console(soft_wrap=True, markup=False, highlight=False)
err_console = Console(stderr=True, markup=False, highlight=False)

PROGRESS_AFTER_S = 5.0  # recordings longer than this get a progress bar


def force_option(*names: str) -> bool:
    """The typer option that allows replacing existing outputs (``--force``, ``--overwrite``)."""
    return typer.Option(False, *(names or ("--force", "--overwrite")),
                        help="Replace output files that already exist (refused otherwise).")


def check_outputs(*outputs: Path | None, force: bool, force_flag: str = "--force",
                  folders: bool = False, inputs: Mapping[str, Path | None] | None = None) -> None:
    """Refuse outputs that would silently replace something, before any work is done.

    Args:
        outputs: the files the command will write (None: not asked for).
        force: the user passed ``force_flag``: existing files may be replaced.
        force_flag: how the command names that option, for the message.
        folders: an output may be a folder (a profile bundle); otherwise an existing folder
            given as an output is refused, with or without ``force``.
        inputs: files the command reads, by what they are (``{"recording": path}``); an
            output that is one of them is refused, with or without ``force``.

    Raises:
        RealPenError: one line naming the path: ``"<path>: exists; pass --force to replace
            it"``, an output given twice, an output that is an input, or a folder.
    """
    given = [Path(out) for out in outputs if out is not None]
    for index, out in enumerate(given):
        for label, source in (inputs or {}).items():
            if source is not None and out.exists() and out.resolve() == Path(source).resolve():
                raise fail(out, f"would replace the {label} itself; name another file to write")
        if any(out.resolve() == other.resolve() for other in given[:index]):
            raise fail(out, "given for two outputs; name a different file for each")
        if out.is_dir() and not folders:
            raise fail(out, "is a folder; give the file to write")
        if out.exists() and not force:
            raise RealPenError(f"{out}: exists; pass {force_flag} to replace it")


@contextlib.contextmanager
def progress_bar(label: str, enabled: bool = True) -> Iterator:
    """Yield a ``progress(done, total)`` callback that drives a rich progress bar on stderr.

    With ``enabled`` false the callback does nothing (short jobs need no bar).
    """
    if not enabled or not err_console.is_terminal:  # a bar is for people, not for logs
        yield None
        return
    from rich.progress import BarColumn, Progress, TaskProgressColumn, TextColumn, TimeRemainingColumn

    columns = (TextColumn("{task.description}"), BarColumn(), TaskProgressColumn(),
               TimeRemainingColumn())
    with Progress(*columns, console=err_console, transient=True) as progress:
        task = progress.add_task(label, total=None)

        def update(done: int, total: int) -> None:
            progress.update(task, completed=done, total=total)

        yield update
