"""The study figures and the self-contained HTML report, from small StudyAnalysis objects."""

from __future__ import annotations

import base64
import html
import io
import math
import re
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from matplotlib.figure import Figure

from realpen.errors import ParameterError
from realpen.stats import figure_plan, power_plot, report
from realpen.stats import figures as study_figures
from realpen.stats.outcome import StudyAnalysis
from realpen.stats.results import RESULT_COLUMNS

EVIL = '<script>alert("x")</script>'
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
MODALITIES = ("tactile", "auditory", "audio-tactile")
PENS = ("pencil", "ballpoint", "marker")


# ------------------------------------------------------------------ building analyses

def cells_of(people: pd.DataFrame, unit: str, *, log: bool = False) -> pd.DataFrame:
    """``cells`` rows (mean ± t CI over participants) of a ``participants`` frame."""
    from scipy import stats

    rows = []
    for (outcome, factor, level), group in people.groupby(["outcome", "factor", "level"],
                                                          sort=False):
        values = np.log(group["value"].to_numpy(float)) if log else group["value"].to_numpy(float)
        mean, sem = values.mean(), stats.sem(values)
        half = stats.t.ppf(0.975, len(values) - 1) * sem
        low, mid, high = mean - half, mean, mean + half
        if log:
            low, mid, high = np.exp([low, mid, high])
        rows.append({"outcome": outcome, "factor": factor, "level": level, "mean": mid,
                     "ci_low": low, "ci_high": high, "ci_method": "t", "n": len(values),
                     "unit": unit})
    return pd.DataFrame(rows)


def people_of(outcome: str, factor: str, levels, codes, values, unit: str) -> pd.DataFrame:
    return pd.DataFrame([{"outcome": outcome, "factor": factor, "level": level,
                          "participant": code, "value": float(values[i, j]), "unit": unit}
                         for i, code in enumerate(codes) for j, level in enumerate(levels)])


def result(analysis: str, outcome: str, effect: str, test: str, name: str, statistic: float,
           p: float, *, df1=math.nan, df2=math.nan, p_adjusted=None, adjust="none",
           es_name="", es=math.nan, n=12, method="scipy.stats") -> dict:
    return {"analysis": analysis, "outcome": outcome, "effect": effect, "test": test,
            "statistic_name": name, "statistic": statistic, "df1": df1, "df2": df2, "p": p,
            "p_adjusted": p if p_adjusted is None else p_adjusted, "adjust": adjust,
            "effect_size_name": es_name, "effect_size": es, "n": n, "method": method}


