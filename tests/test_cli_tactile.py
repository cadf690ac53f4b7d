"""`realpen analyze` and `realpen tactile` end to end, bad input included."""

from __future__ import annotations

import hashlib
import json

import numpy as np
import pytest
import soundfile as sf
from conftest import assert_clean_failure, run_cli
from signals import sines

from realpen.examples import example_recording_path

EXAMPLE = example_recording_path()


def test_analyze_prints_summary_and_writes_json(tmp_path):
    out = tmp_path / "analysis.json"
    result = run_cli("analyze", EXAMPLE, "--top", "5", "--json", out)
    assert result.returncode == 0, result.stderr
    assert "120 units of 100 ms" in result.stdout
    doc = json.loads(out.read_text())
    assert doc["rate"] == 1344 and doc["unit_ms"] == 100
    assert len(doc["units"]) == 120 and len(doc["selected"]) == 15
    assert 0 not in doc["selected"] and 119 not in doc["selected"]
    assert np.all(np.diff(doc["selected"]) == 1)
    assert all(len(u["frequencies_hz"]) == 5 == len(u["powers"]) for u in doc["units"])


def test_tactile_writes_pattern_and_json(tmp_path):
    wav, js = tmp_path / "pattern.wav", tmp_path / "pattern.json"
    result = run_cli("tactile", EXAMPLE, "--actuator", "lra:f0=175,q=8", "--condition", "B",
                     "--model", "sines", "-o", wav, "--json", js, "--seed", "3")
    assert result.returncode == 0, result.stderr
    samples, rate = sf.read(wav)
    assert rate == 8000 and len(samples) == 12000
    doc = json.loads(js.read_text())
    assert doc["source"]["sha256"] == hashlib.sha256(EXAMPLE.read_bytes()).hexdigest()
    assert doc["parameters"]["condition"] == "B" and doc["parameters"]["seed"] == 3
    assert len(doc["subpatterns"]) == 15
    component = doc["subpatterns"][0][0]
    assert set(component) == {"frequency_hz", "power", "weight", "amplitude", "phase", "clipped",
                              "joins_previous", "joins_next"}
    # The JSON is enough to rebuild the WAV.
    t = np.arange(800) / 8000
    middle = slice(40, 760)  # away from the crossfades
    sub = doc["subpatterns"][2]
    rebuilt = sum(c["amplitude"] * np.sin(2 * np.pi * c["frequency_hz"] * t + c["phase"]) for c in sub)
    assert np.allclose(samples[1600:2400][middle], rebuilt[middle], atol=1e-6)


def test_tactile_builds_the_residual_by_default_and_the_method_with_model_sines(tmp_path):
    reports = {}
    for model in (None, "sines"):
        js = tmp_path / f"{model}.json"
        extra = () if model is None else ("--model", model)
        result = run_cli("tactile", EXAMPLE, "-o", tmp_path / f"{model}.wav", "--json", js, *extra)
        assert result.returncode == 0, result.stderr
        reports[model] = json.loads(js.read_text())
    assert reports[None]["parameters"]["model"] == "sines+residual"
    assert len(reports[None]["residual"]["levels"]) == 15
    assert "residual" not in reports["sines"] and "model" not in reports["sines"]["parameters"]
    assert reports[None]["subpatterns"] != reports["sines"]["subpatterns"]  # gains differ
    # A study condition is the method's stimulus unless a model is asked for.
    js = tmp_path / "d.json"
    assert run_cli("tactile", EXAMPLE, "--condition", "D", "-o", tmp_path / "d.wav", "--json",
                   js).returncode == 0
    assert "residual" not in json.loads(js.read_text())
    assert [[c["frequency_hz"] for c in sub] for sub in reports[None]["subpatterns"]] == \
        [[c["frequency_hz"] for c in sub] for sub in reports["sines"]["subpatterns"]]


def test_tactile_on_wav_and_csv_inputs(tmp_path):
    x = sines([90, 180, 350], [1, 0.6, 0.3], 1344, 2.5, noise=0.01)
    wav = tmp_path / "rec.wav"
    sf.write(wav, np.column_stack([x, 0.5 * x, 0.2 * x]), 1344, subtype="PCM_16")
    csv = tmp_path / "rec.csv"
    csv.write_text("ax;ay\n" + "\n".join(f"{v:.6f};{-v:.6f}" for v in x))
    assert run_cli("tactile", wav, "-o", tmp_path / "a.wav").returncode == 0
    result = run_cli("tactile", csv, "--input-rate", "1344", "--axis", "ax", "-o", tmp_path / "b.wav")
    assert result.returncode == 0, result.stderr


