"""The streamed analysis (realpen.io.blocks, realpen.dsp.stream): streamed equals in memory, every
source gives the same result, the unit-spectral DFT321 agrees with the whole-signal method
within stated tolerances, memory does not grow with length, and bad input is named."""

from __future__ import annotations

import json
import tracemalloc
import zipfile

import numpy as np
import pytest
import soundfile as sf
from conftest import run_cli
from signals import sines

from realpen.dsp.filters import prepare
from realpen.dsp.spectrum import analyze, select_units
from realpen.dsp.stream import analyze_stream, analyze_units, unit_fft_size
from realpen.errors import ParameterError, RealPenError
from realpen.examples import example_recording_path
from realpen.io.blocks import ArrayStream, open_stream
from realpen.io.files import json_text
from realpen.io.recording import Recording, load_recording

RATE = 1344
SECONDS = 4.0  # 40 units of 100 ms (134 samples)


def pen_like(seconds: float = SECONDS, noise: float = 0.05, seed: int = 0) -> np.ndarray:
    """Three axes of tones that differ in level per axis, on noise, with gravity on z."""
    tones = [87, 180, 264, 406]
    x = sines(tones, [1, 0.6, 0.4, 0.2], RATE, seconds, noise=noise, seed=seed)
    y = sines(tones, [0.5, 0.7, 0.2, 0.3], RATE, seconds, noise=noise, seed=seed + 10)
    z = sines(tones, [0.3, 0.2, 0.5, 0.1], RATE, seconds, noise=noise, seed=seed + 20) + 9.81
    return np.column_stack([x, y, z])


@pytest.fixture(scope="module")
def quantised(tmp_path_factory) -> tuple[np.ndarray, object]:
    """A pen-like signal on the 16-bit grid (so every format holds it exactly) and a folder."""
    folder = tmp_path_factory.mktemp("sources")
    signal = pen_like()
    signal = signal / (1.1 * np.max(np.abs(signal)))
    sf.write(folder / "rec.wav", signal, RATE, subtype="PCM_16")
    samples, _ = sf.read(folder / "rec.wav", always_2d=True)
    return samples, folder


def assert_same(a, b, rtol: float = 1e-9) -> None:
    """Two analyses equal up to floating-point noise (never the last bits)."""
    for name in ("starts_s", "frequencies_hz", "powers", "band_levels_db"):
        np.testing.assert_allclose(getattr(a, name), getattr(b, name), rtol=rtol, atol=0,
                                   equal_nan=True, err_msg=name)
    assert np.array_equal(a.selected, b.selected)


# --- the padding the peak interpolation needs ------------------------------------------------

@pytest.mark.parametrize("rate, unit", [(RATE, 134), (1700, 170)])  # padding 1.91× and 1.51×
def test_padding_to_1_5_units_still_locates_a_tone(rate, unit):
    """One tone per unit at random frequencies and phases: its peak is within 0.006 of an
    unpadded bin and 0.06 dB (134 samples: 0.003 bins, 0.02 dB; without padding 0.02 and
    0.4 dB). 170 samples in 256 points is the least padding the rule allows."""
    assert unit_fft_size(unit) == 256
    assert unit_fft_size(171) == 512 and unit_fft_size(8) == 16
    rng = np.random.default_rng(1)
    bin_hz = rate / unit
    freqs = rng.uniform(4 * bin_hz, rate / 2 - 4 * bin_hz, 150)
    t = np.arange(unit) / rate
    x = np.concatenate([np.sin(2 * np.pi * f * t + rng.uniform(0, 2 * np.pi)) for f in freqs])
    result = analyze_units(x, rate, unit_ms=1000 * unit / rate, top=1, count=1,
                           highpass_hz=0, dtype=np.float64)
    assert np.max(np.abs(result.frequencies_hz[:, 0] - freqs)) < 0.006 * bin_hz
    assert np.max(np.abs(10 * np.log10(result.powers[:, 0] / 0.5))) < 0.06


# --- streamed equals in memory; every source the same ---------------------------------------

