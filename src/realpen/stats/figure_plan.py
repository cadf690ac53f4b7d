"""Which figures a study analysis gets, their file names and captions, and writing them all.

:func:`study_figure_names` lists every figure that applies to an analysis (the paper's Figures
7, 10, 11 and 12 for the built-in studies, and recognition per modality against chance; means,
confusion and response times for another design; each participant's own data; the power
plot), :func:`figure_caption` words each one for the report (:func:`figure_captions`: all of
them at once), and :func:`save_study_figures` draws them (:mod:`realpen.stats.figures`,
:mod:`realpen.stats.power_plot`) and writes them as PNG (150 dpi) and SVG, all or nothing.

May import: :mod:`realpen.errors`, :mod:`realpen.io`, :mod:`realpen.display` and the figure
modules of :mod:`realpen.stats` (and pandas).
"""

from __future__ import annotations

import os
import re
from collections.abc import Iterable, Sequence
from pathlib import Path

import pandas as pd

from realpen.display.charts import MAX_VECTOR_PARTICIPANTS, factor_label
from realpen.display.images import DPI, FORMATS, figure_images, image_kinds
from realpen.errors import ParameterError
from realpen.io.files import write_files
from realpen.stats.figure_data import (
    LIKERT_JITTER,
    LIKERT_UNIT,
    QUESTIONNAIRE,
    RECOGNITION_OUTCOME,
    RT_OUTCOME,
    cell_table,
    chance_line,
    main_factor,
    outcome_label,
    outcome_names,
    participant_table,
)
from realpen.stats.figures import (
    MAX_PARTICIPANT_PANELS,
    figure7,
    figure10,
    figure11,
    figure12,
    means_figure,
    participants_figure,
    recognition_figure,
)
from realpen.stats.power_plot import has_power_figure, power_figure, split_power

__all__ = ["study_figure_names", "figure_caption", "figure_captions", "save_study_figures"]


def _file_stem(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9._-]+", "_", name).strip("._") or "outcome"


def study_figure_names(analysis) -> list[str]:
    """The names (file stems) of every figure that applies to ``analysis``, in report order.

    For the paper's designs (study1, study2): ``figure7`` (Likert outcomes over
    ``condition``), ``figure10`` (a confusion table), ``recognition`` (recognition per
    modality with the chance line), ``figure11`` (``log_rt`` over ``modality:pen``),
    ``figure12`` (Likert outcomes over ``modality``). For any other design:
    ``confusion`` and ``response-times`` (the same drawings without the paper's numbers) and
    ``means-<outcome>`` (one per outcome). For all: ``participants-<outcome>`` (one per outcome
    with participant values) and ``power``.

    Examples:
        >>> import pandas as pd
        >>> from realpen.stats.outcome import StudyAnalysis
        >>> empty = pd.DataFrame()
        >>> study_figure_names(StudyAnalysis("study1", "Study 1", empty, empty, empty, empty,
        ...                                  empty))
        []
    """
    return [name for name, _, _ in _figure_plan(analysis)]


def figure_caption(name: str, analysis) -> str:
    """The caption (plain text) of the figure ``name`` of :func:`study_figure_names`.

    Examples:
        >>> import pandas as pd
        >>> from realpen.stats.outcome import StudyAnalysis
        >>> table = pd.DataFrame({"outcome": "Q1", "effect": "condition", "test": "Friedman",
        ...                       "participants": [8, 12], "effect_size": 0.5,
        ...                       "power": [0.41, 0.62]})
        >>> empty = pd.DataFrame()
        >>> analysis = StudyAnalysis("study1", "Study 1", empty, empty, empty, empty, empty,
        ...                          power=table)
        >>> figure_caption("power", analysis)
        'Simulated power against the number of participants, per test and effect size (dotted: 80 % power).'
    """
    for planned, _, caption in _figure_plan(analysis):
        if planned == name:
            return caption
    raise ParameterError("name", f"no figure {name!r} for this analysis (it has "
                                 f"{', '.join(study_figure_names(analysis)) or 'none'})")


def figure_captions(analysis) -> dict[str, str]:
    """The caption (plain text) of every figure of :func:`study_figure_names`, by name, in
    report order: :func:`figure_caption` of each, the analysis's tables read once."""
    return {name: caption for name, _, caption in _figure_plan(analysis)}


def _ci_words(cells: pd.DataFrame, outcomes: Iterable[str]) -> str:
    """How the intervals of ``outcomes`` were computed, for a caption."""
    if "ci_method" not in cells.columns:
        return "95 % CI"
    methods = cells.loc[cells["outcome"].isin(list(outcomes)), "ci_method"].dropna().astype(str)
    named = {"t": "t-based", "bootstrap": "bootstrap"}
    found = [named.get(m, m) for m in dict.fromkeys(methods)]
    return f"95 % CI ({', '.join(found)})" if found else "95 % CI"


