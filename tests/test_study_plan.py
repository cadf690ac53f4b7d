"""Counterbalanced plans: the Williams design, each participant's trials for the built-in
designs, balance and its warnings, determinism, and ``realpen study``."""

from __future__ import annotations

import csv
import itertools
import json
import re
import subprocess
import sys
from collections import Counter

import pytest
from conftest import assert_clean_failure, run_cli

from realpen.errors import ParameterError
from realpen.study.design import design_schema, load_design
from realpen.study.plan import (
    CSV_COLUMNS,
    PlannedTrial,
    balance,
    block_orders,
    participant_plan,
    williams,
)

PENS = ("pencil", "ballpoint", "marker")
MODALITIES = ("tactile", "auditory", "audio-tactile")


# ---- the Williams design ----------------------------------------------------------------------

@pytest.mark.parametrize("n", range(2, 9))
def test_williams_balances_positions_and_ordered_adjacent_pairs(n):
    rows = williams(n)
    assert len(rows) == (n if n % 2 == 0 else 2 * n)
    assert all(sorted(row) == list(range(n)) for row in rows)
    repeats = len(rows) // n
    for position in range(n):
        assert Counter(row[position] for row in rows) == {item: repeats for item in range(n)}
    pairs = Counter((a, b) for row in rows for a, b in zip(row, row[1:]))
    assert set(pairs) == {(a, b) for a in range(n) for b in range(n) if a != b}
    assert set(pairs.values()) == {repeats}
    assert len({tuple(row) for row in rows}) == len(rows)  # no sequence twice


def test_williams_small_and_bad_n():
    assert williams(1) == [[0]]
    assert williams(2) == [[0, 1], [1, 0]]
    for bad in (0, -1, 1001, 2.0, True):
        with pytest.raises(ParameterError, match="^n: "):
            williams(bad)


# ---- study 1 ----------------------------------------------------------------------------------

def test_study1_twelve_participants_are_perfectly_balanced():
    design = load_design("study1")
    result = balance(design, 12)
    assert result.balanced and result.warnings == []
    (block,) = result.blocks
    assert block.levels == tuple("ABCDEF") and block.rows == 6
    assert block.positions == {level: (2,) * 6 for level in "ABCDEF"}
    assert set(block.pairs) == set(itertools.permutations("ABCDEF", 2))
    assert set(block.pairs.values()) == {2}
    # and from the plans themselves, not the balance's own counting
    orders = [[t.condition for t in participant_plan(design, i) if t.condition]
              for i in range(12)]
    for position in range(6):
        assert Counter(order[position] for order in orders) == dict.fromkeys("ABCDEF", 2)
    pairs = Counter((a, b) for order in orders for a, b in zip(order, order[1:]))
    assert len(pairs) == 30 and set(pairs.values()) == {2}


def test_study1_ten_participants_warn():
    result = balance(load_design("study1"), 10)
    assert not result.balanced
    assert result.warnings == ["10 participants cannot balance 6 conditions: use a multiple of 6"]
    assert balance(load_design("study1"), 18).balanced


def test_study1_trials():
    design = load_design("study1")
    for index in range(12):
        plan = participant_plan(design, index)
        assert len(plan) == 7
        assert [t.n for t in plan] == list(range(1, 8))
        assert [t.block_index for t in plan] == list(range(7))
        conditions, comments = plan[:6], plan[6]
        assert sorted(t.block for t in conditions) == list("ABCDEF")
        for trial in conditions:
            assert (trial.condition, trial.phase, trial.modality, trial.pen, trial.ink) == (
                trial.block, "experimental", "tactile", "ballpoint", "hidden")
            assert trial.questions == ("Q1", "Q2")
            assert trial.tactile == {"condition": trial.condition}
            assert trial.repetition == 1 and '"B" twice' in trial.task
        assert (comments.block, comments.phase, comments.condition, comments.questions,
                comments.modality, comments.tactile) == ("comments", "questionnaire", "",
                                                         ("comments",), "none", None)


# ---- study 2 ----------------------------------------------------------------------------------

def test_study2_modality_orders():
    design = load_design("study2")
    result = balance(design, 12)
    assert result.balanced and result.warnings == []
    (block,) = result.blocks
    assert block.rows == 6 and block.followers == ("perception",)
    assert block.positions == {m: (4, 4, 4) for m in MODALITIES}
    assert set(block.pairs.values()) == {4}
    sequences = Counter()
    for index in range(12):
        (_, first), (_, second) = block_orders(design, index)
        assert first == second  # part 2 follows part 1's order
        sequences[tuple(first)] += 1
    assert set(sequences) == set(itertools.permutations(MODALITIES))
    assert set(sequences.values()) == {2}
    assert balance(design, 4).warnings == [
        "4 participants cannot balance 3 modalities: use a multiple of 6"]