def study1_analysis(count: int = 12) -> StudyAnalysis:
    rng = np.random.default_rng(7)
    codes = [f"P{k:02d}" for k in range(1, count + 1)]
    conditions = list("ABCDEF")
    frames = []
    for outcome, shift in (("Q1", np.array([0, 0.8, 0.6, -0.6, 0.1, -0.2])),
                           ("Q2", np.array([0.3, 0.4, 0.2, 0.0, -0.1, -0.4]))):
        answers = np.clip(np.round(3 + shift + rng.normal(0, 0.9, (count, 6))), 1, 5)
        frames.append(people_of(outcome, "condition", conditions, codes, answers, "points"))
        frames.append(people_of(outcome, "superposition", ["5", "10", "15"], codes,
                                (answers[:, :3] + answers[:, 3:]) / 2, "points"))
        frames.append(people_of(outcome, "fluctuation", ["15x100ms", "1x1500ms"], codes,
                                np.c_[answers[:, :3].mean(1), answers[:, 3:].mean(1)], "points"))
    people = pd.concat(frames, ignore_index=True)
    paper_method = ("paper-compatible: SPSS-style normal approximation without continuity "
                    "correction; not recommended because ties make it anti-conservative")
    results = pd.DataFrame([
        result("study1/friedman/superposition", "Q1", "superposition", "Friedman", "chi2", 6.1234,
               0.0468, df1=2, es_name="kendall_w", es=0.2551,
               method="scipy.stats.friedmanchisquare, variant (a): mean over fluctuation"),
        result("study1/friedman/fluctuation", "Q1", "fluctuation", "Friedman", "chi2", 1.0,
               0.3173, df1=1, es_name="kendall_w", es=0.0833,
               method="scipy.stats.friedmanchisquare, variant (a)"),
        result("study1/wilcoxon/Q1", "Q1", "D-F", "Wilcoxon signed-rank", "T", 4.5, 0.02512,
               p_adjusted=0.3768, adjust="bonferroni", es_name="r", es=-0.65,
               method="scipy.stats.wilcoxon, method r (normal, continuity correction)"),
        result("study1/wilcoxon/Q1", "Q1", "B-E", "Wilcoxon signed-rank", "T", 8.0, 0.00031,
               p_adjusted=0.00465, adjust="bonferroni", es_name="r", es=-0.58,
               method=paper_method),
    ], columns=list(RESULT_COLUMNS))
    paper = pd.DataFrame([
        {"analysis": "study1/wilcoxon/Q1", "outcome": "Q1", "effect": "D-F", "quantity": "p",
         "paper": 0.025, "ours": 0.02512, "note": ""},
        {"analysis": "study1/wilcoxon/Q1", "outcome": "Q1", "effect": "A-D", "quantity": "p",
         "paper": 0.2, "ours": math.nan, "note": "paper says n.s. only"},
    ])
    # The shape of realpen.stats.power.power_table.
    power_rows = [{"outcome": outcome, "effect": "condition", "test": "Friedman",
                   "participants": n, "effect_size": 0.5, "power": min(0.99, scale * n / 14),
                   "sims": 200} for outcome, scale in (("Q1", 0.5), ("Q2", 0.8))
                  for n in (8, 12, 16, 24)]
    return StudyAnalysis(
        design="study1", title="Study 1: tactile parameters", results=results,
        cells=cells_of(people, "points"), participants=people, confusion=pd.DataFrame(),
        paper=paper,
        methods=["Friedman tests (scipy.stats.friedmanchisquare) for <superposition> & fluctuation.",
                 "Wilcoxon signed-rank post hoc tests, Bonferroni-adjusted."],
        excluded={"P13": "missing condition C"}, notes=["Ties in 40 % of Wilcoxon pairs."],
        options={"paper_compatible": True, "wilcoxon_method": "r"}, source="trials-study1.csv",
        power=pd.DataFrame(power_rows))


