"""How close each tactile rendering comes to a real stylus on paper-like surfaces.

Targets are Penn HaTT texture models (Culbertson, Lopez Delgado and Kuchenbecker, IEEE Haptics
Symposium 2014; read from ../shared/data/hatt_models, never copied): stylus acceleration
synthesised at (speed, force) points that are not model vertices (the toolkit blends the
neighbouring vertices' models there). At each point a "recording" (8 s, one noise seed) is what
every method builds from, and the target is 30 s of the same blended model with another seed:
what is held out is the noise realisation, the way a second pass of the same pen differs from
the first. Every method builds from the same recording, so the comparison between them is fair.

Each method's loop is played through the same actuator model (LRA, f0 175 Hz, Q 8; the loops
are pre-equalised for it with the 20 dB cap) and compared with the target by the measures of
:mod:`realpen.tactile.fidelity`: the sensitivity-weighted log-spectral distance over 30–500 Hz
(curve: ``realpen.tactile.fidelity.SENSITIVITY_SOURCE``), the 1/3-octave band distance and the
envelope-modulation difference, all in dB (lower is closer).

Methods:
- paper-literal: condition B with hard boundaries and amplitudes ∝ power (the method read
  literally);
- B sines: condition B as RealPen builds it (crossfades, amplitude ∝ √power);
- B sines+residual: B plus the stochastic residual (spectral modelling synthesis);
- single model: MakeSense-style, 10 peaks of the whole recording in one loop (one model for the
  whole recording, as its description says; built here with the same peak picking and
  equalisation; its loop is the recording's length less two units, 7.8 s, and the peaks of so
  long a unit may lie 0.13 Hz apart);
- noise loop: the floor — a 1.5 s loop of noise with the target's own model spectrum,
  pre-equalised with the same cap.

Then a stroke whose speed changes (60 → 120 → 180 mm/s at 1.5 N, 2 s each): the profile
conditioned on speed and force (one pattern per HaTT model vertex, followed along the stroke)
against every single frozen pattern of the same grid, at each speed.

Usage: python benchmarks/bench_fidelity.py [--textures N] [--plot fidelity.png] [--data DIR]
Skips (exit 0, with the reason) when the HaTT models are not there.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_DATA = ROOT.parent / "shared" / "data" / "hatt_models"
TEXTURES = ("Resume Paper", "Book", "Tissue Paper", "Cardboard", "Playing Card", "Paper Bag",
            "Coffee Filter", "Greeting Card")
POINTS = ((60.0, 1.5), (120.0, 1.5), (180.0, 1.5))  # (mm/s, N): held out, not model vertices
STROKE_SPEEDS = (60.0, 120.0, 180.0)
STROKE_FORCE = 1.5
STROKE_SMOOTHING_OCTAVES = 1 / 6
ACTUATOR = "lra:f0=175,q=8"
CAP_DB = 20.0
BUILD_S, TARGET_S, SEGMENT_S = 8.0, 30.0, 2.0
MODEL = "sines+residual"  # the conditioned profile is built with the default model
METHODS = ("paper-literal", "B sines", "B sines+residual", "single model", "noise loop")


def method_loops(recording, model_set, speed: float, force: float) -> dict[str, tuple]:
    """(samples, rate) of one loop per method, built from ``recording``."""
    from realpen.tactile.build import tactile_pattern

    units = int(recording.duration * 10) - 2  # every 100 ms unit but the first and last
    loops = {}
    for name, options in (("paper-literal", {"boundary": "hard", "amplitude": "power"}),
                          ("B sines", {"model": "sines"}),
                          ("B sines+residual", {"model": "sines+residual"}),
                          ("single model", {"top": 10, "subpatterns": 1,
                                            "unit_ms": units * 100.0,
                                            "selection_unit_ms": 100.0})):
        pattern = tactile_pattern(recording, ACTUATOR, cap_db=CAP_DB, **options)
        loops[name] = (pattern.samples, pattern.rate)
    loops["noise loop"] = (noise_loop(model_set, speed, force), 8000)
    return loops


def noise_loop(model_set, speed: float, force: float, rate: int = 8000, seconds: float = 1.5,
               seed: int = 0) -> np.ndarray:
    """A loop of noise with the HaTT model's own spectrum at (speed, force), pre-equalised for
    the actuator with the same cap: the best a looped rendering can do."""
    from scipy import signal

    from realpen.tactile.actuator import weighting

    model = model_set.model_at(speed, force)
    frames = int(round(seconds * rate))
    freqs = np.fft.rfftfreq(frames, 1.0 / rate)
    inside = (freqs >= 30.0) & (freqs < model_set.rate / 2)
    _, response = signal.freqz(model.gain * model.ma, model.ar, worN=freqs[inside],
                               fs=model_set.rate)
    magnitude = np.zeros(len(freqs))
    weights = weighting(ACTUATOR, freqs[inside], (30.0, model_set.rate / 2), CAP_DB).weights
    magnitude[inside] = np.abs(response) * weights
    phases = np.random.default_rng(seed).uniform(0, 2 * np.pi, len(freqs))
    loop = np.fft.irfft(magnitude * np.exp(1j * phases), n=frames)
    return loop / np.max(np.abs(loop)) * 10 ** (-1 / 20)


def single_method_table(model_sets, plot: Path | None) -> dict[str, np.ndarray]:
    from realpen.datasets.hatt import synthesize
    from realpen.tactile.fidelity import fidelity

    scores = {name: [] for name in METHODS}
    print(f"{'texture':<16}{'point':>14}  " + "".join(f"{m:>18}" for m in METHODS))
    plotted = False
    for model_set in model_sets:
        for speed, force in POINTS:
            build = synthesize(model_set, speed, force, BUILD_S, seed=1)
            target = synthesize(model_set, speed, force, TARGET_S, seed=2).mono
            loops = method_loops(build, model_set, speed, force)
            row = {name: fidelity(*loops[name], target, model_set.rate, ACTUATOR)
                   for name in METHODS}
            for name in METHODS:
                scores[name].append([row[name][k] for k in ("lsd_db", "third_octave_db",
                                                            "modulation_db")])
            print(f"{model_set.material:<16}{f'{speed:g} mm/s {force:g} N':>14}  "
                  + "".join(f"{row[m]['lsd_db']:18.2f}" for m in METHODS))
            if plot is not None and not plotted:
                save_plot(plot, model_set.material, speed, force, target, model_set.rate, loops)
                plotted = True
    return {name: np.asarray(values) for name, values in scores.items()}


def save_plot(path: Path, material: str, speed: float, force: float, target: np.ndarray,
              target_rate: float, loops: dict) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from realpen.tactile.fidelity import loop_psd, signal_psd, through_actuator

    figure, ax = plt.subplots(figsize=(8, 4.5))
    freqs, psd = signal_psd(target, target_rate)
    band = (freqs >= 30) & (freqs <= 500)

    def level(values, where):
        return 10 * np.log10(values[where] / np.mean(values[where]) + 1e-30)

    ax.plot(freqs[band], level(psd, band), color="black", lw=2, label="target (HaTT, held out)")
    for name, colour in (("paper-literal", "tab:red"), ("B sines", "tab:blue"),
                         ("B sines+residual", "tab:green")):
        samples, rate = loops[name]
        f, p = loop_psd(through_actuator(samples, rate, ACTUATOR), rate)
        inside = (f >= 30) & (f <= 500)
        ax.plot(f[inside], level(p, inside), color=colour, lw=1, alpha=0.8,
                label=f"{name} through the LRA")
    ax.set(xlabel="frequency (Hz)", ylabel="level re mean (dB)", ylim=(-45, 20),
           title=f"{material}, {speed:g} mm/s, {force:g} N: felt spectra (LRA f0 175 Hz, Q 8)")
    ax.legend(fontsize=8, loc="lower left")
    ax.grid(alpha=0.3)
    figure.tight_layout()
    figure.savefig(path, dpi=120)
    plt.close(figure)
    print(f"plot: {path}")


def model_psd(model_set, speed: float, force: float) -> tuple[np.ndarray, np.ndarray]:
    """The exact power spectrum of the HaTT model at (speed, force): the target's own spectrum,
    free of any estimate's scatter (2 Hz grid to Nyquist)."""
    from scipy import signal

    model = model_set.model_at(speed, force)
    freqs = np.arange(0.0, model_set.rate / 2 + 1e-9, 2.0)
    _, response = signal.freqz(model.gain * model.ma, model.ar, worN=freqs, fs=model_set.rate)
    return freqs, model.variance * np.abs(response) ** 2


