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

Limits (:mod:`realpen.io.limits`): the file is at most ``MAX_CSV_BYTES``, a line at most
``MAX_CSV_LINE_CHARS`` and a field at most ``MAX_CSV_FIELD_CHARS`` characters, and at most
``MAX_FRAMES`` numbers are kept. The file is read line by line into preallocated arrays, so
memory stays near 8 bytes a value kept, whatever the file holds.
"""

from __future__ import annotations

import csv
import itertools
import os
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from realpen.errors import ParameterError, fail
from realpen.io.files import check_readable_file
from realpen.io.limits import (
    MAX_CSV_BYTES,
    MAX_CSV_FIELD_CHARS,
    MAX_CSV_LINE_CHARS,
    MAX_FRAMES,
    check_size,
)

__all__ = ["Table", "read_csv", "is_number", "line_breaks", "column_numbers", "DELIMITERS",
           "SNIFF_ROWS"]

DELIMITERS = ",;\t "
SNIFF_ROWS = 20
SNIFF_CHARS = 4096  # csv.Sniffer's quote search grows faster than the square of its sample
_FLUSH_CELLS = 1 << 15  # cells held as text before they are converted into the arrays
_SHOWN_CHARS = 40  # a cell quoted in a message is cut to this many characters


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
            ragged rows; non-numeric, NaN or infinite values; fewer than ``min_rows`` rows;
            a file, line, field or table over its limit (see the module doc).
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
    check_readable_file(path)
    check_size(path, MAX_CSV_BYTES, "CSV files")
    capacity = line_breaks(path) + 1  # at least the rows there are: arrays sized once
    try:
        with open(path, encoding="utf-8-sig") as handle:  # universal newlines, as an editor
            return _read_rows(path, handle, capacity, columns, header, min_rows,
                              f" ({row_hint})" if row_hint else "", optional)
    except UnicodeDecodeError:
        raise fail(path, "not a text CSV file") from None
    except OSError as error:
        raise fail(path, f"cannot read ({error.strerror or error})") from None


def numbered_rows(path: Path, handle) -> tuple[Iterator[tuple[int, list[str]]], str]:
    """The rows of an open CSV file as ``(line number, cells)``, and the delimiter sniffed from
    its first rows; blank lines skipped, every length limit checked as the rows are read.

    Raises:
        RealPenError: a file of blank lines only (the rows raise as they meet a problem).
    """
    numbered = _lines(path, handle)
    head = list(itertools.islice(numbered, SNIFF_ROWS))
    if not head:
        raise fail(path, "file holds only blank lines")
    delimiter = _sniff(line for _, line in head)
    # The number of the line being read (csv.reader does not count ours), and the characters
    # of the row being read so far (a quoted field may span lines).
    where = [head[0][0], 0]

    def texts() -> Iterator[str]:
        for number, line in itertools.chain(head, numbered):
            where[0] = number
            where[1] += len(line)
            yield line

    return _rows(path, csv.reader(texts(), delimiter=delimiter), where), delimiter


def _read_rows(path: Path, handle, capacity: int, columns, header: bool | None, min_rows: int,
               hint: str, optional: Sequence[str]) -> Table:
    """The rows of an open CSV file, converted into arrays a block at a time."""
    rows, delimiter = numbered_rows(path, handle)
    first_line, first = next(rows)
    if header is None:
        header = not is_number(first[0], delimiter != ",")
    if header:
        if all(is_number(cell, delimiter != ",") for cell in first):
            raise fail(path, f"line {first_line}: CSV needs a header row naming its columns "
                             f"(the first row is numbers)")
        names_in_file = tuple(first)
    else:
        names_in_file = None
        rows = itertools.chain([(first_line, first)], rows)
    width = len(names_in_file) if names_in_file is not None else len(first)
    shown = names_in_file or tuple(f"column {index + 1}" for index in range(width))
    indices = _indices(path, columns, names_in_file, width, first_line, hint)
    if optional and columns is not None and names_in_file is not None:
        folded = [name.strip().lower() for name in names_in_file]
        indices += [folded.index(name.strip().lower()) for name in optional
                    if name.strip().lower() in folded]
    # The row numbers count as values: rows × (columns + 1) numbers of 8 bytes at most.
    limit = MAX_FRAMES // (len(indices) + 1)
    values = np.empty((min(capacity, limit), len(indices)))
    lines = np.empty(min(capacity, limit), dtype=np.int64)
    what = "of the header" if names_in_file is not None else "of the first row"
    count, comma = 0, False
    # (line, the cells asked for) of rows read but not yet converted: only those cells are
    # kept, so a wide row costs no more than a narrow one.
    pending: list[tuple[int, list[str]]] = []
    flush_rows = max(1, _FLUSH_CELLS // max(len(indices), 1))

    def flush() -> None:
        nonlocal count, comma
        for position, index in enumerate(indices):
            column, used_comma = column_numbers(path, [cells[position] for _, cells in pending],
                                          pending, shown[index], delimiter, hint)
            values[count:count + len(pending), position] = column
            comma = comma or used_comma
        lines[count:count + len(pending)] = [number for number, _ in pending]
        count += len(pending)
        pending.clear()

    for line_no, row in rows:
        if len(row) != width:
            raise fail(path, f"line {line_no}: {len(row)} values for the {width} columns "
                             f"{what}{hint}")
        if count + len(pending) == limit:
            raise fail(path, f"line {line_no}: more than {limit:,} rows of {len(indices)} "
                             f"column(s); CSV tables are limited to {MAX_FRAMES:,} numbers "
                             f"(row numbers included; use WAV or NPZ for longer recordings)")
        pending.append((line_no, [row[index] for index in indices]))
        if len(pending) >= flush_rows:
            flush()
    if pending:
        flush()
    if count < min_rows:
        raise fail(path, f"CSV needs at least {min_rows} data row(s), has {count}"
                         + (hint if header is False else ""))
    if count < len(values) // 2:  # mostly blank lines: do not keep the unused space alive
        values, lines = values[:count].copy(), lines[:count].copy()
    return Table(names=tuple(shown[index] for index in indices), values=values[:count],
                 lines=lines[:count], header=names_in_file, delimiter=delimiter,
                 decimal_comma=comma, source=path)


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


def line_breaks(path: Path) -> int:
    """How many line breaks (``\\n``, ``\\r\\n`` or ``\\r``) the file has, or a few more.

    Counted on bytes, a block at a time, so that the arrays can be allocated once at their
    final size; a ``\\r\\n`` split across two blocks counts twice, which only over-allocates.
    """
    breaks = 0
    with open(path, "rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            breaks += block.count(b"\n") + block.count(b"\r") - block.count(b"\r\n")
    return breaks


def _lines(path: Path, handle) -> Iterator[tuple[int, str]]:
    """The file's non-blank lines with their 1-based numbers, each within the line limit.

    ``readline`` is given the limit, so an over-long line is refused without being read whole.
    """
    number = 0
    while line := handle.readline(MAX_CSV_LINE_CHARS + 1):
        number += 1
        text = line[:-1] if line.endswith("\n") else line
        if len(text) > MAX_CSV_LINE_CHARS:
            raise fail(path, f"line {number} is over {MAX_CSV_LINE_CHARS:,} characters long; "
                             f"CSV lines are limited to {MAX_CSV_LINE_CHARS:,} characters and "
                             f"fields to {MAX_CSV_FIELD_CHARS:,}")
        if "\x00" in text:
            raise fail(path, "not a text CSV file")
        if text.strip():
            yield number, text


def _rows(path: Path, reader, where: list[int]) -> Iterator[tuple[int, list[str]]]:
    """(line, stripped cells) of each CSV row, every field within ``MAX_CSV_FIELD_CHARS``.

    ``where`` holds the number of the line just read (a row spanning lines, in quotes, is
    named by its last line) and the characters read for this row.
    """
    try:
        for row in reader:
            cells = [cell.strip() for cell in row]
            if where[1] > MAX_CSV_FIELD_CHARS:  # only a longer row can hold a longer field
                longest = max(len(cell) for cell in cells)
                if longest > MAX_CSV_FIELD_CHARS:
                    raise fail(path, f"line {where[0]}: a field of {longest:,} characters; CSV "
                                     f"fields are limited to {MAX_CSV_FIELD_CHARS:,}")
            where[1] = 0
            yield where[0], cells
    except csv.Error as error:
        raise fail(path, f"line {where[0]}: not a CSV row ({error})") from None


def _sniff(lines) -> str:
    """The delimiter of the sample lines: sniffed; when the rows are too irregular to tell, the
    one of ``,``, ``;`` and tab the first row uses most (``,`` when it uses none).

    The sniffer sees whole lines up to ``SNIFF_CHARS`` characters (at least the start of the
    first line): on a long sample full of quotes it would take minutes.
    """
    lines, sample, used = list(lines), [], 0
    for line in lines:
        if used + len(line) > SNIFF_CHARS:
            sample = sample or [line[:SNIFF_CHARS]]
            break
        sample.append(line)
        used += len(line) + 1
    try:
        return csv.Sniffer().sniff("\n".join(sample), delimiters=DELIMITERS).delimiter
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


def column_numbers(path: Path, cells: list[str], data, name: str, delimiter: str,
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
                raise fail(path, f"line {data[position][0]}: '{_shown(cell)}' in column "
                                 f"'{name}' is not a number{hint}") from None
    bad = np.flatnonzero(~np.isfinite(values))
    if len(bad):
        raise fail(path, f"line {data[bad[0]][0]}: column '{name}' is {_shown(cells[bad[0]])} "
                         f"(NaN or infinite)")
    return values, comma


def _shown(cell: str) -> str:
    """A cell as a message quotes it: cut to ``_SHOWN_CHARS`` characters."""
    return cell if len(cell) <= _SHOWN_CHARS else cell[:_SHOWN_CHARS - 3] + "..."
