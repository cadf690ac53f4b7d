"""Study designs as data: the built-in study1/study2, the schema, answers, variants written
without code, and bad designs refused in one line naming the file and the field."""

from __future__ import annotations

import copy
import hashlib
import json
from pathlib import Path

import pytest
import yaml

from realpen.errors import ParameterError, RealPenError
from realpen.study.design import (
    DEMOGRAPHICS,
    MAX_DESIGN_BYTES,
    PHASES,
    Design,
    builtin_designs,
    builtin_path,
    design_schema,
    load_design,
)
from realpen.study.plan import participant_plan

SCHEMA_FILE = Path(__file__).resolve().parents[1] / "docs" / "study-design.schema.json"


def raw(name: str) -> dict:
    """A built-in design as the plain data of its YAML file (to edit into variants)."""
    return yaml.safe_load(builtin_path(name).read_text(encoding="utf-8"))


def write(tmp_path: Path, document: dict, name: str = "variant.yaml") -> Path:
    path = tmp_path / name
    if name.endswith(".json"):
        path.write_text(json.dumps(document), encoding="utf-8")
    else:
        path.write_text(yaml.safe_dump(document, sort_keys=False, allow_unicode=True),
                        encoding="utf-8")
    return path


# ---- the built-in designs ---------------------------------------------------------------------

def test_builtin_designs_load_by_name():
    assert builtin_designs() == ["study1", "study2"]
    for name in builtin_designs():
        design = load_design(name)
        assert design.name == name
        assert Path(design.source) == builtin_path(name)
        assert builtin_path(name).is_file()


def test_study1_is_the_methods_study1():
    design = load_design("study1")
    assert design.participants == 12
    assert [pen.id for pen in design.pens] == ["ballpoint"]
    assert design.modalities == ["tactile"]
    assert [c.id for c in design.conditions] == list("ABCDEF")
    from realpen.tactile.conditions import CONDITIONS, TactileParams

    for condition in design.conditions:
        assert condition.tactile.keywords() == {"condition": condition.id}
        params = TactileParams(**condition.tactile.keywords())
        assert (params.top, params.subpatterns, params.unit_ms) == CONDITIONS[condition.id]
    q1, q2 = design.question("Q1"), design.question("Q2")
    assert q1.text == "Does it feel like writing with a real pen (i.e. ballpoint pen)?"
    assert q2.text == "Is it comfortable to write?"
    for question in (q1, q2):
        assert (question.type, question.points) == ("likert", 5)
        assert question.anchors == {1: "not at all", 5: "very much"}
    comments = design.question("comments")
    assert (comments.type, comments.required) == ("text", False)
    first, last = design.blocks
    assert (first.over, first.order) == ("conditions", "williams")
    assert [group.phase for group in last.trials] == ["questionnaire"]
    assert last.trials[0].questions == ["comments"]
    assert design.defaults.ink == "hidden" and design.defaults.pen == "ballpoint"
    assert design.participant_fields.demographics == list(DEMOGRAPHICS)
    assert design.participant_fields.consent


def test_study2_is_the_methods_study2():
    design = load_design("study2")
    assert design.participants == 12
    assert [pen.id for pen in design.pens] == ["pencil", "ballpoint", "marker"]
    assert design.modalities == ["tactile", "auditory", "audio-tactile"]
    pen = design.question("pen")
    assert (pen.type, pen.choices, pen.correct) == ("choice", ["pencil", "ballpoint", "marker"],
                                                     "pen")
    for qid in ("realism", "comfort", "strength", "balance"):
        question = design.question(qid)
        assert (question.type, question.points) == ("likert", 5)
    assert design.question("strength").anchors == {1: "too subtle", 3: "just right",
                                                   5: "too strong"}
    assert design.question("balance").modalities == ["audio-tactile"]
    recognition, perception = design.blocks
    assert (recognition.over, recognition.order) == ("modalities", "williams")
    assert [(g.phase, g.pens, g.repetitions, g.randomise) for g in recognition.trials] == [
        ("training", "all", 4, True), ("experimental", "all", 6, True)]
    task = "Draw a horizontal line and write the letter B (up to three times), then choose the pen."
    assert all(g.task.startswith(task) for g in recognition.trials)
    # training names the right pen after each choice; the experimental trials do not
    assert [(g.feedback, g.writing) for g in recognition.trials] == [(True, True), (False, True)]
    assert perception.same_order_as == "recognition"
    assert perception.trials[0].pen == "ballpoint"
    assert "zigzags and circles" in perception.trials[0].task
    assert design.participant_fields.demographics == ["age", "gender", "handedness"]