def _dots_words(count: int) -> str:
    """What a caption adds when ``count`` participants' dots are drawn as one faint image
    layer (above :data:`realpen.display.charts.MAX_VECTOR_PARTICIPANTS`); else nothing."""
    if count <= MAX_VECTOR_PARTICIPANTS:
        return ""
    return (f" The {count:,} participants' dots are one rasterised layer, each drawn faint: "
            "the darker the colour, the more of them there.")


def _lines_words(count: int, shift: str) -> str:
    """A Likert figure's words for its grey participant lines: one line each, shifted, up to
    :data:`realpen.display.charts.MAX_VECTOR_PARTICIPANTS` participants; aggregated above."""
    if count <= MAX_VECTOR_PARTICIPANTS:
        return f"grey lines: each participant's answers, {shift}."
    return (f"grey: the {count:,} participants' answers, aggregated: each step from one "
            "answer to the next level's is one line, as wide as how many participants took it "
            "(the widest: the most in its panel), each answer one dot, as large as how many "
            "gave it.")


def _figure_plan(analysis) -> list[tuple[str, object, str]]:
    """``(name, draw, caption)`` of every figure that applies; ``draw()`` returns the Figure."""
    plan: list[tuple[str, object, str]] = []
    participants = participant_table(analysis)

    def people(outcomes: Iterable[str]) -> int:
        return participants.loc[participants["outcome"].isin(list(outcomes)),
                                "participant"].nunique()

    cells = analysis.cells
    has_cells = isinstance(cells, pd.DataFrame) and len(cells) > 0
    shift = f"shifted by at most ±{LIKERT_JITTER:g} points so that tied answers stay visible"
    # The paper's figure numbers name the paper's figures only: another design's figures are
    # named by what they show (and its rating means are the means-* figures).
    paper = analysis.design in ("study1", "study2")
    if has_cells:
        cells = cell_table(analysis)
        likert = outcome_names(cells, factor="condition", unit=LIKERT_UNIT)
        if likert and paper:
            plan.append(("figure7", lambda: figure7(analysis),
                         f"Figure 7. {', '.join(outcome_label(analysis, o) for o in likert)}: "
                         f"mean rating per condition with its {_ci_words(cells, likert)}; "
                         + _lines_words(people(likert), shift)))
    chance = chance_line(analysis)
    # "1/3, guessing among 3 answers": the fraction and where it comes from.
    chance_words = (f"chance ({chance[1]}, guessing among {chance[1].split('/')[1]} answers)"
                    if chance is not None else "")
    if analysis.confusion is not None and len(analysis.confusion):
        plan.append(("figure10" if paper else "confusion", lambda: figure10(analysis),
                     ("Figure 10. " if paper else "")
                     + "Confusion matrix per modality: rows the pen presented, columns "
                     "the pen chosen; each cell gives the count of answers and its percentage "
                     "of the row (the colour, on one scale for all panels); outlined: correct "
                     "answers" + (f"; dashed on the colour bar: {chance_words}."
                                  if chance is not None else ".")))
    if has_cells and paper and RECOGNITION_OUTCOME in outcome_names(cells, factor="modality"):
        plan.append(("recognition", lambda: recognition_figure(analysis),
                     "Recognition per modality: the mean over participants of each one's "
                     f"percentage of right answers, with its {_ci_words(cells, [RECOGNITION_OUTCOME])}"
                     "; faint dots: each participant"
                     + (f"; dashed: {chance_words}." if chance is not None else ".")
                     + _dots_words(people([RECOGNITION_OUTCOME]))))
    if has_cells:
        if RT_OUTCOME in outcome_names(cells, factor="modality:pen"):
            plan.append(("figure11" if paper else "response-times", lambda: figure11(analysis),
                         ("Figure 11. " if paper else "")
                         + "Response time (ms) per modality × pen: the geometric mean "
                         "over participants (exp of the mean of each participant's mean log "
                         f"RT) with its {_ci_words(cells, [RT_OUTCOME])}, exp-transformed; "
                         "faint dots: each participant." + _dots_words(people([RT_OUTCOME]))))
        items = outcome_names(cells, factor="modality", unit=LIKERT_UNIT, known=QUESTIONNAIRE)
        if items and paper:
            single = [item for item in items if
                      cells.loc[(cells["outcome"] == item) & (cells["factor"] == "modality"),
                                "level"].nunique() == 1]
            only = f" Asked in one modality only: {', '.join(single)}." if single else ""
            plan.append(("figure12", lambda: figure12(analysis),
                         f"Figure 12. Questionnaire items per modality: mean rating with its "
                         f"{_ci_words(cells, items)}; {_lines_words(people(items), shift)}"
                         f"{only}"))
        if analysis.design not in ("study1", "study2"):
            for outcome in outcome_names(cells):
                marked = (f"; dashed: {chance_words}" if chance is not None
                          and outcome == RECOGNITION_OUTCOME else "")
                plan.append((f"means-{_file_stem(outcome)}",
                             lambda outcome=outcome: means_figure(analysis, outcome),
                             f"{outcome_label(analysis, outcome)}: mean per level of each "
                             f"factor with its {_ci_words(cells, [outcome])}; dots: each "
                             f"participant{marked}." + _dots_words(people([outcome]))))
    known = QUESTIONNAIRE if analysis.design == "study2" else ()
    for outcome in outcome_names(participants, known=("recognition", RT_OUTCOME, *known)):
        factor = main_factor(participants, outcome)
        count = people([outcome])
        levels = participants.loc[(participants["outcome"] == outcome)
                                  & (participants["factor"] == factor), "level"].unique()
        if count > MAX_PARTICIPANT_PANELS and (len(levels) > 1 or ":" in factor):
            caption = (f"{outcome_label(analysis, outcome)}, participant by participant: each "
                       f"row is one participant's own values across {factor_label(factor)} "
                       f"(exact, as colour), the {count} rows sorted by their mean; above: "
                       "the group mean of each column.")
        elif count > MAX_PARTICIPANT_PANELS:
            caption = (f"{outcome_label(analysis, outcome)}, participant by participant: "
                       "each dot is one "
                       "participant's own value (exact), side by side, drawn as one rasterised layer; "
                       "dashed: the group mean.")
        else:
            caption = (f"{outcome_label(analysis, outcome)}, participant by participant: each "
                       f"panel is one participant's own values across {factor_label(factor)} "
                       "(exact, not shifted); dashed: the group mean.")
        plan.append((f"participants-{_file_stem(outcome)}",
                     lambda outcome=outcome: participants_figure(analysis, outcome), caption))
    if has_power_figure(analysis.power):
        curves, detectable = split_power(analysis.power)
        parts = []
        if len(curves):
            parts.append("simulated power against the number of participants, per test and "
                         "effect size (dotted: 80 % power)")
        if len(detectable):
            parts.append("the smallest effect each test detects with 80 % power against the "
                         "number of participants")
        plan.append(("power", lambda: power_figure(analysis),
                     "; ".join(parts)[0].upper() + "; ".join(parts)[1:] + "."))
    names: dict[str, int] = {}
    unique = []
    for name, draw, caption in plan:  # two outcomes whose names differ only in odd characters
        names[name] = names.get(name, 0) + 1
        caption = caption.replace("\\$", "$")  # captions are plain text, not matplotlib's
        unique.append((name if names[name] == 1 else f"{name}-{names[name]}", draw, caption))
    return unique


