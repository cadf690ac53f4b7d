"""Pen profile bundles: round trips, broken bundles, format 1, canonical versions, the bundled
pens (regenerated within tolerances), the CLI."""

from __future__ import annotations

import json
import math
import zipfile
from pathlib import Path

import numpy as np
import pytest
import soundfile as sf
from conftest import assert_clean_failure, run_cli

from realpen.errors import ParameterError, RealPenError
from realpen.io.files import wav_bytes
from realpen.pens import BUNDLE_ACTUATOR, BUNDLED_PENS, bundled_dir
from realpen.pens.build import build_modelled_pen, write_model_recordings
from realpen.profile import schema
from realpen.profile.build import build_profile, profile_from_parts
from realpen.profile.bundle import PenProfile, save_profile
from realpen.profile.compare import spectral_distance_db
from realpen.profile.registry import load_profile, resolve_profile
from realpen.tactile.actuator import Actuator, parse_actuator
from realpen.tactile.pattern import TactilePattern, json_fields

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    folder = tmp_path_factory.mktemp("model")
    return build_modelled_pen("marker", folder, "lra:f0=200,q=5", seed=11)


def same_profile(a, b) -> None:
    assert a.meta == b.meta
    assert np.array_equal(a.tactile, b.tactile) and np.array_equal(a.sound, b.sound)
    assert a.version == b.version


def test_round_trip_folder_and_zip(built, tmp_path):
    folder = save_profile(built, tmp_path / "marker")
    archive = save_profile(built, tmp_path / "marker.zip")
    from_folder, from_zip = load_profile(folder), load_profile(archive)
    same_profile(built, from_folder)
    same_profile(from_folder, from_zip)
    first = from_folder.meta.tactile.subpatterns[0][0]
    assert first.frequency_hz == built.meta.tactile.subpatterns[0][0].frequency_hz
    assert from_folder.meta.coupling == built.meta.coupling


def test_saving_over_an_existing_bundle_replaces_it(built, tmp_path):
    target = tmp_path / "pen"
    save_profile(built, target)
    (target / "tactile.wav").write_bytes(b"stale")
    save_profile(built, target)
    same_profile(built, load_profile(target))
    assert [p.name for p in tmp_path.iterdir()] == ["pen"]  # no staging folders left behind


def test_a_folder_holding_other_files_is_never_replaced(built, tmp_path):
    target = tmp_path / "thesis"
    target.mkdir()
    (target / "chapter1.txt").write_text("precious")
    with pytest.raises(RealPenError, match="holding other files"):
        save_profile(built, target)
    assert (target / "chapter1.txt").read_text() == "precious"
    assert sorted(p.name for p in target.iterdir()) == ["chapter1.txt"]


def break_bundle(folder: Path, case: str) -> str:
    """Damage a saved bundle; return the text the error must contain."""
    document = json.loads((folder / "profile.json").read_text())
    if case == "missing_wav":
        (folder / "sound.wav").unlink()
        return "missing sound.wav"
    if case == "unknown_format":
        document["format"] = 4
        (folder / "profile.json").write_text(json.dumps(document))
        return "unknown profile format 4"
    if case == "schema":
        del document["tactile"]["subpatterns"]
        (folder / "profile.json").write_text(json.dumps(document))
        return "tactile.subpatterns"
    if case == "nan_phase":
        document["tactile"]["subpatterns"][0][0]["phase"] = float("nan")
        (folder / "profile.json").write_text(json.dumps(document))
        return "NaN is not a number"
    if case == "overflowing_phase":  # 1e999 is valid JSON that Python reads as inf
        document["tactile"]["subpatterns"][0][0]["phase"] = "OVERFLOW"
        (folder / "profile.json").write_text(json.dumps(document).replace('"OVERFLOW"', "1e999"))
        return "phase"
    if case == "empty_subpattern":
        document["tactile"]["subpatterns"][1] = []
        (folder / "profile.json").write_text(json.dumps(document))
        return "subpatterns.1"
    if case == "lengths_disagree":
        document["tactile"]["subpatterns"] = document["tactile"]["subpatterns"][:3]
        (folder / "profile.json").write_text(json.dumps(document))
        return "are 2400 frames, not 12000"
    if case == "bad_actuator":
        document["actuator"]["params"]["q"] = -1
        (folder / "profile.json").write_text(json.dumps(document))
        return "actuator: "
    if case == "bad_coupling":
        document["coupling"]["a_max"] = 0
        (folder / "profile.json").write_text(json.dumps(document))
        return "coupling: a_max"
    if case == "format_true":
        document["format"] = True
        (folder / "profile.json").write_text(json.dumps(document))
        return "unknown profile format True"
    if case == "not_json":
        (folder / "profile.json").write_text("{not json")
        return "not valid JSON"
    if case == "other_wav":
        samples, rate = sf.read(folder / "tactile.wav", dtype="float32")
        (folder / "tactile.wav").write_bytes(wav_bytes(samples * 0.5, rate))
        return "tactile.wav does not match profile.json"
    if case == "wrong_rate":
        samples, _ = sf.read(folder / "tactile.wav", dtype="float32")
        data = wav_bytes(samples, 16000)
        (folder / "tactile.wav").write_bytes(data)
        import hashlib
        document["files"]["tactile"]["sha256"] = hashlib.sha256(data).hexdigest()
        (folder / "profile.json").write_text(json.dumps(document))
        return "at 16000 Hz; profile.json says"
    raise AssertionError(case)


