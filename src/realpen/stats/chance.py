"""Recognition against chance: is each modality's (or pen's) rate of right answers above what
guessing gives?

A recognition question with ``k`` choices is answered right by chance with probability 1/k
(study 2: 1/3). :func:`chance_tests` tests, per level of a factor:

- **the primary test, at the participant level**: each participant's proportion correct at
  that level minus chance, by the one-sample Wilcoxon signed-rank test
  (:func:`realpen.stats.nonparametric.wilcoxon` against the constant chance, its p by the
  named method) with r = z/√n. Not a one-sample t: a proportion of a few trials (study 2:
  18 per modality) is discrete, bounded by 0 and 1 and often tied, so its differences are
  not normal; the signed-rank test assumes only that they are symmetric about their median.
  Participants are the unit of inference, as in the participant-level ANOVA;
- **a secondary test, at the trial level**: the exact binomial test of all trials' right
  answers pooled (:func:`scipy.stats.binomtest`), with Cohen's h. It treats every trial as
  independent, which trials of one person are not: with participants who differ its p is too
  small, and the row says so.

Both are two-sided (a rate below chance — a pen consistently taken for another — is a finding
too), and each family (the levels of one factor, per test) is adjusted for multiplicity.
:func:`recognition_chance` runs them for a study's recognition outcome as result rows
(``chance/<factor>`` and ``chance/<factor>/binomial``).

References:
    Wilcoxon, F. (1945). Individual comparisons by ranking methods. Biometrics Bulletin,
    1(6), 80–83. https://doi.org/10.2307/3001968

    Clopper, C. J., & Pearson, E. S. (1934). The use of confidence or fiducial limits
    illustrated in the case of the binomial. Biometrika, 26(4), 404–413.
    https://doi.org/10.1093/biomet/26.4.404

    Cohen, J. (1988). Statistical power analysis for the behavioral sciences (2nd ed.),
    chapter 6. Lawrence Erlbaum. https://doi.org/10.4324/9780203771587

May import: :mod:`realpen.stats.nonparametric`, :mod:`realpen.stats.trial_models`,
:mod:`realpen.stats.results`, :mod:`realpen.study` (and numpy, pandas, scipy, statsmodels).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from fractions import Fraction

import numpy as np
import pandas as pd
import scipy.stats

from realpen.checks import require_choice
from realpen.errors import ParameterError
from realpen.stats.data import Outcome, Trials
from realpen.stats.multiplicity import LIBRARY, adjusted_p
from realpen.stats.nonparametric import WILCOXON_METHODS, wilcoxon
from realpen.stats.results import test_row as _result_row  # pytest would collect "test_row"
from realpen.stats.results import tidy, with_context
from realpen.stats.trial_models import outcome_trials

__all__ = ["chance_level", "chance_text", "chance_tests", "recognition_chance", "ALL_TRIALS",
           "BINOMIAL_TEST", "DIFFERENCE_DECIMALS"]

ALL_TRIALS = "all"
"""The level (and factor) of an outcome without within factors: all its trials."""
BINOMIAL_TEST = "exact binomial"
DIFFERENCE_DECIMALS = 12
"""Proportions minus chance are rounded to this many decimals, so that equal distances from
chance (7/18 − 1/3 and 1/3 − 5/18) tie exactly, as they do on paper."""
_ADJUSTMENTS = ("holm", "bonferroni", "none")


def chance_level(design, question: str) -> float | None:
    """The probability of answering ``question`` right by guessing: 1 / its number of choices
    (None when it has no choices).

    >>> from realpen.study.design import load_design
    >>> chance_level(load_design("study2"), "pen")
    0.3333333333333333
    """
    found = next((q for q in design.questions if q.id == question), None)
    choices = getattr(found, "choices", None)
    if not choices or isinstance(choices, str):
        return None
    return 1.0 / len(choices)


def chance_text(chance: float) -> str:
    """Chance as a reader writes it: ``1/3``, ``1/4`` (a fraction when it is one of a few
    choices, else a percentage).

    >>> chance_text(1 / 3), chance_text(0.25), chance_text(0.3)
    ('1/3', '1/4', '30 %')
    """
    fraction = Fraction(chance).limit_denominator(100)
    if fraction.numerator == 1 and abs(float(fraction) - chance) < 1e-9:
        return f"1/{fraction.denominator}"
    return f"{100 * chance:.3g} %"


def _adjusted(p: np.ndarray, adjust: str) -> np.ndarray:
    """``p`` adjusted over its finite values (NaN stays NaN and does not count)."""
    return adjusted_p(p, adjust)


def _family_words(adjust: str, tested: int, total: int) -> str:
    if adjust == "none" or tested < 2:
        return "no multiplicity adjustment" if adjust == "none" else \
            "one testable level: no adjustment needed"
    name = "Bonferroni" if adjust == "bonferroni" else "Holm"
    return f"{name} over the {tested} testable of {total} levels ({LIBRARY})"


def chance_tests(data: pd.DataFrame, *, dv: str, within: str | None, subject: str,
                 chance: float, wilcoxon_method: str = "exact", adjust: str = "holm"
                 ) -> pd.DataFrame:
    """Recognition rates against chance, per level of ``within``: the participants' proportions
    by the one-sample Wilcoxon signed-rank test, and the pooled trials by the exact binomial
    test (see the module doc for why each).

    Args:
        data: long format, one row per trial.
        dv: the trial's outcome column (1 right, 0 wrong).
        within: the factor whose levels are tested one by one (levels in Categorical order,
            else as they appear); None: all trials as one level, :data:`ALL_TRIALS`.
        subject: the participant column.
        chance: the probability of a right answer by guessing (0 < chance < 1; 1/3 for three
            choices).
        wilcoxon_method: ``exact``, ``r`` or ``spss``
            (:func:`realpen.stats.nonparametric.wilcoxon`).
        adjust: ``holm``, ``bonferroni`` or ``none``, over the levels, each test apart.

    Returns:
        Two rows per level, the Wilcoxon rows first: :data:`realpen.stats.results.TEST_COLUMNS`
        (Wilcoxon: statistic ``T``, effect size ``r``, ``n`` participants; binomial: statistic
        ``k`` = right answers, effect size ``cohen_h`` = 2·asin√p̂ − 2·asin√chance, ``n``
        trials), then ``effect`` (the level), ``family`` (``participants`` or ``trials``),
        ``p_adjusted``, ``adjust``, ``percent_correct`` (the participants' mean percentage, or
        the pooled one), ``correct`` and ``trials``. A level whose every participant sits
        exactly at chance has a Wilcoxon row without a statistic (nothing to rank).

    Raises:
        ParameterError: a missing column, ``chance`` outside (0, 1), an unknown method.

    Examples:
        >>> import numpy as np, pandas as pd
        >>> from realpen.stats.chance import chance_tests
        >>> rng = np.random.default_rng(2)
        >>> data = pd.DataFrame({"participant": np.repeat(np.arange(12), 36),
        ...                      "modality": np.tile(["tactile", "audio-tactile"], 216)})
        >>> data["correct"] = (rng.random(432) < np.where(data["modality"] == "tactile",
        ...                                               1 / 3, 0.8)).astype(float)
        >>> table = chance_tests(data, dv="correct", within="modality", subject="participant",
        ...                      chance=1 / 3)
        >>> for row in table.itertuples():
        ...     print(row.effect, row.test, f"{row.percent_correct:.1f} %", row.p_adjusted < 0.05)
        tactile Wilcoxon signed-rank 33.8 % False
        audio-tactile Wilcoxon signed-rank 81.9 % True
        tactile exact binomial 33.8 % False
        audio-tactile exact binomial 81.9 % True
    """
    require_choice("wilcoxon_method", wilcoxon_method, WILCOXON_METHODS)
    require_choice("adjust", adjust, _ADJUSTMENTS)
    if not isinstance(data, pd.DataFrame):
        raise ParameterError("data", f"must be a DataFrame, got {type(data).__name__}")
    for name in (dv, subject, *([within] if within is not None else [])):
        if name not in data.columns:
            raise ParameterError("data", f"has no column {name!r}")
    if isinstance(chance, bool) or not isinstance(chance, (int, float)) or not 0 < chance < 1:
        raise ParameterError("chance", f"must be a probability between 0 and 1, got {chance!r}")
    outcome = pd.to_numeric(data[dv], errors="coerce")
    frame = pd.DataFrame({"participant": data[subject].to_numpy(), "correct": outcome.to_numpy(),
                          "level": (data[within] if within is not None
                                    else pd.Series(ALL_TRIALS, index=data.index)).to_numpy()})
    frame = frame.dropna(subset=["correct"])
    if within is not None and isinstance(data[within].dtype, pd.CategoricalDtype):
        levels = [level for level in data[within].cat.categories if (frame["level"] == level).any()]
    else:
        levels = list(dict.fromkeys(frame["level"]))
    said = chance_text(chance)
    participant_rows, trial_rows = [], []
    for level in levels:
        rows = frame[frame["level"] == level]
        proportions = rows.groupby("participant", sort=False, observed=True)["correct"].mean()
        difference = np.round(proportions.to_numpy(float) - chance, DIFFERENCE_DECIMALS)
        percent = 100.0 * float(proportions.mean())
        right, total = int(rows["correct"].sum()), len(rows)
        counts = dict(percent_correct=percent, correct=right, trials=total)
        why = (f"one-sample: each participant's proportion correct at {level} minus chance "
               f"{said}; signed-rank rather than t because a proportion of "
               f"{total / max(len(proportions), 1):.3g} trials is discrete, bounded and tied")
        if difference.any():
            result = wilcoxon(difference, np.zeros_like(difference),
                              method=wilcoxon_method).iloc[0]
            participant_rows.append(_result_row(
                result["test"], result["statistic_name"], result["statistic"], result["p"],
                n=int(result["n"]), method=f"{why}; {result['method']}",
                effect_size_name="r", effect_size=result["effect_size"], effect=level,
                family="participants", **counts))
        else:
            participant_rows.append(_result_row(
                "Wilcoxon signed-rank", "T", math.nan, math.nan, n=len(difference),
                method=f"{why}; every participant is exactly at chance: nothing to test",
                effect_size_name="r", effect=level, family="participants", **counts))
        test = scipy.stats.binomtest(right, total, p=chance, alternative="two-sided")
        pooled = right / total
        cohen_h = 2 * math.asin(math.sqrt(pooled)) - 2 * math.asin(math.sqrt(chance))
        trial_rows.append(_result_row(
            BINOMIAL_TEST, "k", right, float(test.pvalue), n=total,
            method=(f"secondary, treats the {total} trials of {len(proportions)} participants "
                    f"as independent (they are not: with participants who differ this p is "
                    f"too small); scipy.stats.binomtest, {right} of {total} right against "
                    f"chance {said}, two-sided; cohen_h = 2 asin(sqrt(p)) - 2 asin(sqrt(chance))"),
            effect_size_name="cohen_h", effect_size=cohen_h, effect=level, family="trials",
            percent_correct=100.0 * pooled, correct=right, trials=total))
    for family in (participant_rows, trial_rows):
        p = np.array([row["p"] for row in family], dtype=float)
        adjusted = _adjusted(p, adjust)
        words = _family_words(adjust, int(np.isfinite(p).sum()), len(family))
        for row, value in zip(family, adjusted):
            row["p_adjusted"] = float(value)
            row["adjust"] = adjust
            row["method"] += f"; {words}"
    return tidy(participant_rows + trial_rows)


def recognition_chance(trials: Trials, outcome: Outcome, participants: Sequence[str], *,
                       wilcoxon_method: str = "exact", adjust: str = "holm") -> list[pd.DataFrame]:
    """:func:`chance_tests` of a study's recognition outcome, per factor, as result rows.

    Each factor of the outcome (study 2: ``modality``, then ``pen``; :data:`ALL_TRIALS` when it
    has none) gets the Wilcoxon rows as analysis ``chance/<factor>`` and the binomial rows as
    ``chance/<factor>/binomial``, ``effect`` the level, each family adjusted by ``adjust``.
    Chance is 1 / the question's number of choices (:func:`chance_level`).

    Args:
        trials: the checked trials.
        outcome: a ``recognition`` outcome (:func:`realpen.stats.data.outcomes`).
        participants: those complete in the outcome.
        wilcoxon_method, adjust: as :func:`chance_tests`.

    Returns:
        DataFrames in :data:`realpen.stats.results.RESULT_COLUMNS`; none for another kind of
        outcome or a question without choices.
    """
    chance = chance_level(trials.design, outcome.question)
    if outcome.kind != "recognition" or chance is None:
        return []
    data = outcome_trials(trials, outcome, participants)
    parts = []
    for factor in outcome.factors or (None,):
        table = chance_tests(data, dv="correct", within=factor, subject="participant",
                             chance=chance, wilcoxon_method=wilcoxon_method, adjust=adjust)
        name = factor or ALL_TRIALS
        for family, suffix in (("participants", ""), ("trials", "/binomial")):
            rows = table[table["family"] == family]
            part = with_context(rows, analysis=f"chance/{name}{suffix}", outcome=outcome.name,
                                p_adjusted=rows["p_adjusted"], adjust=adjust)
            # T, z and r read the same above and below chance: the sentence says which side
            part["apa"] = [f"M = {percent:.1f} % correct against chance {chance_text(chance)}, "
                           f"{sentence}" if sentence else ""
                           for percent, sentence in zip(rows["percent_correct"], part["apa"])]
            parts.append(part)
    return parts
