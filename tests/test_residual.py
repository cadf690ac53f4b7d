"""The stochastic residual (model "sines+residual"): analysis, rendering, loop seam, JSON, the
pipeline's scale, and what the exports say about it; "sines" stays the method exactly."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy import signal

from realpen.checks import MAX_BANDS
from realpen.dsp.filters import prepare
from realpen.errors import ParameterError
from realpen.exports import render
from realpen.io.recording import as_recording
from realpen.profile.schema import TactileModel
from realpen.sound.loop import seam_report
from realpen.tactile.build import build_pattern
from realpen.tactile.conditions import MODELS, TactileParams
from realpen.tactile.pattern import Component, TactilePattern
from realpen.tactile.residual import Residual, render_residual, residual_bands, residual_envelope

RATE_IN = 1344  # Hz, the method's accelerometer
EDGES = residual_bands(30.0, 672.0, 10.0)


def ar_noise(seconds: float = 20.0, seed: int = 1) -> np.ndarray:
    """A noise-like 'recording': white noise through a resonant AR(2) filter (peak ≈ 150 Hz)
    plus a broad floor — no sinusoids in it at all."""
    rng = np.random.default_rng(seed)
    white = rng.normal(size=int(seconds * RATE_IN))
    return signal.lfilter([1.0], [1.0, -1.2, 0.8], white) + 0.3 * white


@pytest.fixture(scope="module")
def recording() -> np.ndarray:
    return ar_noise()


@pytest.fixture(scope="module")
def pair(recording):
    """The same recording as condition B's sines and as sines + residual (flat actuator)."""
    return tuple(build_pattern(recording, "flat", input_rate=RATE_IN, model=model)
                 for model in MODELS)


def shaped(count: int = 15, seed: int = 3) -> Residual:
    levels = np.random.default_rng(seed).uniform(0.2, 1.0, (count, len(EDGES) - 1)) * 1e-2
    return Residual(EDGES, levels, seed=4)


def band_powers(loop: np.ndarray, rate: float, edges) -> np.ndarray:
    """Mean-square power of a loop in each band (its periodogram as a periodic signal)."""
    power = np.abs(np.fft.rfft(loop)) ** 2 * 2 / len(loop) ** 2
    freqs = np.fft.rfftfreq(len(loop), 1 / rate)
    return np.array([power[(freqs >= a) & (freqs < b)].sum() for a, b in zip(edges[:-1],
                                                                            edges[1:])])


def high_band(loop: np.ndarray, rate: float, cut_hz: float = 1200.0) -> np.ndarray:
    """The loop above ``cut_hz``, filtered circularly (the wrap is filtered like any other
    instant). The residual has nothing above 672 Hz, so what is there is a click."""
    spectrum = np.fft.rfft(loop)
    spectrum[np.fft.rfftfreq(len(loop), 1 / rate) < cut_hz] = 0
    return np.fft.irfft(spectrum, n=len(loop))


# --- the option -------------------------------------------------------------------------------

def test_sines_is_the_method_unchanged(recording, pair):
    sines, _ = pair
    default = build_pattern(recording, "flat", input_rate=RATE_IN)
    assert default.residual is None and sines.residual is None
    assert np.array_equal(default.samples, sines.samples) and default.version == sines.version
    assert "residual" not in sines.to_json()
    # Provenance: "sines" is not written, so old parameters (no "model") read back the same.
    assert "model" not in sines.params.to_json()
    assert TactileParams(**sines.params.to_json()) == sines.params
    assert TactileParams(**sines.params.to_json()).model == "sines"
    assert repr(sines.params) == "TactileParams(top=10, subpatterns=15, unit_ms=100)"


def test_model_is_validated_and_shown():
    with pytest.raises(ParameterError) as info:
        TactileParams(model="noise")
    assert info.value.parameter == "model"
    params = TactileParams(model="sines+residual")
    assert "model='sines+residual'" in repr(params)
    assert params.to_json()["model"] == "sines+residual"
    assert TactileParams(**params.to_json()) == params
    assert params.updated(condition="E").model == "sines+residual"


# --- the Residual type ------------------------------------------------------------------------

