"""The code blocks of docs/exports.md that the exports write, regenerated from the exports.

A block is marked by the command that writes it and the file it comes from::

    <!-- snippet: realpen export pencil -o pencil.ahap → pencil.swift -->
    ```swift
    ...
    ```

``FILE#usage`` takes the usage example out of a C header's comment. Run
``python scripts/docs/export_snippets.py`` to rewrite the blocks after the exports change;
``--check`` exits 1 when a block differs (tests/test_export_snippets.py runs it).
"""

from __future__ import annotations

import re
import sys
import tempfile
from pathlib import Path

PAGE = Path(__file__).resolve().parents[2] / "docs" / "exports.md"
MARKER = re.compile(r"(<!-- snippet: realpen export (?P<pen>\S+) -o (?P<out>\S+) → "
                    r"(?P<file>[^ #]+)(?P<usage>#usage)? -->\n```\w*\n)(?P<body>.*?)(?P<close>```\n)",
                    re.S)


def written(pen: str, out: str, file: str, usage: bool) -> str:
    """The text the export of ``pen`` to ``out`` writes in ``file`` (for ``usage``: the usage
    example of a C header's comment)."""
    from realpen.exports import export_profile, format_for_suffix
    from realpen.profile.registry import resolve_profile

    with tempfile.TemporaryDirectory() as folder:
        export_profile(resolve_profile(pen), format_for_suffix(Path(out)), Path(folder) / out)
        text = (Path(folder) / file).read_text(encoding="utf-8")
    if usage:
        comment = text[:text.index("*/")]
        lines = comment.split(" * Playing it", 1)[1].splitlines()[2:]
        text = "\n".join(line[3:] if line.startswith(" * ") else line[2:] for line in lines)
        text = text.rstrip() + "\n"
    return text


def regenerate(page: str) -> str:
    """``page`` with every marked block replaced by what the export writes."""
    def replace(match: re.Match) -> str:
        body = written(match["pen"], match["out"], match["file"], bool(match["usage"]))
        return match.group(1) + body + match["close"]
    return MARKER.sub(replace, page)


def main(argv: list[str]) -> int:
    page = PAGE.read_text(encoding="utf-8")
    fresh = regenerate(page)
    if "--check" in argv:
        if fresh != page:
            print(f"{PAGE}: code blocks differ from what the exports write; run "
                  f"python scripts/docs/export_snippets.py", file=sys.stderr)
            return 1
        return 0
    PAGE.write_text(fresh, encoding="utf-8")
    print(f"{PAGE}: {len(MARKER.findall(page))} blocks regenerated")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
