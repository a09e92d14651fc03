"""The fleet at factory size on PostgreSQL: ROBOTS robots x 4 camera serials, a year of daily
health summaries (500 x 4 x 365 = 730 000 reports), `fleet ingest` rate, `fleet status` and `fleet trends
SERIAL` latency.

The store is a fresh PostgreSQL database this script creates and drops (default ``calibctl_bench_fleet`` on
the server of CALIBCTL_TEST_PG_URL, default postgresql://postgres@127.0.0.1:5432/test). Each serial gets two
accepted calibrations (bench_store_scale's bulk fill: chained and signed as the store writes them), each robot
is
registered and assigned @1 through the fleet log, and a rollout of every serial's @2 starts (5 canary robots).
One daily report per serial (check on even days, time offset on odd days), one JSON-lines file per robot,
ingested through the workflow the CLI calls (parse, validate, refer-check, insert; all or nothing per file);
then the canary robots report a passing check. Timed: the workflows the CLI calls (``rollouts.start``,
``health.ingest``, ``rollouts.fleet_status``, ``rollouts.promote``, ``health.trends``) and, for comparison,
the former queries (one active-version query per serial; the per-camera spread over the whole table).

Run: python benchmarks/bench_fleet_scale.py [--robots 500] [--days 365] [--keep]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import statistics
import sys
import tempfile
import time
from collections.abc import Callable
from datetime import UTC, datetime, timedelta
from pathlib import Path

import numpy as np
import psycopg

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from benchmarks import bench_store_scale  # noqa: E402
from benchmarks.bench_fleet_health import timed_trends  # noqa: E402
from benchmarks.machine import cpu_model  # noqa: E402
from calibctl.artifacts.common import utc_now  # noqa: E402
from calibctl.artifacts.fleet import FleetEvent  # noqa: E402
from calibctl.config import load_settings  # noqa: E402
from calibctl.signing import create_key  # noqa: E402
from calibctl.store.repository import Store  # noqa: E402
from calibctl.workflows.fleet import health, rollouts  # noqa: E402
from calibctl.workflows.fleet.health import SPREAD_WINDOW  # noqa: E402

ADMIN_URL = os.environ.get("CALIBCTL_TEST_PG_URL", "postgresql://postgres@127.0.0.1:5432/test")


def serial_of(robot: int, camera: int) -> str:
    return f"CAM-{robot * 4 + camera:05d}"  # bench_store_scale.fill's naming


def _event(**fields: object) -> FleetEvent:
    return FleetEvent(actor="bench", station="bench", at=utc_now(), reason="bench", **fields)  # type: ignore[arg-type]


def _files(folder: Path, robots: int, days: int, seed: int = 0) -> list[Path]:
    """One file per robot: per serial and day one report, a check (RMS 0.004 px/degC) or a time offset (2
    ppm)."""
    rng = np.random.default_rng(seed)
    start = datetime.now(UTC).replace(microsecond=0) - timedelta(days=days + 1)
    paths = []
    for r in range(robots):
        lines = []
        for c in range(4):
            serial, base = serial_of(r, c), 0.25 + 0.05 * rng.random()
            for d in range(days):
                temp = 20 + 15 * math.sin(2 * math.pi * d / 365) + rng.normal(0, 2)
                common = {
                    "serial": serial,
                    "robot": f"amr-{r:03d}",
                    "time": (start + timedelta(days=d)).isoformat(),
                    "source_id": f"{serial}/{d}",
                    "temperature_c": temp,
                }
                if d % 2 == 0:
                    lines.append(
                        {
                            **common,
                            "kind": "check",
                            "verdict": "pass",
                            "rms_px": base + 0.004 * temp + rng.normal(0, 0.01),
                        }
                    )
                else:
                    lines.append(
                        {
                            **common,
                            "kind": "timeoffset",
                            "sigma_ms": 0.5,
                            "td_ms": 3.0 + 2 * 86.4 * d + rng.normal(0, 0.5),
                        }
                    )
        path = folder / f"amr-{r:03d}.jsonl"
        path.write_text("".join(json.dumps(line) + "\n" for line in lines))
        paths.append(path)
    return paths


def _timed(fn: Callable[[], object], repeats: int) -> list[float]:
    out = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        out.append(time.perf_counter() - t0)
    return out


def _ms(values: list[float]) -> str:
    return (
        f"median {statistics.median(values) * 1e3:.0f} ms, max {max(values) * 1e3:.0f} ms (n {len(values)})"
    )


def run(url: str, robots: int, days: int, folder: Path) -> list[tuple[str, str]]:
    rows: list[tuple[str, str]] = []
    serials = [serial_of(r, c) for r in range(robots) for c in range(4)]
    t0 = time.perf_counter()
    Store.open(url, create=True).close()
    bench_store_scale.SERIALS = len(serials)
    bench_store_scale.fill(
        url, 2 * len(serials), create_key(folder / "bench.key")
    )  # @1 and @2 of each, @2 active
    with Store.open(url) as store:
        store.append_fleet_events(
            [
                _event(kind="register", robot=f"amr-{r:03d}", serials=[serial_of(r, c) for c in range(4)])
                for r in range(robots)
            ]
        )
        store.append_fleet_events(
            [
                _event(kind="assign", robot=f"amr-{r:03d}", serial=serial_of(r, c), version=1)
                for r in range(robots)
                for c in range(4)
            ]
        )
    rows.append(
        (
            "setup (fill, register, assign)",
            f"{time.perf_counter() - t0:.1f} s: {len(serials)} serials x 2 "
            f"versions, {robots * 5} fleet events",
        )
    )
    settings = load_settings(db=url, station="bench", operator="bench", env={})
    canary = [f"amr-{r:03d}" for r in range(min(5, robots))]
    t1 = time.perf_counter()
    rollouts.start(settings, "bench", [f"{s}@2" for s in serials], canary, "bench")
    rows.append(
        (
            f"`fleet rollout start` of every serial's @2 ({len(serials)} targets, {len(canary)} canary "
            "robots)",
            f"{time.perf_counter() - t1:.1f} s (a `calibctl diff` per target, recorded in the rollout event)",
        )
    )
    t2 = time.perf_counter()
    paths = _files(folder, robots, days)
    gen_s = time.perf_counter() - t2
    t3 = time.perf_counter()
    results = health.ingest(settings, paths)
    ingest_s = time.perf_counter() - t3
    stored = sum(r.stored for r in results)
    assert not any(r.refused for r in results), [r.refused[:3] for r in results if r.refused]
    rows.append(
        (
            "reports ingested",
            f"{stored:,} ({len(serials)} serials x {days} days, {len(paths)} files; "
            f"written in {gen_s:.0f} s)",
        )
    )
    rows.append(("ingest wall", f"{ingest_s:.1f} s = {stored / ingest_s:,.0f} reports/s"))
    canary_lines = [
        json.dumps(
            {
                "source_id": f"canary/{serial_of(r, c)}",
                "serial": serial_of(r, c),
                "robot": f"amr-{r:03d}",
                "time": utc_now().isoformat(),
                "kind": "check",
                "rms_px": 0.3,
                "verdict": "pass",
            }
        )
        for r in range(len(canary))
        for c in range(4)
    ]
    (folder / "canary.jsonl").write_text("\n".join(canary_lines) + "\n")
    assert not health.ingest(settings, [folder / "canary.jsonl"])[0].refused
    status_s = _timed(lambda: rollouts.fleet_status(settings), 5)
    robots_now, staged = rollouts.fleet_status(settings)
    assert len(robots_now.robots) == robots and staged[0].state[canary[0]] == "healthy", staged[0].state
    rows.append((f"`fleet status` (workflow: {robots} robots, the open rollout's gate)", _ms(status_s)))
    with Store.open(url, create=False) as store:
        loop_s = _timed(lambda: [store.active_version(s) for s in serials], 3)
        batch_s = _timed(store.active_versions, 5)
    rows.append(("  active versions, one query per serial (the former pattern)", _ms(loop_s)))
    rows.append(("  active versions, one batched query (now)", _ms(batch_s)))
    t4 = time.perf_counter()
    promoted = rollouts.promote(settings, "bench", "bench")
    rows.append(
        (
            f"`fleet rollout promote` to the other {robots - len(canary)} robots",
            f"{time.perf_counter() - t4:.1f} s "
            f"({len(promoted.promote.gate) if promoted.promote else 0} gate inputs recorded; "
            f"{(robots - len(canary)) * 4} assign events, one transaction)",
        )
    )
    sample = serials[:: max(1, len(serials) // 20)]
    trends_s, slopes, drifts = timed_trends(settings, sample)
    with Store.open(url, create=False) as store:
        rows_s = [t for s in sample for t in _timed(lambda s=s: store.health_rows(s), 1)]
        window = store.health_rows(sample[0])[-1].at - SPREAD_WINDOW
        spread_s = _timed(lambda: store.fleet_check_rms(window), 5)
        whole_s = _timed(store.fleet_check_rms, 3)
    rows.append((f"`fleet trends SERIAL` (workflow, {len(sample)} serials)", _ms(trends_s)))
    rows.append(("  its serial's rows (index serial, kind, at)", _ms(rows_s)))
    rows.append(
        (
            f"  the per-camera spread over {SPREAD_WINDOW.days} days (now; index kind, at, serial, rms_px)",
            _ms(spread_s),
        )
    )
    rows.append(("  the per-camera spread over the whole table (the former query)", _ms(whole_s)))
    rows.append(("recovered RMS slope (true 0.004 px/degC)", f"median {statistics.median(slopes):.4f}"))
    rows.append(("recovered td drift (true 2 ppm)", f"median {statistics.median(drifts):.2f} ppm"))
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--robots", type=int, default=500, help="robots (4 serials each)")
    ap.add_argument("--days", type=int, default=365)
    ap.add_argument(
        "--database", default="calibctl_bench_fleet", help="the database created (and dropped) for it"
    )
    ap.add_argument("--keep", action="store_true", help="leave the database for a look afterwards")
    args = ap.parse_args()
    name = args.database
    with psycopg.connect(ADMIN_URL, autocommit=True) as admin:
        admin.execute(f'DROP DATABASE IF EXISTS "{name}"')
        admin.execute(f'CREATE DATABASE "{name}"')
    url = ADMIN_URL.rsplit("/", 1)[0] + f"/{name}"
    try:
        with tempfile.TemporaryDirectory() as tmp:
            load = os.getloadavg()[0]
            rows = run(url, args.robots, args.days, Path(tmp))
    finally:
        if not args.keep:
            with psycopg.connect(ADMIN_URL, autocommit=True) as admin:
                admin.execute(f'DROP DATABASE IF EXISTS "{name}" WITH (FORCE)')
    print(
        f"# fleet at scale ({datetime.now(UTC):%Y-%m-%d %H:%M} UTC, {cpu_model()}, {os.cpu_count()} CPUs, "
        f"load {load:.1f} at the start and {os.getloadavg()[0]:.1f} at the end, PostgreSQL)\n"
    )
    print("| what | value |\n|---|---|")
    for what, value in rows:
        print(f"| {what} | {value} |")


if __name__ == "__main__":
    main()