@pytest.mark.parametrize("block_frames", [1, 133, 135, 4096])
def test_streamed_equals_in_memory_across_block_sizes(quantised, block_frames):
    samples, folder = quantised
    expected = analyze_units(samples, RATE, count=5, dtype=np.float64)
    got = analyze_stream(open_stream(folder / "rec.wav"), count=5, dtype=np.float64,
                         block_frames=block_frames)
    assert_same(got, expected)
    assert len(got.starts_s) == len(samples) // 134


def write_sources(samples: np.ndarray, folder) -> dict[str, tuple[object, dict]]:
    """The same samples as FLAC, CSV (with and without a time column) and NPZ (stored and
    deflated, C and Fortran order): name → (path, open_stream options)."""
    sf.write(folder / "rec.flac", samples, RATE, subtype="PCM_16")
    rows = "\n".join(",".join(repr(float(v)) for v in row) for row in samples)
    (folder / "rec.csv").write_text("x,y,z\n" + rows + "\n")
    times = np.arange(len(samples)) / RATE
    (folder / "timed.csv").write_text("t;x;y;z\n" + "\n".join(
        ";".join(repr(float(v)) for v in (t, *row)) for t, row in zip(times, samples)))
    np.savez(folder / "stored.npz", samples=samples, rate=float(RATE))
    np.savez(folder / "fortran.npz", samples=np.asfortranarray(samples), rate=RATE)
    np.savez_compressed(folder / "deflated.npz", samples=samples, rate=float(RATE))
    np.savez_compressed(folder / "deflated_f.npz", samples=np.asfortranarray(samples),
                        rate=float(RATE), axes=np.array(["ax", "ay", "az"]))
    names = ["rec.wav", "rec.flac", "timed.csv", "stored.npz", "fortran.npz", "deflated.npz",
             "deflated_f.npz"]
    sources = {name: (folder / name, {}) for name in names}
    sources["rec.csv"] = (folder / "rec.csv", {"rate": RATE})
    return sources


def test_wav_flac_csv_and_npz_give_the_same_analysis(quantised):
    samples, folder = quantised
    expected = analyze_units(samples, RATE, dtype=np.float64)
    for name, (path, options) in write_sources(samples, folder).items():
        stream = open_stream(path, **options)
        # A time column gives the rate from its steps: 1344 Hz to within float rounding.
        assert abs(stream.rate - RATE) < 1e-9 * RATE, name
        got = analyze_stream(stream, dtype=np.float64, block_frames=1000)
        assert stream.frames == len(samples), name
        assert_same(got, expected, rtol=1e-9 if stream.rate == RATE else 1e-6)
        assert np.array_equal(stream.read(100, 1234), samples[100:1234]), name
    assert open_stream(folder / "deflated_f.npz").axes == ("ax", "ay", "az")


def test_read_refuses_a_stretch_outside_the_recording(quantised):
    _, folder = quantised
    stream = open_stream(folder / "rec.wav")
    with pytest.raises(ParameterError) as caught:
        stream.read(10, stream.frames + 1)
    assert caught.value.parameter == "stop"
    with pytest.raises(ParameterError):
        stream.read(-1, 10)


def test_a_jittered_time_column_is_placed_on_the_grid_as_in_memory(tmp_path):
    rng = np.random.default_rng(0)
    times = np.arange(3000) / RATE + rng.uniform(-0.04, 0.04, 3000) / RATE
    rows = np.column_stack([times, np.sin(2 * np.pi * 100 * times), np.cos(2 * np.pi * 37 * times)])
    path = tmp_path / "jitter.csv"
    path.write_text("time,x,y\n" + "\n".join(",".join(repr(float(v)) for v in row)
                                            for row in rows))
    whole = load_recording(path)
    stream = open_stream(path)
    streamed = np.concatenate(list(stream.iter_blocks(100)))  # 30 chunks of 100 rows
    assert stream.rate == whole.rate and streamed.shape == whole.samples.shape
    # One spline per chunk, reaching 32 rows back, against one spline for the file.
    assert np.max(np.abs(streamed - whole.samples)) < 1e-9


# --- the unit-spectral DFT321 against the whole-signal method --------------------------------

