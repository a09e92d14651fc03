"""Detection and calibrate side by side with the plain OpenCV script, sequential and on a process pool.

    PYTHONPATH=. .venv/bin/python benchmarks/bench_parallel_detect.py RENDERED_96 REAL_FOLDER [--repeats 3]
        [--baseline DIR]

RENDERED_96: ``calibctl synth OUT --views 96 --size 1280x960`` (its first 20 views form the 20-view set);
REAL_FOLDER: a real set with a 9x6 board (../shared/datasets/udacity-camcal). Every path runs in a fresh
Python process, as a user runs it, the paths taking turns, ``--repeats`` rounds; best wall time:

Detection (time measured inside the process, after its imports; a pool's start-up included):
  * plain sequential: imread + findChessboardCorners (ADAPTIVE_THRESH | NORMALIZE_IMAGE) + cornerSubPix 11x11;
  * plain pool: the same function on multiprocessing.Pool(jobs) (fork, Linux's default), pool start included;
  * calibctl: ``classify_files`` at jobs 1 and 2 (the default: every core available), pool start included.
End to end (interpreter start to exit, a fresh SQLite store with the board registered each run):
  * ``calibctl capture`` and ``calibctl calibrate`` at jobs 1 and the default;
  * the plain script: the detection above then calibrateCameraExtended, sequential and on a pool.
Recall is printed beside every time: calibctl must find at least what the plain script finds.
``--model M``: calibrate's lens model (default k1k2; the plain script is always calibrateCameraExtended, so
its ratio is then only the before/after rows' reference). ``--baseline DIR``: the code before a change
(``git archive BRANCH_POINT | tar -x -C DIR``); its ``classify_files`` at the default jobs and its
``calibrate``
run as three more rows, taking turns with the others, so before and after meet the same load. Every process
runs in the temporary work folder: ``python -m`` puts the current folder first on sys.path, so a run started
from a checkout measured that checkout's calibctl in the baseline rows too (before 2026-11-27 07:00 UTC).
Every process reads its bytecode from a cache the first (uncounted) round fills, as an installed calibctl
does (``machine.run_env``). CPU: user + system time of the process and of the children it waited for
(getrusage RUSAGE_CHILDREN), the least over the rounds; on a loaded machine it is the steadier measure.
The plain Pool's workers are waited for, so counted; calibctl's warm pool's workers belong to its fork server
and are not: the classify_files rows add the fork server's and its workers' CPU as the script read it from
/proc at the end (since 2026-11-27; the capture and calibrate rows still leave it out). Prints a markdown
report with machine, date and load: the 1-minute load average
at the start of each path's best run is printed beside it.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import os
import platform
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from machine import cpu_model, load_1min, run_env  # benchmarks/machine.py (scripts run from benchmarks/)

# The plain script's per-picture work (after ``import cv2``), also the plain warm loops' (bench_station_plain)
PLAIN_DETECT = r"""
FLAGS = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
CRIT = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 30, 0.001)
def detect(path):
    gray = cv2.imread(path, cv2.IMREAD_GRAYSCALE)
    found, corners = cv2.findChessboardCorners(gray, (9, 6), flags=FLAGS)
    if not found:
        return None, gray.shape[::-1]
    return cv2.cornerSubPix(gray, corners, (11, 11), (-1, -1), CRIT), gray.shape[::-1]
"""
PLAIN = (
    r"""
