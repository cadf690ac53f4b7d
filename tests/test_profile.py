"""Pen profile bundles: round trips, broken bundles, the bundled pens, the CLI."""

from __future__ import annotations

import json
import shutil
import zipfile
from pathlib import Path

import numpy as np
import pytest
import soundfile as sf

from conftest import assert_clean_failure, run_cli
from realpen.tactile.actuator import parse_actuator
from realpen.profile.compare import spectral_distance_db
from realpen.errors import RealPenError
from realpen.io.files import wav_bytes
from realpen.pens import BUNDLE_ACTUATOR, BUNDLED_PENS, bundled_dir
from realpen.pens.build import build_modelled_pen, write_model_recordings
from realpen.profile.bundle import load_profile, resolve_profile, save_profile

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
        document["format"] = 2
        (folder / "profile.json").write_text(json.dumps(document))
        return "unknown profile format 2"
    if case == "schema":
        del document["tactile"]["subpatterns"]
        (folder / "profile.json").write_text(json.dumps(document))
        return "tactile.subpatterns"
    if case == "nan_phase":
        document["tactile"]["subpatterns"][0][0]["phase"] = float("nan")
        (folder / "profile.json").write_text(json.dumps(document))
        return "phase"
    if case == "empty_subpattern":
        document["tactile"]["subpatterns"][1] = []
        (folder / "profile.json").write_text(json.dumps(document))
        return "subpatterns.1"
    if case == "lengths_disagree":
        document["tactile"]["subpatterns"] = document["tactile"]["subpatterns"][:3]
        (folder / "profile.json").write_text(json.dumps(document))
        return "are 2400 frames, not 12000"
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
        document["tactile"]["sha256"] = hashlib.sha256(data).hexdigest()
        (folder / "profile.json").write_text(json.dumps(document))
        return "at 16000 Hz; profile.json says"
    raise AssertionError(case)


CASES = ["missing_wav", "unknown_format", "schema", "not_json", "other_wav", "wrong_rate",
         "nan_phase", "empty_subpattern", "lengths_disagree", "format_true"]


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


def test_bundled_pens_regenerate_identically(tmp_path):
    for name in BUNDLED_PENS:
        scratch = tmp_path / f"scratch_{name}"
        scratch.mkdir()
        fresh = save_profile(build_modelled_pen(name, scratch, BUNDLE_ACTUATOR), tmp_path / name)
        for file in ("profile.json", "tactile.wav", "sound.wav"):
            assert (fresh / file).read_bytes() == (bundled_dir() / name / file).read_bytes(), (name, file)


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
    from realpen.profile.bundle import build_profile
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
        export_profile(saved, fmt, tmp_path / f"real.{fmt}")
        assert (tmp_path / f"real.{fmt}").stat().st_size > 100
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
