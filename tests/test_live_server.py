"""The live server: routes, the WebSocket protocol, the store, the device, tokens, Ctrl-C."""

from __future__ import annotations

import csv
import io
import json
import signal
import socket
import warnings

import numpy as np
import pytest
import soundfile as sf

pytest.importorskip("fastapi")
pytest.importorskip("httpx")
with warnings.catch_warnings():  # starlette's note about a future httpx successor
    warnings.simplefilter("ignore")
    from fastapi.testclient import TestClient  # noqa: E402

from conftest import assert_clean_failure, run_cli, store_rows  # noqa: E402
from live_support import (  # noqa: E402
    LOCAL,
    WS,
    low_rate_profile,
    rows,
    serve,
    stroke_messages,
    talk,
)

from realpen.errors import RealPenError  # noqa: E402
from realpen.exports.base import resample_loop  # noqa: E402
from realpen.live.app import LiveSettings, create_app  # noqa: E402
from realpen.live.catalog import MIN_WAV_RATE, playable_rate, playable_wav  # noqa: E402
from realpen.live.messages import MAX_MESSAGE_BYTES, MessageError, parse_message  # noqa: E402
from realpen.live.store import CSV_COLUMNS, StrokeStore, export_csv  # noqa: E402
from realpen.motion.trajectory import load_trajectory  # noqa: E402
from realpen.profile import load_profile, resolve_profile, save_profile  # noqa: E402


def device_log(client) -> list[dict]:
    return client.get("/api/device/log").json()["entries"]


# ---- HTTP -----------------------------------------------------------------------------------

def test_page_config_and_profiles(client):
    page = client.get("/")
    assert page.status_code == 200 and 'src="static/app.js"' in page.text
    for name in ("app.js", "audio.js", "pen.js", "coupling.js", "ink.js", "link.js", "style.css"):
        assert client.get(f"/static/{name}").status_code == 200, name
    config = client.get("/api/config").json()
    assert config["tactile"] == "none" and config["token_required"] is False
    assert config["modalities"] == ["tactile", "auditory", "audio-tactile", "none"]
    profiles = client.get("/api/profiles").json()["profiles"]
    assert [p["name"] for p in profiles][:3] == ["pencil", "ballpoint", "marker"]
    for entry in profiles[:3]:
        profile = resolve_profile(entry["name"])
        assert entry["version"] == profile.version
        assert entry["coupling"] == profile.meta.coupling.to_json()
        for part, samples, rate in (("sound", profile.sound, profile.meta.sound.rate),
                                    ("tactile", profile.tactile, profile.meta.tactile.rate)):
            response = client.get(f"/{entry[part]['url']}")
            assert response.headers["content-type"] == "audio/wav"
            decoded, decoded_rate = sf.read(io.BytesIO(response.content), dtype="float32")
            assert decoded_rate == rate and np.array_equal(decoded, samples)
    assert client.get("/api/profiles/nosuch/sound.wav").status_code == 404
    assert client.get("/api/profiles/pencil/other.wav").status_code in (404, 422)


def test_extra_profiles_folder_and_a_broken_bundle(tmp_path, monkeypatch):
    monkeypatch.setenv("REALPEN_HOME", str(tmp_path / "home"))
    extra = tmp_path / "pens"
    pencil = resolve_profile("pencil")
    pencil.meta = pencil.meta.model_copy(update={"name": "fountain", "tool": "fountain pen"})
    save_profile(pencil, extra / "fountain")
    (extra / "broken").mkdir()
    (extra / "broken" / "profile.json").write_text("{not json")
    app = create_app(LiveSettings.loopback(store=tmp_path / "s.sqlite3", profiles=[extra]))
    with TestClient(app, base_url=LOCAL) as client:
        names = [p["name"] for p in client.get("/api/profiles").json()["profiles"]]
        assert names == ["pencil", "ballpoint", "marker", "fountain"]
        assert client.get("/api/profiles/fountain/tactile.wav").status_code == 200
    assert any("broken" in problem for problem in app.state.live.catalog.skipped)
    assert load_profile(extra / "fountain").name == "fountain"
    with pytest.raises(RealPenError, match="no such folder"):
        create_app(LiveSettings(store=tmp_path / "s.sqlite3", profiles=[tmp_path / "nope"]))


