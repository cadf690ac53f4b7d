"""Running a study session: create or resume, the next trial, answers, progress, state.

Every function here that takes ``conn`` is a store operation: it runs inside one transaction of
the store's writer (:meth:`realpen.live.writer.BatchWriter.submit`), and its result reaches the
caller only once that transaction is committed. That is what makes an answer durable before it
is acknowledged, and what makes a second answer to a trial impossible: the check that the trial
is unanswered and the write happen in one transaction, on one writer, and the primary key of
``answers`` (session, trial, question) refuses a second row even from another server sharing a
PostgreSQL database.

A session is one participant's run of one design. Its planned trials are written when it is
created (from :func:`realpen.study.plan.participant_plan`), so the plan a participant follows
never changes, even if the design file does later: the design itself is stored with the session's
study (``studies.design``), and resuming reads that copy.

Problems a caller can fix are a :class:`StudyError` of one of four kinds, each with a one-line
``detail``: :class:`StudyNotFound` (no such session or trial), :class:`StudyConflict` (answered
already, not the next trial, finished), :class:`StudyInvalid` (an invalid answer or request) and
:class:`StudyUnavailable` (the store cannot do it now; asking again may work). All are
:class:`~realpen.errors.RealPenError` subclasses that know nothing of HTTP: the live app turns
each kind into its status in one place (:mod:`realpen.live.errors`).
"""

from __future__ import annotations

import hashlib
import json
import math
import re
from dataclasses import dataclass, field
from datetime import UTC, datetime
from typing import Any

from sqlalchemy import Connection, and_, case, func, insert, select, text, update

from realpen.defaults import MODALITIES
from realpen.errors import RealPenError
from realpen.study.design import Design
from realpen.study.plan import PlannedTrial, participant_plan
from realpen.study.tables import (
    ENDED_STATES,
    HOLDS_PLAN_ROW,
    SESSION_STATES,
    answers,
    participants,
    sessions,
    studies,
    trials,
)

__all__ = ["StudyError", "StudyNotFound", "StudyConflict", "StudyInvalid", "StudyUnavailable",
           "storable", "SessionRequest", "DesignCache", "LIVE_MODALITY", "MAX_RT_MS",
           "MAX_CODE_CHARS", "open_session", "next_trial", "answer_trial", "progress",
           "list_sessions", "set_state", "trial_plan", "trial_exists", "trial_answered", "pen_profile",
           "pen_label",
           "design_summary", "now", "SETTABLE_STATES"]

# The live page's WebSocket protocol names the modalities as designs do (``audio-tactile``); the
# map stays for callers that translated a design's modality into the page's.
LIVE_MODALITY = {name: name for name in MODALITIES}
MAX_RT_MS = 24 * 3600 * 1000.0  # a response time beyond a day is a clock error, not an answer
MAX_CODE_CHARS = 64
MAX_SITE_CHARS = 200
WITHDRAWN_CODE = re.compile(r"withdrawn-[0-9]+")
"""What a withdrawn participant's ID becomes in the store (``withdrawn-<session>``): refused
as a new participant's ID, so a withdrawal never collides with one."""
SETTABLE_STATES = tuple(state for state in SESSION_STATES if state != "withdrawn")
"""The states :func:`set_state` sets; ``withdrawn`` is :func:`realpen.study.admin.withdraw`'s."""


def storable(text: str) -> bool:
    """Whether both databases can store ``text``: no NUL (PostgreSQL refuses it) and valid
    Unicode (an unpaired surrogate cannot be encoded as UTF-8)."""
    if "\x00" in text:
        return False
    try:
        text.encode("utf-8")
    except UnicodeEncodeError:
        return False
    return True


class StudyError(RealPenError):
    """A request the study cannot take. Raised as one of its kinds (the subclasses below).

    Attributes:
        detail: what is wrong, on one line (it names the field or the trial).
        extra: further fields for the reply (the stored answer of a trial answered already,
            the ``next`` trial).
    """

    def __init__(self, detail: str, **extra: Any):
        super().__init__(detail)
        self.detail, self.extra = detail, extra


class StudyNotFound(StudyError):
    """No such session, trial or design."""


class StudyConflict(StudyError):
    """The request disagrees with what is stored: a trial answered already, not the next
    trial, a finished session, a write another server made first."""


