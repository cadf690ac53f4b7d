"""Figures of a study analysis: the paper's Figures 7, 10, 11 and 12, every participant's own
data, and the means of a generic design.

Every function reads a :class:`realpen.stats.outcome.StudyAnalysis` (its tables only: nothing
is recomputed here, so a figure shows exactly the numbers of ``results.csv`` and the report),
draws into the Axes it is given, or into a new figure (never pyplot's) when ``ax`` is None,
and returns the :class:`~matplotlib.figure.Figure`. Which figures apply to an analysis, their
captions and files: :mod:`realpen.stats.figure_plan`; the power plot:
:mod:`realpen.stats.power_plot`.

- :func:`figure7` — Likert outcomes (Q1, Q2) per condition: mean ± 95 % CI, participants behind.
- :func:`figure10` — a confusion matrix per modality: counts and row percentages, chance
  marked on the colour bar.
- :func:`recognition_figure` — recognition per modality: mean % correct ± 95 % CI, with the
  chance line.
- :func:`figure11` — response times (ms) per modality × pen: mean ± 95 % CI.
- :func:`figure12` — each questionnaire item per modality: mean ± 95 % CI, participant lines.
- :func:`participants_figure` — one small panel per participant across the main factor.
- :func:`means_figure` — mean ± CI per level of each factor of one outcome (generic designs;
  recognition with the chance line).

Colours are the Okabe–Ito palette (:data:`realpen.display.charts.PALETTE`), and wherever
colour tells groups apart a marker shape does too.

May import: :mod:`realpen.display`, :mod:`realpen.stats.figure_data` (and numpy, pandas,
matplotlib).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pandas as pd
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from realpen.display.axes import axes_list
from realpen.display.charts import (
    MARKERS,
    MAX_VECTOR_PARTICIPANTS,
    PALETTE,
    PARTICIPANT_COLOUR,
    cell_outline,
    draw_mean_ci,
    draw_participant_dots,
    draw_participant_lines,
    factor_label,
    label_text,
    level_axis,
    likert_limits,
    panel_title,
    panels,
    style_axes,
)
from realpen.stats.figure_data import (
    LIKERT_JITTER,
    LIKERT_UNIT,
    QUESTIONNAIRE,
    RECOGNITION_OUTCOME,
    RT_OUTCOME,
    axis_label,
    cell_rows,
    cell_table,
    chance_line,
    main_factor,
    no_data,
    ordered_levels,
    outcome_label,
    outcome_names,
    outcome_unit,
    participant_matrix,
    participant_table,
    require_table,
)

__all__ = ["figure7", "figure10", "figure11", "figure12", "recognition_figure",
           "participants_figure", "means_figure", "MAX_PARTICIPANT_PANELS", "CHANCE_COLOUR"]

MAX_COLUMNS = 4  # participant panels per row: wider would shrink on a page
MAX_PARTICIPANT_PANELS = 48
"""The most participants :func:`participants_figure` draws one panel each (12 rows of 4). A
larger study is one heat map, a row per participant: a panel each would take minutes to lay
out and a page per 48 participants to read. Likewise a single-level factor's participants are
labelled one by one up to this many."""
CHANCE_COLOUR = "#D55E00"
"""The chance line's colour (Okabe–Ito vermilion: apart from the means and the participants)."""


def _draw_chance(axis: Axes, chance: tuple[float, str]) -> None:
    """The dashed chance line across ``axis``, labelled ``chance (1/3)`` for its legend."""
    percent, text = chance
    axis.axhline(percent, color=CHANCE_COLOUR, lw=1.3, ls="--", zorder=3,
                 label=f"chance ({text})")


