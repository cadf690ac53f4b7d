"""Simulated participants: a study's answers before anyone has taken part.

:class:`ResponseModel` says how a simulated participant answers; :func:`simulated_trials`
answers every planned trial of a design in the studies' export format (one row per answer),
and :func:`simulate_store` enters the same answers through the real study service
(:mod:`realpen.study.sessions`) into a real store, so that ``realpen study export`` and
``realpen stats`` can be run on them end to end.

How answers are made (every draw from ``numpy`` PCG64, seeded per participant by
``SeedSequence([seed, index, 2])`` as :mod:`realpen.study.plan` seeds its shuffles, so a
participant's answers depend on nothing else):

- **Likert** (ordered probit; Liddell & Kruschke 2018): a latent normal value, the participant's
  own offset for that question (``N(0, participant_sd)``, drawn once per participant and
  question) + the trial's level effect + ``N(0, 1)`` noise, cut into points ``1..points`` at
  the ``j/points`` quantiles (``j = 1..points-1``) of the *no-effect* latent distribution
  ``N(0, sqrt(1 + participant_sd²))``: under the null every point is equally likely, so all
  points are used. The level effect spreads ``effect`` evenly over the levels of the design's
  main within factor in design order, centred on 0: level ``i`` of ``k`` gets
  ``effect × (i/(k−1) − 1/2)``, so the last level is ``effect`` latent SDs above the first.
  The main factor is the first of the design's conditions, modalities and pens that has two
  levels or more (:func:`main_factor`); a trial not at one of its levels gets no effect.
- **Recognition** (a choice question with ``correct: pen``): right with the probability
  ``rates[modality]`` — with ``pen_effect`` ≠ 0 shifted on the log-odds scale, spread evenly
  and centred over the design's pens like the Likert effect — else one of the other choices,
  uniformly. Training trials are answered the same way.
- Other choice questions: a choice uniformly; text questions: ``""`` (``"simulated"`` when the
  question requires an answer).
- **Response time** (one per trial): lognormal, ``exp(log_rt_mean + modality_rt[modality] +
  N(0, log_rt_sd))`` ms, to the µs (three decimals, as the export writes it).

References:
    Liddell, T. M., & Kruschke, J. K. (2018). Analyzing ordinal data with metric models: What
    could possibly go wrong? Journal of Experimental Social Psychology, 79, 328–348.
    https://doi.org/10.1016/j.jesp.2018.08.009

    Cho, Y., Bianchi, A., Marquardt, N., & Bianchi-Berthouze, N. (2016). RealPen: Providing
    realism in handwriting tasks on touch surfaces using auditory-tactile feedback. UIST '16,
    195–205. https://doi.org/10.1145/2984511.2984550
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np
import pandas as pd
from scipy import special, stats

from realpen.checks import require_number
from realpen.errors import ParameterError, fail
from realpen.study.design import Design
from realpen.study.export import KEY_COLUMNS
from realpen.study.plan import MAX_PARTICIPANTS, PlannedTrial, participant_plan

__all__ = ["ResponseModel", "simulated_trials", "simulate_store", "participant_code",
           "main_factor", "level_positions", "level_of", "check_inputs", "likert_cuts", "pen_rate",
           "PAPER_RATES", "SIMULATED_COLUMNS", "write_simulated", "write_simulated_trials",
           "simulated_bytes", "check_simulated_size"]

PAPER_RATES = {"tactile": 0.4305, "auditory": 0.5096, "audio-tactile": 0.6296}
"""The recognition rates the paper reported per modality (study 2), as proportions."""
SIMULATED_COLUMNS = KEY_COLUMNS + ("site", "repetition", "ink")
"""The columns of :func:`simulated_trials`."""

_ANSWERS = 2  # the purpose of a participant's generator, part of its seed (plan.py uses 0, 1)


@dataclass(frozen=True, kw_only=True)
class ResponseModel:
    """How simulated participants answer (see the module doc for the model).

    Attributes:
        effect: the Likert effect, in latent SDs (of the ``N(0, 1)`` trial noise): the
            difference between the last and the first level of the design's main within factor,
            levels spread evenly in design order; 0: no effect.
        participant_sd: the SD of a participant's own latent offset per Likert question
            (latent SDs).
        rates: modality → the probability of a correct recognition (0..1); default the paper's.
        pen_effect: the difference in the log-odds of a correct recognition between the last and
            the first of the design's pens, spread evenly; 0: every pen at its modality's rate.
        log_rt_mean: the mean of the natural log of the response time in ms (default: 4000 ms).
        log_rt_sd: the SD of log response time between trials.
        modality_rt: modality → added to the log response time (0 for those not named).
    """

    effect: float = 0.0
    participant_sd: float = 0.7
    rates: dict[str, float] = field(default_factory=lambda: dict(PAPER_RATES))
    pen_effect: float = 0.0
    log_rt_mean: float = math.log(4000.0)
    log_rt_sd: float = 0.4
    modality_rt: dict[str, float] = field(default_factory=dict)

    def __post_init__(self) -> None:
        require_number("effect", self.effect)
        require_number("participant_sd", self.participant_sd, minimum=0)
        require_number("pen_effect", self.pen_effect)
        require_number("log_rt_mean", self.log_rt_mean, minimum=-50, maximum=50)
        require_number("log_rt_sd", self.log_rt_sd, minimum=0, maximum=10)
        for name in ("rates", "modality_rt"):
            value = getattr(self, name)
            if not isinstance(value, Mapping):
                raise ParameterError(name, f"must be a dict of modality -> number, got {value!r}")
            for key, number in value.items():
                if not isinstance(key, str):
                    raise ParameterError(name, f"keys must be modality names, got {key!r}")
                if name == "rates":
                    require_number(f"rates[{key!r}]", number, minimum=0, maximum=1)
                else:
                    require_number(f"modality_rt[{key!r}]", number, minimum=-50, maximum=50)
            # A copy: the model stays as made even if the caller's dict changes.
            object.__setattr__(self, name, {key: float(number) for key, number in value.items()})
        for name in ("effect", "participant_sd", "pen_effect", "log_rt_mean", "log_rt_sd"):
            object.__setattr__(self, name, float(getattr(self, name)))


# ---- the design's structure as the model sees it ---------------------------------------------

def main_factor(design: Design) -> tuple[str, tuple[str, ...]]:
    """The design's main within factor and its levels in design order: the first of
    ``("condition", (A, …))``, ``("modality", (its modalities))`` and ``("pen", (its pen
    ids))`` with two levels or more (a design of one pen per condition varies its conditions;
    one that varies only its pens, its pens); with none, its conditions if it has any, else
    its modality.

    >>> from realpen.study.design import load_design
    >>> main_factor(load_design("study2"))
    ('modality', ('tactile', 'auditory', 'audio-tactile'))
    """
    candidates = (("condition", tuple(condition.id for condition in design.conditions)),
                  ("modality", tuple(design.modalities)),
                  ("pen", tuple(pen.id for pen in design.pens)))
    for factor, levels in candidates:
        if len(levels) >= 2:
            return factor, levels
    return candidates[0] if design.conditions else candidates[1]


def level_positions(count: int) -> np.ndarray:
    """Where ``count`` levels sit on an effect of size 1: evenly spread in order, centred on 0
    (``i/(count−1) − 1/2``); one level sits at 0.

    >>> level_positions(3).tolist()
    [-0.5, 0.0, 0.5]
    """
    if count < 2:
        return np.zeros(count)
    return np.arange(count) / (count - 1) - 0.5


def likert_cuts(points: int, participant_sd: float) -> np.ndarray:
    """The ``points − 1`` latent cut points of a Likert scale: the ``j/points`` quantiles of the
    no-effect latent distribution ``N(0, sqrt(1 + participant_sd²))`` (scipy.stats.norm.ppf).
    A latent value ``x`` is the point ``1 + (number of cuts below x)``.

    >>> likert_cuts(2, 0.0).tolist()
    [0.0]
    """
    scale = math.sqrt(1.0 + participant_sd ** 2)
    return stats.norm.ppf(np.arange(1, points) / points) * scale


def level_of(trial: PlannedTrial, factor: str, levels: tuple[str, ...]) -> int | None:
    """The index of ``trial``'s level of the main factor, or None when it is at none of them."""
    value = getattr(trial, factor)
    return levels.index(value) if value in levels else None