def test_phases_are_the_stores():
    from realpen.study.tables import PHASES as STORED

    assert PHASES == STORED


def test_version_is_the_sha256_of_the_canonical_json_and_round_trips():
    for name in builtin_designs():
        design = load_design(name)
        text = design.to_json()
        assert design.version == hashlib.sha256(text.encode("utf-8")).hexdigest()
        assert json.dumps(json.loads(text), sort_keys=True, separators=(",", ":"),
                          ensure_ascii=False) == text
        again = Design.from_json(text)
        assert again.model_dump() == design.model_dump() and again.version == design.version
        assert Design.from_json(text.encode("utf-8")).version == design.version
    assert load_design("study1").version != load_design("study2").version


def test_version_follows_the_content(tmp_path):
    document = raw("study1")
    same = load_design(write(tmp_path, document, "same.yaml"))
    assert same.version == load_design("study1").version  # the file's place does not matter
    document["questions"][0]["text"] = "Does it feel like a pencil?"
    assert load_design(write(tmp_path, document, "other.yaml")).version != same.version


def test_json_design_files_load(tmp_path):
    design = load_design(write(tmp_path, raw("study2"), "study2.json"))
    assert design.version == load_design("study2").version


def test_from_json_refuses_bad_text_in_one_line():
    with pytest.raises(RealPenError, match=r"^design JSON: is not valid JSON"):
        Design.from_json("{")
    text = json.loads(load_design("study1").to_json())
    text["questions"][0]["points"] = 1
    with pytest.raises(RealPenError, match=r"^design JSON: questions\[0\]\.points: "):
        Design.from_json(json.dumps(text))


# ---- questions and answers --------------------------------------------------------------------

def test_likert_answers():
    question = load_design("study1").question("Q1")
    assert [question.validate_answer(point) for point in (1, 3, 5)] == ["1", "3", "5"]
    for bad in (0, 6, "4", 4.0, True, None, [4]):
        with pytest.raises(ValueError, match="1 to 5|required"):
            question.validate_answer(bad)


def test_choice_answers_and_correctness():
    design = load_design("study2")
    question = design.question("pen")
    assert question.validate_answer("marker") == "marker"
    for bad in ("Marker", "pen", 1, None):
        with pytest.raises(ValueError):
            question.validate_answer(bad)
    trial = next(t for t in participant_plan(design, 0) if t.questions == ("pen",))
    assert question.is_correct(trial.pen, trial) is True
    wrong = next(pen for pen in question.choices if pen != trial.pen)
    assert question.is_correct(wrong, trial) is False
    assert question.is_correct("ballpoint", {"pen": "ballpoint"}) is True
    assert design.question("realism").is_correct("3", trial) is None


def test_text_answers():
    question = load_design("study1").question("comments")
    assert question.validate_answer("felt scratchy") == "felt scratchy"
    assert question.validate_answer("") == "" and question.validate_answer(None) == ""
    assert question.validate_answer("x" * 2000) == "x" * 2000
    with pytest.raises(ValueError, match="2,000"):
        question.validate_answer("x" * 2001)
    with pytest.raises(ValueError, match="text"):
        question.validate_answer(5)


def test_lookups_name_what_is_unknown():
    design = load_design("study1")
    with pytest.raises(ParameterError, match="unknown question 'Q3'.*Q1, Q2, comments"):
        design.question("Q3")
    with pytest.raises(ParameterError, match="unknown pen 'pencil'"):
        design.pen("pencil")
    assert design.pen("ballpoint").profile_ref == "ballpoint"
    assert design.condition("E").tactile.keywords() == {"condition": "E"}


# ---- variants without code --------------------------------------------------------------------

def four_pen_seven_point() -> dict:
    """Study 2 with a fourth pen (a fountain pen), the ballpoint on glass, 7-point scales."""
    document = raw("study2")
    document["name"] = "study2-4pens"
    document["pens"] = ["pencil", {"id": "ballpoint", "profile": "ballpoint-glass",
                                   "label": "ballpoint on glass"}, "marker", "fountain"]
    for question in document["questions"]:
        if question["id"] == "pen":
            question["choices"] = "pens"
        if question["type"] == "likert":
            question["points"] = 7
            question["anchors"] = {1: question["anchors"][1], 7: question["anchors"][5]}
    return document


