"""Simulated participants (realpen.stats.simulate) and power before the study (realpen.stats.power)."""

from __future__ import annotations

import importlib.util

import numpy as np
import pandas as pd
import pingouin as pg
import pytest
from scipy import stats

from realpen.errors import ParameterError, RealPenError
from realpen.stats import power as pw
from realpen.stats.simulate import (
    SIMULATED_COLUMNS,
    ResponseModel,
    simulate_store,
    simulated_trials,
)
from realpen.study.design import load_design
from realpen.study.export import KEY_COLUMNS, export_trials
from realpen.study.plan import participant_plan

EQUAL_RATES = {"tactile": 0.5, "auditory": 0.5, "audio-tactile": 0.5}


@pytest.fixture(scope="module")
def study1():
    return load_design("study1")


@pytest.fixture(scope="module")
def study2():
    return load_design("study2")


# ---- simulated trials ------------------------------------------------------------------------

def test_study1_every_planned_trial_is_answered(study1):
    frame = simulated_trials(study1, 12, model=ResponseModel(effect=1.0), seed=3)
    assert tuple(frame.columns) == SIMULATED_COLUMNS
    assert frame["participant"].unique().tolist() == [f"S{i:02d}" for i in range(1, 13)]
    assert frame["session"].unique().tolist() == list(range(1, 13))
    for question in ("Q1", "Q2"):
        answers = frame[frame["question"] == question]
        assert len(answers) == 72
        assert set(answers["answer"]) <= {"1", "2", "3", "4", "5"}
        per_participant = answers.groupby("participant")["condition"].apply(lambda c: "".join(sorted(c)))
        assert set(per_participant) == {"ABCDEF"}
    # each participant's rows follow their own plan, trial by trial
    third = frame[frame["participant"] == "S03"]
    plan = participant_plan(study1, 2)
    assert third.drop_duplicates("trial")[["trial", "block", "phase", "condition"]] \
        .values.tolist() == [[t.n, t.block, t.phase, t.condition] for t in plan]
    comments = frame[frame["question"] == "comments"]
    assert len(comments) == 12 and (comments["answer"] == "").all()
    assert (frame["correct"] == "").all() and (frame["rt_ms"] > 0).all()
    assert frame.equals(simulated_trials(study1, 12, model=ResponseModel(effect=1.0), seed=3))
    other = simulated_trials(study1, 12, model=ResponseModel(effect=1.0), seed=4)
    assert not frame["answer"].equals(other["answer"])


def test_study2_recognition_and_training_rows(study2):
    frame = simulated_trials(study2, 12)
    pen = frame[frame["question"] == "pen"]
    assert len(pen) == 12 * 3 * 30
    assert (pen["phase"] == "training").sum() == 12 * 3 * 12
    assert (pen["correct"] == (pen["answer"] == pen["pen"]).map({True: "1", False: "0"})).all()
    assert set(pen["answer"]) <= {"pencil", "ballpoint", "marker"}
    balance = frame[frame["question"] == "balance"]
    assert len(balance) == 12 and set(balance["modality"]) == {"audio-tactile"}
    for question in ("realism", "comfort", "strength"):
        assert len(frame[frame["question"] == question]) == 36
    assert set(frame["phase"]) == {"training", "experimental", "questionnaire"}


def test_likert_points_are_all_used_under_the_null(study1):
    answers = simulated_trials(study1, 60, seed=1)
    q1 = answers.loc[answers["question"] == "Q1", "answer"].astype(int)
    counts = np.bincount(q1, minlength=6)[1:]
    # 360 answers, 72 expected per point: a chi-squared goodness-of-fit far from rejecting
    assert counts.min() > 0 and stats.chisquare(counts).pvalue > 0.001


def test_cell_values_are_simulated_as_trials_would_give_them(study1, study2):
    """power's fast path (cell values drawn directly) has the distribution of the cells of
    simulated_trials: per level the same mean, within Monte Carlo error."""
    model = ResponseModel(effect=1.5, pen_effect=1.0)
    outcomes = {outcome.name: outcome for outcome in pw._outcomes(study1) + pw._outcomes(study2)}
    rng = np.random.default_rng(5)
    trials = simulated_trials(study1, 240, model=model, seed=2)
    q1 = trials[trials["question"] == "Q1"].assign(value=lambda f: f["answer"].astype(int))
    slow = q1.groupby("condition")["value"].mean().reindex(list("ABCDEF")).to_numpy()
    fast = pw._cells(outcomes["Q1"], model, rng, 100, 24, 1).mean(axis=(0, 1))
    assert np.abs(slow - fast).max() < 0.3  # 4 SE of the difference; A to F differ by ~1.3
    assert slow[-1] - slow[0] > 0.8
    trials = simulated_trials(study2, 40, model=model, seed=2)
    pen = trials[(trials["question"] == "pen") & (trials["phase"] == "experimental")]
    slow = pen.groupby("modality")["correct"].apply(lambda c: (c == "1").mean()) \
        .reindex(["tactile", "auditory", "audio-tactile"]).to_numpy()
    fast = pw._cells(outcomes["recognition"], model, rng, 100, 24, 3).mean(axis=(0, 1))
    assert np.abs(slow - fast).max() < 0.08  # 4 SE; tactile and audio-tactile differ by 0.2