def pen_rate(rate: float, pen_index: int, pens: int, pen_effect: float) -> float:
    """A modality's recognition rate for the pen at ``pen_index`` of ``pens``: shifted on the
    log-odds scale by ``pen_effect`` × its position (scipy.special.logit / expit)."""
    if pen_effect == 0.0 or pens < 2:
        return rate
    return float(special.expit(special.logit(rate) + pen_effect * level_positions(pens)[pen_index]))


def participant_code(number: int, participants: int) -> str:
    """A simulated participant's code: ``S01``, ``S02``, … (three digits from 100 participants,
    so that codes sort in participant order).

    >>> participant_code(7, 12)
    'S07'
    """
    return f"S{number:0{max(2, len(str(participants)))}d}"


def _generator(*key: int) -> np.random.Generator:
    return np.random.Generator(np.random.PCG64(np.random.SeedSequence(list(key))))


def check_inputs(design: Design, participants: int, model: ResponseModel, seed: int) -> None:
    """Check the arguments every simulation takes.

    Raises:
        ParameterError: ``design`` not a Design, ``participants`` not 1..1000, ``model`` not a
            :class:`ResponseModel` or without a recognition rate for a modality the design asks
            a recognition question in, ``seed`` not 0..2⁶³−1.
    """
    if not isinstance(design, Design):
        raise ParameterError("design", f"must be a Design (realpen.study.design.load_design), "
                                       f"got {type(design).__name__}")
    if isinstance(participants, bool) or not isinstance(participants, (int, np.integer)):
        raise ParameterError("participants", f"must be a whole number, got {participants!r}")
    require_number("participants", int(participants), minimum=1, maximum=MAX_PARTICIPANTS)
    if not isinstance(model, ResponseModel):
        raise ParameterError("model", f"must be a ResponseModel, got {type(model).__name__}")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)):
        raise ParameterError("seed", f"must be a whole number, got {seed!r}")
    require_number("seed", int(seed), minimum=0, maximum=2**63 - 1)
    for question in design.questions:
        if question.type == "choice" and question.correct == "pen":
            asked = question.modalities or design.modalities
            missing = [m for m in asked if m in design.modalities and m not in model.rates]
            if missing:
                raise ParameterError("rates", f"no recognition rate for the modality "
                                              f"{missing[0]!r} of {design.name!r} (given: "
                                              f"{', '.join(model.rates) or 'none'})")


