"""End-to-end capture + solve: calibctl against a plain OpenCV script and mrcal, side by side in one run.

    .venv/bin/python benchmarks/bench_e2e.py [--repeats 3] [--seed 1] [--quick] [--out
    benchmarks/out/bench_e2e.md]

Data: ``calibctl synth DIR --scenario good --views 20 --size 1280x960 --seed N`` (PNGs + truth.json), then
the 13 left images of /work/shared/datasets/opencv-left-right (copied to a temporary folder).

(a) plain OpenCV as a user writes it (``plain_opencv``): sequential imread + findChessboardCorners
    (ADAPTIVE_THRESH | NORMALIZE_IMAGE) + cornerSubPix winSize (11, 11) as in OpenCV's tutorial and
    DATASET.md's reference (a 23x23 px search window) + calibrateCamera with the production flags
    (CALIB_FIX_K3 | CALIB_ZERO_TANGENT_DIST | CALIB_FIX_ASPECT_RATIO). Timed in-process, and as a script
    (``--plain-only DIR``: a fresh interpreter importing only cv2 and numpy).
(b) calibctl, what a station runs: capture (folder source, detection on 2 workers, gates, session + images
    written into a fresh SQLite store) then solve (calibrateCameraExtended, sigma, outlier flags, k-fold
    held-out validation, lint, artifact write). Timed in-process (the library calls) and as the CLI (wall
    time including Python start-up). Every timed run gets a fresh copy of a migrated store holding only
    the board, so images are really written each time.
(c) mrcal 2.2 (Debian): mrcal-calibrate-cameras on the SAME corners as (a), written as corners.vnl.
    Timed as the CLI (/usr/bin/python3 start-up and ``import mrcal`` included) and in-process
    (benchmarks/mrcal_solve.py runs the same tool script with runpy after a warm-up).

Every timing: one warm-up, then ``--repeats`` runs; best and median. The machine is shared: the load
average is printed. Accuracy is against truth.json (synthetic) or DATASET.md's plain-OpenCV reference
(real photos). Nothing here is asserted.
"""

from __future__ import annotations

import argparse
import json
import re
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np

HERE = Path(__file__).resolve().parent
MRCAL_PY = "/usr/bin/python3"
MRCAL_TOOL = "/usr/bin/mrcal-calibrate-cameras"
REAL_DIR = Path("/work/shared/datasets/opencv-left-right")
PATTERN = (9, 6)
PRODUCTION_FLAGS = cv2.CALIB_FIX_K3 | cv2.CALIB_ZERO_TANGENT_DIST | cv2.CALIB_FIX_ASPECT_RATIO
CLASSIC_FLAGS = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
SUBPIX_CRITERIA = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 30, 0.001)
IMAGE_SUFFIXES = (".png", ".jpg")


def list_images(folder: Path) -> list[Path]:
    return sorted(p for p in folder.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)


# (a) the plain OpenCV script -------------------------------------------------------------------------


def plain_opencv(paths: list[Path], square: float, flags: int = PRODUCTION_FLAGS) -> dict:
    """What a user writes: detect one image after the other, then one calibrateCamera."""
    t0 = time.perf_counter()
    grid = np.zeros((PATTERN[0] * PATTERN[1], 3), np.float32)
    grid[:, :2] = np.mgrid[0 : PATTERN[0], 0 : PATTERN[1]].T.reshape(-1, 2) * square
    object_points, image_points, corners, size = [], [], {}, (0, 0)
    for path in paths:
        gray = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
        size = (gray.shape[1], gray.shape[0])
        found, c = cv2.findChessboardCorners(gray, PATTERN, flags=CLASSIC_FLAGS)
        if found:
            c = cv2.cornerSubPix(gray, c, (11, 11), (-1, -1), SUBPIX_CRITERIA)
            object_points.append(grid)
            image_points.append(c)
            corners[path.name] = c.reshape(-1, 2).astype(np.float64)
    t1 = time.perf_counter()
    rms, K, D, _, _ = cv2.calibrateCamera(object_points, image_points, size, None, None, flags=flags)
    return {
        "fx": K[0, 0],
        "fy": K[1, 1],
        "cx": K[0, 2],
        "cy": K[1, 2],
        "rms_px": float(rms),
        "dist": D.ravel(),
        "corners": corners,
        "image_size": size,
        "detect_s": t1 - t0,
        "solve_s": time.perf_counter() - t1,
    }


