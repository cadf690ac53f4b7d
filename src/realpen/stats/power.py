"""Power before the study: how often a design's main tests would find an effect, by simulation.

- :func:`power_table` — the share of simulated studies (participants answering as a
  :class:`~realpen.stats.simulate.ResponseModel` says) whose main tests give p < 0.05, per
  outcome and number of participants;
- :func:`minimum_detectable_effect` — the smallest effect those tests find with a given power;
- :func:`friedman_batch`, :func:`rm_anova_batch` — the two tests on many simulated studies at
  once (vectorised numpy; each equals its library function, which a test checks).

The main tests, as the study analyses run them:

- every **Likert** question asked at two or more levels of the design's main within factor
  (its conditions, else its modalities; :func:`realpen.stats.simulate.main_factor`): the
  Friedman test over those levels on each participant's mean answer per level (training
  trials left out);
- every **recognition** question (a choice with ``correct: pen``): the one-way
  repeated-measures ANOVA over modalities of each participant's proportion correct per modality
  (experimental trials), judged on its Greenhouse–Geisser-corrected p (never more liberal than
  the uncorrected p, so the power is not overstated where sphericity fails).

Speed: a simulated study is drawn as the cell values the tests see (each participant's mean
answer or proportion correct per level), not as trial rows: the same model and the same draws
per answer as :func:`realpen.stats.simulate.simulated_trials` (Likert: the participant's
offset, the level's effect, ``N(0, 1)`` noise, the same cut points; recognition: a uniform draw
below the pen's rate per trial), so the cells have the same distribution as those of simulated
trials, and a test compares them. The tests then run on thousands of studies in one numpy call;
``friedman_batch`` and ``rm_anova_batch`` give the p of scipy.stats.friedmanchisquare (the
Friedman of :mod:`realpen.stats.nonparametric`) and of pingouin.rm_anova with
``correction=True`` (``p_GG_corr``; :mod:`realpen.stats.anova`) within 1e-9 relative on random
data (tests/test_stats_power.py). 2000 studies × 4 sample sizes of study 2 take well under a
second.

Every simulated study draws from ``SeedSequence([seed, participants, outcome, chunk])`` (numpy
PCG64; chunks of 250 studies), never from the effect: every effect is simulated with the same
draws (common random numbers), so power changes smoothly with the effect, and the power
:func:`minimum_detectable_effect` reports is what :func:`power_table` gives for that effect
with the same ``sims`` and ``seed``.

References:
    Arnold, B. F., Hogan, D. R., Colford, J. M., & Hubbard, A. E. (2011). Simulation methods to
    estimate design power: an overview for applied research. BMC Medical Research Methodology,
    11, 94. https://doi.org/10.1186/1471-2288-11-94

    Friedman, M. (1937). The use of ranks to avoid the assumption of normality implicit in the
    analysis of variance. Journal of the American Statistical Association, 32(200), 675–701.
    https://doi.org/10.1080/01621459.1937.10503522

    Greenhouse, S. W., & Geisser, S. (1959). On methods in the analysis of profile data.
    Psychometrika, 24(2), 95–112. https://doi.org/10.1007/BF02289823
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd
from scipy import stats

from realpen.checks import require_number
from realpen.errors import ParameterError
from realpen.stats.simulate import (
    ResponseModel,
    check_inputs,
    level_of,
    level_positions,
    likert_cuts,
    main_factor,
    pen_rate,
)
from realpen.study.design import Design
from realpen.study.plan import MAX_PARTICIPANTS, participant_plan

__all__ = ["power_table", "minimum_detectable_effect", "friedman_batch", "rm_anova_batch",
           "POWER_COLUMNS", "MDE_COLUMNS", "ALPHA", "MAX_LIKERT_EFFECT", "RATE_STEP",
           "EFFECT_STEP", "MAX_SIMS"]

POWER_COLUMNS = ("outcome", "effect", "test", "participants", "effect_size", "power", "sims")
"""The columns of :func:`power_table`."""
MDE_COLUMNS = ("outcome", "test", "participants", "parameter", "minimum_effect", "power", "note")
"""The columns of :func:`minimum_detectable_effect`."""
ALPHA = 0.05
"""A simulated study finds the effect when the test's p is below this."""
MAX_LIKERT_EFFECT = 3.0
"""The top of the Likert effect's search range (latent SDs)."""
EFFECT_STEP = 0.01
"""The Likert effect's grid step (latent SDs)."""
RATE_STEP = 0.005
"""The recognition rate spread's grid step (proportion)."""
MAX_SIMS = 1_000_000
_CHUNK = 250  # studies per draw: bounded memory; results do not depend on it across calls
_TESTS = {"likert": "Friedman", "recognition": "RM-ANOVA"}


