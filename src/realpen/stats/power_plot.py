"""The power plot: simulated power, or the smallest detectable effect, against participants.

:func:`power_figure` draws a power table of :func:`realpen.stats.power.power_table` or
:func:`realpen.stats.power.minimum_detectable_effect` (or a study analysis's ``power``);
:func:`save_power_plot` writes it to a file (``realpen stats power --plot``).

May import: :mod:`realpen.errors`, :mod:`realpen.display`, :mod:`realpen.stats.figure_data`
(and numpy, pandas, matplotlib).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pandas as pd
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from realpen.display.charts import MARKERS, PALETTE, label_text, panels, style_axes
from realpen.display.images import DPI, save_figure
from realpen.errors import ParameterError
from realpen.stats.figure_data import no_data, require_table

__all__ = ["POWER_CURVE_COLUMNS", "DETECTABLE_COLUMNS", "split_power", "has_power_figure",
           "power_figure", "save_power_plot"]

POWER_CURVE_COLUMNS = ("outcome", "effect", "test", "participants", "effect_size", "power")
"""The columns of a table of power curves (:func:`realpen.stats.power.power_table`)."""
DETECTABLE_COLUMNS = ("outcome", "test", "participants", "minimum_effect", "power")
"""The columns of a table of smallest detectable effects
(:func:`realpen.stats.power.minimum_detectable_effect`)."""


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
        require_table(table, DETECTABLE_COLUMNS, "power")
        table = table.rename(columns={"minimum_effect": "effect_size"})
        detectable = pd.Series(True, index=table.index)
    else:
        require_table(table, POWER_CURVE_COLUMNS, "power")
        detectable = (table["kind"].astype(str).str.contains("detectable")
                      if "kind" in table.columns else pd.Series(False, index=table.index))
    if "effect" not in table.columns:
        table["effect"] = ""
    for name in ("outcome", "effect", "test"):
        table[name] = table[name].astype(str)
    return table[~detectable], table[detectable]


def has_power_figure(table: pd.DataFrame | None) -> bool:
    """Whether a power table has something to draw against participants (a curve, or the
    smallest effects at two or more sizes); one study's detectable effects are a table."""
    if table is None or len(table) == 0:
        return False
    curves, detectable = split_power(table)
    return len(curves) > 0 or detectable["participants"].nunique() > 1


def _test_label(test: tuple) -> str:
    return " ".join(label_text(part) for part in test if part)


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
        raise no_data("power table", "power_figure")
    curves, detectable = split_power(table)
    kinds = [kind for kind, part in (("curves", curves), ("detectable", detectable)) if len(part)]
    axes, own = panels(ax, len(kinds), columns=1, panel=(8.0, 3.8))
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
        style_axes(axis)
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
    return save_figure(power_figure(table), target, dpi=dpi)
