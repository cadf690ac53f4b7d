"""The core tests of realpen.stats against the reference numbers of R, PSPP, scipy, statsmodels
and pingouin in tests/data/stats_reference (their provenance: the README there), and their
refusals of bad input.

Tolerance: a reference printed with many digits is matched within 1e-6 relative; one printed
rounded (PSPP's ``.803``, R's ``ges`` ``0.532``) is only known to half a unit of its last
digit, so :func:`near` allows max(1e-6 relative, half a unit of the last printed digit), read
from the JSON text itself (decimals parsed as :class:`decimal.Decimal`; integers are exact).
"""

from __future__ import annotations

import json
import math
from decimal import Decimal
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import scipy.stats

from realpen.errors import ParameterError
from realpen.stats.anova import pairwise, rm_anova
from realpen.stats.art import aligned_rank_transform
from realpen.stats.contrasts import contrast_anova, contrast_decomposition, effect_name, effects
from realpen.stats.intervals import cell_cis, mean_ci
from realpen.stats.long import balanced_wide
from realpen.stats.nonparametric import (
    _exact_sign_flip_p,
    _signed_rank_normal,
    friedman,
    wilcoxon,
    wilcoxon_long,
)
from realpen.stats.results import TEST_COLUMNS

GOLDEN = Path(__file__).resolve().parent / "data" / "stats_reference"
METHODS = ("exact", "r", "spss")


def near(actual: float, reference: Decimal | int) -> bool:
    """Within 1e-6 relative, or half a unit of the reference's last printed digit if larger;
    integers (counts, df, rank sums) are exact and get 1e-6 relative only."""
    tolerance = 1e-6 * abs(float(reference))
    if isinstance(reference, Decimal):
        half_unit = Decimal(5) * Decimal(10) ** (reference.as_tuple().exponent - 1)
        tolerance = max(tolerance, float(half_unit))
    return abs(float(actual) - float(reference)) <= tolerance


@pytest.fixture(scope="module")
def golden() -> dict:
    return json.loads((GOLDEN / "stats_reference.json").read_text(), parse_float=Decimal)["cases"]


@pytest.fixture(scope="module")
def anova_2x3() -> pd.DataFrame:
    return pd.read_csv(GOLDEN / "anova_rm_statsmodels.csv", index_col=0).iloc[:48]


def long_from_matrix(matrix: list[list]) -> pd.DataFrame:
    values = np.array(matrix, dtype=float)
    return pd.DataFrame([(f"b{i}", f"c{j}", values[i, j]) for i in range(values.shape[0])
                         for j in range(values.shape[1])], columns=["block", "condition", "y"])


def one_line(error: pytest.ExceptionInfo) -> str:
    text = str(error.value)
    assert "\n" not in text
    return text


# --- golden cases ---------------------------------------------------------------------------

def test_near_reads_the_printed_precision():
    assert near(0.8028, Decimal("0.803")) and not near(0.8024, Decimal("0.803"))
    assert near(11.14285714, Decimal("11.142857")) and not near(11.1429, Decimal("11.142857"))
    assert near(34.0, 34) and not near(34.5, 34)


@pytest.mark.parametrize("case", ["friedman_rounding_times", "friedman_likert_12x4"])
def test_friedman_golden(golden, case):
    reference = golden[case]["expected"]
    row = friedman(long_from_matrix(golden[case]["blocks_x_conditions"]), dv="y", within="condition",
                   subject="block").iloc[0]
    assert tuple(row.index[:len(TEST_COLUMNS)]) == TEST_COLUMNS
    assert near(row["statistic"], reference["chi2"])
    assert near(row["df1"], reference["df"])
    assert near(row["p"], reference["p"])
    if "kendall_w" in reference:
        assert near(row["effect_size"], reference["kendall_w"])
        assert near(row["chi2_uncorrected"], reference["chi2_without_tie_correction"])
    assert row["n"] == len(golden[case]["blocks_x_conditions"]) and "scipy" in row["method"]


