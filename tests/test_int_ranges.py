"""One rule for numbers everywhere (issue 25): the WebSocket schema, the HTTP API and both stores
hold integers to the store's range (:data:`realpen.io.limits.MAX_STORED_INT`); ids in URLs are
digits only; a design's huge YAML integer is one line."""

from __future__ import annotations

import json
import warnings

import pytest
from conftest import assert_clean_failure, run_cli, store_rows
from live_support import WS, stroke_messages, talk

from realpen.errors import ParameterError
from realpen.io.limits import MAX_JSON_INT, MAX_STORED_INT
from realpen.live.messages import MessageError, parse_message
from realpen.live.store import StrokeStore
from realpen.study.design import builtin_path

with warnings.catch_warnings():  # starlette's note about a future httpx successor
    warnings.simplefilter("ignore")
    from fastapi.testclient import TestClient

BIG = MAX_STORED_INT + 1  # 2**31: PostgreSQL's INTEGER cannot hold it


def samples_message(stroke: int, index: int | None, count: int, seq: int) -> dict:
    sample = {"t": 10.0, "x": 1.0, "y": 2.0, "pressure": 0.5, "tilt_x": 0.0, "tilt_y": 0.0,
              "speed": 0.0}
    message = {"type": "samples", "seq": seq, "stroke": stroke, "samples": [sample] * count}
    if index is not None:
        message["index"] = index
    return message


def refused(reply: dict, seq: int, field: str) -> None:
    """An ``invalid_message`` error for ``seq`` naming ``field``: not a store error to retry."""
    assert reply["type"] == "error" and reply["code"] == "invalid_message", reply
    assert reply["seq"] == seq and field in reply["message"], reply


def out_of_range_then_the_largest(ws) -> None:
    """Values just past the store's range are refused on the open connection; the largest
    ones are stored."""
    down = stroke_messages(stroke=BIG, n=1)[0]
    refused(talk(ws, down), down["seq"], "pen_down.stroke")
    trial = {**stroke_messages(stroke=1, n=1)[0], "seq": 2, "study_session": BIG, "trial": 1}
    refused(talk(ws, trial), 2, "pen_down.study_session")
    # the connection lives: the largest stroke number is taken
    down = {**stroke_messages(stroke=MAX_STORED_INT, n=1)[0], "seq": 3}
    assert talk(ws, down)["type"] == "ack"
    # two samples from 2**31 - 1: the second would be 2**31
    refused(talk(ws, samples_message(MAX_STORED_INT, MAX_STORED_INT, 2, 4)), 4, "samples")
    refused(talk(ws, samples_message(MAX_STORED_INT, BIG, 1, 5)), 5, "samples.index")
    reply = talk(ws, samples_message(MAX_STORED_INT, MAX_STORED_INT - 1, 2, 6))
    assert reply["type"] == "ack" and reply["seq"] == 6, reply
    # without an index the store numbers the samples: past the range, a bad message too
    refused(talk(ws, samples_message(MAX_STORED_INT, None, 1, 8)), 8, "")
    up = {"type": "pen_up", "seq": 7, "stroke": MAX_STORED_INT, "t": 11.0}
    assert talk(ws, up)["type"] == "ack"


def test_websocket_refuses_numbers_no_store_holds_on_sqlite(client, store_path):
    with client.websocket_connect(WS) as ws:
        out_of_range_then_the_largest(ws)
        # seq is only echoed, never stored: up to 2**53
        hello = {"type": "hello", "client": "test", "protocol": 1}
        assert talk(ws, {**hello, "seq": MAX_JSON_INT})["seq"] == MAX_JSON_INT
        with pytest.raises(MessageError, match="hello.seq"):
            parse_message(json.dumps({**hello, "seq": MAX_JSON_INT + 1}))
    assert store_rows(store_path, "SELECT page_stroke, sample_count FROM strokes") == \
        [(MAX_STORED_INT, 2)]
    assert store_rows(store_path, "SELECT seq FROM samples ORDER BY seq") == \
        [(MAX_STORED_INT - 1,), (MAX_STORED_INT,)]


def test_websocket_refuses_numbers_no_store_holds_on_postgresql(postgres_server, tmp_path,
                                                                monkeypatch):
    from realpen.live.app import LiveSettings, create_app

    monkeypatch.setenv("REALPEN_HOME", str(tmp_path / "home"))
    url = postgres_server.new_database("ints")
    with TestClient(create_app(LiveSettings.loopback(store=url)),
                    base_url="http://127.0.0.1") as client, client.websocket_connect(WS) as ws:
        out_of_range_then_the_largest(ws)
    assert store_rows(url, "SELECT page_stroke, sample_count FROM strokes") == \
        [(MAX_STORED_INT, 2)]


