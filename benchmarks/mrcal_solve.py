"""mrcal side of benchmarks/bench_e2e.py. Runs under the SYSTEM python (/usr/bin/python3, Debian
python3-mrcal).

calibctl's venv has no mrcal, so bench_e2e.py calls this file as a subprocess:

    /usr/bin/python3 benchmarks/mrcal_solve.py version
        -> {"mrcal": "2.2-4+b1 (Debian python3-mrcal)", "python": "...", "numpy": "..."}
    /usr/bin/python3 benchmarks/mrcal_solve.py evaluate CAMERA.cameramodel
        -> {"lensmodel", "fx", "fy", "cx", "cy", "distortion", "rms_px", "n_inliers",
            "n_outliers", "calobject_warp"}
    /usr/bin/python3 benchmarks/mrcal_solve.py time REPEATS -- MRCAL-CALIBRATE-CAMERAS-ARGS...
        -> {"warmup_s": first run, "times_s": [wall s of the REPEATS runs after it], "cpu_s": [their CPU s]}

``time`` runs the unmodified /usr/bin/mrcal-calibrate-cameras script in this process (runpy, with
sys.argv set, its stdout/stderr discarded) once as a warm-up and then REPEATS times: the solve
without the Python start-up and the ``import mrcal`` that the CLI wall time includes.

``rms_px`` is sqrt(mean over inlier corners of |residual|^2), the same definition as
OpenCV's calibrateCamera RMS (mrcal's own "RMS reprojection error" divides by the number of x and y
measurements, i.e. it is this value / sqrt(2)). mrcal drops outliers by default, so its RMS is over
inliers only; ``n_outliers`` says how many corners it dropped.
"""

from __future__ import annotations

import contextlib
import io
import json
import platform
import runpy
import subprocess
import sys
import time

import mrcal
import numpy as np

MRCAL_TOOL = "/usr/bin/mrcal-calibrate-cameras"


def evaluate(path: str) -> dict:
    model = mrcal.cameramodel(path)
    lensmodel, intrinsics = model.intrinsics()
    inputs = model.optimization_inputs()
    x = mrcal.optimizer_callback(**inputs)[1]
    residuals = mrcal.residuals_chessboard(inputs, residuals=x).reshape(-1, 2)  # inliers only
    n_total = int(np.prod(inputs["observations_board"].shape[:-1]))
    warp = inputs.get("calobject_warp")
    return {
        "lensmodel": lensmodel,
        "fx": float(intrinsics[0]),
        "fy": float(intrinsics[1]),
        "cx": float(intrinsics[2]),
        "cy": float(intrinsics[3]),
        "distortion": [float(v) for v in intrinsics[4:]],
        "rms_px": float(np.sqrt(np.mean(np.sum(residuals**2, axis=1)))),
        "n_inliers": int(residuals.shape[0]),
        "n_outliers": n_total - int(residuals.shape[0]),
        "calobject_warp": None if warp is None else [float(v) for v in warp],
    }


def run_tool_once(args: list[str]) -> tuple[float, float]:
    """(wall s, CPU s) of one run of the tool script in this process."""
    saved = sys.argv
    sys.argv = [MRCAL_TOOL, *args]
    start, cpu_start = time.perf_counter(), time.process_time()
    try:
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
            runpy.run_path(MRCAL_TOOL, run_name="__main__")
    except SystemExit as exc:
        if exc.code not in (None, 0):
            raise RuntimeError(f"mrcal-calibrate-cameras exited with {exc.code}") from exc
    finally:
        sys.argv = saved
    return time.perf_counter() - start, time.process_time() - cpu_start


def main() -> int:
    if len(sys.argv) < 2:
        print(__doc__, file=sys.stderr)
        return 2
    command = sys.argv[1]
    if command == "version":
        package = subprocess.run(
            ["dpkg-query", "-W", "-f=${Version}", "python3-mrcal"], capture_output=True, text=True
        ).stdout.strip()
        print(
            json.dumps(
                {
                    "mrcal": getattr(mrcal, "__version__", None)
                    or f"{package or '?'} (Debian python3-mrcal)",
                    "python": platform.python_version(),
                    "numpy": np.__version__,
                }
            )
        )
    elif command == "evaluate":
        print(json.dumps(evaluate(sys.argv[2])))
    elif command == "time":
        repeats = int(sys.argv[2])
        args = sys.argv[sys.argv.index("--") + 1 :]
        warmup, _ = run_tool_once(args)
        runs = [run_tool_once(args) for _ in range(repeats)]
        print(
            json.dumps({"warmup_s": warmup, "times_s": [w for w, _ in runs], "cpu_s": [c for _, c in runs]})
        )
    else:
        print(f"unknown command {command!r}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
