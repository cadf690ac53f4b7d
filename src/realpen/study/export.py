"""Export a store's studies for analysis: one CSV row per answer, a JSON sidecar, the strokes.

:func:`export_trials` writes

- the trials CSV: one row per answer of every answered trial, columns :data:`CSV_COLUMNS` —
  first exactly ``study, participant, session, block, trial, phase, condition, modality, pen,
  question, answer, correct, rt_ms`` (the order the statistics rely on), then ``site,
  started_at, answered_at``, then ``age, gender, handedness, repetition, ink,
  design_version``. Rows are ordered by study (the design's name), participant (the code the
  operator typed), session, trial, and within a trial by the order of the trial's questions in
  its plan. ``correct`` is ``1``/``0`` for recognition questions and empty otherwise;
  ``rt_ms`` (ms from the trial's start to the answer, as the page measured it) has three
  decimals; ``started_at`` is the trial's start, ``answered_at`` minus ``rt_ms`` (the page's
  own measure, not the session's start); times are ISO 8601 in UTC with milliseconds;
  ``session_state`` is the session's state (``abandoned``: a participant who did not finish);
- its JSON sidecar beside it (``trials.json`` for ``trials.csv``, as BIDS does for events
  files): every column with its ``Description``, ``Units`` where it has one and ``Levels`` for
  the categorical ones (from the designs and trials present), what generated the file, from
  which store (password hidden), when, and the designs (name, version) included;
- optionally the strokes CSV (:data:`STROKE_COLUMNS`, one row per pen sample of the strokes
  drawn in a study session, keyed by session and trial) and its own sidecar;
- optionally the sessions CSV (:data:`SESSION_COLUMNS`, one row per session, answered or not)
  and its own sidecar.

Pilot sessions are left out of every file unless ``include_pilot`` is given; then each file
has a last column ``pilot`` (``1`` for a pilot session, ``0`` for the others). A withdrawn
participant's session has no answers or strokes left (:func:`realpen.study.admin.withdraw`):
it is only in the sessions CSV, as a record with state ``withdrawn`` and no data.

The store is read in one read transaction: a consistent snapshot (what a server commits
meanwhile is in none of the files) that never blocks the live server's writes (SQLite's WAL
journal, PostgreSQL's MVCC); the export takes no writer's lock, so it runs while ``realpen
serve`` writes. Reading never changes a store: one from before the studies (an older
RealPen's) is refused in one line that says to start ``realpen serve`` on it once. Every file
is written atomically: a failure leaves none of them behind, and leaves earlier files of
those names as they were.
"""

from __future__ import annotations

import contextlib
import csv
import json
import os
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import TYPE_CHECKING, Any

from realpen.errors import RealPenError, fail
from realpen.io.files import atomic_path, json_text
from realpen.io.strokes import SAMPLE_FIELDS

if TYPE_CHECKING:
    from realpen.study.db import Database

__all__ = ["export_trials", "ExportSummary", "KEY_COLUMNS", "TIME_COLUMNS", "EXTRA_COLUMNS",
           "CSV_COLUMNS", "STROKE_COLUMNS", "SESSION_COLUMNS", "PILOT_COLUMN", "sidecar_path"]

KEY_COLUMNS = ("study", "participant", "session", "block", "trial", "phase", "condition",
               "modality", "pen", "question", "answer", "correct", "rt_ms")
"""The first columns of the trials CSV, exactly in this order."""
TIME_COLUMNS = ("site", "started_at", "answered_at")
"""The columns after :data:`KEY_COLUMNS`."""
EXTRA_COLUMNS = ("age", "gender", "handedness", "repetition", "ink", "design_version",
                 "session_state")
"""The last columns: demographics, more of the trial and its design, the session's state."""
CSV_COLUMNS = KEY_COLUMNS + TIME_COLUMNS + EXTRA_COLUMNS
STROKE_COLUMNS = ("session", "trial", "stroke", "sample", "pen", "modality") + SAMPLE_FIELDS
"""The columns of the strokes CSV: one row per pen sample."""
SESSION_COLUMNS = ("study", "participant", "session", "state", "index", "seed", "site",
                   "started_at", "finished_at", "withdrawn_at", "trials", "answered",
                   "design_version")
"""The columns of the sessions CSV: one row per session."""
PILOT_COLUMN = "pilot"
"""The column every file gains (last) when pilot sessions are included: 1 pilot, 0 not."""