def study2_analysis(count: int = 12) -> StudyAnalysis:
    rng = np.random.default_rng(11)
    codes = [f"S{k:02d}" for k in range(1, count + 1)]
    cells9 = [f"{m}:{p}" for m in MODALITIES for p in PENS]
    base = np.repeat([43.0, 51.0, 63.0], 3)
    rates = np.clip(np.round((base + rng.normal(0, 18, (count, 9))) / (100 / 6)) * (100 / 6), 0, 100)
    rts = np.exp(np.log(np.repeat([2400.0, 1900.0, 1700.0], 3)) + rng.normal(0, 0.25, (count, 9)))
    frames = [people_of("recognition", "modality:pen", cells9, codes, rates, "%"),
              people_of("recognition", "modality", MODALITIES, codes,
                        rates.reshape(count, 3, 3).mean(2), "%"),
              people_of("log_rt", "modality:pen", cells9, codes, rts, "ms")]
    for item, shift in (("realism", [0, 0.3, 1.0]), ("comfort", [0.2, 0.2, 0.4]),
                        ("strength", [-0.3, 0.2, 0.6])):
        answers = np.clip(np.round(3 + np.array(shift) + rng.normal(0, 0.9, (count, 3))), 1, 5)
        frames.append(people_of(item, "modality", MODALITIES, codes, answers, "points"))
    balance = np.clip(np.round(3.4 + rng.normal(0, 0.9, (count, 1))), 1, 5)
    frames.append(people_of("balance", "modality", ["audio-tactile"], codes, balance, "points"))
    people = pd.concat(frames, ignore_index=True)
    rt = people["outcome"] == "log_rt"
    cells = pd.concat([cells_of(people[~rt], "points"), cells_of(people[rt], "ms", log=True)],
                      ignore_index=True)
    cells.loc[cells["outcome"] == "recognition", "unit"] = "%"
    confusion = []
    for m, modality in enumerate(MODALITIES):
        for i, pen in enumerate(PENS):
            counts = np.array([10, 10, 10])
            counts[i] += 20 + 12 * m
            for j, chosen in enumerate(PENS):
                confusion.append({"modality": modality, "pen": pen, "chosen": chosen,
                                  "count": int(counts[j]),
                                  "row_percent": 100 * counts[j] / counts.sum()})
    results = pd.DataFrame([
        result("study2/anova/recognition", "recognition", "modality", "RM-ANOVA", "F", 9.8765,
               0.00089, df1=2, df2=22, es_name="ges", es=0.21,
               method="pingouin.rm_anova, Greenhouse-Geisser where Mauchly p < .05"),
        result("study2/anova/recognition", "recognition", "modality", "RM-ANOVA", "F", 21.5,
               1e-8, df1=2, df2=142, es_name="ges", es=0.18, n=72,
               method="paper-compatible: repetitions as subjects (pseudo-replication; "
                      "df too large)"),
        result("study2/anova/recognition", "recognition", "modality:pen", "RM-ANOVA", "F", 1.2,
               0.33, df1=2.71, df2=29.84, es_name="ges", es=0.03,
               method="pingouin.rm_anova, Greenhouse-Geisser corrected df"),
        result("study2/friedman/questionnaire", "realism", "modality", "Friedman", "chi2", 8.211,
               0.0165, df1=2, es_name="kendall_w", es=0.342),
    ], columns=list(RESULT_COLUMNS))
    paper = pd.DataFrame([
        {"analysis": "study2/anova/recognition", "outcome": "recognition", "effect": "modality",
         "quantity": "df2", "paper": 142.0, "ours": 22.0, "note": "paper treats repetitions as "
                                                                 "subjects"},
        {"analysis": "study2/friedman/questionnaire", "outcome": "realism", "effect": "modality",
         "quantity": "chi2", "paper": 8.211, "ours": 8.211, "note": ""},
    ])
    return StudyAnalysis(
        design="study2", title="Study 2: recognition", results=results, cells=cells,
        participants=people, confusion=pd.DataFrame(confusion), paper=paper,
        methods=["Two-way repeated-measures ANOVA (pingouin.rm_anova) on per-participant rates."],
        options={"paper_compatible": False}, source="study2.csv",
        # The shape of realpen.stats.power.minimum_detectable_effect (one study: no figure).
        power=pd.DataFrame({"outcome": ["recognition", "realism"], "test": ["RM-ANOVA", "Friedman"],
                            "participants": count, "parameter": ["rate_spread", "effect"],
                            "minimum_effect": [0.18, math.nan], "power": [0.81, 0.62],
                            "note": ["", "under-powered: 0.62 at effect 3, the top of the search "
                                         "range"]}))


def generic_analysis() -> StudyAnalysis:
    rng = np.random.default_rng(3)
    codes = ["G1", "G2", EVIL, "G4", "G5"]
    levels = ["loose:glass", "loose:film", "tight:glass", "tight:film"]
    answers = np.clip(np.round(3 + rng.normal(0, 1, (5, 4))), 1, 5)
    people = pd.concat([
        people_of("score", "grip:surface", levels, codes, answers, "points"),
        people_of("score", "grip", ["loose", "tight"], codes,
                  answers.reshape(5, 2, 2).mean(2), "points")], ignore_index=True)
    results = pd.DataFrame([result("mine/art/score", "score", "grip", "ART RM-ANOVA", "F", 2.5,
                                   0.19, df1=1, df2=4, n=5, method=f"ARTool-like; {EVIL}")],
                           columns=list(RESULT_COLUMNS))
    return StudyAnalysis(
        design="mine", title=f"My design {EVIL}", results=results,
        cells=cells_of(people, "points"), participants=people, confusion=pd.DataFrame(),
        paper=pd.DataFrame(columns=["analysis", "outcome", "effect", "quantity", "paper", "ours",
                                    "note"]),
        methods=[f"Aligned rank transform. {EVIL}"], excluded={EVIL: f"bad {EVIL}"},
        notes=[EVIL], options={"note": EVIL}, source=f"{EVIL}.csv")


