"""``realpen sound loop | render | fit`` run as a user runs them, in a subprocess."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import numpy as np
import pytest
import soundfile as sf
from scipy import signal

from conftest import LMT_DIR, assert_clean_failure, run_cli
from realpen.coupling import Coupling
from realpen.sound import level_db, load_sound, seam_report

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
    done = realpen("sound", "render", "--sound", "loop.wav", "--trajectory", trajectory,
                   "--coupling", "speed_only.json", "-o", "a.wav", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert "the file as a loop" in done.stdout
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