def test_study2_trials():
    design = load_design("study2")
    for index in range(12):
        plan = participant_plan(design, index)
        assert len(plan) == 3 * 30 + 3
        assert [t.n for t in plan] == list(range(1, 94))
        recognition, questionnaire = plan[:90], plan[90:]
        order = [recognition[i * 30].condition for i in range(3)]
        assert sorted(order) == sorted(MODALITIES)
        for b, modality in enumerate(order):
            block = recognition[b * 30:(b + 1) * 30]
            assert {(t.block, t.condition, t.modality, t.block_index, t.ink) for t in block} == {
                (modality, modality, modality, b, "hidden")}
            training, experimental = block[:12], block[12:]
            assert {t.phase for t in training} == {"training"}
            assert {t.phase for t in experimental} == {"experimental"}
            assert Counter(t.pen for t in training) == dict.fromkeys(PENS, 4)
            assert Counter(t.pen for t in experimental) == dict.fromkeys(PENS, 6)
            assert sorted((t.pen, t.repetition) for t in experimental) == sorted(
                (pen, r) for pen in PENS for r in range(1, 7))
            assert all(t.questions == ("pen",) and t.tactile is None for t in block)
        assert [t.condition for t in questionnaire] == order
        for b, trial in enumerate(questionnaire):
            assert trial.block == f"{trial.condition}/questionnaire"
            assert (trial.phase, trial.pen, trial.ink, trial.block_index) == (
                "questionnaire", "ballpoint", "visible", 3 + b)
            expected = ("realism", "comfort", "strength") + (
                ("balance",) if trial.modality == "audio-tactile" else ())
            assert trial.questions == expected


def test_study2_trials_are_randomised_within_each_group():
    design = load_design("study2")
    groups = set()
    for index in range(12):
        plan = participant_plan(design, index)
        for start in range(0, 90, 30):
            groups.add(tuple(t.pen for t in plan[start:start + 12]))
            groups.add(tuple(t.pen for t in plan[start + 12:start + 30]))
    assert len(groups) == 72  # every group of every participant in its own order
    assert ("pencil",) * 4 + ("ballpoint",) * 4 + ("marker",) * 4 not in groups


# ---- determinism ------------------------------------------------------------------------------

def test_plans_are_deterministic():
    design = load_design("study2")
    first = participant_plan(design, 3, seed=11)
    assert participant_plan(load_design("study2"), 3, seed=11) == first
    assert participant_plan(design, 3) == participant_plan(design, 3, seed=design.seed)
    other = participant_plan(design, 3, seed=12)
    assert [t.pen for t in other] != [t.pen for t in first]
    # the counterbalancing does not depend on the seed, only the shuffles do
    assert [t.block for t in other] == [t.block for t in first]
    # another participant in the same row has another shuffle
    assert [t.pen for t in participant_plan(design, 9, seed=11)] != [t.pen for t in first]


def test_the_shuffle_is_pinned():
    """The exact order for study 2, participant 0, the design's seed: a numpy release that
    changed PCG64 or Generator.permutation would change every stored plan."""
    plan = participant_plan(load_design("study2"), 0)
    assert "".join(t.pen[0] for t in plan[:30]) == "pmpbmbpbmmpbbpbbmmpmpbmpbbmmpp"
    assert "".join(t.pen[0] for t in participant_plan(load_design("study2"), 0, seed=7)[:30]) \
        == "ppbmpbmbpmmbppmmmpmpmpbbbbbpbm"


def test_planned_trial_json():
    trial = participant_plan(load_design("study1"), 0)[1]
    data = trial.to_json()
    assert set(data) == {field for field in PlannedTrial.__dataclass_fields__}
    assert data["questions"] == ["Q1", "Q2"] and data["tactile"] == {"condition": "B"}
    assert json.loads(json.dumps(data)) == data
    assert PlannedTrial(**{**data, "questions": tuple(data["questions"])}) == trial


def test_bad_plan_arguments():
    design = load_design("study1")
    for kwargs, name in (({"index": -1}, "index"), ({"index": 0, "seed": -1}, "seed"),
                         ({"index": 1.5}, "index"), ({"index": 0, "seed": 2**63}, "seed")):
        with pytest.raises(ParameterError, match=f"^{name}: "):
            participant_plan(design, **kwargs)
    with pytest.raises(ParameterError, match="^participants: "):
        balance(design, 0)


# ---- the command line -------------------------------------------------------------------------

def test_cli_plan_study1(tmp_path):
    result = run_cli("study", "plan", "study1", "--participants", "12")
    assert result.returncode == 0, result.stderr
    assert result.stderr == ""
    out = result.stdout
    assert "participant 1 (index 0): A, B, F, C, E, D, comments" in out
    assert "participant 12 (index 11):" in out
    assert out.rstrip().endswith("balanced: yes")
    assert "  A         2  2  2  2  2  2" in out


def test_cli_plan_warns_on_stderr():
    result = run_cli("study", "plan", "study1", "-n", "10")
    assert result.returncode == 0
    assert result.stderr.splitlines() == [
        "realpen: warning: 10 participants cannot balance 6 conditions: use a multiple of 6"]
    assert result.stdout.rstrip().endswith("balanced: no")


