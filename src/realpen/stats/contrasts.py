"""Orthonormal contrasts of a subjects × cells table: effects, F, sums of squares, sphericity.

What the repeated-measures ANOVA (:mod:`realpen.stats.anova`) and the aligned rank transform
(:mod:`realpen.stats.art`) share: the list of a design's effects and their names, statsmodels'
F per effect, and :func:`contrast_anova` — each effect's F, sums of squares,
Greenhouse–Geisser and Huynh–Feldt epsilon and Mauchly's test from the covariance of its
orthonormal contrasts, for many tables at once.

May import: numpy, pandas, scipy and statsmodels only (statsmodels inside :func:`anovarm_f`,
which only the ANOVA that names it as its source calls).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence

import numpy as np
import pandas as pd
import scipy.linalg
import scipy.stats

__all__ = ["ZERO_FRACTION", "effects", "effect_name", "anovarm_f", "contrast_anova",
           "contrast_decomposition"]

ZERO_FRACTION = 1e-24
"""Sums of squares below this fraction of Σy² are rounding dust (~1e-31 Σy²), i.e. zero."""


def effects(factors: Sequence[object]) -> list[tuple[int, ...]]:
    """Every main effect and interaction of ``factors`` as factor positions, main effects first.

    >>> effects(["modality", "pen"])
    [(0,), (1,), (0, 1)]
    """
    positions = range(len(factors))
    return [combo for size in range(1, len(factors) + 1) for combo in itertools.combinations(positions, size)]


def effect_name(factors: Sequence[str], effect: tuple[int, ...]) -> str:
    """An effect's name: its factors joined by ``:`` (``"modality:pen"``), as the tables say it.

    >>> effect_name(["modality", "pen"], (0, 1))
    'modality:pen'
    """
    return ":".join(factors[j] for j in effect)


def anovarm_f(long: pd.DataFrame, n_factors: int) -> dict[tuple[int, ...], tuple[float, ...]]:
    """statsmodels' AnovaRM of a :func:`realpen.stats.long.safe_long` frame with ``n_factors``
    factors: ``{effect: (F, df1, df2, p)}``, effects as :func:`effects` lists them."""
    from statsmodels.stats.anova import AnovaRM  # its formula parser: 0.2 s to import

    codes = [f"f{j}" for j in range(n_factors)]
    table = AnovaRM(long, depvar="y", subject="s", within=codes).fit().anova_table
    out = {}
    for effect in effects(codes):
        row = table.loc[effect_name(codes, effect)]
        out[effect] = tuple(float(row[column]) for column in ("F Value", "Num DF", "Den DF", "Pr > F"))
    return out


def _hf_from_gg(eps_gg: np.ndarray, n: int, d: int) -> np.ndarray:
    """Huynh–Feldt epsilon from Greenhouse–Geisser's with Lecoutre's (1991) correction, capped at 1.

    ``((N − g + 1)·d·ε − 2) / (d·(N − g − d·ε))`` with g = 1 group of N subjects (car, afex and
    pingouin.epsilon coincide here: Lecoutre's correction only differs with between-subject
    groups); NaN where the denominator is not positive (too few subjects for the estimate, e.g.
    2 subjects, 3 levels) or ε is.
    """
    if d <= 1:
        return np.ones_like(eps_gg)
    denominator = d * (n - 1 - d * eps_gg)
    with np.errstate(divide="ignore", invalid="ignore"):
        corrected = np.minimum((n * d * eps_gg - 2) / denominator, 1.0)
    return np.where(denominator > 0, corrected, math.nan)


def _mauchly(cov: np.ndarray, df_resid: int, k: int) -> tuple[np.ndarray, np.ndarray]:
    """Mauchly's W and p from covariances ``(..., d, d)`` of d orthonormal contrasts (R's
    ``mauchly.test`` with its second-order term, as pingouin.sphericity; ``k`` the number of
    cells of the effect)."""
    d = cov.shape[-1]
    f = 1 - (2 * d**2 + d + 2) / (6 * d * df_resid)
    if df_resid < d or f <= 0:  # a rank-deficient covariance: the test is undefined
        nothing = np.full(cov.shape[:-2], math.nan)
        return nothing, nothing.copy()
    sign, logdet = np.linalg.slogdet(cov)
    with np.errstate(divide="ignore", invalid="ignore"):
        log_w = np.where(sign > 0, logdet - d * np.log(np.trace(cov, axis1=-2, axis2=-1) / d),
                         -math.inf)
    w2 = (d + 2) * (d - 1) * (d - 2) * (2 * d**3 + 6 * d**2 + 3 * k + 2) / (288 * (df_resid * d * f) ** 2)
    chi2 = -df_resid * f * log_w
    ddof = d * (d + 1) / 2 - 1
    p1, p2 = scipy.stats.chi2.sf(chi2, ddof), scipy.stats.chi2.sf(chi2, ddof + 4)
    return np.exp(log_w), p1 + w2 * (p2 - p1)


def contrast_anova(values: np.ndarray, sizes: Sequence[int]) -> dict[tuple[int, ...], dict[str, np.ndarray]]:
    """The repeated-measures ANOVA of one or many subjects × cells tables at once, from
    orthonormal contrasts.

    The contrasts of an effect are the Kronecker product over factors of orthonormal Helmert
    contrasts (scipy.linalg.helmert) for the factors in the effect and a normalised mean for the
    others (as R's car/afex, SPSS and pingouin build an interaction's). With z = Y·C (subjects ×
    d): SS_effect = n·|mean z|², SS_error = Σ|z − mean z|², F = (SS_effect / d) /
    (SS_error / (d (n − 1))) with p from scipy.stats.f — each effect against its own effect ×
    subject error, the univariate test of statsmodels' AnovaRM (a test checks F, p and ε
    within 1e-9 relative) — and from S = cov(z): ε_GG = tr(S)² / (d·tr(S²)) (Greenhouse &
    Geisser 1959; Box 1954), ε_HF from ε_GG (Huynh & Feldt 1976, with Lecoutre 1991), Mauchly
    (1940). Generalised eta squared is SS_effect / (SS_effect + SS_subjects + every error SS)
    (Olejnik & Algina 2003, all factors within).

    Without variation F is 0/0 (NaN) or x/0 (inf), without numpy's warnings; callers that
    report it decide what such rounding dust means (:data:`ZERO_FRACTION`).

    Args:
        values: ``(..., n subjects, cells)``, n ≥ 2, the cells of 1–3 factors in row-major
            order (the first factor's level changing slowest: the columns of
            :func:`realpen.stats.long.balanced_wide`); any unit.
        sizes: the number of levels of each factor (each ≥ 2), in that order.

    Returns:
        ``{effect: entry}`` for ``()`` (the subjects: ``ss``, ``ss_error``) and every effect of
        :func:`effects`: ``ss``, ``ss_error`` (in the squared unit of the values), ``df1``,
        ``df2``, ``F``, ``p``, ``ges``, ``eps_gg``, ``eps_hf``, ``mauchly_w``, ``p_mauchly``
        (Mauchly NaN for an effect of one contrast), each an array of the leading shape
        (``df1`` and ``df2`` floats).

    Examples:
        >>> y = np.array([[1, 2, 4], [2, 2, 5], [1, 3, 3], [2, 4, 6]], float)
        >>> entry = contrast_anova(y, [3])[(0,)]
        >>> round(float(entry["F"]), 3), entry["df1"], entry["df2"], round(float(entry["eps_gg"]), 3)
        (17.211, 2.0, 6.0, 0.788)
    """
    values = np.asarray(values, dtype=float)
    n = values.shape[-2]
    out: dict[tuple[int, ...], dict[str, np.ndarray]] = {}
    for effect in [(), *effects(range(len(sizes)))]:
        contrast = np.ones((1, 1))
        for j, k in enumerate(sizes):
            part = scipy.linalg.helmert(k).T if j in effect else np.full((k, 1), 1 / math.sqrt(k))
            contrast = np.kron(contrast, part)
        z = values @ contrast
        mean = z.mean(axis=-2)
        deviations = z - mean[..., np.newaxis, :]
        d = z.shape[-1]
        entry = {"ss": n * (mean * mean).sum(axis=-1),
                 "ss_error": (deviations**2).sum(axis=(-2, -1))}
        if effect:
            cells = math.prod(sizes[j] for j in effect)
            df1, df2 = float(d), float(d * (n - 1))
            cov = np.swapaxes(deviations, -2, -1) @ deviations / (n - 1)
            with np.errstate(divide="ignore", invalid="ignore"):
                f_value = (entry["ss"] / df1) / (entry["ss_error"] / df2)
                # No variation at all gives 0/0: epsilon is undefined (NaN), said by the caller.
                eps = np.ones(cov.shape[:-2]) if d <= 1 else np.minimum(
                    np.trace(cov, axis1=-2, axis2=-1) ** 2
                    / (d * np.trace(cov @ cov, axis1=-2, axis2=-1)), 1.0)
            if d <= 1:
                w = p = np.full(cov.shape[:-2], math.nan)
            else:
                w, p = _mauchly(cov, n - 1, cells)
            entry.update(df1=df1, df2=df2, F=f_value, p=scipy.stats.f.sf(f_value, df1, df2),
                         eps_gg=eps, eps_hf=_hf_from_gg(eps, n, d), mauchly_w=w, p_mauchly=p)
        out[effect] = entry
    total_error = sum(entry["ss_error"] for entry in out.values())
    with np.errstate(divide="ignore", invalid="ignore"):
        for effect, entry in out.items():
            if effect:
                entry["ges"] = entry["ss"] / (entry["ss"] + total_error)
    return out


def contrast_decomposition(wide: pd.DataFrame) -> dict[tuple[int, ...], dict[str, float]]:
    """:func:`contrast_anova` of one subjects × cells table, as floats.

    Args:
        wide: subjects × cells, as :func:`realpen.stats.long.balanced_wide` gives it.

    Returns:
        ``{effect: entry}`` as :func:`contrast_anova` gives it, every number a float.
    """
    sizes = [len(level) for level in wide.columns.levels]
    parts = contrast_anova(wide.to_numpy(dtype=float), sizes)
    return {effect: {key: float(value) for key, value in entry.items()}
            for effect, entry in parts.items()}