_JOURNAL_SUFFIXES = ("", "-wal", "-shm", "-journal")
_MODALITIES = {
    "tactile": "tactile feedback only (the pen's actuator)",
    "auditory": "sound only",
    "audio-tactile": "sound and tactile feedback together",
    "auditory-tactile": "sound and tactile feedback together",
    "none": "no feedback",
}
_PHASES = {
    "training": "a training trial (not analysed as an outcome)",
    "experimental": "an experimental trial",
    "questionnaire": "a questionnaire after a block (rating scales, free text)",
}


@dataclass(frozen=True)
class ExportSummary:
    """What :func:`export_trials` wrote.

    Attributes:
        rows: answer rows in the trials CSV.
        sessions: sessions with at least one answer exported.
        participants: participants with at least one answer exported.
        strokes: strokes in the strokes CSV (0 when none was asked for).
        samples: sample rows in the strokes CSV.
        paths: every file written: the trials CSV, its sidecar, then the strokes CSV and its
            sidecar, then the sessions CSV and its sidecar, when asked for.
        session_rows: rows in the sessions CSV (0 when none was asked for).
    """

    rows: int
    sessions: int
    participants: int
    strokes: int
    samples: int
    paths: tuple[Path, ...]
    session_rows: int = 0


def sidecar_path(csv_path: str | os.PathLike) -> Path:
    """The JSON sidecar of a CSV: the same name with ``.json`` (``trials.csv`` → ``trials.json``)."""
    return Path(csv_path).with_suffix(".json")


# ---- opening the store -----------------------------------------------------------------------

def _open(target: str | os.PathLike) -> Database:
    """Open an existing store (never create one) as a reader: without the writer's lock, and
    as it is (a store from before the studies is refused in one line)."""
    from realpen.study.db import open_database

    database = open_database(target, create=False, lock=False)
    if database.revision in (None, "0001"):  # reading never migrates: say how to upgrade
        database.close()
        raise fail(database.display, "the store is older than RealPen's studies; start "
                                     "realpen serve on it once to upgrade it")
    return database


def _check_outputs(target: str | os.PathLike, outputs: list[Path]) -> None:
    """Refuse an output that is the store (or one of its journal files), or two equal ones."""
    from realpen.study.db import store_file

    store = store_file(target)
    for index, out in enumerate(outputs):
        if store is not None:
            for suffix in _JOURNAL_SUFFIXES:
                if _same(out, Path(f"{store}{suffix}")):
                    what = "the store itself" if not suffix else f"the store's {suffix} file"
                    raise fail(out, f"is {what}; give another file name to write")
        if any(_same(out, other) for other in outputs[:index]):
            raise fail(out, "would be written twice (a CSV and a sidecar, or the trials and the "
                            "strokes, share this name); name the files apart")


def _same(a: Path, b: Path) -> bool:
    """Whether two paths name one file: the same path once symbolic links and ``..`` are
    followed, or (both existing) the same file on disk (hard links)."""
    if os.path.realpath(a) == os.path.realpath(b):
        return True
    try:
        return a.exists() and b.exists() and os.path.samefile(a, b)
    except OSError:
        return False


@contextlib.contextmanager
def _snapshot(store: Database) -> Iterator[Any]:
    """A connection in one read transaction: every query sees the same committed state.

    PostgreSQL: REPEATABLE READ, READ ONLY (one snapshot for the whole export; MVCC: no lock a
    writer waits for). SQLite: the store's engine begins a deferred transaction for a reader
    (:mod:`realpen.study.db`), whose snapshot the WAL journal keeps while the server commits.
    """
    with store.engine.connect() as connection:
        if store.dialect == "postgresql":
            connection = connection.execution_options(isolation_level="REPEATABLE READ",
                                                      postgresql_readonly=True)
        with connection.begin():
            yield connection


# ---- the designs -----------------------------------------------------------------------------

def _design_data(text: str) -> Mapping[str, Any]:
    """The design stored with a study as plain data (:meth:`Design.to_json`'s fields). A design
    this RealPen cannot validate (an older format) is read as plain JSON, an unreadable one as
    nothing: the export still writes every row, with fewer descriptions."""
    from realpen.study.design import Design

    try:
        return Design.from_json(text).model_dump(mode="json")
    except (RealPenError, ValueError, TypeError):
        pass
    try:
        data = json.loads(text)
    except (TypeError, ValueError):
        return {}
    return data if isinstance(data, Mapping) else {}


def _entries(data: Mapping[str, Any], field: str) -> list[Mapping[str, Any]]:
    """A design's list of things with an ``id`` (pens, conditions, questions); a pen may be
    given by its id alone."""
    value = data.get(field)
    if not isinstance(value, list):
        return []
    entries = [{"id": entry} if isinstance(entry, str) else entry for entry in value]
    return [entry for entry in entries if isinstance(entry, Mapping) and isinstance(entry.get("id"), str)]