@pytest.mark.parametrize("kwargs, param", [
    ({"band_edges_hz": (30.0,), "levels": ((),)}, "band_edges_hz"),
    ({"band_edges_hz": (30.0, 20.0), "levels": ((1e-3,),)}, "band_edges_hz"),
    ({"band_edges_hz": (0.0, 20.0), "levels": ((1e-3,),)}, "band_edges_hz"),
    ({"band_edges_hz": (30.0, 2e5), "levels": ((1e-3,),)}, "band_edges_hz"),
    ({"band_edges_hz": tuple(range(1, MAX_BANDS + 3)), "levels": ((0.0,) * (MAX_BANDS + 1),)},
     "band_edges_hz"),
    ({"band_edges_hz": "30,40", "levels": ((1e-3,),)}, "band_edges_hz"),
    ({"band_edges_hz": (30.0, 40.0), "levels": ()}, "levels"),
    ({"band_edges_hz": (30.0, 40.0), "levels": ((1e-3, 1e-3),)}, "levels"),
    ({"band_edges_hz": (30.0, 40.0), "levels": ((-1e-3,),)}, "levels"),
    ({"band_edges_hz": (30.0, 40.0), "levels": ((float("nan"),),)}, "levels"),
    ({"band_edges_hz": (30.0, 40.0), "levels": ((True,),)}, "levels"),
    ({"band_edges_hz": (30.0, 40.0), "levels": ((0.0,),) * 1001}, "levels"),
    ({"band_edges_hz": (30.0, 40.0), "levels": ((0.0,),), "seed": -1}, "seed"),
    ({"band_edges_hz": (30.0, 40.0), "levels": ((0.0,),), "seed": True}, "seed"),
])
def test_bad_residuals_are_refused_by_name(kwargs, param):
    with pytest.raises(ParameterError) as info:
        Residual(**kwargs)
    assert info.value.parameter == param


def test_residual_json_and_its_place_in_the_pattern():
    residual = shaped(2)
    assert Residual.from_json(json.loads(json.dumps(residual.to_json()))) == residual
    with pytest.raises(ParameterError, match="unknown field"):
        Residual.from_json({**residual.to_json(), "gain": 1.0})
    sub = [Component(175.0, 0.3)]
    with pytest.raises(ParameterError) as info:  # 2 rows of levels for 3 sub-patterns
        TactilePattern([sub] * 3, residual=residual)
    assert info.value.parameter == "residual"
    pattern = TactilePattern([sub] * 2, residual=residual.to_json())  # a dict is read
    assert pattern.residual == residual
    assert pattern != TactilePattern([sub] * 2)  # the residual is part of the pattern
    assert pattern.version != TactilePattern([sub] * 2).version
    assert "residual in 38 bands" in repr(pattern)


# --- analysis ---------------------------------------------------------------------------------

def test_envelope_is_the_noise_floor_without_the_sines():
    rng = np.random.default_rng(0)
    t = np.arange(RATE_IN * 2) / RATE_IN
    sines = [(87.3, 0.5), (201.9, 1.0), (333.3, 0.3)]
    noise = rng.normal(0, 0.05, len(t))
    x = noise + sum(a * np.sin(2 * np.pi * f * t + 1.0) for f, a in sines)
    edges = (40.0, 120.0, 260.0, 400.0, 600.0)
    floor = 2 * 0.05 ** 2 / RATE_IN  # white noise, one-sided, (unit)²/Hz
    removed = residual_envelope(x, RATE_IN, [f for f, _ in sines], edges)
    assert np.all(np.abs(10 * np.log10(removed / floor)) < 1.0), removed / floor
    # Not removed, a sine's band integrates to its power A²/2 (one scale with the peaks).
    kept = residual_envelope(x, RATE_IN, [], edges)
    assert kept[1] * (edges[2] - edges[1]) == pytest.approx(0.5 + floor * 140, rel=0.05)


def test_bands():
    edges = np.asarray(EDGES)
    assert edges[0] == 30.0 and edges[-1] == 672.0
    widths = np.diff(edges)
    assert np.all(widths >= 10.0 - 1e-9)  # never finer than a 100 ms unit resolves
    assert np.all(edges[1:] / edges[:-1] <= 2 ** (1 / 12) * 1.5 + (10 / edges[:-1]))
    assert len(residual_bands(30.0, 672.0, 1000 / 1500)) - 1 == 54
    assert len(residual_bands(1e-3, 1.9e5, 1e-3)) - 1 == MAX_BANDS


# --- rendering --------------------------------------------------------------------------------

