"""Study designs as data: the schema of a design file (YAML or JSON) and the built-in designs.

A design says *what* a study asks of each participant; :mod:`realpen.study.plan` turns it into
each participant's ordered trials. The built-in designs are the method's two studies,
``study1`` and ``study2`` (``designs/study1.yaml``, ``designs/study2.yaml``); a researcher
writes a variant — four pens, pens recorded on another surface, seven-point scales, another
counterbalancing — as a file, without code. The JSON Schema is :func:`design_schema`
(published as ``docs/study-design.schema.json``).

A design file, field by field (``?`` optional)::

    format?        "realpen.study-design/1"
    name           the study's name in exports (letters, digits, ``- _ .``; e.g. ``study1``)
    title, description?
    participants   the recommended number of participants (a plan may use any number)
    seed?          the default seed of the plans' randomisation (default 0)
    pens           pen ids, or {id, profile?, label?}: ``profile`` is the pen profile the live
                   app loads for it (a name or a bundle path; default: the id) — a pen on
                   another surface is a profile recorded on that surface
    modalities     the feedback modalities used: tactile | auditory | audio-tactile (and
                   none: no feedback, always allowed, e.g. a questionnaire-only trial)
    defaults?      {pen?, modality?, ink?} for every trial (default: the first pen, the first
                   modality, visible ink)
    conditions?    [{id, label?, tactile?, pen?, modality?, ink?}]; ``tactile`` is a study-1
                   condition letter (``B``) or {condition?, top?, subpatterns?, unit_ms?}, the
                   keywords of :class:`realpen.tactile.conditions.TactileParams` for the pattern
                   built from the pen's source (absent: the pen profile's own pattern)
    questions      [{id, type: likert|choice|text, text, points?, anchors?, choices?,
                   correct?, required?, modalities?}]
                   likert: ``points`` 2–11 and ``anchors`` {point: label} labelling at least
                   both ends; choice: ``choices`` (or ``pens``: the design's pen ids) and
                   ``correct: pen`` (right when the answer is the trial's pen); text: at most
                   2000 characters. ``modalities``: ask the question only in trials of these
                   modalities (study 2's ``balance``: audio-tactile only).
    participant_fields?  {demographics: [age, gender, handedness], consent?: text}
    blocks         the session, in order: [{id, over?, levels?, order?, same_order_as?, label?,
                   pen?, modality?, ink?, trials}]
                   over: none (one block) | conditions | modalities (one block per level,
                   ``levels`` defaulting to all of them); order of the levels: williams
                   (balanced Latin square; 2n sequences for odd n) | permutations (all n!) |
                   fixed (as listed) | random (shuffled per participant); or ``same_order_as``
                   an earlier block over the same levels; label: the block's name in exports,
                   ``{level}`` standing for the level (default ``{level}``; the block's id for
                   ``over: none``)
    trials         per block: groups of trials [{phase, pens?, repetitions?, randomise?, task,
                   questions, pen?, modality?, ink?}]
                   phase: training | experimental | questionnaire; pens: ``all`` or a list —
                   ``repetitions`` trials per pen (without ``pens``: ``repetitions`` trials of
                   the one pen in effect); randomise: shuffle the group's trials per participant

A trial's pen, modality and ink come from the first of: its trial group, its level (the
condition, or the modality of a block over modalities), its block, the design's ``defaults``.

Errors. :func:`load_design` refuses a bad design with ONE line naming the file, the field path
and the problem, e.g. ``"my.yaml: blocks[1].trials[0].questions[2]: unknown question 'Q9'
(the design's questions: Q1, Q2, comments)"``.

The design's ``version`` is the SHA-256 of its canonical JSON (:meth:`Design.to_json`: every
field, defaults included, keys sorted, compact), so the same design has the same version on
every machine; it changes when the design's content changes (or when a later RealPen adds a
field to the format).

Imports pydantic and PyYAML; numpy and the tactile module only when a design with tactile
parameters is checked.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
from importlib.resources import files
from pathlib import Path
from typing import Annotated, Any, Literal, get_args

from pydantic import (
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Field,
    PlainValidator,
    PrivateAttr,
    ValidationError,
    WithJsonSchema,
    model_validator,
)

from realpen.errors import ParameterError, fail

__all__ = ["FORMAT", "MODALITIES", "INKS", "PHASES", "ORDERS", "QUESTION_TYPES", "DEMOGRAPHICS",
           "ID_PATTERN", "MAX_DESIGN_BYTES", "MAX_DESIGN_VALUES", "MAX_ANSWER_CHARS",
           "MAX_TRIALS", "MAX_PERMUTATION_LEVELS", "Pen", "TactileSpec", "Condition",
           "Question", "ParticipantFields", "Defaults", "TrialGroup", "Block", "Design",
           "TrialSettings", "load_design", "builtin_designs", "builtin_path", "design_schema"]

FORMAT = "realpen.study-design/1"
MODALITIES = ("tactile", "auditory", "audio-tactile", "none")
INKS = ("visible", "hidden")
PHASES = ("training", "experimental", "questionnaire")  # = realpen.study.tables.PHASES
ORDERS = ("williams", "permutations", "fixed", "random")
QUESTION_TYPES = ("likert", "choice", "text")
DEMOGRAPHICS = ("age", "gender", "handedness")
ID_PATTERN = r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,63}$"  # the profile names' rule
LEVEL = "{level}"

MAX_DESIGN_BYTES = 1024 * 1024
"""The largest design file read (bytes): the built-in designs are about 4 kB."""
MAX_DESIGN_VALUES = 100_000
"""The most values (mappings, lists, scalars) a design file may hold once YAML aliases are
expanded: a YAML "billion laughs" document is refused before it is validated."""
MAX_ANSWER_CHARS = 2000
"""The longest free-text answer (characters)."""
MAX_TRIALS = 5000
"""The most trials a design may plan for one participant (study 2 plans 93)."""
MAX_PERMUTATION_LEVELS = 8
"""The most levels counterbalanced by all permutations (8! = 40,320 sequences)."""

_TEXT = 2000      # characters of a task, a description, a question's text
_LABEL = 200      # characters of a title or a label
_MANY = 64        # pens, conditions, levels, blocks, groups, choices, questions per list

Id = Annotated[str, Field(pattern=ID_PATTERN, description="letters, digits, - _ . (≤ 64)")]
Modality = Literal["tactile", "auditory", "audio-tactile", "none"]
Ink = Literal["visible", "hidden"]


class _Strict(BaseModel):
    # strict: a YAML "5" is not the number 5, a 1 is not true; nothing unknown is accepted.
    model_config = ConfigDict(strict=True, extra="forbid", frozen=True)


# ---- pens, conditions, questions --------------------------------------------------------------

def _pen_shorthand(value: Any) -> Any:
    return {"id": value} if isinstance(value, str) else value


class Pen(_Strict):
    """A pen of the design: its id (what answers and exports say) and the profile it plays."""

    id: Id
    profile: str | None = Field(None, min_length=1, max_length=1000,
                                description="the pen profile the live app loads (a name or a "
                                            "bundle path); default: the id")
    label: str = Field("", max_length=_LABEL, description="how the pen is named on screen")

    @property
    def profile_ref(self) -> str:
        """The profile to load for this pen: ``profile``, else the id."""
        return self.profile or self.id


PenEntry = Annotated[Pen, BeforeValidator(_pen_shorthand, json_schema_input_type=str | Pen)]


class TactileSpec(_Strict):
    """The tactile pattern of a condition: :class:`realpen.tactile.conditions.TactileParams`
    keywords (a study-1 condition letter, or the counts), built from the pen's source."""

    condition: Literal["A", "B", "C", "D", "E", "F"] | None = None
    top: int | None = Field(None, description="principal frequencies per sub-pattern")
    subpatterns: int | None = Field(None, description="sub-patterns in the loop")
    unit_ms: float | None = Field(None, description="sub-pattern length in ms")

    def keywords(self) -> dict:
        """The ``TactileParams`` keywords given (``{"condition": "B"}``)."""
        return {key: value for key, value in self.model_dump().items() if value is not None}


