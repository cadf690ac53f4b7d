"""Statistics that scale (issue 25): the trials CSV read in bounded memory and strictly, the
size limit refused before reading, ``stats simulate`` refusing what ``stats`` refuses, and the
fast paths (RM-ANOVA by contrasts, Monte Carlo sign flips, the heat map of many participants)
giving the numbers of the libraries' paths.

No timing here: the 1,000-participant figures are ``benchmarks/bench_stats.py --scale``.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
import scipy.stats

import realpen.stats.data as data_module
from realpen.errors import RealPenError
from realpen.stats.anova import rm_anova, rm_anova_table
from realpen.stats.data import read_trials
from realpen.stats.nonparametric import _fast_flips_p, _scipy_flips_p
from realpen.stats.simulate import (
    ResponseModel,
    simulated_bytes,
    simulated_trials,
    write_simulated,
    write_simulated_trials,
)
from realpen.study.design import load_design

STUDY1 = load_design("study1")


@pytest.fixture(scope="module")
def trials_text(tmp_path_factory) -> str:
    """Two participants of study 1 as the export writes them."""
    path = tmp_path_factory.mktemp("scale") / "trials.csv"
    write_simulated(simulated_trials(STUDY1, 2, model=ResponseModel(effect=1.0), seed=1), path)
    return path.read_text(encoding="utf-8")


def _rating_line(text: str) -> tuple[int, list[str], list[str]]:
    """The first Q1 row's line number (1-based), the header and its fields."""
    lines = text.splitlines()
    header = lines[0].split(",")
    for number, line in enumerate(lines[1:], start=2):
        fields = line.split(",")
        if fields[header.index("question")] == "Q1":
            return number, header, fields
    raise AssertionError("no Q1 row")


def test_a_byte_order_mark_is_accepted(tmp_path, trials_text):
    plain, marked = tmp_path / "plain.csv", tmp_path / "excel.csv"
    plain.write_text(trials_text, encoding="utf-8")
    marked.write_bytes(b"\xef\xbb\xbf" + trials_text.encode("utf-8"))
    expected = read_trials(plain, STUDY1).frame
    pd.testing.assert_frame_equal(read_trials(marked, STUDY1).frame, expected)


@pytest.mark.parametrize("rating", ["+3", "1e0", "3.0", " 3"])
def test_ratings_must_be_plain_whole_numbers(tmp_path, trials_text, rating):
    number, header, fields = _rating_line(trials_text)
    fields[header.index("answer")] = rating
    lines = trials_text.splitlines()
    lines[number - 1] = ",".join(fields)
    path = tmp_path / "bad.csv"
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    with pytest.raises(RealPenError) as caught:
        read_trials(path, STUDY1)
    message = str(caught.value)
    assert "\n" not in message
    assert message.startswith(f"{path}: line {number}: ")
    assert f"Q1 answer '{rating}' is not a rating from 1 to" in message


def test_plain_ratings_still_read(tmp_path, trials_text):
    path = tmp_path / "good.csv"
    path.write_text(trials_text, encoding="utf-8")
    values = read_trials(path, STUDY1).frame["value"].dropna()
    assert len(values) and values.between(1, 7).all() and (values == values.round()).all()


def test_the_size_limit_is_refused_before_reading(tmp_path, monkeypatch):
    # A sparse file of the limit + 1 bytes: read, it would be refused as having no header.
    path = tmp_path / "huge.csv"
    with open(path, "wb") as handle:
        handle.truncate(data_module.MAX_TRIALS_BYTES + 1)
    opened = []
    monkeypatch.setattr(data_module._ChunkReader, "read", lambda *args: opened.append(args))
    with pytest.raises(RealPenError) as caught:
        read_trials(path, STUDY1)
    assert not opened
    assert str(caught.value) == (f"{path}: is {data_module.MAX_TRIALS_BYTES + 1:,} bytes; trials "
                                 f"CSV files are limited to {data_module.MAX_TRIALS_BYTES:,}")


def test_simulate_refuses_what_stats_would_refuse_writing_nothing(tmp_path, monkeypatch):
    size = simulated_bytes(STUDY1, 3)
    target = tmp_path / "sim.csv"
    monkeypatch.setattr(data_module, "MAX_TRIALS_BYTES", size - 1)
    with pytest.raises(RealPenError) as caught:
        write_simulated_trials(STUDY1, 3, target)
    assert str(caught.value).startswith(f"{target}: would be about {size:,} bytes")
    assert "\n" not in str(caught.value)
    assert list(tmp_path.iterdir()) == []
    # Under the limit: the file is simulated_trials' own, byte for byte, and stats reads it.
    monkeypatch.setattr(data_module, "MAX_TRIALS_BYTES", size + 1000)
    write_simulated_trials(STUDY1, 3, target)
    reference = tmp_path / "reference.csv"
    write_simulated(simulated_trials(STUDY1, 3), reference)
    assert target.read_bytes() == reference.read_bytes()
    assert len(read_trials(target, STUDY1).participants) == 3


