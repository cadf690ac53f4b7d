"""Trial-level models beside the participant-level tests: a binomial GEE for recognition and a
linear mixed model for log response times (statsmodels).

The participant-level analyses (:mod:`realpen.stats.analyses`) reduce each participant to one
value per cell (a proportion correct, a mean log RT) and test those: participants are the unit
of inference, and the repeated-measures ANOVA of those values is the paper's analysis (with
participants rather than repetitions as subjects). The models here are the check that uses
every trial instead — for recognition also its binomial nature (a proportion of 6 trials is
bounded and coarse, a trial is a 0/1 outcome):

- :func:`binomial_gee`: :class:`statsmodels.genmod.generalized_estimating_equations.GEE` with
  a binomial family (logit link) and an exchangeable working correlation within each
  participant; the covariance is Mancl and DeRouen's bias-reduced sandwich, which keeps the
  Wald tests honest with a dozen participants;
- :func:`mixed_model`: :class:`statsmodels.regression.mixed_linear_model.MixedLM` of ln(RT)
  with a random intercept per participant, fitted by REML;
- :func:`fit_binomial_gee`, :func:`fit_mixed_model`: the same models fitted
  (:class:`ModelFit`: statsmodels' results, each cell's fitted mean), :func:`model_rows` their
  rows;
- :func:`trial_model_tests`: both for a study's outcomes, as result rows
  (``gee/recognition``, ``mixedlm/log_rt``).

Each effect (main effects and interactions of the within factors, sum-to-zero contrasts so
that a main effect is averaged over the other factor's levels) gets a Wald chi-square with its
degrees of freedom. A model that does not converge, or a GEE with a cell whose answers are all
right or all wrong (infinite log-odds: separation), gives a row without numbers whose
``method`` says so; statsmodels' warnings never reach the terminal (they become notes).

Above :data:`MAX_MODEL_TRIALS` trials a model is fitted on the first participants (in file
order, whole participants) whose trials fit, and says so: the fits grow with the trials
(a mixed model of 1,000 participants' 54 trials takes about 5 s on one core).

References:
    Liang, K.-Y., & Zeger, S. L. (1986). Longitudinal data analysis using generalized linear
    models. Biometrika, 73(1), 13–22. https://doi.org/10.1093/biomet/73.1.13

    Mancl, L. A., & DeRouen, T. A. (2001). A covariance estimator for GEE with improved
    small-sample properties. Biometrics, 57(1), 126–134.
    https://doi.org/10.1111/j.0006-341X.2001.00126.x

    Baayen, R. H., Davidson, D. J., & Bates, D. M. (2008). Mixed-effects modeling with crossed
    random effects for subjects and items. Journal of Memory and Language, 59(4), 390–412.
    https://doi.org/10.1016/j.jml.2007.12.005

May import: :mod:`realpen.stats.data`, :mod:`realpen.stats.results` (and numpy, pandas,
statsmodels, imported when a model is fitted).
"""

from __future__ import annotations

import itertools
import math
import re
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from realpen.errors import ParameterError
from realpen.stats.data import Outcome, Trials, outcome_rows
from realpen.stats.results import test_row as _result_row  # pytest would collect "test_row"
from realpen.stats.results import tidy, with_context

__all__ = ["binomial_gee", "mixed_model", "fit_binomial_gee", "fit_mixed_model", "model_rows",
           "ModelFit", "trial_model_tests", "outcome_trials", "MAX_MODEL_TRIALS", "GEE_TEST",
           "MIXED_TEST", "PRIMARY_REASON"]

MAX_MODEL_TRIALS = 60_000
"""The most trials a model is fitted on (1,111 participants of study 2's 54): beyond, the
first participants whose trials fit are used and the row says so."""
GEE_TEST = "binomial GEE"
MIXED_TEST = "linear mixed model"
PRIMARY_REASON = ("the participant-level RM-ANOVA stays the primary test: participants are the "
                  "unit of inference, and it analyses each participant's value per cell as the "
                  "paper's ANOVA did (with participants, not repetitions, as subjects); this "
                  "trial-level model is the check that uses every trial")