def write_case(tmp_path, case):
    """Make the bad input of one case; return (arguments, text the message must name)."""
    good_pattern = ["-o", tmp_path / "out.wav", "--json", tmp_path / "out.json"]
    rec = tmp_path / "rec.wav"
    if case == "missing":
        return ["tactile", tmp_path / "nope.wav", *good_pattern], "nope.wav"
    if case == "empty":
        rec.write_bytes(b"")
    elif case == "truncated":
        sf.write(rec, np.zeros(5000), 1344, subtype="PCM_16")
        rec.write_bytes(rec.read_bytes()[:3000])
    elif case == "not_audio":
        rec.write_text("hello\n" * 100)
    elif case == "nan":
        rec = tmp_path / "rec.csv"
        rec.write_text("t,x\n" + "\n".join(f"{i / 1344},{'nan' if i == 50 else 1}" for i in range(4000)))
    elif case in ("short", "silent", "constant", "low_rate", "bad_actuator_csv",
                  "non_monotonic_actuator", "unknown_condition"):
        rate = 40 if case == "low_rate" else 1344
        duration = 1.0 if case == "short" else 3.0
        x = (sines([100], [1], rate, duration) if case not in ("silent", "constant")
             else np.zeros(int(rate * duration)))
        if case == "constant":
            x = x + 0.5
        sf.write(rec, x, rate, subtype="FLOAT")
        if case == "bad_actuator_csv":
            act = tmp_path / "act.csv"
            act.write_text("hz,response\n100,one\n200,1\n")
            return ["tactile", rec, "--actuator", act, *good_pattern], "act.csv"
        if case == "non_monotonic_actuator":
            act = tmp_path / "act.csv"
            act.write_text("hz,response\n100,1\n300,1\n200,1\n")
            return ["tactile", rec, "--actuator", act, *good_pattern], "act.csv"
        if case == "unknown_condition":
            return ["tactile", rec, "--condition", "Z", *good_pattern], "condition"
    return ["tactile", rec, *good_pattern], rec.name


CASES = ["missing", "empty", "truncated", "not_audio", "nan", "short", "silent", "constant",
         "low_rate", "bad_actuator_csv", "non_monotonic_actuator", "unknown_condition"]


@pytest.mark.parametrize("case", CASES)
def test_bad_input_one_line_exit_2_nothing_written(tmp_path, case):
    args, names = write_case(tmp_path, case)
    result = run_cli(*args)
    assert_clean_failure(result, names)
    assert not (tmp_path / "out.wav").exists() and not (tmp_path / "out.json").exists()
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".out")]


def test_analyze_bad_input_too(tmp_path):
    args, names = write_case(tmp_path, "silent")
    result = run_cli("analyze", args[1], "--json", tmp_path / "a.json")
    assert_clean_failure(result, names)
    assert not (tmp_path / "a.json").exists()


def test_condition_and_explicit_counts_conflict(tmp_path):
    result = run_cli("tactile", EXAMPLE, "--condition", "A", "--top", "7", "-o", tmp_path / "x.wav")
    assert_clean_failure(result, "--top")
    result = run_cli("tactile", EXAMPLE, "--condition", "E", "--unit-ms", "100", "-o",
                     tmp_path / "x.wav")
    assert_clean_failure(result, "--unit-ms: condition E sets 1500, not 100")
    assert "unit_ms" not in result.stderr


def good_recording(tmp_path):
    rec = tmp_path / "rec.wav"
    sf.write(rec, sines([100, 230], [1, 0.5], 1344, 3.0, noise=0.01), 1344, subtype="FLOAT")
    return rec