def whole_signal(samples: np.ndarray, count: int = 15):
    recording = Recording(samples, RATE, ("x", "y", "z")[:samples.shape[1]])
    return analyze(prepare(recording).mono, RATE, count=count)


def test_unit_spectra_agree_with_the_whole_signal_dft321_on_the_example():
    """The bundled example (tones on noise): what the two methods find differs only as their
    noise estimates differ. Measured: 98.5 % of the whole-signal method's top 5 found within
    2 Hz, their powers 0.05 dB apart (median), 1.0 dB (99th percentile); the strongest peak
    within 1 Hz in all but 3 of 118 units (two near-equal peaks swapping); runs 3 units apart
    in a recording stationary throughout."""
    recording = load_recording(example_recording_path())
    old = whole_signal(recording.samples)
    new = analyze_units(recording.samples, RATE, dtype=np.float64)
    found, decibels, strongest = [], [], []
    for unit in range(1, len(old.starts_s) - 1):  # the first and last see the filter's edges
        old_f, old_p = old.unit(unit)
        new_f, new_p = new.unit(unit)
        strongest.append(abs(old_f[0] - new_f[0]) < 1.0)
        for f, p in zip(old_f[:5], old_p[:5]):
            nearest = np.argmin(np.abs(new_f - f))
            found.append(abs(new_f[nearest] - f) <= 2.0)
            if found[-1]:
                decibels.append(abs(10 * np.log10(new_p[nearest] / p)))
    assert np.mean(found) >= 0.97
    assert np.median(decibels) <= 0.1 and np.percentile(decibels, 99) <= 1.5
    assert np.mean(strongest) >= 0.95
    assert len(set(old.selected) & set(new.selected)) >= 10


def test_unit_spectra_agree_with_the_whole_signal_dft321_on_tones():
    """Tones on weak noise: every tone of every unit within 0.6 Hz (0.06 of an unpadded bin)
    and 0.75 dB of the whole-signal method's, 0.15 dB in the median (measured over three
    seeds: 0.57 Hz, 0.67 dB and 0.08 dB)."""
    samples = pen_like(6.0)
    old, new = whole_signal(samples), analyze_units(samples, RATE, dtype=np.float64)
    hz, decibels = [], []
    for unit in range(1, len(old.starts_s) - 1):
        old_f, old_p = old.unit(unit)
        new_f, new_p = new.unit(unit)
        for tone in (87, 180, 264, 406):
            i, j = np.argmin(np.abs(old_f - tone)), np.argmin(np.abs(new_f - tone))
            hz.append(abs(old_f[i] - new_f[j]))
            decibels.append(abs(10 * np.log10(new_p[j] / old_p[i])))
    assert max(hz) < 0.6 and max(decibels) < 0.75 and np.median(decibels) < 0.15


def test_the_same_stretch_is_chosen_where_one_is_steadiest():
    t = np.arange(int(8 * RATE)) / RATE
    envelope = 1 + 0.8 * np.sin(2 * np.pi * 1.7 * t) * (np.abs(t - 4) > 1.2)
    noise = 0.1 * np.random.default_rng(3).standard_normal(len(t))
    samples = np.column_stack([sines([120, 250], [1, 0.5], RATE, 8.0, seed=1),
                               sines([120, 330], [0.6, 0.4], RATE, 8.0, seed=2), noise])
    samples = samples * envelope[:, None]
    assert np.array_equal(whole_signal(samples).selected, analyze_units(samples, RATE).selected)


@pytest.mark.parametrize("tone", [32.0, 36.0, 45.0])
def test_the_high_pass_scales_a_tone_near_its_cutoff_without_moving_it(tone):
    """The filter's power response is applied at each peak's own frequency: a tone 2 Hz above
    the 30 Hz cutoff stays within 0.2 Hz and 0.2 dB of the time-domain filter's result (a
    weighted spectrum would move it 4 Hz up)."""
    x = np.sin(2 * np.pi * tone * np.arange(int(3 * RATE)) / RATE + 0.3)
    old = analyze(prepare(Recording(x, RATE, ("x",))).mono, RATE, top=1)
    new = analyze_units(x, RATE, top=1, dtype=np.float64)
    inner = slice(1, -1)
    assert np.max(np.abs(new.frequencies_hz[inner, 0] - old.frequencies_hz[inner, 0])) < 0.2
    assert np.max(np.abs(10 * np.log10(new.powers[inner, 0] / old.powers[inner, 0]))) < 0.2