def figure7(analysis, ax: Axes | Sequence[Axes] | None = None, *,
            outcomes: Sequence[str] | None = None) -> Figure:
    """The paper's Figure 7: each Likert outcome's mean ± CI per condition (A–F).

    One panel per outcome (study 1: Q1 realism, Q2 comfort) with the mean over participants
    and its 95 % confidence interval (as the analysis computed it: ``cells``, factor
    ``condition``); each participant's answers are a thin grey line behind, shifted by at most
    ±0.12 points so that tied answers stay visible.

    Args:
        analysis: a :class:`realpen.stats.outcome.StudyAnalysis` with ``cells`` over
            ``condition`` in ``points``.
        ax: one Axes per outcome; None makes a new figure (not a pyplot one).
        outcomes: which outcomes, in order; None: every Likert outcome over ``condition``.

    Returns:
        The Figure drawn into.

    Examples:
        >>> import pandas as pd
        >>> from realpen.stats.outcome import StudyAnalysis
        >>> cells = pd.DataFrame({"outcome": "Q1", "factor": "condition", "level": list("AB"),
        ...                       "mean": [3.0, 4.0], "ci_low": [2.5, 3.4],
        ...                       "ci_high": [3.5, 4.6], "ci_method": "t", "n": 12,
        ...                       "unit": "points"})
        >>> empty = pd.DataFrame()
        >>> analysis = StudyAnalysis("study1", "Study 1", empty, cells, empty, empty, empty)
        >>> [ax.get_ylabel() for ax in figure7(analysis).axes]
        ['Q1: realism rating (points)']
    """
    cells = cell_table(analysis)
    found = outcome_names(cells, factor="condition", unit=LIKERT_UNIT)
    names = found if outcomes is None else [str(name) for name in outcomes]
    if not names or any(name not in found for name in names):
        raise no_data("Likert cells over condition" if not names else
                      f"Likert cells over condition for {', '.join(set(names) - set(found))}",
                      "figure7")
    axes, own = panels(ax, len(names), columns=3, panel=(5.0, 3.8))
    participants = participant_table(analysis)
    for axis, outcome in zip(axes, names):
        rows = cell_rows(cells, outcome, "condition")
        levels = list(rows.index)
        x = np.arange(len(levels), dtype=float)
        matrix = participant_matrix(participants, outcome, "condition", levels)
        draw_participant_lines(axis, x, matrix, spread=LIKERT_JITTER)
        draw_mean_ci(axis, x, rows)
        style_axes(axis)
        level_axis(axis, levels, "condition")
        values = np.concatenate([rows["mean"].to_numpy(float), matrix.to_numpy(float).ravel()])
        axis.set_ylim(*likert_limits(values))
        axis.set_ylabel(axis_label(analysis, outcome, LIKERT_UNIT))
        panel_title(axis, outcome_label(analysis, outcome), own=own)
    if own:
        axes[0].figure.suptitle("mean ± 95 % CI per condition (grey: each participant)",
                                fontsize="medium")
    return axes[0].figure


def figure10(analysis, ax: Axes | Sequence[Axes] | None = None) -> Figure:
    """The paper's Figure 10: a confusion matrix per modality.

    Rows are the presented pen, columns the pen chosen; each cell shows its count and its
    percentage of the row (the colour), on one colour scale (0–100 %) across the panels. The
    diagonal (correct answers) is outlined, and each panel's title gives its overall rate.
    Chance (one over the answers listed, :func:`realpen.stats.figure_data.chance_line`) is a
    dashed mark on the colour bar and named in its label.

    Args:
        analysis: a :class:`realpen.stats.outcome.StudyAnalysis` with a ``confusion`` table.
        ax: one Axes per modality; None makes a new figure (not a pyplot one).

    Returns:
        The Figure drawn into.

    Examples:
        >>> import pandas as pd
        >>> from realpen.stats.outcome import StudyAnalysis
        >>> confusion = pd.DataFrame({"modality": "tactile", "pen": ["pencil", "pencil"],
        ...                           "chosen": ["pencil", "marker"], "count": [3, 1],
        ...                           "row_percent": [75.0, 25.0]})
        >>> empty = pd.DataFrame()
        >>> analysis = StudyAnalysis("study2", "Study 2", empty, empty, empty, confusion, empty)
        >>> figure10(analysis).axes[0].get_title()
        'tactile: 75.0 % correct'
    """
    confusion = analysis.confusion
    if confusion is None or len(confusion) == 0:
        raise no_data("confusion table", "figure10")
    confusion = require_table(confusion, ("modality", "pen", "chosen", "count", "row_percent"),
                              "confusion").astype({"modality": str, "pen": str, "chosen": str})
    modalities = ordered_levels("modality", confusion["modality"])
    pens = ordered_levels("pen", confusion["pen"])
    chosen = ordered_levels("pen", list(pens) + list(confusion["chosen"]))
    axes, own = panels(ax, len(modalities), columns=3, panel=(4.2, 4.0))
    image = None
    for axis, modality in zip(axes, modalities):
        rows = confusion[confusion["modality"] == modality]
        counts = rows.pivot_table(index="pen", columns="chosen", values="count", aggfunc="sum",
                                  sort=False).reindex(index=pens, columns=chosen)
        percent = rows.pivot_table(index="pen", columns="chosen", values="row_percent",
                                   aggfunc="sum", sort=False).reindex(index=pens, columns=chosen)
        image = axis.imshow(percent.to_numpy(float), cmap="Blues", vmin=0.0, vmax=100.0,
                            aspect="equal")
        for i in range(len(pens)):
            for j in range(len(chosen)):
                count, share = counts.iat[i, j], percent.iat[i, j]
                if not np.isfinite(count):
                    continue
                axis.text(j, i, f"{int(count)}\n{share:.0f} %", ha="center", va="center",
                          fontsize="small", color="white" if share > 55 else "#1a1a1a")
                if pens[i] == chosen[j]:
                    axis.add_patch(cell_outline(j, i))
        total = np.nansum(counts.to_numpy(float))
        right = sum(np.nan_to_num(counts.at[pen, pen]) for pen in pens if pen in chosen)
        rate = f"{100.0 * right / total:.1f} % correct" if total > 0 else "no answers"
        panel_title(axis, f"{label_text(modality)}: {rate}", own=own)
        axis.set_xticks(range(len(chosen)), [label_text(name) for name in chosen])
        axis.set_yticks(range(len(pens)), [label_text(name) for name in pens])
        axis.set_xlabel("pen chosen")
        axis.set_ylabel("pen presented")
        axis.tick_params(length=0)
        axis.spines[:].set_visible(False)
    bar = axes[0].figure.colorbar(image, ax=axes, shrink=0.8, pad=0.02)
    chance = chance_line(analysis)
    if chance is None:
        bar.set_label("share of the presented pen's answers (%)")
    else:
        bar.ax.axhline(chance[0], color=CHANCE_COLOUR, lw=2.4, ls="--")
        bar.set_label(f"share of the presented pen's answers (%)\ndashed: chance "
                      f"({chance[1]} = {chance[0]:.0f} %)")
    if own:
        about = f" (chance {chance[1]})" if chance is not None else ""
        axes[0].figure.suptitle(f"pen recognition per modality: count and row percentage{about}",
                                fontsize="medium")
    return axes[0].figure


