"""The numbers the RealPen paper reported (Cho et al., UIST 2016), set beside ours.

Only the two studies of the paper have any; for another design :func:`paper_numbers` is empty.
Every number the paper gives is a row of ``paper.csv`` (:data:`realpen.stats.outcome.
PAPER_COLUMNS`): its Table 2 (study 1's Friedman tests), study 1's Wilcoxon post hoc p-values,
its Table 4 (study 2's recognition ANOVA), the recognition rates, the response times (mean ±
SD per modality, and their ANOVA) and the questionnaire's Friedman tests. Beside each is ours:
the recommended analysis, and where the paper's choice differs (repetitions as subjects,
SPSS-style Wilcoxon p) also the ``paper-compatible`` row that repeats it (with
``--paper-compatible``). :func:`comparison_table` writes each comparison as two APA-style
sentences, the paper's and ours, for the report.

Where the paper's text does not tie a number to one outcome (study 1's post hoc p-values are
reported for the conditions without naming Q1 or Q2 beside each), ours are given for every
outcome it could belong to, and the note says so. The paper gives no questionnaire means in the
text we have, so none are compared.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np
import pandas as pd

from realpen.stats.outcome import PAPER_COLUMNS, StudyAnalysis
from realpen.stats.results import apa_p, apa_sentence, pair_label

__all__ = ["paper_numbers", "comparison_table", "COMPARISON_COLUMNS", "STUDY1_FRIEDMAN",
           "STUDY1_POSTHOC", "STUDY2_RATES", "STUDY2_RECOGNITION", "STUDY2_RT", "STUDY2_RT_ANOVA",
           "STUDY2_FRIEDMAN", "STUDY2_DF", "TEST_QUANTITIES"]

NaN = math.nan
STUDY1_FRIEDMAN = {("Q1", "superposition"): (6.45, 2, 0.040),
                   ("Q1", "fluctuation"): (8.91, 1, 0.003),
                   ("Q2", "superposition"): (5.66, 2, 0.059),
                   ("Q2", "fluctuation"): (2.88, 1, 0.090)}
"""Study 1's Table 2: Friedman's Fr (chi-squared), df and p per question and factor, each
factor blocked by the other."""
STUDY1_POSTHOC = {pair_label("D", "F"): 0.025, pair_label("B", "E"): 0.046,
                  pair_label("C", "F"): 0.047, pair_label("A", "D"): NaN}
"""Study 1's Wilcoxon post hoc p-values (A vs D: reported not significant, no value)."""
STUDY2_RATES = {"tactile": 43.05, "auditory": 50.96, "audio-tactile": 62.96}
"""Study 2's recognition rates (percent correct) per modality."""
STUDY2_RECOGNITION = {"modality": (9.473, 2, 142, 0.001), "pen": (3.245, 2, 142, 0.042),
                      "modality:pen": (3.962, 4, 284, 0.004)}
"""Study 2's Table 4: the recognition ANOVA's F, df1, df2 and p (modality: p < .001)."""
STUDY2_DF = {effect: numbers[1:3] for effect, numbers in STUDY2_RECOGNITION.items()}
"""Study 2's Table 4: the recognition ANOVA's degrees of freedom."""
STUDY2_RT = {"tactile": (9.247, 5.086), "auditory": (8.851, 6.498), "audio-tactile": (8.497, 4.406)}
"""Study 2's response times per modality: mean and SD in seconds."""
STUDY2_RT_ANOVA = {"pen": (0.860, 2, 142), "modality": (1.927, NaN, NaN),
                   "modality:pen": (0.798, 4, 284)}
"""Study 2's response-time ANOVA: F, df1, df2 (no p given; the modality F without its df)."""
STUDY2_FRIEDMAN = {"realism": 8.211, "comfort": 1.077, "strength": 3.257}
"""Study 2's Friedman chi-squared per questionnaire item, over the three modalities."""
TEST_QUANTITIES = ("statistic", "df1", "df2", "p")
"""The quantities of a test compared (``df2`` only for tests that have one)."""
COMPARISON_COLUMNS = ("analysis", "outcome", "effect", "test", "paper", "ours", "note")
""":func:`comparison_table`: one row per comparison, ``paper`` and ``ours`` as sentences."""

_BOUNDS = {("recognition", "modality", "p"): "< .001"}
_RECOMMENDED = "ours: the recommended analysis"
_PSEUDO = ("ours, paper-compatible: repetitions as subjects, which the paper's df imply (not "
           "recommended: pseudo-replication)")
