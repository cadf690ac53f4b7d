"""Range checks: the limits RealPen enforces on arguments, and the one set of helpers that
checks them.

Every parameter that sizes an allocation or reaches a formula — a rate, a length in ms, a
level, a seed, a count of components or sub-patterns, a pen's speed or force — is checked here
before anything large is made, and refused with a :class:`~realpen.errors.ParameterError`
naming the Python parameter (the command line names its flag instead). The limits lie far
above what the method uses (10 principal frequencies, 15 units of 100 ms, a 300 ms sound unit)
and low enough that no argument makes one call allocate more than a few hundred MB.

A new check goes here. What a *file* may hold (its size, its JSON nesting, a header's frame
count) is :mod:`realpen.io.limits`, which uses the rate limits below.

May import: :mod:`realpen.errors` and the standard library only, so that the numpy-free
parameter classes and the command line's help can use it. numpy's scalars are numbers too: they
register with :mod:`numbers`.
"""

from __future__ import annotations

import math
import numbers

from realpen.errors import ParameterError

__all__ = [
    # rates and lengths of signals
    "MIN_RATE_HZ", "MAX_RATE_HZ", "MIN_SOUND_RATE_HZ", "MAX_MS", "MAX_LEVEL_DBFS",
    # the analysis and the tactile pattern
    "MAX_TOP", "MAX_COMPONENTS", "MAX_SUBPATTERNS", "MAX_UNIT_MS", "MAX_UNITS",
    "MAX_UNIT_SAMPLES", "MIN_UNIT_SAMPLES", "MAX_SEED", "MAX_CAP_DB", "MAX_PATTERN_FRAMES",
    # residual, grid, strokes
    "MAX_BANDS", "MAX_LEVELS", "MAX_GRID_POINTS", "MAX_SPEED_MM_S", "MAX_FORCE_N",
    "MAX_RENDER_FRAMES", "MAX_DURATION_S",
    # helpers
    "is_number", "shown_value", "rate_text", "count_text", "require_number", "require_choice",
    "require_rate", "check_ms", "check_level", "sound_rate_problem", "check_sound_rate",
    "check_pattern_rate", "check_frames", "check_seed", "check_magnitude", "check_number_list",
]

# --- rates and lengths of signals ------------------------------------------------------------

MIN_RATE_HZ = 100
"""The lowest sampling rate (Hz) of a signal read or written: an accelerometer for a pen runs at
1 kHz or more; a header that says 1 Hz is damaged."""
MAX_RATE_HZ = 384_000
"""The highest sampling rate (Hz) of a signal read, analysed or written: audio's highest common
rate (the tactile, sound and export writers use this same number)."""
MIN_SOUND_RATE_HZ = 8000.0
"""The lowest rate (Hz) of a friction sound: below it the 100 Hz – 0.45 × rate bands of the
seam measures collapse."""
MAX_MS = 60000.0
"""The longest length (ms) a loop unit, crossfade, grain or texture may have: a minute. Every
length is checked against it (:func:`check_ms`) before any array is sized by it."""
MAX_LEVEL_DBFS = 0.0
"""The highest loop level (RMS, dBFS) accepted."""

# --- the analysis and the tactile pattern ----------------------------------------------------

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
MAX_PATTERN_FRAMES = 2**24
"""The most samples in one loop of a tactile pattern (16 777 216: 35 min at 8 kHz, 44 s at
384 kHz; 128 MiB as float64). The method's loop is 1.5 s, 12 000 samples at 8 kHz."""

# --- residual, grid, strokes -------------------------------------------------------------------

