"""Benchmark: `calibctl triage` on one million residual rows. Not a test; prints numbers.

    .venv/bin/python benchmarks/bench_triage.py [--rows 1000000] [--repeats 3] [--keep DIR]
    .venv/bin/python benchmarks/bench_triage.py --accuracy 20     # recovered magnitudes, 20 seeds/fault

Generates a seeded buffer with the fault injector (time offset 18.4 ms in cam0, two cameras, 80
features per keyframe), writes it as CSV, then times three stages separately, best and median of
``--repeats`` runs:

    read      CSV -> validated numpy columns (calibctl.workflows.diagnostics.diagnostics_io.read_table)
    triage    per-camera keyframe aggregation + joint and per-covariate fits (pure core)
    end2end   calibctl.workflows.diagnostics.diagnostics.run_triage (read + validate + triage + JSON dict)

and prints rows/s, the machine (nproc, CPU model from /proc/cpuinfo), the date and the versions, so
the numbers can go into BENCHMARKS.md as printed.
"""

from __future__ import annotations

import argparse
import datetime as dt
import os
import platform
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np
from machine import cpu_model  # benchmarks/machine.py (scripts run from benchmarks/)

from calibctl.core.diagnostics.faults import DEFAULT_MAGNITUDE, synth_residual_buffer
from calibctl.core.diagnostics.triage import triage_by_camera
from calibctl.workflows.diagnostics.diagnostics import RESIDUAL_COLUMNS, run_triage
from calibctl.workflows.diagnostics.diagnostics_io import read_table, write_table

FEATURES_PER_KEYFRAME = 80
CAMERAS = 2


def timed(fn, repeats: int) -> tuple[float, float, object]:
    times, result = [], None
    for _ in range(repeats):
        start = time.perf_counter()
        result = fn()
        times.append(time.perf_counter() - start)
    return min(times), statistics.median(times), result


ACCURACY_CHANNEL = {
    "focal": "focal",
    "k1": "k1",
    "principal-point": "rotation_or_principal_point",
    "rotation": "rotation_or_principal_point",
    "translation": "lever_arm",
    "time-offset": "time_offset",
    "rolling-shutter": "line_delay",
    "gauge": None,
}


def accuracy(n_seeds: int) -> None:
    """Inject each fault at the seed's magnitude (noise 0.3 px, default bench) and tabulate what comes
    back."""
    print(
        f"triage accuracy - default bench (500 keyframes x 80 features, noise 0.3 px), seeds 0..{n_seeds - 1}"
    )
    print(
        f"{'fault':<16} {'injected':>12} {'mean recovered':>15} {'worst err %':>12} {'named alone':>12}  "
        "verdict (seed 0)"
    )
    for fault, key in ACCURACY_CHANNEL.items():
        mag = DEFAULT_MAGNITUDE[fault]
        got, alone, verdict = [], 0, ""
        for seed in range(n_seeds):
            b = synth_residual_buffer(fault, mag, noise_px=0.3, seed=seed)
            cam = triage_by_camera(
                b["residual_px"],
                b["radius_px"],
                b["image_speed_px_s"],
                b["inv_range_per_m"],
                b["row"],
                keyframe=b["keyframe"],
            ).cameras[0]
            named = [c.spec.key for c in cam.faults]
            alone += named == ([key] if key else [])
            verdict = verdict or cam.verdict
            if key:
                ch = next(c for c in cam.channels if c.spec.key == key)
                got.append(ch.coef if fault == "principal-point" else ch.value)
        if key:
            err = max(abs(g - mag) / mag for g in got) * 100
            print(
                f"{fault:<16} {mag:>12.6g} {statistics.mean(got):>15.6g} {err:>12.2f} {alone:>7}/{n_seeds} "
                f" {verdict[:70]}"
            )
        else:
            print(f"{fault:<16} {mag:>12.6g} {'-':>15} {'-':>12} {alone:>7}/{n_seeds}  {verdict[:70]}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rows", type=int, default=1_000_000)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument(
        "--keep", type=Path, default=None, help="write the CSV here instead of a temporary directory"
    )
    ap.add_argument(
        "--accuracy", type=int, default=0, metavar="SEEDS", help="print the recovered-magnitude table"
    )
    args = ap.parse_args()
    if args.accuracy:
        accuracy(args.accuracy)
        return

    keyframes = max(12, args.rows // (FEATURES_PER_KEYFRAME * CAMERAS))
    buf = synth_residual_buffer(
        "time-offset",
        0.0184,
        noise_px=0.3,
        seed=2026,
        n_keyframes=keyframes,
        features_per_keyframe=FEATURES_PER_KEYFRAME,
        n_cameras=CAMERAS,
    )
    n_rows = int(buf["residual_px"].size)
    workdir = args.keep or Path(tempfile.mkdtemp(prefix="bench_triage_"))
    workdir.mkdir(parents=True, exist_ok=True)
    csv_path = workdir / "residuals_1m.csv"
    t0 = time.perf_counter()
    write_table(csv_path, buf, force=True)
    write_s = time.perf_counter() - t0

    def read():
        return read_table(
            csv_path, RESIDUAL_COLUMNS, ("temperature_c",), ("camera",), optional_labels=("keyframe",)
        )

    table = read()
    cols = [table.numeric[c] for c in RESIDUAL_COLUMNS]
    keyframe = table.labels["keyframe"]

    def triage():
        return triage_by_camera(*cols, camera=table.text["camera"], keyframe=keyframe)

    stages = {
        "read": timed(read, args.repeats),
        "triage": timed(triage, args.repeats),
        "end2end": timed(lambda: run_triage(csv_path), args.repeats),
    }
    summary = stages["triage"][2]
    td = next(c for c in summary.cameras[0].channels if c.spec.key == "time_offset")

    print(f"calibctl triage benchmark - {dt.datetime.now().astimezone().isoformat(timespec='seconds')}")
    print(f"machine: {os.cpu_count()} CPUs (nproc {len(os.sched_getaffinity(0))}), {cpu_model()}")
    print(
        f"python {platform.python_version()}, numpy {np.__version__}, {platform.system()} "
        f"{platform.release()}"
    )
    print(
        f"input: {n_rows} rows, {CAMERAS} cameras x {keyframes} keyframes x {FEATURES_PER_KEYFRAME} "
        "features, "
        f"{csv_path.stat().st_size / 1e6:.1f} MB CSV (written in {write_s:.2f} s)"
    )
    print(f"{'stage':<9} {'best s':>8} {'median s':>9} {'rows/s (best)':>15}")
    for name, (best, med, _) in stages.items():
        print(f"{name:<9} {best:8.3f} {med:9.3f} {n_rows / best:15,.0f}")
    print(
        f"check: cam0 td = {td.value * 1e3:.3f} ms (injected 18.400), t = {td.t:.0f}; "
        f"cam0 verdict: {summary.cameras[0].verdict}"
    )
    if args.keep is None:
        csv_path.unlink()
        workdir.rmdir()


if __name__ == "__main__":
    main()
