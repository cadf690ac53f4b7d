"""The aligned rank transform (ART): nonparametric factorial analyses of within-subject designs.

:func:`aligned_rank_transform` aligns and ranks the responses for each main effect and
interaction of one to three within-subject factors (Wobbrock et al. 2011, as the ARTool R
package) and analyses the ranks by a repeated-measures ANOVA of every effect's ranks at once
(:func:`realpen.stats.contrasts.contrast_anova`; rows as :mod:`realpen.stats.anova` gives them).
The one-factor rank tests (Friedman, Wilcoxon) are :mod:`realpen.stats.nonparametric`.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import scipy.stats

from realpen.stats.anova import CONTRAST_SOURCE, effect_row
from realpen.stats.contrasts import ZERO_FRACTION, contrast_anova, effects
from realpen.stats.long import balanced_wide, factor_list
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
    ranks for ties; :func:`scipy.stats.rankdata`) and the ranks analysed by a repeated-measures
    ANOVA, of which only that effect's row is kept. All effects' ANOVAs run at once from
    orthonormal contrasts (:func:`realpen.stats.contrasts.contrast_anova`: each effect against
    its own effect × subject error, F and p as statsmodels' AnovaRM gives them, ε and Mauchly
    as :func:`realpen.stats.anova.rm_anova`).

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
    y = wide.to_numpy(dtype=float)
    n = len(y)
    sizes = [len(level) for level in wide.columns.levels]
    aligned = _aligned(y.reshape(n, *sizes)).reshape(-1, *y.shape)  # effects × subjects × cells
    ranked = np.stack([scipy.stats.rankdata(_ranking_precision(one).ravel()).reshape(y.shape)
                       for one in aligned])
    rank_anova = contrast_anova(ranked, sizes)
    checks = _aligned_checks(aligned, sizes)
    rows = []
    for index, effect in enumerate(effects(factors)):
        numbers = {key: float(value[index]) if np.ndim(value) else float(value)
                   for key, value in rank_anova[effect].items()}
        row = effect_row(factors, effect, n=n, numbers=numbers,
                         zero=ZERO_FRACTION * float((ranked[index] ** 2).sum()),
                         source=CONTRAST_SOURCE)
        row.update(test="ART RM-ANOVA", aligned_check=checks[index],
                   method="aligned rank transform (Wobbrock et al. 2011, as ARTool): aligned "
                          "responses ranked with average ties, then " + row["method"])
        rows.append(row)
    return tidy(rows)


def _aligned(cube: np.ndarray) -> np.ndarray:
    """The aligned responses of every effect (effects × the shape of ``cube``): the residual of
    the cell-means model plus the effect's estimate, by inclusion–exclusion over the means of
    the effect's factor subsets (``cube``: subjects × levels of each factor)."""
    factor_axes = range(1, cube.ndim)
    means: dict[tuple[int, ...], np.ndarray] = {}
    for subset in [(), *effects(factor_axes)]:
        # The mean over subjects and the factors outside the subset, at every observation.
        averaged = (0, *(axis for axis in factor_axes if axis - 1 not in subset))
        means[subset] = cube.mean(axis=averaged, keepdims=True)
    residual = cube - means[tuple(range(cube.ndim - 1))]
    aligned = []
    for effect in effects(factor_axes):
        estimate = np.zeros_like(cube)
        for subset in [(), *[e for e in effects(factor_axes) if set(e) <= set(effect)]]:
            estimate = estimate + (-1) ** (len(effect) - len(subset)) * means[subset]
        aligned.append(residual + estimate)
    return np.stack(aligned)


def _aligned_checks(aligned: np.ndarray, sizes: list[int]) -> list[float]:
    """Per effect, the largest |F| of the other effects in the ANOVA of its aligned responses
    (``aligned``: effects × subjects × cells); NaN when there is no other effect.

    An effect whose error sum of squares is rounding dust gets F = 0 when its own is dust too
    (0/0: nothing left, as the check wants) and inf otherwise (a failed alignment)."""
    every = effects(sizes)
    if len(every) == 1:
        return [math.nan]
    anova = contrast_anova(aligned, sizes)
    zero = ZERO_FRACTION * (aligned ** 2).sum(axis=(-2, -1))
    checks = []
    for index, effect in enumerate(every):
        largest = math.nan
        for other in every:
            if other == effect:
                continue
            part = anova[other]
            f_value = float(part["F"][index])
            if part["ss_error"][index] <= zero[index]:
                f_value = 0.0 if part["ss"][index] <= zero[index] else math.inf
            largest = abs(f_value) if math.isnan(largest) else max(largest, abs(f_value))
        checks.append(largest)
    return checks
