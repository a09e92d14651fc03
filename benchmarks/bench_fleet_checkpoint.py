"""`fleet status` on a long fleet log, with and without the fleet checkpoints (store/fleet_checkpoints.py).

A fleet of ROBOTS robots x 4 camera serials: registered and assigned @1 (5 x ROBOTS events), then rollouts of
every serial's next version, each as the workflows write it: the rollout event (each target's diff recorded),
the
5 canary robots' assignments, the promote (its 20 gate inputs) and the other robots' assignments; every 10th
rollout is then rolled back (every robot put back). 4 x ROBOTS + 2 events a rollout (2 002 at 500 robots), so
2.5k, 25k and 250k events are the registrations and about 11 and 124 rollouts (the last one cut where the size
falls).

The log is written in bulk (chain columns computed as ``chain.link`` computes them, the checks on write
skipped:
no calibrations are stored, so every robot's active version reads "no active version"). At each size N, timed
(wall and this process's CPU, median of REPEATS): ``rollouts.fleet_status`` (the workflow `calibctl fleet
status`
calls, in-process) with no checkpoint (the whole log replayed, as before), EVERY events past a checkpoint (the
most a read replays) and right at one; the checkpoint writes (``fleet_checkpoints.write_if_due``, what the
fleet writer calls in its transaction): the first one of a migrated store (the whole log) and a later one.

Run: python benchmarks/bench_fleet_checkpoint.py [--robots 500] [--sizes 2500 25000 250000] [--pg] [--repeats
3]
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import Any

import psycopg
from sqlalchemy import delete, func, insert, select
from sqlalchemy.orm import Session

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from benchmarks.machine import cpu_model  # noqa: E402
from calibctl.artifacts.common import sha256_hex  # noqa: E402
from calibctl.artifacts.fleet import FleetEvent, GateEvidence, TargetDiff  # noqa: E402
from calibctl.config import load_settings  # noqa: E402
from calibctl.store import chain, codec, counters, fleet_checkpoints  # noqa: E402
from calibctl.store.models import FleetCheckpointRow, FleetEventRow  # noqa: E402
from calibctl.store.repository import Store  # noqa: E402
from calibctl.workflows.fleet import rollouts  # noqa: E402

ADMIN_URL = os.environ.get("CALIBCTL_TEST_PG_URL", "postgresql://postgres@127.0.0.1:5432/test")
T0 = datetime(2026, 1, 1, tzinfo=UTC)
CANARY = 5


def _events(robots: int) -> Iterator[FleetEvent]:
    """The log, event after event, without end (see the module's docstring)."""
    who = {"actor": "bench", "station": "bench", "reason": "bench"}
    names = [f"amr-{r:03d}" for r in range(robots)]
    serials = {robot: [f"CAM-{r * 4 + c:05d}" for c in range(4)] for r, robot in enumerate(names)}
    n = 0

    def at() -> datetime:
        nonlocal n
        n += 1
        return T0 + timedelta(seconds=n)

    for robot in names:
        yield FleetEvent(kind="register", robot=robot, serials=serials[robot], at=at(), **who)
    for robot in names:
        for s in serials[robot]:
            yield FleetEvent(kind="assign", robot=robot, serial=s, version=1, at=at(), **who)
    for k in range(1, 10**6):
        name, new = f"r{k:04d}", k + 1
        canary = names[(k * CANARY) % robots :][:CANARY]
        everyone = [s for robot in names for s in serials[robot]]
        yield FleetEvent(
            kind="rollout",
            rollout=name,
            targets=dict.fromkeys(everyone, new),
            canary=canary,
            at=at(),
            diffs={s: TargetDiff(previous=k, verdict="same", p50_px=0.01, max_px=0.03) for s in everyone},
            **who,
        )
        for robot in canary:
            for s in serials[robot]:
                yield FleetEvent(
                    kind="assign", robot=robot, serial=s, version=new, rollout=name, at=at(), **who
                )
        for robot in names:  # the promote's transaction: the other robots' assignments, then the promote
            if robot not in canary:
                for s in serials[robot]:
                    yield FleetEvent(
                        kind="assign", robot=robot, serial=s, version=new, rollout=name, at=at(), **who
                    )
        gate = [
            GateEvidence(
                robot=robot,
                target=s,
                source="report",
                id=f"{name}/{s}",
                sha256="0" * 64,
                kind="check",
                passed=True,
            )
            for robot in canary
            for s in serials[robot]
        ]
        yield FleetEvent(kind="promote", rollout=name, gate=gate, at=at(), **who)
        if k % 10 == 0:
            for robot in names:
                for s in serials[robot]:
                    yield FleetEvent(
                        kind="assign", robot=robot, serial=s, version=k, rollout=name, at=at(), **who
                    )
            yield FleetEvent(kind="rollback", rollout=name, at=at(), **who)


class Log:
    """Appends the log in bulk: rows chained as ``chain.link`` chains them, 5 000 a transaction."""

    def __init__(self, store: Store, robots: int) -> None:
        self.store, self.events, self.length, self.prev = store, _events(robots), 0, None
        self.stream = chain.STREAMS["fleet"]

    def fill_to(self, target: int) -> None:
        """Up to ``target`` events."""
        rows: list[dict[str, Any]] = []
        while self.length < target:
            e = next(self.events)
            self.length += 1
            payload = codec.canonical_text(e)
            row: dict[str, Any] = {
                "id": self.length,
                "subject": e.subject,
                "kind": e.kind,
                "at": e.at,
                "payload": payload,
                "payload_sha256": sha256_hex(payload.encode("utf-8")),
                "chain_seq": self.length,
                "chain_prev": self.prev,
            }
            row["chain_hash"] = chain.record_hash(self.stream, (), self.length, self.prev, chain.body(row))
            row["signature"] = row["key_id"] = None
            self.prev = row["chain_hash"]
            rows.append(row)
            if len(rows) == 5000:
                self._insert(rows)
                rows = []
        self._insert(rows)

    def _insert(self, rows: list[dict[str, Any]]) -> None:
        if rows:
            with Session(self.store._write_engine) as s, s.begin():  # noqa: SLF001 - a benchmark fills in bulk
                s.execute(insert(FleetEventRow), rows)
                counters.raise_to(s, "chain", "fleet", self.length)


def _timed(fn: Callable[[], object], repeats: int) -> tuple[list[float], list[float]]:
    walls, cpus = [], []
    for _ in range(repeats):
        t0, c0 = time.perf_counter(), time.process_time()
        fn()
        walls.append(time.perf_counter() - t0)
        cpus.append(time.process_time() - c0)
    return walls, cpus


def _fmt(t: tuple[list[float], list[float]]) -> str:
    walls, cpus = t
    return f"{statistics.median(walls) * 1e3:,.0f} ms (CPU {statistics.median(cpus) * 1e3:,.0f} ms)"


def _write(store: Store, length: int) -> None:
    with Session(store._write_engine) as s, s.begin():  # noqa: SLF001 - the writer's call, timed alone
        fleet_checkpoints.write_if_due(s, length)


def _checkpoints(store: Store) -> list[int]:
    with Session(store._engine) as s:  # noqa: SLF001
        return list(s.scalars(select(FleetCheckpointRow.position).order_by(FleetCheckpointRow.position)))


def run(url: str, robots: int, sizes: list[int], repeats: int) -> list[list[str]]:
    every = fleet_checkpoints.EVERY
    settings = load_settings(db=url, station="bench", operator="bench", env={})
    table = []
    with Store.open(url, create=True) as store:
        log = Log(store, robots)
        for size in sizes:
            log.fill_to(size - every)
            first = _timed(lambda: _write(store, log.length), 1)  # a migrated store's first: the whole log
            log.fill_to(log.length + every)
            worst = _timed(lambda: rollouts.fleet_status(settings), repeats)
            status, staged = rollouts.fleet_status(settings)
            later = _timed(lambda: _write(store, log.length), 1)
            best = _timed(lambda: rollouts.fleet_status(settings), repeats)
            assert _checkpoints(store)[-1] == log.length == status.events, (_checkpoints(store), log.length)
            with Session(store._write_engine) as s, s.begin():  # noqa: SLF001
                state_bytes = s.scalar(
                    select(func.length(FleetCheckpointRow.state)).where(
                        FleetCheckpointRow.position == log.length
                    )
                )
                kept = [
                    (r.position, r.chain_hash, r.format, r.written_at, r.state, r.state_sha256)
                    for r in s.scalars(select(FleetCheckpointRow))
                ]
                s.execute(delete(FleetCheckpointRow))
            before = _timed(lambda: rollouts.fleet_status(settings), repeats)
            again, staged_again = rollouts.fleet_status(settings)
            assert again.as_json() == status.as_json() and [r.as_json() for r in staged_again] == [
                r.as_json() for r in staged
            ], "a checkpoint changed what status says"
            with Session(store._write_engine) as s, s.begin():  # noqa: SLF001
                s.execute(
                    insert(FleetCheckpointRow),
                    [
                        dict(
                            zip(
                                ("position", "chain_hash", "format", "written_at", "state", "state_sha256"),
                                k,
                                strict=True,
                            )
                        )
                        for k in kept
                    ],
                )
            table.append(
                [
                    f"{log.length:,}",
                    f"{len(staged)}",
                    _fmt(before),
                    _fmt(worst),
                    _fmt(best),
                    _fmt(first),
                    _fmt(later),
                    f"{(state_bytes or 0) / 1e6:.1f} MB",
                ]
            )
    return table


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--robots", type=int, default=500, help="robots (4 serials each)")
    ap.add_argument(
        "--sizes", type=int, nargs="+", default=[2500, 25_000, 250_000], help="log lengths (events)"
    )
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument(
        "--pg", action="store_true", help="PostgreSQL (a database created and dropped) instead of SQLite"
    )
    args = ap.parse_args()
    load0 = os.getloadavg()
    with tempfile.TemporaryDirectory() as tmp:
        if args.pg:
            name = "calibctl_bench_fleet_checkpoint"
            with psycopg.connect(ADMIN_URL, autocommit=True) as admin:
                admin.execute(f'DROP DATABASE IF EXISTS "{name}"')
                admin.execute(f'CREATE DATABASE "{name}"')
            url = ADMIN_URL.rsplit("/", 1)[0] + f"/{name}"
        else:
            url = f"sqlite:///{Path(tmp) / 'bench.db'}"
        try:
            table = run(url, args.robots, args.sizes, args.repeats)
        finally:
            if args.pg:
                with psycopg.connect(ADMIN_URL, autocommit=True) as admin:
                    admin.execute(f'DROP DATABASE IF EXISTS "{name}" WITH (FORCE)')
    load1 = os.getloadavg()
    print(
        f"# fleet status with checkpoints ({datetime.now(UTC):%Y-%m-%d %H:%M} UTC, {cpu_model()}, "
        f"{os.cpu_count()} "
        f"CPUs, load (1/5/15 min) {load0[0]:.1f}/{load0[1]:.1f}/{load0[2]:.1f} at the start and "
        f"{load1[0]:.1f}/{load1[1]:.1f}/{load1[2]:.1f} at the end, {'PostgreSQL' if args.pg else 'SQLite'}, "
        f"{args.robots} robots x 4 serials, EVERY {fleet_checkpoints.EVERY}, median of {args.repeats})\n"
    )
    print(
        f"| events | rollouts | status, whole log replayed (before) | status, {fleet_checkpoints.EVERY:,} "
        "events past "
        "a checkpoint | status at a checkpoint | first checkpoint (whole log) | next checkpoint | "
        "checkpoint size |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for row in table:
        print("| " + " | ".join(row) + " |")


if __name__ == "__main__":
    main()