def test_rendered_noise_has_the_envelope():
    residual = shaped()
    loop = render_residual(residual, 8000, 100.0, 5.0)
    assert loop.shape == (12000,)
    expected = (np.asarray(residual.levels) ** 2 * np.diff(EDGES)).mean(axis=0)
    error_db = 10 * np.log10(band_powers(loop, 8000, EDGES) / expected)
    assert np.max(np.abs(error_db)) < 2.5 and abs(np.mean(error_db)) < 0.3
    assert np.mean(loop ** 2) == pytest.approx(np.mean(residual.powers), rel=0.05)
    # The same noise every time; another rate is another realisation of the same spectrum,
    # without the bands above its Nyquist frequency.
    assert np.array_equal(loop, render_residual(residual, 8000, 100.0, 5.0))
    high = render_residual(residual, 44100, 100.0, 5.0)
    assert len(high) == 15 * 4410
    assert np.mean(high ** 2) == pytest.approx(np.mean(residual.powers), rel=0.05)
    low = render_residual(residual, 1000, 100.0, 5.0)
    below = np.asarray(EDGES)[1:] <= 500
    kept = (np.asarray(residual.levels)[:, below] ** 2 * np.diff(EDGES)[below]).sum(axis=1)
    assert np.mean(low ** 2) == pytest.approx(np.mean(kept), rel=0.1)


@pytest.mark.parametrize("count, subpattern_ms, crossfade_ms", [
    (15, 100.0, 5.0), (15, 100.0, 0.0), (1, 1500.0, 5.0), (3, 100.0, 100.0)])
def test_residual_loops_seamlessly(count, subpattern_ms, crossfade_ms):
    residual = shaped(count)
    loop = render_residual(residual, 8000, subpattern_ms, crossfade_ms)
    # The sound loop's seam measure: the wrap is like any instant inside.
    seam = seam_report(loop, 8000)
    assert seam.level_jump_db <= seam.level_inside_p95_db
    assert seam.flux_wrap_db <= seam.flux_inside_p95_db
    # No click: nothing above the residual's band at the wrap beyond what the crossfades
    # leave inside; a splice of two noises leaves ten times more.
    edge = 16  # 2 ms
    clicks = np.abs(high_band(loop, 8000))
    inside = np.max(clicks[edge:-edge])
    assert np.max(np.r_[clicks[:edge], clicks[-edge:]]) <= inside
    other = render_residual(Residual(EDGES, residual.levels, seed=5), 8000, subpattern_ms,
                            crossfade_ms)
    middle = len(loop) // 2 + 7  # not a sub-pattern boundary
    spliced = np.abs(high_band(np.r_[loop[:middle], other[middle:]], 8000))
    assert np.max(spliced[middle - edge:middle + edge]) > 10 * inside


# --- the pipeline -----------------------------------------------------------------------------

@pytest.mark.parametrize("amplitude", ["sqrt", "power"])
def test_residual_keeps_the_recordings_balance_with_the_sines(recording, amplitude):
    pattern = build_pattern(recording, "flat", input_rate=RATE_IN, model="sines+residual",
                            amplitude=amplitude)
    mono = prepare(as_recording(recording, RATE_IN), None, None, 30.0).mono
    unit = int(round(0.1 * RATE_IN))
    widths = np.diff(pattern.residual.band_edges_hz)
    for index, sub in enumerate(pattern.subpatterns):
        start = int(pattern.analysis.selected[index]) * unit
        freqs, powers = pattern.analysis.unit(int(pattern.analysis.selected[index]))
        recorded = residual_envelope(mono[start:start + unit], RATE_IN, freqs,
                                     pattern.residual.band_edges_hz)
        sines = sum(c.amplitude ** 2 / 2 for c in sub)
        assert pattern.residual.powers[index] / sines == pytest.approx(
            float(np.sum(recorded * widths) / np.sum(powers)), rel=1e-6)
    # Normalised together: the peak of sines + noise sits at the headroom.
    assert np.max(np.abs(pattern.samples)) == pytest.approx(10 ** (-1 / 20))


def test_render_reproduces_the_samples_and_json_round_trips(pair):
    _, full = pair
    assert np.allclose(full.render(), full.samples, rtol=0, atol=1e-12)
    text = json.dumps(full.to_json())
    again = TactilePattern.from_json(json.loads(text))
    assert again == full and again.version == full.version
    assert np.allclose(again.samples, full.samples, rtol=0, atol=1e-12)
    # The version ignores the last bits of the levels.
    nudged = json.loads(text)
    nudged["residual"]["levels"][0][0] *= 1 + 1e-13
    assert TactilePattern.from_json(nudged).version == full.version
    # The profile's tactile section takes it as generated from the dataclass.
    assert TactileModel.model_validate(full.to_json()).residual is not None
    assert full.report()["residual"] == full.residual.to_json()
    assert any(note.startswith("residual: 38 bands") for note in full.notes)


