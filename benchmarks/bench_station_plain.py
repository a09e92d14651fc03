"""A warm station unit against the simplest plain warm loops, side by side in one run.

    PYTHONPATH=. .venv/bin/python benchmarks/bench_station_plain.py RENDERED_96 [--units 6] [--views 20]
        [--same-views] [--baseline DIR] [--jobs N]
    PYTHONPATH=. .venv/bin/python benchmarks/bench_station_plain.py RENDERED_96 --profile [--units 6]
        [--dump F]

RENDERED_96: ``calibctl synth OUT --views 96 --size 1280x960 --seed 3``. Each unit gets its own ``--views``
views (unit k: views 15k .. 15k + 19; a camera on a line is a new camera each time, so nothing one unit
computed answers the next; ``--same-views``: every unit the first views, as bench_station.py does, where
calibctl's remembered answers (core.intrinsics.recent_answers) answer most solves of units 2..). Warm, all
three: each is one process started once, fed one unit folder at a time on stdin, one warm-up unit first
(views 76..95, not counted):

  * calibctl station (``--json``, a fresh SQLite store with board BENCH): its ``unit_s`` and the time from the
    serial written to its line read here;
  * the plain warm loop: imports once, then per unit ``cv2.imread`` + ``findChessboardCorners``
    (ADAPTIVE_THRESH | NORMALIZE_IMAGE) + ``cornerSubPix`` 11x11 per view, sequential, then
    ``calibrateCameraExtended``;
  * the plain ``Pool(N)`` loop: the same, the pool made once at start, each unit's views on ``pool.map``.

The units go round in turn (station, plain, pool, rotated by one each unit), so all three meet the same load;
the 1-minute load average is printed at each unit. ``--baseline DIR``: the code before a change (``git
archive``d) runs a second station in the same turns. ``--profile``: no race; the station's own code in this
process at jobs 1 (every stage inline, so cProfile sees it), warm, and each stage's share of the units' time
(``--dump F``: the profile to F as well, for ``pstats``: which functions are called how often).
``--failed``: no plain loops; per round (``--units``) four units of the first ``--views`` views - clean,
the board left in one picture only (the others blurred past finding it), no board at all, every picture
black - through the
station (and ``--baseline``'s), in turns: each kind's ``unit_s`` and its line (the detector calls are
counted in tests/workflows/station/test_station_probe_cost.py).
Prints markdown with machine, date and load.
"""

from __future__ import annotations

import argparse
import contextlib
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

from bench_parallel_detect import PLAIN_DETECT, template_store
from machine import cpu_model, load_1min, run_env, tree_cpu_s

PLAIN_LOOP = (
    r"""
import sys, time, glob, os
import cv2, numpy as np
OBJ = np.zeros((54, 3), np.float32)
OBJ[:, :2] = np.mgrid[0:9, 0:6].T.reshape(-1, 2) * 0.025
"""
    + PLAIN_DETECT.lstrip("\n")
    + r"""if __name__ == "__main__":
    jobs = int(sys.argv[1])
    pool = None
    if jobs > 1:
        from multiprocessing import Pool
        pool = Pool(jobs)
    print("READY", flush=True)
    for line in sys.stdin:
        t = time.perf_counter()
        paths = sorted(glob.glob(os.path.join(line.strip(), "*.png")))
        found = [detect(p) for p in paths] if pool is None else pool.map(detect, paths)
        views = [c for c, _ in found if c is not None]
        rms = cv2.calibrateCameraExtended([OBJ] * len(views), views, found[0][1], None, None)[0]
        print(f"RESULT {time.perf_counter() - t:.4f} {len(views)} {rms:.4f}", flush=True)
"""
)
WARM_VIEWS = slice(76, 96)
STRIDE = 15


def unit_views(views: list[Path], k: int, count: int, same: bool) -> list[Path]:
    return views[:count] if same else views[STRIDE * k : STRIDE * k + count]


def make_units(work: Path, rendered: Path, units: int, count: int, same: bool) -> list[str]:
    views = sorted(rendered.glob("*.png"))
    serials = ["WARM-UP"] + [f"UNIT-{k:03d}" for k in range(units)]
    for i, serial in enumerate(serials):
        (work / "shots" / serial).mkdir(parents=True)
        picks = views[WARM_VIEWS] if i == 0 else unit_views(views, i - 1, count, same)
        if len(picks) < count:
            raise SystemExit(f"{rendered} has too few views for {units} units of {count}")
        for p in picks:
            shutil.copy(p, work / "shots" / serial / p.name)
    return serials