def _question_text(question: Mapping[str, Any]) -> str:
    """A question's text and its answers: ``"Is it comfortable to write? (5-point: 1 = not at
    all … 5 = very much)"``, ``"Which pen was it? (one of pencil, ballpoint, marker)"``."""
    text = str(question.get("text") or "").strip()
    kind, points, anchors = question.get("type"), question.get("points"), question.get("anchors")
    if kind == "likert":
        labels = sorted(anchors.items(), key=lambda item: int(item[0])) \
            if isinstance(anchors, Mapping) and all(str(k).isdecimal() for k in anchors) else []
        scale = " … ".join(f"{point} = {label}" for point, label in labels)
        answers = f"{points}-point" + (f": {scale}" if scale else "")
    elif kind == "choice" and isinstance(question.get("choices"), list):
        answers = "one of " + ", ".join(map(str, question["choices"]))
    elif kind == "text":
        answers = "free text"
    else:
        answers = str(kind or "")
    return f"{text} ({answers})" if text and answers else text or answers


def _question_details(question: Mapping[str, Any]) -> dict[str, Any]:
    """What the sidecar tells of one question: its type, text, scale or choices, and how an
    answer is judged right."""
    names = {"type": "Type", "text": "Text", "points": "Points", "anchors": "Anchors",
             "choices": "Choices", "correct": "Correct", "required": "Required",
             "modalities": "Modalities"}
    return {name: question[key] for key, name in names.items() if question.get(key) is not None}


def _question_ids(plan_text: str | None) -> list[str]:
    """The ids of a planned trial's questions, in the order the participant answers them."""
    try:
        plan = json.loads(plan_text) if plan_text else {}
    except ValueError:
        return []
    questions = plan.get("questions") if isinstance(plan, Mapping) else None
    return [q for q in questions if isinstance(q, str)] if isinstance(questions, list) else []


# ---- reading ---------------------------------------------------------------------------------

def _studies(connection, store: Database, design: str | None) -> list[Any]:
    from sqlalchemy import select

    from realpen.study import tables as t  # sqlalchemy's tables: loaded with the queries

    rows = connection.execute(select(t.studies.c.id, t.studies.c.name, t.studies.c.version,
                                     t.studies.c.design).order_by(t.studies.c.id)).all()
    if design is not None:
        chosen = [row for row in rows if row.name == design]
        if not chosen:
            names = sorted({row.name for row in rows})
            held = f"it holds {', '.join(names)}" if names else "it holds no study"
            raise fail(store.display, f"no study of the design {design!r} in this store ({held})")
        rows = chosen
    return rows


@dataclass(frozen=True)
class _Sessions:
    """Which sessions' data an export writes, on the schema the store has.

    Attributes:
        administered: the store has the administration columns (``pilot``, ``withdrawn_at``;
            revision 0003 on): an older one is read as it is, with neither pilots nor
            withdrawals.
        include_pilot: pilot sessions are written (with the ``pilot`` column).
    """

    administered: bool
    include_pilot: bool

    def pilot(self):
        """The ``pilot`` column as a select expression (false on an older schema)."""
        from sqlalchemy import false

        from realpen.study import tables as t

        return (t.sessions.c.pilot if self.administered else false()).label("pilot")

    def kept(self, with_withdrawn: bool = False) -> list:
        """The WHERE clauses that keep the sessions this export writes."""
        from sqlalchemy import false

        from realpen.study import tables as t

        clauses = [] if with_withdrawn else [t.sessions.c.state != "withdrawn"]
        if self.administered and not self.include_pilot:
            clauses.append(t.sessions.c.pilot == false())
        return clauses