"""Why the trial-level models are the check and not the primary test (in every row's method)."""

_STATISTIC = "chi2"


def outcome_trials(trials: Trials, outcome: Outcome, participants: Sequence[str]) -> pd.DataFrame:
    """One row per analysed trial of ``outcome`` by ``participants``.

    Args:
        trials: the checked trials (:func:`realpen.stats.data.read_trials`).
        outcome: a ``recognition`` or ``log_rt`` outcome (:func:`realpen.stats.data.outcomes`).
        participants: whose trials (those complete in the outcome).

    Returns:
        Columns ``participant`` (text), the outcome's factors (categorical, design order), and
        ``correct`` (1.0 or 0.0) for recognition or ``log_rt`` (natural log of ``rt_ms``; trials
        without a positive time left out) for response times; in file order.
    """
    # outcome_rows names trials outside any block over conditions as a condition level of
    # their own, as the participant-level analysis does; the raw frame would drop them
    rows = outcome_rows(trials, outcome)
    rows = rows[rows["participant"].isin(list(participants))]
    if outcome.kind == "recognition":
        rows = rows[rows["correct"].notna()]
        name, values = "correct", rows["correct"].to_numpy(dtype=float)
    elif outcome.kind == "log_rt":
        times = rows["rt_ms"].to_numpy(dtype=float)
        with np.errstate(invalid="ignore"):
            timed = np.isfinite(times) & (times > 0)
        rows = rows[timed]
        name, values = "log_rt", np.log(times[timed])
    else:
        raise ParameterError("outcome", f"must be a recognition or log_rt outcome, got "
                                        f"{outcome.kind!r}")
    data = {"participant": rows["participant"].astype(str).to_numpy()}
    for factor in outcome.factors:
        data[factor] = pd.Categorical(rows[factor].astype(str).to_numpy(),
                                      categories=list(outcome.levels[factor]))
    data[name] = values
    result = pd.DataFrame(data)
    if outcome.factors:
        result = result.dropna(subset=list(outcome.factors))
    return result.reset_index(drop=True)


def _first_participants(data: pd.DataFrame, subject: str, limit: int) -> tuple[pd.DataFrame, int]:
    """``data`` cut to the first whole subjects (in order of appearance) whose rows fit in
    ``limit``, and how many subjects it had."""
    codes, order = pd.factorize(data[subject], sort=False)
    if len(data) <= limit:
        return data, len(order)
    counts = np.bincount(codes, minlength=len(order))
    keep = int(np.searchsorted(np.cumsum(counts), limit, side="right"))
    return data[codes < max(keep, 2)], len(order)


@dataclass
class ModelFit:
    """A fitted trial-level model (:func:`fit_binomial_gee`, :func:`fit_mixed_model`).

    Attributes:
        test: :data:`GEE_TEST` or :data:`MIXED_TEST`.
        result: statsmodels' results (None when the model could not be fitted).
        data: the trials fitted, under the model's own column names: ``y`` the response,
            ``g`` the participant, ``f0``, ``f1`` … the factors (categorical).
        factors: ``{model column: factor}`` (``{"f0": "modality", "f1": "pen"}``).
        crossed: whether the factors are fully crossed (else main effects only).
        described: the model in words (for a row's ``method``).
        failure: why there is no test ("" when there is one).
        subset: what ``max_trials`` left out ("" when nothing).
        warnings: what statsmodels warned while fitting, each once.
    """

    test: str
    result: object | None
    data: pd.DataFrame
    factors: dict[str, str]
    crossed: bool
    described: str
    failure: str = ""
    subset: str = ""
    warnings: list[str] = field(default_factory=list)

    def cell_means(self) -> pd.DataFrame:
        """The model's fitted mean of every cell (the fixed effects only): a proportion correct
        for the GEE, a mean log RT for the mixed model; columns: the factors, then ``mean``."""
        cells = self.data.drop_duplicates(list(self.factors))[list(self.factors)]
        cells = cells.sort_values(list(self.factors)).reset_index(drop=True)
        if self.result is None:
            means = np.full(len(cells), math.nan)
        else:
            means = np.asarray(self.result.predict(exog=cells), dtype=float)
        return cells.rename(columns=self.factors).assign(mean=means)