def _tactile_shorthand(value: Any) -> Any:
    return {"condition": value} if isinstance(value, str) else value


TactileEntry = Annotated[TactileSpec, BeforeValidator(_tactile_shorthand,
                                                      json_schema_input_type=str | TactileSpec)]


class _Settings(_Strict):
    pen: Id | None = Field(None, description="a pen id of the design")
    modality: Modality | None = None
    ink: Ink | None = Field(None, description="visible, or hidden (drawn in the background "
                                              "colour)")


class Defaults(_Settings):
    """The pen, modality and ink of every trial that sets none (default: the design's first
    pen, its first modality, visible ink)."""


class Condition(_Settings):
    """A condition: what a block over conditions varies."""

    id: Id
    label: str = Field("", max_length=_LABEL)
    tactile: TactileEntry | None = Field(None, description="a study-1 condition letter A–F or "
                                                           "{condition, top, subpatterns, "
                                                           "unit_ms}; absent: the pen's own "
                                                           "pattern")


def _anchor_keys(value: Any) -> Any:
    # YAML gives integer keys, JSON string keys: both mean the scale point.
    if isinstance(value, dict):
        return {int(key) if isinstance(key, str) and key.isdecimal() and len(key) < 4 else key:
                label for key, label in value.items()}
    return value


Anchors = Annotated[dict[int, Annotated[str, Field(min_length=1, max_length=_LABEL)]],
                    BeforeValidator(_anchor_keys),
                    WithJsonSchema({"type": "object", "propertyNames": {"pattern": "^[0-9]{1,2}$"},
                                    "additionalProperties": {"type": "string", "minLength": 1,
                                                             "maxLength": _LABEL},
                                    "description": "{point: label}; points 1..points, both ends "
                                                   "labelled"})]