def recognition_figure(analysis, ax: Axes | None = None) -> Figure:
    """Recognition per modality: the mean percentage correct ± 95 % CI, with the chance line.

    The means and intervals are those of ``cells`` (outcome ``recognition``, factor
    ``modality``: the mean over participants of each one's percentage correct); each
    participant's percentage is a faint dot beside its mean, and chance
    (:func:`realpen.stats.figure_data.chance_line`: 1/3 in study 2) a dashed line labelled
    ``chance (1/3)``. Without modalities the recognition outcome's first factor is used.

    Args:
        analysis: a :class:`realpen.stats.outcome.StudyAnalysis` with recognition ``cells``.
        ax: the Axes to draw into; None makes a new figure (not a pyplot one).

    Returns:
        The Figure drawn into.

    Examples:
        >>> import pandas as pd
        >>> from realpen.stats.outcome import StudyAnalysis
        >>> cells = pd.DataFrame({"outcome": "recognition", "factor": "modality",
        ...                       "level": ["tactile", "auditory"], "mean": [43.0, 51.0],
        ...                       "ci_low": [35.0, 44.0], "ci_high": [51.0, 58.0],
        ...                       "ci_method": "t", "n": 12, "unit": "%"})
        >>> confusion = pd.DataFrame({"modality": "tactile", "pen": "pencil",
        ...                           "chosen": ["pencil", "ballpoint", "marker"],
        ...                           "count": [3, 1, 0], "row_percent": [75.0, 25.0, 0.0]})
        >>> empty = pd.DataFrame()
        >>> analysis = StudyAnalysis("study2", "Study 2", empty, cells, empty, confusion, empty)
        >>> axis = recognition_figure(analysis).axes[0]
        >>> [line.get_label() for line in axis.get_lines() if line.get_linestyle() == "--"]
        ['chance (1/3)']
    """
    cells = cell_table(analysis)
    factors = [factor for factor in dict.fromkeys(
        cells.loc[cells["outcome"] == RECOGNITION_OUTCOME, "factor"]) if ":" not in factor]
    if not factors:
        raise no_data("recognition cells", "recognition_figure")
    factor = "modality" if "modality" in factors else factors[0]
    rows = cell_rows(cells, RECOGNITION_OUTCOME, factor)
    levels = list(rows.index)
    (axis,) = axes_list(ax, 1, (max(4.5, 1.4 * len(levels) + 2.0), 4.0), "ax")
    x = np.arange(len(levels), dtype=float)
    matrix = participant_matrix(participant_table(analysis), RECOGNITION_OUTCOME, factor, levels)
    for position, level in zip(x, levels):
        if level in matrix.columns:
            draw_participant_dots(axis, position - 0.15, matrix[level].to_numpy(float),
                                  colour=PALETTE[0], width=0.25, span=100.0)
    draw_mean_ci(axis, x + 0.12, rows, label="mean ± 95 % CI")
    chance = chance_line(analysis)
    if chance is not None:
        _draw_chance(axis, chance)
    style_axes(axis)
    level_axis(axis, levels, factor_label(factor), rotate=len(levels) > 4)
    axis.set_ylim(0.0, 100.0)
    axis.set_ylabel(axis_label(analysis, RECOGNITION_OUTCOME, "%"))
    axis.legend(frameon=False, loc="best", fontsize="small")
    panel_title(axis, f"recognition per {factor_label(factor)}: mean % correct ± 95 % CI",
                own=ax is None)
    return axis.figure