import sys, time, glob, os
t0 = time.perf_counter()
import cv2, numpy as np
folder, jobs, solve = sys.argv[1], int(sys.argv[2]), sys.argv[3] == "solve"
"""
    + PLAIN_DETECT.lstrip("\n")
    + r"""if __name__ == "__main__":
    paths = sorted(p for p in glob.glob(os.path.join(folder, "*")) if p.lower().endswith((".png", ".jpg")))
    t = time.perf_counter()
    if jobs == 1:
        found = [detect(p) for p in paths]
    else:
        from multiprocessing import Pool
        with Pool(jobs) as pool:
            found = pool.map(detect, paths)
    t_detect = time.perf_counter() - t
    views = [c for c, _ in found if c is not None]
    if solve:
        obj = np.zeros((54, 3), np.float32)
        obj[:, :2] = np.mgrid[0:9, 0:6].T.reshape(-1, 2) * 0.025
        cv2.calibrateCameraExtended([obj] * len(views), views, found[0][1], None, None)
    print(f"RESULT {t_detect:.4f} {len(views)} {time.perf_counter() - t:.4f}")
"""
)

CALIBCTL_DETECT = r'''
import os, sys, time
from calibctl.core.board.board_spec import BoardSpec
from calibctl.core.capture import worker_pool
from calibctl.core.capture.image_outcomes import classify_files, list_images
def pool_cpu_s(jobs):
    """CPU of the warm pool's fork server and of its live workers (Linux /proc): they are the fork server's
    children, never waited for by this process, so getrusage(RUSAGE_CHILDREN) does not count them."""
    if not worker_pool.is_warm(jobs):
        return 0.0
    from multiprocessing import forkserver
    pids = [forkserver._forkserver._forkserver_pid, *worker_pool.process_pool(jobs)._processes]
    ticks = 0
    for pid in pids:
        fields = open(f"/proc/{pid}/stat").read().rsplit(")", 1)[1].split()
        ticks += int(fields[11]) + int(fields[12])  # utime, stime
    return ticks / os.sysconf("SC_CLK_TCK")
if __name__ == "__main__":
    paths = list_images(sys.argv[1])
    t = time.perf_counter()
    out = classify_files(paths, BoardSpec.chessboard(9, 6, 0.025), workers=int(sys.argv[2]))
    seconds = time.perf_counter() - t
    found = sum(o.corners_px is not None for o in out)
    print(f"RESULT {seconds:.4f} {found} {pool_cpu_s(int(sys.argv[2])):.4f}")
'''


def children_cpu_s() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def run(cmd: list[str], env: dict[str, str] | None, cwd: Path) -> tuple[float, float, str]:
    """(wall s from start to exit, CPU s of the process and the children it waited for, stdout). ``cwd``: a
    folder without a calibctl package, so ``-m calibctl`` imports the one ``env``'s PYTHONPATH names."""
    t, c = time.perf_counter(), children_cpu_s()
    done = subprocess.run(cmd, capture_output=True, text=True, env=env, cwd=cwd)
    wall, cpu = time.perf_counter() - t, children_cpu_s() - c
    if done.returncode not in (0, 1):
        raise RuntimeError(
            f"{' '.join(cmd[:6])} exited {done.returncode}:\n{done.stdout[-2000:]}\n{done.stderr[-2000:]}"
        )
    return wall, cpu, done.stdout


def result_of(stdout: str) -> tuple[float, int]:
    line = next(line for line in stdout.splitlines() if line.startswith("RESULT "))
    _, seconds, found, *_ = line.split()
    return float(seconds), int(found)


def pool_cpu_of(stdout: str) -> float:
    """The warm pool's CPU a ``CALIBCTL_DETECT`` run printed (its fourth RESULT field), else 0."""
    fields = next(line for line in stdout.splitlines() if line.startswith("RESULT ")).split()
    return float(fields[3]) if len(fields) > 3 else 0.0


def boards_of(stdout: str) -> str:
    """Images with a board in a ``capture --json`` / ``calibrate --json`` answer, and whether it solved."""
    doc = json.loads(stdout)
    session = doc["capture"]["session"] if "capture" in doc else doc["session"]
    found = sum(o["corners_found"] > 0 for o in session["outcomes"])
    solved = "" if "capture" not in doc else (", solved" if doc["calibration"] else ", not solved")
    return f"{found} boards, session {session['status']}{solved}"


