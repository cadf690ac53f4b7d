"""Read a studies' trials CSV for analysis, and find the outcomes a design asks for.

:func:`read_trials` reads the export of ``realpen study export`` (its first columns are
:data:`realpen.study.export.KEY_COLUMNS`), keeps one study's rows, and checks every value it
will analyse: a rating must be a whole number on the question's scale, ``correct`` ``1``/``0``,
``rt_ms`` a number of milliseconds or empty (``NA``) where no time was measured — only the
response-time analysis needs it, and refuses its rows without one. A file from other software
may number trials within blocks (an answer is keyed by participant, block, phase, condition,
modality, trial and question) and carry columns of its own (ignored); a ``pilot`` column
(``1`` on a pilot session's rows) leaves those rows out unless they are asked for.

:func:`outcomes` reads the design: every Likert question is an outcome, every choice question
with a right answer is ``recognition``, and its trials' response times are ``log_rt``. An
outcome's within factors come from the cells the design plans for it: of ``condition``,
``modality`` and ``pen``, those that vary are *crossed* factors, except one whose level is
fixed by another's (a pen per condition: the pen is *nested* in the condition and not a factor
of its own; ``condition`` that only repeats the modality, as in a block over modalities, is
left out the same way), and those that do not vary are *constant*. :func:`factor_text` says
so in words for the report. :func:`cell_values` reduces the answers to one value per
participant and cell, and says which participants miss a planned cell.

Every problem is one line that names the file, the line or the participant and cell, and the
problem.

A trials CSV is read in bounded memory: at most :data:`MAX_TRIALS_BYTES` (256 MiB, some 2.5
million answers; a larger file is refused before it is read, so no file can make the reading
slow or large), streamed :data:`CHUNK_ROWS` records at a time into compact columns (text as
categories, numbers as arrays): a file just under the limit peaks near 600 MB. A UTF-8
byte-order mark at its start (Excel writes one) is skipped. A rating must be a plain whole
number (``3``, ``-3``), not ``+3``, ``3.0``, ``1e0`` or `` 3``: the export writes none of
those, and a spreadsheet that did may have changed more than the spelling.
"""

from __future__ import annotations

import csv
import itertools
import math
import os
from dataclasses import dataclass, field

import numpy as np
import pandas as pd
from pandas.api.types import union_categoricals

from realpen.defaults import OLD_MODALITY_NAMES
from realpen.errors import RealPenError, fail
from realpen.io.files import check_readable_file
from realpen.io.limits import check_size
from realpen.study.design import Design
from realpen.study.export import KEY_COLUMNS
from realpen.study.plan import participant_plan

__all__ = ["Trials", "Outcome", "read_trials", "outcomes", "cell_values", "factor_text",
           "outcome_rows", "FACTOR_COLUMNS", "ANSWER_KEY", "MISSING_TIMES", "NO_CONDITION",
           "RECOGNITION", "LOG_RT", "MAX_TRIALS_BYTES", "CHUNK_ROWS"]