def test_tactile_below_3_khz_is_served_at_a_rate_browsers_decode(tmp_path, monkeypatch):
    """Chrome's decodeAudioData refuses WAVs below 3 kHz: a 2 kHz tactile pattern is served
    resampled (as a loop) to the sound's rate, and the profile itself is unchanged."""
    monkeypatch.setenv("REALPEN_HOME", str(tmp_path / "home"))
    slow = load_profile(low_rate_profile(tmp_path / "low"))
    app = create_app(LiveSettings.loopback(store=tmp_path / "s.sqlite3",
                                           profiles=[tmp_path / "low"]))
    with TestClient(app, base_url=LOCAL) as client:
        (entry,) = [p for p in client.get("/api/profiles").json()["profiles"]
                    if p["name"] == "slowpen"]
        sound_rate = slow.meta.sound.rate
        assert entry["tactile"]["rate"] == 2000 and entry["tactile"]["frames"] == 3000
        assert entry["tactile"]["wav_rate"] == sound_rate
        assert entry["sound"]["wav_rate"] == sound_rate
        tactile, rate = sf.read(io.BytesIO(client.get(f"/{entry['tactile']['url']}").content),
                                dtype="float64")
        assert rate == sound_rate >= MIN_WAV_RATE and len(tactile) == 3000 * sound_rate // 2000
        expected = resample_loop(slow.tactile, 2000, sound_rate)
        expected /= max(1.0, np.max(np.abs(expected)))  # the filter's overshoot: back to peak 1
        assert np.allclose(tactile, expected, atol=1e-6)
        assert 0.99 < np.max(np.abs(tactile)) <= 1.0
        # Still a seamless loop: the step across the wrap is like the steps inside.
        steps = np.abs(np.diff(np.concatenate([tactile, tactile[:1]])))
        assert steps[-1] <= 1.01 * steps[:-1].max()
        sound, rate = sf.read(io.BytesIO(client.get(f"/{entry['sound']['url']}").content),
                              dtype="float32")
        assert rate == sound_rate and np.array_equal(sound, slow.sound)
    # The bundled pens (8 kHz) are served as they are (test_page_config_and_profiles).
    assert app.state.live.catalog.get("pencil").tactile_rate == 8000


def test_playable_rates_keep_a_whole_number_of_samples():
    assert playable_rate(12000, 8000, 48000) == 8000  # at or above 3 kHz: unchanged
    assert playable_rate(3000, 2000, 48000) == 48000  # the sound's rate when the loop fits
    assert playable_rate(3001, 2001, 48000) == 4002  # else a whole multiple of its own rate
    assert playable_rate(100, 1000, 2000) == 3000
    assert playable_rate(7, 2999, 44100) == 5998
    period = np.sin(2 * np.pi * 5 * np.arange(3001) / 3001)  # 5 cycles: a seamless loop
    samples, rate = sf.read(io.BytesIO(playable_wav(period, 2001, 48000, "test")), dtype="float64")
    assert rate == 4002 and len(samples) == 6002
    assert np.allclose(samples, np.sin(2 * np.pi * 5 * np.arange(6002) / 6002), atol=5e-3)


def test_host_header_must_be_loopback(client):
    assert client.get("/api/config", headers={"host": "evil.example:8765"}).status_code == 400
    assert client.get("/api/config", headers={"host": "localhost:8765"}).status_code == 200


# ---- the WebSocket protocol -----------------------------------------------------------------

