"""A corpus of bad command lines: every one must fail cleanly and leave everything as it was.

Each case runs ``realpen ARGS`` in-process (:func:`conftest.run_cli`) in a fresh folder holding
good and bad inputs of every kind (a copy of one template), and asserts:

- exit code 2 and exactly one line on stderr, ``realpen: error: …``, naming the file or the
  flag at fault, and no traceback;
- nothing written: every file and folder (and the data folder, ``$REALPEN_HOME``) is
  byte-identical afterwards, so an output that would replace an input leaves the input whole.

The cases cover every command: outputs that are inputs (also through a hard link or a symbolic
link), that are each other or a side file a format writes; sizes no input may ask for; NaN,
infinite and huge numbers as flag values; empty, truncated and garbage files of each kind;
files of the wrong kind; folders where files go.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import sqlite3
import zipfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
import soundfile as sf
from conftest import run_cli
from scipy import signal

HUGE = "99999999999999999999999"  # 23 digits: more than any int64
HUGER = "9" * 400  # more than a float holds: comparing it with a float limit overflows
TEMPLATE_FILES = ("rec.wav", "rec.npz", "t.csv", "m.csv", "coupling.json", "resp.csv",
                  "Models_S.xml", "bundle", "bundle.zip", "store.sqlite", "folder")


# --- the inputs --------------------------------------------------------------------------------

def friction(seconds: float, rate: int = 44100) -> np.ndarray:
    """Band-limited noise like a pen's friction sound, full scale ±1 (RMS 0.05)."""
    b, a = signal.butter(2, [300, 6000], btype="bandpass", fs=rate)
    x = signal.lfilter(b, a, np.random.default_rng(1).standard_normal(int(seconds * rate)))
    return 0.05 * x / x.std()


def make_store(path: Path) -> None:
    """An empty RealPen stroke store."""
    from realpen.live.store import StrokeStore

    StrokeStore(path).close()