def _prepared(data: pd.DataFrame, dv: str, within: str | Sequence[str], subject: str
              ) -> tuple[pd.DataFrame, str, dict[str, str], bool]:
    """The data under the model's column names, the model formula, the map from those names
    back to the factors, and whether the factors are fully crossed (else main effects only)."""
    if not isinstance(data, pd.DataFrame):
        raise ParameterError("data", f"must be a DataFrame, got {type(data).__name__}")
    factors = [within] if isinstance(within, str) else list(within)
    if not factors:
        raise ParameterError("within", "must name at least one factor")
    for name in (dv, subject, *factors):
        if name not in data.columns:
            raise ParameterError("data", f"has no column {name!r}")
    # Own column names: a user's factor may be called anything, a formula may not.
    safe = {f"f{k}": name for k, name in enumerate(factors)}
    frame = pd.DataFrame({"y": pd.to_numeric(data[dv], errors="coerce").to_numpy(dtype=float),
                          "g": data[subject].astype(str).to_numpy()})
    for key, name in safe.items():
        column = data[name]
        frame[key] = (pd.Categorical(column.cat.remove_unused_categories())
                      if isinstance(column.dtype, pd.CategoricalDtype)
                      else pd.Categorical(column.astype(str).to_numpy()))
    frame = frame.dropna().reset_index(drop=True)
    levels = [frame[key].nunique() for key in safe]
    crossed = len(frame.drop_duplicates(list(safe))) == int(np.prod(levels))
    terms = [f"C({key}, Sum)" for key in safe]
    formula = "y ~ " + (" * " if crossed else " + ").join(terms)
    return frame, formula, safe, crossed


def _effect_name(term: str, safe: dict[str, str]) -> str:
    return re.sub(r"C\((f\d+), Sum\)", lambda match: safe[match.group(1)], term)


def _terms(safe: dict[str, str], crossed: bool) -> list[str]:
    """The effects a model tests, in statsmodels' order (main effects, then interactions)."""
    names = list(safe.values())
    if not crossed:
        return names
    return [":".join(combo) for size in range(1, len(names) + 1)
            for combo in itertools.combinations(names, size)]


def _warning_texts(caught: list[warnings.WarningMessage]) -> list[str]:
    return list(dict.fromkeys(str(item.message).strip().split("\n")[0] for item in caught))


def _fit_size(data: pd.DataFrame, subject: str, max_trials: int | None) -> tuple[pd.DataFrame, str]:
    """The data a model is fitted on, and the words saying what was left out (or "")."""
    if max_trials is None:
        return data, ""
    used, everyone = _first_participants(data, subject, max_trials)
    if len(used) == len(data):
        return data, ""
    people = used[subject].nunique()
    return used, (f"fitted on the first {people:,} of {everyone:,} participants ({len(used):,} of "
                  f"{len(data):,} trials): above {max_trials:,} trials the fit takes too long")


def _fitted(test: str, data: pd.DataFrame, dv: str, within: str | Sequence[str], subject: str,
            max_trials: int | None, model_words: str, fit) -> ModelFit:
    """``fit(frame, formula)`` run with statsmodels' warnings caught, as a :class:`ModelFit`."""
    frame, formula, safe, crossed = _prepared(data, dv, within, subject)
    frame, cut = _fit_size(frame, "g", max_trials)
    design = "full factorial" if crossed else "main effects only (cells not fully crossed)"
    described = (f"{model_words}; {design}, sum-to-zero contrasts; Wald chi2 per effect; "
                 f"{len(frame):,} trials of {frame['g'].nunique()} participants"
                 + (f" ({cut})" if cut else ""))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            result, failure = fit(frame, formula)
        except (np.linalg.LinAlgError, ValueError) as error:
            result, failure = None, f"the model could not be fitted ({error})"
    return ModelFit(test, result, frame, safe, crossed, described, failure, cut,
                    _warning_texts(caught))


