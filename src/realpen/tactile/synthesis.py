"""Superposition of sinusoids per sub-pattern, and the joins between sub-patterns.

Per sub-pattern one sinusoid ``a·sin(2πf·t + φ)`` is summed per component, ``t`` counted from
the sub-pattern's start. Sub-patterns follow each other and the whole loops. With
``boundary="crossfade"`` each sub-pattern is synthesised ``crossfade_ms`` longer and neighbours
(the last and the first included, across the loop wrap) overlap, centred on the boundary — a
component that continues a track across the boundary (same frequency, continuous phase) fades
linearly, any other with equal power (sin/cos) — so the loop has no click; ``boundary="hard"``
concatenates, as the method describes literally.

Lengths are whole samples: a sub-pattern is ``round(subpattern_ms × rate / 1000)`` samples and
the crossfade an even number of samples (so it is centred on the boundary), at most one
sub-pattern. The export formats that rebuild the superposition (``.hjif``) use the same
:func:`subpattern_samples` and :func:`fade_samples`.

numpy only.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from realpen.checks import check_frames, require_choice, require_number
from realpen.errors import ParameterError

__all__ = ["BOUNDARIES", "synthesize", "subpattern_samples", "fade_samples",
           "component_arrays"]

BOUNDARIES = ("crossfade", "hard")
_BLOCK_VALUES = 2**22  # sinusoid values computed at once: 32 MiB, however many components






def subpattern_samples(rate: float, subpattern_ms: float) -> int:
    """Samples in one sub-pattern of ``subpattern_ms`` ms at ``rate`` Hz (rounded)."""
    return int(round(subpattern_ms * rate / 1000.0))


def fade_samples(rate: float, subpattern_ms: float, boundary: str, crossfade_ms: float) -> int:
    """Crossfade length in samples: even, centred on the boundary, at most one sub-pattern
    (0 with ``boundary="hard"``)."""
    if boundary != "crossfade":
        return 0
    fade = int(round(crossfade_ms * rate / 1000.0))
    fade -= fade % 2
    return min(fade, subpattern_samples(rate, subpattern_ms))


def component_arrays(sub) -> tuple[np.ndarray, ...]:
    """(frequencies Hz, amplitudes, phases rad, joins_previous, joins_next) of one sub-pattern.

    ``sub`` is a sequence of components (objects with ``frequency_hz``, ``amplitude``,
    ``phase`` and optionally ``joins_previous``/``joins_next``) or a tuple of arrays in that
    order (the flags optional).
    """
    if isinstance(sub, tuple) and len(sub) and isinstance(sub[0], (np.ndarray, list, tuple)):
        arrays = [np.asarray(a, dtype=np.float64) for a in sub[:3]]
        flags = [np.asarray(a, dtype=bool) for a in sub[3:5]]
        flags += [np.zeros(len(arrays[0]), dtype=bool)] * (2 - len(flags))
        return (*arrays, *flags)
    return (np.array([c.frequency_hz for c in sub], dtype=np.float64),
            np.array([c.amplitude for c in sub], dtype=np.float64),
            np.array([c.phase for c in sub], dtype=np.float64),
            np.array([getattr(c, "joins_previous", False) for c in sub], dtype=bool),
            np.array([getattr(c, "joins_next", False) for c in sub], dtype=bool))


def synthesize(subpatterns: Sequence, rate: int, subpattern_ms: float,
               boundary: str = "crossfade", crossfade_ms: float = 5.0) -> np.ndarray:
    """Superpose sinusoids per sub-pattern and join the sub-patterns into one loop.

    Args:
        subpatterns: per sub-pattern either a sequence of components (e.g.
            :class:`~realpen.tactile.pattern.Component`) or a tuple of arrays (frequencies in
            Hz, amplitudes in full scale, phases in radians[, joins_previous, joins_next]).
        rate: output rate in Hz.
        subpattern_ms: length of each sub-pattern in ms.
        boundary: ``"crossfade"`` (across the loop wrap too) or ``"hard"``.
        crossfade_ms: fade length in ms. A component that continues a track across a
            boundary fades linearly (its two halves are in phase); any other fades with equal
            power (sin/cos), as uncorrelated material should.

    Returns:
        The loop, float64, shape (len(subpatterns) × sub-pattern samples,), full scale ±1 if
        the amplitudes are.

    Raises:
        ParameterError: a bad ``rate``, ``subpattern_ms``, ``boundary`` or ``crossfade_ms``, no
            sub-patterns, or a loop longer than :data:`~realpen.checks.MAX_PATTERN_FRAMES` samples (parameter
            ``rate``).

    Example:
        >>> x = synthesize([([100.0], [0.5], [0.0])], 8000, 100, boundary="hard")
        >>> len(x), round(float(abs(x).max()), 3)
        (800, 0.5)
    """
    require_number("rate", rate, minimum=0.0, inclusive=False)
    require_number("subpattern_ms", subpattern_ms, minimum=0.0, inclusive=False)
    require_choice("boundary", boundary, BOUNDARIES)
    require_number("crossfade_ms", crossfade_ms, minimum=0.0)
    if not len(subpatterns):
        raise ParameterError("subpatterns", "needs at least one sub-pattern")
    length = subpattern_samples(rate, subpattern_ms)
    if length < 1:
        raise ParameterError("subpattern_ms", f"{subpattern_ms:g} ms is less than one sample at "
                                              f"{rate:g} Hz")
    total = check_frames(len(subpatterns), rate, subpattern_ms)
    fade = fade_samples(rate, subpattern_ms, boundary, crossfade_ms)
    out = np.zeros(total)
    local = (np.arange(length + fade) - fade // 2) / rate
    u = (np.arange(fade) + 0.5) / max(fade, 1)
    power_in, linear_in = np.sin(0.5 * np.pi * u), u
    for index, sub in enumerate(subpatterns):
        freqs, amps, phases, joins_previous, joins_next = component_arrays(sub)
        if not len(freqs):
            continue
        summed = np.zeros(length + fade)
        # Components in blocks: memory stays a few sub-patterns long however many there are.
        step = max(1, _BLOCK_VALUES // (length + fade))
        for first in range(0, len(freqs), step):
            part = slice(first, first + step)
            waves = amps[part, None] * np.sin(2 * np.pi * freqs[part, None] * local[None, :]
                                              + phases[part, None])
            if fade:
                waves[:, :fade] *= np.where(joins_previous[part, None], linear_in, power_in)
                waves[:, -fade:] *= np.where(joins_next[part, None], linear_in[::-1],
                                             power_in[::-1])
            summed += waves.sum(axis=0)
        positions = (index * length - fade // 2 + np.arange(length + fade)) % total
        np.add.at(out, positions, summed)
    return out
