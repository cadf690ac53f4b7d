"""A feel that follows the pen: the vibration grid's weights, its JSON and profile (format 3),
the CLI that builds it (--vibration-grid, --hatt), and the tactile render along a stroke."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import soundfile as sf
from conftest import assert_clean_failure, run_cli
from scipy import signal

from realpen.errors import ParameterError, RealPenError
from realpen.motion.control import control_signals
from realpen.motion.coupling import Coupling
from realpen.motion.trajectory import Trajectory
from realpen.pens import BUNDLED_PENS, bundled_dir
from realpen.profile.build import profile_from_parts
from realpen.profile.bundle import save_profile
from realpen.profile.registry import load_profile
from realpen.tactile.actuator import parse_actuator
from realpen.tactile.grid import GridPoint, VibrationGrid
from realpen.tactile.pattern import Component, TactilePattern
from realpen.tactile.stroke import point_targets, render_tactile_stroke

RATE = 8000


def tone(*freqs: float, subpatterns: int = 3, actuator=None) -> TactilePattern:
    """A pattern of sub-patterns of the given sinusoids (0.3 each)."""
    return TactilePattern([[Component(f, 0.3, 0.1 * k) for k, f in enumerate(freqs)]] * subpatterns,
                          RATE, actuator=actuator)


def plane_grid() -> VibrationGrid:
    """Seven points in the (speed, force) plane: a rectangle's corners and three inside."""
    where = [(20, 0.5), (200, 0.5), (20, 4.0), (200, 4.0), (80, 1.5), (150, 3.0), (60, 3.2)]
    return VibrationGrid(tuple(GridPoint(s, f, tone(100 + 20 * k)) for k, (s, f) in
                               enumerate(where)), reference=4)


# --- weights -------------------------------------------------------------------------------------

def test_weights_are_exactly_the_point_at_a_grid_point():
    grid = plane_grid()
    for index, point in enumerate(grid.points):
        indices, weights = grid.weights(point.speed_mm_s, point.force_n)
        assert indices.tolist() == [index] and weights.tolist() == [1.0]
        gains = grid.gains(point.speed_mm_s, point.force_n)
        assert gains[index] == 1.0 and np.count_nonzero(gains) == 1


def test_weights_are_barycentric_inside_and_clamped_to_the_hull_outside():
    grid = plane_grid()
    rng = np.random.default_rng(0)
    speeds, forces = rng.uniform(20, 200, 500), rng.uniform(0.5, 4.0, 500)
    matrix = grid.weight_matrix(speeds, forces)
    assert np.all(matrix >= 0) and np.allclose(matrix.sum(axis=1), 1.0, atol=1e-12)
    assert np.all(np.count_nonzero(matrix, axis=1) <= 3)
    # Inside the hull (here the rectangle) the weights reproduce the point: linear precision.
    assert np.allclose(matrix @ grid.coordinates, np.stack([speeds, forces], axis=1), atol=1e-9)
    # Outside, the nearest point of the hull: the rectangle's edge, or its corner.
    indices, weights = grid.weights(300, 2.25)  # right of the right edge, halfway up
    assert indices.tolist() == [1, 3] and np.allclose(weights, [0.5, 0.5])
    assert grid.weights(-50, -3)[0].tolist() == [0]  # beyond the corner: the corner
    assert grid.triangles.shape[1] == 3 and len(grid.triangles) >= 6
    assert grid.scale == (180.0, 3.5)


def test_weights_vary_continuously_between_points():
    """Small steps in (speed, force) make small changes of every weight, along paths that cross
    triangle edges, points and the hull."""
    grid = plane_grid()
    steps = 4000
    t = np.linspace(0, 1, steps)
    paths = [(np.full(steps, 80.0), -1 + 7 * t),  # up through point 4, out of the hull twice
             (-100 + 400 * t, 0.5 + 3.5 * t),  # corner to corner, crossing the hull
             (110 + 120 * np.cos(6.3 * t), 2.2 + 2.5 * np.sin(6.3 * t))]  # around, outside
    for speeds, forces in paths:
        matrix = grid.weight_matrix(speeds, forces)
        step = np.hypot(np.diff(speeds) / 180, np.diff(forces) / 3.5).max()
        jumps = np.abs(np.diff(matrix, axis=0)).max()
        assert jumps < 40 * step, (jumps, step)  # a discontinuity would be a jump near 1
        assert np.allclose(matrix.sum(axis=1), 1.0)


