"""Fleet scale: `lint --all`, full `db verify` and `db verify --since HEAD` against store size.

    .venv/bin/python benchmarks/bench_store_scale.py                 # 1k artifacts, SQLite (about 1 min)
    .venv/bin/python benchmarks/bench_store_scale.py --large         # 1k, 10k, 100k (long: fills take most of
    it) .venv/bin/python benchmarks/bench_store_scale.py --pg            # also PostgreSQL (local server,
    throwaway db)

Each store holds N artifacts over 1 000 serials (N/1000 versions each, every one activated, so N events
too), written through calibctl's own chained, signed insert path (one transaction per 1 000 rows).
Timings are in-process (no interpreter start-up): the workflow calls behind `calibctl lint --all`
and `calibctl db verify`. Beside them, a plain loop shows what the per-serial work costs without
calibctl: json.loads + sha256 of each active payload, one query per serial (the old access pattern).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
import uuid
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from sqlalchemy import func, insert, select  # noqa: E402
from sqlalchemy.orm import Session  # noqa: E402

from benchmarks.machine import cpu_model  # noqa: E402
from calibctl.artifacts.common import utc_now  # noqa: E402
from calibctl.config import Settings, load_settings  # noqa: E402
from calibctl.signing import Signer, create_key, record_message  # noqa: E402
from calibctl.store import chain, codec, counters, history  # noqa: E402
from calibctl.store.models import ArtifactRow, EventRow  # noqa: E402
from calibctl.store.repository import Store  # noqa: E402
from calibctl.workflows.lint import lint as lint_workflow  # noqa: E402
from calibctl.workflows.store_admin import database, records  # noqa: E402
from tests.artifacts.factories import calibration  # noqa: E402

SERIALS = 1000
BATCH = 1000


def _heads(s: Session) -> tuple[dict[str, tuple[int, int, str]], tuple[int, str | None]]:
    """serial -> (last version, last seq, last hash) and the event log's (seq, hash), as stored now."""
    t = ArtifactRow.__table__
    latest = select(t.c.serial, func.max(t.c.chain_seq).label("seq")).group_by(t.c.serial).subquery()
    rows = s.execute(
        select(t.c.serial, t.c.version, t.c.chain_seq, t.c.chain_hash).join(
            latest, (t.c.serial == latest.c.serial) & (t.c.chain_seq == latest.c.seq)
        )
    )
    serials = {r[0]: (int(r[1]), int(r[2]), str(r[3])) for r in rows}
    head = chain.head_of(s, chain.STREAMS["event"], ())
    return serials, (head if head is not None else (0, None))


def fill(url: str, total: int, signer: Signer) -> None:
    """``total`` artifacts over SERIALS serials, each activated: bulk inserts (one multi-row INSERT per
    table and 1 000 rows) whose chain and signature columns are computed as ``chain.link`` computes them
    (the full ``db verify`` after the fill proves they are the same)."""
    template = calibration()
    art_stream, event_stream = chain.STREAMS["artifact"], chain.STREAMS["event"]
    columns = [c.name for c in ArtifactRow.__table__.columns if c.name != "id"]
    event_columns = [c.name for c in EventRow.__table__.columns if c.name != "id"]
    with Store.open(url, signer=signer) as store:
        engine = store._write_engine  # noqa: SLF001 - a benchmark fills in big transactions
        with Session(engine) as s:
            serials, (event_seq, event_prev) = _heads(s)
        for start in range(0, total, BATCH):
            arts, events = [], []
            for i in range(start, min(start + BATCH, total)):
                serial = f"CAM-{i % SERIALS:05d}"
                version, seq, prev = serials.get(serial, (0, 0, None))  # type: ignore[arg-type]
                art = template.model_copy(update={"serial": serial, "version": version + 1}).sealed()
                orm = codec.artifact_row(art, utc_now())
                row = {c: getattr(orm, c) for c in columns}
                row["chain_seq"], row["chain_prev"] = seq + 1, prev
                row["chain_hash"] = chain.record_hash(art_stream, (serial,), seq + 1, prev, chain.body(row))
                row["signature"] = signer.sign(record_message(row["chain_hash"], row["content_sha256"]))
                row["key_id"] = signer.key_id
                arts.append(row)
                serials[serial] = (version + 1, seq + 1, row["chain_hash"])
                event = {
                    "serial": serial,
                    "version": version + 1,
                    "previous_version": version or None,
                    "kind": "activate",
                    "actor": "bench",
                    "station": "bench",
                    "at": utc_now(),
                    "reason": "fill",
                }
                event_seq += 1
                event["chain_seq"], event["chain_prev"] = event_seq, event_prev
                event["chain_hash"] = chain.record_hash(
                    event_stream, (), event_seq, event_prev, chain.body(event)
                )
                event["signature"], event["key_id"] = (
                    signer.sign(record_message(event["chain_hash"], None)),
                    signer.key_id,
                )
                event_prev = event["chain_hash"]
                events.append({c: event.get(c) for c in event_columns})
            with Session(engine) as s, s.begin():
                s.execute(insert(ArtifactRow), arts)
                s.execute(insert(EventRow), events)
                for serial in {a["serial"] for a in arts}:
                    counters.raise_to(s, "artifact", serial, serials[serial][0])
                counters.raise_to(s, "chain", "event", event_seq)


