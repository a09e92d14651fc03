"""`calibctl check` false-fail rate on an UNCHANGED camera against the number of fresh views, on real photos.

Each camera of opencv-left-right (13 left, 13 right photos of a 9x6 board) is calibrated with
`calibctl calibrate` on all its photos, then checked against random subsets of k of those same photos
(seeded), through the CLI. Any FAIL is a false fail: the camera did not change. The check's view
minimum (core.check.recheck.MIN_CHECK_VIEWS) is lowered to 1 here so the statistics themselves are
measured; `calibctl check` refuses below the minimum ("cannot judge", exit 2).

Limits: 13 photos per camera, so subsets of 9-12 views overlap heavily; the rates there are indicative.

Run: python benchmarks/bench_check_few_views.py [--trials 12] [--views 1,3,5,10]
"""

from __future__ import annotations

import argparse
import random
import sys
import tempfile
from pathlib import Path

from typer.testing import CliRunner

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from calibctl.cli.main import app  # noqa: E402
from calibctl.core.check import recheck  # noqa: E402
from calibctl.store.repository import Store  # noqa: E402
from calibctl.workflows.camera import check as check_workflow  # noqa: E402
from tests.artifacts.factories import measured_board  # noqa: E402
from tests.datasets import LEFT_RIGHT  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=12)
    parser.add_argument("--views", default="1,3,5,10")
    args = parser.parse_args()
    check_workflow.MIN_CHECK_VIEWS = 1  # type: ignore[misc] - measure the statistics, not the refusal
    runner = CliRunner()
    root = Path(tempfile.mkdtemp())
    url = f"sqlite:///{root / 'c.db'}"
    with Store.open(url) as store:
        store.add_board(measured_board("LR", square_mm=25.0))
    print(f"minimum in calibctl: {recheck.MIN_CHECK_VIEWS} views; {args.trials} subsets per k per camera")
    for cam in ("left", "right"):
        done = runner.invoke(
            app,
            [
                "--db",
                url,
                "calibrate",
                "--serial",
                cam.upper(),
                "--board",
                "LR",
                "--source",
                f"{LEFT_RIGHT}/{cam}*.jpg",
            ],
        )
        assert done.exit_code == 0, done.output  # noqa: S101
        photos = sorted(LEFT_RIGHT.glob(f"{cam}*.jpg"))
        rng = random.Random(0)
        for k in (int(v) for v in args.views.split(",")):
            fails = 0
            for trial in range(args.trials):
                listed = root / f"{cam}{k}_{trial}.txt"
                listed.write_text("".join(f"{p}\n" for p in rng.sample(photos, k)))
                result = runner.invoke(app, ["--db", url, "check", cam.upper(), "--source", str(listed)])
                fails += result.exit_code == 1
            print(
                f"{cam:5s} {k:2d} views: {fails} of {args.trials} checks FAIL an unchanged camera", flush=True
            )


if __name__ == "__main__":
    main()
