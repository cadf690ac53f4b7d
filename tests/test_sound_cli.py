"""``realpen sound loop | render | fit`` run as a user runs them, in-process (:func:`conftest.run_cli`)."""

from __future__ import annotations

import contextlib
import io
import json
import runpy
import subprocess
import sys
from pathlib import Path
from unittest import mock

import numpy as np
import pytest
import soundfile as sf
from conftest import LMT_DIR, assert_clean_failure, run_cli
from scipy import signal

from realpen.motion.coupling import Coupling
from realpen.sound.loop import level_db, load_sound, seam_report

RATE = 48000
ROUGH_PAPER = LMT_DIR / "G8RoughPaper_Sound_Movement_train1.wav"
realpen = run_cli


def friction_like(seconds: float, seed: int, rate: int = 44100) -> np.ndarray:
    b, a = signal.butter(2, [300, 6000], btype="bandpass", fs=rate)
    x = signal.lfilter(b, a, np.random.default_rng(seed).standard_normal(int(seconds * rate)))
    return 0.05 * x / x.std()


@pytest.fixture
def recording(tmp_path: Path) -> Path:
    path = tmp_path / "pencil.wav"
    sf.write(path, np.column_stack([friction_like(3.0, 1), friction_like(3.0, 1)]), 44100,
             subtype="PCM_16")
    return path


@pytest.fixture
def trajectory(tmp_path: Path) -> Path:
    """Slow and light (0–0.5 s), fast and hard (0.5–1 s), lifted (1–1.3 s), ordinary after."""
    t = np.arange(0, 1.8, 0.005)
    speed = np.select([t < 0.5, t < 1.0, t < 1.3], [20.0, 120.0, 0.0], 50.0)
    pressure = np.select([t < 0.5, t < 1.0, t < 1.3], [0.3, 0.8, 0.0], 0.5)
    x = np.cumsum(speed * 0.005)
    path = tmp_path / "stroke.csv"
    rows = "\n".join(f"{a:.4f},{b:.4f},{10 + 0.1 * b:.4f},{p:.2f}"
                     for a, b, p in zip(t, x, pressure))
    path.write_text("t,x,y,pressure\n" + rows + "\n")
    return path