def test_wilcoxon_golden_without_ties(golden):
    case = golden["wilcoxon_no_ties"]
    reference = case["expected"]
    rows = {method: wilcoxon(case["x"], case["y"], method=method).iloc[0] for method in METHODS}
    for row in rows.values():
        assert near(row["statistic"], reference["T_min"])
        assert near(row["z"], reference["z_normal_no_continuity"])
        assert not row["ties"] and row["zeros"] == 0 and row["n"] == 12
    assert near(rows["exact"]["p"], reference["p_exact"])
    assert near(rows["r"]["p"], reference["p_exact"])  # R is exact here: no ties, n < 50
    assert near(rows["spss"]["p"], reference["p_normal_no_continuity"])
    # R with exact=FALSE: the branch "r" takes with ties or n >= 50.
    difference = np.array(case["x"], float) - np.array(case["y"], float)
    assert near(_signed_rank_normal(difference, continuity=True)[1], reference["p_normal_with_continuity"])


@pytest.mark.parametrize("pair", ["c1_vs_c4", "c1_vs_c2"])
def test_wilcoxon_golden_tied_three_tools_three_p_values(golden, pair):
    case = golden["wilcoxon_tied_likert"]["pairs"][pair]
    reference = case["expected"]
    rows = {method: wilcoxon(case["x"], case["y"], method=method).iloc[0] for method in METHODS}
    assert near(rows["exact"]["p"], reference["p_scipy_default_permutation"])
    assert near(rows["r"]["p"], reference["p_R_normal_with_continuity"])
    assert near(rows["spss"]["p"], reference["p_PSPP_normal_no_continuity"])
    if "p_scipy_asymptotic_no_continuity" in reference:
        assert near(rows["spss"]["p"], reference["p_scipy_asymptotic_no_continuity"])
    if "R_V" in reference:
        assert near(rows["r"]["w_plus"], reference["R_V"])
        # PSPP prints -|z|; ours is signed by direction (here x > y).
        assert near(-abs(rows["spss"]["z"]), reference["z_PSPP"])
    p_values = [rows[method]["p"] for method in METHODS]
    assert len({round(p, 6) for p in p_values}) == 3
    assert rows["exact"]["ties"] and rows["exact"]["zeros"] > 0
    assert "sign flips" in rows["exact"]["method"] and "continuity correction" in rows["r"]["method"]


def test_rm_anova_golden(golden, anova_2x3):
    reference = golden["rm_anova_2x3"]["expected"]
    table = rm_anova(anova_2x3, dv="DV", within=["A", "B"], subject="id").set_index("effect")
    assert list(table.index) == ["A", "B", "A:B"]
    for effect, key in (("A", "A"), ("B", "B"), ("A:B", "AxB")):
        row, expected = table.loc[effect], reference[key]
        assert near(row["statistic"], expected["F"])
        assert near(row["df1"], expected["df1"]) and near(row["df2"], expected["df2"])
        assert near(row["p"], expected["p"])
        assert near(row["effect_size"], expected["ges"])
        if "gg_epsilon" in expected:
            assert near(row["eps_gg"], expected["gg_epsilon"])
            assert near(row["p_gg"], expected["p_gg"])
    assert table.loc["A", "eps_gg"] == 1 and math.isnan(table.loc["A", "mauchly_w"])
    assert not table.loc["B", "sphericity"] and table.loc["A:B", "sphericity"]
    assert (table["eps_hf"] >= table["eps_gg"]).all() and (table["eps_hf"] <= 1).all()


def test_pairwise_golden(golden, anova_2x3):
    reference = golden["rm_anova_2x3"]["expected"]["B_pairwise_bonferroni_p"]
    table = pairwise(anova_2x3, dv="DV", within="B", subject="id", adjust="bonferroni",
                     average_over=["A"]).set_index("effect")
    for effect, key in (("a vs b", "a_vs_b"), ("a vs c", "a_vs_c"), ("b vs c", "b_vs_c")):
        assert near(table.loc[effect, "p_adjusted"], reference[key])
    assert (table["adjust"] == "bonferroni").all() and (table["df1"] == 7).all()


