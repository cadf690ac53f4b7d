"""The "Record a pen" API (no browser): takes, the microphone WAV's upload, the accelerometer
through the pen bridge (a fake pen client sending SAMPLES blocks), and Build, after which the
pen is offered at once."""

from __future__ import annotations

import io
import threading
import time
import warnings

import numpy as np
import pytest
import soundfile

pytest.importorskip("fastapi")
pytest.importorskip("httpx")
with warnings.catch_warnings():  # starlette's note about a future httpx successor
    warnings.simplefilter("ignore")
    from fastapi.testclient import TestClient  # noqa: E402

from realpen.device import protocol as P  # noqa: E402
from realpen.device.bridge import PenBridge  # noqa: E402
from realpen.device.client import SampleBlock  # noqa: E402
from realpen.errors import RealPenError  # noqa: E402
from realpen.live.app import LiveSettings, create_app  # noqa: E402
from realpen.live.device import CommandLog  # noqa: E402
from realpen.profile import resolve_profile  # noqa: E402

RATE = 48000
ACCEL_RATE = 1344
TONES_HZ = (150.0, 260.0)


def pencil_sound(seconds: float = 2.4, rate: int = RATE, channels: int = 1,
                 subtype: str = "PCM_16") -> bytes:
    """The bundled pencil's sound unit looped to ``seconds``, as WAV bytes."""
    unit = resolve_profile("pencil").sound
    frames = int(seconds * rate)
    samples = np.resize(unit, frames) * 0.5
    if channels > 1:
        samples = np.column_stack([samples] * channels)
    buffer = io.BytesIO()
    soundfile.write(buffer, samples, rate, format="WAV", subtype=subtype)
    return buffer.getvalue()


def upload(client, take_id: int, wav: bytes, chunk: int = 60 * 1024) -> dict:
    for offset in range(0, len(wav), chunk):
        reply = client.put(f"/api/record/takes/{take_id}/sound?offset={offset}",
                           content=wav[offset:offset + chunk])
        assert reply.status_code == 200, reply.text
    return client.post(f"/api/record/takes/{take_id}/sound")


def wait_build(client, timeout: float = 60.0) -> dict:
    deadline = time.monotonic() + timeout
    while True:
        job = client.get("/api/record/build").json()
        if job["state"] != "running":
            return job
        assert time.monotonic() < deadline, job
        time.sleep(0.05)


@pytest.fixture
def home(tmp_path, monkeypatch):
    monkeypatch.setenv("REALPEN_HOME", str(tmp_path / "home"))
    return tmp_path / "home"


def test_a_microphone_take_builds_a_sound_only_pen_offered_at_once(tmp_path, home):
    app = create_app(LiveSettings.loopback(store=tmp_path / "s.sqlite3", device=CommandLog()))
    with TestClient(app, base_url="http://127.0.0.1") as client:
        status = client.get("/api/record").json()
        assert status["pen"]["accelerometer"] is False and status["takes"] == []
        assert "record.js" in client.get("/record").text
        take = client.post("/api/record/takes", json={}).json()
        assert take["running"] and take["accel_problem"].startswith("no pen connected")
        assert client.post("/api/record/takes", json={}).status_code == 409  # one at a time
        assert client.get("/api/record/live").json()["take"] == take["id"]
        stopped = client.post(f"/api/record/takes/{take['id']}/stop").json()
        assert not stopped["running"] and stopped["accel"] is None
        done = upload(client, take["id"], pencil_sound())
        assert done.status_code == 200, done.text
        sound = done.json()["sound"]
        assert sound["rate"] == RATE and sound["seconds"] == pytest.approx(2.4)
        assert sound["clipped"] == 0 and -30 < sound["rms_dbfs"] < -3

        assert "scribble" not in [p["name"] for p in client.get("/api/profiles").json()["profiles"]]
        assert client.post("/api/record/build", json={"name": "scribble", "tool": "pencil"}
                           ).status_code == 202
        job = wait_build(client)
        assert job["state"] == "done", job
        offered = {p["name"]: p for p in client.get("/api/profiles").json()["profiles"]}
        assert offered["scribble"]["where"] == "user" and offered["scribble"]["tool"] == "pencil"
        assert client.get("/api/profiles/scribble/sound.wav").status_code == 200
        assert (home / "profiles" / "scribble" / "profile.json").exists()
        # A pen recorded again under its name replaces the installed one; a bundled name is
        # refused before any work.
        assert client.post("/api/record/build", json={"name": "scribble"}).status_code == 202
        assert wait_build(client)["state"] == "done"
        refused = client.post("/api/record/build", json={"name": "pencil"})
        assert refused.status_code == 422 and "bundled" in refused.json()["detail"]