def _choices_field(value: Any) -> Any:
    if value is None or value == "pens":
        return value
    if isinstance(value, list) and all(isinstance(item, str) for item in value):
        if len(value) > _MANY:
            raise ValueError(f"at most {_MANY} choices, got {len(value)}")
        for item in value:
            if not re.match(ID_PATTERN, item):
                raise ValueError(f"choice {item!r} is not an id (letters, digits, - _ .)")
        return value
    raise ValueError("must be a list of ids, or 'pens' (the design's pens)")


Choices = Annotated[Any, PlainValidator(_choices_field),
                    WithJsonSchema({"anyOf": [{"type": "array", "maxItems": _MANY,
                                               "items": {"type": "string",
                                                         "pattern": ID_PATTERN}},
                                              {"const": "pens"}],
                                    "description": "the answers; 'pens': the design's pen ids"})]


class Question(_Strict):
    """A question asked in trials.

    Attributes:
        id: what the answers and exports call it (``Q1``, ``pen``, ``realism``).
        type: ``likert`` (a point 1..points), ``choice`` (one of ``choices``) or ``text``.
        text: the question as the participant reads it.
        points: likert scale points (2–11).
        anchors: likert labels, {point: label}.
        choices: choice answers (ids).
        correct: ``"pen"``: an answer is right when it is the trial's pen.
        required: an answer must be given.
        modalities: asked only in trials of these modalities (None: in every trial that lists
            it).
    """

    id: Id
    type: Literal["likert", "choice", "text"]
    text: str = Field(min_length=1, max_length=_TEXT)
    points: int | None = Field(None, ge=2, le=11)
    anchors: Anchors = Field(default_factory=dict)
    choices: Choices = None
    correct: Literal["pen"] | None = None
    required: bool = True
    modalities: list[Modality] | None = Field(None, min_length=1, max_length=len(MODALITIES))

    def validate_answer(self, value: object) -> str:
        """The answer as stored (text), or ValueError with a short reason.

        A likert answer is a whole number 1..points (not a string, not a bool), a choice one of
        the choices (a string), a text answer a string of at most :data:`MAX_ANSWER_CHARS`
        characters. An optional question left unanswered (None, or "") gives "".

        >>> Question(id="Q1", type="likert", text="Real?", points=5,
        ...          anchors={1: "no", 5: "yes"}).validate_answer(4)
        '4'
        """
        if value is None or value == "":
            if self.required:
                raise ValueError("an answer is required")
            return ""
        if self.type == "likert":
            if isinstance(value, bool) or not isinstance(value, int) or \
                    not 1 <= value <= (self.points or 0):
                raise ValueError(f"must be a whole number from 1 to {self.points}, got "
                                 f"{_shown(value)}")
            return str(value)
        if self.type == "choice":
            if not isinstance(value, str) or value not in (self.choices or ()):
                raise ValueError(f"must be one of {', '.join(self.choices or ())}, got "
                                 f"{_shown(value)}")
            return value
        if not isinstance(value, str):
            raise ValueError(f"must be text, got {_shown(value)}")
        if len(value) > MAX_ANSWER_CHARS:
            raise ValueError(f"is {len(value):,} characters; answers are limited to "
                             f"{MAX_ANSWER_CHARS:,}")
        return value

    def is_correct(self, answer: object, trial: object) -> bool | None:
        """Whether ``answer`` is right for ``trial`` (a PlannedTrial or a mapping with
        ``pen``); None when the question has no right answer."""
        if self.correct != "pen":
            return None
        pen = trial.get("pen") if isinstance(trial, dict) else getattr(trial, "pen", None)
        return str(answer) == pen

    def applies_to(self, modality: str) -> bool:
        """Whether the question is asked in a trial of ``modality``."""
        return self.modalities is None or modality in self.modalities


def _shown(value: object) -> str:
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


class ParticipantFields(_Strict):
    """What the operator records for each participant when the session is created."""

    demographics: list[Literal["age", "gender", "handedness"]] = Field(
        default_factory=lambda: list(DEMOGRAPHICS), max_length=len(DEMOGRAPHICS),
        description="asked of every participant, in this order")
    consent: str | None = Field(None, min_length=1, max_length=20_000,
                                description="the consent text the participant agrees to (the "
                                            "operator records that they did); none: no "
                                            "consent is asked")


# ---- the session's structure ------------------------------------------------------------------

def _pens_field(value: Any) -> Any:
    if value is None or value == "all":
        return value
    if isinstance(value, list) and all(isinstance(item, str) for item in value):
        if not 1 <= len(value) <= _MANY:
            raise ValueError(f"must list 1 to {_MANY} pens, got {len(value)}")
        return value
    raise ValueError("must be 'all' or a list of pen ids")


PenList = Annotated[Any, PlainValidator(_pens_field),
                    WithJsonSchema({"anyOf": [{"const": "all"},
                                              {"type": "array", "minItems": 1, "maxItems": _MANY,
                                               "items": {"type": "string"}}],
                                    "description": "'all' (the design's pens) or pen ids: "
                                                   "`repetitions` trials per pen"})]


