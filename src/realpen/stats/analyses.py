"""The analyses of a study: from checked trials (:mod:`realpen.stats.data`) to a
:class:`~realpen.stats.outcome.StudyAnalysis`.

Every design gets the within-subject analysis of its outcomes (:func:`realpen.stats.data.outcomes`):

- a **Likert** outcome: a Friedman test per factor (on each participant's mean over the other
  factors), Wilcoxon signed-rank tests of every pair of levels (p by the named method,
  adjusted over the pairs) — a factor of two levels gets the Wilcoxon signed-rank test of its
  pair only (a Friedman test of two levels is a sign test) — and with two factors the aligned
  rank transform for their interaction. When the conditions are a full factorial of tactile
  counts (study 1: 5, 10 or 15 principal frequencies × 15 sub-patterns or one), the
  conditions are also split into
  ``superposition`` and ``fluctuation``, each tested "blocked by" the other in the named
  variant (:data:`FRIEDMAN_VARIANTS`);
- the factors are the design's (:func:`realpen.stats.data.outcomes`: crossed, nested in another
  or constant), and the methods say which each outcome has;
- **recognition** (the proportion of right answers per participant and cell) and **log_rt**
  (the mean of ln RT per participant and cell): a repeated-measures ANOVA over the factors
  with Mauchly's test and Greenhouse–Geisser rows, and Bonferroni-adjusted paired t-tests per
  factor, as the paper did — but with participants, not repetitions, as subjects; beside them
  a trial-level model (:mod:`realpen.stats.trial_models`: a binomial GEE, a linear mixed model
  of log RT) as the check that uses every trial, and for recognition the rate against chance
  per level of each factor (:mod:`realpen.stats.chance`).

``--paper-compatible`` adds the paper's own choices beside these, each row's ``method``
starting with ``paper-compatible:`` and saying why it is not recommended.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import asdict, dataclass

import numpy as np
import pandas as pd

from realpen.errors import ParameterError, RealPenError, fail
from realpen.stats.anova import pairwise, rm_anova
from realpen.stats.art import aligned_rank_transform
from realpen.stats.chance import recognition_chance
from realpen.stats.data import (
    ANSWER_KEY,
    Outcome,
    Trials,
    cell_values,
    factor_text,
    outcome_rows,
    outcomes,
)
from realpen.stats.intervals import cell_cis
from realpen.stats.multiplicity import ADJUSTMENTS, adjusted_p
from realpen.stats.nonparametric import friedman
from realpen.stats.outcome import CELL_COLUMNS, CONFUSION_COLUMNS, PARTICIPANT_COLUMNS, StudyAnalysis
from realpen.stats.paper import paper_numbers
from realpen.stats.results import RESULT_COLUMNS, with_context
from realpen.stats.texts import methods_paragraphs
from realpen.stats.trial_models import trial_model_tests

__all__ = ["AnalysisOptions", "analyse", "IncompleteError", "FRIEDMAN_VARIANTS",
           "WILCOXON_METHODS", "ADJUSTMENTS", "CI_METHODS", "SUPERPOSITION", "FLUCTUATION"]

FRIEDMAN_VARIANTS = {
    "average": "(a) each participant's mean over the other factor's levels: one block per "
               "participant",
    "cells": "(b) participant × level of the other factor as blocks (blocks of one participant "
             "are not independent: liberal)",
    "per-level": "(c) one test per level of the other factor",
}
"""What "a Friedman test of one factor blocked by the other" is reduced to; named in every
output."""
WILCOXON_METHODS = ("exact", "r", "spss")
CI_METHODS = ("t", "bootstrap")
SUPERPOSITION = "superposition"
FLUCTUATION = "fluctuation"
_PAPER_WILCOXON = ("paper-compatible: SPSS-style p (normal approximation without continuity "
                   "correction), as the paper's SPSS analysis; not recommended: with a dozen "
                   "tied Likert pairs the normal approximation is poor, use the exact p")
_TWO_LEVELS = ("two levels: the Wilcoxon signed-rank test of the pair is the test of the factor "
               "(a Friedman test of two levels is a sign test, which ignores the size of the "
               "differences)")
_PAPER_PSEUDO = ("paper-compatible: the repetitions of each participant treated as separate "
                 "subjects ({subjects} pseudo-subjects), which the paper's degrees of freedom "
                 "imply; not recommended: repetitions of one person are not independent, so "
                 "the degrees of freedom are inflated and the p-values too small "
                 "(pseudo-replication, Hurlbert 1984)")


class IncompleteError(RealPenError):
    """A participant misses a planned cell and ``exclude_incomplete`` is off; the message
    names the file, the participant and the cell (the caller says how to go on)."""


@dataclass(frozen=True)
class AnalysisOptions:
    """How ``realpen stats`` analyses (defaults: the recommended analysis).

    Attributes:
        paper_compatible: also give the paper's own choices, marked.
        wilcoxon_method: ``exact``, ``r`` or ``spss`` (:func:`realpen.stats.nonparametric.wilcoxon`).
        adjust: the adjustment of the Wilcoxon post hoc p over each outcome's pairs.
        friedman_variant: a key of :data:`FRIEDMAN_VARIANTS`.
        likert_ci: ``bootstrap`` (BCa, the default for Likert means) or ``t``.
        confidence: of every interval (0.95).
        exclude_incomplete: leave out participants missing a planned cell (else refuse).
        seed: of the bootstrap.
    """

    paper_compatible: bool = False
    wilcoxon_method: str = "exact"
    adjust: str = "holm"
    friedman_variant: str = "average"
    likert_ci: str = "bootstrap"
    confidence: float = 0.95
    exclude_incomplete: bool = False
    seed: int = 0

    def __post_init__(self) -> None:
        for name, allowed in (("wilcoxon_method", WILCOXON_METHODS), ("adjust", ADJUSTMENTS),
                              ("friedman_variant", tuple(FRIEDMAN_VARIANTS)),
                              ("likert_ci", CI_METHODS)):
            if getattr(self, name) not in allowed:
                raise ParameterError(name, f"must be one of {', '.join(allowed)}, got "
                                           f"{getattr(self, name)!r}")
        if not 0.5 <= self.confidence < 1:
            raise ParameterError("confidence", f"must be in [0.5, 1), got {self.confidence}")


def analyse(trials: Trials, options: AnalysisOptions = AnalysisOptions()) -> StudyAnalysis:
    """Run every analysis of ``trials``' design.

    Raises:
        IncompleteError: a participant misses a planned cell (without
            ``exclude_incomplete``; the line names the file, the participant and the cell).
        RealPenError: fewer than two participants are complete in an outcome.
    """
    design = trials.design
    found = outcomes(design)
    if not found:
        raise fail(trials.source, f"design '{design.name}' asks no rating or recognition "
                                  f"question: nothing to analyse")
    values: dict[str, pd.DataFrame] = {}
    missing: dict[str, dict[str, str]] = {}
    for outcome in found:
        values[outcome.name], missing[outcome.name] = cell_values(trials, outcome)
    incomplete: dict[str, list[str]] = {}
    for outcome in found:
        for participant, reason in missing[outcome.name].items():
            incomplete.setdefault(participant, []).append(reason)
    if incomplete and not options.exclude_incomplete:
        participant, reasons = next(iter(incomplete.items()))
        more = f" ({len(incomplete) - 1} more incomplete)" if len(incomplete) > 1 else ""
        raise IncompleteError(f"{trials.source}: participant {participant}: {reasons[0]}{more}")
    parts: list[pd.DataFrame] = []
    cells: list[pd.DataFrame] = []
    lines: list[pd.DataFrame] = []
    notes: list[str] = list(trials.notes)
    kept: dict[str, list[str]] = {}
    factorial = _tactile_factorial(design)
    for outcome in found:
        # Each outcome keeps every participant complete in it: one skipped question does not
        # take a participant out of the others.
        kept[outcome.name] = [p for p in trials.participants if p not in missing[outcome.name]]
        if len(kept[outcome.name]) < 2:
            count = len(kept[outcome.name])
            raise fail(trials.source, f"{count} participant{'s' if count != 1 else ''} of study "
                                      f"'{design.name}' complete in {outcome.name}: at least 2 "
                                      f"are needed")
        frame = values[outcome.name]
        frame = frame[frame["participant"].isin(kept[outcome.name])].reset_index(drop=True)
        if outcome.kind == "log_rt":
            _note_zero_times(trials, outcome, kept[outcome.name], notes)
        summary, own = _describe(outcome, frame, options)
        cells.append(summary)
        lines.append(own)
        if outcome.kind == "likert":
            parts.extend(_likert_tests(outcome, frame, options, factorial, notes))
        else:
            parts.extend(_anova_tests(outcome, frame, notes))
            parts.extend(recognition_chance(trials, outcome, kept[outcome.name],
                                            wilcoxon_method=options.wilcoxon_method,
                                            adjust=options.adjust))
            parts.extend(trial_model_tests(trials, outcome, kept[outcome.name], notes))
    if options.paper_compatible:
        parts.extend(_paper_pseudo_replication(trials, found, kept))
    results = (pd.concat(parts, ignore_index=True) if parts
               else pd.DataFrame(columns=list(RESULT_COLUMNS)))
    recognition = next((o for o in found if o.kind == "recognition"), None)
    analysis = StudyAnalysis(
        design=design.name, title=design.title, results=results,
        cells=pd.concat(cells, ignore_index=True)[list(CELL_COLUMNS)],
        participants=pd.concat(lines, ignore_index=True)[list(PARTICIPANT_COLUMNS)],
        confusion=_confusion(trials, recognition,
                             kept[recognition.name] if recognition is not None else []),
        paper=pd.DataFrame(),
        excluded={p: "; ".join(reasons) + " (left out of "
                  + ", ".join(o.name for o in found if p in missing[o.name]) + ")"
                  for p, reasons in incomplete.items()},
        notes=notes, options=asdict(options), source=trials.source)
    analysis.paper = paper_numbers(analysis, trials)
    everyone = [p for p in trials.participants if p not in incomplete]
    analysis.methods = methods_paragraphs(analysis, trials, found, everyone, factorial is not None)
    analysis.methods.insert(min(1, len(analysis.methods)), _factors_paragraph(found))
    return analysis


def _factors_paragraph(found: list[Outcome]) -> str:
    """The factors found in the design for each outcome and how each is treated."""
    return ("Factors, from the cells the design plans for each outcome (crossed: every "
            "combination planned; nested: one factor's level fixes the other's, which is then "
            "not a factor of its own; constant: one level). "
            + " ".join(f"{factor_text(outcome)}." for outcome in found
                       if outcome.kind != "log_rt"))


def _note_zero_times(trials: Trials, outcome: Outcome, kept: list[str], notes: list[str]) -> None:
    rows = trials.frame[(trials.frame["question"] == outcome.question)
                        & trials.frame["participant"].isin(kept)]
    # A trial's number may repeat in other blocks (other software numbers trials per block).
    zero = rows.drop_duplicates([c for c in ANSWER_KEY if c != "question"])["rt_ms"].eq(0).sum()
    if zero:
        notes.append(f"{outcome.name}: {zero} response time{'s' if zero != 1 else ''} of 0 ms "
                     f"left out (no logarithm)")


# -- the conditions as a factorial -------------------------------------------------------------

def _tactile_factorial(design) -> tuple[dict[str, str], dict[str, str]] | None:
    """``({condition: superposition level}, {condition: fluctuation level})`` when the design's
    conditions are a full factorial of principal-frequency counts × loop structures, else None."""
    from realpen.tactile.conditions import TactileParams

    if len(design.conditions) < 4 or any(c.tactile is None for c in design.conditions):
        return None
    superposition: dict[str, str] = {}
    fluctuation: dict[str, str] = {}
    for condition in design.conditions:
        params = TactileParams.resolve(**{"condition": None, **condition.tactile.keywords()})
        superposition[condition.id] = f"{params.top}"
        fluctuation[condition.id] = f"{params.subpatterns}x{params.unit_ms:g}ms"
    pairs = {(superposition[c], fluctuation[c]) for c in superposition}
    tops, loops = set(superposition.values()), set(fluctuation.values())
    if len(tops) < 2 or len(loops) < 2 or len(pairs) != len(superposition) or \
            len(pairs) != len(tops) * len(loops):
        return None
    return superposition, fluctuation


# -- descriptive -------------------------------------------------------------------------------

def _shown_values(outcome: Outcome, values: pd.Series) -> pd.Series:
    if outcome.kind == "recognition":
        return values * 100.0
    if outcome.kind == "log_rt":
        return np.exp(values)
    return values


def _describe(outcome: Outcome, frame: pd.DataFrame, options: AnalysisOptions
              ) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Mean ± CI per level of each factor (and of their combination), and each participant's
    value there, in the unit the report shows."""
    ci = options.likert_ci if outcome.kind == "likert" else "t"
    groupings = [[factor] for factor in outcome.factors]
    if len(outcome.factors) > 1:
        groupings.append(list(outcome.factors))
    if not outcome.factors:
        groupings = [[]]
    cells: list[dict] = []
    lines: list[dict] = []
    for by in groupings:
        means = (frame.groupby(["participant", *by], sort=False, observed=True)["value"].mean()
                 .reset_index()
                 if by else frame.groupby("participant", sort=False)["value"].mean().reset_index())
        name = ":".join(by) if by else "all"
        table = cell_cis(means.assign(_all="all") if not by else means, dv="value",
                         by=by or ["_all"], subject="participant",
                         confidence=options.confidence, method=ci, seed=options.seed)
        for row in table.itertuples(index=False):
            level = ":".join(str(getattr(row, f)) for f in by) if by else "all"
            mean, low, high = _shown_values(outcome, pd.Series([row.mean, row.ci_low, row.ci_high]))
            cells.append({"outcome": outcome.name, "factor": name, "level": level, "mean": mean,
                          "ci_low": low, "ci_high": high, "ci_method": ci, "n": row.n,
                          "unit": outcome.unit})
        shown = _shown_values(outcome, means["value"])
        for row, value in zip(means.itertuples(index=False), shown):
            level = ":".join(str(getattr(row, f)) for f in by) if by else "all"
            lines.append({"outcome": outcome.name, "factor": name, "level": level,
                          "participant": row.participant, "value": value, "unit": outcome.unit})
    return pd.DataFrame(cells, columns=list(CELL_COLUMNS)), pd.DataFrame(
        lines, columns=list(PARTICIPANT_COLUMNS))


