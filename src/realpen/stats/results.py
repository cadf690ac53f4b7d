"""The one shape of every test result: a tidy DataFrame with the columns of ``results.csv``.

Every test function of :mod:`realpen.stats` returns a DataFrame whose first columns are
:data:`TEST_COLUMNS` (one row per test or effect), followed by any columns of its own (``z``,
``eps_gg`` ...). A study analysis adds :data:`CONTEXT_COLUMNS` (which analysis, outcome and
effect; the multiplicity adjustment) and writes :data:`RESULT_COLUMNS` to ``results.csv``.

Column meanings:

- ``analysis``: what was analysed, e.g. ``study1/friedman/superposition`` (see the analyses);
- ``outcome``: the dependent variable: a question id (``Q1``, ``realism``), ``recognition``
  (proportion correct) or ``log_rt`` (natural log of the response time in ms);
- ``effect``: the factor, interaction (``modality:pen``) or pair tested; a pair is named
  ``<a> vs <b>`` (:func:`pair_label`: ``D vs F``, ``tactile vs audio-tactile``), the test is of
  a − b;
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
  choices (with the reason they are not recommended);
- ``apa``: the result as an APA-style sentence to paste (:func:`apa_sentence`), e.g.
  ``χ²(2) = 6.45, p = .040, W = .27``; empty where the test gave no number;
- ``level_a``, ``level_b``: a pair's two levels (the test is of a − b), empty for other rows.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping

import pandas as pd

__all__ = ["TEST_COLUMNS", "CONTEXT_COLUMNS", "RESULT_COLUMNS", "test_row", "tidy",
           "with_context", "PAPER_COMPATIBLE", "PAIR_SEPARATOR", "pair_label", "apa_sentence",
           "apa_p", "completed"]

TEST_COLUMNS = ("test", "statistic_name", "statistic", "df1", "df2", "p", "effect_size_name",
                "effect_size", "n", "method")
"""The columns every test function returns first, in this order."""
CONTEXT_COLUMNS = ("analysis", "outcome", "effect", "p_adjusted", "adjust")
"""The columns an analysis adds."""
RESULT_COLUMNS = ("analysis", "outcome", "effect", "test", "statistic_name", "statistic", "df1",
                  "df2", "p", "p_adjusted", "adjust", "effect_size_name", "effect_size", "n",
                  "method", "apa", "level_a", "level_b")
"""The columns of ``results.csv``, exactly in this order."""
PAPER_COMPATIBLE = "paper-compatible"
"""The word that starts ``method`` for a number that repeats the paper's choices."""
PAIR_SEPARATOR = " vs "
"""Between a pair's two levels in ``effect``: levels may hold hyphens (``audio-tactile``)."""


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
    :data:`RESULT_COLUMNS` order and nothing else: ``level_a``/``level_b`` from a pairwise
    test's ``a``/``b`` columns (empty without them) and ``apa`` from each row
    (:func:`apa_sentence`).

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
    # A pairwise test names its levels in columns a and b (the test is of a - b).
    for column, source in (("level_a", "a"), ("level_b", "b")):
        frame[column] = frame[source].astype(str) if source in frame.columns else ""
    frame["apa"] = [apa_sentence(row) for row in frame.to_dict("records")]
    return frame[list(RESULT_COLUMNS)].reset_index(drop=True)