FACTOR_COLUMNS = ("condition", "modality", "pen")
"""The columns that can be within-subject factors, in the order they are nested."""
RECOGNITION = "recognition"
LOG_RT = "log_rt"
_ANALYSED_PHASES = ("experimental", "questionnaire")
MAX_TRIALS_BYTES = 256 * 1024 * 1024
"""The largest trials CSV read (bytes): 256 MiB, about 2.5 million answers (study 2's export
is some 90 bytes an answer: 22,000 participants of its 93 trials; a lab study of 24 is 0.3 MB).
Read in chunks into compact columns, such a file takes well under 1 GB of memory; a larger
one is refused with one line before it is read. ``realpen stats simulate`` refuses to write
one."""
CHUNK_ROWS = 50_000
"""Records checked and converted at a time: the text of one chunk is all that is held as
Python strings."""
ANSWER_KEY = ("participant", "block", "phase", "condition", "modality", "trial", "question")
"""What makes an answer one answer: a participant answers a question once per trial, and other
software may number trials within blocks (1–30 in each modality block), so the trial number is
read within its block, phase, condition and modality (a participant has one session)."""
NO_CONDITION = "(none)"
"""The ``condition`` level of an outcome's trials outside any block over conditions or
modalities (the export's empty ``condition``), where the outcome is also asked in such a block:
a level of its own, named so a reader sees it."""
MISSING_TIMES = ("", "NA")
"""``rt_ms`` texts read as "no time measured" (NaN): empty, and R's ``NA``."""
_PILOT_YES = ("1",)
_PILOT_NO = ("0", "")
_MAX_STUDY_NAMES = 100  # other studies' names remembered for a message
_PLAIN_INTEGER = r"-?[0-9]+"


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
        nested: each column of :data:`FACTOR_COLUMNS` that varies but is not a factor because
            another fixes its level (``{"pen": "condition"}``: one pen per condition), mapped
            to that factor.
        constant: each column that does not vary over the outcome's cells, with its one level.
        averaged: columns that vary within the levels of the first factor without being crossed
            with it (some combinations are not planned): each participant's value is the mean
            over them.
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
    nested: dict[str, str] = field(default_factory=dict)
    constant: dict[str, str] = field(default_factory=dict)
    averaged: tuple[str, ...] = ()


@dataclass
class Trials:
    """The answers of one study, checked.

    Attributes:
        frame: one row per answer of the analysed phases (training left out), with the
            key columns as text (categorical, sorted categories) except ``trial`` (int),
            ``rt_ms`` (float, ms; NaN where the file gives no time), ``correct`` (1.0, 0.0 or
            NaN), ``value`` (the rating as a float, NaN for other answers), ``repetition``
            (int, 0 where the file has none) and ``line`` (the CSV line); ``answer`` is empty
            for text questions (not analysed), and the file's other columns are not kept.
        training: the training rows, the same columns (counted in the report, not analysed).
        design: the study's design.
        source: the file as given.
        participants: the participants in file order.
        pilot_rows: the answers of pilot sessions left out (``pilot`` column ``1``).
        notes: what the reading left out, worded for the report's notes.
    """

    frame: pd.DataFrame
    training: pd.DataFrame
    design: Design
    source: str
    participants: list[str] = field(default_factory=list)
    pilot_rows: int = 0
    notes: list[str] = field(default_factory=list)


def read_trials(path: str | os.PathLike, design: Design, *, include_pilot: bool = False
                ) -> Trials:
    """Read a trials CSV (``realpen study export``) and keep the rows of ``design``'s study.

    The file is streamed: :data:`CHUNK_ROWS` records at a time are checked and kept in compact
    columns (text as categories, numbers as arrays), so memory follows the study's rows, not
    the file's text; a file over :data:`MAX_TRIALS_BYTES` is refused before it is read. A
    UTF-8 byte-order mark at its start (Excel writes one) is skipped.

    Args:
        path: the CSV file.
        design: the study's design; rows whose ``study`` is another are left out (a file may
            hold several studies).
        include_pilot: keep the rows of pilot sessions (a ``pilot`` column of ``1``); by
            default they are left out, and :attr:`Trials.notes` says how many.

    Raises:
        RealPenError: the file is missing, empty, over :data:`MAX_TRIALS_BYTES`, not a CSV,
            lacks a key column, holds no row of the study, or holds a rating, ``correct``,
            ``rt_ms`` or ``pilot`` that is not valid (a rating must be a plain whole number:
            ``3`` or ``-3``, not ``+3``, ``3.0``, ``1e0`` or `` 3``; an empty ``rt_ms`` is
            valid), or an answer twice; the line names the file, the CSV line, the participant
            and the question.
    """
    source = str(path)
    check_readable_file(path)
    check_size(path, MAX_TRIALS_BYTES, "trials CSV files")
    reader = _ChunkReader(design, source, include_pilot=include_pilot)
    frame = reader.read(path)
    participants = list(dict.fromkeys(frame["participant"]))
    _check_keys(source, frame)
    training = frame[frame["phase"] == "training"]
    unknown = frame[~frame["phase"].isin(("training",) + _ANALYSED_PHASES)]
    if not unknown.empty:
        row = unknown.iloc[0]
        raise fail(source, f"line {row.line}: unknown phase '{row.phase}' (training, "
                           f"experimental, questionnaire)")
    analysed = frame[frame["phase"].isin(_ANALYSED_PHASES)]
    notes = []
    if reader.pilot_rows:
        count = len(reader.pilot_participants)
        notes.append(f"{reader.pilot_rows} answer{'s' if reader.pilot_rows != 1 else ''} of "
                     f"pilot sessions ({count} participant{'s' if count != 1 else ''}) left "
                     f"out")
    return Trials(frame=analysed.reset_index(drop=True), training=training.reset_index(drop=True),
                  design=design, source=source, participants=participants,
                  pilot_rows=reader.pilot_rows, notes=notes)


