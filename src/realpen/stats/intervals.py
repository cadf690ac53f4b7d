"""Confidence intervals of means: Student t, and the BCa bootstrap for Likert-like scores.

- :func:`mean_ci`: (mean, low, high) of one sample.
- :func:`cell_cis`: the same per cell of a long-format table, over subjects' cell values.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import pandas as pd
import scipy.stats

from realpen.checks import require_choice
from realpen.errors import ParameterError
from realpen.stats.long import cell_text, check_columns, shown_level

__all__ = ["mean_ci", "cell_cis", "CI_METHODS"]

CI_METHODS = ("t", "bootstrap")
"""The interval methods :func:`mean_ci` offers."""


def _check_confidence(confidence: object) -> float:
    if isinstance(confidence, bool) or not isinstance(confidence, (int, float)) \
            or not 0 < confidence < 1:
        raise ParameterError("confidence", f"must be a number strictly between 0 and 1, got {confidence!r}")
    return float(confidence)


def mean_ci(values: object, *, confidence: float = 0.95, method: str = "t", n_boot: int = 10_000,
            seed: int = 0) -> tuple[float, float, float]:
    """The mean of ``values`` and its two-sided confidence interval.

    ``"t"``: Student's t interval, mean ± t(1 − α/2, n − 1) · SD/√n (:obj:`scipy.stats.t`).
    ``"bootstrap"``: the bias-corrected and accelerated (BCa) bootstrap of the mean
    (:func:`scipy.stats.bootstrap`, ``n_boot`` resamples from a generator seeded with ``seed``);
    where BCa is degenerate (its acceleration or bias correction undefined) the percentile
    interval is used instead. Constant data give low = high = mean with either method (there is
    no spread to be uncertain about); a single value gives NaN bounds.

    Args:
        values: a one-dimensional sequence of finite numbers (any unit; the interval has it too).
        confidence: the coverage, strictly between 0 and 1 (0.95 for a 95 % interval).
        method: ``"t"`` or ``"bootstrap"``.
        n_boot: bootstrap resamples (≥ 100).
        seed: the bootstrap generator's seed.

    Returns:
        ``(mean, low, high)`` as floats.

    Raises:
        ParameterError: empty input, a missing or non-finite value, or a bad option.

    References:
        Student (1908). The probable error of a mean. Biometrika, 6(1), 1–25.
        https://doi.org/10.1093/biomet/6.1.1

        Efron, B. (1987). Better bootstrap confidence intervals. Journal of the American
        Statistical Association, 82(397), 171–185. https://doi.org/10.1080/01621459.1987.10478410

    Examples:
        >>> from realpen.stats.intervals import mean_ci
        >>> print("mean {:.2f}, 95% CI [{:.2f}, {:.2f}]".format(*mean_ci([3, 4, 4, 5, 6, 4])))
        mean 4.33, 95% CI [3.25, 5.42]
        >>> mean_ci([4, 4, 4], method="bootstrap")
        (4.0, 4.0, 4.0)
    """
    try:
        array = np.asarray(values, dtype=float)
    except (TypeError, ValueError):
        raise ParameterError("values", "must be numbers") from None
    if array.ndim != 1:
        raise ParameterError("values", f"must be one-dimensional, got shape {array.shape}")
    if array.size == 0:
        raise ParameterError("values", "is empty: a mean needs at least one value")
    bad = ~np.isfinite(array)
    if bad.any():
        raise ParameterError("values", f"has a missing or non-finite value at index {int(np.argmax(bad))}")
    level = _check_confidence(confidence)
    require_choice("method", method, CI_METHODS)
    if isinstance(n_boot, bool) or not isinstance(n_boot, (int, np.integer)) or n_boot < 100:
        raise ParameterError("n_boot", f"must be an integer >= 100, got {n_boot!r}")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)):
        raise ParameterError("seed", f"must be an integer, got {seed!r}")
    mean = float(array.mean())
    if array.size == 1:
        return mean, math.nan, math.nan
    if np.ptp(array) == 0:
        return mean, mean, mean
    if method == "t":
        low, high = scipy.stats.t.interval(level, array.size - 1, loc=mean, scale=scipy.stats.sem(array))
        return mean, float(low), float(high)
    low, high = _bootstrap(array, level, int(n_boot), int(seed), "BCa")
    if not (math.isfinite(low) and math.isfinite(high)):
        low, high = _bootstrap(array, level, int(n_boot), int(seed), "percentile")
    return mean, low, high


_BOOTSTRAP_VALUES = 2**22


def _bootstrap(array: np.ndarray, level: float, n_boot: int, seed: int, kind: str) -> tuple[float, float]:
    with warnings.catch_warnings():
        # A degenerate BCa gives NaN with a warning; the caller falls back to the percentile.
        warnings.simplefilter("ignore", scipy.stats.DegenerateDataWarning)
        warnings.simplefilter("ignore", RuntimeWarning)
        # Batches of about 4 M values: the resamples (n_boot × n) and BCa's jackknife (n × n)
        # would otherwise take gigabytes for thousands of values. The draws are one stream,
        # so the batch changes no number.
        result = scipy.stats.bootstrap((array,), np.mean, n_resamples=n_boot, confidence_level=level,
                                       method=kind, vectorized=True, rng=np.random.default_rng(seed),
                                       batch=max(1, _BOOTSTRAP_VALUES // array.size))
    interval = result.confidence_interval
    return float(interval.low), float(interval.high)


def cell_cis(data: pd.DataFrame, *, dv: str, by: list[str], subject: str, confidence: float = 0.95,
             method: str = "t", seed: int = 0) -> pd.DataFrame:
    """Mean and confidence interval of ``dv`` per cell of ``by``, over subjects.

    Each subject's values in a cell are first averaged to one cell value (so repetitions do not
    count as subjects); the cell's mean and interval are :func:`mean_ci` of those values.

    Args:
        data: long format.
        dv: the numeric column (any unit; the intervals have it too).
        by: the columns that define a cell (one or more).
        subject: the subject column.
        confidence: as :func:`mean_ci`.
        method: ``"t"`` or ``"bootstrap"`` (10 000 resamples).
        seed: the bootstrap's seed (every cell's generator starts from it).

    Returns:
        One row per cell (in the columns' Categorical order, else sorted): the ``by`` columns,
        then ``mean``, ``ci_low``, ``ci_high`` and ``n`` (subjects in the cell).

    Raises:
        ParameterError: a missing column, a non-numeric ``dv`` or a missing value (names the
            subject and cell).

    Examples:
        >>> import pandas as pd
        >>> from realpen.stats.intervals import cell_cis
        >>> data = pd.DataFrame({"subject": [1, 1, 2, 2, 3, 3], "pen": ["a", "b"] * 3,
        ...                      "rating": [3, 5, 4, 6, 5, 6]})
        >>> cell_cis(data, dv="rating", by=["pen"], subject="subject").round(2)
          pen  mean  ci_low  ci_high  n
        0   a  4.00    1.52     6.48  3
        1   b  5.67    4.23     7.10  3
    """
    if isinstance(by, str) or not by or not all(isinstance(name, str) for name in by):
        raise ParameterError("by", f"must be a non-empty list of column names, got {by!r}")
    by = list(by)
    if subject in by:
        raise ParameterError("by", f"must not contain the subject column {subject!r}")
    _check_confidence(confidence)
    require_choice("method", method, CI_METHODS)
    check_columns(data, dv=dv, factors=by, subject=subject)
    values = data[dv].astype(float)
    bad = ~np.isfinite(values.to_numpy())
    if bad.any():
        row = data.loc[bad].iloc[0]
        raise ParameterError("data", f"{dv!r} is missing or not finite for subject "
                                     f"{shown_level(row[subject])} at {cell_text(by, tuple(row[by]))}")
    per_subject = data.assign(**{dv: values}).groupby([*by, subject], observed=True, sort=True)[dv].mean()
    rows = []
    for cell, group in per_subject.groupby(level=list(range(len(by))), observed=True, sort=True):
        mean, low, high = mean_ci(group.to_numpy(), confidence=confidence, method=method, seed=seed)
        cell = cell if isinstance(cell, tuple) else (cell,)
        rows.append({**dict(zip(by, cell)), "mean": mean, "ci_low": low, "ci_high": high, "n": len(group)})
    return pd.DataFrame(rows, columns=[*by, "mean", "ci_low", "ci_high", "n"])
