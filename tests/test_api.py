"""The curated API of ``import realpen as rp``: names, laziness, keyword-only options, reprs."""

from __future__ import annotations

import inspect
import json
import runpy
import subprocess
import sys
from pathlib import Path
from unittest import mock

import numpy as np
import pytest

import realpen as rp
from realpen.examples import example_recording_path

QUICKSTART = Path(__file__).resolve().parents[1] / "docs" / "examples" / "quickstart.py"
SPEC = "lra:f0=175,q=8"


@pytest.fixture(scope="module")
def recording():
    return rp.load_recording(example_recording_path())


@pytest.fixture(scope="module")
def pattern(recording):
    return rp.tactile_pattern(recording, actuator=SPEC)


def test_all_names_are_there():
    assert len(set(rp.__all__)) == len(rp.__all__)
    for name in rp.__all__:
        assert getattr(rp, name) is not None, name
    assert set(rp.__all__) <= set(dir(rp))
    for name in ("load_recording", "analyze", "tactile_pattern", "find_loop", "load_profile",
                 "save_profile", "list_profiles", "load_hatt", "export", "parse_actuator"):
        assert callable(getattr(rp, name)), name
    for name in ("Recording", "TactilePattern", "Actuator", "SoundLoop", "Coupling",
                 "RealPenError", "ParameterError"):
        assert inspect.isclass(getattr(rp, name)), name
    assert issubclass(rp.ParameterError, rp.RealPenError)
    assert issubclass(rp.ParameterError, ValueError)
    assert rp.display.plot_analysis is not None
    assert isinstance(rp.__version__, str)
    with pytest.raises(AttributeError, match="no attribute 'nonsense'"):
        rp.nonsense  # noqa: B018


def test_every_display_function_is_listed():
    from realpen import display

    assert set(display.__all__) >= {"plot_analysis", "plot_actuator", "plot_pattern",
                                    "plot_sound_loop", "profile_figure", "save_profile_plot"}
    for name in display.__all__:
        assert callable(getattr(display, name)), name


IMPORT_CHECKS = """
import contextlib, io, json, sys

def loaded(*names):
    return sorted(n for n in names if n in {m.split(".")[0] for m in sys.modules})

state = {}
import realpen
state["realpen"] = loaded("numpy", "scipy", "matplotlib", "soundfile", "pydantic")
import realpen.profile.schema
state["profile.schema"] = loaded("scipy", "soundfile")
import realpen.live.messages
state["live.messages"] = loaded("scipy", "soundfile")
from realpen.cli import main
with contextlib.redirect_stdout(io.StringIO()) as usage:
    try:
        main(["--help"])
    except SystemExit:
        pass
state["help"] = loaded("scipy", "soundfile", "matplotlib", "fastapi", "uvicorn")
state["help_printed"] = "Usage: realpen" in usage.getvalue()
import realpen.display
state["display_pyplot"] = "matplotlib.pyplot" in sys.modules

# The user picked a backend and made a pyplot figure; drawing with realpen.display keeps both.
import matplotlib
matplotlib.use("svg")
import matplotlib.pyplot as plt
user = plt.figure()
rc_before = {k: str(v) for k, v in matplotlib.rcParams.items()}
realpen.display.plot_actuator("lra:f0=175,q=8")
rc_after = {k: str(v) for k, v in matplotlib.rcParams.items()}
state["backend"] = matplotlib.get_backend()
state["figures"] = plt.get_fignums()
state["rc_changed"] = sorted(k for k in rc_before if rc_before[k] != rc_after[k])
print(json.dumps(state))
"""


@pytest.mark.slow
def test_imports_stay_light_and_display_changes_no_global_state():
    """One fresh interpreter, step by step: what each import pulls in, and matplotlib's state.

    ``import realpen`` loads nothing heavy; the profile and WebSocket schemas load neither scipy
    nor soundfile; ``realpen --help`` loads no scipy, soundfile, matplotlib or FastAPI (so it
    answers at once); ``realpen.display`` imports no pyplot and, drawing, leaves the user's
    backend, figures and rcParams as they were.
    """
    done = subprocess.run([sys.executable, "-c", IMPORT_CHECKS], capture_output=True,
                          text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    state = json.loads(done.stdout)
    assert state == {"realpen": [], "profile.schema": [], "live.messages": [], "help": [],
                     "help_printed": True, "display_pyplot": False, "backend": "svg",
                     "figures": [1], "rc_changed": []}


def positional_parameters(function) -> list[str]:
    return [p.name for p in inspect.signature(function).parameters.values()
            if p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD)]


@pytest.mark.parametrize("name, positional", [
    ("analyze", ["data"]),
    ("tactile_pattern", ["recording"]),
    ("load_recording", ["path"]),
    ("find_loop", ["sound"]),
    ("export", ["fmt", "path", "item"]),
])
def test_options_are_keyword_only(name, positional):
    assert positional_parameters(getattr(rp, name)) == positional


