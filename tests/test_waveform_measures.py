"""Waveform measures (realpen.dsp.waveform_measures): MPEG PSNR, SNR, ST-SIM and SPQI.

Exact PSNR for a known error, ST-SIM a real number in [0, 1] even for an inverted waveform
(vibromaf's own gives a complex number there), a resampling round trip of a bundled pattern, and
the pen firmware's playback of each bundled pen — the simulated pen's recorded output against
the pattern at the pen's rate — at 40 dB PSNR or more.
"""

from __future__ import annotations

import math
import time

import numpy as np
import pytest

from realpen.dsp.waveform_measures import (
    WaveformMeasures,
    measure_waveform,
    mpeg_psnr,
    snr_db,
    spqi,
    st_sim,
)
from realpen.errors import ParameterError
from realpen.exports.base import resample_loop
from realpen.profile.registry import resolve_profile

RATE = 8000
PENS = ("pencil", "ballpoint", "marker")


@pytest.fixture(scope="module")
def pencil() -> np.ndarray:
    """The bundled pencil's pattern: 1.5 s at 8 kHz, full scale ±1."""
    profile = resolve_profile("pencil")
    assert int(profile.pattern.rate) == RATE
    return np.asarray(profile.tactile, dtype=np.float64)


def test_identical_signals_score_infinite_psnr_and_snr_and_perfect_st_sim_and_spqi(pencil):
    measures = measure_waveform(pencil, pencil.copy(), RATE)
    assert measures == WaveformMeasures(psnr=math.inf, snr=math.inf, st_sim=1.0, spqi=1.0)
    assert str(measures) == "PSNR inf dB, SNR inf dB, ST-SIM 1.000, SPQI 1.000"


def test_a_known_error_gives_the_exact_psnr_and_snr():
    reference = np.tile([0.5, -0.5], 100)
    decoded = reference + 0.05  # MSE 0.0025: 10·log10(4 / 0.0025) = 10·log10(1600)
    assert mpeg_psnr(decoded, reference) == pytest.approx(10 * math.log10(1600), rel=1e-12)
    assert snr_db(decoded, reference) == pytest.approx(10 * math.log10(0.25 / 0.0025), rel=1e-12)
    assert snr_db(np.ones(4), np.zeros(4)) == -math.inf  # a silent reference, a signal decoded


def test_st_sim_of_an_inverted_waveform_is_a_real_number_of_at_least_zero(pencil):
    # vibromaf raises the negative temporal similarity (−1 here) to the power 2/3: complex.
    score = st_sim(-pencil, pencil, RATE)
    assert isinstance(score, float) and 0.0 <= score <= 1.0
    assert score == 0.0  # the shape is lost entirely: no similarity
    louder = st_sim(2 * pencil, pencil, RATE)  # more than the reference is not closer than it
    assert isinstance(louder, float) and louder == pytest.approx(1.0)


def test_small_noise_gives_the_psnr_of_its_variance_and_st_sim_is_vibromafs_in_range(pencil):
    from vibromaf.metrics.stsim import st_sim as vibromaf_st_sim

    sigma = 0.01
    noisy = pencil + np.random.default_rng(5).normal(0.0, sigma, pencil.size)
    assert mpeg_psnr(noisy, pencil) == pytest.approx(10 * math.log10(4 / sigma**2), abs=0.5)
    # 3 % quieter, the noisy pattern has no more spectral support than the pencil's, so both
    # similarities lie in [0, 1] and nothing is clipped: vibromaf's own figure.
    quieter = 0.97 * pencil + np.random.default_rng(5).normal(0.0, sigma, pencil.size)
    assert st_sim(quieter, pencil, RATE) == pytest.approx(vibromaf_st_sim(quieter, pencil),
                                                          rel=1e-12)
    assert 0.99 < spqi(noisy, pencil, RATE) <= 1.0


def test_a_resampling_round_trip_of_a_bundled_pattern_keeps_the_waveform(pencil):
    there = resample_loop(pencil, RATE, 48000)
    back = resample_loop(there, 48000, RATE)
    measures = measure_waveform(back, pencil, RATE)
    assert measures.psnr >= 40.0, measures
    assert measures.st_sim > 0.99 and measures.spqi > 0.99, measures
    # At 48 kHz the perceptual measures see the signals resampled to 8 kHz first: vibromaf's
    # own figure for the two signals at 8 kHz.
    from scipy.signal import resample_poly
    from vibromaf.metrics.stsim import st_sim as vibromaf_st_sim

    noisy = there + np.random.default_rng(7).normal(0.0, 0.01, there.size)
    expected = vibromaf_st_sim(resample_poly(noisy, 1, 6), resample_poly(there, 1, 6))
    assert st_sim(noisy, there, 48000) == pytest.approx(expected, rel=1e-9)
    assert st_sim(noisy, there, 48000) != pytest.approx(vibromaf_st_sim(noisy, there), rel=1e-6)


