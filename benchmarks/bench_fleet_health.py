"""`calibctl fleet ingest` rate and `fleet trends` latency on a store of a year of daily health reports.

A rendered fleet: ROBOTS robots x 4 camera serials, each serial one `check` (RMS rising 0.004 px/degC with a
seasonal temperature) and one `timeoffset` (20 ppm drift) report a day for DAYS days; one JSON-lines file per
robot,
ingested through the workflow the CLI calls (parse, validate, refer-check, insert: all or nothing per file).
Then `fleet trends` (the workflow: two queries and the fits) for a sample of serials, and the recovered
slopes.

Run: python benchmarks/bench_fleet_health.py [--robots 25] [--days 365] [--db sqlite:///PATH |
postgresql://...] [--keyed]

``--keyed``: a station key signs the reports at ingest, and `fleet trends` checks each report's link and
signature as well as its hashes (as a store with keys does).
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
from datetime import UTC, datetime, timedelta
from pathlib import Path

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from machine import cpu_model  # noqa: E402

from calibctl.artifacts.common import utc_now  # noqa: E402
from calibctl.artifacts.fleet import FleetEvent  # noqa: E402
from calibctl.config import Settings, load_settings  # noqa: E402
from calibctl.signing import create_key  # noqa: E402
from calibctl.store.repository import Store  # noqa: E402
from calibctl.workflows.fleet import health  # noqa: E402


def _files(folder: Path, robots: int, days: int, seed: int = 0) -> list[Path]:
    rng = np.random.default_rng(seed)
    start = datetime.now(UTC).replace(microsecond=0) - timedelta(days=days)
    paths = []
    for r in range(robots):
        lines = []
        for c in range(4):
            serial, base = f"CAM-{r:03d}-{c}", 0.25 + 0.05 * rng.random()
            for d in range(days):
                at = (start + timedelta(days=d)).isoformat()
                temp = 20 + 15 * math.sin(2 * math.pi * d / 365) + rng.normal(0, 2)
                common = {"serial": serial, "robot": f"amr-{r:03d}", "time": at}
                lines.append(
                    {
                        **common,
                        "source_id": f"{serial}/{d}/c",
                        "kind": "check",
                        "verdict": "pass",
                        "rms_px": base + 0.004 * temp + rng.normal(0, 0.01),
                        "temperature_c": temp,
                    }
                )
                lines.append(
                    {
                        **common,
                        "source_id": f"{serial}/{d}/t",
                        "kind": "timeoffset",
                        "sigma_ms": 0.5,
                        "td_ms": 3.0 + 20e-3 * 86400 * d / 10 + rng.normal(0, 0.5),
                        "temperature_c": temp,
                    }
                )
        path = folder / f"amr-{r:03d}.jsonl"
        path.write_text("".join(json.dumps(line) + "\n" for line in lines))
        paths.append(path)
    return paths


def timed_trends(settings: Settings, serials: list[str]) -> tuple[list[float], list[float], list[float]]:
    """``fleet trends`` (the workflow) of each serial: its wall seconds, RMS slope (px/degC) and td drift
    (ppm)."""
    latencies, slopes, drifts = [], [], []
    for serial in serials:
        t1 = time.perf_counter()
        t = health.trends(settings, serial)
        latencies.append(time.perf_counter() - t1)
        assert t.rms_vs_temperature_px_per_c is not None and t.td_drift_ppm is not None
        slopes.append(t.rms_vs_temperature_px_per_c.slope)
        drifts.append(t.td_drift_ppm.slope)
    return latencies, slopes, drifts


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--robots", type=int, default=25, help="robots (4 serials each; 25 -> 100 serials)")
    ap.add_argument("--days", type=int, default=365)
    ap.add_argument(
        "--db", default=None, help="store URL (default: a fresh SQLite file in a temporary folder)"
    )
    ap.add_argument("--samples", type=int, default=20, help="serials timed for trends")
    ap.add_argument("--keyed", action="store_true", help="sign at ingest, check signatures in trends")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        url = args.db or f"sqlite:///{folder / 'fleet.db'}"
        with Store.open(url, create=True) as store:
            for r in range(args.robots):
                store.add_fleet_event(
                    FleetEvent(
                        kind="register",
                        robot=f"amr-{r:03d}",
                        serials=[f"CAM-{r:03d}-{c}" for c in range(4)],
                        actor="bench",
                        station="bench",
                        at=utc_now(),
                        reason="bench",
                    )
                )
        paths = _files(folder, args.robots, args.days)
        env = {}
        if args.keyed:
            create_key(folder / "station.pem")
            env["CALIBCTL_SIGNING_KEY"] = str(folder / "station.pem")
        settings = load_settings(db=url, station="bench", operator="bench", env=env)
        t0 = time.perf_counter()
        results = health.ingest(settings, paths)
        ingest_s = time.perf_counter() - t0
        stored = sum(r.stored for r in results)
        assert not any(r.refused for r in results), [r.refused[:3] for r in results if r.refused]
        serials = [f"CAM-{r:03d}-{c}" for r in range(args.robots) for c in range(4)][
            :: max(1, args.robots * 4 // args.samples)
        ]
        latencies, slopes, drifts = timed_trends(settings, serials)
    print(
        f"# fleet health: ingest and trends ({datetime.now(UTC):%Y-%m-%d %H:%M} UTC, {cpu_model()}, "
        f"load {os.getloadavg()[0]:.1f}, {url.split(':')[0]}{', keyed' if args.keyed else ''})\n"
    )
    print("| what | value |\n|---|---|")
    print(
        f"| reports ingested | {stored} ({args.robots * 4} serials x {args.days} days x 2 kinds, "
        f"{len(paths)} files) |"
    )
    print(f"| ingest wall | {ingest_s:.1f} s = {stored / ingest_s:,.0f} reports/s |")
    print(
        f"| `fleet trends` latency (workflow, {len(latencies)} serials) | median "
        f"{statistics.median(latencies) * 1e3:.0f} ms, "
        f"max {max(latencies) * 1e3:.0f} ms |"
    )
    print(f"| recovered RMS slope (true 0.004 px/degC) | median {statistics.median(slopes):.4f} |")
    print(f"| recovered td drift (true 2 ppm) | median {statistics.median(drifts):.2f} ppm |")


if __name__ == "__main__":
    main()
