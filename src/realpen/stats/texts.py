"""The methods paragraphs of a report: every test, variant, correction and software version,
in words a reviewer can check against ``results.csv``."""

from __future__ import annotations

from importlib import metadata

import pandas as pd

from realpen.stats.data import Outcome, Trials
from realpen.stats.outcome import StudyAnalysis

__all__ = ["methods_paragraphs", "software_versions"]

_PACKAGES = ("realpen", "numpy", "scipy", "pandas", "statsmodels", "pingouin", "matplotlib")
_WILCOXON = {
    "exact": "the exact null distribution of the signed-rank statistic without ties or zeros, "
             "and with them the exact permutation distribution of the signs (all 2^n sign "
             "patterns up to n = 20 non-zero differences, as scipy.stats.wilcoxon's permutation "
             "method; above 20, a Monte Carlo of 100,000 sign patterns with seed 0)",
    "r": "R's wilcox.test default: exact without ties or zeros (n < 50), otherwise the normal "
         "approximation with continuity correction and tie-corrected variance",
    "spss": "the normal approximation without continuity correction, with tie-corrected "
            "variance (SPSS, PSPP)",
}


_ADJUST_REASONS = {
    "holm": "Holm's step-down adjustment, because it keeps the family-wise error rate as "
            "Bonferroni's does and never rejects less (Holm, 1979).",
    "bonferroni": "Bonferroni's adjustment, as asked (Holm's keeps the same error rate and "
                  "rejects at least as often).",
    "none": "No adjustment, as asked: with many pairs some p < .05 are expected by chance.",
}


def software_versions() -> dict[str, str]:
    """``{package: version}`` of Python and the packages the analysis ran on (``not
    installed`` for one that is absent), from :mod:`importlib.metadata`.

    >>> list(software_versions())[:3]
    ['python', 'realpen', 'numpy']
    """
    import platform

    versions = {"python": platform.python_version()}
    for package in _PACKAGES:
        try:
            versions[package] = metadata.version(package)
        except metadata.PackageNotFoundError:
            versions[package] = "not installed"
    return versions


def _analyses(analysis: StudyAnalysis) -> set[str]:
    """The first word of every ``analysis`` of the results (``chance``, ``gee``, ...)."""
    results = analysis.results
    if not isinstance(results, pd.DataFrame) or "analysis" not in results.columns:
        return set()
    return {str(name).split("/")[0] for name in results["analysis"]}


