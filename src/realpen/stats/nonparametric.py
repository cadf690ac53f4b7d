"""Rank tests for within-subject designs, long-format pandas in, tidy DataFrame out.

- :func:`friedman`: Friedman's test (tie-corrected chi-square) with Kendall's W.
- :func:`wilcoxon` / :func:`wilcoxon_long`: the paired signed-rank test with the p-value of a
  named tool (``exact``, ``r``, ``spss``), because on tied small samples they differ.

The aligned rank transform for factorial designs is :mod:`realpen.stats.art`.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import scipy.stats

from realpen.checks import require_choice
from realpen.errors import ParameterError
from realpen.stats.long import balanced_wide, shown_level
from realpen.stats.results import TEST_COLUMNS, pair_label, tidy
from realpen.stats.results import test_row as _result_row  # pytest would collect "test_row"

__all__ = ["friedman", "wilcoxon", "wilcoxon_long", "WILCOXON_METHODS",
           "EXACT_ENUMERATION_MAX", "MONTE_CARLO_RESAMPLES", "MONTE_CARLO_SEED", "R_EXACT_BELOW"]

WILCOXON_METHODS = ("exact", "r", "spss")
"""The p-values :func:`wilcoxon` offers, by the tool whose habit they repeat."""
EXACT_ENUMERATION_MAX = 20
"""With ties or zeros, ``method="exact"`` uses all 2^n sign flips up to this many non-zero
differences (about a million), and samples them above."""
MONTE_CARLO_RESAMPLES = 100_000
"""Sign flips drawn when there are too many to enumerate."""
MONTE_CARLO_SEED = 0
"""The seed of those draws, so a report is reproducible."""
R_EXACT_BELOW = 50
"""R's ``wilcox.test`` computes the exact p-value below this many non-zero differences."""


# --- Friedman -------------------------------------------------------------------------------

def friedman(data: pd.DataFrame, *, dv: str, within: str, subject: str) -> pd.DataFrame:
    """Friedman's rank test of one within-subject factor, with Kendall's W.

    The chi-square is tie-corrected, computed by :func:`scipy.stats.friedmanchisquare`
    (:func:`pingouin.friedman` for 2 levels, which scipy refuses; they agree). Kendall's W is
    chi2 / (n (k − 1)), the tie-corrected coefficient of concordance as pingouin gives it.

    Args:
        data: long format, exactly one row per subject (block) × level.
        dv: the response's column (numeric, e.g. a Likert rating in points).
        within: the factor's column (k ≥ 2 levels).
        subject: the block's column (n ≥ 2 blocks).

    Returns:
        One row: :data:`TEST_COLUMNS` (test ``"Friedman"``, statistic ``chi2``, ``df1`` = k − 1,
        effect size ``kendall_w``, ``n`` blocks), then ``chi2_uncorrected`` (no tie correction)
        and ``k``. When every block is tied throughout, chi2, p and W are NaN (no ranking
        information; R's ``friedman.test`` gives NaN too) and ``method`` says so.

    Raises:
        ParameterError: fewer than 2 levels or blocks, a missing column, or a subject missing a
            level or having several values at one (names the subject and level).

    References:
        Friedman, M. (1937). The use of ranks to avoid the assumption of normality implicit in
        the analysis of variance. Journal of the American Statistical Association, 32(200),
        675–701. https://doi.org/10.1080/01621459.1937.10503522

        Kendall, M. G., & Babington Smith, B. (1939). The problem of m rankings. The Annals of
        Mathematical Statistics, 10(3), 275–287. https://doi.org/10.1214/aoms/1177732186

    Examples:
        >>> import pandas as pd
        >>> from realpen.stats.nonparametric import friedman
        >>> data = pd.DataFrame({"subject": [1, 1, 1, 2, 2, 2, 3, 3, 3, 4, 4, 4],
        ...                      "condition": ["A", "B", "C"] * 4,
        ...                      "rating": [3, 5, 6, 2, 4, 4, 4, 6, 7, 3, 3, 5]})
        >>> row = friedman(data, dv="rating", within="condition", subject="subject").iloc[0]
        >>> print(f"chi2({row.df1:.0f}) = {row.statistic:.3f}, p = {row.p:.4f}, W = {row.effect_size:.3f}")
        chi2(2) = 7.000, p = 0.0302, W = 0.875
    """
    if not isinstance(within, str):
        raise ParameterError("within", f"must be one column name, got {within!r}")
    wide = balanced_wide(data, dv=dv, within=[within], subject=subject)
    values = wide.to_numpy(dtype=float)
    n, k = values.shape
    ranks = scipy.stats.rankdata(values, axis=1)
    chi2_uncorrected = float(12 / (n * k * (k + 1)) * (ranks.sum(axis=0) ** 2).sum() - 3 * n * (k + 1))
    all_tied = bool(np.all(np.ptp(values, axis=1) == 0))
    if all_tied:
        chi2 = p = math.nan
        method = "every block is tied throughout: no ranking information, chi2 undefined"
    elif k >= 3:
        result = scipy.stats.friedmanchisquare(*values.T)
        chi2, p = float(result.statistic), float(result.pvalue)
        method = "scipy.stats.friedmanchisquare (tie-corrected chi2); kendall_w = chi2 / (n (k - 1))"
    else:
        import pingouin as pg  # only here: it brings pyplot, seaborn and xarray with it

        frame = pd.DataFrame(values).rename_axis(index="block", columns="level").stack().rename("y")
        result = pg.friedman(frame.reset_index(), dv="y", within="level", subject="block").iloc[0]
        chi2, p = float(result["Q"]), float(result["p_unc"])
        method = ("pingouin.friedman (tie-corrected chi2; scipy.stats.friedmanchisquare needs 3 "
                  "levels); kendall_w = chi2 / (n (k - 1))")
    return tidy([_result_row("Friedman", "chi2", chi2, p, n=n, method=method, df1=k - 1,
                             effect_size_name="kendall_w", effect_size=chi2 / (n * (k - 1)),
                             chi2_uncorrected=chi2_uncorrected, k=k)])