def test_sound_loop_writes_a_300_ms_unit_and_its_report(tmp_path, recording):
    done = realpen("sound", "loop", recording, "-o", "loop.wav", "--json", "report.json",
                   cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    loop, rate = sf.read(tmp_path / "loop.wav")
    assert rate == RATE and len(loop) == 14400
    report = json.loads((tmp_path / "report.json").read_text())
    assert set(report["scores"]) == {"level_jump_db", "spectral_db", "stationarity_db",
                                     "quietness_db", "cost"}
    seam = report["seam"]
    assert seam["level_jump_db"] < 1.0 and seam["flux_wrap_db"] <= seam["flux_inside_p95_db"]
    assert report["unit_ms"] == 300 and report["crossfade_ms"] == 10
    assert level_db(loop) == pytest.approx(-20.0, abs=0.01)
    # start_s points at the samples the loop was cut from (after the 10 ms crossfade)
    source = load_sound(recording).mono
    start = int(round(report["start_s"] * RATE))
    np.testing.assert_allclose(loop[480:], source[start + 480:start + 14400] * report["gain"],
                               rtol=1e-5, atol=1e-6)


def smpl_loop_of(data: bytes) -> tuple[int, int, int, int]:
    """(sample period ns, MIDI unity note, loop start, loop end) of a WAV's one smpl loop,
    read here with struct (not with RealPen's own reader)."""
    import struct
    position = 12
    while position + 8 <= len(data):
        name, length = struct.unpack_from("<4sI", data, position)
        if name == b"smpl":
            head = struct.unpack_from("<9I", data, position + 8)
            cue, kind, start, end, fraction, plays = struct.unpack_from("<6I", data,
                                                                         position + 8 + 36)
            assert head[7] == 1 and (cue, kind, fraction, plays) == (0, 0, 0, 0)
            return head[2], head[3], start, end
        position += 8 + length + (length & 1)
    raise AssertionError("no smpl chunk")


@pytest.mark.parametrize("mode", ["loop", "granular"])
def test_a_loop_written_by_sound_loop_declares_its_loop_and_round_trips(tmp_path, recording,
                                                                       mode):
    from realpen.sound.loop import SoundLoop
    done = realpen("sound", "loop", recording, "-o", "loop.wav", "--mode", mode,
                   "--length-ms", "1000", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    frames = sf.info(tmp_path / "loop.wav").frames
    assert smpl_loop_of((tmp_path / "loop.wav").read_bytes()) == (20833, 60, 0, frames - 1)
    assert "Loop Count   : 1" in sf.info(tmp_path / "loop.wav").extra_info
    loaded = load_sound(tmp_path / "loop.wav")
    assert isinstance(loaded, SoundLoop) and loaded.frames == frames
    # given to sound loop again, a ready loop is kept as it is
    done = realpen("sound", "loop", "loop.wav", "-o", "again.wav", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert "the file's own smpl loop" in done.stdout
    again, _ = sf.read(tmp_path / "again.wav")
    assert len(again) == frames and level_db(again) == pytest.approx(-20.0, abs=0.01)


def test_profile_build_accepts_a_loop_written_by_sound_loop(tmp_path, recording):
    from realpen.examples import example_recording_path
    from realpen.profile import load_profile
    assert realpen("sound", "loop", recording, "-o", "loop.wav", cwd=tmp_path).returncode == 0
    loop, _ = sf.read(tmp_path / "loop.wav")
    done = realpen("profile", "build", "--name", "mine", "--vibration", example_recording_path(),
                   "--sound", "loop.wav", "-o", "mine", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    profile = load_profile(tmp_path / "mine")
    assert profile.meta.sound.frames == len(loop) == 14400
    np.testing.assert_allclose(profile.sound, loop, atol=1e-6)  # the loop itself, not re-cut
    assert profile.meta.sound.unit_ms == pytest.approx(300.0)


def test_sound_loop_options_and_granular_mode(tmp_path, recording):
    done = realpen("sound", "loop", recording, "--unit-ms", "250", "--crossfade-ms", "5",
                   "-o", "short.wav", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert sf.info(tmp_path / "short.wav").frames == 12000
    done = realpen("sound", "loop", recording, "--mode", "granular", "--length-ms", "1000",
                   "-o", "grains.wav", "--json", "grains.json", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert sf.info(tmp_path / "grains.wav").frames == RATE
    report = json.loads((tmp_path / "grains.json").read_text())
    assert report["mode"] == "granular" and 0 <= report["start_s"] < report["end_s"] <= 3.0
    # the report's seam figures are those of the file that was written
    texture, _ = sf.read(tmp_path / "grains.wav", dtype="float32")
    seam = seam_report(texture.astype(np.float64), RATE)
    for key, value in report["seam"].items():
        assert getattr(seam, key) == pytest.approx(value, abs=1e-3)


def test_sound_render_follows_speed_and_pressure(tmp_path, recording, trajectory):
    done = realpen("sound", "render", "--sound", recording, "--trajectory", trajectory,
                   "-o", "out.wav", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    out, rate = sf.read(tmp_path / "out.wav")
    assert rate == RATE
    stretch = {name: out[int(a * RATE):int(b * RATE)] for name, a, b in
               (("slow", 0.05, 0.5), ("fast", 0.55, 1.0), ("lifted", 1.05, 1.3),
                ("ordinary", 1.35, 1.8))}
    assert level_db(stretch["fast"]) > level_db(stretch["ordinary"]) > level_db(stretch["slow"])
    assert level_db(stretch["fast"]) - level_db(stretch["slow"]) > 10
    assert np.max(np.abs(stretch["lifted"])) < 1e-3 * np.max(np.abs(stretch["fast"]))


def test_sound_render_with_a_loop_file_a_coupling_and_granular_mode(tmp_path, recording,
                                                                    trajectory):
    assert realpen("sound", "loop", recording, "-o", "loop.wav", cwd=tmp_path).returncode == 0
    Coupling(c_p=0.0, c_op=0.0, c_x=0.01, c_ov=0.0).save(tmp_path / "speed_only.json")
    # the loop WAV declares its loop (smpl chunk), so it is played as it is without --as-loop
    done = realpen("sound", "render", "--sound", "loop.wav", "--trajectory", trajectory,
                   "--coupling", "speed_only.json", "-o", "a.wav", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert "the file as a loop" in done.stdout
    done = realpen("sound", "render", "--sound", "loop.wav", "--as-loop", "--trajectory",
                   trajectory, "--coupling", "speed_only.json", "-o", "b.wav", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "a.wav").read_bytes() == (tmp_path / "b.wav").read_bytes()
    out, _ = sf.read(tmp_path / "a.wav")
    # speed only: 120 mm/s plays at gain 1.2, 50 mm/s at 0.5
    fast, ordinary = out[int(0.6 * RATE):int(RATE)], out[int(1.4 * RATE):int(1.8 * RATE)]
    assert level_db(fast) - level_db(ordinary) == pytest.approx(20 * np.log10(1.2 / 0.5), abs=1)
    done = realpen("sound", "render", "--sound", recording, "--trajectory", trajectory,
                   "--mode", "granular", "-o", "g.wav", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    grains, _ = sf.read(tmp_path / "g.wav")
    fast, slow = grains[int(0.55 * RATE):RATE], grains[int(0.05 * RATE):int(0.5 * RATE)]
    assert level_db(fast) > level_db(slow) + 10


def test_sound_fit_writes_a_coupling_the_app_can_load(tmp_path):
    rng = np.random.default_rng(3)
    pressure, speed = rng.uniform(0.25, 1, 400), rng.uniform(15, 150, 400)
    amplitude = 0.9 * (pressure - 0.2) + 0.012 * (speed - 8) + rng.normal(0, 0.01, 400)
    rows = "\n".join(f"{p:.5f},{v:.4f},{a:.5f}" for p, v, a in zip(pressure, speed, amplitude))
    (tmp_path / "m.csv").write_text("pressure,speed,amplitude\n" + rows + "\n")
    done = realpen("sound", "fit", "m.csv", "-o", "coupling.json", "--value", "8",
                   "--json", "fit.json", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    coupling = Coupling.load(tmp_path / "coupling.json")
    for name, truth in (("c_p", 0.9), ("c_op", 0.2), ("c_x", 0.012), ("c_ov", 8.0)):
        assert getattr(coupling, name) == pytest.approx(truth, rel=0.05)
    report = json.loads((tmp_path / "fit.json").read_text())
    assert report["fixed"] == {"name": "c_ov", "value": 8.0} and report["rows"] == 400


# --- bad input: one line naming the file, exit code 2, nothing written -----------------------

def make_bad_inputs(folder: Path) -> dict[str, Path]:
    bad = {}
    bad["empty"] = folder / "empty.wav"
    bad["empty"].write_bytes(b"")
    bad["not audio"] = folder / "letter.wav"
    bad["not audio"].write_text("Dear reader,\n")
    whole = folder / "whole.wav"
    sf.write(whole, friction_like(1.0, 2), 44100, subtype="PCM_16")
    bad["truncated"] = folder / "truncated.wav"
    bad["truncated"].write_bytes(whole.read_bytes()[:20000])
    whole.unlink()
    x = friction_like(1.0, 3)
    x[1000] = np.inf
    bad["inf"] = folder / "inf.wav"
    sf.write(bad["inf"], x, 44100, subtype="FLOAT")
    bad["short"] = folder / "short.wav"
    sf.write(bad["short"], friction_like(0.2, 4), 44100)
    bad["silence"] = folder / "silence.wav"
    sf.write(bad["silence"], np.zeros(44100), 44100)
    bad["csv given as sound"] = folder / "take.csv"
    bad["csv given as sound"].write_text("t,x\n0,1\n")
    return bad


def assert_refused(done: subprocess.CompletedProcess, name: str, folder: Path,
                   before: set[str]) -> None:
    """One line naming the file, exit code 2, no traceback, and no file left behind."""
    assert_clean_failure(done, name)
    assert {p.name for p in folder.iterdir()} == before, "an output or temporary file was left"


@pytest.mark.parametrize("case", ["missing", "empty", "not audio", "truncated", "inf", "short",
                                  "silence", "csv given as sound"])
def test_sound_loop_refuses_bad_recordings(tmp_path, case):
    bad = make_bad_inputs(tmp_path)
    path = bad.get(case, tmp_path / "missing.wav")
    before = {p.name for p in tmp_path.iterdir()}
    done = realpen("sound", "loop", path.name, "-o", "loop.wav", "--json", "report.json",
                   cwd=tmp_path)
    assert_refused(done, path.name, tmp_path, before)


@pytest.mark.parametrize("content", [
    "",                                              # empty
    "t,x,y\n0,0,0\n0.1,1,0\n",                       # no pressure column
    "t,x,y,pressure\n0,0,0,0.5\n0.1,1,0,firm\n",     # not a number
    "t,x,y,pressure\n0,0,0,0.5\n0.1,nan,0,0.5\n",    # NaN
    "t,x,y,pressure\n0,0,0,0.5\n0.1,1,0\n",          # short row
    "t,x,y,pressure\n0.1,0,0,0.5\n0.05,1,0,0.5\n",   # time goes back
    "t,x,y,pressure\n0,0,0,0.5\n0.1,1,0,2\n",        # pressure above 1
    "\x00\x01\x02binary",                           # not text
])
def test_sound_render_refuses_malformed_trajectories(tmp_path, recording, content):
    (tmp_path / "stroke.csv").write_text(content)
    before = {p.name for p in tmp_path.iterdir()}
    done = realpen("sound", "render", "--sound", recording.name, "--trajectory", "stroke.csv",
                   "-o", "out.wav", cwd=tmp_path)
    assert_refused(done, "stroke.csv", tmp_path, before)


@pytest.mark.parametrize("case", ["silence", "not audio", "missing"])
def test_sound_render_refuses_bad_sounds(tmp_path, trajectory, case):
    bad = make_bad_inputs(tmp_path)
    path = bad.get(case, tmp_path / "missing.wav")
    before = {p.name for p in tmp_path.iterdir()}
    done = realpen("sound", "render", "--sound", path.name, "--trajectory", trajectory.name,
                   "-o", "out.wav", cwd=tmp_path)
    assert_refused(done, path.name, tmp_path, before)


@pytest.mark.parametrize("content", ["{broken", '{"c_x": "fast"}', '{"c_x": 1, "extra": 0}'])
def test_sound_render_refuses_bad_coupling(tmp_path, recording, trajectory, content):
    (tmp_path / "coupling.json").write_text(content)
    before = {p.name for p in tmp_path.iterdir()}
    done = realpen("sound", "render", "--sound", recording.name, "--trajectory", trajectory.name,
                   "--coupling", "coupling.json", "-o", "out.wav", cwd=tmp_path)
    assert_refused(done, "coupling.json", tmp_path, before)


@pytest.mark.parametrize("content", ["pressure,speed\n0.5,10\n",
                                     "pressure,speed,amplitude\n0.5,10,0.2\n0.5,20,0.3\n"
                                     "0.5,30,0.4\n0.5,40,0.5\n0.5,50,0.6\n",
                                     "pressure,speed,amplitude\n0.5,-10,0.2\n"])
def test_sound_fit_refuses_bad_measurements(tmp_path, content):
    (tmp_path / "m.csv").write_text(content)
    before = {p.name for p in tmp_path.iterdir()}
    done = realpen("sound", "fit", "m.csv", "-o", "coupling.json", cwd=tmp_path)
    assert_refused(done, "m.csv", tmp_path, before)


@pytest.mark.parametrize("args,problem", [(["--mode", "frozen"], "--mode"),
                                          (["--unit-ms", "20"], "--unit-ms"),
                                          (["--crossfade-ms", "nan"], "--crossfade-ms")])
def test_sound_loop_refuses_bad_options(tmp_path, recording, args, problem):
    before = {p.name for p in tmp_path.iterdir()}
    done = realpen("sound", "loop", recording.name, "-o", "loop.wav", *args, cwd=tmp_path)
    assert done.returncode == 2 and problem in done.stderr and "Traceback" not in done.stderr
    assert {p.name for p in tmp_path.iterdir()} == before


def test_a_crossfade_longer_than_the_unit_is_refused_naming_flags_only(tmp_path, recording):
    done = realpen("sound", "loop", recording.name, "-o", "loop.wav", "--crossfade-ms", "400",
                   cwd=tmp_path)
    assert done.returncode == 2 and "--crossfade-ms" in done.stderr
    assert "unit_ms" not in done.stderr and "(300 ms)" in done.stderr


@pytest.mark.skipif(not ROUGH_PAPER.exists(),
                    reason=f"LMT-108 Rough Paper recording absent ({ROUGH_PAPER}); it is read "
                           "from ../shared/data, never copied into the repo")
def test_sound_loop_on_lmt108_rough_paper(tmp_path, trajectory):
    done = realpen("sound", "loop", ROUGH_PAPER, "-o", "loop.wav", "--json", "r.json",
                   cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    report = json.loads((tmp_path / "r.json").read_text())
    assert 0 <= report["start_s"] <= 4.8 - 0.31
    assert report["seam"]["level_jump_db"] < 1.0
    assert report["seam"]["flux_wrap_db"] <= report["seam"]["flux_inside_p95_db"]
    done = realpen("sound", "render", "--sound", ROUGH_PAPER, "--trajectory", trajectory,
                   "-o", "rough.wav", cwd=tmp_path)
    assert done.returncode == 0, done.stderr


# --- limits on options, outputs all-or-nothing -----------------------------------------------

def render_args(recording: Path, trajectory: Path, *extra: str) -> list:
    return ["sound", "render", "--sound", recording.name, "--trajectory", trajectory.name,
            "-o", "out.wav", *extra]


@pytest.mark.parametrize("command", ["loop", "loop granular", "render", "render granular"])
@pytest.mark.parametrize("level", ["nan", "inf", "300", "0.1"])
def test_level_must_be_finite_and_at_most_0_dbfs(tmp_path, recording, trajectory, command,
                                                 level):
    mode = ["--mode", "granular"] if command.endswith("granular") else []
    args = (["sound", "loop", recording.name, "-o", "loop.wav", "--json", "r.json"]
            if command.startswith("loop") else render_args(recording, trajectory))
    before = {p.name for p in tmp_path.iterdir()}
    done = realpen(*args, *mode, "--level-dbfs", level, cwd=tmp_path)
    assert_refused(done, "--level-dbfs", tmp_path, before)
    assert "at most 0 dBFS" in done.stderr


@pytest.mark.parametrize("command", ["loop", "render", "render granular"])
@pytest.mark.parametrize("rate", ["100", "222", "7000"])
def test_a_rate_too_low_is_refused_naming_the_minimum(tmp_path, recording, trajectory, command,
                                                      rate):
    mode = ["--mode", "granular"] if command.endswith("granular") else []
    args = (["sound", "loop", recording.name, "-o", "loop.wav", "--json", "r.json"]
            if command == "loop" else render_args(recording, trajectory))
    before = {p.name for p in tmp_path.iterdir()}
    done = realpen(*args, *mode, "--rate", rate, cwd=tmp_path)
    assert_refused(done, "--rate", tmp_path, before)
    assert "too low" in done.stderr and "8000 Hz" in done.stderr


@pytest.mark.parametrize("command", ["loop", "loop granular", "render", "render granular"])
def test_constant_recording_is_refused_as_silence(tmp_path, trajectory, command):
    sf.write(tmp_path / "const.wav", np.full(3 * 44100, 0.5), 44100, subtype="PCM_16")
    mode = ["--mode", "granular"] if command.endswith("granular") else []
    args = (["sound", "loop", "const.wav", "-o", "loop.wav"] if command.startswith("loop")
            else ["sound", "render", "--sound", "const.wav", "--trajectory", trajectory.name,
                  "-o", "out.wav"])
    before = {p.name for p in tmp_path.iterdir()}
    done = realpen(*args, *mode, cwd=tmp_path)
    assert_refused(done, "const.wav", tmp_path, before)
    assert "silent" in done.stderr and "constant" in done.stderr


@pytest.mark.parametrize("args,problem", [
    (["--unit-ms", "nan"], "--unit-ms"), (["--unit-ms", "0"], "--unit-ms"),
    (["--crossfade-ms", "nan"], "--crossfade-ms"), (["--crossfade-ms", "-1"], "--crossfade-ms"),
    (["--grain-ms", "nan"], "--grain-ms"), (["--mode", "granular", "--grain-ms", "inf"],
                                            "--grain-ms"),
    (["--mode", "granular", "--as-loop"], "--as-loop"),
])
def test_sound_render_refuses_bad_lengths(tmp_path, recording, trajectory, args, problem):
    before = {p.name for p in tmp_path.iterdir()}
    done = realpen(*render_args(recording, trajectory), *args, cwd=tmp_path)
    assert_refused(done, problem, tmp_path, before)


def test_sound_render_refuses_a_recording_shorter_than_the_unit_unless_told_it_is_a_loop(
        tmp_path, trajectory):
    sf.write(tmp_path / "short.wav", friction_like(0.2, 5), 44100, subtype="PCM_16")
    before = {p.name for p in tmp_path.iterdir()}
    done = realpen("sound", "render", "--sound", "short.wav", "--trajectory", trajectory.name,
                   "-o", "out.wav", cwd=tmp_path)
    assert_refused(done, "short.wav", tmp_path, before)
    assert "shorter than the 300 ms unit" in done.stderr and "--as-loop" in done.stderr
    done = realpen("sound", "render", "--sound", "short.wav", "--as-loop", "--trajectory",
                   trajectory.name, "-o", "out.wav", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert "the file as a loop" in done.stdout
    help_text = " ".join(realpen("sound", "render", "--help").stdout.split())
    assert "--as-loop" in help_text and "ready loop" in help_text


def test_granular_length_is_bounded_and_the_help_says_so(tmp_path, recording):
    before = {p.name for p in tmp_path.iterdir()}
    done = realpen("sound", "loop", recording.name, "--mode", "granular", "--length-ms", "1e9",
                   "-o", "g.wav", "--json", "g.json", cwd=tmp_path)
    assert_refused(done, "--length-ms", tmp_path, before)
    assert "at most 60000 ms (60 s)" in done.stderr
    help_text = " ".join(realpen("sound", "loop", "--help").stdout.split())
    assert "60000" in help_text and "8000" in help_text


@pytest.mark.parametrize("value,names", [("nan", "--value"), ("inf", "--value"),
                                         ("-inf", "--value"), ("1e308", "m.csv")])
@pytest.mark.parametrize("fix", ["c_ov", "c_op"])
def test_sound_fit_refuses_a_held_value_that_breaks_the_constants(tmp_path, value, names, fix):
    rng = np.random.default_rng(4)
    pressure, speed = rng.uniform(0.25, 1, 100), rng.uniform(15, 150, 100)
    amplitude = 0.9 * (pressure - 0.2) + 0.012 * (speed - 8) + rng.normal(0, 0.01, 100)
    rows = "\n".join(f"{p:.5f},{v:.4f},{a:.5f}" for p, v, a in zip(pressure, speed, amplitude))
    (tmp_path / "m.csv").write_text("pressure,speed,amplitude\n" + rows + "\n")
    before = {p.name for p in tmp_path.iterdir()}
    done = realpen("sound", "fit", "m.csv", "-o", "coupling.json", "--fix", fix,
                   f"--value={value}", "--json", "fit.json", cwd=tmp_path)
    assert_refused(done, names, tmp_path, before)


def test_sound_loop_writes_nothing_when_the_report_cannot_be_written(tmp_path, recording):
    (tmp_path / "reports").mkdir()
    before = {p.name for p in tmp_path.iterdir()}
    done = realpen("sound", "loop", recording.name, "-o", "loop.wav", "--json", "reports",
                   cwd=tmp_path)
    assert_refused(done, "reports", tmp_path, before)
    assert not any((tmp_path / "reports").iterdir())
    done = realpen("sound", "loop", recording.name, "-o", "same", "--json", "same",
                   cwd=tmp_path)
    assert_refused(done, "same", tmp_path, before)


def test_sound_fit_writes_nothing_when_the_report_cannot_be_written(tmp_path):
    rng = np.random.default_rng(5)
    pressure, speed = rng.uniform(0.25, 1, 50), rng.uniform(15, 150, 50)
    amplitude = 0.9 * (pressure - 0.2) + 0.012 * (speed - 8)
    rows = "\n".join(f"{p:.5f},{v:.4f},{a:.5f}" for p, v, a in zip(pressure, speed, amplitude))
    (tmp_path / "m.csv").write_text("pressure,speed,amplitude\n" + rows + "\n")
    (tmp_path / "reports").mkdir()
    before = {p.name for p in tmp_path.iterdir()}
    done = realpen("sound", "fit", "m.csv", "-o", "coupling.json", "--json", "reports",
                   cwd=tmp_path)
    assert_refused(done, "reports", tmp_path, before)


@pytest.mark.parametrize("mode", ["loop", "granular"])
def test_a_report_holding_nan_is_refused_before_the_wav_is_written(tmp_path, recording,
                                                                    monkeypatch, mode):
    from realpen.cli import sound_cmds
    from realpen.errors import RealPenError
    from realpen.sound.loop import SoundLoop

    real = SoundLoop.to_json
    monkeypatch.setattr(SoundLoop, "to_json",
                        lambda self, real=real: {**real(self), "gain": float("nan")})
    before = {p.name for p in tmp_path.iterdir()}
    with pytest.raises(RealPenError, match="r.json: .*NaN or infinite") as caught:
        sound_cmds.loop(recording, tmp_path / "loop.wav", unit_ms=300.0, crossfade_ms=10.0,
                        mode=mode, length_ms=1000.0, grain_ms=50.0, seed=0, rate=48000.0,
                        level_dbfs=-20.0, json_out=tmp_path / "r.json", force=False)
    assert "\n" not in str(caught.value)
    assert {p.name for p in tmp_path.iterdir()} == before


def test_bench_sound_reports_scan_time_and_real_time_factor(tmp_path):
    script = Path(__file__).resolve().parents[1] / "benchmarks" / "bench_sound.py"
    output = io.StringIO()
    argv = [str(script), "--seconds", "1.5", "3", "--repeat", "1"]
    with contextlib.redirect_stdout(output), mock.patch.object(sys, "argv", argv):
        runpy.run_path(str(script), run_name="__main__")
    lines = [line for line in output.getvalue().splitlines() if line.startswith("scan ")]
    assert len(lines) == 2, output.getvalue()
    for line, seconds in zip(lines, ("1.5 s", "3 s")):
        assert seconds in line and " s (" in line and "x real time" in line
