"""The live page in a real browser: Debian's Chromium driven by Playwright for Python.

A real ``realpen serve`` runs in a subprocess; pen strokes are trusted pen events with pressure,
tilt and timestamps, injected through the DevTools protocol (``Input.dispatchMouseEvent`` with
``pointerType: "pen"``). The tests read the page's state (``window.realpen``), the device's
command log and the SQLite store, and compare the page's gains with the Python implementation
of Eq. 1. Screenshots go to ``test-artifacts/`` (git-ignored).

Chromium runs with ``--autoplay-policy=no-user-gesture-required``, so every page's AudioContext
runs from the start and the tests always check the audio gains; one test runs a browser without
it, under the HTML user-activation rules, to check how the page starts its audio.
"""

from __future__ import annotations

import json
import math
import socket
import sqlite3
import time
from pathlib import Path

import numpy as np
import pytest
from live_support import CHROMIUM, CHROMIUM_ARGS, CHROMIUM_MISSING, low_rate_profile, serve, spare_server

from realpen.motion.coupling import Coupling, one_pole
from realpen.motion.trajectory import Trajectory
from realpen.profile import resolve_profile

ARTIFACTS = Path(__file__).resolve().parents[1] / "test-artifacts"
GESTURE_ARGS = [arg for arg in CHROMIUM_ARGS if not arg.startswith("--autoplay-policy")]
LANDSCAPE = {"width": 1180, "height": 820}
PORTRAIT = {"width": 820, "height": 1180}

if not CHROMIUM.exists():
    pytest.skip(CHROMIUM_MISSING, allow_module_level=True)
sync_api = pytest.importorskip("playwright.sync_api", reason="playwright is not installed")
httpx = pytest.importorskip("httpx")


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    folder = tmp_path_factory.mktemp("live")
    with serve(folder) as served:
        served.store = folder / "strokes.sqlite3"
        yield served


@pytest.fixture(scope="module")
def lan_server(tmp_path_factory):
    """A server in LAN mode (its token or cookie required) that also offers a pen whose tactile
    pattern is at 2 kHz (a profile folder of its own): one server for the two tests of them."""
    folder = tmp_path_factory.mktemp("lan")
    low_rate_profile(folder / "low")  # like `realpen profile build --rate 2000`
    with serve(folder, "--lan", "--host", "127.0.0.1", "--profiles", str(folder / "low")) as lan:
        lan.store = folder / "strokes.sqlite3"
        yield lan


@pytest.fixture
def browser(chromium):
    return chromium(CHROMIUM_ARGS)


