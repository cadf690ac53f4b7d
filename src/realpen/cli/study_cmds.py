"""``realpen study plan | designs | schema | export | start | withdraw | abandon``: study
designs, their counterbalanced plans, the answers for analysis, and the administration of a
study's sessions (a pilot session, a withdrawal, sessions abandoned).

Only typer and the standard library are imported here; the designs (pydantic, PyYAML) and
plans (numpy) are imported inside the commands, so ``realpen --help`` stays fast. Every command
of the group is registered on :data:`study_app`; what they print is built in
:mod:`realpen.study.plan` and :mod:`realpen.study.design`.
"""

import sys
from pathlib import Path

import typer

from realpen.cli.common import (
    check_outputs,
    command_group,
    console,
    design_input,
    force_option,
    whole_number,
)

__all__ = ["study_app", "register"]

study_app = command_group("User studies: designs, counterbalanced plans, export of the answers, "
                          "sessions (pilot, withdraw, abandon).")

DESIGN_HELP = "A built-in design (study1, study2) or a design file (.yaml, .yml, .json)."
STORE_HELP = ("The store: an SQLite file or a postgresql:// URL (default: strokes.sqlite3 in the "
              "data folder).")
SESSION_HELP = ("The session: its participant's ID (with --study) or the session's id (digits).")


def _store(store: str | None) -> str:
    from realpen.io.paths import default_store

    return str(default_store()) if store is None else store


@study_app.command("plan")
def plan(
    design: str = typer.Argument(..., metavar="DESIGN", help=DESIGN_HELP),
    participants: int = typer.Option(..., "--participants", "-n", min=1,
                                     help="How many participants (plan indices 0..N-1).",
                                     callback=whole_number),
    seed: int | None = typer.Option(None, "--seed", help="Seed of the randomisation "
                                                         "(default: the design's).",
                                    callback=whole_number),
    csv_out: Path | None = typer.Option(None, "--csv", help="Also write one row per planned "
                                                            "trial to this CSV."),
    trials: bool = typer.Option(False, "--trials", help="Print every trial, one per line."),
    force: bool = force_option(),
) -> None:
    """Print each participant's blocks and trials, and the design's balance over N.

    The balance: how often each level comes at each position, and each ordered pair of
    adjacent levels, and whether all are equal. Warnings (e.g. a number of participants that
    cannot balance the design) go to stderr.
    """
    from realpen.study.design import load_design
    from realpen.study.plan import balance, plan_lines, write_plan_csv

    check_outputs(csv_out, force=force, inputs=design_input(design))
    loaded = load_design(design)
    lines = plan_lines(loaded, participants, seed=seed, every_trial=trials)
    result = balance(loaded, participants, seed=seed)
    print("\n".join([*lines, "", *result.lines()]), flush=True)
    for warning in result.warnings:
        print(f"realpen: warning: {warning}", file=sys.stderr, flush=True)
    if csv_out is not None:
        rows = write_plan_csv(loaded, participants, csv_out, seed=seed)
        console.print(f"wrote {csv_out}: {rows} planned trials of {participants} "
                      f"participant{'s' if participants != 1 else ''}")


@study_app.command("designs")
def designs() -> None:
    """List the built-in designs: name, title and file."""
    from realpen.study.design import builtin_designs, load_design

    for name in builtin_designs():
        design = load_design(name)
        console.print(f"{name}  {design.title}  ({design.source})")


@study_app.command("schema")
def schema(
    output: Path | None = typer.Option(None, "-o", "--output",
                                       help="Write the schema here (default: print it)."),
    force: bool = force_option(),
) -> None:
    """The JSON Schema of design files (docs/study-design.schema.json)."""
    from realpen.io.files import json_text, write_json
    from realpen.study.design import design_schema

    if output is None:
        print(json_text(design_schema()), end="", flush=True)
        return
    check_outputs(output, force=force)
    write_json(output, design_schema())
    console.print(f"wrote {output}")


