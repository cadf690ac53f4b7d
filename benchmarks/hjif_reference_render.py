"""How the MPEG haptics reference software plays RealPen's ``.hjif`` exports.

Each bundled pen is exported as ``realpen export PEN -f hjif`` does
(:func:`realpen.exports.export_profile`) and played by the reference software's Synthesizer
(MPEGGroup/HapticReferenceSoftware, ``Synthesizer -f FILE -o OUT.wav -fs RATE``) at the pen's
own rate. Its render (16-bit PCM WAV, full scale ±1) is compared sample by sample with

- the pen's tactile pattern (``profile.pattern.samples``): what the file is meant to carry;
- RealPen's reader (:func:`realpen.load_haptic` then ``render(rate)``): whether RealPen plays
  the file as the reference does;
- and, as a check of the convention chosen, the same file written the former way, with the
  frequency on every keyframe instead of once per effect (the reference renderer advances the
  phase between frequency keyframes as if their positions were milliseconds, so at timescale
  8000 the phases go wrong).

Measures: Pearson correlation and MPEG's PSNR (:func:`realpen.dsp.waveform_measures.mpeg_psnr`,
``10·log10(4 / MSE)``, signals in [−1, 1]). The Synthesizer starts at tick 0 (no ``--pad``)
and stops just before the last keyframe's tick, so it leaves out the pattern's last sample; the
measures use the samples both have, and the lag column is where the cross-correlation peaks
(0: aligned).

The Synthesizer is not part of RealPen; docs/exports.md says how to build it (offline too).

Usage: python benchmarks/hjif_reference_render.py [SYNTHESIZER] [--keep DIR]
       (or set REALPEN_MPEG_SYNTHESIZER to the Synthesizer's path)
Exits 2 with one line when the Synthesizer is not found, 1 when it refuses a file.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402
import soundfile as sf  # noqa: E402

import realpen as rp  # noqa: E402
from realpen.dsp.waveform_measures import mpeg_psnr  # noqa: E402
from realpen.exports import export_profile  # noqa: E402
from realpen.profile.registry import list_profiles  # noqa: E402

ENV_VARIABLE = "REALPEN_MPEG_SYNTHESIZER"
TIMEOUT_S = 300
MAX_LAG = 64  # samples searched each way for the render's offset
# The Synthesizer does not stop when its schema check fails (it crashes further on): this line
# of its stderr is how a refused file is told apart from a render.
REFUSED = "does not match the MPEG specifications"


class SynthesizerFailed(Exception):
    """The Synthesizer refused a file or wrote no render."""


def find_synthesizer(given: str | None) -> Path | None:
    """The Synthesizer's path: ``given``, else :data:`ENV_VARIABLE`; a path or a command on
    ``PATH``. None when neither names an executable file."""
    text = given or os.environ.get(ENV_VARIABLE, "")
    found = shutil.which(text) if text.strip() else None
    return Path(found).resolve() if found else None


def synthesize(synthesizer: Path, hjif: Path, rate: int) -> np.ndarray:
    """Play ``hjif`` with the reference Synthesizer at ``rate`` Hz.

    Returns:
        The render as float64 samples, full scale ±1 (its WAV is 16-bit PCM).

    Raises:
        SynthesizerFailed: it refused the file or wrote no WAV (its first error lines).
    """
    wav = hjif.with_suffix(".reference.wav")
    wav.unlink(missing_ok=True)
    done = subprocess.run([str(synthesizer), "-f", str(hjif), "-o", str(wav), "-fs", str(rate)],
                          capture_output=True, text=True, timeout=TIMEOUT_S, check=False)
    if done.returncode != 0 or REFUSED in done.stderr or not wav.is_file():
        said = " / ".join(line.strip() for line in done.stderr.splitlines()[:3] if line.strip())
        raise SynthesizerFailed(f"{hjif.name}: the Synthesizer exited {done.returncode}"
                                + (f": {said}" if said else ""))
    samples, written_rate = sf.read(wav, dtype="float64", always_2d=True)
    if written_rate != rate:
        raise SynthesizerFailed(f"{wav.name}: written at {written_rate} Hz, asked {rate} Hz")
    return samples[:, 0]


def frequency_on_every_keyframe(hjif: Path) -> Path:
    """A copy of ``hjif`` in the former convention: every keyframe repeats its effect's
    frequency (the first keyframe's). Written beside it; its path is returned."""
    document = json.loads(hjif.read_text(encoding="utf-8"))
    for perception in document["perceptions"]:
        for channel in perception["channels"]:
            for band in channel["bands"]:
                for effect in band["effects"]:
                    frequency = effect["keyframes"][0]["frequency_modulation"]
                    for keyframe in effect["keyframes"]:
                        keyframe["frequency_modulation"] = frequency
    variant = hjif.with_name(hjif.stem + ".every-keyframe.hjif")
    variant.write_text(json.dumps(document), encoding="utf-8")
    return variant


def lag(render: np.ndarray, reference: np.ndarray) -> int:
    """The shift (samples, within ±:data:`MAX_LAG`) at which ``render`` best matches
    ``reference``: positive when the render comes late."""
    frames = min(len(render), len(reference))
    a, b = render[:frames], reference[:frames]
    shifts = range(-MAX_LAG, MAX_LAG + 1)
    scores = [float(np.dot(a[max(s, 0):frames + min(s, 0)], b[max(-s, 0):frames - max(s, 0)]))
              for s in shifts]
    return shifts[int(np.argmax(scores))]


def agreement(render: np.ndarray, reference: np.ndarray) -> str:
    """Correlation and MPEG PSNR (dB) over the samples both signals have, as table text."""
    frames = min(len(render), len(reference))
    a, b = render[:frames], reference[:frames]
    return f"r {np.corrcoef(a, b)[0, 1]:.5f}  {mpeg_psnr(a, b):6.2f} dB"


def measure_pen(name: str, synthesizer: Path, folder: Path) -> str:
    """One table row: pen ``name`` exported to ``folder``, played by ``synthesizer``.

    Raises:
        SynthesizerFailed: see :func:`synthesize`.
    """
    profile = rp.load_profile(name)
    pattern = profile.pattern
    rate = int(pattern.rate)
    hjif = folder / f"{name}.hjif"
    export_profile(profile, "hjif", hjif)
    own = np.asarray(pattern.samples, dtype=np.float64)
    render = synthesize(synthesizer, hjif, rate)
    read_back = rp.load_haptic(hjif).render(rate)
    former = synthesize(synthesizer, frequency_on_every_keyframe(hjif), rate)
    return (f"{name:<10} {rate:>5} {len(render):>6}/{len(own):<6} {lag(render, own):>4}   "
            f"{agreement(render, own)}   {agreement(render, read_back)}   "
            f"{agreement(former, own)}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("synthesizer", nargs="?",
                        help=f"the reference Synthesizer (default: ${ENV_VARIABLE})")
    parser.add_argument("--keep", type=Path, metavar="DIR",
                        help="write the files and renders here (default: a temporary folder)")
    args = parser.parse_args(argv)
    synthesizer = find_synthesizer(args.synthesizer)
    if synthesizer is None:
        print(f"MPEG reference Synthesizer not found: give its path or set {ENV_VARIABLE} "
              f"(build it as docs/exports.md says)", file=sys.stderr)
        return 2
    pens = [bundle.stem for where, bundle in list_profiles() if where == "bundled"]
    print(f"MPEG reference Synthesizer: {synthesizer}")
    print("render: the Synthesizer's; samples: its render / the pattern's; lag: its offset "
          "(samples); measures over the common samples")
    print(f"{'pen':<10} {'Hz':>5} {'samples':>13} {'lag':>4}   "
          f"{'render vs pattern':<22}   {'render vs reader':<22}   "
          f"frequency on every keyframe vs pattern")
    failed = 0
    with tempfile.TemporaryDirectory(prefix="realpen-hjif-") as scratch:
        folder = args.keep or Path(scratch)
        folder.mkdir(parents=True, exist_ok=True)
        for name in pens:
            try:
                print(measure_pen(name, synthesizer, folder), flush=True)
            except (SynthesizerFailed, subprocess.TimeoutExpired) as error:
                failed += 1
                print(f"{name:<10} refused: {error}", flush=True)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
