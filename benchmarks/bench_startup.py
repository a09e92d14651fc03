"""Start-up of each read command in a fresh process, against `python -c 'import cv2, numpy'`.

    .venv/bin/python benchmarks/bench_startup.py [--repeats 7] [--before DIR] [--calibrate]

Each command runs ``--repeats`` times (after one warm-up, so the OS file cache is warm) in a new
interpreter against a small SQLite store holding one board and one calibration (``calibctl demo``);
best and median wall and CPU time are reported, and each command's best wall time over the best of
``python -c 'import cv2, numpy'`` (the issue's reference: a plain OpenCV script's imports). A bare typer app
with calibctl's root options and one command (``FLOOR_APP``) is the floor a typer CLI starts from:
typer 0.29 coerces every option through a pydantic TypeAdapter, so it imports pydantic. ``--before DIR``
also times the calibctl checkout in DIR (e.g. a worktree of main) in the same run, one run of each in turn,
so before/after share the machine's load. Then
``python -X importtime`` of each command is summed per top-level package (self time), which says
where the rest of the time goes. ``--calibrate`` also times ``calibctl calibrate`` of 20 rendered
1280x960 images against the plain OpenCV script (``bench_e2e.py --plain-only``: sequential
findChessboardCorners + cornerSubPix, calibrateCamera) in the same run, and profiles one calibrate
(cProfile with a CPU-time clock, so a stage includes its worker threads' CPU). Nothing is asserted; the
machine is shared, so the load average is printed before each table.

Every child runs with byte-code caching on (``PYTHONDONTWRITEBYTECODE`` removed, the cache under a
temporary ``PYTHONPYCACHEPREFIX``), as an installed calibctl runs: pip compiles the .pyc files at install.
Without it, a checkout run under ``PYTHONDONTWRITEBYTECODE=1`` compiles every calibctl module on every start.
"""

from __future__ import annotations

import argparse
import datetime as dt
import os
import platform
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from collections import defaultdict
from collections.abc import Callable
from pathlib import Path

from machine import cpu_model

REPO = Path(__file__).resolve().parents[1]
SERIAL = "DEMO-CAM-0001"
PYCACHE = Path(tempfile.mkdtemp(prefix="calibctl-pycache-"))


REFERENCE = "python -c 'import cv2, numpy'"
FLOOR_APP = """from pathlib import Path
from typing import Annotated
import typer
app = typer.Typer(rich_markup_mode=None, pretty_exceptions_enable=False)
@app.callback()
def main(db: Annotated[str | None, typer.Option("--db")] = None,
         station_config: Annotated[Path | None, typer.Option("--station-config")] = None,
         json_output: Annotated[bool, typer.Option("--json")] = False) -> None:
    pass
@app.command()
def history(serial: str) -> None:
    print(serial)
app()
"""


def commands(db: str, artifact: Path, floor_app: Path) -> dict[str, list[str]]:
    calibctl = ["-m", "calibctl", "--db", db]
    return {
        "python -c pass": ["-c", "pass"],
        "python -c 'import numpy'": ["-c", "import numpy"],
        "python -c 'import cv2'": ["-c", "import cv2"],
        REFERENCE: ["-c", "import cv2, numpy"],
        "floor: bare typer app, 1 command": [str(floor_app), "history", SERIAL],
        "python -c 'import typer, pydantic, rich.console, rich.table'": [
            "-c",
            "import typer.main, pydantic.main, rich.console, rich.table",
        ],
        "python -c '... and calibctl.artifacts.calibration'": [  # the models history/show/export validate
            "-c",
            "import typer.main, pydantic.main, rich.console, rich.table, calibctl.artifacts.calibration",
        ],
        "calibctl --help": [*calibctl, "--help"],
        "calibctl --version": [*calibctl, "--version"],
        "calibctl board list": [*calibctl, "board", "list"],
        "calibctl history SERIAL": [*calibctl, "history", SERIAL],
        "calibctl show SERIAL": [*calibctl, "show", SERIAL],
        "calibctl export SERIAL": [*calibctl, "export", SERIAL],
        "calibctl lint FILE": [*calibctl, "lint", str(artifact)],
        "calibctl db current": [*calibctl, "db", "current"],
    }