_SPSS = ("ours, paper-compatible: SPSS-style p (not recommended: poor for small tied "
         "samples)")


def paper_numbers(analysis: StudyAnalysis, trials=None) -> pd.DataFrame:
    """The paper's numbers for ``analysis``'s design beside ours (:data:`PAPER_COLUMNS`).

    Args:
        analysis: the study's analysis (its ``results`` and ``cells``).
        trials: its :class:`realpen.stats.data.Trials`, for the response times' mean and SD
            over trials (the analysis keeps each participant's geometric mean only); without
            it ours are NaN there, and the note says so.

    Returns:
        One row per number: ``quantity`` ``statistic``, ``df1``, ``df2``, ``p`` (of a test,
        ``test`` naming ours), ``rate_percent``, ``mean`` or ``sd`` (seconds); ``paper`` NaN
        where the paper gives no value (then ``reported`` is empty, or ``n.s.`` for a post hoc
        test it calls not significant), ``ours`` NaN with a ``note`` where we have none.
    """
    rows: list[dict] = []
    if analysis.design == "study1":
        rows = _study1(analysis)
    elif analysis.design == "study2":
        rows = _study2(analysis, trials)
    return pd.DataFrame(rows, columns=list(PAPER_COLUMNS))


def _reported(value: float, quantity: str, bound: str = "") -> str:
    """A paper number as the paper printed it (p without its leading zero)."""
    if bound:
        return bound
    if not math.isfinite(value):
        return ""
    if quantity == "p":
        return f"{value:.3f}".lstrip("0")
    if quantity in ("df1", "df2"):
        return str(int(value))
    return f"{value:g}"


def _row(analysis: str, outcome: str, effect: str, quantity: str, paper: float, ours: float,
         note: str, test: str = "", bound: str = "") -> dict:
    return {"analysis": analysis, "outcome": outcome, "effect": effect, "quantity": quantity,
            "paper": float(paper), "ours": float(ours), "note": note, "test": test,
            "reported": _reported(float(paper), quantity, bound)}


def _result(results: pd.DataFrame, analysis: str, outcome: str, effect: str,
            test: str | None = None) -> pd.Series | None:
    if results is None or results.empty or "analysis" not in results.columns:
        return None
    found = results[(results["analysis"] == analysis) & (results["outcome"] == outcome)
                    & (results["effect"] == effect)]
    if test is not None:
        found = found[found["test"] == test]
    return None if found.empty else found.iloc[0]


def _test_rows(analysis: str, outcome: str, effect: str, found: pd.Series | None,
               paper: Mapping[str, float], note: str, *, test: str) -> list[dict]:
    """The paper's statistic, df and p beside our row's (every quantity either has)."""
    compared = []
    for quantity in TEST_QUANTITIES:
        ours = float(found[quantity]) if found is not None else NaN
        reported = float(paper.get(quantity, NaN))
        if not (math.isnan(reported) and math.isnan(ours)):
            compared.append((quantity, reported, ours))
    absent = [quantity for quantity, reported, _ in compared if math.isnan(reported)]
    said = note if found is not None else f"{note}; not in this analysis"
    if absent:
        said += f"; the paper gives no {', '.join(absent)}"
    return [_row(analysis, outcome, effect, quantity, reported, ours, said,
                 test=str(found["test"]) if found is not None else test,
                 bound=_BOUNDS.get((outcome, effect, quantity), ""))
            for quantity, reported, ours in compared]


