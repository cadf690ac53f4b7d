"""Small numeric CSV tables with named columns (trajectories, coupling measurements).

Every problem with the file becomes one :class:`~realpen.errors.RealPenError` naming the file.
"""

from __future__ import annotations

import csv
import io
import os
from pathlib import Path
from typing import Sequence

import numpy as np

from .errors import fail


def read_columns(path: str | os.PathLike, required: Sequence[str],
                 min_rows: int = 1) -> dict[str, np.ndarray]:
    """Read the ``required`` columns of a comma-separated file with a header row.

    Column names are matched case-insensitively and surrounding spaces are ignored; other
    columns are allowed and ignored. Every value must be a finite number.

    Args:
        path: the CSV file.
        required: names of the columns to return.
        min_rows: fewest data rows accepted.

    Returns:
        One float64 array per required name (lower case), all of the same length.

    Raises:
        RealPenError: missing, empty or binary file; missing columns; ragged rows; non-numeric,
            NaN or infinite values; fewer than ``min_rows`` rows.
    """
    path = Path(path)
    if not path.exists():
        raise fail(path, "no such file")
    if path.is_dir():
        raise fail(path, "is a folder, not a file")
    if path.stat().st_size == 0:
        raise fail(path, "file is empty")
    try:
        text = path.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError:
        raise fail(path, "not a text CSV file") from None
    lines = [line for line in text.splitlines() if line.strip()]
    if not lines:
        raise fail(path, "file holds only blank lines")
    rows = list(csv.reader(io.StringIO("\n".join(lines))))
    header = [name.strip().lower() for name in rows[0]]
    missing = [name for name in required if name.lower() not in header]
    if missing:
        raise fail(path, f"CSV header needs the column(s) {', '.join(required)}; "
                         f"missing {', '.join(missing)} (header: {','.join(rows[0])})")
    if len(rows) - 1 < min_rows:
        raise fail(path, f"CSV needs at least {min_rows} data row(s), has {len(rows) - 1}")
    indices = [header.index(name.lower()) for name in required]
    values = np.empty((len(rows) - 1, len(required)))
    for line_no, row in enumerate(rows[1:], start=2):
        if len(row) != len(header):
            raise fail(path, f"line {line_no}: {len(row)} values for the {len(header)} columns "
                             f"of the header")
        for column, index in enumerate(indices):
            cell = row[index].strip()
            try:
                value = float(cell)
            except ValueError:
                raise fail(path, f"line {line_no}: '{cell}' in column '{required[column]}' "
                                 f"is not a number") from None
            if not np.isfinite(value):
                raise fail(path, f"line {line_no}: column '{required[column]}' is {cell} "
                                 f"(NaN or infinite)")
            values[line_no - 2, column] = value
    return {name.lower(): values[:, column] for column, name in enumerate(required)}
