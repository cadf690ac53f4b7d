"""The names and limits of a design file: its format, the modalities, orders, phases and caps.

May import: the standard library only.
"""

from __future__ import annotations

__all__ = ["FORMAT", "MODALITIES", "INKS", "PHASES", "ORDERS", "QUESTION_TYPES", "DEMOGRAPHICS",
           "ID_PATTERN", "LEVEL", "MAX_DESIGN_BYTES", "MAX_DESIGN_VALUES", "MAX_ANSWER_CHARS",
           "MAX_TRIALS", "MAX_PERMUTATION_LEVELS"]

FORMAT = "realpen.study-design/1"
MODALITIES = ("tactile", "auditory", "audio-tactile", "none")
INKS = ("visible", "hidden")
PHASES = ("training", "experimental", "questionnaire")  # = realpen.study.tables.PHASES
ORDERS = ("williams", "permutations", "fixed", "random")
QUESTION_TYPES = ("likert", "choice", "text")
DEMOGRAPHICS = ("age", "gender", "handedness")
ID_PATTERN = r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,63}$"  # the profile names' rule
LEVEL = "{level}"
"""What a block's label says for the level it repeats over."""

MAX_DESIGN_BYTES = 1024 * 1024
"""The largest design file read (bytes): the built-in designs are about 4 kB."""
MAX_DESIGN_VALUES = 100_000
"""The most values (mappings, lists, scalars) a design file may hold once YAML aliases are
expanded: a YAML "billion laughs" document is refused before it is validated."""
MAX_ANSWER_CHARS = 2000
"""The longest free-text answer (characters)."""
MAX_TRIALS = 5000
"""The most trials a design may plan for one participant (study 2 plans 93)."""
MAX_PERMUTATION_LEVELS = 8
"""The most levels counterbalanced by all permutations (8! = 40,320 sequences)."""