def test_every_plot_takes_ax_and_keyword_only_options():
    for name in rp.display.__all__:
        function = getattr(rp.display, name)
        if not callable(function) or name == "save_profile_plot":
            continue
        parameters = positional_parameters(function)
        assert parameters[-1] == "ax", name
        assert parameters[:-1] == (["samples", "rate"] if name == "plot_sound_spectrum"
                                   else [next(iter(inspect.signature(function).parameters))]), name


def test_positional_options_are_a_type_error(recording):
    with pytest.raises(TypeError):
        rp.analyze(recording, 1344)
    with pytest.raises(TypeError):
        rp.analyze(recording.samples, 1344)
    with pytest.raises(TypeError):
        rp.tactile_pattern(recording, SPEC)
    with pytest.raises(TypeError):
        rp.load_recording(example_recording_path(), 1344)


def test_analyze_array_and_recording_agree(recording):
    from_recording = rp.analyze(recording)
    from_array = rp.analyze(recording.samples, rate=recording.rate)
    np.testing.assert_array_equal(from_array.frequencies_hz, from_recording.frequencies_hz)
    np.testing.assert_array_equal(from_array.powers, from_recording.powers)
    np.testing.assert_array_equal(from_array.selected, from_recording.selected)
    assert from_array.rate == recording.rate == 1344


def test_analyze_options(recording):
    one_axis = recording.samples[:, 0]
    result = rp.analyze(one_axis, rate=1344, unit_ms=50, top=3, count=5, selection="middle",
                        highpass_hz=40, fmax=400)
    assert result.frequencies_hz.shape[1] == 3 and len(result.selected) == 5
    assert result.unit_ms == 50 and result.selection == "middle"
    assert np.nanmin(result.frequencies_hz) >= 40 and np.nanmax(result.frequencies_hz) <= 400


def test_analyze_refuses_an_array_without_rate_in_python_words(recording):
    with pytest.raises(rp.ParameterError, match="^rate: "):
        rp.analyze(recording.samples)
    with pytest.raises(rp.ParameterError, match="^data: "):
        rp.analyze(recording.samples.T, rate=1344)
    with pytest.raises(rp.ParameterError, match="^unit_ms: "):
        rp.analyze(recording, unit_ms=-1)


def test_tactile_pattern_takes_a_spec_string(recording, pattern):
    # This was an AttributeError: build_pattern(rec, "lra:f0=175,q=8").
    assert isinstance(pattern, rp.TactilePattern)
    assert len(pattern.subpatterns) == 15
    assert all(len(sub) == 10 for sub in pattern.subpatterns)
    same = rp.tactile_pattern(recording, actuator=rp.parse_actuator(SPEC))
    np.testing.assert_array_equal(same.render(8000), pattern.render(8000))


def test_tactile_pattern_conditions_and_options(recording):
    e = rp.tactile_pattern(recording, actuator="flat", condition="E")
    assert len(e.subpatterns) == 1 and len(e.subpatterns[0]) == 10
    explicit = rp.tactile_pattern(recording, actuator="flat", condition=None, top=4,
                                  subpatterns=3, unit_ms=100.0, seed=7)
    assert [len(sub) for sub in explicit.subpatterns] == [4, 4, 4]
    with pytest.raises(rp.RealPenError):
        rp.tactile_pattern(recording, condition="Z")


def one_line(obj) -> str:
    text = repr(obj)
    assert "\n" not in text, f"{type(obj).__name__} repr spans lines: {text[:300]}"
    assert len(text) < 200, f"{type(obj).__name__} repr is {len(text)} characters: {text[:300]}"
    return text


def test_reprs_are_one_short_line(recording, pattern):
    one_line(recording)
    one_line(rp.analyze(recording))
    one_line(pattern)
    one_line(pattern.subpatterns[0][0])
    one_line(rp.parse_actuator(SPEC))
    one_line(rp.find_loop(np.random.default_rng(0).normal(0, 0.1, 48000), rate=48000))
    one_line(rp.Coupling())
    one_line(rp.load_profile("pencil"))


def test_export_a_pattern_made_in_python(pattern, tmp_path):
    written = rp.export("ahap", tmp_path / "b.ahap", pattern)
    document = json.loads((tmp_path / "b.ahap").read_text())
    assert "Pattern" in document
    assert Path(getattr(written, "path", tmp_path / "b.ahap")).exists()


@pytest.mark.slow
def test_quickstart_script_runs(tmp_path):
    with mock.patch.object(sys, "argv", [str(QUICKSTART), str(tmp_path)]):
        runpy.run_path(str(QUICKSTART), run_name="__main__")
    assert (tmp_path / "quickstart.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "Pattern" in json.loads((tmp_path / "pattern-b.ahap").read_text())
