"""The code the exports write for app developers (realpen.exports.snippets) and that
docs/exports.md shows: the page shows exactly what the exports write, the Swift and C# players
compute Eq. 1 as RealPen does, and the C header's usage example compiles and loops its table."""

from __future__ import annotations

import importlib.util
import re
import shutil
import subprocess
from pathlib import Path

import pytest

from realpen.exports import export_profile, render
from realpen.motion.coupling import Coupling
from realpen.profile.registry import resolve_profile
from realpen.tactile.pattern import Component, TactilePattern

ROOT = Path(__file__).resolve().parents[1]
ODD = Coupling(c_p=0.7321, c_op=0.05, c_x=0.0173, c_ov=9.5, a_max=1.7)
POINTS = [(0.0, 50.0), (0.5, 50.0), (1.0, 200.0), (0.2, 5.0), (0.3, 30.0), (-0.1, 40.0)]


def snippet_script():
    spec = importlib.util.spec_from_file_location("export_snippets",
                                                  ROOT / "scripts" / "docs" / "export_snippets.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_docs_page_shows_what_the_exports_write():
    script = snippet_script()
    page = script.PAGE.read_text(encoding="utf-8")
    files = sorted(match["file"] + (match["usage"] or "") for match in script.MARKER.finditer(page))
    assert files == ["PencilPenHaptics.cs", "pencil.kt", "pencil.swift", "pencil_tactile.h#usage"]
    assert script.regenerate(page) == page, \
        "docs/exports.md: run python scripts/docs/export_snippets.py"
    assert "  - Exports for app developers: exports.md" in \
        (ROOT / "mkdocs.yml").read_text(encoding="utf-8")


def translated_gain(source: str, signature: str, rules: list[tuple[str, str]]):
    """A player's gain function run as Python: its body translated line by line."""
    body = re.search(re.escape(signature) + r"\s*\{\n(.*?)\n    \}", source, re.S).group(1)
    lines = []
    for line in body.strip().splitlines():
        line = line.strip().rstrip(";")
        for pattern, replacement in rules:
            line = re.sub(pattern, replacement, line)
        lines.append("    " + line)
    return "def gain(pressure, speedMmS):\n" + "\n".join(lines)


def run_gain(code: str, constants: dict[str, float]):
    namespace = dict(constants)
    exec(code, namespace)
    return namespace["gain"]


def players(tmp_path: Path):
    """(coupling, swift, c#) for the pencil and for a pattern with an unusual coupling."""
    pencil = resolve_profile("pencil")
    export_profile(pencil, "ahap", tmp_path / "pencil.ahap")
    export_profile(pencil, "haptic", tmp_path / "pencil.haptic")
    yield pencil.coupling, (tmp_path / "pencil.swift").read_text(), \
        (tmp_path / "PencilPenHaptics.cs").read_text()
    pattern = TactilePattern([[Component(175.0, 0.5)], [Component(90.0, 0.4)]])
    ahap = render("ahap", pattern, coupling=ODD, name="odd pen")
    haptic = render("haptic", pattern, coupling=ODD, name="odd pen")
    yield ODD, ahap.companions["odd pen.swift"].decode(), \
        haptic.companions["OddPenHaptics.cs"].decode()


def test_the_players_compute_eq1_as_realpen_does(tmp_path):
    for coupling, swift, csharp in players(tmp_path):
        swift_constants = {name: float(value) for name, value in
                           re.findall(r"static let (\w+): Float = ([-+0-9.eE]+)", swift)}
        assert swift_constants == {"cP": coupling.c_p, "cOP": coupling.c_op, "cX": coupling.c_x,
                                   "cOV": coupling.c_ov, "aMax": coupling.a_max}
        swift_gain = run_gain(translated_gain(
            swift, "static func gain(pressure: Float, speedMmS: Float) -> Float",
            [(r"^if (.*) \{ return (.*) \}$", r"if \1: return \2"), (r"^let ", "")]),
            swift_constants)
        csharp_constants = {name: float(value) for name, value in
                            re.findall(r"public const float (\w+) = ([-+0-9.eE]+)f;", csharp)}
        assert csharp_constants == {"CP": coupling.c_p, "COP": coupling.c_op,
                                    "CX": coupling.c_x, "COV": coupling.c_ov,
                                    "AMax": coupling.a_max}
        csharp_gain = run_gain(translated_gain(
            csharp, "public static float Gain(float pressure, float speedMmS)",
            [(r"\b(\d+)f\b", r"\1.0"), (r"^if \((.*)\) return (.*)$", r"if \1: return \2"),
             (r"^float ", ""), (r"Mathf\.Clamp\((\w+), ([^,]+), (\w+)\)", r"min(max(\1, \2), \3)")]),
            csharp_constants)
        for pressure, speed in POINTS:
            want = float(coupling.gain_raw(pressure, speed))
            assert swift_gain(pressure, speed) == pytest.approx(want, abs=1e-12)
            assert csharp_gain(pressure, speed) == pytest.approx(want, abs=1e-12)
        # The drive is the gain over a_max, as the live app's tactile gain.
        assert "Self.gain(pressure: pressure, speedMmS: speedMmS) / Self.aMax" in swift
        assert "HapticController.clipLevel = Gain(pressure, speedMmS) / AMax" in csharp
        assert "player.loopEnabled = true" in swift and "HapticController.Loop(true)" in csharp
    assert {float(ODD.gain_raw(p, v)) for p, v in POINTS} >= {0.0, 1.7}  # both clamps tried


HARNESS = """#include <stdint.h>
#include <stdio.h>
void dac_write_12bit(uint16_t code);
{usage}
static uint16_t written[4];
static unsigned count = 0;
void dac_write_12bit(uint16_t code) {{ written[count++ % 4] = code; }}
int main(void)
{{
    on_sample_tick(); /* the pen is still: mid-scale */
    pen_moving = 1;
    for (unsigned long i = 0; i < {stem}_LENGTH + 2; i++) on_sample_tick();
    printf("%u %u %u %u\\n", written[0], written[1], written[2], written[3]);
    return 0;
}}
"""


@pytest.mark.firmware
def test_the_c_header_usage_example_compiles_and_loops_the_table(tmp_path):
    cc = shutil.which("cc")
    if cc is None:
        pytest.fail("no C compiler (cc) on PATH; scripts/test.sh installs gcc", pytrace=False)
    header = tmp_path / "pencil_tactile.h"
    export_profile(resolve_profile("pencil"), "c-header", header)
    usage = snippet_script().written("pencil", "pencil_tactile.h", "pencil_tactile.h", True)
    assert "\n".join(f" * {line}".rstrip() for line in usage.splitlines()) in header.read_text()
    source = tmp_path / "main.c"
    source.write_text(HARNESS.format(usage=usage, stem="REALPEN_PENCIL"))
    binary = tmp_path / "main"
    built = subprocess.run([cc, "-std=c99", "-Wall", "-Wextra", "-Werror", "-I", str(tmp_path),
                            str(source), "-o", str(binary)], capture_output=True, text=True)
    assert built.returncode == 0, built.stderr
    out = [int(v) for v in subprocess.run([str(binary)], capture_output=True, text=True,
                                          check=True).stdout.split()]
    table = [int(v) for v in re.search(r"_tactile\[REALPEN_PENCIL_LENGTH\] = \{(.*?)\};",
                                       header.read_text(), re.S).group(1).split(",")]
    # Calls 0 (still), then 1 … LENGTH + 2 play table[0 … LENGTH + 1] wrapping after LENGTH.
    calls = len(table) + 3
    expected = {call % 4: (2048 if call == 0 else table[(call - 1) % len(table)])
                for call in range(calls - 4, calls)}
    assert out == [expected[slot] for slot in range(4)]
