"""Plans: counterbalanced orders and each participant's trials, and how well N participants
balance a design.

- :func:`williams` — the balanced Latin square of Williams (1949);
- :func:`participant_plan` — the ordered trials of participant ``index`` (0-based),
  deterministic from the design, the index and the seed;
- :func:`balance` — position and ordered adjacent-pair counts of the levels over N
  participants, whether they are balanced, and warnings when N cannot balance the design;
- :func:`plan_lines`, :func:`write_plan_csv` — what ``realpen study plan`` prints and writes.

Orders. A block over conditions or modalities orders its levels per participant:
``williams`` uses row ``index % rows`` of the Williams design of its levels (n rows for even n,
2n for odd n: the square and its mirror), ``permutations`` row ``index % n!`` of all
permutations in lexicographic order of the listed levels, ``fixed`` the listed order,
``random`` a shuffle per participant, and ``same_order_as`` the order its leader block got.

Randomisation. Every shuffle draws from its own ``numpy.random.Generator`` (PCG64) seeded by
``SeedSequence([seed, index, purpose, block, level, group])`` — block, level and group by their
position in the design (the level by its position in the block's listed levels, not in the
participant's order) — so a participant's trials depend on nothing else: not on the other
participants, nor on where a level falls in the order. ``Generator.permutation`` on PCG64 gives
the same result on every platform and numpy release that keeps NumPy's stream-compatibility
policy; a test pins one plan's exact shuffle.

Block labels. A trial's ``block`` is its block's label: the level's id for a block over
conditions or modalities (study 1: ``"B"``; study 2 part 1: ``"tactile"``), the label template
with ``{level}`` replaced (study 2 part 2: ``"tactile/questionnaire"``), or the block's id for a
block over none (study 1's ``"comments"``). For such a block ``condition`` is ``""``.

Imports numpy (and the design module: pydantic, PyYAML).

References:
    Williams, E. J. (1949). Experimental designs balanced for the estimation of residual
    effects of treatments. Australian Journal of Scientific Research, Series A, 2(2), 149–168.
    https://doi.org/10.1071/CH9490149
"""

from __future__ import annotations

import csv
import itertools
import json
import os
from collections.abc import Iterator
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from realpen.checks import require_number
from realpen.errors import ParameterError
from realpen.study.design import Block, Design

__all__ = ["williams", "sequences", "PlannedTrial", "participant_plan", "block_orders",
           "BlockBalance", "Balance", "balance", "plan_lines", "plan_rows", "write_plan_csv",
           "CSV_COLUMNS", "MAX_PARTICIPANTS", "MAX_INDEX", "MAX_WILLIAMS"]

MAX_PARTICIPANTS = 1000
"""The most participants :func:`balance`, :func:`plan_lines` and :func:`write_plan_csv` cover
(far beyond a within-subject lab study; study 2's plans for that many are 93,000 trials, a
few seconds)."""
MAX_INDEX = 2**31 - 1
"""The largest plan index :func:`participant_plan` takes (a store numbers its sessions)."""
MAX_WILLIAMS = 1000
"""The largest n of :func:`williams`."""
CSV_COLUMNS = ("participant", "n", "block", "block_index", "phase", "condition", "modality",
               "pen", "ink", "repetition", "questions", "task", "tactile")

_ORDER, _TRIALS = 0, 1  # the purposes of a randomisation, part of its seed


def williams(n: int) -> list[list[int]]:
    """The Williams design for ``n`` treatments: rows of 0..n-1.

    Each row is a sequence of all n treatments. For even n the n rows form a Latin square in
    which every treatment follows every other exactly once; for odd n the square and its mirror
    (2n rows) have every treatment in every position twice and every ordered adjacent pair
    exactly twice. ``n = 1`` gives the one row ``[0]``.

    Built from the first row 0, 1, n−1, 2, n−2, … by adding r (mod n) for row r.

    >>> williams(4)
    [[0, 1, 3, 2], [1, 2, 0, 3], [2, 3, 1, 0], [3, 0, 2, 1]]
    >>> len(williams(3))
    6

    Raises:
        ParameterError: ``n`` is not a whole number 1..:data:`MAX_WILLIAMS`.
    """
    if isinstance(n, bool) or not isinstance(n, int):
        raise ParameterError("n", f"must be a whole number, got {n!r}")
    require_number("n", n, minimum=1, maximum=MAX_WILLIAMS)
    first, low, high = [0], 1, n - 1
    while len(first) < n:
        first.append(low)
        low += 1
        if len(first) < n:
            first.append(high)
            high -= 1
    square = [[(item + row) % n for item in first] for row in range(n)]
    if n % 2 == 0 or n == 1:
        return square
    return square + [row[::-1] for row in square]


