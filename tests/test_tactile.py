"""Tactile patterns: the one TactilePattern type, equalisation, seams, conditions A–F,
parameters, determinism."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal
from signals import fit_amplitudes, sines

from realpen.errors import ParameterError, RealPenError
from realpen.examples import example_recording_path
from realpen.io.recording import Recording, load_recording
from realpen.tactile.actuator import parse_actuator
from realpen.tactile.build import build_pattern, tactile_pattern
from realpen.tactile.conditions import CONDITIONS, TactileParams
from realpen.tactile.pattern import Component, TactilePattern, canonical_json
from realpen.tactile.synthesis import synthesize

RATE = 1344
TONES = np.array([62.0, 113.0, 161.0, 208.0, 262.0, 318.0, 377.0, 436.0, 503.0, 581.0])


@pytest.fixture(scope="module")
def tones_recording() -> Recording:
    rng = np.random.default_rng(7)
    amps = rng.uniform(0.2, 1.0, len(TONES))
    x = sines(TONES, amps, RATE, 6.0, noise=0.002, seed=7)
    return Recording(x, RATE, ("z",), units="m/s^2", source="tones")


@pytest.fixture(scope="module")
def example() -> Recording:
    return load_recording(example_recording_path())


def independent_lra(f0: float, q: float, frequencies: np.ndarray) -> np.ndarray:
    w0 = 2 * np.pi * f0
    _, h = signal.freqs([1 / (q * w0), 0], [1 / w0 ** 2, 1 / (q * w0), 1],
                        worN=2 * np.pi * frequencies)
    return np.abs(h)


@pytest.mark.parametrize("condition", ["B", "E"])
def test_equalised_output_matches_target_ratios(tones_recording, condition):
    params = TactileParams.for_condition(condition, cap_db=12)
    pattern = build_pattern(tones_recording, parse_actuator("lra:f0=175,q=3"), params)
    length = int(params.unit_ms * params.rate / 1000)
    fade = int(params.crossfade_ms * params.rate / 1000)
    checked = clipped = 0
    for index, sub in enumerate(pattern.subpatterns):
        freqs = np.array([c.frequency_hz for c in sub])
        powers = np.array([c.power for c in sub])
        inside = pattern.samples[index * length + fade:(index + 1) * length - fade]
        measured = fit_amplitudes(inside, params.rate, freqs)
        output = measured * independent_lra(175, 3, freqs)  # what the actuator would produce
        reference = int(np.argmax([not c.clipped for c in sub]))
        free = np.array([not c.clipped for c in sub])
        got_db = 20 * np.log10(output / output[reference])
        want_db = 10 * np.log10(powers / powers[reference])
        assert np.all(np.abs(got_db - want_db)[free] < 0.5), (got_db - want_db)[free]
        # Clipped components come out weaker than their target, never stronger.
        assert np.all((got_db - want_db)[~free] < 0)
        checked += free.sum()
        clipped += (~free).sum()
    assert checked >= 4 * len(pattern.subpatterns) and clipped > 0


def seam_steps(x: np.ndarray, length: int, count: int) -> tuple[float, float]:
    """Largest step at a seam (wrap included), and largest step inside sub-patterns."""
    steps = np.abs(np.diff(np.concatenate([x, x[:1]])))
    seams = np.arange(1, count + 1) * length - 1  # step from a sub-pattern's last sample
    inside = np.delete(steps, seams)
    return float(steps[seams].max()), float(inside.max())


@pytest.mark.parametrize("condition", list(CONDITIONS))
def test_crossfaded_loop_has_no_click(example, condition):
    params = TactileParams.for_condition(condition)
    pattern = build_pattern(example, parse_actuator("lra:f0=175,q=8"), params)
    length = int(params.unit_ms * params.rate / 1000)
    at_seam, inside = seam_steps(pattern.samples, length, params.subpatterns)
    assert at_seam <= inside


def test_hard_boundaries_are_the_literal_concatenation(example):
    params = TactileParams(boundary="hard")
    pattern = build_pattern(example, parse_actuator("flat"), params)
    length = 800
    for index in (0, 7, 14):
        freqs, amps, phases = (np.array([getattr(c, k) for c in pattern.subpatterns[index]])
                               for k in ("frequency_hz", "amplitude", "phase"))
        t = np.arange(length) / 8000
        expected = (amps[:, None] * np.sin(2 * np.pi * freqs[:, None] * t + phases[:, None])).sum(0)
        assert np.allclose(pattern.samples[index * length:(index + 1) * length], expected)
    # And the seam check above is able to fail: hard seams jump.
    at_seam, inside = seam_steps(pattern.samples, length, 15)
    assert at_seam > inside


@pytest.mark.parametrize("condition", list(CONDITIONS))
def test_conditions_give_counts_and_durations(example, condition):
    top, count, unit_ms = CONDITIONS[condition]
    pattern = build_pattern(example, parse_actuator("flat"), TactileParams.for_condition(condition))
    assert len(pattern.subpatterns) == count
    assert all(len(sub) == top for sub in pattern.subpatterns)
    assert pattern.duration_s == pytest.approx(1.5)
    assert len(pattern.samples) == 12000 == pattern.frames
    assert pattern.subpattern_ms == unit_ms
    # Every condition selects its stretch in the same 100 ms units (D–F analyse it as one).
    assert pattern.analysis.unit_ms == 100.0 and len(pattern.analysis.selected) == 15
    assert np.max(np.abs(pattern.samples)) == pytest.approx(10 ** (-1 / 20), rel=1e-6)


def test_unknown_condition():
    with pytest.raises(ParameterError, match="condition: unknown condition 'G'") as info:
        TactileParams.for_condition("G")
    assert info.value.parameter == "condition"


def test_seeded_phases_are_deterministic(example):
    act = parse_actuator("flat")
    one = build_pattern(example, act, TactileParams(seed=5))
    two = build_pattern(example, act, TactileParams(seed=5))
    other = build_pattern(example, act, TactileParams(seed=6))
    assert np.array_equal(one.samples, two.samples)
    assert not np.allclose(one.samples, other.samples)
    assert [c.frequency_hz for c in one.subpatterns[3]] == [c.frequency_hz for c in other.subpatterns[3]]


def test_amplitude_modes(tones_recording):
    act = parse_actuator("flat")
    sqrt_mode = build_pattern(tones_recording, act, TactileParams(amplitude="sqrt"))
    power_mode = build_pattern(tones_recording, act, TactileParams(amplitude="power"))
    for mode, pattern in (("sqrt", sqrt_mode), ("power", power_mode)):
        sub = pattern.subpatterns[4]
        powers = np.array([c.power for c in sub])
        amps = np.array([c.amplitude for c in sub])
        expected = np.sqrt(powers) if mode == "sqrt" else powers
        assert np.allclose(amps / amps[0], expected / expected[0])


def test_random_phases_keep_crest_factor_low(example):
    pattern = build_pattern(example, parse_actuator("flat"), TactileParams())
    x = pattern.samples
    crest = np.max(np.abs(x)) / np.sqrt(np.mean(x ** 2))
    zero_phase = synthesize([(np.array([c.frequency_hz for c in s]),
                              np.array([c.amplitude for c in s]), np.zeros(len(s)) + np.pi / 2)
                             for s in pattern.subpatterns], 8000, 100)
    crest_aligned = np.max(np.abs(zero_phase)) / np.sqrt(np.mean(zero_phase ** 2))
    assert crest < crest_aligned


def test_output_rate_too_low(tones_recording):
    with pytest.raises(ParameterError, match="^rate: 800 Hz is too low") as info:
        build_pattern(tones_recording, parse_actuator("flat"), TactileParams(rate=800))
    assert info.value.parameter == "rate"


def test_render_refuses_a_rate_beyond_the_maximum():
    pattern = TactilePattern([[Component(175.0, 0.5)]])
    with pytest.raises(ParameterError, match="^rate: must be <= 384000"):
        pattern.render(10 ** 9)
    with pytest.raises(ParameterError, match="^rate: must be <= 384000"):
        TactilePattern([[Component(175.0, 0.5)]], rate=10 ** 9)


def test_a_selected_unit_without_peaks_is_a_data_error_naming_the_recording():
    # Every other 100 ms unit is silent: a selected unit has no peaks to synthesise.
    n = int(round(0.1 * RATE))
    x = np.sin(2 * np.pi * 180 * np.arange(30 * n) / RATE)
    for unit in range(1, 30, 2):
        x[unit * n:(unit + 1) * n] = 0.0
    recording = Recording(x, RATE, ("z",), source="gappy")
    with pytest.raises(RealPenError, match="^gappy: no spectral peaks in selected unit") as info:
        build_pattern(recording, "flat", selection="middle")
    assert not isinstance(info.value, ParameterError)


def test_persistent_tones_do_not_dip_at_crossfades():
    # Two steady tones (and a little noise) persist through every unit: their amplitudes in
    # the pattern must stay steady across every boundary and the loop wrap.
    x = sines([150, 260], [1.0, 0.6], RATE, 4.0, noise=0.01, seed=3)
    pattern = build_pattern(Recording(x, RATE, ("z",), source="two tones"), parse_actuator("flat"),
                            TactileParams())
    tracked = {}
    for target in (150, 260):
        found = [c for sub in pattern.subpatterns for c in sub if abs(c.frequency_hz - target) < 3]
        assert len(found) == 15 and all(c.joins_previous and c.joins_next for c in found)
        tracked[target] = np.mean([c.frequency_hz for c in found])
    looped = np.concatenate([pattern.samples, pattern.samples[:800]])
    half = 40  # a 10 ms window around each point
    at = lambda centre: fit_amplitudes(looped[centre - half:centre + half], 8000,  # noqa: E731
                                       list(tracked.values()))
    boundaries = np.array([at(b) for b in np.arange(1, 16) * 800])  # the last is the wrap
    middles = np.array([at(b) for b in np.arange(15) * 800 + 400])
    assert np.all(boundaries > 0.9 * middles.min(axis=0)), boundaries / middles.mean(axis=0)


def test_hard_boundaries_can_dip():
    # The literal method redraws phases per sub-pattern: the same check finds jumps there.
    x = sines([150, 260], [1.0, 0.6], RATE, 4.0, noise=0.01, seed=3)
    pattern = build_pattern(Recording(x, RATE, ("z",)), parse_actuator("flat"),
                            TactileParams(boundary="hard"))
    phases = [next(c.phase for c in sub if abs(c.frequency_hz - 150) < 3) for sub in pattern.subpatterns]
    assert np.std(np.diff(phases)) > 0.5


def test_single_pattern_tracks_close_on_whole_cycles(example):
    pattern = build_pattern(example, parse_actuator("flat"), TactileParams.for_condition("E"))
    for component in pattern.subpatterns[0]:
        cycles = component.frequency_hz * 1.5
        assert abs(cycles - round(cycles)) < 1e-6
    # With whole cycles the loop is continuous without any crossfade at the wrap.
    x = pattern.samples
    assert abs(x[0] - x[-1]) <= np.max(np.abs(np.diff(x)))


# --- study conditions: one stretch for all six ---------------------------------------------

def test_condition_sets_its_counts():
    for key, (top, count, unit_ms) in CONDITIONS.items():
        params = TactileParams(condition=key.lower())
        assert (params.condition, params.top, params.subpatterns, params.unit_ms) == \
            (key, top, count, unit_ms)
        assert params.stretch_ms == 1500.0
        assert params.selection_unit_ms == 100.0
        assert params.units_per_subpattern == (15 if key in "DEF" else 1)
    # Counts that agree with the condition are accepted; counts that disagree are refused.
    assert TactileParams(condition="D", top=5, subpatterns=1, unit_ms=1500).top == 5
    for counts, name in (({"top": 10}, "top"), ({"subpatterns": 15}, "subpatterns"),
                         ({"unit_ms": 100}, "unit_ms")):
        with pytest.raises(ParameterError, match=f"^{name}: condition D sets") as info:
            TactileParams(condition="D", **counts)
        assert info.value.parameter == name
    with pytest.raises(ParameterError, match="^selection_unit_ms: condition E"):
        TactileParams(condition="E", selection_unit_ms=50)
    # Without a condition the counts default to B's and nothing is recorded.
    default = TactileParams()
    assert (default.top, default.subpatterns, default.unit_ms, default.condition) == (10, 15, 100, None)
    assert TactileParams.resolve(None).condition == "B"
    seven = TactileParams.resolve(None, top=7)
    assert seven.top == 7 and seven.condition is None
    with pytest.raises(ParameterError, match="^top: condition A sets 5, not 7"):
        TactileParams.resolve("A", top=7)


@pytest.mark.parametrize("options, parameter", [
    ({"unit_ms": -1}, "unit_ms"), ({"top": 0}, "top"), ({"subpatterns": 0}, "subpatterns"),
    ({"crossfade_ms": 200}, "crossfade_ms"), ({"cap_db": float("nan")}, "cap_db"),
    ({"rate": 0}, "rate"), ({"seed": -1}, "seed"), ({"boundary": "soft"}, "boundary"),
    ({"rate": 10 ** 9}, "rate"),
    ({"amplitude": "cubic"}, "amplitude"), ({"selection": "best"}, "selection"),
    ({"highpass_hz": -3}, "highpass_hz"), ({"analysis_rate": 0}, "analysis_rate"),
    ({"condition": "Z"}, "condition"), ({"unit_ms": 150, "selection_unit_ms": 100},
                                        "selection_unit_ms"),
    ({"top": 2.5}, "top"),
    # Limits on what sizes the pattern or its analysis (realpen.checks).
    ({"top": 101}, "top"), ({"subpatterns": 1001}, "subpatterns"),
    ({"unit_ms": 60_001}, "unit_ms"), ({"seed": 2 ** 63}, "seed"), ({"cap_db": 61}, "cap_db"),
    ({"rate": 99}, "rate"), ({"analysis_rate": 400_001}, "analysis_rate"),
    ({"analysis_rate": 99}, "analysis_rate"),
    ({"unit_ms": 1e-6}, "unit_ms"),  # less than one sample: not the crossfade's fault
    ({"subpatterns": 300, "unit_ms": 60_000}, "subpatterns"),  # 144 M samples at 8 kHz
    ({"unit_ms": 60_000, "subpatterns": 1, "rate": 384_000}, "unit_ms"),  # 23 M samples
])
def test_bad_parameters_are_named_by_their_python_name(options, parameter):
    with pytest.raises(ParameterError) as info:
        TactileParams(**options)
    assert info.value.parameter == parameter
    assert str(info.value).startswith(f"{parameter}: ") and "--" not in str(info.value)


def stretch_recording() -> Recording:
    """4 s: steady tones (150, 260 Hz) from 1.2 s to 3.2 s; a noisy 410 Hz burst elsewhere."""
    rate, seconds = 1344, 4.0
    t = np.arange(int(rate * seconds)) / rate
    rng = np.random.default_rng(11)
    steady = (t >= 1.2) & (t < 3.2)
    x = np.where(steady, np.sin(2 * np.pi * 150 * t) + 0.6 * np.sin(2 * np.pi * 260 * t),
                 (1 + rng.standard_normal(len(t))) * np.sin(2 * np.pi * 410 * t))
    return Recording(x + 0.01 * rng.standard_normal(len(t)), rate, ("z",), source="stretch")


def test_a_4_s_recording_serves_all_six_conditions_from_one_stretch():
    recording = stretch_recording()
    patterns = {key: build_pattern(recording, "flat", condition=key) for key in CONDITIONS}
    b = patterns["B"]
    # The stretch is chosen as the streamed analysis chooses it (the same units as `realpen
    # analyze`); its units may start a few ms before the steady part, within one frame.
    assert b.stretch_s[0] >= 1.2 - 0.005 and b.stretch_s[1] <= 3.2 + 0.005
    for key, pattern in patterns.items():
        assert pattern.duration_s == pytest.approx(1.5)
        assert pattern.stretch_s == pytest.approx(b.stretch_s), key
        assert np.array_equal(pattern.analysis.selected, b.analysis.selected), key
    for key in "DEF":
        top = CONDITIONS[key][0]
        (sub,) = patterns[key].subpatterns
        assert len(sub) == top
        # The one unit is B's stretch: its strongest components are the steady tones.
        strongest = sorted(c.frequency_hz for c in sorted(sub, key=lambda c: -c.power)[:2])
        assert strongest == pytest.approx([150, 260], abs=1.0), strongest
        assert all(abs(c.frequency_hz - 410) > 5 for c in sub[:2])
    # The stretch is also what the --json report says.
    assert patterns["E"].report()["analysis"]["stretch_s"] == pytest.approx(b.stretch_s, abs=1e-6)


def test_d_matches_the_concatenated_units_of_b():
    """D's unit is exactly B's 15 selected units, analysed as one (not a 1500 ms grid unit)."""
    from realpen.dsp.filters import prepare
    from realpen.dsp.spectrum import principal_frequencies

    recording = stretch_recording()
    b = build_pattern(recording, "flat", condition="B")
    d = build_pattern(recording, "flat", condition="D", boundary="hard")
    mono = prepare(recording, None, None, 30.0).mono
    unit = int(round(0.1 * recording.rate))
    first, last = int(b.analysis.selected[0]), int(b.analysis.selected[-1])
    segment = mono[first * unit:(last + 1) * unit]
    _, freqs, _, _ = principal_frequencies(segment, recording.rate, len(segment) / recording.rate * 1000,
                                           5, 30.0)
    assert [c.frequency_hz for c in d.subpatterns[0]] == pytest.approx(freqs[0], rel=1e-12)


# --- the one pattern type ------------------------------------------------------------------

def test_pattern_from_components_renders_at_any_rate():
    pattern = TactilePattern([[Component(150.0, 0.5, 0.0, joins_next=True)],
                              [Component(150.0, 0.5, np.pi, joins_previous=True),
                               Component(300.0, 0.25)]], subpattern_ms=50)
    assert pattern.frames == 800 and pattern.duration_s == pytest.approx(0.1)
    assert pattern.samples.shape == (800,)
    assert np.array_equal(pattern.samples, pattern.render())
    for rate in (8000, 16000, 44100):
        x = pattern.render(rate)
        assert len(x) == pattern.frames_at(rate) == round(0.1 * rate)
        inside = slice(round(0.01 * rate), round(0.04 * rate))
        t = np.arange(len(x))[inside] / rate
        assert np.allclose(x[inside], 0.5 * np.sin(2 * np.pi * 150 * t), atol=1e-9)
    with pytest.raises(ParameterError, match="^rate: 500 Hz is too low"):
        pattern.render(500)
    # Lists and JSON dicts become tuples of Components.
    assert isinstance(pattern.subpatterns, tuple) and isinstance(pattern.subpatterns[1], tuple)
    again = TactilePattern.from_json(pattern.to_json())
    assert again == pattern and again.version == pattern.version


def test_pattern_json_is_exactly_its_fields_and_equality_ignores_provenance(example):
    built = build_pattern(example, "lra:f0=175,q=8")
    data = built.to_json()
    assert list(data) == ["rate", "subpattern_ms", "boundary", "crossfade_ms", "subpatterns"]
    assert set(data["subpatterns"][0][0]) == {"frequency_hz", "amplitude", "phase", "power",
                                              "weight", "clipped", "joins_previous", "joins_next"}
    bare = TactilePattern.from_json(data)
    assert bare == built and bare.actuator is None and built.actuator.spec == "lra:f0=175,q=8"
    assert built.params == TactileParams() and built.analysis is not None
    assert built.provenance["sha256"] == example.sha256 and built.gain > 0
    # The stored samples are the rendering (float64 rounding aside).
    assert np.max(np.abs(built.samples - bare.render())) < 1e-12
    with pytest.raises(ParameterError, match="unknown field"):
        TactilePattern.from_json({**data, "extra": 1})


def test_pattern_version_ignores_the_last_bits_of_floats():
    pattern = TactilePattern([[Component(270.28028653691086, 0.44480934103839515, 4.002148315014479)]])
    nudged = TactilePattern([[Component(270.280286536911, 0.44480934103839520, 4.002148315014481)]])
    other = TactilePattern([[Component(270.2803, 0.44480934103839515, 4.002148315014479)]])
    assert pattern != nudged and pattern.version == nudged.version
    assert other.version != pattern.version
    assert canonical_json({"b": -0.0, "a": [1.0, 2, "x", None, True]}) == \
        b'{"a":[1.0,2,"x",null,true],"b":0.0}'


@pytest.mark.parametrize("make, parameter", [
    (lambda: Component(-1.0, 0.5), "frequency_hz"),
    (lambda: Component(100.0, float("nan")), "amplitude"),
    (lambda: Component(100.0, 0.5, float("inf")), "phase"),
    (lambda: Component(100.0, 0.5, clipped="yes"), "clipped"),
    (lambda: TactilePattern([]), "subpatterns"),
    (lambda: TactilePattern([[]]), "subpatterns"),
    (lambda: TactilePattern([[Component(100.0, 0.5)]], rate=0), "rate"),
    (lambda: TactilePattern([[Component(100.0, 0.5)]], boundary="soft"), "boundary"),
    (lambda: TactilePattern([[Component(100.0, 0.5)]], crossfade_ms=101), "crossfade_ms"),
    (lambda: TactilePattern([[Component(100.0, 0.5)]]).with_samples(np.zeros(10)), "samples"),
    (lambda: TactilePattern([[Component(100.0, 0.5)]] * 1001), "subpatterns"),
    (lambda: TactilePattern([[Component(100.0 + k, 0.01) for k in range(101)]]), "subpatterns"),
    (lambda: TactilePattern([[Component(100.0, 0.5)]] * 300, subpattern_ms=60_000), "subpatterns"),
    (lambda: TactilePattern([[Component(100.0, 0.5)]] * 2, subpattern_ms=60_000).render(384_000),
     "rate"),
])
def test_bad_patterns_are_refused_by_parameter(make, parameter):
    with pytest.raises(ParameterError) as info:
        make()
    assert info.value.parameter == parameter


def test_one_line_reprs_under_200_characters(example):
    built = build_pattern(example, "lra:f0=175,q=8")
    assert repr(built) == ("TactilePattern(15 sub-patterns × 100 ms, 10 components each, 8000 Hz, "
                           "lra:f0=175,q=8)")
    busy = TactileParams(condition="F", rate=44100, boundary="hard", crossfade_ms=2.5,
                         amplitude="power", seed=12345, cap_db=12.5, headroom_db=3.0,
                         selection="middle", highpass_hz=40.0, fmax_hz=600.0, axis="magnitude",
                         analysis_rate=1344.0)
    texts = [repr(built), repr(built.subpatterns[0][0]), repr(busy), repr(TactileParams()),
             repr(built.actuator), repr(Component(1.5, 0.25, clipped=True, joins_next=True))]
    for text in texts:
        assert "\n" not in text and len(text) < 200, text
    assert repr(TactileParams(condition="E")) == ("TactileParams(condition='E', top=10, "
                                                  "subpatterns=1, unit_ms=1500, "
                                                  "selection_unit_ms=100)")


def test_build_pattern_takes_a_spec_a_path_and_options():
    pattern = build_pattern(example_recording_path(), "lra:f0=175,q=8", condition="E", seed=3)
    assert pattern.params.condition == "E" and pattern.params.seed == 3
    assert len(pattern.subpatterns) == 1 and pattern.actuator.kind == "lra"
    again = tactile_pattern(example_recording_path(), condition="E", seed=3)
    assert again == pattern and np.array_equal(again.samples, pattern.samples)
    x = load_recording(example_recording_path())
    from_array = build_pattern(x.samples, "flat", input_rate=x.rate)
    assert from_array == build_pattern(x, "flat")
    with pytest.raises(ParameterError, match="^input_rate:"):
        build_pattern(x.samples, "flat")
    with pytest.raises(ParameterError, match="^actuator: unknown actuator"):
        build_pattern(x, "voicecoil")


def test_synthesis_checks_its_arguments():
    with pytest.raises(ParameterError, match="^boundary:"):
        synthesize([([100.0], [0.5], [0.0])], 8000, 100, boundary="soft")
    with pytest.raises(ParameterError, match="^subpatterns:"):
        synthesize([], 8000, 100)


MODULES = ["realpen.tactile", "realpen.tactile.actuator", "realpen.tactile.pattern",
           "realpen.tactile.synthesis", "realpen.tactile.conditions", "realpen.tactile.build",
           "realpen.profile", "realpen.profile.schema", "realpen.profile.bundle",
           "realpen.profile.build", "realpen.profile.registry", "realpen.profile.compare",
           "realpen.exports", "realpen.exports.base", "realpen.exports.wav",
           "realpen.exports.c_header", "realpen.exports.ahap", "realpen.exports.haptic",
           "realpen.exports.android", "realpen.exports.hjif", "realpen.exports.envelope",
           "realpen.pens", "realpen.pens.build", "realpen.pens.model", "realpen.live.catalog",
           "realpen.live.device", "realpen.io.recording", "realpen.io.paths",
           "realpen.dsp.filters", "realpen.dsp.spectrum", "realpen.dsp.tracks",
           "realpen.datasets.hatt"]


@pytest.mark.parametrize("name", MODULES)
def test_every_module_has_all_and_names_no_flags(name):
    import importlib
    import inspect
    from pathlib import Path

    module = importlib.import_module(name)
    assert isinstance(module.__all__, list) and module.__all__
    for item in module.__all__:
        assert getattr(module, item) is not None, item
    source = Path(inspect.getfile(module)).read_text(encoding="utf-8")
    assert '"--' not in source and "'--" not in source  # messages use Python parameter names


def test_updated_keeps_counts_consistent(example):
    b = TactileParams(condition="B", seed=3)
    e = b.updated(condition="E")
    assert (e.condition, e.top, e.subpatterns, e.unit_ms, e.selection_unit_ms, e.seed) == \
        ("E", 10, 1, 1500.0, 100.0, 3)
    seven = b.updated(top=7)
    assert seven.condition is None and seven.top == 7
    long = TactileParams().updated(unit_ms=250, subpatterns=6)
    assert long.selection_unit_ms == 250 and long == TactileParams(unit_ms=250, subpatterns=6)
    with pytest.raises(ParameterError, match="^top: condition E sets"):
        b.updated(condition="E", top=5)
    with pytest.raises(ParameterError, match="^colour:"):
        b.updated(colour="red")
    pattern = build_pattern(example, "flat", TactileParams(seed=2), condition="F")
    assert pattern.params.condition == "F" and pattern.params.seed == 2


def test_tactile_crossfade_longer_than_the_unit_names_both():
    with pytest.raises(ParameterError, match=r"^crossfade_ms: 5 ms is longer than the 3 ms "
                                             r"sub-pattern; shorten the crossfade"):
        TactileParams(unit_ms=3)


def test_synthesis_in_blocks_of_components_is_the_same_sum(monkeypatch):
    import realpen.tactile.synthesis as synthesis

    rng = np.random.default_rng(4)
    subs = [(rng.uniform(40, 600, 12), rng.uniform(0, 0.1, 12), rng.uniform(0, 6, 12),
             rng.random(12) < 0.5, rng.random(12) < 0.5) for _ in range(3)]
    whole = synthesize(subs, 8000, 100, "crossfade", 5)
    # 900 values per block: one component of an 840-sample sub-pattern (800 + 40 fade) at a time.
    monkeypatch.setattr(synthesis, "_BLOCK_VALUES", 900)
    np.testing.assert_allclose(synthesize(subs, 8000, 100, "crossfade", 5), whole,
                               rtol=0, atol=1e-12)


@pytest.mark.parametrize("spec", ["", "   "])
def test_an_empty_actuator_spec_is_not_the_current_folder(spec):
    with pytest.raises(ParameterError, match="^actuator: is empty"):
        parse_actuator(spec)