def test_points_on_a_line_and_a_single_point():
    line = VibrationGrid((GridPoint(20, 2, tone(100)), GridPoint(100, 2, tone(200)),
                          GridPoint(60, 2, tone(150))))
    assert line.triangles.shape == (0, 3) and line.scale == (80.0, 1.0)
    indices, weights = line.weights(40, 2)
    assert indices.tolist() == [0, 2] and np.allclose(weights, [0.5, 0.5])
    indices, weights = line.weights(90, 7.5)  # off the line: projected onto it
    assert indices.tolist() == [1, 2] and np.allclose(weights, [0.75, 0.25])
    assert line.weights(500, 2)[0].tolist() == [1] and line.weights(-5, 0)[0].tolist() == [0]
    diagonal = VibrationGrid((GridPoint(0, 0, tone(100)), GridPoint(10, 1, tone(200)),
                              GridPoint(30, 3, tone(150))))
    assert diagonal.triangles.shape == (0, 3)
    indices, weights = diagonal.weights(20, 2)
    assert indices.tolist() == [1, 2] and np.allclose(weights, [0.5, 0.5])
    single = VibrationGrid.single(tone(100))
    for speed, force in ((0, 0), (300, 8), (12.5, 1)):
        assert single.weights(speed, force)[0].tolist() == [0]
        assert single.gains(speed, force).tolist() == [1.0]


def test_grids_refuse_what_cannot_play_in_sync():
    with pytest.raises(ParameterError, match="^points: the pattern of point 1 is 2 sub-patterns"):
        VibrationGrid((GridPoint(20, 1, tone(100)), GridPoint(80, 1, tone(100, subpatterns=2))))
    other_rate = TactilePattern([[Component(100.0, 0.3)]] * 3, 16000)
    with pytest.raises(ParameterError, match="^points: "):
        VibrationGrid((GridPoint(20, 1, tone(100)), GridPoint(80, 1, other_rate)))
    with pytest.raises(ParameterError, match="both at 20 mm/s, 1 N"):
        VibrationGrid((GridPoint(20, 1, tone(100)), GridPoint(20, 1, tone(200))))
    with pytest.raises(ParameterError, match="^reference: "):
        VibrationGrid((GridPoint(20, 1, tone(100)),), reference=1)
    with pytest.raises(ParameterError, match="^points: a grid needs at least one point"):
        VibrationGrid(())
    for speed in (float("nan"), -1.0, float("inf")):
        with pytest.raises(ParameterError, match="^speed_mm_s: "):
            GridPoint(speed, 1, tone(100))
    with pytest.raises(ParameterError, match="^force_n: "):
        plane_grid().weights(50, float("nan"))


def test_json_round_trip():
    grid = plane_grid()
    data = json.loads(json.dumps(grid.to_json()))
    assert list(data) == ["full_pressure_force_n", "reference", "points"]
    assert list(data["points"][0]) == ["speed_mm_s", "force_n", "tactile"]
    again = VibrationGrid.from_json(data)
    assert again == grid and again.version == grid.version and again.reference == 4
    data["points"][0]["extra"] = 1
    with pytest.raises(ParameterError, match="point 0 must hold exactly"):
        VibrationGrid.from_json(data)


# --- profiles ------------------------------------------------------------------------------------

def grid_profile(name: str = "feel"):
    """The pencil's sound and coupling with a three-point grid of tones (reference: the middle)."""
    pencil = load_profile(bundled_dir() / "pencil")
    actuator = parse_actuator("lra:f0=175,q=8")
    patterns = [tone(f, actuator=actuator) for f in (100.0, 150.0, 250.0)]
    grid = VibrationGrid(tuple(GridPoint(s, 2.0, p) for s, p in zip((20, 60, 100), patterns)),
                         reference=1)
    meta = pencil.meta
    section = {"mode": meta.sound.mode, "unit_ms": meta.sound.unit_ms,
               "crossfade_ms": meta.sound.crossfade_ms, "start_s": meta.sound.start_s,
               "rms_dbfs": meta.sound.rms_dbfs, "seam": meta.sound.seam}
    return profile_from_parts(name, "pen", patterns[1], pencil.sound, meta.sound.rate, section,
                              meta.coupling, [], {}, grid=grid)