def test_stroke_reaches_device_in_order_and_the_store(client, store_path):
    messages = stroke_messages("pencil", n=12)
    with client.websocket_connect(WS) as ws:
        hello = talk(ws, {"type": "hello", "seq": 0, "client": "test"})
        assert hello["type"] == "ack" and hello["of"] == "hello" and hello["session"]
        replies = [talk(ws, m) for m in messages]
    assert [r["type"] for r in replies] == ["ack"] * len(messages)
    assert [r["seq"] for r in replies] == [m["seq"] for m in messages]
    stroke_id = replies[0]["stroke_id"]
    log = device_log(client)
    kinds = [e["kind"] for e in log]
    assert kinds[0] == "pen_down" and kinds[-1] == "pen_up"
    assert set(kinds[1:-1]) == {"gain"}
    assert [e["index"] for e in log] == list(range(len(log)))
    assert all(a["at_ns"] <= b["at_ns"] for a, b in zip(log, log[1:]))
    gains = [m["target"] for m in messages if m["type"] == "gain"]
    assert [e["value"] for e in log if e["kind"] == "gain"] == gains
    assert log[0]["detail"]["pen"] == "pencil" and log[0]["detail"]["tactile"] is True
    assert {e["session"] for e in log} == {hello["session"]}
    (stroke,) = rows(store_path, "SELECT id, pen, profile_version, modality, ink, pointer_type, "
                                 "sample_count, end_reason, ended_at FROM strokes")
    assert stroke[:8] == (stroke_id, "pencil", resolve_profile("pencil").version,
                          "audio-tactile", "visible", "pen", 12, "pen_up")
    assert stroke[8] is not None
    samples = rows(store_path, "SELECT seq, t, x, y, pressure, tilt_x, tilt_y, speed FROM samples "
                               "ORDER BY seq")
    assert [s[0] for s in samples] == list(range(12))
    assert samples[0][1] == 0.0 and samples[3][1] == pytest.approx(0.015)
    assert samples[5][4:] == (0.6, 12.0, -3.0, 60.0)


def test_modality_without_touch_sends_no_gains_to_the_device(client):
    with client.websocket_connect(WS) as ws:
        for message in stroke_messages("marker", modality="auditory", n=5):
            assert talk(ws, message)["type"] == "ack"
    log = device_log(client)
    assert [e["kind"] for e in log] == ["pen_down", "pen_up"]
    assert log[0]["detail"]["tactile"] is False


@pytest.mark.parametrize("frame, code, words", [
    ("{not json", "invalid_json", "not valid JSON"),
    ("[1, 2]", "invalid_message", ""),
    ('{"type": "scribble", "seq": 3}', "invalid_message", "scribble"),
    ('{"type": "pen_up", "seq": 4}', "invalid_message", "stroke"),
    ('{"type": "hello", "seq": 5, "client": "x", "extra": 1}', "invalid_message", "extra"),
    ('{"type": "samples", "seq": 6, "stroke": 1, "samples": [{"t": 0, "x": 0, "y": 0, '
     '"pressure": 1.5, "speed": 0}]}', "invalid_message", "pressure"),
    ('{"type": "samples", "seq": 7, "stroke": 1, "samples": [{"t": NaN, "x": 0, "y": 0, '
     '"pressure": 0.5, "speed": 0}]}', "invalid_message", "t"),
    ('{"type": "samples", "seq": 8, "stroke": 1, "samples": []}', "invalid_message", "samples"),
    ('{"type": "gain", "seq": 9, "stroke": 1, "t": 0, "target": -1}', "invalid_message",
     "target"),
    ('{"type": "samples", "seq": 10, "stroke": 1, "samples": [{"t": 0, "x": 0, "y": 0, '
     '"pressure": 0.5, "speed": 0}]}', "protocol", "not down"),
    ('{"type": "pen_up", "seq": 11, "stroke": 1, "t": 0}', "protocol", "not down"),
])
def test_bad_messages_get_an_error_and_the_connection_lives(client, frame, code, words):
    with client.websocket_connect(WS) as ws:
        ws.send_text(frame)
        reply = json.loads(ws.receive_text())
        assert reply["type"] == "error" and reply["code"] == code, reply
        assert words in reply["message"]
        if '"seq": ' in frame and code != "invalid_json":
            assert reply["seq"] == json.loads(frame.replace("NaN", "0"))["seq"]
        assert talk(ws, {"type": "hello", "seq": 99, "client": "after"})["type"] == "ack"
    assert client.get("/api/status").status_code == 200


