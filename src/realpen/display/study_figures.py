"""Figures of a study analysis: the paper's Figures 7, 10, 11 and 12, every participant's own
data, the means of a generic design, and the power of a planned study.

Every function reads a :class:`realpen.stats.outcome.StudyAnalysis` (its tables only: nothing
is recomputed here, so a figure shows exactly the numbers of ``results.csv`` and the report),
draws into the Axes it is given, or into a new figure (never pyplot's) when ``ax`` is None,
and returns the :class:`~matplotlib.figure.Figure`. :func:`save_study_figures` writes every
figure that applies to an analysis as PNG (150 dpi) and SVG.

- :func:`figure7` — Likert outcomes (Q1, Q2) per condition: mean ± 95 % CI, participants behind.
- :func:`figure10` — a confusion matrix per modality: counts and row percentages.
- :func:`figure11` — response times (ms) per modality × pen: mean ± 95 % CI.
- :func:`figure12` — each questionnaire item per modality: mean ± 95 % CI, participant lines.
- :func:`participants_figure` — one small panel per participant across the main factor.
- :func:`means_figure` — mean ± CI per level of each factor of one outcome (generic designs).
- :func:`power_figure`, :func:`save_power_plot` — simulated power against the number of
  participants (``realpen stats power --plot``).

Colours are the Okabe–Ito palette (distinguishable with every common colour-vision
deficiency), and wherever colour tells groups apart a marker shape does too.
"""

from __future__ import annotations

import io
import math
import os
import re
from collections.abc import Iterable, Sequence
from pathlib import Path

import numpy as np
import pandas as pd
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from realpen.display._axes import axes_list
from realpen.errors import ParameterError, fail

__all__ = ["image_kind", "figure7", "figure10", "figure11", "figure12", "participants_figure", "means_figure",
           "power_figure", "save_power_plot", "study_figure_names", "save_study_figures",
           "figure_caption", "split_power", "PALETTE", "MARKERS"]

PALETTE = ("#0072B2", "#D55E00", "#009E73", "#CC79A7", "#E69F00", "#56B4E9", "#000000")
"""Okabe & Ito's colour-blind-safe colours (their yellow left out: unreadable on white)."""
MARKERS = ("o", "s", "D", "^", "v", "P", "X")
"""Marker shapes paired with :data:`PALETTE`, so groups differ in shape as well as colour."""

FORMATS = ("png", "svg")
DPI = 150
MEAN_COLOUR = "#1a1a1a"
PARTICIPANT_COLOUR = "#8c8c8c"
# Likert answers tie a lot: each participant's line is shifted by a fixed amount within
# ±LIKERT_JITTER points so that tied lines stay visible; the captions say so.
LIKERT_JITTER = 0.12
LIKERT_UNIT = "points"
# The built-in studies' names in the order a reader expects (DESIGN.md, data contracts);
# levels of other designs keep the order in which the analysis lists them.
KNOWN_ORDERS = {
    "condition": ("A", "B", "C", "D", "E", "F"),
    "modality": ("tactile", "auditory", "audio-tactile"),
    "pen": ("pencil", "ballpoint", "marker"),
    "superposition": ("5", "10", "15"),
    "fluctuation": ("15x100ms", "1x1500ms"),
}
QUESTIONNAIRE = ("realism", "comfort", "strength", "balance")
STUDY1_LABELS = {"Q1": "Q1: realism", "Q2": "Q2: comfort"}
RT_OUTCOME = "log_rt"
MAX_COLUMNS = 4  # participant panels per row: wider would shrink on a page


# --------------------------------------------------------------------------- table helpers

def _text(value: object) -> str:
    """A user string for a matplotlib label: ``$`` would otherwise start mathtext."""
    return str(value).replace("$", r"\$")


def _require(frame: pd.DataFrame | None, columns: Iterable[str], table: str) -> pd.DataFrame:
    if frame is None or not isinstance(frame, pd.DataFrame):
        raise ParameterError("analysis", f"has no {table} table")
    missing = [column for column in columns if column not in frame.columns]
    if missing:
        raise ParameterError("analysis", f"{table} table lacks column(s) {', '.join(missing)}")
    return frame


def _cells(analysis) -> pd.DataFrame:
    frame = _require(analysis.cells, ("outcome", "factor", "level", "mean", "ci_low", "ci_high",
                                      "unit"), "cells")
    return frame.astype({"outcome": str, "factor": str, "level": str})


def _participants(analysis) -> pd.DataFrame:
    frame = analysis.participants
    if frame is None or len(frame) == 0:
        return pd.DataFrame(columns=["outcome", "factor", "level", "participant", "value", "unit"])
    frame = _require(frame, ("outcome", "factor", "level", "participant", "value"), "participants")
    return frame.astype({"outcome": str, "factor": str, "level": str, "participant": str})


def _ordered(factor: str, levels: Iterable[str]) -> list[str]:
    """``levels`` (unique) in the reader's order: known names first, the rest as listed.

    An interaction's levels (``tactile:pencil``) sort by their parts, the first part first.
    """
    levels = list(dict.fromkeys(str(level) for level in levels))
    names = factor.split(":")
    seen: list[list[str]] = [[] for _ in names]
    for level in levels:
        for k, part in enumerate(level.split(":", len(names) - 1)):
            if k < len(seen) and part not in seen[k]:
                seen[k].append(part)

    def rank(level: str) -> tuple:
        key = []
        for k, part in enumerate(level.split(":", len(names) - 1)[:len(names)]):
            known = KNOWN_ORDERS.get(names[k], ())
            key.append(known.index(part) if part in known else len(known) + seen[k].index(part))
        return tuple(key)

    return sorted(levels, key=rank)


