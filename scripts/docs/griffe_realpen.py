"""Griffe extension for RealPen's API reference: lazy re-exports and Sphinx roles.

Loaded by mkdocstrings (``mkdocs.yml``: ``extensions``). Two things the docstrings rely on that
griffe cannot see by itself:

- Packages re-export names lazily (``_HOMES`` read by :func:`realpen._lazy.lazy_attributes`),
  so ``realpen.Recording`` is no import statement. Each ``_HOMES`` entry becomes an alias, so the
  curated ``rp.*`` page lists those names and references to them resolve.
- The docstrings cross-reference with Sphinx roles (``:func:`realpen.x.y```,
  ``:class:`~realpen.x.Y```, ``:mod:`title <realpen.x>```). Each becomes an autorefs link
  (``[`y()`][realpen.x.y]``); a RealPen target that is not in the built site is then a warning,
  which ``mkdocs build --strict`` turns into a failure. Targets outside RealPen (numpy, scipy,
  the standard library) are rendered as code: the build reads no remote inventory.

A RealPen target that exists but is not public (a private name, a module name outside
``__all__``) is rendered as code too: the site documents the public API only.

Unqualified targets are looked up as Sphinx would find them: the docstring's own scope (its
object, its module's names and imports), then ``realpen.<name>`` (the curated API), then the one
public RealPen object of that name. A name that none of these find is a warning too.

Also mended for the Google-style parser and Markdown, without touching the source: ``Example:``
is read as the ``Examples:`` section (doctests rendered as code, not as text); an entry naming
several parameters (``fmin, fmax: band in Hz``) becomes one entry each; a paragraph that ends in
reST's ``::`` ends in ``:`` (the indented block after it stays a code block); doctest lines
outside an examples section are fenced as ``pycon``.
"""

from __future__ import annotations

import ast
import builtins
import importlib.util
import logging
import re
from collections.abc import Iterator

import griffe

__all__ = ["RealPenDocs"]

# mkdocs counts warnings of loggers under "mkdocs"; --strict fails the build on any of them.
log = logging.getLogger("mkdocs.plugins.realpen_docs")

PACKAGE = "realpen"
ROLE = re.compile(r":(?:py:)?(func|meth|class|exc|mod|data|attr|const|obj):`([^`]+)`")
CALLABLE_ROLES = {"func", "meth"}
TITLED = re.compile(r"(?s)(?P<title>.*?)\s*<(?P<target>[^<>]+)>")
DOCTEST = re.compile(r"^>>> |^>>>$")
EXAMPLE_HEADER = re.compile(r"^(?P<indent> *)Example:[ \t]*$", re.MULTILINE)
NAMED_SECTIONS = re.compile(r"^(?P<indent> *)(Args|Arguments|Parameters|Attributes|Keyword Args|"
                            r"Other Parameters):[ \t]*$")
SEVERAL_NAMES = re.compile(r"^(?P<indent> +)(?P<names>\*{0,2}\w+(?:, \*{0,2}\w+)+)(?P<rest>:.*)$")


class RealPenDocs(griffe.Extension):
    """Adds the lazy re-exports and rewrites every docstring's Sphinx roles (see the module)."""

    def on_package(self, *, pkg: griffe.Module, loader: griffe.GriffeLoader, **kwargs) -> None:
        if pkg.name != PACKAGE:
            return
        for module in _modules(pkg):
            _add_lazy_aliases(module)
        index = _name_index(pkg)
        for obj in _documented(pkg):
            text = EXAMPLE_HEADER.sub(r"\g<indent>Examples:", obj.docstring.value)
            text = _fence_doctests(_literal_blocks(_one_entry_per_name(text)))
            obj.docstring.value = ROLE.sub(lambda m, o=obj: _link(o, m, pkg, index), text)


def _modules(module: griffe.Module) -> Iterator[griffe.Module]:
    yield module
    for member in module.members.values():
        if not member.is_alias and member.is_module:
            yield from _modules(member)


def _documented(obj: griffe.Object) -> Iterator[griffe.Object]:
    if obj.docstring is not None:
        yield obj
    for member in obj.members.values():
        if not member.is_alias:
            yield from _documented(member)


def _add_lazy_aliases(module: griffe.Module) -> None:
    homes = module.members.get("_HOMES")
    if homes is None or homes.is_alias or homes.value is None:
        return
    for name, home in ast.literal_eval(str(homes.value)).items():
        if name not in module.members:
            module.set_member(name, griffe.Alias(name, f"{module.path}.{home}.{name}", parent=module))


def _name_index(pkg: griffe.Module) -> dict[str, list[str]]:
    """Every public object's dotted name suffixes (``Design.to_json``, ``to_json``) → paths."""
    index: dict[str, list[str]] = {}

    def visit(obj: griffe.Object) -> None:
        for name, member in obj.members.items():
            if member.is_alias or (name.startswith("_") and not name.startswith("__")):
                continue
            parts = member.path.split(".")
            for start in range(1, len(parts)):
                index.setdefault(".".join(parts[start:]), []).append(member.path)
            visit(member)

    visit(pkg)
    return index


