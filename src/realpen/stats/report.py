"""The self-contained HTML report of a study analysis: ``report.html``.

:func:`write_report` turns a :class:`realpen.stats.outcome.StudyAnalysis` and its figures
(:func:`realpen.stats.figure_plan.save_study_figures`) into one HTML file that opens
offline and prints: the figures are embedded as ``data:`` URIs, the style is a ``<style>``
block, and nothing refers to another file or to the network. Every value that comes from the
data (participant codes, outcome names, notes, the source's name) is escaped.

The sections, in order: title; the data source and options; what the data are (participants,
excluded ones and why); the methods (verbatim); the results per analysis, each test with its
APA-style sentence and the number of its method in a list that gives each distinct method once
(numbers that repeat the paper's choices marked ``paper-compatible`` and the reason); the
paper's numbers beside ours, each comparison as two sentences written the same way; notes; the
figures with captions; the per-cell means; power, if simulated; the software versions.
"""

from __future__ import annotations

import base64
import html
import math
import os
import re
from collections.abc import Iterable, Sequence
from pathlib import Path

import pandas as pd

from realpen.errors import ParameterError, fail
from realpen.io.files import atomic_path
from realpen.stats.figure_plan import figure_captions
from realpen.stats.paper import comparison_table
from realpen.stats.power_plot import split_power
from realpen.stats.results import PAPER_COMPATIBLE, RESULT_COLUMNS, completed
from realpen.stats.texts import software_versions

__all__ = ["write_report", "report_html", "format_p", "format_df", "format_number",
           "software_versions", "method_list"]

REPORT_NAME = "report.html"
DASH = "—"
_MIME = {".svg": "image/svg+xml", ".png": "image/png"}

_CSS = """
body { font: 15px/1.45 system-ui, -apple-system, "Segoe UI", Roboto, sans-serif; color: #1a1a1a;
       max-width: 80rem; margin: 1.5rem auto; padding: 0 1rem; }
h1 { font-size: 1.6rem; margin-bottom: .2rem; }
h2 { font-size: 1.25rem; border-bottom: 1px solid #ccc; padding-bottom: .2rem; margin-top: 2rem; }
h3 { font-size: 1.05rem; margin: 1.2rem 0 .4rem; font-family: ui-monospace, monospace; }
table { border-collapse: collapse; margin: .4rem 0 1rem; font-size: .88rem; }
th, td { border-bottom: 1px solid #ddd; padding: .25rem .55rem; text-align: left;
         vertical-align: top; }
th { background: #f3f3f3; font-weight: 600; }
td.num { text-align: right; font-variant-numeric: tabular-nums; white-space: nowrap; }
td.key { white-space: nowrap; }
td.method { font-size: .8rem; color: #444; }
td.details { font-size: .8rem; color: #444; min-width: 10rem; }
td.apa { min-width: 15rem; }
ol.methods li { margin: .25rem 0; font-size: .88rem; max-width: 60rem; }
ol.methods li:target { background: #fff4e0; }
.wide { overflow-x: auto; }
tr.paper-compatible td { background: #fff4e0; }
.badge { display: inline-block; font-size: .72rem; font-weight: 600; padding: 0 .4rem;
         border: 1px solid #b35900; border-radius: .6rem; color: #8a4500; background: #ffe7c2;
         white-space: nowrap; }
figure { margin: 1rem 0 2rem; }
figure img { max-width: 100%; height: auto; border: 1px solid #eee; }
figcaption { font-size: .88rem; color: #333; margin-top: .3rem; }
.methods p { max-width: 50rem; }
.muted { color: #666; }
ul.notes li { margin: .2rem 0; }
@media print {
  body { font-size: 10pt; max-width: none; margin: 0; }
  h2 { break-after: avoid; }
  figure, tr { break-inside: avoid; }
  .wide { overflow: visible; }
  tr.paper-compatible td, th, .badge { -webkit-print-color-adjust: exact; print-color-adjust: exact; }
}
"""


# --------------------------------------------------------------------------- numbers