@study_app.command("export")
def export(
    output: Path = typer.Option(..., "-o", "--output",
                                help="Trials CSV to write: one row per answer (a JSON sidecar "
                                     "describing every column goes beside it)."),
    store: str | None = typer.Option(None, "--store", help=STORE_HELP),
    design: str | None = typer.Option(None, "--design",
                                      help="Only this design's sessions (its name, e.g. study1)."),
    strokes: Path | None = typer.Option(None, "--strokes",
                                        help="Also write the study strokes' samples, keyed by "
                                             "session and trial, to this CSV (with a sidecar)."),
    sessions: Path | None = typer.Option(None, "--sessions",
                                         help="Also write one row per session (state, plan row, "
                                              "times; withdrawn ones as records without data) "
                                              "to this CSV (with a sidecar)."),
    include_pilot: bool = typer.Option(False, "--include-pilot",
                                       help="Also write the pilot sessions, with a last column "
                                            "'pilot' (1 pilot, 0 not) in every file."),
    force: bool = force_option(),
) -> None:
    """Write every study answer for analysis (first columns: study, participant, session, block,
    trial, phase, condition, modality, pen, question, answer, correct, rt_ms).

    Pilot sessions are left out unless --include-pilot; withdrawn participants have no data
    (the sessions file keeps their record)."""
    from realpen.study.db import store_file
    from realpen.study.export import export_trials, sidecar_path

    store = _store(store)
    file = store_file(store)
    # An SQLite store's journal files are part of it: writing over one would lose what it holds.
    inputs = {} if file is None else {
        "store": file, **{f"store's {suffix} file": Path(f"{file}{suffix}")
                          for suffix in ("-wal", "-shm", "-journal")}}
    check_outputs(output, sidecar_path(output), strokes,
                  None if strokes is None else sidecar_path(strokes), sessions,
                  None if sessions is None else sidecar_path(sessions), force=force, inputs=inputs)
    summary = export_trials(store, output, design=design, strokes=strokes, sessions=sessions,
                            include_pilot=include_pilot)
    console.print(f"wrote {output}: {summary.rows} answers of {summary.sessions} sessions "
                  f"({summary.participants} participants)"
                  + (f"; {strokes}: {summary.samples} samples of {summary.strokes} strokes"
                     if strokes is not None else "")
                  + (f"; {sessions}: {summary.session_rows} sessions"
                     if sessions is not None else ""), highlight=False)


def _session_line(progress: dict) -> str:
    """One session in one line: id, design, participant, plan row, state, answered trials."""
    pilot = ", pilot" if progress["pilot"] else ""
    return (f"session {progress['session']} of {progress['design']} "
            f"({progress['participant']}{pilot}): plan row {progress['index']}, "
            f"{progress['state']}, {progress['answered']} of {progress['trials']} trials answered")


@study_app.command("start")
def start(
    design: str = typer.Argument(..., metavar="DESIGN", help=DESIGN_HELP),
    participant: str = typer.Option(..., "--participant", "-p",
                                    help="The participant's ID (e.g. P01; a pilot's, e.g. "
                                         "PILOT1)."),
    store: str | None = typer.Option(None, "--store", help=STORE_HELP),
    pilot: bool = typer.Option(False, "--pilot",
                               help="A pilot session: it runs the plan row the next participant "
                                    "would get without taking it, and is left out of exports "
                                    "and statistics unless asked."),
    consent: bool = typer.Option(False, "--consent", help="The participant gave consent."),
    site: str = typer.Option("", "--site", help="Where the session runs (a lab's name)."),
    index: int | None = typer.Option(None, "--index", min=0, callback=whole_number,
                                     help="The plan row (default: the lowest one free)."),
    seed: int | None = typer.Option(None, "--seed", min=0, callback=whole_number,
                                    help="The plan's seed (default: the design's)."),
) -> None:
    """Make a session in the store (or find the participant's), as the operator console's
    Start does; the participant screen then runs it (/study/participant?session=ID) on a
    server that runs the design."""
    from realpen.study.admin import on_store
    from realpen.study.design import load_design
    from realpen.study.sessions import DesignCache, SessionRequest, open_session

    loaded = load_design(design)
    request = SessionRequest(participant, site, {}, consent, index, seed, pilot)
    progress, created = on_store(_store(store), open_session, loaded, request, DesignCache(),
                                 create=True)
    console.print(("made " if created else "found ") + _session_line(progress)
                  + f"; participant screen: /study/participant?session={progress['session']}",
                  highlight=False)