class StudyInvalid(StudyError):
    """An invalid request or answer (the detail names the field or the question)."""


class StudyUnavailable(StudyError):
    """The store cannot do it now (no answer in time, a lost connection); asking again may
    work."""


def now() -> str:
    """The current time as ISO 8601 UTC text with milliseconds (the store's time format)."""
    return datetime.now(UTC).isoformat(timespec="milliseconds")


@dataclass(frozen=True)
class SessionRequest:
    """What the operator (or an external app) gives to start or resume a session.

    Attributes:
        participant: the participant's ID as typed (e.g. ``P07``); 1–64 printable characters.
        site: where the session runs (a lab's name), for multi-site studies.
        demographics: ``age`` (years), ``gender``, ``handedness``; each may be missing.
        consent: whether the participant gave consent (required when the design asks for it).
        index: the plan row (0-based); None: the lowest one no session of the study holds.
        seed: the plan's seed; None: the design's.
        pilot: a pilot session (trying the study out): it runs the plan of ``index`` (by
            default the row the next participant would get) without holding the row, and
            exports and statistics leave it out unless asked.
    """

    participant: str
    site: str = ""
    demographics: dict = field(default_factory=dict)
    consent: bool = False
    index: int | None = None
    seed: int | None = None
    pilot: bool = False

    def __post_init__(self) -> None:
        code = self.participant
        if not isinstance(code, str) or not code.strip() or len(code) > MAX_CODE_CHARS or \
                not code.isprintable():
            raise StudyInvalid(f"participant: give an ID of 1 to {MAX_CODE_CHARS} printable "
                               f"characters (e.g. P07)")
        if not isinstance(self.site, str) or len(self.site) > MAX_SITE_CHARS or \
                not self.site.isprintable():
            raise StudyInvalid(f"site: at most {MAX_SITE_CHARS} printable characters")
        if self.index is not None and not 0 <= self.index < 1_000_000:
            raise StudyInvalid("index: must be between 0 and 999,999")
        if self.seed is not None and not 0 <= self.seed < 2**63:
            raise StudyInvalid("seed: must be between 0 and 2^63 - 1")
        age = self.demographics.get("age")
        if age is not None and (isinstance(age, bool) or not isinstance(age, int)
                                or not 0 < age < 150):
            raise StudyInvalid("demographics.age: must be a whole number of years (1-149)")
        for name in ("gender", "handedness"):
            value = self.demographics.get(name)
            if value is not None and (not isinstance(value, str) or len(value) > 100
                                      or not storable(value)):
                raise StudyInvalid(f"demographics.{name}: at most 100 characters of text "
                                   f"(no NUL, no unpaired surrogate)")
        if WITHDRAWN_CODE.fullmatch(code):
            raise StudyInvalid(f"participant: '{code}' is how the store names a withdrawn "
                               f"participant's record; give another ID")
        unknown = set(self.demographics) - {"age", "gender", "handedness"}
        if unknown:
            raise StudyInvalid(f"demographics: unknown field '{sorted(unknown)[0]}' (age, "
                               f"gender, handedness)")


class DesignCache:
    """The designs of the studies in a store, read once per study (their stored copies)."""

    def __init__(self) -> None:
        self._by_study: dict[int, Design] = {}

    def get(self, conn: Connection, study_id: int) -> Design:
        """The design stored with study ``study_id``."""
        design = self._by_study.get(study_id)
        if design is None:
            text = conn.execute(select(studies.c.design).where(studies.c.id == study_id)).scalar_one()
            design = self._by_study[study_id] = Design.from_json(text)
        return design


def design_summary(design: Design) -> dict:
    """What the operator console shows of a design: name, title, description, the recommended
    number of participants, the plan seed, and the participant fields it asks for."""
    return {"name": design.name, "title": design.title, "description": design.description,
            "participants": design.participants, "seed": design.seed,
            "version": design.version,
            "participant_fields": design.participant_fields.model_dump(mode="json")}


def _study_id(conn: Connection, design: Design) -> int:
    """The id of the study row for this design (its name and content), made if new."""
    query = select(studies.c.id).where(studies.c.name == design.name,
                                       studies.c.version == design.version)
    study_id = conn.execute(query).scalar()
    if study_id is None:
        study_id = conn.execute(insert(studies).values(
            name=design.name, version=design.version, design=design.to_json(),
            created_at=now()).returning(studies.c.id)).scalar_one()
    return study_id


