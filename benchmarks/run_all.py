"""Run every benchmark in sequence and collect its output in benchmarks/out/ (``make bench`` runs this).

    .venv/bin/python benchmarks/run_all.py [--quick] [--only NAME ...] [--list]

Each benchmark runs as its own process (``sys.executable``; bench_e2e.py itself calls mrcal through
/usr/bin/python3), one after the other so they do not compete for the 2 cores. Its stdout goes to
``benchmarks/out/<name>.md`` (plain-text output is wrapped in a code block); a summary with the wall
time, the exit code and the load average before each run is printed and written to
``benchmarks/out/SUMMARY.md``. The numbers are copied into BENCHMARKS.md by hand, with the machine and
the date they were measured on.

Full run: about 4 minutes (221 s on 2026-11-22) on the 2-core shared machine. ``--quick`` (about 1-2 min) uses
each script's short mode: fewer repeats, fewer sessions/trials/rows.
"""

from __future__ import annotations

import argparse
import datetime as dt
import os
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

HERE = Path(__file__).resolve().parent
OUT = HERE / "out"


@dataclass(frozen=True)
class Bench:
    name: str
    script: str
    args: tuple[str, ...]
    quick_args: tuple[str, ...]
    markdown: bool = True  # False: plain-text output, fenced in the .md file


BENCHES = (
    Bench("bench_detect", "bench_detect.py", ("--repeats", "3"), ("--repeats", "1")),
    Bench("bench_uncertainty_30", "bench_uncertainty.py", ("30",), ("30",)),
    Bench("bench_uncertainty_100", "bench_uncertainty.py", ("100",), ("100",)),
    Bench("bench_sigma_fx_tied", "bench_sigma_fx_tied.py", ("400",), ("100",)),
    Bench(
        "bench_triage", "bench_triage.py", ("--repeats", "3"), ("--repeats", "1", "--rows", "200000"), False
    ),
    Bench("bench_triage_accuracy", "bench_triage.py", ("--accuracy", "20"), ("--accuracy", "5"), False),
    Bench("bench_e2e", "bench_e2e.py", ("--repeats", "3"), ("--quick",)),
    Bench(
        "bench_handeye",
        "bench_handeye.py",
        ("--seeds", "50", "--scenes", "5"),
        ("--seeds", "10", "--scenes", "2", "--repeats", "5"),
    ),
    Bench("bench_rig", "bench_rig.py", ("--repeats", "2"), ("--repeats", "1")),
    Bench("bench_rig_caliscope", "bench_rig_caliscope.py", (), ("--runs", "5:k1k2")),
    Bench("bench_rig_caliscope_residual", "bench_rig_caliscope_residual.py", (), ()),
    Bench(
        "bench_tilt",
        "bench_tilt.py",
        ("--sessions", "20", "--render", "5"),
        ("--sessions", "5", "--render", "0"),
    ),
    Bench(
        "bench_outliers", "bench_outliers.py", ("--sessions", "30"), ("--sessions", "5", "--sizes", "640x480")
    ),
    Bench("bench_startup", "bench_startup.py", ("--repeats", "7"), ("--repeats", "2")),
    Bench("bench_import_overlap", "bench_import_overlap.py", ("--repeats", "5"), ("--repeats", "1")),
    Bench("bench_store_scale", "bench_store_scale.py", (), ()),
    Bench("bench_report", "bench_report.py", ("--repeats", "5"), ("--repeats", "2")),
    Bench("bench_fisheye", "bench_fisheye.py", ("30",), ("6",)),
    Bench("bench_model_misfit", "bench_model_misfit.py", (), ()),
    Bench("bench_verdicts", "bench_verdicts.py", (), ()),
    Bench(
        "bench_rig_sigma",
        "bench_rig_sigma.py",
        ("--resamples", "100", "--seeds", "30"),
        ("--resamples", "10", "--seeds", "5"),
    ),
    Bench("bench_check", "bench_check.py", ("--sessions", "200"), ("--sessions", "20", "--refs", "2")),
    Bench("bench_lm", "bench_lm.py", ("--repeats", "5"), ("--fisheye", "2", "--repeats", "1")),
    Bench("bench_lidar", "bench_lidar.py", ("--repeats", "3"), ("--repeats", "1")),
    Bench("bench_lut", "bench_lut.py", ("--repeats", "100"), ("--repeats", "10")),
    Bench("bench_stream", "bench_stream.py", ("--repeats", "3"), ("--repeats", "1", "--size", "640x480")),
    Bench(
        "bench_fleet_health",
        "bench_fleet_health.py",
        ("--robots", "25", "--days", "365"),
        ("--robots", "5", "--days", "90"),
    ),
    Bench(
        "bench_fleet_checkpoint",
        "bench_fleet_checkpoint.py",
        (),
        ("--robots", "50", "--sizes", "2500", "6000"),
    ),
)


