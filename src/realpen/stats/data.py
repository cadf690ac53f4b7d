"""Read a studies' trials CSV for analysis, and find the outcomes a design asks for.

:func:`read_trials` reads the export of ``realpen study export`` (its first columns are
:data:`realpen.study.export.KEY_COLUMNS`), keeps one study's rows, and checks every value it
will analyse: a rating must be a whole number on the question's scale, ``correct`` ``1``/``0``,
``rt_ms`` a number of milliseconds. :func:`outcomes` reads the design: every Likert question is
an outcome, every choice question with a right answer is ``recognition``, and its trials'
response times are ``log_rt``. An outcome's within factors are the columns among
``condition``, ``modality`` and ``pen`` that vary over the cells the design plans for it
(``condition`` is left out where it only repeats the modality, as in a block over modalities).
:func:`cell_values` reduces the answers to one value per participant and cell, and says which
participants miss a planned cell.

Every problem is one line that names the file, the line or the participant and cell, and the
problem.
"""

from __future__ import annotations

import csv
import math
import os
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from realpen.errors import fail
from realpen.io.files import check_readable_file
from realpen.io.limits import MAX_CSV_BYTES, check_size
from realpen.study.design import Design
from realpen.study.export import KEY_COLUMNS
from realpen.study.plan import participant_plan

__all__ = ["Trials", "Outcome", "read_trials", "outcomes", "cell_values", "FACTOR_COLUMNS",
           "RECOGNITION", "LOG_RT"]

FACTOR_COLUMNS = ("condition", "modality", "pen")
"""The columns that can be within-subject factors, in the order they are nested."""
RECOGNITION = "recognition"
LOG_RT = "log_rt"
_ANALYSED_PHASES = ("experimental", "questionnaire")


@dataclass(frozen=True)
class Outcome:
    """One dependent variable of a design.

    Attributes:
        name: the question id, :data:`RECOGNITION` or :data:`LOG_RT`.
        kind: ``likert``, ``recognition`` or ``log_rt``.
        question: the question whose answers (or trials) it is made of.
        factors: its within factors, in :data:`FACTOR_COLUMNS` order (may be empty).
        levels: each factor's planned levels, in design order.
        unit: ``points``, ``%`` or ``ms`` (how the report shows cell means).
        points: the Likert scale's top (0 for other kinds).
        cells: the planned cells, as tuples in ``factors`` order.
        allowed: for each of :data:`FACTOR_COLUMNS`, the values its answers may have (the
            planned ones).
    """

    name: str
    kind: str
    question: str
    factors: tuple[str, ...]
    levels: dict[str, tuple[str, ...]]
    unit: str
    points: int = 0
    cells: tuple[tuple[str, ...], ...] = ()
    allowed: dict[str, tuple[str, ...]] = field(default_factory=dict)


@dataclass
class Trials:
    """The answers of one study, checked.

    Attributes:
        frame: one row per answer of the analysed phases (training left out), with the
            key columns as text except ``trial`` (int), ``rt_ms`` (float, ms), ``correct``
            (1.0, 0.0 or NaN), ``value`` (the rating as a float, NaN for other answers),
            ``repetition`` (int, 0 where the file has none) and ``line`` (the CSV line).
        training: the training rows, the same columns (counted in the report, not analysed).
        design: the study's design.
        source: the file as given.
        participants: the participants in file order.
    """

    frame: pd.DataFrame
    training: pd.DataFrame
    design: Design
    source: str
    participants: list[str] = field(default_factory=list)


