"""CPU time of `realpen stats` (the report) on simulated study 1 and study 2 data, and where it goes.

Target (issue 23): `realpen stats study2` on the simulated study in half the time it took before
the figures were drawn once per view and the aligned-rank-transform ANOVA went through the
vectorised repeated-measures code. Give ``--before SRC`` (the ``src`` folder of an older
checkout, e.g. from ``git archive``) to measure both in one run, round robin.

Each report runs in a fresh process: ``python -c RUNNER`` with the measured ``src`` first on
``PYTHONPATH`` (this venv's libraries), which runs ``realpen stats DESIGN trials.csv -o DIR
--force`` through the real command line. Process CPU (user + system) comes from ``os.wait4``;
inside, the runner reads its own CPU clock around

- start-up: the interpreter and ``realpen.cli``;
- imports: the modules the command imports when it runs (the statistics, the study designs,
  matplotlib through the figure modules), imported first so they can be timed apart;
- statistics: ``read_trials`` and ``analyse``; power: ``report_power`` (the report's
  smallest-detectable-effect search, ``--power-sims`` 200 by default);
- figures: ``save_study_figures`` (drawing and rendering every PNG and SVG); report:
  ``write_report`` (report.html); other: the rest (tables, the folder swap, the command line).

With ``--before``, the two report folders of the last round are compared: the same files, the
same PNG bytes and the same SVG (ids matplotlib draws at random made equal) and CSV text. The
machine's load is printed before and after: a busy machine adds CPU time to every figure alike.

``--scale`` measures instead what issue 25 asks of large studies, on one core (``taskset -c
0`` where it exists, one BLAS thread): the report on ``--participants`` simulated participants
of study 2 (default 1,000; goal: under 60 s) — CPU, wall time and peak RSS of the whole
command — and the reading of a study-2 trials CSV just under the size limit
(:data:`realpen.stats.data.MAX_TRIALS_BYTES`, made by copying the simulated participants under
new codes): its size, read time and peak RSS (goal: at most 1 GB); ``--full-report`` also
times the whole report on that file (goal: at most 1 GB too). Each report's ``report.html``
and largest figure file are sized: the participants' layers are rasterised above 48
participants, so neither grows with the participants.

Usage: python benchmarks/bench_stats.py [--repeats 3] [--participants 12] [--before OLD/src]
       [--after NEW/src] [--studies study1 study2]
       python benchmarks/bench_stats.py --scale [--participants 1000] [--full-report]
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

SRC = Path(__file__).resolve().parents[1] / "src"
GOAL = 0.5  # study 2's CPU after / before
MARK = "BENCH-STATS "
PHASES = ("start-up", "imports", "statistics", "power", "figures", "report", "other")

for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_name, "1")

RUNNER = r'''
import json, resource, sys

def cpu():
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime

import realpen.cli
started = cpu()
import realpen.io.files, realpen.study.design
import realpen.stats.analyses, realpen.stats.data, realpen.stats.outputs, realpen.stats.power
import realpen.stats.figure_plan, realpen.stats.report
imported = cpu()
spent = dict.fromkeys(("statistics", "power", "figures", "report"), 0.0)

def timed(module, name, phase):
    function = getattr(module, name)
    def wrapper(*args, **kwargs):
        before = cpu()
        try:
            return function(*args, **kwargs)
        finally:
            spent[phase] += cpu() - before
    setattr(module, name, wrapper)

timed(realpen.stats.data, "read_trials", "statistics")
timed(realpen.stats.analyses, "analyse", "statistics")
timed(realpen.stats.power, "report_power", "power")
timed(realpen.stats.figure_plan, "save_study_figures", "figures")
timed(realpen.stats.report, "write_report", "report")
try:
    realpen.cli.main(sys.argv[1:])
    code = 0
except SystemExit as stop:
    code = stop.code or 0
finished = cpu()
print("''' + MARK + r'''" + json.dumps({"code": code, "start-up": started, "imports": imported - started,
                                 **spent, "in-process": finished}), flush=True)
'''


def load() -> str:
    try:
        return " ".join(f"{value:.2f}" for value in os.getloadavg())
    except OSError:
        return "unknown"


def child_environment(src: Path) -> dict[str, str]:
    environment = dict(os.environ)
    environment["PYTHONPATH"] = os.pathsep.join([str(src), *filter(None, [os.environ.get("PYTHONPATH")])])
    environment.pop("PYTHONDONTWRITEBYTECODE", None)
    return environment


def wait_cpu(process: subprocess.Popen) -> tuple[int, float]:
    """Wait for ``process`` and return its exit code and CPU seconds (user + system)."""
    _, status, usage = os.wait4(process.pid, 0)
    return os.waitstatus_to_exitcode(status), usage.ru_utime + usage.ru_stime


def measured(src: Path, design: str, trials: Path, output: Path) -> dict[str, float]:
    """One ``realpen stats`` in a fresh process: its phases and its process CPU (from
    ``os.wait4``, the interpreter's start-up included), in seconds."""
    process = subprocess.Popen([sys.executable, "-c", RUNNER, "stats", design, str(trials), "-o",
                                str(output), "--force"], env=child_environment(src),
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    stdout = process.stdout.read()
    stderr = process.stderr.read()
    code, total = wait_cpu(process)
    lines = [line for line in stdout.splitlines() if line.startswith(MARK)]
    if code or not lines:
        raise SystemExit(f"realpen stats {design} ({src}) exited {code}:\n{stderr}")
    phases = json.loads(lines[-1][len(MARK):])
    phases["total"] = total
    phases["start-up"] += total - phases["in-process"]  # the interpreter before the runner's clock
    phases["other"] = total - sum(phases[name] for name in PHASES if name != "other")
    return phases


def svg_text(data: bytes) -> str:
    """An SVG with the ids matplotlib draws at random numbered in order of appearance."""
    seen: dict[str, str] = {}
    return re.sub(r"\b(?:[mpc]|image)[0-9a-f]{10}\b",
                  lambda match: seen.setdefault(match.group(0), f"id{len(seen)}"),
                  data.decode("utf-8"))


def compare_folders(before: Path, after: Path) -> list[str]:
    """What differs between two report folders (figures by bytes, SVG ids aside; text files
    by line)."""
    names = {path.name for path in before.iterdir()} | {path.name for path in after.iterdir()}
    differences = []
    for name in sorted(names):
        old, new = before / name, after / name
        if not old.exists() or not new.exists():
            differences.append(f"{name}: only {'after' if new.exists() else 'before'}")
        elif name.endswith(".png"):
            if old.read_bytes() != new.read_bytes():
                differences.append(f"{name}: other pixels or bytes")
        elif name.endswith(".svg"):
            if svg_text(old.read_bytes()) != svg_text(new.read_bytes()):
                differences.append(f"{name}: other drawing")
        elif name.endswith(".csv"):
            lines = [(a, b) for a, b in zip(old.read_text().splitlines(), new.read_text().splitlines())
                     if a != b]
            if lines or len(old.read_text().splitlines()) != len(new.read_text().splitlines()):
                differences.append(f"{name}: {len(lines)} line(s) differ")
    return differences


SCALE_GOAL_S = 60.0
RSS_GOAL_BYTES = 1024**3
READER = r'''
import sys, time
from realpen.stats.data import read_trials
from realpen.study.design import load_design
trials = read_trials(sys.argv[1], load_design("study2"))
print(f"{len(trials.frame) + len(trials.training)} answers of {len(trials.participants)} participants")
'''


def one_core() -> list[str]:
    """``taskset -c 0`` where it exists: the figures are for one core."""
    return ["taskset", "-c", "0"] if shutil.which("taskset") else []


def timed_run(command: list[str], src: Path) -> tuple[int, float, float, int, str]:
    """Run ``command`` on one core: exit code, CPU s (user + system), wall s, peak RSS (bytes,
    from ``os.wait4``) and its last output line."""
    environment = child_environment(src)
    for name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        environment[name] = "1"
    started = time.perf_counter()
    process = subprocess.Popen(one_core() + command, env=environment, stdout=subprocess.PIPE,
                               stderr=subprocess.STDOUT, text=True)
    output = process.stdout.read()
    _, status, usage = os.wait4(process.pid, 0)
    wall = time.perf_counter() - started
    lines = output.strip().splitlines()
    return (os.waitstatus_to_exitcode(status), usage.ru_utime + usage.ru_stime, wall,
            usage.ru_maxrss * 1024, lines[-1] if lines else "")


FIGURE_SUFFIXES = (".svg", ".png", ".pdf")


def output_sizes(folder: Path) -> str:
    """``report.html``'s size and the largest figure file's, in MB, for a report line."""
    figures = [path for path in folder.iterdir() if path.suffix in FIGURE_SUFFIXES]
    largest = max(figures, key=lambda path: path.stat().st_size, default=None)
    text = f"report.html {(folder / 'report.html').stat().st_size / 1e6:.1f} MB"
    if largest is not None:
        text += f", largest figure {largest.name} {largest.stat().st_size / 1e6:.2f} MB"
    return text


def big_trials(small: Path, target: Path, limit: int) -> int:
    """A study-2 trials CSV just under ``limit`` bytes: ``small``'s participants copied under
    new codes (and sessions), whole participants only. Returns its size."""
    header, *rows = small.read_text(encoding="utf-8").splitlines()
    columns = header.split(",")
    code, session = columns.index("participant"), columns.index("session")
    blocks: list[list[str]] = []
    for row in rows:
        fields = row.split(",")
        if not blocks or fields[code] != blocks[-1][0].split(",")[code]:
            blocks.append([])
        blocks[-1].append(row)
    size = len(header) + 1
    with open(target, "w", encoding="utf-8") as out:
        out.write(header + "\n")
        copy = 0
        while True:
            copy += 1
            for block in blocks:
                lines = []
                for row in block:
                    fields = row.split(",")
                    fields[code] = f"C{copy:03d}{fields[code]}"
                    fields[session] = str(int(fields[session]) + copy * len(blocks))
                    lines.append(",".join(fields) + "\n")
                text = "".join(lines)
                if size + len(text.encode("utf-8")) > limit:
                    return size
                out.write(text)
                size += len(text.encode("utf-8"))


def scale(args: argparse.Namespace) -> None:
    """The figures of issue 25: the large report and the large CSV."""
    src = args.after.resolve()
    sys.path.insert(0, str(src))
    from realpen.stats.data import MAX_TRIALS_BYTES

    print(f"load before: {load()}")
    with tempfile.TemporaryDirectory(prefix="bench-stats-scale-") as folder:
        work = Path(folder)
        trials = work / "study2.csv"
        subprocess.run([sys.executable, "-m", "realpen", "stats", "simulate", "study2", "-n",
                        str(args.participants), "-o", str(trials)], check=True,
                       env=child_environment(src), stdout=subprocess.DEVNULL)
        code, cpu, wall, rss, last = timed_run(
            [sys.executable, "-m", "realpen", "stats", "study2", str(trials), "-o",
             str(work / "report"), "--force"], src)
        goal = "meets" if code == 0 and wall < SCALE_GOAL_S else "misses"
        print(f"report of {args.participants:,} participants ({trials.stat().st_size:,} bytes): "
              f"exit {code}, CPU {cpu:.1f} s, wall {wall:.1f} s, peak RSS {rss / 2**20:.0f} MiB "
              f"({goal} the goal of {SCALE_GOAL_S:g} s wall on one core)")
        if code == 0:
            print(f"  {output_sizes(work / 'report')}")
        big = work / "big.csv"
        size = big_trials(trials, big, MAX_TRIALS_BYTES)
        code, cpu, wall, rss, last = timed_run([sys.executable, "-c", READER, str(big)], src)
        goal = "meets" if code == 0 and rss <= RSS_GOAL_BYTES else "misses"
        print(f"read_trials of a {size:,}-byte CSV (limit {MAX_TRIALS_BYTES:,}): {last}; exit "
              f"{code}, CPU {cpu:.1f} s, wall {wall:.1f} s, peak RSS {rss / 2**20:.0f} MiB "
              f"({goal} the goal of {RSS_GOAL_BYTES / 2**30:g} GiB)")
        if args.full_report:
            code, cpu, wall, rss, last = timed_run(
                [sys.executable, "-m", "realpen", "stats", "study2", str(big), "-o",
                 str(work / "big-report"), "--force"], src)
            goal = "meets" if code == 0 and rss <= RSS_GOAL_BYTES else "misses"
            print(f"report of that CSV: exit {code}, CPU {cpu:.1f} s, wall {wall:.1f} s, peak "
                  f"RSS {rss / 2**20:.0f} MiB ({goal} the goal of {RSS_GOAL_BYTES / 2**30:g} "
                  "GiB)")
            if code == 0:
                print(f"  {output_sizes(work / 'big-report')}")
    print(f"load after: {load()}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeats", type=int, default=3, help="runs of each report (median shown)")
    parser.add_argument("--participants", type=int, default=None,
                        help="simulated participants (default 12; 1000 with --scale)")
    parser.add_argument("--scale", action="store_true",
                        help="one core: the report of many participants and a CSV at the limit")
    parser.add_argument("--full-report", action="store_true",
                        help="with --scale: also the whole report of the CSV at the limit")
    parser.add_argument("--studies", nargs="+", default=["study1", "study2"])
    parser.add_argument("--before", type=Path, help="the src folder of the code to compare with")
    parser.add_argument("--after", type=Path, default=SRC,
                        help="the src folder of the code to measure (default: this checkout's)")
    args = parser.parse_args()
    if args.participants is None:
        args.participants = 1000 if args.scale else 12
    if args.scale:
        scale(args)
        return
    for src in filter(None, (args.before, args.after)):
        if not (src / "realpen" / "__init__.py").is_file():
            raise SystemExit(f"{src}: not a src folder with realpen in it")
    trees = {"after": args.after.resolve()}
    if args.before is not None:
        trees = {"before": args.before.resolve(), "after": args.after.resolve()}
    for src in trees.values():  # bytecode caches first, as installing writes them
        subprocess.run([sys.executable, "-m", "compileall", "-q", str(src / "realpen")], check=True,
                       env=child_environment(src), stdout=subprocess.DEVNULL)
    print(f"load before: {load()}")
    runs: dict[tuple[str, str], list[dict[str, float]]] = {}
    with tempfile.TemporaryDirectory(prefix="bench-stats-") as folder:
        work = Path(folder)
        trials = {}
        for design in args.studies:
            trials[design] = work / f"{design}.csv"
            subprocess.run([sys.executable, "-m", "realpen", "stats", "simulate", design, "-n",
                            str(args.participants), "-o", str(trials[design])], check=True,
                           env=child_environment(trees["after"]), stdout=subprocess.DEVNULL)
        for _ in range(args.repeats):
            for design in args.studies:
                for label, src in trees.items():
                    runs.setdefault((design, label), []).append(
                        measured(src, design, trials[design], work / f"{design}-{label}"))
        compared = {design: compare_folders(work / f"{design}-before", work / f"{design}-after")
                    for design in args.studies if "before" in trees}
    print(f"load after: {load()}")
    print(f"\nrealpen stats DESIGN trials.csv -o DIR, {args.participants} simulated participants: "
          f"process CPU in s, median of {args.repeats} (a fresh process each, round robin)")
    header = f"{'':16}{'total':>8}" + "".join(f"{name:>12}" for name in PHASES)
    print(header)
    medians = {}
    for (design, label), found in runs.items():
        median = {name: statistics.median(run[name] for run in found) for name in ("total", *PHASES)}
        medians[design, label] = median
        print(f"{design + ' ' + label:16}{median['total']:8.2f}"
              + "".join(f"{median[name]:12.2f}" for name in PHASES))
        print(f"{'':16}{'':8}" + "".join(f"{100 * median[name] / median['total']:11.0f}%"
                                         for name in PHASES))
    if "before" in trees:
        print()
        for design in args.studies:
            ratio = medians[design, "after"]["total"] / medians[design, "before"]["total"]
            goal = f" (goal ≤ {GOAL:g})" if design == "study2" else ""
            print(f"{design}: after / before = {ratio:.2f}{goal}; outputs: "
                  + ("the same" if not compared[design] else "; ".join(compared[design])))


if __name__ == "__main__":
    main()