def _answer_rows(connection, study_ids: list[int], chosen: _Sessions) -> list[dict[str, Any]]:
    """Every answer of the answered trials of these studies' chosen sessions, with its trial,
    session, participant and study, in the export's order."""
    from sqlalchemy import select

    from realpen.study import tables as t

    if not study_ids:
        return []
    s, p, st, tr, a = t.sessions, t.participants, t.studies, t.trials, t.answers
    query = (
        select(st.c.name.label("study"), st.c.version.label("design_version"),
               p.c.code.label("participant"), p.c.age, p.c.gender, p.c.handedness,
               p.c.site.label("participant_site"), s.c.id.label("session"),
               s.c.site.label("session_site"), tr.c.n.label("trial"), tr.c.block, tr.c.phase,
               tr.c.condition, tr.c.modality, tr.c.pen, tr.c.ink, tr.c.repetition, tr.c.plan,
               tr.c.answered_at, tr.c.rt_ms, a.c.question, a.c.answer, a.c.correct,
               s.c.state.label("session_state"), chosen.pilot())
        .select_from(a.join(tr, (tr.c.session_id == a.c.session_id) & (tr.c.n == a.c.n))
                     .join(s, s.c.id == tr.c.session_id)
                     .join(p, p.c.id == s.c.participant_id)
                     .join(st, st.c.id == s.c.study_id))
        .where(s.c.study_id.in_(study_ids), tr.c.answered_at.is_not(None), *chosen.kept())
    )
    rows = [dict(row._mapping) for row in connection.execute(query)]
    orders: dict[tuple[int, int], dict[str, int]] = {}
    for row in rows:
        key = (row["session"], row["trial"])
        if key not in orders:
            orders[key] = {qid: i for i, qid in enumerate(_question_ids(row["plan"]))}
    late = 1 << 30  # answers to questions missing from the plan go last, by name
    # Sorted here, not in SQL: text collation differs between SQLite and PostgreSQL.
    rows.sort(key=lambda r: (r["study"], r["participant"], r["session"], r["trial"],
                             orders[r["session"], r["trial"]].get(r["question"], late),
                             r["question"]))
    return rows


def _start_of(answered_at: str | None, rt_ms: float | None) -> str:
    """The trial's start (ISO 8601 UTC, ms): the answer's time minus the response time."""
    if not answered_at or rt_ms is None:
        return ""
    try:
        answered = datetime.fromisoformat(answered_at)
    except ValueError:
        return ""
    if answered.tzinfo is None:  # the store writes UTC; a time without its zone is UTC too
        answered = answered.replace(tzinfo=UTC)
    start = answered.astimezone(UTC) - timedelta(milliseconds=rt_ms)
    # To the nearest ms (isoformat would cut the digits off).
    start = start.replace(microsecond=0) + timedelta(milliseconds=round(start.microsecond / 1000))
    return start.isoformat(timespec="milliseconds")


def _csv_row(row: Mapping[str, Any], columns: tuple[str, ...]) -> list[Any]:
    correct = row["correct"]
    rt = row["rt_ms"]
    values = {
        **row,
        "site": row["session_site"] or row["participant_site"] or "",
        "correct": "" if correct is None else int(bool(correct)),
        "rt_ms": "" if rt is None else f"{rt:.3f}",
        "started_at": _start_of(row["answered_at"], rt),
        PILOT_COLUMN: int(bool(row["pilot"])),
    }
    return ["" if values[name] is None else values[name] for name in columns]


def _session_rows(connection, study_ids: list[int], chosen: _Sessions) -> list[dict[str, Any]]:
    """One row per chosen session of these studies (withdrawn ones too: their record), with
    its trial and answer counts, in the export's order."""
    from sqlalchemy import func, literal, select

    from realpen.study import tables as t

    if not study_ids:
        return []
    s, p, st, tr = t.sessions, t.participants, t.studies, t.trials
    counts = (select(tr.c.session_id, func.count().label("trials"),
                     func.count(tr.c.answered_at).label("answered"))
              .group_by(tr.c.session_id).subquery())
    withdrawn_at = s.c.withdrawn_at if chosen.administered else literal(None)
    query = (
        select(st.c.name.label("study"), st.c.version.label("design_version"),
               p.c.code.label("participant"), s.c.id.label("session"), s.c.state,
               s.c.plan_index.label("index"), s.c.seed, s.c.site.label("session_site"),
               p.c.site.label("participant_site"), s.c.started_at, s.c.finished_at,
               withdrawn_at.label("withdrawn_at"),
               func.coalesce(counts.c.trials, 0).label("trials"),
               func.coalesce(counts.c.answered, 0).label("answered"), chosen.pilot())
        .select_from(s.join(p, p.c.id == s.c.participant_id).join(st, st.c.id == s.c.study_id)
                     .outerjoin(counts, counts.c.session_id == s.c.id))
        .where(s.c.study_id.in_(study_ids), *chosen.kept(with_withdrawn=True))
    )
    rows = [dict(row._mapping) for row in connection.execute(query)]
    rows.sort(key=lambda r: (r["study"], r["participant"], r["session"]))
    return rows


def _session_csv_row(row: Mapping[str, Any], columns: tuple[str, ...]) -> list[Any]:
    values = {**row, "site": row["session_site"] or row["participant_site"] or "",
              PILOT_COLUMN: int(bool(row["pilot"]))}
    return ["" if values[name] is None else values[name] for name in columns]