# -- Likert ------------------------------------------------------------------------------------

def _means_over(frame: pd.DataFrame, factor: str) -> pd.DataFrame:
    return frame.groupby(["participant", factor], sort=False, observed=True)["value"].mean() \
        .reset_index()


def _likert_tests(outcome: Outcome, frame: pd.DataFrame, options: AnalysisOptions,
                  factorial: tuple[dict[str, str], dict[str, str]] | None,
                  notes: list[str]) -> list[pd.DataFrame]:
    parts: list[pd.DataFrame] = []
    factors = list(outcome.factors)
    for factor in factors:
        means = _means_over(frame, factor)
        if means[factor].nunique() < 2:
            continue
        others = [f for f in factors if f != factor]
        averaged = f"; values averaged over {', '.join(others)}" if others else ""
        if means[factor].nunique() == 2:
            # Two levels: the Friedman test is a sign test of the pair; the signed-rank test
            # also weighs the size of each participant's difference.
            parts.extend(_wilcoxon_pairs(outcome, means, factor, options, notes,
                                         paper=factor == "condition",
                                         reason=_TWO_LEVELS + averaged))
            continue
        result = friedman(means, dv="value", within=factor, subject="participant")
        result["method"] = result["method"] + averaged
        parts.append(with_context(result, analysis=f"friedman/{factor}", outcome=outcome.name,
                                  effect=factor))
        # The paper's post hoc Wilcoxon tests compared its conditions.
        parts.extend(_wilcoxon_pairs(outcome, means, factor, options, notes,
                                     paper=factor == "condition"))
    if factorial is not None and "condition" in factors:
        split = _split_conditions(outcome, _means_over(frame, "condition"), factorial)
        parts.extend(_factorial_friedman(outcome, split, options))
        art = _checked(aligned_rank_transform(split, dv="value",
                                              within=[SUPERPOSITION, FLUCTUATION],
                                              subject="participant"))
        parts.append(with_context(art, analysis=f"art/{SUPERPOSITION}:{FLUCTUATION}",
                                  outcome=outcome.name))
    if len(factors) == 2:
        art = _checked(aligned_rank_transform(frame, dv="value", within=factors,
                                              subject="participant"))
        parts.append(with_context(art, analysis=f"art/{':'.join(factors)}", outcome=outcome.name))
    return parts