def _outcomes(frame: pd.DataFrame, *, factor: str | None = None, unit: str | None = None,
              known: Sequence[str] = ()) -> list[str]:
    """Outcomes of ``frame`` (optionally over ``factor`` / with ``unit``), ``known`` first."""
    rows = frame
    if factor is not None:
        rows = rows[rows["factor"] == factor]
    if unit is not None and "unit" in rows.columns:
        rows = rows[rows["unit"].astype(str) == unit]
    found = list(dict.fromkeys(rows["outcome"]))
    return [name for name in known if name in found] + [name for name in found if name not in known]


def _cell_rows(cells: pd.DataFrame, outcome: str, factor: str) -> pd.DataFrame:
    """One outcome × factor's cells, in the reader's order, indexed by level."""
    rows = cells[(cells["outcome"] == outcome) & (cells["factor"] == factor)]
    rows = rows.drop_duplicates("level").set_index("level")
    return rows.loc[_ordered(factor, rows.index)]


def _participant_matrix(participants: pd.DataFrame, outcome: str, factor: str,
                        levels: Sequence[str]) -> pd.DataFrame:
    """Participants × ``levels`` of their values (NaN where a participant has no value)."""
    rows = participants[(participants["outcome"] == outcome) & (participants["factor"] == factor)]
    if rows.empty:
        return pd.DataFrame(columns=list(levels), dtype=float)
    values = pd.to_numeric(rows["value"], errors="coerce")
    table = rows.assign(value=values).pivot_table(index="participant", columns="level",
                                                  values="value", aggfunc="mean", sort=False)
    return table.reindex(columns=list(levels))


def _unit(cells: pd.DataFrame, outcome: str) -> str:
    units = cells.loc[cells["outcome"] == outcome, "unit"].dropna().astype(str).unique()
    return units[0] if len(units) else ""


def _outcome_label(analysis, outcome: str) -> str:
    if getattr(analysis, "design", "") == "study1" and outcome in STUDY1_LABELS:
        return STUDY1_LABELS[outcome]
    if outcome == RT_OUTCOME:
        return "response time"
    return _text(outcome)


def _axis_label(analysis, outcome: str, unit: str) -> str:
    """A y label with the unit: ``rating (points)``, ``recognition (% correct)``."""
    if unit == LIKERT_UNIT:
        return f"{_outcome_label(analysis, outcome)} rating (points)"
    if outcome == "recognition" and unit == "%":
        return "recognition (% correct)"
    if outcome == RT_OUTCOME:
        return "response time (ms)"
    return f"{_outcome_label(analysis, outcome)} ({_text(unit)})" if unit else \
        _outcome_label(analysis, outcome)


def _likert_limits(values: Iterable[float]) -> tuple[float, float]:
    """The y range of a Likert axis: the scale from 1 to (at least) 5, widened to any value or
    interval end beyond it."""
    finite = [float(v) for v in values if np.isfinite(v)]
    return min([1.0] + finite) - 0.4, max([5.0] + finite) + 0.4


# --------------------------------------------------------------------------- drawing helpers

def _panels(ax: Axes | Sequence[Axes] | None, count: int, *, columns: int,
            panel: tuple[float, float]) -> tuple[list[Axes], bool]:
    """``count`` axes: the caller's (checked), or a new constrained grid; and whether new."""
    if ax is not None:
        return axes_list(ax, count, panel, "ax"), False
    columns = max(1, min(columns, count))
    rows = math.ceil(count / columns)
    figure = Figure(figsize=(panel[0] * columns, panel[1] * rows), layout="constrained")
    grid = figure.subplots(rows, columns, squeeze=False).ravel()
    for spare in grid[count:]:
        spare.remove()
    return list(grid[:count]), True


def _style(ax: Axes) -> None:
    ax.spines[["top", "right"]].set_visible(False)
    ax.grid(True, axis="y", color="#e3e3e3", lw=0.8, zorder=0)
    ax.set_axisbelow(True)


def _mean_ci(ax: Axes, x: np.ndarray, rows: pd.DataFrame, *, colour: str = MEAN_COLOUR,
             marker: str = "o", label: str | None = None, line: bool = False) -> None:
    """Means with their CI as error bars (a CI that could not be computed is left out)."""
    mean = rows["mean"].to_numpy(dtype=float)
    low = np.nan_to_num(mean - rows["ci_low"].to_numpy(dtype=float), nan=0.0)
    high = np.nan_to_num(rows["ci_high"].to_numpy(dtype=float) - mean, nan=0.0)
    ax.errorbar(x, mean, yerr=[np.maximum(low, 0), np.maximum(high, 0)], fmt=marker,
                ls="-" if line else "none", color=colour, ecolor=colour, elinewidth=1.6,
                capsize=4, capthick=1.4, ms=6.5, mfc=colour, mec="white", mew=0.8, lw=1.4,
                zorder=4, label=label)