def lean(analysis: StudyAnalysis, *without: str) -> StudyAnalysis:
    """``analysis`` without the participant rows of some outcomes: fewer figures to draw (each
    costs), and figures 7 and 12 must cope with outcomes that have only means."""
    people = analysis.participants
    analysis.participants = people[~people["outcome"].isin(without)]
    return analysis


# Four participants keep the many-panel participant figures quick to draw.
ANALYSES = {"study1": lambda: lean(study1_analysis(4), "Q2"),
            "study2": lambda: lean(study2_analysis(4), "realism", "comfort", "strength"),
            "generic": generic_analysis}
EXPECTED = {
    "study1": ["figure7", "participants-Q1", "power"],
    "study2": ["figure10", "recognition", "figure11", "figure12", "participants-recognition",
               "participants-log_rt", "participants-balance"],
    "generic": ["means-score", "participants-score"],
}


@pytest.fixture(scope="module")
def rendered(tmp_path_factory) -> dict[str, tuple[StudyAnalysis, list[Path], Path]]:
    """Every kind of analysis drawn and reported once, shared by the tests of this module."""
    out = {}
    for kind, build in ANALYSES.items():
        analysis = build()
        folder = tmp_path_factory.mktemp(kind)
        figures = figure_plan.save_study_figures(analysis, folder)
        out[kind] = (analysis, figures, report.write_report(analysis, folder, figures))
    return out


# ------------------------------------------------------------------ figures

@pytest.mark.parametrize("kind", list(ANALYSES))
def test_every_figure_is_written_as_valid_png_and_svg(rendered, kind):
    analysis, figures, _ = rendered[kind]
    assert figure_plan.study_figure_names(analysis) == EXPECTED[kind]
    assert [path.name for path in figures] == [f"{name}.{ext}" for name in EXPECTED[kind]
                                               for ext in ("png", "svg")]
    for path in figures:
        data = path.read_bytes()
        if path.suffix == ".png":
            assert data.startswith(PNG_MAGIC)
        else:
            assert ET.fromstring(data).tag.endswith("svg")
    assert not list(figures[0].parent.glob(".*tmp*"))  # no staged file left behind


def _svg_drawing(data: bytes) -> str:
    """An SVG with the ids matplotlib draws at random numbered in order of appearance."""
    seen: dict[str, str] = {}
    return re.sub(r"\b(?:[mpc]|image)[0-9a-f]{10}\b",
                  lambda match: seen.setdefault(match.group(0), f"id{len(seen)}"), data.decode())


def test_figure_images_draw_each_type_once_as_savefig_would(monkeypatch):
    from realpen.display.images import figure_images

    analysis = study1_analysis(count=3)
    figure = study_figures.participants_figure(analysis, "Q1")
    engine = figure.get_layout_engine()
    draws = []
    original_draw = figure.draw
    monkeypatch.setattr(figure, "draw", lambda renderer: draws.append(renderer) or original_draw(renderer))
    images = figure_images(figure, ["png", "svg"])
    assert len(draws) == 2  # savefig alone draws twice per type (a layout pass, then the drawing)
    assert figure.get_layout_engine() is engine
    assert all(axis._autolabelpos for ax in figure.axes for axis in (ax.xaxis, ax.yaxis))
    reference = study_figures.participants_figure(analysis, "Q1")
    expected = {}
    for kind in ("png", "svg"):  # the PNG's layout kept for the SVG
        buffer = io.BytesIO()
        reference.savefig(buffer, format=kind, dpi=150, metadata={"Date": None} if kind == "svg" else {})
        expected[kind] = buffer.getvalue()
        reference.set_layout_engine("none")
    assert images["png"] == expected["png"]
    assert _svg_drawing(images["svg"]) == _svg_drawing(expected["svg"])


