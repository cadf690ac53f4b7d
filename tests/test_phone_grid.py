"""A phone-sensor CSV with dropped samples put on an even grid, explicitly (issue 21, item 6):
the share interpolated and the longest gap reported, a stated limit, and a refusal that names
the option when it is not given."""

from __future__ import annotations

import numpy as np
import pytest
import soundfile as sf
from conftest import assert_clean_failure, run_cli

import realpen as rp
from realpen.errors import ParameterError, RealPenError
from realpen.io.blocks import open_stream
from realpen.io.timegrid import place_on_grid

RATE = 400.0  # a phone accelerometer's rate
TONES = (60.0, 130.0)


def phone_times(seconds: float, dropped: int, burst: int, seed: int = 1) -> np.ndarray:
    """Timestamps at RATE with jitter, ``dropped`` single samples missing and one gap of
    ``burst`` samples at 10 s (as a phone's sensor delivers them)."""
    rng = np.random.default_rng(seed)
    count = int(seconds * RATE)
    keep = np.ones(count, dtype=bool)
    keep[rng.choice(np.arange(10, count - 10), dropped, replace=False)] = False
    start = int(min(10.0, seconds / 2) * RATE)
    keep[start:start + burst] = False
    times = np.arange(count)[keep] / RATE
    return times + rng.uniform(-0.05, 0.05, len(times)) / RATE


def signal_at(times: np.ndarray) -> np.ndarray:
    return sum(np.sin(2 * np.pi * f * times + k) for k, f in enumerate(TONES))


def write_phone_csv(path, times: np.ndarray) -> None:
    x = signal_at(times)
    data = np.column_stack([times, x, 0.5 * x, 9.81 + 0.1 * x])
    np.savetxt(path, data, fmt="%.6f", delimiter=",", header="timestamp,x,y,z", comments="")


def test_dropped_samples_are_counted_and_the_tones_kept():
    times = phone_times(12.0, dropped=60, burst=12)
    samples, report = place_on_grid(times, signal_at(times)[:, None], source="phone.csv")
    missing = int(12.0 * RATE) - len(times)  # 72 less any drop that fell into the burst
    assert missing >= 70 and report.missing == missing and report.rows == len(times)
    assert report.interpolated_pct == pytest.approx(100 * missing / (12.0 * RATE))
    assert report.longest_gap_s == pytest.approx(13 / RATE, rel=0.05)
    assert report.longest_gap_after_s == pytest.approx(6.0 - 1 / RATE, abs=0.01)
    assert report.rate == pytest.approx(RATE, rel=0.002)
    grid = times[0] + np.arange(len(samples)) / report.rate
    error = np.abs(samples[:, 0] - signal_at(grid))
    # Where the file's samples are regular (jitter only) the grid holds the tones; in a gap it
    # holds no vibration that was there (a spline across one missing sample, a straight line
    # across more: never more than the samples either side), which is why the share is
    # reported and limited.
    steps = np.diff(times)
    after = np.clip(np.searchsorted(times, grid), 2, len(steps) - 2)
    regular = np.all([steps[after + d] < 1.5 / RATE for d in (-2, -1, 0, 1)], axis=0)
    assert regular.mean() > 0.9 and np.max(error[regular]) < 0.2  # of a peak of 2
    burst = steps[after - 1] > 2.5 / RATE
    assert np.max(np.abs(samples[burst, 0])) <= np.max(np.abs(signal_at(times)))
    spectrum = np.abs(np.fft.rfft(samples[:, 0] * np.hanning(len(samples))))
    freqs = np.fft.rfftfreq(len(samples), 1 / report.rate)
    for tone in TONES:
        band = np.abs(freqs - tone) < 5
        assert freqs[band][np.argmax(spectrum[band])] == pytest.approx(tone, abs=0.2)
    assert f"{missing} missing sample(s) interpolated" in str(report)


def test_a_given_rate_and_the_limit():
    times = phone_times(6.0, dropped=0, burst=40)
    values = signal_at(times)[:, None]
    samples, report = place_on_grid(times, values, rate=400.0)
    assert report.rate == 400.0 and len(samples) == report.frames
    with pytest.raises(RealPenError, match=r"^phone.csv: 1\.67 % of the samples are missing "
                                           r"\(40 of 2,400; the longest gap 102\.\d ms after "
                                           r".*over the limit of 1 %"):
        place_on_grid(times, values, max_interpolated_pct=1, source="phone.csv")
    with pytest.raises(ParameterError, match="^even_grid: 300 Hz is below"):
        place_on_grid(times, values, rate=300.0, source="phone.csv")


def test_loading_refuses_a_gap_naming_the_option_and_fills_it_when_asked(tmp_path):
    path = tmp_path / "phone.csv"
    write_phone_csv(path, phone_times(6.0, dropped=20, burst=12))
    with pytest.raises(ParameterError, match=r"^even_grid: needed: .*phone.csv: time column "
                                             r"'timestamp' has a gap of") as caught:
        rp.load_recording(path)
    assert caught.value.parameter == "even_grid"
    with pytest.raises(ParameterError, match="^even_grid: needed"):  # streamed alike
        list(open_stream(path).iter_blocks(1024))
    recording = rp.load_recording(path, even_grid="median")
    assert recording.axes == ("x", "y", "z") and recording.rate == pytest.approx(RATE, rel=0.002)
    assert recording.history[-1].startswith("put on an even grid at")
    assert "32 missing sample(s)" in recording.history[-1]
    assert rp.load_recording(path, even_grid=400).rate == 400.0
    with pytest.raises(RealPenError, match="over the limit of 0.5 %"):
        rp.load_recording(path, even_grid=True, max_interpolated_pct=0.5)


def test_the_option_is_only_for_a_csv_with_times(tmp_path):
    wav = tmp_path / "rec.wav"
    sf.write(wav, np.zeros((1000, 1)), 1344)
    with pytest.raises(ParameterError, match="^even_grid: applies to a CSV with a time column"):
        rp.load_recording(wav, even_grid=True)
    untimed = tmp_path / "untimed.csv"
    untimed.write_text("x\n" + "0.5\n" * 300)
    with pytest.raises(ParameterError, match="has none"):
        rp.load_recording(untimed, rate=400, even_grid=True)
    with pytest.raises(ParameterError, match="^even_grid: must be 'median' or a rate"):
        rp.load_recording(untimed, even_grid="fast")


def test_the_command_line(tmp_path):
    path = tmp_path / "phone.csv"
    write_phone_csv(path, phone_times(6.0, dropped=20, burst=12))
    refused = run_cli("analyze", path)
    assert_clean_failure(refused, "--even-grid: needed: ")
    done = run_cli("analyze", path, "--even-grid", "median")
    assert done.returncode == 0, done.stderr
    text = " ".join(done.stdout.split())
    assert "put on an even grid at" in text and "32 missing sample(s) interpolated" in text
    over = run_cli("tactile", path, "--even-grid", "median", "--max-interpolated", "0.5",
                   "-o", tmp_path / "p.wav")
    assert_clean_failure(over, "over the limit of 0.5 %")
    assert not (tmp_path / "p.wav").exists()