# --- Wilcoxon signed-rank -------------------------------------------------------------------

def _as_vector(parameter: str, values: object) -> np.ndarray:
    try:
        array = np.asarray(values, dtype=float)
    except (TypeError, ValueError):
        raise ParameterError(parameter, "must be numbers") from None
    if array.ndim != 1:
        raise ParameterError(parameter, f"must be one-dimensional, got shape {array.shape}")
    bad = ~np.isfinite(array)
    if bad.any():
        raise ParameterError(parameter, f"has a missing or non-finite value at index {int(np.argmax(bad))}")
    return array


def _signed_rank_normal(d: np.ndarray, *, continuity: bool) -> tuple[float, float]:
    """Normal approximation of the signed-rank test on non-zero differences ``d``: (z, p), z
    from W+ (positive when the differences are mostly positive), tie-corrected variance, with or
    without the continuity correction; by scipy.stats.wilcoxon(method="asymptotic")."""
    result = scipy.stats.wilcoxon(d, method="asymptotic", correction=continuity)
    ranks = scipy.stats.rankdata(np.abs(d))
    w_plus = ranks[d > 0].sum()
    sign = float(np.sign(w_plus - len(d) * (len(d) + 1) / 4))
    return sign * abs(float(result.zstatistic)) + 0.0, float(result.pvalue)


def _exact_sign_flip_p(ranks: np.ndarray, w_plus: float) -> float:
    """Two-sided p of W+ over all 2^m sign flips of the fixed ranks (the exact conditional null
    with ties), counted by convolution rather than listed.

    Average ranks are multiples of 1/2, so the 2^m sums 2·W+ are integers and their counts
    follow from multiplying the generating polynomials ∏(1 + t^(2 r_i)); the p is then
    2·min(P(W+ ≤ w), P(W+ ≥ w)) capped at 1, exactly what scipy.stats.wilcoxon computes with a
    PermutationMethod that enumerates every flip (tests compare them), in microseconds instead
    of scipy's seconds (it re-ranks each flip).
    """
    doubled = np.rint(2 * ranks).astype(np.int64)
    counts = np.zeros(int(doubled.sum()) + 1)
    counts[0] = 1.0
    for step in doubled:
        shifted = np.zeros_like(counts)
        shifted[step:] = counts[:len(counts) - step]
        counts = counts + shifted
    observed = int(np.rint(2 * w_plus))
    total = counts.sum()
    below, above = counts[:observed + 1].sum() / total, counts[observed:].sum() / total
    return float(min(1.0, 2 * min(below, above)))


