"""The fidelity measures of realpen.tactile.fidelity on signals whose answer is known."""

import numpy as np
import pytest

from realpen.errors import ParameterError
from realpen.tactile import fidelity as fid

RATE = 8000


def noise(seconds=4.0, seed=0, rate=RATE):
    return np.random.default_rng(seed).standard_normal(int(seconds * rate))


def test_threshold_is_lowest_at_250_hz_and_weights_sum_to_one():
    freqs = np.arange(30.0, 501.0, 2.0)
    assert freqs[np.argmin(fid.threshold_db(freqs))] == 250.0
    assert fid.threshold_db(40.0) == pytest.approx(10.0, abs=1.0)
    weights = fid.sensitivity_weights(freqs)
    assert weights.sum() == pytest.approx(1.0)
    assert weights[freqs == 250.0][0] / weights[freqs == 40.0][0] > 20


def test_same_spectrum_is_near_zero_and_a_tilt_is_measured_in_db():
    x, y = noise(seed=1), noise(seed=2)
    same = fid.weighted_lsd(fid.signal_psd(x, RATE), fid.signal_psd(y, RATE))
    assert same < 2.5  # two realisations of white noise: only the Welch estimates differ
    freqs, psd = fid.signal_psd(x, RATE)
    # A ±6 dB tilt across the band against flat: the level is matched, the shape stays.
    tilt = psd * 10 ** (np.interp(freqs, [30, 500], [-6, 6]) / 10)
    tilted = fid.weighted_lsd((freqs, tilt), (freqs, psd), weighted=False)
    assert 3.0 < tilted < 4.5  # RMS of a uniform ±6 dB ramp is 6/√3 ≈ 3.46 dB (+ level match)
    level_only = fid.weighted_lsd((freqs, psd * 100), (freqs, psd))
    assert level_only == pytest.approx(0.0, abs=1e-9)
    assert fid.third_octave_distance((freqs, psd * 100), (freqs, psd)) == pytest.approx(0, abs=1e-9)


def test_sparse_spectra_are_floored_at_the_dynamic_range():
    t = np.arange(4 * RATE) / RATE
    tone = np.sin(2 * np.pi * 250 * t)
    distance = fid.weighted_lsd(fid.signal_psd(tone, RATE), fid.signal_psd(noise(), RATE))
    assert distance < fid.DYNAMIC_RANGE_DB


def test_actuator_filtering_of_a_loop_is_circular_and_follows_the_response():
    t = np.arange(RATE) / RATE  # 1 s loop: whole periods of 100 and 175 Hz
    loop = np.sin(2 * np.pi * 100 * t) + np.sin(2 * np.pi * 175 * t)
    out = fid.through_actuator(loop, RATE, "lra:f0=175,q=8")
    spectrum = np.abs(np.fft.rfft(out)) / (RATE / 2)
    from realpen.tactile.actuator import parse_actuator
    expected = parse_actuator("lra:f0=175,q=8").response(np.array([100.0, 175.0]))
    assert spectrum[[100, 175]] == pytest.approx(expected, rel=1e-9)


def test_modulation_difference_sees_an_amplitude_modulated_signal():
    steady = noise(seed=3)
    t = np.arange(len(steady)) / RATE
    modulated = steady * (1 + 0.8 * np.sin(2 * np.pi * 8 * t))
    assert fid.modulation_difference(steady, RATE, noise(seed=4), RATE) < 0.5
    assert fid.modulation_difference(modulated, RATE, steady, RATE) > 2.0


def test_fidelity_of_a_loop_with_the_targets_spectrum_beats_a_tone():
    target = noise(seconds=10, seed=5, rate=1000)
    loop = noise(seconds=1.5, seed=6)
    close = fid.fidelity(loop, RATE, target, 1000, "flat")
    t = np.arange(12000) / RATE
    far = fid.fidelity(np.sin(2 * np.pi * 200 * t), RATE, target, 1000, "flat")
    assert set(close) == {"lsd_db", "third_octave_db", "modulation_db"}
    # A 1.5 s loop has lines 0.67 Hz apart with random amplitudes: about 2 dB from flat.
    assert close["lsd_db"] < 3.0 < 10.0 < far["lsd_db"]
    with pytest.raises(ParameterError, match="x"):
        fid.signal_psd(np.zeros(10), RATE)


def test_smoothing_keeps_the_envelope_and_removes_fine_structure():
    freqs = np.arange(0.0, 1001.0, 2.0)
    rng = np.random.default_rng(7)
    envelope = 1.0 / (1.0 + (freqs / 200.0) ** 2)
    rough = envelope * rng.exponential(1.0, len(freqs))  # a periodogram's scatter
    assert fid.weighted_lsd((freqs, rough), (freqs, envelope)) > 3.0
    assert fid.weighted_lsd((freqs, rough), (freqs, envelope), smooth_octaves=1 / 3) < 1.5
    _, same = fid.smoothed((freqs, envelope), 0.0)
    assert np.array_equal(same, envelope)