def demo_store(folder: Path, checkout: Path) -> tuple[str, Path]:
    """(db URL, an exported artifact file) of ``calibctl demo`` run by ``checkout``'s code in ``folder``."""
    folder.mkdir(parents=True)
    db = f"sqlite:///{folder / 'demo-out/calibctl-demo.db'}"
    subprocess.run(
        [sys.executable, "-m", "calibctl", "demo"],
        cwd=folder,
        env=_env(checkout),
        check=True,
        stdout=subprocess.DEVNULL,
    )
    artifact = folder / "artifact.json"
    artifact.write_bytes(
        subprocess.run(
            [sys.executable, "-m", "calibctl", "--db", db, "export", SERIAL],
            cwd=folder,
            env=_env(checkout),
            capture_output=True,
            check=True,
        ).stdout
    )
    return db, artifact


def _env(checkout: Path) -> dict[str, str]:
    env = {
        k: v
        for k, v in os.environ.items()
        if not k.startswith("CALIBCTL_") and k != "PYTHONDONTWRITEBYTECODE"
    }
    env["PYTHONPATH"] = str(checkout)
    env["PYTHONPYCACHEPREFIX"] = str(PYCACHE / checkout.name)
    return env


def run_times(
    args: list[str],
    checkout: Path,
    repeats: int,
    cwd: Path,
    setup: Callable[[], None] | None = None,
    warm_up: bool = True,
) -> tuple[list[float], list[float]]:
    """Wall and CPU (user + system) seconds of each run (after one untimed run when ``warm_up``). On a
    loaded machine the CPU time is the steadier figure: it does not count the time spent waiting for a
    core."""
    wall, cpu = [], []
    for i in range(repeats + warm_up):
        if setup:
            setup()
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        t0 = time.perf_counter()
        done = subprocess.run(
            [sys.executable, *args],
            cwd=cwd,
            env=_env(checkout),
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            check=False,
        )
        t1 = time.perf_counter()
        if done.returncode not in (0, 1):  # 2: it could not do its job, and timing an error means nothing
            raise SystemExit(
                f"{' '.join(args[:6])} ({checkout}) exited {done.returncode}:\n"
                f"{done.stderr.decode(errors='replace')[-1500:]}"
            )
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        if i or not warm_up:  # the first run only warms the file cache
            wall.append(t1 - t0)
            cpu.append(after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime)
    return wall, cpu


def import_profile(args: list[str], checkout: Path, cwd: Path) -> dict[str, float]:
    """Self time of every imported module, summed per top-level package (ms)."""
    done = subprocess.run(
        [sys.executable, "-X", "importtime", *args],
        cwd=cwd,
        env=_env(checkout),
        capture_output=True,
        text=True,
        check=False,
    )
    per_package: dict[str, float] = defaultdict(float)
    for line in done.stderr.splitlines():
        if not line.startswith("import time:") or "self [us]" in line:
            continue
        self_us, _cumulative, name = line.removeprefix("import time:").split("|")
        per_package[name.strip().split(".")[0]] += int(self_us) / 1000
    return dict(per_package)


# What `calibctl calibrate` must import whatever its own code does: OpenCV and numpy (as the plain script),
# the store (sqlalchemy's ORM), the artifact contract (pydantic), the CLI (typer) and its output (rich).
STACK_IMPORTS = "import cv2, numpy, sqlalchemy.orm, pydantic, typer, rich"

CALIBRATE_STAGES = (  # (function, label): cumulative CPU of one profiled `calibctl calibrate`
    ("calibctl/__main__.py:1(<module>)", "whole process after interpreter start"),
    ("calibctl/cli/main.py:1(<module>)", "import of the CLI (typer, rich, command modules)"),
    (
        "calibctl/workflows/camera/capture.py:1(<module>)",
        "import of the workflows (cv2, numpy, sqlalchemy, pydantic models)",
    ),
    ("calibctl/core/capture/image_outcomes.py", "detection (read, hash, detect, blur; 2 threads)"),
    ("calibctl/store/images.py", "image files + rows (fsync each)"),
    ("calibctl/core/capture/gates.py", "capture gates (tilt, coverage)"),
    ("calibctl/core/intrinsics/outliers.py", "solve with the corner rule (calibrateCameraExtended, sigma)"),
    ("calibctl/core/intrinsics/validation.py", "held-out k-fold validation (5 folds on 2 threads)"),
    ("calibctl/core/capture/camera_split.py", "one-camera check (two-camera split, its folds)"),
    ("calibctl/workflows/lint/lint.py", "lint"),
    ("calibctl/store/repository.py", "store open, reads, session and artifact writes"),
)

PROFILE_CODE = """
import cProfile, pstats, runpy, sys, time
sys.argv = ["calibctl", *sys.argv[2:]]
profile = cProfile.Profile(time.process_time)
profile.enable()
try:
    runpy.run_module("calibctl", run_name="__main__")
except SystemExit:
    pass
profile.disable()
profile.dump_stats(__import__("os").environ["PROFILE_OUT"])
"""