def fit_binomial_gee(data: pd.DataFrame, *, dv: str, within: str | Sequence[str], subject: str,
                     max_trials: int | None = MAX_MODEL_TRIALS) -> ModelFit:
    """The binomial GEE of :func:`binomial_gee`, fitted (its results, cell means, warnings)."""
    from statsmodels.genmod.cov_struct import Exchangeable
    from statsmodels.genmod.families import Binomial
    from statsmodels.genmod.generalized_estimating_equations import GEE

    def fit(frame: pd.DataFrame, formula: str):
        factors = [column for column in frame.columns if column not in ("y", "g")]
        rates = frame.groupby(factors, observed=True)["y"].mean()
        extreme = rates[(rates == 0) | (rates == 1)]
        if len(extreme):
            # Its log-odds would be infinite: the estimates run off and the Wald tests mean
            # nothing (quasi-complete separation).
            cell = ", ".join(str(level) for level in np.atleast_1d(extreme.index[0]))
            return None, (f"every answer in cell {cell} is {'right' if extreme.iloc[0] else 'wrong'}"
                          f" (its log-odds are infinite: separation)")
        model = GEE.from_formula(formula, groups="g", data=frame, family=Binomial(),
                                 cov_struct=Exchangeable())
        result = model.fit(cov_type="bias_reduced")
        return result, "" if result.converged else "the estimating equations did not converge"

    return _fitted(GEE_TEST, data, dv, within, subject, max_trials,
                   "statsmodels GEE, binomial family, logit link, exchangeable working "
                   "correlation within participant, Mancl-DeRouen bias-reduced sandwich "
                   "covariance", fit)


def fit_mixed_model(data: pd.DataFrame, *, dv: str, within: str | Sequence[str], subject: str,
                    max_trials: int | None = MAX_MODEL_TRIALS) -> ModelFit:
    """The linear mixed model of :func:`mixed_model`, fitted (its results, cell means,
    warnings)."""
    from statsmodels.regression.mixed_linear_model import MixedLM

    def fit(frame: pd.DataFrame, formula: str):
        result = MixedLM.from_formula(formula, groups="g", data=frame).fit(reml=True,
                                                                           method="powell")
        return result, "" if result.converged else "the REML fit did not converge"

    return _fitted(MIXED_TEST, data, dv, within, subject, max_trials,
                   "statsmodels MixedLM, a random intercept per participant, REML (Powell's "
                   "optimiser), Wald tests from the fixed effects' model-based covariance", fit)


def model_rows(fit: ModelFit) -> pd.DataFrame:
    """One Wald chi-square row per effect of a fitted model (statsmodels ``wald_test_terms``;
    the intercept left out), or rows without numbers saying why there is no test.

    Returns:
        :data:`realpen.stats.results.TEST_COLUMNS` (statistic ``chi2``, ``df1``, ``n``
        participants), then ``effect``, ``trials``, ``converged``, ``subset``, ``warnings``
        and, for the mixed model, ``participant_var`` (the random intercept's variance) and
        ``residual_var``.
    """
    n, trials = fit.data["g"].nunique(), len(fit.data)
    extra: dict[str, object] = dict(trials=trials, converged=True, subset=fit.subset,
                                    warnings="; ".join(fit.warnings))
    if fit.test == MIXED_TEST:
        extra.update(participant_var=math.nan, residual_var=math.nan)
    failure = fit.failure
    if fit.result is not None and not failure:
        if fit.test == MIXED_TEST:
            extra.update(participant_var=float(fit.result.cov_re.iloc[0, 0]),
                         residual_var=float(fit.result.scale))
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                table = fit.result.wald_test_terms(skip_single=False, scalar=True).table
        except (ValueError, np.linalg.LinAlgError) as error:
            # e.g. every trial with the same value: the covariance has no usable dimensions
            failure = f"no Wald test ({error})"
        else:
            rows = [_result_row(fit.test, _STATISTIC, float(row["statistic"]),
                                float(row["pvalue"]), n=n, method=fit.described,
                                df1=float(row["df_constraint"]),
                                effect=_effect_name(str(term), fit.factors), **extra)
                    for term, row in table.iterrows() if term != "Intercept"]
            if all(math.isfinite(row["statistic"]) and row["statistic"] >= 0 for row in rows):
                return tidy(rows)
            failure = "the Wald tests are not finite or are negative (a singular covariance)"
    extra.update(converged=False)
    return tidy([_result_row(fit.test, _STATISTIC, math.nan, math.nan, n=n,
                             method=f"{failure}: no test; {fit.described}", effect=term, **extra)
                 for term in _terms(fit.factors, fit.crossed)])


