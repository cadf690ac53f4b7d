"""What a reviewer pastes: APA-style sentences, pairs named by their two levels, each method
listed once in the report, and every number the paper gives set beside ours in paper.csv."""

from __future__ import annotations

import html
import math
import re

import numpy as np
import pandas as pd
import pytest

from realpen.stats import paper as paper_module
from realpen.stats.analyses import AnalysisOptions, analyse
from realpen.stats.anova import pairwise
from realpen.stats.data import read_trials
from realpen.stats.report import method_list, report_html
from realpen.stats.results import RESULT_COLUMNS, apa_sentence, completed, with_context
from realpen.stats.simulate import ResponseModel, simulated_trials
from realpen.study.design import load_design

NAN = math.nan


def row(test: str, name: str, statistic: float, p: float, **more) -> dict:
    return {"test": test, "statistic_name": name, "statistic": statistic, "p": p, **more}


# ------------------------------------------------------------------ APA sentences

@pytest.mark.parametrize(("result", "sentence"), [
    (row("Friedman", "chi2", 6.452, 0.0397, df1=2, effect_size_name="kendall_w",
         effect_size=0.2688), "χ²(2) = 6.45, p = .040, W = .27"),
    (row("Wilcoxon signed-rank", "T", 3.0, 0.0253, effect_size_name="r", effect_size=0.6466,
         n=12), "T = 3.0, z = −2.24, p = .025, r = .65"),
    (row("RM-ANOVA", "F", 9.473, 0.00012, df1=2, df2=142, effect_size_name="ges",
         effect_size=0.0521), "F(2, 142) = 9.47, p < .001, η²G = .05"),
    (row("RM-ANOVA, Greenhouse–Geisser", "F", 4.1, 0.0312, df1=1.6834, df2=18.5174,
         effect_size_name="ges", effect_size=0.004), "F(1.68, 18.52) = 4.10, p = .031, η²G = .004"),
    (row("paired t", "t", -2.314, 0.0411, df1=11, effect_size_name="cohen_dz",
         effect_size=-0.668, p_adjusted=0.1233, adjust="bonferroni"),
     "t(11) = −2.31, p = .041 (Bonferroni-adjusted p = .123), d_z = −0.67"),
    (row("binomial GEE", "chi2", 12.3, 0.00213, df1=2), "χ²(2) = 12.30, p = .002"),
    (row("linear mixed model", "chi2", 0.0004, 0.99998, df1=4), "χ²(4) = 0.00, p > .999"),
    (row("exact binomial", "k", 31, 0.0037, n=60, p_adjusted=0.0111, adjust="holm",
         effect_size_name="cohen_h", effect_size=0.3704),
     "p = .004 (k/n = 31/60; Holm-adjusted p = .011), h = 0.37"),
    (row("paired t", "t", -0.0004, 0.9997, df1=11), "t(11) = 0.00, p > .999"),
    (row("Friedman", "chi2", NAN, NAN, df1=2), ""),
])
def test_apa_sentence_of_each_test(result, sentence):
    assert apa_sentence(result) == sentence


def test_completed_fills_the_sentence_and_empty_levels_of_a_frame_made_by_hand():
    frame = pd.DataFrame([row("Friedman", "chi2", 6.452, 0.0397, df1=2, analysis="x")])
    done = completed(frame)
    assert list(done.columns) == list(RESULT_COLUMNS)
    assert done.loc[0, "apa"] == "χ²(2) = 6.45, p = .040" and done.loc[0, "level_b"] == ""


# ------------------------------------------------------------------ pairs and their levels

