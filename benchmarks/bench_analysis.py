"""Analysis throughput and memory of `realpen analyze`, streamed, on 3-axis 1344 Hz recordings.

Targets (issue 23): the streamed analysis of 1 h within 1.5× of one `rfft` pass (n = 134, the
unit) and within 3× of a smooth-length 3-axis `rfft` pass over the same units, read from the
file; its peak resident memory at most 2× that of a process that only decodes the file; whole
commands at most 300 MB peak resident memory for 24 h (issue 13: at least 5000× real time).

What it measures, all on one core (OMP/OPENBLAS/MKL threads 1) and in CPU time
(`time.process_time`), so a busy machine does not mislead:

- the streamed analysis (`realpen.io.blocks.open_stream` + `realpen.dsp.stream.analyze_stream`)
  of a 16-bit WAV written in blocks to a temporary folder: 1 min, 1 h and 4 h (and 24 h with
  `--day`), each in a fresh process so that peak memory figures do not mix;
- the decode-only floor: a process that imports `realpen.io.blocks` and only reads the same
  file in the same blocks (decoding and the value checks every analysis needs);
- the same algorithm on the 1 h array in memory (`analyze_units`), without the file;
- two FFT floors over the same units: the three axes' Hann-windowed 134-sample units in the
  same batches, one `np.fft.rfft` pass at n = 134 (no padding; an awkward length, 2 × 67) and
  one at n = 135 (the smallest 5-smooth length that holds a unit);
- the old in-memory path on the 1 h file for comparison: `load_recording`, whole-signal DFT321
  and high-pass (`prepare`), then `realpen.dsp.spectrum.analyze`;
- whole commands at 1 h and more: peak resident memory (and CPU) of `python -m realpen analyze
  REC.wav` and `python -m realpen profile build --name bench --vibration REC.wav --sound
  SOUND.wav -o OUT` (SOUND: 1 s of 48 kHz noise) from `/usr/bin/time -v`, in their default
  thread settings; a command that refuses the recording is reported as such.

The peak resident memory of a measuring process is its high-water mark (VmHWM), which includes
the Python interpreter and the imported libraries (printed as "at start").

Usage: python benchmarks/bench_analysis.py [--day] [--repeat 3] [--hours 1/60 1 4]
"""

from __future__ import annotations

import argparse
import json
import os
import re
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
UNIT = 134  # samples in a 100 ms unit at 1344 Hz
SMOOTH = 135  # the smallest length ≥ UNIT whose factors are 2, 3 and 5 only
WRITE_FRAMES = 1 << 20
TIME = "/usr/bin/time"


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


def write_sound(path: Path) -> None:
    """1 s of 48 kHz noise, the friction sound `profile build` needs."""
    import soundfile as sf

    noise = 0.1 * np.random.default_rng(1).standard_normal(48000)
    sf.write(path, noise, 48000, subtype="PCM_16")


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
        scipy = sorted(name for name in sys.modules if name.startswith("scipy."))
        return {"cpu_s": min(times), "frames": frames, "units": len(result.starts_s),
                "start_mib": start_rss, "peak_mib": peak_rss_mib(),
                "scipy": sorted({".".join(name.split(".")[:2]) for name in scipy
                                 if not name.split(".")[1].startswith("_")})}
    if mode == "decode":
        from realpen.dsp.stream import UNIT_BATCH
        from realpen.io.blocks import open_stream

        start_rss = peak_rss_mib()
        times = []
        for _ in range(repeat):
            begin = time.process_time()
            stream = open_stream(path)
            for _block in stream.iter_blocks(UNIT_BATCH * UNIT):
                pass
            times.append(time.process_time() - begin)
        return {"cpu_s": min(times), "frames": stream.frames, "start_mib": start_rss,
                "peak_mib": peak_rss_mib()}
    if mode == "old":
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
        return {"cpu_s": min(times), "frames": frames, "units": len(result.starts_s),
                "start_mib": start_rss, "peak_mib": peak_rss_mib()}
    # "memory": the algorithm on an array, and the two rfft floors over the same units
    import soundfile as sf

    from realpen.dsp.stream import UNIT_BATCH, analyze_units

    samples, _ = sf.read(path, dtype="float64", always_2d=True)
    start_rss = peak_rss_mib()
    units = len(samples) // UNIT
    window = 0.5 - 0.5 * np.cos(2 * np.pi * np.arange(UNIT) / UNIT)  # periodic Hann
    windowed = np.ascontiguousarray(
        samples[:units * UNIT].reshape(units, UNIT, AXES).transpose(0, 2, 1)) * window
    times, floors = [], {UNIT: [], SMOOTH: []}
    for _ in range(repeat):  # round robin, so that a busy spell does not favour one
        begin = time.process_time()
        analyze_units(samples, RATE)
        times.append(time.process_time() - begin)
        for length, spent in floors.items():
            begin = time.process_time()
            for first in range(0, units, UNIT_BATCH):
                np.fft.rfft(windowed[first:first + UNIT_BATCH], n=length, axis=-1)
            spent.append(time.process_time() - begin)
    return {"cpu_s": min(times), "rfft_cpu_s": min(floors[UNIT]),
            "smooth_cpu_s": min(floors[SMOOTH]), "frames": len(samples),
            "start_mib": start_rss, "peak_mib": peak_rss_mib()}