# ---- one participant's answers --------------------------------------------------------------

def _participant_answers(design: Design, index: int, model: ResponseModel, seed: int
                         ) -> list[tuple[PlannedTrial, dict[str, object], float]]:
    """Participant ``index``'s planned trials with their answers (question id → the value the
    study API takes: an int for Likert, text otherwise, None for an optional question left
    empty) and response times (ms, three decimals), in plan order."""
    rng = _generator(seed, index, _ANSWERS)
    factor, levels = main_factor(design)
    shifts = model.effect * level_positions(len(levels))
    pens = [pen.id for pen in design.pens]
    likert = [q for q in design.questions if q.type == "likert"]
    # Drawn first, in question order, so the offsets do not depend on the plan's order.
    offsets = {q.id: rng.normal(0.0, model.participant_sd) for q in likert}
    cuts = {q.id: likert_cuts(q.points or 2, model.participant_sd) for q in likert}
    answered = []
    for trial in participant_plan(design, index):
        level = level_of(trial, factor, levels)
        given: dict[str, object] = {}
        for question_id in trial.questions:
            question = design.question(question_id)
            if question.type == "likert":
                latent = offsets[question_id] + (shifts[level] if level is not None else 0.0) \
                    + rng.normal()
                given[question_id] = 1 + int(np.searchsorted(cuts[question_id], latent))
            elif question.type == "choice":
                choices = list(question.choices or ())
                if question.correct == "pen":
                    rate = pen_rate(model.rates[trial.modality], pens.index(trial.pen)
                                    if trial.pen in pens else 0, len(pens), model.pen_effect)
                    others = [choice for choice in choices if choice != trial.pen] or choices
                    if trial.pen in choices and rng.random() < rate:
                        given[question_id] = trial.pen
                    else:
                        given[question_id] = others[int(rng.integers(len(others)))]
                else:
                    given[question_id] = choices[int(rng.integers(len(choices)))]
            else:
                given[question_id] = "simulated" if question.required else None
        log_rt = model.log_rt_mean + model.modality_rt.get(trial.modality, 0.0) + \
            rng.normal(0.0, model.log_rt_sd)
        answered.append((trial, given, round(math.exp(log_rt), 3)))
    return answered