class Station:
    """A warm ``calibctl station`` fed serials; ``unit(serial)`` -> (s here, its unit_s, status, CPU s)."""

    def __init__(self, work: Path, name: str, template: Path, env: dict[str, str], jobs: int | None) -> None:
        store = work / f"{name}.db"
        shutil.copyfile(template, store)
        cmd = [sys.executable, "-m", "calibctl", "--db", f"sqlite:///{store}", "station", "--board", "BENCH"]
        cmd += [
            "--source-template",
            f"{work / 'shots'}/{{serial}}",
            "--json",
            "--spool",
            str(work / f"{name}.sq"),
        ]
        cmd += [] if jobs is None else ["--jobs", str(jobs)]
        self.proc = subprocess.Popen(
            cmd,
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            cwd=work,
            env=env,
        )

    def unit(self, serial: str) -> tuple[float, float, str, float]:
        assert self.proc.stdin is not None and self.proc.stdout is not None
        t, cpu = time.perf_counter(), tree_cpu_s(self.proc.pid)
        self.proc.stdin.write(serial + "\n")
        self.proc.stdin.flush()
        line = self.proc.stdout.readline()
        seen = time.perf_counter() - t
        cpu = tree_cpu_s(self.proc.pid) - cpu
        if not line.startswith("{"):
            raise SystemExit(
                f"the station stopped: {line}{self.proc.stderr.read() if self.proc.stderr else ''}"
            )
        unit = json.loads(line)
        return seen, unit["unit_s"], f"{unit['status']} {unit['views']} views RMS {unit['rms_px']}", cpu

    def close(self) -> None:
        self.proc.communicate("")


class Plain:
    """The plain warm loop (jobs 1) or Pool(jobs) loop; ``unit(folder)`` -> (s here, its own, what, CPU s)."""

    def __init__(self, work: Path, jobs: int, env: dict[str, str]) -> None:
        (work / "plain_loop.py").write_text(PLAIN_LOOP)
        self.proc = subprocess.Popen(
            [sys.executable, str(work / "plain_loop.py"), str(jobs)],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
            cwd=work,
            env=env,
        )
        assert self.proc.stdout is not None and self.proc.stdout.readline().startswith("READY")

    def unit(self, folder: Path) -> tuple[float, float, str, float]:
        assert self.proc.stdin is not None and self.proc.stdout is not None
        t, cpu = time.perf_counter(), tree_cpu_s(self.proc.pid)
        self.proc.stdin.write(f"{folder}\n")
        self.proc.stdin.flush()
        _, inner, views, rms = self.proc.stdout.readline().split()
        return (
            time.perf_counter() - t,
            float(inner),
            f"{views} views RMS {rms}",
            tree_cpu_s(self.proc.pid) - cpu,
        )

    def close(self) -> None:
        self.proc.communicate("")


def row(name: str, values: list[float], ref: list[float] | None = None) -> str:
    med = statistics.median(values)
    ratio = "" if ref is None else f"{med / statistics.median(ref):.2f}"
    paired = (
        "" if ref is None else f"{statistics.median(v / r for v, r in zip(values, ref, strict=True)):.2f}"
    )
    return f"| {name} | {med:.3f} | {min(values):.3f} | {max(values):.3f} | {ratio} | {paired} |"


def stations(args: argparse.Namespace, work: Path, env: dict[str, str]) -> dict[str, Station]:
    """The station, and the one of ``--baseline`` (its own store and bytecode cache) when given."""
    started = {"calibctl station": Station(work, "station", template_store(work), env, args.jobs)}
    if args.baseline is not None:
        before_env = run_env(work / "pycache-before", args.baseline.resolve())
        before = Station(work, "before", template_store(work, args.baseline), before_env, args.jobs)
        started["before: calibctl station"] = before
    return started