def plain_only(folder: Path, square: float, flags: int) -> int:
    """``--plain-only DIR``: the plain script in its own process (wall time with Python start-up)."""
    out = plain_opencv(list_images(folder), square, flags)
    print(json.dumps({k: float(out[k]) for k in ("fx", "fy", "cx", "cy", "rms_px")}))
    return 0


# (c) mrcal --------------------------------------------------------------------------------------------


def write_corners_vnl(path: Path, names: list[str], corners: dict[str, np.ndarray]) -> None:
    """mrcal's corners.vnl: ``# filename x y level``, a row per corner (row-major, level 0), ``- - -`` if
    none."""
    rows = ["# filename x y level"]
    for name in names:
        rows += (
            [f"{name} {x:.6f} {y:.6f} 0" for x, y in corners[name]] if name in corners else [f"{name} - - -"]
        )
    path.write_text("\n".join(rows) + "\n", encoding="utf-8")


def vnl_path(folder: Path) -> Path:
    """Beside the image folder, not in it (calibctl's capture would list it as an ignored file)."""
    return folder.parent / f"{folder.name}-corners.vnl"


def mrcal_helper(*args: str, cwd: Path | None = None) -> dict:
    return json.loads(
        run_checked([MRCAL_PY, str(HERE / "mrcal_solve.py"), *args], cwd=cwd).strip().splitlines()[-1]
    )


def run_mrcal(folder: Path, glob: str, lensmodel: str, focal: float, square: float, repeats: int) -> dict:
    """mrcal-calibrate-cameras on ``vnl_path(folder)``: CLI and in-process times, and its result."""
    outdir = folder.parent / f"{folder.name}-mrcal-{lensmodel}"
    outdir.mkdir(exist_ok=True)
    args = [
        "--corners-cache",
        str(vnl_path(folder)),
        "--lensmodel",
        lensmodel,
        "--focal",
        f"{focal:.0f}",
        "--object-spacing",
        f"{square}",
        "--object-width-n",
        str(PATTERN[0]),
        "--object-height-n",
        str(PATTERN[1]),
        "--outdir",
        str(outdir),
        glob,
    ]
    cli, _ = timed(lambda: run_checked([MRCAL_TOOL, *args], cwd=folder), repeats)
    inproc = mrcal_helper("time", str(repeats), "--", *args, cwd=folder)
    result = mrcal_helper("evaluate", str(outdir / "camera-0.cameramodel"))
    walls = inproc["times_s"]
    return {**result, "cli": cli, "inproc": (min(walls), statistics.median(walls), min(inproc["cpu_s"]))}


# timing -------------------------------------------------------------------------------------------


def cpu_s() -> float:
    """CPU seconds (user + system) of this process, all threads, plus its waited-for children."""
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    return time.process_time() + children.ru_utime + children.ru_stime


def timed(fn: Callable[[], object], repeats: int, setup: Callable[[], None] | None = None):
    """One warm-up, then ``repeats`` timed runs; ``setup`` (untimed) runs before each.
    Returns ((best wall s, median wall s, least CPU s), last result). CPU time barely depends on what
    the other users of the machine do; wall time does."""
    if setup:
        setup()
    result = fn()
    walls, cpus = [], []
    for _ in range(repeats):
        if setup:
            setup()
        start, cpu_start = time.perf_counter(), cpu_s()
        result = fn()
        walls.append(time.perf_counter() - start)
        cpus.append(cpu_s() - cpu_start)
    return (min(walls), statistics.median(walls), min(cpus)), result


def run_checked(cmd: list[str], cwd: Path | None = None) -> str:
    done = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd[:4])}... exited {done.returncode}:\n{done.stdout}\n{done.stderr}")
    return done.stdout


# (b) calibctl (imported lazily: ``--plain-only`` must start as light as a user's script) ---------------

SERIAL = "BENCH-0001"
BOARD_NAME = "BENCH"


