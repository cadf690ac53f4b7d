"""Small commands start fast: each imports only what its work needs (issue 23).

``test_cli.py`` checks that importing the command modules loads neither numpy nor scipy; here,
whole runs of the commands that should stay light (``--help``, ``analyze``, ``profile list``,
``export`` to AHAP), each in a fresh interpreter, leave the libraries they do not use out of
``sys.modules``. The rest is in-process: typer's option values read without pydantic
(:mod:`realpen.cli.coercion`) give what typer gives, and a run builds only the command it names
(:func:`realpen.cli.root.app_for`).
"""

from __future__ import annotations

import io
import json
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import run_cli

# Libraries none of the light commands needs (statistics, figures, the live app, the store).
NEVER = {"scipy", "pandas", "matplotlib", "statsmodels", "fastapi", "uvicorn", "sqlalchemy"}

_RUN = """
import json, sys
from realpen.cli import main
for args in json.loads(sys.argv[1]):
    try:
        main(args)
    except SystemExit as done:
        if done.code not in (0, None):
            raise
print(json.dumps(sorted({name.split(".")[0] for name in sys.modules})))
"""


def loaded_after(*runs: list[str], cwd: Path) -> set[str]:
    """The top-level packages a fresh interpreter holds after running these ``realpen``
    commands one after the other (their output is discarded)."""
    done = subprocess.run([sys.executable, "-c", _RUN, json.dumps([list(map(str, run))
                                                                     for run in runs])],
                          capture_output=True, text=True, cwd=cwd, check=False)
    assert done.returncode == 0, done.stderr
    return set(json.loads(done.stdout.splitlines()[-1]))


def write_recording(path: Path, seconds: float = 3.0) -> Path:
    """A 3-axis 16-bit WAV at 1344 Hz: two tones on noise."""
    import numpy as np
    import soundfile as sf

    t = np.arange(int(seconds * 1344)) / 1344
    rng = np.random.default_rng(0)
    tones = 0.1 * np.sin(2 * np.pi * 180 * t) + 0.05 * np.sin(2 * np.pi * 264 * t)
    sf.write(path, tones[:, None] + 0.01 * rng.standard_normal((len(t), 3)), 1344,
             subtype="PCM_16")
    return path


# --- whole runs, each in a fresh interpreter --------------------------------------------------

@pytest.mark.slow
def test_the_help_loads_no_numerical_library(tmp_path):
    loaded = loaded_after(["--help"], ["analyze", "--help"], cwd=tmp_path)
    assert not loaded & (NEVER | {"numpy", "soundfile", "pydantic"})


@pytest.mark.slow
def test_analyze_loads_neither_scipy_nor_pydantic(tmp_path):
    """The streamed analysis needs numpy and the audio reader; without --analysis-rate nothing
    is resampled, so no scipy.signal (nor any scipy), and its options are read without
    pydantic."""
    loaded = loaded_after(["analyze", write_recording(tmp_path / "shake.wav")], cwd=tmp_path)
    assert {"numpy", "soundfile"} <= loaded
    assert not loaded & (NEVER | {"pydantic"})


@pytest.mark.slow
def test_profile_list_and_an_ahap_export_load_neither_scipy_nor_rich(tmp_path, monkeypatch):
    """Reading profiles needs numpy and the profile schema (pydantic); an AHAP at the
    pattern's own rate resamples nothing, so no scipy; both print plain lines, so no rich."""
    monkeypatch.setenv("REALPEN_HOME", str(tmp_path / "home"))
    loaded = loaded_after(["profile", "list"], ["export", "pencil", "-o", "pencil.ahap"],
                          cwd=tmp_path)
    assert (tmp_path / "pencil.ahap").is_file()
    assert {"numpy", "pydantic"} <= loaded
    assert not loaded & (NEVER | {"rich"})


# --- plain lines without rich -----------------------------------------------------------------

LINES = ["pencil: pencil (4B); tactile 15×100 ms, 10 components", "wrote a:pencil:b.ahap",
         "[bold]not markup[/bold] http://x.y/z 1.5 True", "  spaced  ", "", "鉛筆の音" * 30,
         "e\u0301 ﬁ", "x" * 300,
         # not printable: rich's own handling (tabs expanded, control codes dropped)
         "a\tb", "a\rb\x07", "a\x1b[31mb", "zero\u200bwidth", "no\u00a0break",
         "two\nlines"]


def test_plain_lines_are_printed_as_the_rich_console_prints_them(capsys):
    from rich.console import Console

    from realpen.cli.common import console, print_line

    for line in LINES:
        print_line(line)
        plain = capsys.readouterr().out
        console.rich.print(line)
        assert plain == capsys.readouterr().out, repr(line)
        for terminal in (False, True):  # a narrow terminal: still one line, nothing added
            written = Console(file=io.StringIO(), force_terminal=terminal, width=20,
                              soft_wrap=True, markup=False, highlight=False, emoji=False)
            written.print(line)
            assert plain == written.file.getvalue(), (repr(line), terminal)


# --- option values without pydantic ----------------------------------------------------------