# --- properties -----------------------------------------------------------------------------

def test_exact_sign_flips_equal_scipys_enumeration():
    rng = np.random.default_rng(3)
    difference = (rng.integers(1, 5, 11) - rng.integers(1, 5, 11)).astype(float)
    difference = difference[difference != 0]
    ranks = scipy.stats.rankdata(np.abs(difference))
    every_flip = scipy.stats.PermutationMethod(n_resamples=np.inf)
    enumerated = scipy.stats.wilcoxon(difference, method=every_flip).pvalue
    assert _exact_sign_flip_p(ranks, ranks[difference > 0].sum()) == pytest.approx(enumerated, rel=1e-9)


def test_wilcoxon_monte_carlo_above_twenty_and_effect_sign():
    x = np.tile([5.0, 4, 4, 3, 5, 4, 2, 5], 3)
    y = np.tile([3.0, 4, 2, 3, 1, 2, 3, 3], 3)
    row = wilcoxon(x, y).iloc[0]
    assert row["n_nonzero"] == 18 and "all 2^18" in row["method"]
    row = wilcoxon(np.tile(x, 2)[:30], np.tile(y, 2)[:30]).iloc[0]
    assert "Monte Carlo" in row["method"] and row["p"] < 0.01
    assert row["effect_size"] > 0 and wilcoxon(y, x).iloc[0]["effect_size"] < 0


def test_wilcoxon_long_pairs_by_subject():
    data = pd.DataFrame({"s": [3, 1, 2, 1, 2, 3, 4, 4], "c": ["F", "D", "D", "F", "F", "D", "D", "F"],
                         "y": [5, 2, 3, 4, 5, 2, 3, 4]})
    row = wilcoxon_long(data, dv="y", within="c", subject="s", a="D", b="F", method="r").iloc[0]
    assert row["effect"] == "D vs F" and row["w_plus"] == 0 and row["n"] == 4


def test_contrast_fallback_agrees_with_pingouin(anova_2x3):
    table = rm_anova(anova_2x3, dv="DV", within=["A", "B"], subject="id").set_index("effect")
    parts = contrast_decomposition(balanced_wide(anova_2x3, dv="DV", within=["A", "B"], subject="id"))
    error = sum(part["ss_error"] for part in parts.values())
    for effect, key in (("A", (0,)), ("B", (1,)), ("A:B", (0, 1))):
        ges = parts[key]["ss"] / (parts[key]["ss"] + error)
        assert ges == pytest.approx(table.loc[effect, "effect_size"], rel=1e-9)
        for column in ("eps_gg", "eps_hf"):
            assert parts[key][column] == pytest.approx(table.loc[effect, column], rel=1e-9)
    assert parts[(1,)]["p_mauchly"] == pytest.approx(table.loc["B", "p_mauchly"], rel=1e-9)


def test_rm_anova_three_factors_and_awkward_names():
    rng = np.random.default_rng(5)
    cells = [(s, a, b, c) for s in range(5) for a in ("x", "y") for b in ("audio-tactile", "pencil")
             for c in ("p", "q")]
    data = pd.DataFrame(cells, columns=["who", "pen type", "modality", "C"]).assign(
        score=rng.normal(size=len(cells)))
    table = rm_anova(data, dv="score", within=["pen type", "modality", "C"], subject="who")
    assert list(table["effect"]) == ["pen type", "modality", "C", "pen type:modality", "pen type:C",
                                     "modality:C", "pen type:modality:C"]
    assert (table["df2"] == 4).all() and table["effect_size"].between(0, 1).all()