def test_four_pens_seven_points_another_surface(tmp_path):
    design = load_design(write(tmp_path, four_pen_seven_point()))
    assert design.question("pen").choices == ["pencil", "ballpoint", "marker", "fountain"]
    assert design.pen("ballpoint").profile_ref == "ballpoint-glass"
    assert design.question("realism").validate_answer(7) == "7"
    plan = participant_plan(design, 5)
    assert len(plan) == 3 * (4 * 4 + 4 * 6) + 3
    experimental = [t for t in plan if t.phase == "experimental" and t.condition == "auditory"]
    assert sorted(t.pen for t in experimental) == sorted(["pencil", "ballpoint", "marker",
                                                          "fountain"] * 6)


def test_permutations_fixed_and_random_orders(tmp_path):
    document = raw("study1")
    document["blocks"][0]["levels"] = ["A", "B", "D"]
    for order, rows in (("permutations", 6), ("fixed", 1), ("random", None)):
        document["blocks"][0]["order"] = order
        design = load_design(write(tmp_path, document, f"{order}.yaml"))
        orders = {tuple(t.block for t in participant_plan(design, i)[:3]) for i in range(24)}
        assert all(sorted(o) == ["A", "B", "D"] for o in orders)
        if rows is not None:
            assert len(orders) == rows
        else:
            assert len(orders) > 1


def test_a_design_with_a_training_block_and_visible_ink(tmp_path):
    document = raw("study1")
    document["blocks"].insert(0, {"id": "practice", "label": "practice", "ink": "visible",
                                  "trials": [{"phase": "training", "repetitions": 2,
                                              "task": "Write your name.",
                                              "questions": ["comments"]}]})
    design = load_design(write(tmp_path, document))
    plan = participant_plan(design, 0)
    assert [(t.block, t.phase, t.ink, t.repetition) for t in plan[:2]] == [
        ("practice", "training", "visible", 1), ("practice", "training", "visible", 2)]
    assert plan[2].block_index == 1 and plan[2].ink == "hidden"


# ---- bad designs ------------------------------------------------------------------------------

def edit(name: str, change) -> dict:
    document = copy.deepcopy(raw(name))
    change(document)
    return document


def _set(path: tuple, value):
    def change(document):
        target = document
        for part in path[:-1]:
            target = target[part]
        target[path[-1]] = value
    return change


def _delete(path: tuple):
    def change(document):
        target = document
        for part in path[:-1]:
            target = target[part]
        del target[path[-1]]
    return change