def test_the_contrast_rm_anova_equals_the_libraries_path():
    """Above LIBRARY_MAX_VALUES rm_anova takes the contrasts; on a small design both paths
    must give the same numbers."""
    rng = np.random.default_rng(7)
    subjects, a_levels, b_levels = 9, 3, 2
    rows = [(s, a, b, rng.normal() + 0.4 * a - 0.3 * b * (a == 2))
            for s in range(subjects) for a in range(a_levels) for b in range(b_levels)]
    frame = pd.DataFrame(rows, columns=["s", "A", "B", "y"])
    libraries = rm_anova(frame, dv="y", within=["A", "B"], subject="s")
    contrasts = rm_anova_table(frame, dv="y", within=["A", "B"], subject="s",
                               with_pingouin=False)
    assert "statsmodels AnovaRM (F, df, p)" in libraries["method"].iloc[0]
    for column in ("statistic", "df1", "df2", "p", "effect_size", "eps_gg", "eps_hf", "p_gg",
                   "p_hf", "mauchly_w", "p_mauchly"):
        np.testing.assert_allclose(contrasts[column].to_numpy(float),
                                   libraries[column].to_numpy(float), rtol=1e-9, atol=1e-12,
                                   err_msg=column)


def test_the_contrast_path_is_taken_above_the_library_size(monkeypatch):
    import realpen.stats.anova as anova

    frame = pd.DataFrame({"s": np.repeat(np.arange(4), 3), "A": list("abc") * 4,
                          "y": [3, 5, 6, 2, 4, 4, 4, 6, 7, 3, 3, 5]})
    monkeypatch.setattr(anova, "LIBRARY_MAX_VALUES", 11)
    fast = rm_anova(frame, dv="y", within="A", subject="s").iloc[0]
    assert fast["method"].startswith(anova.CONTRAST_SOURCE)
    assert (fast["statistic"], fast["df1"], fast["df2"]) == pytest.approx((19.0, 2, 6), rel=1e-12)
    assert fast["p"] == pytest.approx(0.0025, abs=5e-5)


@pytest.mark.parametrize("m", [21, 64])
def test_monte_carlo_sign_flips_equal_scipys_permutation_test(m):
    rng = np.random.default_rng(m)
    d = rng.integers(-4, 5, m * 2).astype(float)
    d = d[d != 0][:m]
    ranks = scipy.stats.rankdata(np.abs(d))
    for resamples in (4_000, 20_000):
        assert _fast_flips_p(d, ranks, resamples) == _scipy_flips_p(d, ranks, resamples)


def test_many_participants_are_one_heat_map(monkeypatch):
    import realpen.stats.figures as figures
    from realpen.stats.outcome import StudyAnalysis

    people = [f"P{k}" for k in range(6)]
    rows = pd.DataFrame({"outcome": "Q1", "factor": "condition", "level": list("AB") * 6,
                         "participant": np.repeat(people, 2),
                         "value": [3, 4, 2, 5, 4, 4, 1, 2, 5, 5, 3, 2], "unit": "points"})
    empty = pd.DataFrame()
    analysis = StudyAnalysis("study1", "Study 1", empty, empty, rows, empty, empty)
    monkeypatch.setattr(figures, "MAX_PARTICIPANT_PANELS", 5)
    figure = figures.participants_figure(analysis, "Q1")
    (image,) = figure.axes[0].get_images()
    shown = np.asarray(image.get_array())
    assert shown.shape == (6, 2)
    # Every participant's exact values, a row each, sorted by their mean.
    expected = rows.pivot(index="participant", columns="level", values="value").loc[people]
    order = np.argsort(expected.mean(axis=1).to_numpy(), kind="stable")
    np.testing.assert_array_equal(shown, expected.to_numpy(float)[order])


def test_report_power_of_more_participants_than_simulated_is_a_note():
    from realpen.stats.power import report_power
    from realpen.study.plan import MAX_PARTICIPANTS

    table = report_power(MAX_PARTICIPANTS + 1, STUDY1, sims=10)
    assert list(table["outcome"]) == ["Q1", "Q2"]
    assert table["minimum_effect"].isna().all() and table["power"].isna().all()
    assert table["note"].str.startswith("not simulated: 1,001 participants").all()