def measure(mode: str, path: Path, repeat: int) -> dict:
    """:func:`child` in a fresh Python process."""
    out = subprocess.run([sys.executable, __file__, "--child", mode, str(path), "--repeat",
                          str(repeat)], capture_output=True, text=True, check=True)
    return json.loads(out.stdout.splitlines()[-1])


def command_rss(arguments: list[str], folder: Path) -> dict:
    """Peak resident memory (MiB) and CPU (s) of ``python -m realpen ARGUMENTS`` as
    ``/usr/bin/time -v`` reports them, and whether the command succeeded."""
    environment = {key: value for key, value in os.environ.items()
                   if key not in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")}
    out = subprocess.run([TIME, "-v", sys.executable, "-m", "realpen", *arguments],
                         capture_output=True, text=True, cwd=folder, env=environment)
    report = out.stderr
    rss = re.search(r"Maximum resident set size \(kbytes\): (\d+)", report)
    user = re.search(r"User time \(seconds\): ([\d.]+)", report)
    system = re.search(r"System time \(seconds\): ([\d.]+)", report)
    lines = [line for line in report.splitlines() if line.strip()
             and not line.startswith("\t") and "Command exited" not in line]
    return {"ok": out.returncode == 0, "code": out.returncode,
            "peak_mib": int(rss.group(1)) / 1024 if rss else float("nan"),
            "cpu_s": (float(user.group(1)) + float(system.group(1))) if user and system
            else float("nan"),
            "message": lines[-1].strip() if lines else ""}


def describe(seconds: float) -> str:
    return f"{seconds / 3600:g} h" if seconds >= 3600 else f"{seconds / 60:g} min"


def verdict(met: bool) -> str:
    return "met" if met else "NOT met"


def load_text() -> str:
    one, five, fifteen = os.getloadavg()
    return f"{one:.2f} {five:.2f} {fifteen:.2f} (1, 5, 15 min; {os.cpu_count()} cores)"


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
    print(f"machine load at start: {load_text()}")
    print(f"one core, CPU time; {AXES} axes at {RATE} Hz, 16-bit WAV written to a temporary "
          f"folder; best of {args.repeat} (24 h: 1)")
    print(f"{'recording':>10} {'path':<36} {'CPU s':>8} {'× real time':>12} "
          f"{'peak RSS MiB':>13} {'at start':>9}")
    rows, commands = {}, {}
    with tempfile.TemporaryDirectory(prefix="realpen-bench-") as folder_name:
        folder = Path(folder_name)
        sound = folder / "sound.wav"
        write_sound(sound)
        for length in hours:
            seconds = length * 3600
            path = folder / f"rec-{seconds:.0f}s.wav"
            write_recording(path, seconds)
            runs = [("stream", "streamed from the WAV"), ("decode", "decode only (the floor)")]
            if abs(length - 1.0) < 1e-9:
                runs += [("memory", "same algorithm, array in memory"),
                         ("old", "old: load + whole-signal DFT321")]
            for mode, label in runs:
                result = measure(mode, path, 1 if length >= 24 else args.repeat)
                duration = result["frames"] / RATE
                rows[(length, mode)] = result
                print(f"{describe(seconds):>10} {label:<36} {result['cpu_s']:8.3f} "
                      f"{duration / result['cpu_s']:12.0f} {result['peak_mib']:13.0f} "
                      f"{result['start_mib']:9.0f}")
                if mode == "memory":
                    for key, name in (("rfft_cpu_s", f"one rfft pass, n = {UNIT}"),
                                      ("smooth_cpu_s", f"one rfft pass, n = {SMOOTH}")):
                        print(f"{'':>10} {name + ' (3 axes)':<36} {result[key]:8.3f} "
                              f"{duration / result[key]:12.0f}")
            if length >= 1.0:
                for name, arguments in (
                        ("analyze", ["analyze", str(path)]),
                        ("profile build", ["profile", "build", "--name", "bench", "--vibration",
                                           str(path), "--sound", str(sound), "-o",
                                           str(folder / "bench-profile"), "--force"])):
                    commands[(length, name)] = command_rss(arguments, folder)
            path.unlink()
    print("\nwhole commands (/usr/bin/time -v, default threads): peak RSS MiB, CPU s")
    for (length, name), result in commands.items():
        state = "ok" if result["ok"] else f"refused (exit {result['code']}): {result['message']}"
        print(f"{describe(length * 3600):>10} realpen {name:<14} {result['peak_mib']:8.0f} MiB "
              f"{result['cpu_s']:8.2f} s  {state}")
    if (1.0, "stream") in rows and (1.0, "memory") in rows:
        stream, memory = rows[(1.0, "stream")], rows[(1.0, "memory")]
        decode = rows[(1.0, "decode")]
        speed = stream["frames"] / RATE / stream["cpu_s"]
        print(f"\n1 h streamed: {speed:.0f}× real time (target ≥ 5000×): {verdict(speed >= 5000)}")
        print(f"decode-only floor: {decode['cpu_s']:.3f} s CPU "
              f"({decode['cpu_s'] / stream['cpu_s']:.0%} of the streamed analysis), "
              f"{decode['peak_mib']:.0f} MiB peak RSS")
        for name, cpu in (("streamed from the file", stream["cpu_s"]),
                          ("array in memory", memory["cpu_s"])):
            ratio = cpu / memory["rfft_cpu_s"]
            smooth = cpu / memory["smooth_cpu_s"]
            print(f"{name}: {ratio:.2f}× one rfft pass at n = {UNIT} (target ≤ 1.5×): "
                  f"{verdict(ratio <= 1.5)}; {smooth:.2f}× one at n = {SMOOTH} (target ≤ 3×): "
                  f"{verdict(smooth <= 3)}")
        memory_ratio = stream["peak_mib"] / decode["peak_mib"]
        print(f"1 h streamed peak RSS: {stream['peak_mib']:.0f} MiB, {memory_ratio:.2f}× the "
              f"decode-only floor (target ≤ 2×): {verdict(memory_ratio <= 2)}")
        print(f"scipy modules after analyze_stream: {', '.join(stream['scipy']) or 'none'}")
        if (1.0, "old") in rows:
            old = rows[(1.0, "old")]
            print(f"old in-memory path: {stream['frames'] / RATE / old['cpu_s']:.0f}× real time, "
                  f"{old['peak_mib']:.0f} MiB; streamed is {old['cpu_s'] / stream['cpu_s']:.1f}× "
                  f"faster in {stream['peak_mib']:.0f} MiB")
    for name in ("analyze", "profile build"):
        if (24.0, name) in commands:
            result = commands[(24.0, name)]
            peak = result["peak_mib"] * 1.048576
            print(f"24 h realpen {name}: peak {peak:.0f} MB resident (target ≤ 300 MB): "
                  f"{verdict(result['ok'] and peak <= 300)}")
    print(f"machine load at end: {load_text()}")


if __name__ == "__main__":
    main()
