"""The designs researchers write, analysed as written (issue 24, points 1 and 2).

A design's factors come from the cells it plans for each outcome: crossed, nested (a pen per
condition: the pen is not a factor of its own) or constant, and the report says which. Every
design the schema accepts goes ``realpen stats simulate`` → ``realpen stats`` to a report, or
to one line saying what is missing (exit code 2, no traceback).
"""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest
from conftest import run_cli

from realpen.stats.data import NO_CONDITION, factor_text, outcomes
from realpen.stats.simulate import main_factor
from realpen.study.design import load_design

# seconds each (simulate, analyse, report): with the long modules, not in --fast
pytestmark = pytest.mark.slow

_HEAD = """format: realpen.study-design/1
name: {name}
title: "{name}"
participants: 4
participant_fields: {{demographics: []}}
"""
_REALISM = ('  - {id: realism, type: likert, text: "Real?", points: 5, '
            'anchors: {1: "not at all", 5: "very much"}}\n')

DESIGNS = {
    # the "does my recorded pen feel more real than the ballpoint?": a pen per condition
    "pen-per-condition": """pens: [{id: own, profile: pencil}, {id: bp, profile: ballpoint}]
modalities: [tactile]
conditions: [{id: own, pen: own}, {id: ref, pen: bp}]
questions:
""" + _REALISM + """blocks:
  - id: conditions
    over: conditions
    order: williams
    trials: [{phase: experimental, task: "Write.", questions: [realism]}]
""",
    # pens varied inside one block, Likert only, pens with their own ids and profiles
    "pens-in-block": """pens: [{id: own, profile: pencil}, {id: bp, profile: ballpoint}]
modalities: [audio-tactile]
questions:
""" + _REALISM + """blocks:
  - id: pens
    trials:
      - {phase: experimental, pens: all, repetitions: 2, randomise: true, task: "Write.",
         questions: [realism]}
""",
    # the same with a recognition question over the design's own pen ids
    "own-pen-recognition": """pens: [{id: own, profile: pencil, label: "Pen A"}, {id: bp, profile: ballpoint}]
modalities: [audio-tactile]
questions:
  - {id: which, type: choice, text: "Which pen?", choices: pens, correct: pen}
""" + _REALISM + """blocks:
  - id: pens
    trials:
      - {phase: training, pens: all, feedback: true, task: "Write.", questions: [which]}
      - {phase: experimental, pens: all, repetitions: 2, randomise: true, task: "Write.",
         questions: [which, realism]}
""",
    # a modality × pen design written as one condition per cell
    "conditions-name-cells": """pens: [pencil, ballpoint]
modalities: [tactile, auditory]
conditions: [{id: TP, modality: tactile, pen: pencil}, {id: TB, modality: tactile, pen: ballpoint},
             {id: AP, modality: auditory, pen: pencil}, {id: AB, modality: auditory, pen: ballpoint}]
questions:
""" + _REALISM + """blocks:
  - id: conditions
    over: conditions
    order: williams
    trials: [{phase: experimental, task: "Write.", questions: [realism]}]
""",
    "conditions-by-modalities": """pens: [ballpoint]
modalities: [tactile, audio-tactile]
conditions: [{id: B, tactile: B}, {id: E, tactile: E}]
questions:
""" + _REALISM + """blocks:
  - id: conditions
    over: conditions
    order: williams
    trials:
      - {phase: experimental, modality: tactile, task: "Write.", questions: [realism]}
      - {phase: experimental, modality: audio-tactile, task: "Write.", questions: [realism]}
""",
    # a baseline block over none with the researcher's pen, then conditions with the ballpoint
    "baseline-then-conditions": """pens: [{id: own, profile: pencil}, {id: bp, profile: ballpoint}]
modalities: [tactile]
conditions: [{id: B, tactile: B, pen: bp}, {id: E, tactile: E, pen: bp}]
questions:
  - {id: which, type: choice, text: "Which pen?", choices: pens, correct: pen}
""" + _REALISM + """blocks:
  - id: baseline
    trials: [{phase: experimental, pen: own, task: "Write.", questions: [which, realism]}]
  - id: conditions
    over: conditions
    order: williams
    trials: [{phase: experimental, task: "Write.", questions: [which, realism]}]
""",
    # pens crossed with the modalities in one block, a third pen alone in another: not crossed
    "partly-crossed": """pens: [pencil, ballpoint, marker]
modalities: [tactile, audio-tactile]
questions:
""" + _REALISM + """blocks:
  - id: m
    over: modalities
    trials: [{phase: experimental, pens: [pencil, ballpoint], task: "Write.",
              questions: [realism]}]
  - id: extra
    trials: [{phase: experimental, pen: marker, modality: tactile, task: "Write.",
              questions: [realism]}]
""",
    "one-pen-one-modality": """pens: [ballpoint]
modalities: [tactile]
questions:
  - {id: which, type: choice, text: "Which pen?", choices: [ballpoint, pencil], correct: pen}
""" + _REALISM + """blocks:
  - id: b
    trials: [{phase: experimental, repetitions: 3, task: "Write.", questions: [which, realism]}]
""",
    "text-only": """pens: [ballpoint]
modalities: [tactile]
questions:
  - {id: comments, type: text, text: "Comments?"}
blocks:
  - id: b
    trials: [{phase: experimental, task: "Write.", questions: [comments]}]
""",
}