MAX_BANDS = 256
"""The most bands of a residual (twelfth-octave bands from 30 Hz to 192 kHz are 152)."""
MAX_LEVELS = 65_536
"""The most levels (sub-patterns × bands) of a residual, so a profile's JSON stays within
:data:`realpen.io.limits.MAX_JSON_VALUES` beside the most components a pattern may have
(:data:`MAX_COMPONENTS`); the method's pattern has 15 × 38."""
MAX_GRID_POINTS = 64
"""The most points a vibration grid holds (a HaTT texture has at most 41 vertices)."""
MAX_SPEED_MM_S = 10_000.0
"""The highest pen speed (mm/s) of a grid point: 10 m/s, no hand moves a pen faster."""
MAX_FORCE_N = 1_000.0
"""The highest normal force (N) of a grid point: 100 kgf, no pen is pressed harder."""
MAX_RENDER_FRAMES = 2**25
"""The most samples a rendered stroke may have (33 554 432: 11.6 min at 48 kHz, 87 s at
384 kHz). The render holds about eight arrays of that length (268 MB each as float64), so it
is checked before any of them is made."""
MAX_DURATION_S = 600.0
"""The longest trajectory (s): a longer one usually had ``t`` given in ms."""


# --- helpers -------------------------------------------------------------------------------------

def is_number(value: object) -> bool:
    """A real number: an int, a float, or a numpy integer or floating scalar; never a bool.

    >>> is_number(3), is_number(2.5), is_number(True), is_number("3")
    (True, True, False, False)
    """
    if isinstance(value, bool):
        return False
    if isinstance(value, (int, float)):
        return True
    return isinstance(value, numbers.Real) and type(value).__module__ == "numpy"


def shown_value(value: object) -> str:
    """A value for a message: floats as ``:g``, integers exactly; an integer of more than 30
    digits (too large for a float, or for ``str`` past 4300 digits) by its size; anything else
    by its ``repr``, cut to 60 characters.

    >>> shown_value(0.5), shown_value(10**40), shown_value("x")
    ('0.5', 'an integer of about 41 digits', "'x'")
    """
    if isinstance(value, int) and not isinstance(value, bool):
        if abs(value) < 10**30:
            return str(value)
        digits = math.floor(value.bit_length() * math.log10(2)) + 1
        return f"an integer of about {digits} digits"
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        return f"{value:g}"
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def rate_text(rate: float) -> str:
    """A rate for a message, in Hz; an integer too large for a float is not converted.

    >>> rate_text(44100), rate_text(10**20)
    ('44,100', 'over 1e+15')
    """
    if isinstance(rate, numbers.Integral) and abs(rate) >= 10**15:
        return "over 1e+15" if rate > 0 else "below -1e+15"
    return f"{rate:,.10g}"


def count_text(count: int) -> str:
    """A count from a header for a message: a forged one may have thousands of digits.

    >>> count_text(1234), count_text(10**400)
    ('1,234', 'over 10^15')
    """
    return f"{count:,}" if count < 10**15 else "over 10^15"


def require_number(parameter: str, value: float, minimum: float | None = None,
                   maximum: float | None = None, inclusive: bool = True) -> None:
    """Raise a :class:`ParameterError` unless ``value`` is a finite number within bounds.

    ``minimum`` is inclusive unless ``inclusive`` is false; ``maximum`` is always inclusive.
    Booleans are refused (``True`` is not a count).

    >>> require_number("top", 0, minimum=1)
    Traceback (most recent call last):
    ...
    realpen.errors.ParameterError: top: must be >= 1, got 0
    """
    if isinstance(value, bool) or not isinstance(value, (int, float)) or \
            (isinstance(value, float) and not math.isfinite(value)):
        raise ParameterError(parameter, f"must be a finite number, got {shown_value(value)}")
    if minimum is not None and (value < minimum or (not inclusive and value == minimum)):
        relation = ">=" if inclusive else ">"
        raise ParameterError(parameter, f"must be {relation} {minimum:g}, got {shown_value(value)}")
    if maximum is not None and value > maximum:
        raise ParameterError(parameter, f"must be <= {maximum:g}, got {shown_value(value)}")


def require_choice(parameter: str, value: object, choices: tuple[str, ...]) -> None:
    """Raise a :class:`ParameterError` unless ``value`` is one of ``choices``.

    >>> require_choice("mode", "loop", ("loop", "granular"))
    """
    if value not in choices:
        raise ParameterError(parameter, f"unknown value {value!r} (choose from {', '.join(choices)})")