class CalibctlRig:
    """calibctl's station path on one folder. A template store (migrated, the board registered) is made
    once; ``fresh()`` copies it before each run, so every run writes its session, images and artifact anew."""

    def __init__(self, work: Path, square_mm: float, model: str) -> None:
        import datetime as dt

        from calibctl.store.repository import Store
        from calibctl.workflows.board.boards import BoardRegistration, build_board

        self.work, self.model = work, model
        work.mkdir(parents=True, exist_ok=True)
        self.template, self.db = work / "template.db", work / "run.db"
        self.url = f"sqlite:///{self.db}"
        reg = BoardRegistration(
            BOARD_NAME,
            "chessboard",
            PATTERN[0],
            PATTERN[1],
            square_mm,
            uncertainty_mm=0.02,
            instrument="calipers",
            measured_by="bench",
            measured_on=dt.date.today().isoformat(),
        )
        with Store.open(f"sqlite:///{self.template}") as store:
            store.add_board(build_board(reg, created_by="bench"))

    def fresh(self) -> None:
        shutil.rmtree(self.work / "calibctl-images", ignore_errors=True)
        shutil.copyfile(self.template, self.db)

    def settings(self):
        from calibctl.config import load_settings

        return load_settings(db=self.url, station="bench", operator="bench", env={})

    def run(self, folder: Path):
        """capture + solve in-process, the library call ``calibctl calibrate`` makes. Returns the artifact."""
        from calibctl.workflows.camera import capture as capture_workflow

        request = capture_workflow.CaptureRequest(serial=SERIAL, board=BOARD_NAME, source=str(folder))
        result = capture_workflow.calibrate(self.settings(), request, model=self.model)
        if result.solve is None:
            gates = ", ".join(g.gate for g in result.capture.session.gates if not g.passed)
            raise RuntimeError(f"capture of {folder} was rejected ({gates}); nothing to time")
        return result.solve.artifact

    def session(self, session_id: str):
        from calibctl.store.repository import Store

        with Store.open(self.url) as store:
            return store.get_session(session_id)

    def cli(self, folder: Path, repeats: int) -> tuple[float, float]:
        """Wall time of ``calibctl calibrate`` in its own process (Python start-up and imports included)."""
        cmd = [
            str(Path(sys.executable).parent / "calibctl"),
            "--db",
            self.url,
            "calibrate",
            "--serial",
            SERIAL,
            "--board",
            BOARD_NAME,
            "--source",
            str(folder),
            "--model",
            self.model,
            "--station",
            "bench",
            "--operator",
            "bench",
        ]
        t, _ = timed(lambda: run_checked(cmd), repeats, setup=self.fresh)
        return t


# per-stage profile of one calibctl run ------------------------------------------------------------

PROFILE_TARGETS = (  # (module, attribute, stage); a missing one is skipped
    (
        "calibctl.core.capture.image_outcomes",
        "classify_session",
        "detection (read, sha256, decode, detect, blur; 2 threads)",
    ),
    ("calibctl.workflows.camera.capture", "evaluate_gates", "gates"),
    (
        "calibctl.workflows.camera.pattern_check",
        "larger_board_error",
        "board-size probe (is it a larger chessboard?)",
    ),
    ("calibctl.store.repository:Store", "open", "store open (engine, schema check)"),
    ("calibctl.store.repository:Store", "get_board", "store reads (board, session)"),
    ("calibctl.store.repository:Store", "get_session", "store reads (board, session)"),
    ("calibctl.store.repository:Store", "put_image", "store write: images"),
    ("calibctl.store.repository:Store", "put_images", "store write: images"),  # folders, since 2026-11-22
    ("calibctl.store.repository:Store", "add_session", "store write: session + corners"),
    ("calibctl.workflows.camera.solve", "solve_intrinsics", "solve (calibrateCameraExtended + sigma)"),
    ("calibctl.workflows.camera.solve", "flag_outliers", "outlier flags"),
    ("calibctl.workflows.camera.solve", "validate_holdout", "held-out k-fold validation"),
    ("calibctl.workflows.camera.solve", "facts_from_document", "lint"),
    ("calibctl.workflows.camera.solve", "lint_facts", "lint"),
    ("calibctl.store.repository:Store", "add_artifact", "store write: artifact (seal, version, activate)"),
)


def profile(rig: CalibctlRig, folder: Path, runs: int) -> tuple[float, dict[str, float]]:
    """``runs`` profiled runs: (median total s, median seconds per stage)."""
    results = [profile_run(rig, folder) for _ in range(runs)]
    labels = dict.fromkeys(label for _, stages in results for label in stages)
    return (
        statistics.median(t for t, _ in results),
        {label: statistics.median(stages.get(label, 0.0) for _, stages in results) for label in labels},
    )