def _design_key(name: str) -> int:
    """A design's 64-bit advisory lock key (signed, as PostgreSQL takes it)."""
    digest = hashlib.sha256(f"realpen study design {name}".encode()).digest()
    return int.from_bytes(digest[:8], "big", signed=True)


def _used_rows(conn: Connection, name: str) -> set[int]:
    """The plan rows the sessions of a design (any version of it) hold: a pilot session and a
    withdrawn one hold none (:data:`~realpen.study.tables.HOLDS_PLAN_ROW`)."""
    return set(conn.execute(select(sessions.c.plan_index).join(studies).where(
        studies.c.name == name, text(HOLDS_PLAN_ROW))).scalars())


def _existing_session(conn: Connection, name: str, code: str) -> int | None:
    return conn.execute(
        select(sessions.c.id).join(participants, sessions.c.participant_id == participants.c.id)
        .join(studies, sessions.c.study_id == studies.c.id)
        .where(studies.c.name == name, participants.c.code == code,
               sessions.c.state != "withdrawn")).scalar()


def open_session(conn: Connection, design: Design, request: SessionRequest,
                 cache: DesignCache) -> tuple[dict, bool]:
    """Start a session of ``design`` for a participant, or find the one they have.

    A participant is known by the design's name and their ID: asking again returns their session
    (whatever version of the design it was started with), which is how a session resumes.
    A pilot session (``request.pilot``) runs a plan row without holding it: the first real
    participant after any number of pilots still gets row 0.

    Returns:
        (the session's :func:`progress`, whether it was created now).

    Raises:
        StudyInvalid: missing consent, or a plan row another session of the design holds (a
            pilot may run any row).
    """
    code = request.participant.strip()
    if conn.dialect.name == "postgresql":
        # Servers sharing a database create a design's sessions one at a time, so that a
        # participant gets one session and a plan row one participant, whatever the design's
        # version on each server (held until the transaction ends).
        conn.execute(text("SELECT pg_advisory_xact_lock(:key)"), {"key": _design_key(design.name)})
    existing = _existing_session(conn, design.name, code)
    if existing is not None:
        found = progress(conn, existing, cache)
        if found["pilot"] != bool(request.pilot):
            kind, other = ("a pilot", "a real") if found["pilot"] else ("a real", "a pilot")
            raise StudyConflict(f"{code} already has {kind} session ({existing}) of "
                                f"'{design.name}'; {other} session needs another participant ID")
        return found, False
    if design.participant_fields.consent and request.consent is not True:
        raise StudyInvalid(f"consent: the design '{design.name}' asks for the participant's "
                           f"consent before the session starts")
    study_id = _study_id(conn, design)
    used = _used_rows(conn, design.name)
    if request.index is None:
        index = next(row for row in range(len(used) + 1) if row not in used)  # the lowest free
    else:
        index = request.index
        if index in used and not request.pilot:
            raise StudyInvalid(f"index: plan row {index} is used by another session of "
                               f"'{design.name}'")
    seed = design.seed if request.seed is None else request.seed
    plan = participant_plan(design, index, seed)
    created = now()
    demographics = request.demographics
    participant_id = conn.execute(insert(participants).values(
        study_id=study_id, code=code, site=request.site, age=demographics.get("age"),
        gender=demographics.get("gender"), handedness=demographics.get("handedness"),
        consent=bool(request.consent), created_at=created).returning(participants.c.id)).scalar_one()
    session_id = conn.execute(insert(sessions).values(
        study_id=study_id, participant_id=participant_id, plan_index=index, seed=seed,
        site=request.site, state="running", started_at=created, pilot=request.pilot)
        .returning(sessions.c.id)).scalar_one()
    conn.execute(insert(trials), [{
        "session_id": session_id, "n": trial.n, "block": trial.block,
        "block_index": trial.block_index, "phase": trial.phase, "condition": trial.condition,
        "modality": trial.modality, "pen": trial.pen, "ink": trial.ink,
        "repetition": trial.repetition, "plan": json.dumps(trial.to_json(), sort_keys=True)}
        for trial in plan])
    return progress(conn, session_id, cache), True