CASES = ["missing_wav", "unknown_format", "schema", "not_json", "other_wav", "wrong_rate",
         "nan_phase", "overflowing_phase", "empty_subpattern", "lengths_disagree", "format_true",
         "bad_actuator", "bad_coupling"]


@pytest.mark.parametrize("case", CASES)
def test_broken_bundles_are_refused_in_one_line(built, tmp_path, case):
    folder = save_profile(built, tmp_path / "pen")
    expected = break_bundle(folder, case)
    with pytest.raises(RealPenError) as info:
        load_profile(folder)
    message = str(info.value)
    assert expected in message and str(folder) in message and "\n" not in message
    # The same damage inside a zip is refused the same way.
    archive = tmp_path / "pen.zip"
    with zipfile.ZipFile(archive, "w") as handle:
        for file in folder.iterdir():
            handle.write(file, file.name)
    with pytest.raises(RealPenError, match=expected.split(";")[0].replace("(", r"\(")):
        load_profile(archive)


@pytest.mark.parametrize("reference", ["nothere.ZIP", "nothere.zip", "nothere", "a/nothere",
                                       "", " "])
def test_one_resolver_words_one_mistake_one_way(reference, monkeypatch, tmp_path):
    """load_profile, resolve_profile and the command line resolve a profile in one place, so a
    missing profile reads the same whichever way it was asked for."""
    import realpen

    monkeypatch.chdir(tmp_path)
    messages = set()
    for load in (realpen.load_profile, load_profile, resolve_profile):
        with pytest.raises(RealPenError) as caught:
            load(reference)
        messages.add(str(caught.value))
    assert len(messages) == 1, messages
    if reference == "nothere.ZIP":
        assert messages == {"nothere.ZIP: no such profile (folder or .zip)"}


def test_the_registry_finds_the_bundled_pens_where_the_pens_package_keeps_them():
    from realpen.profile.registry import bundled_profiles_dir

    assert bundled_profiles_dir() == bundled_dir()


def test_not_a_bundle(tmp_path):
    with pytest.raises(RealPenError, match="no such profile"):
        load_profile(tmp_path / "nothing")
    junk = tmp_path / "junk.zip"
    junk.write_text("not a zip")
    with pytest.raises(RealPenError, match="not a profile folder or a readable .zip"):
        load_profile(junk)


def test_bundled_pens_load_and_are_modelled():
    for name in BUNDLED_PENS:
        profile = resolve_profile(name)
        assert profile.name == name and profile.meta.actuator.spec == BUNDLE_ACTUATOR
        assert "not a recording" in profile.meta.description
        assert profile.meta.provenance.model["pen"]["name"] == name
        assert len(profile.meta.tactile.subpatterns) == 15
        assert profile.meta.sound.seam["level_jump_db"] < 1.0


# Tolerances for a regenerated bundled pen against the shipped one. numpy/scipy versions and
# CPUs change the last bits of floats (seen: 2e-16 relative in frequencies, 1e-13 rad in phases
# accumulated along a track); these bounds are far above that and far below anything audible.
COMPONENT_TOLERANCES = {  # field: (relative, absolute)
    "frequency_hz": (1e-6, 0.0),   # Hz, relative
    "amplitude": (0.0, 1e-6),      # full scale
    "phase": (0.0, 1e-6),          # rad, compared around the circle
    "power": (1e-6, 0.0),          # recording unit², relative
    "weight": (1e-6, 0.0),         # relative
}
ROUNDED_TOLERANCE = 1.5e-4  # seam and loop scores are stored rounded to 4 decimals
FLOAT_TOLERANCE = (1e-9, 1e-12)  # any other float (relative, absolute)
WAV_TOLERANCE = 1e-5  # full scale, per sample, both WAVs


