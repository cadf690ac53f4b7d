"""Principal frequencies of unit sequences and the choice of units."""

from __future__ import annotations

import numpy as np
import pytest
from signals import sines

from realpen.dsp.spectrum import analyze, principal_frequencies, select_units
from realpen.errors import ParameterError, RealPenError

RATE = 1344


@pytest.mark.parametrize("seed", range(8))
def test_sinusoids_recovered_within_one_hz(seed):
    rng = np.random.default_rng(seed)
    freqs = np.sort(rng.choice(np.arange(40, 640, 45.0), size=5, replace=False)
                    + rng.uniform(-5, 5, 5))
    amps = rng.uniform(0.2, 1.0, 5)
    x = sines(freqs, amps, RATE, 2.5, noise=0.01, seed=seed)
    _, found, powers, _ = principal_frequencies(x, RATE, unit_ms=100, top=5)
    for unit_freqs, unit_powers in zip(found, powers):
        order = np.argsort(unit_freqs)
        assert np.all(np.abs(unit_freqs[order] - freqs) <= 1.0), (unit_freqs[order], freqs)
        # Powers are mean-square (A²/2) within 1 dB.
        ratio_db = 10 * np.log10(unit_powers[order] / (amps ** 2 / 2))
        assert np.all(np.abs(ratio_db) < 1.0), ratio_db


def test_one_broad_peak_takes_one_place():
    x = sines([100, 300], [1, 0.5], RATE, 2.0, noise=0.001)
    _, found, _, _ = principal_frequencies(x, RATE, top=10)
    # The two tones are the two strongest; no neighbouring bin of the 100 Hz peak is third.
    assert np.allclose(np.sort(found[5, :2]), [100, 300], atol=1)
    assert np.all(np.abs(found[5, 2:][np.isfinite(found[5, 2:])] - 100) > 9)


def test_peaks_stay_in_band():
    x = sines([10, 20, 200], [5, 5, 0.1], RATE, 2.0, noise=0.001)
    _, found, _, _ = principal_frequencies(x, RATE, top=10, fmin=30, fmax=600)
    finite = found[np.isfinite(found)]
    assert finite.min() >= 30 and finite.max() <= 600


def test_stationary_selection_finds_the_steady_run():
    rng = np.random.default_rng(3)
    units = 60
    levels = rng.normal(0, 6, size=(units, 24))  # wildly changing units...
    levels[30:45] = rng.normal(0, 0.1, size=(15, 24)) + 10  # ...and one steady run
    assert list(select_units(levels, 15, "stationary")) == list(range(30, 45))


def test_middle_selection_and_dropped_ends():
    levels = np.zeros((40, 24))
    chosen = select_units(levels, 15, "middle")
    assert list(chosen) == list(range(12, 27))
    chosen = select_units(np.zeros((17, 24)), 15, "stationary")
    assert list(chosen) == list(range(1, 16))  # never the first or the last unit


def test_too_short_and_silent():
    short = sines([100], [1], RATE, 1.6)
    with pytest.raises(RealPenError, match="too short.*1.7 s"):
        analyze(short, RATE, source="short.wav")
    with pytest.raises(RealPenError, match="silent.wav: signal is silent or constant"):
        analyze(np.zeros(RATE * 3), RATE, source="silent.wav")
    with pytest.raises(ParameterError, match="^selection: unknown value 'best'"):
        select_units(np.zeros((40, 24)), 15, "best")


@pytest.mark.parametrize("options, parameter", [
    ({"unit_ms": -1}, "unit_ms"), ({"unit_ms": float("nan")}, "unit_ms"), ({"top": 0}, "top"),
    ({"count": 0}, "count"), ({"selection": "best"}, "selection"), ({"rate": 0}, "rate"),
])
def test_bad_arguments_name_the_python_parameter(options, parameter):
    x = sines([100], [1], RATE, 3.0)
    arguments = {"rate": RATE, **options}
    with pytest.raises(ParameterError) as caught:
        analyze(x, **arguments)
    assert caught.value.parameter == parameter
    assert str(caught.value).startswith(f"{parameter}: ")
    assert "--" not in str(caught.value)  # never a flag of the command line
    with pytest.raises(ParameterError, match="^unit_ms: "):
        principal_frequencies(x, RATE, unit_ms=0)


def test_analysis_json_shape():
    x = sines([100, 250], [1, 0.5], RATE, 2.0)
    result = analyze(x, RATE, top=2, count=15)
    doc = result.to_json()
    assert doc["rate"] == RATE and doc["unit_ms"] == 100
    assert len(doc["units"]) == 20 and len(doc["selected"]) == 15
    unit = doc["units"][3]
    assert set(unit) == {"start_s", "frequencies_hz", "powers"}
    assert unit["start_s"] == pytest.approx(0.3, abs=1e-3)
    assert sorted(round(f) for f in unit["frequencies_hz"]) == [100, 250]


# --- limits: refused before any large allocation -----------------------------------------------

@pytest.mark.parametrize("options, parameter", [
    ({"top": 101}, "top"),                 # MAX_TOP = 100
    ({"top": 2.5}, "top"),                 # a count is whole
    ({"count": 1001}, "count"),            # MAX_SUBPATTERNS = 1000
    ({"unit_ms": 60_001.0}, "unit_ms"),    # MAX_UNIT_MS = one minute
])
def test_analyze_refuses_sizes_past_their_limits(options, parameter):
    x = sines([200], [1], RATE, 3.0)
    with pytest.raises(ParameterError) as caught:
        analyze(x, RATE, **options)
    assert caught.value.parameter == parameter


def test_units_of_too_few_or_too_many_samples_name_unit_ms_and_the_source():
    x = sines([200], [1], RATE, 3.0)
    with pytest.raises(ParameterError, match=r"^unit_ms: 1e-06 ms is only 0 samples at 1344 Hz "
                                             r"\(take3\); a unit needs at least 8"):
        analyze(x, RATE, unit_ms=1e-6, source="take3")
    # 2²⁰ + 1 samples in one unit: its zero-padded FFT would be 2²⁴ points.
    with pytest.raises(ParameterError, match=r"^unit_ms: .* 1,048,577 samples at 1e\+06 Hz"):
        principal_frequencies(np.ones(10), 1e6, unit_ms=1048.577)


def test_more_units_than_the_limit_are_refused_before_their_arrays_are_made(monkeypatch):
    import realpen.dsp.spectrum

    monkeypatch.setattr(realpen.dsp.spectrum, "MAX_UNITS", 50)  # the real one: 2¹⁸
    x = np.random.default_rng(0).normal(size=8 * 51)  # units of 8 samples
    with pytest.raises(ParameterError, match=r"^unit_ms: long\.wav holds 51 units of 1 ms; an "
                                             r"analysis takes at most 50"):
        principal_frequencies(x, 8000.0, unit_ms=1.0, source="long.wav")
    assert len(principal_frequencies(x[:8 * 50], 8000.0, unit_ms=1.0, top=1)[0]) == 50