def require_rate(parameter: str, rate: float) -> None:
    """Raise a :class:`~realpen.errors.ParameterError` unless ``rate`` (Hz) is a number between
    :data:`MIN_RATE_HZ` and :data:`MAX_RATE_HZ`.

    >>> require_rate("rate", 1)
    Traceback (most recent call last):
    ...
    realpen.errors.ParameterError: rate: must be between 100 and 384,000 Hz, got 1
    """
    if isinstance(rate, numbers.Integral) and not isinstance(rate, bool) and abs(rate) > MAX_RATE_HZ:
        # Before require_number, which converts to float: 10**400 would overflow.
        raise ParameterError(parameter, f"must be between {MIN_RATE_HZ:,} and {MAX_RATE_HZ:,} Hz, "
                                        f"got {rate_text(rate)}")
    # Not a positive number at all keeps require_number's wording ("must be > 0, got -5").
    require_number(parameter, rate, minimum=0.0, inclusive=False)
    if not MIN_RATE_HZ <= rate <= MAX_RATE_HZ:
        raise ParameterError(parameter, f"must be between {MIN_RATE_HZ:,} and {MAX_RATE_HZ:,} Hz, "
                                        f"got {rate_text(rate)}")


def check_ms(parameter: str, value: float, maximum: float | None = MAX_MS) -> float:
    """Return ``value`` (a length in ms) as float.

    Args:
        parameter: the Python parameter that gave it, e.g. ``"unit_ms"``, for the message.
        value: the length in ms.
        maximum: the longest length accepted in ms (default :data:`MAX_MS`; None: no limit,
            for lengths computed from checked ones).

    Raises:
        ParameterError: ``value`` is not a finite number of ms above 0, or above ``maximum``.

    >>> check_ms("unit_ms", 0)
    Traceback (most recent call last):
    ...
    realpen.errors.ParameterError: unit_ms: must be a finite number of ms above 0, got 0
    """
    if not is_number(value) or not math.isfinite(value) or value <= 0:
        shown = f"{value:g}" if is_number(value) else repr(value)
        raise ParameterError(parameter, f"must be a finite number of ms above 0, got {shown}")
    if maximum is not None and value > maximum:
        raise ParameterError(parameter, f"must be at most {maximum:g} ms "
                                        f"({maximum / 1000:g} s), got {value:g}")
    return float(value)


def check_level(level_dbfs: float, parameter: str = "level_dbfs") -> float:
    """Return a loop level (RMS in dB re full scale, dBFS) as float; finite, ≤
    :data:`MAX_LEVEL_DBFS`.

    Raises:
        ParameterError: not a finite level of at most 0 dBFS.
    """
    if not is_number(level_dbfs) or not math.isfinite(level_dbfs) or level_dbfs > MAX_LEVEL_DBFS:
        shown = f"{level_dbfs:g}" if is_number(level_dbfs) else repr(level_dbfs)
        raise ParameterError(parameter, f"must be a finite level of at most {MAX_LEVEL_DBFS:g} "
                                        f"dBFS, got {shown}")
    return float(level_dbfs)


def sound_rate_problem(rate: object) -> str | None:
    """What is wrong with the sample rate (Hz) of a friction sound, or None: it must lie from
    :data:`MIN_SOUND_RATE_HZ` to :data:`MAX_RATE_HZ`."""
    if not is_number(rate) or not math.isfinite(rate) or rate <= 0:
        shown = f"{rate:g}" if is_number(rate) else repr(rate)
        return f"must be a positive number of Hz, got {shown}"
    if rate < MIN_SOUND_RATE_HZ:
        return (f"{rate:g} Hz is too low for friction sound; the minimum is "
                f"{MIN_SOUND_RATE_HZ:g} Hz (the seam is judged on bands from 100 Hz up to "
                f"0.45 × rate)")
    if rate > MAX_RATE_HZ:
        return f"{rate:g} Hz is too high; the maximum is {float(MAX_RATE_HZ):g} Hz"
    return None


