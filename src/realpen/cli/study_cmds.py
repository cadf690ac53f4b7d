"""``realpen study plan | designs | schema | export``: study designs, their counterbalanced
plans, and the answers for analysis.

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

study_app = command_group("User studies: designs, counterbalanced plans, export of the answers.")

DESIGN_HELP = "A built-in design (study1, study2) or a design file (.yaml, .yml, .json)."


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
    store: str | None = typer.Option(None, "--store",
                                     help="The store: an SQLite file or a postgresql:// URL "
                                          "(default: strokes.sqlite3 in the data folder)."),
    design: str | None = typer.Option(None, "--design",
                                      help="Only this design's sessions (its name, e.g. study1)."),
    strokes: Path | None = typer.Option(None, "--strokes",
                                        help="Also write the study strokes' samples, keyed by "
                                             "session and trial, to this CSV (with a sidecar)."),
    force: bool = force_option(),
) -> None:
    """Write every study answer for analysis (first columns: study, participant, session, block,
    trial, phase, condition, modality, pen, question, answer, correct, rt_ms)."""
    from realpen.io.paths import default_store
    from realpen.study.db import store_file
    from realpen.study.export import export_trials, sidecar_path

    store = str(default_store()) if store is None else store
    file = store_file(store)
    # An SQLite store's journal files are part of it: writing over one would lose what it holds.
    inputs = {} if file is None else {
        "store": file, **{f"store's {suffix} file": Path(f"{file}{suffix}")
                          for suffix in ("-wal", "-shm", "-journal")}}
    check_outputs(output, sidecar_path(output), strokes,
                  None if strokes is None else sidecar_path(strokes), force=force, inputs=inputs)
    summary = export_trials(store, output, design=design, strokes=strokes)
    console.print(f"wrote {output}: {summary.rows} answers of {summary.sessions} sessions "
                  f"({summary.participants} participants)"
                  + (f"; {strokes}: {summary.samples} samples of {summary.strokes} strokes"
                     if strokes is not None else ""), highlight=False)


def register(app: typer.Typer) -> None:
    """Add ``realpen study`` to the root command."""
    app.add_typer(study_app, name="study")