def template_store(work: Path, code: Path | None = None) -> Path:
    """A store holding board BENCH, made by the code in ``code`` (None: this process's): an older calibctl
    refuses a store a newer one migrated, so a ``--baseline`` gets a template of its own."""
    db = work / ("template.db" if code is None else "template-baseline.db")
    if code is not None:
        subprocess.run(
            [
                sys.executable,
                "-m",
                "calibctl",
                "--db",
                f"sqlite:///{db}",
                "board",
                "add",
                "BENCH",
                "--cols",
                "9",
                "--rows",
                "6",
                "--square-mm",
                "25",
                "--uncertainty-mm",
                "0.02",
                "--instrument",
                "calipers",
                "--measured-by",
                "bench",
                "--measured-on",
                dt.date.today().isoformat(),
            ],
            cwd=work,
            env={**os.environ, "PYTHONPATH": str(code.resolve())},
            check=True,
            capture_output=True,
        )
        return db
    from calibctl.store.repository import Store
    from calibctl.workflows.board.boards import BoardRegistration, build_board

    reg = BoardRegistration(
        "BENCH",
        "chessboard",
        9,
        6,
        25.0,
        uncertainty_mm=0.02,
        instrument="calipers",
        measured_by="bench",
        measured_on=dt.date.today().isoformat(),
    )
    with Store.open(f"sqlite:///{db}") as store:
        store.add_board(build_board(reg, created_by="bench"))
    return db


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("rendered", type=Path)
    parser.add_argument("real", type=Path)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--baseline", type=Path, help="a checkout of the code before the change")
    parser.add_argument("--no-real", action="store_true", help="the rendered sets only")
    parser.add_argument(
        "--model", default="k1k2", help="calibrate's --model (the plain script stays calibrateCameraExtended)"
    )
    args = parser.parse_args()
    args.rendered, args.real = (
        args.rendered.resolve(),
        args.real.resolve(),
    )  # the processes run in the work folder
    cores = len(os.sched_getaffinity(0))
    py = sys.executable
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        r20 = work / "r20"
        r20.mkdir()
        for p in sorted(args.rendered.glob("*.png"))[:20]:
            shutil.copy(p, r20 / p.name)
        sets = [
            ("rendered 1280x960, 96 views", args.rendered),
            ("rendered 1280x960, 20 views", r20),
            (f"real: {args.real.name}", args.real),
        ][: 2 if args.no_real else 3]
        (work / "plain.py").write_text(PLAIN)
        (work / "detect.py").write_text(CALIBCTL_DETECT)
        template = template_store(work)
        template_before = None if args.baseline is None else template_store(work, args.baseline)
        load = os.getloadavg()
        print(
            f"{dt.datetime.now(dt.UTC):%Y-%m-%d %H:%M} UTC, {cpu_model()}, {cores} cores available, Python "
            f"{platform.python_version()}, load average {load[0]:.2f} / {load[1]:.2f} / {load[2]:.2f} at "
            "start "
            f"(a shared machine); best and median of {args.repeats} rounds after a bytecode-warming round; "
            f"calibrate --model {args.model}\n"
        )
        for label, folder in sets:
            det = {
                "plain sequential loop": [py, str(work / "plain.py"), str(folder), "1", "detect"],
                f"plain Pool({cores})": [py, str(work / "plain.py"), str(folder), str(cores), "detect"],
                "calibctl classify_files, jobs 1": [py, str(work / "detect.py"), str(folder), "1"],
                f"calibctl classify_files, jobs {cores} (default)": [
                    py,
                    str(work / "detect.py"),
                    str(folder),
                    str(cores),
                ],
            }
            db = work / "run.db"
            url = f"sqlite:///{db}"
            cli = [py, "-m", "calibctl", "--db", url]
            one = ["--serial", "B-1", "--board", "BENCH", "--source", str(folder)]  # one camera's photos
            e2e = {
                "plain script (detect + calibrateCameraExtended)": [
                    py,
                    str(work / "plain.py"),
                    str(folder),
                    "1",
                    "solve",
                ],
                f"plain script on Pool({cores})": [
                    py,
                    str(work / "plain.py"),
                    str(folder),
                    str(cores),
                    "solve",
                ],
                "calibctl capture --jobs 1": [*cli, "capture", *one, "--jobs", "1", "--json"],
                "calibctl capture (default jobs)": [*cli, "capture", *one, "--json"],
                "calibctl calibrate --jobs 1": [
                    *cli,
                    "calibrate",
                    *one,
                    "--jobs",
                    "1",
                    "--model",
                    args.model,
                    "--json",
                ],
                "calibctl calibrate (default jobs)": [
                    *cli,
                    "calibrate",
                    *one,
                    "--model",
                    args.model,
                    "--json",
                ],
            }
            if args.baseline is not None:
                det[f"before: calibctl classify_files, jobs {cores} (default)"] = det[
                    f"calibctl classify_files, jobs {cores} (default)"
                ]
                for jobs in ("1", "default"):
                    e2e[f"before: calibctl calibrate {'--jobs 1' if jobs == '1' else '(default jobs)'}"] = (
                        e2e[f"calibctl calibrate {'--jobs 1' if jobs == '1' else '(default jobs)'}"]
                    )
            env = run_env(work / "pycache")
            base_env = (
                None if args.baseline is None else run_env(work / "pycache-before", args.baseline.resolve())
            )
            best: dict[str, tuple[float, str, float]] = {}
            least_cpu: dict[str, float] = {}
            every: dict[str, list[tuple[float, float]]] = {}  # (seconds, load) of every counted round
            for round_ in range(args.repeats + 1):  # round 0 fills the bytecode caches and is not counted
                for name, cmd in [*det.items(), *e2e.items()]:
                    shutil.copyfile(
                        template_before if name.startswith("before:") and template_before else template, db
                    )
                    shutil.rmtree(work / "calibctl-images", ignore_errors=True)
                    load = load_1min()
                    wall, cpu, out = run(cmd, base_env if name.startswith("before:") else env, work)
                    if round_ == 0:
                        continue
                    if name in det:
                        cpu += pool_cpu_of(out)
                    least_cpu[name] = min(cpu, least_cpu.get(name, cpu))
                    if name in det:
                        seconds, found = result_of(out)
                        note = f"{found} boards"
                    elif name.startswith("plain"):
                        seconds, note = wall, f"{result_of(out)[1]} boards"
                    else:
                        seconds, note = wall, boards_of(out)
                    every.setdefault(name, []).append((seconds, load))
                    if name not in best or seconds < best[name][0]:
                        best[name] = (seconds, note, load)
            print(
                f"### {label}\n\n| path | best s | vs plain sequential | median s | median vs plain | "
                "process CPU s "
                "(least) | CPU vs plain | recall | load at best | load range "
                "|\n|---|---|---|---|---|---|---|---|---|---|"
            )
            for group, ref in (
                (det, "plain sequential loop"),
                (e2e, "plain script (detect + calibrateCameraExtended)"),
            ):
                for name in group:
                    seconds, note, load = best[name]
                    median = statistics.median(t for t, _ in every[name])
                    loads = [lo for _, lo in every[name]]
                    ref_median = statistics.median(t for t, _ in every[ref])
                    print(
                        f"| {name} | {seconds:.3f} | {seconds / best[ref][0]:.2f}x | {median:.3f} | "
                        f"{median / ref_median:.2f}x | {least_cpu[name]:.2f} | "
                        f"{least_cpu[name] / least_cpu[ref]:.2f}x | {note} | {load:.2f} | "
                        f"{min(loads):.2f}-{max(loads):.2f} |"
                    )
            print(f"\nload average {os.getloadavg()[0]:.2f} after this set\n", flush=True)


if __name__ == "__main__":
    main()
