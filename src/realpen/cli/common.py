"""Shared pieces of the command line: progress bars and console output."""

from __future__ import annotations

import contextlib
from typing import Iterator

from rich.console import Console
from rich.progress import BarColumn, Progress, TaskProgressColumn, TextColumn, TimeRemainingColumn

# Markup off: paths, tool names and descriptions are the user's text, not rich markup.
console = Console(soft_wrap=True, markup=False, highlight=False)
err_console = Console(stderr=True, markup=False, highlight=False)

PROGRESS_AFTER_S = 5.0  # recordings longer than this get a progress bar


@contextlib.contextmanager
def progress_bar(label: str, enabled: bool = True) -> Iterator:
    """Yield a ``progress(done, total)`` callback that drives a rich progress bar on stderr.

    With ``enabled`` false the callback does nothing (short jobs need no bar).
    """
    if not enabled or not err_console.is_terminal:  # a bar is for people, not for logs
        yield None
        return
    columns = (TextColumn("{task.description}"), BarColumn(), TaskProgressColumn(),
               TimeRemainingColumn())
    with Progress(*columns, console=err_console, transient=True) as progress:
        task = progress.add_task(label, total=None)

        def update(done: int, total: int) -> None:
            progress.update(task, completed=done, total=total)

        yield update