class TrialGroup(_Settings):
    """Trials of one phase in a block: ``repetitions`` per pen, in order or shuffled."""

    phase: Literal["training", "experimental", "questionnaire"]
    pens: PenList = None
    repetitions: int = Field(1, ge=1, le=1000, description="trials per pen (or of the one pen "
                                                           "in effect)")
    randomise: bool = Field(False, description="shuffle the group's trials per participant")
    task: str = Field(min_length=1, max_length=_TEXT, description="what the participant does")
    questions: list[Id] = Field(min_length=1, max_length=_MANY,
                                description="question ids, asked in this order")
    writing: bool = Field(True, description="the participant writes before answering (false: "
                                            "questions only, no writing surface)")
    feedback: bool = Field(False, description="after the answer, show the participant the "
                                              "right one (training trials of a recognition "
                                              "task)")


class Block(_Settings):
    """A part of the session, repeated over conditions or modalities (or once)."""

    id: Id
    over: Literal["none", "conditions", "modalities"] = "none"
    levels: list[Id] | None = Field(None, min_length=1, max_length=_MANY,
                                    description="the conditions or modalities, in their fixed "
                                                "order (default: all)")
    order: Literal["williams", "permutations", "fixed", "random"] | None = Field(
        None, description="how each participant's order of the levels is chosen (default "
                          "fixed)")
    same_order_as: Id | None = Field(None, description="an earlier block over the same "
                                                       "levels whose order this one follows")
    label: str | None = Field(None, min_length=1, max_length=_LABEL,
                              description="the block's name in exports; {level} stands for the "
                                          "level")
    trials: list[TrialGroup] = Field(min_length=1, max_length=_MANY)

    def label_for(self, level: str | None) -> str:
        """The block's label for ``level`` (None for a block over none)."""
        if level is None:
            return self.label or self.id
        return (self.label or LEVEL).replace(LEVEL, level)


class TrialSettings(BaseModel):
    """A planned trial's pen, modality, ink and tactile keywords (resolved from the design)."""

    model_config = ConfigDict(frozen=True)

    pen: str
    modality: str
    ink: str
    tactile: dict | None


def _by_id(items: list, id: str, kind: str):
    """The item of ``items`` whose ``id`` is ``id``; a :class:`ParameterError` naming ``kind``
    and the ids there are otherwise."""
    for item in items:
        if item.id == id:
            return item
    raise ParameterError(kind, f"unknown {kind} {id!r} (the design's {kind}s: "
                               f"{', '.join(item.id for item in items) or 'none'})")


