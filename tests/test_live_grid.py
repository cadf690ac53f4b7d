"""The live page's tactile output follows the pen over a profile's vibration grid.

A real ``realpen serve`` offers a four-point grid profile built here (tiny synthetic patterns,
the pencil's sound); Debian's Chromium (Playwright) writes with it through the DevTools
protocol, as in test_live_browser.py. The page's point gains must be Python's
:meth:`~realpen.tactile.grid.VibrationGrid.gains` at the pen's speed and force, and a pen
without a grid must still play exactly one tactile loop.
"""

from __future__ import annotations

import io
import time
from pathlib import Path

import numpy as np
import pytest
import soundfile as sf
from live_support import CHROMIUM, CHROMIUM_ARGS, CHROMIUM_MISSING, serve

from realpen.profile import PenProfile, load_profile, resolve_profile, save_profile
from realpen.tactile.grid import GridPoint, VibrationGrid
from realpen.tactile.pattern import Component, TactilePattern

ARTIFACTS = Path(__file__).resolve().parents[1] / "test-artifacts"

if not CHROMIUM.exists():
    pytest.skip(CHROMIUM_MISSING, allow_module_level=True)
sync_api = pytest.importorskip("playwright.sync_api", reason="playwright is not installed")
httpx = pytest.importorskip("httpx")

# (speed mm/s, force N, frequency Hz): a quadrilateral, two Delaunay triangles.
POINTS = ((10.0, 0.4, 120.0), (150.0, 0.8, 180.0), (40.0, 3.2, 240.0), (200.0, 2.6, 300.0))
REFERENCE = 1


def grid_profile(folder: Path, name: str = "gridpen") -> Path:
    """Save a pen whose tactile pattern follows speed and force over :data:`POINTS` (two
    100 ms sub-patterns of one sinusoid each per point; the pencil's sound)."""
    pencil = resolve_profile("pencil")
    grid = VibrationGrid(tuple(
        GridPoint(speed, force, TactilePattern([[Component(hz, 0.5)], [Component(1.5 * hz, 0.4)]],
                                               rate=pencil.meta.tactile.rate))
        for speed, force, hz in POINTS), reference=REFERENCE)
    pattern = grid.reference_pattern
    meta = pencil.meta.model_copy(update={"name": name, "tool": "grid pen", "tactile": pattern,
                                          "grid": grid, "format": 3})
    return save_profile(PenProfile(meta, pattern.render().astype(np.float32), pencil.sound),
                        folder / name)


@pytest.fixture(scope="module")
def grid_server(tmp_path_factory):
    folder = tmp_path_factory.mktemp("grid")
    grid_profile(folder / "profiles")
    with serve(folder, "--profiles", str(folder / "profiles")) as served:
        served.profile = load_profile(folder / "profiles" / "gridpen")
        yield served


def test_the_server_offers_every_points_loop_and_single_point_pens_as_before(grid_server):
    base, grid = grid_server.base, grid_server.profile.grid
    listed = {p["name"]: p for p in httpx.get(base + "api/profiles").json()["profiles"]}
    assert "grid" not in listed["pencil"]  # exactly today's payload
    sent = listed["gridpen"]["grid"]
    assert sent["triangles"] == grid.triangles.tolist() and len(sent["triangles"]) == 2
    assert sent["scale"] == list(grid.scale) and sent["reference"] == REFERENCE
    assert sent["full_pressure_force_n"] == 4.0
    assert [(p["speed_mm_s"], p["force_n"]) for p in sent["points"]] == \
        [(s, f) for s, f, _ in POINTS]
    assert sent["points"][REFERENCE]["url"] == listed["gridpen"]["tactile"]["url"]
    for point, own in zip(sent["points"], grid.points):
        samples, rate = sf.read(io.BytesIO(httpx.get(base + point["url"]).content))
        assert rate == point["wav_rate"] == own.pattern.rate
        assert np.max(np.abs(samples - own.pattern.render())) < 1e-6  # float32 of the pattern
    assert httpx.get(base + "api/profiles/gridpen/grid/4.wav").status_code == 404
    assert httpx.get(base + "api/profiles/pencil/grid/0.wav").status_code == 404


