"""Drawing pieces of the study figures: panels, means with intervals, participants, levels.

What :mod:`realpen.stats.figures` and :mod:`realpen.stats.power_plot` draw with: a grid of
panels (or the caller's axes), means with their confidence intervals as error bars, each
participant's values behind them as thin lines or faint dots, level axes, a colour-blind-safe
palette. Nothing here knows a study: levels, labels and limits come from the caller.

Colours are the Okabe–Ito palette (distinguishable with every common colour-vision
deficiency), and wherever colour tells groups apart a marker shape does too.

May import: :mod:`realpen.errors`, :mod:`realpen.display.axes` (and numpy, pandas, matplotlib).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence

import numpy as np
import pandas as pd
from matplotlib.axes import Axes
from matplotlib.collections import LineCollection
from matplotlib.figure import Figure
from matplotlib.patches import Rectangle

from realpen.display.axes import axes_list

__all__ = ["PALETTE", "MARKERS", "MEAN_COLOUR", "PARTICIPANT_COLOUR", "label_text", "factor_label",
           "likert_limits", "panels", "panel_title", "style_axes", "draw_mean_ci",
           "draw_participant_lines", "draw_participant_dots", "level_axis", "cell_outline",
           "MAX_VECTOR_PARTICIPANTS", "MAX_VECTOR_STEPS", "participant_alpha"]

PALETTE = ("#0072B2", "#D55E00", "#009E73", "#CC79A7", "#E69F00", "#56B4E9", "#000000")
"""Okabe & Ito's colour-blind-safe colours (their yellow left out: unreadable on white)."""
MARKERS = ("o", "s", "D", "^", "v", "P", "X")
"""Marker shapes paired with :data:`PALETTE`, so groups differ in shape as well as colour."""

MEAN_COLOUR = "#1a1a1a"
"""The colour of a group's means (near black)."""
PARTICIPANT_COLOUR = "#8c8c8c"
"""The grey of each participant's own values, behind the means."""
MAX_VECTOR_PARTICIPANTS = 48
"""The most participants whose lines or dots are drawn as shapes of their own. Beyond it
thousands of shapes would make files of tens of MB that a browser barely opens, and a grey too
dense to read: lines are aggregated (:func:`draw_participant_lines`) and dots drawn as one
image layer (rasterised in SVG and PDF, the means and axes staying vector), each fainter
(:func:`participant_alpha`)."""
MAX_VECTOR_STEPS = 1000
"""The most distinct steps :func:`draw_participant_lines` draws as vector lines when it
aggregates; more (values that rarely repeat) are rasterised."""
PARTICIPANT_ALPHA_FLOOR = 0.02
"""The faintest a participant's line or dot is drawn (opacity): fainter would vanish when the
image's 8-bit colours round it."""


def participant_alpha(count: int, alpha: float) -> float:
    """The opacity of each of ``count`` participants' lines or dots drawn at ``alpha`` up to
    :data:`MAX_VECTOR_PARTICIPANTS`: the same up to there, beyond it scaled down so that the
    layer's darkness follows how many participants overlap rather than saturating.

    >>> participant_alpha(12, 0.5), participant_alpha(480, 0.5), participant_alpha(10**5, 0.5)
    (0.5, 0.05, 0.02)
    """
    if count <= MAX_VECTOR_PARTICIPANTS:
        return alpha
    return max(alpha * MAX_VECTOR_PARTICIPANTS / count, PARTICIPANT_ALPHA_FLOOR)


def label_text(value: object) -> str:
    """A user's string as a matplotlib label shows it literally: ``$`` would otherwise start
    mathtext.

    >>> print(label_text("cost $5"))
    cost \\$5
    """
    return str(value).replace("$", r"\$")


def factor_label(factor: str) -> str:
    """A factor or an interaction (``modality:pen``) as an axis names it (``modality × pen``).

    >>> factor_label("modality:pen")
    'modality × pen'
    """
    return " × ".join(label_text(part) for part in factor.split(":"))


