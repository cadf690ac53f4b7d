"""Repeated-measures ANOVA and paired pairwise comparisons, long-format pandas in, tidy out.

- :func:`rm_anova`: one to three within-subject factors; F, df and p from statsmodels'
  ``AnovaRM``; generalised eta squared, Greenhouse–Geisser and Huynh–Feldt epsilon and Mauchly's
  test from pingouin (``rm_anova``, ``epsilon``, ``sphericity``) for designs of up to two
  factors, from the covariance of orthonormal contrasts for the three-way case pingouin lacks.
- :func:`effect_row`: one effect's row of such a table from its numbers, which the aligned rank
  transform (:mod:`realpen.stats.art`) shares.
- :func:`pairwise`: every pair of levels of one factor, paired t (pingouin) or Wilcoxon
  signed-rank (:func:`realpen.stats.nonparametric.wilcoxon`), Bonferroni or Holm adjusted
  (:mod:`realpen.stats.multiplicity`).

Both take a long-format DataFrame with one row per subject × cell and refuse anything else with
one line naming the subject and the cell (:class:`realpen.errors.ParameterError`). pingouin and
statsmodels are imported by the functions that call them, not with the module: pingouin brings
pyplot, seaborn and xarray (0.9 s of CPU after pandas and scipy), statsmodels' AnovaRM a
formula parser (0.2 s).
"""

from __future__ import annotations

import itertools
import math
import warnings

import numpy as np
import pandas as pd
import scipy.stats

from realpen.checks import require_choice
from realpen.errors import ParameterError
from realpen.stats.contrasts import ZERO_FRACTION, anovarm_f, contrast_anova, effect_name, effects
from realpen.stats.long import MAX_FACTORS, balanced_wide, factor_list, safe_long
from realpen.stats.multiplicity import LIBRARY, adjusted_p
from realpen.stats.nonparametric import WILCOXON_METHODS, wilcoxon
from realpen.stats.results import TEST_COLUMNS, pair_label, tidy
from realpen.stats.results import test_row as _result_row  # pytest would collect "test_row"

__all__ = ["rm_anova", "rm_anova_table", "effect_row", "pairwise", "SPHERICITY_ALPHA", "ADJUSTMENTS",
           "CONTRAST_SOURCE", "LIBRARY_MAX_VALUES"]

SPHERICITY_ALPHA = 0.05
"""Mauchly's test at this level sets the ``sphericity`` column (True: not rejected)."""
ADJUSTMENTS = ("bonferroni", "holm", "none")
"""The multiplicity adjustments :func:`pairwise` offers."""
CONTRAST_SOURCE = ("F, df and p (each effect against its own effect × subject error, as "
                   "statsmodels AnovaRM), generalised eta squared, Greenhouse-Geisser and "
                   "Huynh-Feldt (Lecoutre) epsilon and Mauchly's test, all from orthonormal "
                   "contrasts")
"""``method`` of an ANOVA whose every number comes from :func:`realpen.stats.contrasts.contrast_anova`."""
LIBRARY_MAX_VALUES = 2048
"""The most values (subjects × cells) :func:`rm_anova` refits with statsmodels and pingouin.

statsmodels' AnovaRM solves a least-squares problem with a column for every subject × effect,
so its time grows with the cube of the subjects: 2 s for 200 subjects of 9 cells, about 4 min
for 1,000. Above this many values every number comes from the closed-form sums of squares of
orthonormal contrasts (:func:`realpen.stats.contrasts.contrast_anova`, milliseconds at any
size), which the tests check agree with the libraries within 1e-9 relative; ``method`` names
the source either way."""


# --- sphericity and effect sizes from pingouin -----------------------------------------------

