"""The one reader of numeric CSV tables: recordings, trajectories, measurements, actuator responses.

What it accepts:

- a header row naming the columns (``header=True``), or a header row that may be absent
  (``header=None``: the first row is a header when its first cell is not a number);
- the delimiter sniffed from the first 20 rows among ``,``, ``;``, tab and space (rows too
  irregular to tell: the one of ``,``, ``;`` and tab the first row uses most; one column: ``,``);
- a decimal comma (``0,5``) in files whose delimiter is not a comma (``50;0,5``);
- blank lines anywhere (skipped), ``\\r\\n`` or ``\\r`` line ends, a UTF-8 byte-order mark;
- other, non-numeric columns beside the ones asked for (ignored).

Every value read must be a finite number. Every problem with the file becomes one
:class:`~realpen.errors.RealPenError` naming the file and, for a row, its line as an editor
counts it (the first line is line 1, blank lines count).
"""

from __future__ import annotations

import csv
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from realpen.errors import ParameterError, fail
from realpen.io.files import check_readable_file

__all__ = ["Table", "read_csv", "is_number", "DELIMITERS", "SNIFF_ROWS"]

DELIMITERS = ",;\t "
SNIFF_ROWS = 20


@dataclass(frozen=True, repr=False)
class Table:
    """Columns read from a CSV file, and the file line each data row came from.

    Attributes:
        names: the names of the columns read, as the header spells them (or ``column N``,
            1-based, in a file without a header), in the order they were asked for.
        values: float64 array of shape (rows, len(names)), every value finite.
        lines: the 1-based line number in the file of each data row (blank lines count), so
            that later checks of the values can name the line an editor shows.
        header: the whole header row (stripped), or None when the file has none.
        delimiter: the delimiter the file uses.
        decimal_comma: whether a decimal comma was read anywhere.
        source: the file.
    """

    names: tuple[str, ...]
    values: np.ndarray
    lines: np.ndarray
    header: tuple[str, ...] | None
    delimiter: str
    decimal_comma: bool
    source: Path

    @property
    def columns(self) -> dict[str, np.ndarray]:
        """One float64 array per column read, by lower-case name."""
        return {name.lower(): self.values[:, index] for index, name in enumerate(self.names)}

    def column(self, name: str) -> np.ndarray:
        """The column ``name`` (matched case-insensitively, surrounding spaces ignored)."""
        wanted = name.strip().lower()
        for index, own in enumerate(self.names):
            if own.lower() == wanted:
                return self.values[:, index]
        raise KeyError(name)

    def __len__(self) -> int:
        return len(self.lines)

    def __repr__(self) -> str:
        names = ", ".join(self.names[:6]) + (", ..." if len(self.names) > 6 else "")
        return (f"Table({self.source.name!r}: {len(self.lines)} rows × [{names[:80]}], "
                f"delimiter {self.delimiter!r})")


def read_csv(path: str | os.PathLike, columns: Sequence[str | int] | None = None, *,
             header: bool | None = True, min_rows: int = 1,
             row_hint: str | None = None, optional: Sequence[str] = ()) -> Table:
    """Read numeric columns of a CSV file; see the module doc for what is accepted.

    Args:
        path: the CSV file.
        columns: the columns to read: names (matched case-insensitively, surrounding spaces
            ignored) or 0-based positions; None reads every column, which must then all be
            numeric.
        header: True: the first row names the columns; None: it does when its first cell is
            not a number; False: there is no header.
        min_rows: fewest data rows accepted (≥ 0).
        row_hint: what a row must hold, added to messages about a bad row (e.g. ``"every row
            needs two numbers: frequency in Hz, response"``).
        optional: names of columns read after ``columns`` when the header has them (e.g. a
            trajectory's tilt); ignored when ``columns`` is None or the file has no header.

    Returns:
        The :class:`Table`.

    Raises:
        RealPenError: missing, empty, binary or blank file; a missing header or column;
            ragged rows; non-numeric, NaN or infinite values; fewer than ``min_rows`` rows.
        ParameterError: ``min_rows`` below 0, or ``header`` not True, None or False.

    Example:
        >>> import tempfile, pathlib
        >>> path = pathlib.Path(tempfile.mkdtemp()) / "response.csv"
        >>> _ = path.write_text("hz;gain\\n50;0,5\\n\\n100;1\\n")
        >>> table = read_csv(path)
        >>> table.delimiter, table.column("gain").tolist(), table.lines.tolist()
        (';', [0.5, 1.0], [2, 4])
    """
    if isinstance(min_rows, bool) or not isinstance(min_rows, int) or min_rows < 0:
        raise ParameterError("min_rows", f"must be a whole number >= 0, got {min_rows!r}")
    if header not in (True, None, False):
        raise ParameterError("header", f"must be True, None or False, got {header!r}")
    path = Path(path)
    numbered = _lines(path)
    delimiter = _sniff(line for _, line in numbered[:SNIFF_ROWS])
    rows: list[tuple[int, list[str]]] = []
    try:
        for row in csv.reader((line for _, line in numbered), delimiter=delimiter):
            rows.append((numbered[len(rows)][0], [cell.strip() for cell in row]))
    except csv.Error as error:
        raise fail(path, f"line {numbered[len(rows)][0]}: not a CSV row ({error})") from None
    hint = f" ({row_hint})" if row_hint else ""
    first_line, first = rows[0]
    if header is None:
        header = not is_number(first[0], delimiter != ",")
    if header:
        if all(is_number(cell, delimiter != ",") for cell in first):
            raise fail(path, f"line {first_line}: CSV needs a header row naming its columns "
                             f"(the first row is numbers)")
        names_in_file = tuple(first)
        data = rows[1:]
    else:
        names_in_file = None
        data = rows
    width = len(names_in_file) if names_in_file is not None else len(data[0][1]) if data else 0
    shown = names_in_file or tuple(f"column {index + 1}" for index in range(width))
    indices = _indices(path, columns, names_in_file, width, first_line, hint)
    if optional and columns is not None and names_in_file is not None:
        folded = [name.strip().lower() for name in names_in_file]
        indices += [folded.index(name.strip().lower()) for name in optional
                    if name.strip().lower() in folded]
    if len(data) < min_rows:
        raise fail(path, f"CSV needs at least {min_rows} data row(s), has {len(data)}"
                         + (hint if header is False else ""))
    for line_no, row in data:
        if len(row) != width:
            what = "of the header" if names_in_file is not None else "of the first row"
            raise fail(path, f"line {line_no}: {len(row)} values for the {width} columns "
                             f"{what}{hint}")
    values = np.empty((len(data), len(indices)))
    comma = False
    for position, index in enumerate(indices):
        cells = [row[index] for _, row in data]
        column, used_comma = _numbers(path, cells, data, shown[index], delimiter, hint)
        values[:, position] = column
        comma = comma or used_comma
    return Table(names=tuple(shown[index] for index in indices), values=values,
                 lines=np.array([number for number, _ in data], dtype=np.int64),
                 header=names_in_file, delimiter=delimiter, decimal_comma=comma, source=path)