def likert_limits(values: Iterable[float]) -> tuple[float, float]:
    """The y range (points) of a Likert axis: the scale from 1 to (at least) 5, widened to any
    value or interval end beyond it, with 0.4 points of margin.

    >>> likert_limits([2.0, 6.5, float("nan")])
    (0.6, 6.9)
    """
    finite = [float(v) for v in values if np.isfinite(v)]
    return min([1.0] + finite) - 0.4, max([5.0] + finite) + 0.4


def panels(ax: Axes | Sequence[Axes] | None, count: int, *, columns: int,
           panel: tuple[float, float]) -> tuple[list[Axes], bool]:
    """``count`` axes to draw into, and whether they are new.

    Args:
        ax: the caller's Axes (``count`` of them, checked), or None for a new figure (not a
            pyplot one) with a constrained grid of at most ``columns`` panels per row.
        count: how many panels.
        columns: panels per row of a new grid.
        panel: one panel's (width, height) in inches.

    Raises:
        ParameterError: ``ax`` is not ``count`` Axes (names ``ax``).
    """
    if ax is not None:
        return axes_list(ax, count, panel, "ax"), False
    columns = max(1, min(columns, count))
    rows = math.ceil(count / columns)
    figure = Figure(figsize=(panel[0] * columns, panel[1] * rows), layout="constrained")
    grid = figure.subplots(rows, columns, squeeze=False).ravel()
    for spare in grid[count:]:
        spare.remove()
    return list(grid[:count]), True


def panel_title(ax: Axes, text: str, *, own: bool, **style: object) -> None:
    """Title ``ax`` with ``text`` (``style``: :meth:`matplotlib.axes.Axes.set_title`'s text
    properties, e.g. ``fontsize``).

    On a figure of its own (``own``: made by the caller of this function, with no ticks or
    label above any axes) the title is fixed at the top of the axes, y = 1: where matplotlib
    would put it anyway, but without searching every axis for decorations above at each layout
    pass and each drawing (a tenth of the time a study figure takes to render). On the user's
    own axes matplotlib places it.
    """
    ax.set_title(text, y=1.0 if own else None, **style)


def style_axes(ax: Axes) -> None:
    """The study figures' look: no top or right spine, light horizontal grid lines behind."""
    ax.spines[["top", "right"]].set_visible(False)
    ax.grid(True, axis="y", color="#e3e3e3", lw=0.8, zorder=0)
    ax.set_axisbelow(True)


def draw_mean_ci(ax: Axes, x: np.ndarray, rows: pd.DataFrame, *, colour: str = MEAN_COLOUR,
                 marker: str = "o", label: str | None = None, line: bool = False) -> None:
    """Means with their confidence intervals as error bars at ``x``.

    ``rows`` holds ``mean``, ``ci_low`` and ``ci_high`` (any unit, the axis's); an interval that
    could not be computed (NaN) is left out. ``line`` joins the means.
    """
    mean = rows["mean"].to_numpy(dtype=float)
    low = np.nan_to_num(mean - rows["ci_low"].to_numpy(dtype=float), nan=0.0)
    high = np.nan_to_num(rows["ci_high"].to_numpy(dtype=float) - mean, nan=0.0)
    ax.errorbar(x, mean, yerr=[np.maximum(low, 0), np.maximum(high, 0)], fmt=marker,
                ls="-" if line else "none", color=colour, ecolor=colour, elinewidth=1.6,
                capsize=4, capthick=1.4, ms=6.5, mfc=colour, mec="white", mew=0.8, lw=1.4,
                zorder=4, label=label)