def test_oversized_binary_and_unknown_pen_messages(client):
    pencil = resolve_profile("pencil")
    with client.websocket_connect(WS) as ws:
        big = json.dumps({"type": "hello", "seq": 1, "client": "x" * MAX_MESSAGE_BYTES})
        ws.send_text(big)
        reply = json.loads(ws.receive_text())
        assert reply["code"] == "too_large" and str(MAX_MESSAGE_BYTES) in reply["message"]
        ws.send_bytes(b"\x00\x01")
        assert json.loads(ws.receive_text())["code"] == "binary"
        samples = [{"t": 0, "x": 0, "y": 0, "pressure": 0.5, "speed": 0}] * 513
        reply = talk(ws, {"type": "samples", "seq": 2, "stroke": 1, "samples": samples})
        assert reply["code"] in ("invalid_message", "too_large")
        down = stroke_messages("pencil", n=1)[0]
        reply = talk(ws, {**down, "pen": "quill"})
        assert reply["code"] == "unknown_pen" and "quill" in reply["message"]
        reply = talk(ws, {**down, "profile_version": "0" * 12})
        assert reply["code"] == "unknown_pen" and pencil.version in reply["message"]
        assert talk(ws, down)["type"] == "ack"
        reply = talk(ws, {"type": "gain", "seq": 5, "stroke": 1, "t": 10.0, "target": 3.5})
        assert reply["code"] == "invalid_message" and "a_max" in reply["message"]
        assert talk(ws, {"type": "pen_up", "seq": 6, "stroke": 1, "t": 10.1})["type"] == "ack"


@pytest.mark.parametrize("message, field", [
    ({"type": "hello", "seq": True, "client": "x"}, "seq"),
    ({"type": "hello", "seq": "3", "client": "x"}, "seq"),
    ({"type": "hello", "seq": 1.0, "client": "x"}, "seq"),
    ({"type": "hello", "seq": 1, "client": 7}, "client"),
    ({"type": "gain", "seq": 1, "stroke": True, "t": 0, "target": 1}, "stroke"),
    ({"type": "gain", "seq": 1, "stroke": 1, "t": "0", "target": 1}, "t"),
    ({"type": "gain", "seq": 1, "stroke": 1, "t": 0, "target": False}, "target"),
    ({"type": "samples", "seq": 1, "stroke": 1, "samples": [
        {"t": 0, "x": 0, "y": 0, "pressure": "0.5", "speed": 0}]}, "pressure"),
    ({"type": "pen_up", "seq": 1, "stroke": "1", "t": 0}, "stroke"),
])
def test_message_types_are_strict(message, field):
    """No coercion: true is not seq 1, "0.5" is not a pressure, "1" is not a stroke."""
    with pytest.raises(MessageError) as caught:
        parse_message(json.dumps(message))
    assert caught.value.code == "invalid_message" and field in caught.value.message
    if isinstance(message["seq"], int) and not isinstance(message["seq"], bool):
        assert caught.value.seq == message["seq"]
    else:
        assert caught.value.seq is None


def test_strict_pen_down_takes_only_real_booleans(client):
    down = stroke_messages("pencil", n=1)[0]
    with client.websocket_connect(WS) as ws:
        reply = talk(ws, {"type": "hello", "seq": True, "client": "x"})
        assert reply["type"] == "error" and reply["code"] == "invalid_message"
        assert "seq" not in reply  # never acked as seq 1
        for calibrated in (1, "true"):
            reply = talk(ws, {**down, "calibrated": calibrated})
            assert reply["code"] == "invalid_message" and "calibrated" in reply["message"]
        assert talk(ws, {**down, "px_per_mm": 4})["type"] == "ack"  # a JSON integer is a number


def test_parse_message_limits():
    with pytest.raises(MessageError) as caught:
        parse_message("x" * 10, limit=5)
    assert caught.value.code == "too_large"
    assert parse_message('{"type":"hello","seq":0,"client":"a"}').type == "hello"