def _session_row(conn: Connection, session_id: int, *, lock: bool = False):
    """The session's row with its design's name and participant's ID; ``lock``: first lock
    the session row until the transaction ends (PostgreSQL's FOR UPDATE; SQLite has one
    writer), so that two servers cannot answer, end or withdraw it at once."""
    if lock:
        conn.execute(select(sessions.c.id).where(sessions.c.id == session_id).with_for_update())
    row = conn.execute(_session_rows().where(sessions.c.id == session_id)).mappings().first()
    if row is None:
        raise StudyNotFound(f"no session {session_id}")
    return row


def _first_unanswered(conn: Connection, session_id: int) -> int | None:
    return conn.execute(select(func.min(trials.c.n)).where(
        trials.c.session_id == session_id, trials.c.answered_at.is_(None))).scalar()


def _progress_of(row, blocks: list, design: Design, next_n: int | None) -> dict:
    total = sum(block["trials"] for block in blocks)
    answered = sum(block["answered"] for block in blocks)
    next_n = None if row["state"] in ENDED_STATES else next_n
    return {"session": row["id"], "design": row["design"], "title": design.title,
            "participant": row["code"], "site": row["site"], "index": row["plan_index"],
            "seed": row["seed"], "state": row["state"], "pilot": bool(row["pilot"]),
            "trials": total, "answered": answered, "next": next_n,
            "current": _current_trial(blocks, design, next_n, total),
            "blocks": [{"block": block["block"], "block_index": block["block_index"],
                        "trials": block["trials"], "answered": block["answered"]}
                       for block in blocks],
            "started_at": row["started_at"], "finished_at": row["finished_at"]}


def _current_trial(blocks: list, design: Design, next_n: int | None, total: int) -> dict | None:
    """The trial a running or paused session is at (its first unanswered one), for the
    operator: where it is in the plan, and its condition, modality and pen (id, label and
    profile: the console may name them; the participant screen does not). None when the
    session has no next trial."""
    if next_n is None:
        return None
    block = next((block for block in blocks if block["first_open"] == next_n), None)
    if block is None:  # no block holds it: cannot happen for a plan the store wrote
        return None
    conditions = {condition.id: condition.label for condition in design.conditions}
    pen = next((pen for pen in design.pens if pen.id == block["pen"]), None)
    return {"n": next_n, "of": total, "block": block["block"],
            "block_index": block["block_index"], "block_n": next_n - block["first_n"] + 1,
            "block_of": block["trials"], "phase": block["phase"],
            "condition": block["condition"],
            "condition_label": conditions.get(block["condition"], ""),
            "modality": block["modality"], "pen": block["pen"],
            "pen_label": pen.label if pen else "", "profile": pen.profile_ref if pen else ""}


def _blocks(conn: Connection, session_ids: list[int]) -> tuple[dict, dict]:
    """Per session: its blocks' trial and answer counts, and its first unanswered trial.

    One query: each block's counts, with the phase, condition, modality and pen of the block's
    first unanswered trial (``first_open``; joined back to its row), so that a list of sessions
    shows each one's current trial without a query per session.
    """
    counts = (
        select(trials.c.session_id, trials.c.block_index, trials.c.block,
               func.count().label("trials"), func.count(trials.c.answered_at).label("answered"),
               func.min(trials.c.n).label("first_n"),
               func.min(case((trials.c.answered_at.is_(None), trials.c.n))).label("first_open"))
        .where(trials.c.session_id.in_(session_ids))
        .group_by(trials.c.session_id, trials.c.block_index, trials.c.block)).subquery()
    opened = trials.alias("opened")
    rows = conn.execute(
        select(counts, opened.c.phase, opened.c.condition, opened.c.modality, opened.c.pen)
        .outerjoin(opened, and_(opened.c.session_id == counts.c.session_id,
                                opened.c.n == counts.c.first_open))
        .order_by(counts.c.session_id, counts.c.block_index)).mappings().all()
    blocks: dict[int, list] = {session_id: [] for session_id in session_ids}
    first_open: dict[int, int | None] = dict.fromkeys(session_ids)
    for block in rows:
        blocks[block["session_id"]].append(block)
        if block["first_open"] is not None and (first_open[block["session_id"]] is None or
                                                block["first_open"] < first_open[block["session_id"]]):
            first_open[block["session_id"]] = block["first_open"]
    return blocks, first_open