@study_app.command("withdraw")
def withdraw(
    session: str = typer.Argument(..., metavar="SESSION", help=SESSION_HELP),
    study: str | None = typer.Option(None, "--study",
                                     help="The design's name (e.g. study1), to name the session "
                                          "by its participant's ID."),
    confirm: str | None = typer.Option(None, "--confirm",
                                       help="The participant's ID, when SESSION is the "
                                            "session's id (a withdrawal cannot be undone)."),
    store: str | None = typer.Option(None, "--store", help=STORE_HELP),
) -> None:
    """Withdraw a participant who takes back consent: their answers, strokes and demographics
    are deleted in one transaction; the session stays as a record (state withdrawn, the time,
    no data) and its plan row goes to the next participant."""
    from realpen.study.admin import on_store, withdraw
    from realpen.study.sessions import DesignCache

    def operation(conn):
        session_id = _find(conn, session, study)
        # Named by the participant's ID: that is the confirmation.
        typed = confirm if confirm is not None else (session if study is not None else None)
        if typed is None:
            from realpen.study.sessions import StudyInvalid

            raise StudyInvalid(f"--confirm: give the participant's ID of session {session_id} "
                               f"(a withdrawal deletes their data and cannot be undone)")
        return withdraw(conn, session_id, typed, DesignCache())

    progress = on_store(_store(store), operation)
    console.print(f"withdrew session {progress['session']} of {progress['design']}: its answers, "
                  f"strokes and demographics are deleted; plan row {progress['index']} is free",
                  highlight=False)


def _find(conn, session: str, study: str | None) -> int:
    """The session named on the command line, with the option that names one by its
    participant's ID in the error when it was not given."""
    from realpen.study.admin import find_session
    from realpen.study.sessions import StudyNotFound

    try:
        return find_session(conn, session, study)
    except StudyNotFound as error:
        if study is None:
            raise StudyNotFound(f"{error}; give --study NAME to name a session by its "
                                f"participant's ID") from None
        raise


@study_app.command("abandon")
def abandon(
    session: str | None = typer.Argument(None, metavar="[SESSION]", help=SESSION_HELP),
    study: str | None = typer.Option(None, "--study",
                                     help="The design's name (e.g. study1): names the session "
                                          "by its participant's ID, or limits --stale."),
    stale: float | None = typer.Option(None, "--stale", metavar="HOURS",
                                       help="Instead of one session: every session still "
                                            "running or paused with no answer for HOURS."),
    store: str | None = typer.Option(None, "--store", help=STORE_HELP),
) -> None:
    """End a session the participant left as abandoned (its answers are kept and exported with
    that state; it cannot be resumed), or, with --stale, every session idle that long."""
    from realpen.study.admin import abandon_stale, on_store
    from realpen.study.sessions import DesignCache, StudyInvalid, set_state

    if (session is None) == (stale is None):
        raise StudyInvalid("give either a SESSION or --stale HOURS")
    if stale is not None and not 0 < stale < 1e6:
        raise StudyInvalid("--stale: give the hours without an answer, a number above 0")
    if stale is not None:
        ended = on_store(_store(store), abandon_stale, stale, DesignCache(), study)
        for progress in ended:
            console.print(f"abandoned {_session_line(progress)}", highlight=False)
        console.print(f"{len(ended)} session{'s' if len(ended) != 1 else ''} abandoned "
                      f"(no answer for {stale:g} h)", highlight=False)
        return

    def operation(conn):
        return set_state(conn, _find(conn, session, study), "abandoned", DesignCache())

    progress = on_store(_store(store), operation)
    console.print(f"abandoned {_session_line(progress)}", highlight=False)


def register(app: typer.Typer) -> None:
    """Add ``realpen study`` to the root command."""
    app.add_typer(study_app, name="study")