def profile_run(rig: CalibctlRig, folder: Path) -> tuple[float, dict[str, float]]:
    """One run with the stage functions wrapped (not one of the timed runs); (total s, seconds per stage)."""
    import importlib
    import inspect

    totals: dict[str, float] = {}
    saved = []
    for target, attr, label in PROFILE_TARGETS:
        module_name, _, cls = target.partition(":")
        owner = importlib.import_module(module_name)
        owner = getattr(owner, cls) if cls else owner
        try:
            raw, fn = inspect.getattr_static(owner, attr), getattr(owner, attr)
        except AttributeError:  # an older calibctl without it
            continue

        def wrapped(*a, _fn=fn, _label=label, **k):
            start = time.perf_counter()
            try:
                return _fn(*a, **k)
            finally:
                totals[_label] = totals.get(_label, 0.0) + time.perf_counter() - start

        setattr(
            owner, attr, staticmethod(wrapped) if isinstance(raw, classmethod | staticmethod) else wrapped
        )
        saved.append((owner, attr, raw))
    try:
        rig.fresh()
        start = time.perf_counter()
        rig.run(folder)
        total = time.perf_counter() - start
    finally:
        for owner, attr, raw in reversed(saved):
            setattr(owner, attr, raw)
    return total, totals


# report -------------------------------------------------------------------------------------------