def _sample_rows(connection, study_ids: list[int], chosen: _Sessions) -> Iterable[Any]:
    from sqlalchemy import case, func, select

    from realpen.defaults import OLD_MODALITY_NAMES
    from realpen.study import tables as t

    if not study_ids:
        return []
    k, m, s = t.strokes, t.samples, t.sessions
    query = (
        # strokes stored by an earlier release may carry a modality's old name
        select(k.c.study_session, k.c.trial, k.c.id, m.c.seq, k.c.pen,
               case(OLD_MODALITY_NAMES, value=k.c.modality, else_=k.c.modality),
               *(m.c[name] for name in SAMPLE_FIELDS),
               *([chosen.pilot()] if chosen.include_pilot else []))
        .select_from(m.join(k, k.c.id == m.c.stroke_id).join(s, s.c.id == k.c.study_session))
        .where(s.c.study_id.in_(study_ids), *chosen.kept())
        .order_by(k.c.study_session, func.coalesce(k.c.trial, -1), k.c.id, m.c.seq)
    )
    # Streamed (a server-side cursor on PostgreSQL): a study's samples may not fit in memory.
    return connection.execution_options(stream_results=True, yield_per=10_000).execute(query)


# ---- the sidecars ----------------------------------------------------------------------------

def _distinct(connection, study_ids: list[int], column) -> list[str]:
    """The values of a trials (or answers) column in these studies' sessions, sorted."""
    from sqlalchemy import select

    from realpen.study import tables as t

    if not study_ids:
        return []
    s = t.sessions
    query = select(column).distinct() \
        .select_from(column.table.join(s, s.c.id == column.table.c.session_id)) \
        .where(s.c.study_id.in_(study_ids))
    return sorted(value for value in connection.execute(query).scalars() if value not in (None, ""))


def _described(values: Iterable[str], known: Mapping[str, list[str]], default) -> dict[str, str]:
    """Levels: each value with what the designs say of it (designs that differ: each one)."""
    return {value: "; ".join(known.get(value, [])) or default(value) for value in values}


_STATES = {
    "running": "the session was running when exported",
    "paused": "the operator had paused the session",
    "finished": "the session was finished (every trial answered, or ended by the operator)",
    "abandoned": "the participant left before the end: the answers so far (an incomplete "
                 "participant)",
    "withdrawn": "the participant withdrew consent: their data was deleted (a record only)",
}
_PILOT = {"Description": "Whether the session was a pilot (a try-out of the study, not a "
                         "participant's data): 1 pilot, 0 not. Present only when pilot sessions "
                         "were asked for in the export.",
          "Levels": {"1": "a pilot session", "0": "a participant's session"}}


def _pilot_sidecar(chosen: _Sessions) -> dict[str, Any]:
    return {PILOT_COLUMN: _PILOT} if chosen.include_pilot else {}


