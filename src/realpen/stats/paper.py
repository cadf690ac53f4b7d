"""The numbers the RealPen paper reported (Cho et al., UIST 2016), set beside ours.

Only the two studies of the paper have any; for another design :func:`paper_numbers` is empty.
Where the paper's text does not tie a number to one outcome (study 1's post hoc p-values are
reported for the conditions without naming Q1 or Q2 beside each), ours are given for every
outcome it could belong to, and the note says so.
"""

from __future__ import annotations

import math

import pandas as pd

from realpen.stats.outcome import PAPER_COLUMNS, StudyAnalysis

__all__ = ["paper_numbers", "STUDY1_POSTHOC", "STUDY2_RATES", "STUDY2_FRIEDMAN", "STUDY2_DF"]

STUDY1_POSTHOC = {"D-F": 0.025, "B-E": 0.046, "C-F": 0.047, "A-D": math.nan}
"""Study 1's Wilcoxon post hoc p-values (A–D: reported not significant, no value)."""
STUDY2_RATES = {"tactile": 43.05, "auditory": 50.96, "audio-tactile": 62.96}
"""Study 2's recognition rates (percent correct) per modality."""
STUDY2_FRIEDMAN = {"realism": 8.211, "comfort": 1.077, "strength": 3.257}
"""Study 2's Friedman chi-squared per questionnaire item, over the three modalities."""
STUDY2_DF = {"modality": (2, 142), "pen": (2, 142), "modality:pen": (4, 284)}
"""Study 2's Table 4: the recognition ANOVA's degrees of freedom."""


def paper_numbers(analysis: StudyAnalysis) -> pd.DataFrame:
    """The paper's numbers for ``analysis``'s design beside ours (:data:`PAPER_COLUMNS`)."""
    rows: list[dict] = []
    if analysis.design == "study1":
        rows = _study1(analysis)
    elif analysis.design == "study2":
        rows = _study2(analysis)
    return pd.DataFrame(rows, columns=list(PAPER_COLUMNS))


def _result(results: pd.DataFrame, analysis: str, outcome: str, effect: str,
            test: str | None = None) -> pd.Series | None:
    found = results[(results["analysis"] == analysis) & (results["outcome"] == outcome)
                    & (results["effect"] == effect)]
    if test is not None:
        found = found[found["test"] == test]
    return None if found.empty else found.iloc[0]


def _study1(analysis: StudyAnalysis) -> list[dict]:
    rows = []
    for outcome in ("Q1", "Q2"):
        for pair, reported in STUDY1_POSTHOC.items():
            for name, label in (("wilcoxon/condition", "ours (recommended method)"),
                                ("wilcoxon/condition/paper-compatible", "ours, SPSS-style")):
                found = _result(analysis.results, name, outcome, pair)
                if found is None:
                    continue
                note = (f"{label}; unadjusted p. The paper reports this pair's post hoc p "
                        f"without naming Q1 or Q2 beside it")
                if math.isnan(reported):
                    note += "; the paper reports it as not significant, without a value"
                rows.append({"analysis": name, "outcome": outcome, "effect": pair,
                             "quantity": "p", "paper": reported, "ours": float(found["p"]),
                             "note": note})
    return rows


def _study2(analysis: StudyAnalysis) -> list[dict]:
    rows = []
    cells = analysis.cells
    for modality, rate in STUDY2_RATES.items():
        found = cells[(cells["outcome"] == "recognition") & (cells["factor"] == "modality")
                      & (cells["level"] == modality)]
        rows.append({"analysis": "cells/modality", "outcome": "recognition", "effect": modality,
                     "quantity": "rate_percent", "paper": rate,
                     "ours": float(found["mean"].iloc[0]) if len(found) else math.nan,
                     "note": "mean over participants of each one's percent correct"})
    for effect, (df1, df2) in STUDY2_DF.items():
        for name, label in (("rm-anova", "ours: participants as subjects (recommended)"),
                            ("rm-anova/paper-compatible", "ours, repetitions as subjects")):
            found = _result(analysis.results, name, "recognition", effect, test="RM-ANOVA")
            if found is None:
                continue
            for quantity, reported, value in (("df1", df1, found["df1"]), ("df2", df2, found["df2"])):
                rows.append({"analysis": name, "outcome": "recognition", "effect": effect,
                             "quantity": quantity, "paper": float(reported), "ours": float(value),
                             "note": label})
    for item, chi2 in STUDY2_FRIEDMAN.items():
        found = _result(analysis.results, "friedman/modality", item, "modality")
        rows.append({"analysis": "friedman/modality", "outcome": item, "effect": "modality",
                     "quantity": "chi2", "paper": chi2,
                     "ours": float(found["statistic"]) if found is not None else math.nan,
                     "note": "Friedman over the three modalities"})
    return rows