def test_residual_pattern_loops_seamlessly(pair):
    _, full = pair
    seam = seam_report(full.samples, full.rate)
    assert seam.flux_wrap_db <= seam.flux_inside_p95_db
    assert seam.level_jump_db <= seam.level_inside_p95_db


def log_spectral_distance(loop: np.ndarray, rate: float, source: np.ndarray) -> float:
    """RMS over 30–500 Hz of the dB difference of two Welch spectra (5 Hz resolution), the
    mean difference (overall level) removed."""
    def welch(x, fs):
        freqs, psd = signal.welch(x, fs, nperseg=int(fs / 5))
        return np.interp(np.arange(30.0, 500.0, 5.0), freqs, psd)
    difference = 10 * np.log10(welch(np.tile(loop, 8), rate) / welch(source, RATE_IN))
    return float(np.sqrt(np.mean((difference - difference.mean()) ** 2)))


def test_residual_brings_a_noise_like_recording_closer(recording, pair):
    sines, full = pair
    closer = log_spectral_distance(full.samples, full.rate, recording)
    farther = log_spectral_distance(sines.samples, sines.rate, recording)
    assert closer < 0.6 * farther, (closer, farther)


def test_one_subpattern_and_hard_boundaries(recording):
    for options in ({"condition": "E"}, {"boundary": "hard", "amplitude": "power"}):
        pattern = build_pattern(recording, "lra:f0=175,q=8", input_rate=RATE_IN,
                                model="sines+residual", **options)
        assert len(pattern.residual.levels) == len(pattern.subpatterns)
        assert np.allclose(pattern.render(), pattern.samples, rtol=0, atol=1e-12)
    assert pattern.residual.bands == 38 and len(pattern.subpatterns) == 15


# --- exports ----------------------------------------------------------------------------------

def test_exports_say_what_becomes_of_the_residual(pair):
    sines, full = pair
    for fmt in ("hjif", "ahap", "android", "haptic", "wav", "c-header"):
        assert not any("residual" in limit for limit in render(fmt, sines).limits), fmt
    assert any("not carried" in limit and "residual" in limit
               for limit in render("hjif", full).limits)
    for fmt in ("ahap", "android", "haptic"):
        assert any("residual noise" in limit and "envelope" in limit
                   for limit in render(fmt, full).limits), fmt
    for fmt in ("wav", "c-header"):  # built from the samples: the noise is in them
        assert not any("residual" in limit for limit in render(fmt, full).limits), fmt


def test_study_conditions_stay_sines_for_a_profile_built_with_the_residual():
    """A–F are the method's stimuli: a profile's model never gives them a residual."""
    from realpen.profile import load_profile
    from realpen.study.patterns import condition_pattern

    pen = load_profile("ballpoint")
    provenance = pen.meta.provenance.model_copy(update={"tactile_parameters": {
        **pen.meta.provenance.tactile_parameters, "model": "sines+residual"}})
    residual_pen = type(pen)(pen.meta.model_copy(update={"provenance": provenance}),
                             pen.tactile, pen.sound, pen.path)
    rebuilt = condition_pattern(residual_pen, {"condition": "B"})
    assert rebuilt.residual is None and rebuilt.params.model == "sines"
    assert np.allclose(rebuilt.samples, pen.tactile, atol=1e-4)


def test_a_pattern_refuses_a_residual_above_its_nyquist_or_louder_than_full_scale():
    from realpen.tactile.pattern import Component, TactilePattern
    from realpen.tactile.residual import Residual

    sines = [[Component(100.0, 0.1)]] * 2
    fine = Residual([30.0, 100.0, 400.0], [[1e-3, 1e-3]] * 2, 0)
    assert TactilePattern(sines, 8000, residual=fine).residual == fine
    with pytest.raises(ParameterError, match="residual: has bands up to 5000 Hz"):
        TactilePattern(sines, 8000, residual=Residual([30.0, 100.0, 5000.0], [[1e-3, 1e-3]] * 2, 0))
    with pytest.raises(ParameterError, match="residual: carries a mean-square power"):
        TactilePattern(sines, 8000, residual=Residual([30.0, 100.0, 400.0], [[1.0, 1.0]] * 2, 0))