def _pingouin_sphericity(long: pd.DataFrame, n_factors: int) -> dict[tuple[int, ...], dict[str, float]]:
    """ges, ε_GG, Mauchly from pingouin.rm_anova and ε_HF from pingouin.epsilon (≤ 2 factors)."""
    import pingouin as pg

    within = [f"f{j}" for j in range(n_factors)]
    with warnings.catch_warnings(), np.errstate(divide="ignore", invalid="ignore"):
        # pingouin 0.7 calls DataFrame.dropna(inplace=True), deprecated in pandas 3.1: its noise,
        # not the user's business.
        warnings.filterwarnings("ignore", message="The inplace keyword", category=DeprecationWarning)
        table = pg.rm_anova(long, dv="y", within=within if n_factors > 1 else within[0], subject="s",
                            correction=True, effsize="ng2")
        hf = {effect: float(pg.epsilon(long, dv="y", subject="s", correction="hf",
                                       within=[within[j] for j in effect] if len(effect) > 1
                                       else within[effect[0]]))
              for effect in effects(within)}
    table = table.set_index(table["Source"].astype(str).str.replace(" * ", ":", regex=False))
    out = {}
    for effect in effects(range(n_factors)):
        name = ":".join(within[j] for j in effect)
        row = table.loc[name]
        # pingouin drops all-NaN columns (data without variation), hence .get.
        out[effect] = {"ges": float(row.get("ng2", math.nan)), "eps_gg": float(row.get("eps", math.nan)),
                       "eps_hf": hf[effect],
                       "mauchly_w": float(row.get("W_spher", math.nan)),
                       "p_mauchly": float(row.get("p_spher", math.nan))}
    return out


# --- public ---------------------------------------------------------------------------------