class Design(_Strict):
    """A study design; see the module doc for its fields. Read one with :func:`load_design`."""

    format: Literal["realpen.study-design/1"] = FORMAT
    name: Id
    title: str = Field(min_length=1, max_length=_LABEL)
    description: str = Field("", max_length=_TEXT * 5)
    participants: int = Field(ge=1, le=1000, description="the recommended number")
    seed: int = Field(0, ge=0, le=2**63 - 1, description="the plans' default seed")
    pens: list[PenEntry] = Field(min_length=1, max_length=_MANY)
    modalities: list[Modality] = Field(min_length=1, max_length=len(MODALITIES))
    defaults: Defaults = Field(default_factory=Defaults)
    conditions: list[Condition] = Field(default_factory=list, max_length=_MANY)
    questions: list[Question] = Field(min_length=1, max_length=_MANY)
    participant_fields: ParticipantFields = Field(default_factory=ParticipantFields)
    blocks: list[Block] = Field(min_length=1, max_length=_MANY)

    _source: str = PrivateAttr("")

    @model_validator(mode="before")
    @classmethod
    def _expand_pens(cls, data: Any) -> Any:
        """``choices: pens`` becomes the design's pen ids, so the stored design says them."""
        if not isinstance(data, dict) or not isinstance(data.get("questions"), list) or \
                not isinstance(data.get("pens"), list):
            return data
        ids = [pen if isinstance(pen, str) else pen.get("id") if isinstance(pen, dict) else None
               for pen in data["pens"]]
        if not all(isinstance(pen, str) for pen in ids):
            return data
        questions = [{**question, "choices": list(ids)}
                     if isinstance(question, dict) and question.get("choices") == "pens"
                     else question for question in data["questions"]]
        return {**data, "questions": questions}

    # -- identity ------------------------------------------------------------------------------

    def to_json(self) -> str:
        """The canonical JSON text: every field, keys sorted, compact, UTF-8 as is."""
        return json.dumps(self.model_dump(mode="json"), sort_keys=True, separators=(",", ":"),
                          ensure_ascii=False)

    @property
    def version(self) -> str:
        """SHA-256 (hex) of :meth:`to_json`."""
        return hashlib.sha256(self.to_json().encode("utf-8")).hexdigest()

    @classmethod
    def from_json(cls, text: str | bytes, source: object = "design JSON") -> Design:
        """Read a design back from :meth:`to_json` (or any design JSON text).

        Raises:
            RealPenError: one line naming ``source``, the field and the problem.
        """
        from realpen.io.limits import load_json

        data = text.encode("utf-8") if isinstance(text, str) else bytes(text)
        return _validate(load_json(data, source), source)

    @property
    def source(self) -> str:
        """Where the design was read from (a path), or "" when built in memory."""
        return self._source

    # -- look-ups ------------------------------------------------------------------------------

    def question(self, id: str) -> Question:
        """The question ``id``.

        Raises:
            ParameterError: no such question.
        """
        return _by_id(self.questions, id, "question")

    def pen(self, id: str) -> Pen:
        """The pen ``id`` (its ``profile_ref`` is the profile to load).

        Raises:
            ParameterError: no such pen.
        """
        return _by_id(self.pens, id, "pen")

    def condition(self, id: str) -> Condition:
        """The condition ``id``.

        Raises:
            ParameterError: no such condition.
        """
        return _by_id(self.conditions, id, "condition")

    # -- structure (what plans are made of) ----------------------------------------------------

    def block_levels(self, block: Block) -> list[str]:
        """The levels ``block`` repeats over, in their listed order ([] for ``over: none``)."""
        if block.over == "none":
            return []
        if block.levels is not None:
            return list(block.levels)
        if block.over == "conditions":
            return [condition.id for condition in self.conditions]
        return list(self.modalities)

    def block_order(self, block: Block) -> str:
        """How ``block``'s levels are ordered: an :data:`ORDERS` name, or ``"same"`` (the
        order of ``same_order_as``)."""
        if block.same_order_as is not None:
            return "same"
        return block.order or "fixed"

    def group_pens(self, block: Block, level: str | None, group: TrialGroup) -> list[str]:
        """The pens ``group`` plans a trial (times ``repetitions``) for, in listed order."""
        if group.pens == "all":
            return [pen.id for pen in self.pens]
        if group.pens is not None:
            return list(group.pens)
        return [self.settings(block, level, group).pen]

    def settings(self, block: Block, level: str | None, group: TrialGroup,
                 pen: str | None = None) -> TrialSettings:
        """The pen, modality, ink and tactile keywords of a trial of ``group`` in ``block`` at
        ``level``: the first set of the group (or ``pen``), the level, the block, the design's
        defaults."""
        condition = None
        level_modality = None
        if level is not None and block.over == "conditions":
            condition = self.condition(level)
        elif level is not None and block.over == "modalities":
            level_modality = level
        chain = [group, condition, block, self.defaults]
        pen = pen or _first(chain, "pen") or self.pens[0].id
        modality = group.modality or level_modality or _first(chain[1:], "modality") \
            or self.modalities[0]
        ink = _first(chain, "ink") or "visible"
        tactile = condition.tactile.keywords() if condition is not None and condition.tactile \
            else None
        return TrialSettings(pen=pen, modality=modality, ink=ink, tactile=tactile)

    def trial_questions(self, group: TrialGroup, modality: str) -> tuple[str, ...]:
        """The ids of ``group``'s questions asked in a trial of ``modality``."""
        return tuple(qid for qid in group.questions if self.question(qid).applies_to(modality))


def _first(chain: list, field: str) -> str | None:
    for item in chain:
        value = getattr(item, field, None) if item is not None else None
        if value is not None:
            return value
    return None


# ---- reading and checking ---------------------------------------------------------------------

class _Problem(Exception):
    """A problem at a field path (``blocks[1].trials[0]``), said in one line by the reader."""

    def __init__(self, path: str, message: str):
        super().__init__(f"{path}: {message}" if path else message)


def _path(loc: tuple) -> str:
    text = ""
    for part in loc:
        if isinstance(part, int):
            text += f"[{part}]"
        elif part == "[key]":
            continue
        else:
            text += f".{part}" if text else str(part)
    return text


def _model_at(loc: tuple) -> type[BaseModel] | None:
    """The model whose field ``loc`` ends in (for naming the fields allowed there)."""
    model: Any = Design
    for part in loc:
        if isinstance(part, int):
            continue
        if not (isinstance(model, type) and issubclass(model, BaseModel)) or \
                part not in model.model_fields:
            return None
        model = _inner_model(model.model_fields[part].annotation)
    return model if isinstance(model, type) and issubclass(model, BaseModel) else None


def _inner_model(annotation: Any) -> type[BaseModel] | None:
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return annotation
    for argument in get_args(annotation):
        found = _inner_model(argument)
        if found is not None:
            return found
    return None