class Page:
    """A page of the live app with a pen: strokes through the DevTools protocol.

    ``storage`` presets localStorage; ``broken`` lists URL globs answered with bytes that are
    no WAV (a pen whose audio does not decode); ``init_script`` runs before the page's own.
    """

    def __init__(self, browser, server, query: str = "", viewport=LANDSCAPE, storage=None,
                 broken=(), init_script: str | None = None):
        self.context = browser.new_context(viewport=viewport)
        self.context.set_default_timeout(15_000)
        if storage:
            self.context.add_init_script(
                "".join(f"localStorage.setItem({json.dumps(k)}, {json.dumps(json.dumps(v))});"
                        for k, v in storage.items()))
        if init_script:
            self.context.add_init_script(init_script)
        for pattern in broken:
            self.context.route(pattern, lambda route: route.fulfill(
                status=200, content_type="audio/wav", body=b"RIFF, but not a WAV at all"))
        self.page = self.context.new_page()
        self.problems: list[str] = []
        self.page.on("pageerror", lambda error: self.problems.append(str(error)))
        self.page.on("console", lambda m: m.type == "error" and self.problems.append(m.text))
        self.page.goto(server.url + query)
        self.page.wait_for_function("() => window.realpen && window.realpen.ready")
        self.page.wait_for_function("() => window.realpen.link.state === 'open' && "
                                    "window.realpen.link.session")
        self.cdp = self.context.new_cdp_session(self.page)
        self.box = self.page.locator("#ink").bounding_box()

    def eval(self, script: str, arg=None):
        return self.page.evaluate(script, arg)

    def pen(self, kind: str, x: float, y: float, pressure: float, t: float,
            pointer: str = "pen") -> None:
        self.pen_at(kind, self.box["x"] + x, self.box["y"] + y, pressure, t, pointer)

    def pen_at(self, kind: str, x: float, y: float, pressure: float, t: float,
               pointer: str = "pen") -> None:
        """A pen event at page coordinates (``pen``: relative to the writing surface)."""
        buttons = 0 if kind == "mouseReleased" else 1
        self.cdp.send("Input.dispatchMouseEvent", {
            "type": kind, "x": x, "y": y, "button": "left",
            "buttons": buttons, "clickCount": 1, "pointerType": pointer, "force": pressure,
            "tiltX": 15, "tiltY": -8, "timestamp": t})

    def stroke(self, points, dt: float = 0.008, hold_s: float = 0.0, lift: bool = True,
               pointer: str = "pen") -> None:
        """Press at points[0], move through the rest every ``dt`` s, optionally hold, lift."""
        t0 = time.time()
        (x, y, p), *rest = points
        self.pen("mousePressed", x, y, p, t0, pointer)
        for i, (x, y, p) in enumerate(rest, start=1):
            self.pen("mouseMoved", x, y, p, t0 + i * dt, pointer)
        if hold_s:
            time.sleep(hold_s)
        if lift:
            self.pen("mouseReleased", x, y, 0.0, t0 + len(points) * dt + hold_s, pointer)
            self.settle()

    def settle(self) -> None:
        self.page.wait_for_function("() => !window.realpen.down && "
                                    "window.realpen.link.unacked === 0")

    def settle_gain(self) -> None:
        """Wait until the audio gain has reached its target: it ramps on the audio clock, which
        a loaded machine runs late, so a fixed hold is not always enough."""
        self.page.wait_for_function("() => realpen.targetGain > 0 && "
                                    "Math.abs(realpen.gain - realpen.targetGain) < 1e-3")

    def trace(self, stroke: int | None = None) -> list[dict]:
        entries = self.eval("window.realpen.trace")
        stroke = stroke if stroke is not None else self.eval("window.realpen.stroke")
        return [e for e in entries if e["stroke"] == stroke]

    def close(self) -> None:
        self.context.close()


@pytest.fixture
def open_page(browser, server):
    pages = []

    def make(*args, **kwargs) -> Page:
        page = Page(browser, server, *args, **kwargs)
        pages.append(page)
        return page

    yield make
    for page in pages:
        page.close()


def writing(n: int = 90, x0: float = 60, y0: float = 220):
    """A stroke whose speed ramps from slow to fast while the pressure swings: the gain passes
    through 0, the linear part of Eq. 1 and the a_max clamp."""
    points, x = [], x0
    for i in range(n):
        x += 0.1 + 3.4 * (i / n) ** 2
        points.append((x, y0 + 8 * math.sin(i / 9), 0.5 + 0.4 * math.sin(i / 6)))
    return points


def loops(x0: float, y0: float, n: int = 130, size: float = 24):
    """Cursive loops (a prolate cycloid, like a row of l's), for the screenshots."""
    points = []
    for i in range(n):
        theta = 0.16 * i
        points.append((x0 + size * (0.5 * theta - math.sin(theta)),
                       y0 - size * math.cos(theta), 0.3 + 0.5 * math.sin(i / 25) ** 2))
    return points


def session_log(server, session: str) -> list[dict]:
    entries, since = [], 0
    while True:  # the log comes a page at a time
        page = httpx.get(server.base + "api/device/log", params={"since": since}).json()
        entries += page["entries"]
        if page["next"] >= page["count"]:
            return [e for e in entries if e["session"] == session]
        since = page["next"]


def store_rows(server, sql: str, *args):
    with sqlite3.connect(server.store) as db:
        return db.execute(sql, args).fetchall()


def smoothed_reference(trace: list[dict], smoothing_ms: float) -> np.ndarray:
    """The documented recursion, per audio sample, over the page's held targets."""
    rate = trace[0]["rate"]
    k = np.array([e["k"] for e in trace])
    x = np.zeros(k[-1] - k[0])
    for prev, nxt in zip(trace, trace[1:]):
        x[prev["k"] - k[0]:nxt["k"] - k[0]] = prev["target"]
    y = one_pole(x, rate, smoothing_ms, initial=trace[0]["smoothed"])
    return np.concatenate([[trace[0]["smoothed"]], y])[k - k[0]]


# ---- tests ----------------------------------------------------------------------------------