def corner_distances(c: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """(N,) distances of corners to reference corners, in whichever grid order fits (raw OpenCV order
    varies)."""
    e1, e2 = np.linalg.norm(c - ref, axis=1), np.linalg.norm(c[::-1] - ref, axis=1)
    return e1 if e1.mean() <= e2.mean() else e2


def corner_error_px(found: dict[str, np.ndarray], truth: dict[str, np.ndarray]) -> float:
    """Mean corner error against truth over the views found."""
    errs = [corner_distances(c, truth[name]) for name, c in found.items()]
    return float(np.concatenate(errs).mean()) if errs else float("nan")


def ms(t: tuple[float, float, float] | None) -> str:
    """``best / median | CPU`` in ms."""
    return "- | -" if t is None else f"{t[0] * 1e3:.0f} / {t[1] * 1e3:.0f} | {t[2] * 1e3:.0f}"


def err(v: float, ref: float) -> str:
    return f"{v - ref:+.3f}"


def machine_lines(repeats: int) -> list[str]:
    import datetime as dt
    import os
    import platform

    import calibctl

    def first(path: str, key: str) -> str:
        try:
            return next(
                line.split(":", 1)[1].strip()
                for line in Path(path).read_text().splitlines()
                if line.startswith(key)
            )
        except (OSError, StopIteration):
            return "unknown"

    mem_kib = first("/proc/meminfo", "MemTotal").split()[0]
    ram_gib = int(mem_kib) / 2**20 if mem_kib.isdigit() else float("nan")
    mrcal = mrcal_helper("version")
    load = ", ".join(f"{v:.2f}" for v in os.getloadavg())
    return [
        f"Run {dt.datetime.now().astimezone().isoformat(timespec='seconds')} on {platform.node()}: "
        f"nproc {len(os.sched_getaffinity(0))}, {first('/proc/cpuinfo', 'model name')}, {ram_gib:.1f} GiB "
        "RAM, "
        f"load average {load} (1/5/15 min) at the start; shared machine.",
        f"Versions: Python {platform.python_version()}, OpenCV {cv2.__version__}, numpy {np.__version__}, "
        f"calibctl {calibctl.__version__}; mrcal {mrcal['mrcal']} under /usr/bin/python3 "
        f"{mrcal['python']} with numpy {mrcal['numpy']}.",
        f"Timings: one warm-up, then best / median of {repeats} runs, in ms.",
    ]


def sigma_fx(art) -> float | None:
    return art.stdev.sigma.get("fx")


def z_cell(value: float, true: float, sigma: float | None) -> str:
    """``sigma | z`` table cells."""
    return "n/a | n/a" if not sigma else f"{sigma:.3f} | {(value - true) / sigma:+.2f}"


def accuracy_row(
    name: str, model: str, r: dict, truth: dict, corner_err: float, sig: dict | None = None
) -> str:
    sig = sig or {}
    return (
        f"| {name} | {model} | {err(r['fx'], truth['fx'])} | {err(r['fy'], truth['fy'])} | "
        f"{err(r['cx'], truth['cx'])} | {err(r['cy'], truth['cy'])} | {r['rms_px']:.4f} | {corner_err:.4f} | "
        f"{z_cell(r['fx'], truth['fx'], sig.get('fx'))} | {z_cell(r['cx'], truth['cx'], sig.get('cx'))} |"
    )


def calibctl_solve_on(plain: dict, square: float, model: str) -> dict:
    """calibctl's solver (core.intrinsics.solve.solve_intrinsics) on the plain script's corners: the solver
    alone."""
    from calibctl.core.intrinsics.solve import solve_intrinsics

    grid = np.zeros((PATTERN[0] * PATTERN[1], 3))
    grid[:, :2] = np.mgrid[0 : PATTERN[0], 0 : PATTERN[1]].T.reshape(-1, 2) * square
    corners = list(plain["corners"].values())
    sol = solve_intrinsics([grid] * len(corners), corners, plain["image_size"], model)
    K = sol.camera_matrix
    return {
        "fx": K[0, 0],
        "fy": K[1, 1],
        "cx": K[0, 2],
        "cy": K[1, 2],
        "rms_px": sol.rms_px,
        "sigma": dict(sol.sigma),
    }


def artifact_numbers(art) -> dict:
    K = art.camera_matrix
    return {"fx": K[0][0], "fy": K[1][1], "cx": K[0][2], "cy": K[1][2], "rms_px": art.rms_px}


def synthetic_section(args: argparse.Namespace, tmp: Path) -> list[str]:
    folder, n = tmp / "synth", args.repeats
    run_checked(
        [
            sys.executable,
            "-m",
            "calibctl",
            "synth",
            str(folder),
            "--scenario",
            "good",
            "--views",
            str(args.views),
            "--size",
            args.size,
            "--seed",
            str(args.seed),
        ]
    )
    truth_doc = json.loads((folder / "truth.json").read_text())
    K, square = truth_doc["camera"]["K"], truth_doc["board"]["square_size_m"]
    truth = {"fx": K[0][0], "fy": K[1][1], "cx": K[0][2], "cy": K[1][2]}
    truth_corners = {
        Path(v["file"]).name: np.asarray(v["corners_px"], np.float64) for v in truth_doc["views"]
    }
    paths = list_images(folder)

    t_plain, plain = timed(lambda: plain_opencv(paths, square), n)
    t_plain_proc, _ = timed(
        lambda: run_checked([sys.executable, __file__, "--plain-only", str(folder), "--square", str(square)]),
        n,
    )
    plain_free = plain_opencv(paths, square, flags=0)
    on_plain = calibctl_solve_on(plain, square, "k1k2")
    write_corners_vnl(vnl_path(folder), [p.name for p in paths], plain["corners"])
    mrcal = {
        m: run_mrcal(folder, "*.png", m, truth["fx"], square, n)
        for m in (("LENSMODEL_OPENCV5",) if args.quick else ("LENSMODEL_OPENCV5", "LENSMODEL_OPENCV4"))
    }

    rig = CalibctlRig(tmp / "calibctl-synth", square * 1000, "k1k2")
    t_lib, art = timed(lambda: rig.run(folder), n, setup=rig.fresh)
    session = rig.session(art.provenance.session_id)
    ours_corners = {v.name: np.asarray(v.corners_px, np.float64) for v in session.views}
    t_cli = rig.cli(folder, n)
    t_start, _ = timed(lambda: run_checked([str(Path(sys.executable).parent / "calibctl"), "--version"]), n)
    total, stages = profile(rig, folder, n)
    solve_stage_s = sum(
        v
        for k, v in stages.items()
        if not k.startswith(("detection", "gates", "store write: images", "store write: session"))
    )
    mr5 = mrcal["LENSMODEL_OPENCV5"]
    w, h = plain["image_size"]
    lines = [
        f"### Synthetic: {len(paths)} images at {w}x{h} (`calibctl synth --scenario good --seed "
        f"{args.seed}`)",
        "",
        f"Truth: fx = fy = {truth['fx']:.1f}, cx = {truth['cx']:.2f}, cy = {truth['cy']:.2f} px, "
        f"distortion {truth_doc['camera']['dist']} (k1 k2 p1 p2 k3).",
        f"Capture gates: {', '.join(g.gate + (' pass' if g.passed else ' FAIL') for g in session.gates)}; "
        f"session {session.status}, {len(session.views)}/{len(paths)} views accepted; artifact {art.status}, "
        f"held-out RMS {art.held_out.rms_px:.4f} px ({art.held_out.k_folds} folds), outer ring fit / "
        "held-out "
        f"{art.held_out.fit_outer_ring_rms_px:.4f} / {art.held_out.outer_ring_rms_px:.4f} px.",
        "",
        "#### Wall time",
        "",
        "| path | what it does | wall best / median ms | CPU ms |",
        "|---|---|---|---|",
        "| (a) plain OpenCV, in-process | sequential detect + calibrateCamera (detect "
        f"{plain['detect_s'] * 1e3:.0f} ms, "
        f"solve {plain['solve_s'] * 1e3:.0f} ms in the last run) | {ms(t_plain)} |",
        "| (a) plain OpenCV script, own process | the same plus Python start-up, import cv2 | "
        f"{ms(t_plain_proc)} |",
        f"| (b) calibctl library | capture (detect on 2 threads, gates, store session + images) + solve "
        f"(sigma, outliers, {art.held_out.k_folds}-fold held-out, lint, artifact write) | {ms(t_lib)} |",
        "| (b) calibctl CLI, own process | `calibctl calibrate` (the same, plus Python start-up and "
        f"imports) | {ms(t_cli)} |",
        "| (b) calibctl CLI start-up alone | `calibctl --version` (imports of the CLI app) | "
        f"{ms(t_start)} |",
    ]
    for m, r in mrcal.items():
        lines += [
            f"| (c) mrcal-calibrate-cameras {m}, CLI | solve only on (a)'s corners (no detection), "
            f"outlier rejection + board warp (defaults) | {ms(r['cli'])} |",
            f"| (c) mrcal {m}, in-process | the same tool script via runpy, after a warm-up | "
            f"{ms(r['inproc'])} |",
        ]
    lines += [
        "",
        "Ratios (best wall time; CPU time in brackets):",
        "",
        f"- calibctl library / plain OpenCV in-process: {t_lib[0] / t_plain[0]:.2f} "
        f"({t_lib[2] / t_plain[2]:.2f})",
        f"- calibctl CLI / plain OpenCV script process: {t_cli[0] / t_plain_proc[0]:.2f} "
        f"({t_cli[2] / t_plain_proc[2]:.2f})",
        f"- calibctl CLI / mrcal-calibrate-cameras {list(mrcal)[0][10:]} CLI (which does no detection): "
        f"{t_cli[0] / mr5['cli'][0]:.2f} ({t_cli[2] / mr5['cli'][2]:.2f})",
        "- calibctl solve part (profile below: store open/reads, solve, outliers, held-out, lint, "
        "artifact write)"
        f" / mrcal {list(mrcal)[0][10:]} in-process solve: {solve_stage_s / mr5['inproc'][0]:.2f}",
        f"- calibctl library end-to-end / (plain detection + mrcal in-process solve): "
        f"{t_lib[0] / (plain['detect_s'] + mr5['inproc'][0]):.2f}",
        "",
        f"#### Where calibctl's time goes (median of {n} profiled library runs: {total * 1e3:.0f} ms)",
        "",
        "Stages are the functions the workflow calls, wrapped with a timer; a stage's median and the "
        "total's median come from different runs, so the shares need not add up to 100%.",
        "",
        "| stage | ms | share |",
        "|---|---|---|",
    ]
    for label, s in sorted(stages.items(), key=lambda kv: -kv[1]):
        lines.append(f"| {label} | {s * 1e3:.1f} | {s / total:.0%} |")
    other = max(0.0, total - sum(stages.values()))
    lines += [
        f"| other (pydantic documents, hashing, glue) | {other * 1e3:.1f} | {other / total:.0%} |",
        "",
        "#### Accuracy against truth.json",
        "",
        "| tool | model | fx err px | fy err px | cx err px | cy err px | RMS px | mean corner err px | "
        "reported sigma fx px | z fx | reported sigma cx px | z cx |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
        accuracy_row(
            "(a) plain OpenCV",
            "production flags (k1 k2, fx = fy)",
            plain,
            truth,
            corner_error_px(plain["corners"], truth_corners),
        ),
        accuracy_row(
            "(a) plain OpenCV, flags=0",
            "k1 k2 p1 p2 k3, fx and fy free",
            plain_free,
            truth,
            corner_error_px(plain_free["corners"], truth_corners),
        ),
        accuracy_row(
            "(b) calibctl",
            f"{art.model.name} (production)",
            artifact_numbers(art),
            truth,
            corner_error_px(ours_corners, truth_corners),
            art.stdev.sigma,
        ),
        accuracy_row(
            "(b) calibctl solver on (a)'s corners",
            "k1k2 (production)",
            on_plain,
            truth,
            corner_error_px(plain["corners"], truth_corners),
            on_plain["sigma"],
        ),
    ]
    lines += [
        accuracy_row(
            f"(c) mrcal {m}",
            f"{m[10:]}, on (a)'s corners",
            r,
            truth,
            corner_error_px(plain["corners"], truth_corners),
        )
        for m, r in mrcal.items()
    ]
    lines += [
        "",
        "RMS is per corner (sqrt of the mean squared residual length; mrcal's is re-computed the same way "
        "over its inliers: "
        + ", ".join(f"{m[10:]} dropped {r['n_outliers']}" for m, r in mrcal.items())
        + "). "
        "z = (estimate - truth) / calibctl's reported sigma; it only covers corner noise, not a lens the "
        "model "
        "cannot represent (see the notes in BENCHMARKS.md).",
    ]
    return lines


def dataset_reference() -> dict:
    """fx fy cx cy RMS of DATASET.md's plain-OpenCV default-flags solve of the 13 left images."""
    text = (REAL_DIR / "DATASET.md").read_text(encoding="utf-8")
    m = re.search(r"fx ([\d.]+), fy ([\d.]+), cx ([\d.]+), cy ([\d.]+), RMS ([\d.]+) px", text)
    if m is None:
        raise RuntimeError(f"no reference numbers found in {REAL_DIR / 'DATASET.md'}")
    return dict(zip(("fx", "fy", "cx", "cy", "rms_px"), map(float, m.groups()), strict=True))


def real_row(name: str, model: str, r: dict, ref: dict, t: tuple[float, float] | None, note: str = "") -> str:
    return (
        f"| {name} | {model} | {r['fx']:.4f} | {r['fy']:.4f} | {r['cx']:.4f} | {r['cy']:.4f} | "
        f"{r['rms_px']:.4f} | "
        f"{r['fx'] - ref['fx']:+.4f} / {r['fy'] - ref['fy']:+.4f} / {r['cx'] - ref['cx']:+.4f} / "
        f"{r['cy'] - ref['cy']:+.4f} | {ms(t)} | {note} |"
    )


def real_section(args: argparse.Namespace, tmp: Path) -> list[str]:
    """The same three on the 13 left opencv-left-right photos (square 1.0 units; calibctl's board is 25 mm,
    which only scales the translations: the intrinsics do not depend on the square size)."""
    folder, n, ref = tmp / "left", args.repeats, dataset_reference()
    folder.mkdir()
    for path in sorted(REAL_DIR.glob("left*.jpg")):
        shutil.copy2(path, folder / path.name)
    paths = list_images(folder)
    t_plain, plain = timed(lambda: plain_opencv(paths, 1.0, flags=0), n)
    plain_prod = plain_opencv(paths, 1.0)
    write_corners_vnl(vnl_path(folder), [p.name for p in paths], plain["corners"])
    mrcal = {
        m: run_mrcal(folder, "left*.jpg", m, 540.0, 1.0, n)
        for m in ("LENSMODEL_OPENCV5", "LENSMODEL_OPENCV4")
    }
    rig = CalibctlRig(tmp / "calibctl-left", 25.0, "opencv-default")
    t_lib, art = timed(lambda: rig.run(folder), n, setup=rig.fresh)
    rig_prod = CalibctlRig(tmp / "calibctl-left-k1k2", 25.0, "k1k2")
    rig_prod.fresh()
    art_prod = rig_prod.run(folder)
    session = rig.session(art.provenance.session_id)
    flagged = [v.name for v in art.views if v.outlier]
    ours = {v.name: np.asarray(v.corners_px, np.float64) for v in session.views}
    moved = {name: corner_distances(ours[name], c) for name, c in plain["corners"].items() if name in ours}
    far = [
        f"{name} (max {d.max():.2f} px, {int((d > 0.5).sum())} corners > 0.5 px)"
        for name, d in moved.items()
        if d.max() > 0.5
    ]
    lines = [
        f"### Real photos: opencv-left-right, {len(paths)} left images, 640x480",
        "",
        f"Reference (DATASET.md, plain OpenCV default flags, square 1.0): fx {ref['fx']}, fy {ref['fy']}, "
        f"cx {ref['cx']}, cy {ref['cy']}, RMS {ref['rms_px']} px. mrcal --focal 540, --object-spacing 1.0.",
        f"calibctl capture: {len(session.views)}/{len(paths)} views accepted, gates "
        f"{', '.join(g.gate + (' pass' if g.passed else ' FAIL') for g in session.gates)}; artifact "
        f"{art.status}; "
        f"outlier views flagged: {', '.join(flagged) or 'none'}; held-out RMS {art.held_out.rms_px:.4f} px.",
        "",
        "| tool | model | fx | fy | cx | cy | RMS px | delta vs reference fx / fy / cx / cy | wall best / "
        "median ms "
        "| CPU ms | note |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
        f"| reference | OpenCV flags=0 | {ref['fx']:.4f} | {ref['fy']:.4f} | {ref['cx']:.4f} | "
        f"{ref['cy']:.4f} | "
        f"{ref['rms_px']:.4f} | | | | DATASET.md |",
        real_row("(a) plain OpenCV", "flags=0", plain, ref, t_plain, "same recipe as the reference"),
        real_row(
            "(b) calibctl library",
            "opencv-default (flags=0)",
            artifact_numbers(art),
            ref,
            t_lib,
            "capture + solve; its own detector",
        ),
        real_row(
            "(b) calibctl solver on (a)'s corners",
            "opencv-default (flags=0)",
            calibctl_solve_on(plain, 1.0, "opencv-default"),
            ref,
            None,
            "the solver alone",
        ),
        real_row(
            "(c) mrcal",
            "OPENCV5",
            mrcal["LENSMODEL_OPENCV5"],
            ref,
            mrcal["LENSMODEL_OPENCV5"]["inproc"],
            f"in-process time; {mrcal['LENSMODEL_OPENCV5']['n_outliers']} outliers dropped, board warp "
            "solved",
        ),
        real_row(
            "(c) mrcal",
            "OPENCV4",
            mrcal["LENSMODEL_OPENCV4"],
            ref,
            mrcal["LENSMODEL_OPENCV4"]["inproc"],
            f"{mrcal['LENSMODEL_OPENCV4']['n_outliers']} outliers dropped",
        ),
        real_row("(a) plain OpenCV", "production flags", plain_prod, ref, None, "not the reference's model"),
        real_row(
            "(b) calibctl",
            "k1k2 (production)",
            artifact_numbers(art_prod),
            ref,
            None,
            f"sigma fx {sigma_fx(art_prod):.3f} px, lint {art_prod.status}",
        ),
    ]
    lines += [
        "",
        f"Corners: calibctl's detector and the plain script's cornerSubPix 11x11 differ by more than 0.5 px "
        f"on {', '.join(far) or 'no view'}; mean difference over all corners "
        f"{np.concatenate(list(moved.values())).mean():.3f} px.",
        "",
        "mrcal RMS is over its inliers only (outliers dropped, board warp solved), so it is not comparable "
        "one to one with OpenCV's RMS over every corner.",
    ]
    return lines


def run_report(args: argparse.Namespace) -> int:
    if args.quick:
        args.repeats = 1
    lines = [
        "## End-to-end capture + solve: calibctl vs plain OpenCV vs mrcal",
        "",
        *machine_lines(args.repeats),
        "",
    ]
    with tempfile.TemporaryDirectory(prefix="bench_e2e_") as tmp:
        lines += synthetic_section(args, Path(tmp))
        if not args.quick:
            lines += ["", *real_section(args, Path(tmp))]
    report = "\n".join(lines) + "\n"
    print(report)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(report, encoding="utf-8")
    return 0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3, help="timed runs after the warm-up")
    parser.add_argument("--seed", type=int, default=1, help="calibctl synth seed")
    parser.add_argument("--views", type=int, default=20)
    parser.add_argument("--size", default="1280x960")
    parser.add_argument(
        "--quick", action="store_true", help="1 timed run, no OPENCV4 row, no real-photo section"
    )
    parser.add_argument("--out", type=Path, default=HERE / "out" / "bench_e2e.md")
    parser.add_argument(
        "--plain-only", type=Path, metavar="DIR", help="run only the plain OpenCV script on DIR"
    )
    parser.add_argument("--square", type=float, default=0.025, help="square size for --plain-only")
    args = parser.parse_args()
    if args.plain_only:
        return plain_only(args.plain_only, args.square, PRODUCTION_FLAGS)
    return run_report(args)


if __name__ == "__main__":
    sys.exit(main())
