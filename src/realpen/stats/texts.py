"""The methods paragraphs of a report: every test, variant, correction and software version,
in words a reviewer can check against ``results.csv``."""

from __future__ import annotations

from importlib import metadata

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


def methods_paragraphs(analysis: StudyAnalysis, trials: Trials, found: list[Outcome],
                       kept: list[str], factorial: bool) -> list[str]:
    """The methods of ``analysis``, one paragraph per entry."""
    options = analysis.options
    confidence = f"{100 * options['confidence']:g} %"
    kinds = {outcome.kind for outcome in found}
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
        f"participants, not trials, are the units of analysis.")
    if "likert" in kinds:
        text = (f"Ratings: Friedman tests (scipy.stats.friedmanchisquare, chi-squared corrected "
                f"for ties; Kendall's W = chi2 / (n (k - 1))) of each factor on each participant's "
                f"mean over the other factors, and Wilcoxon signed-rank tests of every pair of "
                f"levels (zeros dropped as Wilcoxon proposed; p by method "
                f"'{options['wilcoxon_method']}': {_WILCOXON[options['wilcoxon_method']]}; effect "
                f"size r = z / sqrt(n) with z from the normal approximation; p adjusted over "
                f"each factor's pairs by {options['adjust']}).")
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
                     f"and so reports larger error df).")
        elif any(len(o.factors) == 2 for o in found if o.kind == "likert"):
            text += (" Interactions of two factors: the aligned rank transform (Wobbrock et al., "
                     "CHI 2011) with a repeated-measures ANOVA of the aligned ranks, each effect "
                     "against its own effect × participant error.")
        text += (f" Means are shown with {confidence} "
                 + ("BCa bootstrap intervals (scipy.stats.bootstrap, 10,000 resamples, seed "
                    f"{options['seed']}; percentile intervals where BCa is undefined, e.g. "
                    f"when every participant gave the same rating)"
                    if options['likert_ci'] == 'bootstrap' else "Student t intervals") + ".")
        paragraphs.append(text)
    if kinds & {"recognition", "log_rt"}:
        paragraphs.append(
            f"Recognition and response times: repeated-measures ANOVAs (statsmodels AnovaRM) "
            f"with participants as subjects; Mauchly's test of sphericity and the "
            f"Greenhouse–Geisser and Huynh–Feldt epsilons (pingouin); generalised eta squared "
            f"(Olejnik & Algina, 2003). For every effect with more than two levels a second row "
            f"gives the Greenhouse–Geisser corrected degrees of freedom and p, to be read when "
            f"sphericity is violated. Post hoc: paired t-tests (pingouin) of every pair of levels "
            f"on participants' means over the other factor, Bonferroni-adjusted as in the paper. "
            f"Cell means with {confidence} Student t intervals; response times as geometric "
            f"means (exp of the mean log) in ms.")
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
    versions = ", ".join(f"{name} {version}" for name, version in software_versions().items())
    paragraphs.append(f"Software: {versions}.")
    return paragraphs
