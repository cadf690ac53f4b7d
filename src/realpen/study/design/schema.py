"""The schema of a design file: pydantic models of its pens, conditions, questions and blocks.

:class:`Design` is the whole file; :func:`validate_design` turns a parsed file into one (the
schema, then :func:`realpen.study.design.checks.check_design`, each problem worded by
:mod:`realpen.study.design.messages`); :func:`design_schema` is its JSON Schema. Reading files
and the built-in designs: :mod:`realpen.study.design.loader`.

May import: :mod:`realpen.errors`, :mod:`realpen.io` (the JSON reader), the other modules of
:mod:`realpen.study.design` (and pydantic).
"""

from __future__ import annotations

import hashlib
import json
import re
from typing import Annotated, Any, Literal

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
from realpen.io.limits import load_json
from realpen.study.design.checks import DesignProblem, check_design
from realpen.study.design.constants import (
    DEMOGRAPHICS,
    FORMAT,
    ID_PATTERN,
    LEVEL,
    MAX_ANSWER_CHARS,
    MODALITIES,
)
from realpen.study.design.messages import problem_line, shown

__all__ = ["Pen", "TactileSpec", "Condition", "Question", "ParticipantFields", "Defaults",
           "TrialGroup", "Block", "Design", "TrialSettings", "validate_design", "design_schema"]

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
                                 f"{shown(value)}")
            return str(value)
        if self.type == "choice":
            if not isinstance(value, str) or value not in (self.choices or ()):
                raise ValueError(f"must be one of {', '.join(self.choices or ())}, got "
                                 f"{shown(value)}")
            return value
        if not isinstance(value, str):
            raise ValueError(f"must be text, got {shown(value)}")
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
        data = text.encode("utf-8") if isinstance(text, str) else bytes(text)
        return validate_design(load_json(data, source), source)

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


# ---- reading ---------------------------------------------------------------------------------

def validate_design(document: Any, source: object) -> Design:
    """A design from a parsed document (the mapping a YAML or JSON file holds), checked.

    Args:
        document: the parsed file.
        source: what the messages name (the file's path).

    Returns:
        The design, its :attr:`Design.source` set to ``source``.

    Raises:
        RealPenError: one line naming ``source``, the field path and the problem (the first
            one, with how many more there are).
    """
    if document is None:
        raise fail(source, "is empty: a design needs name, title, pens, questions, blocks, …")
    if not isinstance(document, dict):
        raise fail(source, f"must be a mapping of the design's fields (name, title, pens, "
                           f"questions, blocks, …), got {type(document).__name__}")
    try:
        design = Design.model_validate(document)
    except ValidationError as error:
        # With the inputs: a wrong value is quoted back ("got 'x'").
        raise fail(source, problem_line(error.errors(include_url=False), Design)) from None
    try:
        check_design(design)
    except DesignProblem as problem:
        raise fail(source, str(problem)) from None
    design._source = str(source)
    return design


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