def _trials_sidecar(connection, store: Database, studies: list[Any], exported_at: str,
                    rows: int, chosen: _Sessions) -> dict[str, Any]:
    """The trials CSV's sidecar: every column, and the designs' levels of the categorical ones."""
    from realpen.study import tables as t

    ids = [row.id for row in studies]
    pens: dict[str, list[str]] = {}
    conditions: dict[str, list[str]] = {}
    questions: dict[str, list[str]] = {}
    details: dict[str, dict[str, Any]] = {}
    modalities: set[str] = set()

    def note(found: dict[str, list[str]], key: str, text: str) -> None:
        if text and text not in found.setdefault(key, []):
            found[key].append(text)

    for row in studies:
        data = _design_data(row.design)
        for pen in _entries(data, "pens"):
            note(pens, pen["id"], pen.get("label") or f"the {pen.get('profile') or pen['id']} pen "
                                                      f"profile")
        for condition in _entries(data, "conditions"):
            note(conditions, condition["id"], str(condition.get("label") or ""))
        for question in _entries(data, "questions"):
            note(questions, question["id"], _question_text(question))
            details.setdefault(row.name, {})[question["id"]] = _question_details(question)
        modalities.update(m for m in data.get("modalities") or () if isinstance(m, str))
    trial = t.trials.c

    def condition_default(value: str) -> str:
        return f"the {value} modality" if value in _MODALITIES else f"condition {value}"

    return {
        "study": {"Description": "The design's name (the built-in study1 or study2, or a user "
                                 "design's name).",
                  "Levels": {row.name: f"design {row.name}" for row in studies}},
        "participant": {"Description": "The participant's ID as the operator typed it (e.g. "
                                       "P07); unique within a study."},
        "session": {"Description": "The session's id in the store (one session per study and "
                                   "participant); the strokes CSV's 'session'."},
        "block": {"Description": "The block of the trial, as the design labels it (study 1: the "
                                 "condition, or 'comments'; study 2: the modality, or "
                                 "'<modality>/questionnaire')."},
        "trial": {"Description": "The trial's number within its session, from 1, in the order "
                                 "the participant did them; the strokes CSV's 'trial'."},
        "phase": {"Description": "The trial's phase.",
                  "Levels": {phase: _PHASES[phase] for phase in t.PHASES}},
        "condition": {"Description": "The trial's condition (study 2: its modality; empty in a "
                                     "block without conditions).",
                      "Levels": _described(_distinct(connection, ids, trial.condition), conditions,
                                           condition_default)},
        "modality": {"Description": "The feedback the pen gave during the trial.",
                     "Levels": _described(sorted(modalities | set(_distinct(
                         connection, ids, trial.modality))), {}, lambda m: _MODALITIES.get(
                             m, f"modality {m}"))},
        "pen": {"Description": "The trial's pen (the design's pen id).",
                "Levels": _described(sorted(set(pens) | set(_distinct(connection, ids, trial.pen))),
                                     pens, lambda p: f"the {p} pen profile")},
        "question": {"Description": "The question answered (its id in the design). In "
                                    "recognition trials it is 'pen' and the answer the chosen "
                                    "pen.",
                     "Levels": _described(sorted(set(questions) | set(_distinct(
                         connection, ids, t.answers.c.question))), questions, str),
                     "Questions": details},
        "answer": {"Description": "The answer as text: a rating's point (a whole number), the "
                                  "chosen option's id (e.g. the pen), or free text (empty: an "
                                  "optional question left unanswered)."},
        "correct": {"Description": "Whether the answer was right: 1 or 0 for questions with a "
                                   "right answer (recognition), empty for the others.",
                    "Levels": {"1": "right", "0": "wrong"}},
        "rt_ms": {"Description": "Response time: from the trial's start to the answer, as the "
                                 "participant's page measured it (performance.now()); written "
                                 "with 3 decimals.", "Units": "ms"},
        "site": {"Description": "The site (lab) where the session ran, as the operator typed "
                                "it (the participant's when the session has none)."},
        "started_at": {"Description": "The trial's start: answered_at minus rt_ms (the page's "
                                      "own measure of the response time; not the session's "
                                      "start). ISO 8601, UTC, milliseconds.",
                       "Units": "ISO 8601 UTC"},
        "answered_at": {"Description": "When the server received and committed the answer. "
                                       "ISO 8601, UTC, milliseconds.", "Units": "ISO 8601 UTC"},
        "age": {"Description": "The participant's age (empty: not recorded).", "Units": "years"},
        "gender": {"Description": "The participant's gender as recorded (empty: not recorded)."},
        "handedness": {"Description": "The participant's handedness as recorded (empty: not "
                                      "recorded)."},
        "repetition": {"Description": "The trial's repetition number within its group of trials "
                                      "of the same pen, from 0."},
        "ink": {"Description": "How the ink was drawn during the trial.",
                "Levels": {"visible": "the pen's ink was shown",
                           "hidden": "the ink was drawn in the background colour (not seen)"}},
        "design_version": {"Description": "The SHA-256 of the design as run (its canonical JSON): "
                                          "rows with the same design_version ran the same design.",
                           "Levels": {row.version: row.name for row in studies}},
        "session_state": {"Description": "The session's state when exported: an abandoned "
                                         "session's answers are those of a participant who did "
                                         "not finish.",
                          "Levels": {state: _STATES[state] for state in t.SESSION_STATES
                                     if state != "withdrawn"}},
        **_pilot_sidecar(chosen),
        **_provenance(store, studies, exported_at, "realpen study export"),
        "Rows": rows,
    }


def _provenance(store: Database, studies: list[Any], exported_at: str, command: str) -> dict:
    return {"GeneratedBy": [{"Name": "RealPen", "Version": _realpen_version(),
                             "Description": command}],
            "Store": store.display,
            "ExportedAt": exported_at,
            "Designs": [{"Name": row.name, "Version": row.version} for row in studies]}