def _monte_carlo_sign_flip_p(nonzero: np.ndarray, ranks: np.ndarray) -> float:
    """Two-sided p of W+ from :data:`MONTE_CARLO_RESAMPLES` seeded random sign flips: the flips
    and the p of :func:`scipy.stats.permutation_test` (as scipy.stats.wilcoxon's
    PermutationMethod), drawn and counted in a way that scales (:func:`_scipy_flips_p`).

    scipy draws each flip as a shuffle of the pair (d, −d) and gathers every flipped sample
    before summing: seconds per test at a thousand differences. The same shuffles are the low
    bits of the generator's 32-bit draws, so W+ of every flip is one matrix product of those
    bits with the ranks (sums of half-integers: exact in any order). Checked once per process
    against scipy itself (:func:`_fast_flips_agree`); where they differ (another numpy draws
    otherwise) scipy computes the p."""
    if _fast_flips_agree():
        return _fast_flips_p(nonzero, ranks)
    return _scipy_flips_p(nonzero, ranks)


def _scipy_flips_p(nonzero: np.ndarray, ranks: np.ndarray, resamples: int = MONTE_CARLO_RESAMPLES
                   ) -> float:
    """The p of :func:`_monte_carlo_sign_flip_p` by :func:`scipy.stats.permutation_test`."""
    def w_plus(d: np.ndarray, axis: int = -1) -> np.ndarray:
        return np.sum(np.where(d > 0, ranks, 0.0), axis=axis)

    result = scipy.stats.permutation_test((nonzero,), w_plus, permutation_type="samples",
                                          vectorized=True, n_resamples=resamples,
                                          batch=_FLIP_BATCH, alternative="two-sided",
                                          rng=np.random.default_rng(MONTE_CARLO_SEED))
    return float(result.pvalue)


_FLIP_BATCH = 10_000
_FLIP_DRAWS = 2**22


