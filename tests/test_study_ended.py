"""A session that has ended or been withdrawn takes nothing more, from any path; and the IDs
that would mix pilot and real data are refused.

The strokes of a withdrawn participant are deleted with their answers: a page still open on
their trial must not store new ones (nor samples of a stroke begun before the withdrawal), and
is told so as a bad message (not a store error to retry, not a closed connection).
"""

from __future__ import annotations

from live_support import WS, rows, talk

from realpen.profile import resolve_profile

SAMPLE = {"t": 1.3, "x": 1.0, "y": 2.0, "pressure": 0.5, "tilt_x": 0.0, "tilt_y": 0.0,
          "speed": 1.0}


def pen_down(session: int, stroke: int, seq: int) -> dict:
    return {"type": "pen_down", "seq": seq, "stroke": stroke, "t": 1.0, "pen": "ballpoint",
            "profile_version": resolve_profile("ballpoint").version, "modality": "tactile",
            "ink": "hidden", "px_per_mm": 4.0, "study_session": session, "trial": 1}


def start(client, participant: str, **extra) -> int:
    reply = client.post("/api/sessions", json={"design": "study1", "participant": participant,
                                               "consent": True, **extra})
    assert reply.status_code == 201, reply.text
    return reply.json()["session"]


def test_no_stroke_or_sample_lands_in_a_withdrawn_session(client, store_path):
    session = start(client, "P01")
    with client.websocket_connect(WS) as ws:
        assert talk(ws, pen_down(session, 0, 1))["type"] == "ack"
        assert talk(ws, {"type": "pen_up", "seq": 2, "stroke": 0, "t": 1.2})["type"] == "ack"
        assert talk(ws, pen_down(session, 1, 3))["type"] == "ack"  # in progress at withdrawal
        reply = client.post(f"/api/sessions/{session}/withdraw", json={"confirm": "P01"})
        assert reply.status_code == 200 and reply.json()["state"] == "withdrawn"
        late = talk(ws, {"type": "samples", "seq": 4, "stroke": 1, "samples": [SAMPLE]})
        assert (late["code"], late["message"]) == (
            "invalid_message", f"study_session: study session {session} is withdrawn: it takes "
                               f"no strokes")
        assert talk(ws, {"type": "pen_up", "seq": 5, "stroke": 1, "t": 1.4})["type"] == "ack"
        new = talk(ws, pen_down(session, 2, 6))  # the same page, its trial already checked
        assert (new["type"], new["code"]) == ("error", "invalid_message")
        assert talk(ws, {"type": "hello", "seq": 7, "client": "test", "protocol": 1})["type"] \
            == "ack"  # the connection goes on
    assert rows(store_path, "SELECT COUNT(*) FROM strokes") == [(0,)]
    assert rows(store_path, "SELECT COUNT(*) FROM samples") == [(0,)]


def test_an_abandoned_session_takes_no_stroke_and_no_answer(client, store_path):
    session = start(client, "P02")
    reply = client.post(f"/api/sessions/{session}/state", json={"state": "abandoned"})
    assert reply.status_code == 200 and reply.json()["state"] == "abandoned"
    with client.websocket_connect(WS) as ws:
        refused = talk(ws, pen_down(session, 0, 1))
        assert (refused["code"], refused["message"]) == (
            "invalid_message", f"study_session: study session {session} is abandoned: it takes "
                               f"no strokes")
    answer = client.post(f"/api/sessions/{session}/trials/1",
                         json={"answers": {"Q1": 3, "Q2": 3}, "rt_ms": 900.0})
    assert answer.status_code == 409
    assert client.get(f"/api/sessions/{session}").json()["state"] == "abandoned"
    assert rows(store_path, "SELECT COUNT(*) FROM strokes") == [(0,)]


def test_a_pilot_and_a_real_session_never_share_a_participant_id(client):
    pilot = start(client, "P03", pilot=True)
    real = client.post("/api/sessions", json={"design": "study1", "participant": "P03",
                                              "consent": True})
    assert real.status_code == 409
    assert real.json()["detail"] == (f"P03 already has a pilot session ({pilot}) of 'study1'; "
                                     f"a real session needs another participant ID")
    start(client, "P04")
    again = client.post("/api/sessions", json={"design": "study1", "participant": "P04",
                                               "consent": True, "pilot": True})
    assert again.status_code == 409 and "already has a real session" in again.json()["detail"]
    resumed = client.post("/api/sessions", json={"design": "study1", "participant": "P03",
                                                 "consent": True, "pilot": True})
    assert resumed.status_code == 200 and resumed.json()["session"] == pilot


def test_a_withdrawn_records_name_is_not_a_participant_id(client):
    reply = client.post("/api/sessions", json={"design": "study1", "participant": "withdrawn-2",
                                               "consent": True})
    assert reply.status_code == 422 and "withdrawn participant's record" in reply.json()["detail"]
    first = start(client, "P05")
    second = start(client, "P06")
    assert client.post(f"/api/sessions/{first}/withdraw", json={"confirm": "P05"}).status_code \
        == 200
    assert client.post(f"/api/sessions/{second}/withdraw", json={"confirm": "P06"}).status_code \
        == 200


def test_the_strokes_export_leaves_pilot_sessions_out_unless_asked(client, store_path, tmp_path):
    from realpen.live.store import export_csv

    real, pilot = start(client, "P07"), start(client, "P08", pilot=True)
    with client.websocket_connect(WS) as ws:
        for stroke, session in enumerate((real, pilot)):
            assert talk(ws, pen_down(session, stroke, 3 * stroke + 1))["type"] == "ack"
            batch = {"type": "samples", "seq": 3 * stroke + 2, "stroke": stroke,
                     "samples": [SAMPLE]}
            assert talk(ws, batch)["type"] == "ack"
            assert talk(ws, {"type": "pen_up", "seq": 3 * stroke + 3, "stroke": stroke,
                             "t": 1.4})["type"] == "ack"
    assert export_csv(store_path, tmp_path / "real.csv") == (1, 1)
    assert export_csv(store_path, tmp_path / "all.csv", include_pilot=True) == (2, 2)