# ---- the vectorised tests equal the libraries' --------------------------------------------------

def _long(values: np.ndarray) -> pd.DataFrame:
    n, k = values.shape
    return pd.DataFrame({"subject": np.repeat(np.arange(n), k),
                         "level": np.tile([f"L{i}" for i in range(k)], n), "y": values.ravel()})


def _random_studies(rng, n: int, k: int) -> np.ndarray:
    """Six studies: half Likert-like (many ties), half continuous."""
    ties = rng.integers(1, 6, size=(3, n, k)).astype(float)
    smooth = rng.normal(size=(3, n, k)) + rng.normal(size=(3, 1, k)) * 0.5
    return np.concatenate([ties, smooth])


@pytest.mark.parametrize("n, k", [(6, 2), (8, 3), (12, 6)])
def test_friedman_batch_equals_the_libraries(n, k):
    studies = _random_studies(np.random.default_rng(n * k), n, k)
    chi2, p = pw.friedman_batch(studies)
    own = None
    if importlib.util.find_spec("realpen.stats.nonparametric") is not None:
        from realpen.stats.nonparametric import friedman as own
    for index, values in enumerate(studies):
        if k >= 3:  # scipy needs three levels
            reference = stats.friedmanchisquare(*values.T)
            assert chi2[index] == pytest.approx(reference.statistic, rel=1e-9)
            assert p[index] == pytest.approx(reference.pvalue, rel=1e-9)
        reference = pg.friedman(_long(values), dv="y", within="level", subject="subject")
        assert p[index] == pytest.approx(reference["p_unc"].iloc[0], rel=1e-9)
        if own is not None:
            result = own(_long(values), dv="y", within="level", subject="subject")
            assert p[index] == pytest.approx(result["p"].iloc[0], rel=1e-9)


# pingouin's own rm_anova calls a pandas method pandas 3.1 deprecates; not ours to mend.
@pytest.mark.filterwarnings("ignore:The inplace keyword:DeprecationWarning")
@pytest.mark.parametrize("n, k", [(6, 2), (8, 3), (12, 4)])
def test_rm_anova_batch_equals_the_libraries(n, k):
    from realpen.stats.anova import rm_anova

    studies = _random_studies(np.random.default_rng(100 + n * k), n, k)
    result = pw.rm_anova_batch(studies)
    for index, values in enumerate(studies):
        reference = pg.rm_anova(_long(values), dv="y", within="level", subject="subject",
                                correction=True)
        assert result["F"][index] == pytest.approx(reference["F"].iloc[0], rel=1e-9)
        assert result["p"][index] == pytest.approx(reference["p_unc"].iloc[0], rel=1e-9)
        if k > 2:
            assert result["p_gg"][index] == pytest.approx(reference["p_GG_corr"].iloc[0], rel=1e-9)
        own = rm_anova(_long(values), dv="y", within="level", subject="subject")
        assert result["p"][index] == pytest.approx(own["p"].iloc[0], rel=1e-9)
        assert result["p_gg"][index] == pytest.approx(own["p_gg"].iloc[0], rel=1e-9)


# ---- power -----------------------------------------------------------------------------------

def test_power_is_near_alpha_without_an_effect(study1, study2):
    table = pw.power_table(study1, [12], model=ResponseModel(effect=0.0), sims=400, seed=1)
    assert tuple(table.columns) == pw.POWER_COLUMNS
    assert table["outcome"].tolist() == ["Q1", "Q2"] and set(table["effect"]) == {"condition"}
    assert table["power"].between(0.01, 0.11).all(), table
    table = pw.power_table(study2, [12], model=ResponseModel(rates=EQUAL_RATES), sims=400, seed=1)
    assert table["outcome"].tolist() == ["recognition", "realism", "comfort", "strength"]
    assert table["test"].tolist() == ["RM-ANOVA", "Friedman", "Friedman", "Friedman"]
    assert table["power"].between(0.01, 0.11).all(), table
    assert (table["effect_size"] == 0).all() and (table["sims"] == 400).all()


