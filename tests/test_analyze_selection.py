"""`realpen analyze`, `realpen tactile` and `rp.analyze` select the same units (issue 21, item 6):
the README's example (units 100–114 of 120), and an odd number of units."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import run_cli

import realpen as rp
from realpen.examples import example_recording_path
from realpen.io.recording import load_recording, save_npz


@pytest.fixture(scope="module")
def recordings(tmp_path_factory):
    """The README's example, and the same cut to 113 units and a half (an odd count)."""
    example = load_recording(example_recording_path())
    odd = tmp_path_factory.mktemp("odd") / "odd.npz"
    save_npz(example.with_samples(example.samples[:113 * 134 + 67], "cut"), odd)
    return {"example": example_recording_path(), "odd": odd}


@pytest.mark.parametrize("which, units", [("example", 120), ("odd", 113)])
def test_the_command_line_and_python_select_the_same_units(recordings, tmp_path, which, units):
    path = recordings[which]
    analyzed = run_cli("analyze", path, "--json", tmp_path / "analysis.json")
    assert analyzed.returncode == 0, analyzed.stderr
    report = json.loads((tmp_path / "analysis.json").read_text())
    assert len(report["units"]) == units
    built = run_cli("tactile", path, "--model", "sines", "-o", tmp_path / "pattern.wav",
                    "--json", tmp_path / "pattern.json")
    assert built.returncode == 0, built.stderr
    tactile = json.loads((tmp_path / "pattern.json").read_text())["analysis"]["selected_units"]
    recording = load_recording(path)
    in_python = [int(i) for i in rp.analyze(recording).selected]
    pattern = rp.tactile_pattern(recording, model="sines")
    from_recording = pattern.report()["analysis"]["selected_units"]
    assert report["selected"] == tactile == in_python == from_recording
    assert len(in_python) == 15 and in_python[0] >= 1 and in_python[-1] <= units - 2
    if which == "example":
        assert in_python[0] == 100  # what `realpen analyze` printed before, and prints now
        first, last = in_python[0], in_python[-1]
        assert f"selected units {first}–{last}" in " ".join(analyzed.stdout.split())


def test_an_array_with_its_rate_selects_as_its_file(recordings):
    recording = load_recording(recordings["odd"])
    from_array = rp.analyze(recording.samples, rate=recording.rate)
    assert np.array_equal(from_array.selected, rp.analyze(recording).selected)
    middle = rp.analyze(recording, selection="middle").selected
    assert middle[0] == 1 + (113 - 2 - 15) // 2  # the method's middle run, the same in both
