"""The store's tables, in SQLAlchemy Core: one schema for SQLite and PostgreSQL.

Live writing (the live app, with or without a study):

``strokes``   one row per stroke: the page connection (``session``), the page's own id
              (``page``, the same across reconnects), its stroke number (``page_stroke``), the
              pen (profile name and content version), modality, ink, pointer type, the page's
              calibration (px/mm), the pen-down time on the page clock (``page_t0``, s), start
              and end (ISO 8601 UTC), why it ended (:data:`END_REASONS`), how many samples it
              has, and, when drawn in a study, its study session and trial number;
``samples``   one row per pen sample, numbered within its stroke (``seq``): ``t`` in s since
              pen down, ``x``, ``y`` in mm, ``pressure`` 0–1, ``tilt_x``, ``tilt_y`` in
              degrees, ``speed`` in mm/s (:data:`realpen.io.strokes.SAMPLE_FIELDS`).

Studies:

``studies``       a design as run: its name, its content hash (``version``) and the design
                  itself (canonical JSON), so an export can always be read against the design
                  that produced it;
``participants``  a participant of a study: the ID the operator typed (``code``, e.g. ``P07``),
                  site, demographics and consent;
``sessions``      one per study and participant: its plan's index and seed, state
                  (:data:`SESSION_STATES`), site, start and end, whether it is a ``pilot``
                  (it runs a plan row without taking it), and when the participant withdrew
                  (``withdrawn_at``; the session then keeps no data: see
                  :mod:`realpen.study.admin`). A plan row is held by one session of a study
                  at most, among those that hold one (:data:`HOLDS_PLAN_ROW`);
``trials``        the session's planned trials, written when the session is created (``n``
                  from 1), each with its block, phase, condition, modality, pen, ink and
                  question ids; ``answered_at`` and ``rt_ms`` (ms from the trial's start to
                  the answer, measured by the page) once answered;
``answers``       one row per question of an answered trial: the answer as text, whether it
                  was right (recognition questions; else NULL).

Times are ISO 8601 text in UTC with milliseconds, the same on both databases. Ids, numbers and
counts are 32-bit integers (PostgreSQL's INTEGER) on both: :data:`MAX_ID` is the largest any of
them holds (:data:`realpen.io.limits.MAX_STORED_INT`, the one rule the WebSocket schema and the
HTTP API share); only a session's plan seed is 64-bit.
"""

from __future__ import annotations

from sqlalchemy import (
    BigInteger,
    Boolean,
    Column,
    Float,
    ForeignKey,
    ForeignKeyConstraint,
    Index,
    Integer,
    MetaData,
    PrimaryKeyConstraint,
    Table,
    Text,
    UniqueConstraint,
    false,
    text,
)

from realpen.io.limits import MAX_STORED_INT
from realpen.io.strokes import SAMPLE_FIELDS

__all__ = ["MAX_ID", "metadata", "strokes", "samples", "studies", "participants", "sessions", "trials",
           "answers", "END_REASONS", "SESSION_STATES", "ENDED_STATES", "PHASES",
           "HOLDS_PLAN_ROW"]

MAX_ID = MAX_STORED_INT
"""The largest id, number or count a store holds (2**31 - 1, on SQLite as on PostgreSQL)."""
END_REASONS = ("pen_up", "disconnect", "replaced", "shutdown", "crash")
SESSION_STATES = ("running", "paused", "finished", "abandoned", "withdrawn")
"""A session's states: ``running`` and ``paused`` have a next trial; the others have ended."""
ENDED_STATES = ("finished", "abandoned", "withdrawn")
"""The states a session never leaves (it cannot be resumed)."""
HOLDS_PLAN_ROW = "NOT pilot AND state <> 'withdrawn'"
"""SQL: a session holds its plan row (neither a pilot nor withdrawn)."""
PHASES = ("training", "experimental", "questionnaire")

# Constraint names follow one convention so that Alembic migrations can name them on both
# databases.
metadata = MetaData(naming_convention={
    "ix": "ix_%(table_name)s_%(column_0_N_name)s",
    "uq": "uq_%(table_name)s_%(column_0_N_name)s",
    "fk": "fk_%(table_name)s_%(column_0_name)s_%(referred_table_name)s",
    "pk": "pk_%(table_name)s",
})

studies = Table(
    "studies", metadata,
    Column("id", Integer, primary_key=True, autoincrement=True),
    Column("name", Text, nullable=False),
    Column("version", Text, nullable=False),
    Column("design", Text, nullable=False),
    Column("created_at", Text, nullable=False),
    UniqueConstraint("name", "version"),
)