def plain_loop(url: str) -> float:
    """The old access pattern in its simplest form: per serial, one query for the active row, parse, hash."""
    with Store.open(url, create=False) as store, Session(store._engine) as s:  # noqa: SLF001
        t0 = time.perf_counter()
        for serial in s.scalars(select(ArtifactRow.serial).distinct()):
            version = history.CAMERAS.active(s, serial)
            row = s.scalars(
                select(ArtifactRow).where(ArtifactRow.serial == serial, ArtifactRow.version == version)
            ).one()
            json.loads(row.payload)
            hashlib.sha256(row.payload.encode()).hexdigest()
        return time.perf_counter() - t0


CPU: dict[str, float] = {}


def timed(fn, name: str = "") -> tuple[float, object]:  # type: ignore[no-untyped-def]
    """Wall seconds (and, under ``name``, this process's CPU seconds: the machine is shared)."""
    t0, c0 = time.perf_counter(), time.process_time()
    result = fn()
    if name:
        CPU[name] = time.process_time() - c0
    return time.perf_counter() - t0, result


def reads(settings: Settings, url: str) -> dict[str, float]:
    """CPU ms of history / show / export of one serial: in-process (best of 3) and as a CLI process
    (user+sys of the child, start-up included)."""
    serial = f"CAM-{SERIALS // 2:05d}"
    calls = {
        "history": (lambda: records.history(settings, serial), ["history", serial]),
        "show": (lambda: records.show(settings, serial), ["show", serial]),
        "export": (
            lambda: records.export(settings, serial, "ros", None, force=False),
            ["export", serial, "--format", "ros"],
        ),
    }
    out: dict[str, float] = {}
    for name, (call, argv) in calls.items():
        best = float("inf")
        for _ in range(3):
            c0 = time.process_time()
            call()
            best = min(best, time.process_time() - c0)
        out[name] = 1000 * best
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        subprocess.run(
            [sys.executable, "-m", "calibctl", "--db", url, *argv],
            check=True,
            capture_output=True,
            env={**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parent.parent)},
        )
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        out[name + "_cli"] = 1000 * (after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime)
    return out


