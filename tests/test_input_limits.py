"""The input limits of realpen.io.limits, enforced by every reader before it allocates.

Bad files are built here, small on disk: forged .npy and WAV headers, zip-deflated zeros and
sparse files. Most tests call the readers in-process; the few at the end run
``python -m realpen`` under an address-space limit, so that a reader that allocated what a
header claims would fail them.
"""

from __future__ import annotations

import contextlib
import dataclasses
import io
import os
import resource
import struct
import subprocess
import sys
import time
import tracemalloc
import zipfile
from pathlib import Path

import numpy as np
import pytest
import soundfile as sf
from conftest import assert_clean_failure, run_cli
from test_hatt import synthetic_xml

from realpen.checks import MAX_RATE_HZ, MAX_UNITS, MIN_RATE_HZ
from realpen.datasets.hatt import load_hatt, synthesize
from realpen.errors import ParameterError, RealPenError
from realpen.examples import example_recording_path
from realpen.io import csvtable
from realpen.io.blocks import MAX_STREAM_SAMPLES
from realpen.io.csvtable import read_csv
from realpen.io.files import riff_chunks
from realpen.io.limits import (
    MAX_CHANNELS,
    MAX_CSV_BYTES,
    MAX_CSV_FIELD_CHARS,
    MAX_CSV_LINE_CHARS,
    MAX_FRAMES,
    MAX_MODEL_ORDER,
    MAX_NPZ_ARRAY_BYTES,
    MAX_NPZ_DIRECTORY_BYTES,
    MAX_XML_BYTES,
)
from realpen.io.recording import as_recording, load_recording
from realpen.motion.coupling import Coupling

RATE = 1344
SMALL_PEAK = 32 * 1024 * 1024  # bytes: what refusing a file may allocate, however large it claims


@contextlib.contextmanager
def traced_peak():
    """Measure the peak of Python and numpy allocations (numpy reports to tracemalloc)."""
    result = {}
    tracemalloc.start()
    try:
        yield result
    finally:
        result["peak"] = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()


def refused(call, *names: str) -> str:
    """Run ``call``, expect one RealPenError line that contains every one of ``names``."""
    with pytest.raises(RealPenError) as caught:
        call()
    message = str(caught.value)
    assert "\n" not in message and all(name in message for name in names), message
    return message


# --- building bad files --------------------------------------------------------------------

def npy_header(shape, descr="<f8", fortran=False) -> bytes:
    """A .npy version 1.0 magic and header declaring ``shape`` and ``descr`` (no data)."""
    buffer = io.BytesIO()
    np.lib.format.write_array_header_1_0(
        buffer, {"descr": descr, "fortran_order": fortran, "shape": tuple(shape)})
    return buffer.getvalue()


def write_npz(path: Path, members: dict[str, bytes], zeros: dict[str, int] | None = None,
              compression: int = zipfile.ZIP_DEFLATED) -> Path:
    """An NPZ whose member ``name.npy`` holds ``members[name]`` followed by ``zeros[name]``
    zero bytes, deflated as they stream (so gigabytes of zeros take a megabyte)."""
    zeros = zeros or {}
    with zipfile.ZipFile(path, "w", compression) as archive:
        for name, data in members.items():
            with archive.open(f"{name}.npy", "w", force_zip64=True) as handle:
                handle.write(data)
                left = zeros.get(name, 0)
                block = bytes(1 << 20)
                while left > 0:
                    handle.write(block[:min(left, len(block))])
                    left -= len(block)
    return path


def rate_member(rate: float) -> bytes:
    return npy_header(()) + struct.pack("<d", rate)


def forged_wav(path: Path, frames: int, rate: int = RATE) -> Path:
    """A mono 16-bit WAV whose data chunk declares ``frames`` frames, stored as a sparse file
    of that length (no disk blocks for the zeros)."""
    sf.write(path, np.zeros(16), rate, subtype="PCM_16")
    with open(path, "r+b") as handle:
        offset = next(start for name, start, _ in riff_chunks(handle) if name == b"data")
        handle.seek(offset - 4)
        handle.write(struct.pack("<I", 2 * frames))
        handle.seek(4)
        handle.write(struct.pack("<I", offset - 8 + 2 * frames))
        handle.truncate(offset + 2 * frames)
    return path


