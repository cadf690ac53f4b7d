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

The package, one job per module:

- :mod:`~realpen.study.design.constants` — the format's names and limits;
- :mod:`~realpen.study.design.schema` — the pydantic models (:class:`Design` and its parts), the
  validation of a parsed file, the JSON Schema;
- :mod:`~realpen.study.design.checks` — the rules the schema cannot state;
- :mod:`~realpen.study.design.messages` — pydantic's errors worded as field paths, through
  :func:`realpen.validation.validation_line`;
- :mod:`~realpen.study.design.loader` — the built-in designs and reading YAML and JSON files.

Every public name is importable from here (``from realpen.study.design import load_design,
Design``). Imports pydantic; PyYAML when a YAML file is read; numpy and the tactile module
only when a design with tactile parameters is checked. May import: :mod:`realpen.errors`,
:mod:`realpen.io`, :mod:`realpen.validation`, :mod:`realpen.tactile`.
"""

from realpen.study.design.constants import (
    DEMOGRAPHICS,
    FORMAT,
    ID_PATTERN,
    INKS,
    MAX_ANSWER_CHARS,
    MAX_DESIGN_BYTES,
    MAX_DESIGN_VALUES,
    MAX_PERMUTATION_LEVELS,
    MAX_TRIALS,
    MODALITIES,
    ORDERS,
    PHASES,
    QUESTION_TYPES,
)
from realpen.study.design.loader import builtin_designs, builtin_path, load_design
from realpen.study.design.schema import (
    Block,
    Condition,
    Defaults,
    Design,
    ParticipantFields,
    Pen,
    Question,
    TactileSpec,
    TrialGroup,
    TrialSettings,
    design_schema,
)

__all__ = ["FORMAT", "MODALITIES", "INKS", "PHASES", "ORDERS", "QUESTION_TYPES", "DEMOGRAPHICS",
           "ID_PATTERN", "MAX_DESIGN_BYTES", "MAX_DESIGN_VALUES", "MAX_ANSWER_CHARS",
           "MAX_TRIALS", "MAX_PERMUTATION_LEVELS", "Pen", "TactileSpec", "Condition",
           "Question", "ParticipantFields", "Defaults", "TrialGroup", "Block", "Design",
           "TrialSettings", "load_design", "builtin_designs", "builtin_path", "design_schema"]
