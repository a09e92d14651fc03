"""Start-up of each read command in a fresh process, against `python -c 'import cv2'`.

    .venv/bin/python benchmarks/bench_startup.py [--repeats 7] [--before DIR]

Each command runs ``--repeats`` times (after one warm-up, so the OS file cache is warm) in a new
interpreter against a small SQLite store holding one board and one calibration (``calibctl demo``);
best and median wall and CPU time are reported. ``--before DIR`` also times the calibctl checkout in DIR
(e.g. a worktree of main) in the same run, so before/after share the machine's load. Then
``python -X importtime`` of each command is summed per top-level package (self time), which says
where the rest of the time goes. Nothing is asserted; the machine is shared, so the load average is
printed before each table.
"""

from __future__ import annotations

import argparse
import datetime as dt
import os
import platform
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path

from machine import cpu_model

REPO = Path(__file__).resolve().parents[1]
SERIAL = "DEMO-CAM-0001"


def commands(db: str, artifact: Path) -> dict[str, list[str]]:
    calibctl = ["-m", "calibctl", "--db", db]
    return {
        "python -c pass": ["-c", "pass"],
        "python -c 'import numpy'": ["-c", "import numpy"],
        "python -c 'import cv2'": ["-c", "import cv2"],
        "calibctl --help": [*calibctl, "--help"],
        "calibctl --version": [*calibctl, "--version"],
        "calibctl board list": [*calibctl, "board", "list"],
        "calibctl history SERIAL": [*calibctl, "history", SERIAL],
        "calibctl show SERIAL": [*calibctl, "show", SERIAL],
        "calibctl export SERIAL": [*calibctl, "export", SERIAL],
        "calibctl lint FILE": [*calibctl, "lint", str(artifact)],
        "calibctl db current": [*calibctl, "db", "current"],
    }


def _env(checkout: Path) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if not k.startswith("CALIBCTL_")}
    env["PYTHONPATH"] = str(checkout)
    return env


def run_times(args: list[str], checkout: Path, repeats: int, cwd: Path) -> tuple[list[float], list[float]]:
    """Wall and CPU (user + system) seconds of each run. On a loaded machine the CPU time is the
    steadier figure: it does not count the time spent waiting for a core."""
    wall, cpu = [], []
    for i in range(repeats + 1):
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        t0 = time.perf_counter()
        subprocess.run([sys.executable, *args], cwd=cwd, env=_env(checkout), stdout=subprocess.DEVNULL,
                       stderr=subprocess.DEVNULL, check=False)
        t1 = time.perf_counter()
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        if i:  # the first run only warms the file cache
            wall.append(t1 - t0)
            cpu.append(after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime)
    return wall, cpu


def import_profile(args: list[str], checkout: Path, cwd: Path) -> dict[str, float]:
    """Self time of every imported module, summed per top-level package (ms)."""
    done = subprocess.run([sys.executable, "-X", "importtime", *args], cwd=cwd, env=_env(checkout),
                          capture_output=True, text=True, check=False)
    per_package: dict[str, float] = defaultdict(float)
    for line in done.stderr.splitlines():
        if not line.startswith("import time:") or "self [us]" in line:
            continue
        self_us, _cumulative, name = line.removeprefix("import time:").split("|")
        per_package[name.strip().split(".")[0]] += int(self_us) / 1000
    return dict(per_package)


def _load() -> str:
    return ", ".join(f"{v:.2f}" for v in os.getloadavg())


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--before", type=Path, help="another calibctl checkout to time in the same run")
    opts = parser.parse_args()
    work = Path(tempfile.mkdtemp(prefix="calibctl-startup-"))
    db = f"sqlite:///{work / 'demo-out/calibctl-demo.db'}"
    subprocess.run([sys.executable, "-m", "calibctl", "demo"], cwd=work, env=_env(REPO), check=True,
                   stdout=subprocess.DEVNULL)
    artifact = work / "artifact.json"
    artifact.write_bytes(subprocess.run([sys.executable, "-m", "calibctl", "--db", db, "export", SERIAL],
                                        cwd=work, env=_env(REPO), capture_output=True, check=True).stdout)
    checkouts = {"this checkout": REPO, **({"before": opts.before.resolve()} if opts.before else {})}
    print(f"# calibctl start-up per command ({dt.datetime.now(dt.UTC):%Y-%m-%d %H:%M} UTC)\n")
    print(f"{cpu_model()}, {os.cpu_count()} CPUs, Python {platform.python_version()}; "
          f"best / median of {opts.repeats} runs after a warm-up, ms.\n")
    print(f"Load average before: {_load()}\n")
    print("| command | " + " | ".join(f"{c}: wall | {c}: CPU" for c in checkouts) + " |")
    print("|---|" + "---|" * 2 * len(checkouts))
    for label, args in commands(db, artifact).items():
        cells = []
        for checkout in checkouts.values():
            wall, cpu = run_times(args, checkout, opts.repeats, work)
            cells += [f"{min(wall) * 1000:.0f} / {statistics.median(wall) * 1000:.0f}",
                      f"{min(cpu) * 1000:.0f} / {statistics.median(cpu) * 1000:.0f}"]
            if label.startswith("python"):
                cells = cells * len(checkouts)  # no calibctl involved: one measurement
                break
        print(f"| `{label}` | " + " | ".join(cells) + " |")
    print(f"\nLoad average after: {_load()}\n")
    print("## Import self time per top-level package (ms, one `python -X importtime` run, this checkout)\n")
    profiles = {label: import_profile(args, REPO, work) for label, args in commands(db, artifact).items()
                if label.startswith("calibctl")}
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
    return 0


if __name__ == "__main__":
    sys.exit(main())
