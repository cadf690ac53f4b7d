"""The limits of the analysis and synthesis parameters that size an allocation.

The analysis (:mod:`realpen.dsp.spectrum`), the tactile parameters
(:class:`realpen.tactile.conditions.TactileParams`), the tactile pattern
(:class:`realpen.tactile.pattern.TactilePattern`) and the granular sound check their arguments
against these before anything large is allocated, and refuse what exceeds them with a
:class:`~realpen.errors.ParameterError` naming the parameter (the command line names its flag).
They lie far above what the method uses (10 principal frequencies, 15 units of 100 ms) and low
enough that no argument makes one call allocate more than a few hundred MB.

The limits of what is *read* (rates, frames, file sizes) are :mod:`realpen.io.limits`.

Standard library only: the numpy-free parameter classes import it.
"""

from __future__ import annotations

__all__ = ["MAX_COMPONENTS", "MAX_TOP", "MAX_SUBPATTERNS", "MAX_UNIT_MS", "MAX_UNITS", "MAX_UNIT_SAMPLES",
           "MIN_UNIT_SAMPLES", "MAX_SEED", "MAX_CAP_DB"]

MAX_TOP = 100
"""The most principal frequencies per unit (``top``, N) and so the most components of one
sub-pattern: the method uses 5–15. The analysis holds ``units × top`` of them."""

MAX_COMPONENTS = 50_000
"""The most components of one pattern in all (its sub-patterns' together): a profile's JSON
must stay within :data:`realpen.io.limits.MAX_JSON_VALUES`; the method's pattern has 150."""

MAX_SUBPATTERNS = 1000
"""The most consecutive units selected (``count``) and sub-patterns of a pattern (K): the
method uses 15."""

MAX_UNIT_MS = 60_000.0
"""The longest unit sequence and sub-pattern (ms): one minute; the method's are 100 and
1500 ms."""

MAX_UNITS = 2**21
"""The most unit sequences one analysis splits a signal into (2 097 152: over 58 h of 100 ms
units, more than any recording RealPen reads holds at the default unit). Each holds ``top``
frequencies and powers and 24 band levels: at most a few GB at ``top`` = 100."""

MAX_UNIT_SAMPLES = 2**20
"""The most samples in one unit sequence (1 048 576: 13 min at 1.344 kHz, 2.6 s at 400 kHz).
Its spectrum is zero-padded to 8 times that (an FFT of 2²³ points, 134 MB as complex)."""

MIN_UNIT_SAMPLES = 8
"""The fewest samples in one unit sequence: fewer leave no spectrum to find peaks in."""

MAX_SEED = 2**63 - 1
"""The largest seed of the random phases and grain offsets: it fits the 64-bit integers of
JSON readers and SQLite, so a profile that records its seed can be read back."""

MAX_CAP_DB = 60.0
"""The highest cap of the actuator weighting (dB): a 1000-fold boost of the weakest-responding
component; the default is 20 dB."""