def test_art_aligned_check_is_zero_on_random_data():
    rng = np.random.default_rng(7)
    cells = [(s, a, b) for s in range(6) for a in ("a1", "a2") for b in ("b1", "b2", "b3")]
    data = pd.DataFrame(cells, columns=["s", "A", "B"]).assign(y=rng.normal(size=len(cells)))
    table = aligned_rank_transform(data, dv="y", within=["A", "B"], subject="s")
    assert list(table["effect"]) == ["A", "B", "A:B"] and (table["test"] == "ART RM-ANOVA").all()
    assert (table["aligned_check"] < 1e-8).all()
    assert list(table["df2"]) == [5, 10, 10] and table["p"].between(0, 1).all()
    one = aligned_rank_transform(data[data["B"] == "b1"], dv="y", within=["A"], subject="s").iloc[0]
    assert one["effect"] == "A" and math.isnan(one["aligned_check"])


def _random_tables(sizes: tuple[int, ...], n: int = 7) -> tuple[list[str], np.ndarray, list[pd.DataFrame]]:
    """A table of normal values and one of 1–5 ratings (ties) over ``sizes`` levels, as an
    array (tables × subjects × cells) and in long format (columns s, A, B, D, y)."""
    rng = np.random.default_rng(sum(sizes) * 10 + len(sizes))
    cells = math.prod(sizes)
    batch = np.concatenate([rng.normal(size=(1, n, cells)),
                            rng.integers(1, 6, size=(1, n, cells)).astype(float)])
    factors = ["A", "B", "D"][:len(sizes)]  # statsmodels refuses a factor named C
    index = pd.MultiIndex.from_product([[f"s{i}" for i in range(n)],
                                        *[[f"{name.lower()}{j}" for j in range(k)]
                                          for name, k in zip(factors, sizes)]], names=["s", *factors])
    frames = [pd.DataFrame({"y": values.ravel()}, index=index).reset_index() for values in batch]
    return factors, batch, frames


# pingouin's own rm_anova calls a pandas method pandas 3.1 deprecates; not ours to mend.
@pytest.mark.filterwarnings("ignore:The inplace keyword:DeprecationWarning")
@pytest.mark.parametrize("sizes", [(3,), (2, 3), (2, 2, 3)])
def test_contrast_anova_equals_statsmodels_and_rm_anova(sizes):
    from statsmodels.stats.anova import AnovaRM

    factors, batch, frames = _random_tables(sizes)
    parts = contrast_anova(batch, sizes)
    for index, long in enumerate(frames):
        reference = AnovaRM(long, depvar="y", subject="s", within=factors).fit().anova_table
        table = rm_anova(long, dv="y", within=factors, subject="s").set_index("effect")
        for effect in effects(factors):
            name, entry = effect_name(factors, effect), parts[effect]
            assert (entry["df1"], entry["df2"]) == tuple(reference.loc[name, ["Num DF", "Den DF"]])
            assert entry["F"][index] == pytest.approx(reference.loc[name, "F Value"], rel=1e-9)
            assert entry["p"][index] == pytest.approx(reference.loc[name, "Pr > F"], rel=1e-9)
            assert entry["ges"][index] == pytest.approx(table.loc[name, "effect_size"], rel=1e-9)
            if entry["df1"] > 1:
                for column in ("eps_gg", "eps_hf", "p_mauchly"):
                    assert entry[column][index] == pytest.approx(table.loc[name, column], rel=1e-9)


@pytest.mark.parametrize("sizes", [(2, 3), (2, 2, 2)])
def test_art_equals_statsmodels_on_the_aligned_ranks(sizes):
    """The ART's vectorised alignment and ANOVA against the definition, spelled out in pandas,
    and statsmodels' AnovaRM of the ranks."""
    from statsmodels.stats.anova import AnovaRM

    factors, _, frames = _random_tables(sizes)
    for long in frames[1:]:  # ratings: aligned responses with ties
        table = aligned_rank_transform(long, dv="y", within=factors, subject="s").set_index("effect")
        y = long["y"]
        residual = y - long.groupby(factors)["y"].transform("mean")
        for effect in effects(factors):
            estimate = 0.0
            for subset in [(), *[e for e in effects(factors) if set(e) <= set(effect)]]:
                mean = long.groupby([factors[j] for j in subset])["y"].transform("mean") \
                    if subset else y.mean()
                estimate = estimate + (-1) ** (len(effect) - len(subset)) * mean
            ranks = long.assign(y=scipy.stats.rankdata((residual + estimate).round(9)))
            reference = AnovaRM(ranks, depvar="y", subject="s", within=factors).fit().anova_table
            name = effect_name(factors, effect)
            assert table.loc[name, "statistic"] == pytest.approx(reference.loc[name, "F Value"], rel=1e-9)
            assert table.loc[name, "p"] == pytest.approx(reference.loc[name, "Pr > F"], rel=1e-9)
            assert table.loc[name, "aligned_check"] < 1e-9