def test_grid_profile_round_trip_is_format_3(tmp_path):
    profile = grid_profile()
    folder = save_profile(profile, tmp_path / "feel")
    document = json.loads((folder / "profile.json").read_text())
    assert document["format"] == 3 and document["grid"]["reference"] == 1
    assert list(document)[:6] == ["format", "name", "tool", "description", "tactile", "grid"]
    loaded = load_profile(folder)
    assert loaded.meta == profile.meta and loaded.version == profile.version
    grid = loaded.grid
    assert [p.speed_mm_s for p in grid.points] == [20, 60, 100]
    assert grid.reference_pattern is not None and np.array_equal(grid.reference_pattern.samples,
                                                                  loaded.tactile)
    assert all(p.pattern.actuator == loaded.actuator for p in grid.points)
    assert np.allclose(grid.points[2].pattern.samples, tone(250.0).render())
    # Without the grid the same pen is format 2 again.
    plain = profile_from_parts("plain", "pen", profile.pattern, profile.sound, 48000,
                               profile.meta.sound.model_dump(exclude={"rate", "frames"}),
                               profile.coupling, [], {})
    assert plain.meta.format == 2 and "grid" not in plain.meta.model_dump(mode="json")
    assert plain.grid.points[0].pattern == profile.pattern and len(plain.grid.points) == 1


@pytest.mark.parametrize("change, expected", [
    (lambda d: d["grid"].update(reference=7), "grid: reference: must be a point's index"),
    (lambda d: d["grid"]["points"][0]["tactile"]["subpatterns"].pop(), "grid: "),
    (lambda d: d["grid"]["points"][2].update(speed_mm_s=20), "both at 20 mm/s"),
    (lambda d: d["grid"].update(reference=0), "reference point (0) is not the tactile"),
    (lambda d: d.update(format=2), "format: a profile with a grid is format 3, not 2"),
    (lambda d: d["grid"]["points"][1].update(speed_mm_s="fast"), "grid.points.1.speed_mm_s"),
])
def test_a_bad_grid_is_one_line_naming_the_bundle(tmp_path, change, expected):
    folder = save_profile(grid_profile(), tmp_path / "feel")
    document = json.loads((folder / "profile.json").read_text())
    change(document)
    (folder / "profile.json").write_text(json.dumps(document))
    with pytest.raises(RealPenError) as info:
        load_profile(folder)
    message = str(info.value)
    assert message.startswith(f"{folder}: profile.json: ") and "\n" not in message
    assert expected in message, message


def _without_digests(document: dict) -> dict:
    return {**document, "files": {kind: {key: value for key, value in entry.items()
                                         if key != "sha256"}
                                  for kind, entry in document["files"].items()}}


def test_bundled_pens_saved_again_are_the_same(tmp_path):
    # The samples are rendered again in floating point and rounded to 16 bits, so another
    # processor or numpy release may move a sample by one step (and the files' digests with it):
    # everything else must be as shipped.
    for name in BUNDLED_PENS:
        shipped = load_profile(bundled_dir() / name)
        folder = save_profile(shipped, tmp_path / name)
        for file in ("tactile.wav", "sound.wav"):
            saved, saved_rate = sf.read(folder / file, dtype="int16", always_2d=True)
            bundled, bundled_rate = sf.read(bundled_dir() / name / file, dtype="int16",
                                            always_2d=True)
            assert saved_rate == bundled_rate and saved.shape == bundled.shape
            assert np.max(np.abs(saved.astype(int) - bundled.astype(int))) <= 1
        saved_document = json.loads((folder / "profile.json").read_text())
        bundled_document = json.loads((bundled_dir() / name / "profile.json").read_text())
        assert _without_digests(saved_document) == _without_digests(bundled_document)
        assert load_profile(folder).version == shipped.version and shipped.meta.format == 2


# --- the feel along a stroke ---------------------------------------------------------------------

