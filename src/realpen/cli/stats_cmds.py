"""``realpen stats DESIGN TRIALS -o DIR`` and ``realpen stats power DESIGN``: the studies'
statistics and their power.

``realpen stats DESIGN TRIALS`` is short for ``realpen stats report DESIGN TRIALS``. Only typer
and the standard library are imported here; the analyses (pandas, statsmodels, pingouin) are
imported inside the commands.
"""

import sys
from pathlib import Path

import typer

from realpen.cli.common import (
    DefaultCommandGroup,
    check_outputs,
    command_group,
    console,
    design_input,
    force_option,
    progress_bar,
    terminate_as_interrupt,
    whole_number,
    working,
)
from realpen.errors import RealPenError

__all__ = ["stats_app", "register"]

DESIGN_HELP = "A built-in design (study1, study2) or a design file (.yaml, .yml, .json)."


class _ReportByDefault(DefaultCommandGroup):
    """``realpen stats DESIGN ...`` runs ``report``; ``power`` reads its participants spread."""

    default_command = "report"

    def parse_args(self, ctx, args):
        if args and args[0] == "power":
            args = _spread_participants(args)
        return super().parse_args(ctx, args)


def _spread_participants(args: list[str]) -> list[str]:
    """``--participants 8 12 16`` (and ``8,12,16``) as click reads a repeated option:
    ``--participants 8 --participants 12 --participants 16``."""
    spread: list[str] = []
    flag, given = None, 0
    for token in args:
        if token in ("--participants", "-n"):
            flag, given = token, 0
            continue
        if flag is not None:
            numbers = [part for part in token.split(",") if part]
            if numbers and all(part.lstrip("+-").isdigit() for part in numbers):
                spread += [item for number in numbers for item in (flag, number)]
                given += 1
                continue
            if not given:  # a value that is not a number: click names the problem
                spread += [flag, token]
                flag = None
                continue
            flag = None
        spread.append(token)
    if flag is not None and not given:
        spread.append(flag)  # a flag without a value: click says so
    return spread


def _power_sims(value: int) -> int:
    """--power-sims: 0 (no power section) or enough simulated studies to mean something."""
    whole_number(value)
    if value != 0 and not 10 <= value <= 1_000_000:
        raise typer.BadParameter(f"give 0 (leave the power out) or 10 to 1,000,000, got {value}")
    return value


stats_app = command_group(
    "The studies' statistics: `realpen stats DESIGN trials.csv -o REPORT_DIR` (the report), or "
    "`realpen stats power DESIGN --participants 8 12 16` (before a study).", cls=_ReportByDefault)


@stats_app.command("report")
def report(
    design: str = typer.Argument(..., metavar="DESIGN", help=DESIGN_HELP),
    trials: Path = typer.Argument(..., metavar="TRIALS",
                                  help="The trials CSV of `realpen study export`."),
    output: Path = typer.Option(..., "-o", "--output",
                                help="The report folder to write: results.csv, the tables, the "
                                     "figures (PNG, SVG) and report.html."),
    paper_compatible: bool = typer.Option(
        False, "--paper-compatible",
        help="Also give the paper's own choices (SPSS-style Wilcoxon; repetitions as subjects "
             "in the recognition ANOVA), each marked with why it is not recommended."),
    wilcoxon: str = typer.Option("exact", "--wilcoxon",
                                 help="Wilcoxon p-values: exact, r (R's wilcox.test) or spss."),
    adjust: str = typer.Option("holm", "--adjust",
                               help="Adjustment of the Wilcoxon post hoc p (and of the "
                                    "--friedman-blocks per-level tests): holm, bonferroni or "
                                    "none."),
    friedman_blocks: str = typer.Option(
        "average", "--friedman-blocks",
        help="How a factor is tested 'blocked by' the other: average (over the other factor), "
             "cells (participant × other level as blocks) or per-level (one test per level)."),
    likert_ci: str = typer.Option("bootstrap", "--likert-ci",
                                  help="Intervals of rating means: bootstrap (BCa) or t."),
    exclude_incomplete: bool = typer.Option(
        False, "--exclude-incomplete",
        help="Leave participants out of the outcomes whose planned cells they miss (listed in "
             "the report); without it they are refused."),
    include_pilot: bool = typer.Option(
        False, "--include-pilot",
        help="Analyse the pilot sessions' answers too (rows whose pilot column is 1, which "
             "`realpen study export --include-pilot` writes); without it they are left out and "
             "counted in the report."),
    power_sims: int = typer.Option(
        200, "--power-sims", callback=_power_sims,
        help="Simulated studies per step of the smallest-detectable-effect search in the "
             "report: 0 (leave it out) or 10 to 1,000,000."),
    seed: int = typer.Option(0, "--seed", min=0, callback=whole_number,
                             help="Seed of the bootstrap and the power simulation."),
    force: bool = force_option(),
) -> None:
    """Analyse a study's answers into a report folder.

    Writes results.csv (one row per test), the tables, the paper's Figures 7, 10, 11 and 12 as
    PNG and SVG, and a self-contained report.html.
    """
    from realpen.io.files import check_readable_file
    from realpen.stats.analyses import AnalysisOptions, IncompleteError, analyse
    from realpen.stats.data import read_trials
    from realpen.stats.outputs import check_report_folder, write_report_folder
    from realpen.study.design import load_design

    options = AnalysisOptions(paper_compatible=paper_compatible, wilcoxon_method=wilcoxon,
                              adjust=adjust, friedman_variant=friedman_blocks,
                              likert_ci=likert_ci, exclude_incomplete=exclude_incomplete,
                              seed=seed)
    check_readable_file(trials)
    check_outputs(output, force=force, folders=True,
                  inputs={"trials CSV": trials, **design_input(design)})
    check_report_folder(output, replace=force)
    loaded = load_design(design)
    with terminate_as_interrupt():
        with working("analysing"):
            try:
                analysis = analyse(read_trials(trials, loaded, include_pilot=include_pilot),
                                   options)
            except IncompleteError as error:
                raise RealPenError(f"{error}; rerun with --exclude-incomplete to leave incomplete "
                                   f"participants out of the outcomes they miss") from None
        if power_sims:
            from realpen.stats.power import report_power

            participants_seen = analysis.participants["participant"].nunique()
            with progress_bar("power") as progress:
                analysis.power = report_power(participants_seen, loaded, sims=power_sims,
                                              seed=seed, progress=progress)
        for participant, reason in analysis.excluded.items():
            print(f"realpen: warning: participant {participant} partly excluded: {reason}",
                  file=sys.stderr)
        with working("writing the report"):
            written = write_report_folder(analysis, output)
    tests = len(analysis.results)
    console.print(f"wrote {output}: {tests} tests of {analysis.design} in results.csv, "
                  f"{len(written)} files; open {output / 'report.html'}")


