"""Two servers on one PostgreSQL database: sessions, plan rows and answers stay one each."""

from __future__ import annotations

import threading

import pytest
from fastapi.testclient import TestClient

from realpen.live.app import LiveSettings, create_app

ROUNDS = 6


@pytest.fixture
def two_servers(postgres_server, tmp_path, monkeypatch):
    """Two live apps in-process on one new PostgreSQL database (as two labs would run)."""
    monkeypatch.setenv("REALPEN_HOME", str(tmp_path / "home"))
    url = postgres_server.new_database("twolabs")
    apps = [create_app(LiveSettings.loopback(store=url)) for _ in range(2)]
    with TestClient(apps[0], base_url="http://127.0.0.1") as first, \
            TestClient(apps[1], base_url="http://127.0.0.1") as second:
        yield first, second


def at_once(calls) -> list:
    """Run the calls in threads released together; their results in order."""
    barrier, results = threading.Barrier(len(calls)), [None] * len(calls)

    def run(i, call):
        barrier.wait()
        results[i] = call()

    threads = [threading.Thread(target=run, args=(i, call)) for i, call in enumerate(calls)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join(timeout=60)
    return results


def body(participant: str) -> dict:
    return {"design": "study1", "participant": participant, "consent": True}


def test_sessions_made_at_once_on_two_servers_are_one_each(two_servers):
    first, second = two_servers
    for round_ in range(ROUNDS):
        same = at_once([lambda r=round_: first.post("/api/sessions", json=body(f"S{r}")),
                        lambda r=round_: second.post("/api/sessions", json=body(f"S{r}"))])
        assert sorted(reply.status_code for reply in same) == [200, 201], [r.text for r in same]
        assert same[0].json()["session"] == same[1].json()["session"]
        other = at_once([lambda r=round_: first.post("/api/sessions", json=body(f"A{r}")),
                         lambda r=round_: second.post("/api/sessions", json=body(f"B{r}"))])
        assert [reply.status_code for reply in other] == [201, 201], [r.text for r in other]
    listed = first.get("/api/sessions").json()["sessions"]
    assert len(listed) == 3 * ROUNDS
    assert sorted(item["index"] for item in listed) == list(range(3 * ROUNDS))  # no row twice


def test_one_trial_answered_at_once_on_two_servers_is_stored_once(two_servers):
    first, second = two_servers
    session = first.post("/api/sessions", json=body("P01")).json()["session"]
    for n in (1, 2, 3):
        replies = at_once([
            lambda n=n: first.post(f"/api/sessions/{session}/trials/{n}",
                               json={"answers": {"Q1": 2, "Q2": 2}, "rt_ms": 10.0}),
            lambda n=n: second.post(f"/api/sessions/{session}/trials/{n}",
                                json={"answers": {"Q1": 5, "Q2": 5}, "rt_ms": 20.0})])
        assert sorted(reply.status_code for reply in replies) == [201, 409]
        winner = next(reply for reply in replies if reply.status_code == 201)
        loser = next(reply for reply in replies if reply.status_code == 409)
        assert winner.json()["trial"] == n and set(loser.json()["answers"]) == {"Q1", "Q2"}
    progress = second.get(f"/api/sessions/{session}").json()
    assert progress["answered"] == 3 and progress["next"] == 4
