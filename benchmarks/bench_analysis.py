"""Analysis throughput and memory of `realpen analyze`, streamed, on 3-axis 1344 Hz recordings.

Targets (issue 13): at least 5000× real time on one core for 1 h of 3-axis data, within 10× of
one `rfft` pass over the same units, and at most 300 MB peak resident memory for 24 h.

What it measures, all on one core (OMP/OPENBLAS/MKL threads 1) and in CPU time
(`time.process_time`), so a busy machine does not mislead:

- the streamed analysis (`realpen.io.blocks.open_stream` + `realpen.dsp.stream.analyze_stream`)
  of a 16-bit WAV written in blocks to a temporary folder: 1 min, 1 h and 4 h (and 24 h with
  `--day`), each in a fresh process so that peak memory figures do not mix;
- the same algorithm on the 1 h array in memory (`analyze_units`), without the file;
- one `np.fft.rfft` pass over the same units: the three axes' Hann-windowed 134-sample units,
  no padding, in the same batches (the floor any per-unit spectrum costs);
- the old in-memory path on the 1 h file for comparison: `load_recording`, whole-signal DFT321
  and high-pass (`prepare`), then `realpen.dsp.spectrum.analyze`.

The peak resident memory is the high-water mark of the measuring process (VmHWM), which includes
the Python interpreter and the imported libraries (printed as "at start").

Usage: python benchmarks/bench_analysis.py [--day] [--repeat 3] [--hours 1/60 1 4]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_name, "1")

import numpy as np  # noqa: E402

RATE = 1344
AXES = 3
WRITE_FRAMES = 1 << 20


def peak_rss_mib() -> float:
    """This process's peak resident memory in MiB: VmHWM of its own address space. (Linux's
    ru_maxrss of a child starts at its parent's size when forked, which would mix the
    figures.)"""
    try:
        with open("/proc/self/status") as status:
            for line in status:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) / 1024
    except OSError:
        pass
    import resource

    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def write_recording(path: Path, seconds: float, seed: int = 0) -> int:
    """A 3-axis 16-bit WAV of pen-like vibration (tones that drift in level, on noise, with a
    gravity offset on z), written a block at a time; returns its frames."""
    import soundfile as sf

    frames = int(round(seconds * RATE))
    rng = np.random.default_rng(seed)
    tones = np.array([87.0, 180.0, 264.0, 406.0])
    gains = np.array([[0.08, 0.05, 0.03, 0.01], [0.05, 0.06, 0.02, 0.01],
                      [0.03, 0.02, 0.04, 0.02]])
    with sf.SoundFile(path, "w", samplerate=RATE, channels=AXES, subtype="PCM_16") as out:
        for start in range(0, frames, WRITE_FRAMES):
            n = min(WRITE_FRAMES, frames - start)
            t = (start + np.arange(n)) / RATE
            drift = 1 + 0.5 * np.sin(2 * np.pi * t / 7.3)[:, None]  # a slow change in level
            block = 0.02 * rng.standard_normal((n, AXES))
            for k, freq in enumerate(tones):
                block += np.sin(2 * np.pi * freq * t + k)[:, None] * gains[:, k] * drift
            block[:, 2] += 0.3
            out.write(block)
    return frames


def child(mode: str, path: str, repeat: int) -> dict:
    """One measurement, in its own process; returns what it saw."""
    start_rss = peak_rss_mib()
    if mode == "stream":
        from realpen.dsp.stream import analyze_stream
        from realpen.io.blocks import open_stream

        start_rss = peak_rss_mib()
        times = []
        for _ in range(repeat):
            begin = time.process_time()
            stream = open_stream(path)
            result = analyze_stream(stream)
            times.append(time.process_time() - begin)
        frames = stream.frames
    elif mode == "old":
        from realpen.dsp.filters import prepare
        from realpen.dsp.spectrum import analyze
        from realpen.io.recording import load_recording

        start_rss = peak_rss_mib()
        times = []
        for _ in range(repeat):
            begin = time.process_time()
            recording = load_recording(path)
            prepared = prepare(recording)
            result = analyze(prepared.mono, prepared.rate)
            times.append(time.process_time() - begin)
            frames = len(recording.samples)
            del recording, prepared
    else:  # "memory": the algorithm on an array, and one plain rfft pass over the same units
        import soundfile as sf
        from scipy import signal

        from realpen.dsp.stream import UNIT_BATCH, analyze_units

        samples, _ = sf.read(path, dtype="float64", always_2d=True)
        start_rss = peak_rss_mib()
        times, rfft_times = [], []
        unit = 134
        units = len(samples) // unit
        window = signal.get_window("hann", unit)
        windowed = np.ascontiguousarray(
            samples[:units * unit].reshape(units, unit, AXES).transpose(0, 2, 1)) * window
        for _ in range(repeat):
            begin = time.process_time()
            result = analyze_units(samples, RATE)
            times.append(time.process_time() - begin)
            begin = time.process_time()
            for first in range(0, units, UNIT_BATCH):
                np.fft.rfft(windowed[first:first + UNIT_BATCH], axis=-1)
            rfft_times.append(time.process_time() - begin)
        frames = len(samples)
        return {"cpu_s": min(times), "rfft_cpu_s": min(rfft_times), "frames": frames,
                "start_mib": start_rss, "peak_mib": peak_rss_mib()}
    return {"cpu_s": min(times), "frames": frames, "units": len(result.starts_s),
            "start_mib": start_rss, "peak_mib": peak_rss_mib()}


def measure(mode: str, path: Path, repeat: int) -> dict:
    """:func:`child` in a fresh Python process."""
    out = subprocess.run([sys.executable, __file__, "--child", mode, str(path), "--repeat",
                          str(repeat)], capture_output=True, text=True, check=True)
    return json.loads(out.stdout.splitlines()[-1])


def describe(seconds: float) -> str:
    return f"{seconds / 3600:g} h" if seconds >= 3600 else f"{seconds / 60:g} min"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--day", action="store_true", help="also 24 h (a 700 MB temporary WAV)")
    parser.add_argument("--repeat", type=int, default=3, help="runs per figure (best is shown)")
    parser.add_argument("--hours", type=float, nargs="+", default=[1 / 60, 1.0, 4.0])
    parser.add_argument("--child", nargs=2, metavar=("MODE", "PATH"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        print(json.dumps(child(args.child[0], args.child[1], args.repeat)))
        return
    hours = sorted(set(args.hours) | ({24.0} if args.day else set()))
    print(f"one core, CPU time; {AXES} axes at {RATE} Hz, 16-bit WAV written to a temporary "
          f"folder; best of {args.repeat} (24 h: 1)")
    print(f"{'recording':>10} {'path':<34} {'CPU s':>8} {'× real time':>12} "
          f"{'peak RSS MiB':>13} {'at start':>9}")
    rows = {}
    with tempfile.TemporaryDirectory(prefix="realpen-bench-") as folder:
        for length in hours:
            seconds = length * 3600
            path = Path(folder) / f"rec-{seconds:.0f}s.wav"
            write_recording(path, seconds)
            runs = [("stream", "streamed from the WAV")]
            if abs(length - 1.0) < 1e-9:
                runs += [("memory", "same algorithm, array in memory"),
                         ("old", "old: load + whole-signal DFT321")]
            for mode, label in runs:
                result = measure(mode, path, 1 if length >= 24 else args.repeat)
                duration = result["frames"] / RATE
                rows[(length, mode)] = result
                print(f"{describe(seconds):>10} {label:<34} {result['cpu_s']:8.3f} "
                      f"{duration / result['cpu_s']:12.0f} {result['peak_mib']:13.0f} "
                      f"{result['start_mib']:9.0f}")
                if mode == "memory":
                    print(f"{'':>10} {'one rfft pass over the same units':<34} "
                          f"{result['rfft_cpu_s']:8.3f} "
                          f"{duration / result['rfft_cpu_s']:12.0f}")
            path.unlink()
    if (1.0, "stream") in rows and (1.0, "memory") in rows:
        stream, memory = rows[(1.0, "stream")], rows[(1.0, "memory")]
        speed = stream["frames"] / RATE / stream["cpu_s"]
        print(f"\n1 h streamed: {speed:.0f}× real time (target ≥ 5000×): "
              f"{'met' if speed >= 5000 else 'NOT met'}")
        for name, cpu in (("streamed from the file", stream["cpu_s"]),
                          ("array in memory", memory["cpu_s"])):
            ratio = cpu / memory["rfft_cpu_s"]
            print(f"ratio to one rfft pass, {name}: {ratio:.1f}× (target ≤ 10×): "
                  f"{'met' if ratio <= 10 else 'NOT met'}")
        if (1.0, "old") in rows:
            old = rows[(1.0, "old")]
            print(f"old in-memory path: {stream['frames'] / RATE / old['cpu_s']:.0f}× real time, "
                  f"{old['peak_mib']:.0f} MiB; streamed is {old['cpu_s'] / stream['cpu_s']:.1f}× "
                  f"faster in {stream['peak_mib']:.0f} MiB")
    if (24.0, "stream") in rows:
        peak = rows[(24.0, "stream")]["peak_mib"] * 1.048576
        print(f"24 h streamed: peak {peak:.0f} MB resident (target ≤ 300 MB): "
              f"{'met' if peak <= 300 else 'NOT met'}")


if __name__ == "__main__":
    main()
