"""Loading recordings, DFT321, resampling and the high-pass filter."""

from __future__ import annotations

import numpy as np
import pytest
import soundfile as sf
from signals import sines

from realpen.dsp.filters import combine_axes, dft321, highpass, prepare, resample
from realpen.errors import ParameterError, RealPenError
from realpen.io.recording import Recording, load_recording

RATE = 1344


@pytest.mark.parametrize("subtype", ["PCM_16", "PCM_24", "PCM_32", "FLOAT", "DOUBLE"])
@pytest.mark.parametrize("channels", [1, 3])
def test_wav_any_subtype_and_channel_count(tmp_path, subtype, channels):
    x = 0.5 * np.column_stack([sines([100 + 50 * c], [1.0], RATE, 1.0) for c in range(channels)])
    path = tmp_path / "rec.wav"
    sf.write(path, x, RATE, subtype=subtype)
    rec = load_recording(path)
    assert rec.rate == RATE and rec.samples.shape == (RATE, channels)
    assert rec.axes == ("x", "y", "z")[:channels]
    assert np.max(np.abs(rec.samples - x)) < 1e-4
    assert rec.sha256 and len(rec.sha256) == 64 and rec.source == str(path)


def test_csv_with_time_column_and_sniffed_delimiter(tmp_path):
    t = np.arange(500) / RATE
    x = sines([120], [1.0], RATE, 500 / RATE)
    for delimiter in [",", ";", "\t"]:
        path = tmp_path / "rec.csv"
        lines = [delimiter.join(["time", "ax", "ay"])]
        lines += [delimiter.join(f"{v:.9f}" for v in row) for row in zip(t, x, -x)]
        path.write_text("\n".join(lines) + "\n")
        rec = load_recording(path)
        assert rec.rate == pytest.approx(RATE, rel=1e-6)
        assert rec.axes == ("ax", "ay")
        assert np.allclose(rec.samples[:, 1], -x, atol=1e-8)


def test_csv_without_time_column_needs_rate(tmp_path):
    path = tmp_path / "rec.csv"
    path.write_text("x,y,z\n" + "\n".join("1,2,3" for _ in range(10)))
    with pytest.raises(ParameterError, match=r"^rate: needed in Hz: .*rec.csv") as caught:
        load_recording(path)
    assert caught.value.parameter == "rate" and "--" not in str(caught.value)
    assert load_recording(path, rate=1000).rate == 1000


def test_npz_without_rate_needs_rate(tmp_path):
    path = tmp_path / "rec.npz"
    np.savez(path, samples=np.ones((100, 2)))
    with pytest.raises(ParameterError, match=r"^rate: needed in Hz: .*rec.npz"):
        load_recording(path)
    assert load_recording(path, rate=500).rate == 500


@pytest.mark.parametrize("rate", [0, -1.0, float("nan"), float("inf")])
def test_bad_rate_names_the_parameter_not_a_flag(tmp_path, rate):
    path = tmp_path / "rec.csv"
    path.write_text("x\n" + "\n".join("1" for _ in range(10)))
    with pytest.raises(ParameterError) as caught:
        load_recording(path, rate=rate)
    assert caught.value.parameter == "rate" and str(caught.value).startswith("rate: ")
    assert isinstance(caught.value, ValueError)  # code that catches ValueError keeps working


def test_npz_keeps_axes_units_and_rate(tmp_path):
    path = tmp_path / "rec.npz"
    np.savez(path, samples=np.ones((100, 2)), rate=500.0, axes=np.array(["a", "b"]),
             units=np.array("g"))
    rec = load_recording(path)
    assert (rec.rate, rec.axes, rec.units) == (500.0, ("a", "b"), "g")


@pytest.mark.parametrize("case, message", [
    ("missing", "no such file"),
    ("empty", "file is empty"),
    ("not_audio", "not a readable audio file"),
    ("truncated", "truncated"),
    ("nan_csv", "NaN"),
    ("backwards_time", "not strictly increasing"),
    ("bad_npz", "not a readable NPZ"),
])
def test_bad_files_give_one_line_naming_the_file(tmp_path, case, message):
    path = tmp_path / {"nan_csv": "bad.csv", "backwards_time": "bad.csv",
                       "bad_npz": "bad.npz"}.get(case, "bad.wav")
    if case == "empty":
        path.write_bytes(b"")
    elif case == "not_audio":
        path.write_text("this is not audio at all\n" * 20)
    elif case == "truncated":
        sf.write(path, np.zeros(10000), RATE, subtype="PCM_16")
        path.write_bytes(path.read_bytes()[:5000])
    elif case == "nan_csv":
        path.write_text("t,x\n0,1\n0.001,nan\n0.002,1\n")
    elif case == "backwards_time":
        path.write_text("t,x\n0,1\n0.002,1\n0.001,1\n")
    elif case == "bad_npz":
        path.write_bytes(b"PK\x03\x04garbage")
    with pytest.raises(RealPenError) as info:
        load_recording(path)
    assert str(path) in str(info.value) and message in str(info.value)
    assert "\n" not in str(info.value)


def test_inf_in_wav_is_rejected(tmp_path):
    path = tmp_path / "inf.wav"
    x = np.zeros(100)
    x[50] = np.inf
    sf.write(path, x, RATE, subtype="DOUBLE")
    with pytest.raises(RealPenError, match="NaN or infinite"):
        load_recording(path)


