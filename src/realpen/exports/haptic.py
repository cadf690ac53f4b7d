"""Lofelt / Meta Haptics Studio ``.haptic``, data model version 1.0.0.

Fields as in the Lofelt data model (``core/datamodel`` of Lofelt/NiceVibrations: README and
``src/v1.rs``): ``version`` {major, minor, patch} (required), ``metadata`` (editor, author,
source, project, tags, description; optional) and ``signals.continuous.envelopes`` with an
``amplitude`` list of {time, amplitude[, emphasis]} (required, non-empty) and an optional
``frequency`` list of {time, frequency}. Times are in seconds and must not decrease; amplitude
and frequency are 0 … 1. The normalised frequency "corresponds with the scaled output of the
centroid tracker"; no mapping to Hz is published.

The envelopes are the pattern's frame RMS and spectral centroid. Lofelt's own AHAP converter
plays ``intensity = √amplitude`` and ``sharpness = √frequency``, so this export writes the
squares of the AHAP export's values — converting this file with Lofelt's tools gives the same
curves as :mod:`realpen.exports.ahap`. No emphasis is written: the pattern has no transients.

What it cannot carry: the superposed components (one amplitude and one frequency at a time);
a loop flag — the file holds ``repeats`` periods (the Lofelt SDK loops clips at playback);
the sound (Haptics Studio pairs a clip with its audio file outside the ``.haptic``).
"""

from __future__ import annotations

import json

from realpen._version import __version__
from realpen.exports import envelope as env
from realpen.exports.base import RESIDUAL_IN_ENVELOPE, Export, check_pattern, check_span, residual_limits
from realpen.exports.haptic_rules import check_haptic
from realpen.exports.snippets import unity_player, unity_script_name
from realpen.tactile.pattern import TactilePattern

__all__ = ["SUFFIX", "LIMITS", "build", "export"]

SUFFIX = ".haptic"
LIMITS = (
    "one amplitude and one frequency at a time: the RMS envelope and the spectral centroid",
    "no loop flag: loop the clip at playback",
    "the sound is not in the .haptic file",
)


def build(pattern: TactilePattern, *, repeats: int = 1, name: str = "pattern", tool: str = "",
          version: str | None = None) -> dict:
    """The ``.haptic`` document, as a dict ready for ``json.dumps``.

    Args:
        pattern: the tactile pattern.
        repeats: periods of the tactile pattern laid end to end.
        name, tool, version: for ``metadata`` (version default: the pattern's).
    """
    pattern = check_pattern(pattern)
    repeats = check_span(pattern, repeats, name)
    measured = env.measure(pattern.samples, pattern.rate, source=name)
    times, intensity = env.loop_curve(measured, measured.intensity, repeats)
    _, sharp = env.loop_curve(measured, env.sharpness(measured.centroid_hz), repeats)
    what = f"{tool}: " if tool else ""
    return {
        "version": {"major": 1, "minor": 0, "patch": 0},
        "metadata": {
            "editor": f"RealPen {__version__}",
            "author": "",
            "source": f"{name} (version {version or pattern.version})",
            "project": "RealPen",
            "tags": ["RealPen", name],
            "description": f"{what}{repeats} × {measured.period_s * 1000:g} ms tactile pattern",
        },
        "signals": {"continuous": {"envelopes": {
            "amplitude": [{"time": round(float(t), 6), "amplitude": round(float(a) ** 2, 4)}
                          for t, a in zip(times, intensity)],
            "frequency": [{"time": round(float(t), 6), "frequency": round(float(s) ** 2, 4)}
                          for t, s in zip(times, sharp)],
        }}},
    }


def export(pattern: TactilePattern, sound=None, coupling=None, *, name: str = "pattern",
           tool: str = "", version: str | None = None, repeats: int = 1,
           haptic_file: str | None = None) -> Export:
    """Render the ``.haptic`` file and, when ``coupling`` is given, a Unity script
    (:func:`realpen.exports.snippets.unity_player`) that loops it with Nice Vibrations, its level
    following Eq. 1; see the module docstring. ``sound`` is not carried.

    Args:
        haptic_file: the clip's file name (default ``<name>.haptic``); names the script
            (:func:`~realpen.exports.snippets.unity_script_name`).

    Raises:
        RealPenError: the document breaks a Lofelt v1 rule
            (:func:`~realpen.exports.haptic_rules.check_haptic`); nothing is written.
    """
    document = check_haptic(build(pattern, repeats=repeats, name=name, tool=tool,
                                  version=version), f"{name}{SUFFIX}")
    points = document["signals"]["continuous"]["envelopes"]["amplitude"]
    summary = (f"{len(points)} amplitude and frequency breakpoints over "
               f"{points[-1]['time'] * 1000:g} ms")
    companions = {}
    if coupling is not None:
        clip = haptic_file or f"{name}{SUFFIX}"
        companions[unity_script_name(clip)] = unity_player(name, coupling, clip).encode("utf-8")
        summary += ", a Unity script applying Eq. 1"
    return Export((json.dumps(document, indent=2, allow_nan=False) + "\n").encode("utf-8"),
                  summary, companions, LIMITS + residual_limits(pattern, RESIDUAL_IN_ENVELOPE))
