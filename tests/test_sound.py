"""Loop-unit search, crossfade, seam report, loading and granular synthesis."""

from __future__ import annotations

import inspect
import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
import soundfile as sf
from conftest import LMT_DIR
from scipy import signal

import realpen
from realpen.errors import ParameterError, RealPenError
from realpen.io.files import read_smpl_loop
from realpen.io.recording import Recording
from realpen.io.strokes import SAMPLE_FIELDS, StrokeSample
from realpen.motion.control import control_signals
from realpen.motion.coupling import Coupling
from realpen.motion.trajectory import Trajectory, load_trajectory
from realpen.sound.granular import granular, granular_loop, steady_part
from realpen.sound.loop import (
    SoundLoop,
    crossfade_gains,
    find_loop,
    find_loop_unit,
    level_db,
    load_sound,
    make_loop,
    scan_windows,
    seam_report,
)
from realpen.sound.stroke import render_stroke

RATE = 48000
UNIT = 14400   # 300 ms
FADE = 480     # 10 ms
EDGE = 960     # 20 ms
LMT = LMT_DIR  # ../shared/data/lmt108_sound: read in place, never copied into the repo


def noise(seconds: float, seed: int, rms: float = 0.1) -> np.ndarray:
    return np.random.default_rng(seed).standard_normal(int(seconds * RATE)) * rms


def lowpassed(seconds: float, seed: int, cutoff: float = 2000.0, rms: float = 0.1) -> np.ndarray:
    b, a = signal.butter(4, cutoff, fs=RATE)
    x = signal.lfilter(b, a, noise(seconds, seed))
    return x * rms / x.std()


def spectral_centroid(x: np.ndarray) -> float:
    freqs, power = signal.welch(x, RATE, nperseg=2048)
    return float(np.sum(freqs * power) / np.sum(power))


# --- synthetic signals with a known discontinuity ---------------------------------------------

AT = int(1.4 * RATE)  # where the discontinuity is


def with_discontinuity(kind: str, seed: int) -> np.ndarray:
    x = noise(3.0, seed)
    if kind == "level step":
        x[AT:] *= 10 ** (-12 / 20)
    elif kind == "spectrum change":
        x[AT:] = lowpassed(3.0, seed + 100)[AT:]
    elif kind == "click":
        x[AT:AT + 48] *= 10
    elif kind == "dropout":
        x[AT:AT + EDGE] = 0.0
    elif kind == "looped noise, gain step":
        x = np.tile(noise(0.3, seed + 7), 10)
        x[AT:] *= 10 ** (6 / 20)
    return x


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("kind", ["level step", "spectrum change", "click", "dropout",
                                  "looped noise, gain step"])
def test_discontinuity_is_rejected_for_a_clean_window(kind, seed):
    x = with_discontinuity(kind, seed)
    unit = find_loop_unit(x, RATE)
    start = int(round(unit.start_s * RATE))
    read = range(start, start + UNIT + FADE)  # everything the loop is made from
    assert AT not in read and AT + EDGE not in read, f"unit at {unit.start_s} s holds the {kind}"
    scan = scan_windows(x, RATE)
    straddling = (scan.starts <= AT) & (scan.starts + UNIT + FADE > AT)
    assert scan.cost[straddling].min() > unit.scores["cost"]
    assert unit.seam.level_jump_db < 0.5


def test_level_step_windows_score_a_large_level_jump():
    x = with_discontinuity("level step", 0)
    scan = scan_windows(x, RATE)
    # head before the step, tail and continuation after it. The head's first 10 ms blend the
    # two (equal power: the mean of both powers), its last 10 ms are the head's own level.
    across = (scan.starts + EDGE < AT) & (scan.starts + UNIT - EDGE > AT)
    clean = scan.starts + UNIT + FADE < AT
    quiet = 10 ** (-12 / 10)
    expected = 12 + 10 * np.log10((1 + (1 + quiet) / 2) / 2)
    assert np.median(scan.level_jump_db[across]) == pytest.approx(expected, abs=0.5)
    assert np.median(scan.level_jump_db[clean]) < 0.5


@pytest.mark.parametrize("frequency", [440.0, 443.0, 1000.0, 3100.3])
def test_stationary_tone_loops_with_small_level_jump(frequency):
    x = 0.3 * np.sin(2 * np.pi * frequency * np.arange(2 * RATE) / RATE)
    unit = find_loop_unit(x, RATE)
    assert unit.seam.level_jump_db < 0.5
    assert len(unit.samples) == UNIT
    # the whole loop keeps the tone's level: no dip or bump anywhere, the crossfade included
    levels = [level_db(unit.samples[i:i + EDGE]) for i in range(0, UNIT - EDGE, 240)]
    assert max(levels) - min(levels) < 0.5


def test_plain_sin_cos_crossfade_bumps_a_tone_that_compensation_fixes():
    x = 0.3 * np.sin(2 * np.pi * 440.0 * np.arange(2 * RATE) / RATE)  # 132 cycles per unit
    plain = find_loop_unit(x, RATE, compensate=False)
    fixed = find_loop_unit(x, RATE)
    assert plain.seam.level_jump_db > 1.0
    assert fixed.seam.level_jump_db < 0.1
    assert fixed.correlation == pytest.approx(1.0, abs=1e-6)


def test_crossfade_gains_keep_power_for_any_correlation():
    fade_in, fade_out = crossfade_gains(480, 0.0)
    np.testing.assert_allclose(fade_in ** 2 + fade_out ** 2, 1.0, atol=1e-12)
    fade_in, fade_out = crossfade_gains(480, 1.0)
    np.testing.assert_allclose(fade_in + fade_out, 1.0, atol=1e-12)
    for rho in (-0.3, 0.4, 0.8):
        fade_in, fade_out = crossfade_gains(480, rho)
        power = fade_in ** 2 + fade_out ** 2 + 2 * rho * fade_in * fade_out
        np.testing.assert_allclose(power, 1.0, atol=1e-12)
    assert np.all(np.diff(fade_in) > 0) and np.all(np.diff(fade_out) < 0)


def test_unit_is_cut_where_start_s_says_and_wraps_into_the_continuation():
    x = noise(2.0, 3)
    unit = find_loop_unit(x, RATE)
    start = int(round(unit.start_s * RATE))
    assert start % 240 == 0  # on the 5 ms scan grid
    np.testing.assert_array_equal(unit.samples[FADE:], x[start + FADE:start + UNIT])
    # right after the wrap the loop plays what followed the tail in the recording
    assert abs(unit.samples[0] - x[start + UNIT]) < 0.01 * np.abs(x).max()
    again, rho = make_loop(x, start, UNIT, FADE)
    np.testing.assert_array_equal(again, unit.samples)
    assert rho == pytest.approx(unit.correlation)