participants = Table(
    "participants", metadata,
    Column("id", Integer, primary_key=True, autoincrement=True),
    Column("study_id", Integer, ForeignKey("studies.id", ondelete="CASCADE"), nullable=False),
    Column("code", Text, nullable=False),
    Column("site", Text, nullable=False, server_default=""),
    Column("age", Integer),
    Column("gender", Text),
    Column("handedness", Text),
    Column("consent", Boolean, nullable=False, server_default=false()),
    Column("created_at", Text, nullable=False),
    UniqueConstraint("study_id", "code"),
)

sessions = Table(
    "sessions", metadata,
    Column("id", Integer, primary_key=True, autoincrement=True),
    Column("study_id", Integer, ForeignKey("studies.id", ondelete="CASCADE"), nullable=False),
    Column("participant_id", Integer, ForeignKey("participants.id", ondelete="CASCADE"),
           nullable=False),
    Column("plan_index", Integer, nullable=False),
    Column("seed", BigInteger, nullable=False),  # plan seeds go up to 2^63 - 1
    Column("site", Text, nullable=False, server_default=""),
    Column("state", Text, nullable=False, server_default="running"),
    Column("started_at", Text, nullable=False),
    Column("finished_at", Text),
    Column("pilot", Boolean, nullable=False, server_default=false()),
    Column("withdrawn_at", Text),
    UniqueConstraint("study_id", "participant_id"),
    Index("sessions_by_plan_row", "study_id", "plan_index", unique=True,
          sqlite_where=text(HOLDS_PLAN_ROW), postgresql_where=text(HOLDS_PLAN_ROW)),
)

trials = Table(
    "trials", metadata,
    Column("session_id", Integer, ForeignKey("sessions.id", ondelete="CASCADE"),
           nullable=False),
    Column("n", Integer, nullable=False),
    Column("block", Text, nullable=False),
    Column("block_index", Integer, nullable=False),
    Column("phase", Text, nullable=False),
    Column("condition", Text, nullable=False, server_default=""),
    Column("modality", Text, nullable=False, server_default=""),
    Column("pen", Text, nullable=False, server_default=""),
    Column("ink", Text, nullable=False, server_default="visible"),
    Column("repetition", Integer, nullable=False, server_default="0"),
    Column("plan", Text, nullable=False),  # the planned trial as JSON (task, questions, tactile)
    Column("answered_at", Text),
    Column("rt_ms", Float),
    PrimaryKeyConstraint("session_id", "n"),
)

answers = Table(
    "answers", metadata,
    Column("session_id", Integer, nullable=False),
    Column("n", Integer, nullable=False),
    Column("question", Text, nullable=False),
    Column("answer", Text, nullable=False),
    Column("correct", Boolean),
    PrimaryKeyConstraint("session_id", "n", "question"),
    ForeignKeyConstraint(["session_id", "n"], ["trials.session_id", "trials.n"],
                         name="fk_answers_trial", ondelete="CASCADE"),
)

strokes = Table(
    "strokes", metadata,
    Column("id", Integer, primary_key=True, autoincrement=True),
    Column("session", Text, nullable=False),
    Column("page_stroke", Integer, nullable=False),
    Column("pen", Text, nullable=False),
    Column("profile_version", Text, nullable=False),
    Column("modality", Text, nullable=False),
    Column("ink", Text, nullable=False),
    Column("pointer_type", Text, nullable=False),
    Column("px_per_mm", Float, nullable=False),
    Column("calibrated", Integer, nullable=False),
    Column("page_t0", Float, nullable=False),
    Column("started_at", Text, nullable=False),
    Column("ended_at", Text),
    Column("end_reason", Text),
    Column("sample_count", Integer, nullable=False, server_default="0"),
    Column("page", Text),
    Column("study_session", Integer, ForeignKey("sessions.id", ondelete="SET NULL")),
    Column("trial", Integer),
    Index("strokes_by_page", "page", "page_stroke", unique=True),
    Index("strokes_by_trial", "study_session", "trial"),
)

samples = Table(
    "samples", metadata,
    Column("stroke_id", Integer, ForeignKey("strokes.id", ondelete="CASCADE"), nullable=False),
    Column("seq", Integer, nullable=False),
    *(Column(name, Float, nullable=False) for name in SAMPLE_FIELDS),
    PrimaryKeyConstraint("stroke_id", "seq"),
    sqlite_with_rowid=False,
)