# ---- the two tests on many studies at once ---------------------------------------------------

def friedman_batch(values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The Friedman test of many studies at once: ``values[..., subject, level]``.

    Ranks within each subject (average ranks for ties: scipy.stats.rankdata), the tie-corrected
    chi-squared statistic ``(12/(n k (k+1)) Σ R_j² − 3 n (k+1)) / (1 − Σ(t³ − t)/(n k (k²−1)))``
    and its p from the chi-squared distribution with ``k − 1`` df (scipy.stats.chi2.sf): the
    computation of scipy.stats.friedmanchisquare (which needs k ≥ 3) and pingouin.friedman
    (k ≥ 2), vectorised over the leading axes (a test checks chi2 and p within 1e-9 relative
    against both). A study whose every subject ties every level has NaN.

    Args:
        values: an array ``(..., n subjects, k levels)``, n ≥ 2, k ≥ 2.

    Returns:
        ``(chi2, p)``, each of the leading shape.

    References:
        Friedman, M. (1937). https://doi.org/10.1080/01621459.1937.10503522

    Examples:
        >>> x = np.array([[1, 2, 3], [2, 1, 3], [1, 3, 2], [1, 2, 3]], float)
        >>> chi2, p = friedman_batch(x)
        >>> round(float(chi2), 4), round(float(p), 4)
        (4.5, 0.1054)
    """
    values = np.asarray(values, dtype=float)
    n, k = values.shape[-2:]
    ranks = stats.rankdata(values, axis=-1)
    # Σ over tie groups of t³ − t is Σ over values of (t² − 1), t the size of the value's group.
    group = (values[..., :, None] == values[..., None, :]).sum(axis=-1)
    ties = (group * group - 1).sum(axis=(-2, -1))
    correction = 1.0 - ties / (k * (k * k - 1.0) * n)
    rank_sums = ranks.sum(axis=-2)
    with np.errstate(divide="ignore", invalid="ignore"):
        chi2 = (12.0 / (k * n * (k + 1)) * (rank_sums ** 2).sum(axis=-1) - 3.0 * n * (k + 1)) \
            / correction
        chi2 = np.where(correction > 0, chi2, np.nan)
    return chi2, stats.chi2.sf(chi2, k - 1)


def rm_anova_batch(values: np.ndarray) -> dict[str, np.ndarray]:
    """The one-way repeated-measures ANOVA of many studies at once: ``values[..., subject, level]``.

    ``F = MS_levels / MS_error`` with ``k − 1`` and ``(n − 1)(k − 1)`` df (the error being the
    subject × level residual), its p (scipy.stats.f.sf), the Greenhouse–Geisser ε (from the
    double-centred covariance matrix of the levels: ``tr(S)² / ((k − 1) Σ S_ij²)``) and the
    corrected p with both df times ε: the numbers of pingouin.rm_anova (``p_unc``, ``eps``,
    ``p_GG_corr``, ``correction=True``) and statsmodels' AnovaRM (F, p), vectorised over the
    leading axes (a test checks p within 1e-9 relative). A study with no residual variance gets
    F = inf (p = 0) when its level means differ and NaN when they do not.

    Args:
        values: an array ``(..., n subjects, k levels)``, n ≥ 2, k ≥ 2.

    Returns:
        ``{"F", "p", "eps", "p_gg"}``, each of the leading shape; df1 = k − 1, df2 = (n − 1)(k − 1).

    References:
        Greenhouse, S. W., & Geisser, S. (1959). https://doi.org/10.1007/BF02289823

    Examples:
        >>> x = np.array([[1, 2, 4], [2, 2, 5], [1, 3, 3], [2, 4, 6]], float)
        >>> out = rm_anova_batch(x)
        >>> round(float(out["F"]), 3), round(float(out["p"]), 4), round(float(out["p_gg"]), 4)
        (17.211, 0.0033, 0.0077)
    """
    values = np.asarray(values, dtype=float)
    n, k = values.shape[-2:]
    grand = values.mean(axis=(-2, -1), keepdims=True)
    level_means = values.mean(axis=-2, keepdims=True)
    subject_means = values.mean(axis=-1, keepdims=True)
    ss_levels = n * ((level_means - grand) ** 2).sum(axis=(-2, -1))
    residual = values - level_means - subject_means + grand
    ss_error = (residual ** 2).sum(axis=(-2, -1))
    df1, df2 = k - 1.0, (n - 1.0) * (k - 1.0)
    centred = values - level_means
    covariance = np.einsum("...ni,...nj->...ij", centred, centred) / (n - 1.0)
    covariance = covariance - covariance.mean(axis=-1, keepdims=True) \
        - covariance.mean(axis=-2, keepdims=True) + covariance.mean(axis=(-2, -1), keepdims=True)
    with np.errstate(divide="ignore", invalid="ignore"):
        f = (ss_levels / df1) / (ss_error / df2)
        eps = np.trace(covariance, axis1=-2, axis2=-1) ** 2 / (df1 * (covariance ** 2).sum(axis=(-2, -1)))
    return {"F": f, "p": stats.f.sf(f, df1, df2), "eps": eps,
            "p_gg": stats.f.sf(f, df1 * eps, df2 * eps)}


# ---- what is tested ---------------------------------------------------------------------------

@dataclass(frozen=True)
class _Outcome:
    """One main test of a design: its outcome, the levels it compares, and per participant how
    many answers each cell is made of (Likert: per level; recognition: per level and pen)."""

    name: str
    kind: str
    question: str
    factor: str
    levels: tuple[str, ...]
    positions: tuple[float, ...]
    counts: tuple[tuple[int, ...], ...]
    points: int = 0


def _outcomes(design: Design) -> list[_Outcome]:
    """The design's main tests, from participant 0's plan (every participant's plan has the same
    trials, in another order)."""
    factor, levels = main_factor(design)
    positions = level_positions(len(levels))
    modalities = tuple(design.modalities)
    pens = [pen.id for pen in design.pens]
    plan = [trial for trial in participant_plan(design, 0) if trial.phase != "training"]
    recognition = [q for q in design.questions if q.type == "choice" and q.correct == "pen"]
    found = []
    for question in design.questions:
        if question.type == "likert":
            counts = [0] * len(levels)
            for trial in plan:
                level = level_of(trial, factor, levels)
                if question.id in trial.questions and level is not None:
                    counts[level] += 1
            used = [i for i, count in enumerate(counts) if count]
            if len(used) >= 2:
                found.append(_Outcome(question.id, "likert", question.id, factor,
                                      tuple(levels[i] for i in used),
                                      tuple(float(positions[i]) for i in used),
                                      tuple((counts[i],) for i in used), question.points or 2))
        elif question in recognition:
            counts = [[0] * len(pens) for _ in modalities]
            for trial in plan:
                if question.id in trial.questions and trial.modality in modalities and \
                        trial.pen in pens:
                    counts[modalities.index(trial.modality)][pens.index(trial.pen)] += 1
            used = [i for i, row in enumerate(counts) if sum(row)]
            if len(used) >= 2:
                name = "recognition" if len(recognition) == 1 else f"recognition:{question.id}"
                found.append(_Outcome(name, "recognition", question.id, "modality",
                                      tuple(modalities[i] for i in used),
                                      tuple(level_positions(len(used)).tolist()),
                                      tuple(tuple(counts[i]) for i in used)))
    return found


def _cells(outcome: _Outcome, model: ResponseModel, rng: np.random.Generator, sims: int,
           n: int, pens: int) -> np.ndarray:
    """``sims`` studies' cell values ``(sims, n, levels)``: each participant's mean Likert answer,
    or proportion correct, per level (the model of :mod:`realpen.stats.simulate`)."""
    cells = np.empty((sims, n, len(outcome.levels)))
    if outcome.kind == "likert":
        cuts = likert_cuts(outcome.points, model.participant_sd)
        offsets = rng.normal(0.0, model.participant_sd, (sims, n, 1))
        for index, ((count,), position) in enumerate(zip(outcome.counts, outcome.positions)):
            latent = offsets + model.effect * position + rng.normal(size=(sims, n, count))
            cells[..., index] = (np.searchsorted(cuts, latent) + 1).mean(axis=-1)
        return cells
    for index, (level, per_pen) in enumerate(zip(outcome.levels, outcome.counts)):
        right = np.zeros((sims, n))
        for pen, count in enumerate(per_pen):
            if count:
                rate = pen_rate(model.rates[level], pen, pens, model.pen_effect)
                right += (rng.random((sims, n, count)) < rate).sum(axis=-1)
        cells[..., index] = right / sum(per_pen)
    return cells


def _p_values(outcome: _Outcome, cells: np.ndarray) -> np.ndarray:
    if outcome.kind == "likert":
        return friedman_batch(cells)[1]
    return rm_anova_batch(cells)["p_gg"]


def _generator(*key: int) -> np.random.Generator:
    return np.random.Generator(np.random.PCG64(np.random.SeedSequence(list(key))))


def _found(outcome: _Outcome, index: int, model: ResponseModel, n: int, chunk: int, size: int,
           seed: int, pens: int) -> int:
    """How many of chunk ``chunk``'s ``size`` simulated studies find the effect (p < ALPHA)."""
    rng = _generator(seed, n, index, chunk)
    with np.errstate(invalid="ignore"):
        return int((_p_values(outcome, _cells(outcome, model, rng, size, n, pens)) < ALPHA).sum())


def _chunks(sims: int) -> list[tuple[int, int]]:
    return [(chunk, min(_CHUNK, sims - start)) for chunk, start in enumerate(range(0, sims, _CHUNK))]


def _power(outcome: _Outcome, index: int, model: ResponseModel, n: int, sims: int, seed: int,
           pens: int) -> float:
    return sum(_found(outcome, index, model, n, chunk, size, seed, pens)
               for chunk, size in _chunks(sims)) / sims


def _effect_size(outcome: _Outcome, model: ResponseModel) -> float:
    if outcome.kind == "likert":
        return model.effect
    rates = [model.rates[level] for level in outcome.levels]
    return max(rates) - min(rates)


# ---- checks ----------------------------------------------------------------------------------

def _check_size(parameter: str, value: object, minimum: int, maximum: int) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise ParameterError(parameter, f"must be a whole number, got {value!r}")
    require_number(parameter, int(value), minimum=minimum, maximum=maximum)
    return int(value)


def _prepare(design: Design, model: ResponseModel | None, seed: int, sims: int
             ) -> tuple[ResponseModel, list[_Outcome]]:
    model = ResponseModel() if model is None else model
    check_inputs(design, 2, model, seed)
    _check_size("sims", sims, 1, MAX_SIMS)
    outcomes = _outcomes(design)
    if not outcomes:
        raise ParameterError("design", f"{design.name!r} has no Likert question asked at two or "
                                       f"more levels and no recognition question over two or "
                                       f"more modalities: nothing to test")
    return model, outcomes


# ---- the public functions ---------------------------------------------------------------------

def power_table(design: Design, participants: Sequence[int], *, model: ResponseModel | None = None,
                sims: int = 2000, seed: int = 0,
                progress: Callable[[int, int], object] | None = None) -> pd.DataFrame:
    """The power of a design's main tests: the share of simulated studies with p < 0.05.

    For every number of participants, ``sims`` studies are simulated with ``model`` (the
    module doc says how, and which tests: Friedman per Likert question over the main factor,
    the repeated-measures ANOVA of recognition over modalities with Greenhouse–Geisser p), and
    each test counts the studies in which it finds its effect. The Monte Carlo standard error
    of a power ``P`` is ``sqrt(P (1 − P) / sims)`` (about 0.01 at ``sims=2000``).

    Args:
        design: the study design (:func:`realpen.study.design.load_design`).
        participants: the numbers of participants to simulate, each 2..1000.
        model: how the participants answer; default ``ResponseModel()`` (no Likert effect, the
            paper's recognition rates).
        sims: simulated studies per number of participants, 1..1,000,000.
        seed: the simulation's seed, 0..2⁶³−1.
        progress: called as ``progress(done, total)`` with the simulated studies done so far
            (after every 250 of them) and the total, ``sims × len(participants)``.

    Returns:
        One row per outcome (design order) and number of participants (as given), columns
        :data:`POWER_COLUMNS`: ``outcome`` (a Likert question's id, or ``recognition``),
        ``effect`` (the factor tested: ``condition`` or ``modality``), ``test`` (``Friedman``
        or ``RM-ANOVA``), ``participants``, ``effect_size`` (what was simulated: Likert the
        model's ``effect`` in latent SDs; recognition the difference between the highest and
        the lowest rate, a proportion), ``power`` (0..1) and ``sims``.

    Raises:
        ParameterError: a bad argument, or a design with nothing to test.

    Examples:
        >>> from realpen.study.design import load_design
        >>> table = power_table(load_design("study1"), [12], model=ResponseModel(effect=1.5),
        ...                     sims=250)
        >>> table[["outcome", "test", "participants"]].values.tolist()
        [['Q1', 'Friedman', 12], ['Q2', 'Friedman', 12]]
        >>> bool((table["power"] > 0.5).all())
        True
    """
    model, outcomes = _prepare(design, model, seed, sims)
    if isinstance(participants, (str, bytes)) or not isinstance(participants, Sequence) or \
            not participants:
        raise ParameterError("participants", f"must be a list of numbers of participants, got "
                                             f"{participants!r}")
    sizes = [_check_size("participants", n, 2, MAX_PARTICIPANTS) for n in participants]
    if progress is not None and not callable(progress):
        raise ParameterError("progress", f"must be a function (done, total), got {progress!r}")
    pens, seed, sims = len(design.pens), int(seed), int(sims)
    found = np.zeros((len(sizes), len(outcomes)), dtype=int)
    total, done = sims * len(sizes), 0
    for row, n in enumerate(sizes):
        for chunk, size in _chunks(sims):
            for index, outcome in enumerate(outcomes):
                found[row, index] += _found(outcome, index, model, n, chunk, size, seed, pens)
            done += size
            if progress is not None:
                progress(done, total)
    rows = [(outcome.name, outcome.factor, _TESTS[outcome.kind], n,
             _effect_size(outcome, model), found[row, index] / sims, sims)
            for index, outcome in enumerate(outcomes) for row, n in enumerate(sizes)]
    return pd.DataFrame(rows, columns=list(POWER_COLUMNS))


def minimum_detectable_effect(design: Design, participants: int, *,
                              model: ResponseModel | None = None, power: float = 0.8,
                              sims: int = 500, seed: int = 0) -> pd.DataFrame:
    """The smallest effect each main test finds with the given power, by simulation.

    Each candidate is simulated as :func:`power_table` simulates it (the same draws for every
    candidate, so power rises smoothly with the effect); the search is a bisection over a
    monotone grid, assuming power rises with the effect:

    - Likert questions: ``effect`` (latent SDs between the last and the first level) from 0 to
      :data:`MAX_LIKERT_EFFECT` in steps of :data:`EFFECT_STEP`; the rest of ``model`` as given;
    - recognition: the rates spread evenly over the modalities in design order around the mean of
      ``model``'s rates for them, ``rate_spread`` (the highest minus the lowest rate) from 0 to
      the most that keeps every rate within 0..1 (``2 × min(mean, 1 − mean)``) in steps of
      :data:`RATE_STEP`.

    Args:
        design: the study design.
        participants: the number of participants, 2..1000.
        model: the rest of the model (participant SD, recognition rates' mean, pen effect).
        power: the power to reach, 0 < power < 1.
        sims: simulated studies per candidate effect.
        seed: the simulation's seed.

    Returns:
        One row per outcome, columns :data:`MDE_COLUMNS`: ``parameter`` (``effect`` or
        ``rate_spread``), ``minimum_effect`` (the smallest grid value whose simulated power is
        at least ``power``; NaN when even the top of the range is under-powered), ``power``
        (the simulated power there; at the top of the range when under-powered) and ``note``
        (``""``, or why the effect is NaN).

    Raises:
        ParameterError: a bad argument, or a design with nothing to test.

    Examples:
        >>> from realpen.study.design import load_design
        >>> found = minimum_detectable_effect(load_design("study1"), 12, sims=100)
        >>> found[["outcome", "parameter"]].values.tolist()
        [['Q1', 'effect'], ['Q2', 'effect']]
        >>> bool((found["power"] >= 0.8).all())
        True
    """
    model, outcomes = _prepare(design, model, seed, sims)
    n = _check_size("participants", participants, 2, MAX_PARTICIPANTS)
    require_number("power", power, minimum=0, maximum=1)
    if not 0 < power < 1:
        raise ParameterError("power", f"must be between 0 and 1 (exclusive), got {power:g}")
    pens, seed, sims = len(design.pens), int(seed), int(sims)
    rows = []
    for index, outcome in enumerate(outcomes):
        parameter, grid, candidate = _search_space(outcome, model)
        found, reached, note = _bisect(
            grid, power, lambda value, o=outcome, i=index, make=candidate:
            _power(o, i, make(value), n, sims, seed, pens))
        if note:
            unit = "latent SDs" if outcome.kind == "likert" else "(a proportion)"
            note = f"under-powered: {note} at {parameter} {grid[-1]:g} {unit}, the top of the search range"
        rows.append((outcome.name, _TESTS[outcome.kind], n, parameter, found, reached, note))
    return pd.DataFrame(rows, columns=list(MDE_COLUMNS))


def _search_space(outcome: _Outcome, model: ResponseModel
                  ) -> tuple[str, np.ndarray, Callable[[float], ResponseModel]]:
    """The parameter searched for an outcome, its grid (rising) and the model of a grid value."""
    if outcome.kind == "likert":
        grid = np.round(np.arange(round(MAX_LIKERT_EFFECT / EFFECT_STEP) + 1) * EFFECT_STEP, 10)
        return "effect", grid, lambda value: dataclasses.replace(model, effect=float(value))
    mean = float(np.mean([model.rates[level] for level in outcome.levels]))
    top = 2.0 * min(mean, 1.0 - mean)
    grid = np.round(np.arange(math.floor(top / RATE_STEP + 1e-9) + 1) * RATE_STEP, 10)

    def spread(value: float) -> ResponseModel:
        rates = {level: min(1.0, max(0.0, mean + value * position))
                 for level, position in zip(outcome.levels, outcome.positions)}
        return dataclasses.replace(model, rates={**model.rates, **rates})

    return "rate_spread", grid, spread


def _bisect(grid: np.ndarray, target: float, power_at: Callable[[float], float]
            ) -> tuple[float, float, str]:
    """The smallest grid value whose power reaches ``target`` (power assumed to rise along the
    grid), its power, and ``""``; or NaN, the power at the top and a note when the top falls
    short."""
    low, high = 0, len(grid) - 1
    reached = power_at(grid[high])
    if reached < target:
        return math.nan, reached, f"power {reached:.2f} even"
    low_power = power_at(grid[low])
    if low_power >= target:
        return float(grid[low]), low_power, ""
    while high - low > 1:
        middle = (low + high) // 2
        middle_power = power_at(grid[middle])
        if middle_power >= target:
            high, reached = middle, middle_power
        else:
            low = middle
    return float(grid[high]), reached, ""


# ---- for the command line and the report ----------------------------------------------------

def parse_rates(text: str) -> dict[str, float]:
    """Recognition rates written ``tactile=0.43,auditory=0.51`` as ``{modality: rate}``.

    >>> parse_rates("tactile=0.43, auditory=.5")
    {'tactile': 0.43, 'auditory': 0.5}
    """
    rates: dict[str, float] = {}
    for part in (piece.strip() for piece in text.split(",")):
        name, sep, value = part.partition("=")
        try:
            rate = float(value) if sep and name.strip() else math.nan
        except ValueError:
            rate = math.nan
        if not 0 <= rate <= 1:
            raise ParameterError("rates", f"give modality=rate pairs with rates from 0 to 1, "
                                          f"e.g. tactile=0.43,auditory=0.51; got {part!r}")
        rates[name.strip()] = rate
    return rates


def response_model(*, effect: float = 0.0, rates: str | None = None) -> ResponseModel:
    """The :class:`ResponseModel` of a Likert ``effect`` (latent SDs) and ``rates`` written as
    :func:`parse_rates` reads them (None: the paper's)."""
    if rates is None:
        return ResponseModel(effect=effect)
    return ResponseModel(effect=effect, rates=parse_rates(rates))


def power_lines(table: pd.DataFrame) -> list[str]:
    """:func:`power_table`'s rows as aligned text lines for a terminal."""
    header = f"{'outcome':<12} {'test':<9} {'factor':<10} {'effect':>14} {'participants':>12} " \
             f"{'power':>6}"
    lines = [header]
    for row in table.itertuples(index=False):
        unit = "SD" if row.test == _TESTS["likert"] else "rate diff"
        effect = f"{row.effect_size:.3g} {unit}"
        lines.append(f"{row.outcome:<12} {row.test:<9} {row.effect:<10} {effect:>14} "
                     f"{row.participants:>12d} {row.power:>6.3f}")
    lines.append("effect: for ratings, the difference between the highest and the lowest level "
                 "in SDs of a participant's latent rating; for recognition, the highest minus "
                 "the lowest rate")
    lines.append(f"power: the share of {int(table['sims'].iloc[0])} simulated studies with "
                 f"p < {ALPHA:g}; Monte Carlo SE about sqrt(power (1 - power) / sims)")
    return lines


def report_power(participants: int, design: Design, *, sims: int = 200, seed: int = 0,
                 progress: Callable[[int, int], object] | None = None) -> pd.DataFrame:
    """The smallest effects a study of ``participants`` could detect with 80 % power
    (:func:`minimum_detectable_effect` under the default :class:`ResponseModel`), for the
    report of a finished study.

    A study of more than :data:`realpen.study.plan.MAX_PARTICIPANTS` participants (which a
    trials CSV may hold) is not simulated: each outcome's row says so in ``note``, with NaN
    effect and power (at that size every main test detects far smaller effects than a lab
    study's, and the simulation would take minutes)."""
    if progress is not None:
        progress(0, 1)
    if not _outcomes(design):  # nothing varies: no test, so no effect to detect
        if progress is not None:
            progress(1, 1)
        return pd.DataFrame(columns=list(MDE_COLUMNS))
    if isinstance(participants, (int, np.integer)) and participants > MAX_PARTICIPANTS:
        _, outcomes = _prepare(design, None, seed, sims)
        note = (f"not simulated: {participants:,} participants, more than the "
                f"{MAX_PARTICIPANTS:,} the power simulation covers")
        rows = [(outcome.name, _TESTS[outcome.kind], int(participants),
                 "effect" if outcome.kind == "likert" else "rate_spread", math.nan, math.nan,
                 note) for outcome in outcomes]
        found = pd.DataFrame(rows, columns=list(MDE_COLUMNS))
        if progress is not None:
            progress(1, 1)
        return found
    found = minimum_detectable_effect(design, participants, sims=sims, seed=seed)
    if progress is not None:
        progress(1, 1)
    return found