def test_both_stores_refuse_what_they_cannot_hold(store_target):
    """The store's own check, for callers other than the WebSocket (and a page that leaves the
    numbering to the store until it runs out): a ParameterError, nothing written."""
    store = StrokeStore(store_target)
    try:
        fields = dict(session="s", pen="pencil", profile_version="0" * 12, modality="none",
                      ink="visible", pointer_type="pen", px_per_mm=4.0, calibrated=False,
                      page_t0=1.0)
        with pytest.raises(ParameterError, match="page_stroke"):
            store.begin_stroke(page_stroke=BIG, **fields)
        with pytest.raises(ParameterError, match="trial"):
            store.begin_stroke(page_stroke=1, study_session=1, trial=BIG, **fields)
        stroke = store.begin_stroke(page_stroke=MAX_STORED_INT, **fields)
        row = (1.0, 0.0, 0.0, 0.5, 0.0, 0.0, 0.0)
        with pytest.raises(ParameterError, match="samples"):
            store.add_samples(stroke, [row, row], first=MAX_STORED_INT)
        assert store.add_samples(stroke, [row], first=MAX_STORED_INT) == 1
        with pytest.raises(ParameterError, match="2147483648"):
            store.add_samples(stroke, [row])  # numbered after the last: 2**31
        assert store.count() == (1, 1)
    finally:
        store.close()


def test_url_ids_are_digits_only(client):
    # 1_0 was session 10, 1.0, +1 and " 1" session 1; ١ is an Arabic-Indic one
    for text in ("1_0", "1.0", "+1", "%201", "1%20", "-1", "1e0", "0x1", "%D9%A1"):
        reply = client.get(f"/api/sessions/{text}")
        assert reply.status_code == 422, (text, reply.text)
        assert reply.json()["detail"].startswith("path.session_id: Input should be a whole "
                                                 "number in the digits 0-9 only"), reply.text


def test_url_numbers_and_bodies_keep_the_store_range(client):
    assert client.get(f"/api/sessions/{MAX_STORED_INT}").json() == \
        {"detail": f"no session {MAX_STORED_INT}"}
    assert client.get("/api/sessions/0000000001").json() == {"detail": "no session 1"}
    for url in (f"/api/sessions/{BIG}", f"/api/sessions/1/trials/{BIG}/tactile.wav",
                f"/api/sessions/{'9' * 5000}", f"/api/profiles/pencil/grid/{BIG}.wav"):
        reply = client.get(url)
        assert reply.status_code == 422, (url[:60], reply.text)
        assert reply.json()["detail"].endswith(f"less than or equal to {MAX_STORED_INT}")
    for url in ("/api/sessions?limit=1_0", "/api/device/log?since=1.0",
                "/api/pens/pencil/pen-pattern?rate=%2B8000", "/api/sessions/1/trials/+1/tactile.wav"):
        reply = client.get(url)
        assert reply.status_code == 422 and "digits 0-9" in reply.json()["detail"], (url, reply.text)
    assert client.get("/api/sessions?limit=0005").status_code == 200
    for body in ({"design": "study1", "participant": "P1", "index": BIG},
                 {"design": "study1", "participant": "P1", "demographics": {"age": BIG}}):
        reply = client.post("/api/sessions", json=body)
        assert reply.status_code == 422, reply.text
    reply = client.post(f"/api/sessions/{BIG}/trials/1", json={"answers": {}, "rt_ms": 1.0})
    assert reply.status_code == 422 and "path.session_id" in reply.json()["detail"]


def test_a_huge_yaml_integer_is_one_line(tmp_path):
    text = builtin_path("study1").read_text(encoding="utf-8")
    assert "\nseed: 1\n" in text
    design = tmp_path / "huge.yaml"
    design.write_text(text.replace("\nseed: 1\n", "\nseed: " + "1" * 5000 + "\n"))
    result = run_cli("study", "plan", design, "--participants", "2")
    assert_clean_failure(result, f"{design}: seed: a number of 5,000 characters")
    nested = tmp_path / "nested.yaml"
    nested.write_text(text.replace("questions: [Q1, Q2]\n",
                                   "questions: [Q1, Q2]\n        repeat: 0x" + "f" * 5000 + "\n"))
    assert_clean_failure(run_cli("study", "plan", nested, "--participants", "2"),
                         "blocks[0].trials[0].repeat: a number of 5,002 characters")