class _ChunkReader:
    """Reads a trials CSV chunk by chunk: every record's fields counted, the study's rows
    checked and kept as compact columns, the first problem of each kind remembered so that
    the one reported is the one a reading of the whole file would find first (trial, then
    repetition, rt_ms, correct, rating; each in file order)."""

    def __init__(self, design: Design, source: str, *, include_pilot: bool = False) -> None:
        self.design = design
        self.source = source
        self.include_pilot = include_pilot
        self.pilot_rows = 0
        self.pilot_participants: set[str] = set()
        self.studies: set[str] = set()
        self.chunks: list[pd.DataFrame] = []
        self.problems: dict[int, str] = {}
        self.has_repetition = False
        likert = {q.id: q for q in design.questions if q.type == "likert"}
        self.likert = likert
        self.recognition = {q.id for q in design.questions if q.correct == "pen"}
        self.kept_answers = set(likert) | {q.id for q in design.questions if q.type == "choice"}

    def read(self, path: str | os.PathLike) -> pd.DataFrame:
        source = self.source
        try:
            with open(path, newline="", encoding="utf-8-sig") as handle:
                reader = csv.reader(handle)
                header = next(reader, None)
                if not header:
                    raise fail(source, "has no header line (a trials CSV from `realpen study "
                                       "export`)")
                if len(set(header)) != len(header):
                    raise fail(source, "line 1: a column name appears twice")
                missing = [column for column in KEY_COLUMNS if column not in header]
                if missing:
                    raise fail(source, f"missing column{'s' if len(missing) > 1 else ''} "
                                       f"{', '.join(missing)} (a trials CSV from `realpen study "
                                       f"export` starts with {', '.join(KEY_COLUMNS)})")
                self.has_repetition = "repetition" in header
                kept = [*KEY_COLUMNS, *(["repetition"] if self.has_repetition else [])]
                positions = [header.index(column) for column in kept]
                study = header.index("study")
                pilot = header.index("pilot") if "pilot" in header else None
                participant = header.index("participant")
                records: list[list[str]] = []
                lines: list[int] = []
                start = reader.line_num + 1
                for record in reader:
                    if record:
                        if len(record) != len(header):
                            raise fail(source, f"line {start}: {len(record)} fields, the "
                                               f"header has {len(header)}")
                        name = record[study]
                        if name == self.design.name and pilot is not None and \
                                self._left_out_pilot(record[pilot], start, record[participant]):
                            pass
                        elif name == self.design.name:
                            records.append([record[i] for i in positions])
                            lines.append(start)
                            if len(records) >= CHUNK_ROWS:
                                self._add(records, lines, kept)
                                records, lines = [], []
                        elif len(self.studies) < _MAX_STUDY_NAMES:
                            self.studies.add(name)
                    start = reader.line_num + 1
                if records:
                    self._add(records, lines, kept)
        except UnicodeDecodeError:
            raise fail(source, "is not UTF-8 text (a trials CSV from `realpen study export`)") \
                from None
        except csv.Error as error:
            raise fail(source, f"is not a readable CSV file ({error})") from None
        if not self.chunks:
            studies = sorted(self.studies)
            if self.pilot_rows:
                raise fail(source, f"no answers of study '{self.design.name}' but those of "
                                   f"pilot sessions ({self.pilot_rows}, left out unless pilot "
                                   f"sessions are included)")
            raise fail(source, f"no answers of study '{self.design.name}'"
                               + (f" (studies in the file: {', '.join(studies)})" if studies
                                  else " (the file has no rows)"))
        if self.problems:
            raise RealPenError(self.problems[min(self.problems)])
        return _joined(self.chunks)

    def _problem(self, kind: int, message: str) -> None:
        self.problems.setdefault(kind, message)

    def _left_out_pilot(self, text: str, line: int, participant: str) -> bool:
        """Whether a row is a pilot session's that is left out (counted); a ``pilot`` that is
        not 1, 0 or empty is a problem (the row is kept, so it is reported in file order)."""
        if text in _PILOT_NO:
            return False
        if text not in _PILOT_YES:
            self._problem(5, f"{self.source}: line {line}: participant {participant}: pilot "
                             f"'{text}' must be 1 (a pilot session), 0 or empty")
            return False
        if self.include_pilot:
            return False
        self.pilot_rows += 1
        self.pilot_participants.add(participant)
        return True

    def _add(self, records: list[list[str]], lines: list[int], kept: list[str]) -> None:
        """Check one chunk of the study's records and keep it as compact columns."""
        frame = pd.DataFrame(records, columns=kept, dtype=object)
        frame["line"] = np.asarray(lines, dtype=np.int64)
        # files of other software (and earlier releases' strokes) may say "auditory-tactile"
        for column in ("modality", "condition"):
            frame[column] = frame[column].replace(OLD_MODALITY_NAMES)
        trial = self._whole(frame, "trial", frame["trial"], 0)
        repetition = (self._whole(frame, "repetition", frame["repetition"].replace("", "0"), 1)
                      if self.has_repetition else np.zeros(len(frame), dtype=np.int64))
        shown = pd.Series(trial, index=frame.index)
        rt_ms = self._milliseconds(frame, shown)
        correct = self._correct(frame, shown)
        value = self._ratings(frame, shown)
        answers = frame["answer"].where(frame["question"].isin(self.kept_answers), "")
        compact = {column: pd.Categorical(frame[column].to_numpy(dtype=object))
                   for column in KEY_COLUMNS if column not in ("trial", "rt_ms", "correct",
                                                                "answer")}
        compact.update(answer=pd.Categorical(answers.to_numpy(dtype=object)), trial=trial,
                       rt_ms=rt_ms, correct=correct, value=value, repetition=repetition,
                       line=frame["line"].to_numpy())
        self.chunks.append(pd.DataFrame(compact)[[*KEY_COLUMNS, "repetition", "line", "value"]])

    def _first(self, frame: pd.DataFrame, bad: np.ndarray) -> pd.Series:
        return frame.iloc[int(np.argmax(bad))]

    def _whole(self, frame: pd.DataFrame, column: str, texts: pd.Series, kind: int) -> np.ndarray:
        """Whole numbers as Python's int() reads them, each distinct text parsed once."""
        parsed = {}
        for text in pd.unique(texts):
            try:
                parsed[text] = int(text)
            except ValueError:
                parsed[text] = None
        numbers = texts.map(parsed)
        bad = numbers.isna().to_numpy()
        if bad.any():
            row = self._first(frame, bad)
            self._problem(kind, f"{self.source}: line {row.line}: {column} "
                                f"'{texts.iloc[int(np.argmax(bad))]}' is not a whole number")
            numbers = numbers.fillna(0)
        return numbers.to_numpy(dtype=np.int64)

    def _where(self, row: pd.Series, trial: object) -> str:
        return f"{self.source}: line {row.line}: participant {row.participant}, trial {trial}"

    def _milliseconds(self, frame: pd.DataFrame, trial: pd.Series) -> np.ndarray:
        def number(text: str) -> float:
            try:
                return float(text)
            except ValueError:
                return math.nan

        values = np.fromiter((number(text) for text in frame["rt_ms"]), dtype=float,
                             count=len(frame))
        # No time measured (a rating row of other software): NaN, refused only by the
        # response-time analysis, which needs it.
        missing = frame["rt_ms"].isin(MISSING_TIMES).to_numpy()
        values[missing] = math.nan
        with np.errstate(invalid="ignore"):
            bad = ~(np.isfinite(values) & (values >= 0)) & ~missing
        if bad.any():
            at = int(np.argmax(bad))
            row = frame.iloc[at]
            self._problem(2, f"{self._where(row, trial.iloc[at])}: rt_ms '{row.rt_ms}' is not "
                             f"a number of milliseconds >= 0 (or empty: not measured)")
        return values

    def _correct(self, frame: pd.DataFrame, trial: pd.Series) -> np.ndarray:
        judged = (frame["question"].isin(self.recognition)
                  & frame["phase"].isin(_ANALYSED_PHASES)).to_numpy()
        text = frame["correct"]
        free_ok = text.isin(("1", "0", "")).to_numpy()
        right = np.where(frame["answer"].to_numpy() == frame["pen"].to_numpy(), "1", "0")
        judged_ok = text.to_numpy() == right
        bad = np.where(judged, ~judged_ok, ~free_ok)
        if bad.any():
            at = int(np.argmax(bad))
            row = frame.iloc[at]
            where = self._where(row, trial.iloc[at])
            if judged[at]:
                self._problem(3, f"{where}: correct '{row.correct}' disagrees with the answer "
                                 f"'{row.answer}' to {row.question} for pen '{row.pen}' "
                                 f"(expected {right[at]})")
            else:
                self._problem(3, f"{where}: correct '{row.correct}' must be 1, 0 or empty")
        values = np.full(len(frame), math.nan)
        values[text.to_numpy() == "1"] = 1.0
        values[text.to_numpy() == "0"] = 0.0
        values[judged] = (right[judged] == "1").astype(float)
        return values

    def _ratings(self, frame: pd.DataFrame, trial: pd.Series) -> np.ndarray:
        """Likert answers: plain whole numbers on the question's scale (NaN elsewhere)."""
        values = np.full(len(frame), math.nan)
        questions = frame["question"]
        first: tuple[int, str] | None = None  # the chunk's first bad rating, over questions
        for question_id, question in self.likert.items():
            rows = np.flatnonzero((questions == question_id).to_numpy())
            if not len(rows):
                continue
            answers = frame["answer"].iloc[rows]
            empty = (answers == "").to_numpy() & (not question.required)
            plain = answers.str.fullmatch(_PLAIN_INTEGER).fillna(False).to_numpy(dtype=bool)
            numbers = pd.to_numeric(answers.where(plain, "0")).to_numpy(dtype=float)
            inside = plain & (numbers >= 1) & (numbers <= question.points)
            bad = ~inside & ~empty
            if bad.any() and (first is None or rows[int(np.argmax(bad))] < first[0]):
                at = rows[int(np.argmax(bad))]
                row = frame.iloc[at]
                why = "" if plain[int(np.argmax(bad))] else " (a plain whole number)"
                first = (at, f"{self._where(row, trial.iloc[at])}: {row.question} answer "
                             f"'{row.answer}' is not a rating from 1 to {question.points}{why}")
            values[rows[inside]] = numbers[inside]
        if first is not None:
            self._problem(4, first[1])
        return values