def test_cli_plan_study2_is_compact_and_trials_prints_every_one():
    compact = run_cli("study", "plan", "study2", "-n", "12")
    assert compact.returncode == 0, compact.stderr
    assert len(compact.stdout.splitlines()) < 12 * 12 + 40
    assert "pens: p = pencil, b = ballpoint, m = marker" in compact.stdout
    every = run_cli("study", "plan", "study2", "-n", "2", "--trials", "--seed", "5")
    assert every.returncode == 0, every.stderr
    lines = [line for line in every.stdout.splitlines() if re.match(r" +[0-9]+  [a-z]", line)]
    assert len(lines) == 2 * 93


def test_cli_plan_csv(tmp_path):
    out = tmp_path / "plan.csv"
    result = run_cli("study", "plan", "study2", "-n", "12", "--csv", out)
    assert result.returncode == 0, result.stderr
    assert f"wrote {out}: 1116 planned trials of 12 participants" in result.stdout
    with open(out, newline="", encoding="utf-8") as handle:
        rows = list(csv.DictReader(handle))
    assert tuple(rows[0]) == CSV_COLUMNS
    assert len(rows) == 12 * 93
    design = load_design("study2")
    plan = participant_plan(design, 7)
    mine = [row for row in rows if row["participant"] == "7"]
    assert [(int(r["n"]), r["block"], r["phase"], r["pen"], r["questions"]) for r in mine] == [
        (t.n, t.block, t.phase, t.pen, ";".join(t.questions)) for t in plan]
    again = run_cli("study", "plan", "study2", "-n", "12", "--csv", out)
    assert_clean_failure(again, "exists; pass --force")
    forced = run_cli("study", "plan", "study1", "-n", "12", "--csv", out, "--force")
    assert forced.returncode == 0, forced.stderr
    assert len(out.read_text(encoding="utf-8").splitlines()) == 1 + 12 * 7


def test_cli_plan_never_writes_over_the_design(tmp_path):
    design = tmp_path / "mine.yaml"
    design.write_text(load_design("study1").to_json(), encoding="utf-8")  # JSON is YAML
    before = design.read_bytes()
    result = run_cli("study", "plan", design, "-n", "6", "--csv", design, "--force")
    assert_clean_failure(result, "would replace the design itself")
    assert design.read_bytes() == before


def test_cli_bad_design_is_one_line(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text(load_design("study1").to_json().replace('"Q2"]', '"Q7"]'), encoding="utf-8")
    result = run_cli("study", "plan", bad, "-n", "12")
    assert_clean_failure(result, f"{bad}: blocks[0].trials[0].questions[1]: unknown question 'Q7'")
    assert result.stdout == ""
    broken = tmp_path / "broken.yaml"
    broken.write_text("name: [x\n", encoding="utf-8")
    assert_clean_failure(run_cli("study", "plan", broken, "-n", "2"), "YAML syntax error at line")
    assert_clean_failure(run_cli("study", "plan", tmp_path / "none.yaml", "-n", "2"),
                         "no such design file")
    assert_clean_failure(run_cli("study", "plan", "study1", "-n", "0"), "--participants")
    assert_clean_failure(run_cli("study", "plan", "study1", "-n", "2", "--seed", "-3"),
                         "--seed: must be >= 0")


def test_cli_designs():
    result = run_cli("study", "designs")
    assert result.returncode == 0, result.stderr
    lines = result.stdout.splitlines()
    assert lines[0].startswith("study1  Study 1: tactile parameters  (")
    assert lines[1].startswith("study2  Study 2: recognition and perception  (")
    assert lines[0].endswith("study1.yaml)")


def test_cli_schema(tmp_path):
    printed = run_cli("study", "schema")
    assert printed.returncode == 0, printed.stderr
    assert json.loads(printed.stdout) == design_schema()
    out = tmp_path / "schema.json"
    written = run_cli("study", "schema", "-o", out)
    assert written.returncode == 0, written.stderr
    assert json.loads(out.read_text(encoding="utf-8")) == design_schema()
    assert_clean_failure(run_cli("study", "schema", "-o", out), "exists; pass --force")


@pytest.mark.slow
def test_study_help_stays_light():
    """``realpen study plan --help`` loads no numpy, PyYAML or design module (typer itself
    loads pydantic for a subcommand's help; ``realpen --help`` does not)."""
    code = (
        "import contextlib, io, json, sys\n"
        "from realpen.cli import main\n"
        "state = {}\n"
        "for args in (['--help'], ['study', 'plan', '--help']):\n"
        "    with contextlib.redirect_stdout(io.StringIO()) as out:\n"
        "        try:\n"
        "            main(args)\n"
        "        except SystemExit:\n"
        "            pass\n"
        "    state[' '.join(args)] = (sorted(n for n in ('numpy', 'scipy', 'yaml', 'pydantic',\n"
        "        'sqlalchemy', 'realpen.study.design', 'realpen.study.plan')\n"
        "        if n in sys.modules), 'Usage:' in out.getvalue())\n"
        "print(json.dumps(state))\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 0, done.stderr
    state = json.loads(done.stdout)
    assert state["--help"] == [[], True]
    assert state["study plan --help"][1] is True
    assert set(state["study plan --help"][0]) <= {"pydantic"}