def figure11(analysis, ax: Axes | None = None) -> Figure:
    """The paper's Figure 11: response time (ms) per modality × pen, mean ± 95 % CI.

    Grouped by modality, one colour and marker per pen. The means are those of ``cells``
    (outcome ``log_rt``, factor ``modality:pen``, already in ms: geometric means with their
    exp-transformed intervals); each participant's value is a faint dot beside its mean when
    the analysis lists them.

    Args:
        analysis: a :class:`realpen.stats.outcome.StudyAnalysis`.
        ax: the Axes to draw into; None makes a new figure (not a pyplot one).

    Returns:
        The Figure drawn into.

    Examples:
        >>> import pandas as pd
        >>> from realpen.stats.outcome import StudyAnalysis
        >>> cells = pd.DataFrame({"outcome": "log_rt", "factor": "modality:pen",
        ...                       "level": ["tactile:pencil", "auditory:pencil"],
        ...                       "mean": [2100.0, 1800.0], "ci_low": [1900.0, 1650.0],
        ...                       "ci_high": [2300.0, 1950.0], "ci_method": "t", "n": 12,
        ...                       "unit": "ms"})
        >>> empty = pd.DataFrame()
        >>> analysis = StudyAnalysis("study2", "Study 2", empty, cells, empty, empty, empty)
        >>> figure11(analysis).axes[0].get_ylabel()
        'response time (ms)'
    """
    cells = cell_table(analysis)
    factor = "modality:pen"
    if RT_OUTCOME not in outcome_names(cells, factor=factor):
        raise no_data("cells of log_rt over modality:pen", "figure11")
    (axis,) = axes_list(ax, 1, (7.5, 4.2), "ax")
    rows = cell_rows(cells, RT_OUTCOME, factor)
    split = [level.split(":", 1) for level in rows.index]
    modalities = ordered_levels("modality", [parts[0] for parts in split])
    pens = ordered_levels("pen", [parts[1] if len(parts) > 1 else "" for parts in split])
    matrix = participant_matrix(participant_table(analysis), RT_OUTCOME, factor, list(rows.index))
    width = 0.7 / max(len(pens), 1)
    values = np.concatenate([rows[["ci_low", "ci_high"]].to_numpy(float).ravel(),
                             matrix.to_numpy(float).ravel()])
    span = float(np.nanmax(values) - np.nanmin(values)) if np.isfinite(values).any() else 1.0
    for k, pen in enumerate(pens):
        colour, marker = PALETTE[k % len(PALETTE)], MARKERS[k % len(MARKERS)]
        levels = [f"{modality}:{pen}" for modality in modalities if f"{modality}:{pen}" in rows.index]
        x = np.array([modalities.index(level.split(":", 1)[0]) for level in levels], float)
        x = x + (k - (len(pens) - 1) / 2) * width
        for position, level in zip(x, levels):
            if level in matrix.columns:
                draw_participant_dots(axis, position - width * 0.28, matrix[level].to_numpy(float),
                                      colour=colour, width=width * 0.3, span=span)
        draw_mean_ci(axis, x + width * 0.12, rows.loc[levels], colour=colour, marker=marker,
                     label=label_text(pen))
    style_axes(axis)
    level_axis(axis, modalities, "modality")
    axis.set_ylabel("response time (ms)")
    axis.legend(title="pen", frameon=False, loc="best", fontsize="small")
    panel_title(axis, "response time per modality × pen: geometric mean ± 95 % CI",
                own=ax is None)
    return axis.figure


