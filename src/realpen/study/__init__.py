"""Studies: designs (data files), plans and counterbalancing, sessions, and the store.

- :mod:`~realpen.study.tables` — the store's tables (SQLAlchemy Core): strokes and samples
  of the live app, and studies, participants, sessions, trials and answers;
- :mod:`~realpen.study.db` — opening a store (SQLite file or PostgreSQL URL) and bringing its
  schema up to date with Alembic (``migrations/``);
- :mod:`~realpen.study.design` — the design file (YAML or JSON): its schema, the rules beyond
  it, the wording of its problems, reading it, and the built-in designs ``study1`` and
  ``study2`` (``designs/``);
- :mod:`~realpen.study.plan` — counterbalancing (Williams Latin squares, permutations) and
  each participant's order of blocks and trials;
- :mod:`~realpen.study.sessions` — running a session: create or resume, the next trial,
  answers (each durably committed before it is acknowledged), progress;
- :mod:`~realpen.study.admin` — administering a study: withdraw a participant (their data
  deleted, a record kept), abandon sessions, find a session by its participant;
- :mod:`~realpen.study.patterns` — a trial's tactile pattern: the pen's own, or rebuilt from
  its source with a condition's parameters;
- :mod:`~realpen.study.export` — one row per answer for analysis, a JSON sidecar, strokes,
  sessions.

May import: :mod:`realpen.io`, :mod:`realpen.errors`, :mod:`realpen.validation`,
:mod:`realpen._version`, :mod:`realpen.tactile`, :mod:`realpen.profile`, :mod:`realpen.pens`;
never :mod:`realpen.stats`, :mod:`realpen.display`, :mod:`realpen.live` or :mod:`realpen.cli`.
"""
