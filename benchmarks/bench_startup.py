"""Start-up cost of the small `realpen` commands, against a bare `python -c "import numpy"`.

Target (issue 23): a command that neither plots nor analyses statistics costs at most 2× the
process CPU of a numpy import — `realpen analyze` on a 1 min recording, `profile list`,
`export` of a bundled pen and `--help`. `stats power` is measured too (it simulates and tests,
so it has no target). Two rows without RealPen import only the libraries `analyze` (numpy,
soundfile, typer, rich's table) and `profile list` (numpy, soundfile, typer, pydantic) need: the
floor those commands cannot go below.

Each command runs in a fresh process, round robin, ``--repeats`` times (median shown): process
CPU is the child's user + system time and peak RSS its ``ru_maxrss``, both from ``os.wait4``.
This process imports the standard library only and keeps its own memory small, because
Linux's ``ru_maxrss`` of a child starts at its parent's size when it is forked; the recording
(1 min, 3 axes at 1344 Hz, 16-bit) is written with the ``wave`` module. Profiles are looked up
in an empty ``REALPEN_HOME``, so only the bundled ones are listed. A first, unmeasured run of
each command writes the modules' bytecode caches (as installing does; ``PYTHONDONTWRITEBYTECODE``
is dropped for the children), so no figure includes compiling a source file that changed. The
machine's load is printed before and after: a busy machine adds CPU time to every figure alike.

Last, the slowest command (and the slowest with a target, if that is another) runs once more
under ``-X importtime``: its modules by cumulative import time show where the time goes.

Usage: python benchmarks/bench_startup.py [--repeats 5] [--top 25]
"""

from __future__ import annotations

import argparse
import math
import os
import statistics
import subprocess
import sys
import tempfile
import wave
from array import array
from pathlib import Path

RATE = 1344
AXES = 3
SECONDS = 60
TARGET = 2.0  # × the CPU of a numpy import

for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_name, "1")


def write_recording(path: Path, seconds: float = SECONDS) -> None:
    """A 3-axis 16-bit WAV of pen-like vibration: four tones that drift in level, on a
    deterministic noise, with a gravity offset on z."""
    tones = (87.0, 180.0, 264.0, 406.0)
    gains = ((0.08, 0.05, 0.03, 0.01), (0.05, 0.06, 0.02, 0.01), (0.03, 0.02, 0.04, 0.02))
    frames = int(round(seconds * RATE))
    codes = array("h")
    state = 12345
    for n in range(frames):
        t = n / RATE
        drift = 1 + 0.5 * math.sin(2 * math.pi * t / 7.3)
        for axis in range(AXES):
            state = (1103515245 * state + 12345) & 0x7FFFFFFF  # a small LCG: no numpy here
            value = 0.02 * (state / 0x3FFFFFFF - 1.0)
            value += drift * sum(gain * math.sin(2 * math.pi * freq * t + k)
                                 for k, (freq, gain) in enumerate(zip(tones, gains[axis])))
            value += 0.3 if axis == 2 else 0.0
            codes.append(max(-32768, min(32767, round(value * 32767))))
    if sys.byteorder == "big":
        codes.byteswap()
    with wave.open(str(path), "wb") as out:
        out.setnchannels(AXES)
        out.setsampwidth(2)
        out.setframerate(RATE)
        out.writeframes(codes.tobytes())


def commands(folder: Path) -> list[tuple[str, list[str], bool]]:
    """(label, arguments after ``python``, whether the ≤ 2× target applies)."""
    recording = folder / "recording-1min.wav"
    realpen = ["-m", "realpen"]
    return [
        ("python -c 'import numpy'", ["-c", "import numpy"], False),
        # The libraries alone, no RealPen: what `analyze` and `profile list` cannot do without.
        ("libraries of analyze", ["-c", "import numpy, soundfile, typer.main, rich.table"],
         False),
        ("libraries of profile list", ["-c", "import numpy, soundfile, typer.main\n"
                                       "from pydantic import BaseModel, Field"], False),
        ("realpen --help", [*realpen, "--help"], True),
        ("realpen analyze (1 min)", [*realpen, "analyze", str(recording)], True),
        ("realpen profile list", [*realpen, "profile", "list"], True),
        ("realpen export pencil (ahap)",
         [*realpen, "export", "pencil", "--format", "ahap", "-o", str(folder / "pencil.ahap"),
          "--force"], True),
        ("realpen stats power (10 sims)",
         [*realpen, "stats", "power", "study1", "-n", "8", "--sims", "10"], False),
    ]