def test_page_loads_with_pickers_and_audio(open_page):
    page = open_page()
    assert page.page.title() == "RealPen"
    pens = page.page.locator("#pens button").all_inner_texts()
    assert [p.strip() for p in pens][:3] == ["Pencil", "Ballpoint", "Marker"]
    modalities = page.page.locator("#modalities button").evaluate_all(
        "bs => bs.map(b => b.dataset.value)")
    assert modalities == ["tactile", "auditory", "audio-tactile", "none"]
    state = page.eval("({pen: realpen.pen, modality: realpen.modality, ink: realpen.ink, "
                      "version: realpen.profileVersion, audio: realpen.audio, "
                      "coupling: realpen.coupling, notice: realpen.notice})")
    assert state["audio"]["state"] == "running"  # the autoplay flag: no gesture needed
    assert state["audio"]["playing"] == "pencil" and state["notice"] is None
    assert state["pen"] == "pencil" and state["ink"] == "visible"
    assert state["version"] == resolve_profile("pencil").version
    assert state["coupling"] == resolve_profile("pencil").meta.coupling.to_json()
    assert state["audio"]["sampleRate"] > 0 and state["audio"]["baseLatency"] is not None
    assert page.problems == []


def test_pen_stroke_gives_ink_eq1_gain_device_messages_and_a_stored_stroke(open_page, server):
    # The modality's old name in a bookmarked URL still works; the page says today's.
    page = open_page("?pen=pencil&modality=auditory-tactile&ink=visible")
    assert page.eval("realpen.modality") == "audio-tactile"
    coupling = Coupling(**page.eval("realpen.coupling"))
    points = writing()
    page.stroke(points, hold_s=0.12, lift=False)  # hold still: the audio gain settles
    page.settle_gain()
    held = page.eval("({gain: realpen.gain, target: realpen.targetGain, "
                     "state: realpen.audio.state})")
    assert held["state"] == "running"  # the browser runs with the autoplay flag
    assert held["target"] > 0 and held["gain"] == pytest.approx(held["target"], abs=1e-3)
    x, y, _ = points[-1]
    page.pen("mouseReleased", x, y, 0.0, time.time())
    page.settle()
    page.page.wait_for_function("() => realpen.gain < 1e-3")  # on the audio clock: waited for
    assert page.eval("realpen.gain") < 1e-3  # silent on lift

    assert page.eval("realpen.inkedPixels()") > 200
    trace = page.trace()
    down, up = trace[:-1], trace[-1]
    assert len(down) == len(points) and up["pressure"] == 0 and up["target"] == 0
    pressure = np.array([e["pressure"] for e in down])
    speed = np.array([e["speed"] for e in down])
    target = np.array([e["target"] for e in down])
    assert speed[0] == 0 and speed.max() > 100
    # Eq. 1 before smoothing: exactly the Python implementation.
    assert np.max(np.abs(target - coupling.gain_raw(pressure, speed))) <= 1e-12
    assert (target == 0).any() and (target == coupling.a_max).any()
    assert ((target > 0) & (target < coupling.a_max)).sum() > 10
    # The smoothed gain: the documented one-pole recursion at the audio rate.
    smoothed = np.array([e["smoothed"] for e in trace])
    reference = smoothed_reference(trace, coupling.smoothing_ms)
    assert np.max(np.abs(smoothed - reference)) < 1e-9

    session = page.eval("realpen.link.session")
    log = session_log(server, session)
    kinds = [e["kind"] for e in log]
    assert kinds[0] == "pen_down" and kinds[-1] == "pen_up" and kinds.count("pen_down") == 1
    assert set(kinds[1:-1]) == {"gain"}
    assert all(a["at_ns"] <= b["at_ns"] and a["index"] < b["index"] for a, b in zip(log, log[1:]))
    sent = [float(v) for i, v in enumerate(target) if i == 0 or v != target[i - 1]]
    assert [e["value"] for e in log if e["kind"] == "gain"] == sent
    assert log[0]["detail"]["pen"] == "pencil" and log[0]["detail"]["tactile"] is True

    (stroke,) = store_rows(server, "SELECT id, pen, profile_version, modality, ink, pointer_type, "
                                   "sample_count, end_reason FROM strokes WHERE session = ?",
                           session)
    assert stroke[1:] == ("pencil", resolve_profile("pencil").version, "audio-tactile",
                          "visible", "pen", len(points), "pen_up")
    samples = store_rows(server, "SELECT t, pressure, speed, tilt_x, tilt_y FROM samples "
                                 "WHERE stroke_id = ? ORDER BY seq", stroke[0])
    stored = np.array(samples)
    assert np.array_equal(stored[:, 1], pressure) and np.array_equal(stored[:, 2], speed)
    assert stored[0, 0] == 0 and np.all(np.diff(stored[:, 0]) > 0)
    page_t = np.array([e["t"] for e in down])
    assert np.allclose(stored[:, 0], page_t - page_t[0], rtol=0, atol=1e-12)
    assert stored[-1, 0] == pytest.approx(0.008 * (len(points) - 1), abs=1e-3)
    assert set(stored[:, 3]) == {15.0} and set(stored[:, 4]) == {-8.0}
    assert page.eval("realpen.link.errors") == 0 and page.problems == []


