"""What the study figures read: the analysis's tables shaped for drawing, and the studies' names.

A figure never recomputes a statistic: it reads a :class:`realpen.stats.outcome.StudyAnalysis`'s
tables. This module checks those tables, puts levels in the order a reader expects (the
built-in studies' conditions, modalities and pens), lays out each participant's values as a
participants × levels table, and words outcomes and axes (``Q1: realism rating (points)``).
:mod:`realpen.stats.figures`, :mod:`realpen.stats.power_plot` and
:mod:`realpen.stats.figure_plan` share it.

May import: :mod:`realpen.errors`, :mod:`realpen.display`, :mod:`realpen.stats.data` (and pandas).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence

import pandas as pd

from realpen.display.charts import label_text
from realpen.errors import ParameterError
from realpen.stats.data import LOG_RT, RECOGNITION

__all__ = ["LIKERT_UNIT", "LIKERT_JITTER", "KNOWN_ORDERS", "QUESTIONNAIRE", "STUDY1_LABELS",
           "RT_OUTCOME", "RECOGNITION_OUTCOME", "require_table", "cell_table",
           "participant_table", "ordered_levels", "outcome_names", "cell_rows",
           "participant_matrix", "outcome_unit", "outcome_label", "axis_label", "main_factor",
           "chance_line", "no_data"]

LIKERT_JITTER = 0.12
"""Likert answers tie a lot: each participant's line is shifted by a fixed amount within
± this many points so that tied lines stay visible; the captions say so."""
LIKERT_UNIT = "points"
"""The unit of a Likert outcome in ``cells``."""
# Levels of other designs keep the order in which the analysis lists them.
KNOWN_ORDERS = {
    "condition": ("A", "B", "C", "D", "E", "F"),
    "modality": ("tactile", "auditory", "audio-tactile"),
    "pen": ("pencil", "ballpoint", "marker"),
    "superposition": ("5", "10", "15"),
    "fluctuation": ("15x100ms", "1x1500ms"),
}
"""The built-in studies' levels in the order a reader expects (DESIGN.md, data contracts)."""
QUESTIONNAIRE = ("realism", "comfort", "strength", "balance")
"""Study 2's questionnaire items, in the order its figure shows them."""
STUDY1_LABELS = {"Q1": "Q1: realism", "Q2": "Q2: comfort"}
"""How study 1's Likert outcomes are named on a figure."""
RT_OUTCOME = LOG_RT
"""The response-time outcome (its cells are in ms: geometric means)."""
RECOGNITION_OUTCOME = RECOGNITION
"""The recognition outcome (its cells are in % correct)."""


def require_table(frame: pd.DataFrame | None, columns: Iterable[str], table: str) -> pd.DataFrame:
    """``frame``, checked to be a DataFrame with ``columns``.

    Raises:
        ParameterError: no table, or a column missing (names ``analysis`` and ``table``).
    """
    if frame is None or not isinstance(frame, pd.DataFrame):
        raise ParameterError("analysis", f"has no {table} table")
    missing = [column for column in columns if column not in frame.columns]
    if missing:
        raise ParameterError("analysis", f"{table} table lacks column(s) {', '.join(missing)}")
    return frame


def cell_table(analysis) -> pd.DataFrame:
    """The analysis's ``cells``, checked, with ``outcome``, ``factor`` and ``level`` as text.

    Raises:
        ParameterError: no ``cells`` table or a column missing.
    """
    frame = require_table(analysis.cells, ("outcome", "factor", "level", "mean", "ci_low",
                                           "ci_high", "unit"), "cells")
    return frame.astype({"outcome": str, "factor": str, "level": str})


def participant_table(analysis) -> pd.DataFrame:
    """The analysis's ``participants`` (empty when it lists none), ids and levels as text.

    Raises:
        ParameterError: a column missing.
    """
    frame = analysis.participants
    if frame is None or len(frame) == 0:
        return pd.DataFrame(columns=["outcome", "factor", "level", "participant", "value", "unit"])
    frame = require_table(frame, ("outcome", "factor", "level", "participant", "value"), "participants")
    return frame.astype({"outcome": str, "factor": str, "level": str, "participant": str})


def ordered_levels(factor: str, levels: Iterable[str]) -> list[str]:
    """``levels`` (unique) in the reader's order: known names first, the rest as listed.

    An interaction's levels (``tactile:pencil``) sort by their parts, the first part first.
    """
    levels = list(dict.fromkeys(str(level) for level in levels))
    names = factor.split(":")
    seen: list[list[str]] = [[] for _ in names]
    for level in levels:
        for k, part in enumerate(level.split(":", len(names) - 1)):
            if k < len(seen) and part not in seen[k]:
                seen[k].append(part)

    def rank(level: str) -> tuple:
        key = []
        for k, part in enumerate(level.split(":", len(names) - 1)[:len(names)]):
            known = KNOWN_ORDERS.get(names[k], ())
            key.append(known.index(part) if part in known else len(known) + seen[k].index(part))
        return tuple(key)

    return sorted(levels, key=rank)