def build_template(root: Path) -> None:
    """Good inputs of every kind, and empty, garbage and truncated ones."""
    from test_hatt import synthetic_xml

    from realpen.examples import example_recording_path
    from realpen.motion.coupling import Coupling
    from realpen.pens import bundled_dir

    sf.write(root / "rec.wav", friction(3.0), 44100, subtype="PCM_16")
    shutil.copy(example_recording_path(), root / "rec.npz")
    t = np.arange(0, 1.8, 0.005)
    (root / "t.csv").write_text("t,x,y,pressure\n" + "".join(
        f"{a:.3f},{50 * a:.3f},10,0.5\n" for a in t))
    rng = np.random.default_rng(0)
    pressure, speed = rng.uniform(0.1, 1, 40), rng.uniform(0, 100, 40)
    amplitude = np.clip(0.6 * (pressure - 0.1) + 0.02 * (speed - 12), 0, 2)
    (root / "m.csv").write_text("pressure,speed,amplitude\n" + "".join(
        f"{p:.4f},{v:.4f},{a:.4f}\n" for p, v, a in zip(pressure, speed, amplitude)))
    (root / "coupling.json").write_text(json.dumps(Coupling().to_json()))
    (root / "resp.csv").write_text("hz,gain\n50,0.2\n175,1\n500,0.3\n")
    (root / "Models_S.xml").write_text(synthetic_xml())
    shutil.copytree(bundled_dir() / "pencil", root / "bundle")
    with zipfile.ZipFile(root / "bundle.zip", "w") as archive:
        for item in sorted((root / "bundle").iterdir()):
            archive.write(item, item.name)
    make_store(root / "store.sqlite")
    (root / "folder").mkdir()
    garbage = np.random.default_rng(7).integers(0, 256, 4096, dtype=np.uint8).tobytes()
    for suffix in ("wav", "npz", "csv", "json", "zip", "xml", "sqlite"):
        (root / f"empty.{suffix}").write_bytes(b"")
        (root / f"garbage.{suffix}").write_bytes(garbage)
    for name in ("rec.wav", "rec.npz", "bundle.zip"):
        data = (root / name).read_bytes()
        (root / f"truncated{Path(name).suffix}").write_bytes(data[:len(data) // 2])
    # Nested 100 000 deep: json.loads would recurse past Python's limit.
    (root / "deep.json").write_text("[" * 100_000 + "]" * 100_000)
    (root / "digits.json").write_text(json.dumps(Coupling().to_json())
                                      .replace('"c_p": 0.6', '"c_p": ' + "7" * 5000))
    (root / "notime.csv").write_text("x,y,z\n" + "".join(
        f"{np.sin(k / 3):.4f},{np.cos(k / 5):.4f},{np.sin(k / 7):.4f}\n" for k in range(3000)))


# --- case-specific inputs (made in the case's own folder) -------------------------------------

def hard_link(name: str, target: str) -> Callable[[Path], None]:
    def setup(root: Path) -> None:
        os.link(root / target, root / name)
    return setup


def symlink(name: str, target: str) -> Callable[[Path], None]:
    def setup(root: Path) -> None:
        (root / name).symlink_to(target)
    return setup


def copy_into(name: str, folder: str) -> Callable[[Path], None]:
    def setup(root: Path) -> None:
        shutil.copy(root / name, root / folder / name)
    return setup


def existing(name: str, data: bytes = b"keep me") -> Callable[[Path], None]:
    def setup(root: Path) -> None:
        (root / name).write_bytes(data)
    return setup


def big_field_csv(root: Path) -> None:
    """A trajectory CSV whose one field is 30 MB."""
    (root / "bigfield.csv").write_text("t,x,y,pressure\n0," + "1" * 30_000_000 + ",0,0.5\n"
                                       "0.1,1,0,0.5\n")


def long_trajectory(root: Path) -> None:
    """A trajectory CSV of two events 599 s apart (the longest a stroke may last is 600 s)."""
    (root / "long.csv").write_text("t,x,y,pressure\n0,0,0,0.5\n599,10,0,0.5\n")


def digits_csv(root: Path) -> None:
    """A recording CSV with a 5,000-digit number."""
    (root / "digits.csv").write_text("t,x\n0,1\n0.001," + "9" * 5000 + "\n0.002,1\n")


def npz_rate(rate: float) -> Callable[[Path], None]:
    def setup(root: Path) -> None:
        samples = friction(0.5)[:, None]
        np.savez(root / "odd.npz", samples=samples, rate=np.float64(rate))
    return setup


def npz_huge_shape(root: Path) -> None:
    """An NPZ whose samples header promises 10¹² × 3 samples (its data is 64 bytes)."""
    import io

    header = io.BytesIO()
    np.lib.format.write_array_header_1_0(
        header, {"descr": "<f8", "fortran_order": False, "shape": (10**12, 3)})
    rate = io.BytesIO()
    np.save(rate, np.float64(1344))
    with zipfile.ZipFile(root / "huge.npz", "w") as archive:
        archive.writestr("samples.npy", header.getvalue() + bytes(64))
        archive.writestr("rate.npy", rate.getvalue())


def coupling_with(**changes) -> Callable[[Path], None]:
    def setup(root: Path) -> None:
        document = json.loads((root / "coupling.json").read_text())
        (root / "changed.json").write_text(json.dumps({**document, **changes}))
    return setup


def bundle_with_seam(value: object) -> Callable[[Path], None]:
    """A copy of the pencil bundle whose seam report holds ``value`` (not a number)."""
    def setup(root: Path) -> None:
        shutil.copytree(root / "bundle", root / "badseam")
        document = json.loads((root / "badseam" / "profile.json").read_text())
        document["sound"]["seam"]["level_jump_db"] = value
        (root / "badseam" / "profile.json").write_text(json.dumps(document, indent=2))
    return setup


def damaged_store(root: Path) -> None:
    """A stroke store whose first page (the schema) is whole and whose other pages are not."""
    make_store(root / "damaged.sqlite")
    data = bytearray((root / "damaged.sqlite").read_bytes())
    page = sqlite3.connect(":memory:").execute("PRAGMA page_size").fetchone()[0]
    garbage = np.random.default_rng(3).integers(0, 256, len(data), dtype=np.uint8).tobytes()
    data[page:] = garbage[page:]
    (root / "damaged.sqlite").write_bytes(bytes(data))


# --- the corpus --------------------------------------------------------------------------------

@dataclass(frozen=True)
class Bad:
    """One bad invocation: its arguments, the texts its one line may hold to name what is at
    fault (one of them must be there), extra inputs."""

    args: tuple[str, ...]
    names: tuple[str, ...]
    setup: Callable[[Path], None] | None = None


def bad(case_id: str, args: str | list[str], names: str | tuple[str, ...],
        setup: Callable[[Path], None] | None = None):
    words = tuple(args.split()) if isinstance(args, str) else tuple(args)
    names = (names,) if isinstance(names, str) else names
    return pytest.param(Bad(words, names, setup), id=case_id)


SYNTH = "hatt synth Models_S.xml --speed 100 --force 1 --seconds 1"
TACTILE = "tactile rec.npz -o out.wav"
LOOP = "sound loop rec.wav -o out.wav"
RENDER = "sound render --sound rec.wav --trajectory t.csv -o out.wav"
FIT = "sound fit m.csv -o out.json"
BUILD = "profile build --name mine --vibration rec.npz --sound rec.wav"
FEEL = "tactile render pencil --trajectory t.csv -o out.wav"
GRID_BUILD = "profile build --name mine --sound rec.wav -o out.zip --vibration-grid grid.csv"


def grid_csv(text: str) -> Callable[[Path], None]:
    """A grid CSV ``grid.csv`` holding ``text``."""
    def setup(root: Path) -> None:
        (root / "grid.csv").write_text(text)
    return setup

CORPUS = [
    # -- an output that is an input, another output, or a side file --------------------------
    bad("analyze-json-is-recording", "analyze rec.wav --json rec.wav", "rec.wav"),
    bad("analyze-json-is-recording-forced", "analyze rec.wav --json rec.wav --force", "rec.wav"),
    bad("analyze-json-hard-link-to-recording", "analyze rec.wav --json same.wav --force",
        "same.wav", hard_link("same.wav", "rec.wav")),
    bad("tactile-output-is-recording", "tactile rec.npz -o rec.npz --force", "rec.npz"),
    bad("tactile-output-symlink-to-recording", "tactile rec.npz -o link.wav --force",
        "link.wav", symlink("link.wav", "rec.npz")),
    bad("tactile-output-twice", f"{TACTILE} --json out.wav", "out.wav"),
    bad("tactile-output-is-actuator-csv", "tactile rec.npz -o resp.csv --actuator resp.csv "
        "--force", "resp.csv"),
    bad("tactile-output-exists", TACTILE, "out.wav", existing("out.wav")),
    bad("tactile-build-output-is-recording", "tactile build rec.npz -o rec.npz --force",
        "rec.npz"),
    bad("tactile-render-output-is-trajectory", "tactile render pencil --trajectory t.csv "
        "-o t.csv --force", "t.csv"),
    bad("tactile-render-output-inside-bundle", "tactile render bundle --trajectory t.csv "
        "-o bundle/feel.wav --force", "feel.wav"),
    bad("tactile-render-output-exists", FEEL, "out.wav", existing("out.wav")),
    bad("profile-build-grid-output-is-grid-recording", "profile build --name mine --sound "
        "rec.wav --vibration-grid grid.csv -o rec.npz --force", "rec.npz",
        grid_csv("speed_mm_s,force_n,path\n50,1,rec.npz\n")),
    bad("profile-build-output-is-hatt-model", "profile build --name mine --sound rec.wav "
        "--hatt Models_S.xml -o Models_S.xml --force", "Models_S.xml"),
    bad("sound-loop-output-is-recording", "sound loop rec.wav -o rec.wav --force", "rec.wav"),
    bad("sound-loop-json-is-output", f"{LOOP} --json out.wav", "out.wav"),
    bad("sound-render-output-is-trajectory", "sound render --sound rec.wav --trajectory t.csv "
        "-o t.csv --force", "t.csv"),
    bad("sound-render-output-is-coupling", "sound render --sound rec.wav --trajectory t.csv "
        "--coupling coupling.json -o coupling.json --force", "coupling.json"),
    bad("sound-render-output-is-sound", "sound render --sound rec.wav --trajectory t.csv "
        "-o rec.wav --force", "rec.wav"),
    bad("sound-fit-output-is-measurements", "sound fit m.csv -o m.csv --force", "m.csv"),
    bad("sound-fit-report-is-base", f"{FIT} --base coupling.json --json coupling.json --force",
        "coupling.json"),
    bad("export-output-is-bundle-zip", "export bundle.zip -f wav -o bundle.zip --force",
        "bundle.zip"),
    bad("export-output-inside-bundle", "export bundle -f wav -o bundle/sound.wav --force",
        "sound.wav"),
    bad("export-ahap-side-file-exists", "export pencil -f ahap -o x.ahap", "x-sound.wav",
        existing("x-sound.wav")),
    bad("export-ahap-side-file-is-bundle-wav", "export bundle -f ahap -o bundle/tactile.ahap "
        "--force", "bundle"),
    bad("hatt-synth-output-is-model", f"{SYNTH} -o Models_S.xml --overwrite", "Models_S.xml"),
    bad("profile-build-output-is-recording", f"{BUILD} -o rec.npz --force", "rec.npz"),
    bad("profile-build-output-folder-holds-recording", "profile build --name mine --vibration "
        "bundle/rec.npz --sound rec.wav -o bundle --force", "bundle", copy_into("rec.npz", "bundle")),
    bad("profile-show-plot-exists", "profile show pencil --plot rec.wav", "rec.wav"),
    bad("strokes-export-output-is-store", "strokes export --store store.sqlite -o store.sqlite "
        "--force", "store.sqlite"),
    # -- sizes no input may ask for -------------------------------------------------------------
    bad("analyze-analysis-rate-1e9", "analyze rec.npz --analysis-rate 1e9", "--analysis-rate"),
    bad("analyze-top-1e9", "analyze rec.npz --top 1000000000", "--top"),
    bad("analyze-top-huge", f"analyze rec.npz --top {HUGE}", "--top"),
    bad("analyze-top-400-digits", f"analyze rec.npz --top {HUGER}", "--top"),
    bad("tactile-seed-400-digits", f"{TACTILE} --seed {HUGER}", "--seed"),
    bad("profile-build-top-400-digits", f"{BUILD} -o out.zip --top {HUGER}", "--top"),
    bad("analyze-subpatterns-1e9", "analyze rec.npz --subpatterns 1000000000", "--subpatterns"),
    bad("analyze-unit-ms-1e12", "analyze rec.npz --unit-ms 1e12", "--unit-ms"),
    bad("analyze-csv-rate-1e12", "analyze notime.csv --rate 1e12", "--rate"),
    bad("tactile-rate-2e9", f"{TACTILE} --rate 2000000000", "--rate"),
    bad("tactile-top-1e9", f"{TACTILE} --top 1000000000", "--top"),
    bad("tactile-subpatterns-1e9", f"{TACTILE} --subpatterns 1000000000", "--subpatterns"),
    bad("tactile-unit-ms-1e12", f"{TACTILE} --unit-ms 1e12", "--unit-ms"),
    bad("tactile-analysis-rate-1e9", f"{TACTILE} --analysis-rate 1e9", "--analysis-rate"),
    bad("tactile-pattern-too-long", f"{TACTILE} --subpatterns 500 --unit-ms 60000 --rate 384000",
        "--subpatterns"),
    bad("tactile-cap-db-1e300", f"{TACTILE} --cap-db 1e300", "--cap-db"),
    bad("tactile-seed-huge", f"{TACTILE} --seed {HUGE}", "--seed"),
    bad("sound-loop-unit-ms-1e12", f"{LOOP} --unit-ms 1e12", "--unit-ms"),
    bad("sound-loop-crossfade-ms-1e12", f"{LOOP} --crossfade-ms 1e12", "--crossfade-ms"),
    bad("sound-loop-rate-1e9", f"{LOOP} --rate 1e9", "--rate"),
    bad("sound-loop-grain-ms-1e12", f"{LOOP} --mode granular --grain-ms 1e12", "--grain-ms"),
    bad("sound-loop-length-ms-1e12", f"{LOOP} --mode granular --length-ms 1e12", "--length-ms"),
    bad("sound-loop-seed-huge", f"{LOOP} --mode granular --seed {HUGE}", "--seed"),
    bad("sound-render-unit-ms-1e12", f"{RENDER} --unit-ms 1e12", "--unit-ms"),
    bad("sound-render-grain-ms-1e12", f"{RENDER} --mode granular --grain-ms 1e12", "--grain-ms"),
    bad("sound-render-long-stroke-at-384-khz", "sound render --sound rec.wav --trajectory "
        "long.csv -o out.wav --rate 384000", "--rate", long_trajectory),
    bad("sound-render-smoothing-1e12", f"{RENDER} --coupling changed.json", "changed.json",
        coupling_with(smoothing_ms=1e12)),
    bad("export-rate-1e9", "export pencil -f wav -o p.wav --rate 1000000000", "--rate"),
    bad("analyze-json-in-a-link-loop", "analyze rec.wav --json loopa", "loopa",
        lambda root: (os.symlink("loopb", root / "loopa"), os.symlink("loopa", root / "loopb"))),
    bad("tactile-input-is-a-link-loop", "tactile loopa -o out.wav", "loopa",
        lambda root: (os.symlink("loopb", root / "loopa"), os.symlink("loopa", root / "loopb"))),
    bad("analyze-json-name-too-long", ["analyze", "rec.wav", "--json", "a" * 300 + ".json"],
        "too long"),
    bad("export-empty-profile-name", ["export", "", "-f", "wav", "-o", "p.wav"], "empty"),
    bad("profile-show-empty-name", ["profile", "show", ""], "empty"),
    bad("export-rate-1", "export pencil -f c-header -o p.h --rate 1", "--rate"),
    bad("export-repeats-1e9", "export pencil -f haptic -o p.haptic --repeats 1000000000",
        "--repeats"),
    bad("export-stereo-too-long", "export pencil -f wav --stereo --rate 384000 --repeats 100 "
        "-o p.wav", "--repeats"),
    bad("export-repeats-huge", f"export pencil -f wav -o p.wav --repeats {HUGE}", "--repeats"),
    bad("hatt-synth-seconds-1e12", f"{SYNTH} -o s.wav".replace("--seconds 1", "--seconds 1e12"),
        "--seconds"),
    bad("hatt-synth-rate-1e9", f"{SYNTH} -o s.wav --rate 1000000000", "--rate"),
    bad("profile-build-top-1e9", f"{BUILD} -o out.zip --top 1000000000", "--top"),
    bad("profile-build-sound-unit-1e12", f"{BUILD} -o out.zip --sound-unit-ms 1e12",
        "--sound-unit-ms"),
    bad("tactile-render-rate-1e9", f"{FEEL} --rate 1000000000", "--rate"),
    bad("tactile-render-rate-huge", f"{FEEL} --rate {HUGE}", "--rate"),
    bad("tactile-render-long-stroke-at-384-khz", "tactile render pencil --trajectory long.csv "
        "-o out.wav --rate 384000", "--rate", long_trajectory),
    bad("profile-build-grid-too-many-rows", GRID_BUILD, "grid.csv", grid_csv(
        "speed_mm_s,force_n,path\n" + "".join(f"{k},1,rec.npz\n" for k in range(65)))),
    # -- numbers that are no numbers, and misleading messages ---------------------------------
    bad("analyze-unit-ms-tiny", "analyze rec.npz --unit-ms 0.000001", "--unit-ms"),
    bad("analyze-unit-ms-nan", "analyze rec.npz --unit-ms nan", "--unit-ms"),
    bad("analyze-highpass-inf", "analyze rec.npz --highpass inf", "--highpass"),
    bad("analyze-highpass-above-nyquist", "analyze rec.npz --highpass 1000", "--highpass"),
    bad("tactile-crossfade-longer-than-unit", f"{TACTILE} --unit-ms 3", "--crossfade-ms"),
    bad("tactile-input-rate-nan", "tactile notime.csv -o out.wav --input-rate nan",
        "--input-rate"),
    bad("tactile-unit-ms-tiny", f"{TACTILE} --unit-ms 0.000001", "--unit-ms"),
    bad("tactile-cap-db-nan", f"{TACTILE} --cap-db nan", "--cap-db"),
    bad("tactile-actuator-nan", f"{TACTILE} --actuator lra:f0=nan", "--actuator"),
    bad("tactile-actuator-empty", [*TACTILE.split(), "--actuator", ""], "--actuator"),
    bad("sound-loop-unit-ms-tiny", f"{LOOP} --unit-ms 0.000001", "--unit-ms"),
    bad("sound-loop-unit-shorter-than-crossfade", f"{LOOP} --unit-ms 5", "--unit-ms"),
    bad("sound-loop-grain-too-long-for-any-texture", f"{LOOP} --mode granular --grain-ms 60000 "
        f"--length-ms 60000", "--grain-ms"),
    bad("sound-loop-level-nan", f"{LOOP} --level-dbfs nan", "--level-dbfs"),
    bad("sound-render-rate-nan", f"{RENDER} --rate nan", "--rate"),
    bad("sound-fit-value-inf", f"{FIT} --value inf", "--value"),
    bad("hatt-synth-speed-nan", f"{SYNTH} -o s.wav".replace("--speed 100", "--speed nan"),
        "--speed"),
    bad("profile-build-unit-ms-tiny", f"{BUILD} -o out.zip --unit-ms 0.000001", "--unit-ms"),
    bad("tactile-render-rate-too-low", f"{FEEL} --rate 400", "--rate"),
    bad("profile-build-grid-speed-nan", GRID_BUILD, "grid.csv",
        grid_csv("speed_mm_s,force_n,path\nnan,1,rec.npz\n")),
    bad("profile-build-grid-force-negative", GRID_BUILD, "line 3",
        grid_csv("speed_mm_s,force_n,path\n50,1,rec.npz\n80,-1,rec.wav\n")),
    bad("profile-build-grid-point-twice", GRID_BUILD, "line 3",
        grid_csv("speed_mm_s,force_n,path\n50,1,rec.npz\n50,1,rec.wav\n")),
    bad("profile-build-two-vibrations", f"{BUILD} -o out.zip --hatt Models_S.xml",
        "exactly one of --vibration"),
    bad("profile-build-nothing", "profile build --name mine -o out.zip",
        "give --sound, a vibration source"),
    bad("strokes-export-stroke-huge", f"strokes export --store store.sqlite --stroke {HUGE} "
        f"-o out.csv", ("--stroke", "store.sqlite")),
    bad("strokes-export-stroke-400-digits", f"strokes export --store store.sqlite --stroke "
        f"{HUGER} -o out.csv", ("--stroke", "store.sqlite")),
    bad("serve-port-huge", f"serve --store store.sqlite --port {HUGE}", "--port"),
    bad("serve-port-400-digits", f"serve --store store.sqlite --port {HUGER}", "--port"),
    # -- empty, truncated and garbage files -----------------------------------------------------
    bad("analyze-empty-wav", "analyze empty.wav", "empty.wav"),
    bad("analyze-garbage-wav", "analyze garbage.wav", "garbage.wav"),
    bad("analyze-truncated-wav", "analyze truncated.wav", "truncated.wav"),
    bad("analyze-big-csv-field", "analyze bigfield.csv", "bigfield.csv", big_field_csv),
    bad("analyze-csv-5000-digits", "analyze digits.csv", "digits.csv", digits_csv),
    bad("tactile-garbage-npz", "tactile garbage.npz -o out.wav", "garbage.npz"),
    bad("tactile-truncated-npz", "tactile truncated.npz -o out.wav", "truncated.npz"),
    bad("tactile-npz-rate-1e300", "tactile odd.npz -o out.wav", "odd.npz", npz_rate(1e300)),
    bad("tactile-npz-huge-shape", "tactile huge.npz -o out.wav", "huge.npz", npz_huge_shape),
    bad("tactile-garbage-actuator-csv", f"{TACTILE} --actuator garbage.csv", "garbage.csv"),
    bad("sound-loop-empty-wav", "sound loop empty.wav -o out.wav", "empty.wav"),
    bad("sound-render-garbage-trajectory", "sound render --sound rec.wav --trajectory "
        "garbage.csv -o out.wav", "garbage.csv"),
    bad("sound-render-big-csv-field", "sound render --sound rec.wav --trajectory bigfield.csv "
        "-o out.wav", "bigfield.csv", big_field_csv),
    bad("sound-render-deep-coupling", f"{RENDER} --coupling deep.json", "deep.json"),
    bad("sound-render-5000-digit-coupling", f"{RENDER} --coupling digits.json", "digits.json"),
    bad("sound-render-empty-coupling", f"{RENDER} --coupling empty.json", "empty.json"),
    bad("sound-fit-empty-csv", "sound fit empty.csv -o out.json", "empty.csv"),
    bad("sound-fit-garbage-base", f"{FIT} --base garbage.json", "garbage.json"),
    bad("sound-fit-deep-base", f"{FIT} --base deep.json", "deep.json"),
    bad("export-garbage-zip", "export garbage.zip -f wav -o p.wav", "garbage.zip"),
    bad("export-profile-wrong-suffix", "export profile pencil -f wav -o p.mp3", "p.mp3"),
    bad("export-read-missing", "export read nothere.hjif", "nothere.hjif"),
    bad("export-read-not-json", "export read bad.ahap --render out.wav", "bad.ahap",
        setup=lambda work: (work / "bad.ahap").write_text("{not json")),
    bad("export-read-render-rate", "export read p.haptic --render out.wav --rate 5", "--rate",
        setup=lambda work: (work / "p.haptic").write_text(
            '{"version": {"major": 1, "minor": 0, "patch": 0}, "signals": {"continuous": '
            '{"envelopes": {"amplitude": [{"time": 0, "amplitude": 0.5}, '
            '{"time": 0.1, "amplitude": 0.5}]}}}}')),
    bad("export-truncated-zip", "export truncated.zip -f wav -o p.wav", "truncated.zip"),
    bad("profile-show-garbage-zip", "profile show garbage.zip", "garbage.zip"),
    bad("profile-show-seam-not-a-number", "profile show badseam", "badseam",
        bundle_with_seam("loud")),
    bad("profile-build-deep-coupling", f"{BUILD} -o out.zip --coupling deep.json", "deep.json"),
    bad("profile-build-garbage-grid-csv", GRID_BUILD.replace("grid.csv", "garbage.csv"),
        "garbage.csv"),
    bad("profile-build-empty-grid-csv", GRID_BUILD.replace("grid.csv", "empty.csv"),
        "empty.csv"),
    bad("profile-build-grid-csv-without-header", GRID_BUILD, "grid.csv",
        grid_csv("50,1,rec.npz\n")),
    bad("profile-build-grid-csv-header-only", GRID_BUILD, "grid.csv",
        grid_csv("speed_mm_s,force_n,path\n")),
    bad("profile-build-grid-missing-recording", GRID_BUILD, "line 2",
        grid_csv("speed_mm_s,force_n,path\n50,1,none.wav\n")),
    bad("profile-build-grid-garbage-recording", GRID_BUILD, "garbage.npz",
        grid_csv("speed_mm_s,force_n,path\n50,1,garbage.npz\n80,1,rec.npz\n")),
    bad("profile-build-grid-lists-itself", GRID_BUILD, ("grid.csv", "line 3", "itself"),
        grid_csv("speed_mm_s,force_n,path\n50,1,rec.npz\n80,1,grid.csv\n")),
    # A 44.1 kHz sound as a point's vibration: the row's file is named with the rate's problem.
    bad("profile-build-grid-point-too-fast-for-the-rate", GRID_BUILD, ("--rate", "point 1",
        "rec.wav"), grid_csv("speed_mm_s,force_n,path\n50,1,rec.npz\n80,1,rec.wav\n")),
    bad("profile-build-garbage-hatt", "profile build --name mine --sound rec.wav -o out.zip "
        "--hatt garbage.xml", "garbage.xml"),
    bad("tactile-render-garbage-profile", "tactile render garbage.zip --trajectory t.csv "
        "-o out.wav", "garbage.zip"),
    bad("tactile-render-unknown-profile", "tactile render quill --trajectory t.csv -o out.wav",
        "quill"),
    bad("tactile-render-garbage-trajectory", "tactile render pencil --trajectory garbage.csv "
        "-o out.wav", "garbage.csv"),
    bad("tactile-render-empty-profile-name", ["tactile", "render", "", "--trajectory", "t.csv",
                                              "-o", "out.wav"], "empty"),
    bad("hatt-list-garbage-xml", "hatt list garbage.xml", "garbage.xml"),
    bad("strokes-export-garbage-store", "strokes export --store garbage.sqlite -o out.csv",
        "garbage.sqlite"),
    bad("serve-damaged-store", "serve --port 0 --store damaged.sqlite", "damaged.sqlite",
        damaged_store),
    # -- files of the wrong kind, folders where files go ----------------------------------------
    bad("sound-loop-npz-recording", "sound loop rec.npz -o out.wav", "rec.npz"),
    bad("sound-fit-wav-measurements", "sound fit rec.wav -o out.json", "rec.wav"),
    bad("sound-render-wav-coupling", f"{RENDER} --coupling rec.wav", "rec.wav"),
    bad("export-wav-as-bundle", "export rec.wav -f wav -o p.wav", "rec.wav"),
    bad("hatt-list-wav", "hatt list rec.wav", "rec.wav"),
    bad("profile-list-file-as-folder", "profile list --profiles rec.wav", "rec.wav"),
    bad("hatt-synth-mp3-output", f"{SYNTH} -o s.mp3", "s.mp3"),
    bad("analyze-folder", "analyze folder", "folder"),
    bad("analyze-json-folder", "analyze rec.npz --json folder --force", "folder"),
    bad("tactile-output-folder", "tactile rec.npz -o folder --force", "folder"),
    bad("tactile-render-output-folder", f"{FEEL} --force".replace("out.wav", "folder"),
        "folder"),
    bad("tactile-render-trajectory-folder", "tactile render pencil --trajectory folder "
        "-o out.wav", "folder"),
    bad("profile-build-grid-csv-folder", GRID_BUILD.replace("grid.csv", "folder"), "folder"),
    bad("sound-render-trajectory-folder", "sound render --sound rec.wav --trajectory folder "
        "-o out.wav", "folder"),
    bad("export-output-folder", "export pencil -f hjif -o folder --force", "folder"),
    bad("serve-store-folder", "serve --port 0 --store folder", "folder"),
    bad("serve-new-token-without-lan", "serve --port 0 --new-token", "--new-token"),
    # studies
    bad("study-plan-unknown-design", "study plan study9 -n 12", "study9"),
    bad("study-plan-missing-design", "study plan none.yaml -n 12", "none.yaml"),
    bad("study-plan-folder-design", "study plan folder -n 2", "folder"),
    bad("study-plan-garbage-yaml", "study plan d.yaml -n 2", "d.yaml",
        existing("d.yaml", b"name: [x\n")),
    bad("study-plan-csv-is-design", "study plan d.yaml -n 2 --csv d.yaml --force", "d.yaml",
        existing("d.yaml", b"name: x\n")),
    bad("study-plan-csv-exists", "study plan study1 -n 2 --csv t.csv", "t.csv", existing("t.csv")),
    bad("study-plan-csv-is-folder", "study plan study1 -n 2 --csv folder --force", "folder"),
    bad("study-plan-seed-huge", f"study plan study1 -n 2 --seed {HUGE}", "--seed"),
    bad("study-plan-participants-zero", "study plan study1 -n 0", "--participants"),
    bad("study-plan-participants-many", "study plan study1 -n 2000", "--participants"),
    bad("study-designs-extra-argument", "study designs x", "study designs"),
    bad("study-schema-output-is-folder", "study schema -o folder --force", "folder"),
    bad("study-export-missing-store", "study export --store none.sqlite -o answers.csv", "none.sqlite"),
    bad("study-export-not-a-store", "study export --store rec.wav -o answers.csv", "rec.wav"),
    bad("study-export-over-store", "study export --store store.sqlite -o store.sqlite --force",
        "store.sqlite"),
    bad("study-export-over-wal", "study export --store store.sqlite -o store.sqlite-wal --force",
        "store.sqlite-wal"),
    bad("study-export-output-folder", "study export --store store.sqlite -o folder --force",
        "folder"),
    bad("study-export-unknown-design", "study export --store store.sqlite --design study9 -o answers.csv",
        "study9"),
    bad("study-export-password-in-query", "study export --store "
        "postgresql://u@/x?host=/nonexistent&password=hunter2 -o answers.csv", "password=***"),
    bad("study-export-bad-url", "study export --store postgresql://u:secret@/x?host=/nonexistent "
        "-o answers.csv", "postgresql://u:***@"),
    bad("study-start-unknown-design", "study start study9 -p P01 --store store.sqlite", "study9"),
    bad("study-withdraw-missing-store", "study withdraw P01 --study study1 --store none.sqlite",
        "none.sqlite"),
    bad("study-abandon-nothing-named", "study abandon --store store.sqlite", "--stale"),
    bad("stats-missing-trials", "stats report study1 none.csv -o report", "none.csv"),
    bad("stats-trajectory-as-trials", "stats report study1 t.csv -o report", "t.csv"),
    bad("stats-empty-trials", "stats study1 empty.csv -o report", "empty.csv"),
    bad("stats-garbage-trials", "stats study1 garbage.csv -o report", "garbage.csv"),
    bad("stats-folder-trials", "stats study1 folder -o report", "folder"),
    bad("stats-unknown-design", "stats study9 t.csv -o report", "study9"),
    bad("stats-report-over-trials", "stats study1 t.csv -o t.csv --force", "t.csv"),
    bad("stats-report-exists", "stats study1 t.csv -o folder", "folder"),
    bad("stats-report-holds-trials", "stats study1 folder/t.csv -o folder --force", "folder",
        copy_into("t.csv", "folder")),
    bad("stats-bad-wilcoxon", "stats study1 t.csv -o report --wilcoxon fisher", "--wilcoxon"),
    bad("stats-bad-adjust", "stats study1 t.csv -o report --adjust fdr", "--adjust"),
    bad("stats-bad-blocks", "stats study1 t.csv -o report --friedman-blocks some",
        "--friedman-blocks"),
    bad("stats-bad-ci", "stats study1 t.csv -o report --likert-ci z", "--likert-ci"),
    bad("stats-power-sims-huge", f"stats study1 t.csv -o report --power-sims {HUGE}",
        "--power-sims"),
    bad("stats-power-sims-one", "stats study1 t.csv -o report --power-sims 1", "--power-sims"),
    bad("stats-force-foreign-folder", "stats study1 t.csv -o folder --force", "folder",
        copy_into("rec.wav", "folder")),
    bad("stats-report-is-cwd", "stats study1 t.csv -o . --force", "."),
    bad("stats-options-first", "stats -o report study9 t.csv", "study9"),
    bad("stats-power-unknown-design", "stats power study9 -n 8", "study9"),
    bad("stats-power-one-participant", "stats power study1 -n 1", "--participants"),
    bad("stats-power-huge-participants", f"stats power study1 -n 8 {HUGE}", "--participants"),
    bad("stats-power-no-participants", "stats power study1", "--participants"),
    bad("stats-power-nan-effect", "stats power study1 -n 8 --effect nan", "--effect"),
    bad("stats-power-bad-rates", "stats power study2 -n 8 --rates tactile=2", "--rates"),
    bad("stats-power-sims-few", "stats power study1 -n 8 --sims 0", "--sims"),
    bad("stats-power-plot-exists", "stats power study1 -n 8 --sims 10 --plot t.csv", "t.csv"),
    bad("stats-power-plot-folder", "stats power study1 -n 8 --sims 10 --plot folder --force",
        "folder"),
    bad("stats-power-plot-type", "stats power study1 -n 8 --sims 10 --plot power.xyz", "power.xyz"),
    bad("stats-simulate-unknown-design", "stats simulate study9 -n 2 -o sim.csv", "study9"),
    bad("stats-simulate-exists", "stats simulate study1 -n 2 -o t.csv", "t.csv"),
    bad("stats-simulate-no-participants", "stats simulate study1 -n 0 -o sim.csv",
        "--participants"),
    bad("stats-simulate-over-store", "stats simulate study1 -n 2 --store store.sqlite "
        "-o store.sqlite --force", "store.sqlite"),
    bad("stats-simulate-not-a-store", "stats simulate study1 -n 2 --store rec.wav -o sim.csv",
        "rec.wav"),
    # the pen (nothing answers on these ports; no simulated pen starts)
    bad("device-list-seconds-nan", "device list --seconds nan", "--seconds"),
    bad("device-list-seconds-negative", "device list --seconds -1", "--seconds"),
    bad("device-list-extra-argument", "device list COM3", "device list"),
    bad("device-info-no-port", "device info", "--port"),
    bad("device-timeout-nan", "device --timeout nan info --port rec.wav", "--timeout"),
    bad("device-timeout-zero", "device --timeout 0 ping --port rec.wav", "--timeout"),
    bad("device-info-empty-port", ["device", "info", "--port", ""], "--port"),
    bad("device-info-missing-port", "device info --port none/ttyACM0", "none/ttyACM0"),
    bad("device-info-file-as-port", "device info --port rec.wav", "rec.wav"),
    bad("device-info-folder-as-port", "device --port folder info", "folder"),
    bad("device-upload-unknown-profile", "device upload quill --port none", "quill"),
    bad("device-upload-garbage-profile", "device upload garbage.zip --port none",
        "garbage.zip"),
    bad("device-upload-file-as-port", "device upload pencil --port rec.wav", "rec.wav"),
    bad("device-play-gain-above-one", "device play --gain 2 --port rec.wav", "--gain"),
    bad("device-play-gain-nan", "device play --gain nan --port rec.wav", "--gain"),
    bad("device-play-rate-1e9", "device play --rate 1e9 --port rec.wav", "--rate"),
    bad("device-play-fade-huge", f"device play --fade-ms {HUGE} --port rec.wav", "--fade-ms"),
    bad("device-play-fade-negative", "device play --fade-ms -1 --port rec.wav", "--fade-ms"),
    bad("device-stop-fade-too-long", "device stop --fade-ms 70000 --port rec.wav", "--fade-ms"),
    bad("device-stop-missing-port", "device stop --port none", "none"),
    bad("device-ping-count-zero", "device ping --count 0 --port rec.wav", "--count"),
    bad("device-ping-count-huge", f"device ping --count {HUGE} --port rec.wav", "--count"),
    bad("device-ping-count-400-digits", f"device ping -n {HUGER} --port rec.wav", "--count"),
    bad("device-monitor-seconds-nan", "device monitor --seconds nan --port rec.wav",
        "--seconds"),
    bad("device-monitor-seconds-zero", "device monitor --seconds 0 --port rec.wav", "--seconds"),
    bad("device-monitor-folder-as-port", "device monitor --port folder", "folder"),
    bad("device-sim-record-exists", "device sim --record rec.wav", "rec.wav"),
    bad("device-sim-record-not-wav", "device sim --record out.mp3", "out.mp3"),
    bad("device-sim-record-folder", "device sim --record folder --force", "folder"),
    bad("device-sim-trace-is-record", "device sim --record out.wav --trace out.wav", "out.wav"),
    bad("device-sim-trace-exists", "device sim --trace t.csv", "t.csv"),
    # --record is written when the pen stops: a place that takes no file is refused at once
    bad("device-sim-record-in-a-file", "device sim --record /etc/passwd/x.wav",
        "/etc/passwd/x.wav"),
    bad("device-sim-record-unwritable", "device sim --record /proc/x.wav", "/proc/x.wav"),
    bad("device-sim-record-no-folder", "device sim --record nowhere/x.wav", "nowhere/x.wav"),
    bad("record-not-a-capture-file", "record --port rec.wav --seconds 1 -o out.mp3", "out.mp3"),
    bad("record-seconds-zero", "record --port rec.wav --seconds 0 -o out.wav", "--seconds"),
    bad("record-range-3", "record --port rec.wav --seconds 1 --range 3 -o out.wav", "--range"),
    bad("record-output-exists", "record --port rec.wav --seconds 1 -o rec.wav", "rec.wav"),
    bad("record-file-as-port", "record --port rec.wav --seconds 1 -o out.wav", "rec.wav"),
    bad("record-output-unwritable", "record --port rec.wav --seconds 1 -o /proc/x.wav",
        "/proc/x.wav"),
    bad("actuator-measure-not-csv", "actuator measure --port rec.wav -o out.mp3", "out.mp3"),
    bad("actuator-measure-repeats-1", "actuator measure --port rec.wav -o out.csv --repeats 1",
        "--repeats"),
    bad("actuator-measure-file-as-port", "actuator measure --port rec.wav -o out.csv",
        "rec.wav"),
    bad("actuator-verify-no-such-csv", "actuator verify --port rec.wav --actuator nope.csv",
        "nope.csv"),
    bad("actuator-verify-gain-2", "actuator verify --port rec.wav --actuator lra --gain 2",
        "--gain"),
    # a group option's value is no subcommand: the flag named is the subcommand's
    bad("device-port-first-play-gain", "device --port /dev/null play --gain 2", "--gain"),
    bad("device-port-first-ping-count", "device -p /dev/null ping -n 0", "--count"),
]


# --- the test ----------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def template(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("corpus-template")
    build_template(root)
    assert all((root / name).exists() for name in TEMPLATE_FILES)
    return root


def snapshot(root: Path) -> dict[str, tuple]:
    """Every path under ``root``: a link's target, a folder, or a file's SHA-256."""
    state = {}
    for folder, folders, files in os.walk(root):
        for name in folders + files:
            path = Path(folder) / name
            where = path.relative_to(root).as_posix()
            if path.is_symlink():
                state[where] = ("link", os.readlink(path))
            elif path.is_dir():
                state[where] = ("folder",)
            else:
                state[where] = ("file", hashlib.sha256(path.read_bytes()).hexdigest())
    return state


@pytest.mark.parametrize("case", CORPUS)
def test_bad_invocation_fails_in_one_line_and_writes_nothing(case, template, tmp_path,
                                                            monkeypatch):
    work = tmp_path / "work"
    shutil.copytree(template, work, symlinks=True)
    home = tmp_path / "home"
    home.mkdir()
    monkeypatch.setenv("REALPEN_HOME", str(home))
    # A serve case that got past its checks would run until stopped: fail instead.
    import realpen.live.server

    def no_serving(*args, **kwargs):
        raise AssertionError("the server started; the input was not refused")

    monkeypatch.setattr(realpen.live.server, "run", no_serving)
    if case.setup is not None:
        case.setup(work)
    before = snapshot(tmp_path)

    result = run_cli(*case.args, cwd=work)

    assert "Traceback" not in result.stderr, result.stderr[-3000:]
    assert result.returncode == 2, (result.returncode, result.stdout[-500:], result.stderr[-500:])
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("realpen: error: "), lines[0]
    assert any(name in lines[0] for name in case.names), (case.names, lines[0])
    assert snapshot(tmp_path) == before, "files were written or changed"


def test_the_corpus_covers_every_command():
    """At least 30 cases, and every runnable command has some."""
    from test_cli import leaf_commands

    commands = set(leaf_commands())
    covered = set()
    for param in CORPUS:
        args = param.values[0].args
        covered |= {" ".join(args[:n]) for n in (1, 2)} & commands
    assert len(CORPUS) >= 30
    assert covered == commands, sorted(commands - covered)