def race(args: argparse.Namespace, work: Path, serials: list[str]) -> None:
    env = run_env(work / "pycache")
    contenders: dict[str, Station | Plain] = {**stations(args, work, env)}
    contenders["plain warm loop (sequential)"] = Plain(work, 1, env)
    contenders[f"plain warm Pool({args.pool}) loop"] = Plain(work, args.pool, env)
    seen: dict[str, list[float]] = {name: [] for name in contenders}
    inner: dict[str, list[float]] = {name: [] for name in contenders}
    cpu: dict[str, list[float]] = {name: [] for name in contenders}
    what: dict[str, set[str]] = {name: set() for name in contenders}
    loads = []
    names = list(contenders)
    for i, serial in enumerate(serials):
        loads.append(load_1min())
        order = names[i % len(names) :] + names[: i % len(names)]
        for name in order:
            who = contenders[name]
            got = who.unit(serial) if isinstance(who, Station) else who.unit(work / "shots" / serial)
            if i > 0:  # the warm-up unit is not counted
                seen[name].append(got[0])
                inner[name].append(got[1])
                cpu[name].append(got[3])
                what[name].add(got[2].rsplit(" RMS", 1)[0])
    for who in contenders.values():
        who.close()
    ref = seen["plain warm loop (sequential)"]
    print(
        "| path (warm, one process each) | per unit, median s | min s | max s | median / plain loop | "
        "median of unit ratios |\n|---|---|---|---|---|---|"
    )
    for name in names:
        print(
            row(
                f"{name}: unit written to result read",
                seen[name],
                None if name.startswith("plain warm loop") else ref,
            )
        )
    for name in names:
        own = "unit_s (serial read to verdict out)" if name.endswith("station") else "its own clock"
        print(row(f"{name}: {own}", inner[name]))
    cpu_ref = cpu["plain warm loop (sequential)"]
    for name in names:
        label = f"{name}: CPU s of its processes (user + system)"
        print(row(label, cpu[name], None if name.startswith("plain warm loop") else cpu_ref))
    results = "; ".join(f"{name}: {', '.join(sorted(w))}" for name, w in what.items())
    print(
        f"\nresults: {results}; 1-minute load average {min(loads):.2f}-{max(loads):.2f} at the units' "
        f"starts, {load_1min():.2f} at the end"
    )


# (stage, [(file, function) whose cumulative time it is], [(file, function) taken off]): of the units' time
Key = tuple[str, str]
STAGES: tuple[tuple[str, list[Key], list[Key]], ...] = (
    ("detection: decode, detect, refine (classify_files)", [("image_outcomes.py", "classify_files")], []),
    (
        "pattern check: 3 pictures decoded, their margins looked at (probes only on a maybe)",
        [("capture.py", "_load_samples"), ("pattern_check.py", "larger_board_error")],
        [],
    ),
    ("gates: tilt, coverage, observability (a small lens fit)", [("gates.py", "evaluate_gates")], []),
    (
        "gates: one camera (two-camera split, its 3-fold held-out)",
        [("camera_split.py", "one_camera_gate")],
        [],
    ),
    ("gates: projection (the session's solve with uncertainty)", [("capture.py", "_projection")], []),
    (
        "session and images written",
        [("repository.py", "add_session"), ("capture.py", "images_durable")],
        [],
    ),
    (
        "solve: corner rule, 5-fold held-out, one camera (remembered), misfit floor",
        [("solve.py", "_solve_numbers")],
        [],
    ),
    ("solve: artifact built and linted", [("solve.py", "build_artifact")], [("solve.py", "_solve_numbers")]),
    ("calibration written (seal, chain, counters)", [("cameras.py", "add_artifact")], []),
)


def profile(args: argparse.Namespace, work: Path, serials: list[str]) -> None:
    import cProfile
    import pstats

    from calibctl.config import load_settings
    from calibctl.workflows.station.station import StationRequest, UnitResult, run_station

    db = template_store(work)
    settings = load_settings(db=f"sqlite:///{db}", jobs=1, env={})
    request = StationRequest("BENCH", f"{work / 'shots'}/{{serial}}", spool=work / "spool.sqlite")
    lines: list[UnitResult] = []
    run_station(settings, request, serials[:1], lines.append)  # warm
    load = load_1min()
    prof = cProfile.Profile(time.process_time)  # CPU, not wall: the host is shared
    cpu = time.process_time()
    with prof:
        run_station(settings, request, serials[1:], lines.append)
    cpu = time.process_time() - cpu
    units = [u.unit_s for u in lines[1:]]
    if args.dump:
        prof.dump_stats(args.dump)
    stats = pstats.Stats(prof).stats  # type: ignore[attr-defined]
    cum: dict[tuple[str, str], float] = {}
    for (file, _, func), (_, _, _, ct, _) in stats.items():
        cum[(Path(file).name, func)] = cum.get((Path(file).name, func), 0.0) + ct
    total = cpu
    shares = {
        stage: sum(cum.get(key, 0.0) for key in plus) - sum(cum.get(key, 0.0) for key in minus)
        for stage, plus, minus in STAGES
    }
    print(
        f"station units at jobs 1 in this process, profiled (cProfile): {len(units)} units, median unit_s "
        f"{statistics.median(units):.3f} s, {cpu / len(units):.3f} CPU s a unit (process CPU, the profiler's "
        f"clock); 1-minute load average {load:.2f} at start, {load_1min():.2f} at the end\n"
    )
    print("| stage | CPU s per unit | share of the unit's CPU |\n|---|---|---|")
    for stage, seconds in shares.items():
        print(f"| {stage} | {seconds / len(units):.3f} | {seconds / total:.0%} |")
    rest = total - sum(shares.values())
    print(
        f"| the rest (store opens, session read back, lint, records) | {rest / len(units):.3f} | "
        f"{rest / total:.0%} |"
    )
    solves = {
        func: (calls, ct)
        for (_, _, func), (_, calls, _, ct, _) in stats.items()
        if func in ("<calibrateCamera>", "<calibrateCameraExtended>")
    }
    print(
        "\nOpenCV calibrations (calls a unit, CPU ms a unit): "
        + ", ".join(
            f"{func.strip('<>')} {calls / len(units):.1f}, {ct / len(units) * 1e3:.1f}"
            for func, (calls, ct) in sorted(solves.items())
        )
    )