def test_power_rises_with_the_effect_and_with_participants(study1, study2):
    calls = []
    table = pw.power_table(study1, [8, 24], model=ResponseModel(effect=1.0), sims=400,
                           progress=lambda done, total: calls.append((done, total)))
    assert calls[-1] == (800, 800) and [done for done, _ in calls] == sorted(done for done, _ in calls)
    q1 = table[table["outcome"] == "Q1"].set_index("participants")["power"]
    assert q1[24] > q1[8] + 0.2
    strong = pw.power_table(study1, [8], model=ResponseModel(effect=2.0), sims=400)
    assert strong.loc[0, "power"] > q1[8] + 0.2
    recognition = pw.power_table(study2, [4, 12], model=ResponseModel(), sims=400)
    rates = recognition[recognition["outcome"] == "recognition"].set_index("participants")
    assert rates.loc[12, "power"] > rates.loc[4, "power"] + 0.2
    assert rates.loc[12, "effect_size"] == pytest.approx(0.6296 - 0.4305)
    again = pw.power_table(study2, [4, 12], model=ResponseModel(), sims=400)
    assert again.equals(recognition)  # deterministic from the seed


def test_minimum_detectable_effect_reaches_the_power(study2):
    found = pw.minimum_detectable_effect(study2, 12, sims=200, seed=2)
    assert tuple(found.columns) == pw.MDE_COLUMNS
    assert found["parameter"].tolist() == ["rate_spread", "effect", "effect", "effect"]
    assert (found["power"] >= 0.8).all() and (found["note"] == "").all()
    likert = found.set_index("outcome").loc["realism"]
    at = pw.power_table(study2, [12], model=ResponseModel(effect=likert["minimum_effect"]),
                        sims=200, seed=2).set_index("outcome")
    assert at.loc["realism", "power"] == likert["power"] >= 0.8
    below = pw.power_table(study2, [12], sims=200, seed=2, model=ResponseModel(
        effect=likert["minimum_effect"] - pw.EFFECT_STEP)).set_index("outcome")
    assert below.loc["realism", "power"] < 0.8  # the smallest on the grid
    spread = found.set_index("outcome").loc["recognition", "minimum_effect"]
    mean = np.mean([0.4305, 0.5096, 0.6296])
    rates = {"tactile": mean - spread / 2, "auditory": mean, "audio-tactile": mean + spread / 2}
    at = pw.power_table(study2, [12], model=ResponseModel(rates=rates), sims=200, seed=2)
    assert at.loc[0, "power"] >= 0.8 and 0 < spread < 0.3


def test_an_underpowered_design_says_so(study1):
    # Two participants cannot make a 6-level Friedman test significant (chi2 <= 10, p >= 0.075).
    found = pw.minimum_detectable_effect(study1, 2, sims=50)
    assert found["minimum_effect"].isna().all()
    assert found.loc[0, "note"].startswith("under-powered: power 0.00 even at effect 3")


# ---- through the real study service -----------------------------------------------------------

def test_simulated_answers_go_through_the_store_and_export_unchanged(study2, tmp_path):
    # Two participants (186 trials): each trial is two transactions of the real service, each
    # committed to disk, as a live study's are.
    store, csv_path = tmp_path / "study.sqlite3", tmp_path / "trials.csv"
    model = ResponseModel(effect=0.8, pen_effect=0.5)
    stored = simulate_store(study2, 2, store, model=model, seed=7, site="Lab S")
    expected = simulated_trials(study2, 2, model=model, seed=7, site="Lab S")
    assert stored == len(expected) == 2 * (90 + 10)
    summary = export_trials(store, csv_path)
    assert summary.rows == stored and summary.participants == 2
    exported = pd.read_csv(csv_path, dtype=str, keep_default_na=False)
    for column in KEY_COLUMNS + ("site", "repetition", "ink"):
        if column == "rt_ms":
            assert np.allclose(exported[column].astype(float), expected[column], rtol=0, atol=1e-3)
        else:
            assert exported[column].tolist() == expected[column].astype(str).tolist(), column
    with pytest.raises(RealPenError, match="already holds 2 sessions of 'study2'"):
        simulate_store(study2, 1, store, model=model)


# ---- bad input ---------------------------------------------------------------------------------

def test_bad_arguments_are_one_line(study1, study2):
    with pytest.raises(ParameterError, match=r"^rates\['tactile'\]: must be <= 1, got 1.5$"):
        ResponseModel(rates={"tactile": 1.5})
    with pytest.raises(ParameterError, match="^participant_sd: must be >= 0"):
        ResponseModel(participant_sd=-1)
    with pytest.raises(ParameterError, match="^rates: no recognition rate for the "
                                             "modality 'auditory'"):
        simulated_trials(study2, 2, model=ResponseModel(rates={"tactile": 0.5}))
    with pytest.raises(ParameterError, match="^participants: must be >= 1, got 0$"):
        simulated_trials(study1, 0)
    with pytest.raises(ParameterError, match="^participants: must be >= 2, got 1$"):
        pw.power_table(study1, [12, 1])
    with pytest.raises(ParameterError, match="^participants: must be a list"):
        pw.power_table(study1, 12)
    with pytest.raises(ParameterError, match="^sims: must be >= 1"):
        pw.power_table(study1, [12], sims=0)
    with pytest.raises(ParameterError, match=r"^power: must be between 0 and 1 \(exclusive\)"):
        pw.minimum_detectable_effect(study1, 12, power=1.0)
