"""The station's per-unit time against the plain script's detect + solve of the same views.

    PYTHONPATH=. .venv/bin/python benchmarks/bench_station.py RENDERED_FOLDER [--units 6] [--views 20]
    [--baseline DIR]

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

``--watch``: the line as it really runs - the unit's folders start empty, and after each serial a feeder (this
script) renames the views into the folder one by one, a pause drawn uniformly from ``--pace-s LO,HI`` (seeded)
before each, as a camera app saves the pictures while the operator moves the board; the station runs with
``--watch --views N --settle-s 0`` and detects each as it lands (``--settle-s S`` above 0: the pictures are
written in place, and the station takes one as complete once unchanged for S). Reported beside the plain
script's detect + solve of the same folder (which can start only once the last picture is there): the
station's ``after_last_image_s`` (last picture's ctime to verdict out), the same seen from here (last
picture complete to the line read), ``unit_s``, and the CPU time (user + sys) of the station's process tree
per unit, polling included, beside the plain script's whole-process CPU.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import os
import platform
import random
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from bench_parallel_detect import PLAIN, children_cpu_s, template_store
from machine import cpu_model, load_1min, run_env


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("rendered", type=Path)
    parser.add_argument("--units", type=int, default=6)
    parser.add_argument("--views", type=int, default=20)
    parser.add_argument("--baseline", type=Path, help="a checkout of the code before the change")
    parser.add_argument(
        "--watch", action="store_true", help="pictures fed one by one into empty unit folders"
    )
    parser.add_argument("--pace-s", default="0.1,0.3", help="--watch: the pause before each picture, LO,HI s")
    parser.add_argument(
        "--settle-s",
        type=float,
        default=0.0,
        help="--watch: 0 renames each picture into place; above 0 writes it in place, the station "
        "judging it complete after this long unchanged",
    )
    args = parser.parse_args()
    if args.watch:
        watch(args)
        return
    py = sys.executable
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        views = sorted(args.rendered.glob("*.png"))[: args.views]
        serials = [f"UNIT-{i:03d}" for i in range(args.units)]
        for serial in serials:
            (work / "shots" / serial).mkdir(parents=True)
            for p in views:
                shutil.copy(p, work / "shots" / serial / p.name)
        (work / "plain.py").write_text(PLAIN)
        db = template_store(work)
        templates = {"calibctl station": db}
        if args.baseline is not None:  # its own store: an older calibctl refuses one a newer one migrated
            templates["before: calibctl station"] = template_store(work, args.baseline)
        load = os.getloadavg()
        print(
            f"{dt.datetime.now(dt.UTC):%Y-%m-%d %H:%M} UTC, {cpu_model()}, {len(os.sched_getaffinity(0))} "
            "cores "
            f"available, Python {platform.python_version()}, load average {load[0]:.2f} / {load[1]:.2f} / "
            f"{load[2]:.2f} at start (a shared machine); {args.units} units of {len(views)} views\n"
        )
        env = run_env(work / "pycache")
        stations = {"calibctl station": env}
        if args.baseline is not None:
            stations["before: calibctl station"] = run_env(work / "pycache-before", args.baseline.resolve())
        for i, (name, station_env) in enumerate(stations.items()):  # one unit each fills the bytecode caches
            shutil.copyfile(templates[name], work / f"warm{i}.db")
            subprocess.run(
                station_argv(
                    py, work / f"warm{i}.db", work / f"warm{i}-spool.sqlite", work / "shots"
                ),  # a spool per store
                input=serials[0] + "\n",
                capture_output=True,
                text=True,
                cwd=work,
                env=station_env,
                check=True,
            )
        subprocess.run(
            [py, str(work / "plain.py"), str(work / "shots" / serials[0]), "1", "solve"],
            capture_output=True,
            env=env,
            check=True,
        )
        procs, walls, unit_times = {}, {}, {name: [] for name in stations}
        for name, station_env in stations.items():
            store = work / f"{len(procs)}.db"
            shutil.copyfile(templates[name], store)
            walls[name] = time.perf_counter()
            procs[name] = subprocess.Popen(
                station_argv(py, store, work / f"{len(procs)}-spool.sqlite", work / "shots"),
                stdin=subprocess.PIPE,
                stdout=subprocess.PIPE,
                stderr=subprocess.PIPE,
                text=True,
                cwd=work,
                env=station_env,
            )
        plain_inner, plain_wall, loads, statuses = [], [], [], set()
        for serial in serials:
            loads.append(load_1min())
            for name, proc in procs.items():
                assert proc.stdin is not None and proc.stdout is not None
                proc.stdin.write(serial + "\n")
                proc.stdin.flush()
                line = proc.stdout.readline()
                if not line.startswith("{"):
                    raise SystemExit(
                        f"{name} stopped: "
                        f"{line}{proc.stdout.read()}{proc.stderr.read() if proc.stderr else ''}"
                    )
                unit = json.loads(line)
                if unit["status"] not in ("pass", "fail"):  # an error line's unit_s times nothing
                    raise SystemExit(f"{name}: unit {serial} {unit['status']}: {unit['message']}")
                unit_times[name].append(unit["unit_s"])
                statuses.add(unit["status"])
            t = time.perf_counter()
            out = subprocess.run(
                [py, str(work / "plain.py"), str(work / "shots" / serial), "1", "solve"],
                capture_output=True,
                text=True,
                check=True,
                env=env,
            ).stdout
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
        print(
            f"| calibctl station, unit_s (units 2..{args.units}, warm) | "
            f"{statistics.median(unit_s[1:]):.3f} | "
            f"{min(unit_s[1:]):.3f} | {max(unit_s[1:]):.3f} |"
        )
        print(f"| calibctl station, first unit | {unit_s[0]:.3f} | | |")
        if args.baseline is not None:
            before = unit_times["before: calibctl station"]
            print(
                f"| before: calibctl station, unit_s (units 2..{args.units}, warm) | "
                f"{statistics.median(before[1:]):.3f} "
                f"| {min(before[1:]):.3f} | {max(before[1:]):.3f} |"
            )
        print(
            f"| plain script, detect + solve after its imports | {statistics.median(plain_inner):.3f} | "
            f"{min(plain_inner):.3f} | {max(plain_inner):.3f} |"
        )
        print(
            f"| plain script, whole process | {statistics.median(plain_wall):.3f} | {min(plain_wall):.3f} | "
            f"{max(plain_wall):.3f} |"
        )
        print(
            f"\ncalibctl station whole run (start-up, {args.units} units, exit, the plain runs between units "
            f"included): {station_wall:.2f} s; verdicts: {', '.join(sorted(statuses))}; 1-minute load "
            "average "
            f"{min(loads):.2f}-{max(loads):.2f} at the units' starts, {load_1min():.2f} at the end"
        )


def station_argv(py: str, store: Path, spool: Path, shots: Path) -> list[str]:
    """`calibctl station` on one store with a spool of its own, each serial's photos in SHOTS/SERIAL."""
    station = ["station", "--board", "BENCH", "--source-template", f"{shots}/{{serial}}", "--json"]
    return [py, "-m", "calibctl", "--db", f"sqlite:///{store}", *station, "--spool", str(spool)]