def sequences(design: Design, block: Block) -> list[list[str]] | None:
    """The sequences of ``block``'s levels that participants cycle through (row
    ``index % len``), or None when each participant's order is drawn at random (``random``)
    or taken from another block (``same_order_as``). A block over none has ``[[]]``."""
    levels = design.block_levels(block)
    order = design.block_order(block)
    if order in ("random", "same"):
        return None
    if order == "williams" and levels:
        return [[levels[i] for i in row] for row in williams(len(levels))]
    if order == "permutations":
        return [list(row) for row in itertools.permutations(levels)]
    return [levels]


@dataclass(frozen=True)
class PlannedTrial:
    """One trial of a participant's plan.

    Attributes:
        n: the trial's number in the session, from 1.
        block: the block's label (see the module doc: ``"B"``, ``"tactile"``,
            ``"tactile/questionnaire"``, ``"comments"``).
        block_index: the block's position in this participant's session, from 0.
        phase: ``training``, ``experimental`` or ``questionnaire``.
        condition: the level: a condition id, or for a block over modalities the modality;
            ``""`` in a block over none.
        modality: ``tactile``, ``auditory``, ``audio-tactile`` or ``none``.
        pen: the pen's id in the design.
        ink: ``visible`` or ``hidden``.
        repetition: the trial's repetition of its pen within its trial group, from 1.
        task: what the participant is asked to do.
        questions: the question ids asked, in order.
        tactile: :class:`~realpen.tactile.conditions.TactileParams` keywords of the pattern to
            build from the pen's source (``{"condition": "B"}``), or None: the pen profile's
            own pattern.
        writing: whether the participant writes (False: the questions only).
        feedback: whether the right answer is shown after the participant's.
    """

    n: int
    block: str
    block_index: int
    phase: str
    condition: str
    modality: str
    pen: str
    ink: str
    repetition: int
    task: str
    questions: tuple[str, ...]
    tactile: dict | None = None
    writing: bool = True
    feedback: bool = False

    def to_json(self) -> dict:
        """Every field, JSON-ready (``questions`` as a list)."""
        data = asdict(self)
        data["questions"] = list(self.questions)
        data["tactile"] = dict(self.tactile) if self.tactile is not None else None
        return data


def _check_seed(seed: int) -> int:
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)):
        raise ParameterError("seed", f"must be a whole number, got {seed!r}")
    require_number("seed", int(seed), minimum=0, maximum=2**63 - 1)
    return int(seed)


def _check_index(index: int) -> int:
    if isinstance(index, bool) or not isinstance(index, (int, np.integer)):
        raise ParameterError("index", f"must be a whole number, got {index!r}")
    require_number("index", int(index), minimum=0, maximum=MAX_INDEX)
    return int(index)


def _generator(*key: int) -> np.random.Generator:
    return np.random.Generator(np.random.PCG64(np.random.SeedSequence(list(key))))


def block_orders(design: Design, index: int, seed: int | None = None
                 ) -> list[tuple[Block, list[str] | None]]:
    """Participant ``index``'s order of the levels of each block, in the design's block order:
    ``(block, levels)`` with ``levels`` None for a block over none.

    Raises:
        ParameterError: ``index`` or ``seed`` out of range (``index`` 0..:data:`MAX_INDEX`,
            ``seed`` 0..2⁶³−1).
    """
    index = _check_index(index)
    seed = _check_seed(design.seed if seed is None else seed)
    chosen: dict[str, list[str]] = {}
    orders: list[tuple[Block, list[str] | None]] = []
    for position, block in enumerate(design.blocks):
        if block.over == "none":
            orders.append((block, None))
            continue
        rows = sequences(design, block)
        levels = design.block_levels(block)
        if block.same_order_as is not None:
            order = list(chosen[block.same_order_as])
        elif rows is None:  # random
            permutation = _generator(seed, index, _ORDER, position).permutation(len(levels))
            order = [levels[i] for i in permutation]
        else:
            order = list(rows[index % len(rows)])
        chosen[block.id] = order
        orders.append((block, order))
    return orders