MORE_CASES = {
    "cap_nan": (["--cap-db", "nan"], "--cap-db"),
    "cap_negative": (["--cap-db", "-10"], "--cap-db"),
    "actuator_inf": (["--actuator", "lra:f0=inf"], "f0"),
    "actuator_overflow": (["--actuator", "lra:q=1e400"], "q"),
    "unit_nan": (["--unit-ms", "nan"], "--unit-ms"),
    "unit_negative": (["--unit-ms", "-100"], "--unit-ms"),
    "crossfade_nan": (["--crossfade-ms", "nan"], "--crossfade-ms"),
    "highpass_nan": (["--highpass", "nan"], "--highpass"),
    "analysis_rate_zero": (["--analysis-rate", "0"], "--analysis-rate"),
    "seed_negative": (["--seed", "-1"], "--seed"),
    "top_not_a_number": (["--top", "abc"], "--top"),
}


@pytest.mark.parametrize("case", list(MORE_CASES))
def test_bad_options_one_line_exit_2_nothing_written(tmp_path, case):
    options, names = MORE_CASES[case]
    rec = good_recording(tmp_path)
    result = run_cli("tactile", rec, *options, "-o", tmp_path / "out.wav", "--json", tmp_path / "out.json")
    assert_clean_failure(result, names)
    assert not (tmp_path / "out.wav").exists() and not (tmp_path / "out.json").exists()


def test_unwritable_json_leaves_no_wav(tmp_path):
    rec = good_recording(tmp_path)
    blocker = tmp_path / "blocker"
    blocker.write_text("a file where a folder should be")
    result = run_cli("tactile", rec, "-o", tmp_path / "out.wav", "--json", blocker / "out.json")
    assert_clean_failure(result, "out.json")
    assert not (tmp_path / "out.wav").exists()
    result = run_cli("tactile", rec, "-o", tmp_path)
    assert_clean_failure(result, "is a folder")


@pytest.mark.parametrize("case", ["lsb_noise", "npz_rate_text", "npz_rate_zero", "csv_no_header",
                                  "csv_gap", "npy_renamed"])
def test_more_bad_recordings(tmp_path, case):
    rng = np.random.default_rng(0)
    if case == "lsb_noise":  # a constant with ±1 LSB of 16-bit noise is not vibration
        rec = tmp_path / "rec.wav"
        sf.write(rec, 0.5 + rng.integers(-1, 2, 4032) / 32768, 1344, subtype="PCM_16")
    elif case.startswith("npz"):
        rec = tmp_path / "rec.npz"
        rate = "fast" if case == "npz_rate_text" else 0.0
        np.savez(rec, samples=rng.standard_normal(4032), rate=np.array(rate))
    elif case == "npy_renamed":
        rec = tmp_path / "rec.npz"
        with open(rec, "wb") as handle:
            np.save(handle, rng.standard_normal(4032))
    else:
        rec = tmp_path / "rec.csv"
        t = np.arange(4032) / 1344
        if case == "csv_gap":
            t[2000:] += 1.0
        body = "\n".join(f"{a:.6f},{b:.6f}" for a, b in zip(t, rng.standard_normal(4032)))
        rec.write_text(body if case == "csv_no_header" else "t,x\n" + body)
    result = run_cli("tactile", rec, "--input-rate", "1344", "-o", tmp_path / "out.wav")
    assert_clean_failure(result, rec.name)
    assert not (tmp_path / "out.wav").exists()


def test_csv_hint_names_the_right_option(tmp_path):
    rec = tmp_path / "rec.csv"
    rec.write_text("ax,ay\n" + "\n".join("1,2" for _ in range(10)))
    assert_clean_failure(run_cli("tactile", rec, "-o", tmp_path / "o.wav"), "--input-rate")
    assert_clean_failure(run_cli("analyze", rec), "--rate")


# --- Python names in the library, flags on the command line ----------------------------------

def test_the_library_names_the_parameter_the_command_line_names_the_flag():
    from realpen.dsp.spectrum import analyze as analyze_signal
    from realpen.errors import ParameterError

    with pytest.raises(ParameterError) as caught:
        analyze_signal(sines([100], [1], 1344, 3.0), 1344, unit_ms=-1)
    assert str(caught.value) == "unit_ms: must be > 0, got -1"
    assert "--unit-ms" not in str(caught.value)
    result = run_cli("analyze", EXAMPLE, "--unit-ms", "-1")
    assert_clean_failure(result, "realpen: error: --unit-ms: must be > 0, got -1")
    assert "unit_ms" not in result.stderr


