"""Write a report folder: ``results.csv``, the tables, the figures (PNG, SVG) and ``report.html``.

The folder appears whole or not at all: everything is written into a new folder beside it,
which then takes the target's name (an existing target, allowed by the caller, is moved aside
first and removed only once the new one is in place).
"""

from __future__ import annotations

import os
import shutil
import tempfile
from pathlib import Path

import pandas as pd

from realpen.stats.outcome import StudyAnalysis
from realpen.stats.results import RESULT_COLUMNS

__all__ = ["write_report_folder", "TABLE_FILES"]

TABLE_FILES = ("results.csv", "cells.csv", "participants.csv", "confusion.csv", "paper.csv")
"""The CSV files of a report folder (``power.csv`` too when there is a power table)."""


def _write_csv(frame: pd.DataFrame, path: Path) -> None:
    # repr-exact floats: a reader comparing with another tool must not meet our rounding
    frame.to_csv(path, index=False, float_format="%.10g", lineterminator="\n")


def write_report_folder(analysis: StudyAnalysis, folder: str | os.PathLike) -> list[Path]:
    """Write every output of ``analysis`` into ``folder`` (created, or replaced whole).

    Returns:
        the paths written, as they are after the folder took its name.
    """
    from realpen.display.study_figures import save_study_figures
    from realpen.stats.report import write_report

    target = Path(folder)
    target.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=f".{target.name}.", dir=target.parent))
    try:
        _write_csv(analysis.results[list(RESULT_COLUMNS)], staging / "results.csv")
        _write_csv(analysis.cells, staging / "cells.csv")
        _write_csv(analysis.participants, staging / "participants.csv")
        _write_csv(analysis.confusion, staging / "confusion.csv")
        _write_csv(analysis.paper, staging / "paper.csv")
        if analysis.power is not None:
            _write_csv(analysis.power, staging / "power.csv")
        figures = save_study_figures(analysis, staging)
        write_report(analysis, staging, figures)
        staging.chmod(0o777 & ~_umask())
        names = sorted(path.name for path in staging.iterdir())
        _swap(staging, target)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
    return [target / name for name in names]


def _umask() -> int:
    from realpen.io.files import current_umask

    return current_umask()


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