def _participant_lines(ax: Axes, x: np.ndarray, matrix: pd.DataFrame, *, discrete: bool) -> None:
    """Each participant's values as a thin line behind the means (shifted apart if ``discrete``)."""
    count = len(matrix)
    for k, (_, values) in enumerate(matrix.iterrows()):
        shift = ((k - (count - 1) / 2) / max(count - 1, 1)) * 2 * LIKERT_JITTER \
            if discrete and count > 1 else 0.0
        y = values.to_numpy(dtype=float) + shift
        ax.plot(x, y, color=PARTICIPANT_COLOUR, lw=0.8, alpha=0.45, marker="o", ms=2.5,
                zorder=2)


def _participant_dots(ax: Axes, x: float, values: np.ndarray, *, colour: str, width: float,
                      span: float) -> None:
    """Values as faint dots beside ``x``; equal (or nearly, within 2 % of ``span``) values
    are spread sideways so each one shows."""
    values = np.asarray(values, dtype=float)
    values = values[np.isfinite(values)]
    if values.size == 0:
        return
    tolerance = 0.02 * span if span > 0 else 1e-9
    bins = np.round(values / tolerance)
    offsets = np.zeros_like(values)
    for b in np.unique(bins):
        members = np.flatnonzero(bins == b)
        step = min(width / max(len(members), 1), 0.05)
        offsets[members] = (np.arange(len(members)) - (len(members) - 1) / 2) * step
    ax.scatter(x + offsets, values, s=12, color=colour, alpha=0.5, linewidths=0, zorder=2)


def _level_axis(ax: Axes, levels: Sequence[str], label: str, *, rotate: bool = False) -> None:
    ax.set_xticks(range(len(levels)), [_text(level) for level in levels],
                  rotation=30 if rotate else 0, ha="right" if rotate else "center")
    ax.set_xlim(-0.6, len(levels) - 0.4)
    ax.set_xlabel(label)


def _factor_label(factor: str) -> str:
    return " × ".join(_text(part) for part in factor.split(":"))


def _no_data(what: str, figure_name: str) -> ParameterError:
    return ParameterError("analysis", f"has no {what} (needed by {figure_name})")


# --------------------------------------------------------------------------- the figures

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
    cells = _cells(analysis)
    found = _outcomes(cells, factor="condition", unit=LIKERT_UNIT)
    names = found if outcomes is None else [str(name) for name in outcomes]
    if not names or any(name not in found for name in names):
        raise _no_data("Likert cells over condition" if not names else
                       f"Likert cells over condition for {', '.join(set(names) - set(found))}",
                       "figure7")
    axes, own = _panels(ax, len(names), columns=3, panel=(5.0, 3.8))
    participants = _participants(analysis)
    for axis, outcome in zip(axes, names):
        rows = _cell_rows(cells, outcome, "condition")
        levels = list(rows.index)
        x = np.arange(len(levels), dtype=float)
        matrix = _participant_matrix(participants, outcome, "condition", levels)
        _participant_lines(axis, x, matrix, discrete=True)
        _mean_ci(axis, x, rows)
        _style(axis)
        _level_axis(axis, levels, "condition")
        values = np.concatenate([rows["mean"].to_numpy(float), matrix.to_numpy(float).ravel()])
        axis.set_ylim(*_likert_limits(values))
        axis.set_ylabel(_axis_label(analysis, outcome, LIKERT_UNIT))
        axis.set_title(_outcome_label(analysis, outcome))
    if own:
        axes[0].figure.suptitle("mean ± 95 % CI per condition (grey: each participant)",
                                fontsize="medium")
    return axes[0].figure