def completed(results: pd.DataFrame) -> pd.DataFrame:
    """``results`` with every column of :data:`RESULT_COLUMNS`, in order: a missing or empty
    ``apa`` is written from the row's test columns, missing level columns are empty.

    Rows made by :func:`with_context` have them already; this is for frames built by hand.

    >>> row = {"test": "paired t", "statistic_name": "t", "statistic": 2.31, "df1": 11.0,
    ...        "p": 0.041, "effect_size_name": "cohen_dz", "effect_size": 0.667}
    >>> completed(pd.DataFrame([row]))[["apa", "level_a"]].iloc[0].tolist()
    ['t(11) = 2.31, p = .041, d_z = 0.67', '']
    """
    frame = results.copy().reset_index(drop=True)
    for column in RESULT_COLUMNS:
        if column not in frame.columns:
            frame[column] = math.nan
    for column in ("apa", "level_a", "level_b"):
        frame[column] = [value if isinstance(value, str) else "" for value in frame[column]]
    frame["apa"] = [text or apa_sentence(row)
                    for text, row in zip(frame["apa"], frame.to_dict("records"))]
    return frame[list(RESULT_COLUMNS)]


def pair_label(a: object, b: object) -> str:
    """The ``effect`` of a pairwise test of ``a`` − ``b``: ``"<a> vs <b>"``.

    A hyphen would be ambiguous (``tactile-audio-tactile``); the two levels are also in the
    ``level_a`` and ``level_b`` columns.

    >>> pair_label("tactile", "audio-tactile")
    'tactile vs audio-tactile'
    """
    return f"{a}{PAIR_SEPARATOR}{b}"


# --- APA-style sentences ---------------------------------------------------------------------

MINUS = "\u2212"
"""The minus sign of a printed number (APA: a true minus, not a hyphen)."""
_STATISTIC_SYMBOLS = {"chi2": "χ²", "F": "F", "t": "t", "T": "T", "z": "z", "W": "W",
                      "V": "V", "U": "U", "H": "H"}
_EFFECT_SYMBOLS = {"kendall_w": ("W", True), "r": ("r", True), "ges": ("η²G", True),
                   "eta2": ("η²", True), "partial_eta2": ("η²p", True),
                   "cohen_dz": ("d_z", False), "cohen_d": ("d", False), "cohen_h": ("h", False)}
"""``effect_size_name``: (symbol, bounded by 1 so printed without a leading zero)."""
_ADJUSTMENT_NAMES = {"holm": "Holm", "bonferroni": "Bonferroni"}


def _finite(value: object) -> float | None:
    try:
        number = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        return None
    return None if math.isnan(number) else number


def _signed(text: str) -> str:
    """``text`` (a formatted number) with a true minus sign, and no sign on a rounded zero."""
    if text.startswith("-"):
        digits = text[1:]
        return digits if not digits.strip("0.") else MINUS + digits
    return text


def _number(value: float, decimals: int = 2, *, bounded: bool = False) -> str:
    """A number with ``decimals`` decimals (infinity as ``∞``); ``bounded`` (|value| ≤ 1 by
    definition, APA): without the leading zero."""
    if math.isinf(value):
        return ("" if value > 0 else MINUS) + "∞"
    text = _signed(f"{value:.{decimals}f}")
    if bounded:
        text = text.replace("0.", ".", 1) if text.lstrip(MINUS).startswith("0.") else text
    return text


def _df(value: float) -> str:
    """Degrees of freedom: whole as an integer, corrected (Greenhouse–Geisser) with 2 decimals."""
    return str(int(round(value))) if abs(value - round(value)) < 1e-9 else f"{value:.2f}"


def apa_p(p: float) -> str:
    """``p`` as APA writes it, with ``p``: ``p = .040``, ``p < .001``, ``p > .999``.

    >>> apa_p(0.0398), apa_p(0.0004), apa_p(1.0)
    ('p = .040', 'p < .001', 'p > .999')
    """
    if p < 0.001:
        return "p < .001"
    if p > 0.999:
        return "p > .999"
    return "p = " + _number(p, 3, bounded=True)


def _effect_size(name: str, value: float) -> str:
    symbol, bounded = _EFFECT_SYMBOLS.get(name, (name, False))
    if name == "r":
        value = abs(value)  # the sign is the direction of a − b, kept in effect_size
    decimals = 2 if value == 0 or abs(round(value, 2)) > 0 else 3
    return f"{symbol} = {_number(value, decimals, bounded=bounded)}"