def rm_anova(data: pd.DataFrame, *, dv: str, within: str | list[str], subject: str) -> pd.DataFrame:
    """Repeated-measures ANOVA with one to three within-subject factors.

    F, df and p come from :class:`statsmodels.stats.anova.AnovaRM` (the univariate test, each
    effect against its own effect × subject error). Generalised eta squared (``ges``; Olejnik &
    Algina 2003, as R's ez and afex: SS_effect / (SS_effect + SS_subjects + all error SS)),
    Greenhouse–Geisser ε and Mauchly's test come from :func:`pingouin.rm_anova`, Huynh–Feldt ε
    (with Lecoutre's correction, as car/afex, capped at 1) from :func:`pingouin.epsilon`. With
    three factors (which pingouin does not handle) all of these come from the covariance of the
    effect's orthonormal contrasts (Kronecker products of Helmert contrasts): ε_GG =
    tr(S)² / (d·tr(S²)) (Greenhouse & Geisser 1959), ε_HF as above (Huynh & Feldt 1976),
    Mauchly's W = det(S) / (tr(S)/d)^d with R's chi-square approximation (Mauchly 1940).

    Above :data:`LIBRARY_MAX_VALUES` values (subjects × cells) the libraries' refits would take
    minutes, and every number comes from the contrasts instead, as for three factors (the same
    numbers within 1e-9 relative; ``method`` says which source gave them).

    An effect with one degree of freedom (a factor of 2 levels) has sphericity trivially: ε = 1,
    ``mauchly_w`` and ``p_mauchly`` are NaN and ``p_gg`` = ``p_hf`` = ``p``.

    An effect without error variance (every subject shows exactly the same differences) gets
    F = inf and p = 0; one without any variance at all F = p = NaN; both with NaN ε and
    Mauchly, and ``method`` says so (the libraries would return rounding noise there).

    Args:
        data: long format, exactly one row per subject × cell (average repetitions first).
        dv: the dependent variable's column (numeric, any unit).
        within: a factor's column or a list of 1–3 (interactions are named ``"A:B"``).
        subject: the subject (participant) column.

    Returns:
        One row per effect (main effects first, then interactions): :data:`TEST_COLUMNS`
        (test ``"RM-ANOVA"``, statistic ``F``, effect size ``ges``, ``p`` uncorrected), then
        ``effect``, ``eps_gg``, ``eps_hf``, ``p_gg``, ``p_hf``, ``mauchly_w``, ``p_mauchly`` and
        ``sphericity`` (Mauchly not rejected at :data:`SPHERICITY_ALPHA`).

    Raises:
        ParameterError: a missing column, a factor with one level, fewer than 2 subjects, a
            subject missing a cell or having several values in one (names them).

    References:
        Greenhouse, S. W., & Geisser, S. (1959). On methods in the analysis of profile data.
        Psychometrika, 24, 95–112. https://doi.org/10.1007/BF02289823

        Huynh, H., & Feldt, L. S. (1976). Estimation of the Box correction for degrees of
        freedom from sample data in randomized block and split-plot designs. Journal of
        Educational Statistics, 1(1), 69–82. https://doi.org/10.3102/10769986001001069

        Lecoutre, B. (1991). A correction for the ε̃ approximate test in repeated measures
        designs with two or more independent groups. Journal of Educational Statistics, 16(4),
        371–372. https://doi.org/10.3102/10769986016004371

        Mauchly, J. W. (1940). Significance test for sphericity of a normal n-variate
        distribution. The Annals of Mathematical Statistics, 11(2), 204–209.
        https://doi.org/10.1214/aoms/1177731915

        Olejnik, S., & Algina, J. (2003). Generalized eta and omega squared statistics.
        Psychological Methods, 8(4), 434–447. https://doi.org/10.1037/1082-989X.8.4.434

    Examples:
        >>> import pandas as pd
        >>> from realpen.stats.anova import rm_anova
        >>> data = pd.DataFrame({"subject": [1, 1, 1, 2, 2, 2, 3, 3, 3, 4, 4, 4],
        ...                      "pen": ["a", "b", "c"] * 4,
        ...                      "score": [3, 5, 6, 2, 4, 4, 4, 6, 7, 3, 3, 5]})
        >>> row = rm_anova(data, dv="score", within="pen", subject="subject").iloc[0]
        >>> print(f"{row.effect}: F({row.df1:.0f}, {row.df2:.0f}) = {row.statistic:.2f}, p = {row.p:.4f}")
        pen: F(2, 6) = 19.00, p = 0.0025
        >>> print(f"ges = {row.effect_size:.3f}, eps_gg = {row.eps_gg:.3f}, p_gg = {row.p_gg:.4f}")
        ges = 0.514, eps_gg = 0.750, p_gg = 0.0074
    """
    return rm_anova_table(data, dv=dv, within=within, subject=subject, with_pingouin=None)


def rm_anova_table(data: pd.DataFrame, *, dv: str, within: str | list[str], subject: str,
                   with_pingouin: bool | None) -> pd.DataFrame:
    """:func:`rm_anova`; with ``with_pingouin`` false every number (F and p too) comes from
    :func:`realpen.stats.contrasts.contrast_anova` for any number of factors, without the
    libraries' refits (the tests check it agrees with statsmodels and pingouin); None: the
    libraries up to :data:`LIBRARY_MAX_VALUES` values, the contrasts above."""
    factors = factor_list(within)
    wide = balanced_wide(data, dv=dv, within=factors, subject=subject)
    y = wide.to_numpy(dtype=float)
    n = len(wide)
    if with_pingouin is None:
        with_pingouin = y.size <= LIBRARY_MAX_VALUES
    parts = contrast_anova(y, [len(level) for level in wide.columns.levels])
    zero = ZERO_FRACTION * float((y ** 2).sum())
    widest = int(np.prod([len(level) - 1 for level in wide.columns.levels]))
    if not with_pingouin:
        return tidy([effect_row(factors, effect, n=n, numbers=_floats(parts[effect]),
                                zero=zero, source=CONTRAST_SOURCE) for effect in effects(factors)])
    long = safe_long(wide)
    with np.errstate(divide="ignore", invalid="ignore"):
        # Without within-subject variation F is 0/0 or x/0; the rows below say which.
        f_table = anovarm_f(long, len(factors))
    # pingouin's Mauchly divides by zero when subjects are fewer than an effect's contrasts + 1;
    # the contrast path gives NaN there (Mauchly is undefined) and the same numbers otherwise.
    if len(factors) <= 2 and n - 1 >= widest:
        extra = _pingouin_sphericity(long, len(factors))
        source = ("statsmodels AnovaRM (F, df, p); pingouin.rm_anova (generalised eta squared, "
                  "Greenhouse-Geisser epsilon, Mauchly); pingouin.epsilon (Huynh-Feldt with "
                  "Lecoutre's correction, capped at 1)")
    else:
        extra = {effect: _floats(parts[effect]) for effect in effects(factors)}
        source = ("statsmodels AnovaRM (F, df, p); generalised eta squared, Greenhouse-Geisser and "
                  "Huynh-Feldt (Lecoutre) epsilon and Mauchly's test from the covariance of "
                  "orthonormal contrasts")
    rows = []
    for effect in effects(factors):
        f_value, df1, df2, p = f_table[effect]
        numbers = {**extra[effect], "F": f_value, "df1": df1, "df2": df2, "p": p,
                   "ss": float(parts[effect]["ss"]), "ss_error": float(parts[effect]["ss_error"])}
        rows.append(effect_row(factors, effect, n=n, numbers=numbers, zero=zero, source=source))
    return tidy(rows)