def figure10(analysis, ax: Axes | Sequence[Axes] | None = None) -> Figure:
    """The paper's Figure 10: a confusion matrix per modality.

    Rows are the presented pen, columns the pen chosen; each cell shows its count and its
    percentage of the row (the colour), on one colour scale (0–100 %) across the panels. The
    diagonal (correct answers) is outlined, and each panel's title gives its overall rate.

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
        raise _no_data("confusion table", "figure10")
    confusion = _require(confusion, ("modality", "pen", "chosen", "count", "row_percent"),
                         "confusion").astype({"modality": str, "pen": str, "chosen": str})
    modalities = _ordered("modality", confusion["modality"])
    pens = _ordered("pen", confusion["pen"])
    chosen = _ordered("pen", list(pens) + list(confusion["chosen"]))
    axes, own = _panels(ax, len(modalities), columns=3, panel=(4.2, 4.0))
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
                    axis.add_patch(_outline(j, i))
        total = np.nansum(counts.to_numpy(float))
        right = sum(np.nan_to_num(counts.at[pen, pen]) for pen in pens if pen in chosen)
        rate = f"{100.0 * right / total:.1f} % correct" if total > 0 else "no answers"
        axis.set_title(f"{_text(modality)}: {rate}")
        axis.set_xticks(range(len(chosen)), [_text(name) for name in chosen])
        axis.set_yticks(range(len(pens)), [_text(name) for name in pens])
        axis.set_xlabel("pen chosen")
        axis.set_ylabel("pen presented")
        axis.tick_params(length=0)
        axis.spines[:].set_visible(False)
    bar = axes[0].figure.colorbar(image, ax=axes, shrink=0.8, pad=0.02)
    bar.set_label("share of the presented pen's answers (%)")
    if own:
        axes[0].figure.suptitle("pen recognition per modality: count and row percentage",
                                fontsize="medium")
    return axes[0].figure


def _outline(x: float, y: float):
    from matplotlib.patches import Rectangle

    return Rectangle((x - 0.5, y - 0.5), 1.0, 1.0, fill=False, ec="#1a1a1a", lw=1.4, zorder=3)


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
    cells = _cells(analysis)
    factor = "modality:pen"
    if RT_OUTCOME not in _outcomes(cells, factor=factor):
        raise _no_data("cells of log_rt over modality:pen", "figure11")
    (axis,) = axes_list(ax, 1, (7.5, 4.2), "ax")
    rows = _cell_rows(cells, RT_OUTCOME, factor)
    split = [level.split(":", 1) for level in rows.index]
    modalities = _ordered("modality", [parts[0] for parts in split])
    pens = _ordered("pen", [parts[1] if len(parts) > 1 else "" for parts in split])
    matrix = _participant_matrix(_participants(analysis), RT_OUTCOME, factor, list(rows.index))
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
                _participant_dots(axis, position - width * 0.28, matrix[level].to_numpy(float),
                                  colour=colour, width=width * 0.3, span=span)
        _mean_ci(axis, x + width * 0.12, rows.loc[levels], colour=colour, marker=marker,
                 label=_text(pen))
    _style(axis)
    _level_axis(axis, modalities, "modality")
    axis.set_ylabel("response time (ms)")
    axis.legend(title="pen", frameon=False, loc="best", fontsize="small")
    axis.set_title("response time per modality × pen: geometric mean ± 95 % CI")
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
    cells = _cells(analysis)
    items = _outcomes(cells, factor="modality", unit=LIKERT_UNIT, known=QUESTIONNAIRE)
    if not items:
        raise _no_data("Likert cells over modality", "figure12")
    modalities = _ordered("modality", cells.loc[(cells["factor"] == "modality")
                                                & cells["outcome"].isin(items), "level"])
    axes, own = _panels(ax, len(items), columns=4, panel=(3.6, 3.6))
    participants = _participants(analysis)
    everything = []
    for axis, item in zip(axes, items):
        rows = _cell_rows(cells, item, "modality")
        x = np.array([modalities.index(level) for level in rows.index], dtype=float)
        matrix = _participant_matrix(participants, item, "modality", list(rows.index))
        _participant_lines(axis, x, matrix, discrete=True)
        _mean_ci(axis, x, rows)
        _style(axis)
        _level_axis(axis, modalities, "modality", rotate=True)
        axis.set_title(_text(item))
        everything += list(rows["mean"]) + list(matrix.to_numpy(float).ravel())
    limits = _likert_limits(everything)
    for k, axis in enumerate(axes):
        axis.set_ylim(*limits)
        axis.set_ylabel("rating (points)" if k == 0 or not own else "")
    if own:
        axes[0].figure.suptitle("questionnaire per modality: mean ± 95 % CI "
                                "(grey: each participant)", fontsize="medium")
    return axes[0].figure


def _main_factor(participants: pd.DataFrame, outcome: str) -> str:
    """The factor a participant figure runs over: ``condition``, else the main factor with
    the most levels, else the interaction."""
    rows = participants[participants["outcome"] == outcome]
    factors = list(dict.fromkeys(rows["factor"]))
    if "condition" in factors:
        return "condition"
    single = [name for name in factors if ":" not in name] or factors
    return max(single, key=lambda name: rows.loc[rows["factor"] == name, "level"].nunique())


def participants_figure(analysis, outcome: str, ax: Sequence[Axes] | None = None, *,
                        factor: str | None = None) -> Figure:
    """Every participant's own values across the levels of ``factor``, one small panel each.

    Each panel shows one participant's cell values (a line with markers, exact values: no
    shift) over the group's means (dashed grey), on axes shared by all panels, so a reader
    sees who follows the group and who does not. For a two-factor interaction
    (``modality:pen``) each panel has one line per level of the first factor. A factor with a
    single level (an item asked in one modality) is one panel instead: every participant's
    value side by side, the group mean dashed.

    Args:
        analysis: a :class:`realpen.stats.outcome.StudyAnalysis` with ``participants`` rows of
            ``outcome``.
        outcome: the outcome to show (``Q1``, ``recognition`` ...).
        ax: one Axes per participant (one Axes for a single-level factor); None makes a new
            figure (not a pyplot one).
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
    participants = _participants(analysis)
    if outcome not in set(participants["outcome"]):
        raise _no_data(f"participant values of {outcome!r}", "participants_figure")
    factor = _main_factor(participants, outcome) if factor is None else str(factor)
    rows = participants[(participants["outcome"] == outcome) & (participants["factor"] == factor)]
    if rows.empty:
        raise _no_data(f"participant values of {outcome!r} over {factor!r}", "participants_figure")
    levels = _ordered(factor, rows["level"])
    matrix = _participant_matrix(participants, outcome, factor, levels)
    unit = str(rows["unit"].dropna().iloc[0]) if "unit" in rows and rows["unit"].notna().any() else ""
    people = list(matrix.index)
    if len(levels) == 1 and ":" not in factor:
        return _one_level(analysis, outcome, factor, matrix, unit, ax)
    axes, own = _panels(ax, len(people), columns=MAX_COLUMNS, panel=(2.4, 2.1))
    cells = analysis.cells if isinstance(analysis.cells, pd.DataFrame) else pd.DataFrame()
    means = None
    if {"outcome", "factor", "level", "mean"} <= set(cells.columns):
        found = _cells(analysis)
        found = found[(found["outcome"] == outcome) & (found["factor"] == factor)]
        if not found.empty:
            means = found.drop_duplicates("level").set_index("level")["mean"].reindex(levels)
    if means is None:
        means = matrix.mean(axis=0)
    names = factor.split(":", 1)
    interaction = len(names) == 2
    if interaction:
        firsts = _ordered(names[0], [level.split(":", 1)[0] for level in levels])
        seconds = _ordered(names[1], [level.split(":", 1)[1] for level in levels])
        ticks = seconds
    else:
        ticks = levels
    values = np.concatenate([matrix.to_numpy(float).ravel(), means.to_numpy(float)])
    finite = values[np.isfinite(values)]
    if unit == LIKERT_UNIT:
        limits = _likert_limits(finite)
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
                          marker=marker, ms=3.5, lw=1.3, zorder=3, label=_text(first))
        else:
            x = np.arange(len(levels), dtype=float)
            # A lone level has no line to dash: the mean is then a short bar.
            axis.plot(x, means.to_numpy(float), color=PARTICIPANT_COLOUR, lw=1.0, ls="--",
                      marker="_" if len(levels) == 1 else "", ms=18, mew=1.5, zorder=2,
                      label="group mean")
            axis.plot(x, matrix.loc[person].to_numpy(float), color=PALETTE[0], marker="o",
                      ms=3.5, lw=1.4, zorder=3, label="participant")
        _style(axis)
        axis.set_title(_text(person), fontsize="small")
        axis.set_ylim(*limits)
        axis.set_xticks(range(len(ticks)), [_text(t) for t in ticks], fontsize="small",
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
        xlabel = _text(names[1]) if interaction else _factor_label(factor)
        figure.supxlabel(xlabel, fontsize="medium")
        figure.supylabel(_axis_label(analysis, outcome, unit), fontsize="medium")
        note = "dashed: group mean" if not interaction else "dashed: group mean per " + \
            _text(names[0])
        figure.suptitle(f"{_outcome_label(analysis, outcome)}: each participant across "
                        f"{_factor_label(factor)} ({note})", fontsize="medium")
        handles, labels = axes[0].get_legend_handles_labels()
        if interaction:
            figure.legend(handles, labels, loc="outside right upper", fontsize="small",
                          frameon=False, title=_text(names[0]), title_fontsize="small")
    return figure


def _one_level(analysis, outcome: str, factor: str, matrix: pd.DataFrame, unit: str,
               ax: Axes | None) -> Figure:
    """Every participant's value of a single-level factor, side by side, with the mean."""
    (axis,) = axes_list(ax, 1, (max(4.0, 0.45 * len(matrix) + 1.5), 3.4), "ax")
    values = matrix.iloc[:, 0].to_numpy(float)
    x = np.arange(len(values), dtype=float)
    axis.axhline(float(np.nanmean(values)), color=PARTICIPANT_COLOUR, lw=1.2, ls="--",
                 zorder=2, label="group mean")
    axis.plot(x, values, "o", color=PALETTE[0], ms=6, zorder=3, label="participant")
    _style(axis)
    people = [_text(code) for code in matrix.index]
    axis.set_xticks(x, people, rotation=30 if sum(map(len, people)) > 4 * len(people) else 0,
                    ha="right" if sum(map(len, people)) > 4 * len(people) else "center")
    axis.set_xlim(-0.7, len(values) - 0.3)
    if unit == LIKERT_UNIT:
        axis.set_ylim(*_likert_limits(values))
    axis.set_xlabel("participant")
    axis.set_ylabel(_axis_label(analysis, outcome, unit))
    axis.set_title(f"{_outcome_label(analysis, outcome)} ({_factor_label(factor)} "
                   f"{_text(matrix.columns[0])} only): each participant (dashed: group mean)",
                   fontsize="medium")
    return axis.figure


def means_figure(analysis, outcome: str, ax: Axes | Sequence[Axes] | None = None) -> Figure:
    """Mean ± CI of ``outcome`` per level of each factor the analysis lists (generic designs).

    One panel per factor (and interaction) in ``cells``; the participants' own values, when
    listed, are faint dots beside each mean (equal values spread sideways).

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
    cells = _cells(analysis)
    rows = cells[cells["outcome"] == outcome]
    if rows.empty:
        raise _no_data(f"cells of {outcome!r}", "means_figure")
    factors = list(dict.fromkeys(rows["factor"]))
    factors = [name for name in factors if ":" not in name] + [n for n in factors if ":" in n]
    unit = _unit(cells, outcome)
    axes, own = _panels(ax, len(factors), columns=3, panel=(4.2, 3.6))
    participants = _participants(analysis)
    everything = []
    for axis, factor in zip(axes, factors):
        cell_rows = _cell_rows(cells, outcome, factor)
        levels = list(cell_rows.index)
        x = np.arange(len(levels), dtype=float)
        matrix = _participant_matrix(participants, outcome, factor, levels)
        values = np.concatenate([cell_rows[["ci_low", "ci_high"]].to_numpy(float).ravel(),
                                 matrix.to_numpy(float).ravel()])
        span = float(np.nanmax(values) - np.nanmin(values)) if np.isfinite(values).any() else 1.0
        for position, level in zip(x, levels):
            _participant_dots(axis, position - 0.15, matrix[level].to_numpy(float),
                              colour=PALETTE[0], width=0.25, span=span)
        _mean_ci(axis, x + 0.12, cell_rows)
        _style(axis)
        _level_axis(axis, levels, _factor_label(factor),
                    rotate=len(levels) > 4 and max(map(len, levels)) > 3)
        axis.set_ylabel(_axis_label(analysis, outcome, unit))
        everything += list(values)
    if unit == LIKERT_UNIT:
        for axis in axes:
            axis.set_ylim(*_likert_limits(everything))
    if own:
        axes[0].figure.suptitle(f"{_outcome_label(analysis, outcome)}: mean ± 95 % CI per level "
                                "(dots: each participant)", fontsize="medium")
    return axes[0].figure


POWER_CURVE_COLUMNS = ("outcome", "effect", "test", "participants", "effect_size", "power")
DETECTABLE_COLUMNS = ("outcome", "test", "participants", "minimum_effect", "power")


def split_power(table: pd.DataFrame) -> tuple[pd.DataFrame, pd.DataFrame]:
    """(simulated power rows, smallest-detectable-effect rows) of a power table.

    Two shapes are understood: :func:`realpen.stats.power.power_table`'s (``outcome, effect,
    test, participants, effect_size, power``: power curves) and
    :func:`realpen.stats.power.minimum_detectable_effect`'s (``outcome, test, participants,
    parameter, minimum_effect, power, note``: smallest detectable effects). Both parts come
    back with ``outcome, effect, test, participants, effect_size, power`` (a detectable row's
    ``effect_size`` is its ``minimum_effect``; ``effect`` is empty when the table has none),
    plus the table's other columns. In a table of the first shape, a ``kind`` column that says
    ``detectable`` marks detectable rows.

    Raises:
        ParameterError: a table of neither shape.

    Examples:
        >>> import pandas as pd
        >>> table = pd.DataFrame({"outcome": "Q1", "test": "Friedman", "participants": [12],
        ...                       "parameter": "effect", "minimum_effect": [0.9],
        ...                       "power": [0.81], "note": ""})
        >>> [len(part) for part in split_power(table)]
        [0, 1]
    """
    if not isinstance(table, pd.DataFrame):
        raise ParameterError("power", f"must be a DataFrame, got {type(table).__name__}")
    table = table.copy()
    if "minimum_effect" in table.columns:
        _require(table, DETECTABLE_COLUMNS, "power")
        table = table.rename(columns={"minimum_effect": "effect_size"})
        detectable = pd.Series(True, index=table.index)
    else:
        _require(table, POWER_CURVE_COLUMNS, "power")
        detectable = (table["kind"].astype(str).str.contains("detectable")
                      if "kind" in table.columns else pd.Series(False, index=table.index))
    if "effect" not in table.columns:
        table["effect"] = ""
    for name in ("outcome", "effect", "test"):
        table[name] = table[name].astype(str)
    return table[~detectable], table[detectable]


def _has_power_figure(table: pd.DataFrame | None) -> bool:
    """Whether a power table has something to draw against participants (a curve, or the
    smallest effects at two or more sizes); one study's detectable effects are a table."""
    if table is None or len(table) == 0:
        return False
    curves, detectable = split_power(table)
    return len(curves) > 0 or detectable["participants"].nunique() > 1


