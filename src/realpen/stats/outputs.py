"""Write a report folder: ``results.csv``, the tables, the figures (PNG, SVG) and ``report.html``.

The folder appears whole or not at all: everything is written into a new folder beside it,
which then takes the target's name (an existing target, allowed by the caller, is moved aside
first and removed only once the new one is in place). Only a folder a report made (it holds
:data:`MARKER`) or an empty one is ever replaced, so ``--force`` cannot remove someone's files.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from pathlib import Path

import pandas as pd

from realpen.errors import fail
from realpen.io.files import current_umask
from realpen.stats.outcome import StudyAnalysis
from realpen.stats.results import completed

__all__ = ["write_report_folder", "check_report_folder", "TABLE_FILES", "MARKER"]

MARKER = ".realpen-report"
"""The file every report folder holds: only a folder with it (or an empty one) is replaced."""

TABLE_FILES = ("results.csv", "cells.csv", "participants.csv", "confusion.csv", "paper.csv")
"""The CSV files of a report folder (``power.csv`` too when there is a power table)."""


def _write_csv(frame: pd.DataFrame, path: Path) -> None:
    # repr-exact floats: a reader comparing with another tool must not meet our rounding
    frame.to_csv(path, index=False, float_format="%.10g", lineterminator="\n")


def check_report_folder(folder: str | os.PathLike, *, replace: bool) -> Path:
    """Refuse, before any work, a report folder that could not be written or must not be
    replaced.

    Args:
        folder: the report folder to write.
        replace: an existing report folder may be replaced (``--force``).

    Raises:
        RealPenError: one line naming the folder: it is a file, it exists (without
            ``replace``), it is a folder that no report made (it holds other files), it holds
            the current folder, or its parent is missing or not writable.
    """
    target = Path(folder)
    here = Path.cwd().resolve()
    resolved = target.resolve()
    if resolved == here or resolved in here.parents:
        raise fail(target, "holds the current folder; name a new folder for the report")
    if target.is_symlink() or (target.exists() and not target.is_dir()):
        raise fail(target, "is not a folder; name a folder for the report")
    if target.exists():
        if not replace:
            raise fail(target, "exists; it is replaced only when that is asked for")
        contents = list(target.iterdir())
        if contents and not (target / MARKER).is_file():
            raise fail(target, f"is a folder no report made (it has no {MARKER}); it is never "
                               f"replaced: name a new folder")
    parent = resolved.parent
    if not parent.is_dir():
        raise fail(target, f"its parent folder {parent} does not exist")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise fail(target, f"its parent folder {parent} is not writable")
    return target


def write_report_folder(analysis: StudyAnalysis, folder: str | os.PathLike) -> list[Path]:
    """Write every output of ``analysis`` into ``folder`` (created, or replaced whole).

    Returns:
        the paths written, as they are after the folder took its name.
    """
    from realpen.stats.figure_plan import save_study_figures
    from realpen.stats.report import write_report

    target = check_report_folder(folder, replace=True)
    staging = Path(tempfile.mkdtemp(prefix=f".{target.name}.", dir=target.parent))
    try:
        (staging / MARKER).write_text("A RealPen report folder (realpen stats): it may be "
                                      "replaced whole by the next report written here.\n")
        # completed: rows an analysis did not make through with_context get their sentence too
        _write_csv(completed(analysis.results), staging / "results.csv")
        _write_csv(analysis.cells, staging / "cells.csv")
        _write_csv(analysis.participants, staging / "participants.csv")
        _write_csv(analysis.confusion, staging / "confusion.csv")
        _write_csv(analysis.paper, staging / "paper.csv")
        if analysis.power is not None:
            _write_csv(analysis.power, staging / "power.csv")
        figures = save_study_figures(analysis, staging)
        write_report(analysis, staging, figures)
        staging.chmod(0o777 & ~current_umask())
        names = sorted(path.name for path in staging.iterdir())
        _swap(staging, target)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
    return [target / name for name in names]


def _swap(staging: Path, target: Path) -> None:
    if not target.exists() and not target.is_symlink():
        os.replace(staging, target)
        return
    aside = Path(tempfile.mkdtemp(prefix=f".{target.name}.old.", dir=target.parent))
    aside.rmdir()
    os.replace(target, aside)
    try:
        os.replace(staging, target)
    except BaseException:
        os.replace(aside, target)
        raise
    if aside.is_dir() and not aside.is_symlink():
        shutil.rmtree(aside, ignore_errors=True)
    else:
        aside.unlink()