def read_trials(path: str | os.PathLike, design: Design) -> Trials:
    """Read a trials CSV (``realpen study export``) and keep the rows of ``design``'s study.

    Args:
        path: the CSV file.
        design: the study's design; rows whose ``study`` is another are left out (a file may
            hold several studies).

    Raises:
        RealPenError: the file is missing, empty, not a CSV, lacks a key column, holds no row
            of the study, or holds a rating, ``correct`` or ``rt_ms`` that is not valid; the
            line names the file, the CSV line, the participant and the question.
    """
    source = str(path)
    check_readable_file(path)
    check_size(path, MAX_CSV_BYTES, "CSV files")
    frame = _read_csv(path, source)
    missing = [column for column in KEY_COLUMNS if column not in frame.columns]
    if missing:
        raise fail(source, f"missing column{'s' if len(missing) > 1 else ''} "
                           f"{', '.join(missing)} (a trials CSV from `realpen study export` "
                           f"starts with {', '.join(KEY_COLUMNS)})")
    studies = sorted(set(frame["study"]))
    frame = frame[frame["study"] == design.name]
    if frame.empty:
        raise fail(source, f"no answers of study '{design.name}'"
                           + (f" (studies in the file: {', '.join(studies)})" if studies
                              else " (the file has no rows)"))
    frame = frame.copy()
    frame["trial"] = [_whole(source, row, "trial", row.trial) for row in frame.itertuples()]
    frame["repetition"] = ([_whole(source, row, "repetition", row.repetition or "0")
                            for row in frame.itertuples()]
                           if "repetition" in frame.columns else 0)
    frame["rt_ms"] = [_milliseconds(source, row) for row in frame.itertuples()]
    frame["correct"] = [_correct(source, row, design) for row in frame.itertuples()]
    frame["value"] = [_rating(source, row, design) for row in frame.itertuples()]
    _check_keys(source, frame)
    participants = list(dict.fromkeys(frame["participant"]))
    training = frame[frame["phase"] == "training"]
    unknown = frame[~frame["phase"].isin(("training",) + _ANALYSED_PHASES)]
    if not unknown.empty:
        row = unknown.iloc[0]
        raise fail(source, f"line {row.line}: unknown phase '{row.phase}' (training, "
                           f"experimental, questionnaire)")
    analysed = frame[frame["phase"].isin(_ANALYSED_PHASES)]
    return Trials(frame=analysed.reset_index(drop=True), training=training.reset_index(drop=True),
                  design=design, source=source, participants=participants)


def _read_csv(path: str | os.PathLike, source: str) -> pd.DataFrame:
    """Every record as text, with ``line``: the file line it starts on (a quoted answer may
    span lines, so records and lines differ)."""
    try:
        with open(path, newline="", encoding="utf-8") as handle:
            reader = csv.reader(handle)
            header = next(reader, None)
            if not header:
                raise fail(source, "has no header line (a trials CSV from `realpen study export`)")
            if len(set(header)) != len(header):
                raise fail(source, "line 1: a column name appears twice")
            records, lines = [], []
            start = reader.line_num + 1
            for record in reader:
                if record:
                    if len(record) != len(header):
                        raise fail(source, f"line {start}: {len(record)} fields, the header has "
                                           f"{len(header)}")
                    records.append(record)
                    lines.append(start)
                start = reader.line_num + 1
    except UnicodeDecodeError:
        raise fail(source, "is not UTF-8 text (a trials CSV from `realpen study export`)") from None
    except csv.Error as error:
        raise fail(source, f"is not a readable CSV file ({error})") from None
    frame = pd.DataFrame(records, columns=header, dtype=str)
    frame["line"] = lines
    return frame


def _check_keys(source: str, frame: pd.DataFrame) -> None:
    """One session per participant, one answer per trial and question: merged exports must not
    pool two people under one code, nor count an answer twice."""
    sessions = frame.groupby("participant", sort=False)["session"].unique()
    for participant, found in sessions.items():
        if len(found) > 1:
            raise fail(source, f"participant {participant} has answers in {len(found)} sessions "
                               f"({', '.join(map(str, found[:4]))}): give every participant "
                               f"their own code")
    repeated = frame[frame.duplicated(["participant", "trial", "question"], keep=False)]
    if not repeated.empty:
        first = repeated.iloc[0]
        lines = repeated[(repeated["trial"] == first.trial)
                         & (repeated["question"] == first.question)
                         & (repeated["participant"] == first.participant)]["line"].tolist()
        raise fail(source, f"lines {', '.join(map(str, lines[:4]))}: participant "
                           f"{first.participant} answers {first.question} of trial "
                           f"{first.trial} {len(lines)} times")


