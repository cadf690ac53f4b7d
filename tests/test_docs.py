"""The documentation tells the truth about the command line, and the API reference's roles link.

The site itself is built by ``scripts/build-docs.sh`` (``mkdocs build --strict``); these checks
are the cheap part that needs no MkDocs: every ``--flag`` written in a command line of the
README or of ``docs/*.md`` is a flag of that command, ``docs/live.md`` gives every option of the
commands it documents, and the docs build's griffe extension turns Sphinx roles into links.
"""

from __future__ import annotations

import functools
import importlib.util
import re
from pathlib import Path

import pytest
import typer.main

from realpen.cli import app, command_path

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
FLAG = re.compile(r"(?<![\w-])--[a-z][a-z0-9-]*")


INLINE = re.compile(r"`(realpen [^`]+)`")


def shell_command_lines(text: str) -> list[str]:
    """The ``realpen …`` command lines of a page: in code blocks (continuations joined), and in
    inline code."""
    commands: list[str] = []
    fenced = False
    for line in text.splitlines():
        if line.startswith("```"):
            fenced = not fenced
            continue
        if not fenced:
            commands += INLINE.findall(line)
            continue
        code = line.split(" #")[0].rstrip()
        if code.startswith("realpen "):
            commands.append(code)
        elif commands and code.startswith(" ") and code.lstrip()[:1] in ("[", "-"):
            commands[-1] += " " + code.strip()
    return commands


@functools.cache
def root_command():
    return typer.main.get_command(app)


def command_for(words: list[str]) -> tuple[list[str], object]:
    """The command a command line's words run (a group's default command included)."""
    path = command_path(words).split()
    command = root_command()
    for word in path:
        command = command.commands[word]
    return path, command


def flags_of(command) -> set[str]:
    return {name for param in command.params for name in param.opts + param.secondary_opts
            if name.startswith("--")}


def documented_commands() -> list[tuple[str, str]]:
    return [(page.name, line) for page in PAGES
            for line in shell_command_lines(page.read_text(encoding="utf-8"))]


def test_the_pages_have_command_lines_to_check():
    pages = {page for page, _ in documented_commands()}
    assert {"README.md", "live.md", "studies.md", "stats.md"} <= pages


@pytest.mark.parametrize(("page", "line"), documented_commands())
def test_every_flag_in_a_documented_command_line_is_a_flag_of_that_command(page, line):
    path, command = command_for(line.split()[1:])
    unknown = set(FLAG.findall(line)) - flags_of(command) - {"--help"}
    assert not unknown, f"{page}: `realpen {' '.join(path)}` has no {sorted(unknown)}: {line}"


@pytest.mark.parametrize("words", [["serve"], ["strokes", "export"]])
def test_live_md_gives_every_option_of_the_commands_it_documents(words):
    text = (ROOT / "docs" / "live.md").read_text(encoding="utf-8")
    synopsis = " ".join(line for line in shell_command_lines(text)
                        if line.startswith("realpen " + " ".join(words) + " "))
    path, command = command_for(words)
    assert path == words
    # One spelling of each option is enough (--force stands for --force/--overwrite).
    missing = [param.opts for param in command.params
               if param.opts and param.opts[0].startswith("--") and param.opts[0] != "--help"
               and not set(param.opts) & set(FLAG.findall(synopsis))]
    assert not missing, f"docs/live.md's synopsis of realpen {' '.join(words)} lacks {missing}"


# The docs build's griffe extension (scripts/docs/griffe_realpen.py), on a small package.

def load_extension():
    pytest.importorskip("griffe", reason="the docs extra is not installed")
    spec = importlib.util.spec_from_file_location(
        "griffe_realpen", ROOT / "scripts" / "docs" / "griffe_realpen.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


PACKAGE = {
    "__init__.py": '''"""The package: :func:`analyze`, :class:`~realpen.sub.Thing`, :mod:`realpen.sub`.

Also :class:`Thing`, :func:`the helper <realpen.sub.helper>`, :func:`numpy.fft.rfft`,
:class:`ValueError`, :func:`realpen.sub._private` and :data:`realpen.sub.nothere`.

>>> 1 + 1
2
"""
__all__ = ["analyze"]
_HOMES = {"Thing": "sub"}


def analyze(data):
    """Analyse.

    Args:
        data: a :class:`Thing`.
        fmin, fmax: the band in Hz.

    Example:
        >>> analyze(1)
    """
''',
    "sub.py": '''"""The sub-module."""
__all__ = ["Thing", "helper"]


class Thing:
    """A thing."""


def helper():
    """Help."""


def _private():
    """Private."""
''',
}


@pytest.fixture
def loaded(tmp_path):
    import griffe

    extension = load_extension()
    (tmp_path / "realpen").mkdir()
    for name, source in PACKAGE.items():
        (tmp_path / "realpen" / name).write_text(source, encoding="utf-8")
    loader = griffe.GriffeLoader(extensions=griffe.load_extensions(extension.RealPenDocs()),
                                 search_paths=[str(tmp_path)])
    return loader.load("realpen")


def test_sphinx_roles_become_checked_links_and_outside_names_code(loaded):
    text = loaded.docstring.value
    assert "[`analyze()`][realpen.analyze]" in text
    assert "[`Thing`][realpen.sub.Thing]" in text  # ~ shows the last part
    assert "[`realpen.sub`][realpen.sub]" in text
    assert "[`the helper`][realpen.sub.helper]" in text  # an explicit title
    assert "`numpy.fft.rfft()`" in text and "[`numpy" not in text  # no remote inventory
    assert "`ValueError`" in text and "][ValueError]" not in text
    assert "`realpen.sub._private()`" in text and "][realpen.sub._private]" not in text
    # A RealPen target that does not exist stays a link, which the strict build reports.
    assert "[`realpen.sub.nothere`][realpen.sub.nothere]" in text
    assert "```pycon\n>>> 1 + 1\n2\n```" in text


def test_lazy_names_are_aliases_and_sections_read_as_google_style(loaded):
    assert loaded["Thing"].is_alias and loaded["Thing"].target_path == "realpen.sub.Thing"
    text = loaded["analyze"].docstring.value
    assert "[`Thing`][realpen.sub.Thing]" in text
    assert "    fmin: the band in Hz." in text and "    fmax: the band in Hz." in text
    assert "\nExamples:\n" in text


def test_every_package_and_top_level_module_has_a_page_in_the_api_reference():
    source = ROOT / "src" / "realpen"
    names = {path.parent.name for path in source.glob("*/__init__.py")}
    names |= {path.stem for path in source.glob("*.py")}
    names = {name for name in names if not name.startswith("_")}
    nav = (ROOT / "mkdocs.yml").read_text(encoding="utf-8")
    missing = sorted(name for name in names
                     if not (ROOT / "docs" / "api" / f"{name}.md").is_file()
                     or f"api/{name}.md" not in nav)
    assert not missing, f"no docs/api/NAME.md page in mkdocs.yml's nav for realpen.{missing}"
