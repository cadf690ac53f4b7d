"""Long-format tables for the within-subject tests: checks, level order, and the subjects × cells table.

Every test of :mod:`realpen.stats.anova`, :mod:`realpen.stats.nonparametric`,
:mod:`realpen.stats.art` and :mod:`realpen.stats.intervals` takes a long-format DataFrame (one
row per subject × cell). This module checks such a table once, in one wording — a missing
column, a subject without a cell, two values in one cell, each named by subject and cell — and
shapes it into the subjects × cells table the tests compute on.

May import: :mod:`realpen.errors` (and numpy, pandas).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pandas as pd

from realpen.errors import ParameterError

__all__ = ["MAX_FACTORS", "shown_level", "cell_text", "level_order", "factor_list",
           "check_columns", "balanced_wide", "safe_long"]

MAX_FACTORS = 3
"""The most within-subject factors a test takes (pingouin's two, and the three-way case)."""


def shown_level(value: object) -> str:
    """A level or subject as a message shows it: strings quoted, numbers bare, numpy scalars
    unwrapped.

    >>> import numpy as np
    >>> shown_level("pencil"), shown_level(np.int64(3))
    ("'pencil'", '3')
    """
    if isinstance(value, np.generic):
        value = value.item()
    return repr(value) if isinstance(value, str) else str(value)


def cell_text(factors: Sequence[str], cell: object) -> str:
    """A cell as a message shows it: ``factor=level`` pairs (``cell`` a level or a tuple of them).

    >>> cell_text(["modality", "pen"], ("tactile", "pencil"))
    "modality='tactile', pen='pencil'"
    """
    cell = cell if isinstance(cell, tuple) else (cell,)
    return ", ".join(f"{factor}={shown_level(level)}" for factor, level in zip(factors, cell))


def level_order(column: pd.Series) -> list:
    """The levels of a column in a fixed order: a Categorical's own order (observed ones only),
    otherwise sorted (so the order never depends on which participant came first).

    >>> import pandas as pd
    >>> level_order(pd.Series(["b", "a", "b"]))
    ['a', 'b']
    """
    if isinstance(column.dtype, pd.CategoricalDtype):
        present = set(column.dropna().unique())
        return [level for level in column.cat.categories if level in present]
    unique = list(pd.unique(column.dropna()))
    try:
        return sorted(unique)
    except TypeError:
        return sorted(unique, key=str)


def factor_list(within: str | Sequence[str], *, most: int = MAX_FACTORS) -> list[str]:
    """``within`` (one column name or a list of 1 to ``most``) as a list of distinct names.

    Raises:
        ParameterError: not column names, too many, or a name twice (``within``).
    """
    factors = [within] if isinstance(within, str) else list(within) if within is not None else []
    if not factors or not all(isinstance(factor, str) for factor in factors):
        raise ParameterError("within", f"must be a column name or a list of 1 to {most}, got {within!r}")
    if len(factors) > most:
        raise ParameterError("within", f"at most {most} factors are supported, got {len(factors)}")
    if len(set(factors)) != len(factors):
        raise ParameterError("within", f"names a factor twice: {factors}")
    return factors


def check_columns(data: object, *, dv: str, factors: Sequence[str], subject: str) -> None:
    """Check that ``data`` is a DataFrame with a numeric ``dv`` and complete ``subject`` and
    ``factors`` columns, all different.

    Raises:
        ParameterError: the first problem, naming the parameter, the column and the row.
    """
    if not isinstance(data, pd.DataFrame):
        raise ParameterError("data", f"must be a pandas DataFrame (long format), got {type(data).__name__}")
    for parameter, names in (("dv", [dv]), ("subject", [subject]), ("within", factors)):
        for name in names:
            if name not in data.columns:
                raise ParameterError(parameter, f"no column {name!r} in data (columns: "
                                                f"{', '.join(map(str, data.columns))})")
    if dv in factors or subject in factors or dv == subject:
        raise ParameterError("within", f"dv, subject and within must be different columns, got dv={dv!r}, "
                                       f"subject={subject!r}, within={list(factors)}")
    values = data[dv]
    if not (pd.api.types.is_numeric_dtype(values) or pd.api.types.is_bool_dtype(values)):
        raise ParameterError("dv", f"column {dv!r} is not numeric (dtype {values.dtype})")
    for name in (subject, *factors):
        missing = data[name].isna()
        if missing.any():
            raise ParameterError("data", f"column {name!r} is empty in row {data.index[missing.argmax()]}")


def balanced_wide(data: pd.DataFrame, *, dv: str, within: Sequence[str], subject: str,
                  min_levels: int = 2) -> pd.DataFrame:
    """The subjects × cells table of a long-format ``data``, each cell holding exactly one
    finite value.

    Args:
        data: long format, one row per subject × cell.
        dv: the value's column (numeric, any unit).
        within: the factors' columns; each needs ``min_levels`` levels or more.
        subject: the subject column (2 subjects or more).
        min_levels: the fewest levels a factor may have.

    Returns:
        Subjects (rows, in :func:`level_order`) × cells (columns: a MultiIndex over ``within``,
        levels in :func:`level_order`), values as floats.

    Raises:
        ParameterError: anything else — a missing or non-finite value, a subject without a
            cell or with several values in one — naming the subject and the cell.

    Examples:
        >>> import pandas as pd
        >>> data = pd.DataFrame({"s": [1, 1, 2, 2], "pen": ["a", "b"] * 2, "y": [3, 5, 2, 4]})
        >>> balanced_wide(data, dv="y", within=["pen"], subject="s").to_numpy().tolist()
        [[3.0, 5.0], [2.0, 4.0]]
    """
    factors = list(within)
    check_columns(data, dv=dv, factors=factors, subject=subject)
    levels = [level_order(data[factor]) for factor in factors]
    for factor, found in zip(factors, levels):
        if len(found) < min_levels:
            raise ParameterError("within", f"factor {factor!r} has {len(found)} level(s) "
                                           f"({', '.join(map(shown_level, found))}); a test needs at "
                                           f"least {min_levels}")
    subjects = level_order(data[subject])
    if len(subjects) < 2:
        raise ParameterError("data", f"needs at least 2 subjects in {subject!r}, got {len(subjects)}")
    values = data[dv].astype(float)
    bad = ~np.isfinite(values.to_numpy())
    if bad.any():
        row = data.loc[bad].iloc[0]
        raise ParameterError("data", f"{dv!r} is missing or not finite for subject "
                                     f"{shown_level(row[subject])} at "
                                     f"{cell_text(factors, tuple(row[factors]))}")
    keys = [subject, *factors]
    counts = data.groupby(keys, observed=True, sort=False).size()
    if (counts > 1).any():
        key = counts.index[int(np.argmax(counts.to_numpy() > 1))]
        raise ParameterError("data", f"subject {shown_level(key[0])} has {counts[key]} values at "
                                     f"{cell_text(factors, key[1:])} (one per subject and cell expected: "
                                     f"average repetitions first)")
    full = pd.MultiIndex.from_product([subjects, *levels], names=keys)
    if len(counts) < len(full):
        missing = full.difference(counts.index, sort=False)
        key = missing[0]
        raise ParameterError("data", f"subject {shown_level(key[0])} has no value at "
                                     f"{cell_text(factors, key[1:])} (every subject needs every cell)")
    long = pd.Series(values.to_numpy(), index=pd.MultiIndex.from_frame(data[keys]))
    wide = long.unstack(factors)
    if not isinstance(wide.columns, pd.MultiIndex):
        wide.columns = pd.MultiIndex.from_arrays([wide.columns], names=factors)
    columns = pd.MultiIndex.from_product(levels, names=factors)
    return wide.reindex(index=subjects, columns=columns)


def safe_long(wide: pd.DataFrame) -> pd.DataFrame:
    """A :func:`balanced_wide` table back in long format with plain names: columns ``s`` (the
    subject), ``f0``, ``f1`` … (the factors) and ``y``, levels coded ``l0000``, ``l0001`` ….

    statsmodels builds a formula from the names, so a factor named ``pen type`` or a level
    ``audio-tactile`` must not reach it.
    """
    factors = list(wide.columns.names)
    frame = wide.copy()
    frame.index = [f"s{i}" for i in range(len(frame))]
    frame.columns = pd.MultiIndex.from_tuples(
        [tuple(f"l{codes[j]:04d}" for j in range(len(factors)))
         for codes in zip(*[wide.columns.codes[j] for j in range(len(factors))])],
        names=[f"f{j}" for j in range(len(factors))])
    long = frame.stack(list(range(len(factors)))).rename("y").reset_index()
    return long.rename(columns={"level_0": "s"})
