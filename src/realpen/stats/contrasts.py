"""Orthonormal contrasts of a subjects × cells table: effects, sums of squares, sphericity.

What the repeated-measures ANOVA (:mod:`realpen.stats.anova`) and the aligned rank transform
(:mod:`realpen.stats.art`) share: the list of a design's effects and their names, statsmodels'
F per effect, and each effect's sums of squares, Greenhouse–Geisser and Huynh–Feldt epsilon and
Mauchly's test from the covariance of its orthonormal contrasts.

May import: numpy, pandas, scipy and statsmodels only.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence

import numpy as np
import pandas as pd
import scipy.linalg
import scipy.stats
from statsmodels.stats.anova import AnovaRM

__all__ = ["ZERO_FRACTION", "effects", "effect_name", "anovarm_f", "contrast_decomposition"]

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
    codes = [f"f{j}" for j in range(n_factors)]
    table = AnovaRM(long, depvar="y", subject="s", within=codes).fit().anova_table
    out = {}
    for effect in effects(codes):
        row = table.loc[effect_name(codes, effect)]
        out[effect] = tuple(float(row[column]) for column in ("F Value", "Num DF", "Den DF", "Pr > F"))
    return out


def _hf_from_gg(eps_gg: float, n: int, d: int) -> float:
    """Huynh–Feldt epsilon from Greenhouse–Geisser's with Lecoutre's (1991) correction, capped at 1.

    ``((N − g + 1)·d·ε − 2) / (d·(N − g − d·ε))`` with g = 1 group of N subjects (car, afex and
    pingouin.epsilon coincide here: Lecoutre's correction only differs with between-subject groups).
    """
    if d <= 1:
        return 1.0
    denominator = d * (n - 1 - d * eps_gg)
    if denominator <= 0:  # too few subjects for the estimate (e.g. 2 subjects, 3 levels)
        return math.nan
    return float(min((n * d * eps_gg - 2) / denominator, 1.0))


def _mauchly(cov: np.ndarray, df_resid: int, k: int) -> tuple[float, float]:
    """Mauchly's W and p from the covariance of d orthonormal contrasts (R's ``mauchly.test``
    with its second-order term, as pingouin.sphericity; ``k`` the number of cells of the effect)."""
    d = cov.shape[0]
    f = 1 - (2 * d**2 + d + 2) / (6 * d * df_resid)
    if df_resid < d or f <= 0:  # a rank-deficient covariance: the test is undefined
        return math.nan, math.nan
    sign, logdet = np.linalg.slogdet(cov)
    log_w = logdet - d * math.log(np.trace(cov) / d) if sign > 0 else -math.inf
    w2 = (d + 2) * (d - 1) * (d - 2) * (2 * d**3 + 6 * d**2 + 3 * k + 2) / (288 * (df_resid * d * f) ** 2)
    chi2 = -df_resid * f * log_w
    ddof = d * (d + 1) / 2 - 1
    p1, p2 = scipy.stats.chi2.sf(chi2, ddof), scipy.stats.chi2.sf(chi2, ddof + 4)
    return float(math.exp(log_w)), float(p1 + w2 * (p2 - p1))


def contrast_decomposition(wide: pd.DataFrame) -> dict[tuple[int, ...], dict[str, float]]:
    """Per effect: sums of squares, Greenhouse–Geisser and Huynh–Feldt epsilon and Mauchly's test,
    from orthonormal contrasts of the subjects × cells table.

    The contrasts of an effect are the Kronecker product over factors of orthonormal Helmert
    contrasts (scipy.linalg.helmert) for the factors in the effect and a normalised mean for the
    others (as R's car/afex, SPSS and pingouin build an interaction's). With z = Y·C (subjects ×
    d): SS_effect = n·|mean z|², SS_error = Σ|z − mean z|², S = cov(z), and
    ε_GG = tr(S)² / (d·tr(S²)) (Greenhouse & Geisser 1959; Box 1954), ε_HF from ε_GG
    (Huynh & Feldt 1976, with Lecoutre 1991), Mauchly (1940) from S.

    Args:
        wide: subjects × cells, as :func:`realpen.stats.long.balanced_wide` gives it.

    Returns:
        ``{effect: entry}`` for ``()`` (the subjects: ``ss``, ``ss_error``) and every effect of
        :func:`effects` (also ``eps_gg``, ``eps_hf``, ``mauchly_w``, ``p_mauchly``; Mauchly is
        NaN for an effect of one contrast), sums of squares in the squared unit of the values.
    """
    y = wide.to_numpy(dtype=float)
    n = y.shape[0]
    sizes = [len(level) for level in wide.columns.levels]
    out: dict[tuple[int, ...], dict[str, float]] = {}
    for effect in [(), *effects(range(len(sizes)))]:
        contrast = np.ones((1, 1))
        for j, k in enumerate(sizes):
            part = scipy.linalg.helmert(k).T if j in effect else np.full((k, 1), 1 / math.sqrt(k))
            contrast = np.kron(contrast, part)
        z = y @ contrast
        mean = z.mean(axis=0)
        deviations = z - mean
        d = z.shape[1]
        cells = int(np.prod([sizes[j] for j in effect])) if effect else 1
        entry = {"ss": float(n * mean @ mean), "ss_error": float((deviations**2).sum())}
        if effect:
            cov = deviations.T @ deviations / (n - 1)
            with np.errstate(divide="ignore", invalid="ignore"):
                # No variation at all gives 0/0: epsilon is undefined (NaN), said by the caller.
                eps = 1.0 if d <= 1 else float(min(np.trace(cov) ** 2 / (d * np.trace(cov @ cov)),
                                                   1.0))
            w, p = (math.nan, math.nan) if d <= 1 else _mauchly(cov, n - 1, cells)
            entry.update(eps_gg=eps, eps_hf=_hf_from_gg(eps, n, d), mauchly_w=w, p_mauchly=p)
        out[effect] = entry
    return out