def test_pairwise_holm_never_above_bonferroni():
    rng = np.random.default_rng(11)
    data = pd.DataFrame([(s, c) for s in range(8) for c in "ABCD"], columns=["s", "c"])
    data["y"] = rng.normal(size=len(data)) + data["c"].map({"A": 0, "B": 0.5, "C": 1, "D": 1.5})
    holm = pairwise(data, dv="y", within="c", subject="s", adjust="holm")
    bonferroni = pairwise(data, dv="y", within="c", subject="s", adjust="bonferroni")
    assert len(holm) == 6 and list(holm["effect"])[:3] == ["A vs B", "A vs C", "A vs D"]
    assert (holm["p_adjusted"] <= bonferroni["p_adjusted"] + 1e-15).all()
    assert (holm["p_adjusted"] >= holm["p"]).all() and (holm["p_adjusted"] < bonferroni["p_adjusted"]).any()
    ranks = pairwise(data, dv="y", within="c", subject="s", test="wilcoxon", adjust="none")
    assert (ranks["p_adjusted"] == ranks["p"]).all() and "w_plus" in ranks.columns


def test_mean_ci():
    assert mean_ci([4, 4, 4, 4]) == (4.0, 4.0, 4.0)
    assert mean_ci([4, 4, 4, 4], method="bootstrap") == (4.0, 4.0, 4.0)
    mean, low, high = mean_ci([1, 2, 3])
    assert mean == 2 and high - mean == pytest.approx(scipy.stats.t.ppf(0.975, 2) / math.sqrt(3), rel=1e-9)
    mean, low, high = mean_ci([1, 2, 2, 3, 5, 4, 2], method="bootstrap", n_boot=2000)
    assert low < mean < high
    assert mean_ci([1, 2, 2, 3, 5, 4, 2], method="bootstrap", n_boot=2000) == (mean, low, high)
    single = mean_ci([3.5])
    assert single[0] == 3.5 and math.isnan(single[1])


def test_cell_cis_average_repetitions_first():
    data = pd.DataFrame({"s": [1, 1, 1, 2, 2, 3, 3], "pen": ["a", "a", "b", "a", "b", "a", "b"],
                         "y": [1.0, 3.0, 4.0, 2.0, 5.0, 2.0, 6.0]})
    table = cell_cis(data, dv="y", by=["pen"], subject="s")
    assert list(table.columns) == ["pen", "mean", "ci_low", "ci_high", "n"]
    assert list(table["n"]) == [3, 3] and table.loc[0, "mean"] == pytest.approx(2.0)
    assert table.loc[0, ["mean", "ci_low", "ci_high"]].tolist() == pytest.approx(list(mean_ci([2.0, 2, 2])))


def test_degenerate_data_give_nan_with_a_reason_not_noise():
    flat = pd.DataFrame([(s, c, 3.0) for s in range(4) for c in "ABC"], columns=["s", "c", "y"])
    row = rm_anova(flat, dv="y", within="c", subject="s").iloc[0]
    assert math.isnan(row["statistic"]) and "no within-subject variation" in row["method"]
    shifted = flat.assign(y=flat["y"] + flat["s"] + flat["c"].map({"A": 0, "B": 1, "C": 3}))
    row = rm_anova(shifted, dv="y", within="c", subject="s").iloc[0]
    assert row["statistic"] == math.inf and row["p"] == 0 and math.isnan(row["eps_gg"])
    row = friedman(flat, dv="y", within="c", subject="s").iloc[0]
    assert math.isnan(row["statistic"]) and "tied" in row["method"]
    table = pairwise(flat.assign(y=flat["y"] + (flat["c"] == "C") * np.arange(12.0)), dv="y", within="c",
                     subject="s", test="wilcoxon").set_index("effect")
    assert math.isnan(table.loc["A vs B", "p_adjusted"]) and table.loc["A vs C", "p_adjusted"] == 0.25