def stroke(speeds: list[float], seconds: float = 1.0, pressure: float = 0.5) -> Trajectory:
    """A straight stroke at 200 events/s: ``seconds`` at each speed in turn (mm/s)."""
    steps = [np.full(int(seconds * 200), v / 200) for v in speeds]
    x = np.concatenate([[0.0], np.cumsum(np.concatenate(steps))])
    t = np.arange(len(x)) / 200
    return Trajectory.checked(t, x, np.zeros(len(x)), np.full(len(x), pressure))


def band_power(samples: np.ndarray, start_s: float, stop_s: float, hz: float) -> float:
    freqs, power = signal.periodogram(samples[int(start_s * RATE):int(stop_s * RATE)], RATE)
    return float(power[np.abs(freqs - hz) < 5].sum())


def test_the_feel_follows_the_speed():
    profile = grid_profile()
    out = render_tactile_stroke(profile.grid, stroke([20, 100, 60]), coupling=profile.coupling)
    assert out.dtype == np.float64 and len(out) == int(3 * RATE) + 1 + 200
    slow, fast, between = (0.3, 0.9), (1.3, 1.9), (2.3, 2.9)
    assert band_power(out, *slow, 100) > 1000 * band_power(out, *slow, 250)
    assert band_power(out, *fast, 250) > 1000 * band_power(out, *fast, 100)
    # Halfway (60 mm/s is a grid point): its own 150 Hz pattern alone.
    assert band_power(out, *between, 150) > 1000 * band_power(out, *between, 250)
    # 40 mm/s: the 100 and 150 Hz points at equal power (gain sqrt(0.5) each).
    mixed = render_tactile_stroke(profile.grid, stroke([40]), coupling=profile.coupling)
    ratio = band_power(mixed, 0.3, 0.9, 100) / band_power(mixed, 0.3, 0.9, 150)
    assert 0.8 < ratio < 1.25 and band_power(mixed, 0.3, 0.9, 250) < 1e-6 * ratio
    alone = render_tactile_stroke(profile.grid.points[0].pattern, stroke([40]),
                                  coupling=profile.coupling)
    share = band_power(mixed, 0.3, 0.9, 100) / band_power(alone, 0.3, 0.9, 100)
    # Equal power (gain sqrt(w), not w), under the grid's mix gain.
    assert share == pytest.approx(0.5 * profile.grid.mix_gain ** 2, abs=0.02)


def test_the_mix_never_peaks_above_the_loudest_loop():
    grid = plane_grid()
    assert 0 < grid.mix_gain < 1  # tones that align at t = 0 would otherwise add up
    assert VibrationGrid.single(tone(100)).mix_gain == 1.0
    loops = np.stack([p.samples for p in grid.patterns])
    loudest = np.max(np.abs(loops))
    rng = np.random.default_rng(3)
    peaks = [np.max(np.abs(grid.mix_gain * (grid.gains(speed, force) @ loops)))
             for speed, force in rng.uniform([0, 0], [220, 4.5], (60, 2))]
    assert max(peaks) <= loudest * (1 + 1e-9)  # the bound is exact, not sampled
    assert max(peaks) > 0.9 * loudest  # and not needlessly low


def test_point_gains_start_at_the_reference_and_hold_while_lifted():
    grid = grid_profile().grid
    t = np.arange(8) * 0.1
    x = np.array([0, 0, 4, 8, 8, 8, 18, 28], dtype=float)
    pressure = np.array([0, 0.5, 0.5, 0.5, 0, 0, 0.5, 0.5])
    targets = point_targets(grid, Trajectory.checked(t, x, np.zeros(8), pressure))
    assert targets[0].tolist() == [0, 1, 0]  # before the pen is down: the reference
    assert np.allclose(targets[3], [np.sqrt(0.5), np.sqrt(0.5), 0])  # 40 mm/s
    assert np.array_equal(targets[4], targets[3]) and np.array_equal(targets[5], targets[3])
    assert targets[6].tolist() == [1, 0, 0]  # touch-down: speed 0, clamped to 20 mm/s
    assert targets[7].tolist() == [0, 0, 1]  # 100 mm/s