def tree_cpu_s(root: int) -> float:
    """User + sys CPU seconds of ``root`` and every process below it (the fork server, the detection workers),
    with the children they reaped."""
    stats: dict[int, tuple[int, float]] = {}
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                fields = (entry / "stat").read_text().rsplit(")", 1)[1].split()
            except OSError:
                continue
            stats[int(entry.name)] = (int(fields[1]), sum(float(f) for f in fields[11:15]))
    below, total = {root}, 0.0
    for _ in range(8):  # the tree is three deep
        below |= {pid for pid, (ppid, _) in stats.items() if ppid in below}
    for pid in below:
        total += stats.get(pid, (0, 0.0))[1]
    return total / os.sysconf("SC_CLK_TCK")


def feed(
    folder: Path, views: list[Path], pace: tuple[float, float], rng: random.Random, in_place: bool
) -> float:
    """A camera app saving the unit's pictures: each written under a temporary name and renamed into place
    (or, ``in_place``, written under its own name); returns the perf_counter time the last one was
    complete."""
    folder.mkdir(parents=True, exist_ok=True)
    for p in views:
        time.sleep(rng.uniform(*pace))
        shutil.copyfile(p, folder / (p.name if in_place else f"{p.name}.part"))
        if not in_place:
            os.replace(folder / f"{p.name}.part", folder / p.name)
    return time.perf_counter()


def summary_row(name: str, values: list[float]) -> str:
    return f"| {name} | {statistics.median(values):.3f} | {min(values):.3f} | {max(values):.3f} |"