def test_dft321_keeps_summed_spectral_energy():
    rng = np.random.default_rng(1)
    axes = rng.standard_normal((4001, 3)) * [1.0, 0.4, 2.0]
    combined = dft321(axes)
    energy_axes = np.sum(np.abs(np.fft.rfft(axes, axis=0)) ** 2)
    energy_combined = np.sum(np.abs(np.fft.rfft(combined)) ** 2)
    assert energy_combined == pytest.approx(energy_axes, rel=1e-9)
    # Time-domain energy too (Parseval), since all axes share the same bins.
    assert np.sum(combined ** 2) == pytest.approx(np.sum(axes ** 2), rel=1e-9)


def test_dft321_of_one_axis_is_that_axis_up_to_sign():
    x = sines([80, 200], [1, 0.5], RATE, 1.0)
    combined = dft321(np.column_stack([x, np.zeros_like(x), np.zeros_like(x)]))
    assert np.allclose(combined, x, atol=1e-9)


def test_combine_axes_choices():
    x = sines([80], [1], RATE, 1.0)
    rec = Recording(np.column_stack([x, 2 * x, 3 * x]), RATE, ("x", "y", "z"))
    assert np.allclose(combine_axes(rec, "y").mono, 2 * x)
    assert combine_axes(rec).axes == ("dft321",)
    magnitude = combine_axes(rec, "magnitude").mono
    assert abs(magnitude.mean()) < 1e-9
    with pytest.raises(RealPenError, match="no axis 'w'"):
        combine_axes(rec, "w")


def test_highpass_removes_low_keeps_high_zero_phase():
    x_low = sines([5], [1], RATE, 4.0, phases=[0])
    x_high = sines([150], [1], RATE, 4.0, phases=[0])
    rec = Recording(x_low + x_high, RATE, ("x",))
    out = highpass(rec, 30).mono
    middle = slice(RATE, 3 * RATE)
    assert np.max(np.abs(out[middle] - x_high[middle])) < 0.01  # zero phase: no delay
    assert out.std() < 0.75


def test_highpass_rate_too_low_for_band():
    rec = Recording(np.zeros(100), 50.0, ("x",), source="slow.csv")
    with pytest.raises(RealPenError, match="slow.csv.*too low"):
        highpass(rec, 30)


@pytest.mark.parametrize("call, parameter", [
    (lambda rec: highpass(rec, -5), "cutoff_hz"),
    (lambda rec: resample(rec, 0), "rate"),
    (lambda rec: resample(rec, 0.001), "rate"),
    (lambda rec: prepare(rec, analysis_rate=-1), "analysis_rate"),
    (lambda rec: prepare(rec, highpass_hz=float("nan")), "highpass_hz"),
    (lambda rec: prepare(rec, axis="w"), "axis"),
])
def test_filter_arguments_are_named_as_in_python(call, parameter):
    x = sines([80], [1], RATE, 1.0)
    rec = Recording(np.column_stack([x, x]), RATE, ("x", "y"))
    with pytest.raises(ParameterError) as caught:
        call(rec)
    assert caught.value.parameter == parameter
    assert str(caught.value).startswith(f"{parameter}: ") and "--" not in str(caught.value)


def test_resample_polyphase_keeps_a_tone():
    x = sines([100], [1], 1000, 2.0, phases=[0])
    out = resample(Recording(x, 1000, ("x",)), RATE)
    assert out.rate == pytest.approx(RATE)
    assert len(out.mono) == pytest.approx(2 * RATE, abs=2)
    spectrum = np.abs(np.fft.rfft(out.mono * np.hanning(len(out.mono))))
    peak = np.fft.rfftfreq(len(out.mono), 1 / out.rate)[spectrum.argmax()]
    assert peak == pytest.approx(100, abs=1)


def test_time_column_variants_and_jitter(tmp_path):
    rng = np.random.default_rng(2)
    t = np.arange(2000) / RATE
    jittered = t + rng.uniform(-0.2, 0.2, len(t)) / RATE  # ±20 % of a step, still increasing
    x = sines([120], [1.0], RATE, 2000 / RATE, phases=[0])
    path = tmp_path / "rec.csv"
    path.write_text("Time (s),acc_x\n" + "\n".join(f"{a:.9f},{np.sin(2 * np.pi * 120 * a):.9f}"
                                                     for a in jittered))
    rec = load_recording(path)
    assert rec.axes == ("acc_x",)
    assert rec.rate == pytest.approx(RATE, rel=0.01)
    # Interpolated onto an even grid: the tone comes back where it belongs.
    grid = jittered[0] + np.arange(len(rec.mono)) / rec.rate
    assert np.max(np.abs(rec.mono - np.sin(2 * np.pi * 120 * grid))) < 0.05
    assert len(x) >= len(rec.mono) - 2


def test_axis_letters_fall_back_to_column_order():
    x = sines([80], [1], RATE, 1.0)
    rec = Recording(np.column_stack([x, 2 * x, 3 * x]), RATE, ("ax", "ay", "az"))
    assert np.allclose(combine_axes(rec, "z").mono, 3 * x)
    with pytest.raises(RealPenError, match="no axis 'w'"):
        combine_axes(rec, "w")
