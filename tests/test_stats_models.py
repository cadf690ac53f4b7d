"""Recognition against chance, the trial-level models beside the participant-level tests, and
the chance line in the recognition figures.

Study 2 is simulated (:func:`realpen.stats.simulate.simulated_trials`, 12 participants, fixed
seeds) with recognition rates far above chance and at chance; the models are checked against
a direct statsmodels fit of the same data.
"""

from __future__ import annotations

import warnings

import numpy as np
import pandas as pd
import pytest

from realpen.stats.analyses import AnalysisOptions, analyse
from realpen.stats.chance import chance_level, chance_tests, recognition_chance
from realpen.stats.data import outcomes, read_trials
from realpen.stats.figures import figure10, means_figure, recognition_figure
from realpen.stats.outcome import StudyAnalysis
from realpen.stats.results import RESULT_COLUMNS
from realpen.stats.simulate import ResponseModel, simulated_trials
from realpen.stats.trial_models import (
    binomial_gee,
    fit_binomial_gee,
    fit_mixed_model,
    mixed_model,
    outcome_trials,
    trial_model_tests,
)
from realpen.study.design import load_design

STUDY2 = load_design("study2")
MODALITIES = ("tactile", "auditory", "audio-tactile")


def study2_trials(tmp_path, *, rates: dict[str, float], seed: int, name: str = "trials.csv",
                  modality_rt: dict[str, float] | None = None):
    model = ResponseModel(rates=rates, modality_rt=modality_rt or {})
    path = tmp_path / name
    simulated_trials(STUDY2, 12, model=model, seed=seed).to_csv(path, index=False)
    return read_trials(path, STUDY2)


def recognition_of(trials):
    return next(o for o in outcomes(trials.design) if o.kind == "recognition")


def log_rt_of(trials):
    return next(o for o in outcomes(trials.design) if o.kind == "log_rt")


@pytest.fixture(scope="module")
def high(tmp_path_factory):
    """Study 2 with every modality recognised 90 % of the time."""
    return study2_trials(tmp_path_factory.mktemp("high"), rates=dict.fromkeys(MODALITIES, 0.9),
                         seed=5)


@pytest.fixture(scope="module")
def graded(tmp_path_factory):
    """Study 2 with a known modality effect: 40, 55 and 85 % right; audio-tactile answered
    e^0.3 = 1.35 times slower."""
    return study2_trials(tmp_path_factory.mktemp("graded"),
                         rates={"tactile": 0.4, "auditory": 0.55, "audio-tactile": 0.85}, seed=6,
                         modality_rt={"audio-tactile": 0.3})


# ------------------------------------------------------------------ chance

def test_chance_is_one_over_the_choices():
    assert chance_level(STUDY2, "pen") == pytest.approx(1 / 3)
    assert chance_level(STUDY2, "realism") is None


def test_recognition_far_above_chance_is_significant_per_modality_and_pen(high):
    recognition = recognition_of(high)
    parts = recognition_chance(high, recognition, high.participants)
    rows = pd.concat(parts, ignore_index=True)
    assert list(rows.columns) == list(RESULT_COLUMNS)
    assert set(rows["analysis"]) == {"chance/modality", "chance/modality/binomial",
                                     "chance/pen", "chance/pen/binomial"}
    primary = rows[rows["analysis"] == "chance/modality"]
    assert list(primary["effect"]) == list(MODALITIES)
    assert (primary["test"] == "Wilcoxon signed-rank").all()
    assert (primary["n"] == 12).all()
    # 12 participants all far above chance: the exact signed-rank p is 2/2^12 at most, Holm x3.
    assert (primary["p_adjusted"] < 0.01).all()
    assert (primary["effect_size"] > 0.8).all()
    assert (primary["adjust"] == "holm").all()
    assert primary["method"].str.contains("chance 1/3").all()
    binomial = rows[rows["analysis"] == "chance/modality/binomial"]
    assert (binomial["test"] == "exact binomial").all()
    assert (binomial["n"] == 12 * 18).all()  # trials, not participants
    assert (binomial["p"] < 1e-20).all()
    assert binomial["method"].str.contains("as independent").all()