def _study1(analysis: StudyAnalysis) -> list[dict]:
    rows = []
    results = analysis.results
    variant = str((analysis.options or {}).get("friedman_variant", "average"))
    for (outcome, factor), (chi2, df, p) in STUDY1_FRIEDMAN.items():
        other = "fluctuation" if factor == "superposition" else "superposition"
        name = f"friedman/{factor}/{variant}"
        found = _result(results, name, outcome, factor)
        note = (f"{_RECOMMENDED}: {factor} blocked by {other} reduced by variant '{variant}'; "
                f"the paper ran 'Friedman's two-way ANOVA by ranks'")
        if found is None and variant == "per-level":
            note += " (variant 'per-level' gives one test per level: none to set beside it)"
        rows += _test_rows(name, outcome, factor, found, {"statistic": chi2, "df1": df, "p": p},
                           note, test="Friedman")
    for outcome in ("Q1", "Q2"):
        for pair, reported in STUDY1_POSTHOC.items():
            for name, label in (("wilcoxon/condition", _RECOMMENDED),
                                ("wilcoxon/condition/paper-compatible", _SPSS)):
                found = _result(results, name, outcome, pair)
                if found is None:
                    continue
                note = (f"{label}; unadjusted p. The paper reports this pair's post hoc p "
                        f"without naming Q1 or Q2 beside it")
                if math.isnan(reported):
                    note += "; the paper reports it as not significant, without a value"
                rows.append(_row(name, outcome, pair, "p", reported, float(found["p"]), note,
                                 test=str(found["test"]),
                                 bound="n.s." if math.isnan(reported) else ""))
    return rows


def _rt_seconds(analysis: StudyAnalysis, trials) -> dict[str, np.ndarray]:
    """Each modality's response times in seconds over the analysed trials of the RT outcome."""
    if trials is None:
        return {}
    from realpen.stats.data import outcomes

    found = next((o for o in outcomes(trials.design) if o.kind == "log_rt"), None)
    if found is None or "modality" not in trials.frame.columns:
        return {}
    people = analysis.participants
    kept = (set(people.loc[people["outcome"] == found.name, "participant"].astype(str))
            if isinstance(people, pd.DataFrame) and "outcome" in people.columns else set())
    frame = trials.frame
    rows = frame[(frame["question"] == found.question)
                 & frame["participant"].astype(str).isin(kept)]
    times = rows["rt_ms"].to_numpy(dtype=float)
    with np.errstate(invalid="ignore"):
        timed = np.isfinite(times) & (times > 0)
    modality = rows["modality"].astype(str).to_numpy()[timed]
    seconds = times[timed] / 1000.0
    return {level: seconds[modality == level] for level in STUDY2_RT}


def _study2(analysis: StudyAnalysis, trials) -> list[dict]:
    rows = []
    results = analysis.results
    cells = analysis.cells
    for modality, rate in STUDY2_RATES.items():
        found = (cells[(cells["outcome"] == "recognition") & (cells["factor"] == "modality")
                       & (cells["level"] == modality)]
                 if isinstance(cells, pd.DataFrame) and "outcome" in cells.columns
                 else pd.DataFrame())
        rows.append(_row("cells/modality", "recognition", modality, "rate_percent", rate,
                         float(found["mean"].iloc[0]) if len(found) else NaN,
                         "mean over participants of each one's percent correct"))
    for outcome, table in (("recognition", STUDY2_RECOGNITION), ("log_rt", STUDY2_RT_ANOVA)):
        for effect, numbers in table.items():
            paper = dict(zip(TEST_QUANTITIES, numbers))
            for name, label in (("rm-anova", f"{_RECOMMENDED}: participants as subjects"),
                                ("rm-anova/paper-compatible", _PSEUDO)):
                found = _result(results, name, outcome, effect, test="RM-ANOVA")
                if found is None and name.endswith("paper-compatible"):
                    continue
                note = label
                if outcome == "log_rt":
                    note += ("; ours on each participant's mean ln RT, the paper's on RT in "
                             "seconds; its df imply repetitions as subjects, which no "
                             "paper-compatible row repeats for response times")
                rows += _test_rows(name, outcome, effect, found, paper, note, test="RM-ANOVA")
    seconds = _rt_seconds(analysis, trials)
    for modality, (mean, sd) in STUDY2_RT.items():
        values = seconds.get(modality, np.array([]))
        note = ("arithmetic mean and SD of the response time (s) over every analysed trial; "
                "the paper does not say whether its SD is over trials or participants")
        if trials is None:
            note = "needs the trials (the analysis keeps each participant's geometric mean)"
        for quantity, reported, ours in (
                ("mean", mean, float(values.mean()) if len(values) else NaN),
                ("sd", sd, float(values.std(ddof=1)) if len(values) > 1 else NaN)):
            rows.append(_row("response-times/modality", "rt_seconds", modality, quantity,
                             reported, ours, note))
    for item, chi2 in STUDY2_FRIEDMAN.items():
        found = _result(results, "friedman/modality", item, "modality")
        rows += _test_rows("friedman/modality", item, "modality", found, {"statistic": chi2},
                           "Friedman over the three modalities; the paper gives chi-squared "
                           "only (and no means in its text)", test="Friedman")
    return rows


