"""The rules of a design that its schema cannot state, each broken one named by its field path.

Ids are unique and every id a design uses is one it defines; likert scales have their ends
labelled; a block's order, levels and label fit what it repeats over; every trial asks a
question; the whole plans at most :data:`~realpen.study.design.constants.MAX_TRIALS` trials per
participant. The checks read a design that pydantic has already validated
(:mod:`realpen.study.design.schema`, which calls :func:`check_design`); the models are not
imported here, so that the schema can call the checks.

May import: :mod:`realpen.errors`, :mod:`realpen.study.design.constants`; :mod:`realpen.tactile`
only when a design has tactile parameters.
"""

from __future__ import annotations

from typing import Any

from realpen.errors import ParameterError
from realpen.study.design.constants import LEVEL, MAX_PERMUTATION_LEVELS, MAX_TRIALS

__all__ = ["DesignProblem", "check_design"]


class DesignProblem(Exception):
    """A problem at a field path (``blocks[1].trials[0]``), said in one line by the reader."""

    def __init__(self, path: str, message: str):
        super().__init__(f"{path}: {message}" if path else message)


def _duplicates(path: str, values: list[str], what: str) -> None:
    seen: set[str] = set()
    for index, value in enumerate(values):
        if value in seen:
            raise DesignProblem(f"{path}[{index}]", f"duplicate {what} {value!r}")
        seen.add(value)


def _one_of(path: str, value: str | None, known: list[str], what: str) -> None:
    if value is not None and value not in known:
        raise DesignProblem(path, f"unknown {what} {value!r} (the design's {what}s: "
                             f"{', '.join(known) or 'none'})")


def check_design(design: Any) -> None:
    """Check the rules a design's schema cannot state: ids unique and known, scales consistent,
    the structure plannable (at most :data:`MAX_TRIALS` trials per participant).

    Args:
        design: a :class:`realpen.study.design.Design` that pydantic has validated.

    Raises:
        DesignProblem: the first rule broken, with the field path it is at.
    """
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

    def settings(path: str, item: Any) -> None:
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
            raise DesignProblem(where, f"the design plans more than {MAX_TRIALS:,} trials per "
                                  f"participant")


def _check_tactile(path: str, spec: Any) -> None:
    # The tactile module (and numpy) load only when a design has tactile parameters.
    from realpen.tactile.conditions import TactileParams

    try:
        TactileParams(**spec.keywords())
    except ParameterError as error:
        field = error.parameter if error.parameter in type(spec).model_fields else ""
        raise DesignProblem(f"{path}.{field}" if field else path, error.problem) from None


def _check_question(path: str, question: Any, pens: list[str], modalities: list[str]) -> None:
    kind = question.type
    if kind == "likert":
        if question.points is None:
            raise DesignProblem(f"{path}.points", "a likert question needs points (2–11)")
        for point in question.anchors:
            if not 1 <= point <= question.points:
                raise DesignProblem(f"{path}.anchors", f"anchor {point} is outside the scale's points "
                                                  f"1..{question.points}")
        ends = [end for end in (1, question.points) if end not in question.anchors]
        if ends:
            raise DesignProblem(f"{path}.anchors", f"label both ends of the scale: no anchor for "
                                              f"{' and '.join(map(str, ends))} (points: "
                                              f"{question.points})")
    else:
        for field in ("points", "anchors"):
            if getattr(question, field):
                raise DesignProblem(f"{path}.{field}", f"only likert questions have {field}")
    if kind == "choice":
        if question.choices is None:
            raise DesignProblem(f"{path}.choices", "a choice question needs choices")
        if question.choices == "pens":  # left by Design's pen expansion only when the pens are bad
            raise DesignProblem(f"{path}.choices", "'pens' needs the design's pens listed")
        if len(question.choices) < 2:
            raise DesignProblem(f"{path}.choices", "a choice question needs at least 2 choices")
        _duplicates(f"{path}.choices", question.choices, "choice")
    else:
        if question.choices is not None:
            raise DesignProblem(f"{path}.choices", "only choice questions have choices")
        if question.correct is not None:
            raise DesignProblem(f"{path}.correct", "only choice questions have a correct answer")
    if question.modalities is not None:
        _duplicates(f"{path}.modalities", list(question.modalities), "modality")
        for index, modality in enumerate(question.modalities):
            _one_of(f"{path}.modalities[{index}]", modality, modalities, "modality")


