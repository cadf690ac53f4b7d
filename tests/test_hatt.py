"""Tests of the HaTT importer: real files from ../shared/data (skipped when absent) and small
synthetic files written to tmp_path (always run)."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from scipy import signal

from realpen.datasets.hatt import load_hatt, lsf_to_poly, synthesize
from realpen.errors import ParameterError, RealPenError

HATT = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "hatt_models"


@pytest.fixture(scope="module")
def hatt_files() -> list[Path]:
    files = sorted(HATT.glob("Models_*.xml")) if HATT.is_dir() else []
    if not files:
        pytest.skip(f"HaTT model files not found in {HATT} (research-only data, never in the repo)")
    return files


@pytest.fixture(scope="module")
def book(hatt_files):
    path = HATT / "Models_Book.xml"
    if not path.exists():
        pytest.skip(f"{path} not found")
    return load_hatt(path)


# ---- a small synthetic model set: 5 vertices, 4 triangles, ARMA(4, 2) ----

def _model_xml(num, speed, force, ar_lsf, ma_lsf, var, gain):
    def values(tag, xs):
        return f"<{tag}>" + "".join(f"<value>{float(x)!r}</value>" for x in xs) + f"</{tag}>"
    return (f"<model><modNum>{num}</modNum>{values('ARcoeff', lsf_to_poly(ar_lsf))}"
            f"{values('ARlsf', ar_lsf)}{values('MAcoeff', lsf_to_poly(ma_lsf))}"
            f"{values('MAlsf', ma_lsf)}<var>{var}</var><gain>{gain}</gain>"
            f"<speedMod>{speed}</speedMod><forceMod>{force}</forceMod></model>")


VERTS = [(0.0, 0.0), (200.0, 0.0), (0.0, 4.0), (200.0, 4.0), (100.0, 2.0)]
TRIS = [(1, 2, 5), (2, 4, 5), (4, 3, 5), (3, 1, 5)]  # 1-based, as in HaTT files


def synthetic_xml(tris=TRIS, verts=VERTS, num_mod=None, drop=None, replace=None) -> str:
    models = "".join(
        _model_xml(k + 1, s, f, ar_lsf=[0.3 + 0.2 * k / 5, 0.8, 1.5, 2.2 + 0.1 * k / 5],
                   ma_lsf=[1.0, 2.0 + 0.3 * k / 5], var=0.001 * k, gain=2.0 + k)
        for k, (s, f) in enumerate(verts))
    text = ("<?xml version='1.0'?><modelSet><material>Synthetic</material>"
            "<SampleRate>1000</SampleRate><mu>0.2</mu>"
            f"<numMod>{num_mod or len(verts)}</numMod><numTri>{len(tris)}</numTri>"
            "<maxSpeed>200</maxSpeed><maxForce>4</maxForce>"
            "<speedList>" + "".join(f"<value>{s}</value>" for s, _ in verts) + "</speedList>"
            "<forceList>" + "".join(f"<value>{f}</value>" for _, f in verts) + "</forceList>"
            + "".join("<tri>" + "".join(f"<value>{i}</value>" for i in t) + "</tri>" for t in tris)
            + models + "</modelSet>")
    if drop:
        start = text.index(f"<{drop}>")
        text = text[:start] + text[text.index(f"</{drop}>", start) + len(drop) + 3:]
    if replace:
        text = text.replace(*replace, 1)
    return text


@pytest.fixture
def synthetic(tmp_path) -> Path:
    path = tmp_path / "Models_Synthetic.xml"
    path.write_text(synthetic_xml())
    return path


def _lsf_of(poly: np.ndarray) -> np.ndarray:
    """LSFs by root finding (the textbook definition), for testing lsf_to_poly."""
    ext = np.concatenate([poly, [0.0]])
    angles = []
    for sym in (ext + ext[::-1], ext - ext[::-1]):
        angles.extend(a for a in np.angle(np.roots(sym)) if 1e-6 < a < np.pi - 1e-6)
    return np.sort(angles)


@pytest.mark.parametrize("order", [1, 2, 5, 8, 19, 20])
def test_lsf_to_poly_inverts_the_lsf_definition(order):
    rng = np.random.default_rng(order)
    poles = []
    while len(poles) < order:
        if order - len(poles) >= 2 and rng.random() < 0.7:
            z = rng.uniform(0.2, 0.97) * np.exp(1j * rng.uniform(0.05, np.pi - 0.05))
            poles += [z, np.conj(z)]
        else:
            poles.append(rng.uniform(-0.95, 0.95))
    poly = np.real(np.poly(poles))
    lsf = _lsf_of(poly)
    assert len(lsf) == order and np.all(np.diff(lsf) > 0)
    np.testing.assert_allclose(lsf_to_poly(lsf), poly, atol=1e-8)


# ---- real HaTT files ----

def test_every_file_loads_with_a_valid_triangulation(hatt_files):
    for path in hatt_files:
        s = load_hatt(path)
        n = len(s.models)
        assert s.rate == 1000 and s.vertices.shape == (n, 2) and s.material, path.name
        assert s.triangles.min() >= 0 and s.triangles.max() < n, path.name
        assert set(np.unique(s.triangles)) == set(range(n)), f"{path.name}: unused vertex"
        # the triangles tile the modelled rectangle [0, max speed] x [0, max force]
        c = s.vertices[s.triangles]
        area = 0.5 * np.abs(np.linalg.det(c[:, :2] - c[:, 2:])).sum()
        assert area == pytest.approx(s.max_speed * s.max_force, rel=1e-6), path.name


@pytest.mark.slow
def test_stored_lsfs_give_the_stored_coefficients(hatt_files):
    for path in hatt_files:
        for k, m in enumerate(load_hatt(path).models):
            np.testing.assert_allclose(lsf_to_poly(m.ar_lsf), m.ar, atol=5e-5,
                                       err_msg=f"{path.name} model {k + 1} AR")
            np.testing.assert_allclose(lsf_to_poly(m.ma_lsf), m.ma, atol=5e-5,
                                       err_msg=f"{path.name} model {k + 1} MA")


def test_model_at_a_vertex_is_that_vertex_model(book):
    for k, (speed, force) in enumerate(book.vertices):
        got, want = book.model_at(speed, force), book.models[k]
        np.testing.assert_array_equal(got.ar, want.ar)
        np.testing.assert_array_equal(got.ma, want.ma)
        assert (got.variance, got.gain) == (want.variance, want.gain)
        # a hair away, the LSF interpolation gives (nearly) the same filter
        near = book.model_at(min(speed + 1e-6, book.max_speed), min(force + 1e-9, book.max_force))
        np.testing.assert_allclose(near.ar, want.ar, atol=1e-4)
        assert near.variance == pytest.approx(want.variance, abs=1e-8)


def test_interpolated_models_are_stable_and_clamped(book):
    for speed in np.linspace(0, book.max_speed, 23):
        for force in np.linspace(0, book.max_force, 17):
            m = book.model_at(speed, force)
            assert np.max(np.abs(np.roots(m.ar))) < 1.0
            assert m.variance >= 0 and m.gain > 0
    above = book.model_at(10 * book.max_speed, 10 * book.max_force)
    corner = book.model_at(book.max_speed, book.max_force)
    np.testing.assert_array_equal(above.ar, corner.ar)
    assert book.model_at(-5.0, 2.0).variance == book.model_at(0.0, 2.0).variance == 0.0


def test_synthesis_is_seeded_finite_and_sized(book):
    a = synthesize(book, 150.0, 2.0, 1.5, seed=7)
    b = synthesize(book, 150.0, 2.0, 1.5, seed=7)
    c = synthesize(book, 150.0, 2.0, 1.5, seed=8)
    assert a.rate == 1000 and a.samples.shape == (1500, 1) and a.units == "m/s^2"
    assert "Book" in a.source and "150 mm/s" in a.source and "2 N" in a.source
    assert np.all(np.isfinite(a.samples)) and np.array_equal(a.samples, b.samples)
    assert not np.array_equal(a.samples, c.samples)


@pytest.mark.parametrize("speed, force", [(150.0, 2.0), (240.0, 4.097146), (75.0, 0.9)])
def test_synthesis_variance_matches_the_arma_theory(book, speed, force):
    model = book.model_at(speed, force)
    x = synthesize(book, speed, force, 200.0, seed=3).mono
    assert x.var() == pytest.approx(model.output_variance(), rel=0.10)
    # warm-up discarded: the first second is as strong as the rest
    assert x[:1000].var() == pytest.approx(model.output_variance(), rel=0.5)


def test_spectrum_of_book_moves_up_and_grows_with_speed(book):
    def centroid_and_rms(speed):
        x = synthesize(book, speed, 2.0, 60.0, seed=1).mono
        f, p = signal.welch(x, fs=1000, nperseg=1024)
        return (f * p).sum() / p.sum(), x.std()
    slow, fast = centroid_and_rms(60.0), centroid_and_rms(300.0)
    assert fast[0] > slow[0] + 10.0  # Hz
    assert fast[1] > 1.3 * slow[1]


@pytest.mark.slow
def test_speed_and_force_may_vary_over_time(book):
    constant = synthesize(book, np.full(2000, 150.0), 2.0, 2.0, seed=4)
    np.testing.assert_allclose(constant.samples, synthesize(book, 150.0, 2.0, 2.0, seed=4).samples)
    # blockwise filtering keeps its memory: a negligible ramp gives the constant-speed output
    creep = synthesize(book, np.linspace(150.0, 150.0 + 1e-7, 2000), 2.0, 2.0, seed=4)
    np.testing.assert_allclose(creep.samples, constant.samples, atol=1e-6)
    ramp = synthesize(book, np.linspace(20.0, 300.0, 20000), 2.0, 20.0, seed=4).mono
    assert ramp.shape == (20000,) and np.all(np.isfinite(ramp))
    assert ramp[-4000:].std() > 1.3 * ramp[:4000].std()
    with pytest.raises(RealPenError, match="speed_mm_s"):
        synthesize(book, np.ones(10), 2.0, 2.0)


# ---- synthetic files (always run) ----

def test_synthetic_file_round_trip(synthetic):
    s = load_hatt(synthetic)
    assert s.material == "Synthetic" and s.triangles.min() == 0 and s.triangles.max() == 4
    assert s.model_at(100.0, 2.0) is s.models[4]
    mid = s.model_at(50.0, 1.0)  # middle of the edge from vertex 1 (0, 0) to the centre
    np.testing.assert_allclose(mid.ar_lsf, 0.5 * (s.models[0].ar_lsf + s.models[4].ar_lsf))
    np.testing.assert_allclose(mid.ar, lsf_to_poly(mid.ar_lsf))
    assert mid.gain == pytest.approx(0.5 * (s.models[0].gain + s.models[4].gain))
    centre_of_t1 = s.vertices[[0, 1, 4]].mean(axis=0)
    m = s.model_at(*centre_of_t1)
    np.testing.assert_allclose(m.ar_lsf, np.mean([s.models[i].ar_lsf for i in (0, 1, 4)], axis=0))
    assert m.variance == pytest.approx(np.mean([s.models[i].variance for i in (0, 1, 4)]))
    x = synthesize(s, *centre_of_t1, 100.0, seed=2).mono
    assert x.var() == pytest.approx(m.output_variance(), rel=0.10)
    assert np.all(synthesize(s, 0.0, 0.0, 0.5).samples == 0.0)  # variance 0 at rest


def test_reprs_are_one_short_line(synthetic):
    s = load_hatt(synthetic)
    for obj in (s, s.models[0], s.model_at(50.0, 1.0)):
        text = repr(obj)
        assert "\n" not in text and len(text) < 200, text[:300]
    assert repr(s).startswith("HattModelSet('Synthetic', 5 models at 1000 Hz")


def test_ar_only_models_are_accepted(tmp_path):
    path = tmp_path / "Models_AR.xml"
    path.write_text(re.sub(r"<(MAcoeff|MAlsf|gain)>.*?</\1>", "", synthetic_xml()))
    s = load_hatt(path)
    m = s.model_at(120.0, 3.0)
    assert m.gain == 1.0 and list(m.ma) == [1.0] and len(m.ma_lsf) == 0
    x = synthesize(s, 120.0, 3.0, 100.0, seed=5).mono
    assert x.var() == pytest.approx(m.output_variance(), rel=0.10)


@pytest.mark.parametrize("content, problem", [
    (None, "no such file"),
    ("", "file is empty"),
    ("this is not xml <", "not a valid XML file"),
    ("<?xml version='1.0'?><other/>", "not a HaTT model file"),
    (synthetic_xml(drop="SampleRate"), "missing <SampleRate>"),
    (synthetic_xml(drop="forceList"), "missing <forceList>"),
    (synthetic_xml(replace=("<mu>0.2</mu>", "<mu>abc</mu>")), "<mu> is not numeric"),
    (synthetic_xml(num_mod=6), "<numMod> is 6"),
    (synthetic_xml(tris=[(0, 1, 4), (1, 3, 4)]), "vertex indices must be 1..5"),
    (synthetic_xml(tris=[(1, 2)]), "exactly 3 vertex indices"),
    (synthetic_xml(tris=[(1, 2, 2)]), "degenerate"),
    (synthetic_xml(replace=("<numTri>4</numTri>", "<numTri>5</numTri>")), "<numTri> does not match"),
    (synthetic_xml(replace=("<var>0.0</var>", "<var>-1</var>")), "<var> of model 1 is negative"),
    (synthetic_xml(replace=("<ARlsf><value>0.3</value>", "<ARlsf><value>0.9</value>")),
     "AR LSFs of model 1 are not increasing"),
    (synthetic_xml(replace=("<speedMod>0.0</speedMod>", "<speedMod>50</speedMod>")),
     "model 1 is at (50 mm/s"),
])
def test_bad_files_raise_one_line_errors_naming_the_file(tmp_path, content, problem):
    path = tmp_path / "Models_Bad.xml"
    if content is not None:
        path.write_text(content)
    with pytest.raises(RealPenError) as caught:
        load_hatt(path)
    message = str(caught.value)
    assert "Models_Bad.xml" in message and problem in message and "\n" not in message


def test_bad_synthesis_parameters(synthetic):
    s = load_hatt(synthetic)
    for args, kwargs, parameter in (((100.0, 1.0, 0.0), {}, "duration_s"),
                                    ((100.0, 1.0, 1e-4), {}, "duration_s"),
                                    ((100.0, 1.0, 1e9), {}, "duration_s"),
                                    ((100.0, float("nan"), 1.0), {}, "force_n"),
                                    ((float("inf"), 1.0, 1.0), {}, "speed_mm_s"),
                                    ((np.ones(3), 1.0, 1.0), {}, "speed_mm_s"),
                                    ((100.0, 1.0, 1.0), {"seed": -1}, "seed"),
                                    ((100.0, 1.0, 1.0), {"seed": 1.5}, "seed"),
                                    ((100.0, 1.0, 1.0), {"update_s": 0}, "update_s")):
        with pytest.raises(ParameterError) as caught:
            synthesize(s, *args, **kwargs)
        assert caught.value.parameter == parameter, caught.value
        assert str(caught.value).startswith(f"{parameter}: ") and "--" not in str(caught.value)
    with pytest.raises(ParameterError, match="^force_n: "):
        s.model_at(100.0, float("nan"))


# ---- the command line: realpen hatt list | synth ----

def test_cli_hatt_list_prints_the_speed_force_grid(hatt_dir):
    from conftest import run_cli

    path = hatt_dir / "Models_Book.xml"
    model_set = load_hatt(path)
    result = run_cli("hatt", "list", path)
    assert result.returncode == 0, result.stderr
    lines = result.stdout.splitlines()
    assert lines[0].startswith(f"{path}: 'Book', {len(model_set.models)} models at 1000 Hz")
    rows = [[cell.strip() for cell in line.split("│")[1:-1]] for line in lines
            if line.startswith("│") and line.split("│")[1].strip().isdigit()]
    assert len(rows) == len(model_set.models)
    printed = sorted((float(speed), float(force)) for _, speed, force, _, _ in rows)
    expected = sorted((round(s, 1), round(f, 3)) for s, f in model_set.vertices)
    assert np.allclose(printed, expected)


def test_cli_hatt_synth_writes_a_recording_that_realpen_reads(hatt_dir, tmp_path):
    from conftest import run_cli

    from realpen.io.recording import load_recording

    path = hatt_dir / "Models_Book.xml"
    out = tmp_path / "book.wav"
    result = run_cli("hatt", "synth", path, "--speed", "150", "--force", "1.5", "--seconds", "2",
                     "--seed", "4", "-o", out)
    assert result.returncode == 0, result.stderr
    assert result.stdout.startswith(f"wrote {out}: 2.00 s at 1000 Hz")
    written = load_recording(out)
    expected = synthesize(load_hatt(path), 150.0, 1.5, 2.0, seed=4)
    assert written.rate == 1000 and written.samples.shape == (2000, 1)
    np.testing.assert_allclose(written.mono, expected.mono, rtol=1e-6, atol=1e-6)  # float32 WAV
    # Refused unless --overwrite (--force is the normal force here); resampled with --rate.
    result = run_cli("hatt", "synth", path, "--speed", "150", "--force", "1.5", "--seconds", "2",
                     "-o", out)
    assert result.returncode == 2 and result.stderr == (
        f"realpen: error: {out}: exists; pass --overwrite to replace it\n")
    npz = tmp_path / "book.npz"
    result = run_cli("hatt", "synth", path, "--speed", "1000", "--force", "1.5", "--seconds",
                     "1", "--rate", "1344", "-o", npz)
    assert result.returncode == 0, result.stderr
    assert "note: speed 1000 mm/s is outside the modelled" in result.stdout
    resampled = load_recording(npz)
    assert resampled.rate == 1344 and resampled.units == "m/s^2" and len(resampled.mono) == 1344
    assert run_cli("hatt", "synth", path, "--speed", "150", "--force", "1.5", "--seconds", "2",
                   "--seed", "4", "-o", out, "--overwrite").returncode == 0


@pytest.mark.parametrize("options, message", [
    (["--seconds", "0"], "--seconds: must be > 0, got 0"),
    (["--seconds", "nan"], "--seconds: must be a finite number"),
    (["--seconds", "1e9"], "--seconds: must be <= 86400"),
    (["--speed", "inf"], "--speed: must be finite"),
    (["--force", "nan"], "--force: must be finite"),
    (["--seed", "-1"], "--seed: must be a whole number >= 0"),
    (["--rate", "0"], "--rate: must be > 0"),
])
def test_cli_hatt_synth_bad_options_name_the_flag(synthetic, tmp_path, options, message):
    from conftest import assert_clean_failure, run_cli

    base = {"--speed": "100", "--force": "1", "--seconds": "1"}
    base.update(dict(zip(options[::2], options[1::2])))
    args = [item for pair in base.items() for item in pair]
    result = run_cli("hatt", "synth", synthetic, *args, "-o", tmp_path / "out.wav")
    assert_clean_failure(result, f"realpen: error: {message}")
    assert not (tmp_path / "out.wav").exists()


def test_cli_hatt_bad_files_and_outputs(tmp_path, synthetic):
    from conftest import assert_clean_failure, run_cli

    bad = tmp_path / "Models_Bad.xml"
    bad.write_text("<modelSet>")
    assert_clean_failure(run_cli("hatt", "list", bad), "Models_Bad.xml: not a valid XML file")
    assert_clean_failure(run_cli("hatt", "list", tmp_path / "none.xml"), "none.xml")
    args = ["hatt", "synth", synthetic, "--speed", "100", "--force", "1", "--seconds", "1"]
    assert_clean_failure(run_cli(*args, "-o", tmp_path / "out.mp3"),
                         "out.mp3: write a .wav or .npz file")
    assert_clean_failure(run_cli(*args, "-o", tmp_path), "is a folder")
    assert_clean_failure(run_cli("hatt", "synth", synthetic, "--speed", "100", "--seconds", "1",
                                 "-o", tmp_path / "x.wav"), "--force")  # the force is required
    assert sorted(p.name for p in tmp_path.iterdir()) == ["Models_Bad.xml", "Models_Synthetic.xml"]