# --- refusals: one line each, naming the thing ------------------------------------------------

def likert() -> pd.DataFrame:
    return long_from_matrix([[4, 2, 3], [3, 2, 5], [5, 1, 4], [3, 2, 3]])


@pytest.mark.parametrize(("change", "words"), [
    (lambda d: d.drop(index=4), ["subject 'b1'", "condition='c1'", "no value"]),
    (lambda d: pd.concat([d, d.iloc[[5]]]), ["subject 'b1'", "condition='c2'", "2 values"]),
    (lambda d: d[d["condition"] == "c0"], ["condition", "1 level"]),
    (lambda d: d[d["block"] == "b0"], ["at least 2 subjects"]),
    (lambda d: d.assign(y=d["y"].where(d.index != 7)), ["missing", "subject 'b2'", "condition='c1'"]),
    (lambda d: d.assign(y=d["y"].astype(str)), ["dv", "not numeric"]),
    (lambda d: d.drop(columns="y"), ["dv", "no column 'y'"]),
])
def test_friedman_refuses(change, words):
    with pytest.raises(ParameterError) as error:
        friedman(change(likert()), dv="y", within="condition", subject="block")
    text = one_line(error)
    assert all(word in text for word in words), text


def test_rm_anova_and_pairwise_refuse_unbalanced(anova_2x3):
    with pytest.raises(ParameterError) as error:
        rm_anova(anova_2x3.drop(index=17), dv="DV", within=["A", "B"], subject="id")
    assert "subject 2 has no value at A='a', B='c'" in one_line(error)
    with pytest.raises(ParameterError) as error:
        pairwise(anova_2x3, dv="DV", within="B", subject="id")
    assert "2 values" in one_line(error) and "average" in str(error.value)
    with pytest.raises(ParameterError) as error:
        pairwise(anova_2x3, dv="DV", within="B", subject="id", adjust="sidak", average_over=["A"])
    assert one_line(error).startswith("adjust:")


@pytest.mark.parametrize(("x", "y", "words"), [
    ([1, 2, 3], [1, 2], ["y:", "3 values", "2"]),
    ([1, math.nan, 3], [1, 2, 3], ["x:", "index 1"]),
    ([1, 2, 3], [1, 2, 3], ["zero"]),
])
def test_wilcoxon_refuses(x, y, words):
    with pytest.raises(ParameterError) as error:
        wilcoxon(x, y)
    text = one_line(error)
    assert all(word in text for word in words), text
    with pytest.raises(ParameterError) as error:
        wilcoxon([1, 2], [2, 1], method="sas")
    assert one_line(error).startswith("method:")


def test_wilcoxon_long_refuses_a_subject_missing_one():
    data = pd.DataFrame({"s": [1, 1, 2, 3, 3], "c": ["D", "F", "D", "D", "F"], "y": [1, 2, 3, 4, 6]})
    with pytest.raises(ParameterError) as error:
        wilcoxon_long(data, dv="y", within="c", subject="s", a="D", b="F")
    assert "subject 2 has no value at c='F'" in one_line(error)


@pytest.mark.parametrize(("values", "options", "start"), [
    ([], {}, "values: is empty"),
    ([1, math.nan], {}, "values: has a missing"),
    ([1, 2], {"confidence": 95}, "confidence:"),
    ([1, 2], {"method": "jackknife"}, "method:"),
])
def test_mean_ci_refuses(values, options, start):
    with pytest.raises(ParameterError) as error:
        mean_ci(values, **options)
    assert one_line(error).startswith(start)