def _session_rows():
    return (select(sessions, studies.c.name.label("design"), participants.c.code)
            .join(studies, sessions.c.study_id == studies.c.id)
            .join(participants, sessions.c.participant_id == participants.c.id))


def progress(conn: Connection, session_id: int, cache: DesignCache) -> dict:
    """A session's progress: state, trials answered of planned, the next trial, per block.

    ``current`` is the trial a running or paused session is at (None once it has ended):
    ``n`` of ``of`` trials, its ``block`` (``block_n`` of ``block_of`` in it), ``phase``,
    ``condition`` (and its label), ``modality`` and ``pen`` (its id, label and profile).
    ``pilot`` says whether the session was made as a pilot.

    Raises:
        StudyNotFound: there is no such session.
    """
    row = _session_row(conn, session_id)
    blocks, first_open = _blocks(conn, [session_id])
    return _progress_of(row, blocks[session_id], cache.get(conn, row["study_id"]),
                        first_open[session_id])


def list_sessions(conn: Connection, cache: DesignCache, limit: int = 200) -> list[dict]:
    """The progress of the newest ``limit`` sessions, newest first (two queries in all)."""
    rows = conn.execute(_session_rows().order_by(sessions.c.id.desc()).limit(limit)) \
        .mappings().all()
    blocks, first_open = _blocks(conn, [row["id"] for row in rows])
    return [_progress_of(row, blocks[row["id"]], cache.get(conn, row["study_id"]),
                         first_open[row["id"]]) for row in rows]


def trial_plan(conn: Connection, session_id: int, n: int,
               cache: DesignCache) -> tuple[PlannedTrial, Design]:
    """A session's planned trial ``n`` and the session's design.

    Raises:
        StudyNotFound: no such session or trial.
    """
    row = _session_row(conn, session_id)
    plan = conn.execute(select(trials.c.plan).where(
        trials.c.session_id == session_id, trials.c.n == n)).scalar()
    if plan is None:
        raise StudyNotFound(f"session {session_id} has no trial {n}")
    return _planned(plan), cache.get(conn, row["study_id"])


def trial_answered(conn: Connection, session_id: int, n: int) -> bool:
    """Whether trial ``n`` of the session holds an answer (as this statement sees the store)."""
    return conn.execute(select(trials.c.answered_at).where(
        trials.c.session_id == session_id, trials.c.n == n)).scalar() is not None


def trial_exists(conn: Connection, session_id: int, n: int) -> bool:
    """Whether study session ``session_id`` has a trial ``n`` (a stroke may name it)."""
    return conn.execute(select(trials.c.n).where(trials.c.session_id == session_id,
                                                 trials.c.n == n)).first() is not None


def _planned(plan_json: str) -> PlannedTrial:
    data = json.loads(plan_json)
    data["questions"] = tuple(data.get("questions", ()))
    return PlannedTrial(**data)


def pen_profile(design: Design, pen: str) -> str:
    """The profile the live app plays for a design's pen: its ``profile``, else its id.

    The live page loads the pen by this name; answers, trials and exports keep the pen's id.

    Args:
        design: the session's design.
        pen: a pen id of the design, or "" for a trial without a pen.

    Returns:
        The profile's name (or bundle path) as the design gives it; "" for a trial without a
        pen.

    Raises:
        ParameterError: ``pen`` is not a pen of the design.
    """
    return design.pen(pen).profile_ref if pen else ""


def pen_label(design: Design, pen: str) -> str:
    """How the participant may be shown a design's pen: its ``label``, "" when it has none (the
    participant screen then names no pen) or for a trial without a pen."""
    return design.pen(pen).label if pen else ""


def _choice_labels(design: Design, choices: list[str]) -> list[str]:
    """What the participant reads for each choice: a pen's label when the choice is a labelled
    pen's id, else the choice as the design wrote it."""
    labels = {pen.id: pen.label for pen in design.pens if pen.label}
    return [labels.get(choice, choice) for choice in choices]