def _split_conditions(outcome: Outcome, means: pd.DataFrame,
                      factorial: tuple[dict[str, str], dict[str, str]]) -> pd.DataFrame:
    """Each participant's mean per condition, with its superposition and fluctuation levels
    (categorical, in the design's condition order)."""
    conditions = list(outcome.levels["condition"])
    return means.assign(**{
        name: pd.Categorical(means["condition"].astype(str).map(mapping),
                             categories=list(dict.fromkeys(mapping[c] for c in conditions)))
        for name, mapping in ((SUPERPOSITION, factorial[0]), (FLUCTUATION, factorial[1]))})


def _checked(art: pd.DataFrame) -> pd.DataFrame:
    """ART rows whose method reports Wobbrock's check: the other effects' F in an ANOVA of the
    aligned, unranked responses (about 0 when the alignment is right)."""
    art = art.copy()
    art["method"] = [f"{method}; alignment check: largest F of the other effects "
                     f"{check:.2g} (should be about 0)"
                     for method, check in zip(art["method"], art["aligned_check"])]
    return art


def _wilcoxon_pairs(outcome: Outcome, means: pd.DataFrame, factor: str, options: AnalysisOptions,
                    notes: list[str], *, paper: bool, reason: str = "") -> list[pd.DataFrame]:
    """Wilcoxon signed-rank tests of every pair of ``factor``'s levels (``reason``, why these
    are the factor's test, appended to each row's method), and the paper's SPSS-style p beside
    them when asked."""
    parts = []
    methods = [(options.wilcoxon_method, "")]
    if options.paper_compatible and paper:
        methods.append(("spss", _PAPER_WILCOXON))
    for method, mark in methods:
        pairs = pairwise(means, dv="value", within=factor, subject="participant",
                         test="wilcoxon", adjust=options.adjust, wilcoxon_method=method)
        if "ties" in pairs and pairs["ties"].any() and not mark:
            notes.append(f"{outcome.name}, {factor}: tied differences in "
                         f"{int(pairs['ties'].sum())} of {len(pairs)} Wilcoxon pairs; their "
                         f"p-values depend on the method (here '{method}')")
        if mark:
            pairs["method"] = mark + "; " + pairs["method"]
        elif reason:
            pairs["method"] = pairs["method"] + "; " + reason
        analysis = f"wilcoxon/{factor}" + ("/paper-compatible" if mark else "")
        parts.append(with_context(pairs, analysis=analysis, outcome=outcome.name,
                                  p_adjusted=pairs["p_adjusted"],
                                  adjust=options.adjust))
    return parts