# --- WAV: rate, channels and frames from the header ---------------------------------------

@pytest.mark.parametrize("rate", [1, MIN_RATE_HZ - 1, MAX_RATE_HZ + 1])
def test_wav_rate_outside_the_limits_is_refused(tmp_path, rate):
    path = tmp_path / "rate.wav"
    sf.write(path, np.zeros(400), rate, subtype="PCM_16")
    refused(lambda: load_recording(path), str(path), f"{MIN_RATE_HZ}–{MAX_RATE_HZ:,} Hz")


@pytest.mark.parametrize("rate", [MIN_RATE_HZ, MAX_RATE_HZ])
def test_wav_rates_at_the_limits_are_read(tmp_path, rate):
    path = tmp_path / "edge.wav"
    sf.write(path, 0.5 * np.sin(np.arange(400)), rate, subtype="PCM_16")
    assert load_recording(path).rate == rate


def test_wav_with_too_many_channels_is_refused(tmp_path):
    path = tmp_path / "wide.wav"
    sf.write(path, np.zeros((10, MAX_CHANNELS + 1)), RATE, subtype="PCM_16")
    refused(lambda: load_recording(path), str(path), f"limited to 1–{MAX_CHANNELS}")


def test_wav_header_claiming_too_many_frames_is_refused_before_reading(tmp_path):
    path = forged_wav(tmp_path / "long.wav", MAX_FRAMES + 1)
    with traced_peak() as memory:
        refused(lambda: load_recording(path), str(path), f"{MAX_FRAMES + 1:,} frames",
                f"limited to {MAX_FRAMES:,} samples")
    assert memory["peak"] < SMALL_PEAK


# --- NPZ: headers checked, members inflated only to their declared size --------------------

@pytest.mark.parametrize("shape, descr, problem", [
    ((10 ** 12, 3), "<f8", f"limited to {MAX_FRAMES:,} samples"),
    ((MAX_FRAMES + 1,), "<i2", f"limited to {MAX_FRAMES:,} samples"),
    ((10, MAX_CHANNELS + 1), "<f4", f"limited to 1–{MAX_CHANNELS}"),
    ((-5, 3), "<f8", "impossible shape"),
    ((10 ** 4000, 3), "<f8", "over 10^15 frames"),
    ((2, 2, 2), "<f8", "must be 1-D or 2-D"),
    ((10, 3), "<c16", "must hold real numbers"),
])
def test_npz_header_out_of_limits_is_refused_before_allocating(tmp_path, shape, descr, problem):
    path = write_npz(tmp_path / "forged.npz", {"samples": npy_header(shape, descr),
                                               "rate": rate_member(RATE)})
    with traced_peak() as memory:
        refused(lambda: load_recording(path), str(path), problem)
    assert memory["peak"] < SMALL_PEAK


def test_npz_member_is_inflated_only_to_its_declared_size(tmp_path):
    # 64 MiB of deflated zeros behind a header declaring 1000 × 3 float64 (24 kB).
    path = write_npz(tmp_path / "bomb.npz", {"samples": npy_header((1000, 3)),
                                             "rate": rate_member(RATE)},
                     zeros={"samples": 64 << 20})
    assert path.stat().st_size < 1 << 20
    with traced_peak() as memory:
        recording = load_recording(path)
    assert recording.samples.shape == (1000, 3) and recording.rate == RATE
    assert memory["peak"] < 8 << 20


def test_npz_fortran_order_and_byte_order_read_like_numpy(tmp_path):
    samples = np.arange(12, dtype=">i4").reshape(4, 3)
    path = write_npz(tmp_path / "f.npz", {
        "samples": npy_header((4, 3), ">i4", fortran=True) + samples.T.tobytes(),
        "rate": rate_member(500.0)})
    recording = load_recording(path)
    assert np.array_equal(recording.samples, samples.astype(np.float64))
    assert np.array_equal(recording.samples, np.load(path)["samples"])


