"""The library's defaults and choices that the command line shows in its help, stated once.

The sound loop's and the granular texture's defaults, the study-1 conditions, the tactile
models, the export formats and the pen's reply timeout are defined here and nowhere else: the
library modules (:mod:`realpen.sound.loop`, :mod:`realpen.sound.granular`,
:mod:`realpen.tactile.conditions`, :mod:`realpen.exports`, :mod:`realpen.device.client`) take
them from here, and so does the ``realpen`` command, whose ``--help`` must answer without
loading numpy. The limits that arguments are checked against are :mod:`realpen.checks`.

May import: the standard library only (a test checks that importing it loads no numpy).
"""

from __future__ import annotations

__all__ = ["SOUND_RATE_HZ", "SOUND_UNIT_MS", "SOUND_CROSSFADE_MS", "SOUND_REFERENCE_DBFS",
           "SOUND_MODES", "GRAIN_MS", "TEXTURE_LENGTH_MS", "CONDITIONS", "TACTILE_MODELS",
           "RECOMMENDED_MODEL", "EXPORT_FORMATS", "DEVICE_TIMEOUT_S", "MODALITIES",
           "OLD_MODALITY_NAMES", "modality_name"]

# --- friction sound (realpen.sound) ---------------------------------------------------------

SOUND_RATE_HZ = 48000
"""The rate (Hz) a friction sound is loaded at unless told otherwise."""
SOUND_UNIT_MS = 300.0
"""The length of a loop unit (ms)."""
SOUND_CROSSFADE_MS = 10.0
"""The crossfade at a loop's wrap (ms)."""
SOUND_REFERENCE_DBFS = -20.0
"""The RMS (dBFS) of a normalised loop: the level that coupling gain 1 plays at."""
SOUND_MODES = ("loop", "granular")
"""How a sound unit is made: one seamless unit cut from the recording, or a texture of grains."""
GRAIN_MS = 50.0
"""The length of a grain of a granular texture (ms)."""
TEXTURE_LENGTH_MS = 3000.0
"""The length of a granular texture (ms)."""

# --- tactile patterns (realpen.tactile) -----------------------------------------------------

CONDITIONS: dict[str, tuple[int, int, float]] = {
    "A": (5, 15, 100.0), "B": (10, 15, 100.0), "C": (15, 15, 100.0),
    "D": (5, 1, 1500.0), "E": (10, 1, 1500.0), "F": (15, 1, 1500.0),
}
"""Study 1's conditions: (principal frequencies, sub-patterns, sub-pattern length in ms)."""
TACTILE_MODELS = ("sines", "sines+residual")
"""The method's sinusoids; plus the stochastic residual between them."""
RECOMMENDED_MODEL = "sines+residual"
"""The model the command line builds with unless told otherwise: on HaTT paper textures its
felt spectrum is 2.3× closer to the real vibration than the method's sines in the
sensitivity-weighted log-spectral distance (median 3.30 against 7.64 dB; 1/3-octave band
levels about equal, 6.59 against 6.46 dB; ``benchmarks/bench_fidelity.py``).
:class:`~realpen.tactile.conditions.TactileParams` itself defaults to ``"sines"``, the method,
and the study's conditions A–F always use it."""

# --- feedback modalities (live app, studies, statistics) ------------------------------------

MODALITIES = ("tactile", "auditory", "audio-tactile", "none")
"""The feedback a pen gives while it writes: vibration only, sound only, both, or nothing. The
one spelling of each that the project writes and shows (designs, the live page and its
WebSocket, every export, the statistics)."""
OLD_MODALITY_NAMES = {"auditory-tactile": "audio-tactile"}
"""Names earlier releases wrote (the live page, its WebSocket and ``realpen strokes export``
said ``auditory-tactile``): still read, as the current name."""


def modality_name(name: str) -> str:
    """The current name of a feedback modality: an old spelling becomes today's, any other
    text is returned as it is (checking it is the caller's schema's job).

    Every boundary that reads a modality (a WebSocket message, a URL parameter, a stored row, a
    CSV read back) passes it through here, so the rest of the project sees one name.

    Args:
        name: a modality as given (e.g. ``"auditory-tactile"``).

    Returns:
        The name in :data:`MODALITIES` it stands for, or ``name`` unchanged.

    >>> modality_name("auditory-tactile")
    'audio-tactile'
    >>> modality_name("tactile")
    'tactile'
    """
    return OLD_MODALITY_NAMES.get(name, name)


# --- exports and the pen --------------------------------------------------------------------

EXPORT_FORMATS = ("wav", "c-header", "ahap", "haptic", "android", "hjif")
"""The export formats, in the order :data:`realpen.exports.FORMATS` lists them."""
DEVICE_TIMEOUT_S = 2.0
"""Seconds to wait for each reply of the pen: a reply takes milliseconds over USB, tens of ms
over Bluetooth."""