def test_the_page_mixes_the_point_loops_at_the_pens_speed_and_force(grid_server, chromium):
    grid = grid_server.profile.grid
    context = chromium(CHROMIUM_ARGS).new_context(viewport={"width": 1180, "height": 820})
    try:
        context.set_default_timeout(15_000)
        page = context.new_page()
        problems: list[str] = []
        page.on("pageerror", lambda error: problems.append(str(error)))
        page.goto(grid_server.url + "?pen=gridpen&modality=tactile&tactile=audio")
        page.wait_for_function("() => window.realpen && window.realpen.ready && "
                               "window.realpen.link.state === 'open'")
        writing = Writing(page, context)
        audio = page.evaluate("realpen.audio")
        assert audio["playing"] == "gridpen" and audio["tactileLoops"] == len(POINTS)
        assert audio["pointGains"] == [float(i == REFERENCE) for i in range(len(POINTS))]
        # The grid bus keeps the mix at or below the loudest loop's peak.
        assert audio["mixGain"] == pytest.approx(grid.mix_gain, rel=1e-6)
        assert 0 < grid.mix_gain <= 1

        # The page's grid, everywhere: inside, on edges, outside the hull, at the points.
        rng = np.random.default_rng(13)
        queries = np.concatenate([rng.uniform([0, 0], [260, 4.5], (300, 2)),
                                  [(s, f) for s, f, _ in POINTS], [(80, 0.6), (0, 0)]])
        sent = page.evaluate("realpen.profiles.find((p) => p.name === 'gridpen').grid")
        gains = page.evaluate("([g, q]) => { const grid = new realpen.model.VibrationGrid(g);"
                              " return q.map(([s, f]) => grid.gains(s, f)); }",
                              [sent, queries.tolist()])
        expected = np.array([grid.gains(s, f) for s, f in queries])
        assert np.max(np.abs(np.array(gains) - expected)) < 1e-9

        # Two strokes: slow and light (inside a triangle: three loops mix), then fast and
        # firm (beyond the hull: the two loops of its nearest edge).
        for px_per_step, pressure, mixing in ((1.0, 0.2, 3), (6.0, 0.75, 2)):
            writing.stroke([(80 + px_per_step * i, 200 + 150 * (mixing == 2), pressure)
                            for i in range(40)])
            # Holding still, the smoothed gains settle (on the audio clock: waited for).
            page.wait_for_function(
                "() => realpen.pointGains.every((g, i) => "
                "Math.abs(g - realpen.pointTargets[i]) < 1e-3) && realpen.tactileTarget > 0 "
                "&& Math.abs(realpen.tactileGain - realpen.tactileTarget) < 1e-3")
            held = page.evaluate("({speed: realpen.speed, pressure: realpen.pressure, "
                                 "targets: realpen.pointTargets, gains: realpen.pointGains,"
                                 " tactile: realpen.tactileGain, "
                                 "tactileTarget: realpen.tactileTarget})")
            force = held["pressure"] * grid.full_pressure_force_n
            want = grid.gains(held["speed"], force)
            assert np.max(np.abs(np.array(held["targets"]) - want)) < 1e-6
            assert np.count_nonzero(want) == mixing, (held["speed"], force)
            assert np.sum(want ** 2) == pytest.approx(1.0)  # equal power
            assert np.max(np.abs(np.array(held["gains"]) - want)) < 1e-3
            assert held["tactileTarget"] > 0
            assert held["tactile"] == pytest.approx(held["tactileTarget"], abs=1e-3)
            writing.lift()
        # The device log hears the strokes as with any pen (a pen plays the reference pattern).
        session = page.evaluate("realpen.link.session")
        log = httpx.get(grid_server.base + "api/device/log").json()["entries"]
        downs = [e for e in log if e["session"] == session and e["kind"] == "pen_down"]
        assert [e["detail"]["pen"] for e in downs] == ["gridpen", "gridpen"]
        ARTIFACTS.mkdir(exist_ok=True)
        page.screenshot(path=str(ARTIFACTS / "live-grid.png"))

        # A pen without a grid: one tactile loop, no point gains.
        page.click("#pens button[data-value=pencil]")
        page.wait_for_function("() => realpen.pen === 'pencil'")
        writing.stroke([(300 + 3 * i, 500, 0.5) for i in range(30)])
        page.wait_for_function("() => realpen.tactileTarget > 0 && "
                               "Math.abs(realpen.tactileGain - realpen.tactileTarget) < 1e-3")
        state = page.evaluate("({audio: realpen.audio, targets: realpen.pointTargets, "
                              "gains: realpen.pointGains, tactile: realpen.tactileGain, "
                              "tactileTarget: realpen.tactileTarget})")
        assert state["audio"]["tactileLoops"] == 1 and state["audio"]["playing"] == "pencil"
        assert state["targets"] is None and state["gains"] is None
        assert state["tactileTarget"] > 0
        assert state["tactile"] == pytest.approx(state["tactileTarget"], abs=1e-3)
        writing.lift()
        assert problems == []
    finally:
        context.close()


class Writing:
    """Pen strokes on the writing surface through the DevTools protocol (trusted events)."""

    def __init__(self, page, context):
        self.page = page
        self.cdp = context.new_cdp_session(page)
        self.box = page.locator("#ink").bounding_box()
        self.last = None

    def event(self, kind: str, x: float, y: float, pressure: float, t: float) -> None:
        self.cdp.send("Input.dispatchMouseEvent", {
            "type": kind, "x": self.box["x"] + x, "y": self.box["y"] + y, "button": "left",
            "buttons": 0 if kind == "mouseReleased" else 1, "clickCount": 1,
            "pointerType": "pen", "force": pressure, "timestamp": t})
        self.last = (x, y, t)

    def stroke(self, points, dt: float = 0.008) -> None:
        """Press at points[0] and move through the rest, one every ``dt`` s; the pen stays down."""
        t0 = time.time()
        for i, (x, y, pressure) in enumerate(points):
            self.event("mousePressed" if i == 0 else "mouseMoved", x, y, pressure, t0 + i * dt)

    def lift(self) -> None:
        x, y, t = self.last
        self.event("mouseReleased", x, y, 0.0, t + 0.01)
        self.page.wait_for_function("() => !window.realpen.down && "
                                    "window.realpen.link.unacked === 0")