def participant_plan(design: Design, index: int, seed: int | None = None) -> list[PlannedTrial]:
    """The trials of participant ``index`` (0-based), in order.

    Deterministic: the same design, index and seed give the same plan on every machine.

    Args:
        design: the study design.
        index: the participant's plan index, 0-based (the counterbalancing row is
            ``index % rows``).
        seed: seed of the randomisation (default: the design's ``seed``), 0..2⁶³−1.

    >>> from realpen.study.design import load_design
    >>> plan = participant_plan(load_design("study1"), 0)
    >>> [trial.block for trial in plan]
    ['A', 'B', 'F', 'C', 'E', 'D', 'comments']

    Raises:
        ParameterError: ``index`` or ``seed`` out of range.
    """
    seed = _check_seed(design.seed if seed is None else seed)
    trials: list[PlannedTrial] = []
    block_index = 0
    for position, (block, order) in enumerate(block_orders(design, index, seed)):
        listed = design.block_levels(block)
        for level in order if order is not None else [None]:
            label = block.label_for(level)
            for g, group in enumerate(block.trials):
                pens = design.group_pens(block, level, group)
                settings = {pen: design.settings(block, level, group, pen) for pen in pens}
                asked = {pen: design.trial_questions(group, settings[pen].modality)
                         for pen in pens}
                units = [(pen, repetition) for pen in pens
                         for repetition in range(1, group.repetitions + 1)]
                if group.randomise and len(units) > 1:
                    level_key = listed.index(level) if level is not None else 0
                    shuffle = _generator(seed, index, _TRIALS, position, level_key, g)
                    units = [units[i] for i in shuffle.permutation(len(units))]
                for pen, repetition in units:
                    trial = settings[pen]
                    trials.append(PlannedTrial(
                        n=len(trials) + 1, block=label, block_index=block_index,
                        phase=group.phase, condition=level or "", modality=trial.modality,
                        pen=trial.pen, ink=trial.ink, repetition=repetition, task=group.task,
                        questions=asked[pen], tactile=trial.tactile, writing=group.writing,
                        feedback=group.feedback))
            block_index += 1
    return trials


# ---- balance ----------------------------------------------------------------------------------

@dataclass(frozen=True)
class BlockBalance:
    """How one counterbalanced block's levels fall over the participants.

    Attributes:
        block: the block's id.
        over: ``conditions`` or ``modalities``.
        order: ``williams``, ``permutations``, ``fixed`` or ``random``.
        levels: the levels, as listed.
        rows: how many sequences participants cycle through (None: random).
        positions: level → how many participants have it at position 1, 2, …
        pairs: (first, next) → how many times ``next`` directly follows ``first``, for every
            ordered pair of distinct levels.
        balanced: every level in every position equally often, and every ordered adjacent
            pair equally often.
        followers: the blocks that take this block's order (``same_order_as``).
    """

    block: str
    over: str
    order: str
    levels: tuple[str, ...]
    rows: int | None
    positions: dict[str, tuple[int, ...]]
    pairs: dict[tuple[str, str], int]
    balanced: bool
    followers: tuple[str, ...] = ()

    def to_json(self) -> dict:
        """JSON-ready: ``pairs`` as ``{"first>next": count}``."""
        data = asdict(self)
        data["positions"] = {level: list(counts) for level, counts in self.positions.items()}
        data["pairs"] = {f"{first}>{second}": count for (first, second), count in
                         self.pairs.items()}
        data["levels"], data["followers"] = list(self.levels), list(self.followers)
        return data


@dataclass(frozen=True)
class Balance:
    """The balance of a design over ``participants`` participants (see :func:`balance`).

    Attributes:
        participants: how many.
        blocks: one per block with its own order over two or more levels.
        balanced: every one of them is balanced (True when there is none).
        warnings: what N cannot balance, in one line each.
    """

    participants: int
    blocks: tuple[BlockBalance, ...]
    balanced: bool
    warnings: list[str] = field(default_factory=list)

    def lines(self) -> list[str]:
        """The balance as ``realpen study plan`` prints it: per block a table of position
        counts (rows: levels, columns: positions) and one of ordered adjacent-pair counts
        (rows: the first level, columns: the next), then ``balanced: yes|no``."""
        out = [f"balance over {self.participants} participants"]
        for item in self.blocks:
            rows = "random orders" if item.rows is None else \
                f"{item.rows} sequence{'s' if item.rows != 1 else ''}"
            out.append(f"block {item.block}: {item.order} over {len(item.levels)} {item.over} "
                       f"({rows})" + (f"; followed by {', '.join(item.followers)}"
                                      if item.followers else ""))
            width = max(len("position"), *(len(level) for level in item.levels))
            cell = max(3, len(str(self.participants)) + 1,
                       *(len(level) + 1 for level in item.levels))
            out.append(f"  {'position':<{width}}" +
                       "".join(f"{p:>{cell}}" for p in range(1, len(item.levels) + 1)))
            for level in item.levels:
                out.append(f"  {level:<{width}}" +
                           "".join(f"{count:>{cell}}" for count in item.positions[level]))
            out.append("  adjacent pairs (row: first, column: next)")
            out.append(f"  {'':<{width}}" + "".join(f"{level:>{cell}}" for level in item.levels))
            for first in item.levels:
                out.append(f"  {first:<{width}}" + "".join(
                    f"{'-' if first == second else item.pairs[first, second]:>{cell}}"
                    for second in item.levels))
            out.append(f"  balanced: {'yes' if item.balanced else 'no'}")
        if not self.blocks:
            out.append("no block orders levels: nothing to counterbalance")
        out.append(f"balanced: {'yes' if self.balanced else 'no'}")
        return out

    def to_json(self) -> dict:
        """JSON-ready."""
        return {"participants": self.participants, "balanced": self.balanced,
                "warnings": list(self.warnings), "blocks": [b.to_json() for b in self.blocks]}