def save_study_figures(analysis, directory: str | os.PathLike, *,
                       formats: Sequence[str] = FORMATS, dpi: int = DPI) -> list[Path]:
    """Write every figure that applies to ``analysis`` into ``directory``, all or nothing.

    Each figure of :func:`study_figure_names` is drawn once and saved in every format
    (``figure7.png``, ``figure7.svg``, ``participants-Q1.png`` ...). All files are rendered in
    memory first and then written atomically (:func:`realpen.io.files.write_files`), so a
    failure leaves none of them behind, half-written or not. SVG text is drawn as paths, so
    the files look the same without the fonts.

    Args:
        analysis: a :class:`realpen.stats.outcome.StudyAnalysis`.
        directory: the folder to write into (made if missing).
        formats: file types, each one matplotlib can write (``png``, ``svg``, ``pdf``).
        dpi: resolution of raster formats in dots per inch.

    Returns:
        The paths written, figure by figure, in the order of ``formats``.

    Examples:
        >>> import pandas as pd, tempfile
        >>> from realpen.stats.outcome import StudyAnalysis
        >>> table = pd.DataFrame({"outcome": "Q1", "effect": "condition", "test": "Friedman",
        ...                       "participants": [8, 12], "effect_size": 0.5,
        ...                       "power": [0.41, 0.62]})
        >>> empty = pd.DataFrame()
        >>> analysis = StudyAnalysis("study1", "Study 1", empty, empty, empty, empty, empty,
        ...                          power=table)
        >>> with tempfile.TemporaryDirectory() as folder:
        ...     [path.name for path in save_study_figures(analysis, folder)]
        ['power.png', 'power.svg']
    """
    kinds = image_kinds(formats, dpi)
    directory = Path(directory)
    files: dict[Path, bytes] = {}
    for name, draw, _ in _figure_plan(analysis):
        for kind, data in figure_images(draw(), kinds, dpi=dpi).items():
            files[directory / f"{name}.{kind}"] = data
    write_files(files)
    return list(files)