def assert_close_documents(fresh, shipped, path=""):
    """Equal structure and non-float values; floats within the tolerances above."""
    if isinstance(shipped, dict):
        assert isinstance(fresh, dict) and set(fresh) == set(shipped), path
        for key in shipped:
            assert_close_documents(fresh[key], shipped[key], f"{path}.{key}")
        return
    if isinstance(shipped, list):
        assert isinstance(fresh, list) and len(fresh) == len(shipped), path
        for index, (a, b) in enumerate(zip(fresh, shipped)):
            assert_close_documents(a, b, f"{path}.{index}")
        return
    if isinstance(shipped, float) and isinstance(fresh, (int, float)) \
            and not isinstance(fresh, bool):
        key = path.rsplit(".", 1)[-1]
        rel, tol = COMPONENT_TOLERANCES.get(key, FLOAT_TOLERANCE)
        if ".seam." in path or ".scores." in path:
            rel, tol = 0.0, ROUNDED_TOLERANCE
        difference = abs(fresh - shipped)
        if key == "phase":
            difference = abs((fresh - shipped + math.pi) % (2 * math.pi) - math.pi)
        assert difference <= max(tol, rel * abs(shipped)), (path, fresh, shipped)
        return
    assert fresh == shipped, (path, fresh, shipped)


def test_bundled_pens_regenerate_within_tolerances_and_with_the_same_version(tmp_path):
    for name in BUNDLED_PENS:
        scratch = tmp_path / f"scratch_{name}"
        scratch.mkdir()
        fresh_path = save_profile(build_modelled_pen(name, scratch, BUNDLE_ACTUATOR),
                                  tmp_path / name)
        fresh, shipped = load_profile(fresh_path), load_profile(bundled_dir() / name)
        fresh_doc = json.loads((fresh_path / "profile.json").read_text())
        shipped_doc = json.loads((bundled_dir() / name / "profile.json").read_text())
        for document in (fresh_doc, shipped_doc):  # the WAVs' hashes follow the samples below
            for wav in document["files"].values():
                wav.pop("sha256")
        assert_close_documents(fresh_doc, shipped_doc, name)
        for part in ("tactile", "sound"):
            a, b = getattr(fresh, part), getattr(shipped, part)
            assert a.shape == b.shape and np.max(np.abs(a - b)) <= WAV_TOLERANCE, (name, part)
        assert fresh.version == shipped.version, name


def test_bundled_pens_are_the_current_format():
    """Format 2: the lowest that holds a pen without residual and grid (format 3 holds those)."""
    assert schema.FORMAT == 3
    for name in BUNDLED_PENS:
        document = json.loads((bundled_dir() / name / "profile.json").read_text())
        assert document["format"] == 2


def test_bundled_pens_reproduce_the_methods_observation():
    pens = {name: resolve_profile(name) for name in BUNDLED_PENS}
    pencil_marker = spectral_distance_db(pens["pencil"], pens["marker"])
    ballpoint_pencil = spectral_distance_db(pens["ballpoint"], pens["pencil"])
    ballpoint_marker = spectral_distance_db(pens["ballpoint"], pens["marker"])
    # The ballpoint stands apart; pencil and marker are alike.
    assert ballpoint_pencil > 2 * pencil_marker
    assert ballpoint_marker > 2 * pencil_marker


def test_cli_build_list_show(tmp_path):
    vibration, sound = write_model_recordings("pencil", tmp_path)
    out = tmp_path / "mine"
    result = run_cli("profile", "build", "--name", "mine", "--tool", "pencil", "--vibration",
                     vibration, "--sound", sound, "--actuator", "lra:f0=175,q=4", "--condition",
                     "A", "-o", out)
    assert result.returncode == 0, result.stderr
    profile = load_profile(out)
    assert all(len(sub) == 5 for sub in profile.meta.tactile.subpatterns)
    assert {s.role for s in profile.meta.provenance.sources} == {"vibration", "sound"}
    assert run_cli("profile", "build", "--name", "mine", "--vibration", vibration, "--sound", sound,
                   "-o", tmp_path / "mine.zip").returncode == 0
    listing = run_cli("profile", "list", "--profiles", tmp_path)
    assert listing.returncode == 0
    for name in (*BUNDLED_PENS, "mine"):
        assert name in listing.stdout
    png = tmp_path / "show.png"
    shown = run_cli("profile", "show", str(out), "--plot", png)
    assert shown.returncode == 0, shown.stderr
    assert png.stat().st_size > 10_000 and png.read_bytes()[:4] == b"\x89PNG"