def _question_json(design: Design, question_id: str) -> dict:
    question = design.question(question_id)
    data = {"id": question.id, "type": question.type, "text": question.text,
            "required": question.required}
    if question.type == "likert":
        data["points"] = question.points
        data["anchors"] = {str(point): label for point, label in question.anchors.items()}
    elif question.type == "choice":
        data["choices"] = list(question.choices)
        data["labels"] = _choice_labels(design, data["choices"])
    return data


def next_trial(conn: Connection, session_id: int, cache: DesignCache) -> dict:
    """The first unanswered trial of a session, with everything the page needs to run it, or
    ``{"done": true}`` when every trial is answered or the session was finished.

    Raises:
        StudyNotFound: there is no such session.
    """
    row = _session_row(conn, session_id)
    n = None if row["state"] in ENDED_STATES else _first_unanswered(conn, session_id)
    if n is None:
        return {"done": True, "session": session_id, "state": row["state"]}
    design = cache.get(conn, row["study_id"])
    plan = _planned(conn.execute(select(trials.c.plan).where(
        trials.c.session_id == session_id, trials.c.n == n)).scalar_one())
    total = conn.execute(select(func.count()).where(trials.c.session_id == session_id)).scalar_one()
    tactile = plan.modality in ("tactile", "audio-tactile")
    return {"trial": n, "total": total, "session": session_id, "state": row["state"],
            "block": plan.block, "block_index": plan.block_index, "phase": plan.phase,
            "condition": plan.condition, "modality": plan.modality,
            "live_modality": LIVE_MODALITY.get(plan.modality, "none"), "pen": plan.pen,
            "profile": pen_profile(design, plan.pen), "pen_label": pen_label(design, plan.pen),
            "ink": plan.ink, "repetition": plan.repetition, "task": plan.task,
            "writing": plan.writing, "feedback": plan.feedback,
            "tactile_url": f"/api/sessions/{session_id}/trials/{n}/tactile.wav" if tactile else None,
            "questions": [_question_json(design, question) for question in plan.questions]}


def _stored_answer(conn: Connection, session_id: int, n: int) -> dict:
    rows = conn.execute(select(answers.c.question, answers.c.answer).where(
        answers.c.session_id == session_id, answers.c.n == n)).all()
    rt_ms = conn.execute(select(trials.c.rt_ms).where(
        trials.c.session_id == session_id, trials.c.n == n)).scalar()
    return {"answers": dict(rows), "rt_ms": rt_ms}


def _check_answers(design: Design, plan: PlannedTrial, given: dict) -> list[tuple[str, str, Any]]:
    """Validate a trial's answers against its questions: (question, stored text, correct)."""
    if not isinstance(given, dict):
        raise StudyInvalid("answers: must be an object of question id -> answer")
    unknown = [question for question in given if question not in plan.questions]
    if unknown:
        raise StudyInvalid(f"{unknown[0]}: not a question of trial {plan.n} (its questions: "
                           f"{', '.join(plan.questions) or 'none'})")
    rows = []
    for question_id in plan.questions:
        question = design.question(question_id)
        if question_id not in given or given[question_id] is None:
            if question.required:
                raise StudyInvalid(f"{question_id}: an answer is required")
            # Every question asked gets its row: an optional one left unanswered is "", so the
            # export keeps the trial (its time, its rt) even when nothing else was answered.
            rows.append((question_id, "", None))
            continue
        try:
            stored = question.validate_answer(given[question_id])
        except ValueError as error:
            raise StudyInvalid(f"{question_id}: {error}") from None
        if not storable(stored):
            raise StudyInvalid(f"{question_id}: text with a NUL or an unpaired surrogate")
        rows.append((question_id, stored, question.is_correct(stored, plan)))
    return rows