def design_file(folder: Path, name: str) -> Path:
    path = folder / f"{name}.yaml"
    path.write_text(_HEAD.format(name=name) + DESIGNS[name])
    return path


def structure(name: str, tmp_path: Path) -> dict[str, tuple]:
    design = load_design(design_file(tmp_path, name))
    return {o.name: (o.factors, o.nested, o.constant) for o in outcomes(design)}


def test_a_pen_per_condition_is_nested_and_pens_in_a_block_are_the_factor(tmp_path):
    assert structure("pen-per-condition", tmp_path) == {
        "realism": (("condition",), {"pen": "condition"}, {"modality": "tactile"})}
    assert structure("pens-in-block", tmp_path)["realism"][0] == ("pen",)
    assert structure("conditions-by-modalities", tmp_path)["realism"] == (
        ("condition", "modality"), {}, {"pen": "ballpoint"})
    assert structure("one-pen-one-modality", tmp_path)["realism"][0] == ()
    baseline = outcomes(load_design(design_file(tmp_path, "baseline-then-conditions")))[0]
    assert baseline.levels["condition"] == ("B", "E", NO_CONDITION)
    assert baseline.nested == {"pen": "condition"}
    partly = outcomes(load_design(design_file(tmp_path, "partly-crossed")))[0]
    assert (partly.factors, partly.nested, partly.averaged) == (
        ("condition",), {"modality": "condition"}, ("pen",))
    assert "pen varies within condition but is not crossed with it" in factor_text(partly)
    # the simulated effect lies on the factor the design varies
    assert main_factor(load_design(tmp_path / "pens-in-block.yaml")) == ("pen", ("own", "bp"))
    assert main_factor(load_design("study1"))[0] == "condition"


def test_the_factor_text_says_how_each_is_treated(tmp_path):
    design = load_design(design_file(tmp_path, "pen-per-condition"))
    assert factor_text(outcomes(design)[0]) == (
        "realism: condition (2 levels) within participants (two levels: the Wilcoxon "
        "signed-rank test of the pair, not a Friedman test); pen nested in condition (each "
        "condition fixes its pen): not a factor of its own; modality constant (tactile)")


def report_or_one_line(result) -> bool:
    """True for a report; a failure must be one line, exit code 2, without a traceback."""
    if result.returncode == 0:
        return True
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert result.returncode == 2 and len(lines) == 1, (result.returncode, result.stderr)
    assert "Traceback" not in result.stderr
    return False


@pytest.mark.parametrize("name", list(DESIGNS))
def test_every_design_simulates_and_reports_or_says_what_is_missing(tmp_path, name):
    design = design_file(tmp_path, name)
    trials, out = tmp_path / "trials.csv", tmp_path / "report"
    made = run_cli("stats", "simulate", str(design), "-n", "4", "-o", str(trials), "--effect", "1")
    assert made.returncode == 0, made.stderr
    # the power simulation once (a variant's main factor found), not on every design
    sims = "10" if name in ("pens-in-block", "one-pen-one-modality") else "0"
    result = run_cli("stats", str(design), str(trials), "-o", str(out), "--power-sims", sims,
                     *(["--paper-compatible"] if name == "baseline-then-conditions" else []))
    reported = report_or_one_line(result)
    if name == "text-only":
        assert not reported and "asks no rating or recognition question" in result.stderr
        return
    # nothing varies in one-pen-one-modality: no power simulation, but still a report
    assert reported, result.stderr
    html = (out / "report.html").read_text()
    assert "Factors, from the cells the design plans" in html
    table = pd.read_csv(out / "results.csv")
    if name in ("pen-per-condition", "pens-in-block"):
        # two levels: the paired Wilcoxon signed-rank test, no Friedman
        assert list(table["analysis"]) == [f"wilcoxon/{structure(name, tmp_path)['realism'][0][0]}"]
    if name == "pen-per-condition":
        assert "pen nested in condition" in html
    if name == "baseline-then-conditions":  # the block over none is a level of its own
        pairs = table[table["analysis"] == "pairwise-t/condition/paper-compatible"]
        assert set(pairs["effect"]) == {"B vs E", f"B vs {NO_CONDITION}", f"E vs {NO_CONDITION}"}
    if name == "conditions-by-modalities":
        assert "art/condition:modality" in set(table["analysis"])
    if name == "conditions-name-cells":  # the crossed factors, their interaction included
        assert "art/modality:pen" in set(table["analysis"])
        assert "each condition is one modality × pen cell" in html