def test_a_single_pattern_is_the_loop_gated_as_today():
    """One pattern (a profile without a grid): the loop times the Eq. 1 gain over a_max,
    smoothed, as the live page plays its one tactile loop."""
    pencil = load_profile(bundled_dir() / "pencil")
    trajectory = stroke([30, 80, 0, 50], seconds=0.4)
    coupling = pencil.coupling
    out = render_tactile_stroke(pencil.grid, trajectory, coupling=coupling)
    _, gain, _ = control_signals(trajectory, coupling, pencil.meta.tactile.rate)
    loop = pencil.tactile.astype(np.float64)
    today = gain / coupling.a_max * loop[np.arange(len(gain)) % len(loop)]
    assert np.allclose(out, today, rtol=1e-12, atol=1e-15) and np.abs(out).max() > 0.1
    assert np.allclose(render_tactile_stroke(pencil.pattern, trajectory, coupling=coupling), out)
    # At another rate the loop is rendered at it.
    assert len(render_tactile_stroke(pencil.pattern, trajectory, 16000)) == \
        len(control_signals(trajectory, Coupling(), 16000)[0])


# --- the command line ----------------------------------------------------------------------------

def write_recordings(folder: Path) -> tuple[Path, Path]:
    """Three 2-s vibration WAVs (1344 Hz) dominated by 90, 160 and 300 Hz, a grid CSV naming
    them at 20, 60 and 100 mm/s (one in a subfolder), and a friction sound (48 kHz)."""
    rng = np.random.default_rng(3)
    rate, time = 1344, np.arange(2 * 1344) / 1344
    (folder / "rec").mkdir()
    rows = []
    for speed, hz, name in ((20, 90, "slow.wav"), (60, 160, "rec/mid.wav"),
                            (100, 300, "fast.wav")):
        shake = np.sin(2 * np.pi * hz * time) + 0.05 * rng.standard_normal(len(time))
        sf.write(folder / name, 0.3 * shake, rate, subtype="FLOAT")
        rows.append(f"{speed},2,{name}")
    csv = folder / "grid.csv"
    csv.write_text("speed_mm_s,force_n,path\n" + "\n".join(rows) + "\n")
    b, a = signal.butter(2, [300, 6000], btype="bandpass", fs=48000)
    noise = signal.lfilter(b, a, rng.standard_normal(48000))
    sf.write(folder / "sound.wav", 0.05 * noise / noise.std(), 48000, subtype="FLOAT")
    return csv, folder / "sound.wav"


def strongest_hz(pattern: TactilePattern) -> float:
    sub = pattern.subpatterns[0]
    return max(sub, key=lambda c: c.amplitude * (c.weight or 1) ** -1).frequency_hz


def test_cli_vibration_grid_end_to_end(tmp_path):
    csv, sound = write_recordings(tmp_path)
    out = tmp_path / "feel"
    result = run_cli("profile", "build", "--name", "feel", "--vibration-grid", csv, "--sound",
                     sound, "-o", out, "--condition", "A")
    assert result.returncode == 0, result.stderr
    assert "at 3 points" in result.stdout
    profile = load_profile(out)
    grid = profile.grid
    assert profile.meta.format == 3 and grid.reference == 1  # the middle point
    assert [round(strongest_hz(p.pattern)) for p in grid.points] == [90, 160, 300]
    assert [s.name for s in profile.meta.provenance.sources] == ["slow.wav", "mid.wav",
                                                                 "fast.wav", "sound.wav"]
    shown = run_cli("profile", "show", out)
    assert shown.returncode == 0, shown.stderr
    assert "grid: 3 points, speed 20–100 mm/s, force 2–2 N" in shown.stdout
    assert "tactile model: sines" in shown.stdout
    trajectory = tmp_path / "stroke.csv"
    t = np.arange(0, 1.0, 0.005)
    trajectory.write_text("t,x,y,pressure\n" + "".join(f"{a:.3f},{100 * a:.3f},0,0.5\n"
                                                        for a in t))
    feel = tmp_path / "feel.wav"
    result = run_cli("tactile", "render", out, "--trajectory", trajectory, "-o", feel)
    assert result.returncode == 0, result.stderr
    samples, rate = sf.read(feel)
    assert rate == 8000 and len(samples) > 7000 and np.abs(samples).max() > 0.05
    assert "3 patterns (following speed and force)" in result.stdout
    # The default command still reads a recording.
    result = run_cli("tactile", tmp_path / "slow.wav", "-o", tmp_path / "slow-pattern.wav")
    assert result.returncode == 0, result.stderr
    bad = tmp_path / "bad.csv"
    bad.write_text("speed_mm_s,force_n,path\n20,2,slow.wav\n\n60,2,missing.wav\n")
    result = run_cli("profile", "build", "--name", "x", "--vibration-grid", bad, "--sound",
                     sound, "-o", tmp_path / "x")
    assert_clean_failure(result, f"{bad}: line 4: missing.wav: no such file")