def _joined(chunks: list[pd.DataFrame]) -> pd.DataFrame:
    """The chunks as one frame, each text column one categorical (sorted categories, so its
    order is the text's)."""
    if len(chunks) == 1:
        frame = chunks[0]
        parts = {column: [frame[column]] for column in frame.columns}
    else:
        parts = {column: [chunk[column] for chunk in chunks] for column in chunks[0].columns}
    joined = {}
    for column, pieces in parts.items():
        if isinstance(pieces[0].dtype, pd.CategoricalDtype):
            joined[column] = union_categoricals(pieces, sort_categories=True)
        else:
            joined[column] = np.concatenate([piece.to_numpy() for piece in pieces])
    return pd.DataFrame(joined)


def _check_keys(source: str, frame: pd.DataFrame) -> None:
    """One session per participant, one answer per trial and question: merged exports must not
    pool two people under one code, nor count an answer twice. A trial is known by its number
    within its block (:data:`ANSWER_KEY`), as other software may number trials per block."""
    sessions = frame.groupby("participant", sort=False, observed=True)["session"].unique()
    for participant, found in sessions.items():
        if len(found) > 1:
            raise fail(source, f"participant {participant} has answers in {len(found)} sessions "
                               f"({', '.join(map(str, found[:4]))}): give every participant "
                               f"their own code")
    repeated = frame[frame.duplicated(list(ANSWER_KEY), keep=False)]
    if not repeated.empty:
        first = repeated.iloc[0]
        same = np.logical_and.reduce([(repeated[column] == first[column]).to_numpy()
                                      for column in ANSWER_KEY])
        lines = repeated[same]["line"].tolist()
        raise fail(source, f"lines {', '.join(map(str, lines[:4]))}: participant "
                           f"{first.participant} answers {first.question} of trial "
                           f"{first.trial} {len(lines)} times")