def test_hidden_ink_leaves_the_canvas_blank(open_page, server):
    page = open_page("?ink=hidden")
    page.stroke(writing())
    assert len(page.trace()) > 10 and page.eval("realpen.targetGain") == 0
    blank = page.eval("""(() => {
        const c = document.getElementById('ink');
        const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
        let inked = 0; for (let i = 3; i < d.length; i += 4) if (d[i]) inked++;
        return inked; })()""")
    assert blank == 0 and page.eval("realpen.inkedPixels()") == 0
    session = page.eval("realpen.link.session")
    assert store_rows(server, "SELECT ink FROM strokes WHERE session = ?", session) == \
        [("hidden",)]
    assert page.page.locator("body.ink-hidden").count() == 1


def test_page_gain_functions_equal_the_python_implementation(open_page):
    page = open_page()
    rng = np.random.default_rng(7)
    pressure = np.concatenate([[0, -0.1, 1, 1e-9, 0.1], rng.uniform(0, 1, 300)])
    speed = np.concatenate([[0, 500, 12, 1e4, 0], rng.uniform(0, 250, 300)])
    couplings = [Coupling(**page.eval("realpen.coupling")), Coupling(c_p=1.3, c_op=0.05,
                 c_x=0.011, c_ov=3.0, a_max=1.5, smoothing_ms=0.0, rate_exponent=0.5)]
    for coupling in couplings:
        c = coupling.to_json()
        result = page.eval("""([c, P, V]) => ({
            gain: P.map((p, i) => realpen.model.gainRaw(c, p, V[i])),
            rate: V.map((v) => realpen.model.playbackRate(c, v))})""",
                           [c, pressure.tolist(), speed.tolist()])
        assert np.array_equal(result["gain"], coupling.gain_raw(pressure, speed))
        assert np.allclose(result["rate"], coupling.playback_rate(speed), rtol=0, atol=1e-12)
        values = coupling.gain_raw(pressure, speed)
        for rate in (44100, 48000):
            page_smoothed = page.eval("([v, r, ms]) => realpen.model.onePole(v, r, ms, 0.3)",
                                      [values.tolist(), rate, coupling.smoothing_ms])
            assert np.max(np.abs(np.array(page_smoothed) - one_pole(
                values, rate, coupling.smoothing_ms, initial=0.3))) < 1e-12


def test_tactile_modality_drives_the_right_channel_only(open_page, server):
    page = open_page("?pen=marker&modality=tactile&tactile=audio")
    assert page.eval("realpen.audio.tactileAudio") is True
    a_max = page.eval("realpen.coupling.a_max")
    page.stroke(writing(60), hold_s=0.12, lift=False)
    held = page.eval("({gain: realpen.gain, tactile: realpen.tactileGain, target: "
                     "realpen.targetGain, tactileTarget: realpen.tactileTarget, "
                     "state: realpen.audio.state})")
    assert held["target"] > 0 and held["tactileTarget"] == pytest.approx(held["target"] / a_max)
    assert held["state"] == "running"  # the browser runs with the autoplay flag
    assert held["gain"] < 1e-3  # no sound in the tactile condition
    assert held["tactile"] == pytest.approx(held["tactileTarget"], abs=1e-3)
    page.pen("mouseReleased", 300, 220, 0.0, time.time())
    page.settle()
    log = session_log(server, page.eval("realpen.link.session"))
    assert log[0]["kind"] == "pen_down" and log[0]["detail"]["pen"] == "marker"
    assert log[-1]["kind"] == "pen_up" and "gain" in {e["kind"] for e in log}