def test_one_stroke_sample_definition_for_messages_store_and_rendering(store_target, tmp_path):
    from realpen.io.strokes import SAMPLE_FIELDS, StrokeSample
    from realpen.live import messages, store
    from realpen.motion.trajectory import Trajectory

    assert messages.Sample is StrokeSample
    assert store.SAMPLE_FIELDS == SAMPLE_FIELDS == tuple(StrokeSample.model_fields)
    assert store.CSV_COLUMNS[-len(SAMPLE_FIELDS):] == SAMPLE_FIELDS
    strokes = store.StrokeStore(store_target)
    sid = strokes.begin_stroke(session="s", page_stroke=1, pen="pencil",
                               profile_version="0" * 12, modality="none", ink="hidden",
                               pointer_type="pen", px_per_mm=3.78, calibrated=False, page_t0=5.0)
    samples = [StrokeSample(t=5.0 + k / 100, x=float(k), y=2.0, pressure=0.5, tilt_x=10.0,
                            speed=100.0 * (k > 0)) for k in range(4)]
    strokes.add_samples(sid, samples)
    strokes.close()
    columns = [row[0] for row in store_rows(store_target, (
        "SELECT name FROM pragma_table_info('samples')" if strokes.path else
        "SELECT column_name FROM information_schema.columns WHERE table_name = 'samples' "
        "ORDER BY ordinal_position"))]
    assert tuple(columns[2:]) == SAMPLE_FIELDS
    store.export_csv(store_target, tmp_path / "s.csv", stroke=sid)
    trajectory = load_trajectory(tmp_path / "s.csv")
    assert trajectory.tilt_x.tolist() == [10.0] * 4
    again = Trajectory.from_samples(samples)
    np.testing.assert_allclose(trajectory.t + 5.0, again.t)
    np.testing.assert_allclose(trajectory.speed(), [0, 100, 100, 100])


def test_two_pages_at_once(client, store_path):
    first, second = stroke_messages("pencil", n=6), stroke_messages("ballpoint", n=6)
    with client.websocket_connect(WS) as a, client.websocket_connect(WS) as b:
        sessions = [talk(a, {"type": "hello", "seq": 0, "client": "a"})["session"],
                    talk(b, {"type": "hello", "seq": 0, "client": "b"})["session"]]
        assert sessions[0] != sessions[1]
        assert client.get("/api/status").json()["pages"] == 2
        for m1, m2 in zip(first, second):  # interleaved, message by message
            assert talk(a, m1)["type"] == "ack"
            assert talk(b, m2)["type"] == "ack"
    log = device_log(client)
    for session, pen in zip(sessions, ("pencil", "ballpoint")):
        kinds = [e["kind"] for e in log if e["session"] == session]
        assert kinds[0] == "pen_down" and kinds[-1] == "pen_up" and len(kinds) == 8
        assert [e["detail"]["pen"] for e in log
                if e["session"] == session and e["kind"] == "pen_down"] == [pen]
    stored = rows(store_path, "SELECT session, pen, sample_count FROM strokes ORDER BY id")
    assert sorted(stored) == sorted([(sessions[0], "pencil", 6), (sessions[1], "ballpoint", 6)])


def test_disconnect_and_new_pen_down_end_the_open_stroke(client, store_path):
    messages = stroke_messages("pencil", n=4)
    with client.websocket_connect(WS) as ws:
        for m in messages[:5]:  # pen_down and two samples, no pen_up
            talk(ws, m)
        again = stroke_messages("pencil", stroke=2, n=2, seq0=10)
        for m in again[:3]:
            talk(ws, m)
    # The disconnect's end is queued to the store's writer; any request through the store comes
    # after it, so once /api/status answers, it is committed.
    assert client.get("/api/status").json()["strokes"] == 2
    ends = rows(store_path, "SELECT page_stroke, end_reason FROM strokes ORDER BY id")
    assert ends == [(1, "replaced"), (2, "disconnect")]
    kinds = [e["kind"] for e in device_log(client)]
    assert kinds == ["pen_down", "gain", "gain", "pen_up", "pen_down", "gain", "pen_up"]


# ---- the store and its export ----------------------------------------------------------------

def test_store_in_a_place_it_cannot_be_made(tmp_path):
    blocker = tmp_path / "f"
    blocker.write_text("a file")
    for path in (blocker / "x.sqlite3", "/proc/x.sqlite3", tmp_path):
        with pytest.raises(RealPenError, match=f"^{path}: ") as caught:
            StrokeStore(path)
        assert "\n" not in str(caught.value)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["f"]


def test_discard_removes_only_a_new_empty_store(tmp_path):
    new = StrokeStore(tmp_path / "new.sqlite3")
    new.discard()
    assert list(tmp_path.iterdir()) == []
    kept = StrokeStore(tmp_path / "kept.sqlite3")
    kept.begin_stroke(session="s", page_stroke=1, pen="pencil", profile_version="0" * 12,
                      modality="none", ink="visible", pointer_type="pen", px_per_mm=4.0,
                      calibrated=False, page_t0=0.0)
    kept.discard()
    again = StrokeStore(tmp_path / "kept.sqlite3")  # it existed: never removed
    again.discard()
    assert StrokeStore(tmp_path / "kept.sqlite3").count() == (1, 0)


