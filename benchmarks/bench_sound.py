"""Loop-unit scan speed: every 300 ms window, every 5 ms, of a 48 kHz friction-like signal.

Times :func:`realpen.sound.scan_windows` (the search behind ``realpen sound loop``) on a 4.8 s
signal (the length of an LMT-108 recording) and on a 300 s one, one core. Prints, per signal,
the best wall-clock time in seconds over ``--repeat`` runs and how many times faster than real
time that is. Speed targets are measured here, not asserted by timed tests, which would flake on
slow shared machines.

Usage: python benchmarks/bench_sound.py [--seconds 4.8 300] [--repeat 3]
"""

from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402
from scipy import signal  # noqa: E402

from realpen.sound.loop import HOP_MS, UNIT_MS, scan_windows  # noqa: E402

RATE = 48000


def friction_like(seconds: float, seed: int = 0) -> np.ndarray:
    """Band-passed noise (300 Hz–6 kHz) at −26 dBFS RMS, slowly swelling like a hand."""
    frames = int(round(seconds * RATE))
    rng = np.random.default_rng(seed)
    sos = signal.butter(2, [300, 6000], btype="bandpass", fs=RATE, output="sos")
    x = signal.sosfilt(sos, rng.standard_normal(frames))
    swell = 1 + 0.3 * np.sin(2 * np.pi * 0.7 * np.arange(frames) / RATE)
    return 0.05 * swell * x / x.std()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, nargs="+", default=[4.8, 300.0],
                        help="signal lengths in s (default 4.8 and 300)")
    parser.add_argument("--repeat", type=int, default=3, help="runs per length; the best counts")
    args = parser.parse_args()
    print(f"loop-unit scan: {UNIT_MS:g} ms windows every {HOP_MS:g} ms at {RATE} Hz, one core")
    for seconds in args.seconds:
        x = friction_like(seconds)
        timings = []
        for _ in range(max(1, args.repeat)):
            began = time.perf_counter()
            scan = scan_windows(x, RATE)
            timings.append(time.perf_counter() - began)
        best = min(timings)
        print(f"scan {seconds:g} s signal ({len(scan.starts)} windows): {best:.3f} s "
              f"({seconds / best:.0f}x real time; median {np.median(timings):.3f} s over "
              f"{len(timings)} runs)")


if __name__ == "__main__":
    main()