def _check_block(design: Any, where: str, block: Any, earlier: list[str],
                 labels: dict[str, str], pens: list[str], modalities: list[str]) -> int:
    """Check one block; returns how many trials it plans per participant."""
    if block.over == "none":
        for field in ("levels", "order", "same_order_as"):
            if getattr(block, field) is not None:
                raise DesignProblem(f"{where}.{field}", "only a block over conditions or modalities "
                                                   "has " + field.replace("_", " "))
    if block.order is not None and block.same_order_as is not None:
        raise DesignProblem(f"{where}.same_order_as", "give order or same_order_as, not both")
    if block.over == "conditions" and not design.conditions:
        raise DesignProblem(f"{where}.over", "the design has no conditions")
    levels = design.block_levels(block)
    known = [c.id for c in design.conditions] if block.over == "conditions" else modalities
    what = "condition" if block.over == "conditions" else "modality"
    if block.levels is not None:
        _duplicates(f"{where}.levels", levels, what)
        for index, level in enumerate(levels):
            _one_of(f"{where}.levels[{index}]", level, known, what)
    if design.block_order(block) == "permutations" and len(levels) > MAX_PERMUTATION_LEVELS:
        raise DesignProblem(f"{where}.order", f"all permutations of {len(levels)} levels are too many "
                                         f"sequences (at most {MAX_PERMUTATION_LEVELS} levels); "
                                         f"use williams")
    if block.same_order_as is not None:
        if block.same_order_as not in earlier:
            raise DesignProblem(f"{where}.same_order_as", f"no earlier block {block.same_order_as!r} "
                                                     f"(earlier blocks: "
                                                     f"{', '.join(earlier) or 'none'})")
        leader = next(other for other in design.blocks if other.id == block.same_order_as)
        if leader.over != block.over or \
                sorted(design.block_levels(leader)) != sorted(levels):
            raise DesignProblem(f"{where}.same_order_as", f"block {leader.id!r} is not over the same "
                                                     f"levels")
    if block.over != "none" and block.label is not None and LEVEL not in block.label \
            and len(levels) > 1:
        raise DesignProblem(f"{where}.label", f"must hold {LEVEL}: the block repeats over "
                                         f"{len(levels)} levels")
    for level in levels or [None]:
        label = block.label_for(level)
        if label in labels:
            raise DesignProblem(f"{where}.label", f"block label {label!r} is also {labels[label]}'s; "
                                             f"labels name the blocks in exports")
        labels[label] = where
    trials = 0
    for g, group in enumerate(block.trials):
        path = f"{where}.trials[{g}]"
        _one_of(f"{path}.pen", group.pen, pens, "pen")
        _one_of(f"{path}.modality", group.modality, modalities, "modality")
        if group.modality is not None and block.over == "modalities":
            raise DesignProblem(f"{path}.modality", "the block's levels set the modality")
        if group.pens is not None and group.pen is not None:
            raise DesignProblem(f"{path}.pen", "give pen or pens, not both")
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
                    raise DesignProblem(f"{path}.questions", f"no question is asked in its "
                                                        f"{trial.modality} trials (each "
                                                        f"applies to other modalities)")
                for qid in asked:
                    question = design.question(qid)
                    if question.correct == "pen" and pen not in (question.choices or ()):
                        raise DesignProblem(f"{path}.questions", f"question {qid!r} is right when the "
                                                            f"answer is the trial's pen, but "
                                                            f"{pen!r} is not among its choices")
            trials += len(group_pens) * group.repetitions
    return trials
