"""Build a profile of a modelled pen through the same pipeline as recorded pens."""

from __future__ import annotations

from pathlib import Path

from realpen.io.files import write_wav
from realpen.io.recording import load_recording
from realpen.pens.model import PENS, PaperModel, friction_sound, vibration
from realpen.profile.build import build_profile
from realpen.profile.bundle import PenProfile
from realpen.sound.loop import load_sound
from realpen.tactile.actuator import parse_actuator

__all__ = ["MODEL_SEED", "write_model_recordings", "build_modelled_pen"]

MODEL_SEED = 2016


def write_model_recordings(name: str, folder: Path, seed: int = MODEL_SEED) -> tuple[Path, Path]:
    """Write the model's vibration (3-axis, 1344 Hz, m/s²) and sound (48 kHz) WAVs of a pen.

    Returns:
        (vibration path, sound path) inside ``folder``.
    """
    pen = PENS[name]
    shake = vibration(pen, PaperModel(), seed=seed)
    vibration_path = Path(folder) / f"{name}_vibration.wav"
    sound_path = Path(folder) / f"{name}_sound.wav"
    # m/s² in float WAV: the values are kept exactly; the unit is recorded in the provenance.
    write_wav(vibration_path, shake.samples, int(shake.rate))
    write_wav(sound_path, friction_sound(pen, PaperModel(), seed=seed), 48000)
    return vibration_path, sound_path


def build_modelled_pen(name: str, folder: Path, actuator: str, seed: int = MODEL_SEED) -> PenProfile:
    """Model a pen's recordings into ``folder`` and build its profile from them.

    Args:
        name: one of :data:`realpen.pens.model.PENS` (pencil, ballpoint, marker).
        folder: where the modelled recordings are written.
        actuator: the actuator spec the tactile pattern is equalised for.
        seed: the model's seed.
    """
    pen = PENS[name]
    vibration_path, sound_path = write_model_recordings(name, folder, seed)
    description = (f"Modelled {pen.tool} on paper (RealPen pen model, seed {seed}); "
                   f"not a recording of a real pen.")
    model = {"pen": pen.to_json(), "paper": PaperModel().__dict__, "seed": seed,
             "vibration_units": "m/s^2"}
    return build_profile(name, pen.tool, load_recording(vibration_path), load_sound(sound_path),
                         parse_actuator(actuator), description=description, model=model)