def _factorial_friedman(outcome: Outcome, frame: pd.DataFrame, options: AnalysisOptions
                        ) -> list[pd.DataFrame]:
    """Superposition blocked by fluctuation and the reverse, in the chosen variant."""
    parts = []
    variant = options.friedman_variant
    for factor, other in ((SUPERPOSITION, FLUCTUATION), (FLUCTUATION, SUPERPOSITION)):
        described = f"blocked by {other}: variant {FRIEDMAN_VARIANTS[variant]}"
        analysis = f"friedman/{factor}/{variant}"
        if variant == "average":
            means = _means_over(frame, factor)
            result = friedman(means, dv="value", within=factor, subject="participant")
            result["method"] = result["method"] + "; " + described
            parts.append(with_context(result, analysis=analysis, outcome=outcome.name,
                                      effect=factor))
        elif variant == "cells":
            blocks = frame.assign(block=frame["participant"].astype(str) + "|" + frame[other].astype(str))
            result = friedman(blocks, dv="value", within=factor, subject="block")
            result["method"] = result["method"] + "; " + described
            parts.append(with_context(result, analysis=analysis, outcome=outcome.name,
                                      effect=factor))
        else:
            tests = []
            for level in frame[other].cat.categories:
                result = friedman(frame[frame[other] == level], dv="value", within=factor,
                                  subject="participant")
                result["method"] = result["method"] + "; " + described
                result["effect"] = f"{factor} | {other}={level}"
                tests.append(result)
            joined = pd.concat(tests, ignore_index=True)
            adjusted = _adjust(joined["p"].to_numpy(), options.adjust)
            parts.append(with_context(joined, analysis=analysis, outcome=outcome.name,
                                      p_adjusted=adjusted, adjust=options.adjust))
    return parts