def _check_participants(participants: int) -> int:
    if isinstance(participants, bool) or not isinstance(participants, (int, np.integer)):
        raise ParameterError("participants", f"must be a whole number, got {participants!r}")
    require_number("participants", int(participants), minimum=1, maximum=MAX_PARTICIPANTS)
    return int(participants)


def balance(design: Design, participants: int, seed: int | None = None) -> Balance:
    """How evenly ``participants`` participants (plan indices 0..N−1) balance the design's
    block orders.

    For each block that orders two or more levels itself (not ``same_order_as``): how often
    each level comes at each position and how often each level directly follows each other;
    balanced when all position counts are equal and all ordered-pair counts are equal.

    >>> from realpen.study.design import load_design
    >>> balance(load_design("study1"), 10).warnings
    ['10 participants cannot balance 6 conditions: use a multiple of 6']

    Args:
        design: the study design.
        participants: how many participants, 1..:data:`MAX_PARTICIPANTS`.
        seed: the plans' seed (default the design's; matters for ``random`` orders only).

    Raises:
        ParameterError: ``participants`` or ``seed`` out of range.
    """
    participants = _check_participants(participants)
    orders = [block_orders(design, index, seed) for index in range(participants)]
    own = [(position, block) for position, block in enumerate(design.blocks)
           if block.over != "none" and block.same_order_as is None
           and len(design.block_levels(block)) > 1]
    results: list[BlockBalance] = []
    warnings: list[str] = []
    for position, block in own:
        levels = tuple(design.block_levels(block))
        positions = {level: [0] * len(levels) for level in levels}
        pairs = {(a, b): 0 for a in levels for b in levels if a != b}
        for participant in orders:
            order = participant[position][1] or []
            for place, level in enumerate(order):
                positions[level][place] += 1
            for first, second in zip(order, order[1:]):
                pairs[first, second] += 1
        balanced = len({c for counts in positions.values() for c in counts}) == 1 and \
            len(set(pairs.values())) == 1
        rows = sequences(design, block)
        kind = design.block_order(block)
        followers = tuple(other.id for other in design.blocks if other.same_order_as == block.id)
        results.append(BlockBalance(block.id, block.over, kind, levels,
                                    None if rows is None else len(rows),
                                    {level: tuple(counts) for level, counts in positions.items()},
                                    pairs, balanced, followers))
        if balanced:
            continue
        where = f" (block {block.id})" if len(own) > 1 else ""
        if kind in ("williams", "permutations"):
            warnings.append(f"{participants} participants cannot balance {len(levels)} "
                            f"{block.over}: use a multiple of {len(rows)}{where}")
        elif kind == "fixed":
            warnings.append(f"block {block.id}: its {len(levels)} {block.over} come in one "
                            f"fixed order for everyone (not counterbalanced)")
        else:
            warnings.append(f"block {block.id}: random orders balance {len(levels)} "
                            f"{block.over} only on average; use williams or permutations")
    return Balance(participants, tuple(results), all(item.balanced for item in results),
                   warnings)


# ---- what the command line prints and writes --------------------------------------------------

def _pen_codes(pens: list[str]) -> dict[str, str]:
    """The shortest unique prefix of each pen id (``p``, ``b``, ``m``)."""
    codes = {}
    for pen in pens:
        for size in range(1, len(pen) + 1):
            prefix = pen[:size]
            if sum(other.startswith(prefix) for other in pens) == 1 or size == len(pen):
                codes[pen] = prefix
                break
    return codes