@pytest.mark.parametrize("tone", [10.0, 15.0])
def test_without_a_high_pass_low_tones_are_kept_as_they_are(tone):
    """highpass_hz=0: only each unit's mean goes, as in the whole-signal path (a parabola
    would bend a 10 Hz tone in a 100 ms unit by several dB)."""
    x = np.sin(2 * np.pi * tone * np.arange(int(3 * RATE)) / RATE + 0.3)
    old = analyze(prepare(Recording(x, RATE, ("x",)), highpass_hz=0).mono, RATE, top=1, fmin=0)
    new = analyze_units(x, RATE, top=1, highpass_hz=0, dtype=np.float64)
    inner = slice(1, -1)
    assert np.max(np.abs(new.frequencies_hz[inner, 0] - old.frequencies_hz[inner, 0])) < 0.5
    assert np.max(np.abs(10 * np.log10(new.powers[inner, 0] / old.powers[inner, 0]))) < 0.5


def test_slow_hand_motion_hides_no_low_tone():
    """2 m/s² of motion at 0.7–2.3 Hz on every axis (the whole-signal high-pass removes it
    before any window; here each unit's parabolic trend goes): a 0.01 m/s² tone at 40 Hz is
    still a peak in every unit, and no motion leaks into the strongest three."""
    t = np.arange(int(SECONDS * RATE)) / RATE
    vibration = np.column_stack([sines([87, 180, 264], [0.05, 0.03, 0.02], RATE, SECONDS,
                                       noise=0.005, seed=s) for s in range(3)])
    vibration += 0.01 * np.sin(2 * np.pi * 40 * t)[:, None]
    motion = 2.0 * np.column_stack([np.sin(2 * np.pi * f * t + p)
                                    for f, p in ((1.5, 0), (2.3, 1), (0.7, 2))])
    result = analyze_units(vibration + motion, RATE, top=5)
    freqs = result.frequencies_hz[1:-1]
    assert np.all(np.any(np.abs(freqs - 40) < 1.5, axis=1))
    assert not np.any(freqs[:, :3] < 70)


# --- the choice of units, storage, axes ------------------------------------------------------

@pytest.mark.parametrize("count", [1, 5, 15])
def test_the_streamed_choice_is_select_units(quantised, count):
    samples, _ = quantised
    for selection in ("stationary", "middle"):
        result = analyze_stream(ArrayStream(samples, RATE), count=count, selection=selection,
                                dtype=np.float64, block_frames=1000)
        expected = select_units(result.band_levels_db, count, selection)
        assert np.array_equal(result.selected, expected)


def test_results_are_float32_unless_asked(quantised):
    samples, _ = quantised
    small, full = analyze_units(samples, RATE), analyze_units(samples, RATE, dtype=np.float64)
    assert small.powers.dtype == np.float32 and small.band_levels_db.dtype == np.float32
    np.testing.assert_allclose(small.powers, full.powers, rtol=1e-6, equal_nan=True)
    assert np.array_equal(small.selected, full.selected)
    power = small.to_json()["units"][3]["powers"][0]
    # Written with the shortest digits that read back as the float32 kept, a unit at a time.
    assert np.float32(power) == small.powers[3, 0] and len(repr(power)) <= 16
    assert "".join(small.json_chunks()) == json_text(small.to_json())


def test_axes_are_picked_by_name_position_or_magnitude(quantised):
    samples, _ = quantised
    stream = ArrayStream(samples, RATE, axes=("ax", "ay", "az"))
    assert_same(analyze_stream(stream, axis="y"), analyze_units(samples[:, 1], RATE))
    assert_same(analyze_stream(stream, axis="ay"), analyze_units(samples[:, 1], RATE))
    magnitude = analyze_stream(stream, axis="magnitude", top=1)
    whole = analyze(prepare(Recording(samples, RATE, ("x", "y", "z")), "magnitude").mono,
                    RATE, top=1)
    assert np.median(np.abs(magnitude.frequencies_hz[:, 0] - whole.frequencies_hz[:, 0])) < 0.5
    with pytest.raises(ParameterError) as caught:
        analyze_stream(stream, axis="w")
    assert caught.value.parameter == "axis"