def check_sound_rate(rate: float, parameter: str = "rate") -> float:
    """Return the sample rate of a friction sound in Hz as float, from
    :data:`MIN_SOUND_RATE_HZ` to :data:`MAX_RATE_HZ`.

    Raises:
        ParameterError: a rate that is not finite, or outside 8 kHz – 384 kHz.
    """
    problem = sound_rate_problem(rate)
    if problem is not None:
        raise ParameterError(parameter, problem)
    return float(rate)


def check_pattern_rate(rate: float) -> int:
    """The rate of a tactile pattern as a whole number of Hz, from :data:`MIN_RATE_HZ` to
    :data:`MAX_RATE_HZ`.

    Raises:
        ParameterError: (parameter ``rate``) otherwise.
    """
    require_number("rate", rate, minimum=MIN_RATE_HZ, maximum=MAX_RATE_HZ)
    if int(rate) != rate:
        raise ParameterError("rate", f"must be a whole number of Hz, got {rate:g}")
    return int(rate)


def check_frames(count: int, rate: float, subpattern_ms: float, parameter: str = "rate") -> int:
    """Samples in a loop of ``count`` sub-patterns of ``subpattern_ms`` ms at ``rate`` Hz
    (each rounded to whole samples), checked against :data:`MAX_PATTERN_FRAMES` before
    anything is synthesised.

    Args:
        parameter: the parameter to name when the loop is too long.

    Raises:
        ParameterError: (named ``parameter``) a loop longer than :data:`MAX_PATTERN_FRAMES`.
    """
    frames = int(round(subpattern_ms * rate / 1000.0)) * count
    if frames > MAX_PATTERN_FRAMES:
        raise ParameterError(parameter, f"{count} sub-pattern(s) of {subpattern_ms:g} ms at "
                                        f"{rate:g} Hz make a loop of {frames:,} samples; a "
                                        f"pattern holds at most {MAX_PATTERN_FRAMES:,} (fewer "
                                        f"or shorter sub-patterns, or a lower rate)")
    return frames


def check_seed(seed: int) -> int:
    """``seed`` (of random phases or grain offsets) as an int from 0 to :data:`MAX_SEED`.

    Raises:
        ParameterError: (parameter ``seed``) otherwise.
    """
    if isinstance(seed, bool) or not isinstance(seed, numbers.Integral) \
            or not 0 <= seed <= MAX_SEED:
        raise ParameterError("seed", f"must be a whole number from 0 to {MAX_SEED}, got {seed!r}")
    return int(seed)


def check_magnitude(parameter: str, value: object, maximum: float) -> float:
    """``value`` as a float: a finite number from 0 to ``maximum`` (a speed, a force).

    >>> check_magnitude("force_n", -1, 1000.0)
    Traceback (most recent call last):
    ...
    realpen.errors.ParameterError: force_n: must be a finite number from 0 to 1000, got -1
    """
    if not is_number(value):
        raise ParameterError(parameter, f"must be a number, got {type(value).__name__}")
    value = float(value)
    if not math.isfinite(value) or not 0.0 <= value <= maximum:
        raise ParameterError(parameter, f"must be a finite number from 0 to {maximum:g}, "
                                        f"got {value:g}")
    return value


def check_number_list(parameter: str, value: object, maximum: int | None = None) -> list:
    """``value`` as a list: a sequence (not a string or a mapping) of at most ``maximum``
    numbers (None: the length is not checked here, nor are the items).

    Raises:
        ParameterError: not a sequence, too long, or an item that is not a number.
    """
    if isinstance(value, (str, bytes, dict)) or not hasattr(value, "__len__"):
        raise ParameterError(parameter, f"must be a list of numbers, got {type(value).__name__}")
    items = list(value)
    if maximum is None:
        return items
    if len(items) > maximum:
        raise ParameterError(parameter, f"holds {len(items):,} values; at most {maximum:,}")
    for item in items:
        if not is_number(item):
            raise ParameterError(parameter, f"must hold numbers only, got {type(item).__name__}")
    return items