def _finite(value: object) -> float | None:
    try:
        number = float(value)
    except (TypeError, ValueError):
        return None
    return number if math.isfinite(number) else None


def format_p(p: object) -> str:
    """A p-value as a report shows it: ``< .001``, else 3 decimals without the leading zero.

    Examples:
        >>> format_p(0.0004), format_p(0.02512), format_p(1.0), format_p(float("nan"))
        ('< .001', '.025', '1.000', '—')
    """
    number = _finite(p)
    if number is None:
        return DASH
    if number < 0.001:
        return "< .001"
    text = f"{number:.3f}"
    return text[1:] if text.startswith("0.") else text


def format_df(df: object) -> str:
    """Degrees of freedom: an integer when whole, else 2 decimals (corrected df).

    Examples:
        >>> format_df(22.0), format_df(29.8412), format_df(None)
        ('22', '29.84', '—')
    """
    number = _finite(df)
    if number is None:
        return DASH
    if abs(number - round(number)) < 1e-9:
        return str(int(round(number)))
    return f"{number:.2f}"


def format_number(value: object, digits: int = 3) -> str:
    """A statistic or effect size with ``digits`` decimals (a rounded zero has no minus sign);
    missing or non-finite values are a dash.

    Examples:
        >>> format_number(8.2114), format_number(-0.5), format_number(1934.2, 0)
        ('8.211', '-0.500', '1934')
        >>> format_number(-0.0001)
        '0.000'
    """
    number = _finite(value)
    if number is None:
        return DASH
    text = f"{number:.{digits}f}"
    return text[1:] if text.startswith("-") and float(text) == 0 else text  # no "-0.000"


def _quantity(value: object, quantity: str) -> str:
    """A number of the paper table, formatted by what it is."""
    if quantity.lower() in ("p", "p_value", "p_adjusted"):
        return format_p(value)
    if quantity.lower().startswith("df"):
        return format_df(value)
    number = _finite(value)
    if number is not None and abs(number - round(number)) < 1e-9 and abs(number) >= 10:
        return str(int(round(number)))
    return format_number(value)


# --------------------------------------------------------------------------- html pieces

def _e(value: object) -> str:
    """Any value as escaped HTML text (NaN and None as a dash)."""
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return DASH
    return html.escape(str(value), quote=True)


def _table(header: Sequence[str], rows: Iterable[Sequence[str]], *, row_classes=None,
           numeric: Iterable[int] = (), keys: Iterable[int] = ()) -> str:
    """An HTML table; ``rows`` hold cell HTML (already escaped). ``numeric`` columns are right
    aligned, ``keys`` columns (names a reader scans for) do not wrap."""
    numeric, keys = set(numeric), set(keys)
    head = "".join(f"<th>{_e(name)}</th>" for name in header)
    body = []
    for k, row in enumerate(rows):
        css = f' class="{row_classes[k]}"' if row_classes and row_classes[k] else ""
        cells = "".join(f'<td class="num">{cell}</td>' if j in numeric else
                        f'<td class="key">{cell}</td>' if j in keys else
                        f'<td class="{_CELL_CLASSES[header[j]]}">{cell}</td>'
                        if header[j] in _CELL_CLASSES else
                        f"<td>{cell}</td>" for j, cell in enumerate(row))
        body.append(f"<tr{css}>{cells}</tr>")
    return (f'<div class="wide"><table><thead><tr>{head}</tr></thead>'
            f"<tbody>{''.join(body)}</tbody></table></div>")


_CELL_CLASSES = {"method": "method", "details": "details", "APA-style": "apa", "paper": "apa",
                 "ours": "apa"}


def _frame(analysis, name: str) -> pd.DataFrame:
    frame = getattr(analysis, name, None)
    return frame if isinstance(frame, pd.DataFrame) else pd.DataFrame()


def _paper_reason(method: str) -> str:
    """What a ``paper-compatible: ...`` method says after its mark."""
    rest = method[len(PAPER_COMPATIBLE):]
    return rest.lstrip(" :;,—–-") or "repeats the paper's choice"


