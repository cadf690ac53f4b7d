"""The "Record a pen" page in a real browser: Debian's Chromium (Playwright) with a fake
microphone fed from a WAV of pencil friction sound, the live app in this process driving the
simulated pen (its firmware under the MicroPython Unix port, with its simulated LIS3DH).

One take records the sim pen's accelerometer through the server and the microphone on the page;
it is kept, Build makes the pen, and the writing page's pen picker offers it at once. The
screenshots of the take and of the picker after Build go to ``test-artifacts/`` (when that
folder can be made) for a person to look at.
"""

from __future__ import annotations

import threading
import time
from pathlib import Path

import numpy as np
import pytest
import soundfile
from live_support import CHROMIUM, CHROMIUM_ARGS, CHROMIUM_MISSING

from realpen.profile import resolve_profile

if not CHROMIUM.exists():
    pytest.skip(CHROMIUM_MISSING, allow_module_level=True)
pytest.importorskip("playwright.sync_api", reason="playwright is not installed")

SHOTS = Path(__file__).resolve().parents[1] / "test-artifacts"
NAME = "recorded-pencil"


def fake_microphone(path: Path, seconds: float = 6.0) -> Path:
    """The bundled pencil's friction sound, looped, as a 48 kHz mono 16-bit WAV: what
    Chromium's fake microphone plays (again and again)."""
    unit = resolve_profile("pencil").sound
    samples = np.resize(unit, int(seconds * 48000)) * 0.5
    soundfile.write(path, samples, 48000, subtype="PCM_16")
    return path


@pytest.fixture(scope="module")
def served(tmp_path_factory):
    """The live app with ``--device sim``, under uvicorn on a thread; yields its base URL."""
    import socket

    import uvicorn

    from realpen.live.app import LiveSettings, create_app
    from realpen.live.device import open_device

    folder = tmp_path_factory.mktemp("record")
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("REALPEN_HOME", str(folder / "home"))
        device = open_device("sim")
        app = create_app(LiveSettings.loopback(store=folder / "s.sqlite3", device=device))
        sock = socket.socket()
        sock.bind(("127.0.0.1", 0))
        server = uvicorn.Server(uvicorn.Config(app, log_level="warning"))
        thread = threading.Thread(target=server.run, kwargs={"sockets": [sock]}, daemon=True)
        thread.start()
        deadline = time.monotonic() + 30
        while not server.started:
            assert thread.is_alive() and time.monotonic() < deadline, "the live app did not start"
            time.sleep(0.01)
        try:
            yield f"http://127.0.0.1:{sock.getsockname()[1]}/", folder
        finally:
            server.should_exit = True
            thread.join(timeout=20)
            sock.close()


def shot(page, name: str) -> None:
    try:
        SHOTS.mkdir(parents=True, exist_ok=True)
    except OSError:
        return
    page.screenshot(path=str(SHOTS / name), full_page=True)


def test_record_a_take_keep_it_build_and_the_pen_is_in_the_picker(chromium, served, tmp_path):
    base, _ = served
    wav = fake_microphone(tmp_path / "pencil-friction.wav")
    browser = chromium([*CHROMIUM_ARGS, "--use-fake-ui-for-media-stream",
                        "--use-fake-device-for-media-stream",
                        f"--use-file-for-fake-audio-capture={wav}"])
    context = browser.new_context(viewport={"width": 1100, "height": 900})
    context.set_default_timeout(20_000)
    page = context.new_page()
    problems: list[str] = []
    page.on("pageerror", lambda error: problems.append(str(error)))
    try:
        page.goto(base + "record")
        page.wait_for_function("() => window.realpenRecord && window.realpenRecord.ready")
        if page.evaluate("() => window.realpenRecord.mic.state") != "on":
            page.click("#mic-start")
        page.wait_for_function("() => window.realpenRecord.mic.state === 'on'")
        settings = page.evaluate("() => window.realpenRecord.mic.settings")
        assert page.evaluate("() => window.realpenRecord.mic.rate") == 48000
        assert not settings.get("echoCancellation") and not settings.get("autoGainControl")
        assert not settings.get("noiseSuppression")
        # The sim pen (server side) connects and says it has an accelerometer.
        page.wait_for_function("() => document.querySelector('#accel-state').textContent"
                               ".startsWith('Recording the accelerometer')")

        page.click("#record")
        page.wait_for_function("() => { const l = window.realpenRecord.level;"
                               " return l && l.accel && l.accel.samples > 1344 * 2.5; }")
        page.wait_for_function("() => document.querySelector('#mic-level-value').textContent"
                               ".endsWith('dBFS')")
        shot(page, "record-take.png")
        page.click("#record")  # Stop
        page.wait_for_selector("#takes-body tr[data-take] td:nth-child(4):has-text('dBFS')")
        row = page.locator("#takes-body tr[data-take]").first
        assert "Hz" in row.locator("td").nth(2).inner_text()  # the accelerometer's rate
        assert row.locator("input[type=checkbox]").is_checked()  # kept
        shot(page, "record-takes.png")

        page.fill("#name", NAME)
        page.select_option("#tool", "pencil")
        page.click("#build")
        page.wait_for_selector("#write-with", timeout=60_000)
        assert NAME in page.inner_text("#build-state")
        page.click("#write-with")
        page.wait_for_function("() => window.realpen && window.realpen.ready")
        button = page.locator(f"#pens button[data-value='{NAME}']")
        assert button.get_attribute("aria-checked") == "true"
        shot(page, "record-built-pen-in-picker.png")
        assert not problems, problems
    finally:
        context.close()