def test_mouse_writes_with_the_documented_constant_pressure(open_page, server):
    page = open_page("?modality=auditory")
    mouse = page.page.mouse
    mouse.move(page.box["x"] + 100, page.box["y"] + 300)
    mouse.down()
    for i in range(1, 25):
        mouse.move(page.box["x"] + 100 + 8 * i, page.box["y"] + 300 + 2 * i)
    mouse.up()
    page.settle()
    trace = page.trace()
    constant = page.eval("realpen.model.MOUSE_PRESSURE")
    assert constant == 0.5 and {e["pressure"] for e in trace[:-1]} == {constant}
    session = page.eval("realpen.link.session")
    assert store_rows(server, "SELECT pointer_type, modality FROM strokes WHERE session = ?",
                      session) == [("mouse", "auditory")]
    assert [e["kind"] for e in session_log(server, session)] == ["pen_down", "pen_up"]


def test_calibration_sets_mm_and_speed(open_page, server):
    page = open_page(storage={"realpen.pxPerMm": 8.0})
    assert page.eval("[realpen.pxPerMm, realpen.calibrated]") == [8.0, True]
    points = [(100 + 4 * i, 300, 0.5) for i in range(40)]  # 4 px per 8 ms = 62.5 mm/s
    page.stroke(points)
    trace = page.trace()[:-1]
    session = page.eval("realpen.link.session")
    xy = np.array(store_rows(server, "SELECT p.x, p.y FROM samples p JOIN strokes s ON "
                                     "s.id = p.stroke_id WHERE s.session = ? ORDER BY p.seq",
                             session))
    assert np.allclose(np.diff(xy[:, 0]), 0.5) and np.all(xy[:, 1] == xy[0, 1])
    # Speed: path length over the last SPEED_WINDOW_MS, from the page's own timestamps.
    window = page.eval("realpen.model.SPEED_WINDOW_MS") / 1000
    # The page and the library's stroke rendering measure speed the same way.
    times = np.array([e["t"] for e in trace])
    expected = Trajectory(times, xy[:, 0], xy[:, 1], np.ones(len(times))).speed(window * 1000)
    assert np.max(np.abs(np.array([e["speed"] for e in trace]) - expected)) < 1e-9
    assert np.allclose(expected[3:], 62.5, rtol=0.03)  # 4 px / 8 ms at 8 px/mm
    assert store_rows(server, "SELECT px_per_mm, calibrated FROM strokes WHERE session = ?",
                      session) == [(8.0, 1)]
    # The dialog: one step longer, save, kept in the browser.
    page.page.click("#calibrate")
    page.page.click("#cal-plus")
    page.page.click("#calibration button[value=save]")
    page.page.wait_for_function("() => Math.abs(realpen.pxPerMm - 8.01) < 1e-9")
    assert page.page.locator("#calibrate").inner_text() == "8.01 px/mm"
    assert page.eval("JSON.parse(localStorage.getItem('realpen.pxPerMm'))") == \
        pytest.approx(8.01)


@pytest.mark.parametrize("viewport, name", [(LANDSCAPE, "live.png"),
                                            (PORTRAIT, "live-portrait.png")])
def test_screenshot_on_a_tablet(open_page, viewport, name):
    page = open_page("?modality=audio-tactile&ink=visible", viewport=viewport)
    for row, pen in enumerate(("pencil", "ballpoint", "marker")):
        page.page.click(f"#pens button[data-value={pen}]")
        page.page.wait_for_function(f"() => realpen.pen === '{pen}'")
        page.stroke(loops(60, 90 + 110 * row))  # a row of loops: ink enough to see
    overflow = page.eval("document.documentElement.scrollWidth - window.innerWidth")
    assert overflow <= 0
    heights = page.page.locator("header button, footer button").evaluate_all(
        "bs => bs.map(b => b.getBoundingClientRect().height)")
    assert min(heights) >= 44  # large touch targets
    ARTIFACTS.mkdir(exist_ok=True)
    page.page.screenshot(path=str(ARTIFACTS / name))
    assert (ARTIFACTS / name).stat().st_size > 10_000
    assert page.problems == []


def test_lan_mode_page_works_with_its_token_only(browser, lan_server):
    lan = lan_server
    refused = browser.new_page()
    assert refused.goto(lan.base).status == 401
    refused.close()
    # The printed URL (?token=…) and a preset; modules load with the cookie.
    page = Page(browser, lan, "&modality=tactile")
    try:
        # The cookie works, so the token leaves the address bar and the history entry.
        assert page.page.url == lan.base + "?modality=tactile"
        page.stroke(writing(30))
        session = page.eval("realpen.link.session")
        assert store_rows(lan, "SELECT sample_count FROM strokes WHERE session = ?",
                          session) == [(30,)]
        page.page.reload()  # the cookie alone keeps the page working
        page.page.wait_for_function("() => window.realpen && window.realpen.ready && "
                                    "window.realpen.link.state === 'open'")
        assert page.eval("realpen.modality") == "tactile" and lan.token not in page.page.url
        assert page.problems == []
    finally:
        page.close()