@pytest.mark.parametrize("options, flag", [
    (["--top", "0"], "--top: must be >= 1"),
    (["--subpatterns", "0"], "--subpatterns: must be >= 1"),   # the library's `count`
    (["--select", "best"], "--select: unknown value 'best'"),  # the library's `selection`
    (["--highpass", "-1"], "--highpass: must be >= 0"),        # the library's `highpass_hz`
    (["--analysis-rate", "0"], "--analysis-rate: must be > 0"),
    (["--axis", "w"], "--axis: unknown value 'w'"),
])
def test_analyze_maps_every_library_parameter_to_its_flag(options, flag):
    assert_clean_failure(run_cli("analyze", EXAMPLE, *options), f"realpen: error: {flag}")


def test_the_recording_rate_is_input_rate_for_tactile_and_rate_for_analyze(tmp_path):
    rec = tmp_path / "rec.csv"
    rec.write_text("ax\n" + "\n".join(f"{v:.5f}" for v in sines([100], [1], 1344, 3.0)))
    result = run_cli("tactile", rec, "--input-rate", "-5", "-o", tmp_path / "o.wav")
    assert_clean_failure(result, "realpen: error: --input-rate: must be > 0, got -5")
    result = run_cli("analyze", rec, "--rate", "-5")
    assert_clean_failure(result, "realpen: error: --rate: must be > 0, got -5")


# --- analyze --all ---------------------------------------------------------------------------

def table_units(stdout: str) -> list[str]:
    """The unit column of the printed table (a star marks a selected unit under --all)."""
    return [line.split("│")[1].strip() for line in stdout.splitlines()
            if line.startswith("│") and line.split("│")[1].strip().rstrip("*").isdigit()]


def test_analyze_prints_the_selected_units_and_with_all_every_unit():
    selected = run_cli("analyze", EXAMPLE, "--top", "2")
    assert selected.returncode == 0, selected.stderr
    units = table_units(selected.stdout)
    assert len(units) == 15 and not any(u.endswith("*") for u in units)
    every = run_cli("analyze", EXAMPLE, "--top", "2", "--all")
    assert every.returncode == 0, every.stderr
    units = table_units(every.stdout)
    assert [u.rstrip("*") for u in units] == [str(i) for i in range(120)]
    assert [u.rstrip("*") for u in units if u.endswith("*")] == table_units(selected.stdout)
    help_text = " ".join(run_cli("analyze", "--help").stdout.split())
    assert "selected unit sequences" in help_text and "--all" in help_text


# --- an existing output is replaced only with --force ----------------------------------------

def test_tactile_and_analyze_refuse_existing_outputs_before_any_work(tmp_path):
    wav, js = tmp_path / "p.wav", tmp_path / "p.json"
    wav.write_bytes(b"keep")
    # Refused before the recording is read: the missing recording is not what is reported.
    result = run_cli("tactile", tmp_path / "missing.wav", "-o", wav)
    assert_clean_failure(result, f"realpen: error: {wav}: exists; pass --force to replace it")
    js.write_text("{}")
    result = run_cli("tactile", EXAMPLE, "-o", tmp_path / "new.wav", "--json", js)
    assert_clean_failure(result, f"{js}: exists; pass --force to replace it")
    assert not (tmp_path / "new.wav").exists() and wav.read_bytes() == b"keep"
    result = run_cli("tactile", EXAMPLE, "-o", wav, "--json", js, "--force")
    assert result.returncode == 0, result.stderr
    assert sf.info(wav).frames == 12000 and len(json.loads(js.read_text())["subpatterns"]) == 15
    result = run_cli("analyze", EXAMPLE, "--json", js)
    assert_clean_failure(result, f"{js}: exists; pass --force to replace it")
    result = run_cli("analyze", EXAMPLE, "--json", js, "--overwrite")  # the same option
    assert result.returncode == 0, result.stderr
    assert len(json.loads(js.read_text())["units"]) == 120


def test_an_output_is_never_the_recording_or_another_output(tmp_path):
    rec = tmp_path / "rec.npz"
    rec.write_bytes(EXAMPLE.read_bytes())
    result = run_cli("tactile", rec, "-o", rec, "--force")
    assert_clean_failure(result, f"{rec}: would replace the recording itself")
    result = run_cli("tactile", rec, "-o", tmp_path / "a.wav", "--json", tmp_path / "a.wav")
    assert_clean_failure(result, "given for two outputs")
    assert rec.read_bytes() == EXAMPLE.read_bytes()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rec.npz"]