def _floats(entry: dict[str, np.ndarray]) -> dict[str, float]:
    return {key: float(value) for key, value in entry.items()}


def effect_row(factors: list[str], effect: tuple[int, ...], *, n: int, numbers: dict[str, float],
               zero: float, source: str) -> dict:
    """One effect's row of a repeated-measures ANOVA table (:func:`rm_anova`'s columns).

    Args:
        factors: the factors' names; ``effect`` their positions (:func:`realpen.stats.contrasts.effects`).
        n: the number of subjects.
        numbers: the effect's ``F``, ``df1``, ``df2``, ``p``, ``ges``, ``eps_gg``, ``eps_hf``,
            ``mauchly_w``, ``p_mauchly``, ``ss`` and ``ss_error`` (sums of squares in the
            squared unit of the values).
        zero: sums of squares at or below this are rounding dust (same unit): without error
            variance F is inf (p = 0), without any variance NaN, both with NaN ε and Mauchly,
            and ``method`` says so.
        source: how the numbers were computed, the start of ``method``.
    """
    f_value, df1, df2, p = (numbers[key] for key in ("F", "df1", "df2", "p"))
    name = effect_name(factors, effect)
    if numbers["ss_error"] <= zero:
        # Floating-point dust, not data: an F of 1e30 or 0.18 from 1e-30/1e-29 would mislead.
        no_effect = numbers["ss"] <= zero
        f_value, p = (math.nan, math.nan) if no_effect else (math.inf, 0.0)
        return _result_row("RM-ANOVA", "F", f_value, p, n=n, df1=df1, df2=df2,
                           method=source + ("; no within-subject variation: F undefined"
                                            if no_effect else "; no error variance: F infinite")
                           + "; epsilon and Mauchly undefined",
                           effect_size_name="ges", effect_size=numbers["ges"], effect=name,
                           eps_gg=math.nan, eps_hf=math.nan, p_gg=p, p_hf=p, mauchly_w=math.nan,
                           p_mauchly=math.nan, sphericity=False)
    method = source
    if df1 <= 1:
        eps_gg = eps_hf = 1.0
        mauchly_w = p_mauchly = math.nan
        sphericity = True
        method += "; 2 levels: sphericity holds trivially (epsilon = 1)"
    else:
        eps_gg, eps_hf = numbers["eps_gg"], numbers["eps_hf"]
        mauchly_w, p_mauchly = numbers["mauchly_w"], numbers["p_mauchly"]
        if n - 1 < df1:
            # Mauchly's test needs the contrasts' covariance to have full rank.
            mauchly_w = p_mauchly = math.nan
            method += (f"; Mauchly's test untestable: {n} subjects give n - 1 < {df1:g} "
                       f"contrasts")
        sphericity = bool(p_mauchly > SPHERICITY_ALPHA)  # False when untestable (NaN)
    p_gg = float(scipy.stats.f.sf(f_value, df1 * eps_gg, df2 * eps_gg))
    p_hf = float(scipy.stats.f.sf(f_value, df1 * eps_hf, df2 * eps_hf))
    return _result_row("RM-ANOVA", "F", f_value, p, n=n, method=method, df1=df1, df2=df2,
                       effect_size_name="ges", effect_size=numbers["ges"], effect=name,
                       eps_gg=eps_gg, eps_hf=eps_hf, p_gg=p_gg, p_hf=p_hf, mauchly_w=mauchly_w,
                       p_mauchly=p_mauchly, sphericity=sphericity)