def answer_trial(conn: Connection, session_id: int, n: int, given: dict, rt_ms: float,
                 cache: DesignCache) -> dict:
    """Store the answers to trial ``n`` and its response time (ms from the trial's start to the
    answer, measured by the page); the session finishes with its last trial.

    Returns:
        ``{"trial": n, "next": the next unanswered trial or None}``, and for a trial with
        feedback (training) ``"feedback"``: per question that has a right answer,
        ``{"correct": bool, "answer": the right answer}``.

    Raises:
        StudyNotFound: no such session or trial.
        StudyConflict: the trial was answered already (``extra`` holds the stored answer), is
            not the next one (``extra["next"]``), or the session has ended (finished,
            abandoned, withdrawn).
        StudyInvalid: an invalid answer (the detail names the question) or response time.
    """
    row = _session_row(conn, session_id, lock=True)
    plan_json = conn.execute(select(trials.c.plan, trials.c.answered_at).where(
        trials.c.session_id == session_id, trials.c.n == n)).first()
    if plan_json is None:
        raise StudyNotFound(f"session {session_id} has no trial {n}")
    if plan_json.answered_at is not None:
        raise StudyConflict(f"trial {n} of session {session_id} is answered already",
                            **_stored_answer(conn, session_id, n))
    if row["state"] in ENDED_STATES:
        raise StudyConflict(f"session {session_id} is {row['state']}")
    expected = _first_unanswered(conn, session_id)
    if expected != n:
        # Another server may have answered trial n since it was read above (PostgreSQL reads
        # each statement's own snapshot): say so, with the stored answer, as for a retry.
        if trial_answered(conn, session_id, n):
            raise StudyConflict(f"trial {n} of session {session_id} is answered already",
                                **_stored_answer(conn, session_id, n))
        raise StudyConflict(f"trial {n} is not the next one of session {session_id} (next: "
                            f"{expected})", next=expected)
    if isinstance(rt_ms, bool) or not isinstance(rt_ms, int | float) or not math.isfinite(rt_ms) \
            or not 0 <= rt_ms <= MAX_RT_MS:
        raise StudyInvalid(f"rt_ms: must be a number of milliseconds from 0 to {MAX_RT_MS:.0f}")
    design = cache.get(conn, row["study_id"])
    plan = _planned(plan_json.plan)
    rows = _check_answers(design, plan, given)
    answered_at = now()
    changed = conn.execute(update(trials).where(
        and_(trials.c.session_id == session_id, trials.c.n == n, trials.c.answered_at.is_(None)))
        .values(answered_at=answered_at, rt_ms=float(rt_ms))).rowcount
    if changed != 1:  # another server answered it between our check and our write
        raise StudyConflict(f"trial {n} of session {session_id} is answered already",
                            **_stored_answer(conn, session_id, n))
    if rows:
        conn.execute(insert(answers), [{"session_id": session_id, "n": n, "question": question,
                                        "answer": text, "correct": correct}
                                       for question, text, correct in rows])
    following = _first_unanswered(conn, session_id)
    if following is None:
        conn.execute(update(sessions).where(sessions.c.id == session_id,
                                            sessions.c.state.not_in(ENDED_STATES))
                     .values(state="finished", finished_at=answered_at))
    reply = {"trial": n, "next": following}
    if plan.feedback:
        reply["feedback"] = {question: {"correct": bool(correct), "answer": plan.pen}
                             for question, _, correct in rows if correct is not None}
    return reply


def set_state(conn: Connection, session_id: int, state: str, cache: DesignCache) -> dict:
    """Pause, resume, finish or abandon a session; returns its :func:`progress`.

    A session that has ended (finished, abandoned or withdrawn) stays so: its unanswered trials
    are not offered again. ``abandoned`` ends a session the participant left: its answers so far
    stay and are exported with that state. Setting the state a session is in changes nothing.

    Raises:
        StudyNotFound: no such session.
        StudyInvalid: a state not in :data:`SETTABLE_STATES` (``withdrawn`` is
            :func:`realpen.study.admin.withdraw`'s).
        StudyConflict: changing the state of a session that has ended.
    """
    if state not in SETTABLE_STATES:
        raise StudyInvalid(f"state: must be one of {', '.join(SETTABLE_STATES)}")
    row = _session_row(conn, session_id, lock=True)
    if row["state"] in ENDED_STATES and state != row["state"]:
        raise StudyConflict(f"session {session_id} is {row['state']} and cannot be "
                            f"{'resumed' if state in ('running', 'paused') else state}")
    if row["state"] != state:
        values = {"state": state}
        if state in ENDED_STATES:
            values["finished_at"] = now()
        # never over an end another server made meanwhile
        conn.execute(update(sessions).where(sessions.c.id == session_id,
                                            sessions.c.state.not_in(ENDED_STATES)).values(**values))
    return progress(conn, session_id, cache)