def _source_section(analysis) -> str:
    rows = [("design", _e(analysis.design)), ("data", _e(analysis.source or "(not given)"))]
    rows += [(_e(name), _e(value)) for name, value in (analysis.options or {}).items()]
    return ('<section id="source"><h2>Data source and options</h2>'
            + _table(("setting", "value"), rows) + "</section>")


def _participant_codes(analysis) -> list[str]:
    for name in ("participants", "cells"):
        frame = _frame(analysis, name)
        if "participant" in frame.columns and len(frame):
            return list(dict.fromkeys(frame["participant"].astype(str)))
    return []


def _data_section(analysis) -> str:
    codes = _participant_codes(analysis)
    results = _frame(analysis, "results")
    parts = ['<section id="data"><h2>The data</h2>']
    if codes:
        parts.append(f"<p>{len(codes)} participant{'s' if len(codes) != 1 else ''} analysed: "
                     f"{', '.join(_e(code) for code in codes)}.</p>")
    elif "n" in results.columns and results["n"].notna().any():
        parts.append(f"<p>Up to {int(results['n'].max())} subjects per test.</p>")
    for name in ("cells", "results"):
        frame = _frame(analysis, name)
        if name == "cells" and "outcome" in frame.columns and len(frame):
            outcomes = list(dict.fromkeys(frame["outcome"].astype(str)))
            parts.append(f"<p>Outcomes: {', '.join(_e(o) for o in outcomes)}.</p>")
        elif name == "results":
            parts.append(f"<p>{len(frame)} test result{'s' if len(frame) != 1 else ''} "
                         f"(results.csv).</p>")
    excluded = analysis.excluded or {}
    if excluded:
        parts.append(f"<p>Left out of the outcomes whose planned cells they miss (and kept in "
                     f"the others): {len(excluded)} participant"
                     f"{'s' if len(excluded) != 1 else ''}.</p>")
        parts.append(_table(("participant", "reason"),
                            [(_e(code), _e(reason)) for code, reason in excluded.items()]))
    else:
        parts.append('<p class="muted">No participant was excluded.</p>')
    parts.append("</section>")
    return "".join(parts)


def _methods_section(analysis) -> str:
    paragraphs = "".join(f"<p>{_e(text)}</p>" for text in analysis.methods or [])
    return ('<section id="methods" class="methods"><h2>Methods</h2>'
            + (paragraphs or '<p class="muted">No methods text was given.</p>') + "</section>")


_TOKEN = re.compile(r"\d+(?:\.\d+)?(?:e[-+]?\d+)?|[^\W\d]+|\s+|.")
_PART = re.compile(r"[^;,]+")
_DETAIL_MAX = 48
"""A part of a method (between ``;`` or ``,``) that differs between rows is shown beside the row
when at most this long; a longer one only in the method list (and whole in results.csv)."""
_MERGE_TOKENS = 8
"""Methods that differ in at most this many words, numbers or signs are listed as one."""
VARIES = "…"
"""Stands in a listed method for what differs between the rows using it."""


def _opcodes(first: list[str], other: list[str]) -> list[tuple[str, int, int, int, int]] | None:
    """How ``other`` differs from ``first`` (difflib opcodes), or None when the two differ in
    more than :data:`_MERGE_TOKENS` tokens (then they are two methods)."""
    import difflib

    codes = difflib.SequenceMatcher(None, first, other, autojunk=False).get_opcodes()
    changed = sum(max(i2 - i1, j2 - j1) for tag, i1, i2, j1, j2 in codes if tag != "equal")
    return codes if changed <= _MERGE_TOKENS else None