# --- the comparisons as sentences -----------------------------------------------------------

def _paper_sentence(group: pd.DataFrame, test: str) -> str:
    """The paper's numbers of one comparison written as :func:`apa_sentence` writes ours."""
    values = dict(zip(group["quantity"], group["paper"]))
    reported = dict(zip(group["quantity"], group["reported"].fillna("").astype(str)))
    if "rate_percent" in values:
        return f"{values['rate_percent']:.2f} %"
    if "mean" in values or "sd" in values:
        return _mean_sd(values.get("mean", NaN), values.get("sd", NaN))
    p = values.get("p", NaN)
    statistic = values.get("statistic", NaN)
    if not math.isfinite(statistic):  # a p-value alone (the post hoc tests), or "n.s."
        sentence = apa_p(p) if math.isfinite(p) else reported.get("p", "")
    else:
        sentence = apa_sentence({"test": test, "statistic_name": _STATISTIC_NAMES.get(test, ""),
                                 "statistic": statistic, "df1": values.get("df1", NaN),
                                 "df2": values.get("df2", NaN), "p": p})
    if sentence and reported.get("p", "").startswith("<"):  # a bound, not a value
        sentence = sentence.replace(apa_p(p), f"p {reported['p']}")
    return sentence


_STATISTIC_NAMES = {"Friedman": "chi2", "RM-ANOVA": "F", "Wilcoxon signed-rank": "T",
                    "paired t": "t"}


def _mean_sd(mean: float, sd: float) -> str:
    parts = [f"M = {mean:.3f} s" if math.isfinite(mean) else "",
             f"SD = {sd:.3f} s" if math.isfinite(sd) else ""]
    return ", ".join(part for part in parts if part)


def _our_sentence(group: pd.DataFrame, results: pd.DataFrame | None) -> str:
    values = dict(zip(group["quantity"], group["ours"]))
    first = group.iloc[0]
    if "rate_percent" in values:
        rate = values["rate_percent"]
        return f"{rate:.2f} %" if math.isfinite(rate) else ""
    if "mean" in values or "sd" in values:
        return _mean_sd(values.get("mean", NaN), values.get("sd", NaN))
    test = str(first.get("test") or "")
    found = _result(results, first["analysis"], first["outcome"], first["effect"],
                    test=test or None)
    if found is None:
        return ""
    if "apa" in found.index and isinstance(found["apa"], str) and found["apa"]:
        sentence = found["apa"]
    else:
        sentence = apa_sentence(found.to_dict())
    if set(values) == {"p"}:  # the paper gives the unadjusted p: ours first, unadjusted
        sentence = apa_sentence({**found.to_dict(), "adjust": "none"})
    return sentence


def comparison_table(analysis: StudyAnalysis) -> pd.DataFrame:
    """Each comparison of ``analysis.paper`` as two sentences: the paper's numbers and ours.

    One row per ``analysis, outcome, effect`` of the paper table (in its order): ``paper`` the
    paper's statistic, df and p written as :func:`realpen.stats.results.apa_sentence` writes
    ours (``F(2, 142) = 9.47, p < .001``; a rate ``62.96 %``; a mean ``M = 9.247 s, SD =
    5.086 s``), ``ours`` our row's APA sentence (its ``apa``), ``note`` as in the paper table.

    Returns:
        :data:`COMPARISON_COLUMNS`; empty when the paper table is.
    """
    paper = analysis.paper
    if not isinstance(paper, pd.DataFrame) or paper.empty:
        return pd.DataFrame(columns=list(COMPARISON_COLUMNS))
    paper = paper.copy()
    for column in ("test", "reported"):
        if column not in paper.columns:
            paper[column] = ""
    paper["test"] = paper["test"].fillna("").astype(str)
    rows = []
    keys = ["analysis", "outcome", "effect", "test"]
    for key, group in paper.groupby(keys, sort=False):
        name, outcome, effect, test = key
        notes = list(dict.fromkeys(str(note) for note in group["note"].fillna("") if note))
        rows.append({"analysis": name, "outcome": outcome, "effect": effect, "test": test,
                     "paper": _paper_sentence(group, test),
                     "ours": _our_sentence(group, analysis.results), "note": " / ".join(notes)})
    return pd.DataFrame(rows, columns=list(COMPARISON_COLUMNS))
