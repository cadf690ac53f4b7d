"""The one map from the library's Python parameter names to the command line's flags.

The library words every bad argument with the Python name of the parameter
(:class:`realpen.errors.ParameterError`: ``"unit_ms: must be > 0, got -1"``); the command line
shows it with the flag the user typed (``"--unit-ms: must be > 0, got -1"``). This module is the
only place that knows which flag stands for which parameter:

- :data:`DEFAULT_FLAGS`: the flag a parameter has wherever a command takes it;
- :data:`COMMAND_FLAGS`: per command (``"tactile build"``, ``"sound loop"``, ...), the
  parameters it names differently. A key may be qualified by the library function that owns the
  parameter, ``"load_recording.rate"``: ``tactile build`` reads a recording whose ``rate`` is
  ``--input-rate``, while its output ``rate`` is ``--rate``. The qualified key matches when that
  function is on the call stack of the error (innermost first), so the map says *which*
  ``rate`` without the library knowing anything of flags.

A parameter in neither map keeps its Python name, which still says what is wrong. Importing this
module imports nothing heavy (it runs for ``realpen --help``).
"""

from __future__ import annotations

import traceback
from collections.abc import Sequence

from realpen.errors import ParameterError

__all__ = ["DEFAULT_FLAGS", "COMMAND_FLAGS", "flag_for", "raising_functions", "describe"]

DEFAULT_FLAGS: dict[str, str] = {
    # recordings and their analysis (realpen.io, realpen.dsp)
    "rate": "--rate",
    "subtype": "--subtype",
    "unit_ms": "--unit-ms",
    "top": "--top",
    "count": "--subpatterns",
    "subpatterns": "--subpatterns",
    "selection": "--select",
    "highpass_hz": "--highpass",
    "cutoff_hz": "--highpass",
    "axis": "--axis",
    "analysis_rate": "--analysis-rate",
    "input_rate": "--input-rate",
    "even_grid": "--even-grid",
    "max_interpolated_pct": "--max-interpolated",
    # studies (realpen.study)
    "participants": "--participants",
    # statistics (realpen.stats)
    "wilcoxon_method": "--wilcoxon",
    "adjust": "--adjust",
    "friedman_variant": "--friedman-blocks",
    "likert_ci": "--likert-ci",
    "effect": "--effect",
    "rates": "--rates",
    "sims": "--sims",
    # tactile patterns (realpen.tactile)
    "condition": "--condition",
    "actuator": "--actuator",
    "boundary": "--boundary",
    "crossfade_ms": "--crossfade-ms",
    "amplitude": "--amplitude",
    "seed": "--seed",
    "cap_db": "--cap-db",
    "model": "--model",
    # friction sound and coupling (realpen.sound)
    "mode": "--mode",
    "length_ms": "--length-ms",
    "grain_ms": "--grain-ms",
    "level_dbfs": "--level-dbfs",
    "find_unit": "--as-loop",  # its problems are a file too short to search: the remedy is named
    "fix": "--fix",
    "value": "--value",
    # profiles and exports (realpen.profile, realpen.exports)
    "name": "--name",
    "fmt": "--format",
    "stereo": "--stereo",
    "repeats": "--repeats",
    # the live app (realpen.live)
    "port": "--port",
    "tactile": "--tactile",
    # HaTT texture models (realpen.datasets.hatt)
    "speed_mm_s": "--speed",
    "force_n": "--force",
    "duration_s": "--seconds",
}

COMMAND_FLAGS: dict[str, dict[str, str]] = {
    # The pen's commands: --count is how many PINGs (not --subpatterns); gain and ramp time
    # are checked by realpen.device.client.state_payload.
    "device ping": {"count": "--count"},
    "device play": {"gain": "--gain", "fade_ms": "--fade-ms"},
    "device stop": {"fade_ms": "--fade-ms"},
    # The report's power simulation is --power-sims.
    "stats report": {"sims": "--power-sims"},
    # The recording's rate (a CSV without time) is --input-rate; --rate is the pattern's.
    "tactile build": {"load_recording.rate": "--input-rate", "open_stream.rate": "--input-rate"},
    "profile build": {
        "load_recording.rate": "--input-rate",
        "open_stream.rate": "--input-rate",
        # build_profile's own unit_ms and crossfade_ms are the sound loop's; the tactile
        # pattern's unit (checked in build_pattern, or before build_profile runs) is --unit-ms.
        "build_pattern.unit_ms": "--unit-ms",
        "build_profile.unit_ms": "--sound-unit-ms",
        "build_profile.crossfade_ms": "--sound-crossfade-ms",
        # The sound is resampled to 48 kHz; when that is too much, the recording is at fault.
        "load_sound.rate": "--sound",
        "_mono.rate": "--sound",
    },
}


def raising_functions(error: BaseException) -> list[str]:
    """Names of the RealPen functions on ``error``'s traceback, innermost first.

    Only frames of ``realpen.*`` modules count, so click's and typer's own frames never match a
    qualified key of :data:`COMMAND_FLAGS`.
    """
    names = []
    for frame, _ in traceback.walk_tb(error.__traceback__):
        if str(frame.f_globals.get("__name__", "")).startswith("realpen."):
            names.append(frame.f_code.co_name)
    return names[::-1]


def flag_for(command: str, parameter: str, functions: Sequence[str] = ()) -> str:
    """The flag (or argument) of ``command`` that stands for the Python ``parameter``.

    Args:
        command: the command path without the program name, e.g. ``"sound loop"``.
        parameter: the library's parameter name, e.g. ``"unit_ms"``.
        functions: RealPen functions on the error's call stack, innermost first (see
            :func:`raising_functions`); they select qualified keys such as
            ``"load_recording.rate"``.

    Returns:
        The flag (``"--unit-ms"``), or ``parameter`` itself when no map names it.

    >>> flag_for("tactile build", "rate", ["_load_csv", "load_recording"])
    '--input-rate'
    >>> flag_for("tactile build", "rate", ["resolve"])
    '--rate'
    """
    overrides = COMMAND_FLAGS.get(command, {})
    for function in functions:
        qualified = f"{function}.{parameter}"
        if qualified in overrides:
            return overrides[qualified]
    return overrides.get(parameter) or DEFAULT_FLAGS.get(parameter) or parameter


def describe(error: ParameterError, command: str) -> str:
    """``error`` as the command line says it: ``"--flag: problem"``."""
    return f"{flag_for(command, error.parameter, raising_functions(error))}: {error.problem}"