def measure(url: str, total: int, key: Path) -> dict[str, float]:
    signer = create_key(key, force=True)
    t_fill, _ = timed(lambda: fill(url, total, signer))
    settings = load_settings(db=url, env={"CALIBCTL_SIGNING_KEY": str(key)})
    read_ms = reads(settings, url)
    t_lint, results = timed(lambda: lint_workflow.lint(settings, [], None, True), "lint_all")
    assert len(results) == SERIALS and not any(r.failed for r in results)  # type: ignore[arg-type]
    t_verify, report = timed(lambda: database.verify(settings), "verify")
    assert report.ok and report.signatures_checked == 2 * total, report.problems[:3]  # type: ignore[attr-defined]
    fill(url, SERIALS, signer)  # one more version per serial: what a "night" adds
    t_since, since = timed(lambda: database.verify(settings, since=report.head), "since")  # type: ignore[attr-defined]
    assert since.ok and since.records_checked == 2 * SERIALS, since.problems[:3]  # type: ignore[attr-defined]
    return {
        "fill": t_fill,
        "lint_all": t_lint,
        "plain": plain_loop(url),
        "verify": t_verify,
        "since": t_since,
        "lint_cpu": CPU["lint_all"],
        "verify_cpu": CPU["verify"],
        "since_cpu": CPU["since"],
        **read_ms,
    }


def _pg_url() -> tuple[str, str]:
    import psycopg

    admin = os.environ.get("CALIBCTL_TEST_PG_URL", "postgresql://postgres@127.0.0.1:5432/test")
    name = f"bench_{uuid.uuid4().hex[:8]}"
    with psycopg.connect(admin, autocommit=True) as conn:
        conn.execute(f"CREATE DATABASE {name}")
    return admin, name


def _pg_drop(admin: str, name: str) -> None:
    import psycopg

    with psycopg.connect(admin, autocommit=True) as conn:
        conn.execute(f"DROP DATABASE IF EXISTS {name} WITH (FORCE)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--large", action="store_true", help="1k, 10k and 100k artifacts (default: 1k)")
    parser.add_argument("--sizes", type=int, nargs="+", help="artifact counts to measure (overrides --large)")
    parser.add_argument("--pg", action="store_true", help="also on the local PostgreSQL")
    args = parser.parse_args()
    sizes = args.sizes or ([1000, 10_000, 100_000] if args.large else [1000])
    print(
        f"# store scale: {cpu_model()}, nproc {os.cpu_count()}, load {os.getloadavg()[0]:.2f}, "
        f"{utc_now():%Y-%m-%d %H:%M} UTC\n"
    )
    print("wall seconds, with this process's CPU seconds in brackets (the 2 cores were shared)\n")
    print(
        "| backend | artifacts | lint --all s | lint ms/serial (CPU) | plain loop s | db verify s | "
        "verify ms per 1k records (CPU) | --since HEAD s, +1k artifacts (CPU) | history / show / export "
        "CPU ms "
        "in-process | same, CLI process CPU ms | fill s |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    backends = ["sqlite"] + (["postgresql"] if args.pg else [])
    for backend in backends:
        for total in sizes:
            with tempfile.TemporaryDirectory() as tmp:
                admin = name = ""
                if backend == "sqlite":
                    url = f"sqlite:///{Path(tmp) / 'scale.db'}"
                else:
                    admin, name = _pg_url()
                    url = f"postgresql+psycopg://postgres@127.0.0.1:5432/{name}"
                try:
                    m = measure(url, total, Path(tmp) / "key.pem")
                finally:
                    if name:
                        _pg_drop(admin, name)
            records = 2 * total  # artifacts + events, each chained and signed
            print(
                f"| {backend} | {total} | {m['lint_all']:.2f} | {1000 * m['lint_all'] / SERIALS:.2f} "
                f"({1000 * m['lint_cpu'] / SERIALS:.2f}) | {m['plain']:.2f} | {m['verify']:.1f} | "
                f"{1000 * m['verify'] / (records / 1000):.0f} "
                f"({1000 * m['verify_cpu'] / (records / 1000):.0f}) | "
                f"{m['since']:.2f} ({m['since_cpu']:.2f}) | {m['history']:.0f} / {m['show']:.0f} / "
                f"{m['export']:.0f} | "
                f"{m['history_cli']:.0f} / {m['show_cli']:.0f} / {m['export_cli']:.0f} | {m['fill']:.0f} |",
                flush=True,
            )


if __name__ == "__main__":
    main()