def binomial_gee(data: pd.DataFrame, *, dv: str, within: str | Sequence[str], subject: str,
                 max_trials: int | None = MAX_MODEL_TRIALS) -> pd.DataFrame:
    """A binomial GEE of 0/1 trial outcomes over the within factors, Wald chi2 per effect.

    ``dv ~ f1 * f2 ...`` (sum-to-zero contrasts; main effects only when the cells are not fully
    crossed) by :class:`statsmodels.genmod.generalized_estimating_equations.GEE`: binomial
    family, logit link, an exchangeable working correlation within each subject, and Mancl and
    DeRouen's bias-reduced sandwich covariance (``cov_type="bias_reduced"``). Each effect's
    Wald chi-square is statsmodels' ``wald_test_terms``. :func:`fit_binomial_gee` gives the
    fitted model itself.

    Args:
        data: long format, one row per trial.
        dv: the trial's outcome column (1 right, 0 wrong).
        within: the factor column(s).
        subject: the participant column (the GEE's groups).
        max_trials: fit on the first subjects whose trials fit in this many (None: all).

    Returns:
        One row per effect (:func:`model_rows`): test ``"binomial GEE"``, statistic ``chi2``.
        A fit that does not converge has NaN statistics and says so in ``method``.

    Raises:
        ParameterError: ``data`` lacks a column or names no factor.

    Examples:
        >>> import numpy as np, pandas as pd
        >>> from realpen.stats.trial_models import binomial_gee
        >>> rng = np.random.default_rng(1)
        >>> data = pd.DataFrame({"participant": np.repeat(np.arange(20), 40),
        ...                      "modality": np.tile(["tactile", "audio-tactile"], 400)})
        >>> data["correct"] = (rng.random(800) < np.where(data["modality"] == "tactile",
        ...                                               0.4, 0.8)).astype(float)
        >>> row = binomial_gee(data, dv="correct", within="modality",
        ...                    subject="participant").iloc[0]
        >>> print(row.effect, f"chi2({row.df1:.0f}) = {row.statistic:.1f}", row.p < 0.001)
        modality chi2(1) = 82.8 True
    """
    return model_rows(fit_binomial_gee(data, dv=dv, within=within, subject=subject,
                                       max_trials=max_trials))


