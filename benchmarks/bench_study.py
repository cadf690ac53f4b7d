"""Throughput and latency of the study API with durable commits, on SQLite and PostgreSQL.

Starts a real ``realpen serve`` (a subprocess, loopback, a fresh store) on each database — an
SQLite file (WAL, ``synchronous=FULL``), then, when PostgreSQL is installed, a new database on a
server of its own (tests/pg_support.py: ``initdb`` in a temporary folder, Unix socket, ``fsync``
and ``synchronous_commit`` on) — and drives the HTTP API the participant page uses, with study 2
(93 trials a session; each recognition trial one ``pen`` question):

- one client: answers as fast as it can, trial after trial (``GET /next`` then ``POST`` the
  answer, as the page does), over fresh sessions, for ``--seconds`` (default 5): answers per
  second, and the POST's latency. Every 201 comes after the answer's commit;
- ``--clients`` (default 20) concurrent sessions back to back, a lab full of tablets: one thread per client,
  each with its own connection, answering its session's trials in order (``--trials`` each,
  default 50 of the 93): the POST's latency p50 / p99 / max, and answers per second overall;
- the same clients as tablets at a person's pace (``--paced`` answers each, one every
  ``--pace`` s): the latency a participant meets in a full lab.

Then every answer acknowledged is checked to be in the store exactly once (answers, and answered
trials). It prints one table. Runs in well under 2 minutes.

Usage: python benchmarks/bench_study.py [--seconds 5] [--clients 20] [--trials 50]
       [--paced 10] [--pace 0.5] [--no-postgres]
"""

from __future__ import annotations

import argparse
import contextlib
import sys
import tempfile
import threading
import time
from pathlib import Path

import httpx
import numpy as np
from sqlalchemy import create_engine, text
from sqlalchemy.pool import NullPool

TESTS = Path(__file__).resolve().parents[1] / "tests"
sys.path.insert(0, str(TESTS))

from live_support import serve, study_answers  # noqa: E402
from pg_support import PostgresUnavailable, running_postgres  # noqa: E402

DESIGN = "study2"


class Client:
    """One participant's page: opens its session, answers its trials in order."""

    def __init__(self, base: str, code: str):
        self.api = httpx.Client(base_url=base, timeout=30)
        self.code = code
        reply = self.api.post("/api/sessions", json={"design": DESIGN, "participant": code,
                                                     "consent": True})
        assert reply.status_code == 201, reply.text
        self.session = reply.json()["session"]
        self.acknowledged = 0  # trials answered (201)
        self.rows = 0  # answers in them (a questionnaire trial has several)
        self.latencies_ns: list[int] = []

    def answer_next(self) -> bool:
        """Answer the next trial; False when the session is done."""
        trial = self.api.get(f"/api/sessions/{self.session}/next").json()
        if trial.get("done"):
            return False
        body = {"answers": study_answers(trial), "rt_ms": 1234.5}
        sent = time.perf_counter_ns()
        reply = self.api.post(f"/api/sessions/{self.session}/trials/{trial['trial']}", json=body)
        self.latencies_ns.append(time.perf_counter_ns() - sent)
        assert reply.status_code == 201, reply.text
        self.acknowledged += 1
        self.rows += len(body["answers"])
        return True

    def close(self) -> None:
        self.api.close()


def one_client(base: str, seconds: float) -> dict:
    """Answers per second of one client answering as fast as it can (fresh sessions as needed)."""
    clients: list[Client] = []
    warm = Client(base, "warmup")  # first requests load the design, the plan, the pools
    for _ in range(10):
        warm.answer_next()
    warm.close()
    started = time.perf_counter()
    while time.perf_counter() - started < seconds:
        client = Client(base, f"S{len(clients):03d}")
        clients.append(client)
        while time.perf_counter() - started < seconds and client.answer_next():
            pass
        client.close()
    elapsed = time.perf_counter() - started
    answered = sum(c.acknowledged for c in clients)
    return {"answered": answered, "rate": answered / elapsed,
            "latencies": [x for c in clients for x in c.latencies_ns],
            "sessions": {c.session: (c.acknowledged, c.rows) for c in clients}}


def concurrent(base: str, count: int, trials: int, prefix: str, pace: float = 0.0) -> dict:
    """``count`` clients at once, each answering ``trials`` trials of its own session in order:
    back to back (``pace`` 0), or one answer every ``pace`` s (a person's pace; the clients'
    starts spread over one period)."""
    clients = [Client(base, f"{prefix}{i:02d}") for i in range(count)]
    errors: list[BaseException] = []
    gate = threading.Barrier(count + 1)

    def work(index: int, client: Client) -> None:
        gate.wait()
        start = time.perf_counter() + pace * index / count
        try:
            while client.acknowledged < trials:
                if pace:
                    time.sleep(max(0.0, start + pace * client.acknowledged - time.perf_counter()))
                if not client.answer_next():
                    break
        except BaseException as error:  # reported below, not lost in the thread
            errors.append(error)

    threads = [threading.Thread(target=work, args=item) for item in enumerate(clients)]
    for thread in threads:
        thread.start()
    gate.wait()
    started = time.perf_counter()
    for thread in threads:
        thread.join()
    elapsed = time.perf_counter() - started
    for client in clients:
        client.close()
    if errors:
        raise errors[0]
    answered = sum(c.acknowledged for c in clients)
    return {"answered": answered, "rate": answered / elapsed,
            "latencies": [x for c in clients for x in c.latencies_ns],
            "sessions": {c.session: (c.acknowledged, c.rows) for c in clients}}