def test_cli_build_bad_input_leaves_nothing(tmp_path):
    vibration, sound = write_model_recordings("pencil", tmp_path)
    out = tmp_path / "bad"
    result = run_cli("profile", "build", "--name", "bad", "--vibration", tmp_path / "none.wav",
                     "--sound", sound, "-o", out)
    assert_clean_failure(result, "none.wav")
    silent = tmp_path / "silent.wav"
    sf.write(silent, np.zeros(48000), 48000)
    result = run_cli("profile", "build", "--name", "bad", "--vibration", vibration, "--sound",
                     silent, "-o", out)
    assert_clean_failure(result, "silent.wav")
    result = run_cli("profile", "show", "no-such-pen")
    assert_clean_failure(result, "no-such-pen")
    assert not out.exists()
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".bad")]


def test_profile_from_real_recordings(hatt_dir, lmt_dir, tmp_path):
    """HaTT paper model for vibration, LMT-108 Rough Paper for sound; never bundled."""
    from realpen.datasets.hatt import load_hatt, synthesize
    from realpen.sound.loop import load_sound
    vibration = synthesize(load_hatt(hatt_dir / "Models_Resume Paper.xml"), 100.0, 1.5, 4.0, seed=2)
    sound = load_sound(lmt_dir / "G8RoughPaper_Sound_Movement_train1.wav")
    profile = build_profile("resume-paper", "stylus", vibration, sound,
                            parse_actuator("lra:f0=175,q=8"))
    saved = load_profile(save_profile(profile, tmp_path / "real.zip"))
    same_profile(profile, saved)
    # The exports take it like a bundled pen.
    from realpen.exports import FORMATS, export_profile
    for fmt in FORMATS:
        out = tmp_path / f"real{FORMATS[fmt].SUFFIX}"
        export_profile(saved, fmt, out)
        assert out.stat().st_size > 100
    assert profile.meta.sound.seam["level_jump_db"] < 1.0
    assert profile.meta.provenance.sources[1].name == "G8RoughPaper_Sound_Movement_train1.wav"
    assert not any(Path(ROOT, "src").rglob("*RoughPaper*"))


def test_cli_user_text_is_not_markup_and_plot_type_is_checked(tmp_path):
    vibration, sound = write_model_recordings("marker", tmp_path)
    out = tmp_path / "felt"
    result = run_cli("profile", "build", "--name", "felt", "--tool", "felt [/] tip", "--description",
                     "see [/b] notes", "--vibration", vibration, "--sound", sound, "-o", out)
    assert result.returncode == 0, result.stderr
    shown = run_cli("profile", "show", str(out))
    assert shown.returncode == 0 and "felt [/] tip" in shown.stdout and "see [/b] notes" in shown.stdout
    listed = run_cli("profile", "list", "--profiles", tmp_path)
    assert listed.returncode == 0 and "felt [/] tip" in listed.stdout
    assert_clean_failure(run_cli("profile", "show", "pencil", "--plot", tmp_path / "p.txt"), "p.txt")
    assert not (tmp_path / "p.txt").exists()


# --- format 1, the schema, the canonical version ---------------------------------------------

def downgrade_to_format_1(folder: Path) -> None:
    """Rewrite a saved bundle's profile.json as RealPen 0.1 wrote it (format 1)."""
    document = json.loads((folder / "profile.json").read_text())
    files = document.pop("files")
    tactile, sound = document["tactile"], document["sound"]
    document["format"] = 1
    document["tactile"] = {"file": "tactile.wav", "rate": tactile.pop("rate"),
                           "frames": files["tactile"]["frames"],
                           "sha256": files["tactile"]["sha256"], **tactile}
    document["sound"] = {"file": "sound.wav", "rate": sound.pop("rate"),
                         "frames": sound.pop("frames"), "sha256": files["sound"]["sha256"],
                         **sound}
    document["actuator"].setdefault("table_hz", None)
    document["actuator"].setdefault("table_response", None)
    (folder / "profile.json").write_text(json.dumps(document, indent=2))


def test_format_1_bundles_still_load(built, tmp_path):
    folder = save_profile(built, tmp_path / "old")
    downgrade_to_format_1(folder)
    assert json.loads((folder / "profile.json").read_text())["format"] == 1
    old = load_profile(folder)
    same_profile(built, old)  # the same pen, the same version
    # Saving it again writes format 2.
    again = save_profile(old, tmp_path / "new")
    assert json.loads((again / "profile.json").read_text())["format"] == 2
    same_profile(old, load_profile(again))