def method_list(methods: Sequence[str]) -> tuple[list[str], list[int], list[str]]:
    """Each distinct method once, and what each row adds to it.

    Methods that differ only in a few words or numbers (the zeros a Wilcoxon test dropped, a
    sphericity test's W and p, the level a test is of) are one method, listed with
    :data:`VARIES` where they differ; each row's details are the short parts of its own
    method (between ``;`` or ``,``) that differ.

    Args:
        methods: each row's ``method``, in row order.

    Returns:
        ``(texts, numbers, details)``: the distinct methods in order of first use, each row's
        number in that list (from 1), each row's details (``""`` when none).

    Examples:
        >>> texts, numbers, details = method_list(["exact; zeros dropped (2)",
        ...                                        "exact; zeros dropped (3)", "spss"])
        >>> texts, numbers, details
        (['exact; zeros dropped (…)', 'spss'], [1, 1, 2], ['zeros dropped (2)', 'zeros dropped (3)', ''])
    """
    tokens = [list(_TOKEN.finditer(text)) for text in methods]
    words = [[match.group(0) for match in found] for found in tokens]
    groups: list[tuple[int, list[int]]] = []  # (the first row, every row)
    codes: dict[int, list[tuple[str, int, int, int, int]]] = {}  # row -> against its first
    for row in range(len(methods)):
        for first, members in groups:
            found = _opcodes(words[first], words[row])
            if found is not None:
                members.append(row)
                codes[row] = found
                break
        else:
            groups.append((row, [row]))
            codes[row] = [("equal", 0, len(words[row]), 0, len(words[row]))]
    texts: list[str] = []
    numbers = [0] * len(methods)
    details = [""] * len(methods)
    for first, members in groups:
        # Positions of the first row's tokens that some row changes (2k: token k, 2k - 1: the
        # gap before it, where a row inserts).
        marks: set[int] = set()
        for row in members:
            for tag, i1, i2, _, _ in codes[row]:
                if tag != "equal":
                    marks.update(range(2 * i1, 2 * i2, 2) if i2 > i1 else {2 * i1 - 1})
        template, previous = [], False
        for position, word in enumerate(words[first]):
            varies = 2 * position in marks and not word.isspace()
            if (varies or 2 * position - 1 in marks) and not previous:
                template.append(VARIES)
            if not varies:
                template.append(word)
            previous = varies
        if 2 * len(words[first]) - 1 in marks and not previous:
            template.append(VARIES)
        texts.append("".join(template))
        for row in members:
            numbers[row] = len(texts)
            own: set[int] = set()  # this row's tokens where the rows differ
            for tag, i1, i2, j1, j2 in codes[row]:
                if tag != "equal":
                    own.update(range(j1, j2))
                else:
                    own.update(j1 + k for k in range(i2 - i1) if 2 * (i1 + k) in marks)
            spans = [tokens[row][k].span() for k in own if not words[row][k].isspace()]
            parts = [part.group(0).strip() for part in _PART.finditer(methods[row])
                     if any(part.start() <= a and b <= part.end() for a, b in spans)]
            details[row] = ", ".join(part for part in parts if len(part) <= _DETAIL_MAX)
    return texts, numbers, details