def _explain(error: dict) -> str:
    """One pydantic error as a path and a plain problem."""
    loc = tuple(error["loc"])
    kind = error["type"]
    if kind == "extra_forbidden":
        model = _model_at(loc[:-1])
        allowed = f" (allowed here: {', '.join(model.model_fields)})" if model else ""
        return f"{_path(loc)}: unknown field{allowed}"
    if kind == "missing":
        return f"{_path(loc)}: missing (required)"
    message = error["msg"].removeprefix("Value error, ")
    message = message[0].lower() + message[1:] if message else message
    if kind == "string_pattern_mismatch":
        message = "must be an id: a letter or digit, then letters, digits, - _ . (≤ 64)"
    elif kind in ("model_type", "model_attributes_type", "dict_type"):
        message = "must be a mapping (field: value)"
    elif kind == "list_type":
        message = "must be a list"
    if "input" in error and not isinstance(error["input"], (dict, list)):
        message += f", got {_shown(error['input'])}"
    if loc and loc[-1] == "[key]":  # a mapping's key: {1: "no"} has the key 1
        loc, message = loc[:-2], f"key {loc[-2]!r}: {message}"
    where = _path(loc)
    return f"{where}: {message}" if where else message


def _validate(document: Any, source: object) -> Design:
    if document is None:
        raise fail(source, "is empty: a design needs name, title, pens, questions, blocks, …")
    if not isinstance(document, dict):
        raise fail(source, f"must be a mapping of the design's fields (name, title, pens, "
                           f"questions, blocks, …), got {type(document).__name__}")
    try:
        design = Design.model_validate(document)
    except ValidationError as error:
        problems = error.errors(include_url=False)
        # A misspelt field is also a missing one: the unknown name says what went wrong.
        problems.sort(key=lambda problem: problem["type"] != "extra_forbidden")
        others = len(problems) - 1
        more = f" (and {others} more problem{'s' if others > 1 else ''})" if others else ""
        raise fail(source, _explain(problems[0]) + more) from None
    try:
        _check(design)
    except _Problem as problem:
        raise fail(source, str(problem)) from None
    design._source = str(source)
    return design


def _duplicates(path: str, values: list[str], what: str) -> None:
    seen: set[str] = set()
    for index, value in enumerate(values):
        if value in seen:
            raise _Problem(f"{path}[{index}]", f"duplicate {what} {value!r}")
        seen.add(value)


def _one_of(path: str, value: str | None, known: list[str], what: str) -> None:
    if value is not None and value not in known:
        raise _Problem(path, f"unknown {what} {value!r} (the design's {what}s: "
                             f"{', '.join(known) or 'none'})")


def _check(design: Design) -> None:
    """The rules the schema cannot state: ids unique and known, scales consistent, the
    structure plannable."""
    pens = [pen.id for pen in design.pens]
    _duplicates("pens", pens, "pen")
    _duplicates("modalities", list(design.modalities), "modality")
    modalities = list(dict.fromkeys([*design.modalities, "none"]))
    conditions = [condition.id for condition in design.conditions]
    _duplicates("conditions", conditions, "condition")
    questions = [question.id for question in design.questions]
    _duplicates("questions", questions, "question")
    _duplicates("blocks", [block.id for block in design.blocks], "block")
    _duplicates("participant_fields.demographics", list(design.participant_fields.demographics),
                "field")

    def settings(path: str, item: _Settings) -> None:
        _one_of(f"{path}.pen", item.pen, pens, "pen")
        _one_of(f"{path}.modality", item.modality, modalities, "modality")

    settings("defaults", design.defaults)
    for index, condition in enumerate(design.conditions):
        settings(f"conditions[{index}]", condition)
        if condition.tactile is not None:
            _check_tactile(f"conditions[{index}].tactile", condition.tactile)
    for index, question in enumerate(design.questions):
        _check_question(f"questions[{index}]", question, pens, modalities)

    block_ids: list[str] = []
    labels: dict[str, str] = {}
    total = 0
    for b, block in enumerate(design.blocks):
        where = f"blocks[{b}]"
        settings(where, block)
        total += _check_block(design, where, block, block_ids, labels, pens, modalities)
        block_ids.append(block.id)
        if total > MAX_TRIALS:
            raise _Problem(where, f"the design plans more than {MAX_TRIALS:,} trials per "
                                  f"participant")


def _check_tactile(path: str, spec: TactileSpec) -> None:
    from realpen.tactile.conditions import TactileParams

    try:
        TactileParams(**spec.keywords())
    except ParameterError as error:
        field = error.parameter if error.parameter in TactileSpec.model_fields else ""
        raise _Problem(f"{path}.{field}" if field else path, error.problem) from None


