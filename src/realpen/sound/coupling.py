"""Eq. 1 of the method, under the name the documentation has always given it.

The coupling drives the tactile loop as well as the sound, so it lives below both, in
:mod:`realpen.motion.coupling`; this module re-exports it for code that imports it from here.
"""

from realpen.motion.coupling import (
    FIXABLE,
    FORMAT,
    MAX_SMOOTHING_MS,
    REPRODUCE_TOLERANCE,
    Coupling,
    CouplingFit,
    fit_coupling,
    load_measurements,
    one_pole,
)

__all__ = ["Coupling", "CouplingFit", "one_pole", "fit_coupling", "load_measurements", "FORMAT",
           "FIXABLE", "REPRODUCE_TOLERANCE", "MAX_SMOOTHING_MS"]