def _results_section(analysis) -> str:
    results = _frame(analysis, "results")
    parts = ['<section id="results"><h2>Results</h2>']
    missing = [c for c in RESULT_COLUMNS if c not in results.columns and
               c not in ("apa", "level_a", "level_b")]
    if results.empty or missing:
        parts.append('<p class="muted">No test results.</p></section>')
        return "".join(parts)
    results = completed(results)
    marked = results["method"].astype(str).str.startswith(PAPER_COMPATIBLE)
    if marked.any():
        parts.append(f'<p><span class="badge">{PAPER_COMPATIBLE}</span> marks numbers that '
                     "repeat the paper's choices; they are not recommended, for the reason "
                     "given in their method.</p>")
    texts, numbers, details = method_list(results["method"].astype(str).tolist())
    parts.append("<p>Each row gives its result as an APA-style sentence to paste, and the number "
                 'of its method in the <a href="#test-methods">list below the tables</a> (with '
                 "the row's own numbers beside it; results.csv has each row's full method).</p>")
    header = ("outcome", "effect", "test", "APA-style", "statistic", "value", "df1", "df2", "p",
              "p adjusted", "adjust", "effect size", "value", "n", "method", "details")
    for name, group in results.groupby("analysis", sort=False):
        rows, classes = [], []
        for index, row in zip(group.index, group.itertuples(index=False)):
            paper = str(row.method).startswith(PAPER_COMPATIBLE)
            test = _e(row.test) + (f'<br><span class="badge">{PAPER_COMPATIBLE}</span>'
                                   if paper else "")
            n = _finite(row.n)
            number = numbers[index]
            rows.append((_e(row.outcome), _e(row.effect), test, _e(row.apa or DASH),
                         _e(row.statistic_name), format_number(row.statistic),
                         format_df(row.df1), format_df(row.df2), _e(format_p(row.p)),
                         _e(format_p(row.p_adjusted)), _e(row.adjust),
                         _e(row.effect_size_name or ""), format_number(row.effect_size),
                         DASH if n is None else str(int(n)),
                         f'<a href="#method-{number}">[{number}]</a>', _e(details[index])))
            classes.append(PAPER_COMPATIBLE if paper else "")
        parts.append(f"<h3>{_e(name)}</h3>")
        parts.append(_table(header, rows, row_classes=classes,
                            numeric=(5, 6, 7, 8, 9, 12, 13), keys=(0, 1)))
    items = "".join(f'<li id="method-{k}">'
                    + (f'<span class="badge">{PAPER_COMPATIBLE}</span> {_e(_paper_reason(text))}'
                       if text.startswith(PAPER_COMPATIBLE) else _e(text)) + "</li>"
                    for k, text in enumerate(texts, start=1))
    parts.append(f'<h3 id="test-methods">How each row was computed</h3>'
                 f"<p>{VARIES} stands for a number that differs between the rows using the "
                 f'method: it is in the row\'s details.</p><ol class="methods">{items}</ol>')
    parts.append("</section>")
    return "".join(parts)


def _paper_section(analysis) -> str:
    paper = _frame(analysis, "paper")
    if paper.empty:
        return ""
    comparisons = comparison_table(analysis)
    rows = [(_e(row.analysis), _e(row.outcome), _e(row.effect), _e(row.paper or DASH),
             _e(row.ours or DASH), _e(row.note or ""))
            for row in comparisons.itertuples(index=False)]
    numbers = []
    for row in paper.itertuples(index=False):
        quantity = str(getattr(row, "quantity", ""))
        reported = getattr(row, "reported", "")
        # A bound (< .001) or "n.s." as the paper printed it, not as a number
        shown = (str(reported) if isinstance(reported, str) and reported
                 and (reported.startswith("<") or _finite(row.paper) is None)
                 else _quantity(row.paper, quantity))
        numbers.append((_e(row.analysis), _e(row.outcome), _e(row.effect), _e(quantity),
                        _e(shown), _e(_quantity(row.ours, quantity))))
    return ('<section id="paper"><h2>The paper\'s numbers beside ours</h2>'
            "<p>Each comparison written the same way for the paper and for us (a dash: not "
            "given). Where the paper's choice differs from ours, the paper-compatible row that "
            "repeats it is listed too, when the analysis gives the paper-compatible numbers.</p>"
            + _table(("analysis", "outcome", "effect", "paper", "ours", "note"), rows,
                     keys=(0, 1, 2))
            + "<details><summary>Every number (paper.csv)</summary>"
            + _table(("analysis", "outcome", "effect", "quantity", "paper", "ours"), numbers,
                     numeric=(4, 5))
            + "</details></section>")


def _notes_section(analysis) -> str:
    if not analysis.notes:
        return ""
    items = "".join(f"<li>{_e(note)}</li>" for note in analysis.notes)
    return f'<section id="notes"><h2>Notes</h2><ul class="notes">{items}</ul></section>'