def figure12(analysis, ax: Axes | Sequence[Axes] | None = None) -> Figure:
    """The paper's Figure 12: each questionnaire item per modality, mean ± 95 % CI.

    One panel per item (study 2: realism, comfort, strength, balance — balance asked only
    after audio-tactile trials) with every participant's answers as a thin grey line behind,
    shifted by at most ±0.12 points so that tied answers stay visible. All panels share the
    modality axis, so an item not asked in a modality leaves that place empty.

    Args:
        analysis: a :class:`realpen.stats.outcome.StudyAnalysis` with Likert ``cells`` over
            ``modality``.
        ax: one Axes per item; None makes a new figure (not a pyplot one).

    Returns:
        The Figure drawn into.

    Examples:
        >>> import pandas as pd
        >>> from realpen.stats.outcome import StudyAnalysis
        >>> cells = pd.DataFrame({"outcome": "realism", "factor": "modality",
        ...                       "level": ["tactile", "auditory"], "mean": [2.5, 3.1],
        ...                       "ci_low": [2.0, 2.6], "ci_high": [3.0, 3.6],
        ...                       "ci_method": "bootstrap", "n": 12, "unit": "points"})
        >>> empty = pd.DataFrame()
        >>> analysis = StudyAnalysis("study2", "Study 2", empty, cells, empty, empty, empty)
        >>> [ax.get_title() for ax in figure12(analysis).axes]
        ['realism']
    """
    cells = cell_table(analysis)
    items = outcome_names(cells, factor="modality", unit=LIKERT_UNIT, known=QUESTIONNAIRE)
    if not items:
        raise no_data("Likert cells over modality", "figure12")
    modalities = ordered_levels("modality", cells.loc[(cells["factor"] == "modality")
                                                      & cells["outcome"].isin(items), "level"])
    axes, own = panels(ax, len(items), columns=4, panel=(3.6, 3.6))
    participants = participant_table(analysis)
    everything = []
    for axis, item in zip(axes, items):
        rows = cell_rows(cells, item, "modality")
        x = np.array([modalities.index(level) for level in rows.index], dtype=float)
        matrix = participant_matrix(participants, item, "modality", list(rows.index))
        draw_participant_lines(axis, x, matrix, spread=LIKERT_JITTER)
        draw_mean_ci(axis, x, rows)
        style_axes(axis)
        level_axis(axis, modalities, "modality", rotate=True)
        panel_title(axis, label_text(item), own=own)
        everything += list(rows["mean"]) + list(matrix.to_numpy(float).ravel())
    limits = likert_limits(everything)
    for k, axis in enumerate(axes):
        axis.set_ylim(*limits)
        axis.set_ylabel("rating (points)" if k == 0 or not own else "")
    if own:
        axes[0].figure.suptitle("questionnaire per modality: mean ± 95 % CI "
                                "(grey: each participant)", fontsize="medium")
    return axes[0].figure


