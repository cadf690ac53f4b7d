"""The actuator measurement offline: CPU time of the analysis and its accuracy over noise draws.

What it measures, on one core (OMP/OPENBLAS/MKL threads 1) and in CPU time
(`time.process_time`), so a busy machine does not mislead:

- `realpen.tactile.measure.analyse_sweep` on captures of 4, 10 and 40 sweep loops (2 s each, at
  the LIS3DH's 1344 Hz × 1.013, three axes), the rate given 1e-5 off (no refinement needed)
  and 1.5 % off (the drift refined from the sweep);
- `realpen.tactile.multisine.flatness` on 4 loops of the equalised multisine;
- the accuracy over `--draws` noise draws and start phases: the fitted f0's error (%), the
  largest |H| error over 40–500 Hz normalised at f0 (dB), the smallest coherence there.

The pen's loop is simulated as in tests/test_actuator_measure.py: a bilinear LRA (f0 175 Hz,
Q 8) at 8 kHz, read at the sensor's times from its Fourier series below 660 Hz, 5 mg RMS noise
and 1 mg steps.

Usage: python benchmarks/bench_actuator_measure.py [--draws 8]
"""

from __future__ import annotations

import argparse
import os

for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_name, "1")

import time  # noqa: E402

import numpy as np  # noqa: E402
from scipy import signal  # noqa: E402

from realpen.tactile.measure import analyse_sweep, fit_resonance, sweep_pattern  # noqa: E402
from realpen.tactile.multisine import equalised_multisine, flatness  # noqa: E402

G = 9.80665
PEN_RATE, TRUE_RATE, F0, Q = 8000, 1344 * 1.013, 175.0, 8.0
DIRECTION = np.array([0.3, 0.9, 0.3]) / np.linalg.norm([0.3, 0.9, 0.3])


def lra():
    w0 = 2 * PEN_RATE * np.tan(np.pi * F0 / PEN_RATE)
    return signal.bilinear([w0 / Q, 0.0], [1.0, w0 / Q, w0 ** 2], PEN_RATE)


def sensed(loop: np.ndarray, seconds: float, seed: int, start_s: float) -> np.ndarray:
    n = len(loop)
    response = signal.freqz(*lra(), worN=np.fft.rfftfreq(n, 1 / PEN_RATE), fs=PEN_RATE)[1]
    moved = np.fft.irfft(np.fft.rfft(loop) * response, n)
    period = n / PEN_RATE
    harmonics = np.arange(int(660 * period) + 1)
    coefficients = np.fft.rfft(moved)[harmonics] / n
    coefficients[1:] *= 2
    count, block = int(seconds * TRUE_RATE), 1024
    steps = np.exp(2j * np.pi * np.outer(np.arange(block) / TRUE_RATE, harmonics) / period)
    values = np.empty(count)
    for first in range(0, count, block):
        phase = np.exp(2j * np.pi * harmonics * (start_s + first / TRUE_RATE) / period)
        values[first:first + block] = np.real(steps @ (coefficients * phase))[:count - first]
    rng = np.random.default_rng(seed)
    axes = values[:, None] * DIRECTION[None] + rng.normal(0.0, 0.005, (count, 3))
    return np.round(axes / 0.001) * 0.001 * G


def cpu(function, *args, **kwargs) -> tuple[float, object]:
    start = time.process_time()
    result = function(*args, **kwargs)
    return time.process_time() - start, result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--draws", type=int, default=8)
    args = parser.parse_args()
    sweep = sweep_pattern(PEN_RATE)
    truth = np.abs(signal.freqz(*lra(), worN=[F0], fs=PEN_RATE)[1][0])
    print("analyse_sweep, CPU s:")
    for loops in (4, 10, 40):
        capture = sensed(sweep.samples, (loops + 1) * sweep.period_s + 0.3, 1, 0.77)
        for label, factor in (("rate 1e-5 off", 1 + 1e-5), ("rate 1.5 % off", 0.985)):
            seconds, _ = cpu(analyse_sweep, capture, TRUE_RATE * factor, sweep)
            print(f"  {loops:3d} loops ({capture.shape[0] / TRUE_RATE:5.1f} s), {label}: "
                  f"{seconds:.3f}")
    multisine = equalised_multisine("lra:f0=175,q=8", PEN_RATE)
    capture = sensed(multisine.samples, 5 * multisine.period_s + 0.3, 2, 0.31)
    seconds, result = cpu(flatness, capture, TRUE_RATE, multisine)
    print(f"flatness, 4 loops: {seconds:.3f} CPU s, ±{result.deviation_db:.2f} dB")
    errors = []
    for draw in range(args.draws):
        capture = sensed(sweep.samples, 5 * sweep.period_s + 0.3, 100 + draw, 0.23 * draw)
        response = analyse_sweep(capture, TRUE_RATE * (1 + 1e-5), sweep)
        fit = fit_resonance(response.frequency_hz, response.magnitude, weights=response.coherence)
        band = response.frequency_hz >= 40
        at_f0 = np.argmin(np.abs(response.frequency_hz - F0))
        expected = np.abs(signal.freqz(*lra(), worN=response.frequency_hz, fs=PEN_RATE)[1])
        difference = (20 * np.log10(response.magnitude / response.magnitude[at_f0])
                      - 20 * np.log10(expected / truth))
        errors.append((100 * (fit.f0_hz / F0 - 1), np.max(np.abs(difference[band])),
                       np.min(response.coherence[band])))
    table = np.array(errors)
    print(f"accuracy over {args.draws} draws (4 loops): f0 error {table[:, 0].min():+.2f} … "
          f"{table[:, 0].max():+.2f} %, largest |H| error {table[:, 1].max():.2f} dB, smallest "
          f"coherence {table[:, 2].min():.3f}")


if __name__ == "__main__":
    main()