def run(arguments: list[str], env: dict[str, str], cwd: Path) -> tuple[float, float]:
    """Run ``python arguments`` once; its CPU seconds (user + system) and peak RSS in MiB."""
    child = subprocess.Popen([sys.executable, *arguments], cwd=cwd, env=env,
                             stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    stderr = child.stderr.read()
    child.stderr.close()
    _, status, usage = os.wait4(child.pid, 0)
    child.returncode = os.waitstatus_to_exitcode(status)
    if child.returncode != 0:
        raise SystemExit(f"{' '.join(arguments)} failed ({child.returncode}):\n"
                         f"{stderr.decode(errors='replace')}")
    return usage.ru_utime + usage.ru_stime, usage.ru_maxrss / 1024


def import_times(arguments: list[str], env: dict[str, str], cwd: Path) -> list[tuple[int, int, str]]:
    """``-X importtime`` of one run: (cumulative µs, depth, module), slowest first."""
    out = subprocess.run([sys.executable, "-X", "importtime", *arguments], cwd=cwd, env=env,
                         stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, check=True)
    rows = []
    for line in out.stderr.splitlines():
        if not line.startswith("import time:") or "cumulative" in line:
            continue
        _, cumulative, name = line.split("|")
        depth = (len(name) - len(name.lstrip()) - 1) // 2
        rows.append((int(cumulative), depth, name.strip()))
    return sorted(rows, reverse=True)


def load() -> str:
    return " ".join(f"{value:.2f}" for value in os.getloadavg())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5, help="runs of each command (median)")
    parser.add_argument("--top", type=int, default=25, help="modules shown by import time")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="realpen-startup-") as name:
        folder = Path(name)
        write_recording(folder / "recording-1min.wav")
        (folder / "home").mkdir()
        env = {**os.environ, "REALPEN_HOME": str(folder / "home")}
        for variable in ("PYTHONDONTWRITEBYTECODE", "PYTHONPROFILEIMPORTTIME"):
            env.pop(variable, None)  # the warm-up run leaves valid bytecode, as an install has
        runs = commands(folder)
        print(f"machine load (1, 5, 15 min) before: {load()}; {os.cpu_count()} cores; "
              f"Python {sys.version.split()[0]}")
        for arguments in (arguments for _, arguments, _ in runs):  # warm the caches once
            run(arguments, env, folder)
        cpu: dict[str, list[float]] = {label: [] for label, _, _ in runs}
        rss: dict[str, list[float]] = {label: [] for label, _, _ in runs}
        for _ in range(args.repeats):
            for label, arguments, _ in runs:
                seconds, mib = run(arguments, env, folder)
                cpu[label].append(seconds)
                rss[label].append(mib)
        print(f"machine load after: {load()}")
        median = {label: statistics.median(values) for label, values in cpu.items()}
        floor = median[runs[0][0]]
        print(f"\nprocess CPU (user + system), median of {args.repeats} round-robin runs; "
              f"target ≤ {TARGET:g}× a numpy import where it applies")
        print(f"{'command':<32} {'CPU s':>7} {'× numpy':>8} {'peak RSS MiB':>13}  target")
        for label, _, targeted in runs:
            ratio = median[label] / floor
            verdict = ("met" if ratio <= TARGET else "NOT met") if targeted else "-"
            print(f"{label:<32} {median[label]:7.3f} {ratio:8.2f} "
                  f"{statistics.median(rss[label]):13.1f}  {verdict}")
        slowest = max(runs[1:], key=lambda item: median[item[0]])
        targeted = max((item for item in runs if item[2]), key=lambda item: median[item[0]])
        for label, arguments, _ in [slowest] + ([targeted] if targeted != slowest else []):
            print(f"\n{label}: modules by cumulative import time (-X importtime, one run; "
                  f"indent = nesting)")
            for cumulative, depth, module in import_times(arguments, env, folder)[:args.top]:
                print(f"{cumulative / 1000:9.1f} ms  {'  ' * min(depth, 8)}{module}")


if __name__ == "__main__":
    main()
