"""What a study analysis hands to the report and the figures: :class:`StudyAnalysis`.

The analyses (:mod:`realpen.stats.analyses`) fill it; :mod:`realpen.stats.report` and
:mod:`realpen.stats.figures` only read it. Every table is a tidy DataFrame whose columns
are listed below, so the report and the figures never recompute a statistic.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import pandas as pd

__all__ = ["StudyAnalysis", "CELL_COLUMNS", "PARTICIPANT_COLUMNS", "CONFUSION_COLUMNS",
           "PAPER_COLUMNS"]

CELL_COLUMNS = ("outcome", "factor", "level", "mean", "ci_low", "ci_high", "ci_method", "n",
                "unit")
"""``cells``: one row per outcome × level of a factor (``factor`` ``condition``, ``modality``,
``pen``, or two joined by ``:`` with ``level`` joined the same way, e.g. ``modality:pen`` and
``tactile:pencil``): the mean over participants (of each participant's cell value) with its
confidence interval (``ci_method`` ``t`` or ``bootstrap``), ``n`` participants, ``unit``
(``points``, ``%``, ``ms``). Response times are in ms: the geometric mean (exp of the mean log)
and its interval exp-transformed."""
PARTICIPANT_COLUMNS = ("outcome", "factor", "level", "participant", "value", "unit")
"""``participants``: each participant's own cell value (the lines a reader sees)."""
CONFUSION_COLUMNS = ("modality", "pen", "chosen", "count", "row_percent")
"""``confusion``: for recognition, how often each presented ``pen`` was answered as ``chosen``,
per modality; ``row_percent`` is 100 × count / the row's total."""
PAPER_COLUMNS = ("analysis", "outcome", "effect", "quantity", "paper", "ours", "note", "test",
                 "reported")
"""``paper``: one number the paper reported beside ours (:mod:`realpen.stats.paper`).
``quantity`` is ``statistic``, ``df1``, ``df2`` or ``p`` of a test (``test`` names ours, the
``analysis``, ``outcome`` and ``effect`` find its row of ``results``), ``rate_percent``, or
``mean``/``sd`` (response times in s); ``paper`` is NaN where the paper gives no value and
``reported`` the number as the paper printed it (``< .001`` for a bound, ``n.s.`` for a test
it calls not significant without a value, empty when not given);
``ours`` may be NaN with a ``note`` saying why."""


@dataclass
class StudyAnalysis:
    """Everything one ``realpen stats`` run found.

    Attributes:
        design: the design's name (``study1``, ``study2`` or another).
        title: a human title for the report.
        results: the rows of ``results.csv`` (:data:`realpen.stats.results.RESULT_COLUMNS`).
        cells: :data:`CELL_COLUMNS`.
        participants: :data:`PARTICIPANT_COLUMNS`.
        confusion: :data:`CONFUSION_COLUMNS` (empty without recognition questions).
        paper: :data:`PAPER_COLUMNS` (empty for designs the paper did not run).
        methods: the methods paragraphs (plain text, one per entry), naming every test,
            variant, correction and software version.
        excluded: ``{participant: reason}`` of those left out (``--exclude-incomplete``).
        notes: warnings worth a reader's eye (e.g. sphericity violated, ties in Wilcoxon).
        options: the options of the run (``paper_compatible``, ``wilcoxon_method`` ...) as
            ``{name: value}``, printed in the report.
        source: the trials file analysed (its name as given).
        power: optional power table: ``outcome, effect, test, participants, effect_size,
            power`` rows, and the smallest detectable effect rows (``power`` = 0.8).
    """

    design: str
    title: str
    results: pd.DataFrame
    cells: pd.DataFrame
    participants: pd.DataFrame
    confusion: pd.DataFrame
    paper: pd.DataFrame
    methods: list[str] = field(default_factory=list)
    excluded: dict[str, str] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    options: dict[str, object] = field(default_factory=dict)
    source: str = ""
    power: pd.DataFrame | None = None