def _sessions_sidecar(store: Database, studies: list[Any], exported_at: str, rows: int,
                      chosen: _Sessions) -> dict[str, Any]:
    from realpen.study import tables as t

    return {
        "study": {"Description": "The design's name (the trials CSV's 'study')."},
        "participant": {"Description": "The participant's ID as the operator typed it; "
                                       "'withdrawn-<session>' once the participant withdrew."},
        "session": {"Description": "The session's id in the store (the trials CSV's "
                                   "'session')."},
        "state": {"Description": "The session's state.",
                  "Levels": {state: _STATES[state] for state in t.SESSION_STATES}},
        "index": {"Description": "The plan row the session ran (0-based): its counterbalanced "
                                 "order. A pilot's or a withdrawn session's row is free for a "
                                 "participant."},
        "seed": {"Description": "The seed of the session's plan."},
        "site": {"Description": "The site (lab) where the session ran."},
        "started_at": {"Description": "When the session was made. ISO 8601, UTC, milliseconds.",
                       "Units": "ISO 8601 UTC"},
        "finished_at": {"Description": "When the session finished or was abandoned (empty: it "
                                       "has not ended, or was withdrawn before it ended). ISO "
                                       "8601, UTC, milliseconds.", "Units": "ISO 8601 UTC"},
        "withdrawn_at": {"Description": "When the participant withdrew consent (empty: they "
                                        "did not). ISO 8601, UTC, milliseconds.",
                         "Units": "ISO 8601 UTC"},
        "trials": {"Description": "The session's planned trials (0 once withdrawn)."},
        "answered": {"Description": "Its answered trials (0 once withdrawn)."},
        "design_version": {"Description": "The SHA-256 of the design as run (its canonical JSON).",
                           "Levels": {row.version: row.name for row in studies}},
        **_pilot_sidecar(chosen),
        **_provenance(store, studies, exported_at, "realpen study export, sessions file"),
        "Rows": rows,
    }


def _strokes_sidecar(store: Database, studies: list[Any], exported_at: str, strokes: int,
                     samples: int, chosen: _Sessions) -> dict[str, Any]:
    return {
        "session": {"Description": "The study session the stroke was drawn in (the 'session' "
                                   "column of the trials CSV)."},
        "trial": {"Description": "The trial the stroke was drawn in (the 'trial' column of the "
                                 "trials CSV; empty: between trials)."},
        "stroke": {"Description": "The stroke's id in the store."},
        "sample": {"Description": "The sample's number within its stroke, from 0."},
        "pen": {"Description": "The pen profile that rendered the stroke."},
        "modality": {"Description": "The feedback the pen gave while drawing the stroke."},
        "t": {"Description": "Time since pen down.", "Units": "s"},
        "x": {"Description": "Position across the writing surface, from its left edge.",
              "Units": "mm"},
        "y": {"Description": "Position down the writing surface, from its top edge.",
              "Units": "mm"},
        "pressure": {"Description": "Normalised pen pressure, 0–1 (0: lifted; a mouse reports "
                                    "0.5).", "Units": "arbitrary (0–1)"},
        "tilt_x": {"Description": "Pen tilt across (Pointer Events tiltX), -90–90.",
                   "Units": "degrees"},
        "tilt_y": {"Description": "Pen tilt down (Pointer Events tiltY), -90–90.",
                   "Units": "degrees"},
        "speed": {"Description": "Pen speed as the page measured it (over 20 ms).",
                  "Units": "mm/s"},
        **_pilot_sidecar(chosen),
        **_provenance(store, studies, exported_at, "realpen study export, strokes file"),
        "Strokes": strokes,
        "Rows": samples,
    }


def _realpen_version() -> str:
    from realpen._version import __version__

    return __version__


# ---- the export ------------------------------------------------------------------------------