def outcome_names(frame: pd.DataFrame, *, factor: str | None = None, unit: str | None = None,
                  known: Sequence[str] = ()) -> list[str]:
    """Outcomes of ``frame`` (optionally over ``factor`` / with ``unit``), ``known`` first."""
    rows = frame
    if factor is not None:
        rows = rows[rows["factor"] == factor]
    if unit is not None and "unit" in rows.columns:
        rows = rows[rows["unit"].astype(str) == unit]
    found = list(dict.fromkeys(rows["outcome"]))
    return [name for name in known if name in found] + [name for name in found if name not in known]


def cell_rows(cells: pd.DataFrame, outcome: str, factor: str) -> pd.DataFrame:
    """One outcome × factor's cells, in the reader's order, indexed by level."""
    rows = cells[(cells["outcome"] == outcome) & (cells["factor"] == factor)]
    rows = rows.drop_duplicates("level").set_index("level")
    return rows.loc[ordered_levels(factor, rows.index)]


def participant_matrix(participants: pd.DataFrame, outcome: str, factor: str,
                       levels: Sequence[str]) -> pd.DataFrame:
    """Participants × ``levels`` of their values (NaN where a participant has no value)."""
    rows = participants[(participants["outcome"] == outcome) & (participants["factor"] == factor)]
    if rows.empty:
        return pd.DataFrame(columns=list(levels), dtype=float)
    values = pd.to_numeric(rows["value"], errors="coerce")
    table = rows.assign(value=values).pivot_table(index="participant", columns="level",
                                                  values="value", aggfunc="mean", sort=False)
    return table.reindex(columns=list(levels))


def outcome_unit(cells: pd.DataFrame, outcome: str) -> str:
    """The unit of ``outcome``'s cells (``points``, ``%``, ``ms``), or "" when none is given."""
    units = cells.loc[cells["outcome"] == outcome, "unit"].dropna().astype(str).unique()
    return units[0] if len(units) else ""


def outcome_label(analysis, outcome: str) -> str:
    """How a figure names ``outcome`` (``Q1: realism`` in study 1, ``response time``)."""
    if getattr(analysis, "design", "") == "study1" and outcome in STUDY1_LABELS:
        return STUDY1_LABELS[outcome]
    if outcome == RT_OUTCOME:
        return "response time"
    return label_text(outcome)


def axis_label(analysis, outcome: str, unit: str) -> str:
    """A y label with the unit: ``rating (points)``, ``recognition (% correct)``."""
    if unit == LIKERT_UNIT:
        return f"{outcome_label(analysis, outcome)} rating (points)"
    if outcome == "recognition" and unit == "%":
        return "recognition (% correct)"
    if outcome == RT_OUTCOME:
        return "response time (ms)"
    return f"{outcome_label(analysis, outcome)} ({label_text(unit)})" if unit else \
        outcome_label(analysis, outcome)


def main_factor(participants: pd.DataFrame, outcome: str) -> str:
    """The factor a participant figure runs over: ``condition``, else the main factor with
    the most levels, else the interaction."""
    rows = participants[participants["outcome"] == outcome]
    factors = list(dict.fromkeys(rows["factor"]))
    if "condition" in factors:
        return "condition"
    single = [name for name in factors if ":" not in name] or factors
    return max(single, key=lambda name: rows.loc[rows["factor"] == name, "level"].nunique())


def chance_line(analysis) -> tuple[float, str] | None:
    """Where guessing puts the recognition rate: ``(percent, "1/k")`` for a question of ``k``
    answers, or None without a confusion table.

    ``k`` is the number of answers the ``confusion`` table lists, which holds every pen
    presented and every other answer given (a choice that is not a pen and that nobody chose
    is not counted; with the usual ``choices: pens``, and in study 2, it is exact).

    Examples:
        >>> import pandas as pd
        >>> from realpen.stats.outcome import StudyAnalysis
        >>> confusion = pd.DataFrame({"modality": "tactile", "pen": ["pencil"] * 3,
        ...                           "chosen": ["pencil", "ballpoint", "marker"],
        ...                           "count": [3, 1, 0], "row_percent": [75.0, 25.0, 0.0]})
        >>> empty = pd.DataFrame()
        >>> chance_line(StudyAnalysis("study2", "Study 2", empty, empty, empty, confusion, empty))
        (33.333333333333336, '1/3')
    """
    confusion = getattr(analysis, "confusion", None)
    if not isinstance(confusion, pd.DataFrame) or "chosen" not in confusion.columns:
        return None
    answers = confusion["chosen"].astype(str).nunique()
    if answers < 2:
        return None
    return 100.0 / answers, f"1/{answers}"


def no_data(what: str, figure_name: str) -> ParameterError:
    """The error of a figure whose analysis lacks ``what`` (names ``analysis``)."""
    return ParameterError("analysis", f"has no {what} (needed by {figure_name})")