def is_number(text: str, decimal_comma: bool = False) -> bool:
    """Whether ``text`` parses as a float (a CSV cell that is a value, not a name).

    Args:
        text: the cell.
        decimal_comma: also accept a decimal comma (``"0,5"``).
    """
    try:
        float(text)
    except ValueError:
        if decimal_comma and "," in text:
            return is_number(text.replace(",", "."))
        return False
    return True


def _lines(path: Path) -> list[tuple[int, str]]:
    """The file's non-blank lines with their 1-based numbers."""
    check_readable_file(path)
    try:
        text = path.read_text(encoding="utf-8-sig")  # universal newlines: \r\n and \r become \n
    except UnicodeDecodeError:
        raise fail(path, "not a text CSV file") from None
    except OSError as error:
        raise fail(path, f"cannot read ({error.strerror or error})") from None
    if "\x00" in text:
        raise fail(path, "not a text CSV file")
    numbered = [(number, line) for number, line in enumerate(text.split("\n"), start=1)
                if line.strip()]
    if not numbered:
        raise fail(path, "file holds only blank lines")
    return numbered


def _sniff(lines) -> str:
    """The delimiter of the sample lines: sniffed; when the rows are too irregular to tell, the
    one of ``,``, ``;`` and tab the first row uses most (``,`` when it uses none)."""
    lines = list(lines)
    try:
        return csv.Sniffer().sniff("\n".join(lines), delimiters=DELIMITERS).delimiter
    except csv.Error:
        counts = [(lines[0].count(delimiter), delimiter) for delimiter in ",;\t"] if lines else []
        best = max(counts, key=lambda item: item[0], default=(0, ","))
        return best[1] if best[0] > 0 else ","


def _indices(path: Path, columns, names: tuple[str, ...] | None, width: int, line: int,
             hint: str) -> list[int]:
    if columns is None:
        return list(range(width))
    folded = [name.strip().lower() for name in names] if names is not None else None
    indices, missing = [], []
    for wanted in columns:
        if isinstance(wanted, int) and not isinstance(wanted, bool):
            if not 0 <= wanted < width:
                raise fail(path, f"CSV has {width} column(s); column {wanted + 1} is needed"
                                 f"{hint}")
            indices.append(wanted)
        elif folded is None:
            raise fail(path, f"CSV needs a header row naming the column {wanted!r}")
        elif wanted.strip().lower() in folded:
            indices.append(folded.index(wanted.strip().lower()))
        else:
            missing.append(str(wanted))
    if missing:
        raise fail(path, f"line {line}: CSV header needs the column(s) "
                         f"{', '.join(map(str, columns))}; missing {', '.join(missing)} "
                         f"(header: {','.join(names)})")
    return indices


def _numbers(path: Path, cells: list[str], data, name: str, delimiter: str,
             hint: str) -> tuple[np.ndarray, bool]:
    """One column's cells as finite floats; (values, whether a decimal comma was read)."""
    comma = False
    try:
        values = np.array(cells, dtype=np.float64)
    except ValueError:
        values = np.empty(len(cells))
        for position, cell in enumerate(cells):
            try:
                values[position] = float(cell)
            except ValueError:
                if delimiter != "," and "," in cell and is_number(cell.replace(",", ".")):
                    values[position] = float(cell.replace(",", "."))
                    comma = True
                    continue
                raise fail(path, f"line {data[position][0]}: '{cell}' in column '{name}' is "
                                 f"not a number{hint}") from None
    bad = np.flatnonzero(~np.isfinite(values))
    if len(bad):
        raise fail(path, f"line {data[bad[0]][0]}: column '{name}' is {cells[bad[0]]} "
                         f"(NaN or infinite)")
    return values, comma