def mixed_model(data: pd.DataFrame, *, dv: str, within: str | Sequence[str], subject: str,
                max_trials: int | None = MAX_MODEL_TRIALS) -> pd.DataFrame:
    """A linear mixed model of ``dv`` over the within factors with a random intercept per
    subject, Wald chi2 per effect.

    ``dv ~ f1 * f2 ...`` (sum-to-zero contrasts; main effects only when the cells are not fully
    crossed) + a random intercept per subject by
    :class:`statsmodels.regression.mixed_linear_model.MixedLM`, fitted by REML with Powell's
    derivative-free optimiser (the gradient optimisers fail when the participants' variance is
    about 0, as it may be), each effect's Wald chi-square from the fixed effects' model-based
    covariance (statsmodels' ``wald_test_terms``). :func:`fit_mixed_model` gives the fitted
    model itself.

    Args:
        data: long format, one row per trial.
        dv: the response (e.g. ``log_rt``, the natural log of a response time in ms).
        within: the factor column(s).
        subject: the participant column (the random intercept's groups).
        max_trials: fit on the first subjects whose trials fit in this many (None: all).

    Returns:
        One row per effect (:func:`model_rows`): test ``"linear mixed model"``, statistic
        ``chi2``, with ``participant_var`` and ``residual_var``. A fit that does not converge
        has NaN statistics and says so in ``method``.

    Raises:
        ParameterError: ``data`` lacks a column or names no factor.

    Examples:
        >>> import numpy as np, pandas as pd
        >>> from realpen.stats.trial_models import mixed_model
        >>> rng = np.random.default_rng(2)
        >>> data = pd.DataFrame({"participant": np.repeat(np.arange(12), 30),
        ...                      "pen": np.tile(["pencil", "ballpoint", "marker"], 120)})
        >>> data["log_rt"] = (8.0 + np.repeat(rng.normal(0, 0.3, 12), 30)
        ...                   + np.where(data["pen"] == "marker", 0.2, 0.0)
        ...                   + rng.normal(0, 0.4, 360))
        >>> row = mixed_model(data, dv="log_rt", within="pen", subject="participant").iloc[0]
        >>> print(row.effect, f"chi2({row.df1:.0f})", row.p < 0.01, row.converged)
        pen chi2(2) True True
    """
    return model_rows(fit_mixed_model(data, dv=dv, within=within, subject=subject,
                                      max_trials=max_trials))


def trial_model_tests(trials: Trials, outcome: Outcome, participants: Sequence[str],
                      notes: list[str], *, max_trials: int | None = MAX_MODEL_TRIALS
                      ) -> list[pd.DataFrame]:
    """The trial-level model of a study outcome as result rows, beside its participant-level
    RM-ANOVA.

    ``recognition``: :func:`binomial_gee` (analysis ``gee/<outcome>``); ``log_rt``:
    :func:`mixed_model` (analysis ``mixedlm/<outcome>``); other outcomes, or one without
    within factors, get none. Each row's ``method`` names the model and its covariance and
    says why the participant-level test is the primary one (:data:`PRIMARY_REASON`).

    Args:
        trials: the checked trials.
        outcome: the outcome (:func:`realpen.stats.data.outcomes`).
        participants: those complete in the outcome (the participant-level tests' own).
        notes: the analysis's notes, to which a fit that failed, was cut to
            ``max_trials`` or was warned about adds one line.
        max_trials: as :func:`binomial_gee`.

    Returns:
        A list of one DataFrame in :data:`realpen.stats.results.RESULT_COLUMNS` (or empty).
    """
    if outcome.kind not in ("recognition", "log_rt") or not outcome.factors:
        return []
    data = outcome_trials(trials, outcome, participants)
    if data["participant"].nunique() < 2:
        return []
    if outcome.kind == "recognition":
        rows = binomial_gee(data, dv="correct", within=list(outcome.factors),
                            subject="participant", max_trials=max_trials)
        analysis, why = f"gee/{outcome.name}", (
            f"{PRIMARY_REASON} and its binomial nature (a 0/1 answer, not a bounded proportion)")
    else:
        rows = mixed_model(data, dv="log_rt", within=list(outcome.factors),
                           subject="participant", max_trials=max_trials)
        analysis, why = f"mixedlm/{outcome.name}", (
            f"{PRIMARY_REASON}, weighing each participant by their trials")
    model = rows["test"].iloc[0]
    if not rows["converged"].all():
        notes.append(f"{outcome.name}: the trial-level {model} gave no test: "
                     f"{rows['method'].iloc[0].split(': no test;')[0]}")
    elif rows["subset"].iloc[0]:
        notes.append(f"{outcome.name}: the trial-level {model} was {rows['subset'].iloc[0]}")
    boundary = [text for text in rows["warnings"].iloc[0].split("; ") if "boundary" in text]
    if boundary and rows["converged"].all():
        notes.append(f"{outcome.name}: in the trial-level {model} the participants' variance is "
                     "estimated at about 0 (on the boundary): participants barely differ beyond "
                     "the trials' own variation, and the model is then close to an ordinary "
                     "regression")
    rows["method"] = rows["method"] + "; " + why
    return [with_context(rows, analysis=analysis, outcome=outcome.name)]