def export_trials(target: str | os.PathLike, output: str | os.PathLike, *,
                  design: str | None = None,
                  strokes: str | os.PathLike | None = None,
                  sessions: str | os.PathLike | None = None,
                  include_pilot: bool = False) -> ExportSummary:
    """Write a store's answers as CSV (one row per answer) with a JSON sidecar; optionally the
    strokes drawn in study sessions (one row per sample) and the sessions (one row each) with
    theirs.

    Args:
        target: the store: a SQLite file or a database URL (``postgresql://…``). It must
            exist; it is only read.
        output: the trials CSV to write (columns :data:`CSV_COLUMNS`); its sidecar goes beside
            it (:func:`sidecar_path`).
        design: only the studies of this design (by name, e.g. ``study1``); None: all.
        strokes: the strokes CSV to write (columns :data:`STROKE_COLUMNS`: ``t`` in s since pen
            down, ``x``, ``y`` in mm, ``pressure`` 0–1, tilts in degrees, ``speed`` in mm/s),
            with its own sidecar; None: no strokes.
        sessions: the sessions CSV to write (columns :data:`SESSION_COLUMNS`; withdrawn
            sessions too, as records without data), with its own sidecar; None: none.
        include_pilot: also write the pilot sessions' data; every file then ends with the
            column :data:`PILOT_COLUMN` (1 for a pilot session, 0 otherwise).

    Returns:
        An :class:`ExportSummary`. A store with no study data still gets the header and the
        sidecar (0 rows).

    Raises:
        RealPenError: one line naming the store or the file: no such store, not a RealPen
            store or a damaged one, no study of ``design``, an output that is the store (or
            its journal files) or that two outputs share, or a file that cannot be written.
            Nothing is written then.

    Example (a store with one finished study-1 session: 6 conditions × 2 questions, and the
    comments)::

        summary = export_trials("study.sqlite3", "trials.csv", strokes="strokes.csv")
        summary.rows, [path.name for path in summary.paths]
        # (13, ['trials.csv', 'trials.json', 'strokes.csv', 'strokes.json'])
    """
    from sqlalchemy.exc import SQLAlchemyError

    output = Path(output)
    outputs = [output, sidecar_path(output)]
    if strokes is not None:
        outputs += [Path(strokes), sidecar_path(strokes)]
    if sessions is not None:
        outputs += [Path(sessions), sidecar_path(sessions)]
    _check_outputs(target, outputs)
    store = _open(target)
    pilot = (PILOT_COLUMN,) if include_pilot else ()
    chosen = _Sessions(administered=store.revision not in ("0001", "0002"),
                       include_pilot=include_pilot)
    try:
        exported_at = datetime.now(UTC).isoformat(timespec="milliseconds")
        with _snapshot(store) as connection, contextlib.ExitStack() as files:
            studies = _studies(connection, store, design)
            ids = [row.id for row in studies]
            staged = dict(zip(outputs, (files.enter_context(atomic_path(path))
                                        for path in outputs), strict=True))
            rows = _answer_rows(connection, ids, chosen)
            columns = CSV_COLUMNS + pilot
            with _writing(output), open(staged[output], "w", newline="",
                                        encoding="utf-8") as handle:
                writer = csv.writer(handle)
                writer.writerow(columns)
                writer.writerows(_csv_row(row, columns) for row in rows)
            _write_sidecar(staged, sidecar_path(output), _trials_sidecar(
                connection, store, studies, exported_at, len(rows), chosen))
            stroke_ids, samples = set(), 0
            if strokes is not None:
                path = Path(strokes)
                with _writing(path), open(staged[path], "w", newline="", encoding="utf-8") as handle:
                    writer = csv.writer(handle)
                    writer.writerow(STROKE_COLUMNS + pilot)
                    for row in _sample_rows(connection, ids, chosen):
                        values = ["" if value is None else value for value in row]
                        if include_pilot:
                            values[-1] = int(bool(values[-1]))
                        writer.writerow(values)
                        stroke_ids.add(row[2])
                        samples += 1
                _write_sidecar(staged, sidecar_path(path), _strokes_sidecar(
                    store, studies, exported_at, len(stroke_ids), samples, chosen))
            session_rows = 0
            if sessions is not None:
                path = Path(sessions)
                found = _session_rows(connection, ids, chosen)
                with _writing(path), open(staged[path], "w", newline="", encoding="utf-8") as handle:
                    writer = csv.writer(handle)
                    writer.writerow(SESSION_COLUMNS + pilot)
                    writer.writerows(_session_csv_row(row, SESSION_COLUMNS + pilot)
                                     for row in found)
                session_rows = len(found)
                _write_sidecar(staged, sidecar_path(path), _sessions_sidecar(
                    store, studies, exported_at, session_rows, chosen))
        return ExportSummary(rows=len(rows), sessions=len({row["session"] for row in rows}),
                             participants=len({(row["study"], row["participant"]) for row in rows}),
                             strokes=len(stroke_ids), samples=samples, paths=tuple(outputs),
                             session_rows=session_rows)
    except SQLAlchemyError as error:  # a damaged store, not a RealPen store, a lost connection
        raise fail(store.display, f"cannot read the store ({_first_line(error)})") from None
    finally:
        store.close()


def _write_sidecar(staged: dict[Path, Path], path: Path, data: dict[str, Any]) -> None:
    """Write a sidecar's data to its staged file (errors name the sidecar)."""
    with _writing(path):
        staged[path].write_text(json_text(data, path), encoding="utf-8")


@contextlib.contextmanager
def _writing(path: Path) -> Iterator[None]:
    """Name the output in an error of writing it (a full disk); its staged file is removed."""
    try:
        yield
    except OSError as error:
        raise fail(path, f"cannot write ({error.strerror or error})") from None


def _first_line(error: BaseException) -> str:
    cause = getattr(error, "orig", None) or error
    lines = [line.strip() for line in str(cause).splitlines() if line.strip()]
    return lines[0] if lines else type(cause).__name__