def participants_figure(analysis, outcome: str, ax: Sequence[Axes] | None = None, *,
                        factor: str | None = None) -> Figure:
    """Every participant's own values across the levels of ``factor``, one small panel each.

    Each panel shows one participant's cell values (a line with markers, exact values: no
    shift) over the group's means (dashed grey), on axes shared by all panels, so a reader
    sees who follows the group and who does not. For a two-factor interaction
    (``modality:pen``) each panel has one line per level of the first factor. A factor with a
    single level (an item asked in one modality) is one panel instead: every participant's
    value side by side, the group mean dashed.

    Above :data:`MAX_PARTICIPANT_PANELS` participants the panels become one heat map: a row
    per participant (sorted by their mean over the levels), a column per level, the colour
    their exact value, the group means written above the columns.

    Args:
        analysis: a :class:`realpen.stats.outcome.StudyAnalysis` with ``participants`` rows of
            ``outcome``.
        outcome: the outcome to show (``Q1``, ``recognition`` ...).
        ax: one Axes per participant (one Axes for a single-level factor or a heat map); None
            makes a new figure (not a pyplot one).
        factor: the factor across which to draw; None: ``condition`` if present, else the
            main factor with the most levels.

    Returns:
        The Figure drawn into.

    Examples:
        >>> import pandas as pd
        >>> from realpen.stats.outcome import StudyAnalysis
        >>> people = pd.DataFrame({"outcome": "Q1", "factor": "condition",
        ...                        "level": list("ABAB"), "participant": ["P1", "P1", "P2", "P2"],
        ...                        "value": [3, 4, 2, 5], "unit": "points"})
        >>> empty = pd.DataFrame()
        >>> analysis = StudyAnalysis("study1", "Study 1", empty, empty, people, empty, empty)
        >>> [ax.get_title() for ax in participants_figure(analysis, "Q1").axes]
        ['P1', 'P2']
    """
    participants = participant_table(analysis)
    if outcome not in set(participants["outcome"]):
        raise no_data(f"participant values of {outcome!r}", "participants_figure")
    factor = main_factor(participants, outcome) if factor is None else str(factor)
    rows = participants[(participants["outcome"] == outcome) & (participants["factor"] == factor)]
    if rows.empty:
        raise no_data(f"participant values of {outcome!r} over {factor!r}", "participants_figure")
    levels = ordered_levels(factor, rows["level"])
    matrix = participant_matrix(participants, outcome, factor, levels)
    unit = str(rows["unit"].dropna().iloc[0]) if "unit" in rows and rows["unit"].notna().any() else ""
    people = list(matrix.index)
    if len(levels) == 1 and ":" not in factor:
        return _one_level(analysis, outcome, factor, matrix, unit, ax)
    cells = analysis.cells if isinstance(analysis.cells, pd.DataFrame) else pd.DataFrame()
    means = None
    if {"outcome", "factor", "level", "mean"} <= set(cells.columns):
        found = cell_table(analysis)
        found = found[(found["outcome"] == outcome) & (found["factor"] == factor)]
        if not found.empty:
            means = found.drop_duplicates("level").set_index("level")["mean"].reindex(levels)
    if means is None:
        means = matrix.mean(axis=0)
    if len(people) > MAX_PARTICIPANT_PANELS:
        return _heat_map(analysis, outcome, factor, matrix, means, unit, ax)
    axes, own = panels(ax, len(people), columns=MAX_COLUMNS, panel=(2.4, 2.1))
    names = factor.split(":", 1)
    interaction = len(names) == 2
    if interaction:
        firsts = ordered_levels(names[0], [level.split(":", 1)[0] for level in levels])
        seconds = ordered_levels(names[1], [level.split(":", 1)[1] for level in levels])
        ticks = seconds
    else:
        ticks = levels
    values = np.concatenate([matrix.to_numpy(float).ravel(), means.to_numpy(float)])
    finite = values[np.isfinite(values)]
    if unit == LIKERT_UNIT:
        limits = likert_limits(finite)
    elif finite.size:
        pad = 0.06 * max(float(finite.max() - finite.min()), 1e-9)
        limits = (float(finite.min()) - pad, float(finite.max()) + pad)
    else:
        limits = (0.0, 1.0)
    columns = max(1, min(MAX_COLUMNS, len(people)))
    tilt = sum(len(t) for t in ticks) > 12  # labels that would run into each other
    for k, (axis, person) in enumerate(zip(axes, people)):
        if interaction:
            for j, first in enumerate(firsts):
                picked = [f"{first}:{second}" for second in seconds]
                x = np.arange(len(seconds), dtype=float)
                colour, marker = PALETTE[j % len(PALETTE)], MARKERS[j % len(MARKERS)]
                axis.plot(x, means.reindex(picked).to_numpy(float), color=colour, lw=0.9,
                          ls="--", alpha=0.5, zorder=2)
                axis.plot(x, matrix.loc[person].reindex(picked).to_numpy(float), color=colour,
                          marker=marker, ms=3.5, lw=1.3, zorder=3, label=label_text(first))
        else:
            x = np.arange(len(levels), dtype=float)
            # A lone level has no line to dash: the mean is then a short bar.
            axis.plot(x, means.to_numpy(float), color=PARTICIPANT_COLOUR, lw=1.0, ls="--",
                      marker="_" if len(levels) == 1 else "", ms=18, mew=1.5, zorder=2,
                      label="group mean")
            axis.plot(x, matrix.loc[person].to_numpy(float), color=PALETTE[0], marker="o",
                      ms=3.5, lw=1.4, zorder=3, label="participant")
        style_axes(axis)
        panel_title(axis, label_text(person), own=own, fontsize="small")
        axis.set_ylim(*limits)
        axis.set_xticks(range(len(ticks)), [label_text(t) for t in ticks], fontsize="small",
                        rotation=30 if tilt else 0, ha="right" if tilt else "center")
        axis.set_xlim(-0.4, len(ticks) - 0.6)
        axis.tick_params(axis="y", labelsize="small")
        if own:
            if k + columns < len(people):  # a panel below shows the labels
                axis.tick_params(axis="x", labelbottom=False)
            if k % columns:
                axis.tick_params(axis="y", labelleft=False)
    figure = axes[0].figure
    if own:
        xlabel = label_text(names[1]) if interaction else factor_label(factor)
        figure.supxlabel(xlabel, fontsize="medium")
        figure.supylabel(axis_label(analysis, outcome, unit), fontsize="medium")
        note = "dashed: group mean" if not interaction else "dashed: group mean per " + \
            label_text(names[0])
        figure.suptitle(f"{outcome_label(analysis, outcome)}: each participant across "
                        f"{factor_label(factor)} ({note})", fontsize="medium")
        handles, labels = axes[0].get_legend_handles_labels()
        if interaction:
            figure.legend(handles, labels, loc="outside right upper", fontsize="small",
                          frameon=False, title=label_text(names[0]), title_fontsize="small")
    return figure


