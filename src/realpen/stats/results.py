"""The one shape of every test result: a tidy DataFrame with the columns of ``results.csv``.

Every test function of :mod:`realpen.stats` returns a DataFrame whose first columns are
:data:`TEST_COLUMNS` (one row per test or effect), followed by any columns of its own (``z``,
``eps_gg`` ...). A study analysis adds :data:`CONTEXT_COLUMNS` (which analysis, outcome and
effect; the multiplicity adjustment) and writes :data:`RESULT_COLUMNS` to ``results.csv``.

Column meanings:

- ``analysis``: what was analysed, e.g. ``study1/friedman/superposition`` (see the analyses);
- ``outcome``: the dependent variable: a question id (``Q1``, ``realism``), ``recognition``
  (proportion correct) or ``log_rt`` (natural log of the response time in ms);
- ``effect``: the factor, interaction (``modality:pen``) or pair (``D-F``) tested;
- ``test``: the test's name (``Friedman``, ``Wilcoxon signed-rank``, ``RM-ANOVA``,
  ``ART RM-ANOVA``, ``paired t``);
- ``statistic_name`` / ``statistic``: ``chi2``, ``T`` (the smaller signed-rank sum), ``F``, ``t``;
- ``df1``, ``df2``: degrees of freedom (NaN where the test has none);
- ``p``: the p-value as the test gives it (for an RM-ANOVA, uncorrected for sphericity: the
  corrected ones are ``p_gg``/``p_hf`` columns and the analysis says which it reports);
- ``p_adjusted`` / ``adjust``: after a multiplicity adjustment (``bonferroni``, ``holm``) over
  the family named by ``analysis``; ``p`` again and ``none`` where there was none;
- ``effect_size_name`` / ``effect_size``: ``kendall_w``, ``r`` (z/sqrt(n)), ``ges``
  (generalised eta squared), ``cohen_dz``;
- ``n``: the number of subjects (blocks) the test saw;
- ``method``: how it was computed, in words a reader can check: the library function, the
  variant, the correction; ``paper-compatible: ...`` marks numbers that repeat the paper's
  choices (with the reason they are not recommended).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping

import pandas as pd

__all__ = ["TEST_COLUMNS", "CONTEXT_COLUMNS", "RESULT_COLUMNS", "test_row", "tidy",
           "with_context", "PAPER_COMPATIBLE"]

TEST_COLUMNS = ("test", "statistic_name", "statistic", "df1", "df2", "p", "effect_size_name",
                "effect_size", "n", "method")
"""The columns every test function returns first, in this order."""
CONTEXT_COLUMNS = ("analysis", "outcome", "effect", "p_adjusted", "adjust")
"""The columns an analysis adds."""
RESULT_COLUMNS = ("analysis", "outcome", "effect", "test", "statistic_name", "statistic", "df1",
                  "df2", "p", "p_adjusted", "adjust", "effect_size_name", "effect_size", "n",
                  "method")
"""The columns of ``results.csv``, exactly in this order."""
PAPER_COMPATIBLE = "paper-compatible"
"""The word that starts ``method`` for a number that repeats the paper's choices."""


def test_row(test: str, statistic_name: str, statistic: float, p: float, *, n: int,
             method: str, df1: float = math.nan, df2: float = math.nan,
             effect_size_name: str = "", effect_size: float = math.nan, **extra: object) -> dict:
    """One result as a dict with :data:`TEST_COLUMNS` first, then ``extra`` in the given order."""
    row = {"test": test, "statistic_name": statistic_name, "statistic": float(statistic),
           "df1": float(df1), "df2": float(df2), "p": float(p),
           "effect_size_name": effect_size_name, "effect_size": float(effect_size),
           "n": int(n), "method": method}
    row.update(extra)
    return row


def tidy(rows: Iterable[Mapping], index: Iterable | None = None) -> pd.DataFrame:
    """A DataFrame of result rows with :data:`TEST_COLUMNS` first (in order), then the rest."""
    frame = pd.DataFrame(list(rows), index=None if index is None else list(index))
    first = [column for column in TEST_COLUMNS if column in frame.columns]
    rest = [column for column in frame.columns if column not in TEST_COLUMNS]
    return frame[first + rest]


def with_context(results: pd.DataFrame, *, analysis: str, outcome: str,
                 effect: str | Iterable[str] | None = None, p_adjusted: Iterable[float] | None = None,
                 adjust: str = "none") -> pd.DataFrame:
    """``results`` (a test function's output) with :data:`CONTEXT_COLUMNS` added, columns in
    :data:`RESULT_COLUMNS` order and nothing else.

    Args:
        effect: one name for every row, one per row, or None: the frame's own ``effect``
            column (an RM-ANOVA's ``Source``-like column must be named ``effect``).
        p_adjusted: one adjusted p per row; None: ``p`` itself, with ``adjust="none"``.
    """
    frame = results.copy()
    frame["analysis"] = analysis
    frame["outcome"] = outcome
    if effect is not None:
        frame["effect"] = [effect] * len(frame) if isinstance(effect, str) else list(effect)
    frame["p_adjusted"] = frame["p"] if p_adjusted is None else list(p_adjusted)
    frame["adjust"] = adjust if p_adjusted is not None else "none"
    return frame[list(RESULT_COLUMNS)].reset_index(drop=True)
