"""Analysis throughput on one hour of 3-axis 1344 Hz data (target ≥ 2000× real time, one core).

Measures the whole analysis path of `realpen analyze`: DFT321 of three axes, zero-phase 30 Hz
high-pass, 100 ms unit spectra, top-10 peaks per unit and the stationary-run selection. Prints
seconds of recording analysed per wall-clock second and the peak resident memory.

Usage: python benchmarks/bench_analysis.py [--hours 1] [--repeat 3]
"""

from __future__ import annotations

import argparse
import os
import resource
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from realpen.dsp.filters import prepare  # noqa: E402
from realpen.dsp.spectrum import analyze  # noqa: E402
from realpen.io.recording import Recording  # noqa: E402

RATE = 1344.0


def peak_rss_mib() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--hours", type=float, default=1.0)
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    frames = int(args.hours * 3600 * RATE)
    rng = np.random.default_rng(0)
    samples = rng.standard_normal((frames, 3)).astype(np.float64)
    recording = Recording(samples, RATE, ("x", "y", "z"), units="m/s^2", source="benchmark")
    del samples
    before = peak_rss_mib()
    duration = frames / RATE
    timings = []
    for _ in range(args.repeat):
        start = time.perf_counter()
        prepared = prepare(recording)
        result = analyze(prepared.mono, prepared.rate, unit_ms=100, top=10, count=15)
        timings.append(time.perf_counter() - start)
        del prepared
    best = min(timings)
    print(f"recording: {duration:.0f} s ({args.hours:g} h), 3 axes at {RATE:g} Hz, "
          f"{len(result.starts_s)} units of 100 ms")
    print(f"analysis time: best {best:.2f} s, median {np.median(timings):.2f} s over {args.repeat} runs")
    print(f"throughput: {duration / best:.0f}x real time (best), "
          f"{duration / np.median(timings):.0f}x (median); target >= 2000x")
    print(f"peak memory: {peak_rss_mib():.0f} MiB resident "
          f"(input recording alone {recording.samples.nbytes / 2**20:.0f} MiB; "
          f"{before:.0f} MiB before analysis)")


if __name__ == "__main__":
    main()