def _check_question(path: str, question: Question, pens: list[str], modalities: list[str]) -> None:
    kind = question.type
    if kind == "likert":
        if question.points is None:
            raise _Problem(f"{path}.points", "a likert question needs points (2–11)")
        for point in question.anchors:
            if not 1 <= point <= question.points:
                raise _Problem(f"{path}.anchors", f"anchor {point} is outside the scale's points "
                                                  f"1..{question.points}")
        ends = [end for end in (1, question.points) if end not in question.anchors]
        if ends:
            raise _Problem(f"{path}.anchors", f"label both ends of the scale: no anchor for "
                                              f"{' and '.join(map(str, ends))} (points: "
                                              f"{question.points})")
    else:
        for field in ("points", "anchors"):
            if getattr(question, field):
                raise _Problem(f"{path}.{field}", f"only likert questions have {field}")
    if kind == "choice":
        if question.choices is None:
            raise _Problem(f"{path}.choices", "a choice question needs choices")
        if question.choices == "pens":  # left by _expand_pens only when the pens are bad
            raise _Problem(f"{path}.choices", "'pens' needs the design's pens listed")
        if len(question.choices) < 2:
            raise _Problem(f"{path}.choices", "a choice question needs at least 2 choices")
        _duplicates(f"{path}.choices", question.choices, "choice")
    else:
        if question.choices is not None:
            raise _Problem(f"{path}.choices", "only choice questions have choices")
        if question.correct is not None:
            raise _Problem(f"{path}.correct", "only choice questions have a correct answer")
    if question.modalities is not None:
        _duplicates(f"{path}.modalities", list(question.modalities), "modality")
        for index, modality in enumerate(question.modalities):
            _one_of(f"{path}.modalities[{index}]", modality, modalities, "modality")


def _check_block(design: Design, where: str, block: Block, earlier: list[str],
                 labels: dict[str, str], pens: list[str], modalities: list[str]) -> int:
    """Check one block; returns how many trials it plans per participant."""
    if block.over == "none":
        for field in ("levels", "order", "same_order_as"):
            if getattr(block, field) is not None:
                raise _Problem(f"{where}.{field}", "only a block over conditions or modalities "
                                                   "has " + field.replace("_", " "))
    if block.order is not None and block.same_order_as is not None:
        raise _Problem(f"{where}.same_order_as", "give order or same_order_as, not both")
    if block.over == "conditions" and not design.conditions:
        raise _Problem(f"{where}.over", "the design has no conditions")
    levels = design.block_levels(block)
    known = [c.id for c in design.conditions] if block.over == "conditions" else modalities
    what = "condition" if block.over == "conditions" else "modality"
    if block.levels is not None:
        _duplicates(f"{where}.levels", levels, what)
        for index, level in enumerate(levels):
            _one_of(f"{where}.levels[{index}]", level, known, what)
    if design.block_order(block) == "permutations" and len(levels) > MAX_PERMUTATION_LEVELS:
        raise _Problem(f"{where}.order", f"all permutations of {len(levels)} levels are too many "
                                         f"sequences (at most {MAX_PERMUTATION_LEVELS} levels); "
                                         f"use williams")
    if block.same_order_as is not None:
        if block.same_order_as not in earlier:
            raise _Problem(f"{where}.same_order_as", f"no earlier block {block.same_order_as!r} "
                                                     f"(earlier blocks: "
                                                     f"{', '.join(earlier) or 'none'})")
        leader = next(other for other in design.blocks if other.id == block.same_order_as)
        if leader.over != block.over or \
                sorted(design.block_levels(leader)) != sorted(levels):
            raise _Problem(f"{where}.same_order_as", f"block {leader.id!r} is not over the same "
                                                     f"levels")
    if block.over != "none" and block.label is not None and LEVEL not in block.label \
            and len(levels) > 1:
        raise _Problem(f"{where}.label", f"must hold {LEVEL}: the block repeats over "
                                         f"{len(levels)} levels")
    for level in levels or [None]:
        label = block.label_for(level)
        if label in labels:
            raise _Problem(f"{where}.label", f"block label {label!r} is also {labels[label]}'s; "
                                             f"labels name the blocks in exports")
        labels[label] = where
    trials = 0
    for g, group in enumerate(block.trials):
        path = f"{where}.trials[{g}]"
        _one_of(f"{path}.pen", group.pen, pens, "pen")
        _one_of(f"{path}.modality", group.modality, modalities, "modality")
        if group.modality is not None and block.over == "modalities":
            raise _Problem(f"{path}.modality", "the block's levels set the modality")
        if group.pens is not None and group.pen is not None:
            raise _Problem(f"{path}.pen", "give pen or pens, not both")
        if isinstance(group.pens, list):
            _duplicates(f"{path}.pens", group.pens, "pen")
            for index, pen in enumerate(group.pens):
                _one_of(f"{path}.pens[{index}]", pen, pens, "pen")
        _duplicates(f"{path}.questions", group.questions, "question")
        for index, qid in enumerate(group.questions):
            _one_of(f"{path}.questions[{index}]", qid, [q.id for q in design.questions],
                    "question")
        for level in levels or [None]:
            group_pens = design.group_pens(block, level, group)
            for pen in group_pens:
                trial = design.settings(block, level, group, pen)
                asked = design.trial_questions(group, trial.modality)
                if not asked:
                    raise _Problem(f"{path}.questions", f"no question is asked in its "
                                                        f"{trial.modality} trials (each "
                                                        f"applies to other modalities)")
                for qid in asked:
                    question = design.question(qid)
                    if question.correct == "pen" and pen not in (question.choices or ()):
                        raise _Problem(f"{path}.questions", f"question {qid!r} is right when the "
                                                            f"answer is the trial's pen, but "
                                                            f"{pen!r} is not among its choices")
            trials += len(group_pens) * group.repetitions
    return trials


