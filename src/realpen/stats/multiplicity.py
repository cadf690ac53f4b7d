"""Multiplicity adjustment of a family of p-values (Holm, Bonferroni).

pingouin's :func:`pingouin.multicomp` does the work. statsmodels' ``multipletests`` gives the
same numbers, but its Holm branch runs a full garbage collection on every call (statsmodels
0.15): some 0.1 s each in a process that holds a report's tables and figures, and an analysis
adjusts dozens of families.
"""

from __future__ import annotations

import numpy as np

__all__ = ["ADJUSTMENTS", "adjusted_p", "LIBRARY"]

ADJUSTMENTS = ("holm", "bonferroni", "none")
"""The adjustments offered, by their names in ``results.csv``'s ``adjust`` column."""
LIBRARY = "pingouin multicomp"
"""How a ``method`` text names the function that adjusted."""
_PINGOUIN_NAMES = {"holm": "holm", "bonferroni": "bonf"}


def adjusted_p(p: np.ndarray | list[float], method: str) -> np.ndarray:
    """``p`` adjusted together over its finite values (NaN stays NaN and is not counted).

    Args:
        p: the family's p-values (probabilities, NaN where a test gave none).
        method: one of :data:`ADJUSTMENTS`; ``none`` returns a copy of ``p``.

    Returns:
        The adjusted p-values (at most 1), in the order given.

    >>> adjusted_p([0.01, 0.04, float("nan"), 0.03], "holm").round(2).tolist()
    [0.03, 0.06, nan, 0.06]
    """
    if method not in ADJUSTMENTS:
        raise ValueError(f"adjustment {method!r}: must be one of {', '.join(ADJUSTMENTS)}")
    values = np.array(p, dtype=float)
    tested = np.isfinite(values)
    if method == "none" or tested.sum() < 2:
        return values
    import pingouin

    values[tested] = pingouin.multicomp(values[tested], method=_PINGOUIN_NAMES[method])[1]
    return values
