"""The studies' analyses and ``realpen stats``: simulated participants → export format →
results, checked against the library functions, and the bad data a user can bring.

The study-2 data are simulated once per module (:func:`realpen.stats.simulate.simulated_trials`)
and written as the export writes them; the store round trip (the real session service and
``realpen study export``) is tested once, end to end, at the bottom.
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from conftest import assert_clean_failure, run_cli
from scipy import stats as scipy_stats

from realpen.errors import RealPenError
from realpen.stats.analyses import AnalysisOptions, IncompleteError, analyse
from realpen.stats.data import cell_values, outcomes, read_trials
from realpen.stats.results import RESULT_COLUMNS
from realpen.stats.simulate import ResponseModel, simulated_trials
from realpen.study.design import load_design

STUDY1 = load_design("study1")
STUDY2 = load_design("study2")


def write_csv(frame: pd.DataFrame, path: Path) -> Path:
    frame.to_csv(path, index=False)
    return path


@pytest.fixture(scope="module")
def study1_csv(tmp_path_factory) -> Path:
    frame = simulated_trials(STUDY1, 12, model=ResponseModel(effect=1.2), seed=3)
    return write_csv(frame, tmp_path_factory.mktemp("s1") / "trials.csv")


@pytest.fixture(scope="module")
def study2_csv(tmp_path_factory) -> Path:
    frame = simulated_trials(STUDY2, 12, model=ResponseModel(effect=0.8, pen_effect=0.5), seed=4)
    return write_csv(frame, tmp_path_factory.mktemp("s2") / "trials.csv")


@pytest.fixture(scope="module")
def study1(study1_csv):
    return analyse(read_trials(study1_csv, STUDY1))


@pytest.fixture(scope="module")
def study2(study2_csv):
    return analyse(read_trials(study2_csv, STUDY2))


@pytest.fixture(scope="module")
def study2_paper(study2_csv):
    return analyse(read_trials(study2_csv, STUDY2), AnalysisOptions(paper_compatible=True))


def rows(results: pd.DataFrame, **where) -> pd.DataFrame:
    mask = np.ones(len(results), dtype=bool)
    for column, value in where.items():
        mask &= (results[column] == value).to_numpy()
    return results[mask]


def test_results_have_the_fixed_columns_and_name_every_method(study1, study2):
    for analysis in (study1, study2):
        assert list(analysis.results.columns) == list(RESULT_COLUMNS)
        assert analysis.results["method"].str.len().min() > 10
        assert analysis.results["p"].between(0, 1).all()
        assert (analysis.results["p_adjusted"] >= analysis.results["p"] - 1e-12).all()


def test_study1_friedman_of_the_conditions_equals_scipy_on_participants_cells(study1_csv, study1):
    trials = read_trials(study1_csv, STUDY1)
    q1 = next(o for o in outcomes(STUDY1) if o.name == "Q1")
    values, missing = cell_values(trials, q1)
    assert not missing
    wide = values.pivot(index="participant", columns="condition", values="value")
    expected = scipy_stats.friedmanchisquare(*[wide[c] for c in "ABCDEF"])
    found = rows(study1.results, analysis="friedman/condition", outcome="Q1").iloc[0]
    assert found["statistic"] == pytest.approx(expected.statistic, rel=1e-9)
    assert found["p"] == pytest.approx(expected.pvalue, rel=1e-9)
    assert (found["df1"], found["n"]) == (5, 12)


@pytest.mark.slow
def test_study1_splits_the_conditions_and_names_the_friedman_variant(study1_csv, study1):
    for factor in ("superposition", "fluctuation"):
        found = rows(study1.results, analysis=f"friedman/{factor}/average", outcome="Q2")
        assert len(found) == 1 and "variant (a)" in found.iloc[0]["method"]
    art = rows(study1.results, analysis="art/superposition:fluctuation", outcome="Q1")
    assert set(art["effect"]) == {"superposition", "fluctuation", "superposition:fluctuation"}
    assert set(art["df1"]) == {1, 2}
    per_level = analyse(read_trials(study1_csv, STUDY1),
                        AnalysisOptions(friedman_variant="per-level")).results
    found = rows(per_level, analysis="friedman/superposition/per-level", outcome="Q1")
    assert sorted(found["effect"]) == ["superposition | fluctuation=15x100ms",
                                       "superposition | fluctuation=1x1500ms"]
    assert (found["adjust"] == "holm").all()
    cells = analyse(read_trials(study1_csv, STUDY1),
                    AnalysisOptions(friedman_variant="cells")).results
    found = rows(cells, analysis="friedman/superposition/cells", outcome="Q1").iloc[0]
    assert found["n"] == 24  # 12 participants × 2 fluctuation levels as blocks


def test_study1_posthoc_pairs_are_all_fifteen_with_holm(study1):
    pairs = rows(study1.results, analysis="wilcoxon/condition", outcome="Q1")
    assert len(pairs) == 15 and "D vs F" in set(pairs["effect"])
    assert (pairs["adjust"] == "holm").all()
    paper = study1.paper
    assert set(paper["effect"]) >= {"D vs F", "B vs E", "C vs F", "A vs D"}


def test_study1_cells_are_per_condition_with_intervals(study1):
    cells = rows(study1.cells, outcome="Q1", factor="condition")
    assert list(cells["level"]) == list("ABCDEF")
    assert (cells["ci_low"] <= cells["mean"]).all() and (cells["mean"] <= cells["ci_high"]).all()
    assert (cells["ci_method"] == "bootstrap").all()
    assert len(rows(study1.participants, outcome="Q1", factor="condition")) == 72


def test_study2_recognition_anova_has_participants_as_subjects(study2):
    anova = rows(study2.results, analysis="rm-anova", outcome="recognition", test="RM-ANOVA")
    df = {row.effect: (row.df1, row.df2) for row in anova.itertuples()}
    assert df == {"modality": (2, 22), "pen": (2, 22), "modality:pen": (4, 44)}
    corrected = rows(study2.results, analysis="rm-anova", outcome="recognition",
                     test="RM-ANOVA, Greenhouse–Geisser")
    assert set(corrected["effect"]) == {"modality", "pen", "modality:pen"}
    assert (corrected["df2"] <= 44 + 1e-9).all()
    assert not study2.results["method"].str.startswith("paper-compatible").any()


def test_study2_anova_equals_statsmodels_on_the_participants_rates(study2_csv, study2):
    from statsmodels.stats.anova import AnovaRM

    trials = read_trials(study2_csv, STUDY2)
    recognition = next(o for o in outcomes(STUDY2) if o.name == "recognition")
    values, _ = cell_values(trials, recognition)
    assert values["trials"].eq(6).all()  # 6 experimental trials per modality × pen
    table = AnovaRM(values, depvar="value", subject="participant",
                    within=["modality", "pen"]).fit().anova_table
    found = rows(study2.results, analysis="rm-anova", outcome="recognition", test="RM-ANOVA",
                 effect="modality").iloc[0]
    assert found["statistic"] == pytest.approx(table.loc["modality", "F Value"], rel=1e-9)
    assert found["p"] == pytest.approx(table.loc["modality", "Pr > F"], rel=1e-9)


def test_paper_compatible_adds_the_papers_df_marked(study2, study2_paper):
    marked = study2_paper.results[study2_paper.results["method"].str.startswith("paper-compatible")]
    anova = rows(marked, analysis="rm-anova/paper-compatible", outcome="recognition",
                 test="RM-ANOVA")
    df = {row.effect: (row.df1, row.df2) for row in anova.itertuples()}
    assert df == {"modality": (2, 142), "pen": (2, 142), "modality:pen": (4, 284)}
    assert marked["method"].str.contains("not recommended").all()
    # The paper ran post hoc Wilcoxon tests on study 1's conditions only.
    assert rows(marked, analysis="wilcoxon/modality/paper-compatible").empty
    # the recommended rows are all still there, unchanged
    plain = study2.results[~study2.results["method"].str.startswith("paper-compatible")]
    unmarked = study2_paper.results[
        ~study2_paper.results["method"].str.startswith("paper-compatible")].reset_index(drop=True)
    pd.testing.assert_frame_equal(plain.reset_index(drop=True), unmarked)
    paper = study2_paper.paper
    df2 = rows(paper, analysis="rm-anova/paper-compatible", effect="modality", quantity="df2")
    assert float(df2["ours"].iloc[0]) == 142 == float(df2["paper"].iloc[0])


def test_study2_questionnaire_confusion_and_times(study2):
    friedman = rows(study2.results, analysis="friedman/modality")
    assert set(friedman["outcome"]) == {"realism", "comfort", "strength"}
    assert "balance" not in set(study2.results["outcome"])
    assert len(rows(study2.cells, outcome="balance")) == 1
    confusion = study2.confusion
    assert confusion["count"].sum() == 12 * 3 * 18  # experimental trials only
    for (_, _), group in confusion.groupby(["modality", "pen"]):
        assert group["row_percent"].sum() == pytest.approx(100.0)
    times = rows(study2.cells, outcome="log_rt", factor="modality:pen")
    assert len(times) == 9 and (times["unit"] == "ms").all()
    assert times["mean"].between(1000, 20000).all()  # geometric means in ms, not logs


@pytest.mark.slow
def test_the_wilcoxon_method_is_named_and_changes_tied_p(study1_csv):
    trials = read_trials(study1_csv, STUDY1)
    found = {}
    for method in ("exact", "r", "spss"):
        results = analyse(trials, AnalysisOptions(wilcoxon_method=method,
                                                  paper_compatible=method == "exact")).results
        pairs = rows(results, analysis="wilcoxon/condition", outcome="Q1")
        found[method] = pairs["p"].to_numpy()
        assert pairs["method"].str.contains(method if method != "r" else "R").all()
        if method == "exact":
            paper = rows(results, analysis="wilcoxon/condition/paper-compatible", outcome="Q1")
            found["paper"] = paper["p"].to_numpy()
            assert paper["method"].str.startswith("paper-compatible: SPSS-style").all()
    assert not np.allclose(found["r"], found["spss"])
    np.testing.assert_allclose(found["paper"], found["spss"], rtol=1e-12)


# -- bad data ----------------------------------------------------------------------------------

def edited(source: Path, target: Path, change) -> Path:
    with open(source, newline="") as handle:
        records = list(csv.DictReader(handle))
    records = change(records)
    with open(target, "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(records[0].keys()) if records else ["x"])
        writer.writeheader()
        writer.writerows(records)
    return target


@pytest.mark.slow
def test_a_participant_missing_a_cell_is_refused_or_excluded_and_listed(study1_csv, tmp_path):
    path = edited(study1_csv, tmp_path / "t.csv", lambda records: [
        r for r in records if not (r["participant"] == "S03" and r["condition"] == "E"
                                   and r["question"] == "Q1")])
    with pytest.raises(IncompleteError, match=r"t\.csv: participant S03: no answer to Q1 in "
                                              r"condition E$"):
        analyse(read_trials(path, STUDY1))
    refused = run_cli("stats", "study1", str(path), "-o", str(tmp_path / "r"))
    assert_clean_failure(refused, "condition E; rerun with --exclude-incomplete")
    analysis = analyse(read_trials(path, STUDY1), AnalysisOptions(exclude_incomplete=True))
    assert analysis.excluded == {"S03": "no answer to Q1 in condition E (left out of Q1)"}
    # left out of the outcome it misses only
    friedman = rows(analysis.results, analysis="friedman/condition")
    assert dict(zip(friedman["outcome"], friedman["n"])) == {"Q1": 11, "Q2": 12}


@pytest.mark.parametrize(("change", "message"), [
    (lambda r: [{k: v for k, v in x.items() if k != "rt_ms"} for x in r], "missing column rt_ms"),
    (lambda r: [{**x, "answer": "four"} if x["question"] == "Q2" else x for x in r],
     r"line \d+: participant S\d+, trial \d+: Q2 answer 'four' is not a rating from 1 to 5"),
    (lambda r: [{**x, "answer": "9"} if x["question"] == "Q1" else x for x in r],
     "Q1 answer '9' is not a rating from 1 to 5"),
    (lambda r: [{**x, "rt_ms": "-3"} for x in r], "rt_ms '-3' is not a number"),
    (lambda r: [{**x, "study": "other"} for x in r],
     "no answers of study 'study1' \\(studies in the file: other\\)"),
    (lambda r: [x for x in r if x["participant"] == "S01"],
     "1 participant of study 'study1' complete in Q1: at least 2 are needed"),
    (lambda r: [{**x, "condition": "G"} if x["participant"] == "S02" and x["trial"] == "3" else x
                for x in r], r"participant S02, trial 3: condition 'G' is not planned for Q1"),
    (lambda r: r + [r[5]], r"participant S01 answers Q2 of trial 3 2 times"),
    (lambda r: [{**x, "session": "9"} if x["participant"] == "S01" and x["trial"] == "2" else x
                for x in r], r"participant S01 has answers in 2 sessions \(1, 9\)"),
])
def test_bad_trials_files_get_one_line(study1_csv, tmp_path, change, message):
    path = edited(study1_csv, tmp_path / "bad.csv", change)
    with pytest.raises(RealPenError, match=message) as caught:
        analyse(read_trials(path, STUDY1))
    assert "\n" not in str(caught.value) and str(caught.value).startswith(str(path))


@pytest.mark.slow
def test_two_participants_and_untestable_sphericity_do_not_crash(tmp_path):
    frame = simulated_trials(STUDY2, 2, seed=1)
    analysis = analyse(read_trials(write_csv(frame, tmp_path / "two.csv"), STUDY2))
    anova = rows(analysis.results, analysis="rm-anova", outcome="recognition", test="RM-ANOVA")
    assert set(anova["df2"]) == {2, 4}  # df1 × (2 - 1)
    assert anova["method"].str.contains("Mauchly's test untestable").all()
    assert not any("violated" in note for note in analysis.notes)
    small = simulated_trials(STUDY1, 2, model=ResponseModel(effect=1.0), seed=1)
    art = rows(analyse(read_trials(write_csv(small, tmp_path / "s1.csv"), STUDY1)).results,
               analysis="art/superposition:fluctuation")
    assert len(art) == 6 and (art["n"] == 2).all()


def test_recognition_answers_must_agree_with_the_pen_and_zero_times_are_noted(tmp_path):
    frame = simulated_trials(STUDY2, 3, seed=2)
    wrong = frame.copy()
    index = wrong.index[(wrong["question"] == "pen") & (wrong["phase"] == "experimental")][0]
    wrong.loc[index, "correct"] = "1" if wrong.loc[index, "correct"] == "0" else "0"
    with pytest.raises(RealPenError, match=r"correct '\d' disagrees with the answer"):
        read_trials(write_csv(wrong, tmp_path / "w.csv"), STUDY2)
    zero = frame.copy()
    zero.loc[index, "rt_ms"] = 0.0
    analysis = analyse(read_trials(write_csv(zero, tmp_path / "z.csv"), STUDY2))
    assert "log_rt: 1 response time of 0 ms left out (no logarithm)" in analysis.notes


def test_several_recognition_questions_are_separate_outcomes():
    document = STUDY2.model_dump(mode="json")
    second = {**next(q for q in document["questions"] if q["id"] == "pen"), "id": "pen2"}
    document["questions"].append(second)
    for group in document["blocks"][0]["trials"]:
        group["questions"] = ["pen", "pen2"]
    from realpen.study.design import Design

    design = Design.model_validate(document)
    names = [(o.name, o.question) for o in outcomes(design) if o.kind != "likert"]
    assert names == [("recognition:pen", "pen"), ("log_rt:pen", "pen"),
                     ("recognition:pen2", "pen2"), ("log_rt:pen2", "pen2")]


# -- the command ---------------------------------------------------------------------------------

@pytest.mark.slow
def test_the_command_writes_the_report_folder(study2_csv, tmp_path):
    out = tmp_path / "report"
    result = run_cli("stats", "study2", str(study2_csv), "-o", str(out), "--paper-compatible",
                     "--power-sims", "0")
    assert result.returncode == 0, result.stderr
    assert f"wrote {out}" in result.stdout
    table = pd.read_csv(out / "results.csv")
    assert list(table.columns) == list(RESULT_COLUMNS)
    modality = table[(table["outcome"] == "recognition") & (table["effect"] == "modality")
                     & (table["test"] == "RM-ANOVA")]
    assert sorted(zip(modality["df1"], modality["df2"])) == [(2, 22), (2, 142)]
    html = (out / "report.html").read_text()
    assert "paper-compatible" in html and "Greenhouse" in html
    for name in ("figure10", "figure11", "figure12"):
        assert (out / f"{name}.png").stat().st_size > 1000 and (out / f"{name}.svg").exists()
    again = run_cli("stats", "study2", str(study2_csv), "-o", str(out))
    assert_clean_failure(again, "exists; pass --force")


def test_the_command_refuses_an_unknown_design_and_leaves_nothing(study2_csv, tmp_path):
    out = tmp_path / "report"
    result = run_cli("stats", "study9", str(study2_csv), "-o", str(out))
    assert_clean_failure(result, "study9: unknown design")
    assert not out.exists() and list(tmp_path.iterdir()) == []


def test_power_command_prints_a_table_and_plots(tmp_path):
    plot = tmp_path / "power.png"
    result = run_cli("stats", "power", "study2", "--participants", "8", "16", "--sims", "200",
                     "--effect", "1.0", "--plot", str(plot))
    assert result.returncode == 0, result.stderr
    lines = [line for line in result.stdout.splitlines() if line.startswith(("realism",
                                                                             "recognition"))]
    assert len(lines) == 4
    powers = {(line.split()[0], line.split()[-2]): float(line.split()[-1]) for line in lines}
    assert powers[("realism", "16")] > powers[("realism", "8")]
    assert plot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.slow
def test_simulated_participants_through_the_store_to_the_report(tmp_path):
    """The whole path a study takes: plan → answers through the study service into a real
    SQLite store → its export → ``realpen stats``."""
    store, trials, out = tmp_path / "sim.sqlite", tmp_path / "trials.csv", tmp_path / "report"
    made = run_cli("stats", "simulate", "study1", "-n", "6", "--store", str(store), "-o",
                   str(trials), "--effect", "2")
    assert made.returncode == 0, made.stderr
    exported = pd.read_csv(trials)
    assert exported["participant"].nunique() == 6 and len(exported) == 6 * (6 * 2 + 1)
    result = run_cli("stats", "study1", str(trials), "-o", str(out), "--power-sims", "0")
    assert result.returncode == 0, result.stderr
    table = pd.read_csv(out / "results.csv")
    found = table[(table["analysis"] == "friedman/condition") & (table["outcome"] == "Q1")]
    assert found["n"].tolist() == [6] and found["df1"].tolist() == [5]
    assert (out / "figure7.svg").exists() and (out / "report.html").stat().st_size > 10_000
    (out / "results.csv").write_text("stale")
    again = run_cli("stats", "study1", str(trials), "-o", str(out), "--power-sims", "0",
                    "--force")
    assert again.returncode == 0, again.stderr
    assert pd.read_csv(out / "results.csv").equals(table)  # replaced whole, same numbers
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []


def test_only_a_report_folder_is_ever_replaced(tmp_path, monkeypatch):
    from realpen.stats.outputs import MARKER, check_report_folder

    monkeypatch.chdir(tmp_path)
    report, foreign, empty = tmp_path / "report", tmp_path / "thesis", tmp_path / "empty"
    for folder in (report, foreign, empty):
        folder.mkdir()
    (report / MARKER).write_text("")
    (report / "results.csv").write_text("")
    (foreign / "thesis.tex").write_text("keep me")
    assert check_report_folder(report, replace=True) == report
    assert check_report_folder(empty, replace=True) == empty
    with pytest.raises(RealPenError, match="thesis: is a folder no report made"):
        check_report_folder(foreign, replace=True)
    with pytest.raises(RealPenError, match="report: exists; it is replaced only when"):
        check_report_folder(report, replace=False)
    with pytest.raises(RealPenError, match="holds the current folder"):
        check_report_folder(Path("."), replace=True)
    with pytest.raises(RealPenError, match="parent folder .* does not exist"):
        check_report_folder(tmp_path / "no" / "report", replace=False)