def test_store_reopens_and_refuses_other_files(store_target, tmp_path):
    store = StrokeStore(store_target)
    sid = store.begin_stroke(session="s", page_stroke=1, pen="pencil", profile_version="0" * 12,
                             modality="none", ink="hidden", pointer_type="mouse", px_per_mm=3.78,
                             calibrated=False, page_t0=5.0)
    store.add_samples(sid, [(5.0, 1, 2, 0.5, 0, 0, 0), (5.01, 1.5, 2, 0.5, 0, 0, 50.0)])
    store.close()
    if store.path is not None:  # SQLite: the journal is checkpointed into the file and removed
        assert not (tmp_path / "s.sqlite3-wal").exists()
    again = StrokeStore(store_target)
    assert again.count() == (1, 2)
    again.close()
    bogus = tmp_path / "bogus.sqlite3"
    bogus.write_text("hello")
    with pytest.raises(RealPenError, match="not a RealPen stroke store"):
        StrokeStore(bogus)
    with pytest.raises(RealPenError, match="no such stroke store"):
        export_csv(tmp_path / "missing.sqlite3", tmp_path / "out.csv")


def test_strokes_export_cli(client, store_path, tmp_path):
    with client.websocket_connect(WS) as ws:
        for message in stroke_messages("pencil", n=8) + stroke_messages("marker", stroke=2, n=5,
                                                                        seq0=100):
            talk(ws, message)
    out = tmp_path / "strokes.csv"
    result = run_cli("strokes", "export", "--store", store_path, "-o", out)
    assert result.returncode == 0, result.stderr
    assert "13 samples of 2 strokes" in result.stdout
    with open(out, newline="") as handle:
        table = list(csv.DictReader(handle))
    assert tuple(table[0]) == CSV_COLUMNS and len(table) == 13
    assert {r["pen"] for r in table} == {"pencil", "marker"}
    assert float(table[1]["t"]) == pytest.approx(0.005) and float(table[1]["speed"]) == 60.0
    stroke_id = rows(store_path, "SELECT id FROM strokes WHERE pen='marker'")[0][0]
    single = tmp_path / "one.csv"
    assert run_cli("strokes", "export", "--store", store_path, "-o", single, "--stroke",
                   stroke_id).returncode == 0
    trajectory = load_trajectory(single)
    assert len(trajectory.t) == 5 and trajectory.pressure[0] == 0.6
    assert_clean_failure(run_cli("strokes", "export", "--store", store_path, "-o", out),
                         "exists; pass --force")
    assert_clean_failure(run_cli("strokes", "export", "--store", tmp_path / "none.sqlite3",
                                 "-o", out, "--force"), "no such stroke store")
    assert_clean_failure(run_cli("strokes", "export", "--store", store_path, "-o", out,
                                 "--stroke", "999", "--force"), "no stroke with id 999")


def test_strokes_export_to_a_place_it_cannot_write(client, store_path, tmp_path):
    with client.websocket_connect(WS) as ws:
        for message in stroke_messages("pencil", n=3):
            talk(ws, message)
    folder = tmp_path / "somedir"
    folder.mkdir()
    (folder / "keep.txt").write_text("x")
    blocker = tmp_path / "f"
    blocker.write_text("a file, not a folder")
    before = sorted(p.name for p in tmp_path.iterdir())
    for output, words in ((folder, "somedir"), (blocker / "x.csv", "f/x.csv"),
                          ("/proc/x.csv", "/proc/x.csv")):
        assert_clean_failure(run_cli("strokes", "export", "--store", store_path, "-o", output),
                             words)
    assert_clean_failure(run_cli("strokes", "export", "--store", store_path, "-o", store_path),
                         "stroke store itself")
    assert sorted(p.name for p in tmp_path.iterdir()) == before  # nothing half-written
    assert [p.name for p in folder.iterdir()] == ["keep.txt"]
    assert blocker.read_text() == "a file, not a folder"
    assert rows(store_path, "SELECT COUNT(*) FROM samples") == [(3,)]


# ---- a real server: tokens, sizes, options, Ctrl-C -------------------------------------------

websockets_sync = pytest.importorskip("websockets.sync.client")
httpx = pytest.importorskip("httpx")