def _heat_map(analysis, outcome: str, factor: str, matrix: pd.DataFrame, means: pd.Series,
              unit: str, ax: Axes | None) -> Figure:
    """Every participant's values as one image: a row each (sorted by their mean), a column
    per level; the group means written above their columns."""
    levels = list(matrix.columns)
    rows = matrix.to_numpy(float)
    with np.errstate(invalid="ignore"):
        order = np.argsort(np.nanmean(rows, axis=1), kind="stable")
    (axis,) = axes_list(ax, 1, (max(5.0, 0.9 * len(levels) + 2.5), 6.0), "ax")
    finite = rows[np.isfinite(rows)]
    low, high = (likert_limits(finite) if unit == LIKERT_UNIT else
                 (float(finite.min()), float(finite.max())) if finite.size else (0.0, 1.0))
    image = axis.imshow(rows[order], aspect="auto", interpolation="nearest", cmap="viridis",
                        vmin=low, vmax=high)
    tilt = sum(len(str(level)) for level in levels) > 24
    axis.set_xticks(range(len(levels)), [label_text(level) for level in levels],
                    rotation=30 if tilt else 0, ha="right" if tilt else "center")
    axis.set_yticks([0, len(order) - 1], ["lowest mean", "highest mean"])
    axis.set_xlabel(factor_label(factor))
    axis.set_ylabel(f"{len(order)} participants, sorted by their mean")
    top = axis.secondary_xaxis("top")
    top.set_xticks(range(len(levels)), [f"{value:.3g}" for value in
                                        means.reindex(levels).to_numpy(float)],
                   fontsize="small", rotation=30 if tilt else 0)
    top.set_xlabel("group mean", fontsize="small")
    bar = axis.figure.colorbar(image, ax=axis, shrink=0.8, pad=0.02)
    bar.set_label(axis_label(analysis, outcome, unit))
    if ax is None:
        axis.figure.suptitle(f"{outcome_label(analysis, outcome)}: each participant (a row) "
                             f"across {factor_label(factor)}", fontsize="medium")
    return axis.figure


def _one_level(analysis, outcome: str, factor: str, matrix: pd.DataFrame, unit: str,
               ax: Axes | None) -> Figure:
    """Every participant's value of a single-level factor, side by side, with the mean."""
    labelled = len(matrix) <= MAX_PARTICIPANT_PANELS
    width = 0.45 * len(matrix) + 1.5 if labelled else 10.0
    (axis,) = axes_list(ax, 1, (max(4.0, width), 3.4), "ax")
    values = matrix.iloc[:, 0].to_numpy(float)
    x = np.arange(len(values), dtype=float)
    axis.axhline(float(np.nanmean(values)), color=PARTICIPANT_COLOUR, lw=1.2, ls="--",
                 zorder=2, label="group mean")
    (dots,) = axis.plot(x, values, "o", color=PALETTE[0], ms=6 if labelled else 2, zorder=3,
                        label="participant")
    if len(values) > MAX_VECTOR_PARTICIPANTS:
        dots.set_rasterized(True)  # a shape per participant would make a file of MB
    style_axes(axis)
    people = [label_text(code) for code in matrix.index]
    if labelled:
        axis.set_xticks(x, people, rotation=30 if sum(map(len, people)) > 4 * len(people) else 0,
                        ha="right" if sum(map(len, people)) > 4 * len(people) else "center")
    else:  # a few participants named along the axis: a label each would overlap
        ticks = np.unique(np.linspace(0, len(values) - 1, 6).round().astype(int))
        axis.set_xticks(ticks, [people[i] for i in ticks], rotation=30, ha="right")
    axis.set_xlim(-0.7, len(values) - 0.3)
    if unit == LIKERT_UNIT:
        axis.set_ylim(*likert_limits(values))
    axis.set_xlabel("participant")
    axis.set_ylabel(axis_label(analysis, outcome, unit))
    # An outcome without a factor has the one level "all": naming it would read "(all all only)".
    only = ("" if factor == "all" else
            f" ({factor_label(factor)} {label_text(matrix.columns[0])} only)")
    panel_title(axis, f"{outcome_label(analysis, outcome)}{only}: each participant (dashed: "
                      "group mean)", own=ax is None, fontsize="medium")
    return axis.figure