def _where(source: str, row) -> str:
    return f"{source}: line {row.line}: participant {row.participant}, trial {row.trial}"


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
        raw = list(dict.fromkeys((t.condition, t.modality, t.pen) for t in trials))
        cells = [(condition or NO_CONDITION, modality, pen) for condition, modality, pen in raw]
        factors, nested, constant, averaged = _structure(cells)
        indices = [FACTOR_COLUMNS.index(name) for name in factors]
        planned = tuple(dict.fromkeys(tuple(cell[i] for i in indices) for cell in cells))
        levels = {name: tuple(dict.fromkeys(cell[i] for cell in cells))
                  for name, i in zip(factors, indices)}
        levels = {name: _design_order(design, name, values) for name, values in levels.items()}
        allowed = {name: tuple(dict.fromkeys(cell[i] for cell in raw))
                   for i, name in enumerate(FACTOR_COLUMNS)}
        # Several recognition questions each get their own outcome names.
        suffix = f":{question.id}" if len(recognitions) > 1 else ""
        if question.type == "likert":
            found.append(Outcome(question.id, "likert", question.id, tuple(factors), levels,
                                 "points", question.points, planned, allowed, nested, constant,
                                 averaged))
        elif question.correct == "pen":
            found.append(Outcome(RECOGNITION + suffix, "recognition", question.id,
                                 tuple(factors), levels, "%", 0, planned, allowed, nested,
                                 constant, averaged))
            found.append(Outcome(LOG_RT + suffix, "log_rt", question.id, tuple(factors), levels,
                                 "ms", 0, planned, allowed, nested, constant, averaged))
    return found