def _adjust(p: np.ndarray, method: str) -> np.ndarray:
    if method == "none" or len(p) < 2:
        return p
    return adjusted_p(p, method)


# -- recognition and response times ------------------------------------------------------------

def _anova_tests(outcome: Outcome, frame: pd.DataFrame, notes: list[str]) -> list[pd.DataFrame]:
    factors = list(outcome.factors)
    if not factors:
        return []
    parts = [_rm_anova_rows(frame, factors, outcome.name, "rm-anova", notes)]
    for factor in factors:
        if frame[factor].nunique() < 2:
            continue
        means = _means_over(frame, factor)
        pairs = pairwise(means, dv="value", within=factor, subject="participant", test="t",
                         adjust="bonferroni")
        parts.append(with_context(pairs, analysis=f"pairwise-t/{factor}", outcome=outcome.name,
                                  p_adjusted=pairs["p_adjusted"], adjust="bonferroni"))
    return parts


def _rm_anova_rows(frame: pd.DataFrame, factors: list[str], outcome: str, analysis: str,
                   notes: list[str], mark: str = "", subject: str = "participant") -> pd.DataFrame:
    """The RM-ANOVA's rows, and for every effect of more than two levels a second row with
    Greenhouse–Geisser corrected degrees of freedom and p."""
    table = rm_anova(frame, dv="value", within=factors if len(factors) > 1 else factors[0],
                     subject=subject)
    rows = []
    for row in table.to_dict("records"):
        sphericity = _sphericity_text(row)
        base = dict(row)
        base["method"] = (mark + "; " if mark else "") + f"{row['method']}; {sphericity}"
        rows.append(base)
        if row["df1"] > 1 and np.isfinite(row.get("eps_gg", np.nan)):
            corrected = dict(base)
            eps = row["eps_gg"]
            corrected.update(test=f"{row['test']}, Greenhouse–Geisser", df1=row["df1"] * eps,
                             df2=row["df2"] * eps, p=row["p_gg"])
            rows.append(corrected)
            if np.isfinite(row.get("p_mauchly", np.nan)) and not row.get("sphericity", True) \
                    and not mark:
                notes.append(f"{outcome}: sphericity is violated for {row['effect']} (Mauchly "
                             f"p = {row['p_mauchly']:.3f}): read its Greenhouse–Geisser row")
    result = pd.DataFrame(rows)
    return with_context(result, analysis=analysis if not mark else f"{analysis}/paper-compatible",
                        outcome=outcome)


