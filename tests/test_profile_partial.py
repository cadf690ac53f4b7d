"""A pen from one recording alone: sound-only and tactile-only profiles, built, bundled, offered
by the live app and exported (issue 21, item 4's `realpen profile build` part)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import assert_clean_failure, run_cli

from realpen.errors import ParameterError, RealPenError
from realpen.examples import example_recording_path
from realpen.pens import bundled_dir
from realpen.profile.build import build_profile
from realpen.profile.bundle import read_bundle, save_profile
from realpen.profile.registry import load_profile

SOUND = bundled_dir() / "pencil" / "sound.wav"  # a sound loop of the bundled pencil


def test_cli_builds_a_sound_only_pen_that_says_so(tmp_path):
    result = run_cli("profile", "build", "--name", "mic-only", "--sound", SOUND,
                     "-o", tmp_path / "mic")
    assert result.returncode == 0, result.stderr
    assert "no tactile part (a sound-only pen)" in result.stdout
    document = json.loads((tmp_path / "mic" / "profile.json").read_text())
    assert document["parts"] == ["sound"] and document["format"] == 3
    profile = read_bundle(tmp_path / "mic")
    assert not profile.has_tactile and profile.has_sound
    assert not np.any(profile.tactile) and np.any(profile.sound)  # the vibration is silence
    shown = run_cli("profile", "show", tmp_path / "mic")
    assert shown.returncode == 0 and "tactile: none (a sound-only pen" in shown.stdout


def test_cli_builds_a_tactile_only_pen(tmp_path):
    result = run_cli("profile", "build", "--name", "accel-only", "--vibration",
                     example_recording_path(), "-o", tmp_path / "accel")
    assert result.returncode == 0, result.stderr
    assert "no sound part (a tactile-only pen)" in result.stdout
    profile = read_bundle(tmp_path / "accel")
    assert profile.has_tactile and not profile.has_sound
    assert np.any(profile.tactile) and not np.any(profile.sound)
    assert profile.meta.sound.rate == 48000 and profile.meta.sound.unit_ms == 300


def test_cli_needs_one_of_the_two(tmp_path):
    result = run_cli("profile", "build", "--name", "nothing", "-o", tmp_path / "none")
    assert_clean_failure(result, "give --sound, a vibration source")
    assert not (tmp_path / "none").exists()


def test_library_refuses_neither_in_python_words():
    with pytest.raises(ParameterError, match="^vibration: and sound are both None"):
        build_profile("nothing", "pen", None, None, "flat")


def test_a_full_pen_is_unchanged_and_parts_are_read_back_as_they_were(tmp_path):
    pencil = load_profile("pencil")
    assert pencil.has_tactile and pencil.has_sound and pencil.meta.parts is None
    document = json.loads((bundled_dir() / "pencil" / "profile.json").read_text())
    assert "parts" not in document  # format 2 bundles keep their bytes and versions
    sound_only = build_profile("s", "pencil", None, pencil.sound_loop, "lra:f0=175,q=8")
    save_profile(sound_only, tmp_path / "s")
    assert read_bundle(tmp_path / "s").version == sound_only.version


def test_the_live_catalog_offers_both_and_plays_silence_for_the_missing_part(tmp_path):
    from realpen.live.catalog import CatalogEntry

    pencil = load_profile("pencil")
    for name, vibration, sound in (("s", None, pencil.sound_loop),
                                   ("t", example_recording_path(), None)):
        save_profile(build_profile(name, "pencil", vibration, sound, "lra:f0=175,q=8"),
                     tmp_path / name)
        entry = CatalogEntry(read_bundle(tmp_path / name), "user")
        entry.check()
        listed = entry.to_json()
        assert listed["sound"]["url"] and listed["tactile"]["url"]
        assert entry.sound_wav and entry.tactile_wav


def test_exports_refuse_a_sound_only_pen_in_one_line(tmp_path):
    import realpen as rp

    pencil = load_profile("pencil")
    sound_only = build_profile("s", "pencil", None, pencil.sound_loop, "lra:f0=175,q=8")
    with pytest.raises(RealPenError, match="sound-only pen .*no tactile pattern to export"):
        rp.export("ahap", tmp_path / "s.ahap", sound_only)
    assert not list(tmp_path.iterdir())


def test_the_schema_reads_parts_strictly(tmp_path):
    from realpen.profile.schema import ProfileMeta

    document = load_profile("pencil").meta.model_dump(mode="json")
    both = ProfileMeta.model_validate({**document, "parts": ["sound", "tactile"]})
    assert both.parts is None and both.format == 2  # both parts: a pen as any other
    one = ProfileMeta.model_validate({**document, "parts": ["tactile"], "format": None})
    assert one.format == 3 and not one.has_sound
    for bad, words in ((["ink"], "parts"), ([], "parts"), (["sound"], "format")):
        with pytest.raises(ValueError, match=words):
            ProfileMeta.model_validate({**document, "parts": bad, "format": 2})