def _fixes(cells: list[tuple[str, ...]], by: int, of: int) -> bool:
    """Whether each level of column ``by`` comes with one level of column ``of`` only."""
    seen: dict[str, str] = {}
    return all(seen.setdefault(cell[by], cell[of]) == cell[of] for cell in cells)


def _names_crossed_cells(cells: list[tuple[str, ...]], condition: int, others: list[int]) -> bool:
    """Whether each condition is one combination of the ``others`` columns and back, and every
    combination of theirs is planned (the conditions only name a crossed design's cells)."""
    of_condition: dict[str, tuple[str, ...]] = {}
    of_combination: dict[tuple[str, ...], str] = {}
    for cell in cells:
        combination = tuple(cell[i] for i in others)
        if of_condition.setdefault(cell[condition], combination) != combination or \
                of_combination.setdefault(combination, cell[condition]) != cell[condition]:
            return False
    full = math.prod(len({cell[i] for cell in cells}) for i in others)
    return len(of_combination) == full


def _structure(cells: list[tuple[str, ...]]
               ) -> tuple[list[str], dict[str, str], dict[str, str], tuple[str, ...]]:
    """An outcome's ``(factors, nested, constant, averaged)`` from its planned
    ``(condition, modality, pen)`` cells (see :class:`Outcome`).

    A column whose level another column fixes is nested in that one, not a factor of its own
    (between two that fix each other, the earlier of :data:`FACTOR_COLUMNS` stays the factor);
    the factors left must then be crossed, every combination planned, or those after the first
    are averaged over.

    >>> _structure([("own", "tactile", "own"), ("ref", "tactile", "bp")])
    (['condition'], {'pen': 'condition'}, {'modality': 'tactile'}, ())
    >>> _structure([("tactile", "tactile", p) for p in "ab"] + [("auditory", "auditory", p)
    ...            for p in "ab"])
    (['modality', 'pen'], {}, {}, ())
    >>> _structure([("c1", "tactile", "a"), ("c2", "auditory", "a"), ("c3", "tactile", "b"),
    ...             ("c4", "auditory", "b")])
    (['modality', 'pen'], {'condition': 'modality × pen'}, {}, ())
    """
    varying = [i for i in range(len(FACTOR_COLUMNS)) if len({cell[i] for cell in cells}) > 1]
    constant = {FACTOR_COLUMNS[i]: cells[0][i] for i in range(len(FACTOR_COLUMNS))
                if i not in varying}
    condition, modality = FACTOR_COLUMNS.index("condition"), FACTOR_COLUMNS.index("modality")
    if condition in varying and modality in varying and \
            all(cell[condition] == cell[modality] for cell in cells):
        varying.remove(condition)  # a block over modalities names its level twice
    nested: dict[str, str] = {}
    others = [i for i in varying if i != condition]
    if condition in varying and len(others) >= 2 and _names_crossed_cells(cells, condition,
                                                                           others):
        # conditions written one per cell of a crossed design (tactile+pencil, tactile+marker,
        # …): the crossed columns are the factors, so their interaction is tested too
        varying.remove(condition)
        nested[FACTOR_COLUMNS[condition]] = " × ".join(FACTOR_COLUMNS[i] for i in others)
    for first, second in itertools.combinations(list(varying), 2):
        if first not in varying or second not in varying:
            continue
        if _fixes(cells, first, second):
            varying.remove(second)
            nested[FACTOR_COLUMNS[second]] = FACTOR_COLUMNS[first]
        elif _fixes(cells, second, first):
            varying.remove(first)
            nested[FACTOR_COLUMNS[first]] = FACTOR_COLUMNS[second]
    combinations = {tuple(cell[i] for i in varying) for cell in cells}
    full = math.prod(len({cell[i] for cell in cells}) for i in varying)
    averaged: tuple[str, ...] = ()
    if len(combinations) < full:
        averaged = tuple(FACTOR_COLUMNS[i] for i in varying[1:])
        varying = varying[:1]
    return [FACTOR_COLUMNS[i] for i in varying], nested, constant, averaged