def _sphericity_text(row: dict) -> str:
    if row["df1"] <= 1:
        return "two levels: sphericity holds trivially"
    text = f"ε_GG = {row['eps_gg']:.3f}, ε_HF = {row['eps_hf']:.3f}"
    if np.isfinite(row.get("p_mauchly", np.nan)):
        verdict = "held" if row.get("sphericity", True) else "violated"
        text += f"; Mauchly W = {row['mauchly_w']:.3f}, p = {row['p_mauchly']:.3f} ({verdict})"
    else:
        text += "; Mauchly's test not computable: read the Greenhouse–Geisser row"
    return text


def _paper_pseudo_replication(trials: Trials, found: list[Outcome], kept: dict[str, list[str]]
                              ) -> list[pd.DataFrame]:
    """The paper's recognition ANOVA: every repetition of a participant its own subject."""
    parts = []
    for outcome in found:
        if outcome.kind != "recognition" or not outcome.factors:
            continue
        rows = outcome_rows(trials, outcome)
        rows = rows[rows["correct"].notna() & rows["participant"].isin(kept[outcome.name])]
        # The session's order is the file's (trial numbers may restart in every block).
        rows = rows.sort_values(["participant", "line"], kind="stable")
        factors = list(outcome.factors)
        repetition = rows.groupby(["participant", *factors], sort=False).cumcount() + 1
        pseudo = rows.assign(subject=rows["participant"].astype(str) + "#" + repetition.astype(str),
                             value=rows["correct"],
                             **{name: pd.Categorical(rows[name], categories=list(outcome.levels[name]))
                                for name in factors})
        counts = pseudo.groupby("subject").size()
        complete = counts[counts == len(outcome.cells)].index
        pseudo = pseudo[pseudo["subject"].isin(complete)]
        mark = _PAPER_PSEUDO.format(subjects=len(complete))
        parts.append(_rm_anova_rows(pseudo, factors, outcome.name, "rm-anova", [], mark=mark,
                                    subject="subject"))
        for factor in factors:
            means = pseudo.groupby(["subject", factor], sort=False, observed=True)["value"] \
                .mean().reset_index()
            pairs = pairwise(means, dv="value", within=factor, subject="subject", test="t",
                             adjust="bonferroni")
            pairs["method"] = mark + "; " + pairs["method"]
            parts.append(with_context(pairs, analysis=f"pairwise-t/{factor}/paper-compatible",
                                      outcome=outcome.name, p_adjusted=pairs["p_adjusted"],
                                      adjust="bonferroni"))
    return parts