def test_scan_scores_what_the_seam_report_measures():
    x = lowpassed(3.0, 5) * np.repeat(np.random.default_rng(5).uniform(0.5, 1.5, 30), RATE // 10)
    unit = find_loop_unit(x, RATE)
    assert unit.scores["level_jump_db"] == pytest.approx(unit.seam.level_jump_db, abs=1e-9)
    assert set(unit.scores) == {"level_jump_db", "spectral_db", "stationarity_db",
                                "quietness_db", "cost"}
    weighted = sum(unit.weights[k] * unit.scores[k] for k in unit.weights)
    assert unit.scores["cost"] == pytest.approx(weighted)


def test_seam_report_flags_a_bad_splice():
    x = noise(0.3, 9)
    clean = seam_report(np.tile(x, 1), RATE)  # a cut of stationary noise: any wrap is ordinary
    spliced = x.copy()
    spliced[-EDGE:] *= 10 ** (-15 / 20)  # the last 20 ms drop by 15 dB: a jump at the wrap
    bad = seam_report(spliced, RATE)
    assert bad.level_jump_db == pytest.approx(15.0, abs=0.5)
    assert bad.flux_wrap_db > bad.flux_inside_p95_db
    assert clean.level_jump_db < 1.0
    assert bad.pairs == clean.pairs == (UNIT - 2 * EDGE) // 240 + 1


def test_near_silence_is_not_chosen():
    x = noise(3.0, 4, rms=0.1)
    x[: 2 * RATE] *= 10 ** (-50 / 20)  # two quiet seconds, then one loud one
    scan = scan_windows(x, RATE)
    unit = find_loop_unit(x, RATE)
    assert unit.start_s >= 2.0
    assert scan.rejected.sum() > 0
    assert unit.rejected == int(scan.rejected.sum())


def test_silence_and_short_recordings_are_refused():
    with pytest.raises(RealPenError, match="take.wav: recording is silent"):
        find_loop_unit(np.zeros(RATE), RATE, source="take.wav")
    with pytest.raises(RealPenError, match="short.wav: recording lasts 200 ms, shorter than the "
                                           "300 ms unit"):
        find_loop_unit(noise(0.2, 0), RATE, source="short.wav")
    with pytest.raises(ParameterError, match="^crossfade_ms: ") as caught:
        find_loop_unit(noise(1.0, 0), RATE, crossfade_ms=300)
    assert caught.value.parameter == "crossfade_ms"
    with pytest.raises(ParameterError, match="^unit_ms: "):
        find_loop_unit(noise(1.0, 0), RATE, unit_ms=float("nan"))


def test_scan_scores_every_window_on_the_5_ms_grid():
    # Speed is measured by benchmarks/bench_sound.py, not asserted here: wall-clock limits
    # flake on slow shared machines.
    x = noise(4.8, 11)
    scan = scan_windows(x, RATE, hop_ms=5.0)
    assert len(scan.starts) == (len(x) - UNIT - FADE) // 240 + 1
    np.testing.assert_array_equal(np.diff(scan.starts), 240)
    assert np.all(np.isfinite(scan.cost))


def test_scan_reports_progress_to_the_end():
    x = noise(20.0, 12)
    calls = []
    find_loop_unit(x, RATE, progress=lambda done, total: calls.append((done, total)))
    windows = (len(x) - UNIT - FADE) // 240 + 1
    assert len(calls) >= 2 and calls[-1] == (windows, windows)
    assert [done for done, _ in calls] == sorted(done for done, _ in calls)


# --- loading ----------------------------------------------------------------------------------

@pytest.mark.parametrize("suffix,subtype", [(".wav", "PCM_16"), (".flac", "PCM_24"),
                                            (".ogg", "VORBIS")])
def test_load_sound_mixes_down_and_resamples(tmp_path, suffix, subtype):
    left = lowpassed(1.0, 1) * 0.5
    path = tmp_path / f"take{suffix}"
    sf.write(path, np.column_stack([left, left]), 44100, subtype=subtype)
    sound = load_sound(path)
    assert sound.rate == 48000
    assert sound.axes == ("mono",)
    assert abs(len(sound.mono) - len(left) * 48000 / 44100) <= 2
    assert level_db(sound.mono) == pytest.approx(level_db(left), abs=0.5)
    assert any(step.startswith("mixdown:2ch") for step in sound.history)
    assert load_sound(path, rate=None).rate == 44100


def test_load_sound_mixdown_is_the_mean_of_the_channels(tmp_path):
    left, right = noise(0.5, 1), noise(0.5, 2)
    path = tmp_path / "stereo.wav"
    sf.write(path, np.column_stack([left, right]), 48000, subtype="FLOAT")
    np.testing.assert_allclose(load_sound(path).mono, (left + right) / 2, atol=1e-7)


def test_load_sound_refuses_bad_files(tmp_path):
    empty = tmp_path / "empty.wav"
    empty.write_bytes(b"")
    text = tmp_path / "notes.wav"
    text.write_text("not audio\n")
    silent = tmp_path / "silent.wav"
    sf.write(silent, np.zeros(RATE), RATE)
    nan = tmp_path / "nan.wav"
    x = noise(0.5, 0)
    x[100] = np.nan
    sf.write(nan, x, RATE, subtype="FLOAT")
    table = tmp_path / "stroke.csv"
    table.write_text("t,x,y,pressure\n0,0,0,1\n")
    whole = tmp_path / "whole.wav"
    sf.write(whole, noise(1.0, 0), RATE)
    cut = tmp_path / "cut.wav"
    cut.write_bytes(whole.read_bytes()[:30000])
    for path in (tmp_path / "missing.wav", empty, text, silent, nan, table, cut):
        with pytest.raises(RealPenError) as caught:
            load_sound(path)
        message = str(caught.value)
        assert message.startswith(str(path)) and "\n" not in message


# --- granular ---------------------------------------------------------------------------------

def test_steady_part_leaves_out_bursts_and_quiet_stretches():
    x = noise(3.0, 2)
    burst = slice(int(1.0 * RATE), int(1.3 * RATE))
    x[burst] *= 10          # +20 dB
    x[int(2.0 * RATE):int(2.4 * RATE)] *= 0.01  # −40 dB
    span = 2402
    part = steady_part(x, RATE, span * 1000 / RATE)
    ends = part.starts + part.span
    for low, high in ((1.0, 1.3), (2.0, 2.4)):
        lo, hi = int(low * RATE), int(high * RATE)
        assert not np.any((part.starts < hi) & (ends > lo)), f"grains read {low}–{high} s"
    assert part.rms == pytest.approx(0.1, rel=0.1)
    assert len(part.starts) > 100


def test_granular_texture_is_steady_and_seamless():
    x = lowpassed(3.0, 6)
    texture = granular_loop(x, RATE, length_ms=2000, seed=1)
    assert len(texture.samples) == 2 * RATE
    assert level_db(texture.samples) == pytest.approx(-20.0, abs=1.0)
    levels = [level_db(texture.samples[i:i + 4800]) for i in range(0, 2 * RATE, 4800)]
    assert np.std(levels) < 1.0
    assert texture.seam.pairs > 300


def test_granular_texture_wraps_without_a_splice():
    # Low-passed noise barely moves from one sample to the next; a splice of two unrelated
    # stretches jumps. Over many seeds the step across the wrap of a circular texture must be
    # as small as any other step, and the step of a texture that is merely cut is not.
    x = lowpassed(3.0, 15, cutoff=1000)
    part = steady_part(x, RATE, 2402 * 1000 / RATE)

    def wrap_step_ratio(circular: bool) -> float:
        ratios = []
        for seed in range(30):
            y = granular(x, RATE, RATE, part, seed=seed, circular=circular)
            typical = np.mean(np.diff(y) ** 2)
            ratios.append((y[0] - y[-1]) ** 2 / typical)
        return float(np.mean(ratios))

    assert wrap_step_ratio(circular=True) < 2.0
    assert wrap_step_ratio(circular=False) > 20.0


def test_granular_does_not_repeat_like_a_loop():
    x = lowpassed(3.0, 7)
    texture = granular_loop(x, RATE, length_ms=1200, seed=2).samples
    loop = np.tile(find_loop_unit(x, RATE).samples, 4)
    period = UNIT

    def repetition(y):
        a, b = y[:len(y) - period], y[period:]
        return float(np.dot(a, b) / np.sqrt(np.dot(a, a) * np.dot(b, b)))

    assert repetition(loop) > 0.99
    assert abs(repetition(texture)) < 0.2


def test_playback_rate_makes_grains_brighter():
    x = lowpassed(3.0, 8, cutoff=3000)
    part = steady_part(x, RATE, 2 * 2400 * 1000 / RATE)
    slow = granular(x, RATE, RATE, part, playback_rate=np.full(RATE, 0.8))
    fast = granular(x, RATE, RATE, part, playback_rate=np.full(RATE, 1.25))
    ratio = spectral_centroid(fast) / spectral_centroid(slow)
    assert ratio == pytest.approx(1.25 / 0.8, rel=0.1)


# --- real recordings (LMT-108) ----------------------------------------------------------------

def lmt_files() -> list[Path]:
    return sorted(LMT.glob("*.wav")) if LMT.is_dir() else []


@pytest.mark.skipif(not lmt_files(), reason=f"LMT-108 sound folder absent ({LMT}); it is read "
                                            "from ../shared/data, never copied into the repo")
@pytest.mark.parametrize("path", lmt_files(), ids=lambda p: p.stem)
def test_lmt108_unit_loops_seamlessly(path):
    sound = load_sound(path)
    unit = find_loop_unit(sound.mono, sound.rate, source=path)
    assert len(unit.samples) == UNIT
    assert 0 <= unit.start_s <= len(sound.mono) / RATE - 0.31
    assert unit.seam.level_jump_db < 1.0
    assert unit.seam.flux_wrap_db <= unit.seam.flux_inside_p95_db


@pytest.mark.skipif(not (LMT / "G8RoughPaper_Sound_Movement_train1.wav").exists(),
                    reason=f"LMT-108 Rough Paper recording absent from {LMT}")
def test_lmt108_rough_paper_granular_texture():
    sound = load_sound(LMT / "G8RoughPaper_Sound_Movement_train1.wav")
    texture = granular_loop(sound.mono, sound.rate, seed=0)
    assert len(texture.samples) == 3 * RATE
    assert sum(b - a for a, b in texture.part.stretches) / RATE > 1.0
    levels = [level_db(texture.samples[i:i + 4800]) for i in range(0, 3 * RATE, 4800)]
    assert np.std(levels) < 1.5
    assert level_db(texture.samples) == pytest.approx(-20.0, abs=1.5)


# --- rendering a stroke -----------------------------------------------------------------------

# (start s, end s, speed mm/s, pressure): slow and light, fast and hard, lifted, ordinary
SEGMENTS = [(0.0, 0.5, 20.0, 0.3), (0.5, 1.0, 120.0, 0.8), (1.0, 1.3, 0.0, 0.0),
            (1.3, 1.8, 50.0, 0.5)]


def stroke(event_rate: float = 200.0) -> Trajectory:
    t = np.arange(0, 1.8, 1 / event_rate)
    speed = np.select([(t >= a) & (t < b) for a, b, _, _ in SEGMENTS], [s[2] for s in SEGMENTS])
    pressure = np.select([(t >= a) & (t < b) for a, b, _, _ in SEGMENTS],
                         [s[3] for s in SEGMENTS])
    x = np.cumsum(speed / event_rate) * np.cos(0.3)
    y = np.cumsum(speed / event_rate) * np.sin(0.3)
    return Trajectory.checked(t, x, y, pressure)


def segment(samples: np.ndarray, low: float, high: float) -> np.ndarray:
    return samples[int(low * RATE):int(high * RATE)]


@pytest.mark.parametrize("mode", ["loop", "granular"])
def test_rendered_stroke_is_louder_faster_and_harder_and_silent_when_lifted(mode):
    recording = lowpassed(3.0, 12, cutoff=4000)
    rendered = render_stroke(recording, RATE, stroke(), Coupling(), mode)
    out = rendered.samples
    slow, fast, lifted, ordinary = (segment(out, a + 0.05, b) for a, b, _, _ in SEGMENTS)
    assert level_db(fast) > level_db(ordinary) + 3 > level_db(slow) + 6
    # gain 1 plays at −20 dBFS, so each stretch sits at −20 dB + 20·log10(Eq. 1)
    coupling = Coupling()
    for part, (_, _, speed, pressure) in zip((slow, fast, ordinary), SEGMENTS[:2] + SEGMENTS[3:]):
        expected = -20 + 20 * np.log10(float(coupling.gain_raw(pressure, speed)))
        assert level_db(part) == pytest.approx(expected, abs=1.5)
    assert np.max(np.abs(lifted)) < 1e-3 * np.max(np.abs(fast))
    assert np.all(rendered.target_gain[int(1.0 * RATE) + 1:int(1.3 * RATE)] == 0)


@pytest.mark.parametrize("mode", ["loop", "granular"])
def test_faster_strokes_sound_brighter_through_the_playback_rate(mode):
    recording = lowpassed(3.0, 13, cutoff=3000)
    brighter = render_stroke(recording, RATE, stroke(), Coupling(), mode).samples
    constant = render_stroke(recording, RATE, stroke(), Coupling(rate_exponent=0), mode).samples
    ratio = (spectral_centroid(segment(brighter, 0.6, 1.0))
             / spectral_centroid(segment(brighter, 0.1, 0.5)))
    assert ratio == pytest.approx((120 / 50) ** 0.25 / 0.8, rel=0.1)  # 0.8 = rate_min at 20 mm/s
    flat = (spectral_centroid(segment(constant, 0.6, 1.0))
            / spectral_centroid(segment(constant, 0.1, 0.5)))
    assert flat == pytest.approx(1.0, abs=0.05)


def test_control_signals_follow_eq1_per_event_then_smooth():
    trajectory = stroke()
    coupling = Coupling()
    target, gain, playback = control_signals(trajectory, coupling, RATE)
    events = np.round((trajectory.t - trajectory.t[0]) * RATE).astype(int)
    np.testing.assert_allclose(target[events],
                               coupling.gain_raw(trajectory.pressure, trajectory.speed()))
    np.testing.assert_allclose(gain, coupling.smooth(target, RATE))
    tail = int(np.ceil(5 * coupling.smoothing_ms / 1000 * RATE))
    assert len(gain) == int(np.floor(trajectory.duration_s * RATE)) + 1 + tail
    assert gain[-1] < 0.01 * gain.max()
    assert playback.min() >= coupling.rate_min and playback.max() <= coupling.rate_max


def test_speed_is_causal_and_zero_at_touch_down():
    trajectory = Trajectory.checked([0, 0.1, 0.2, 0.3, 0.4], [0, 3, 7, 7, 10], [0, 4, 4, 4, 0],
                                    [0.5, 0.5, 0.5, 0.0, 0.5])
    np.testing.assert_allclose(trajectory.speed(), [0, 50, 40, 0, 0])


def test_render_uses_a_ready_loop_as_is():
    loop = find_loop_unit(lowpassed(3.0, 14), RATE).samples
    rendered = render_stroke(loop, RATE, stroke(), Coupling(rate_exponent=0), find_unit=False)
    assert rendered.unit is None
    begin = int(0.6 * RATE)
    steady = rendered.samples[begin:begin + UNIT]
    gain = float(Coupling().gain_raw(0.8, 120.0))
    level = 10 ** (-20 / 20) / np.sqrt(np.mean(loop ** 2))
    expected = np.roll(loop, -begin % UNIT) * level
    np.testing.assert_allclose(steady, gain * expected, rtol=1e-6, atol=1e-9)


def test_load_trajectory_validates(tmp_path):
    good = tmp_path / "stroke.csv"
    good.write_text("pressure,t,x,y\n0.5,0,0,0\n0.6,0.01,1,0\n")
    trajectory = load_trajectory(good)
    np.testing.assert_array_equal(trajectory.t, [0, 0.01])
    np.testing.assert_allclose(trajectory.speed(), [0, 100])
    cases = {"t,x,y\n0,0,0\n0.1,1,1\n": "missing pressure",
             "t,x,y,pressure\n0,0,0,0.5\n": "at least 2 data row",
             "t,x,y,pressure\n0,0,0,0.5\n0,1,0,0.5\n": "t must increase strictly",
             "t,x,y,pressure\n0,0,0,0.5\n0.1,1,0,1.2\n": "pressure 1.2 must be between 0 and 1",
             "t,x,y,pressure\n0,0,0,0.5\n0.1,nan,0,0.5\n": "NaN or infinite",
             "t,x,y,pressure\n0,0,0,0.5\n0.1,1,0\n": "3 values for the 4 columns",
             "t,x,y,pressure\n0,0,0,0.5\n0.1,1,0,hard\n": "'hard' in column 'pressure'",
             "t,x,y,pressure\n0,0,0,0.5\n1000,1,0,0.5\n": "t must be in seconds"}
    for content, problem in cases.items():
        bad = tmp_path / "bad.csv"
        bad.write_text(content)
        with pytest.raises(RealPenError, match=problem) as caught:
            load_trajectory(bad)
        assert str(caught.value).startswith(str(bad))


# --- limits on what the sound side takes (one-line errors, never NaN or absurd output) --------

@pytest.mark.parametrize("level", [float("nan"), float("inf"), 300.0, 0.5])
def test_level_must_be_finite_and_at_most_0_dbfs_everywhere(level):
    x = lowpassed(3.0, 20, cutoff=4000)
    with pytest.raises(ParameterError, match="^level_dbfs: must be a finite level of at most 0"):
        find_loop_unit(x, RATE).normalised(level)
    with pytest.raises(ParameterError, match="^level_dbfs: "):
        granular_loop(x, RATE, length_ms=1000, level_dbfs=level)
    with pytest.raises(ParameterError, match="^level_dbfs: "):
        find_loop(x, rate=RATE, level_dbfs=level)
    for mode in ("loop", "granular"):
        with pytest.raises(ParameterError, match="^level_dbfs: "):
            render_stroke(x, RATE, stroke(), Coupling(), mode, level_dbfs=level)


def test_level_of_0_dbfs_is_accepted():
    x = lowpassed(3.0, 20, cutoff=4000)
    assert level_db(find_loop_unit(x, RATE).normalised(0.0).samples) == pytest.approx(0.0)
    rendered = render_stroke(x, RATE, stroke(), Coupling(), "granular", level_dbfs=0.0)
    assert np.all(np.isfinite(rendered.samples))


def test_a_rate_too_low_for_the_bands_is_refused_naming_the_minimum(tmp_path):
    path = tmp_path / "take.wav"
    sf.write(path, noise(1.0, 21), RATE)
    for rate in (100.0, 222.0, 7999.0):
        with pytest.raises(ParameterError, match=r"^rate: .* too low .* minimum is 8000 Hz"):
            load_sound(path, rate=rate)
    low = tmp_path / "low.wav"
    sf.write(low, np.random.default_rng(0).standard_normal(4000) * 0.1, 4000)
    with pytest.raises(RealPenError, match=r"low.wav: 4000 Hz is too low"):
        load_sound(low, rate=None)
    x = noise(2.0, 22)[::480]  # 2 s at 100 Hz
    for call in (lambda: find_loop_unit(x, 100), lambda: seam_report(x, 100),
                 lambda: granular_loop(x, 100, length_ms=1000),
                 lambda: render_stroke(x, 100, stroke()),
                 lambda: render_stroke(x, 100, stroke(), mode="granular")):
        with pytest.raises(RealPenError, match="minimum is 8000 Hz"):
            call()
    assert load_sound(path, rate=8000).rate == 8000


def test_constant_input_is_refused_as_silence(tmp_path):
    for value in (0.5, -0.25):
        with pytest.raises(RealPenError, match=r"take.wav: recording is silent \(a constant"):
            find_loop_unit(np.full(RATE, value), RATE, source="take.wav")
        with pytest.raises(RealPenError, match="recording is silent"):
            render_stroke(np.full(RATE, value), RATE, stroke(), source="take.wav")
        with pytest.raises(RealPenError, match="recording is silent"):
            granular_loop(np.full(3 * RATE, value), RATE, source="take.wav")
    path = tmp_path / "dc.wav"
    sf.write(path, np.full(44100, 0.5), 44100, subtype="PCM_16")  # resampling rings at the ends
    with pytest.raises(RealPenError, match=r"dc.wav: recording is silent \(a constant value"):
        load_sound(path)
    # a DC offset under real sound is not silence
    assert find_loop_unit(0.3 + noise(1.0, 23), RATE).seam.level_jump_db < 1.0


@pytest.mark.parametrize("kwargs", [
    {"unit_ms": float("nan")}, {"unit_ms": float("inf")}, {"unit_ms": 0.0}, {"unit_ms": -300.0},
    {"crossfade_ms": float("nan")}, {"crossfade_ms": 0.0}, {"crossfade_ms": -1.0},
    {"grain_ms": float("nan")}, {"grain_ms": 0.0}])
def test_lengths_must_be_finite_and_positive_everywhere(kwargs):
    (name,) = kwargs
    x = lowpassed(3.0, 24)
    for mode in ("loop", "granular"):
        with pytest.raises(ParameterError, match=f"^{name}: ") as caught:
            render_stroke(x, RATE, stroke(), Coupling(), mode, **kwargs)
        assert caught.value.parameter == name and "--" not in str(caught.value)
        with pytest.raises(ParameterError, match=f"^{name}: "):
            render_stroke(x, RATE, stroke(), Coupling(), mode, find_unit=False, **kwargs)
    if "grain_ms" in kwargs:
        with pytest.raises(ParameterError, match=f"^{name}: "):
            granular_loop(x, RATE, **kwargs)
    else:
        with pytest.raises(ParameterError, match=f"^{name}: "):
            find_loop_unit(x, RATE, **kwargs)
        with pytest.raises(ParameterError, match=f"^{name}: "):
            find_loop(x, rate=RATE, **kwargs)


def test_render_searches_a_short_recording_only_when_not_told_it_is_a_loop():
    short = lowpassed(0.5, 25)  # longer than the unit, shorter than two units
    with pytest.raises(ParameterError, match=r"^find_unit: take.wav lasts 200 ms, shorter than "
                                             r"the 300 ms unit plus the 10 ms crossfade"):
        render_stroke(short[:int(0.2 * RATE)], RATE, stroke(), source="take.wav")
    searched = render_stroke(short, RATE, stroke())  # no longer played as a loop by length
    assert searched.unit is not None and len(searched.unit.samples) == UNIT
    as_is = render_stroke(short[:int(0.2 * RATE)], RATE, stroke(), find_unit=False)
    assert as_is.unit is None and np.all(np.isfinite(as_is.samples))


@pytest.mark.parametrize("length_ms", [60001.0, 1e9, float("inf")])
def test_granular_texture_length_is_bounded_to_60_s(length_ms):
    with pytest.raises(ParameterError, match=r"^length_ms: must be at most 60000 ms \(60 s\)"
                       if np.isfinite(length_ms) else "^length_ms: "):
        granular_loop(lowpassed(3.0, 26), RATE, length_ms=length_ms)


# --- speed: the live page's 20 ms window ------------------------------------------------------

def page_speed(t, x, y, pressure, window: float = 0.020) -> np.ndarray:
    """pen.js SpeedMeter, line by line; the meter restarts at each touch-down, 0 when lifted."""
    speeds, points, speed, down = [], [], 0.0, False
    for ti, xi, yi, pi in zip(t, x, y, pressure):
        if pi <= 0:
            down = False
            speeds.append(0.0)
            continue
        if not down:  # pointerdown: meter.reset()
            points, speed, down = [], 0.0, True
        travelled = points[-1][3] + np.hypot(xi - points[-1][1], yi - points[-1][2]) \
            if points else 0.0
        points.append((ti, xi, yi, travelled))
        while len(points) > 2 and points[1][0] <= ti - window:
            points.pop(0)
        if ti - points[0][0] > 0:
            speed = (travelled - points[0][3]) / (ti - points[0][0])
        speeds.append(speed)
    return np.array(speeds)


def irregular_strokes(seed: int = 0) -> Trajectory:
    """Coalesced-looking events: 2–9 ms apart, jittery positions, two lifts."""
    rng = np.random.default_rng(seed)
    t = np.cumsum(rng.uniform(0.002, 0.009, 400))
    x = np.cumsum(rng.normal(0.3, 0.2, 400))
    y = np.cumsum(rng.normal(0.0, 0.2, 400))
    pressure = rng.uniform(0.2, 0.9, 400)
    pressure[120:140] = 0.0
    pressure[300:301] = 0.0
    return Trajectory.checked(t, x, y, pressure)


def test_speed_is_the_pages_path_length_over_the_last_20_ms():
    trajectory = irregular_strokes()
    expected = page_speed(trajectory.t, trajectory.x, trajectory.y, trajectory.pressure)
    np.testing.assert_allclose(trajectory.speed(), expected, rtol=1e-12, atol=1e-12)
    speed = trajectory.speed()
    assert speed[0] == speed[140] == speed[301] == 0  # touch-downs
    assert np.all(speed[120:140] == 0) and speed[300] == 0  # lifted
    # Events 1/128 s (7.8 ms) apart: the window reaches back three steps (23.4 ms), so one long
    # step of 1 mm among 0.1 mm steps is averaged over three steps, not seen alone (128 mm/s).
    t = np.arange(10) / 128
    x = np.cumsum([0, 0.1, 0.1, 0.1, 0.1, 1.0, 0.1, 0.1, 0.1, 0.1])
    steps = Trajectory.checked(t, x, np.zeros(10), np.full(10, 0.5)).speed()
    np.testing.assert_allclose(steps, [0, 12.8, 12.8, 12.8, 12.8, 51.2, 51.2, 51.2, 12.8, 12.8])


@pytest.mark.slow
@pytest.mark.skipif(shutil.which("node") is None, reason="node is not installed")
def test_speed_matches_pen_js_run_by_node(tmp_path):
    page = Path(realpen.__file__).parent / "live" / "static" / "pen.js"
    shutil.copy(page, tmp_path / "pen.mjs")
    trajectory = irregular_strokes(seed=3)
    (tmp_path / "run.mjs").write_text(
        "import { SpeedMeter } from './pen.mjs';\n"
        "import { readFileSync } from 'node:fs';\n"
        "const rows = JSON.parse(readFileSync(process.argv[2], 'utf8'));\n"
        "const meter = new SpeedMeter();\n"
        "let down = false;\n"
        "const out = rows.map(([t, x, y, p]) => {\n"
        "  if (!(p > 0)) { down = false; return 0; }\n"
        "  if (!down) { meter.reset(); down = true; }\n"
        "  return meter.push(t, x, y);\n"
        "});\n"
        "console.log(JSON.stringify(out));\n")
    rows = np.column_stack([trajectory.t, trajectory.x, trajectory.y, trajectory.pressure])
    (tmp_path / "rows.json").write_text(json.dumps(rows.tolist()))
    done = subprocess.run(["node", "run.mjs", "rows.json"], cwd=tmp_path, capture_output=True,
                          text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    np.testing.assert_allclose(trajectory.speed(), json.loads(done.stdout), rtol=1e-12,
                               atol=1e-12)


def test_trajectory_errors_name_the_file_line(tmp_path):
    cases = {"t,x,y,pressure\n\n0,0,0,0.5\n\n0.1,1,0,firm\n": "line 5: 'firm'",
             "\nt,x,y,pressure\n0,0,0,0.5\n\n\n0.1,1,0,1.5\n": "line 6: pressure 1.5",
             "t,x,y,pressure\n0,0,0,0.5\n\n0.2,1,0,0.5\n0.1,2,0,0.5\n":
                 r"line 5: t = 0.1 s comes after 0.2 s \(line 4\)",
             "t,x,y,pressure\n\n0,0,0,0.5\n0.1,1,0\n": "line 4: 3 values"}
    for content, problem in cases.items():
        path = tmp_path / "stroke.csv"
        path.write_text(content)
        with pytest.raises(RealPenError, match=problem) as caught:
            load_trajectory(path)
        assert "data row" not in str(caught.value)
    path.write_text("t,x,y,pressure\r\n0,0,0,0.5\r\n\r\n0.1,1,0,-1\r\n")
    with pytest.raises(RealPenError, match="line 4: pressure -1"):
        load_trajectory(path)


# --- documentation: every public function says the units of what it takes --------------------

UNIT_OF = {"rate": "Hz", "speed": "mm/s", "level_dbfs": "dBFS", "rms_dbfs": "dBFS",
           "tolerance_db": "dB", "window_ms": "ms"}


def public_callables():
    from realpen.io import csvtable
    from realpen.motion import control, coupling, trajectory
    from realpen.sound import granular, loop, stroke, unit
    for module in (unit, loop, granular, stroke, trajectory, control, coupling, csvtable):
        for name, item in vars(module).items():
            if name.startswith("_") or getattr(item, "__module__", None) != module.__name__:
                continue
            if inspect.isfunction(item):
                yield f"{module.__name__}.{name}", item
            elif inspect.isclass(item):
                for method_name, method in vars(item).items():
                    method = getattr(method, "__func__", method)
                    if inspect.isfunction(method) and not method_name.startswith("_"):
                        yield f"{module.__name__}.{name}.{method_name}", method


def test_public_functions_give_the_units_of_their_arguments():
    missing = []
    for where, function in public_callables():
        doc = inspect.getdoc(function) or ""
        for parameter in inspect.signature(function).parameters:
            unit = UNIT_OF.get(parameter, "ms" if parameter.endswith("_ms") else None)
            if unit is not None and unit not in doc:
                missing.append(f"{where}({parameter}): no '{unit}' in the docstring")
    assert not missing, "\n".join(missing)


# --- the one SoundLoop type -------------------------------------------------------------------

def test_find_loop_takes_an_array_a_recording_or_a_path_and_gives_a_sound_loop(tmp_path):
    x = lowpassed(2.0, 30)
    from_array = find_loop(x, rate=RATE)
    assert isinstance(from_array, SoundLoop) and from_array.mode == "loop"
    np.testing.assert_array_equal(from_array.samples, find_loop_unit(x, RATE).samples)
    stereo = Recording(np.column_stack([x, x]), RATE, ("left", "right"), source="take.wav")
    from_recording = find_loop(stereo)
    np.testing.assert_allclose(from_recording.samples, from_array.samples, atol=1e-12)
    assert from_recording.source == "take.wav" and "mixdown:2ch" in from_recording.history
    path = tmp_path / "take.wav"
    sf.write(path, x, RATE, subtype="FLOAT")
    from_path = find_loop(path, level_dbfs=-20.0)
    assert from_path.start_s == from_array.start_s
    assert from_path.rms_dbfs == pytest.approx(-20.0) and from_path.source == str(path)
    with pytest.raises(ParameterError, match="^rate: needed in Hz"):
        find_loop(x)
    with pytest.raises(TypeError):
        find_loop(x, RATE)  # options are keyword-only


def test_sound_loop_reports_its_making_in_one_line_and_in_json():
    x = lowpassed(3.0, 31)
    unit = find_loop(x, rate=RATE, source="pencil.wav").normalised()
    texture = granular_loop(x, RATE, length_ms=1000, seed=4)
    ready = SoundLoop.from_samples(unit.samples, RATE, source="loop.wav")
    for loop, mode in ((unit, "loop"), (texture, "granular"), (ready, "loop")):
        text = repr(loop)
        assert text.startswith("SoundLoop(") and "\n" not in text and len(text) < 200, text
        document = loop.to_json()
        json.dumps(document, allow_nan=False)
        assert document["mode"] == loop.mode == mode
        for key in ("rate", "frames", "length_ms", "start_s", "end_s", "seam", "gain",
                    "rms_dbfs"):
            assert key in document, (mode, key)
    assert unit.to_json()["scores"]["cost"] == pytest.approx(unit.scores["cost"], abs=1e-4)
    assert texture.to_json()["grain_ms"] == 50.0 and texture.part is not None
    assert ready.to_json()["scores"] is None and ready.seam is not None
    assert len(repr(unit.seam)) < 200 and len(repr(scan_windows(x, RATE))) < 200
    with pytest.raises(ParameterError, match="^mode: "):
        SoundLoop(samples=x, rate=RATE, mode="frozen")


def smpl_chunks(data: bytes) -> list[tuple[int, ...]]:
    """Every ``smpl`` chunk of a WAV, read here with struct, not with RealPen's reader:
    (manufacturer, product, period ns, unity note, pitch fraction, SMPTE format, SMPTE offset,
    loops, sampler data, then per loop: cue id, type, start, end, fraction, play count)."""
    import struct
    assert data[:4] == b"RIFF" and data[8:12] == b"WAVE"
    assert struct.unpack_from("<I", data, 4)[0] == len(data) - 8  # the RIFF size was updated
    found, position = [], 12
    while position + 8 <= len(data):
        name, length = struct.unpack_from("<4sI", data, position)
        if name == b"smpl":
            head = struct.unpack_from("<9I", data, position + 8)
            loops = [struct.unpack_from("<6I", data, position + 8 + 36 + 24 * k)
                     for k in range(head[7])]
            found.append(head + sum(loops, ()))
            assert length == 36 + 24 * head[7] + head[8]
        position += 8 + length + (length & 1)
    assert position == len(data)
    return found


def test_a_saved_loop_carries_a_standard_smpl_loop_and_loads_back_as_a_ready_loop(tmp_path):
    unit = find_loop(lowpassed(2.0, 32), rate=RATE).normalised()
    path = tmp_path / "loop.wav"
    unit.save(path)
    data = path.read_bytes()
    assert data == unit.wav_bytes() == unit.wav_bytes()  # deterministic
    assert smpl_chunks(data) == [(0, 0, 20833, 60, 0, 0, 0, 1, 0, 0, 0, 0, UNIT - 1, 0, 0)]
    assert read_smpl_loop(path) == read_smpl_loop(data) == (0, UNIT - 1)
    info = sf.info(path).extra_info  # libsndfile reads the same chunk
    assert "smpl" in info and "Loop Count   : 1" in info and f"End : {UNIT - 1}" in info
    samples, rate = sf.read(path, dtype="float32")
    np.testing.assert_array_equal(samples, unit.samples.astype(np.float32))
    loaded = load_sound(path)
    assert isinstance(loaded, SoundLoop) and loaded.rate == RATE
    np.testing.assert_array_equal(loaded.samples, unit.samples.astype(np.float32))
    assert loaded.source == str(path) and any("smpl-loop" in s for s in loaded.history)
    assert find_loop(path) is not None and find_loop(path).frames == UNIT  # already a loop
    # at another rate the loop is resampled circularly: its length scales, the wrap stays clean
    slower = load_sound(path, rate=44100)
    assert slower.frames == round(UNIT * 44100 / RATE) and slower.seam.level_jump_db < 1.0
    # a recording without the chunk is still a recording
    sf.write(tmp_path / "plain.wav", unit.samples, RATE, subtype="FLOAT")
    assert isinstance(load_sound(tmp_path / "plain.wav"), Recording)
    assert read_smpl_loop(tmp_path / "plain.wav") is None


def test_a_smpl_loop_inside_a_longer_file_is_cut_out(tmp_path):
    from realpen.io.files import add_smpl_loop, wav_bytes
    x = lowpassed(1.0, 33)
    path = tmp_path / "sampler.wav"
    path.write_bytes(add_smpl_loop(wav_bytes(x, RATE), start=4800, end=4800 + UNIT - 1))
    loaded = load_sound(path)
    np.testing.assert_array_equal(loaded.samples, x[4800:4800 + UNIT].astype(np.float32))
    assert loaded.start_s == pytest.approx(0.1)
    with pytest.raises(ParameterError, match="^end: "):
        add_smpl_loop(wav_bytes(x, RATE), end=len(x))


def test_render_plays_a_sound_loop_as_it_is():
    unit = find_loop(lowpassed(3.0, 14), rate=RATE)
    as_loop = render_stroke(unit, None, stroke(), Coupling(rate_exponent=0))
    as_samples = render_stroke(unit.samples, RATE, stroke(), Coupling(rate_exponent=0),
                               find_unit=False)
    np.testing.assert_array_equal(as_loop.samples, as_samples.samples)
    assert as_loop.unit is None and as_loop.loop is unit and len(repr(as_loop)) < 200
    with pytest.raises(ParameterError, match="^rate: "):
        render_stroke(unit, 44100, stroke())


# --- one stroke-sample definition ------------------------------------------------------------

def test_trajectory_converts_to_and_from_stroke_samples():
    trajectory = irregular_strokes(seed=5)
    samples = trajectory.to_samples()
    assert all(isinstance(sample, StrokeSample) for sample in samples)
    assert [sample.speed for sample in samples] == pytest.approx(trajectory.speed().tolist())
    again = Trajectory.from_samples(samples)
    for name in ("t", "x", "y", "pressure"):
        np.testing.assert_array_equal(getattr(again, name), getattr(trajectory, name))
    assert SAMPLE_FIELDS[:4] == ("t", "x", "y", "pressure")
    text = repr(trajectory)
    assert text.startswith("Trajectory(400 events") and len(text) < 200


def test_trajectory_takes_the_stroke_samples_ranges_and_tilt(tmp_path):
    path = tmp_path / "stroke.csv"
    path.write_text("t,x,y,pressure,tilt_x,tilt_y,note\n0,0,0,0.5,10,-5,a\n0.01,1,0,0.5,12,-5,b\n")
    trajectory = load_trajectory(path)
    np.testing.assert_array_equal(trajectory.tilt_x, [10, 12])
    assert trajectory.to_samples()[1].tilt_y == -5.0
    path.write_text("t,x,y,pressure,tilt_x\n0,0,0,0.5,10\n0.01,1,0,0.5,95\n")
    with pytest.raises(RealPenError, match="line 3: tilt_x = 95 degrees must be between -90"):
        load_trajectory(path)
    with pytest.raises(RealPenError, match="row 2: x = 2e\\+06 mm"):
        Trajectory.checked([0, 1], [0, 2e6], [0, 0], [0.5, 0.5])


# --- the one CSV reader -----------------------------------------------------------------------

def test_csv_reader_sniffs_semicolons_and_decimal_commas(tmp_path):
    from realpen.io.csvtable import read_csv
    path = tmp_path / "table.csv"
    path.write_text("\ufeffpressure;speed;amplitude\r\n0,5;10;0,2\r\n\r\n0,75;20,5;0,3\r\n")
    table = read_csv(path, ("speed", "pressure"))
    assert table.delimiter == ";" and table.decimal_comma
    assert table.column("Pressure").tolist() == [0.5, 0.75]
    assert table.columns["speed"].tolist() == [10.0, 20.5]
    assert table.lines.tolist() == [2, 4] and len(repr(table)) < 200
    path.write_text("50\t0.1\n100\t1\n")
    headerless = read_csv(path, header=None)
    assert headerless.header is None and headerless.values.tolist() == [[50, 0.1], [100, 1]]


@pytest.mark.parametrize("content,problem", [
    ("a,b\n1,2\n\n3,x\n", "line 4: 'x' in column 'b' is not a number"),
    ("a,b\n1,2\n3,inf\n", "line 3: column 'b' is inf (NaN or infinite)"),
    ("a;b\n1;2\n3\n", "line 3: 1 values for the 2 columns of the header"),
    ("1,2\n3,4\n", "line 1: CSV needs a header row naming its columns"),
    ("a,b\n", "CSV needs at least 1 data row(s), has 0"),
    ("\n \n", "file holds only blank lines"),
])
def test_csv_reader_names_the_file_and_line(tmp_path, content, problem):
    from realpen.io.csvtable import read_csv
    path = tmp_path / "table.csv"
    path.write_text(content)
    with pytest.raises(RealPenError) as caught:
        read_csv(path)
    assert str(caught.value) == f"{path}: {problem}" or (
        str(caught.value).startswith(f"{path}: ") and problem in str(caught.value))


# --- limits: lengths, seeds, smoothing and render size ------------------------------------------

@pytest.mark.parametrize("kwargs", [{"unit_ms": 60_001.0}, {"crossfade_ms": 1e12},
                                    {"grain_ms": 60_001.0}])
def test_lengths_are_at_most_a_minute_everywhere(kwargs):
    (name,) = kwargs
    x = lowpassed(1.0, 27)
    for mode in ("loop", "granular"):
        with pytest.raises(ParameterError, match=rf"^{name}: must be at most 60000 ms \(60 s\)"):
            render_stroke(x, RATE, stroke(), Coupling(), mode, **kwargs)
    call = granular_loop if "grain_ms" in kwargs else find_loop_unit
    with pytest.raises(ParameterError, match=rf"^{name}: must be at most 60000 ms"):
        call(x, RATE, **kwargs)


def test_a_unit_too_short_for_its_seam_measures_is_blamed_before_the_crossfade():
    with pytest.raises(ParameterError, match=r"^unit_ms: must be at least 60 ms"):
        find_loop_unit(lowpassed(1.0, 28), RATE, unit_ms=5.0)  # shorter than the 10 ms crossfade


@pytest.mark.parametrize("seed", [-1, 2 ** 63, 1.5, True])
def test_grain_seeds_are_whole_numbers_of_64_bits(seed):
    x = lowpassed(3.0, 29)
    with pytest.raises(ParameterError, match="^seed: must be a whole number from 0 to "
                                             "9223372036854775807"):
        granular_loop(x, RATE, length_ms=500, seed=seed)
    with pytest.raises(ParameterError, match="^seed: "):
        render_stroke(x, RATE, stroke(), mode="granular", seed=seed)


def test_a_render_longer_than_the_limit_is_refused_before_it_is_made(monkeypatch):
    import realpen.sound.stroke

    long = Trajectory.checked([0.0, 599.0], [0.0, 10.0], [0.0, 0.0], [0.5, 0.5])
    with pytest.raises(ParameterError, match=r"^rate: a 599 s stroke at 384000 Hz is "
                                             r"230,\d{3},\d{3} samples; a render holds at most "
                                             r"33,554,432"):
        render_stroke(lowpassed(1.0, 30), 384000, long)
    # The limit is the render's length: a lowered one refuses the ordinary 1.8 s stroke too.
    monkeypatch.setattr(realpen.sound.stroke, "MAX_RENDER_FRAMES", RATE)
    with pytest.raises(ParameterError, match="^rate: "):
        render_stroke(lowpassed(1.0, 30), RATE, stroke())


def test_smoothing_time_constant_is_bounded():
    from realpen.motion.coupling import MAX_SMOOTHING_MS

    assert Coupling(smoothing_ms=MAX_SMOOTHING_MS).smoothing_ms == MAX_SMOOTHING_MS
    with pytest.raises(RealPenError, match="c.json: smoothing_ms: "):
        Coupling.from_json({"smoothing_ms": MAX_SMOOTHING_MS * 1.001}, "c.json")


def test_grains_in_blocks_make_the_same_texture(monkeypatch):
    import realpen.sound.granular

    x = lowpassed(3.0, 31)
    whole = granular_loop(x, RATE, length_ms=1000).samples
    monkeypatch.setattr(realpen.sound.granular, "_BLOCK_VALUES", 5000)  # two 2400-sample grains
    np.testing.assert_allclose(granular_loop(x, RATE, length_ms=1000).samples, whole,
                               rtol=0, atol=1e-12)


def test_a_grain_too_long_for_any_texture_is_blamed_not_the_length():
    x = lowpassed(1.0, 32)
    with pytest.raises(ParameterError, match=r"^grain_ms: must be at most 30000 ms \(a texture "
                                             r"holds two grains"):
        granular_loop(x, RATE, grain_ms=40_000, length_ms=60_000)
    with pytest.raises(ParameterError, match=r"^length_ms: must be at least 200 ms \(two 100 ms "
                                             r"grains"):
        granular_loop(x, RATE, grain_ms=100, length_ms=150)