def test_a_stroke_drawn_across_a_server_crash_is_stored_whole_and_once(browser, tmp_path):
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = str(probe.getsockname()[1])
    store = tmp_path / "strokes.sqlite3"
    points = writing(80)
    # The second server starts with the first, and runs once the first is killed: a restart.
    with spare_server(tmp_path, "--port", port) as restart, \
            serve(tmp_path, "--port", port) as first:
        first.store = store
        page = Page(browser, first)
        try:
            page.stroke(points[:40], lift=False)
            page.page.wait_for_function("() => window.realpen.link.unacked === 0")
            first.process.kill()  # SIGKILL mid-stroke: nothing is closed cleanly
            first.process.wait(timeout=10)
            t0 = time.time()
            for i, (x, y, p) in enumerate(points[40:]):  # the pen goes on while the server is away
                page.pen("mouseMoved", x, y, p, t0 + i * 0.008)
            page.pen("mouseReleased", *points[-1][:2], 0.0, t0 + 0.5)
            page.page.wait_for_function("() => window.realpen.link.state === 'closed' && "
                                        "window.realpen.link.unacked > 0")
            with serve(tmp_path, spare=restart) as second:  # same port, same store
                second.store = store
                page.page.wait_for_function("() => window.realpen.link.state === 'open' && "
                                            "window.realpen.link.unacked === 0", timeout=30_000)
        finally:
            page.close()
    ((count, reason),) = store_rows(first, "SELECT sample_count, end_reason FROM strokes")
    assert reason == "pen_up"  # the resent pen-up replaced the 'crash' found at restart
    xs = [x for (x,) in store_rows(first, "SELECT x FROM samples ORDER BY seq")]
    assert count == len(xs) == len(set(xs)) and count >= 80  # every sample, each once
    assert xs == sorted(xs)  # in drawing order (the stroke goes left to right)


def test_a_reload_keeps_and_sends_what_the_server_had_not_acknowledged(browser, server):
    # The module's server: the strokes of this test are those stored after ``before``.
    ((before,),) = store_rows(server, "SELECT COALESCE(MAX(id), 0) FROM strokes")
    relay = {"on": True}  # off: the socket swallows everything, both ways

    def route(ws):
        upstream = ws.connect_to_server()
        ws.on_message(lambda m: relay["on"] and upstream.send(m))
        upstream.on_message(lambda m: relay["on"] and ws.send(m))

    page = Page(browser, server)
    try:
        page.page.route_web_socket("**/ws", route)
        page.page.reload()
        page.page.wait_for_function("() => window.realpen && window.realpen.ready && "
                                    "window.realpen.link.state === 'open'")
        page.stroke(writing(30))
        relay["on"] = False
        page.stroke(writing(40, y0=320), lift=False)
        page.pen("mouseReleased", 200, 320, 0.0, time.time() + 1)
        page.page.wait_for_function("() => !window.realpen.down && "
                                    "window.realpen.link.unacked > 0")
        unacked = page.eval("realpen.link.unacked")
        page.page.on("dialog", lambda dialog: dialog.accept())  # "leave the page?"
        relay["on"] = True
        page.page.reload()
        page.page.wait_for_function("() => window.realpen && window.realpen.ready && "
                                    "window.realpen.link.state === 'open' && "
                                    "window.realpen.link.unacked === 0")
        assert page.eval("realpen.stroke") == 2  # the same page: its numbers go on
        assert page.problems == []
    finally:
        page.close()
    strokes = store_rows(server, "SELECT page_stroke, sample_count, end_reason, page, id FROM "
                                 "strokes WHERE id > ? ORDER BY id", before)
    assert [row[:1] + row[2:3] for row in strokes] == [(1, "pen_up"), (2, "pen_up")]
    assert strokes[0][3] == strokes[1][3]  # one page across the reload
    assert strokes[1][1] >= 40 and unacked >= 3  # pen-down, its samples, pen-up: all kept
    xs = [x for (x,) in store_rows(server, "SELECT x FROM samples WHERE stroke_id = ? "
                                           "ORDER BY seq", strokes[1][4])]
    assert len(xs) == len(set(xs)) == strokes[1][1]