def _confusion(trials: Trials, recognition: Outcome | None, kept: list[str]) -> pd.DataFrame:
    """Presented pen × chosen pen per modality, of the (first) recognition question."""
    if recognition is None:
        return pd.DataFrame(columns=list(CONFUSION_COLUMNS))
    rows = trials.frame[(trials.frame["question"] == recognition.question)
                        & trials.frame["correct"].notna()
                        & trials.frame["participant"].isin(kept)]
    modalities = recognition.levels.get("modality", tuple(dict.fromkeys(rows["modality"])))
    pens = recognition.levels.get("pen", tuple(dict.fromkeys(rows["pen"])))
    chosen_levels = list(dict.fromkeys([*pens, *sorted(set(rows["answer"]) - set(pens))]))
    counts = rows.groupby(["modality", "pen", "answer"]).size()
    table = []
    for modality, pen in itertools.product(modalities, pens):
        total = sum(int(counts.get((modality, pen, chosen), 0)) for chosen in chosen_levels)
        for chosen in chosen_levels:
            count = int(counts.get((modality, pen, chosen), 0))
            table.append({"modality": modality, "pen": pen, "chosen": chosen, "count": count,
                          "row_percent": 100.0 * count / total if total else math.nan})
    return pd.DataFrame(table, columns=list(CONFUSION_COLUMNS))