def test_a_chance_sentence_says_on_which_side_of_chance_a_level_lies(tmp_path):
    trials = study2_trials(tmp_path, rates={"tactile": 0.05, "auditory": 0.9,
                                            "audio-tactile": 0.9}, seed=8)
    outcome = recognition_of(trials)
    parts = recognition_chance(trials, outcome, trials.participants)
    rows = pd.concat(parts)
    rows = rows[rows["analysis"] == "chance/modality"].set_index("effect")
    below, above = rows.loc["tactile", "apa"], rows.loc["auditory", "apa"]
    assert below.startswith("M = ") and "correct against chance 1/3, T = " in below
    assert float(below[4:].split(" %")[0]) < 100 / 3 < float(above[4:].split(" %")[0])


def test_recognition_at_chance_is_mostly_not_significant():
    rejected = tested = 0
    model = ResponseModel(rates=dict.fromkeys(MODALITIES, 1 / 3))
    for seed in range(4):
        answers = simulated_trials(STUDY2, 12, model=model, seed=seed)
        data = answers[(answers["question"] == "pen") & (answers["phase"] == "experimental")]
        table = chance_tests(data.astype({"correct": float}), dv="correct", within="modality",
                             subject="participant", chance=1 / 3)
        primary = table[table["family"] == "participants"]
        rejected += int((primary["p_adjusted"] < 0.05).sum())
        tested += len(primary)
    assert tested == 12
    assert rejected <= 2  # Holm over three levels: about 0.6 of 12 expected


def test_a_level_exactly_at_chance_has_no_statistic_but_the_others_are_tested():
    data = pd.DataFrame({"participant": np.repeat(np.arange(4), 6),
                         "modality": np.tile(["tactile", "tactile", "tactile", "auditory",
                                              "auditory", "auditory"], 4),
                         "correct": np.tile([1, 0, 0, 1, 1, 1], 4).astype(float)})
    table = chance_tests(data, dv="correct", within="modality", subject="participant",
                         chance=1 / 3)
    at_chance = table[(table["effect"] == "tactile") & (table["family"] == "participants")]
    assert np.isnan(at_chance["statistic"].iloc[0])
    assert "exactly at chance" in at_chance["method"].iloc[0]
    above = table[(table["effect"] == "auditory") & (table["family"] == "participants")]
    assert above["p_adjusted"].iloc[0] == pytest.approx(above["p"].iloc[0])  # one testable level


# ------------------------------------------------------------------ trial-level models

def test_gee_recovers_the_direction_of_a_known_modality_effect(graded):
    data = outcome_trials(graded, recognition_of(graded), graded.participants)
    fit = fit_binomial_gee(data, dv="correct", within=["modality", "pen"],
                           subject="participant")
    assert fit.failure == ""
    means = fit.cell_means().groupby("modality", observed=True)["mean"].mean()
    assert means["tactile"] < means["auditory"] < means["audio-tactile"]
    assert means["audio-tactile"] == pytest.approx(0.85, abs=0.08)
    notes: list[str] = []
    (rows,) = trial_model_tests(graded, recognition_of(graded), graded.participants, notes)
    assert list(rows["effect"]) == ["modality", "pen", "modality:pen"]
    assert (rows["analysis"] == "gee/recognition").all()
    assert (rows["test"] == "binomial GEE").all()
    assert (rows["statistic_name"] == "chi2").all()
    assert list(rows["df1"]) == [2, 2, 4]
    assert rows.set_index("effect").loc["modality", "p"] < 1e-6
    assert rows["method"].str.contains("exchangeable").all()
    assert rows["method"].str.contains("unit of inference").all()