def simulated_trials(design: Design, participants: int, *, model: ResponseModel | None = None,
                     seed: int = 0, site: str = "simulated") -> pd.DataFrame:
    """Simulated participants' answers to every planned trial, in the studies' export format.

    One row per answer (training, experimental and questionnaire trials), participants
    ``S01``… on plan rows 0… of the design's own plan seed
    (:func:`realpen.study.plan.participant_plan` gives block, trial, phase, condition, modality,
    pen, repetition and ink), answered by ``model`` (see the module doc). Deterministic from
    ``seed``: participant ``i`` draws from ``SeedSequence([seed, i, 2])`` (numpy PCG64), so the
    first participants' answers do not depend on how many there are.

    Args:
        design: the study design (:func:`realpen.study.design.load_design`).
        participants: how many, 1..1000.
        model: how they answer; default ``ResponseModel()`` (no Likert effect, the paper's
            recognition rates).
        seed: the answers' seed, 0..2⁶³−1 (not the plan's: plans use the design's seed, as the
            study service does).
        site: the ``site`` column.

    Returns:
        A DataFrame with :data:`SIMULATED_COLUMNS`, ordered by participant, trial and the
        trial's question order (the export's order): text columns as ``str``, ``session``
        (= the participant's number), ``trial`` and ``repetition`` as ``int``, ``answer``
        text (a Likert point as ``"4"``, ``""`` for an empty optional answer), ``correct``
        ``"1"``/``"0"`` for recognition and ``""`` otherwise, ``rt_ms`` float (ms).

    Raises:
        ParameterError: a bad argument, or a model without a rate for a modality the design
            asks a recognition question in.

    Examples:
        >>> from realpen.study.design import load_design
        >>> frame = simulated_trials(load_design("study1"), 2, model=ResponseModel(effect=1.0))
        >>> len(frame), frame["participant"].unique().tolist()
        (26, ['S01', 'S02'])
        >>> frame.loc[0, ["condition", "question"]].tolist()
        ['A', 'Q1']
    """
    model = ResponseModel() if model is None else model
    check_inputs(design, participants, model, seed)
    if not isinstance(site, str):
        raise ParameterError("site", f"must be text, got {site!r}")
    return pd.concat([_participant_frame(design, index, int(participants), model, int(seed), site)
                      for index in range(int(participants))], ignore_index=True)


def _participant_frame(design: Design, index: int, participants: int, model: ResponseModel,
                       seed: int, site: str) -> pd.DataFrame:
    """Participant ``index``'s rows of :func:`simulated_trials`."""
    code = participant_code(index + 1, participants)
    rows = []
    for trial, given, rt_ms in _participant_answers(design, index, model, seed):
        for question_id in trial.questions:
            value = given[question_id]
            correct = ""
            if design.question(question_id).correct == "pen":
                correct = "1" if value == trial.pen else "0"
            rows.append((design.name, code, index + 1, trial.block, trial.n, trial.phase,
                         trial.condition, trial.modality, trial.pen, question_id,
                         "" if value is None else str(value), correct, rt_ms, site,
                         trial.repetition, trial.ink))
    frame = pd.DataFrame(rows, columns=list(SIMULATED_COLUMNS))
    return frame.astype({"session": "int64", "trial": "int64", "repetition": "int64",
                         "rt_ms": "float64"})


_EXPORT_EXTRA_BYTES = 80
"""What a store's export adds to each simulated row (bytes): the start and answer times and
the participant's details (``realpen.study.export``)."""