@pytest.mark.slow
def test_cli_hatt_end_to_end(hatt_dir, tmp_path):
    model = hatt_dir / "Models_Book.xml"
    _, sound = write_recordings(tmp_path)
    out = tmp_path / "book.zip"
    result = run_cli("profile", "build", "--name", "book", "--hatt", model, "--sound", sound,
                     "-o", out)
    assert result.returncode == 0, result.stderr
    from realpen.datasets.hatt import load_hatt

    models = load_hatt(model)
    kept = int(np.sum(np.all(models.vertices > 0, axis=1)))
    profile = load_profile(out)
    grid = profile.grid
    assert len(grid.points) == kept and profile.meta.format == 3
    assert sorted((p.speed_mm_s, p.force_n) for p in grid.points) == \
        sorted(map(tuple, models.vertices[np.all(models.vertices > 0, axis=1)].tolist()))
    assert profile.meta.provenance.model["hatt"] == "Book"
    assert any("left out" in note for note in profile.meta.provenance.notes)
    assert "note: " in result.stdout and "left out" in result.stdout
    shown = run_cli("profile", "show", out)
    assert f"grid: {kept} points, from HaTT 'Book'" in shown.stdout
    # The reference is the point nearest the grid's middle, and its pattern is the table.
    middle = np.median(grid.coordinates / grid.scale, axis=0)
    distance = np.sum((grid.coordinates / grid.scale - middle) ** 2, axis=1)
    assert grid.reference == int(np.argmin(distance))
    assert profile.meta.tactile == grid.points[grid.reference].pattern


def test_build_profile_takes_points_and_a_reference(tmp_path):
    from realpen.io.recording import load_recording
    from realpen.profile.build import build_profile, grid_from_recordings
    from realpen.sound.loop import load_sound

    csv, sound = write_recordings(tmp_path)
    recordings = [(20, 2, load_recording(tmp_path / "slow.wav")),
                  (100, 2, load_recording(tmp_path / "fast.wav"))]
    done = []
    profile = build_profile("two", "pen", recordings, load_sound(sound), "flat", reference=1,
                            progress=lambda d, n: done.append((d, n)))
    assert done == [(1, 2), (2, 2)] and profile.grid.reference == 1
    assert round(strongest_hz(profile.pattern)) == 300
    with pytest.raises(ParameterError, match="^reference: "):
        grid_from_recordings(recordings, "flat", reference=2)
    with pytest.raises(ParameterError, match="^points: point 1: force_n"):
        grid_from_recordings([recordings[0], (100, -2, recordings[1][2])], "flat")
    one = build_profile("one", "pen", recordings[:1], load_sound(sound), "flat")
    assert one.meta.format == 2 and one.meta.grid is None  # one point is no grid
    assert replace(one.grid, notes=()).points[0].pattern == one.pattern


def test_a_grid_refuses_patterns_louder_than_full_scale():
    loud = TactilePattern([[Component(100.0 + 10 * k, 1.0) for k in range(4)]] * 3, RATE)
    with pytest.raises(ParameterError, match="point 1.*full"):
        VibrationGrid((GridPoint(20, 1, tone(100)), GridPoint(100, 1, loud)))


def test_every_export_says_it_carries_only_the_reference_point():
    from realpen.exports import FORMATS, render

    profile = grid_profile()
    for fmt in FORMATS:
        limits = render(fmt, profile).limits
        assert any("vibration grid (3 points" in limit and "60 mm/s" in limit
                   for limit in limits), fmt
    single = load_profile(bundled_dir() / "pencil")
    assert not any("grid" in limit for limit in render("wav", single).limits)
