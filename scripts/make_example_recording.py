"""Regenerate the synthetic example recording that ships with RealPen.

The example stands in for an accelerometer recording of a pen on paper (three axes at
1344 Hz, m/s²). It is synthetic: broadband friction noise shaped by a few resonances of the
hand–pen system, with a slow fluctuation of level and a short pen-down transient at the start
and pen-lift at the end (so the first and last units differ, as in real recordings). It is
deterministic: running this script again gives the same samples.

Usage: python scripts/make_example_recording.py [OUT.npz]
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from scipy import signal

RATE = 1344.0
DURATION_S = 12.0
RESONANCES_HZ = ((92.0, 6.0, 1.0), (178.0, 9.0, 0.8), (263.0, 7.0, 0.55), (410.0, 10.0, 0.35))


def make_example(seed: int = 2016) -> np.ndarray:
    """Three-axis synthetic pen-on-paper acceleration, shape (frames, 3), in m/s²."""
    rng = np.random.default_rng(seed)
    frames = int(DURATION_S * RATE)
    excitation = rng.standard_normal(frames)
    vibration = np.zeros(frames)
    for f0, q, gain in RESONANCES_HZ:
        b, a = signal.iirpeak(f0, q, fs=RATE)
        vibration += gain * signal.lfilter(b, a, excitation)
    t = np.arange(frames) / RATE
    envelope = 1.0 + 0.15 * np.sin(2 * np.pi * 0.7 * t) + 0.05 * np.sin(2 * np.pi * 2.3 * t)
    envelope *= np.clip(t / 0.05, 0, 1) * np.clip((DURATION_S - t) / 0.05, 0, 1)
    vibration *= envelope
    mixing = np.array([[0.45, 0.30, 0.85], [0.20, 0.35, 0.90], [0.30, 0.25, 0.80]])
    axes = np.stack([signal.lfilter(*signal.iirpeak(f0, 4.0, fs=RATE), vibration) * 0.3
                     + vibration for f0, _, _ in RESONANCES_HZ[:3]], axis=1)
    samples = axes * mixing.diagonal()[None, :] + 0.02 * rng.standard_normal((frames, 3))
    return samples.astype(np.float32)


def main() -> None:
    default = Path(__file__).resolve().parents[1] / "src/realpen/examples/synthetic_pen_3axis.npz"
    out = Path(sys.argv[1]) if len(sys.argv) > 1 else default
    with open(out, "wb") as handle:
        np.savez_compressed(handle, samples=make_example(), rate=np.float64(RATE),
                            axes=np.array(["x", "y", "z"]), units=np.array("m/s^2"))
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