def draw_participant_lines(ax: Axes, x: np.ndarray, matrix: pd.DataFrame, *,
                           spread: float = 0.0) -> None:
    """Each participant's values (a row of ``matrix``, participants × levels) as a thin grey
    line behind the means.

    With ``spread`` > 0 the lines are shifted apart by fixed amounts within ±``spread`` (in the
    axis's unit), so that tied values (Likert answers) stay visible. Above
    :data:`MAX_VECTOR_PARTICIPANTS` participants, where a line per participant would only make
    a grey block, the lines are aggregated instead (``spread`` unused): each distinct step
    between neighbouring levels one line, as wide as how many participants took it, each
    distinct value one dot, as large as how many gave it.
    """
    count = len(matrix)
    if count > MAX_VECTOR_PARTICIPANTS:
        _participant_steps(ax, np.asarray(x, dtype=float), matrix.to_numpy(dtype=float))
        return
    for k, (_, values) in enumerate(matrix.iterrows()):
        shift = ((k - (count - 1) / 2) / max(count - 1, 1)) * 2 * spread if count > 1 else 0.0
        y = values.to_numpy(dtype=float) + shift
        ax.plot(x, y, color=PARTICIPANT_COLOUR, lw=0.8, alpha=0.45, marker="o", ms=2.5,
                zorder=2)


def _participant_steps(ax: Axes, x: np.ndarray, values: np.ndarray) -> None:
    """:func:`draw_participant_lines` of many participants, aggregated: each distinct step
    from one level's value to the next level's is one line, as wide as how many participants
    took it (the widest: the most, in this panel), and each distinct value one dot, as large
    as how many gave it. A missing value breaks a participant's line there, as before."""
    segments, taken = [], []
    for j in range(values.shape[1] - 1):
        pair = values[:, j:j + 2]
        steps, counts = np.unique(pair[np.isfinite(pair).all(axis=1)], axis=0,
                                  return_counts=True)
        segments += [((x[j], a), (x[j + 1], b)) for a, b in steps]
        taken += list(counts)
    if segments:
        share = np.asarray(taken, dtype=float) / max(taken)
        lines = LineCollection(segments, colors=PARTICIPANT_COLOUR, linewidths=0.3 + 4.5 * share,
                               alpha=0.45, zorder=2, capstyle="round")
        lines.set_rasterized(len(segments) > MAX_VECTOR_STEPS)
        ax.add_collection(lines, autolim=False)
    columns = np.broadcast_to(x, values.shape)[np.isfinite(values)]
    points, counts = np.unique(np.column_stack([columns, values[np.isfinite(values)]]), axis=0,
                               return_counts=True)
    if len(points):
        dots = ax.scatter(points[:, 0], points[:, 1], s=6.0 + 60.0 * counts / counts.max(),
                          color=PARTICIPANT_COLOUR, alpha=0.6, linewidths=0, zorder=2)
        dots.set_rasterized(len(points) > MAX_VECTOR_STEPS)


def draw_participant_dots(ax: Axes, x: float, values: np.ndarray, *, colour: str, width: float,
                          span: float) -> None:
    """Values as faint dots beside ``x``; equal (or nearly, within 2 % of ``span``, the axis's
    range) values are spread sideways within ``width`` so each one shows. Above
    :data:`MAX_VECTOR_PARTICIPANTS` values the dots are rasterised and fainter
    (:func:`participant_alpha`)."""
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
    dots = ax.scatter(x + offsets, values, s=12, color=colour,
                      alpha=participant_alpha(values.size, 0.5), linewidths=0, zorder=2)
    if values.size > MAX_VECTOR_PARTICIPANTS:
        dots.set_rasterized(True)


def level_axis(ax: Axes, levels: Sequence[str], label: str, *, rotate: bool = False) -> None:
    """An x axis of ``levels`` at 0, 1, 2 …, labelled ``label``; ``rotate`` tilts long names."""
    ax.set_xticks(range(len(levels)), [label_text(level) for level in levels],
                  rotation=30 if rotate else 0, ha="right" if rotate else "center")
    ax.set_xlim(-0.6, len(levels) - 0.4)
    ax.set_xlabel(label)


def cell_outline(x: float, y: float) -> Rectangle:
    """A frame around the image cell at column ``x``, row ``y`` (a confusion matrix's diagonal)."""
    return Rectangle((x - 0.5, y - 0.5), 1.0, 1.0, fill=False, ec="#1a1a1a", lw=1.4, zorder=3)