def apa_sentence(row: Mapping) -> str:
    """One result as an APA-style sentence to paste, from its test columns.

    The statistic with its degrees of freedom (``χ²(2) = 6.45``, ``F(2, 142) = 9.47``,
    ``t(11) = 2.31``; corrected df with 2 decimals), ``p`` (``p = .040``, ``p < .001``; an
    adjusted p in parentheses: ``(Holm-adjusted p = .150)``), then the effect size. Statistics
    have 2 decimals (a Wilcoxon rank sum T 1), p 3; effect sizes 2 (3 when 2 would round to
    zero), without a leading zero where they cannot exceed 1 (W, r, η²G); negatives with a
    true minus sign (−). A Wilcoxon signed-rank row (statistic ``T``) also gives z = −|r|·√n,
    the normal z of T as SPSS prints it, and r as |r| (the direction of a − b is the sign of
    ``effect_size``); an exact binomial test (statistic ``k``, ``n`` trials) is written
    ``p = .004 (k/n = 31/60)`` (an adjusted p inside the parentheses).

    Args:
        row: a mapping with ``test``, ``statistic_name``, ``statistic``, ``df1``, ``df2``,
            ``p``, and optionally ``p_adjusted``, ``adjust``, ``effect_size_name``,
            ``effect_size`` and ``n`` (a row of :data:`RESULT_COLUMNS`).

    Returns:
        The sentence, or ``""`` when the test gave no statistic (e.g. every difference zero,
        a model that did not converge); without a p (NaN) the sentence has none.

    Examples:
        >>> apa_sentence({"test": "Friedman", "statistic_name": "chi2", "statistic": 6.452,
        ...               "df1": 2, "p": 0.0397, "effect_size_name": "kendall_w",
        ...               "effect_size": 0.2688})
        'χ²(2) = 6.45, p = .040, W = .27'
        >>> apa_sentence({"test": "RM-ANOVA", "statistic_name": "F", "statistic": 9.473,
        ...               "df1": 2, "df2": 142, "p": 0.00013, "effect_size_name": "ges",
        ...               "effect_size": 0.0521})
        'F(2, 142) = 9.47, p < .001, η²G = .05'
    """
    name = str(row.get("statistic_name") or "")
    statistic, p = _finite(row.get("statistic")), _finite(row.get("p"))
    if statistic is None:
        return ""
    df1, df2 = _finite(row.get("df1")), _finite(row.get("df2"))
    n = _finite(row.get("n"))
    effect_name = str(row.get("effect_size_name") or "")
    effect = _finite(row.get("effect_size"))
    parts = []
    adjust = str(row.get("adjust") or "none")
    adjusted = _finite(row.get("p_adjusted"))
    if adjust != "none" and adjusted is not None and p is not None:
        said = f"{_ADJUSTMENT_NAMES.get(adjust, adjust)}-adjusted {apa_p(adjusted)}"
    else:
        said = ""
    if name == "k" and n is not None and p is not None and \
            "binomial" in str(row.get("test", "")).lower():
        counts = f"k/n = {int(round(statistic))}/{int(round(n))}"
        parts.append(f"{apa_p(p)} ({counts}{'; ' + said if said else ''})")
    else:
        symbol = _STATISTIC_SYMBOLS.get(name, name)
        dfs = ", ".join(_df(df) for df in (df1, df2) if df is not None)
        decimals = 1 if name == "T" else 2
        parts.append(f"{symbol}{f'({dfs})' if dfs else ''} = {_number(statistic, decimals)}")
        if name == "T" and effect_name == "r" and effect is not None and n:
            parts.append(f"z = {_number(-abs(effect) * math.sqrt(n))}")
        if p is not None:
            parts.append(apa_p(p) + (f" ({said})" if said else ""))
    if effect_name and effect is not None:
        parts.append(_effect_size(effect_name, effect))
    return ", ".join(parts)