def test_profile_json_holds_exactly_the_pattern_and_the_actuator(built, tmp_path):
    folder = save_profile(built, tmp_path / "pen")
    document = json.loads((folder / "profile.json").read_text())
    assert list(document) == ["format", "name", "tool", "description", "tactile", "sound",
                              "actuator", "coupling", "files", "provenance"]
    assert document["tactile"] == built.pattern.to_json()
    # A pattern without a residual writes no "residual" key (tests/test_residual.py).
    assert list(document["tactile"]) == [f.name for f in json_fields(TactilePattern)
                                         if f.name not in ("subpatterns", "residual")] \
        + ["subpatterns"]
    assert document["actuator"] == built.actuator.to_json()
    loaded = load_profile(folder)
    assert isinstance(loaded.meta.tactile, TactilePattern) and isinstance(loaded.actuator, Actuator)
    # The pydantic schema is generated from the dataclass, not written beside it.
    assert set(schema.TactileModel.model_fields) == {f.name for f in json_fields(TactilePattern)}
    assert not hasattr(schema, "ActuatorSection") and not hasattr(schema, "ComponentEntry")
    json_schema = schema.ProfileMeta.model_json_schema()
    assert "TactileModel" in json_schema["$defs"] and "ComponentModel" in json_schema["$defs"]


def test_the_pattern_of_a_profile(built):
    pattern = built.pattern
    assert pattern == built.meta.tactile and np.array_equal(pattern.samples, built.tactile)
    assert pattern.actuator.spec == "lra:f0=200,q=5" and pattern.params.condition is None
    assert np.max(np.abs(pattern.render() - built.tactile)) < 1e-6  # float32 WAV vs float64
    assert built.sound_loop.rate == 48000 and np.array_equal(built.sound_loop.samples, built.sound)


def test_version_is_a_canonical_hash(built):
    document = built.meta.model_dump(mode="json")
    assert built.version == schema.profile_version(document)
    component = document["tactile"]["subpatterns"][0][0]
    # The last bits of a float (another numpy, another CPU) do not change the version ...
    component["frequency_hz"] = math.nextafter(component["frequency_hz"], math.inf)
    component["phase"] = component["phase"] * (1 + 3e-15)
    document["files"]["tactile"]["sha256"] = "f" * 64  # nor do the WAVs' bytes
    assert schema.profile_version(document) == built.version
    # ... a change in the 9 significant digits kept does.
    component["frequency_hz"] *= 1 + 1e-6
    assert schema.profile_version(document) != built.version
    # The key order does not matter.
    reordered = dict(reversed(list(built.meta.model_dump(mode="json").items())))
    assert schema.profile_version(reordered) == built.version


def test_names_and_reprs(built, tmp_path):
    with pytest.raises(ParameterError, match="^name: 'bad name' is not a valid") as info:
        profile_from_parts("bad name", "pen", built.pattern, built.sound, 48000,
                           {"unit_ms": 300.0, "crossfade_ms": 10.0, "rms_dbfs": -20.0, "seam": {}},
                           built.coupling, [], {})
    assert info.value.parameter == "name"
    text = repr(built)
    assert text.startswith("PenProfile('marker', 'marker', tactile 15×100 ms at 8000 Hz")
    assert len(text) < 200 and "\n" not in text
    long = PenProfile(built.meta.model_copy(update={"tool": "x" * 300}), built.tactile, built.sound)
    assert len(repr(long)) < 200
    assert load_profile("pencil").name == "pencil"  # a bare name is looked up
    with pytest.raises(RealPenError, match="quill: no such profile"):
        load_profile("quill")


def test_samples_that_do_not_fit_the_pattern_are_not_saved(built, tmp_path):
    import dataclasses

    short = dataclasses.replace(built, tactile=built.tactile[:-8])
    with pytest.raises(ParameterError, match="^tactile: "):
        save_profile(short, tmp_path / "short")
    assert not (tmp_path / "short").exists()


def test_build_profile_takes_a_spec_string(tmp_path):
    from realpen.io.recording import load_recording
    from realpen.sound.loop import load_sound

    vibration, sound = write_model_recordings("pencil", tmp_path)
    profile = build_profile("p", "pencil", load_recording(vibration), load_sound(sound), "flat")
    assert profile.actuator == parse_actuator("flat") and profile.meta.format == 2