def stored(url: str, sessions: dict[int, tuple[int, int]]) -> tuple[int, int]:
    """(answered trials, answer rows) the store holds for these sessions."""
    engine = create_engine(url, poolclass=NullPool)
    ids = ",".join(str(s) for s in sessions)
    try:
        with engine.connect() as db:
            trials = db.execute(text(f"SELECT COUNT(*) FROM trials WHERE session_id IN ({ids}) "
                                     f"AND answered_at IS NOT NULL")).scalar()
            answers = db.execute(text(f"SELECT COUNT(*) FROM answers WHERE session_id IN "
                                      f"({ids})")).scalar()
    finally:
        engine.dispose()
    return int(trials), int(answers)


def run(name: str, target: str, url: str, folder: Path, args) -> dict:
    """The three measures on one store; checks that every acknowledged answer is stored, once."""
    began = time.perf_counter()
    with serve(folder, "--store", target) as server:
        single = one_client(server.base, args.seconds)
        many = concurrent(server.base, args.clients, args.trials, "C")
        paced = concurrent(server.base, args.clients, args.paced, "H", pace=args.pace)
    sessions = {**single["sessions"], **many["sessions"], **paced["sessions"]}
    acknowledged = sum(trials for trials, _ in sessions.values())
    rows = sum(rows for _, rows in sessions.values())
    trials, answers = stored(url, sessions)
    # nothing acknowledged is missing, nothing is stored twice
    assert (trials, answers) == (acknowledged, rows), (name, trials, answers, acknowledged, rows)
    return {"name": name, "single": single, "many": many, "paced": paced, "stored": trials,
            "acknowledged": acknowledged, "seconds": time.perf_counter() - began}


def ms(values_ns: list[int], q: float) -> float:
    return float(np.percentile(np.asarray(values_ns, dtype=np.float64) / 1e6, q))


def report(results: list[dict], args) -> None:
    print(f"\nstudy API, {DESIGN}; every 201 follows the answer's commit (SQLite WAL "
          f"synchronous=FULL; PostgreSQL fsync, synchronous_commit on). Latency: the POST of an "
          f"answer, round trip.")
    print(f"  1 client: answers as fast as it can for {args.seconds:g} s (GET next + POST each)")
    print(f"  {args.clients} back to back: {args.clients} sessions at once, {args.trials} trials "
          f"each, no pause")
    print(f"  {args.clients} tablets: {args.clients} sessions at once, {args.paced} trials each, "
          f"one answer every {args.pace:g} s per tablet")
    header = (f"{'store':<11} {'measure':<16} {'answers':>7} {'answers/s':>9} {'p50 ms':>7} "
              f"{'p99 ms':>7} {'max ms':>7}")
    print("\n" + header)
    print("-" * len(header))
    for r in results:
        for label, key in (("1 client", "single"), (f"{args.clients} back to back", "many"),
                           (f"{args.clients} tablets", "paced")):
            m = r[key]
            print(f"{r['name']:<11} {label:<16} {m['answered']:>7} {m['rate']:>9.0f} "
                  f"{ms(m['latencies'], 50):>7.1f} {ms(m['latencies'], 99):>7.1f} "
                  f"{ms(m['latencies'], 100):>7.1f}")
        print(f"{r['name']:<11} stored {r['stored']} of {r['acknowledged']} acknowledged trials "
              f"(0 lost, 0 twice); {r['seconds']:.0f} s")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=5.0,
                        help="how long the one client answers (s)")
    parser.add_argument("--clients", type=int, default=20, help="concurrent sessions")
    parser.add_argument("--trials", type=int, default=50,
                        help="trials each back-to-back client answers (study 2 has 93)")
    parser.add_argument("--paced", type=int, default=10,
                        help="trials each paced client (a tablet) answers")
    parser.add_argument("--pace", type=float, default=0.5,
                        help="seconds between a tablet's answers")
    parser.add_argument("--no-postgres", action="store_true", help="SQLite only")
    args = parser.parse_args()
    began = time.perf_counter()
    results = []
    with tempfile.TemporaryDirectory(prefix="bench-study-") as tmp:
        folder = Path(tmp)
        store = folder / "study.sqlite3"
        results.append(run("sqlite", str(store), f"sqlite:///{store}", folder / "sqlite", args))
        if not args.no_postgres:
            try:
                with running_postgres() as server:
                    url = server.new_database("bench")
                    results.append(run("postgresql", url, url, folder / "postgresql", args))
            except PostgresUnavailable as reason:
                print(f"postgresql: not measured ({reason})")
    report(results, args)
    print(f"\n(total {time.perf_counter() - began:.0f} s)")


if __name__ == "__main__":
    with contextlib.suppress(KeyboardInterrupt):
        main()