FAILED_KINDS = ("CLEAN", "ONE-BOARD", "NO-BOARD", "BLACK")


def failed(args: argparse.Namespace, work: Path) -> None:
    import cv2

    views = sorted(args.rendered.resolve().glob("*.png"))[: args.views]
    grays = {p: cv2.imread(str(p), cv2.IMREAD_GRAYSCALE) for p in views[1:]}
    blurred = {p: cv2.GaussianBlur(gray, (0, 0), 25) for p, gray in grays.items() if gray is not None}
    serials = ["WARM-UP"]
    (work / "shots" / "WARM-UP").mkdir(parents=True)
    for p in views:
        shutil.copy(p, work / "shots" / "WARM-UP" / p.name)
    for r in range(args.units):
        for kind in FAILED_KINDS:
            folder = work / "shots" / f"{kind}-{r}"
            folder.mkdir(parents=True)
            for i, p in enumerate(views):
                if kind == "BLACK":  # a camera delivering black frames, a lens cap
                    cv2.imwrite(str(folder / p.name), 0 * blurred[views[1]])
                elif kind == "NO-BOARD" or (kind == "ONE-BOARD" and i > 0):
                    cv2.imwrite(str(folder / p.name), blurred.get(p, blurred[views[1]]))
                else:
                    shutil.copy(p, folder / p.name)
            serials.append(f"{kind}-{r}")
    running = stations(args, work, run_env(work / "pycache"))
    got: dict[tuple[str, str], list[float]] = {}
    lines: dict[tuple[str, str], set[str]] = {}
    loads = []
    for i, serial in enumerate(serials):
        loads.append(load_1min())
        names = list(running)
        for name in names[i % len(names) :] + names[: i % len(names)]:
            _, unit_s, what, _ = running[name].unit(serial)
            if i > 0:
                kind = serial.rsplit("-", 1)[0]
                got.setdefault((name, kind), []).append(unit_s)
                lines.setdefault((name, kind), set()).add(what.split(" ", 1)[0])
    for station in running.values():
        station.close()
    print("| station | unit | unit_s median | min | max | line |\n|---|---|---|---|---|---|")
    for (name, kind), values in got.items():
        print(
            f"| {name} | {kind} | {statistics.median(values):.3f} | {min(values):.3f} | {max(values):.3f} | "
            f"{', '.join(sorted(lines[(name, kind)]))} |"
        )
    print(f"\n1-minute load average {min(loads):.2f}-{max(loads):.2f} at the units' starts")


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("rendered", type=Path)
    parser.add_argument("--units", type=int, default=6)
    parser.add_argument("--views", type=int, default=20)
    parser.add_argument("--same-views", action="store_true", help="every unit the same views")
    parser.add_argument("--baseline", type=Path, help="the code before a change, git archive'd")
    parser.add_argument("--jobs", type=int, help="the station's --jobs (default: every core)")
    parser.add_argument(
        "--pool", type=int, default=len(os.sched_getaffinity(0)), help="the plain pool's size"
    )
    parser.add_argument("--profile", action="store_true", help="stage shares of the station's units (jobs 1)")
    parser.add_argument("--dump", type=Path, help="with --profile: the pstats file to write")
    parser.add_argument("--failed", action="store_true", help="units with failed views beside clean ones")
    args = parser.parse_args()
    load = os.getloadavg()
    print(
        f"{dt.datetime.now(dt.UTC):%Y-%m-%d %H:%M} UTC, {cpu_model()}, {len(os.sched_getaffinity(0))} cores "
        f"available, Python {platform.python_version()}, load average {load[0]:.2f} / {load[1]:.2f} / "
        f"{load[2]:.2f} at start (a shared machine); {args.units} units of {args.views} views, "
        f"{'the same views each' if args.same_views else 'views of their own'}, one warm-up unit first\n"
    )
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        if args.failed:
            with contextlib.chdir(work):
                failed(args, work)
            return
        serials = make_units(work, args.rendered.resolve(), args.units, args.views, args.same_views)
        with contextlib.chdir(work):
            (profile if args.profile else race)(args, work, serials)


if __name__ == "__main__":
    main()