def ws_url(base: str, token: str | None = None) -> str:
    return base.replace("http://", "ws://") + "ws" + (f"?token={token}" if token else "")


@pytest.mark.slow
def test_lan_token_is_required_on_http_and_websocket(tmp_path):
    from websockets.exceptions import InvalidStatus

    with serve(tmp_path, "--lan", "--host", "127.0.0.1") as server:
        assert server.token and len(server.token) >= 20
        # kept in the data folder, readable by its owner only: a restarted server keeps it
        kept = tmp_path / "home" / "lan-token"
        assert kept.read_text().strip() == server.token
        assert kept.stat().st_mode & 0o777 == 0o600
        base = server.base
        for path in ("", "static/app.js", "api/config", "api/profiles",
                     "api/profiles/pencil/sound.wav", "api/device/log"):
            assert httpx.get(base + path).status_code == 401, path
            assert httpx.get(base + path, params={"token": "wrong"}).status_code == 401, path
        page = httpx.get(base, params={"token": server.token})
        assert page.status_code == 200 and "realpen_token" in page.headers["set-cookie"]
        assert "HttpOnly" in page.headers["set-cookie"]
        assert httpx.get(base + "static/app.js",
                         cookies={"realpen_token": server.token}).status_code == 200
        assert httpx.get(base + "api/config", headers={
            "Authorization": f"Bearer {server.token}"}).status_code == 200
        for url in (ws_url(base), ws_url(base, "wrong")):
            with pytest.raises(InvalidStatus) as refused:
                websockets_sync.connect(url, open_timeout=5)
            assert refused.value.response.status_code == 403
        with websockets_sync.connect(ws_url(base, server.token)) as ws:
            ws.send(json.dumps({"type": "hello", "seq": 0, "client": "t"}))
            assert json.loads(ws.recv(timeout=5))["type"] == "ack"
        with pytest.raises(InvalidStatus) as refused:  # another site's page
            websockets_sync.connect(ws_url(base, server.token), open_timeout=5,
                                    origin="http://evil.example")
        assert refused.value.response.status_code == 403


@pytest.mark.slow
def test_oversized_frames_and_the_server_keeps_answering(tmp_path):
    from websockets.exceptions import ConnectionClosed

    with serve(tmp_path) as server:
        with websockets_sync.connect(ws_url(server.base), max_size=None) as ws:
            ws.send(json.dumps({"type": "hello", "seq": 1, "client": "x" * 100_000}))
            reply = json.loads(ws.recv(timeout=5))
            assert reply["code"] == "too_large" and "seq" not in reply
            ws.send(json.dumps({"type": "hello", "seq": 2, "client": "ok"}))
            assert json.loads(ws.recv(timeout=5))["type"] == "ack"
        with websockets_sync.connect(ws_url(server.base), max_size=None) as ws:
            with pytest.raises(ConnectionClosed) as closed:  # beyond the protocol limit
                ws.send("x" * (2 * 1024 * 1024))
                ws.recv(timeout=5)
            assert closed.value.rcvd is None or closed.value.rcvd.code == 1009
        with websockets_sync.connect(ws_url(server.base)) as ws:
            ws.send(json.dumps({"type": "hello", "seq": 3, "client": "still here"}))
            assert json.loads(ws.recv(timeout=5))["type"] == "ack"
        assert httpx.get(server.base + "api/status").status_code == 200


@pytest.mark.slow
def test_ctrl_c_stops_cleanly_with_nothing_lost(tmp_path):
    store_path = tmp_path / "strokes.sqlite3"
    messages = stroke_messages("ballpoint", n=30)[:-1]  # the pen is still down at Ctrl-C
    with serve(tmp_path) as server:
        assert server.base.startswith("http://127.0.0.1:")
        with websockets_sync.connect(ws_url(server.base)) as ws:
            for message in messages:
                ws.send(json.dumps(message))
                assert json.loads(ws.recv(timeout=5))["type"] == "ack"
            output = server.stop(signal.SIGINT)
    assert server.process.returncode == 0, output
    assert "stopped: the store holds 1 strokes, 30 samples" in output
    assert "Traceback" not in output
    assert not (tmp_path / "strokes.sqlite3-wal").exists()
    (stroke,) = rows(store_path, "SELECT sample_count, end_reason, ended_at FROM strokes")
    assert stroke[0] == 30 and stroke[1] in ("disconnect", "shutdown") and stroke[2]
    assert rows(store_path, "SELECT COUNT(*) FROM samples")[0][0] == 30