def simulated_bytes(design: Design, participants: int, *, model: ResponseModel | None = None,
                    seed: int = 0, site: str = "simulated", store: bool = False) -> int:
    """The size (bytes) of the trials CSV that simulating ``participants`` would write,
    estimated before simulating them: the header and the first participant's rows, written as
    :func:`write_simulated` writes them, times the participants (every participant answers the
    same planned trials; only the widths of answers and times differ, by a few bytes).

    Args:
        design, participants, model, seed, site: as :func:`simulated_trials`.
        store: the file is the export of a simulated store, whose rows also carry
            times and the participant's details (:data:`_EXPORT_EXTRA_BYTES` more a row).
    """
    model = ResponseModel() if model is None else model
    check_inputs(design, participants, model, seed)
    first = _participant_frame(design, 0, int(participants), model, int(seed), site)
    text = first.to_csv(index=False, float_format="%.3f", lineterminator="\n")
    header = text.index("\n") + 1
    per_participant = len(text.encode("utf-8")) - header
    if store:
        per_participant += _EXPORT_EXTRA_BYTES * len(first)
    return header + per_participant * int(participants)


def check_simulated_size(design: Design, participants: int, target: object, *,
                         model: ResponseModel | None = None, seed: int = 0,
                         store: bool = False) -> int:
    """Refuse, before anything is simulated, a simulation whose trials CSV ``realpen stats``
    would refuse (over :data:`realpen.stats.data.MAX_TRIALS_BYTES`).

    Returns:
        The estimated size (bytes, :func:`simulated_bytes`).

    Raises:
        RealPenError: one line naming ``target``, the estimate and the limit.
    """
    from realpen.stats.data import MAX_TRIALS_BYTES

    size = simulated_bytes(design, participants, model=model, seed=seed, store=store)
    if size > MAX_TRIALS_BYTES:
        most = max(1, int(participants) * MAX_TRIALS_BYTES // size)
        raise fail(target, f"would be about {size:,} bytes ({int(participants):,} simulated "
                           f"participants of {design.name}); trials CSV files are limited to "
                           f"{MAX_TRIALS_BYTES:,}, which `realpen stats` reads: simulate at "
                           f"most about {most:,}")
    return size


def simulate_store(design: Design, participants: int, store: str | os.PathLike, *,
                   model: ResponseModel | None = None, seed: int = 0,
                   site: str = "simulated") -> int:
    """Enter :func:`simulated_trials`' answers through the real study service into a store.

    The store is opened as the live server opens it (:func:`realpen.study.db.open_database`
    with ``create=True``: an SQLite file or a PostgreSQL URL, made or migrated as needed).
    Each participant ``S01``… gets a session with :func:`realpen.study.sessions.open_session`
    (plan row ``i``, consent given, ``site``), then every trial is fetched with
    :func:`~realpen.study.sessions.next_trial` and answered with
    :func:`~realpen.study.sessions.answer_trial`, each call in its own transaction as the live
    routes run them; so the store holds what a real study would, and the session checks every
    answer. In a new store the sessions are numbered 1…, as :func:`simulated_trials` numbers
    them, and ``realpen study export`` gives the same rows.

    Args:
        design: the study design.
        participants: how many, 1..1000.
        store: an SQLite file path or URL, or a PostgreSQL URL.
        model, seed, site: as :func:`simulated_trials`.

    Returns:
        The number of answers stored (rows of the export).

    Raises:
        ParameterError: a bad argument.
        RealPenError: one line naming the store: it cannot be opened, it already holds one of
            these participants of this design, the service refused an answer, or the store
            failed part way (:func:`realpen.study.db.store_error`: a full disk says so). A
            store this call made is then removed, so a failure leaves no half-simulated
            store behind (one that existed keeps the sessions committed before).
    """
    from realpen.study import sessions as service
    from realpen.study.db import STORE_ERRORS, hide_password, open_database, store_error

    model = ResponseModel() if model is None else model
    check_inputs(design, participants, model, seed)
    if not isinstance(site, str):
        raise ParameterError("site", f"must be text, got {site!r}")
    database = open_database(store, create=True)
    shown = hide_password(store)
    cache = service.DesignCache()
    stored = 0

    def run(operation, *args):
        # One transaction per operation, committed before the next: as the live routes do.
        with database.engine.begin() as conn:
            return operation(conn, *args)

    try:
        _check_no_sessions(database, design, shown)
        for index in range(int(participants)):
            code = participant_code(index + 1, int(participants))
            request = service.SessionRequest(code, site, {}, True, index)
            try:
                opened, created = run(service.open_session, design, request, cache)
            except service.StudyError as error:
                raise fail(shown, f"participant {code}: {error.detail}") from None
            if not created:
                raise fail(shown, f"already holds participant {code} of {design.name!r}; "
                                  f"simulate into a new store")
            session = opened["session"]
            for trial, given, rt_ms in _participant_answers(design, index, model, int(seed)):
                try:
                    offered = run(service.next_trial, session, cache)
                    if offered.get("trial") != trial.n or offered.get("pen") != trial.pen:
                        raise fail(shown, f"participant {code}: the session offers trial "
                                          f"{offered.get('trial')}, the plan says {trial.n}")
                    run(service.answer_trial, session, trial.n, given, rt_ms, cache)
                except service.StudyError as error:
                    raise fail(shown, f"participant {code}, trial {trial.n}: "
                                      f"{error.detail}") from None
                stored += len(trial.questions)
    except STORE_ERRORS as error:  # a full disk, a lost server: one line, as serve says it
        database.close()
        database.remove_files()
        raise store_error(store, error) from None
    except BaseException:
        database.close()
        database.remove_files()
        raise
    database.close()
    return stored


def _check_no_sessions(database, design: Design, shown: str) -> None:
    """Simulated answers never join a store's real ones: refuse a store that holds any
    session of the design."""
    from sqlalchemy import func, select

    from realpen.study.tables import sessions, studies

    with database.engine.connect() as conn:
        count = conn.execute(select(func.count()).select_from(sessions.join(
            studies, sessions.c.study_id == studies.c.id)).where(
            studies.c.name == design.name)).scalar_one()
    if count:
        raise fail(shown, f"already holds {count} session{'s' if count != 1 else ''} of "
                          f"{design.name!r}; simulate into a store without them (a new file)")


def write_simulated(frame: pd.DataFrame, target: str | os.PathLike) -> None:
    """Write :func:`simulated_trials`' frame as a trials CSV (the export's column order and
    number formats: ``rt_ms`` with three decimals), atomically."""
    from realpen.io.files import atomic_path

    with atomic_path(target) as temporary:
        frame.to_csv(temporary, index=False, float_format="%.3f", lineterminator="\n")


def write_simulated_trials(design: Design, participants: int, target: str | os.PathLike, *,
                           model: ResponseModel | None = None, seed: int = 0,
                           site: str = "simulated") -> None:
    """Simulate and write participants one at a time: the file :func:`write_simulated` writes
    of :func:`simulated_trials`, byte for byte, holding one participant's rows in memory.

    Refused first, writing nothing, when the file would exceed
    :data:`realpen.stats.data.MAX_TRIALS_BYTES` (:func:`check_simulated_size`); the written
    size is checked again as it grows (an estimate is an estimate).

    Raises:
        ParameterError: a bad argument.
        RealPenError: one line naming ``target``: too large, or it cannot be written.
    """
    from realpen.io.files import atomic_path
    from realpen.stats.data import MAX_TRIALS_BYTES

    model = ResponseModel() if model is None else model
    check_simulated_size(design, participants, target, model=model, seed=seed)
    if not isinstance(site, str):
        raise ParameterError("site", f"must be text, got {site!r}")
    with atomic_path(target) as temporary:
        with open(temporary, "w", encoding="utf-8", newline="") as handle:
            for index in range(int(participants)):
                frame = _participant_frame(design, index, int(participants), model, int(seed),
                                           site)
                frame.to_csv(handle, index=False, header=index == 0, float_format="%.3f",
                             lineterminator="\n")
                if handle.tell() > MAX_TRIALS_BYTES:
                    raise fail(target, f"grew past {MAX_TRIALS_BYTES:,} bytes, the most "
                                       f"`realpen stats` reads, at participant {index + 1:,}: "
                                       f"simulate fewer")