def _many(count: int) -> object:
    """An analysis of ``count`` participants' Q1 over conditions A-C and log_rt over
    modality x pen (the tables the figures read; nothing computed)."""
    from realpen.stats.outcome import StudyAnalysis

    rng = np.random.default_rng(count)
    people = [f"P{k:03d}" for k in range(count)]
    q1, rt = list("ABC"), ["tactile:pencil", "tactile:marker", "auditory:pencil", "auditory:marker"]
    participants = pd.concat([
        pd.DataFrame({"outcome": "Q1", "factor": "condition", "level": q1 * count,
                      "participant": np.repeat(people, 3), "value": rng.integers(1, 6, 3 * count),
                      "unit": "points"}),
        pd.DataFrame({"outcome": "log_rt", "factor": "modality:pen", "level": rt * count,
                      "participant": np.repeat(people, 4),
                      "value": rng.normal(2000, 300, 4 * count), "unit": "ms"})])
    cells = (participants.groupby(["outcome", "factor", "level", "unit"], sort=False)["value"]
             .mean().rename("mean").reset_index())
    cells = cells.assign(ci_low=cells["mean"] * 0.95, ci_high=cells["mean"] * 1.05,
                         ci_method="t", n=count)
    empty = pd.DataFrame()
    return StudyAnalysis("study2", "Study 2", empty, cells, participants, empty, empty)


@pytest.mark.parametrize("count", [12, 2000])
def test_participant_layers_above_the_threshold_are_aggregated_or_rasterised(count):
    """Up to MAX_VECTOR_PARTICIPANTS a vector line (Figure 7) or dot (Figure 11) per
    participant, as before. Above it Figure 7's lines are aggregated, each distinct step one
    line as wide as how many participants took it, and Figure 11's dots one rasterised layer
    per cell: the SVG stays small whatever the count (a vector line each: 1.5 MB for 2,000)."""
    import io

    from matplotlib.collections import LineCollection

    from realpen.display.charts import MAX_VECTOR_PARTICIPANTS
    from realpen.stats.figures import figure7, figure11

    analysis = _many(count)
    many = count > MAX_VECTOR_PARTICIPANTS
    (axis,) = figure7(analysis).axes
    participant_lines = [line for line in axis.lines if line.get_zorder() == 2]
    layers = [c for c in axis.collections if c.get_zorder() == 2]
    if many:
        assert participant_lines == []
        (lines,) = [c for c in layers if isinstance(c, LineCollection)]
        values = analysis.participants.query("outcome == 'Q1'").pivot(
            index="participant", columns="level", values="value")
        steps = pd.concat([values[["A", "B"]].value_counts(), values[["B", "C"]].value_counts()])
        assert len(lines.get_segments()) == len(steps)  # 5 x 5 answers: at most 50, not 2,000
        widest = lines.get_segments()[int(np.argmax(lines.get_linewidths()))]
        assert tuple(widest[:, 1]) in set(steps[steps == steps.max()].index)
    else:
        assert len(participant_lines) == count and layers == []
    svg = io.BytesIO()
    axis.figure.savefig(svg, format="svg", dpi=150)
    if many:
        assert len(svg.getvalue()) < 150_000, len(svg.getvalue())
    (axis,) = figure11(analysis).axes
    dots = [c for c in axis.collections if c.get_zorder() == 2]
    assert len(dots) == 4 and all(bool(c.get_rasterized()) == many for c in dots)
    svg = io.BytesIO()
    axis.figure.savefig(svg, format="svg", dpi=150)
    if many:
        assert len(svg.getvalue()) < 400_000, len(svg.getvalue())


def test_simulate_store_on_a_disk_that_fills_part_way_is_one_line(tmp_path, monkeypatch):
    """The disk fills after the store is made and some answers are in (SQLite's
    ``max_page_count`` answers SQLITE_FULL as a full disk does): one line, exit 2, no export
    and no half-simulated store left."""
    import sqlite3

    from conftest import assert_clean_failure, run_cli
    from sqlalchemy import event
    from sqlalchemy.engine import Engine

    from realpen.study import sessions
    from realpen.study.db import open_database

    empty = tmp_path / "empty.sqlite3"
    open_database(empty, create=True).close()
    with sqlite3.connect(empty) as db:
        room = db.execute("PRAGMA page_count").fetchone()[0] + 2  # a page or two of answers
    db.close()
    answered = []
    answer_trial = sessions.answer_trial

    def counted(*args, **kwargs):
        result = answer_trial(*args, **kwargs)
        answered.append(1)
        return result

    def little_room(dbapi_connection, record) -> None:
        if isinstance(dbapi_connection, sqlite3.Connection):
            dbapi_connection.execute(f"PRAGMA max_page_count={room}")

    monkeypatch.setattr(sessions, "answer_trial", counted)
    folder = tmp_path / "run"
    folder.mkdir()
    store, output = folder / "sim.sqlite3", folder / "sim.csv"
    event.listen(Engine, "connect", little_room)
    try:
        result = run_cli("stats", "simulate", "study1", "-n", "12", "--store", str(store),
                         "-o", str(output))
    finally:
        event.remove(Engine, "connect", little_room)
    assert answered  # it filled part way, not at the start
    assert_clean_failure(result, f"{store}: the disk is full (database or disk is full); free "
                                 "some space on it and try again")
    assert list(folder.iterdir()) == []