def test_serve_refuses_bad_options(tmp_path):
    # --port 0 (any free port): a test must never depend on the default port being free.
    assert_clean_failure(run_cli("serve", "--port", "0", "--tactile", "loud"), "--tactile")
    assert_clean_failure(run_cli("serve", "--port", "0", "--host", "0.0.0.0"), "--lan")
    assert_clean_failure(run_cli("serve", "--port", "0", "--profiles", tmp_path / "nope",
                                 "--store", tmp_path / "s.sqlite3"), "no such folder")
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen(1)
        port = taken.getsockname()[1]
        assert_clean_failure(run_cli("serve", "--port", port, "--store", tmp_path / "s.sqlite3"),
                             f"--port: cannot listen on 127.0.0.1 port {port}")
    bogus = tmp_path / "bogus.sqlite3"
    bogus.write_text("not sqlite")
    assert_clean_failure(run_cli("serve", "--port", "0", "--store", bogus),
                         "not a RealPen stroke store")


def test_serve_store_errors_are_one_line_and_leave_nothing(tmp_path):
    blocker = tmp_path / "f"
    blocker.write_text("a file")
    for store in ("/proc/x.sqlite3", blocker / "x.sqlite3"):
        assert_clean_failure(run_cli("serve", "--port", "0", "--store", store), str(store))
    new = tmp_path / "new.sqlite3"
    with socket.socket() as taken:  # the port is refused before the store is made
        taken.bind(("127.0.0.1", 0))
        taken.listen(1)
        port = taken.getsockname()[1]
        assert_clean_failure(run_cli("serve", "--port", port, "--store", new),
                             f"--port: cannot listen on 127.0.0.1 port {port}")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["f"]  # no new.sqlite3, -wal, -shm


def broken_profiles(tmp_path):
    extra = tmp_path / "pens"
    (extra / "broken").mkdir(parents=True)
    (extra / "broken" / "profile.json").write_text("{not json")
    return extra


@pytest.mark.slow
def test_a_skipped_profile_is_reported_once_on_stdout(tmp_path):
    extra = broken_profiles(tmp_path)
    with serve(tmp_path, "--profiles", str(extra), stderr_to=tmp_path / "stderr.txt") as server:
        assert httpx.get(server.base + "api/status").status_code == 200  # serving
        output = server.stop()
        errors = server.errors()
    assert errors == "", errors
    skipped = [line for line in output.splitlines() if "broken" in line]
    assert len(skipped) == 1 and skipped[0].startswith("  skipped profile: ")
    # With a later error, stderr holds that error's one line and nothing about the profile.
    assert_clean_failure(run_cli("serve", "--port", "0", "--profiles", extra, "--store",
                                 "/proc/x.sqlite3"), "/proc/x.sqlite3")


@pytest.mark.slow
def test_serve_prints_url_and_tactile_setting(tmp_path):
    with serve(tmp_path, "--tactile", "audio") as server:
        assert server.token is None
        config = httpx.get(server.base + "api/config").json()
        assert config["tactile"] == "audio"
        output = server.stop()
    assert "tactile: audio, right channel" in output and "pens: pencil, ballpoint, marker" in output


def test_the_lan_token_is_kept_until_a_new_one_is_asked_for(tmp_path):
    from realpen.errors import RealPenError
    from realpen.live.auth import kept_token

    path = tmp_path / "home" / "lan-token"
    first = kept_token(path)
    assert kept_token(path) == first and path.stat().st_mode & 0o777 == 0o600
    renewed = kept_token(path, renew=True)
    assert renewed != first and kept_token(path) == renewed
    path.write_text("not a token!\n")  # damaged: a new one replaces it
    assert kept_token(path) not in ("not a token!", renewed)
    (tmp_path / "file").write_text("")
    with pytest.raises(RealPenError, match="cannot keep the LAN token"):
        kept_token(tmp_path / "file" / "lan-token")
    assert [p.name for p in path.parent.iterdir()] == ["lan-token"]  # no temporary files left