BAD = [
    ("unknown question id", "study1", _set(("blocks", 0, "trials", 0, "questions"),
                                           ["Q1", "Q2", "Q9"]),
     "blocks[0].trials[0].questions[2]: unknown question 'Q9'"),
    ("unknown pen", "study2", _set(("blocks", 1, "trials", 0, "pen"), "quill"),
     "blocks[1].trials[0].pen: unknown pen 'quill'"),
    ("unknown pen in a list", "study2", _set(("blocks", 0, "trials", 1, "pens"),
                                             ["pencil", "quill"]),
     "blocks[0].trials[1].pens[1]: unknown pen 'quill'"),
    ("anchors outside the scale", "study1", _set(("questions", 1, "anchors"),
                                                 {1: "no", 5: "yes", 6: "more"}),
     "questions[1].anchors: anchor 6 is outside the scale's points 1..5"),
    ("seven points, five-point anchors", "study1", _set(("questions", 0, "points"), 7),
     "questions[0].anchors: label both ends of the scale: no anchor for 7"),
    ("points out of range", "study1", _set(("questions", 0, "points"), 12),
     "questions[0].points: input should be less than or equal to 11"),
    ("duplicate question id", "study1", _set(("questions", 1, "id"), "Q1"),
     "questions[1]: duplicate question 'Q1'"),
    ("duplicate condition id", "study1", _set(("conditions", 5, "id"), "A"),
     "conditions[5]: duplicate condition 'A'"),
    ("duplicate block label", "study2", _set(("blocks", 1, "label"), "{level}"),
     "blocks[1].label: block label 'tactile' is also blocks[0]'s"),
    ("unknown field (a typo)", "study1", lambda d: d["blocks"][0].update(
        trails=d["blocks"][0].pop("trials")),
     "blocks[0].trails: unknown field (allowed here:"),
    ("missing field", "study1", _delete(("title",)), "title: missing (required)"),
    ("a string for a number", "study1", _set(("participants",), "12"),
     "participants: input should be a valid integer, got '12'"),
    ("unknown order", "study1", _set(("blocks", 0, "order"), "latin"),
     "blocks[0].order: input should be 'williams', 'permutations', 'fixed' or 'random'"),
    ("unknown modality", "study1", _set(("blocks", 1, "trials", 0, "modality"), "smell"),
     "blocks[1].trials[0].modality: input should be 'tactile'"),
    ("modality not in the design", "study1", _set(("blocks", 1, "trials", 0, "modality"),
                                                  "auditory"),
     "blocks[1].trials[0].modality: unknown modality 'auditory'"),
    ("bad tactile letter", "study1", _set(("conditions", 0, "tactile"), "Z"),
     "conditions[0].tactile.condition: input should be 'A'"),
    ("bad tactile count", "study1", _set(("conditions", 0, "tactile"), {"top": 0}),
     "conditions[0].tactile.top: must be >= 1, got 0"),
    ("tactile counts disagree with the letter", "study1",
     _set(("conditions", 0, "tactile"), {"condition": "A", "top": 10}),
     "conditions[0].tactile.top: condition A sets 5, not 10"),
    ("choice without choices", "study1", _set(("questions", 2, "type"), "choice"),
     "questions[2].choices: a choice question needs choices"),
    ("choices on a likert question", "study1", _set(("questions", 0, "choices"), ["a", "b"]),
     "questions[0].choices: only choice questions have choices"),
    ("right answer not among the choices", "study2", _set(("questions", 0, "choices"),
                                                          ["pencil", "ballpoint"]),
     "blocks[0].trials[0].questions: question 'pen' is right when the answer is the trial's "
     "pen, but 'marker' is not among its choices"),
    ("same order as a later block", "study2", _set(("blocks", 1, "same_order_as"), "perception"),
     "blocks[1].same_order_as: no earlier block 'perception'"),
    ("order and same order", "study2", _set(("blocks", 1, "order"), "williams"),
     "blocks[1].same_order_as: give order or same_order_as, not both"),
    ("levels on a block over none", "study1", _set(("blocks", 1, "levels"), ["A"]),
     "blocks[1].levels: only a block over conditions or modalities has levels"),
    ("unknown level", "study1", _set(("blocks", 0, "levels"), ["A", "G"]),
     "blocks[0].levels[1]: unknown condition 'G'"),
    ("too many permutations", "study1", lambda d: (
        d["conditions"].extend({"id": f"X{i}"} for i in range(3)),
        d["blocks"][0].update(order="permutations")),
     "blocks[0].order: all permutations of 9 levels are too many"),
    ("a question asked nowhere", "study2", _set(("blocks", 0, "trials", 0, "questions"),
                                                ["balance"]),
     "blocks[0].trials[0].questions: no question is asked in its tactile trials"),
    ("bad name", "study1", _set(("name",), "study 1"),
     "name: must be an id"),
    ("negative seed", "study1", _set(("seed",), -1),
     "seed: input should be greater than or equal to 0"),
    ("repetitions zero", "study2", _set(("blocks", 0, "trials", 0, "repetitions"), 0),
     "blocks[0].trials[0].repetitions: input should be greater than or equal to 1"),
    ("pens neither all nor a list", "study2", _set(("blocks", 0, "trials", 0, "pens"), "some"),
     "blocks[0].trials[0].pens: must be 'all' or a list of pen ids"),
    ("too many trials", "study2", lambda d: [group.update(repetitions=1000)
                                             for group in d["blocks"][0]["trials"]],
     "blocks[0]: the design plans more than 5,000 trials per participant"),
    ("unknown demographic", "study1", _set(("participant_fields", "demographics"),
                                           ["age", "income"]),
     "participant_fields.demographics[1]: input should be 'age', 'gender' or 'handedness'"),
    ("anchor that is no number", "study1", _set(("questions", 0, "anchors"),
                                                {"low": "no", 1: "no", 5: "yes"}),
     "questions[0].anchors: key 'low': input should be a valid integer"),
    ("a number for a mapping", "study1", _set(("defaults",), 3),
     "defaults: must be a mapping (field: value), got 3"),
    ("a string for a list", "study1", _set(("pens",), "ballpoint"),
     "pens: must be a list, got 'ballpoint'"),
    ("unknown field in a pen", "study2", _set(("pens", 0), {"id": "pencil", "colour": "grey"}),
     "pens[0].colour: unknown field (allowed here: id, profile, label)"),
    ("empty block", "study1", _set(("blocks", 0, "trials"), []),
     "blocks[0].trials: list should have at least 1 item"),
]