def methods_paragraphs(analysis: StudyAnalysis, trials: Trials, found: list[Outcome],
                       kept: list[str], factorial: bool) -> list[str]:
    """The methods of ``analysis``, one paragraph per entry, each choice with its reason.

    The paragraphs: the data and the unit of analysis; ratings; recognition and response
    times; recognition against chance and the trial-level models (when the results have
    them); the paper-compatible numbers (when asked for); the software. The report shows
    them once; each row of ``results.csv`` keeps its own ``method``.
    """
    options = analysis.options
    confidence = f"{100 * options['confidence']:g} %"
    kinds = {outcome.kind for outcome in found}
    ran = _analyses(analysis)
    adjust = str(options["adjust"])
    paragraphs = []
    count = len(analysis.excluded)
    excluded = (f" {count} participant{'s' if count != 1 else ''} missing planned cells "
                f"{'were' if count != 1 else 'was'} left out of the outcomes concerned only "
                f"(listed below, with those outcomes)." if analysis.excluded else "")
    paragraphs.append(
        f"Data: {len(trials.participants)} participants of study '{analysis.design}' from "
        f"{trials.source}; {len(kept)} complete in every outcome."
        f"{excluded} Training trials ({len(trials.training)} answers) were not analysed. Each "
        f"participant contributes one value per cell: the mean rating of a Likert question, "
        f"the proportion of correct recognitions, or the mean of the natural log of the response "
        f"time (ms) of the cell's trials; tests compare participants' cell values, so "
        f"participants, not trials, are the units of analysis. Why: the trials of one person "
        f"are not independent of each other, and the question is whether people (not trials) "
        f"tell the conditions apart; a test of trials would count each person many times.")
    if "likert" in kinds:
        text = (f"Ratings: rank tests, because ratings are ordinal (the points of a Likert scale "
                f"are ordered, but their distances need not be equal, and a dozen participants "
                f"cannot show that their means are normal). Friedman tests "
                f"(scipy.stats.friedmanchisquare, chi-squared corrected for ties; Kendall's W = "
                f"chi2 / (n (k - 1))) of each factor on each participant's mean over the other "
                f"factors, and Wilcoxon signed-rank tests of every pair of levels (zeros dropped "
                f"as Wilcoxon proposed; p by method '{options['wilcoxon_method']}': "
                f"{_WILCOXON[options['wilcoxon_method']]}; effect size r = z / sqrt(n) with z "
                f"from the normal approximation; p adjusted over each factor's pairs by "
                f"{adjust}).")
        if options["wilcoxon_method"] == "exact":
            text += (" The exact p because with a dozen participants and tied ratings the "
                     "normal approximation (SPSS's, R's with ties) is inaccurate.")
        text += " " + _ADJUST_REASONS.get(adjust, "")
        if factorial:
            text += (f" The conditions are a full factorial of the number of principal "
                     f"frequencies (superposition) and the loop's structure (fluctuation). A "
                     f"Friedman test is one-factor, so 'superposition blocked by fluctuation' "
                     f"(and the reverse) is reduced by variant '{options['friedman_variant']}'; "
                     f"the variants are (a) average over the other factor, (b) participant × "
                     f"other level as blocks, (c) one test per other level. Their interaction is "
                     f"tested with the aligned rank transform (Wobbrock et al., CHI 2011) on "
                     f"each participant's mean per condition: responses aligned for each "
                     f"effect, ranked, and analysed by a repeated-measures ANOVA of the ranks "
                     f"(from orthonormal contrasts; the univariate test of statsmodels AnovaRM) "
                     f"in which each effect is tested against its own "
                     f"effect × participant error (ARTool's Error(S) model pools these errors "
                     f"and so reports larger error df). Why: a rank test of an interaction needs "
                     f"the alignment, ranking raw ratings would mix the main effects into it.")
        elif any(len(o.factors) == 2 for o in found if o.kind == "likert"):
            text += (" Interactions of two factors: the aligned rank transform (Wobbrock et al., "
                     "CHI 2011) with a repeated-measures ANOVA of the aligned ranks, each effect "
                     "against its own effect × participant error (a rank test of an interaction "
                     "needs the alignment).")
        text += (f" Means are shown with {confidence} "
                 + ("BCa bootstrap intervals (scipy.stats.bootstrap, 10,000 resamples, seed "
                    f"{options['seed']}; percentile intervals where BCa is undefined, e.g. "
                    f"when every participant gave the same rating), since a t interval assumes "
                    f"the normal means ratings need not have"
                    if options['likert_ci'] == 'bootstrap' else "Student t intervals") + ".")
        paragraphs.append(text)
    if kinds & {"recognition", "log_rt"}:
        paragraphs.append(
            f"Recognition and response times: repeated-measures ANOVAs (statsmodels AnovaRM) "
            f"with participants as subjects. Why an ANOVA: it is the paper's analysis (its Table "
            f"4), on each participant's proportion correct per cell, so our numbers can be set "
            f"beside the paper's; a proportion over several trials, and a mean log time, are "
            f"means, closer to normal than single answers. Mauchly's test of sphericity and the "
            f"Greenhouse–Geisser and Huynh–Feldt epsilons (pingouin); generalised eta squared "
            f"(Olejnik & Algina, 2003), comparable across designs. For every effect with more "
            f"than two levels a second row gives the Greenhouse–Geisser corrected degrees of "
            f"freedom and p, to be read when sphericity is violated: with three levels the "
            f"variances of the differences often differ, which makes the uncorrected F liberal, "
            f"and Greenhouse–Geisser is the conservative correction. Post hoc: paired t-tests "
            f"(pingouin) of every pair of levels on participants' means over the other factor, "
            f"Bonferroni-adjusted as in the paper. Response times are analysed as the natural "
            f"log of the time in ms, because times are right-skewed (a few slow answers make a "
            f"long tail) and their spread grows with their mean; the log makes them nearly "
            f"symmetric. Cell means with {confidence} Student t intervals; response times as "
            f"geometric means (exp of the mean log) in ms.")
    if "chance" in ran:
        paragraphs.append(
            "Recognition against chance (1 / the number of pens to choose from): per level of "
            "each factor, a one-sample Wilcoxon signed-rank test of each participant's "
            "proportion correct minus chance, the primary test, with participants as the "
            "units as above; signed-rank rather than t because a proportion of a few trials is "
            "discrete, bounded and tied. p adjusted over the levels of each factor by "
            f"{adjust}. Beside it, secondary, the exact binomial test of all trials pooled "
            "(scipy.stats.binomtest, Cohen's h as effect size): it treats every trial as "
            "independent, which they are not, so its p is too small when participants differ.")
    if ran & {"gee", "mixedlm"}:
        paragraphs.append(
            "Trial-level models, beside the participant-level tests: for recognition a binomial "
            "GEE (statsmodels, logit link, exchangeable working correlation within each "
            "participant, Mancl–DeRouen bias-reduced sandwich covariance, sum-to-zero "
            "contrasts), for log response times a linear mixed model (statsmodels MixedLM, "
            "random intercept per participant, REML); each effect by a Wald chi-squared test. "
            "Why both: the models use every trial, and for recognition its 0/1 nature, which a "
            "proportion per cell smooths over; the participant-level test stays the primary "
            "one, because participants are the unit of inference and it is the analysis the "
            "paper reports. Where the two disagree, the report's reader should look at the "
            "participants' own values (the figures).")
    if options["paper_compatible"]:
        paragraphs.append(
            "Paper-compatible numbers (marked in every table and in results.csv, where method "
            "starts with 'paper-compatible'): for the post hoc comparisons of conditions, the "
            "Wilcoxon p-values SPSS gives (normal approximation without continuity correction), "
            "and for recognition the ANOVA and "
            "pairwise tests with each repetition of a participant as its own subject, which is "
            "what the paper's F(2, 142) and F(4, 284) imply. They are given to reproduce the "
            "paper; they are not recommended: the first is inaccurate for small tied samples, "
            "the second counts the same person several times (pseudo-replication) and so "
            "overstates the evidence.")
    paragraphs.append(
        "Reporting: every test is also written as an APA-style sentence (results.csv column "
        "apa: the statistic with its degrees of freedom, p with three decimals or p < .001, "
        "the effect size); a pair of levels is named 'a vs b' (columns level_a and level_b), "
        "its statistic of a - b.")
    versions = ", ".join(f"{name} {version}" for name, version in software_versions().items())
    paragraphs.append(f"Software: {versions}.")
    return paragraphs