def _stage_cpu(stats_path: Path) -> dict[str, float]:
    """Largest cumulative CPU seconds of a function matching each CALIBRATE_STAGES key (its outermost
    call)."""
    import pstats

    stats = pstats.Stats(str(stats_path)).stats  # type: ignore[attr-defined]
    out: dict[str, float] = {}
    for key, label in CALIBRATE_STAGES:
        file_part, _, fn_part = key.partition(":")
        best = 0.0
        for (filename, line, name), (_cc, _nc, _tt, ct, _callers) in stats.items():
            if not filename.endswith(file_part):
                continue
            if f"{line}({name})" != fn_part if fn_part else name == "<module>":
                continue  # a stage named by its file alone is its functions, not its import
            best = max(best, ct)
        out[label] = best
    return out


def calibrate_section(work: Path, repeats: int, checkouts: dict[str, Path]) -> None:
    """``calibctl calibrate`` of 20 rendered 1280x960 images against the plain OpenCV script, same run."""
    images = work / "synth-1280"
    subprocess.run(
        [
            sys.executable,
            "-m",
            "calibctl",
            "synth",
            str(images),
            "--scenario",
            "good",
            "--views",
            "20",
            "--size",
            "1280x960",
            "--seed",
            "1",
        ],
        cwd=work,
        env=_env(REPO),
        check=True,
        stdout=subprocess.DEVNULL,
    )
    db = work / "calibrate.db"
    templates = {}  # one per checkout: an older calibctl refuses a store a newer one migrated
    for i, (name, checkout) in enumerate(checkouts.items()):
        templates[name] = work / f"calibrate-template-{i}.db"
        subprocess.run(
            [
                sys.executable,
                "-m",
                "calibctl",
                "--db",
                f"sqlite:///{templates[name]}",
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
                "2026-11-23",
            ],
            cwd=work,
            env=_env(checkout),
            check=True,
            stdout=subprocess.DEVNULL,
        )

    def fresh(name: str = "this checkout") -> Callable[[], None]:
        def setup() -> None:
            shutil.rmtree(work / "calibctl-images", ignore_errors=True)
            shutil.copyfile(templates[name], db)

        return setup

    calibrate = [
        "-m",
        "calibctl",
        "--db",
        f"sqlite:///{db}",
        "calibrate",
        "--serial",
        "BENCH-0001",
        "--board",
        "BENCH",
        "--source",
        str(images),
        "--station",
        "bench",
        "--operator",
        "bench",
    ]
    plain = [str(REPO / "benchmarks/bench_e2e.py"), "--plain-only", str(images), "--square", "0.025"]
    print("## `calibctl calibrate` of 20 images at 1280x960 against the plain OpenCV script\n")
    print(f"Load average before: {_load()}\n")
    print("| path | wall best / median ms | CPU best / median ms |\n|---|---|---|")
    runs = [
        ("plain OpenCV script, own process", plain, None, REPO),
        (f"imports alone: `python -c '{STACK_IMPORTS}'`", ["-c", STACK_IMPORTS], None, REPO),
    ]
    for name, checkout in checkouts.items():
        runs += [
            (f"`calibctl calibrate`, own process ({name})", calibrate, fresh(name), checkout),
            (
                f"`calibctl --version` ({name}: start-up with cv2 and numpy)",
                ["-m", "calibctl", "--version"],
                None,
                checkout,
            ),
        ]
    rows = {}
    for label, args, setup, checkout in runs:
        wall, cpu = run_times(args, checkout, repeats, work, setup)
        rows[label] = (min(wall), min(cpu))
        print(
            f"| {label} | {min(wall) * 1000:.0f} / {statistics.median(wall) * 1000:.0f} | "
            f"{min(cpu) * 1000:.0f} / {statistics.median(cpu) * 1000:.0f} |"
        )
    pw, pc = rows[runs[0][0]]
    sw, _ = rows[runs[1][0]]
    print(
        "\n- the imports calibrate cannot do without (the design fixes sqlalchemy, pydantic, typer and "
        "rich) take "
        f"**{sw / pw:.2f}x** the plain script's whole wall time, before calibctl's own code runs"
    )
    for name in checkouts:
        cw, cc = rows[f"`calibctl calibrate`, own process ({name})"]
        print(f"- calibctl ({name}) / plain: **{cw / pw:.2f}x wall, {cc / pc:.2f}x CPU** (best of each)")
    print(f"\nLoad average after: {_load()}\n")
    fresh()()
    out = work / "calibrate.prof"
    subprocess.run(
        [sys.executable, "-c", PROFILE_CODE, "-", *calibrate[2:]],
        cwd=work,
        env={**_env(REPO), "PROFILE_OUT": str(out)},
        check=False,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    print(
        "Where one `calibctl calibrate` spends its CPU (cProfile with a CPU-time clock, cumulative, largest "
        "call of the stage's functions; the profiler inflates Python-heavy stages such as imports):\n"
    )
    print("| stage | CPU ms |\n|---|---|")
    for label, seconds in _stage_cpu(out).items():
        print(f"| {label} | {seconds * 1000:.0f} |")
    print()


def _load() -> str:
    return ", ".join(f"{v:.2f}" for v in os.getloadavg())


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--before", type=Path, help="another calibctl checkout to time in the same run")
    parser.add_argument(
        "--calibrate", action="store_true", help="also time `calibctl calibrate` against the plain script"
    )
    opts = parser.parse_args()
    work = Path(tempfile.mkdtemp(prefix="calibctl-startup-"))
    floor_app = work / "floor_app.py"
    floor_app.write_text(FLOOR_APP)
    checkouts = {"this checkout": REPO, **({"before": opts.before.resolve()} if opts.before else {})}
    # each checkout reads a store its own code made: an older calibctl refuses one a newer one migrated
    per_checkout = {
        name: commands(*demo_store(work / f"store-{i}", checkout), floor_app)
        for i, (name, checkout) in enumerate(checkouts.items())
    }
    print(f"# calibctl start-up per command ({dt.datetime.now(dt.UTC):%Y-%m-%d %H:%M} UTC)\n")
    print(
        f"{cpu_model()}, {os.cpu_count()} CPUs, Python {platform.python_version()}; "
        f"best / median of {opts.repeats} runs after a warm-up, ms.\n"
    )
    print(f"Load average before: {_load()}\n")
    print("| command | " + " | ".join(f"{c}: wall | {c}: CPU | {c}: x cv2+numpy" for c in checkouts) + " |")
    print("|---|" + "---|" * 3 * len(checkouts))
    reference = 0.0
    for label in per_checkout["this checkout"]:
        cells = []
        runs = checkouts if label.startswith("calibctl") else dict(list(checkouts.items())[:1])
        times = {name: ([], []) for name in runs}
        for i in range(opts.repeats):  # the checkouts in turn, so a change in the machine's load hits both
            for name, checkout in runs.items():
                wall, cpu = run_times(per_checkout[name][label], checkout, 1, work, warm_up=i == 0)
                times[name][0].extend(wall)
                times[name][1].extend(cpu)
        for wall, cpu in times.values():
            reference = min(wall) if label == REFERENCE else reference
            cells += [
                f"{min(wall) * 1000:.0f} / {statistics.median(wall) * 1000:.0f}",
                f"{min(cpu) * 1000:.0f} / {statistics.median(cpu) * 1000:.0f}",
                f"{min(wall) / reference:.2f}" if reference else "-",
            ]
            if not label.startswith("calibctl"):
                cells = cells * len(checkouts)  # no calibctl involved: one measurement
                break
        print(f"| `{label}` | " + " | ".join(cells) + " |")
    print(f"\nLoad average after: {_load()}\n")
    print("## Import self time per top-level package (ms, one `python -X importtime` run, this checkout)\n")
    profiles = {
        label: import_profile(args, REPO, work)
        for label, args in per_checkout["this checkout"].items()
        if label.startswith("calibctl")
    }
    peak: dict[str, float] = defaultdict(float)
    for prof in profiles.values():
        for package, ms in prof.items():
            peak[package] = max(peak[package], ms)
    top = sorted(peak, key=peak.__getitem__, reverse=True)[:9]  # the packages that cost most somewhere
    print("| command | total | " + " | ".join(top) + " | other |")
    print("|---|---|" + "---|" * (len(top) + 1))
    for label, prof in profiles.items():
        cells = [f"{prof.get(p, 0):.0f}" for p in top]
        other = sum(ms for p, ms in prof.items() if p not in top)
        print(f"| `{label}` | {sum(prof.values()):.0f} | " + " | ".join(cells) + f" | {other:.0f} |")
    if opts.calibrate:
        print()
        calibrate_section(work, opts.repeats, checkouts)
    return 0


if __name__ == "__main__":
    sys.exit(main())
