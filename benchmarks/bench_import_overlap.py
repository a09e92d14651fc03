"""Can `calibctl calibrate` hide its store imports behind detection? One process, two orders, same images.

    .venv/bin/python benchmarks/bench_import_overlap.py [--repeats 5] [--images DIR]

``calibctl calibrate`` must import sqlalchemy's ORM, pydantic's artifact models, typer and rich besides
OpenCV and numpy (benchmarks/results/startup.md: those imports alone take about 0.8x the plain OpenCV script's
whole run). Detection needs only cv2, numpy and calibctl.core, and runs on worker threads that release
the GIL inside OpenCV, so one might hide the imports behind it. Each run here is a fresh interpreter
that imports cv2, numpy and calibctl.core, then either

* ``sequential``: detects 20 rendered 1280x960 images (``core.capture.image_outcomes.classify_files``, 2
workers)
  and then imports the store, solve and capture workflows, or
* ``overlap``: starts those imports on a thread and detects at the same time.

It prints wall time of the detection and of the whole run, and the process CPU, best and median of
``--repeats`` runs each, interleaved. Nothing is asserted.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

from machine import cpu_model

REPO = Path(__file__).resolve().parents[1]

CHILD = r"""
import json, os, sys, threading, time
t0 = time.perf_counter()
import cv2, numpy
from calibctl.core.capture import image_outcomes
from calibctl.core.board.board_spec import BoardSpec
mode, folder = sys.argv[1], sys.argv[2]
paths = sorted(os.path.join(folder, p) for p in os.listdir(folder) if p.endswith(".png"))
def store_imports():
    import calibctl.store.repository  # noqa: F401
    import calibctl.workflows.camera.capture  # noqa: F401
    import calibctl.workflows.camera.solve  # noqa: F401
importer = threading.Thread(target=store_imports) if mode == "overlap" else None
if importer:
    importer.start()
t1 = time.perf_counter()
image_outcomes.classify_files(paths, BoardSpec.chessboard(9, 6, 0.025), workers=2)
t2 = time.perf_counter()
if importer:
    importer.join()
else:
    store_imports()
t3 = time.perf_counter()
print(json.dumps({"detect_s": t2 - t1, "total_s": t3 - t0, "cpu_s": time.process_time()}))
"""


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument(
        "--images", type=Path, help="a folder of 9x6 board PNGs (default: render 20 at 1280x960)"
    )
    opts = parser.parse_args()
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    env["PYTHONPATH"] = str(REPO)
    images = opts.images
    if images is None:
        images = Path(tempfile.mkdtemp(prefix="calibctl-overlap-")) / "synth-1280"
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
            env=env,
            check=True,
            stdout=subprocess.DEVNULL,
        )
    runs: dict[str, list[dict[str, float]]] = {"sequential": [], "overlap": []}
    for i in range(opts.repeats + 1):
        for mode in runs:
            done = subprocess.run(
                [sys.executable, "-c", CHILD, mode, str(images)],
                env=env,
                capture_output=True,
                text=True,
                check=True,
            )
            if i:  # the first round warms the file cache
                runs[mode].append(json.loads(done.stdout.strip().splitlines()[-1]))
    print(
        f"{cpu_model()}, {os.cpu_count()} CPUs, load average "
        f"{', '.join(f'{v:.2f}' for v in os.getloadavg())}; "
        f"best / median of {opts.repeats}, ms\n"
    )
    print("| order | detection wall | whole run wall | process CPU |\n|---|---|---|---|")
    for mode, rows in runs.items():
        cells = []
        for key in ("detect_s", "total_s", "cpu_s"):
            values = [r[key] * 1000 for r in rows]
            cells.append(f"{min(values):.0f} / {statistics.median(values):.0f}")
        print(f"| {mode} | " + " | ".join(cells) + " |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