def _embedded(figures: Sequence[str | os.PathLike]) -> dict[str, Path]:
    """One file per figure (SVG preferred, else PNG), by figure name, in the given order."""
    chosen: dict[str, Path] = {}
    for item in figures:
        path = Path(item)
        suffix = path.suffix.lower()
        if suffix not in _MIME:
            continue  # other formats (pdf) are written for readers, not embedded
        if not path.is_file():
            raise fail(path, "no such file (a figure of the report)")
        if path.stem not in chosen or (suffix == ".svg" and chosen[path.stem].suffix != ".svg"):
            chosen[path.stem] = path
    return chosen


def _caption_html(name: str, caption: str) -> str:
    """``Figure 7.`` captions start with their number in bold; the others with their name."""
    if caption.startswith("Figure "):
        number, _, rest = caption.partition(". ")
        return f"<b>{_e(number)}.</b> {_e(rest)}"
    return f"<b>{_e(name)}.</b> {_e(caption)}"


def _figures_section(analysis, figures: Sequence[str | os.PathLike]) -> str:
    chosen = _embedded(figures)
    parts = ['<section id="figures"><h2>Figures</h2>']
    if not chosen:
        parts.append('<p class="muted">No figures.</p>')
    captions = figure_captions(analysis)
    for name, path in chosen.items():
        caption = captions.get(name, name)
        data = base64.b64encode(path.read_bytes()).decode("ascii")
        parts.append(f'<figure id="figure-{_e(name)}"><img src="data:{_MIME[path.suffix.lower()]};'
                     f'base64,{data}" alt="{_e(caption)}"><figcaption>{_caption_html(name, caption)}'
                     "</figcaption></figure>")
    parts.append("</section>")
    return "".join(parts)


def _cells_section(analysis) -> str:
    cells = _frame(analysis, "cells")
    parts = ['<section id="cells"><h2>Means per cell</h2>']
    needed = ("outcome", "factor", "level", "mean", "ci_low", "ci_high")
    if cells.empty or any(c not in cells.columns for c in needed):
        parts.append('<p class="muted">No cell means.</p></section>')
        return "".join(parts)
    rows = []
    for row in cells.itertuples(index=False):
        unit = str(getattr(row, "unit", "") or "")
        digits = 0 if unit == "ms" else 2
        interval = f"{format_number(row.ci_low, digits)} – {format_number(row.ci_high, digits)}"
        n = _finite(getattr(row, "n", None))
        rows.append((_e(row.outcome), _e(row.factor), _e(row.level),
                     format_number(row.mean, digits), _e(interval),
                     _e(getattr(row, "ci_method", "")), DASH if n is None else str(int(n)),
                     _e(unit)))
    parts.append(_table(("outcome", "factor", "level", "mean", "95 % CI", "CI method", "n",
                         "unit"), rows, numeric=(3, 4, 6)))
    parts.append("</section>")
    return "".join(parts)


def _power_section(analysis) -> str:
    power = getattr(analysis, "power", None)
    if power is None or len(power) == 0:
        return ""
    curves, detectable = split_power(power)
    parts = ['<section id="power"><h2>Power</h2>']
    if len(detectable):
        extra = [name for name in ("parameter", "note") if name in detectable.columns]
        rows = [(_e(r.outcome), _e(r.test), format_df(r.participants),
                 *([_e(r.parameter)] if "parameter" in extra else []),
                 format_number(r.effect_size), format_number(r.power, 2),
                 *([_e(r.note or "")] if "note" in extra else []))
                for r in detectable.itertuples(index=False)]
        header = ("outcome", "test", "participants", *(["parameter"] if "parameter" in extra
                                                       else []),
                  "smallest effect", "power there", *(["note"] if "note" in extra else []))
        parts.append("<p>The smallest effect each main test detects with 80 % power, by "
                     "simulation (a dash: not reached within the range searched; see the "
                     "note):</p>")
        parts.append(_table(header, rows, numeric=(2, header.index("smallest effect"),
                                                   header.index("power there"))))
    if len(curves):
        sims = "sims" in curves.columns
        rows = [(_e(r.outcome), _e(r.effect), _e(r.test), format_df(r.participants),
                 format_number(r.effect_size), format_number(r.power, 2),
                 *([format_df(r.sims)] if sims else []))
                for r in curves.itertuples(index=False)]
        parts.append("<p>Simulated power per number of participants and effect size:</p>")
        parts.append(_table(("outcome", "effect", "test", "participants", "effect size", "power",
                             *(["simulations"] if sims else [])), rows,
                            numeric=(3, 4, 5, 6)))
    parts.append("</section>")
    return "".join(parts)