def test_figures_draw_into_given_axes_and_show_the_tables_numbers():
    analysis = study1_analysis(count=4)
    figure = Figure()
    axes = figure.subplots(1, 2)
    assert study_figures.figure7(analysis, ax=axes) is figure
    # The error bars are the cells' numbers: Q1's mean for condition A is the first point.
    cells = analysis.cells.set_index(["outcome", "factor", "level"])
    container = axes[0].containers[0]
    x, y = container.lines[0].get_data()
    assert y[0] == pytest.approx(cells.loc[("Q1", "condition", "A"), "mean"], rel=1e-6)
    assert [t.get_text() for t in axes[0].get_xticklabels()] == list("ABCDEF")
    with pytest.raises(ParameterError, match="ax: needs 2 matplotlib Axes"):
        study_figures.figure7(analysis, ax=axes[0])


def test_figure10_shows_count_and_row_percent_on_one_scale():
    figure = study_figures.figure10(study2_analysis(count=3))
    panels = [axis for axis in figure.axes if axis.images]
    assert len(panels) == 3
    assert {axis.images[0].get_clim() for axis in panels} == {(0.0, 100.0)}
    texts = [t.get_text() for t in panels[0].texts]
    assert "30\n60 %" in texts  # tactile, pencil answered pencil: 30 of 50


def test_an_outcome_without_a_factor_is_titled_without_its_one_level():
    # Balance asked in one modality only: the analysis gives it no factor ("all").
    people = people_of("balance", "all", ["all"], ["S1", "S2", "S3"],
                       np.array([[3.0], [4.0], [5.0]]), "points")
    empty = pd.DataFrame()
    analysis = StudyAnalysis("study2", "t", empty, cells_of(people, "points"), people, empty,
                             empty)
    (title,) = [ax.get_title() for ax in study_figures.participants_figure(analysis,
                                                                           "balance").axes]
    assert "all" not in title and title.startswith("balance") and "each participant" in title
    people["factor"], people["level"] = "modality", "audio-tactile"
    analysis.participants = people
    (title,) = [ax.get_title() for ax in study_figures.participants_figure(analysis,
                                                                           "balance").axes]
    assert "(modality audio-tactile only)" in title


def test_missing_tables_are_one_clear_error():
    empty = pd.DataFrame()
    analysis = StudyAnalysis("study2", "t", empty, empty, empty, empty, empty)
    with pytest.raises(ParameterError, match="analysis: has no confusion table"):
        study_figures.figure10(analysis)
    with pytest.raises(ParameterError, match="formats: unknown image type"):
        figure_plan.save_study_figures(analysis, "unused", formats=["gif89"])


def test_power_tables_of_both_shapes_are_understood(rendered):
    curves, detectable = power_plot.split_power(study1_analysis(count=3).power)
    assert len(curves) == 8 and detectable.empty
    curves, detectable = power_plot.split_power(study2_analysis(count=3).power)
    assert curves.empty and list(detectable["effect_size"].fillna(-1)) == [0.18, -1]
    with pytest.raises(ParameterError, match="power table lacks column"):
        power_plot.split_power(pd.DataFrame({"outcome": ["Q1"], "power": [0.5]}))
    text = html_of(rendered, "study2")
    assert 'id="power"' in text and "rate_spread" in text and "under-powered" in text


# ------------------------------------------------------------------ report

def html_of(rendered, kind: str) -> str:
    return rendered[kind][2].read_text(encoding="utf-8")