@stats_app.command("power")
def power(
    design: str = typer.Argument(..., metavar="DESIGN", help=DESIGN_HELP),
    participants: list[int] = typer.Option(
        ..., "--participants", "-n", min=2, callback=lambda values: [whole_number(v) for v in values],
        metavar="N...",
        help="Numbers of participants to simulate (repeat or list: -n 8 -n 12, or "
             "--participants 8 12 16)."),
    effect: float = typer.Option(
        0.5, "--effect",
        help="Rating effect: the difference between the highest and the lowest level in SD "
             "units of a participant's latent rating."),
    rates: str | None = typer.Option(
        None, "--rates",
        help="Recognition rates for every modality of the design, e.g. tactile=0.43,"
             "auditory=0.51,audio-tactile=0.63 (default: the paper's)."),
    sims: int = typer.Option(2000, "--sims", min=10, callback=whole_number,
                             help="Simulated studies per number of participants."),
    seed: int = typer.Option(0, "--seed", min=0, callback=whole_number,
                             help="Seed of the simulation."),
    plot: Path | None = typer.Option(None, "--plot",
                                     help="Also draw power against participants (.png or .svg)."),
    force: bool = force_option(),
) -> None:
    """Power before a study: how often its main tests find the effect.

    Simulates the design and prints, for each number of participants, the share of simulated
    studies in which each main test gives p < 0.05.
    """
    from realpen.stats.power import power_lines, power_table, response_model
    from realpen.study.design import load_design

    check_outputs(plot, force=force, inputs=design_input(design))
    if plot is not None:
        from realpen.display.images import image_kind

        image_kind(plot)
    loaded = load_design(design)
    model = response_model(effect=effect, rates=rates)
    with progress_bar("simulating") as progress:
        table = power_table(loaded, participants, model=model, sims=sims, seed=seed,
                            progress=progress)
    print("\n".join(power_lines(table)), flush=True)
    if plot is not None:
        from realpen.stats.power_plot import save_power_plot

        save_power_plot(table, plot)
        console.print(f"wrote {plot}")


@stats_app.command("simulate")
def simulate(
    design: str = typer.Argument(..., metavar="DESIGN", help=DESIGN_HELP),
    participants: int = typer.Option(..., "--participants", "-n", min=1, callback=whole_number,
                                     help="How many simulated participants (S01, S02, ...)."),
    output: Path = typer.Option(..., "-o", "--output",
                                help="The trials CSV to write: the columns `realpen stats` "
                                     "reads (with --store, the store's full export)."),
    store: str | None = typer.Option(
        None, "--store",
        help="Enter every answer through the study service into this store (an SQLite file or "
             "a postgresql:// URL) that holds no session of the design yet, and write its "
             "export, as a real study would."),
    effect: float = typer.Option(0.5, "--effect",
                                 help="Rating effect in latent SDs between the highest and the "
                                      "lowest level."),
    rates: str | None = typer.Option(None, "--rates",
                                     help="Recognition rates for every modality of the design, "
                                          "e.g. tactile=0.43,auditory=0.51,audio-tactile=0.63 "
                                          "(default: the paper's)."),
    seed: int = typer.Option(0, "--seed", min=0, callback=whole_number,
                             help="Seed of the answers (plans use the design's seed)."),
    force: bool = force_option(),
) -> None:
    """Simulated participants answering a design's plan.

    Data to try the analysis on before a study: `realpen stats DESIGN trials.csv -o report`.
    """
    from realpen.stats.power import response_model
    from realpen.stats.simulate import check_simulated_size, simulate_store, write_simulated_trials
    from realpen.study.design import load_design

    check_outputs(output, force=force, inputs=design_input(design))
    loaded = load_design(design)
    model = response_model(effect=effect, rates=rates)
    check_simulated_size(loaded, participants, output, model=model, seed=seed,
                         store=store is not None)
    if store is None:
        write_simulated_trials(loaded, participants, output, model=model, seed=seed)
    else:
        from realpen.study.db import store_file
        from realpen.study.export import export_trials, sidecar_path

        file = store_file(store)
        check_outputs(output, sidecar_path(output), force=force,
                      inputs={**design_input(design), **({} if file is None else {"store": file})})
        simulate_store(loaded, participants, store, model=model, seed=seed)
        export_trials(store, output, design=loaded.name)
    console.print(f"wrote {output}: {participants} simulated participant"
                  f"{'s' if participants != 1 else ''} of {loaded.name}")


def register(app: typer.Typer) -> None:
    """Add ``realpen stats`` to the root command."""
    app.add_typer(stats_app, name="stats")