@pytest.mark.parametrize("what, name, change, expected", BAD, ids=[case[0] for case in BAD])
def test_bad_designs_are_one_line_naming_the_field(tmp_path, what, name, change, expected):
    path = write(tmp_path, edit(name, change), "bad.yaml")
    with pytest.raises(RealPenError) as caught:
        load_design(path)
    message = str(caught.value)
    assert "\n" not in message
    assert message.startswith(f"{path}: "), message
    assert expected in message, message


BAD_TEXT = [
    ("syntax error", "name: study1\ntitle: [oops\n",
     "YAML syntax error at line 3, column 1: did not find expected ',' or ']' (while parsing a "
     "flow sequence at line 2, column 8)"),
    ("duplicate key", "name: a\nname: b\n", "YAML line 2, column 1: duplicate key 'name'"),
    ("empty file", "", "is empty"),
    ("a list, not a mapping", "- 1\n- 2\n", "must be a mapping of the design's fields"),
    ("alias bomb", "a: &a [x, x, x, x, x, x, x, x, x, x]\n" + "".join(
        f"b{i}: &b{i} [{', '.join([f'*{prev}'] * 10)}]\n"
        for i, prev in enumerate(["a"] + [f"b{j}" for j in range(6)])),
     "holds more than 100,000 values"),
    ("a date for a title", None, "title: input should be a valid string"),
]


@pytest.mark.parametrize("what, text, expected", BAD_TEXT, ids=[case[0] for case in BAD_TEXT])
def test_bad_design_files_are_one_line(tmp_path, what, text, expected):
    path = tmp_path / "bad.yaml"
    if text is None:
        text = builtin_path("study1").read_text(encoding="utf-8").replace(
            'title: "Study 1: tactile parameters"', "title: 2024-05-01")
    path.write_text(text, encoding="utf-8")
    with pytest.raises(RealPenError) as caught:
        load_design(path)
    message = str(caught.value)
    assert "\n" not in message and message.startswith(f"{path}: "), message
    assert expected in message, message


def test_files_that_are_no_designs(tmp_path):
    big = tmp_path / "big.yaml"
    big.write_bytes(b"#" * (MAX_DESIGN_BYTES + 1))
    with pytest.raises(RealPenError, match="design files are limited to"):
        load_design(big)
    binary = tmp_path / "bin.yaml"
    binary.write_bytes(b"\xff\xfe\x00")
    with pytest.raises(RealPenError, match="bin.yaml: is not UTF-8 text"):
        load_design(binary)
    with pytest.raises(RealPenError, match="missing.yaml: no such design file"):
        load_design(tmp_path / "missing.yaml")
    with pytest.raises(RealPenError, match="study3: unknown design: give a built-in design"):
        load_design("study3")
    other = tmp_path / "design.txt"
    other.write_text("name: x\n")
    with pytest.raises(RealPenError, match="design.txt: is not a design: give a .yaml"):
        load_design(other)


# ---- the published schema ---------------------------------------------------------------------

def test_schema_file_is_up_to_date():
    assert SCHEMA_FILE.is_file(), "run: realpen study schema -o docs/study-design.schema.json"
    published = json.loads(SCHEMA_FILE.read_text(encoding="utf-8"))
    assert published == design_schema(), \
        "docs/study-design.schema.json is stale: run realpen study schema -o " \
        "docs/study-design.schema.json --force"


def test_schema_describes_the_shorthands():
    schema = design_schema()
    assert schema["$schema"].endswith("2020-12/schema")
    assert schema["additionalProperties"] is False
    assert set(schema["required"]) == {"name", "title", "participants", "pens", "modalities",
                                       "questions", "blocks"}
    question = schema["$defs"]["Question"]["properties"]
    assert {"const": "pens"} in question["choices"]["anyOf"]
    group = schema["$defs"]["TrialGroup"]["properties"]
    assert {"const": "all"} in group["pens"]["anyOf"]
