"""The aligned rank transform (ART): nonparametric factorial analyses of within-subject designs.

:func:`aligned_rank_transform` aligns and ranks the responses for each main effect and
interaction of one to three within-subject factors (Wobbrock et al. 2011, as the ARTool R
package) and analyses the ranks by the repeated-measures ANOVA of :mod:`realpen.stats.anova`.
The one-factor rank tests (Friedman, Wilcoxon) are :mod:`realpen.stats.nonparametric`.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import scipy.stats

from realpen.stats.anova import rm_anova_table
from realpen.stats.contrasts import ZERO_FRACTION, anovarm_f, contrast_decomposition, effect_name, effects
from realpen.stats.long import balanced_wide, factor_list, safe_long
from realpen.stats.results import tidy

__all__ = ["aligned_rank_transform"]


def _ranking_precision(values: np.ndarray) -> np.ndarray:
    """Values rounded to 12 significant digits of their largest magnitude, so aligned responses
    that are equal in exact arithmetic (but differ in the last bits) tie when ranked."""
    scale = float(np.max(np.abs(values))) if len(values) else 0.0
    if scale == 0:
        return values
    return np.round(values, 11 - int(math.floor(math.log10(scale))))


def aligned_rank_transform(data: pd.DataFrame, *, dv: str, within: list[str], subject: str) -> pd.DataFrame:
    """The aligned rank transform (ART) for a fully within-subject design of 1–3 factors.

    For each effect (main effects, then interactions), the responses are aligned: the residual
    of the full cell-means model (y minus its cell's mean over subjects) plus the effect's
    estimate (for A: mean_A − grand mean; for A:B: mean_AB − mean_A − mean_B + grand mean; the
    three-way one likewise by inclusion–exclusion), as Wobbrock et al. (2011) and the ARTool R
    package (Kay et al.) do. The aligned responses are ranked over all observations (average
    ranks for ties; :func:`scipy.stats.rankdata`) and the ranks analysed by
    :func:`realpen.stats.anova.rm_anova` (statsmodels AnovaRM), of which only that effect's row
    is kept.

    ``aligned_check`` is ARTool's correctness check: the largest |F| of the *other* effects in
    a repeated-measures ANOVA of that effect's aligned, unranked responses, which must be ~0
    (NaN with one factor: there is no other effect).

    Args:
        data: long format, exactly one row per subject × cell.
        dv: the response's column (numeric, e.g. a rating in points).
        within: 1–3 factor columns.
        subject: the subject column.

    Returns:
        One row per effect: :data:`realpen.stats.results.TEST_COLUMNS` (test
        ``"ART RM-ANOVA"``, F on the ranks, ``ges`` of the ranks), then ``effect`` (named as
        :func:`realpen.stats.anova.rm_anova` names it), the sphericity columns of
        :func:`realpen.stats.anova.rm_anova` (of the ranks) and ``aligned_check``.

    Raises:
        ParameterError: as :func:`realpen.stats.anova.rm_anova`.

    References:
        Wobbrock, J. O., Findlater, L., Gergle, D., & Higgins, J. J. (2011). The aligned rank
        transform for nonparametric factorial analyses using only ANOVA procedures. Proc. CHI
        2011, 143–146. https://doi.org/10.1145/1978942.1978963

        Kay, M., Elkin, L. A., Higgins, J. J., & Wobbrock, J. O. ARTool: Aligned Rank Transform
        for Nonparametric Factorial ANOVAs (R package). https://doi.org/10.5281/zenodo.594511

    Examples:
        >>> import pandas as pd
        >>> from realpen.stats.art import aligned_rank_transform
        >>> data = pd.DataFrame({"subject": [s for s in range(4) for _ in range(4)],
        ...                      "A": ["a1", "a1", "a2", "a2"] * 4, "B": ["b1", "b2"] * 8,
        ...                      "rating": [1, 2, 3, 5, 2, 2, 3, 6, 1, 3, 4, 5, 2, 3, 3, 7]})
        >>> table = aligned_rank_transform(data, dv="rating", within=["A", "B"], subject="subject")
        >>> for row in table.itertuples():
        ...     print(f"{row.effect}: F({row.df1:.0f}, {row.df2:.0f}) = {row.statistic:.2f}, p = {row.p:.4f}")
        A: F(1, 3) = 1228.80, p = 0.0001
        B: F(1, 3) = 136.53, p = 0.0013
        A:B: F(1, 3) = 2.47, p = 0.2143
        >>> bool(table["aligned_check"].max() < 1e-9)
        True
    """
    factors = factor_list(within)
    wide = balanced_wide(data, dv=dv, within=factors, subject=subject)
    long = safe_long(wide)
    codes = [f"f{j}" for j in range(len(factors))]
    y = long["y"].to_numpy(dtype=float)
    residual = y - long.groupby(codes, sort=False)["y"].transform("mean").to_numpy()
    grand = y.mean()
    means: dict[tuple[int, ...], np.ndarray] = {(): np.full(len(y), grand)}
    for effect in effects(factors):
        means[effect] = long.groupby([codes[j] for j in effect], sort=False)["y"].transform("mean").to_numpy()
    rows = []
    for effect in effects(factors):
        estimate = np.zeros(len(y))
        for subset in [(), *[e for e in effects(factors) if set(e) <= set(effect)]]:
            estimate += (-1) ** (len(effect) - len(subset)) * means[subset]
        aligned = residual + estimate
        ranked = long.assign(y=scipy.stats.rankdata(_ranking_precision(aligned)))
        name = effect_name(factors, effect)
        table = _rank_anova(ranked, factors)
        row = table.loc[table["effect"] == name].iloc[0].to_dict()
        row.update(test="ART RM-ANOVA", aligned_check=_aligned_check(long.assign(y=aligned), effect),
                   method="aligned rank transform (Wobbrock et al. 2011, as ARTool): aligned "
                          "responses ranked with average ties, then " + row["method"])
        rows.append(row)
    return tidy(rows)


def _aligned_check(aligned: pd.DataFrame, effect: tuple[int, ...]) -> float:
    """The largest |F| of the effects other than ``effect`` in statsmodels' AnovaRM of the
    aligned responses (a :func:`realpen.stats.long.safe_long` frame); NaN when there is no other effect.

    An effect whose error sum of squares is rounding dust gets F = 0 when its own is dust too
    (0/0: nothing left, as the check wants) and inf otherwise (a failed alignment)."""
    codes = [column for column in aligned.columns if column.startswith("f")]
    if len(codes) == 1:
        return math.nan
    with np.errstate(invalid="ignore", divide="ignore"):
        table = anovarm_f(aligned, len(codes))
    wide = aligned.set_index(["s", *codes])["y"].unstack(codes)
    parts = contrast_decomposition(wide)
    zero = ZERO_FRACTION * float((aligned["y"] ** 2).sum())
    largest = math.nan
    for other, (f_value, *_rest) in table.items():
        if other == effect:
            continue
        if parts[other]["ss_error"] <= zero:
            f_value = 0.0 if parts[other]["ss"] <= zero else math.inf
        largest = abs(f_value) if math.isnan(largest) else max(largest, abs(f_value))
    return largest


def _rank_anova(ranked: pd.DataFrame, factors: list[str]) -> pd.DataFrame:
    """:func:`realpen.stats.anova.rm_anova` of a :func:`realpen.stats.long.safe_long` frame, its
    effects renamed to ``factors``'."""
    codes = [f"f{j}" for j in range(len(factors))]
    table = rm_anova_table(ranked, dv="y", within=codes, subject="s", with_pingouin=False)
    names = {effect_name(codes, effect): effect_name(factors, effect) for effect in effects(factors)}
    return table.assign(effect=table["effect"].map(names))