def means_figure(analysis, outcome: str, ax: Axes | Sequence[Axes] | None = None) -> Figure:
    """Mean ± CI of ``outcome`` per level of each factor the analysis lists (generic designs).

    One panel per factor (and interaction) in ``cells``; the participants' own values, when
    listed, are faint dots beside each mean (equal values spread sideways). Recognition (in %)
    gets the dashed chance line in every panel
    (:func:`realpen.stats.figure_data.chance_line`).

    Args:
        analysis: a :class:`realpen.stats.outcome.StudyAnalysis`.
        outcome: the outcome to show.
        ax: one Axes per factor; None makes a new figure (not a pyplot one).

    Returns:
        The Figure drawn into.

    Examples:
        >>> import pandas as pd
        >>> from realpen.stats.outcome import StudyAnalysis
        >>> cells = pd.DataFrame({"outcome": "score", "factor": "grip",
        ...                       "level": ["loose", "tight"], "mean": [3.0, 4.0],
        ...                       "ci_low": [2.5, 3.4], "ci_high": [3.5, 4.6],
        ...                       "ci_method": "t", "n": 8, "unit": "points"})
        >>> empty = pd.DataFrame()
        >>> analysis = StudyAnalysis("mine", "Mine", empty, cells, empty, empty, empty)
        >>> [ax.get_xlabel() for ax in means_figure(analysis, "score").axes]
        ['grip']
    """
    cells = cell_table(analysis)
    rows = cells[cells["outcome"] == outcome]
    if rows.empty:
        raise no_data(f"cells of {outcome!r}", "means_figure")
    factors = list(dict.fromkeys(rows["factor"]))
    factors = [name for name in factors if ":" not in name] + [n for n in factors if ":" in n]
    unit = outcome_unit(cells, outcome)
    axes, own = panels(ax, len(factors), columns=3, panel=(4.2, 3.6))
    participants = participant_table(analysis)
    chance = chance_line(analysis) if outcome == RECOGNITION_OUTCOME and unit == "%" else None
    everything = []
    for axis, factor in zip(axes, factors):
        level_rows = cell_rows(cells, outcome, factor)
        levels = list(level_rows.index)
        x = np.arange(len(levels), dtype=float)
        matrix = participant_matrix(participants, outcome, factor, levels)
        values = np.concatenate([level_rows[["ci_low", "ci_high"]].to_numpy(float).ravel(),
                                 matrix.to_numpy(float).ravel()])
        span = float(np.nanmax(values) - np.nanmin(values)) if np.isfinite(values).any() else 1.0
        for position, level in zip(x, levels):
            draw_participant_dots(axis, position - 0.15, matrix[level].to_numpy(float),
                                  colour=PALETTE[0], width=0.25, span=span)
        draw_mean_ci(axis, x + 0.12, level_rows)
        if chance is not None:
            _draw_chance(axis, chance)
        style_axes(axis)
        level_axis(axis, levels, factor_label(factor),
                   rotate=len(levels) > 4 and max(map(len, levels)) > 3)
        axis.set_ylabel(axis_label(analysis, outcome, unit))
        everything += list(values)
    if unit == LIKERT_UNIT:
        for axis in axes:
            axis.set_ylim(*likert_limits(everything))
    if chance is not None:
        axes[0].legend(frameon=False, loc="best", fontsize="small")
    if own:
        axes[0].figure.suptitle(f"{outcome_label(analysis, outcome)}: mean ± 95 % CI per level "
                                "(dots: each participant)", fontsize="medium")
    return axes[0].figure
