"""Exports: WAV, C header, AHAP, .haptic, Android, .hjif — library and command line."""

from __future__ import annotations

import dataclasses
import io
import json
import re
import shutil
import struct
import subprocess

import numpy as np
import pytest
import soundfile as sf
from conftest import assert_clean_failure, run_cli
from scipy.signal import resample as fft_resample

from realpen.errors import ParameterError, RealPenError
from realpen.exports import (
    FORMATS,
    SUFFIXES,
    ahap,
    android,
    c_header,
    companion_paths,
    export,
    export_profile,
    format_for_suffix,
    profile_inputs,
    render,
    wav,
)
from realpen.exports import envelope as env
from realpen.exports.base import resample_loop
from realpen.io.files import read_smpl_loop
from realpen.profile.registry import resolve_profile
from realpen.tactile.pattern import TactilePattern

PENS = ("pencil", "ballpoint", "marker")
FRAME_S = 0.010


@pytest.fixture(scope="module")
def pens():
    return {name: resolve_profile(name) for name in PENS}


@pytest.fixture(scope="module")
def swept(pens):
    """A profile whose pattern has a strong, known envelope and centroid.

    Sub-pattern k (100 ms) is a sine at 60·(400/60)^(k/14) Hz; the level follows a raised
    cosine over the period from 0.2 to 1.
    """
    base = pens["pencil"]
    rate = base.meta.tactile.rate
    t = np.arange(len(base.tactile)) / rate
    period = len(t) / rate
    freqs = 60.0 * (400.0 / 60.0) ** (np.arange(15) / 14)
    level = 0.2 + 0.8 * 0.5 * (1 - np.cos(2 * np.pi * t / period))
    x = 0.9 * level * np.sin(2 * np.pi * freqs[(t // 0.1).astype(int)] * t)
    return dataclasses.replace(base, tactile=x.astype(np.float32)), freqs


def doc(fmt: str, item, **options) -> dict:
    """The JSON document of an export of a profile or a pattern."""
    return json.loads(render(fmt, item, **options).data)


def frame_rms(x: np.ndarray, rate: int) -> tuple[np.ndarray, np.ndarray]:
    """Independent measure: RMS of consecutive 10 ms frames and their centre times in s."""
    hop = int(round(FRAME_S * rate))
    frames = np.asarray(x, dtype=np.float64)[: len(x) // hop * hop].reshape(-1, hop)
    return np.sqrt((frames ** 2).mean(axis=1)), (np.arange(len(frames)) + 0.5) * hop / rate


def component_centroids(profile) -> np.ndarray:
    """Power-weighted centroid of each sub-pattern's components, from profile.json."""
    subpatterns = profile.meta.tactile.subpatterns
    return np.array([sum(c.amplitude ** 2 * c.frequency_hz for c in sub)
                     / sum(c.amplitude ** 2 for c in sub) for sub in subpatterns])


def subpattern_means(times: np.ndarray, values: np.ndarray, count: int, unit_s: float
                     ) -> np.ndarray:
    """Mean of a curve over the middle 80 % of each sub-pattern (away from crossfades)."""
    means = []
    for k in range(count):
        grid = np.linspace((k + 0.1) * unit_s, (k + 0.9) * unit_s, 50)
        means.append(np.interp(grid, times, values).mean())
    return np.array(means)


def assert_follows(times, values, x, rate, minimum=0.9):
    """The exported curve, read at the frame centres, correlates with the measured frame RMS."""
    rms, centres = frame_rms(x, rate)
    curve = np.interp(centres, times, values)
    r = np.corrcoef(curve, rms)[0, 1]
    assert r > minimum, r


def sorted_times(times) -> bool:
    return bool(np.all(np.diff(np.asarray(times, dtype=float)) >= 0))


# --- envelope --------------------------------------------------------------------------------

def test_envelope_measures_a_known_signal():
    rate = 8000
    t = np.arange(12000) / rate
    x = np.where(t < 0.75, 0.5 * np.sin(2 * np.pi * 100 * t), np.sin(2 * np.pi * 300 * t))
    measured = env.measure(x, rate)
    centres = measured.centres_s
    # The centroid window is 40 ms and wraps around the loop: stay away from both changes.
    away = (np.abs(centres - 0.75) > 0.03) & (centres > 0.03) & (centres < 1.47)
    first, second = away & (centres < 0.75), away & (centres > 0.75)
    assert len(measured.rms) == 150 and measured.period_s == pytest.approx(1.5)
    assert np.allclose(measured.rms[first], 0.5 / np.sqrt(2), rtol=0.01)
    assert np.allclose(measured.rms[second], 1 / np.sqrt(2), rtol=0.01)
    assert np.allclose(measured.centroid_hz[first], 100, rtol=0.03)
    assert np.allclose(measured.centroid_hz[second], 300, rtol=0.03)
    assert measured.intensity.max() == pytest.approx(1.0)
    # The pattern loops: the first frame's window reaches back into the 300 Hz end.
    assert measured.centroid_hz[0] > 120


def test_envelope_refuses_a_silent_pattern():
    with pytest.raises(RealPenError, match="silent"):
        env.measure(np.zeros(12000), 8000, source="quiet")


def test_sharpness_mapping_is_log_and_invertible():
    hz = np.array([10.0, 30.0, np.sqrt(30 * 500), 500.0, 900.0])
    assert env.sharpness(hz) == pytest.approx([0, 0, 0.5, 1, 1])
    assert env.sharpness_to_hz(env.sharpness(hz[1:4])) == pytest.approx(hz[1:4])


def test_loop_curve_spans_the_repeats_and_closes_the_wrap(pens):
    measured = env.measure(pens["pencil"].tactile, 8000)
    times, values = env.loop_curve(measured, measured.intensity, repeats=3)
    assert times[0] == 0 and times[-1] == pytest.approx(4.5)
    assert np.all(np.diff(times) > 0)
    assert len(times) == 3 * 150 + 4
    boundaries = np.isin(np.round(times, 9), [0.0, 1.5, 3.0, 4.5])
    assert np.ptp(values[boundaries]) == 0
    assert min(values[0], values[1], values[-2]) <= values[0] <= max(values[1], values[-2])


# --- wav ------------------------------------------------------------------------------------

def test_wav_mono_is_the_pattern_and_repeats_tile_it(pens):
    profile = pens["pencil"]
    samples, rate = wav.mono_samples(profile.pattern)
    assert rate == 8000 and np.array_equal(samples, profile.tactile)
    data = render("wav", profile, repeats=3, subtype="float").data
    read, rate = sf.read(io.BytesIO(data), dtype="float32")
    assert rate == 8000 and np.array_equal(read, np.tile(profile.tactile, 3))


SF_INSTRUMENT = struct.Struct("<i6bxxi" + "iIII" * 16)  # sndfile.h: gain, notes, loops[16]
SFC_GET_INSTRUMENT, SF_LOOP_FORWARD = 0x10D0, 801


def libsndfile_loops(path) -> list[tuple[int, int, int, int]]:
    """The loops libsndfile itself reads from a file's ``smpl`` chunk (``SFC_GET_INSTRUMENT``):
    (mode, start, end, count) each, libsndfile's end being exclusive; [] without a chunk."""
    buffer = sf._ffi.new("char[]", SF_INSTRUMENT.size)
    with sf.SoundFile(path) as handle:
        found = sf._snd.sf_command(handle._file, SFC_GET_INSTRUMENT, buffer, SF_INSTRUMENT.size)
    if not found:
        return []
    fields = SF_INSTRUMENT.unpack(bytes(sf._ffi.buffer(buffer)))
    count = fields[7]
    return [tuple(fields[8 + 4 * k:12 + 4 * k]) for k in range(count)]


@pytest.mark.parametrize("subtype,written,step", [("pcm16", "PCM_16", 2.0 ** -16),
                                                  ("pcm24", "PCM_24", 2.0 ** -24),
                                                  ("float", "FLOAT", 0.0)])
def test_wav_subtypes_carry_the_smpl_loop_libsndfile_reads(tmp_path, pens, subtype, written,
                                                             step):
    profile = pens["marker"]
    out = tmp_path / "marker.wav"
    export_profile(profile, "wav", out, stereo=True, subtype=subtype)
    info = sf.info(out)
    assert (info.subtype, info.frames, info.channels) == (written, 72000, 2)
    expected, _ = wav.stereo_samples(profile.pattern, profile.sound_loop)
    read, _ = sf.read(out, dtype="float64")
    assert np.max(np.abs(read - expected)) <= step
    assert read_smpl_loop(out) == (0, 71999)
    assert libsndfile_loops(out) == [(SF_LOOP_FORWARD, 0, 72000, 0)]  # forward, forever
    assert render("wav", profile, stereo=True, subtype=subtype).data == out.read_bytes()


def test_wav_default_is_pcm16_and_bad_subtypes_are_refused(pens):
    data = render("wav", pens["pencil"], repeats=2).data
    assert sf.info(io.BytesIO(data)).subtype == "PCM_16"
    assert read_smpl_loop(data) == (0, 23999)
    assert not any("loop" in limit for limit in render("wav", pens["pencil"]).limits)
    with pytest.raises(ParameterError, match=r"^subtype: must be one of pcm16, pcm24, float, "
                                             r"got 'PCM_16'"):
        render("wav", pens["pencil"], subtype="PCM_16")
    from realpen.cli.export_cmds import WAV_SUBTYPES

    assert WAV_SUBTYPES == wav.SUBTYPES


def test_resampled_loop_stays_seamless():
    rate, new_rate = 8000, 44100
    t = np.arange(12000) / rate
    x = 0.6 * np.sin(2 * np.pi * 120 * t) + 0.3 * np.sin(2 * np.pi * 333.3333333333333 * t)
    y = resample_loop(x, rate, new_rate)
    u = np.arange(len(y)) / new_rate
    expected = 0.6 * np.sin(2 * np.pi * 120 * u) + 0.3 * np.sin(2 * np.pi * 333.3333333333333 * u)
    assert len(y) == 66150
    # Accurate everywhere, the two ends (where the loop wraps) included.
    assert np.max(np.abs(y - expected)) < 2e-3
    assert np.max(np.abs(y[:50] - expected[:50])) < 2e-3
    assert np.max(np.abs(y[-50:] - expected[-50:])) < 2e-3


def test_resample_refuses_a_rate_that_breaks_the_loop():
    with pytest.raises(ParameterError, match="^rate: .*whole number of samples"):
        resample_loop(np.zeros(12000), 8000, 44101)
    for rate in (0, 99, 10 ** 9):  # 10⁹ Hz: a one-line error, not a 30 GB allocation
        with pytest.raises(ParameterError, match="^rate: must be a whole number of Hz from 100 "
                                                 "to 384000, got"):
            resample_loop(np.zeros(12000), 8000, rate)
    # Within the rates, a period too long at the new rate is refused before resampling.
    with pytest.raises(ParameterError, match="^rate: .*an export holds at most 33,554,432"):
        resample_loop(np.zeros(2**24), 8000, 384000)


def test_wav_stereo_puts_sound_left_and_tactile_right(pens):
    profile = pens["marker"]
    samples, rate = wav.stereo_samples(profile.pattern, profile.sound_loop)
    assert rate == 48000 and samples.shape == (72000, 2)  # 1500 ms = 5 × the 300 ms sound unit
    assert np.array_equal(samples[:, 0], np.tile(profile.sound, 5))
    reference = fft_resample(profile.tactile.astype(np.float64), 72000)  # periodic by nature
    assert np.max(np.abs(samples[:, 1] - reference)) < 5e-3
    assert np.corrcoef(samples[:, 1], reference)[0, 1] > 0.9999


def test_wav_stereo_refuses_loops_without_a_common_length(pens):
    profile = pens["pencil"]
    odd = dataclasses.replace(profile, sound=np.concatenate([profile.sound, profile.sound[:1]]))
    with pytest.raises(RealPenError, match="no common length"):
        wav.stereo_samples(odd.pattern, odd.sound_loop)


# --- c header ------------------------------------------------------------------------------

def test_quantise_scale_and_clipping():
    codes = c_header.quantise(np.array([-1.0, 0.0, 1.0, 0.5, 1.7, -3.0]))
    assert codes.tolist() == [1, 2048, 4095, 3072, 4095, 0]
    assert codes.dtype == np.uint16


PROGRAM = """#include <stdio.h>
#include "{header}"
int main(void) {{
    printf("%s %lu %lu %d\\n", {stem}_NAME, (unsigned long){stem}_RATE_HZ,
           (unsigned long){stem}_LENGTH, {stem}_LOOP);
    for (unsigned long i = 0; i < {stem}_LENGTH; i++) printf("%u\\n", (unsigned){lower}_tactile[i]);
    return 0;
}}
"""


@pytest.mark.slow
@pytest.mark.skipif(shutil.which("cc") is None, reason="no C compiler (cc) on this machine")
@pytest.mark.parametrize("name,rate", [("pencil", None), ("ballpoint", 16000)])
def test_c_header_compiles_and_its_table_is_the_quantised_pattern(tmp_path, pens, name, rate):
    profile = pens[name]
    header = tmp_path / f"{name}_tactile.h"
    export_profile(profile, "c-header", header, rate=rate)
    stem = c_header.identifier(name)
    source = tmp_path / "main.c"
    source.write_text(PROGRAM.format(header=header.name, stem=stem, lower=stem.lower()))
    binary = tmp_path / "main"
    compiled = subprocess.run(["cc", "-std=c99", "-Wall", "-Wextra", "-Werror", "-o", str(binary),
                               str(source)], capture_output=True, text=True)
    assert compiled.returncode == 0, compiled.stderr
    lines = subprocess.run([str(binary)], capture_output=True, text=True, check=True).stdout.split()
    pattern = profile.tactile.astype(np.float64)
    if rate is not None:
        pattern = resample_loop(pattern, profile.meta.tactile.rate, rate)
    expected = np.clip(np.round(2048 + 2047 * pattern), 0, 4095).astype(int)
    assert lines[:4] == [name, str(rate or 8000), str(len(expected)), "1"]
    table = np.array(lines[4:], dtype=int)
    assert len(table) == (12000 if rate is None else 24000)
    assert np.array_equal(table, expected)


# --- ahap ----------------------------------------------------------------------------------

def ahap_curve(document: dict, parameter: str) -> tuple[np.ndarray, np.ndarray]:
    """The absolute-time curve of one parameter, from its (chunked) parameter curves."""
    times, values = [], []
    for entry in document["Pattern"]:
        curve = entry.get("ParameterCurve")
        if curve and curve["ParameterID"] == parameter:
            for point in curve["ParameterCurveControlPoints"]:
                times.append(curve["Time"] + point["Time"])
                values.append(point["ParameterValue"])
    times, values = np.array(times), np.array(values)
    keep = np.concatenate([[True], np.diff(times) > 1e-9])  # chunks share their boundary point
    return times[keep], values[keep]


@pytest.mark.parametrize("name", PENS)
def test_ahap_has_the_required_structure(pens, name):
    document = doc("ahap", pens[name], created="2025-01-01")
    assert document["Version"] == 1.0 and isinstance(document["Pattern"], list)
    entry_times = [next(iter(entry.values()))["Time"] for entry in document["Pattern"]]
    assert sorted_times(entry_times)
    events = [entry["Event"] for entry in document["Pattern"] if "Event" in entry]
    continuous = [e for e in events if e["EventType"] == "HapticContinuous"]
    assert len(continuous) == 1 and continuous[0]["Time"] == 0
    assert continuous[0]["EventDuration"] == pytest.approx(1.5)
    assert {p["ParameterID"] for p in continuous[0]["EventParameters"]} == {"HapticIntensity",
                                                                            "HapticSharpness"}
    audio = [e for e in events if e["EventType"] == "AudioCustom"]
    assert [e["Time"] for e in audio] == pytest.approx([0, 0.3, 0.6, 0.9, 1.2])
    assert {e["EventWaveformPath"] for e in audio} == {f"{name}-sound.wav"}
    curves = [entry["ParameterCurve"] for entry in document["Pattern"] if "ParameterCurve" in entry]
    assert {c["ParameterID"] for c in curves} == {"HapticIntensityControl",
                                                  "HapticSharpnessControl"}
    for curve in curves:
        points = curve["ParameterCurveControlPoints"]
        assert 2 <= len(points) <= 16
        assert points[0]["Time"] == 0  # relative to the curve's own Time
        assert np.all(np.diff([p["Time"] for p in points]) > 0)
        assert all(0 <= p["ParameterValue"] <= 1 for p in points)
    for parameter in ("HapticIntensityControl", "HapticSharpnessControl"):
        times, _ = ahap_curve(document, parameter)
        assert times[0] == 0 and times[-1] == pytest.approx(1.5) and np.all(np.diff(times) > 0)


@pytest.mark.parametrize("name", PENS)
def test_ahap_curves_follow_the_pattern(pens, name):
    profile = pens[name]
    document = doc("ahap", profile)
    times, intensity = ahap_curve(document, "HapticIntensityControl")
    assert_follows(times, intensity, profile.tactile, profile.meta.tactile.rate)
    assert intensity.max() == pytest.approx(1.0, abs=1e-3)
    times, sharp = ahap_curve(document, "HapticSharpnessControl")
    hz = subpattern_means(times, env.sharpness_to_hz(sharp), 15, 0.1)
    expected = component_centroids(profile)
    assert np.max(np.abs(hz / expected - 1)) < 0.1
    assert np.corrcoef(hz, expected)[0, 1] > 0.9


def test_ahap_follows_a_strongly_varying_pattern(swept):
    profile, freqs = swept
    document = doc("ahap", profile)
    times, intensity = ahap_curve(document, "HapticIntensityControl")
    assert_follows(times, intensity, profile.tactile, 8000, minimum=0.98)
    assert intensity.min() < 0.3
    times, sharp = ahap_curve(document, "HapticSharpnessControl")
    hz = subpattern_means(times, env.sharpness_to_hz(sharp), 15, 0.1)
    assert np.allclose(hz, freqs, rtol=0.1)


def test_ahap_splits_long_patterns_into_30_s_events(pens):
    document = doc("ahap", pens["pencil"], repeats=25, sound_events=False)
    continuous = [e["Event"] for e in document["Pattern"]
                  if e.get("Event", {}).get("EventType") == "HapticContinuous"]
    assert [(e["Time"], e["EventDuration"]) for e in continuous] == [(0, 30), (30, 7.5)]
    types = [e.get("Event", {}).get("EventType") for e in document["Pattern"]]
    assert "AudioCustom" not in types
    times, _ = ahap_curve(document, "HapticIntensityControl")
    assert times[-1] == pytest.approx(37.5) and np.all(np.diff(times) > 0)


def test_ahap_export_writes_the_sound_it_plays(tmp_path, pens):
    profile = pens["ballpoint"]
    written = export_profile(profile, "ahap", tmp_path / "pen.ahap")
    document = json.loads((tmp_path / "pen.ahap").read_text())
    paths = {e["Event"]["EventWaveformPath"] for e in document["Pattern"]
             if e.get("Event", {}).get("EventType") == "AudioCustom"}
    assert paths == {"pen-sound.wav"}
    assert written.companions == [tmp_path / "pen-sound.wav", tmp_path / "pen.swift"]
    assert written.companions == companion_paths("ahap", tmp_path / "pen.ahap")
    player = (tmp_path / "pen.swift").read_text()
    assert 'Bundle.main.url(forResource: "pen", withExtension: "ahap")' in player
    assert f"static let cX: Float = {profile.coupling.c_x:.6g}" in player
    sound, rate = sf.read(tmp_path / "pen-sound.wav")
    assert rate == 48000 and len(sound) == len(profile.sound)
    assert np.max(np.abs(sound - profile.sound)) <= 1 / 32768 + 1e-9


def test_ahap_limits_are_checked_before_writing(pens):
    import copy

    made = doc("ahap", pens["pencil"], created="2025-01-01")
    assert ahap.check_limits(copy.deepcopy(made)) == made
    assert ahap.pattern_end(made) == pytest.approx(1.5)

    def broken(change):
        document = copy.deepcopy(made)
        change(document["Pattern"])
        return document

    def one_curve(entries):  # the first two intensity curves as one of 31 points
        curves = [e["ParameterCurve"] for e in entries if "ParameterCurve" in e
                  and e["ParameterCurve"]["ParameterID"] == "HapticIntensityControl"]
        shift = curves[1]["Time"] - curves[0]["Time"]
        curves[0]["ParameterCurveControlPoints"] += [
            {**point, "Time": point["Time"] + shift}
            for point in curves[1]["ParameterCurveControlPoints"][1:]]

    def long_event(entries):
        next(e for e in entries if "Event" in e)["Event"]["EventDuration"] = 31.0

    def late_curve(entries):
        next(e for e in entries if "ParameterCurve" in e)["ParameterCurve"]["Time"] = 599.99

    def many_sounds(entries):
        sound = next(e for e in entries if e.get("Event", {}).get("EventType") == "AudioCustom")
        entries += [copy.deepcopy(sound) for _ in range(ahap.MAX_SOUND_EVENTS)]

    for change, message in (
            (one_curve, r"^pencil: the HapticIntensityControl curve at 0 s holds 31 control "
                        r"points; an AHAP parameter curve holds at most 16$"),
            (long_event, r"^pencil: the continuous event at 0 s lasts 31 s; Core Haptics "
                         r"plays a continuous event for at most 30 s$"),
            (late_curve, r"^pencil: the AHAP pattern lasts 600\.1\d* s; an AHAP export holds "
                         r"at most 600 s$"),
            (many_sounds, r"^pencil: the AHAP holds 10,005 AudioCustom events; the limit is "
                          r"10,000$")):
        with pytest.raises(RealPenError, match=message):
            ahap.check_limits(broken(change), "pencil")


# --- .haptic --------------------------------------------------------------------------------

@pytest.mark.parametrize("name", PENS)
def test_haptic_has_the_v1_fields_and_follows_the_pattern(pens, name):
    profile = pens[name]
    document = doc("haptic", profile)
    assert document["version"] == {"major": 1, "minor": 0, "patch": 0}
    envelopes = document["signals"]["continuous"]["envelopes"]
    amplitude, frequency = envelopes["amplitude"], envelopes["frequency"]
    assert amplitude and frequency
    for points, key in ((amplitude, "amplitude"), (frequency, "frequency")):
        assert set(points[0]) == {"time", key}
        assert sorted_times([p["time"] for p in points])
        assert all(0 <= p[key] <= 1 for p in points)
        assert points[0]["time"] == 0 and points[-1]["time"] == pytest.approx(1.5)
    times = np.array([p["time"] for p in amplitude])
    # Lofelt plays intensity = √amplitude: the root follows the RMS.
    assert_follows(times, np.sqrt([p["amplitude"] for p in amplitude]), profile.tactile, 8000)
    hz = subpattern_means(times, env.sharpness_to_hz(np.sqrt([p["frequency"] for p in frequency])),
                          15, 0.1)
    assert np.max(np.abs(hz / component_centroids(profile) - 1)) < 0.1


def test_haptic_amplitude_matches_the_ahap_intensity_squared(pens):
    profile = pens["pencil"]
    lofelt = doc("haptic", profile)["signals"]["continuous"]["envelopes"]["amplitude"]
    times, intensity = ahap_curve(doc("ahap", profile), "HapticIntensityControl")
    assert np.allclose([p["time"] for p in lofelt], times, atol=1e-6)
    assert np.allclose(np.sqrt([p["amplitude"] for p in lofelt]), intensity, atol=2e-3)


# --- android --------------------------------------------------------------------------------

@pytest.mark.parametrize("name", PENS)
def test_android_waveform_steps_follow_the_pattern(pens, name):
    profile = pens[name]
    document = doc("android", profile)
    wave = document["waveform"]
    timings, amplitudes = wave["timings_ms"], wave["amplitudes"]
    assert len(timings) == len(amplitudes) == 150 and wave["repeat"] == 0
    assert all(isinstance(v, int) and v > 0 for v in timings) and sum(timings) == 1500
    assert all(isinstance(v, int) and 0 <= v <= 255 for v in amplitudes) and max(amplitudes) == 255
    centres = (np.cumsum(timings) - np.asarray(timings) / 2) / 1000
    assert_follows(centres, np.asarray(amplitudes, dtype=float), profile.tactile, 8000)


@pytest.mark.parametrize("name", PENS)
def test_android_envelopes_fit_every_capable_device(pens, name):
    profile = pens[name]
    document = doc("android", profile)
    expected = component_centroids(profile)
    for key, level, tone in (("waveform_envelope", "amplitude", "frequency_hz"),
                             ("basic_envelope", "intensity", "sharpness")):
        points = document[key]["control_points"]
        assert len(points) <= 16
        durations = [p["duration_ms"] for p in points]
        assert all(isinstance(d, int) and 20 <= d <= 1000 for d in durations)
        assert sum(durations) == 1500 + 20  # one period, then the ramp to zero
        assert points[-1][level] == 0 and all(0 <= p[level] <= 1 for p in points)
        values = np.array([p[tone] for p in points[:-1]])
        hz = values if tone == "frequency_hz" else env.sharpness_to_hz(values)
        assert np.all(hz > expected.min() * 0.8) and np.all(hz < expected.max() * 1.2)
    assert document["basic_envelope"]["initial_sharpness"] == document["basic_envelope"][
        "control_points"][0]["sharpness"]


def test_android_envelope_follows_a_strongly_varying_pattern(swept):
    profile, freqs = swept
    points = doc("android", profile)["waveform_envelope"]["control_points"]
    stamps = np.cumsum([p["duration_ms"] for p in points]) / 1000
    level = np.array([p["amplitude"] for p in points])
    # Segment means of the raised-cosine level: low at the ends, 1 in the middle.
    assert level[len(level) // 2] > 0.8 and level[0] < 0.5 and level[-2] < 0.5
    hz = np.array([p["frequency_hz"] for p in points[:-2]])
    truth = np.interp(stamps[:-2], (np.arange(15) + 0.5) * 0.1, freqs)
    assert np.corrcoef(np.log(hz), np.log(truth))[0, 1] > 0.95


def test_android_kotlin_snippet_holds_the_arrays(tmp_path, pens):
    profile = pens["marker"]
    export_profile(profile, "android", tmp_path / "Marker.kt")
    export_profile(profile, "android", tmp_path / "marker.json")
    source = (tmp_path / "Marker.kt").read_text()
    document = json.loads((tmp_path / "marker.json").read_text())
    assert "\n".join(document["kotlin"]) + "\n" == source
    assert "object MarkerVibration" in source
    assert "VibrationEffect.createWaveform(TIMINGS, AMPLITUDES, 0)" in source
    assert "VibrationEffect.WaveformEnvelopeBuilder()" in source
    assert "VibrationEffect.BasicEnvelopeBuilder()" in source
    array = re.search(r"intArrayOf\(([^)]*)\)", source).group(1)
    assert [int(v) for v in array.split(",")] == document["waveform"]["amplitudes"]
    points = len(document["basic_envelope"]["control_points"])
    assert source.count(".addControlPoint(") == 2 * points
    assert source.count("(") == source.count(")") and source.count("{") == source.count("}")


def test_android_limits_are_checked_before_writing(tmp_path, pens):
    pattern = pens["pencil"].pattern
    with pytest.raises(ParameterError, match=r"^repeats: an Android export holds one period: 2 "
                                             r"periods need 30 envelope control points, and "
                                             r"devices guarantee 16"):
        export("android", tmp_path / "p.json", pattern, repeats=2)
    short = TactilePattern([pattern.subpatterns[0]], subpattern_ms=30, crossfade_ms=1)
    with pytest.raises(RealPenError, match=r"^short: the tactile pattern lasts 30 ms; Android "
                                           r"envelope control points last at least 20 ms"):
        export("android", tmp_path / "p.json", short, name="short")
    long = TactilePattern(pattern.subpatterns, subpattern_ms=1000)  # 15 s
    with pytest.raises(RealPenError, match=r"^long: the tactile pattern lasts 15000 ms; .*at "
                                           r"most 1000 ms apart .*at most 14000 ms"):
        export("android", tmp_path / "p.json", long, name="long")
    assert list(tmp_path.iterdir()) == []
    shortest = TactilePattern([pattern.subpatterns[0]], subpattern_ms=40, crossfade_ms=1)
    points = doc("android", shortest)["basic_envelope"]["control_points"]
    assert [p["duration_ms"] for p in points] == [20, 20, 20]
    measured = env.Envelope(np.array([0.0, 0.0004, 0.01]), np.ones(2), np.full(2, 100.0))
    with pytest.raises(RealPenError, match=r"^pen: createWaveform step 0 lasts 0 ms; Android "
                                           r"needs timings above 0 ms"):
        android.check_waveform(android.waveform(measured), "pen")
    envelope = doc("android", pattern)["basic_envelope"]
    too_many = {"control_points": envelope["control_points"] + envelope["control_points"][:1]}
    with pytest.raises(RealPenError, match=r"^pen: the Android envelope has 17 control points; "
                                           r"devices guarantee 16"):
        android.check_envelope(too_many, "pen")
    for duration in (19, 1001):
        bad = {"control_points": [{**envelope["control_points"][0], "duration_ms": duration}]}
        with pytest.raises(RealPenError, match=rf"^pen: Android envelope control point 0 lasts "
                                               rf"{duration} ms; devices guarantee 20 … 1000 ms"):
            android.check_envelope(bad, "pen")


def kotlin_gain(source: str):
    """The Kotlin ``gain(pressure, speedMmS)`` of an Android export, run as Python: its
    constants read back from the text and its body translated line by line."""
    constants = {name: float(value) for name, value in
                 re.findall(r"const val (\w+) = ([-+0-9.eE]+)f\b", source)}
    body = re.search(r"fun gain\(pressure: Float, speedMmS: Float\): Float \{\n(.*?)\n    \}",
                     source, re.S).group(1)
    lines = []
    for line in body.strip().splitlines():
        line = re.sub(r"\b(\d+)f\b", r"\1.0", line.strip())
        line = re.sub(r"^if \((.*)\) return (.*)$", r"if \1: return \2", line)
        line = re.sub(r"^val ", "", line)
        line = re.sub(r"(\w+)\.coerceIn\(([^,]+), ([^)]+)\)", r"min(max(\1, \2), \3)", line)
        lines.append("    " + line)
    namespace = dict(constants)
    exec("def gain(pressure, speedMmS):\n" + "\n".join(lines), namespace)
    return namespace["gain"], constants


def test_android_kotlin_applies_the_coupling_as_realpen_does(pens, notebook_pattern):
    from realpen.motion.coupling import Coupling

    odd = Coupling(c_p=0.7321, c_op=0.05, c_x=0.0173, c_ov=9.5, a_max=1.7)
    points = [(0.0, 50.0), (0.5, 50.0), (1.0, 200.0), (0.2, 5.0), (0.3, 30.0), (-0.1, 40.0)]
    for coupling, source in ((odd, render("android", notebook_pattern, coupling=odd,
                                          kotlin_only=True).data.decode()),
                             (pens["pencil"].coupling,
                              render("android", pens["pencil"], kotlin_only=True).data.decode())):
        gain, constants = kotlin_gain(source)
        assert constants == {"C_P": coupling.c_p, "C_OP": coupling.c_op, "C_X": coupling.c_x,
                             "C_OV": coupling.c_ov, "A_MAX": coupling.a_max}
        for pressure, speed in points:
            assert gain(pressure, speed) == pytest.approx(
                float(coupling.gain_raw(pressure, speed)), abs=1e-12), (pressure, speed)
        assert "fun waveform(pressure: Float, speedMmS: Float): VibrationEffect?" in source
        assert "val drive = gain(pressure, speedMmS) / A_MAX" in source
        assert ("if (AMPLITUDES[i] == 0) 0 else (AMPLITUDES[i] * drive).roundToInt()"
                ".coerceIn(1, 255)") in source
    # Both ends of the clamp and the lifted pen are among the points.
    assert {float(odd.gain_raw(p, v)) for p, v in points} >= {0.0, 1.7}
    plain = render("android", notebook_pattern, kotlin_only=True).data.decode()
    assert "const val" not in plain and "fun gain(" not in plain and "roundToInt" not in plain
    assert "fun waveform(): VibrationEffect" in plain


# --- export_profile -------------------------------------------------------------------------

def test_export_profile_refuses_unknown_formats_and_options(tmp_path, pens):
    with pytest.raises(ParameterError, match=r"^fmt: unknown format 'mp3' \(known: wav, "):
        export_profile(pens["pencil"], "mp3", tmp_path / "x.mp3")
    with pytest.raises(ParameterError, match="^stereo: not used by format 'ahap'"):
        export_profile(pens["pencil"], "ahap", tmp_path / "x.ahap", stereo=True)
    with pytest.raises(ParameterError, match="^repeats: not used by format 'c-header'"):
        export_profile(pens["pencil"], "c-header", tmp_path / "x.h", repeats=2)
    with pytest.raises(ParameterError, match="^repeats: must be a whole number"):
        export_profile(pens["pencil"], "haptic", tmp_path / "x.haptic", repeats=0)
    with pytest.raises(ParameterError, match="^subtype: not used by format 'hjif'"):
        export_profile(pens["pencil"], "hjif", tmp_path / "x.hjif", subtype="float")
    assert list(tmp_path.iterdir()) == []


def test_each_format_is_written_to_its_own_suffix(tmp_path, pens):
    assert {fmt: SUFFIXES[fmt] for fmt in FORMATS} == {
        "wav": (".wav",), "c-header": (".h",), "ahap": (".ahap",), "haptic": (".haptic",),
        "android": (".json", ".kt"), "hjif": (".hjif",)}
    for fmt, module in FORMATS.items():
        assert format_for_suffix(f"dir.x/pen{module.SUFFIX.upper()}") == fmt
    assert format_for_suffix("Pen.kt") == "android"
    from realpen.cli.export_cmds import _SUFFIXES as help_text  # the numpy-free --output help

    assert all(f"{fmt} {suffixes[0]}" in help_text for fmt, suffixes in SUFFIXES.items())
    for name, found in (("pen.mp3", "the suffix .mp3"), ("pen", "no suffix")):
        with pytest.raises(RealPenError, match=rf"^{name}: has {found}; no export format is "
                                               rf"written to it \(.*wav \.wav, .*android "
                                               rf"\.json or \.kt, hjif \.hjif\)$"):
            format_for_suffix(name)
    out = tmp_path / "p.mp3"
    with pytest.raises(RealPenError, match=rf"^{re.escape(str(out))}: a wav export is written "
                                           rf"to a \.wav file, not \.mp3 \(name the file "
                                           rf"p\.wav"):
        export_profile(pens["pencil"], "wav", out)
    with pytest.raises(RealPenError, match=r"an android export is written to a \.json or \.kt "
                                           r"file, not \.wav"):
        export("android", tmp_path / "p.wav", pens["pencil"].pattern)
    with pytest.raises(RealPenError, match=r"a hjif export is written to a \.hjif file, and "
                                           r"this name has none"):
        export("hjif", tmp_path / "hjif", pens["pencil"].pattern)
    assert list(tmp_path.iterdir()) == []
    assert export("wav", tmp_path / "P.WAV", pens["pencil"].pattern).path.exists()


def test_every_format_renders_every_pen(pens):
    for name, profile in pens.items():
        for fmt in FORMATS:
            result = render(fmt, profile)
            assert result.data and result.summary and result.limits, (name, fmt)


# --- command line ---------------------------------------------------------------------------

@pytest.mark.parametrize("fmt,suffix", [("wav", ".wav"), ("c-header", ".h"), ("ahap", ".ahap"),
                                        ("haptic", ".haptic"), ("android", ".json"),
                                        ("hjif", ".hjif")])
def test_cli_exports_each_format(tmp_path, fmt, suffix):
    out = tmp_path / f"pen{suffix}"
    result = run_cli("export", "pencil", "--format", fmt, "-o", out)
    assert result.returncode == 0, result.stderr
    assert f"wrote {out}" in result.stdout and "cannot carry" in result.stdout
    assert out.stat().st_size > 0
    if suffix not in (".wav", ".h"):
        json.loads(out.read_text())
    leftovers = [p.name for p in tmp_path.iterdir() if p.name.startswith(".")]
    assert leftovers == []


def test_cli_infers_the_format_from_the_suffix(tmp_path):
    out = tmp_path / "pen.ahap"
    result = run_cli("export", "pencil", "-o", out)
    assert result.returncode == 0, result.stderr
    assert json.loads(out.read_text())["Version"] == 1.0
    assert (tmp_path / "pen-sound.wav").exists() and "note: ahap cannot carry" in result.stdout
    wav_out = tmp_path / "pen.wav"
    result = run_cli("export", "pencil", "-o", wav_out, "--subtype", "pcm24")
    assert result.returncode == 0, result.stderr
    assert sf.info(wav_out).subtype == "PCM_24" and read_smpl_loop(wav_out) == (0, 11999)


def test_cli_stereo_wav_with_rate_and_repeats(tmp_path):
    out = tmp_path / "stereo.wav"
    result = run_cli("export", "marker", "--format", "wav", "--stereo", "--rate", "44100",
                     "--repeats", "2", "-o", out)
    assert result.returncode == 0, result.stderr
    samples, rate = sf.read(out)
    assert rate == 44100 and samples.shape == (2 * 66150, 2)


def bad_case(tmp_path, case):
    """Arguments of one bad invocation and the text its message must name."""
    out = tmp_path / "out.file"
    wav_out = tmp_path / "out.wav"
    if case == "unknown_format":
        return ["export", "pencil", "--format", "mp3", "-o", out], "--format: unknown format 'mp3'"
    if case == "suffix_not_the_format":
        return (["export", "pencil", "-f", "wav", "-o", tmp_path / "p.mp3"],
                f"{tmp_path / 'p.mp3'}: a wav export is written to a .wav file, not .mp3")
    if case == "suffix_of_no_format":
        return ["export", "pencil", "-o", out], f"{out}: has the suffix .file; no export format"
    if case == "unknown_subtype":
        return ["export", "pencil", "--subtype", "pcm8", "-o", wav_out], "--subtype"
    if case == "no_such_profile":
        return ["export", "quill", "--format", "wav", "-o", wav_out], "quill: no such profile"
    if case == "broken_bundle":
        bundle = tmp_path / "broken"
        bundle.mkdir()
        (bundle / "profile.json").write_text("{")
        return ["export", bundle, "--format", "wav", "-o", wav_out], "broken"
    if case == "stereo_not_wav":
        return (["export", "pencil", "--format", "ahap", "--stereo", "-o", tmp_path / "o.ahap"],
                "--stereo")
    if case == "rate_zero":
        return (["export", "pencil", "--format", "c-header", "--rate", "0", "-o",
                 tmp_path / "o.h"], "--rate")
    if case == "rate_breaks_loop":
        return ["export", "pencil", "--format", "wav", "--rate", "44101", "-o", wav_out], "--rate"
    if case == "rate_not_used":
        return (["export", "pencil", "--format", "hjif", "--rate", "8000", "-o",
                 tmp_path / "o.hjif"], "--rate")
    if case == "repeats_zero":
        return (["export", "pencil", "--format", "haptic", "--repeats", "0", "-o",
                 tmp_path / "o.haptic"], "--repeats")
    if case == "android_repeats":
        return (["export", "pencil", "--repeats", "2", "-o", tmp_path / "o.json"],
                "--repeats: an Android export holds one period")
    if case == "output_is_folder":
        return ["export", "pencil", "--format", "wav", "-o", tmp_path], str(tmp_path)
    if case == "parent_is_file":
        blocker = tmp_path / "blocker"
        blocker.write_text("x")
        return ["export", "pencil", "--format", "haptic", "-o", blocker / "out.haptic"], "blocker"
    raise AssertionError(case)


@pytest.mark.parametrize("case", ["unknown_format", "suffix_not_the_format",
                                  "suffix_of_no_format", "unknown_subtype", "no_such_profile",
                                  "broken_bundle", "stereo_not_wav", "rate_zero",
                                  "rate_breaks_loop", "rate_not_used", "repeats_zero",
                                  "android_repeats", "output_is_folder", "parent_is_file"])
def test_cli_bad_input_fails_cleanly_and_writes_nothing(tmp_path, case):
    args, names = bad_case(tmp_path, case)
    before = {p.name for p in tmp_path.iterdir()}
    result = run_cli(*args)
    assert_clean_failure(result, names)
    assert {p.name for p in tmp_path.iterdir()} == before


# --- a pattern from a notebook --------------------------------------------------------------

@pytest.fixture(scope="module")
def notebook_pattern():
    from realpen.examples import example_recording_path
    from realpen.tactile.build import tactile_pattern

    return tactile_pattern(example_recording_path(), "lra:f0=175,q=8", condition="E")


def test_a_pattern_exports_in_every_format_without_a_profile(tmp_path, notebook_pattern):
    for fmt, module in FORMATS.items():
        result = render(fmt, notebook_pattern)
        assert result.data and result.summary and result.limits, fmt
        written = export(fmt, tmp_path / f"e{module.SUFFIX}", notebook_pattern)
        assert written.path.stat().st_size > 0 and written.companions == [], fmt
    ahap_doc = doc("ahap", notebook_pattern, created="2025-01-01")
    assert not [e for e in ahap_doc["Pattern"] if e.get("Event", {}).get("EventType") == "AudioCustom"]
    assert any("no sound" in limit for limit in render("ahap", notebook_pattern).limits)
    assert notebook_pattern.version in ahap_doc["Metadata"]["Description"]
    header = render("c-header", notebook_pattern, name="my-pen").data.decode()
    assert "REALPEN_MY_PEN_RATE_HZ 8000UL" in header
    hjif_doc = doc("hjif", notebook_pattern)
    assert hjif_doc["perceptions"][0]["reference_devices"][0]["name"] == "lra:f0=175,q=8"


def test_formats_that_need_the_sound_say_so(tmp_path, notebook_pattern):
    with pytest.raises(ParameterError, match="^sound: a stereo WAV .* needs the sound") as info:
        render("wav", notebook_pattern, stereo=True)
    assert info.value.parameter == "sound"
    with pytest.raises(ParameterError, match="^sound: AHAP sound events .* need the sound"):
        export("ahap", tmp_path / "x.ahap", notebook_pattern, sound_events=True)
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(ParameterError, match="^sound: is not a loop"):
        render("wav", notebook_pattern, sound=SimpleLoop(np.zeros(100), 48000, is_loop=False),
               stereo=True)


@dataclasses.dataclass
class SimpleLoop:
    """What the exports need of a sound loop: samples (full scale) and a rate in Hz."""

    samples: np.ndarray
    rate: int
    is_loop: bool = True


def test_a_pattern_with_a_sound_loop_and_coupling(tmp_path, notebook_pattern, pens):
    from realpen.motion.coupling import Coupling

    t = np.arange(14400) / 48000
    loop = SimpleLoop(0.1 * np.sin(2 * np.pi * 1000 * t), 48000)
    written = export("ahap", tmp_path / "nb.ahap", notebook_pattern, sound=loop, name="nb")
    # Without a coupling there is no Swift player: only the sound of a profile's two companions.
    assert written.companions == [tmp_path / "nb-sound.wav"]
    assert companion_paths("ahap", tmp_path / "nb.ahap")[:1] == written.companions
    assert companion_paths("hjif", tmp_path / "nb.hjif") == []
    sound, rate = sf.read(tmp_path / "nb-sound.wav")
    assert rate == 48000 and np.max(np.abs(sound - loop.samples)) <= 1 / 32768 + 1e-9
    samples, rate = wav.stereo_samples(notebook_pattern, loop)
    assert samples.shape == (72000, 2)
    assert np.array_equal(samples[:, 0], np.tile(loop.samples, 5).astype(np.float32))
    document = android.build(notebook_pattern, Coupling(c_p=0.7), name="nb")
    assert document["coupling"]["c_p"] == 0.7 and "object NbVibration" in "\n".join(document["kotlin"])
    assert "coupling" not in android.build(notebook_pattern)
    # A profile exports exactly as its pattern, loop and coupling do.
    profile = pens["ballpoint"]
    inputs = profile_inputs(profile)
    for fmt in FORMATS:
        options = {"ahap": {"created": "2025-01-01"}, "hjif": {"date": "2025-01-01"}}.get(fmt, {})
        by_profile = render(fmt, profile, **options)
        by_parts = render(fmt, inputs["pattern"], inputs["sound"], inputs["coupling"],
                          name=inputs["name"], tool=inputs["tool"], version=inputs["version"],
                          **options)
        assert by_profile.data == by_parts.data, fmt
    direct = ahap.build(profile.pattern, profile.sound_loop, created="2025-01-01", name="ballpoint",
                        tool=profile.meta.tool, version=profile.version)
    assert direct == doc("ahap", profile, created="2025-01-01")


def test_export_repr_is_one_line(pens):
    text = repr(render("ahap", pens["pencil"]))
    assert text.startswith("Export(")
    assert "companions ['pencil-sound.wav', 'pencil.swift']" in text
    assert len(text) < 200 and "\n" not in text


# --- limits: what one export may hold ----------------------------------------------------------

def test_exports_hold_at_most_ten_minutes(pens):
    pattern = pens["pencil"].pattern  # 1.5 s
    for fmt in ("haptic", "wav"):
        assert render(fmt, pattern, repeats=100).data  # 150 s
    long = TactilePattern(pattern.subpatterns, subpattern_ms=45_000)  # 675 s, 5.4 M samples
    for fmt in ("ahap", "haptic", "android", "hjif", "wav"):
        with pytest.raises(RealPenError, match="^long: the tactile pattern lasts 675 s; an "
                                               "export holds at most 600 s"):
            render(fmt, long, name="long")
    medium = TactilePattern(pattern.subpatterns, subpattern_ms=1000)  # 15 s
    with pytest.raises(ParameterError, match=r"^repeats: 41 periods of 15 s last 615 s"):
        render("haptic", medium, repeats=41)


@pytest.mark.slow
def test_sample_exports_are_bounded_in_frames(pens):
    with pytest.raises(ParameterError, match=r"^repeats: 100 × 576,000 frames at 384000 Hz make "
                                             r"57,600,000 frames"):
        render("wav", pens["pencil"], stereo=True, rate=384000, repeats=100)
    stereo = render("wav", pens["pencil"], stereo=True, rate=384000, repeats=50)
    assert sf.info(io.BytesIO(stereo.data)).frames == 50 * 576000


def test_hjif_effects_are_counted_before_they_are_made(pens, monkeypatch):
    from realpen.exports import hjif

    made = json.loads(render("hjif", pens["pencil"], repeats=2).data)
    count = len(made["perceptions"][0]["channels"][0]["bands"][0]["effects"])
    monkeypatch.setattr(hjif, "MAX_EFFECTS", count - 1)
    with pytest.raises(RealPenError, match=r"^pencil: a \.hjif file of 2 period\(s\) would hold "
                                           r"[\d,]+ sine effects; the limit is"):
        render("hjif", pens["pencil"], repeats=2)


def test_ahap_sound_events_are_bounded(pens):
    from types import SimpleNamespace

    tiny = SimpleNamespace(samples=np.ones(2), rate=48000)  # a 42 µs loop: 36 000 events
    with pytest.raises(RealPenError, match="more than 10,000 AudioCustom events"):
        render("ahap", pens["pencil"].pattern, sound=tiny, name="pencil")


def test_envelope_measured_in_blocks_is_the_same(pens, monkeypatch):
    x = pens["marker"].tactile.astype(np.float64)
    whole = env.measure(x, 8000)
    monkeypatch.setattr(env, "_BLOCK_VALUES", 3000)  # one 2048-point window at a time
    blocked = env.measure(x, 8000)
    np.testing.assert_allclose(blocked.centroid_hz, whole.centroid_hz, rtol=1e-12)
    np.testing.assert_array_equal(blocked.rms, whole.rms)