def test_pairs_are_named_by_both_levels_and_split_into_columns():
    levels = ["tactile", "auditory", "audio-tactile"]
    data = pd.DataFrame([(s, m) for s in range(6) for m in levels], columns=["s", "modality"])
    data["y"] = np.arange(len(data)) % 5 + data["modality"].map(
        {"tactile": 0.0, "auditory": 0.5, "audio-tactile": 1.5})
    data["modality"] = pd.Categorical(data["modality"], categories=levels)
    pairs = pairwise(data, dv="y", within="modality", subject="s", test="wilcoxon")
    table = with_context(pairs, analysis="wilcoxon/modality", outcome="realism",
                         p_adjusted=pairs["p_adjusted"], adjust="holm")
    assert list(table["effect"]) == ["tactile vs auditory", "tactile vs audio-tactile",
                                     "auditory vs audio-tactile"]
    assert list(zip(table["level_a"], table["level_b"])) == [
        ("tactile", "auditory"), ("tactile", "audio-tactile"), ("auditory", "audio-tactile")]
    assert all(text.startswith("T = ") for text in table["apa"])
    friedman_like = with_context(pairs.drop(columns=["a", "b"]), analysis="x", outcome="y")
    assert (friedman_like["level_a"] == "").all()


# ------------------------------------------------------------------ methods once

def test_method_list_gives_methods_that_differ_in_numbers_once_with_row_details():
    methods = ["exact; zeros dropped (2); Holm over 15 pairs",
               "exact; zeros dropped (3); Holm over 15 pairs",
               "scipy.stats.friedmanchisquare",
               "exact; zeros dropped (2); Holm over 15 pairs"]
    texts, numbers, details = method_list(methods)
    assert texts == ["exact; zeros dropped (…); Holm over 15 pairs",
                     "scipy.stats.friedmanchisquare"]
    assert numbers == [1, 1, 2, 1]
    assert details == ["zeros dropped (2)", "zeros dropped (3)", "", "zeros dropped (2)"]


# ------------------------------------------------------------------ simulated studies

@pytest.fixture(scope="module")
def study1(tmp_path_factory):
    design = load_design("study1")
    path = tmp_path_factory.mktemp("s1") / "trials.csv"
    simulated_trials(design, 8, model=ResponseModel(effect=1.0), seed=5).to_csv(path, index=False)
    return analyse(read_trials(path, design), AnalysisOptions(paper_compatible=True))


@pytest.fixture(scope="module")
def study2(tmp_path_factory):
    design = load_design("study2")
    path = tmp_path_factory.mktemp("s2") / "trials.csv"
    simulated_trials(design, 8, model=ResponseModel(effect=0.8), seed=6).to_csv(path, index=False)
    return analyse(read_trials(path, design), AnalysisOptions(paper_compatible=True))


def test_every_result_row_has_its_sentence(study1, study2):
    for analysis in (study1, study2):
        results = analysis.results
        assert list(results.columns) == list(RESULT_COLUMNS)
        tested = results["statistic"].notna()
        assert (results.loc[tested, "apa"] != "").all()
        pairs = results["effect"].str.contains(" vs ")
        assert (results.loc[pairs, "level_a"] != "").all()
        assert (results.loc[~pairs, "level_a"] == "").all()


def test_the_report_gives_each_method_once(study1):
    text = report_html(study1)
    results = study1.results
    wilcoxon = results[results["analysis"] == "wilcoxon/condition"]
    assert len(wilcoxon) == 30  # Q1 and Q2, 15 pairs each
    # The Wilcoxon method's text: once per listed variant (ties or none, zeros or none, the
    # paper-compatible one), not once per row.
    common = html.escape("r = z/sqrt(n) with z uncorrected; Holm over the 15 testable of 15 pairs")
    listed = re.findall(r'<li id="method-(\d+)">(.*?)</li>', text, flags=re.S)
    assert [number for number, _ in listed] == [str(k) for k in range(1, len(listed) + 1)]
    assert 1 <= text.count(common) == sum(common in item for _, item in listed) <= 4
    assert len(listed) < 12 < len(results)
    assert len(re.findall(r'href="#method-\d+"', text)) == len(results)
    for sentence in results["apa"]:
        assert html.escape(sentence) in text


def numbers(paper: pd.DataFrame, outcome: str, effect: str, analysis: str | None = None
            ) -> dict[str, float]:
    found = paper[(paper["outcome"] == outcome) & (paper["effect"] == effect)]
    if analysis is not None:
        found = found[found["analysis"] == analysis]
    return dict(zip(found["quantity"], found["paper"]))