def factor_text(outcome: Outcome) -> str:
    """How ``outcome``'s factors were found and are treated, in one sentence for the report.

    >>> from realpen.study.design import load_design
    >>> factor_text(outcomes(load_design("study2"))[0])
    'recognition: modality (3 levels) × pen (3 levels), crossed within participants'
    >>> factor_text(outcomes(load_design("study1"))[0])
    'Q1: condition (6 levels) within participants; modality constant (tactile), pen constant (ballpoint)'
    """
    sizes = [f"{name} ({len(outcome.levels[name])} levels)" for name in outcome.factors]
    if not sizes:
        text = f"{outcome.name}: no within factor (one cell)"
    elif len(sizes) == 1:
        text = f"{outcome.name}: {sizes[0]} within participants"
        if len(outcome.levels[outcome.factors[0]]) == 2 and outcome.kind == "likert":
            text += " (two levels: the Wilcoxon signed-rank test of the pair, not a Friedman test)"
    else:
        text = f"{outcome.name}: {' × '.join(sizes)}, crossed within participants"
    for name, by in outcome.nested.items():
        if " × " in by:
            text += f"; each {name} is one {by} cell: the crossed factors are tested, not {name}"
        else:
            text += (f"; {name} nested in {by} (each {by} fixes its {name}): not a factor of "
                     f"its own")
    if outcome.averaged:
        text += (f"; {', '.join(outcome.averaged)} varies within {outcome.factors[0]} but is "
                 f"not crossed with it (not every combination is planned): each participant's "
                 f"value is averaged over it")
    shown = {name: level for name, level in outcome.constant.items() if level != NO_CONDITION}
    if shown:
        text += "; " + ", ".join(f"{name} constant ({level})" for name, level in shown.items())
    return text


