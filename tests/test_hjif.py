"""MPEG-I haptics (.hjif): the export is valid under the published schemas, and reading it back
(realpen.exports.readers.hjif, as the reference software renders) gives the pattern."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from test_grid import grid_profile

from realpen.dsp.waveform_measures import mpeg_psnr
from realpen.errors import ParameterError, RealPenError
from realpen.exports import export, render
from realpen.exports.hjif import MAX_PHASE, creation_date
from realpen.exports.reading import load_haptic
from realpen.profile.registry import resolve_profile
from realpen.tactile.pattern import Component, TactilePattern

PENS = ("pencil", "ballpoint", "marker")
SCHEMAS = Path(__file__).resolve().parents[2] / "shared" / "standards" / "mpeg-haptics" \
    / "Specifications"


@pytest.fixture(scope="module")
def pens():
    return {name: resolve_profile(name) for name in PENS}


@pytest.fixture(scope="module")
def validator():
    """A draft-04 validator of MPEG_haptics.schema.json with its nine referenced schemas and a
    date-time format check."""
    if not SCHEMAS.is_dir():
        pytest.skip(f"the MPEG haptics schemas are not here: {SCHEMAS} is absent")
    import jsonschema
    import referencing
    from referencing.jsonschema import DRAFT4

    files = sorted(SCHEMAS.glob("*.schema.json"))
    assert len(files) == 10, files
    registry = referencing.Registry().with_resources(
        (path.name, referencing.Resource.from_contents(json.loads(path.read_text()),
                                                       default_specification=DRAFT4))
        for path in files)
    checker = jsonschema.Draft4Validator.FORMAT_CHECKER
    # Without rfc3339-validator jsonschema skips date-time silently; this test must not.
    assert not checker.conforms("2026-11-28", "date-time")
    schema = json.loads((SCHEMAS / "MPEG_haptics.schema.json").read_text())
    return jsonschema.Draft4Validator(schema, registry=registry, format_checker=checker)


def errors_of(validator, document: dict) -> list[str]:
    return [f"{'/'.join(map(str, e.absolute_path))}: {e.message[:100]}"
            for e in validator.iter_errors(document)]


def document_of(item, **options) -> dict:
    return json.loads(render("hjif", item, **options).data)


@pytest.mark.parametrize("name", PENS)
def test_every_bundled_pen_is_valid_under_the_published_schemas(validator, pens, name):
    document = document_of(pens[name], repeats=2)
    assert errors_of(validator, document) == []
    perception = document["perceptions"][0]
    device = perception["reference_devices"][0]
    assert device["id"] >= 1 and device["type"] == "LRA"
    assert perception["channels"][0]["reference_device_id"] == device["id"]


def test_a_grid_profile_and_a_notebook_pattern_are_valid(validator):
    assert errors_of(validator, document_of(grid_profile())) == []
    pattern = TactilePattern([[Component(175.2, 0.5, phase=6.2831849)],
                              [Component(80.0, 0.25), Component(300.7, 0.25)]])
    document = document_of(pattern, date="2025-01-02")
    assert errors_of(validator, document) == []
    assert document["date"] == "2025-01-02T00:00:00Z"
    assert document["perceptions"][0]["reference_devices"][0]["type"] == "Unknown"


def test_the_schemas_catch_what_the_export_once_got_wrong(validator, pens):
    """The check can fail: a device id of 0 and a bare date are both refused."""
    document = document_of(pens["pencil"])
    document["perceptions"][0]["reference_devices"][0]["id"] = 0
    document["date"] = "2026-11-28"
    found = errors_of(validator, document)
    assert len(found) == 2 and any(e.startswith("date:") for e in found), found


@pytest.mark.parametrize("name", PENS)
def test_frequency_is_written_once_per_effect(pens, name):
    """The reference renderer advances the phase between frequency keyframes as if positions
    were milliseconds; one frequency keyframe per effect plays right at any timescale."""
    band = document_of(pens[name])["perceptions"][0]["channels"][0]["bands"][0]
    for effect in band["effects"]:
        keys = effect["keyframes"]
        assert isinstance(keys[0]["frequency_modulation"], int)
        assert all("frequency_modulation" not in k for k in keys[1:])
        assert all("amplitude_modulation" in k for k in keys)
        assert 0 <= effect["phase"] <= MAX_PHASE
    frequencies = [e["keyframes"][0]["frequency_modulation"] for e in band["effects"]]
    assert band["lower_frequency_limit"] == min(frequencies)
    assert band["upper_frequency_limit"] == max(frequencies)


@pytest.mark.parametrize("name", PENS)
def test_reading_the_file_back_gives_the_pattern(tmp_path, pens, name):
    """MPEG's own measure, against RealPen's render of the pattern: ≥ 40 dB PSNR."""
    profile = pens[name]
    clip = load_haptic(export("hjif", tmp_path / f"{name}.hjif", profile).path)
    pattern = profile.pattern
    assert clip.format == "hjif" and clip.duration_s == pytest.approx(pattern.duration_s)
    decoded = clip.render(pattern.rate)
    assert len(decoded) == pattern.frames
    psnr = mpeg_psnr(decoded, np.asarray(pattern.samples, dtype=np.float64))
    assert psnr >= 40.0, f"{name}: {psnr:.1f} dB"
    # Inside the file (the wrap crossfades are cut at its two ends) two periods add up too.
    twice = load_haptic(export("hjif", tmp_path / f"{name}-2.hjif", profile, repeats=2).path)
    x = np.tile(np.asarray(pattern.samples, dtype=np.float64), 2)
    y = twice.render(pattern.rate)
    inner = slice(20, len(x) - 20)
    assert np.corrcoef(x[inner], y[inner])[0, 1] > 0.999


@pytest.mark.parametrize("boundary,count,unit_ms", [("hard", 15, 100.0),
                                                     ("crossfade", 1, 1500.0)])
def test_other_pattern_layouts_come_back(tmp_path, pens, boundary, count, unit_ms):
    """Hard boundaries, and one 1500 ms sub-pattern (conditions D–F) split into pieces."""
    pattern = TactilePattern(pens["marker"].meta.tactile.subpatterns[:count], 8000, unit_ms,
                             boundary, 5.0)
    path = export("hjif", tmp_path / "x.hjif", pattern).path
    effects = json.loads(path.read_text())["perceptions"][0]["channels"][0]["bands"][0]["effects"]
    assert len(effects) > len(pattern.subpatterns[0])
    x, y = pattern.samples, load_haptic(path).render(8000)
    inner = slice(20, len(x) - 20)
    error = np.sqrt(np.mean((x[inner] - y[inner]) ** 2) / np.mean(x[inner] ** 2))
    assert error < 0.05, error


def test_creation_dates_are_rfc3339_date_times():
    assert creation_date("2025-03-04T05:06:07+02:00") == "2025-03-04T05:06:07+02:00"
    assert creation_date("2025-03-04T05:06:07") == "2025-03-04T05:06:07Z"
    assert creation_date().endswith("Z") and "T" in creation_date()
    with pytest.raises(ParameterError, match=r"^date: must be an ISO 8601 date or date-time, "
                                             r"got 'yesterday'$"):
        creation_date("yesterday")


# --- the reader on files other tools write ---------------------------------------------------

def hjif_file(tmp_path: Path, band: dict, timescale: int | None = 1000) -> Path:
    document = {"version": "2023", "profile": "Main", "level": 1, "date": "2025-01-01T00:00:00Z",
                "description": "", "avatars": [], "perceptions": [{
                    "id": 0, "avatar_id": 0, "description": "", "perception_modality":
                    "Vibrotactile", "effect_library": [], "channels": [{
                        "id": 0, "description": "", "gain": 0.5, "mixing_coefficient": 1,
                        "bands": [band]}]}]}
    if timescale is not None:
        document["timescale"] = timescale
    path = tmp_path / "other.hjif"
    path.write_text(json.dumps(document))
    return path


def test_a_frequency_glide_renders_as_its_chirp(tmp_path):
    """Two frequency keyframes: the frequency glides linearly, the phase is its integral in
    seconds (not in the reference renderer's milliseconds)."""
    band = {"band_type": "VectorialWave", "lower_frequency_limit": 0,
            "upper_frequency_limit": 1000, "effects": [{
                "effect_type": "Basis", "position": 100, "phase": 0.5, "keyframes": [
                    {"relative_position": 0, "amplitude_modulation": 1.0,
                     "frequency_modulation": 100},
                    {"relative_position": 400, "amplitude_modulation": 1.0,
                     "frequency_modulation": 300}]}]}
    clip = load_haptic(hjif_file(tmp_path, band, timescale=2000))
    assert clip.duration_s == pytest.approx(501 / 2000)
    y = clip.render(8000)
    t = np.arange(len(y)) / 8000 - 0.05  # s from the effect's position (100 ticks at 2000/s)
    inside = (t >= 0) & (t <= 0.2)
    expected = 0.5 * np.sin(0.5 + 2 * np.pi * (100 * t + 0.5 * (200 / 0.2) * t ** 2))
    assert np.max(np.abs(y[inside] - expected[inside])) < 1e-9
    assert not np.any(y[~inside])


def test_default_timescale_base_signals_curves_and_transients(tmp_path):
    square = {"band_type": "VectorialWave", "lower_frequency_limit": 0,
              "upper_frequency_limit": 100, "effects": [{
                  "effect_type": "Basis", "base_signal": "Square", "keyframes": [
                      {"relative_position": 0, "amplitude_modulation": 1.0,
                       "frequency_modulation": 10},
                      {"relative_position": 999}]}]}
    y = load_haptic(hjif_file(tmp_path, square, timescale=None)).render(1000)
    assert len(y) == 1000 and set(np.round(y, 9)) == {0.5, -0.5}  # gain 0.5, 1000 ticks/s
    curve = {"band_type": "Curve", "curve_type": "Linear", "lower_frequency_limit": 0,
             "upper_frequency_limit": 0, "effects": [{
                 "effect_type": "Basis", "position": 0, "keyframes": [
                     {"relative_position": 0, "amplitude_modulation": 0.0},
                     {"relative_position": 100, "amplitude_modulation": 1.0}]}]}
    y = load_haptic(hjif_file(tmp_path, curve)).render(1000)
    assert np.allclose(y, 0.5 * np.arange(101) / 100)
    transient = {"band_type": "Transient", "lower_frequency_limit": 0,
                 "upper_frequency_limit": 0, "effects": [{
                     "effect_type": "Basis", "position": 10, "keyframes": [
                         {"relative_position": 0, "amplitude_modulation": 0.8}]}]}
    y = load_haptic(hjif_file(tmp_path, transient)).render(1000)
    burst = 0.5 * 0.8 * np.sin(4 * np.pi * np.arange(23) / 22)
    assert np.allclose(y[10:33], burst) and not np.any(y[:10])


@pytest.mark.parametrize("change,expected", [
    (lambda band: band.update(band_type="WaveletWave"),
     "perceptions[0].channels[0].bands[0].band_type: WaveletWave bands are not read"),
    (lambda band: band["effects"][0].update(effect_type="Reference"),
     "bands[0].effects[0].effect_type: Reference effects are not read"),
    (lambda band: band["effects"][0]["keyframes"][0].update(amplitude_modulation=2),
     "keyframes[0].amplitude_modulation: must be from -1 to 1, got 2"),
    (lambda band: band["effects"][0]["keyframes"].reverse(),
     "keyframes[1].relative_position: keyframes must be in time order (0 after 400)"),
    (lambda band: band["effects"][0].update(phase="0"),
     "effects[0].phase: must be a number, got '0'"),
    (lambda band: band.pop("effects"), "bands[0].effects: is missing"),
    (lambda band: band.update(band_type="Curve", curve_type=5), "bands[0].curve_type: must be "
                                                                 "text, got 5"),
    (lambda band: (band.update(band_type="Curve"),
                   [k.pop("amplitude_modulation") for k in band["effects"][0]["keyframes"]]),
     "effects[0].keyframes: a Curve effect needs keyframes with amplitude_modulation"),
    (lambda band: band["effects"][0]["keyframes"][1].update(relative_position=2**40),
     "plays 1.09951e+09 s; RealPen reads haptic files of at most 3600 s"),
])
def test_malformed_files_are_refused_in_one_line(tmp_path, change, expected):
    band = {"band_type": "VectorialWave", "lower_frequency_limit": 0,
            "upper_frequency_limit": 1000, "effects": [{
                "effect_type": "Basis", "position": 0, "keyframes": [
                    {"relative_position": 0, "amplitude_modulation": 1.0,
                     "frequency_modulation": 100},
                    {"relative_position": 400, "amplitude_modulation": 1.0}]}]}
    change(band)
    path = hjif_file(tmp_path, band)
    with pytest.raises(RealPenError) as info:
        load_haptic(path)
    message = str(info.value)
    assert message.startswith(f"{path}: ") and "\n" not in message
    assert expected in message, message


def test_a_render_is_refused_when_the_effects_span_too_much(tmp_path, pens, monkeypatch):
    from realpen.exports.readers import hjif as reader

    clip = load_haptic(export("hjif", tmp_path / "p.hjif", pens["pencil"]).path)
    monkeypatch.setattr(reader, "MAX_RENDER_SAMPLES", 100_000)
    with pytest.raises(RealPenError, match=r"p\.hjif: its \d+ effects span [\d.]+ s in all: "
                                           r"[\d,]+ samples at 8000 Hz; RealPen renders at most "
                                           r"100,000$"):
        clip.render(8000)
