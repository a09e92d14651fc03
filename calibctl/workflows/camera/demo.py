"""``calibctl demo``: the main job end to end, with no camera and no arguments.

It renders two synthetic sessions through a known camera (a good board set, and a flat one the
gates must reject), registers a board with a measured square size, captures both, solves the good
one, lints it, shows the history, exports ROS camera_info YAML and compares the result with the
truth the renderer used. Everything lives in ``demo-out/`` (its own SQLite store included), which
the demo recreates on every run; seeds are fixed, so the numbers are the same on every machine with
the same OpenCV build.
"""

from __future__ import annotations

import json
import shutil
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from calibctl.config import Settings
from calibctl.errors import AlreadyExistsError
from calibctl.files import write_atomic
from calibctl.workflows.board import boards
from calibctl.workflows.camera.capture import CaptureRequest, CaptureResult, capture
from calibctl.workflows.camera.solve import SolveOutcome, SolveRequest, solve
from calibctl.workflows.lint import run
from calibctl.workflows.store_admin import records
from calibctl.workflows.synth.synth import TRUTH_FILE, run_synth

DEMO_DIR = Path("demo-out")
MARKER = ".calibctl-demo"
SERIAL = "DEMO-CAM-0001"
BOARD = "demo-A17"
SEED_GOOD = 20261122
SEED_FLAT = 20261123
VIEWS = 14


@dataclass
class DemoStep:
    """One step of the demo, handed to the renderer as soon as it is done."""

    title: str
    kind: str  # board | capture | solve | lint | history | export | truth
    payload: Any


@dataclass
class TruthComparison:
    fx_true: float
    fx_est: float
    sigma_fx: float | None
    cx_true: float
    cx_est: float
    sigma_cx: float | None

    @property
    def z_fx(self) -> float | None:
        return (self.fx_est - self.fx_true) / self.sigma_fx if self.sigma_fx else None

    @property
    def z_cx(self) -> float | None:
        return (self.cx_est - self.cx_true) / self.sigma_cx if self.sigma_cx else None


def prepare_dir(out: Path) -> None:
    """(Re)create the demo folder; refuse to wipe a folder the demo did not make."""
    if out.exists() and any(out.iterdir()) and not (out / MARKER).exists():
        raise AlreadyExistsError(
            f"{out} exists and was not made by calibctl demo", "pass --out to another folder"
        )
    if out.exists():
        shutil.rmtree(out)
    out.mkdir(parents=True)
    write_atomic(out / MARKER, "made by calibctl demo; recreated on every run\n")


def run_demo(settings: Settings, out: Path, emit: Callable[[DemoStep], None]) -> SolveOutcome:
    """Run every step, calling ``emit`` after each. ``settings.db_url`` is the demo's store."""
    good = run_synth(out / "good-session", "good", seed=SEED_GOOD, views=VIEWS)
    flat = run_synth(out / "flat-session", "flat", seed=SEED_FLAT, views=VIEWS)
    truth = json.loads((good.out_dir / TRUTH_FILE).read_text())
    square_mm = truth["board"]["square_size_m"] * 1000.0

    board = boards.add_board(
        settings,
        boards.BoardRegistration(
            name=BOARD,
            kind="chessboard",
            cols=truth["board"]["cols"],
            rows=truth["board"]["rows"],
            square_mm=square_mm,
            uncertainty_mm=0.02,
            instrument="Mitutoyo 500-196 calipers (demo)",
            measured_by="demo-qa",
            measured_on="2026-03-11",
            note="rendered board, measured by definition",
            span_mm=square_mm * (max(truth["board"]["cols"], truth["board"]["rows"]) - 1),
            span_uncertainty_mm=0.1,
            span_instrument="steel rule 300 mm (demo)",
        ),
    )
    emit(DemoStep(f"1. board {board.ref} registered with a measured square size", "board", board))

    rejected: CaptureResult = capture(
        settings, CaptureRequest(serial=SERIAL, board=board.ref, source=str(flat.out_dir))
    )
    emit(
        DemoStep(
            "2. capture of a flat board set (the operator forgot to tilt): the gates say what to do",
            "capture",
            rejected,
        )
    )

    accepted = capture(settings, CaptureRequest(serial=SERIAL, board=board.ref, source=str(good.out_dir)))
    emit(DemoStep("3. capture of a good board set", "capture", accepted))

    solved = solve(settings, SolveRequest(session_id=accepted.session.session_id))
    emit(
        DemoStep(
            "4. solve: every parameter with its one-sigma, held-out error and lint verdict", "solve", solved
        )
    )

    results = run.lint(settings, [], SERIAL, False)
    emit(DemoStep(f"5. calibctl lint --serial {SERIAL}", "lint", results))

    emit(DemoStep(f"6. calibctl history {SERIAL}", "history", records.history(settings, SERIAL)))

    ros_path = out / "camera_info.yaml"
    records.export(settings, SERIAL, "ros", ros_path, force=True)
    emit(DemoStep(f"7. exported ROS camera_info YAML to {ros_path}", "export", ros_path.read_text()))

    art = solved.artifact
    K = truth["camera"]["K"]
    comparison = TruthComparison(
        fx_true=K[0][0],
        fx_est=art.camera_matrix[0][0],
        sigma_fx=art.stdev.sigma.get("fx"),
        cx_true=K[0][2],
        cx_est=art.camera_matrix[0][2],
        sigma_cx=art.stdev.sigma.get("cx"),
    )
    emit(DemoStep("8. against the renderer's truth", "truth", comparison))
    return solved