# ---- pens whose audio is unusual or broken ----------------------------------------------------

def test_a_pen_with_a_2_khz_tactile_pattern_loads_and_plays(browser, lan_server):
    """Chrome's decodeAudioData refuses WAVs below 3 kHz: the server resamples such patterns."""
    page = Page(browser, lan_server, "&pen=slowpen&modality=tactile&tactile=audio")
    try:
        state = page.eval("({pen: realpen.pen, audio: realpen.audio, notice: realpen.notice,"
                          " error: realpen.error})")
        assert state["pen"] == "slowpen" and state["error"] is None
        assert state["notice"] is None and state["audio"]["playing"] == "slowpen"
        tactile = state["audio"]["buffers"]["tactile"]
        assert tactile["duration"] == pytest.approx(1.5, abs=1e-3)  # 3000 frames at 2 kHz
        page.stroke(writing(60), hold_s=0.12, lift=False)
        held = page.eval("({tactile: realpen.tactileGain, target: realpen.tactileTarget, "
                         "state: realpen.audio.state})")
        assert held["state"] == "running" and held["target"] > 0
        assert held["tactile"] == pytest.approx(held["target"], abs=1e-3)
        page.pen("mouseReleased", 300, 220, 0.0, time.time())
        page.settle()
        assert page.eval("JSON.parse(localStorage.getItem('realpen.pen'))") == "slowpen"
        assert page.problems == []
    finally:
        page.close()


def test_picking_a_pen_whose_audio_fails_keeps_the_current_pen(open_page):
    page = open_page("?pen=pencil&modality=auditory", broken=["**/api/profiles/marker/*.wav"])
    page.page.click("#pens button[data-value=marker]")
    page.page.wait_for_function("() => realpen.notice !== null")
    state = page.eval("({pen: realpen.pen, version: realpen.profileVersion, "
                      "playing: realpen.audio.playing, notice: realpen.notice, "
                      "saved: JSON.parse(localStorage.getItem('realpen.pen')), "
                      "checked: document.querySelector('#pens [aria-checked=true]').dataset.value,"
                      " shown: !document.getElementById('notice').hidden})")
    assert state["pen"] == "pencil" and state["playing"] == "pencil"
    assert state["version"] == resolve_profile("pencil").version
    assert state["checked"] == "pencil" and state["saved"] == "pencil" and state["shown"]
    assert "marker" in state["notice"] and "still writing with pencil" in state["notice"]
    assert page.problems == []  # no unhandled rejection, no console error
    page.stroke(writing(40), hold_s=0.1, lift=False)  # the pencil still plays
    assert page.eval("realpen.gain") == pytest.approx(page.eval("realpen.targetGain"), abs=1e-3)
    page.pen("mouseReleased", 300, 220, 0.0, time.time())
    page.settle()
    page.page.click("#pens button[data-value=ballpoint]")  # a pen that loads: the notice goes
    page.page.wait_for_function("() => realpen.pen === 'ballpoint' && realpen.notice === null")
    assert page.eval("realpen.audio.playing") == "ballpoint"
    assert page.page.locator("#notice").is_hidden()


def test_a_saved_pen_whose_audio_fails_does_not_block_the_page(open_page):
    page = open_page(storage={"realpen.pen": "marker"}, broken=["**/api/profiles/marker/*.wav"])
    state = page.eval("({pen: realpen.pen, playing: realpen.audio.playing, "
                      "notice: realpen.notice, error: realpen.error, "
                      "saved: JSON.parse(localStorage.getItem('realpen.pen'))})")
    assert state["error"] is None and state["pen"] == "pencil" and state["playing"] == "pencil"
    assert "marker" in state["notice"] and "writing with pencil" in state["notice"]
    assert state["saved"] == "pencil"  # the next load starts with a pen that works
    assert page.problems == []
    page.stroke(writing(30))
    assert page.eval("realpen.link.errors") == 0


# ---- starting audio under the HTML user-activation rules --------------------------------------