@pytest.mark.parametrize("options, parameter", [
    ({"highpass_hz": 700}, "highpass_hz"), ({"highpass_hz": -1}, "highpass_hz"),
    ({"unit_ms": 0}, "unit_ms"), ({"top": 0}, "top"), ({"count": 0}, "count"),
    ({"selection": "best"}, "selection"), ({"dtype": np.int16}, "dtype"),
    ({"block_frames": 0}, "block_frames"), ({"fmax": 10}, "fmax"),
])
def test_bad_options_are_named_in_python_words(quantised, options, parameter):
    samples, _ = quantised
    with pytest.raises(ParameterError) as caught:
        analyze_units(samples, RATE, **options)
    assert caught.value.parameter == parameter


# --- memory ----------------------------------------------------------------------------------

def traced_peak(path) -> int:
    """Peak bytes numpy and Python allocate while a file is analysed."""
    tracemalloc.start()
    try:
        analyze_stream(open_stream(path))
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


def test_memory_does_not_grow_with_the_recording(tmp_path):
    """Streamed, the analysis holds one block's work (about 10 MB) and the per-unit results:
    10 frequencies, 10 powers and 24 band levels as float32 and one run variance, 184 bytes a
    unit. 10 min of 3 axes is 19 MB as float64."""
    signal = 0.1 * np.random.default_rng(0).standard_normal((600 * RATE, 3))
    sf.write(tmp_path / "long.wav", signal, RATE, subtype="PCM_16")
    sf.write(tmp_path / "short.wav", signal[:300 * RATE], RATE, subtype="PCM_16")
    short, long = traced_peak(tmp_path / "short.wav"), traced_peak(tmp_path / "long.wav")
    assert long < 0.7 * signal.nbytes
    assert (long - short) / 3000 < 220  # bytes per unit of the 5 minutes more (measured 185)


# --- bad input: one RealPenError naming the file ---------------------------------------------