@pytest.mark.parametrize("kind", list(ANALYSES))
def test_report_is_self_contained(rendered, kind):
    text = html_of(rendered, kind)
    assert rendered[kind][2].name == "report.html"
    links = re.findall(r"""(?:src|href)\s*=\s*["']?([^"'\s>]+)""", text, flags=re.I)
    assert links, "the figures are embedded"
    assert all(link.startswith(("data:", "#")) for link in links), links
    assert not re.search(r"url\(\s*['\"]?(?!data:)", text)  # no CSS fetches either
    assert "@import" not in text
    # Every figure is in, decodable.
    images = re.findall(r'src="data:image/svg\+xml;base64,([^"]+)"', text)
    assert len(images) == len(EXPECTED[kind])
    assert ET.fromstring(base64.b64decode(images[0])).tag.endswith("svg")


@pytest.mark.parametrize("kind", list(ANALYSES))
def test_report_has_methods_results_and_versions(rendered, kind):
    analysis = rendered[kind][0]
    text = html_of(rendered, kind)
    for paragraph in analysis.methods:
        assert html.escape(paragraph) in text
    for row in analysis.results.itertuples():
        assert html.escape(row.test) in text and html.escape(row.analysis) in text
    for package in ("python", "numpy", "scipy", "pandas", "statsmodels", "pingouin",
                    "matplotlib", "realpen"):
        assert f"<td>{package}</td>" in text
    order = [text.index(marker) for marker in ('id="source"', 'id="data"', 'id="methods"',
                                               'id="results"', 'id="figures"', 'id="cells"',
                                               'id="software"')]
    assert order == sorted(order)


def test_report_marks_paper_compatible_rows_with_the_reason(rendered):
    text = html_of(rendered, "study1")
    marked = re.findall(r'<tr class="paper-compatible">.*?</tr>', text, flags=re.S)
    assert len(marked) == 1
    assert 'class="badge"' in marked[0] and "B-E" in marked[0]
    # The reason is given once, in the method the row refers to.
    number = re.search(r'href="#method-(\d+)"', marked[0]).group(1)
    listed = re.search(rf'<li id="method-{number}">(.*?)</li>', text, flags=re.S).group(1)
    assert 'class="badge"' in listed and "ties make it anti-conservative" in listed
    assert len(re.findall(r'<tr class="paper-compatible">', html_of(rendered, "study2"))) == 1


def test_report_formats_numbers(rendered):
    text = html_of(rendered, "study2")
    assert "&lt; .001" in text  # p = 0.00089
    assert '<td class="num">2</td><td class="num">22</td>' in text  # whole df as integers
    assert '<td class="num">2.71</td><td class="num">29.84</td>' in text  # corrected df with 2 decimals
    assert "9.877" in text  # the statistic, 3 decimals
    s1 = html_of(rendered, "study1")
    assert ".025" in s1 and ".377" in s1 and "bonferroni" in s1
    assert "paper says n.s. only" in s1 and 'id="power"' in s1
    assert 'id="power"' not in html_of(rendered, "generic")


def test_report_escapes_user_text(rendered):
    text = html_of(rendered, "generic")
    assert "<script" not in text.lower()
    assert html.escape(EVIL) in text
    assert "P13" in html_of(rendered, "study1") and "missing condition C" in html_of(rendered,
                                                                                    "study1")


def test_report_refuses_a_missing_figure(tmp_path):
    analysis = generic_analysis()
    with pytest.raises(Exception, match="no such file"):
        report.write_report(analysis, tmp_path, [tmp_path / "figure7.svg"])
    assert not (tmp_path / "report.html").exists()


def test_number_formats():
    assert report.format_p(0.0004) == "< .001"
    assert report.format_p(0.0251) == ".025"
    assert report.format_p(1.0) == "1.000"
    assert report.format_p(math.nan) == "—"
    assert report.format_df(142.0) == "142"
    assert report.format_df(2.714) == "2.71"
