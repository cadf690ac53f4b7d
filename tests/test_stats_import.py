"""Trials CSVs as other software writes them: ``realpen stats`` reads what it needs and ignores
the rest (issue 24, point 2).

- a rating row may leave ``rt_ms`` empty (no time measured): accepted; only the response-time
  analysis refuses a trial without one, in one line naming the rows;
- trials may be numbered within blocks (1–30 in each modality block): an answer is keyed by
  block and trial, not by trial alone;
- columns of its own are ignored, wherever they are;
- a ``pilot`` column leaves pilot sessions out unless they are asked for.

The golden check: the bundled study-1 and study-2 designs' simulations, rewritten in that
style, give exactly the numbers of the original export.
"""

from __future__ import annotations

import pandas as pd
import pytest
from conftest import run_cli

from realpen.errors import RealPenError
from realpen.stats.analyses import AnalysisOptions, analyse
from realpen.stats.data import read_trials
from realpen.stats.simulate import ResponseModel, simulated_trials
from realpen.study.design import load_design

# seconds each (simulate, analyse, report): with the long modules, not in --fast
pytestmark = pytest.mark.slow

STUDY1 = load_design("study1")
STUDY2 = load_design("study2")


def as_other_software(frame: pd.DataFrame, design) -> pd.DataFrame:
    """``frame`` (the export's rows) as another tool writes them: no time on rating rows,
    trials numbered from 1 within each block, a column of its own first."""
    likert = {q.id for q in design.questions if q.type != "choice"}
    other = frame.copy().astype({"rt_ms": object})
    other.loc[other["question"].isin(likert), "rt_ms"] = ""
    first_rows = other.drop_duplicates(["participant", "trial"])
    within = first_rows.groupby(["participant", "block"], sort=False).cumcount() + 1
    renumber = dict(zip(zip(first_rows["participant"], first_rows["trial"]), within))
    other["trial"] = [renumber[key] for key in zip(other["participant"], other["trial"])]
    other.insert(0, "device", "tablet-7")
    other["operator_note"] = "ok"
    return other


def numbers(analysis) -> dict[str, pd.DataFrame]:
    return {"results": analysis.results, "cells": analysis.cells,
            "participants": analysis.participants, "confusion": analysis.confusion}


@pytest.mark.parametrize(("design", "participants", "options"), [
    (STUDY1, 6, AnalysisOptions(likert_ci="t")),
    (STUDY2, 6, AnalysisOptions(paper_compatible=True, likert_ci="t")),
], ids=["study1", "study2"])
def test_other_softwares_file_gives_the_exports_numbers(tmp_path, design, participants, options):
    frame = simulated_trials(design, participants, model=ResponseModel(effect=1.0, pen_effect=0.5),
                             seed=11)
    original = tmp_path / "export.csv"
    frame.to_csv(original, index=False, float_format="%.3f")
    rewritten = tmp_path / "other.csv"
    other = as_other_software(frame, design)
    other.to_csv(rewritten, index=False, float_format="%.3f")
    assert other["trial"].max() < frame["trial"].max()  # the numbers do restart per block
    ours, theirs = (analyse(read_trials(path, design), options) for path in (original, rewritten))
    for name, table in numbers(ours).items():
        pd.testing.assert_frame_equal(numbers(theirs)[name], table, check_exact=True, obj=name)
    assert theirs.notes == ours.notes


def test_a_trial_without_a_time_is_refused_only_by_the_response_time_analysis(tmp_path):
    frame = simulated_trials(STUDY2, 3, seed=2).astype({"rt_ms": object})
    recognition = frame.index[(frame["question"] == "pen") & (frame["phase"] == "experimental")]
    frame.loc[recognition[:7], "rt_ms"] = ""
    frame.loc[recognition[7], "rt_ms"] = "NA"  # R's missing value
    path = tmp_path / "t.csv"
    frame.to_csv(path, index=False)
    trials = read_trials(path, STUDY2)
    assert trials.frame["rt_ms"].isna().sum() == 8
    lines = ", ".join(str(index + 2) for index in recognition[:5])
    with pytest.raises(RealPenError, match=rf"t\.csv: lines {lines} and 3 more: no rt_ms on 8 "
                                           rf"answers to pen, whose response times the log_rt "
                                           rf"analysis needs") as caught:
        analyse(trials)
    assert "\n" not in str(caught.value)
    result = run_cli("stats", "study2", str(path), "-o", str(tmp_path / "r"), "--power-sims", "0")
    assert result.returncode == 2 and result.stderr.count("\n") == 1, result.stderr
    assert "no rt_ms on 8 answers" in result.stderr and "Traceback" not in result.stderr