# ---- files ------------------------------------------------------------------------------------

_BUILTIN = ("study1", "study2")


def builtin_designs() -> list[str]:
    """The names of the built-in designs (``["study1", "study2"]``)."""
    return list(_BUILTIN)


def builtin_path(name: str) -> Path:
    """The file of built-in design ``name``.

    Raises:
        ParameterError: not a built-in design.
    """
    if name not in _BUILTIN:
        raise ParameterError("design", f"unknown built-in design {name!r} (choose from "
                                       f"{', '.join(_BUILTIN)})")
    return Path(str(files("realpen.study") / "designs" / f"{name}.yaml"))


def load_design(source: str | os.PathLike) -> Design:
    """Read a design: a built-in name (``"study1"``, ``"study2"``) or a ``.yaml``/``.yml``/
    ``.json`` file.

    Raises:
        RealPenError: one line naming the file, the field path and the problem: a YAML or
            JSON syntax error (with its line), an unknown field, a wrong type, an unknown or
            duplicate id, likert anchors outside the scale, an unplannable structure, …
    """
    if isinstance(source, str) and source in _BUILTIN:
        path = builtin_path(source)
    else:
        path = Path(source)
    suffix = path.suffix.lower()
    if isinstance(source, str) and not suffix and os.sep not in source and "/" not in source \
            and not path.exists():
        raise fail(source, f"unknown design: give a built-in design ({', '.join(_BUILTIN)}) or "
                           f"a .yaml, .yml or .json file")
    if suffix not in (".yaml", ".yml", ".json"):
        raise fail(path, f"is not a design: give a .yaml, .yml or .json file, or a built-in "
                         f"design ({', '.join(_BUILTIN)})")
    if not path.is_file():
        raise fail(path, "no such design file" if not path.exists() else "is not a file")
    if suffix == ".json":
        from realpen.io.limits import check_size, load_json

        check_size(path, MAX_DESIGN_BYTES, "design files")
        document = load_json(path)
    else:
        document = _load_yaml(path)
    from realpen.io.limits import count_values

    if count_values(document, MAX_DESIGN_VALUES, keys=True) > MAX_DESIGN_VALUES:
        raise fail(path, f"holds more than {MAX_DESIGN_VALUES:,} values (YAML aliases "
                         f"included); the limit is {MAX_DESIGN_VALUES:,}")
    return _validate(document, path)


def _load_yaml(path: Path) -> Any:
    import yaml

    from realpen.io.limits import read_bounded

    data = read_bounded(path, MAX_DESIGN_BYTES, "design files")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as error:
        raise fail(path, f"is not UTF-8 text ({error.reason} at byte {error.start})") from None
    try:
        return yaml.load(text, Loader=_loader())  # noqa: S506 - a SafeLoader subclass
    except yaml.MarkedYAMLError as error:
        mark = error.problem_mark or error.context_mark
        where = f"line {mark.line + 1}, column {mark.column + 1}: " if mark else ""
        problem = " ".join(str(error.problem or error.context or "invalid YAML").split())
        if error.problem and error.context and error.context_mark:
            problem += (f" ({error.context} at line {error.context_mark.line + 1}, column "
                        f"{error.context_mark.column + 1})")
        kind = "YAML" if isinstance(error, yaml.constructor.ConstructorError) else \
            "YAML syntax error at"
        raise fail(path, f"{kind} {where}{problem}") from None
    except yaml.YAMLError as error:
        raise fail(path, f"YAML syntax error: {' '.join(str(error).split())}") from None
    except RecursionError:
        raise fail(path, "is nested too deeply") from None


_LOADER = None


def _loader():
    """A safe YAML loader (the C one when PyYAML has it) that refuses duplicate keys."""
    global _LOADER
    if _LOADER is None:
        import yaml

        base = getattr(yaml, "CSafeLoader", yaml.SafeLoader)

        class DesignLoader(base):  # type: ignore[misc, valid-type]
            def construct_mapping(self, node, deep=False):
                seen = set()
                for key_node, _ in node.value:
                    key = self.construct_object(key_node, deep=deep)
                    try:
                        duplicate = key in seen
                    except TypeError:  # an unhashable key: the base class says so
                        break
                    if duplicate:
                        raise yaml.constructor.ConstructorError(
                            None, None, f"duplicate key {key!r}", key_node.start_mark)
                    seen.add(key)
                return super().construct_mapping(node, deep=deep)

        _LOADER = DesignLoader
    return _LOADER


def design_schema() -> dict:
    """The JSON Schema of a design file (draft 2020-12), as ``docs/study-design.schema.json``
    publishes it."""
    schema = Design.model_json_schema()
    return {"$schema": "https://json-schema.org/draft/2020-12/schema",
            "title": "RealPen study design (realpen.study-design/1)",
            "description": "A study design for `realpen study plan` and `realpen serve` (YAML or "
                           "JSON). The built-in designs study1 and study2 follow it.",
            **{key: value for key, value in schema.items() if key not in ("title",
                                                                         "description")}}