def _link(obj: griffe.Object, match: re.Match[str], pkg: griffe.Module,
          index: dict[str, list[str]]) -> str:
    role, content = match.groups()
    titled = TITLED.fullmatch(content)
    title = titled["title"] if titled else None
    written = re.sub(r"\s+", "", titled["target"] if titled else content)
    short = written.startswith("~")
    target = written.lstrip("~.")
    if role in CALLABLE_ROLES and target.endswith("()"):
        target = target[:-2]
    if title is None:
        title = target.rsplit(".", 1)[-1] if short else target
        if role in CALLABLE_ROLES:
            title += "()"
    path = _resolve(obj, target, pkg, index)
    if path is None or _visibility(pkg, path) == "hidden":
        return f"`{title}`"
    return f"[`{title}`][{path}]"


def _visibility(pkg: griffe.Module, path: str) -> str:
    """``"public"`` (in the site), ``"hidden"`` (exists, not public) or ``"missing"``.

    A hidden target (a private name, a module name left out of ``__all__``) is rendered as code:
    it exists, but the site documents the public API only. A missing one stays a link, which
    autorefs then reports.
    """
    obj: griffe.Object | griffe.Alias = pkg
    hidden = False
    for part in path.split(".")[1:]:
        if obj.is_alias:
            try:
                obj = obj.final_target
            except (griffe.AliasResolutionError, griffe.CyclicAliasError):
                return "public"  # outside RealPen: autorefs decides
        member = obj.members.get(part)
        if member is None and obj.is_class:
            member = obj.all_members.get(part)  # inherited
        if member is None:
            return "missing"
        hidden = hidden or not member.is_public
        obj = member
    return "hidden" if hidden else "public"


def _resolve(obj: griffe.Object, target: str, pkg: griffe.Module,
             index: dict[str, list[str]]) -> str | None:
    """The RealPen path a role points at, None for an outside target (rendered as code)."""
    if target == PACKAGE or target.startswith(PACKAGE + "."):
        return target  # autorefs checks that the built site has it
    first, _, rest = target.partition(".")
    try:
        found = obj.resolve(first)
    except (griffe.NameResolutionError, ValueError, AttributeError, KeyError):
        found = None
    if found is not None:
        if found != PACKAGE and not found.startswith(PACKAGE + "."):
            return None
        return f"{found}.{rest}" if rest else found
    if first in vars(builtins) or _is_outside_module(first):
        return None
    if first in pkg.members:
        return f"{PACKAGE}.{target}"
    module = obj if obj.is_module else obj.module
    local = [path for path in index.get(target, []) if path.startswith(module.path + ".")]
    candidates = local or index.get(target, [])
    if len(candidates) == 1:
        return candidates[0]
    where = f"{obj.docstring.parent.relative_filepath}:{obj.docstring.lineno}"
    reason = "is ambiguous: " + ", ".join(candidates) if candidates else "names nothing in RealPen"
    log.warning("%s: the reference %r in the docstring of %s %s", where, target, obj.path, reason)
    return None


def _is_outside_module(name: str) -> bool:
    if name == PACKAGE:
        return False
    try:
        return importlib.util.find_spec(name) is not None
    except (ImportError, ValueError):
        return False


def _literal_blocks(text: str) -> str:
    """reST's ``text::`` before an indented block: Markdown wants ``text:`` (the block stays)."""
    lines = text.split("\n")
    for number, line in enumerate(lines):
        if line.rstrip().endswith("::") and not line.lstrip().startswith(">>>"):
            stripped = line.rstrip()[:-2].rstrip()
            lines[number] = stripped + ":" if stripped.strip() else ""
    return "\n".join(lines)


def _fence_doctests(text: str) -> str:
    """Doctest lines at the docstring's own margin (not in an ``Example:`` section) as code."""
    lines = text.split("\n")
    out: list[str] = []
    fenced = False
    for line in lines:
        if not fenced and DOCTEST.match(line):
            if out and out[-1].strip():
                out.append("")
            out.append("```pycon")
            fenced = True
        elif fenced and not line.strip():
            out.append("```")
            fenced = False
        out.append(line)
    if fenced:
        out.append("```")
    return "\n".join(out)


def _one_entry_per_name(text: str) -> str:
    """``a, b: text`` in an Args or Attributes section as ``a: text`` and ``b: text``."""
    lines = text.split("\n")
    out: list[str] = []
    section_indent: int | None = None
    number = 0
    while number < len(lines):
        line = lines[number]
        number += 1
        header = NAMED_SECTIONS.match(line)
        if header:
            section_indent = len(header["indent"])
        elif line.strip() and section_indent is not None and \
                len(line) - len(line.lstrip()) <= section_indent:
            section_indent = None
        entry = SEVERAL_NAMES.match(line) if section_indent is not None else None
        if entry is None or len(entry["indent"]) <= section_indent:
            out.append(line)
            continue
        body = [entry["rest"]]
        while number < len(lines) and (not lines[number].strip() or
                                       len(lines[number]) - len(lines[number].lstrip())
                                       > len(entry["indent"])):
            body.append("\n" + lines[number])
            number += 1
        for name in entry["names"].split(", "):
            out.append(entry["indent"] + name + "".join(body))
    return "\n".join(out)