def _test_label(test: tuple) -> str:
    return " ".join(_text(part) for part in test if part)


def power_figure(analysis, ax: Axes | Sequence[Axes] | None = None) -> Figure:
    """Simulated power against the number of participants, one line per test and effect size.

    The dotted line is 80 % power. When the table holds smallest detectable effects (see
    :func:`split_power`), a panel shows those against the number of participants.

    Args:
        analysis: a :class:`realpen.stats.outcome.StudyAnalysis` with a ``power`` table, or
            that table itself (:func:`realpen.stats.power.power_table`'s or
            :func:`realpen.stats.power.minimum_detectable_effect`'s).
        ax: one Axes per panel (power; smallest effects; both when the table has both); None
            makes a new figure (not a pyplot one).

    Returns:
        The Figure drawn into.

    Examples:
        >>> import pandas as pd
        >>> table = pd.DataFrame({"outcome": "Q1", "effect": "condition", "test": "Friedman",
        ...                       "participants": [8, 12, 16], "effect_size": 0.5,
        ...                       "power": [0.41, 0.62, 0.79]})
        >>> power_figure(table).axes[0].get_xlabel()
        'participants'
    """
    table = analysis if isinstance(analysis, pd.DataFrame) else getattr(analysis, "power", None)
    if table is None or len(table) == 0:
        raise _no_data("power table", "power_figure")
    curves, detectable = split_power(table)
    kinds = [kind for kind, part in (("curves", curves), ("detectable", detectable)) if len(part)]
    axes, own = _panels(ax, len(kinds), columns=1, panel=(8.0, 3.8))
    drawn = dict(zip(kinds, axes))
    keys = ["outcome", "effect", "test"]
    both = pd.concat([curves, detectable])
    tests = list(dict.fromkeys(map(tuple, both[keys].to_numpy())))
    styles = {test: (PALETTE[k % len(PALETTE)], MARKERS[k % len(MARKERS)])
              for k, test in enumerate(tests)}

    def rows_of(part: pd.DataFrame, test: tuple) -> pd.DataFrame:
        chosen = (part[keys].to_numpy() == np.array(test, dtype=object)).all(axis=1)
        return part[chosen].sort_values("participants")

    if "curves" in drawn:
        axis = drawn["curves"]
        dashes = ["-", "--", ":", "-."]
        for test in tests:
            rows = rows_of(curves, test)
            sizes = list(dict.fromkeys(rows["effect_size"]))
            for j, size in enumerate(sizes):
                line = rows[rows["effect_size"] == size]
                colour, marker = styles[test]
                axis.plot(line["participants"].to_numpy(float), line["power"].to_numpy(float),
                          color=colour, marker=marker, ls=dashes[j % len(dashes)], lw=1.5, ms=5,
                          label=f"{_test_label(test)}, effect {size:.3g}")
        axis.axhline(0.8, color="#4d4d4d", lw=1.0, ls=":", zorder=1)
        axis.annotate("80 %", (0.0, 0.8), xycoords=("axes fraction", "data"), xytext=(4, 3),
                      textcoords="offset points", ha="left", fontsize="small", color="#4d4d4d")
        axis.set(ylim=(0.0, 1.02), xlabel="participants",
                 ylabel="power (share of studies with p < .05)", title="simulated power")
        # Beside the axes: lines of low power would run under a legend inside.
        axis.legend(fontsize="small", frameon=False, loc="upper left", bbox_to_anchor=(1.01, 1))
    if "detectable" in drawn:
        axis = drawn["detectable"]
        for test in tests:
            rows = rows_of(detectable, test)
            if rows.empty:
                continue
            colour, marker = styles[test]
            axis.plot(rows["participants"].to_numpy(float), rows["effect_size"].to_numpy(float),
                      color=colour, marker=marker, lw=1.5, ms=5, label=_test_label(test))
        axis.set(xlabel="participants", ylabel="smallest effect (each test's own scale)",
                 title="smallest effect detected with 80 % power")
        axis.legend(fontsize="small", frameon=False, loc="upper left", bbox_to_anchor=(1.01, 1))
    counts = sorted(set(pd.to_numeric(both["participants"], errors="coerce").dropna()))
    for axis in axes:
        _style(axis)
        axis.set_xticks(counts, [f"{c:g}" for c in counts])
    return axes[0].figure