def load_average() -> str:
    return " ".join(f"{v:.2f}" for v in os.getloadavg())


def run_one(bench: Bench, quick: bool) -> tuple[int, float, str]:
    """Run one benchmark; returns (exit code, wall seconds, load average before it)."""
    args = list(bench.quick_args if quick else bench.args)
    if bench.script in ("bench_detect.py", "bench_e2e.py"):  # these also write their report themselves
        args += ["--out", str(OUT / f"{bench.name}.md")]
    load = load_average()
    start = time.perf_counter()
    done = subprocess.run(
        [sys.executable, str(HERE / bench.script), *args], capture_output=True, text=True, cwd=HERE.parent
    )
    elapsed = time.perf_counter() - start
    body = done.stdout if bench.markdown else f"```text\n{done.stdout}```\n"
    header = (
        f"<!-- {bench.script} {' '.join(args)}; "
        f"{dt.datetime.now().astimezone().isoformat(timespec='seconds')};"
        f" {elapsed:.1f} s; load average before: {load} -->\n\n"
    )
    if done.returncode != 0:
        body += f"\n**exit code {done.returncode}**\n\n```text\n{done.stderr[-4000:]}```\n"
    (OUT / f"{bench.name}.md").write_text(header + body, encoding="utf-8")
    return done.returncode, elapsed, load


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="each script's short mode")
    parser.add_argument("--only", nargs="+", metavar="NAME", help="run only these (names as in --list)")
    parser.add_argument("--list", action="store_true", help="list the benchmarks and exit")
    args = parser.parse_args()
    if args.list:
        for b in BENCHES:
            print(f"{b.name:<24} {b.script} {' '.join(b.args)}   (quick: {' '.join(b.quick_args)})")
        return 0
    chosen = [b for b in BENCHES if not args.only or b.name in args.only]
    unknown = set(args.only or ()) - {b.name for b in BENCHES}
    if unknown:
        print(f"unknown benchmark(s): {', '.join(sorted(unknown))}; see --list", file=sys.stderr)
        return 2
    OUT.mkdir(parents=True, exist_ok=True)
    rows = []
    t0 = time.perf_counter()
    for bench in chosen:
        print(f"running {bench.name} ...", file=sys.stderr, flush=True)
        code, elapsed, load = run_one(bench, args.quick)
        rows.append(
            f"| {bench.name} | {'ok' if code == 0 else f'FAILED ({code})'} | {elapsed:.1f} | {load} | "
            f"benchmarks/out/{bench.name}.md |"
        )
    summary = (
        "\n".join(
            [
                f"## Benchmark run {dt.datetime.now().astimezone().isoformat(timespec='seconds')}"
                f"{' (--quick)' if args.quick else ''}",
                "",
                f"nproc {len(os.sched_getaffinity(0))}; total {time.perf_counter() - t0:.0f} s; "
                f"load average now {load_average()}",
                "",
                "| benchmark | status | wall s | load average before (1/5/15 min) | output |",
                "|---|---|---|---|---|",
                *rows,
            ]
        )
        + "\n"
    )
    (OUT / "SUMMARY.md").write_text(summary, encoding="utf-8")
    print(summary)
    return 0 if all("| ok |" in r for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
