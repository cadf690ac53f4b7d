"""The envelope formats read back: ``.haptic``, ``.ahap`` and the Android JSON render to the
pattern's envelope; Lofelt's own test vectors are accepted or refused as Lofelt's data model
does; each Lofelt-converted ``.ahap`` reads to the same envelope as its ``.haptic``."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import soundfile as sf

import realpen as rp
from realpen.errors import RealPenError
from realpen.exports import export, reading
from realpen.exports.haptic_rules import check_haptic
from realpen.exports.readers import carrier
from realpen.exports.reading import frame_rms, load_haptic

PENS = ("pencil", "ballpoint", "marker")
FORMATS = (("haptic", ".haptic"), ("ahap", ".ahap"), ("android", ".json"))
LOFELT = Path(__file__).resolve().parents[2] / "shared" / "standards" / "lofelt-test-data"

# Lofelt's data model tests (core/datamodel/src/lib.rs and v1.rs of Lofelt/NiceVibrations) say
# which vectors are valid v1: the valid_* files, validation_v1_optionals and v1_additional_fields
# (a newer minor version with unknown fields: read, the fields ignored) validate; the truncate_*
# files are the inputs and expected outputs of its truncation tests, all well-formed v1 (the
# one-breakpoint file is refused only by truncation, not by validation); the ios/*.haptic files
# are the converter tests' inputs. The other v1 files must each fail on one rule, named here as
# this reader words it.
INVALID_V1 = {
    "invalid_fields_v1.haptic": "signals: is missing",
    "invalid_version_v1.haptic": "version.major: must be 1",
    "validation_v1_amplitude.haptic": "amplitude[3].amplitude: must be from 0 to 1",
    "validation_v1_sequence.haptic": "amplitude[2].time: breakpoint times must not decrease",
    "validation_v1_emphasis_amplitude.haptic":
        "emphasis.amplitude: an emphasis amplitude must be at least its breakpoint's amplitude",
    "validation_v1_emphasis_amplitude_range.haptic": "emphasis.amplitude: must be from 0 to 1",
    "validation_v1_emphasis_frequency_range.haptic": "emphasis.frequency: must be from 0 to 1",
}
# (.haptic, the .ahap Lofelt's converter made of it), as Lofelt's converter tests pair them.
TWINS = (*((f"ios/{n}.haptic", f"ios/{n}.ahap")
           for n in ("2_points", "3_points", "16_points", "17_points", "long_clip")),
         ("ios/valid_v1_multiple_emphasis.haptic", "ios/valid_v1_multiple_transients.ahap"),
         ("valid_v1.haptic", "ios/ahap_from_valid_v1.ahap"),
         ("valid_required_v1.haptic", "ios/ahap_from_valid_v1_required.ahap"))


def lofelt() -> Path:
    if not LOFELT.is_dir():
        pytest.skip(f"the Lofelt test vectors are not here: {LOFELT} is absent "
                    f"(../shared/standards is never bundled)")
    return LOFELT


def as_haptic(tmp_path: Path, document: object, name: str = "x.haptic") -> Path:
    path = tmp_path / name
    path.write_text(json.dumps(document))
    return path


@pytest.fixture(scope="module")
def exported(tmp_path_factory) -> dict:
    """Each bundled pen's three envelope exports read back, with the pattern's own envelope."""
    folder = tmp_path_factory.mktemp("envelope-exports")
    read = {}
    for pen in PENS:
        profile = rp.load_profile(pen)
        rate = int(profile.pattern.rate)
        own = frame_rms(profile.pattern.samples, rate)
        for fmt, suffix in FORMATS:
            path = folder / f"{pen}{suffix}"
            export(fmt, path, profile)
            read[pen, fmt] = (load_haptic(path), own, rate)
    return read


@pytest.mark.parametrize("pen", PENS)
@pytest.mark.parametrize("fmt", [fmt for fmt, _ in FORMATS])
def test_export_reads_back_to_the_pattern_envelope(exported, pen, fmt):
    # Measured: pencil .haptic/.ahap 0.962, android 0.995; ballpoint 0.979, 0.9997; marker
    # 0.971, 0.999 (the .haptic and AHAP curves join frame centres linearly, which smooths).
    clip, own, rate = exported[pen, fmt]
    assert clip.format == fmt
    assert clip.duration_s == pytest.approx(len(own) * 0.010, abs=0.011)
    rendered = clip.envelope(rate)
    count = min(len(rendered), len(own))
    assert abs(len(rendered) - len(own)) <= 1
    r = float(np.corrcoef(rendered[:count], own[:count])[0, 1])
    assert r >= 0.95, f"{pen} {fmt}: 10 ms RMS envelope correlation {r:.4f} < 0.95"
    assert any("sine" in note for note in clip.notes)  # the carrier model is stated


def test_ahap_export_reports_its_sound_events(exported):
    clip = exported["pencil", "ahap"][0]
    assert "audio events" in clip.summary
    assert any("not vibration" in note for note in clip.notes)


def test_haptic_export_is_checked_before_writing(monkeypatch, tmp_path):
    from realpen.exports import haptic

    broken = haptic.build

    def descending(*args, **kwargs):
        document = broken(*args, **kwargs)
        document["signals"]["continuous"]["envelopes"]["amplitude"][2]["time"] = 0.0
        return document

    monkeypatch.setattr(haptic, "build", descending)
    target = tmp_path / "pencil.haptic"
    with pytest.raises(RealPenError, match=r"amplitude\[2\]\.time: breakpoint times must not "
                                           r"decrease .*\(Lofelt v1\)"):
        export("haptic", target, rp.load_profile("pencil"))
    assert not target.exists()


def test_lofelt_valid_vectors_are_accepted():
    root = lofelt()
    valid = sorted(set(root.glob("*.haptic")) | set(root.glob("ios/*.haptic")))
    valid = [path for path in valid if path.name not in INVALID_V1]
    assert len(valid) >= 20
    for path in valid:
        clip = load_haptic(path)
        assert clip.format == "haptic" and clip.summary.startswith("Lofelt v1.")
        assert np.all(np.isfinite(clip.render(2000)))


@pytest.mark.parametrize("name", sorted(INVALID_V1))
def test_lofelt_invalid_vectors_are_refused_naming_the_rule(name):
    path = lofelt() / name
    with pytest.raises(RealPenError) as caught:
        load_haptic(path)
    message = str(caught.value)
    assert message.startswith(f"{path}: ") and "\n" not in message
    assert INVALID_V1[name] in message


def test_lofelt_v0_files_are_refused_in_one_line():
    files = sorted(lofelt().glob("*.vij"))
    assert len(files) == 11
    for path in files:
        with pytest.raises(RealPenError) as info:
            load_haptic(path)
        message = str(info.value)
        assert message.startswith(f"{path}: ") and "\n" not in message, message
        assert message.endswith("version: is missing: a file without one is Lofelt v0 (.vij), "
                                "which is not read; convert it to v1"), message


@pytest.mark.parametrize("haptic_name, ahap_name", TWINS)
def test_lofelt_ahap_reads_like_its_haptic_twin(haptic_name, ahap_name):
    # The .ahap holds the converter's float32 values (7 digits), so the two renders differ
    # only by rounding: at most 1e-3 of full scale in any 10 ms frame (measured ≤ 7e-5) and,
    # where the clip is not silent, correlated ≥ 0.9999. A mapping error (a missing √, the
    # emphasis ducking, relative curve times) moves frames by 0.05 or more.
    root = lofelt()
    from_haptic, from_ahap = load_haptic(root / haptic_name), load_haptic(root / ahap_name)
    assert from_haptic.duration_s == pytest.approx(from_ahap.duration_s, abs=1e-6)
    first, second = from_haptic.envelope(2000), from_ahap.envelope(2000)
    assert len(first) == len(second)
    gap = float(np.abs(first - second).max())
    assert gap <= 1e-3, f"{haptic_name} vs {ahap_name}: envelopes differ by {gap:.2e}"
    if first.std() > 0:
        r = float(np.corrcoef(first, second)[0, 1])
        assert r >= 0.9999, f"{haptic_name} vs {ahap_name}: correlation {r:.6f}"


def test_lofelt_absolute_curve_times_are_detected():
    clip = load_haptic(lofelt() / "ios" / "17_points.ahap")
    assert any("absolute" in note for note in clip.notes)
    envelope = clip.envelope(2000)
    # The second curve (points at 15 s and 16 s) carries the intensity from 0.387 to 0.4;
    # read as relative, 15 s + 15 s would fall past the end and hold 0.387.
    assert envelope[-1] == pytest.approx(0.4 / np.sqrt(2), abs=0.01)


def test_ahap_semantics(tmp_path):
    """Intensity control multiplies, sharpness control adds, transients are bursts."""
    document = {"Version": 1.0, "Pattern": [
        {"Event": {"Time": 0.0, "EventType": "HapticContinuous", "EventDuration": 0.4,
                   "EventParameters": [{"ParameterID": "HapticIntensity", "ParameterValue": 0.8},
                                       {"ParameterID": "HapticSharpness",
                                        "ParameterValue": 0.2}]}},
        {"ParameterCurve": {"ParameterID": "HapticIntensityControl", "Time": 0.2,
                            "ParameterCurveControlPoints": [
                                {"Time": 0.0, "ParameterValue": 0.5},
                                {"Time": 0.1, "ParameterValue": 0.5}]}},
        {"Parameter": {"ParameterID": "HapticSharpnessControl", "Time": 0.0,
                       "ParameterValue": 0.3}},
        {"Event": {"Time": 0.5, "EventType": "HapticTransient"}},
        {"Event": {"Time": 0.0, "EventType": "AudioCustom", "EventWaveformPath": "x.wav"}},
    ]}
    path = tmp_path / "x.ahap"
    path.write_text(json.dumps(document))
    clip = load_haptic(path)
    assert clip.duration_s == pytest.approx(0.5 + carrier.TRANSIENT_S)
    assert "1 continuous and 1 transient" in clip.summary and "1 audio events" in clip.summary
    envelope = clip.envelope(8000)
    assert envelope[5:15].mean() == pytest.approx(0.8 / np.sqrt(2), rel=0.05)
    assert envelope[25:35].mean() == pytest.approx(0.4 / np.sqrt(2), rel=0.05)
    assert envelope[48] == 0 and envelope[50] > 0.1


MALFORMED = (
    ("x.ahap", {"Pattern": [{"Event": {"Time": 0, "EventType": "HapticBuzz"}}]},
     "Pattern[0].Event.EventType: must be one of"),
    ("x.ahap", {"Pattern": [{"Event": {"Time": -1, "EventType": "HapticTransient"}}]},
     "Pattern[0].Event.Time: must be from 0 to 3600, got -1"),
    ("x.ahap", {"Pattern": [{"Event": {"Time": 0, "EventType": "HapticContinuous"}}]},
     "Pattern[0].Event.EventDuration: is missing"),
    ("x.ahap", {"Pattern": [{"ParameterCurve": {
        "ParameterID": "HapticIntensityControl", "Time": 0, "ParameterCurveControlPoints": [
            {"Time": 0.2, "ParameterValue": 1}, {"Time": 0.1, "ParameterValue": 0}]}}]},
     "ParameterCurveControlPoints[1].Time: control points must be in time order"),
    ("x.ahap", {"Pattern": [{"ParameterCurves": {}}]},
     "Pattern[0]: must hold one Event, Parameter or ParameterCurve, got ParameterCurves"),
    ("x.haptic", {"version": {"major": 1}, "signals": {"continuous": {"envelopes": {
        "amplitude": []}}}}, "amplitude: the amplitude envelope must not be empty (Lofelt v1)"),
    ("x.haptic", {"version": {"major": 1}, "signals": {"continuous": {"envelopes": {
        "amplitude": [{"time": 0, "amplitude": "loud"}]}}}},
     "amplitude[0].amplitude: must be a number"),
    ("x.haptic", {"version": {"major": 1}, "signals": {"continuous": {"envelopes": {
        "amplitude": [{"time": 0, "amplitude": 0.5}],
        "frequency": [{"time": 0, "frequency": 2}]}}}},
     "frequency[0].frequency: must be from 0 to 1, got 2 (Lofelt v1)"),
    ("x.json", {"format": "something-else"},
     "format: is not RealPen's Android export (format 'realpen-android-vibration')"),
    ("x.json", {"format": "realpen-android-vibration", "version": 1,
                "waveform": {"timings_ms": [10, 10], "amplitudes": [255]}},
     "waveform.amplitudes: must hold one amplitude per timing"),
    ("x.json", {"format": "realpen-android-vibration", "version": 1,
                "waveform": {"timings_ms": [10], "amplitudes": [300]}},
     "waveform.amplitudes[0]: must be from 0 to 255"),
    # Inputs that once built gigabytes or ended in a traceback.
    ("x.haptic", {"version": {"major": 1}, "signals": {"continuous": {"envelopes": {
        "amplitude": [{"time": 0, "amplitude": 0.5}, {"time": 1e15, "amplitude": 0.5}]}}}},
     "amplitude[1].time: must be from 0 to 3600, got 1e+15"),
    ("x.ahap", {"Pattern": [{"Event": {"EventType": "HapticTransient", "Time": 10**30}}]},
     "Pattern[0].Event.Time: must be from 0 to 3600, got 1e+30"),
    ("x.json", {"format": "realpen-android-vibration", "version": 1,
                "waveform": {"timings_ms": [10], "amplitudes": [30]},
                "waveform_envelope": {"initial_frequency_hz": 150, "control_points": [
                    {"amplitude": 0.5, "frequency_hz": 150, "duration_ms": 10}]},
                "basic_envelope": {"control_points": 5}},
     "basic_envelope.control_points: must be an array, got 5"),
    ("x.json", {"format": "realpen-android-vibration", "version": 1,
                "waveform": {"timings_ms": [10**12], "amplitudes": [30]},
                "waveform_envelope": {"initial_frequency_hz": 150, "control_points": [
                    {"amplitude": 0.5, "frequency_hz": 150, "duration_ms": 10}]}},
     "plays 1e+09 s; RealPen reads haptic files of at most 3600 s"),
)


@pytest.mark.parametrize("name, document, expected", MALFORMED,
                         ids=[f"{name}-{expected.split(':')[0]}" for name, _, expected in MALFORMED])
def test_malformed_files_are_one_line_errors(tmp_path, name, document, expected):
    path = as_haptic(tmp_path, document, name)
    with pytest.raises(RealPenError) as caught:
        load_haptic(path)
    message = str(caught.value)
    assert "\n" not in message and message.startswith(f"{path}: ")
    assert expected in message


def test_check_haptic_returns_the_document():
    document = {"version": {"major": 1, "minor": 2}, "signals": {"continuous": {"envelopes": {
        "amplitude": [{"time": 0, "amplitude": 0.1, "emphasis": {"amplitude": 0.1,
                                                                  "frequency": 0}}]}}}}
    assert check_haptic(document, "x.haptic") is document


def test_realpen_export_read_renders_every_format(tmp_path):
    """`realpen export PROFILE -o FILE` then `realpen export read FILE --render`: for each
    format the rendered WAV lasts the pattern and follows its envelope."""
    from conftest import run_cli

    profile = rp.load_profile("marker")
    own = reading.frame_rms(profile.pattern.samples, profile.pattern.rate)
    for suffix in (".hjif", ".haptic", ".ahap", ".json"):
        out = tmp_path / f"marker{suffix}"
        assert run_cli("export", "marker", "-o", out).returncode == 0
        wav = tmp_path / f"marker{suffix}.wav"
        result = run_cli("export", "read", out, "--render", wav, "--rate", "8000")
        assert result.returncode == 0, result.stderr
        first = result.stdout.splitlines()[0]
        assert first.startswith(f"{out}: {reading.format_of_file(out)}: ") and "1500 ms" in first
        assert f"wrote {wav}: 12000 samples at 8000 Hz" in result.stdout
        samples, rate = sf.read(wav)
        assert rate == 8000 and len(samples) == 12000
        r = np.corrcoef(reading.frame_rms(samples, rate), own)[0, 1]
        assert r > 0.95, (suffix, r)
    again = run_cli("export", "read", out, "--render", wav)
    assert again.returncode == 2 and "--force" in again.stderr
    mp3 = run_cli("export", "read", out, "--render", tmp_path / "x.mp3")
    assert mp3.returncode == 2 and "name it x.wav" in mp3.stderr
    assert not (tmp_path / "x.mp3").exists()


def test_an_ahap_continuous_event_lasts_at_most_30_s(tmp_path):
    path = as_haptic(tmp_path, {"Pattern": [{"Event": {
        "EventType": "HapticContinuous", "Time": 0, "EventDuration": 1e9}}]}, "long.ahap")
    clip = load_haptic(path)
    assert clip.duration_s == 30.0
    assert any("EventDuration" in note and "clamped" in note for note in clip.notes)
    assert len(clip.render(100)) == 3000


def test_overlapping_continuous_events_render_in_one_pass():
    """Many events over the whole clip: the levels add (clipped at 1) without a pass each."""
    pattern = carrier.Pattern()
    pattern.continuous += [(0.0, 1.0, 0.01, 0.5)] * 50_000
    pattern.continuous.append((0.5, 0.25, 0.3, 0.5))
    y = pattern.render(1000)
    assert len(y) == 1000 and np.max(np.abs(y)) == pytest.approx(1.0, abs=0.01)
    single = carrier.Pattern(continuous=[(0.0, 1.0, 1.0, 0.5)]).render(1000)
    assert np.allclose(y, single)