def save_power_plot(table: pd.DataFrame, target: str | os.PathLike, *, dpi: int = DPI) -> Path:
    """Draw :func:`power_figure` of ``table`` into an image file (type by suffix), atomically.

    Args:
        table: :func:`realpen.stats.power.power_table`'s (or
            :func:`realpen.stats.power.minimum_detectable_effect`'s) table.
        target: the file to write (``.png``, ``.svg`` or another type matplotlib writes).
        dpi: resolution of raster formats in dots per inch.

    Returns:
        The path written.

    Raises:
        RealPenError: an image type matplotlib cannot write (named by the suffix).

    Examples:
        >>> import pandas as pd, tempfile, pathlib
        >>> table = pd.DataFrame({"outcome": "Q1", "effect": "condition", "test": "Friedman",
        ...                       "participants": [8, 12], "effect_size": 0.5,
        ...                       "power": [0.41, 0.62]})
        >>> with tempfile.TemporaryDirectory() as folder:
        ...     save_power_plot(table, pathlib.Path(folder) / "power.svg").name
        'power.svg'
    """
    from realpen.io.files import atomic_path

    target = Path(target)
    kind = image_kind(target)
    figure = power_figure(table)
    with atomic_path(target) as tmp:
        figure.savefig(tmp, format=kind, dpi=dpi, metadata=_metadata(kind))
    return target