def test_npz_refuses_pickled_objects(tmp_path):
    path = tmp_path / "objects.npz"
    np.savez(path, samples=np.array([1.0, "a"], dtype=object), rate=RATE)
    refused(lambda: load_recording(path), str(path), "'samples'", "objects")


@pytest.mark.parametrize("case, problem", [
    ("record", "records are refused"),
    ("bzip2", "must be stored or deflated"),
    ("huge_axes", f"limited to {MAX_NPZ_ARRAY_BYTES:,}"),
    ("truncated", "truncated"),
    ("npy", "single .npy array"),
    ("directory", f"limited to {MAX_NPZ_DIRECTORY_BYTES:,}"),
])
def test_npz_bad_members_are_one_line(tmp_path, case, problem):
    path = tmp_path / f"{case}.npz"
    samples = npy_header((4, 1)) + bytes(32)
    if case == "record":
        write_npz(path, {"samples": npy_header((4,), [("a", "<f8")]) + bytes(32),
                         "rate": rate_member(RATE)})
    elif case == "bzip2":
        write_npz(path, {"samples": samples, "rate": rate_member(RATE)},
                  compression=zipfile.ZIP_BZIP2)
    elif case == "huge_axes":  # one string of 400 MB, declared in a 128-byte header
        write_npz(path, {"samples": samples, "rate": rate_member(RATE),
                         "axes": npy_header((1,), "<U100000000")})
    elif case == "truncated":
        write_npz(path, {"samples": npy_header((1000, 3)) + bytes(100), "rate": rate_member(RATE)})
    elif case == "npy":
        np.save(tmp_path / "one.npy", np.zeros(10))
        (tmp_path / "one.npy").rename(path)
    elif case == "directory":  # thousands of empty members: zipfile would parse them all
        with zipfile.ZipFile(path, "w") as archive:
            archive.writestr("samples.npy", samples)
            for index in range(MAX_NPZ_DIRECTORY_BYTES // 32):
                archive.writestr(f"padding_{index:08d}.npy", b"")
    refused(lambda: load_recording(path), str(path), problem)


@pytest.mark.parametrize("rate", [1e300, 0.5, MAX_RATE_HZ * 2, float("nan")])
def test_npz_rate_out_of_range_is_refused(tmp_path, rate):
    path = tmp_path / "rate.npz"
    np.savez(path, samples=np.random.default_rng(0).normal(size=(500, 3)), rate=rate)
    refused(lambda: load_recording(path), str(path), "sampling rate",
            f"{MIN_RATE_HZ}–{MAX_RATE_HZ:,} Hz")


# --- values: overflow is named, not called silence -----------------------------------------

def test_values_beyond_a_plausible_range_are_named(tmp_path):
    samples = np.random.default_rng(0).normal(size=(2000, 3))
    samples[7, 1] = 1e307
    path = tmp_path / "overflow.npz"
    np.savez(path, samples=samples, rate=float(RATE))
    message = refused(lambda: load_recording(path), str(path), "1e+307", "frame 7",
                      "not a measurement")
    assert "silent" not in message
    result = run_cli("analyze", path)
    assert_clean_failure(result, "not a measurement")
    with pytest.raises(ParameterError) as caught:
        as_recording(samples, rate=RATE)
    assert caught.value.parameter == "data" and "frame 7" in str(caught.value)


def test_nan_is_still_reported_as_nan(tmp_path):
    samples = np.zeros((100, 2))
    samples[40, 0] = np.nan
    path = tmp_path / "nan.npz"
    np.savez(path, samples=samples, rate=float(RATE))
    refused(lambda: load_recording(path), str(path), "NaN or infinite", "frame 40")


# --- the rate a caller gives ---------------------------------------------------------------

@pytest.mark.parametrize("rate", [1, 99.5, 1e9])
def test_caller_rate_is_checked_against_the_same_range(tmp_path, rate):
    path = tmp_path / "rec.csv"
    path.write_text("x\n" + "\n".join(f"{np.sin(k):.5f}" for k in range(200)))
    with pytest.raises(ParameterError) as caught:
        load_recording(path, rate=rate)
    assert caught.value.parameter == "rate"
    assert f"between {MIN_RATE_HZ} and {MAX_RATE_HZ:,} Hz" in str(caught.value)
    with pytest.raises(ParameterError) as caught:
        as_recording(np.zeros(100), rate=rate)
    assert caught.value.parameter == "rate"
    assert_clean_failure(run_cli("tactile", path, "--input-rate", str(rate), "-o",
                                 tmp_path / "o.wav"), "--input-rate: must be between")
    assert_clean_failure(run_cli("analyze", path, "--rate", str(rate)), "--rate: must be between")


def test_caller_rate_too_large_for_a_float_is_refused(tmp_path):
    path = tmp_path / "rec.csv"
    path.write_text("x\n" + "\n".join(f"{np.sin(k):.5f}" for k in range(200)))
    with pytest.raises(ParameterError, match="between 100 and 384,000 Hz, got over 1e"):
        load_recording(path, rate=10 ** 400)


# --- CSV: file, line and field sizes; rows kept ----------------------------------------------

def test_csv_field_over_the_limit_is_refused(tmp_path):
    path = tmp_path / "field.csv"
    path.write_text("t,x\n0,1\n0.001," + "1" * 5000 + "\n0.002,1\n")
    refused(lambda: load_recording(path), str(path), "line 3",
            f"CSV fields are limited to {MAX_CSV_FIELD_CHARS:,}")
    # A quoted field may run over lines that are each short; it is measured whole.
    path.write_text('t,x\n0,"' + ("1" * 10 + "\n") * (MAX_CSV_FIELD_CHARS // 10 + 1) + '"\n')
    refused(lambda: read_csv(path), str(path), f"CSV fields are limited to {MAX_CSV_FIELD_CHARS:,}")


def test_csv_long_number_is_named_briefly(tmp_path):
    path = tmp_path / "digits.csv"
    path.write_text("t,x\n0,1\n0.001," + "9" * 1000 + "\n")  # under the field limit, overflows
    message = refused(lambda: load_recording(path), str(path), "line 3", "NaN or infinite")
    assert len(message) < len(str(path)) + 120


def test_csv_line_over_the_limit_is_refused_without_reading_it_whole(tmp_path):
    path = tmp_path / "line.csv"
    with open(path, "w") as handle:
        handle.write("t,x\n0,")
        handle.write("1" * (30 << 20))
        handle.write("\n")
    with traced_peak() as memory:
        refused(lambda: load_recording(path), str(path), "line 2",
                f"CSV lines are limited to {MAX_CSV_LINE_CHARS:,}")
    assert memory["peak"] < 4 << 20


def test_csv_file_over_the_size_limit_is_refused_unread(tmp_path):
    path = tmp_path / "big.csv"
    path.write_text("t,x\n0,1\n")
    with open(path, "r+b") as handle:
        handle.truncate(MAX_CSV_BYTES + 1)  # sparse
    refused(lambda: load_recording(path), str(path), f"CSV files are limited to {MAX_CSV_BYTES:,}")


def test_csv_rows_kept_are_capped(tmp_path, monkeypatch):
    monkeypatch.setattr(csvtable, "MAX_FRAMES", 100)  # one column and its row numbers: 50 rows
    path = tmp_path / "rows.csv"
    path.write_text("x\n" + "1\n" * 50)
    assert len(read_csv(path)) == 50
    path.write_text("x\n" + "1\n" * 51)
    refused(lambda: read_csv(path), str(path), "line 52", "CSV tables are limited to 100 numbers")


def test_csv_reading_keeps_values_and_line_numbers(tmp_path):
    path = tmp_path / "gaps.csv"
    path.write_text("\ufeffhz;gain\r\n\r\n50;0,5\r\n100;1\r\n\r\n200;2,25\r\n")
    table = read_csv(path)
    assert table.delimiter == ";" and table.decimal_comma
    assert table.values.tolist() == [[50.0, 0.5], [100.0, 1.0], [200.0, 2.25]]
    assert table.lines.tolist() == [3, 4, 6]


def test_csv_time_column_giving_an_impossible_rate_is_refused(tmp_path):
    path = tmp_path / "ms.csv"  # times in milliseconds: 1.344 Hz read as seconds
    path.write_text("time,x\n" + "\n".join(f"{k / 1.344:.6f},{np.sin(k):.5f}" for k in range(300)))
    refused(lambda: load_recording(path), str(path), "time column 'time'", "in seconds?")


def test_csv_sniffing_of_quote_heavy_lines_is_quick(tmp_path):
    # csv.Sniffer takes minutes on 20 such lines of 64 k characters; the sample is bounded.
    path = tmp_path / "quotes.csv"
    path.write_text(("," + '"' * 1) * (MAX_CSV_LINE_CHARS // 2) + "\n" + "1\n" * 20)
    start = time.monotonic()
    with pytest.raises(RealPenError):
        load_recording(path, rate=RATE)
    assert time.monotonic() - start < 20


# --- JSON and XML --------------------------------------------------------------------------

@pytest.mark.parametrize("content, problem", [
    ("[" * 100_000 + "]" * 100_000, "nested"),
    ('{"c_p": ' + "1" * 5000 + "}", "longer than"),
])
def test_coupling_json_goes_through_the_bounded_reader(tmp_path, content, problem):
    path = tmp_path / "coupling.json"
    path.write_text(content)
    refused(lambda: Coupling.load(path), str(path), problem)


@pytest.mark.parametrize("replace, problem", [
    (("<SampleRate>1000</SampleRate>", "<SampleRate>1</SampleRate>"), f"{MIN_RATE_HZ}–"),
    (("<tri><value>1</value>", "<tri><value>" + "1" * 5000 + "</value>"), "limited to 64"),
    (("<mu>0.2</mu>", "<mu>" + "2" * 5000 + "</mu>"), "limited to 64"),
])
def test_hatt_values_out_of_limits_are_refused(tmp_path, replace, problem):
    path = tmp_path / "Models_Bad.xml"
    path.write_text(synthetic_xml(replace=replace))
    refused(lambda: load_hatt(path), str(path), problem)


def test_hatt_order_and_size_limits(tmp_path):
    path = tmp_path / "Models_Deep.xml"
    order = "".join(f"<value>{0.01 * k}</value>" for k in range(MAX_MODEL_ORDER + 1))
    path.write_text(synthetic_xml(replace=("<ARcoeff>", "<ARcoeff>" + order)))
    refused(lambda: load_hatt(path), str(path), f"limited to order {MAX_MODEL_ORDER}")
    path.write_text(synthetic_xml())
    with open(path, "r+b") as handle:
        handle.truncate(MAX_XML_BYTES + 1)
    refused(lambda: load_hatt(path), str(path), f"limited to {MAX_XML_BYTES:,}")


def test_hatt_synthesis_is_capped_at_max_frames(tmp_path):
    path = tmp_path / "Models_Synthetic.xml"
    path.write_text(synthetic_xml())
    fast = dataclasses.replace(load_hatt(path), rate=float(MAX_RATE_HZ))
    with pytest.raises(ParameterError) as caught:
        synthesize(fast, 100.0, 2.0, MAX_FRAMES / MAX_RATE_HZ + 1.0)
    assert caught.value.parameter == "duration_s" and f"{MAX_FRAMES:,}" in str(caught.value)


# --- whole command lines under an address-space limit ----------------------------------------

ADDRESS_SPACE = 2 << 30  # bytes: a normal call needs about 1 GiB of address space


def run_limited(*args, cwd: Path) -> subprocess.CompletedProcess:
    """``python -m realpen ARGS`` with at most ``ADDRESS_SPACE`` bytes of address space."""
    def limit() -> None:
        resource.setrlimit(resource.RLIMIT_AS, (ADDRESS_SPACE, ADDRESS_SPACE))

    # One BLAS/OpenMP thread: each thread's arena reserves address space of its own.
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1",
           "MKL_NUM_THREADS": "1"}
    return subprocess.run([sys.executable, "-m", "realpen", *map(str, args)], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=300, preexec_fn=limit)


@pytest.mark.slow
def test_a_good_recording_is_analysed_under_the_memory_limit(tmp_path):
    result = run_limited("analyze", example_recording_path(), cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert "Hz" in result.stdout


def _npz_bomb(tmp_path: Path) -> Path:
    # 1.4 × 10⁹ float64 declared (11 GB), 16 MiB of zeros deflated to about 16 kB.
    return write_npz(tmp_path / "bomb.npz", {"samples": npy_header((469_762_048, 3)),
                                             "rate": rate_member(RATE)},
                     zeros={"samples": 16 << 20})


def _long_wav(tmp_path: Path) -> Path:
    return forged_wav(tmp_path / "long.wav", 450_000_000)  # 900 MB, sparse


def _long_field(tmp_path: Path) -> Path:
    path = tmp_path / "field.csv"
    path.write_text("t,x\n0,1\n0.001," + "7" * (30 << 20) + "\n")
    return path


@pytest.mark.parametrize("make, limit", [
    # `analyze` streams: the streaming limit on samples, and on units (93 h of 100 ms units).
    (_npz_bomb, f"limited to {MAX_STREAM_SAMPLES:,} samples"),
    (_long_wav, f"an analysis takes at most {MAX_UNITS:,}"),
    (_long_field, f"CSV lines are limited to {MAX_CSV_LINE_CHARS:,}"),
])
@pytest.mark.slow
def test_worst_files_are_refused_in_one_line_under_the_memory_limit(tmp_path, make, limit):
    path = make(tmp_path)
    result = run_limited("analyze", path.name, cwd=tmp_path)
    assert result.returncode == 2, (result.returncode, result.stderr[-2000:])
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and path.name in lines[0] and limit in lines[0], result.stderr
    assert "Traceback" not in result.stderr


def test_npz_header_length_is_bounded_before_numpy_reads_it(tmp_path):
    """A .npy v2 header may declare 4 GiB; a deflate bomb would deliver it."""
    import struct

    path = tmp_path / "header.npz"
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as archive:
        archive.writestr("samples.npy", b"\x93NUMPY\x02\x00" + struct.pack("<I", 10**8)
                         + b" " * 10**8)  # 100 MB of header, ~100 kB on disk
    assert path.stat().st_size < 1_000_000
    with pytest.raises(RealPenError, match="100,000,000-byte .npy header; headers are limited"):
        load_recording(path)


def test_npz_values_that_take_no_bytes_are_refused(tmp_path):
    """A '<U0' array of 10^30 items is 0 bytes: it passes any size limit but not a count."""
    import io

    header = f"{{'descr': '<U0', 'fortran_order': False, 'shape': ({10**30},), }}"
    header = header.ljust(118) + "\n"
    members = {"axes.npy": np.lib.format.magic(1, 0) + len(header).to_bytes(2, "little")
               + header.encode()}
    for key, value in (("samples", np.zeros((2000, 3))), ("rate", np.float64(1344.0))):
        buffer = io.BytesIO()
        np.save(buffer, value)
        members[f"{key}.npy"] = buffer.getvalue()
    path = tmp_path / "u0.npz"
    with zipfile.ZipFile(path, "w") as archive:
        for name, data in members.items():
            archive.writestr(name, data)
    with pytest.raises(RealPenError, match="'axes' holds <U0 values, which take no bytes"):
        load_recording(path)