def test_a_time_that_is_not_a_number_is_still_refused(tmp_path):
    frame = simulated_trials(STUDY1, 2, seed=1).astype({"rt_ms": object})
    frame.loc[3, "rt_ms"] = "soon"
    frame.to_csv(tmp_path / "t.csv", index=False)
    with pytest.raises(RealPenError, match=r"line 5: participant S01, trial \d+: rt_ms 'soon' "
                                           r"is not a number of milliseconds"):
        read_trials(tmp_path / "t.csv", STUDY1)


def test_an_answer_twice_in_one_block_is_refused_with_trials_numbered_per_block(tmp_path):
    other = as_other_software(simulated_trials(STUDY2, 2, seed=3), STUDY2)
    path = tmp_path / "t.csv"
    other.to_csv(path, index=False)
    assert read_trials(path, STUDY2).frame["trial"].max() == 30  # 12 training + 18 a block
    pd.concat([other, other.iloc[[40]]]).to_csv(path, index=False)
    row = other.iloc[40]
    with pytest.raises(RealPenError, match=rf"lines 42, {len(other) + 2}: participant "
                                           rf"{row.participant} answers pen of trial {row.trial} "
                                           rf"2 times"):
        read_trials(path, STUDY2)


def test_pilot_sessions_are_left_out_unless_asked_for(tmp_path):
    frame = simulated_trials(STUDY1, 4, seed=5)
    frame["pilot"] = (frame["participant"] == "S01").map({True: "1", False: "0"})
    frame.loc[frame["participant"] == "S02", "pilot"] = ""
    path = tmp_path / "t.csv"
    frame.to_csv(path, index=False)
    trials = read_trials(path, STUDY1)
    assert trials.participants == ["S02", "S03", "S04"] and trials.pilot_rows == 13
    assert trials.notes == ["13 answers of pilot sessions (1 participant) left out"]
    assert read_trials(path, STUDY1, include_pilot=True).participants == ["S01", "S02", "S03",
                                                                          "S04"]
    frame.loc[frame["participant"] != "S01", "pilot"] = "1"
    frame.to_csv(path, index=False)
    with pytest.raises(RealPenError, match="no answers of study 'study1' but those of pilot "
                                           "sessions \\(52,"):
        read_trials(path, STUDY1)
    frame.loc[7, "pilot"] = "yes"
    frame.to_csv(path, index=False)
    with pytest.raises(RealPenError, match=r"line 9: participant S01: pilot 'yes' must be 1"):
        read_trials(path, STUDY1)


def test_the_command_analyses_pilot_sessions_only_when_asked(tmp_path):
    frame = simulated_trials(STUDY1, 4, seed=5)
    frame["pilot"] = (frame["participant"] == "S01").map({True: "1", False: "0"})
    frame.to_csv(tmp_path / "t.csv", index=False)
    seen = {}
    for flags in ((), ("--include-pilot",)):
        out = tmp_path / f"report{len(flags)}"
        result = run_cli("stats", "study1", str(tmp_path / "t.csv"), "-o", str(out),
                         "--power-sims", "0", "--likert-ci", "t", *flags)
        assert result.returncode == 0, result.stderr
        seen[flags] = sorted(pd.read_csv(out / "participants.csv")["participant"].unique())
        html = (out / "report.html").read_text()
        assert ("left out" in html) == (not flags)
    assert seen[()] == ["S02", "S03", "S04"]
    assert seen[("--include-pilot",)] == ["S01", "S02", "S03", "S04"]


def test_the_modalitys_earlier_name_is_read_as_today_s(tmp_path):
    frame = simulated_trials(STUDY2, 2, seed=3)
    old = frame.replace({"modality": {"audio-tactile": "auditory-tactile"},
                         "condition": {"audio-tactile": "auditory-tactile"}})
    assert (old["modality"] == "auditory-tactile").any()
    frame.to_csv(tmp_path / "new.csv", index=False)
    old.to_csv(tmp_path / "old.csv", index=False)
    new_frame = read_trials(tmp_path / "new.csv", STUDY2).frame
    old_frame = read_trials(tmp_path / "old.csv", STUDY2).frame
    pd.testing.assert_frame_equal(old_frame, new_frame)