def test_the_mixed_model_is_statsmodels_own_fit(graded):
    from statsmodels.regression.mixed_linear_model import MixedLM

    data = outcome_trials(graded, log_rt_of(graded), graded.participants)
    fit = fit_mixed_model(data, dv="log_rt", within=["modality", "pen"], subject="participant")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the direct fit's own warnings (a boundary variance)
        direct = MixedLM.from_formula("log_rt ~ C(modality, Sum) * C(pen, Sum)",
                                      groups="participant", data=data).fit(reml=True,
                                                                           method="powell")
        expected = direct.wald_test_terms(skip_single=False, scalar=True).table
    np.testing.assert_allclose(fit.result.fe_params.to_numpy(), direct.fe_params.to_numpy(),
                               rtol=1e-10)
    rows = mixed_model(data, dv="log_rt", within=["modality", "pen"], subject="participant")
    np.testing.assert_allclose(rows["statistic"], expected["statistic"].iloc[1:], rtol=1e-10)
    np.testing.assert_allclose(rows["df1"], expected["df_constraint"].iloc[1:])
    assert (rows["test"] == "linear mixed model").all()
    assert rows.set_index("effect").loc["modality", "p"] < 1e-6  # audio-tactile 1.35 x slower


def test_models_in_the_analysis_leak_no_warning_and_a_large_study_is_cut_with_a_note(graded):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        analysis = analyse(graded, AnalysisOptions(likert_ci="t"))  # no bootstrap: quicker
    found = set(analysis.results["analysis"])
    assert {"gee/recognition", "mixedlm/log_rt", "chance/modality"} <= found
    notes: list[str] = []
    (rows,) = trial_model_tests(graded, log_rt_of(graded), graded.participants, notes,
                                max_trials=200)
    assert rows["method"].str.contains("fitted on the first 3 of 12 participants").all()
    assert any("fitted on the first 3 of 12 participants" in note for note in notes)


def test_a_model_that_cannot_be_fitted_is_a_row_without_numbers():
    data = pd.DataFrame({"participant": np.repeat(np.arange(6), 4),
                         "pen": np.tile(["pencil", "marker"], 12),
                         "log_rt": np.nan})
    data.loc[0, "log_rt"] = 8.0
    rows = mixed_model(data, dv="log_rt", within="pen", subject="participant")
    assert len(rows) == 1 and not rows["converged"].iloc[0]
    assert np.isnan(rows["statistic"].iloc[0]) and "no test" in rows["method"].iloc[0]
    # Every marker recognised: an infinite log-odds, so the GEE's Wald tests would mean nothing.
    data["correct"] = np.tile([0.0, 1.0, 1.0, 1.0], 6)
    rows = binomial_gee(data, dv="correct", within="pen", subject="participant")
    assert np.isnan(rows["statistic"].iloc[0])
    assert rows["method"].iloc[0].startswith("every answer in cell marker is right")


# ------------------------------------------------------------------ figures

def _recognition_analysis(design: str = "study2") -> StudyAnalysis:
    cells = pd.DataFrame({"outcome": "recognition", "factor": "modality",
                          "level": list(MODALITIES), "mean": [43.05, 50.96, 62.96],
                          "ci_low": [35.0, 43.0, 55.0], "ci_high": [51.0, 59.0, 71.0],
                          "ci_method": "t", "n": 12, "unit": "%"})
    confusion = pd.DataFrame([{"modality": modality, "pen": pen, "chosen": chosen, "count": 4,
                               "row_percent": 100 / 3}
                              for modality in MODALITIES
                              for pen in ("pencil", "ballpoint", "marker")
                              for chosen in ("pencil", "ballpoint", "marker")])
    empty = pd.DataFrame()
    return StudyAnalysis(design, "Study 2", empty, cells, empty, confusion, empty)


def _chance_lines(axis) -> list:
    return [line for line in axis.get_lines()
            if line.get_linestyle() == "--" and line.get_label() == "chance (1/3)"]


def test_the_recognition_figures_draw_the_chance_line_at_one_third():
    axis = recognition_figure(_recognition_analysis()).axes[0]
    (line,) = _chance_lines(axis)
    assert np.allclose(line.get_ydata(), 100 / 3)
    assert "chance (1/3)" in [text.get_text() for text in axis.get_legend().get_texts()]
    (panel,) = means_figure(_recognition_analysis("mine"), "recognition").axes
    (line,) = _chance_lines(panel)
    assert np.allclose(line.get_ydata(), 100 / 3)
    figure = figure10(_recognition_analysis())
    bar = figure.axes[-1]
    assert "chance (1/3 = 33 %)" in bar.get_ylabel()
    assert any(np.allclose(line.get_ydata(), 100 / 3) for line in bar.get_lines())