def stroke_table(model_sets, seeds=(0, 1, 2)) -> list[dict]:
    """The conditioned profile along a stroke whose speed changes, against single frozen
    patterns built at each of the stroke's speeds; envelope distances, mean over ``seeds``."""
    from realpen.datasets.hatt import synthesize
    from realpen.motion.trajectory import Trajectory
    from realpen.tactile.build import tactile_pattern
    from realpen.tactile.fidelity import loop_psd, signal_psd, through_actuator, weighted_lsd
    from realpen.tactile.grid import grid_from_hatt
    from realpen.tactile.stroke import render_tactile_stroke

    rate = 8000
    rows = []

    def distance(spectrum, target):
        return weighted_lsd(spectrum, target, smooth_octaves=STROKE_SMOOTHING_OCTAVES)

    for model_set in model_sets:
        targets = [model_psd(model_set, speed, STROKE_FORCE) for speed in STROKE_SPEEDS]
        conditioned = np.zeros((len(seeds), len(STROKE_SPEEDS)))
        frozen = np.zeros((len(seeds), len(STROKE_SPEEDS), len(STROKE_SPEEDS)))  # built, felt
        for k, seed in enumerate(seeds):
            grid = grid_from_hatt(model_set, ACTUATOR, seed=seed, cap_db=CAP_DB, model=MODEL)
            t = np.arange(0.0, SEGMENT_S * len(STROKE_SPEEDS), 0.005)
            segment = np.minimum((t // SEGMENT_S).astype(int), len(STROKE_SPEEDS) - 1)
            speed = np.asarray(STROKE_SPEEDS)[segment]
            x = np.concatenate([[0.0], np.cumsum(speed[:-1] * np.diff(t))])
            pressure = np.full(len(t), STROKE_FORCE / grid.full_pressure_force_n)
            stroke = Trajectory.checked(t, x, np.zeros(len(t)), pressure, "benchmark stroke")
            felt = through_actuator(render_tactile_stroke(grid, stroke, rate), rate, ACTUATOR)
            for index in range(len(STROKE_SPEEDS)):
                # The steady part of the segment: the crossfade from the previous speed is over.
                first = int((index * SEGMENT_S + 0.25) * rate)
                last = int(((index + 1) * SEGMENT_S - 0.05) * rate)
                conditioned[k, index] = distance(signal_psd(felt[first:last], rate),
                                                 targets[index])
            for built, speed_mm_s in enumerate(STROKE_SPEEDS):
                recording = synthesize(model_set, speed_mm_s, STROKE_FORCE, BUILD_S,
                                       seed=100 + seed)
                loop = tactile_pattern(recording, ACTUATOR, cap_db=CAP_DB, model=MODEL).samples
                spectrum = loop_psd(through_actuator(loop, rate, ACTUATOR), rate)
                for index in range(len(STROKE_SPEEDS)):
                    frozen[k, built, index] = distance(spectrum, targets[index])
        rows.append({"texture": model_set.material, "conditioned": conditioned.mean(axis=0),
                     "frozen": frozen.mean(axis=0)})
    return rows


def print_stroke(rows) -> None:
    speeds = "/".join(f"{v:g}" for v in STROKE_SPEEDS)
    print(f"Stroke {' -> '.join(f'{v:g}' for v in STROKE_SPEEDS)} mm/s at {STROKE_FORCE:g} N: "
          f"envelope distance (weighted LSD of 1/{round(1 / STROKE_SMOOTHING_OCTAVES)}-octave "
          f"envelopes, dB) at each speed, mean of 3 builds")
    print(f"{'texture':<16}{'conditioned':>22}" + "".join(
        f"{f'frozen @ {v:g}':>22}" for v in STROKE_SPEEDS) + f"{'closer at every speed':>24}")
    every_speed = every_frozen = 0
    for row in rows:
        mine, frozen = row["conditioned"], row["frozen"]
        wins = [bool(np.all(mine < frozen[built])) for built in range(len(STROKE_SPEEDS))]
        away = [bool(np.all(np.delete(mine < frozen[built], built)))
                for built in range(len(STROKE_SPEEDS))]
        every_speed += all(away)
        every_frozen += all(wins)
        cells = "".join(f"{'/'.join(f'{d:.2f}' for d in frozen[b]):>22}"
                        for b in range(len(STROKE_SPEEDS)))
        verdict = f"{sum(wins)}/{len(wins)} frozen"
        print(f"{row['texture']:<16}{'/'.join(f'{d:.2f}' for d in mine):>22}{cells}{verdict:>24}")
    print(f"(each cell: distance at {speeds} mm/s)")
    print(f"conditioned closer than every frozen pattern at every speed: {every_frozen}/{len(rows)} "
          f"textures; closer than each frozen pattern at every speed but the one it was built "
          f"at: {every_speed}/{len(rows)}")
    mean_wins = sum(bool(np.all(row["conditioned"].mean() < row["frozen"].mean(axis=1)))
                    for row in rows)
    print(f"conditioned closer over the whole stroke (mean of the speeds) than every frozen "
          f"pattern: {mean_wins}/{len(rows)} textures")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA,
                        help="folder of HaTT Models_*.xml files")
    parser.add_argument("--textures", type=int, default=len(TEXTURES),
                        help="how many paper-like textures (at most 8)")
    parser.add_argument("--plot", type=Path, default=Path("fidelity-spectra.png"),
                        help="where to save the spectra of the first case (PNG)")
    parser.add_argument("--no-stroke", action="store_true", help="skip the stroke comparison")
    args = parser.parse_args()
    paths = [args.data / f"Models_{name}.xml" for name in TEXTURES[:args.textures]]
    missing = [p for p in paths if not p.is_file()]
    if missing:
        print(f"skipped: HaTT models not found ({missing[0]}); they are research-only data kept "
              f"in ../shared/data/hatt_models, see its README")
        return 0
    from realpen.datasets.hatt import load_hatt

    started = time.process_time()
    model_sets = [load_hatt(p) for p in paths]
    print("Felt-spectrum distances to held-out HaTT targets (weighted LSD, dB; lower is closer)")
    scores = single_method_table(model_sets, args.plot)
    print()
    print(f"{'method':<20}{'LSD median':>12}{'LSD range':>16}{'1/3-oct':>10}{'modulation':>12}")
    for name in METHODS:
        values = scores[name]
        print(f"{name:<20}{np.median(values[:, 0]):12.2f}"
              f"{f'{values[:, 0].min():.2f}–{values[:, 0].max():.2f}':>16}"
              f"{np.median(values[:, 1]):10.2f}{np.median(values[:, 2]):12.2f}")
    literal, floor = scores["paper-literal"][:, 0], scores["noise loop"][:, 0]
    print()
    for name in ("B sines", "B sines+residual"):
        ratio = np.median(scores[name][:, 0] / literal)
        to_floor = np.median(scores[name][:, 0]) / np.median(floor)
        print(f"{name}: median ratio to paper-literal {ratio:.2f} (target <= 0.70: "
              f"{'met' if ratio <= 0.70 else 'NOT met'}); median / noise-loop floor "
              f"{to_floor:.2f} (target <= 1.5: {'met' if to_floor <= 1.5 else 'NOT met'})")
    if not args.no_stroke:
        print()
        print_stroke(stroke_table(model_sets))
    print(f"CPU time: {time.process_time() - started:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
