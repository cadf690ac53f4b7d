"""Answers survive a server killed with SIGKILL at any moment (SQLite and PostgreSQL).

Two clients answer study-2 trials as fast as they can through the HTTP API of a real
``realpen serve``; the server is killed (SIGKILL) while answers are in flight; a new server on
the same store takes over and the clients resend what they were not sure of and finish. Then
the store is compared with what was acknowledged: every answer that got a 201 is stored, once.
"""

from __future__ import annotations

import concurrent.futures
import contextlib
import threading
import time

import httpx
import pytest
from live_support import serve, spare_server, study_answers
from sqlalchemy import create_engine, text

pytestmark = pytest.mark.slow  # three servers and a whole study per store: 8-15 s each

PARTICIPANTS = ("P01", "P02")
KILLS = (20, 70)  # the server is killed once the clients have this many answers acknowledged


class Participant:
    """One client: answers its session's trials in order, remembers what was acknowledged."""

    def __init__(self, code: str):
        self.code, self.session = code, None
        self.acknowledged: dict[int, dict] = {}
        self.pending: tuple[int, dict] | None = None  # sent, no reply seen

    def run(self, base: str, stop: threading.Event | None = None) -> None:
        with httpx.Client(base_url=base, timeout=10) as api:
            if self.session is None:
                reply = api.post("/api/sessions", json={"design": "study2",
                                                        "participant": self.code, "consent": True})
                self.session = reply.json()["session"]
            if self.pending is not None:  # resend what may or may not have arrived
                n, given = self.pending
                reply = api.post(f"/api/sessions/{self.session}/trials/{n}",
                                 json={"answers": given, "rt_ms": 500.0})
                assert reply.status_code in (201, 409), reply.text
                if reply.status_code == 409:  # it had arrived: the stored answer is ours
                    stored = reply.json()["answers"]
                    assert stored == {k: str(v) for k, v in given.items()}
                self.acknowledged[n], self.pending = given, None
            while stop is None or not stop.is_set():
                trial = api.get(f"/api/sessions/{self.session}/next").json()
                if trial.get("done"):
                    return
                given = study_answers(trial)
                self.pending = (trial["trial"], given)
                reply = api.post(f"/api/sessions/{self.session}/trials/{trial['trial']}",
                                 json={"answers": given, "rt_ms": 500.0})
                assert reply.status_code == 201, reply.text
                self.acknowledged[trial["trial"]], self.pending = given, None


def _until_killed(participant: Participant, base: str) -> None:
    try:
        participant.run(base)
    except (httpx.HTTPError, ValueError):
        pass  # the server died under it; what it was sending stays pending


def _url(target) -> str:
    target = str(target)
    return target if "://" in target else f"sqlite:///{target}"


def test_no_acknowledged_answer_is_lost_or_doubled(tmp_path, store_target):
    people = [Participant(code) for code in PARTICIPANTS]
    in_flight = 0
    with contextlib.ExitStack() as unused:
        # The three servers start at once: each restart then waits only for what follows
        # Python's imports (the store opened and recovered, the port bound), as a user's would.
        spares = [unused.enter_context(spare_server(tmp_path, "--store", str(store_target)))
                  for _ in range(len(KILLS) + 1)]
        for kill_after, spare in zip(KILLS, spares):
            with serve(tmp_path, spare=spare) as server:
                threads = [threading.Thread(target=_until_killed, args=(person, server.base))
                           for person in people]
                for thread in threads:
                    thread.start()
                deadline = time.monotonic() + 60
                while sum(len(p.acknowledged) for p in people) < kill_after and \
                        time.monotonic() < deadline:
                    time.sleep(0.002)
                server.process.kill()  # SIGKILL, with answers in flight
                server.process.wait(timeout=10)
                for thread in threads:
                    thread.join(timeout=20)
            in_flight += sum(person.pending is not None for person in people)
            assert sum(len(person.acknowledged) for person in people) >= kill_after
        acknowledged_before = sum(len(person.acknowledged) for person in people)
        with serve(tmp_path, spare=spares[-1]) as server, \
                concurrent.futures.ThreadPoolExecutor(len(people)) as clients:
            # Both finish side by side, as they answered; result() raises what a client raised.
            for finished in [clients.submit(person.run, server.base) for person in people]:
                finished.result()
            progress = [httpx.get(f"{server.base}api/sessions/{person.session}").json()
                        for person in people]
    assert all(item["state"] == "finished" for item in progress)
    engine = create_engine(_url(store_target))
    try:
        with engine.connect() as db:
            stored = db.execute(text(
                "SELECT session_id, n, question, answer FROM answers")).all()
            answered_trials = db.execute(text(
                "SELECT COUNT(*) FROM trials WHERE answered_at IS NOT NULL")).scalar()
    finally:
        engine.dispose()
    by_trial: dict[tuple[int, int], dict] = {}
    duplicated = 0
    for session, n, question, answer in stored:
        answers = by_trial.setdefault((session, n), {})
        duplicated += question in answers
        answers[question] = answer
    acknowledged = {(person.session, n): given for person in people
                    for n, given in person.acknowledged.items()}
    lost = sum(1 for key in acknowledged if key not in by_trial)
    wrong = sum(1 for key, given in acknowledged.items()
                if key in by_trial and by_trial[key] != {k: str(v) for k, v in given.items()})
    kind = "postgresql" if "://" in str(store_target) else "sqlite"
    print(f"\n{kind}: answered {len(acknowledged)} "
          f"(before the last of {len(KILLS)} kills {acknowledged_before}, in flight at a kill {in_flight}), "
          f"stored {len(by_trial)}, lost {lost}, duplicated {duplicated}, changed {wrong}")
    assert lost == 0 and duplicated == 0 and wrong == 0
    assert len(by_trial) == len(acknowledged) == answered_trials == sum(i["trials"] for i in progress)
