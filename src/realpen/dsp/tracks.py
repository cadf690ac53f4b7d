"""Frequency tracks across sub-patterns: which component continues which, and its phase.

A principal frequency often persists from one 100 ms unit to the next (a resonance of the hand
and pen does). If each sub-pattern drew its own random phases, the crossfade would blend such a
tone with itself at a random phase difference, and its amplitude would dip by up to −∞ dB at the
boundary. So components are linked into tracks across neighbouring sub-patterns (the last to
the first, across the loop wrap), each track keeps its phase continuous, and linked components
are crossfaded in amplitude (linear) while unlinked ones fade in and out with equal power.

A track that runs all the way around the loop must also close on itself: its frequencies are
nudged by at most 1 / (2 × its length) Hz (0.33 Hz for 1500 ms) so that it completes a whole
number of cycles.
"""

from __future__ import annotations

import numpy as np

__all__ = ["link_components", "continuous_phases", "joins"]


def link_components(frequencies: list[np.ndarray], tolerance_hz: float,
                    cyclic: bool = True) -> list[np.ndarray]:
    """Link each component to at most one component of the next sub-pattern.

    Pairs closer than ``tolerance_hz`` are linked one-to-one, nearest first.

    Args:
        frequencies: per sub-pattern, component frequencies in Hz.
        tolerance_hz: largest frequency difference of a link, in Hz.
        cyclic: link the last sub-pattern to the first (the loop wrap).

    Returns:
        Per sub-pattern, for each component the index of its successor in the next sub-pattern
        (or −1).
    """
    count = len(frequencies)
    successors = [np.full(len(f), -1, dtype=int) for f in frequencies]
    for index in range(count if cyclic else count - 1):
        here, there = frequencies[index], frequencies[(index + 1) % count]
        if not len(here) or not len(there):
            continue
        distance = np.abs(here[:, None] - there[None, :])
        taken = np.zeros(len(there), dtype=bool)
        for flat in np.argsort(distance, axis=None):
            i, j = divmod(int(flat), len(there))
            if distance[i, j] > tolerance_hz:
                break
            if successors[index][i] < 0 and not taken[j]:
                successors[index][i] = j
                taken[j] = True
    return successors


def continuous_phases(frequencies: list[np.ndarray], successors: list[np.ndarray],
                      length_s: float, rng: np.random.Generator
                      ) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Phases that keep every track continuous, and frequencies that close looping tracks.

    A track's first component gets a random phase; each successor starts with the phase its
    predecessor reaches at the boundary, φ' = φ + 2π f L. Tracks that loop back on themselves
    are nudged to whole cycles first.

    Args:
        frequencies: per sub-pattern, frequencies in Hz.
        successors: from :func:`link_components`.
        length_s: sub-pattern length L in seconds.
        rng: source of the random phases.

    Returns:
        (phases in radians, frequencies in Hz) per sub-pattern.
    """
    count = len(frequencies)
    freqs = [np.array(f, dtype=np.float64) for f in frequencies]
    phases = [np.zeros(len(f)) for f in frequencies]
    has_predecessor = [np.zeros(len(f), dtype=bool) for f in frequencies]
    for index, links in enumerate(successors):
        for j in links[links >= 0]:
            has_predecessor[(index + 1) % count][j] = True
    done = [np.zeros(len(f), dtype=bool) for f in frequencies]

    def walk(index: int, i: int) -> list[tuple[int, int]]:
        chain = [(index, i)]
        while True:
            k, c = chain[-1]
            nxt = successors[k][c]
            if nxt < 0 or ((k + 1) % count, int(nxt)) == chain[0]:
                return chain
            chain.append(((k + 1) % count, int(nxt)))

    starts = [(k, i) for k in range(count) for i in range(len(freqs[k])) if not has_predecessor[k][i]]
    starts += [(k, i) for k in range(count) for i in range(len(freqs[k])) if has_predecessor[k][i]]
    for k0, i0 in starts:
        if done[k0][i0]:
            continue
        chain = walk(k0, i0)
        last_k, last_i = chain[-1]
        closes = successors[last_k][last_i] >= 0  # a loop: the chain returns to its start
        if closes:
            cycles = sum(freqs[k][i] for k, i in chain) * length_s
            nudge = -(cycles - np.round(cycles)) / (len(chain) * length_s)
            for k, i in chain:
                freqs[k][i] += nudge
        phase = rng.uniform(0.0, 2 * np.pi)
        for k, i in chain:
            phases[k][i] = np.mod(phase, 2 * np.pi)
            done[k][i] = True
            phase += 2 * np.pi * freqs[k][i] * length_s
    return phases, freqs


def joins(successors: list[np.ndarray]) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Per sub-pattern, which components continue from the previous one and into the next."""
    count = len(successors)
    joins_next = [links >= 0 for links in successors]
    joins_previous = [np.zeros(len(links), dtype=bool) for links in successors]
    for index, links in enumerate(successors):
        joins_previous[(index + 1) % count][links[links >= 0]] = True
    return joins_previous, joins_next