def test_bad_uploads_are_refused_in_one_line(tmp_path, home):
    app = create_app(LiveSettings.loopback(store=tmp_path / "s.sqlite3", device=CommandLog()))
    with TestClient(app, base_url="http://127.0.0.1") as client:
        take = client.post("/api/record/takes", json={"accelerometer": False}).json()
        early = client.put(f"/api/record/takes/{take['id']}/sound?offset=0", content=b"RIFF")
        assert early.status_code == 409 and "stop it" in early.json()["detail"]
        client.post(f"/api/record/takes/{take['id']}/stop")
        skipped = client.put(f"/api/record/takes/{take['id']}/sound?offset=10", content=b"x")
        assert skipped.status_code == 422
        assert skipped.json()["detail"] == (f"take {take['id']}: sound chunk at byte 10, "
                                            f"expected 0 (chunks in order)")
        cases = {"not a readable WAV": b"RIFF" + b"\0" * 100,
                 "2 channels, expected 1 (mono)": pencil_sound(0.5, channels=2),
                 "22050 Hz, expected 44100 or 48000 Hz": pencil_sound(0.5, rate=22050),
                 "PCM_24 samples": pencil_sound(0.5, subtype="PCM_24")}
        for problem, wav in cases.items():
            reply = upload(client, take["id"], wav)
            assert reply.status_code == 422, problem
            detail = reply.json()["detail"]
            assert detail.startswith(f"take {take['id']} sound: ") and problem in detail
            assert "\n" not in detail
        big = client.put(f"/api/record/takes/{take['id']}/sound?offset=0",
                         content=b"\0" * (64 * 1024 + 1))
        assert big.status_code == 413  # each chunk within the server's body limit
        assert client.post("/api/record/build", json={"name": "nothing"}).status_code == 422
        assert client.delete(f"/api/record/takes/{take['id']}").status_code == 204
        assert client.get("/api/record").json()["takes"] == []
        assert client.post(f"/api/record/takes/{take['id']}/stop").status_code == 422
        assert client.post("/api/record/build", json={"name": "x", "actuator": "/etc/passwd"}
                           ).status_code == 422


# ---- the accelerometer through the pen bridge ------------------------------------------------

INFO = {"protocol": 1, "fw_major": 1, "fw_minor": 0, "fw_patch": 0, "sample_rate": 8000,
        "max_pattern_bytes": 32768, "features": P.FEATURE_USB | P.FEATURE_ACCEL,
        "name": "fake pen"}


class SensorClient:
    """A pen client whose accelerometer feels two tones on x (and gravity on z), sent as
    SAMPLES blocks of 32 with the pen's clock, as fast as they are read."""

    def __init__(self):
        self.capturing = False
        self.index = 0
        self.lock = threading.Lock()

    def hello(self):
        return dict(INFO)

    def ping(self):
        return 0.001, 0

    def read_event(self, timeout=None):
        return None

    def set_state(self, *args, **kwargs):
        pass

    def upload(self, samples, rate, **kwargs):
        return 1

    def close(self):
        pass

    def start_capture(self, range_g=2, rate_hz=1344):
        self.capturing, self.index, self.range_g = True, 0, range_g

    def stop_capture(self):
        self.capturing = False

    def read_samples(self, timeout=None):
        if not self.capturing:
            return None
        time.sleep(0.002)
        n = P.MAX_BLOCK_SAMPLES
        t = (self.index + np.arange(n)) / ACCEL_RATE
        x = sum(0.2 * np.sin(2 * np.pi * f * t) for f in TONES_HZ)
        digits = np.column_stack([x * 1000, 0 * t, np.full(n, 1000.0)])  # mg at ±2 g
        raw = (np.rint(digits).astype(np.int16) << 4).astype("<i2")
        t_us = int((self.index + n) / ACCEL_RATE * 1e6)
        payload = P.pack_samples(self.index, t_us, self.range_g, 0, raw.tobytes())
        self.index += n
        return SampleBlock.from_payload(payload, time.monotonic())


