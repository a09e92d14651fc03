"""The station's per-unit time against the plain script's detect + solve of the same views.

    PYTHONPATH=. .venv/bin/python benchmarks/bench_station.py RENDERED_FOLDER [--units 6] [--views 20] [--baseline DIR]

Copies the first ``--views`` images of RENDERED_FOLDER (``calibctl synth OUT --views 96 --size
1280x960``) into one folder per unit, then runs ``calibctl station --serials FILE --json`` once (a fresh
SQLite store with the board registered) and reads each unit's ``unit_s`` (serial read to verdict out:
capture, gates, store, solve with its held-out validation and lint, store). The plain script
(benchmarks/bench_parallel_detect.py: imread + findChessboardCorners + cornerSubPix, then
calibrateCameraExtended) runs as many times, each a fresh process; its time after its imports (detect +
solve) is the per-unit reference, its whole run (interpreter start to exit) is printed too. The serials
are fed one at a time on stdin and each unit is followed by one plain-script run, so both meet the same load;
``--baseline DIR`` (the code before a change, ``git archive``d) runs a second station beside the first, fed
the same serials in turn. Bytecode is cached as for an installed calibctl (``machine.run_env``). Prints a
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
from machine import cpu_model, load_1min, run_env


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("rendered", type=Path)
    parser.add_argument("--units", type=int, default=6)
    parser.add_argument("--views", type=int, default=20)
    parser.add_argument("--baseline", type=Path, help="a checkout of the code before the change")
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
        (work / "plain.py").write_text(PLAIN)
        db = template_store(work)
        load = os.getloadavg()
        print(f"{dt.datetime.now(dt.UTC):%Y-%m-%d %H:%M} UTC, {cpu_model()}, {len(os.sched_getaffinity(0))} cores "
              f"available, Python {platform.python_version()}, load average {load[0]:.2f} / {load[1]:.2f} / "
              f"{load[2]:.2f} at start (a shared machine); {args.units} units of {len(views)} views\n")
        env = run_env(work / "pycache")
        stations = {"calibctl station": env}
        if args.baseline is not None:
            stations["before: calibctl station"] = run_env(work / "pycache-before", args.baseline.resolve())
        for i, station_env in enumerate(stations.values()):  # one unit each fills the bytecode caches (not counted)
            shutil.copyfile(db, work / f"warm{i}.db")
            subprocess.run([py, "-m", "calibctl", "--db", f"sqlite:///{work / f'warm{i}.db'}", "station", "--board",
                            "BENCH", "--source-template", f"{work / 'shots'}/{{serial}}", "--json",
                            "--spool", str(work / f"warm{i}-spool.sqlite")],  # a spool per store
                           input=serials[0] + "\n", capture_output=True, text=True, cwd=work, env=station_env,
                           check=True)
        subprocess.run([py, str(work / "plain.py"), str(work / "shots" / serials[0]), "1", "solve"],
                       capture_output=True, env=env, check=True)
        procs, walls, unit_times = {}, {}, {name: [] for name in stations}
        for name, station_env in stations.items():
            store = work / f"{len(procs)}.db"
            shutil.copyfile(db, store)
            walls[name] = time.perf_counter()
            procs[name] = subprocess.Popen(
                [py, "-m", "calibctl", "--db", f"sqlite:///{store}", "station", "--board", "BENCH",
                 "--source-template", f"{work / 'shots'}/{{serial}}", "--json",
                 "--spool", str(work / f"{len(procs)}-spool.sqlite")], stdin=subprocess.PIPE,
                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=work, env=station_env)
        plain_inner, plain_wall, loads, statuses = [], [], [], set()
        for serial in serials:
            loads.append(load_1min())
            for name, proc in procs.items():
                assert proc.stdin is not None and proc.stdout is not None
                proc.stdin.write(serial + "\n")
                proc.stdin.flush()
                line = proc.stdout.readline()
                if not line.startswith("{"):
                    raise SystemExit(f"{name} stopped: {line}{proc.stdout.read()}{proc.stderr.read() if proc.stderr else ''}")
                unit = json.loads(line)
                unit_times[name].append(unit["unit_s"])
                statuses.add(unit["status"])
            t = time.perf_counter()
            out = subprocess.run([py, str(work / "plain.py"), str(work / "shots" / serial), "1", "solve"],
                                 capture_output=True, text=True, check=True, env=env).stdout
            plain_wall.append(time.perf_counter() - t)
            plain_inner.append(float(out.split()[-1]))
        for name, proc in procs.items():
            proc.communicate("")
            walls[name] = time.perf_counter() - walls[name]
            if proc.returncode != 0:
                raise SystemExit(f"{name} exited {proc.returncode}")
        units = [{"unit_s": u} for u in unit_times["calibctl station"]]
        station_wall = walls["calibctl station"]
        unit_s = [u["unit_s"] for u in units]
        print("| path | per unit, median s | min s | max s |\n|---|---|---|---|")
        print(f"| calibctl station, unit_s (units 2..{args.units}, warm) | {statistics.median(unit_s[1:]):.3f} | "
              f"{min(unit_s[1:]):.3f} | {max(unit_s[1:]):.3f} |")
        print(f"| calibctl station, first unit | {unit_s[0]:.3f} | | |")
        if args.baseline is not None:
            before = unit_times["before: calibctl station"]
            print(f"| before: calibctl station, unit_s (units 2..{args.units}, warm) | {statistics.median(before[1:]):.3f} "
                  f"| {min(before[1:]):.3f} | {max(before[1:]):.3f} |")
        print(f"| plain script, detect + solve after its imports | {statistics.median(plain_inner):.3f} | "
              f"{min(plain_inner):.3f} | {max(plain_inner):.3f} |")
        print(f"| plain script, whole process | {statistics.median(plain_wall):.3f} | {min(plain_wall):.3f} | "
              f"{max(plain_wall):.3f} |")
        print(f"\ncalibctl station whole run (start-up, {args.units} units, exit, the plain runs between units "
              f"included): {station_wall:.2f} s; verdicts: {', '.join(sorted(statuses))}; 1-minute load average "
              f"{min(loads):.2f}-{max(loads):.2f} at the units' starts, {load_1min():.2f} at the end")


if __name__ == "__main__":
    main()