def plan_lines(design: Design, participants: int, *, seed: int | None = None,
               every_trial: bool = False) -> list[str]:
    """Each participant's plan as ``realpen study plan`` prints it.

    Per participant one line with the order of its blocks, then one line per run of trials of
    one trial group (trial numbers, block, phase, the pens in order — abbreviated when they
    vary — and the questions); with ``every_trial`` one line per trial instead.

    Raises:
        ParameterError: ``participants`` or ``seed`` out of range.
    """
    participants = _check_participants(participants)
    seed = _check_seed(design.seed if seed is None else seed)
    codes = _pen_codes([pen.id for pen in design.pens])
    # Every participant has the same blocks and trial count: only their order differs.
    first = participant_plan(design, 0, seed)
    out = [f"{design.name}: {design.title}",
           f"{participants} participant{'s' if participants != 1 else ''} (the design "
           f"recommends {design.participants}), seed {seed}, {len(first)} trials each"]
    if len(codes) > 1 and not every_trial:
        out.append("pens: " + ", ".join(f"{code} = {pen}" for pen, code in codes.items()))
    width = max((len(trial.block) for trial in first), default=5)
    for index in range(participants):
        plan = first if index == 0 else participant_plan(design, index, seed)
        blocks = list(dict.fromkeys(trial.block for trial in plan))
        out.append("")
        out.append(f"participant {index + 1} (index {index}): {', '.join(blocks)}")
        if every_trial:
            for trial in plan:
                tactile = f" tactile {json.dumps(trial.tactile, sort_keys=True)}" \
                    if trial.tactile else ""
                out.append(f"  {trial.n:>4}  {trial.block:<{width}}  {trial.phase:<13}  "
                           f"{trial.modality:<13}  {trial.pen}  ink {trial.ink}  "
                           f"rep {trial.repetition}  [{' '.join(trial.questions)}]{tactile}")
            continue
        for run in _runs(plan):
            first, last = run[0], run[-1]
            numbers = f"{first.n}" if len(run) == 1 else f"{first.n}-{last.n}"
            pens = [trial.pen for trial in run]
            if len(set(pens)) == 1:
                shown = pens[0] if len(run) == 1 else f"{pens[0]} ×{len(run)}"
            else:
                shown = " ".join(codes.get(pen, pen) for pen in pens)
            questions = list(dict.fromkeys(q for trial in run for q in trial.questions))
            out.append(f"  {numbers:>9}  {first.block:<{width}}  {first.phase:<13}  "
                       f"{first.modality:<13}  ink {first.ink:<7}  {shown}  "
                       f"[{' '.join(questions)}]")
    return out


def _runs(plan: list[PlannedTrial]) -> Iterator[list[PlannedTrial]]:
    """Consecutive trials of one block and phase with the same task."""
    run: list[PlannedTrial] = []
    for trial in plan:
        if run and (trial.block_index, trial.phase, trial.task, trial.modality, trial.ink) != \
                (run[-1].block_index, run[-1].phase, run[-1].task, run[-1].modality,
                 run[-1].ink):
            yield run
            run = []
        run.append(trial)
    if run:
        yield run


def plan_rows(design: Design, participants: int, *, seed: int | None = None
              ) -> Iterator[tuple]:
    """One row (the values of :data:`CSV_COLUMNS`) per planned trial of participants
    0..N−1: ``participant`` is the plan index (0-based), ``questions`` the ids joined by
    ``;``, ``tactile`` JSON or ``""``."""
    participants = _check_participants(participants)
    for index in range(participants):
        for trial in participant_plan(design, index, seed):
            yield (index, trial.n, trial.block, trial.block_index, trial.phase, trial.condition,
                   trial.modality, trial.pen, trial.ink, trial.repetition,
                   ";".join(trial.questions), trial.task,
                   json.dumps(trial.tactile, sort_keys=True) if trial.tactile else "")


def write_plan_csv(design: Design, participants: int, path: str | os.PathLike, *,
                   seed: int | None = None) -> int:
    """Write the plans of participants 0..N−1 as CSV (:data:`CSV_COLUMNS`), atomically.

    Returns:
        The number of rows (planned trials) written.

    Raises:
        ParameterError: ``participants`` or ``seed`` out of range (nothing is written).
        RealPenError: the file cannot be written.
    """
    from realpen.io.files import atomic_path

    participants = _check_participants(participants)  # every check before the file
    _check_seed(design.seed if seed is None else seed)
    count = 0
    with atomic_path(Path(path)) as tmp:
        with open(tmp, "w", newline="", encoding="utf-8") as handle:
            writer = csv.writer(handle)
            writer.writerow(CSV_COLUMNS)
            for row in plan_rows(design, participants, seed=seed):
                writer.writerow(row)
                count += 1
    return count
