"""Tactile pattern synthesis: equalisation, seams, conditions A–F, determinism."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

from realpen.tactile.actuator import parse_actuator
from realpen.errors import RealPenError
from realpen.examples import example_recording_path
from realpen.io.recording import Recording, load_recording
from realpen.tactile.pattern import CONDITIONS, TactileParams, build_pattern, synthesize
from signals import fit_amplitudes, sines

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
    assert len(pattern.samples) == 12000
    assert pattern.analysis.unit_ms == unit_ms
    assert np.max(np.abs(pattern.samples)) == pytest.approx(10 ** (-1 / 20), rel=1e-6)


def test_unknown_condition():
    with pytest.raises(RealPenError, match="unknown condition 'G'"):
        TactileParams.for_condition("G")


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
    with pytest.raises(RealPenError, match="--rate"):
        build_pattern(tones_recording, parse_actuator("flat"), TactileParams(rate=800))


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