def test_accelerometer_and_microphone_takes_build_a_pen(tmp_path, home):
    client_side = SensorClient()
    bridge = PenBridge(lambda: client_side, name="fake", kind="test", log=CommandLog())
    app = create_app(LiveSettings.loopback(store=tmp_path / "s.sqlite3", device=bridge))
    with TestClient(app, base_url="http://127.0.0.1") as client:
        deadline = time.monotonic() + 5
        while not client.get("/api/record").json()["pen"]["accelerometer"]:
            assert time.monotonic() < deadline
            time.sleep(0.02)
        take = client.post("/api/record/takes", json={"range_g": 2}).json()
        while client.get("/api/record/live").json()["accel"]["samples"] < 3 * ACCEL_RATE:
            time.sleep(0.02)
        live = client.get("/api/record/live").json()["accel"]
        # x holds two tones of 0.2 g: RMS 0.2 g (1.96 m/s²); y nothing; z only gravity
        assert live["rms_ms2"][0] == pytest.approx(0.2 * 9.80665, rel=0.05)
        assert live["rms_ms2"][1] == 0 and live["clipped"] == 0
        stopped = client.post(f"/api/record/takes/{take['id']}/stop").json()
        accel = stopped["accel"]
        assert accel and stopped["accel_problem"] is None
        assert accel["rate_hz"] == pytest.approx(ACCEL_RATE, rel=1e-3)
        assert accel["gaps"] == 0 and accel["seconds"] >= 3
        assert upload(client, take["id"], pencil_sound()).status_code == 200
        short = client.post("/api/record/takes", json={}).json()  # left out of Build
        client.post(f"/api/record/takes/{short['id']}/stop")
        assert client.patch(f"/api/record/takes/{short['id']}", json={"keep": False}
                            ).json()["keep"] is False
        assert client.post("/api/record/build", json={"name": "felt"}).status_code == 202
        job = wait_build(client)
        assert job["state"] == "done", job
    bridge.close()
    profile = resolve_profile("felt")
    frequencies = [c.frequency_hz for sub in profile.meta.tactile.subpatterns for c in sub]
    for tone in TONES_HZ:
        assert min(abs(f - tone) for f in frequencies) < 5
    assert profile.meta.sound.rate == RATE


def test_a_pen_without_a_sensor_records_the_microphone_only(tmp_path, home):
    class NoSensor(SensorClient):
        def start_capture(self, range_g=2, rate_hz=1344):
            raise RealPenError("fake: the pen has no accelerometer")

    bridge = PenBridge(NoSensor, name="fake", kind="test", log=CommandLog())
    app = create_app(LiveSettings.loopback(store=tmp_path / "s.sqlite3", device=bridge))
    with TestClient(app, base_url="http://127.0.0.1") as client:
        deadline = time.monotonic() + 5
        while not client.get("/api/record").json()["pen"]["connected"]:
            assert time.monotonic() < deadline
            time.sleep(0.02)
        take = client.post("/api/record/takes", json={}).json()
        stopped = client.post(f"/api/record/takes/{take['id']}/stop").json()
        assert stopped["accel"] is None
        assert stopped["accel_problem"] == "fake: the pen has no accelerometer"
        assert bridge.status()["connected"]  # a refusal is no reason to drop the link
    bridge.close()


def test_a_capture_lets_the_pages_commands_through_and_runs_one_at_a_time(tmp_path):
    from realpen.live.device import Origin

    class Logged(SensorClient):
        def __init__(self):
            super().__init__()
            self.states = []

        def set_state(self, playing, gain, rate=1.0, fade_ms=5):
            self.states.append((int(playing), round(gain, 3), self.capturing))

    pen = Logged()
    bridge = PenBridge(lambda: pen, name="fake", kind="test", log=CommandLog(),
                       pattern=lambda profile, rate: np.zeros(80, dtype=np.int16))
    try:
        blocks: list = []
        run = bridge.capture(blocks.append)
        assert run.started.wait(5) and run.info["name"] == "fake pen"
        other = bridge.capture(blocks.append)
        origin = Origin("s", 1, 0)
        bridge.pen_down(origin, resolve_profile("pencil"), True)
        bridge.gain(origin, resolve_profile("pencil").meta.coupling.a_max)
        deadline = time.monotonic() + 5
        while len(pen.states) < 2 or not other.done:
            assert time.monotonic() < deadline, pen.states
            time.sleep(0.01)
        assert other.error == "another capture is running"
        assert pen.states[:2] == [(1, 0.0, True), (1, 1.0, True)]  # played while capturing
        assert run.stop(5) is None and not pen.capturing and blocks
    finally:
        bridge.close()


def test_the_page_and_the_server_agree_on_sizes():
    import math
    import re
    from pathlib import Path

    from realpen.live import recording
    from realpen.live.bodies import MAX_BODY_BYTES
    from realpen.live.routes.pages import STATIC_DIR

    wav_js = Path(STATIC_DIR, "record-wav.js").read_text()
    product = re.search(r"export const CHUNK_BYTES = ([0-9 *]+);", wav_js).group(1)
    chunk = math.prod(int(factor) for factor in product.split("*"))
    assert chunk <= MAX_BODY_BYTES
    assert f"magnitude >= {recording.MIC_CLIP}" in wav_js
    page_js = Path(STATIC_DIR, "record.js").read_text()
    rate = int(re.search(r"const SAMPLE_RATE = (\d+);", page_js).group(1))
    assert rate in recording.SOUND_RATES