def image_kind(target: str | os.PathLike) -> str:
    """The image type matplotlib writes for ``target``'s suffix (``"png"``, ``"svg"`` …).

    Raises:
        RealPenError: a suffix matplotlib cannot write, named with the types it can.
    """
    from matplotlib.backend_bases import FigureCanvasBase

    kind = Path(target).suffix.lower().lstrip(".")
    supported = FigureCanvasBase.get_supported_filetypes()
    if kind not in supported:
        raise fail(target, f"unknown image type '.{kind}' (use one of "
                           f"{', '.join('.' + k for k in sorted(supported))})")
    return kind


def _metadata(kind: str) -> dict:
    # No date in the files: the same analysis gives the same bytes.
    return {"Date": None} if kind in ("svg", "pdf") else {}


# --------------------------------------------------------------------------- saving

def _file_stem(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9._-]+", "_", name).strip("._") or "outcome"


def study_figure_names(analysis) -> list[str]:
    """The names (file stems) of every figure that applies to ``analysis``, in report order.

    For the paper's designs (study1, study2): ``figure7`` (Likert outcomes over
    ``condition``), ``figure10`` (a confusion table), ``figure11`` (``log_rt`` over
    ``modality:pen``), ``figure12`` (Likert outcomes over ``modality``). For any other design:
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


def _ci_words(cells: pd.DataFrame, outcomes: Iterable[str]) -> str:
    """How the intervals of ``outcomes`` were computed, for a caption."""
    if "ci_method" not in cells.columns:
        return "95 % CI"
    methods = cells.loc[cells["outcome"].isin(list(outcomes)), "ci_method"].dropna().astype(str)
    named = {"t": "t-based", "bootstrap": "bootstrap"}
    found = [named.get(m, m) for m in dict.fromkeys(methods)]
    return f"95 % CI ({', '.join(found)})" if found else "95 % CI"


def _figure_plan(analysis) -> list[tuple[str, object, str]]:
    """``(name, draw, caption)`` of every figure that applies; ``draw()`` returns the Figure."""
    plan: list[tuple[str, object, str]] = []
    cells = analysis.cells
    has_cells = isinstance(cells, pd.DataFrame) and len(cells) > 0
    shift = f"shifted by at most ±{LIKERT_JITTER:g} points so that tied answers stay visible"
    # The paper's figure numbers name the paper's figures only: another design's figures are
    # named by what they show (and its rating means are the means-* figures).
    paper = analysis.design in ("study1", "study2")
    if has_cells:
        cells = _cells(analysis)
        likert = _outcomes(cells, factor="condition", unit=LIKERT_UNIT)
        if likert and paper:
            plan.append(("figure7", lambda: figure7(analysis),
                         f"Figure 7. {', '.join(_outcome_label(analysis, o) for o in likert)}: "
                         f"mean rating per condition with its {_ci_words(cells, likert)}; "
                         f"grey lines: each participant's answers, {shift}."))
    if analysis.confusion is not None and len(analysis.confusion):
        plan.append(("figure10" if paper else "confusion", lambda: figure10(analysis),
                     ("Figure 10. " if paper else "")
                     + "Confusion matrix per modality: rows the pen presented, columns "
                     "the pen chosen; each cell gives the count of answers and its percentage "
                     "of the row (the colour, on one scale for all panels); outlined: correct "
                     "answers."))
    if has_cells:
        if RT_OUTCOME in _outcomes(cells, factor="modality:pen"):
            plan.append(("figure11" if paper else "response-times", lambda: figure11(analysis),
                         ("Figure 11. " if paper else "")
                         + "Response time (ms) per modality × pen: the geometric mean "
                         "over participants (exp of the mean of each participant's mean log "
                         f"RT) with its {_ci_words(cells, [RT_OUTCOME])}, exp-transformed; "
                         "faint dots: each participant."))
        items = _outcomes(cells, factor="modality", unit=LIKERT_UNIT, known=QUESTIONNAIRE)
        if items and paper:
            single = [item for item in items if
                      cells.loc[(cells["outcome"] == item) & (cells["factor"] == "modality"),
                                "level"].nunique() == 1]
            only = f" Asked in one modality only: {', '.join(single)}." if single else ""
            plan.append(("figure12", lambda: figure12(analysis),
                         f"Figure 12. Questionnaire items per modality: mean rating with its "
                         f"{_ci_words(cells, items)}; grey lines: each participant's answers, "
                         f"{shift}.{only}"))
        if analysis.design not in ("study1", "study2"):
            for outcome in _outcomes(cells):
                plan.append((f"means-{_file_stem(outcome)}",
                             lambda outcome=outcome: means_figure(analysis, outcome),
                             f"{_outcome_label(analysis, outcome)}: mean per level of each "
                             f"factor with its {_ci_words(cells, [outcome])}; dots: each "
                             "participant."))
    participants = _participants(analysis)
    known = QUESTIONNAIRE if analysis.design == "study2" else ()
    for outcome in _outcomes(participants, known=("recognition", RT_OUTCOME, *known)):
        factor = _main_factor(participants, outcome)
        plan.append((f"participants-{_file_stem(outcome)}",
                     lambda outcome=outcome: participants_figure(analysis, outcome),
                     f"{_outcome_label(analysis, outcome)}, participant by participant: each "
                     f"panel is one participant's own values across {_factor_label(factor)} "
                     "(exact, not shifted); dashed: the group mean."))
    if _has_power_figure(analysis.power):
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
    from matplotlib.backend_bases import FigureCanvasBase

    from realpen.io.files import write_files

    formats = [str(kind).lower().lstrip(".") for kind in formats]
    supported = FigureCanvasBase.get_supported_filetypes()
    for kind in formats:
        if kind not in supported:
            raise ParameterError("formats", f"unknown image type {kind!r} (choose from "
                                            f"{', '.join(sorted(supported))})")
    if not formats:
        raise ParameterError("formats", "needs at least one image type")
    if isinstance(dpi, bool) or not isinstance(dpi, int) or dpi < 10:
        raise ParameterError("dpi", f"must be a whole number >= 10, got {dpi!r}")
    directory = Path(directory)
    files: dict[Path, bytes] = {}
    for name, draw, _ in _figure_plan(analysis):
        figure = draw()
        for kind in formats:
            buffer = io.BytesIO()
            figure.savefig(buffer, format=kind, dpi=dpi, metadata=_metadata(kind))
            files[directory / f"{name}.{kind}"] = buffer.getvalue()
            # The first save laid the figure out; keep that layout for the other formats
            # rather than solve it again (a third of the time a figure takes to save).
            figure.set_layout_engine("none")
    write_files(files)
    return list(files)
