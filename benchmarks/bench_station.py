"""The station's per-unit time against the plain script's detect + solve of the same views.

    PYTHONPATH=. .venv/bin/python benchmarks/bench_station.py RENDERED_FOLDER [--units 6] [--views 20]

Copies the first ``--views`` images of RENDERED_FOLDER (``calibctl synth OUT --views 96 --size
1280x960``) into one folder per unit, then runs ``calibctl station --serials FILE --json`` once (a fresh
SQLite store with the board registered) and reads each unit's ``unit_s`` (serial read to verdict out:
capture, gates, store, solve with its held-out validation and lint, store). The plain script
(benchmarks/bench_parallel_detect.py: imread + findChessboardCorners + cornerSubPix, then
calibrateCameraExtended) runs as many times, each a fresh process; its time after its imports (detect +
solve) is the per-unit reference, its whole run (interpreter start to exit) is printed too. Prints a
markdown table with machine, date and load.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import os
import platform
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from bench_parallel_detect import PLAIN, template_store
from machine import cpu_model


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("rendered", type=Path)
    parser.add_argument("--units", type=int, default=6)
    parser.add_argument("--views", type=int, default=20)
    args = parser.parse_args()
    py = sys.executable
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        views = sorted(args.rendered.glob("*.png"))[:args.views]
        serials = [f"UNIT-{i:03d}" for i in range(args.units)]
        for serial in serials:
            (work / "shots" / serial).mkdir(parents=True)
            for p in views:
                shutil.copy(p, work / "shots" / serial / p.name)
        (work / "serials.txt").write_text("\n".join(serials) + "\n")
        (work / "plain.py").write_text(PLAIN)
        db = template_store(work)
        load = os.getloadavg()
        print(f"{dt.datetime.now(dt.UTC):%Y-%m-%d %H:%M} UTC, {cpu_model()}, {len(os.sched_getaffinity(0))} cores "
              f"available, Python {platform.python_version()}, load average {load[0]:.2f} / {load[1]:.2f} / "
              f"{load[2]:.2f} at start (a shared machine); {args.units} units of {len(views)} views\n")
        t = time.perf_counter()
        done = subprocess.run([py, "-m", "calibctl", "--db", f"sqlite:///{db}", "station", "--board", "BENCH",
                               "--source-template", f"{work / 'shots'}/{{serial}}", "--serials",
                               str(work / "serials.txt"), "--json"], capture_output=True, text=True, cwd=work)
        station_wall = time.perf_counter() - t
        units = [json.loads(line) for line in done.stdout.splitlines() if line.startswith("{")]
        if done.returncode != 0 or len(units) != args.units:
            raise SystemExit(f"station exited {done.returncode}:\n{done.stdout}\n{done.stderr}")
        plain_inner, plain_wall = [], []
        for serial in serials:
            t = time.perf_counter()
            out = subprocess.run([py, str(work / "plain.py"), str(work / "shots" / serial), "1", "solve"],
                                 capture_output=True, text=True, check=True).stdout
            plain_wall.append(time.perf_counter() - t)
            plain_inner.append(float(out.split()[-1]))
        unit_s = [u["unit_s"] for u in units]
        print("| path | per unit, median s | min s | max s |\n|---|---|---|---|")
        print(f"| calibctl station, unit_s (units 2..{args.units}, warm) | {statistics.median(unit_s[1:]):.3f} | "
              f"{min(unit_s[1:]):.3f} | {max(unit_s[1:]):.3f} |")
        print(f"| calibctl station, first unit | {unit_s[0]:.3f} | | |")
        print(f"| plain script, detect + solve after its imports | {statistics.median(plain_inner):.3f} | "
              f"{min(plain_inner):.3f} | {max(plain_inner):.3f} |")
        print(f"| plain script, whole process | {statistics.median(plain_wall):.3f} | {min(plain_wall):.3f} | "
              f"{max(plain_wall):.3f} |")
        print(f"\ncalibctl station whole run (start-up, {args.units} units, exit): {station_wall:.2f} s; verdicts: "
              f"{', '.join(sorted({u['status'] for u in units}))}; load average {os.getloadavg()[0]:.2f} at the end")


if __name__ == "__main__":
    main()