def _check_times(trials: Trials, outcome: Outcome, rows: pd.DataFrame) -> None:
    """The response-time analysis needs a time on every trial it analyses: refuse, in one line
    naming the first lines and their count, the rows without one."""
    missing = rows.loc[rows["rt_ms"].isna(), "line"]
    if missing.empty:
        return
    first = ", ".join(str(line) for line in missing.iloc[:5])
    more = f" and {len(missing) - 5} more" if len(missing) > 5 else ""
    raise fail(trials.source, f"line{'s' if len(missing) > 1 else ''} {first}{more}: no rt_ms "
                              f"on {len(missing)} answer{'s' if len(missing) > 1 else ''} to "
                              f"{outcome.question}, whose response times the {outcome.name} "
                              f"analysis needs (give the time in ms)")


def _design_order(design: Design, factor: str, values: tuple[str, ...]) -> tuple[str, ...]:
    known = {"condition": [c.id for c in design.conditions], "modality": design.modalities,
             "pen": [p.id for p in design.pens]}[factor]
    return tuple(sorted(values, key=lambda v: known.index(v) if v in known else len(known)))


def outcome_rows(trials: Trials, outcome: Outcome) -> pd.DataFrame:
    """The answers to ``outcome``'s question, each checked to be at a planned level, with the
    empty ``condition`` of trials outside a block over conditions as :data:`NO_CONDITION`
    where that is a level of the outcome's factor.

    Raises:
        RealPenError: an answer at a level the design does not plan for the question (one line
            naming the file, the line, the participant and the trial).
    """
    rows = trials.frame[trials.frame["question"] == outcome.question]
    for column, values in outcome.allowed.items():
        stray = rows[~rows[column].isin(values)]
        if not stray.empty:
            row = stray.iloc[0]
            raise fail(_where(trials.source, row), f"{column} '{row[column]}' is not planned for "
                                                   f"{outcome.question} (the design's: "
                                                   f"{', '.join(values)})")
    if NO_CONDITION in outcome.levels.get("condition", ()):
        rows = rows.assign(condition=rows["condition"].astype(str).replace("", NO_CONDITION))
    return rows


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
    rows = outcome_rows(trials, outcome)
    factors = list(outcome.factors)
    if outcome.kind == "likert":
        rows = rows[rows["value"].notna()]
        column = "value"
    elif outcome.kind == "recognition":
        rows = rows[rows["correct"].notna()]
        column = "correct"
    else:
        _check_times(trials, outcome, rows)
        # A 0 ms response time has no logarithm; analyse() notes how many were left out.
        rows = rows[rows["rt_ms"] > 0].assign(log_rt=lambda f: np.log(f["rt_ms"]))
        column = "log_rt"
    grouped = (rows.groupby(["participant", *factors], sort=False, observed=True)[column]
               .agg(["mean", "size"]).reset_index()
               .rename(columns={"mean": "value", "size": "trials"}))
    incomplete: dict[str, str] = {}
    keep: list[str] = []
    # Which participants have each planned cell: one pass over the grouped rows, not one
    # search of them per participant.
    if factors:
        texts = grouped[factors].astype(str)
        keys = pd.Series(list(zip(*(texts[name] for name in factors))), index=grouped.index)
    else:
        keys = pd.Series([()] * len(grouped), index=grouped.index, dtype=object)
    having: dict[tuple[str, ...], set[str]] = {cell: set() for cell in outcome.cells}
    for participant, key in zip(grouped["participant"].astype(str), keys):
        if key in having:
            having[key].add(participant)
    for participant in trials.participants:
        missing = [cell for cell in outcome.cells if participant not in having[cell]]
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
        values = values[[key in planned for key in keys[values.index]]].copy()
        for name in factors:  # design order, which the tests and figures keep
            values[name] = pd.Categorical(values[name].astype(str),
                                          categories=list(outcome.levels[name]))
    return values.reset_index(drop=True), incomplete