def bad_file(tmp_path, case: str):
    samples = pen_like(3.0) / 20
    if case == "truncated-wav":
        path = tmp_path / "cut.wav"
        sf.write(path, samples, RATE, subtype="PCM_16")
        path.write_bytes(path.read_bytes()[:5000])
        return path, "truncated"
    if case == "garbage-flac":
        path = tmp_path / "noise.flac"
        path.write_bytes(b"fLaC" + bytes(range(256)) * 8)
        return path, "not a readable audio file"
    if case == "non-numeric-csv":
        path = tmp_path / "words.csv"
        lines = [",".join(f"{v:.5f}" for v in row) for row in samples]
        lines[3000] = "0.1,oops,0.2"
        path.write_text("x,y,z\n" + "\n".join(lines))
        return path, "line 3002: 'oops' in column 'y' is not a number"
    if case == "nan-late":
        path = tmp_path / "late.npz"
        samples[3500, 2] = np.nan
        np.savez(path, samples=samples, rate=float(RATE))
        return path, "NaN or infinite values (first at frame 3500)"
    if case == "npz-without-samples":
        path = tmp_path / "other.npz"
        np.savez(path, signal=samples, rate=float(RATE))
        return path, "no 'samples' array"
    if case == "npz-3d":
        path = tmp_path / "cube.npz"
        np.savez(path, samples=samples.reshape(-1, 3, 1), rate=float(RATE))
        return path, "must be 1-D or 2-D"
    if case == "npz-text":
        path = tmp_path / "text.npz"
        np.savez(path, samples=np.array(["a", "b"]), rate=float(RATE))
        return path, "must hold real numbers"
    if case == "npz-cut-member":
        path = tmp_path / "cut.npz"
        np.savez(path, samples=samples, rate=float(RATE))
        with zipfile.ZipFile(path) as archive:
            data = archive.read("samples.npy")
        with zipfile.ZipFile(path, "w") as archive:  # a stored member shorter than its header
            archive.writestr("samples.npy", data[:len(data) // 2])
            archive.writestr("rate.npy", b"")
        return path, "truncated"
    if case == "silent":
        path = tmp_path / "quiet.wav"
        sf.write(path, np.zeros((4 * RATE, 3)), RATE, subtype="FLOAT")
        return path, "silent or constant"
    if case == "short":
        path = tmp_path / "brief.wav"
        sf.write(path, samples[:RATE], RATE, subtype="PCM_16")
        return path, "too short"
    raise AssertionError(case)


@pytest.mark.parametrize("case", ["truncated-wav", "garbage-flac", "non-numeric-csv", "nan-late",
                                  "npz-without-samples", "npz-3d", "npz-text", "npz-cut-member",
                                  "silent", "short"])
def test_bad_input_is_one_error_naming_the_file(tmp_path, case):
    path, problem = bad_file(tmp_path, case)
    options = {"rate": RATE} if path.suffix == ".csv" else {}
    with pytest.raises(RealPenError) as caught:
        analyze_stream(open_stream(path, **options), block_frames=1000)
    assert not isinstance(caught.value, ParameterError)
    assert str(caught.value).startswith(f"{path}: ") and problem in str(caught.value)


def test_a_csv_without_time_needs_a_rate(tmp_path):
    path = tmp_path / "plain.csv"
    path.write_text("x\n" + "\n".join("0.5" for _ in range(10)))
    with pytest.raises(ParameterError) as caught:
        open_stream(path)
    assert caught.value.parameter == "rate" and "plain.csv" in str(caught.value)


# --- the command line ------------------------------------------------------------------------

def test_realpen_analyze_streams_and_falls_back_for_a_new_rate(quantised, tmp_path):
    samples, folder = quantised
    sf.write(tmp_path / "rec.flac", samples, RATE, subtype="PCM_16")
    out = tmp_path / "a.json"
    result = run_cli("analyze", tmp_path / "rec.flac", "--json", out, "--top", "4")
    assert result.returncode == 0, result.stderr
    assert "→ dft321, high-pass 30 Hz" in result.stdout and "4.00 s" in result.stdout
    expected = analyze_stream(open_stream(tmp_path / "rec.flac"), top=4).to_json()
    assert json.loads(out.read_text()) == json.loads(json.dumps(expected))
    result = run_cli("analyze", tmp_path / "rec.flac", "--analysis-rate", "1000", "--axis",
                     "magnitude", "--json", out, "--force")
    assert result.returncode == 0, result.stderr
    assert json.loads(out.read_text())["rate"] == 1000 and "→ magnitude" in result.stdout


@pytest.mark.slow
def test_the_streamed_path_imports_no_scipy_module_it_does_not_use():
    """scipy.ndimage, scipy.interpolate and scipy.signal took half the streamed analysis's
    resident memory (51 MB) for work its short spectra never do: none of them is loaded."""
    import subprocess
    import sys

    code = ("import sys, numpy as np\n"
            "from realpen.dsp.stream import analyze_stream\n"
            "from realpen.io.blocks import ArrayStream\n"
            "t = np.arange(3 * 1344) / 1344\n"
            "x = np.column_stack([np.sin(2 * np.pi * 200 * t), np.cos(2 * np.pi * 90 * t)])\n"
            "analyze_stream(ArrayStream(x, 1344), count=5)\n"
            "print(' '.join(sorted(m for m in sys.modules if m.startswith('scipy'))))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True)
    loaded = out.stdout.split()
    for heavy in ("scipy.ndimage", "scipy.interpolate", "scipy.signal"):
        assert heavy not in loaded, loaded


def test_without_band_levels_the_same_units_are_chosen():
    stream = open_stream(example_recording_path())
    kept, dropped = analyze_stream(stream), analyze_stream(stream, keep_bands=False)
    assert np.array_equal(kept.selected, dropped.selected)
    assert np.array_equal(kept.frequencies_hz, dropped.frequencies_hz, equal_nan=True)
    assert kept.band_levels_db.shape[1] > 0 and dropped.band_levels_db.shape == (len(kept.starts_s), 0)