def test_paper_csv_of_study1_has_table2_and_the_posthoc_tests(study1):
    paper = study1.paper
    assert list(paper.columns)[:7] == ["analysis", "outcome", "effect", "quantity", "paper",
                                       "ours", "note"]
    for outcome, factor, chi2, df, p in (("Q1", "superposition", 6.45, 2, 0.040),
                                         ("Q1", "fluctuation", 8.91, 1, 0.003),
                                         ("Q2", "superposition", 5.66, 2, 0.059),
                                         ("Q2", "fluctuation", 2.88, 1, 0.090)):
        assert numbers(paper, outcome, factor) == {"statistic": chi2, "df1": df, "p": p}
    for pair, p in (("D vs F", 0.025), ("B vs E", 0.046), ("C vs F", 0.047)):
        assert numbers(paper, "Q1", pair, "wilcoxon/condition") == {"p": p}
        assert numbers(paper, "Q1", pair, "wilcoxon/condition/paper-compatible") == {"p": p}
    not_significant = paper[paper["effect"] == "A vs D"]
    assert len(not_significant) == 4 and set(not_significant["reported"]) == {"n.s."}
    sentences = paper_module.comparison_table(study1)
    assert set(sentences.loc[sentences["effect"] == "A vs D", "paper"]) == {"n.s."}
    tested = paper[paper["quantity"].isin(["statistic", "df1", "p"])]
    assert tested["ours"].notna().all()


def test_paper_csv_of_study2_has_every_number_the_paper_gives(study2):
    paper = study2.paper
    for modality, rate in (("tactile", 43.05), ("auditory", 50.96), ("audio-tactile", 62.96)):
        assert numbers(paper, "recognition", modality) == {"rate_percent": rate}
    for effect, values in (("modality", (9.473, 2, 142, 0.001)), ("pen", (3.245, 2, 142, 0.042)),
                           ("modality:pen", (3.962, 4, 284, 0.004))):
        expected = dict(zip(("statistic", "df1", "df2", "p"), values))
        for name in ("rm-anova", "rm-anova/paper-compatible"):
            assert numbers(paper, "recognition", effect, name) == expected
    bound = paper[(paper["outcome"] == "recognition") & (paper["effect"] == "modality")
                  & (paper["quantity"] == "p")]
    assert set(bound["reported"]) == {"< .001"}
    rt = {effect: numbers(paper, "log_rt", effect, "rm-anova")["statistic"]
          for effect in ("pen", "modality", "modality:pen")}
    assert rt == {"pen": 0.860, "modality": 1.927, "modality:pen": 0.798}
    assert numbers(paper, "log_rt", "pen", "rm-anova")["df2"] == 142
    for modality, mean, sd in (("tactile", 9.247, 5.086), ("auditory", 8.851, 6.498),
                               ("audio-tactile", 8.497, 4.406)):
        assert numbers(paper, "rt_seconds", modality) == {"mean": mean, "sd": sd}
        ours = paper[(paper["outcome"] == "rt_seconds") & (paper["effect"] == modality)]
        assert ours["ours"].between(0.05, 60).all()  # seconds, from the trials
    for item, chi2 in (("realism", 8.211), ("comfort", 1.077), ("strength", 3.257)):
        assert numbers(paper, item, "modality")["statistic"] == chi2
    # Ours beside each: statistic, df and p of every test the paper reports.
    tests = paper[paper["test"].fillna("") != ""]
    assert tests["ours"].notna().all()
    assert {"statistic", "df1", "df2", "p"} <= set(tests["quantity"])


def test_the_report_sets_the_papers_sentence_beside_ours(study2):
    table = paper_module.comparison_table(study2)
    anova = table[(table["analysis"] == "rm-anova") & (table["outcome"] == "recognition")
                  & (table["effect"] == "modality")].iloc[0]
    assert anova["paper"] == "F(2, 142) = 9.47, p < .001"
    assert anova["ours"].startswith("F(2, 14) = ")  # 8 participants
    rt = table[table["outcome"] == "rt_seconds"].iloc[0]
    assert rt["paper"] == "M = 9.247 s, SD = 5.086 s" and rt["ours"].startswith("M = ")
    text = report_html(study2)
    section = text[text.index('id="paper"'):]
    assert html.escape("F(2, 142) = 9.47, p < .001") in section
    assert "−118" not in section and "ours − paper" not in section