def _where(source: str, row) -> str:
    return f"{source}: line {row.line}: participant {row.participant}, trial {row.trial}"


def _whole(source: str, row, column: str, text: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise fail(f"{source}: line {row.line}", f"{column} '{text}' is not a whole "
                                                  f"number") from None


def _milliseconds(source: str, row) -> float:
    try:
        value = float(row.rt_ms)
    except ValueError:
        value = math.nan
    if not math.isfinite(value) or value < 0:
        raise fail(_where(source, row), f"rt_ms '{row.rt_ms}' is not a number of "
                                        f"milliseconds >= 0")
    return value


def _correct(source: str, row, design: Design) -> float:
    question = _question(design, row.question)
    if question is None or question.correct != "pen" or row.phase not in _ANALYSED_PHASES:
        if row.correct in ("1", "0", ""):
            return float(row.correct) if row.correct else math.nan
        raise fail(_where(source, row), f"correct '{row.correct}' must be 1, 0 or empty")
    right = "1" if row.answer == row.pen else "0"
    if row.correct != right:
        raise fail(_where(source, row), f"correct '{row.correct}' disagrees with the answer "
                                        f"'{row.answer}' to {row.question} for pen '{row.pen}' "
                                        f"(expected {right})")
    return float(right)


def _rating(source: str, row, design: Design) -> float:
    question = _question(design, row.question)
    if question is None or question.type != "likert":
        return math.nan
    if row.answer == "" and not question.required:
        return math.nan
    try:
        value = float(row.answer)
    except ValueError:
        value = math.nan
    if not math.isfinite(value) or value != int(value) or not 1 <= value <= question.points:
        raise fail(_where(source, row), f"{row.question} answer '{row.answer}' is not a rating "
                                        f"from 1 to {question.points}")
    return value


def _question(design: Design, question_id: str):
    return next((question for question in design.questions if question.id == question_id), None)


def outcomes(design: Design) -> list[Outcome]:
    """The outcomes ``design`` asks for, with their factors and planned cells.

    The planned cells are those of the design's plan for participant 0 (counterbalancing
    changes only the order, never the cells), training trials left out.

    >>> from realpen.study.design import load_design
    >>> [(o.name, o.factors) for o in outcomes(load_design("study1"))]
    [('Q1', ('condition',)), ('Q2', ('condition',))]
    >>> [(o.name, o.factors) for o in outcomes(load_design("study2"))][:3]
    [('recognition', ('modality', 'pen')), ('log_rt', ('modality', 'pen')), ('realism', ('modality',))]
    """
    plan = [trial for trial in participant_plan(design, 0) if trial.phase in _ANALYSED_PHASES]
    found: list[Outcome] = []
    recognitions = [q.id for q in design.questions if q.type == "choice" and q.correct == "pen"
                    and any(q.id in trial.questions for trial in plan)]
    for question in design.questions:
        trials = [trial for trial in plan if question.id in trial.questions]
        if not trials or question.type == "text":
            continue
        cells = list(dict.fromkeys((t.condition, t.modality, t.pen) for t in trials))
        factors = [name for i, name in enumerate(FACTOR_COLUMNS)
                   if len({cell[i] for cell in cells}) > 1]
        if "condition" in factors and "modality" in factors and \
                all(cell[0] == cell[1] for cell in cells):
            factors.remove("condition")  # a block over modalities names its level twice
        indices = [FACTOR_COLUMNS.index(name) for name in factors]
        planned = tuple(dict.fromkeys(tuple(cell[i] for i in indices) for cell in cells))
        levels = {name: tuple(dict.fromkeys(cell[i] for cell in cells))
                  for name, i in zip(factors, indices)}
        levels = {name: _design_order(design, name, values) for name, values in levels.items()}
        allowed = {name: tuple(dict.fromkeys(cell[i] for cell in cells))
                   for i, name in enumerate(FACTOR_COLUMNS)}
        # Several recognition questions each get their own outcome names.
        suffix = f":{question.id}" if len(recognitions) > 1 else ""
        if question.type == "likert":
            found.append(Outcome(question.id, "likert", question.id, tuple(factors), levels,
                                 "points", question.points, planned, allowed))
        elif question.correct == "pen":
            found.append(Outcome(RECOGNITION + suffix, "recognition", question.id,
                                 tuple(factors), levels, "%", 0, planned, allowed))
            found.append(Outcome(LOG_RT + suffix, "log_rt", question.id, tuple(factors), levels,
                                 "ms", 0, planned, allowed))
    return found


def _design_order(design: Design, factor: str, values: tuple[str, ...]) -> tuple[str, ...]:
    known = {"condition": [c.id for c in design.conditions], "modality": design.modalities,
             "pen": [p.id for p in design.pens]}[factor]
    return tuple(sorted(values, key=lambda v: known.index(v) if v in known else len(known)))


def cell_values(trials: Trials, outcome: Outcome) -> tuple[pd.DataFrame, dict[str, str]]:
    """Each participant's value per planned cell of ``outcome``.

    The value: for ``likert`` the mean rating of the cell's answers (one answer per cell in
    the method's designs); for ``recognition`` the proportion correct (0–1) over the cell's
    trials; for ``log_rt`` the mean of ln(rt_ms) over the cell's trials (one RT per trial).

    Returns:
        ``(values, incomplete)``: ``values`` has columns ``participant``, the outcome's
        factors, ``value`` and ``trials`` (how many answers made the value), for the
        participants with every planned cell; ``incomplete`` maps each other participant to
        the first missing cell, worded for a reader (``"no answer to Q1 in condition E"``).
    """
    rows = trials.frame[trials.frame["question"] == outcome.question]
    for column, values in outcome.allowed.items():
        stray = rows[~rows[column].isin(values)]
        if not stray.empty:
            row = stray.iloc[0]
            raise fail(_where(trials.source, row), f"{column} '{row[column]}' is not planned for "
                                                   f"{outcome.question} (the design's: "
                                                   f"{', '.join(values)})")
    factors = list(outcome.factors)
    if outcome.kind == "likert":
        rows = rows[rows["value"].notna()]
        column = "value"
    elif outcome.kind == "recognition":
        rows = rows[rows["correct"].notna()]
        column = "correct"
    else:
        # A 0 ms response time has no logarithm; analyse() notes how many were left out.
        rows = rows[rows["rt_ms"] > 0].assign(log_rt=lambda f: np.log(f["rt_ms"]))
        column = "log_rt"
    grouped = (rows.groupby(["participant", *factors], sort=False, observed=True)[column]
               .agg(["mean", "size"]).reset_index()
               .rename(columns={"mean": "value", "size": "trials"}))
    incomplete: dict[str, str] = {}
    keep: list[str] = []
    for participant in trials.participants:
        have = grouped[grouped["participant"] == participant]
        present = {tuple(str(v) for v in cell) for cell in have[factors].itertuples(index=False)} \
            if factors else ({()} if len(have) else set())
        missing = [cell for cell in outcome.cells if cell not in present]
        if missing:
            where = ", ".join(f"{name} {level}" for name, level in zip(factors, missing[0]))
            what = {"likert": f"no answer to {outcome.question}",
                    "recognition": f"no answered {outcome.question} trial",
                    "log_rt": f"no response time of a {outcome.question} trial"}[outcome.kind]
            incomplete[participant] = f"{what}{' in ' + where if where else ''}" + (
                f" (and {len(missing) - 1} more cell{'s' if len(missing) > 2 else ''})"
                if len(missing) > 1 else "")
        else:
            keep.append(participant)
    values = grouped[grouped["participant"].isin(keep)]
    planned = set(outcome.cells)
    if factors:
        inside = [tuple(str(v) for v in cell) in planned
                  for cell in values[factors].itertuples(index=False)]
        values = values[inside].copy()
        for name in factors:  # design order, which the tests and figures keep
            values[name] = pd.Categorical(values[name], categories=list(outcome.levels[name]))
    return values.reset_index(drop=True), incomplete