@pytest.mark.parametrize("call, message", [
    (lambda x: mpeg_psnr(x[:-1], x), r"^decoded: must have as many samples as reference \(12,000\), "
                                     r"got 11,999$"),
    (lambda x: snr_db(np.stack([x, x]), x), r"^decoded: must be one-dimensional .* shape \(2, "),
    (lambda x: mpeg_psnr(x, np.where(x > 0, np.nan, x)), r"^reference: must hold finite samples"),
    (lambda x: st_sim(x[:400], x[:400], 8000), r"^reference: must last at least 64 ms .* got 50 ms$"),
    (lambda x: spqi(x, x, 8000.5), r"^rate: must be a whole number of Hz, got 8000\.5$"),
    (lambda x: measure_waveform(x, x, 10), r"^rate: must be between 100 and 384,000 Hz, got 10$"),
])
def test_bad_arguments_are_one_line_naming_the_parameter(pencil, call, message):
    with pytest.raises(ParameterError, match=message) as caught:
        call(pencil)
    assert "\n" not in str(caught.value)


# --- the pen firmware's playback ----------------------------------------------------------

RAMP = 40  # the 5 ms gain ramp at 8 kHz that starts every stroke (docs/protocol.md)


def _played_since(sim, start: int) -> int:
    """Samples the player has rendered since recorded sample ``start`` (underruns' silence,
    during which the player stands still, not counted)."""
    silent = sum(e["missing"] for e in sim.events()
                 if e["event"] == "underrun" and e["sample"] >= start)
    return len(sim.samples()) - start - silent


def _player_output(recorded: np.ndarray, events: list[dict], start: int, frames: int
                   ) -> np.ndarray:
    """``frames`` samples the player rendered from recorded sample ``start`` on, the silence
    of the sink's underruns cut out (the player stood still during them)."""
    keep = np.ones(len(recorded), dtype=bool)
    for event in events:
        if event["event"] == "underrun":
            keep[event["sample"]:event["sample"] + event["missing"]] = False
    keep[:start] = False
    played = recorded[keep][:frames]
    assert len(played) == frames, "the recording ended early"
    return played


@pytest.mark.firmware
def test_the_firmware_plays_each_bundled_pen_at_40_db_psnr_or_more(tmp_path):
    """One period of each pen's pattern, played by the firmware under the MicroPython Unix
    port at full gain, against the pattern at the pen's rate.

    The pen is sent ``round(32767 · x)`` (:func:`~realpen.device.pattern.pen_pattern`) and
    plays ``(p · 32767) >> 15`` at full gain; the recorded output over 32767 is compared with
    the float pattern itself, so the int16 quantisation and the Q15 gain are part of what is
    measured. A stroke starts at the pattern's first sample under a 5 ms ramp; the period
    compared starts after the ramp, at sample 40, and wraps round to it.
    """
    from realpen.device.client import PenClient
    from realpen.device.pattern import FULL_SCALE, pen_pattern
    from realpen.device.protocol import EV_PATTERN
    from realpen.device.sim import SimPen
    from realpen.device.transport import open_transport

    profiles = {name: resolve_profile(name) for name in PENS}
    with SimPen(trace=tmp_path / "trace.jsonl") as sim:
        with PenClient(open_transport(sim.port)) as client:
            rate = client.hello().sample_rate
            assert rate == RATE
            for name, profile in profiles.items():
                samples = pen_pattern(profile, rate)
                pattern_id = client.upload(samples, rate)
                deadline = time.monotonic() + 5
                while time.monotonic() < deadline:  # idle: it swaps in at once
                    event = client.read_event(0.1)
                    if event is not None and (event.kind, event.value) == (EV_PATTERN,
                                                                           pattern_id):
                        break
                else:
                    pytest.fail(f"{name}: the pen never announced pattern {pattern_id}")
                client.set_state(True, 1.0, fade_ms=5)
                client.sync()
                deadline = time.monotonic() + 60
                while time.monotonic() < deadline:
                    starts = [e for e in sim.events() if e["event"] == "set_state"]
                    if starts and starts[-1]["playing"] and \
                            _played_since(sim, starts[-1]["sample"]) >= RAMP + samples.size:
                        break
                    time.sleep(0.05)
                client.set_state(False, 0.0, fade_ms=5)
                client.sync()
                time.sleep(0.05)  # the 5 ms fade to silence, and the pen idle again
        recorded, events = sim.samples(), sim.events()
    starts = [e["sample"] for e in events if e["event"] == "set_state" and e["playing"]]
    swaps = [e["sample"] for e in events if e["event"] == "swap"]
    assert len(starts) == len(swaps) == len(PENS) and all(
        swap <= start for swap, start in zip(swaps, starts))
    failures = []
    for (name, profile), start in zip(profiles.items(), starts):
        pattern = np.asarray(profile.tactile, dtype=np.float64)  # already at the pen's rate
        played = _player_output(recorded, events, start, RAMP + pattern.size)[RAMP:]
        measures = measure_waveform(played / FULL_SCALE, np.roll(pattern, -RAMP), RATE)
        print(f"{name}: {measures}")  # the figures, shown with -s or on failure
        if measures.psnr < 40.0:
            failures.append(f"{name}: {measures}")
    assert not failures, failures