def _fast_flips_p(nonzero: np.ndarray, ranks: np.ndarray, resamples: int = MONTE_CARLO_RESAMPLES
                  ) -> float:
    """:func:`_scipy_flips_p` without the gathering: scipy's shuffle of each pair keeps d where
    the generator's 32-bit draw is odd (numpy's bounded draw of 0..1 is its low bit), so W+ of
    a flip is the sum of the ranks whose sign the draw keeps positive."""
    rng = np.random.default_rng(MONTE_CARLO_SEED)
    positive = nonzero > 0
    observed = float(ranks[positive].sum())
    # W+ = Σ_positive r·bit + Σ_negative r·(1 − bit): one product of the bits with ±r. Every
    # partial sum is a multiple of 1/2 below Σr = m(m + 1)/2, exact in float32 (faster) while
    # twice that fits its 24-bit significand.
    exact32 = len(ranks) * (len(ranks) + 1) < 2**24
    dtype = np.float32 if exact32 else np.float64
    weights = np.where(positive, ranks, -ranks).astype(dtype)
    negative_sum = float(ranks[~positive].sum())
    null = np.empty(resamples)
    # Flip k uses the stream's draws k·m … (k + 1)·m − 1 however they are batched; batches of
    # about 4 M draws keep memory flat at any m.
    batch = max(1, min(_FLIP_BATCH, _FLIP_DRAWS // len(ranks)))
    for start in range(0, resamples, batch):
        size = min(batch, resamples - start)
        draws = rng.integers(0, 2**32, size=(size, len(ranks)), dtype=np.uint32)
        bits = (draws & 1).astype(dtype)
        null[start:start + size] = (bits @ weights).astype(float) + negative_sum
    gamma = abs(np.finfo(float).eps * 100 * observed)  # scipy's tolerance for equal sums
    less = (np.count_nonzero(null <= observed + gamma) + 1) / (resamples + 1)
    greater = (np.count_nonzero(null >= observed - gamma) + 1) / (resamples + 1)
    return float(np.clip(min(less, greater) * 2, 0.0, 1.0))


_AGREEMENT: list[bool] = []


def _fast_flips_agree() -> bool:
    """Whether :func:`_fast_flips_p` gives scipy's p (the same draws), tried once per process
    on 25 tied differences with 3,000 flips (milliseconds)."""
    if not _AGREEMENT:
        d = np.array([1, -2, 3, 1, -1, 2, 2, -3, 1, 1, -1, 4, 2, 1, -2, 1, 3, -1, 1, 2, -2, 1, 1,
                      -4, 2], dtype=float)
        ranks = scipy.stats.rankdata(np.abs(d))
        fast = [_fast_flips_p(d, ranks, resamples) for resamples in (3_000, 25_000)]
        slow = [_scipy_flips_p(d, ranks, resamples) for resamples in (3_000, 25_000)]
        _AGREEMENT.append(fast == slow)
    return _AGREEMENT[0]


def wilcoxon(x: object, y: object, *, method: str = "exact") -> pd.DataFrame:
    """Paired Wilcoxon signed-rank test of x − y, two-sided, with the p-value of a named tool.

    Zero differences are dropped (Wilcoxon's zero method, as R and SPSS do). The p-values:

    - ``"exact"``: without ties or zeros the exact null distribution
      (:func:`scipy.stats.wilcoxon`, ``method="exact"``); with them the exact conditional
      (permutation) distribution of the observed ranks over all 2^n sign flips for n ≤
      :data:`EXACT_ENUMERATION_MAX` non-zero differences (the distribution scipy's own default
      enumerates with a :class:`scipy.stats.PermutationMethod` for small samples; counted here
      by convolution, which gives the same p in microseconds instead of seconds) and a seeded
      Monte Carlo of :data:`MONTE_CARLO_RESAMPLES` flips above
      (:func:`scipy.stats.permutation_test`).
    - ``"r"``: R's ``wilcox.test`` default: exact without ties or zeros when n <
      :data:`R_EXACT_BELOW`, otherwise the normal approximation with continuity correction and
      tie-corrected variance (:func:`scipy.stats.wilcoxon`, ``method="asymptotic"``,
      ``correction=True``).
    - ``"spss"``: the normal approximation without continuity correction, tie-corrected
      variance, as SPSS and PSPP (:func:`scipy.stats.wilcoxon`, ``correction=False``).

    Args:
        x, y: paired values (same length, finite; any unit, e.g. rating points).
        method: ``"exact"``, ``"r"`` or ``"spss"``.

    Returns:
        One row: :data:`TEST_COLUMNS` (test ``"Wilcoxon signed-rank"``, statistic ``T`` =
        min(W+, W−), effect size ``r`` = z / √n (Rosenthal 1991) with z the normal z without
        continuity correction, positive when x > y; ``n`` the number of pairs before dropping
        zeros), then ``w_plus`` (R's V), ``z`` (that z), ``n_nonzero``, ``ties`` (tied
        non-zero |differences|) and ``zeros`` (their count).

    Raises:
        ParameterError: unequal lengths, a missing value, or no non-zero difference.

    References:
        Wilcoxon, F. (1945). Individual comparisons by ranking methods. Biometrics Bulletin,
        1(6), 80–83. https://doi.org/10.2307/3001968

        Rosenthal, R. (1991). Meta-analytic procedures for social research (rev. ed.). Sage.
        https://doi.org/10.4135/9781412984997

    Examples:
        >>> from realpen.stats.nonparametric import wilcoxon
        >>> x = [4, 3, 5, 3, 5, 3, 2, 5, 4, 4, 4, 3]
        >>> y = [2, 2, 1, 2, 3, 1, 2, 3, 2, 1, 1, 3]
        >>> for method in ("exact", "r", "spss"):
        ...     print(method, f"{wilcoxon(x, y, method=method).loc[0, 'p']:.4f}")
        exact 0.0020
        r 0.0052
        spss 0.0045
        >>> row = wilcoxon(x, y).iloc[0]
        >>> print(f"T = {row.statistic:g}, V = {row.w_plus:g}, r = {row.effect_size:.2f}")
        T = 0, V = 55, r = 0.82
    """
    require_choice("method", method, WILCOXON_METHODS)
    xs, ys = _as_vector("x", x), _as_vector("y", y)
    if len(xs) != len(ys):
        raise ParameterError("y", f"must pair with x: x has {len(xs)} values, y has {len(ys)}")
    difference = xs - ys
    nonzero = difference[difference != 0]
    zeros = len(difference) - len(nonzero)
    m = len(nonzero)
    if m < 1:
        raise ParameterError("y", f"every one of the {len(difference)} differences x - y is zero: "
                                  f"nothing to test")
    ranks = scipy.stats.rankdata(np.abs(nonzero))
    w_plus = float(ranks[nonzero > 0].sum())
    w_minus = float(ranks[nonzero < 0].sum())
    ties = bool(len(np.unique(np.abs(nonzero))) < m)
    z, p_normal = _signed_rank_normal(nonzero, continuity=False)
    exact_possible = not ties and zeros == 0
    about = f"zeros dropped ({zeros})" if zeros else "no zeros"
    about += ", tied |differences|" if ties else ", no ties"
    if method == "spss":
        p = p_normal
        how = ("normal approximation without continuity correction, tie-corrected variance "
               "(SPSS/PSPP style; scipy.stats.wilcoxon method='asymptotic', correction=False)")
    elif method == "r":
        if exact_possible and m < R_EXACT_BELOW:
            p = float(scipy.stats.wilcoxon(nonzero, method="exact").pvalue)
            how = (f"exact null distribution (R wilcox.test default: no ties or zeros, n < "
                   f"{R_EXACT_BELOW}; scipy.stats.wilcoxon method='exact')")
        else:
            p = _signed_rank_normal(nonzero, continuity=True)[1]
            how = ("normal approximation with continuity correction, tie-corrected variance "
                   "(R wilcox.test default; scipy.stats.wilcoxon method='asymptotic', correction=True)")
    elif exact_possible:
        p = float(scipy.stats.wilcoxon(nonzero, method="exact").pvalue)
        how = "exact null distribution (scipy.stats.wilcoxon method='exact')"
    elif m <= EXACT_ENUMERATION_MAX:
        p = _exact_sign_flip_p(ranks, w_plus)
        how = (f"exact conditional distribution: all 2^{m} sign flips of the observed ranks, "
               f"counted by convolution (the distribution scipy.stats.wilcoxon enumerates with a "
               f"PermutationMethod)")
    else:
        p = _monte_carlo_sign_flip_p(nonzero, ranks)
        how = (f"Monte Carlo conditional distribution: {MONTE_CARLO_RESAMPLES} random sign flips "
               f"(seed {MONTE_CARLO_SEED}) of the observed ranks, too many (2^{m}) to enumerate "
               f"(scipy.stats.permutation_test, as scipy.stats.wilcoxon's PermutationMethod)")
    method_text = f"{method}: {how}; {about}; r = z/sqrt(n) with z uncorrected"
    return tidy([_result_row("Wilcoxon signed-rank", "T", min(w_plus, w_minus), p, n=len(difference),
                             method=method_text, effect_size_name="r",
                             effect_size=z / math.sqrt(len(difference)), w_plus=w_plus, z=z,
                             n_nonzero=m, ties=ties, zeros=zeros)])


def wilcoxon_long(data: pd.DataFrame, *, dv: str, within: str, subject: str, a: object, b: object,
                  method: str = "exact") -> pd.DataFrame:
    """:func:`wilcoxon` of levels ``a`` versus ``b`` of ``within``, paired by subject.

    Args:
        data: long format; each subject has exactly one row at ``a`` and one at ``b`` (other
            levels are ignored).
        dv, within, subject: column names (``dv`` numeric).
        a, b: the two levels; the test is of a − b.
        method: as :func:`wilcoxon`.

    Returns:
        :func:`wilcoxon`'s row with ``effect`` (``"a vs b"``:
        :func:`realpen.stats.results.pair_label`), ``a`` and ``b`` first among its own
        columns.

    Raises:
        ParameterError: an unknown level, or a subject missing one of the two (names it).

    Examples:
        >>> import pandas as pd
        >>> from realpen.stats.nonparametric import wilcoxon_long
        >>> data = pd.DataFrame({"subject": [1, 1, 2, 2, 3, 3, 4, 4, 5, 5, 6, 6],
        ...                      "condition": ["D", "F"] * 6,
        ...                      "rating": [2, 4, 3, 5, 2, 5, 3, 4, 1, 3, 2, 5]})
        >>> row = wilcoxon_long(data, dv="rating", within="condition", subject="subject",
        ...                     a="D", b="F").iloc[0]
        >>> print(f"{row.effect}: T = {row.statistic:g}, p = {row.p:.4f}")
        D vs F: T = 0, p = 0.0312
    """
    require_choice("method", method, WILCOXON_METHODS)
    if not isinstance(within, str):
        raise ParameterError("within", f"must be one column name, got {within!r}")
    if isinstance(data, pd.DataFrame) and within in data.columns:
        for parameter, level in (("a", a), ("b", b)):
            if not (data[within] == level).any():
                raise ParameterError(parameter, f"no level {shown_level(level)} in column {within!r}")
        if a == b:
            raise ParameterError("b", f"must differ from a, both are {shown_level(a)}")
        data = data[data[within].isin([a, b])]
    wide = balanced_wide(data, dv=dv, within=[within], subject=subject)
    result = wilcoxon(wide[(a,)].to_numpy(), wide[(b,)].to_numpy(), method=method)
    row = result.iloc[0].to_dict()
    first = {key: row.pop(key) for key in list(row) if key in TEST_COLUMNS}
    return tidy([{**first, "effect": pair_label(a, b), "a": a, "b": b, **row}])