def pairwise(data: pd.DataFrame, *, dv: str, within: str, subject: str, test: str = "t",
             adjust: str = "holm", wilcoxon_method: str = "exact",
             average_over: list[str] | None = None) -> pd.DataFrame:
    """Paired comparisons of every pair of levels of one within-subject factor.

    Each subject contributes one value per level: its mean over the factors named in
    ``average_over`` (the data must then hold every subject × level × those factors' cell once),
    or its single value. ``test="t"``: paired t by :func:`pingouin.ttest` (``paired=True``), with
    Cohen's d_z = mean / SD of the differences (Lakens 2013); ``test="wilcoxon"``:
    :func:`realpen.stats.nonparametric.wilcoxon` with ``wilcoxon_method``. The p-values of all
    pairs are adjusted together by :func:`realpen.stats.multiplicity.adjusted_p`
    (``bonferroni``, ``holm``; ``none`` keeps them); a pair that cannot be tested (every
    difference zero) has NaN p and does not count in the family.

    Args:
        data: long format.
        dv: the dependent variable's column (numeric).
        within: the factor whose levels are compared (levels in Categorical order, else sorted).
        subject: the subject column.
        test: ``"t"`` or ``"wilcoxon"``.
        adjust: ``"bonferroni"``, ``"holm"`` or ``"none"``.
        wilcoxon_method: ``"exact"``, ``"r"`` or ``"spss"`` (see
            :func:`realpen.stats.nonparametric.wilcoxon`).
        average_over: the other within factors, averaged within each subject.

    Returns:
        One row per pair: :data:`TEST_COLUMNS`, then ``effect`` (``"a vs b"``:
        :func:`realpen.stats.results.pair_label`), ``a``, ``b``,
        ``p_adjusted``, ``adjust``, then the test's own columns (``mean_diff``, the mean of
        a − b, for t; the Wilcoxon columns for Wilcoxon). The statistic's sign is that of a − b.

    References:
        Holm, S. (1979). A simple sequentially rejective multiple test procedure. Scandinavian
        Journal of Statistics, 6(2), 65–70. https://www.jstor.org/stable/4615733

        Lakens, D. (2013). Calculating and reporting effect sizes to facilitate cumulative
        science: a practical primer for t-tests and ANOVAs. Frontiers in Psychology, 4, 863.
        https://doi.org/10.3389/fpsyg.2013.00863

    Examples:
        >>> import pandas as pd
        >>> from realpen.stats.anova import pairwise
        >>> data = pd.DataFrame({"subject": [1, 1, 1, 2, 2, 2, 3, 3, 3, 4, 4, 4],
        ...                      "pen": ["a", "b", "c"] * 4,
        ...                      "score": [3, 5, 6, 2, 4, 4, 4, 6, 7, 3, 3, 5]})
        >>> table = pairwise(data, dv="score", within="pen", subject="subject", adjust="bonferroni")
        >>> for row in table.itertuples():
        ...     print(f"{row.effect}: t = {row.statistic:.2f}, p_bonferroni = {row.p_adjusted:.3f}")
        a vs b: t = -3.00, p_bonferroni = 0.173
        a vs c: t = -8.66, p_bonferroni = 0.010
        b vs c: t = -2.45, p_bonferroni = 0.275
    """
    if not isinstance(within, str):
        raise ParameterError("within", f"must be one column name, got {within!r}")
    require_choice("test", test, ("t", "wilcoxon"))
    require_choice("adjust", adjust, ADJUSTMENTS)
    require_choice("wilcoxon_method", wilcoxon_method, WILCOXON_METHODS)
    others = [] if average_over is None else factor_list(average_over, most=MAX_FACTORS)
    if within in others:
        raise ParameterError("average_over", f"must not contain the compared factor {within!r}")
    wide = balanced_wide(data, dv=dv, within=[within, *others], subject=subject)
    means = wide.T.groupby(level=0, sort=False).mean().T
    levels = list(means.columns)
    pairs = list(itertools.combinations(levels, 2))
    averaged = f" on each subject's mean over {', '.join(others)}" if others else ""
    if test == "t":
        import pingouin as pg
    rows = []
    for a, b in pairs:
        x, y = means[a].to_numpy(), means[b].to_numpy()
        name = pair_label(a, b)
        diff = x - y
        if test == "t":
            with warnings.catch_warnings(), np.errstate(divide="ignore", invalid="ignore"):
                # Identical columns: pingouin warns and gives NaN, which the row reports.
                warnings.filterwarnings("ignore", message="x and y are equals", category=UserWarning)
                result = pg.ttest(x, y, paired=True).iloc[0]
            sd = float(np.std(diff, ddof=1))
            dz = float(np.mean(diff) / sd) if sd > 0 else math.nan
            row = _result_row("paired t", "t", float(result["T"]), float(result["p_val"]), n=len(x),
                              method=f"pingouin.ttest(paired=True){averaged}; cohen_dz = mean/SD of "
                                     f"differences",
                              df1=float(result["dof"]), effect_size_name="cohen_dz", effect_size=dz,
                              effect=name, a=a, b=b, p_adjusted=math.nan, adjust=adjust,
                              mean_diff=float(np.mean(diff)))
        elif not diff.any():
            # One pair without any difference must not sink the other pairs' comparisons.
            row = _result_row("Wilcoxon signed-rank", "T", math.nan, math.nan, n=len(x),
                              method=f"{wilcoxon_method}: every difference is zero, nothing to test",
                              effect_size_name="r", effect=name, a=a, b=b, p_adjusted=math.nan,
                              adjust=adjust, w_plus=math.nan, z=math.nan, n_nonzero=0, ties=False,
                              zeros=len(x))
        else:
            result = wilcoxon(x, y, method=wilcoxon_method).iloc[0].to_dict()
            extras = {key: value for key, value in result.items() if key not in TEST_COLUMNS}
            row = _result_row(result["test"], result["statistic_name"], result["statistic"], result["p"],
                              n=result["n"], method=result["method"] + averaged, df1=result["df1"],
                              df2=result["df2"], effect_size_name=result["effect_size_name"],
                              effect_size=result["effect_size"], effect=name, a=a, b=b,
                              p_adjusted=math.nan, adjust=adjust, **extras)
        rows.append(row)
    p_values = np.array([row["p"] for row in rows])
    tested = np.isfinite(p_values)
    adjusted = adjusted_p(p_values, adjust)
    if adjust == "none":
        family = "; no multiplicity adjustment"
    else:
        family = (f"; {'Bonferroni' if adjust == 'bonferroni' else 'Holm'} over the "
                  f"{int(tested.sum())} testable of {len(rows)} pairs ({LIBRARY})")
    for row, value in zip(rows, adjusted):
        row["p_adjusted"] = float(value)
        row["method"] += family
    return tidy(rows)
