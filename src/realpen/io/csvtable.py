"""Small numeric CSV tables with named columns (trajectories, coupling measurements).

Every problem with the file becomes one :class:`~realpen.errors.RealPenError` naming the file.
"""

from __future__ import annotations

import csv
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np

from realpen.errors import fail
from realpen.io.files import check_readable_file


@dataclass(frozen=True)
class Table:
    """Columns read from a CSV file, and the file line each data row came from.

    Attributes:
        columns: one float64 array per required column name (lower case).
        lines: the 1-based line number in the file of each data row (blank lines count), so
            that later checks of the values can name the line an editor shows.
    """

    columns: dict[str, np.ndarray]
    lines: np.ndarray


def read_columns(path: str | os.PathLike, required: Sequence[str],
                 min_rows: int = 1) -> dict[str, np.ndarray]:
    """Read the ``required`` columns of a comma-separated file with a header row.

    The same as :func:`read_table` without the line numbers.
    """
    return read_table(path, required, min_rows).columns


def read_table(path: str | os.PathLike, required: Sequence[str], min_rows: int = 1) -> Table:
    """Read the ``required`` columns of a comma-separated file with a header row.

    Column names are matched case-insensitively and surrounding spaces are ignored; other
    columns are allowed and ignored. Every value must be a finite number. Blank lines are
    skipped; messages name the line as counted in the file (the first line is line 1).

    Args:
        path: the CSV file.
        required: names of the columns to return.
        min_rows: fewest data rows accepted.

    Returns:
        The :class:`Table`: one float64 array per required name (lower case), all of the same
        length, and the file line of each row.

    Raises:
        RealPenError: missing, empty or binary file; missing columns; ragged rows; non-numeric,
            NaN or infinite values; fewer than ``min_rows`` rows.
    """
    path = Path(path)
    check_readable_file(path)
    try:
        text = path.read_text(encoding="utf-8-sig")  # universal newlines: \r\n and \r become \n
    except UnicodeDecodeError:
        raise fail(path, "not a text CSV file") from None
    numbered = [(number, line) for number, line in enumerate(text.split("\n"), start=1)
                if line.strip()]
    if not numbered:
        raise fail(path, "file holds only blank lines")
    rows = []
    for number, line in numbered:
        try:
            rows.append((number, next(csv.reader([line]))))
        except csv.Error as error:
            raise fail(path, f"line {number}: not a CSV row ({error})") from None
    header_line, header_row = rows[0]
    header = [name.strip().lower() for name in header_row]
    missing = [name for name in required if name.lower() not in header]
    if missing:
        raise fail(path, f"line {header_line}: CSV header needs the column(s) "
                         f"{', '.join(required)}; missing {', '.join(missing)} "
                         f"(header: {','.join(header_row)})")
    data = rows[1:]
    if len(data) < min_rows:
        raise fail(path, f"CSV needs at least {min_rows} data row(s), has {len(data)}")
    indices = [header.index(name.lower()) for name in required]
    values = np.empty((len(data), len(required)))
    for position, (line_no, row) in enumerate(data):
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
            values[position, column] = value
    return Table(columns={name.lower(): values[:, column] for column, name in enumerate(required)},
                 lines=np.array([number for number, _ in data], dtype=np.int64))


def is_number(text: str) -> bool:
    """Whether ``text`` parses as a float (a CSV cell that is a value, not a name)."""
    try:
        float(text)
    except ValueError:
        return False
    return True