def watch(args: argparse.Namespace) -> None:
    """The --watch run (see the module docstring)."""
    py = sys.executable
    lo, hi = (float(x) for x in args.pace_s.split(","))
    rng = random.Random(24)
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        views = sorted(args.rendered.glob("*.png"))[: args.views]
        serials = [f"UNIT-{i:03d}" for i in range(args.units + 1)]  # the first one warms the bytecode cache
        (work / "plain.py").write_text(PLAIN)
        db = template_store(work)
        load = os.getloadavg()
        how = f"written in place (--settle-s {args.settle_s:g})" if args.settle_s > 0 else "renamed"
        print(
            f"{dt.datetime.now(dt.UTC):%Y-%m-%d %H:%M} UTC, {cpu_model()}, {len(os.sched_getaffinity(0))} "
            "cores "
            f"available, Python {platform.python_version()}, load average {load[0]:.2f} / {load[1]:.2f} / "
            f"{load[2]:.2f} at start (a shared machine); {args.units} units of {len(views)} views, each "
            "picture "
            f"{how} into the "
            f"unit's folder after a pause of {lo:g}-{hi:g} s (uniform, seeded)\n"
        )
        env = run_env(work / "pycache")
        command = [
            *station_argv(py, work / "station.db", work / "spool.sqlite", work / "shots"),
            "--watch",
            "--views",
            str(len(views)),
            "--settle-s",
            str(args.settle_s),
        ]
        shutil.copyfile(db, work / "station.db")
        proc = subprocess.Popen(
            command,
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            cwd=work,
            env=env,
        )
        assert proc.stdin is not None and proc.stdout is not None
        rows: dict[str, list[float]] = {
            k: [] for k in ("after", "seen", "unit", "cpu", "plain", "plain_wall", "plain_cpu")
        }
        loads, statuses = [], set()
        for n, serial in enumerate(serials):
            loads.append(load_1min())
            cpu = tree_cpu_s(proc.pid)
            proc.stdin.write(serial + "\n")
            proc.stdin.flush()
            last_in = feed(work / "shots" / serial, views, (lo, hi), rng, args.settle_s > 0)
            line = proc.stdout.readline()
            seen = time.perf_counter() - last_in
            if not line.startswith("{"):
                raise SystemExit(
                    "the station stopped: "
                    f"{line}{proc.stdout.read()}{proc.stderr.read() if proc.stderr else ''}"
                )
            unit = json.loads(line)
            statuses.add(unit["status"])
            cpu = tree_cpu_s(proc.pid) - cpu
            t, c = time.perf_counter(), children_cpu_s()
            out = subprocess.run(
                [py, str(work / "plain.py"), str(work / "shots" / serial), "1", "solve"],
                capture_output=True,
                text=True,
                check=True,
                env=env,
            ).stdout
            if n == 0:
                continue
            rows["plain_wall"].append(time.perf_counter() - t)
            rows["plain_cpu"].append(children_cpu_s() - c)
            rows["plain"].append(float(out.split()[-1]))
            for key, value in (
                ("after", unit["after_last_image_s"]),
                ("seen", seen),
                ("unit", unit["unit_s"]),
                ("cpu", cpu),
            ):
                rows[key].append(value)
        proc.communicate("")
        if proc.returncode != 0:
            raise SystemExit(f"the station exited {proc.returncode}")
        print(
            "| per unit (units 2..; the first warmed the caches) | median s | min s | max s "
            "|\n|---|---|---|---|"
        )
        print(
            summary_row(
                "station --watch: after_last_image_s (last picture's ctime to verdict out)", rows["after"]
            )
        )
        print(
            summary_row(
                "station --watch: last picture complete (renamed or written) to the verdict line read here",
                rows["seen"],
            )
        )
        print(
            summary_row(
                "plain script, detect + solve after its imports (starts after the last picture)",
                rows["plain"],
            )
        )
        print(summary_row("plain script, whole process", rows["plain_wall"]))
        print(summary_row("station --watch: unit_s (serial to verdict, the feed included)", rows["unit"]))
        print(
            summary_row("station --watch: CPU s (user+sys, its process tree, polling included)", rows["cpu"])
        )
        print(summary_row("plain script: CPU s (user+sys, whole process)", rows["plain_cpu"]))
        ratio = statistics.median(rows["after"]) / statistics.median(rows["plain"])
        paired = statistics.median(a / p for a, p in zip(rows["after"], rows["plain"], strict=True))
        print(
            f"\nafter_last_image_s / plain detect + solve: {ratio:.2f} (medians), {paired:.2f} (median of "
            "the "
            f"units' own ratios, each unit beside the plain run that followed it); verdicts: "
            f"{', '.join(sorted(statuses))}; 1-minute load average {min(loads):.2f}-{max(loads):.2f} at "
            "the units' "
            f"starts, {load_1min():.2f} at the end"
        )


if __name__ == "__main__":
    main()