VALUES = {
    int: ["12", "-3", "0", "-0", "007", "+5", " 12", "1_000", "1.0", "1.5", "1e3", "0x10", "",
          "abc", "9" * 19, "9" * 30, "١٢", "12\n", 7, True, 2.0],
    float: ["0.05", "175", "-2.5", "1e-3", "1E5", "1.", ".5", "inf", "nan", "-0", "1e400",
            "1_0", " 1 ", "", "x", "0.1234567890123456789", "12345678901234567", 20, 2.5,
            2**60, True],
    str: ["lra:f0=175,q=8", "", " spaced ", "a\udcffb", "ünï"],
    Path: ["out.wav", "", "a//b/", "~/x", "a\udcffb", "-", Path("given.wav")],
}


def read_both(annotation, value, minimum=None):
    """(fast, typer) readings of ``value`` for an option of this type: each the value read or
    the message of the error raised."""
    import typer

    from realpen.cli.coercion import install_fast_coercion

    kwargs = {} if minimum is None else {"min": minimum}

    def command(option=typer.Option(None, "--option", **kwargs)):
        """A command with one option."""

    command.__annotations__ = {"option": annotation}
    app = typer.Typer(add_completion=False)
    app.command()(command)
    readings = []
    for fast in (True, False):
        click_command = typer.main.get_command(app)
        if fast:
            assert install_fast_coercion(click_command) == 1
        param = next(p for p in click_command.params if p.name == "option")
        ctx = click_command.make_context("command", [], resilient_parsing=True)
        try:
            read = param.get_runtime_param().coerce(value, param=param, ctx=ctx)
            readings.append((type(read), read if read == read else "nan"))
        except Exception as error:  # the message is what is compared
            readings.append((type(error), str(error)))
    return readings


@pytest.mark.parametrize("annotation", [int, float, str, Path])
def test_option_values_read_without_pydantic_as_typer_reads_them(annotation):
    for value in VALUES[annotation]:
        fast, typer_reading = read_both(annotation, value)
        assert fast == typer_reading, (annotation, value)


def test_bounded_and_repeated_option_values_read_as_typer_reads_them():
    for value in ["1", "2", "3", "-5", 1, 2]:
        fast, typer_reading = read_both(int, value, minimum=2)
        assert fast == typer_reading, value
    for values in [("8", "12"), ("8", "1"), ("8", "x"), ()]:
        fast, typer_reading = read_both(list[int], values, minimum=2)
        assert fast == typer_reading, values


def test_decimal_numbers_read_alike_to_the_last_bit():
    """Python and pydantic both round decimal text correctly: random numbers of every form the
    fast reader takes (up to 16 + 15 digits and a two-digit exponent) read to the same float."""
    import random

    from pydantic import TypeAdapter

    from realpen.cli.coercion import _DECIMAL

    pydantic_float, rng = TypeAdapter(float), random.Random(23)
    for _ in range(500):
        text = (rng.choice(["", "-"]) + str(rng.randrange(10 ** rng.randint(1, 16)))
                + rng.choice(["", "." + str(rng.randrange(10 ** 15)).zfill(rng.randint(1, 15))])
                + rng.choice(["", f"e{rng.randint(-99, 99)}", f"E+{rng.randint(0, 99)}"]))
        if _DECIMAL.fullmatch(text):
            assert float(text) == pydantic_float.validate_python(text), text


def test_every_option_of_the_command_line_gets_the_fast_reader():
    """A typer release that renames the hooks would silently bring pydantic back: every
    option of ``realpen`` is one the fast reader takes."""
    import typer.main

    from realpen.cli import app
    from realpen.cli.coercion import install_fast_coercion

    command = typer.main.get_command(app)
    options = []
    pending = [command]
    while pending:
        current = pending.pop()
        pending.extend(getattr(current, "commands", {}).values())
        options += current.params
    assert install_fast_coercion(command) == len(options) > 100


# --- a run builds only the command it names ---------------------------------------------------

def test_each_top_level_command_is_registered_by_the_module_named_for_it():
    import typer.main

    from realpen.cli import root

    whole = typer.main.get_command(root.app)
    assert set(whole.commands) == set(root.COMMANDS)
    for module in root.COMMAND_MODULES:
        part = typer.main.get_command(root.build_app((module,)))
        assert set(part.commands) == {name for name, home in root.COMMANDS.items()
                                      if home == module}, module
    assert root.app_for(["--version"]) is root.app and root.app_for([]) is root.app
    assert set(typer.main.get_command(root.app_for(["strokes", "export"])).commands) == {
        "serve", "strokes"}


def test_command_signatures_are_not_strings():
    """typer reads every command's signature at each run; string annotations (``from
    __future__ import annotations``) made it compile some 600 of them, 0.05 s a run."""
    import __future__

    import importlib

    from realpen.cli import root

    for name in (*root.COMMAND_MODULES, "root"):
        module = importlib.import_module(f"realpen.cli.{name}")
        assert vars(module).get("annotations") is not __future__.annotations, name


def test_printed_paths_are_the_users_text(tmp_path):
    """Emoji codes are not replaced in what a command prints (a file named with colons)."""
    recording = write_recording(tmp_path / "a:pencil:b.wav")
    result = run_cli("analyze", recording)
    assert result.returncode == 0, result.stderr
    assert result.stdout.startswith(f"{recording}: 3.00 s")