def _software_section() -> str:
    rows = [(_e(name), _e(version)) for name, version in software_versions().items()]
    return ('<section id="software"><h2>Software</h2>'
            + _table(("software", "version"), rows) + "</section>")


# --------------------------------------------------------------------------- the report

def report_html(analysis, figures: Sequence[str | os.PathLike] = ()) -> str:
    """The report of ``analysis`` as one HTML document (a string); see :func:`write_report`.

    Examples:
        >>> import pandas as pd
        >>> from realpen.stats.outcome import StudyAnalysis
        >>> empty = pd.DataFrame()
        >>> text = report_html(StudyAnalysis("study1", "Study <1>", empty, empty, empty, empty,
        ...                                  empty, methods=["Friedman tests."]))
        >>> "<h1>Study &lt;1&gt;</h1>" in text, "<p>Friedman tests.</p>" in text
        (True, True)
    """
    body = [f"<h1>{_e(analysis.title)}</h1>",
            f'<p class="muted">RealPen study analysis of design {_e(analysis.design)}.</p>',
            _source_section(analysis), _data_section(analysis), _methods_section(analysis),
            _results_section(analysis), _paper_section(analysis), _notes_section(analysis),
            _figures_section(analysis, figures), _cells_section(analysis),
            _power_section(analysis), _software_section()]
    return ("<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
            "<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">"
            f"<title>{_e(analysis.title)}</title><style>{_CSS}</style></head><body>"
            + "\n".join(part for part in body if part) + "</body></html>\n")


def write_report(analysis, directory: str | os.PathLike,
                 figures: Sequence[str | os.PathLike]) -> Path:
    """Write ``report.html`` for ``analysis`` into ``directory``, atomically, and return its path.

    The file is self-contained: each figure is embedded as a ``data:`` URI (the SVG of a
    figure when there is one, else its PNG; other formats are skipped), the style is inline,
    and there is no link to another file or to the network, so it opens offline and can be
    mailed as it is. Tables come from the analysis as they are (no statistic is computed
    here): p as ``< .001`` or 3 decimals, statistics and effect sizes with 3, df as integers
    when whole (else 2 decimals); each row with its APA-style sentence (the ``apa`` column,
    written from the row where missing) and the number of its method in a list that gives
    each distinct method once (:func:`method_list`); rows whose ``method`` starts with
    ``paper-compatible`` carry a badge, and their method the reason. The paper's numbers are
    set beside ours as sentences (:func:`realpen.stats.paper.comparison_table`). Software
    versions come from :mod:`importlib.metadata`.

    Args:
        analysis: a :class:`realpen.stats.outcome.StudyAnalysis`.
        directory: the folder to write into (made if missing).
        figures: the figure files to embed, as :func:`realpen.stats.figure_plan.
            save_study_figures` returns them (shown in this order, captioned by name).

    Returns:
        The path of ``report.html``.

    Raises:
        RealPenError: a figure file is missing, or the folder cannot be written.

    Examples:
        >>> import pandas as pd, tempfile
        >>> from realpen.stats.outcome import StudyAnalysis
        >>> empty = pd.DataFrame()
        >>> analysis = StudyAnalysis("study1", "Study 1", empty, empty, empty, empty, empty)
        >>> with tempfile.TemporaryDirectory() as folder:
        ...     write_report(analysis, folder, []).name
        'report.html'
    """
    if isinstance(figures, (str, os.PathLike)):
        raise ParameterError("figures", "must be a list of figure files, not one path")
    text = report_html(analysis, list(figures))
    target = Path(directory) / REPORT_NAME
    with atomic_path(target) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return target