# Emulates the HTML rules (Safari on an iPad applies them; desktop Chrome is more lenient: it
# activates on any event of the DevTools protocol, and a page that Playwright opened already has
# sticky activation, so Chrome would start the context as soon as a source starts): only these
# events give user activation — a mouse's pointerdown or mousedown, a pen's or finger's pointerup,
# touchend, a key — for 1 s, and AudioContext.resume() starts the audio only then (otherwise it
# stays pending, as Chrome's does). Each context is suspended by script as it is made, which
# Chrome keeps until resume() is called.
ACTIVATION_RULES = """(() => {
  const Context = window.AudioContext;
  window.AudioContext = class extends Context {
    constructor(...args) { super(...args); Context.prototype.suspend.call(this); }
  };
  let activeUntil = -1;
  const log = [];
  window.__resumeCalls = log;
  const gives = (e) => e.isTrusted && ((e.type === 'keydown' && e.key !== 'Escape')
    || e.type === 'mousedown' || e.type === 'touchend'
    || (e.type === 'pointerdown' && e.pointerType === 'mouse')
    || (e.type === 'pointerup' && e.pointerType !== 'mouse'));
  for (const type of ['keydown', 'mousedown', 'touchend', 'pointerdown', 'pointerup']) {
    window.addEventListener(type, (e) => {
      if (gives(e)) activeUntil = performance.now() + 1000;
    }, true);
  }
  const resume = Context.prototype.resume;
  Context.prototype.resume = function () {
    const e = window.event;
    const allowed = performance.now() < activeUntil;
    log.push({ event: e ? `${e.type}:${e.pointerType || ''}` : null, allowed });
    return allowed ? resume.call(this) : new Promise(() => {});
  };
})();"""


@pytest.fixture
def gesture_browser(chromium):
    """Chromium without the autoplay flag: an AudioContext starts suspended."""
    return chromium(GESTURE_ARGS)


def test_audio_starts_from_the_first_event_that_gives_activation(gesture_browser, server):
    page = Page(gesture_browser, server, "?modality=auditory", init_script=ACTIVATION_RULES)
    try:
        assert page.eval("realpen.audio.state") == "suspended"
        assert page.page.locator("#st-audio").inner_text() == "tap to start audio"
        # A pen's pointerdown gives no activation: refused, and tried again at the next event,
        # anywhere on the page (here on the status bar, where no control is).
        pill = page.page.locator("#st-audio").bounding_box()
        x, y = pill["x"] + pill["width"] / 2, pill["y"] + pill["height"] / 2
        page.pen_at("mousePressed", x, y, 0.5, time.time())
        calls = page.eval("window.__resumeCalls")
        assert calls[0] == {"event": "pointerdown:pen", "allowed": False}
        page.pen_at("mouseReleased", x, y, 0.0, time.time())
        page.page.wait_for_function("() => realpen.audio.state === 'running'", timeout=5000)
        calls = page.eval("window.__resumeCalls")
        # Off the writing surface nothing cancels the pen's pointerdown, so the compatibility
        # mousedown follows it, and that gives activation (the surface's strokes: next test).
        first = next(i for i, c in enumerate(calls) if c["allowed"])
        assert calls[:first + 1] == [{"event": "pointerdown:pen", "allowed": False},
                                     {"event": "mousedown:", "allowed": True}]
        page.page.wait_for_function(
            "() => document.getElementById('st-audio').textContent.startsWith('audio ')")
        # Running: a stroke plays at once, and nothing asks again.
        page.stroke(writing(40), hold_s=0.1, lift=False)
        page.settle_gain()
        assert page.eval("realpen.gain") == pytest.approx(page.eval("realpen.targetGain"),
                                                          abs=1e-3)
        page.pen("mouseReleased", 300, 220, 0.0, time.time())
        page.settle()
        assert len(page.eval("window.__resumeCalls")) == len(calls)
        assert page.problems == []
    finally:
        page.close()


def test_a_pen_stroke_starts_audio_when_the_pen_lifts(gesture_browser, server):
    page = Page(gesture_browser, server, "?modality=auditory", init_script=ACTIVATION_RULES)
    try:
        page.stroke(writing(20), lift=False)
        assert page.eval("realpen.audio.state") == "suspended"  # the pen is down: no activation
        assert page.eval("window.__resumeCalls")[0] == {"event": "pointerdown:pen",
                                                        "allowed": False}
        page.pen("mouseReleased", 300, 220, 0.0, time.time())
        page.page.wait_for_function("() => realpen.audio.state === 'running'", timeout=5000)
        calls = page.eval("window.__resumeCalls")
        first = next(i for i, c in enumerate(calls) if c["allowed"])
        assert calls[:first + 1] == [{"event": "pointerdown:pen", "allowed": False},
                                     {"event": "pointerup:pen", "allowed": True}]
    finally:
        page.close()
