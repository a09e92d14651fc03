"""The station's verdicts stay what they were: the same inputs give the same lines, outcomes, views, corners,
gates and stored numbers as the code they were recorded from, at 1, 2 and 4 jobs.

``station_verdicts.json`` was recorded from main at 6bb9ba8 (before the station's unit was made cheaper)
by ``python -m tests.workflows.station.test_station_verdicts_kept OUT.json`` on the rendered units below.
Re-recorded once since, when the stored noise floor became capped at the fit it judges: only the two
accepted units' ``detector_rms_px`` moved (0.0517 -> 0.0382 and 0.0519 -> 0.0399 px); every verdict, line,
outcome, corner and gate stayed as recorded.
Numbers are compared as the CLI and the records print them (reasons and messages verbatim) and, for the
rest, to 6 significant digits; corners to 1e-6 px.
"""

from __future__ import annotations

import hashlib
import json
import shutil
import sys
import threading
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest

from calibctl.config import load_settings
from calibctl.errors import NotFoundError, NumericalError
from calibctl.store.repository import Store
from calibctl.workflows.camera import solve as solve_workflow
from calibctl.workflows.station.station import StationRequest, UnitResult, run_station
from tests.artifacts.factories import measured_board
from tests.workflows.synth_folders import rendered

RECORDED = Path(__file__).with_name("station_verdicts.json")
UNITS = ("CAM-GOOD", "CAM-HOLES", "CAM-FLAT")


def _g(x: float | None) -> str | None:
    return None if x is None else f"{x:.6g}"


def unit_folders(root: Path, good: Path, flat: Path) -> Path:
    """The station's folder: a clean unit, one with failed views (boardless pictures and a truncated file)
    and a flat one (rejected by the gates)."""
    shots = root / "shots"
    shutil.copytree(good, shots / "CAM-GOOD", ignore=shutil.ignore_patterns("*.json"))
    shutil.copytree(good, shots / "CAM-HOLES", ignore=shutil.ignore_patterns("*.json"))
    shutil.copytree(flat, shots / "CAM-FLAT", ignore=shutil.ignore_patterns("*.json"))
    holes = sorted((shots / "CAM-HOLES").glob("*.png"))
    blank = cv2.GaussianBlur(cv2.imread(str(holes[0]), cv2.IMREAD_GRAYSCALE), (0, 0), 40)
    for path in holes[2:5]:
        cv2.imwrite(str(path), blank)  # readable, no board
    holes[5].write_bytes(holes[5].read_bytes()[:300])  # truncated
    return shots


def _corner_digest(corners: Any) -> str:
    rounded = np.round(np.asarray(corners, np.float64) * 1e6).astype(np.int64)
    return hashlib.sha256(rounded.tobytes()).hexdigest()[:16]


def unit_record(store: Store, line: UnitResult) -> dict[str, Any]:
    out: dict[str, Any] = {
        "serial": line.serial,
        "status": line.status,
        "message": line.message,
        "hint": line.hint,
        "views": line.views,
        "rms_px": _g(line.rms_px),
    }
    if line.session_id is None:
        return out
    session = store.get_session(line.session_id)
    out["session"] = {
        "status": session.status,
        "image_size": list(session.image_size or ()),
        "outcomes": [[o.name, o.status, o.reason, o.corners_found] for o in session.outcomes],
        "gates": [
            [g.gate, g.passed, g.advisory, _g(g.value), _g(g.threshold), g.reason, g.hint]
            for g in session.gates
        ],
        "views": [
            [v.name, _corner_digest(v.corners_px), _g(v.tilt_deg), v.tilt_direction] for v in session.views
        ],
    }
    if line.version is None:
        return out
    art = store.get_artifact(line.serial, line.version)
    out["calibration"] = {
        "status": art.status,
        "model": art.model.name,
        "camera_matrix": [[_g(x) for x in row] for row in art.camera_matrix],
        "dist_coeffs": [_g(x) for x in art.dist_coeffs],
        "rms_px": _g(art.rms_px),
        "detector_rms_px": _g(art.detector_rms_px),
        "sigma": {k: _g(v) for k, v in sorted(art.stdev.sigma.items())},
        "sigma_refused": art.stdev.refused_reason,
        "held_out": [
            art.held_out.k_folds,
            _g(art.held_out.rms_px),
            _g(art.held_out.outer_ring_rms_px),
            _g(art.held_out.fit_outer_ring_rms_px),
        ]
        if art.held_out is not None
        else None,
        "views": [[v.name, _g(v.rms_px), v.outlier, v.dropped] for v in art.views],
        "rejected_corners": [[c.view, c.corner_id] for c in art.rejected_corners],
        "consistency": None
        if art.camera_consistency is None
        else [_g(art.camera_consistency.ratio), art.camera_consistency.two_cameras_suspected],
        "lint": sorted(f"{f.severity}:{f.code}" for f in art.lint),
    }
    return out


def station_records(shots: Path, db: Path, jobs: int) -> list[dict[str, Any]]:
    url = f"sqlite:///{db}"
    with Store.open(url) as store:
        store.add_board(measured_board("A17", square_mm=25.0))
    settings = load_settings(db=url, station="line-3", operator="op-ana", env={}, jobs=jobs)
    lines: list[UnitResult] = []
    run_station(
        settings,
        StationRequest("A17", f"{shots}/{{serial}}", spool=db.with_suffix(".spool")),
        UNITS,
        lines.append,
    )
    with Store.open(url) as store:
        return [unit_record(store, line) for line in lines]


@pytest.fixture(scope="module")
def shots(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return unit_folders(
        tmp_path_factory.mktemp("kept"),
        rendered(tmp_path_factory, "good"),
        rendered(tmp_path_factory, "flat"),
    )


@pytest.mark.parametrize("jobs", [1, 2, 4])
def test_the_station_gives_the_recorded_verdicts(
    shots: Path, tmp_path: Path, jobs: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    """And each solved unit's numbers are computed once: with 2 jobs or more on the station's early thread,
    while the session is written (``solve.start_numbers``); with 1 in the solve, on the station's thread."""
    threads: list[str] = []
    real = solve_workflow._solve_numbers

    def counted(*args: Any) -> Any:
        threads.append(threading.current_thread().name)
        return real(*args)

    monkeypatch.setattr(solve_workflow, "_solve_numbers", counted)
    recorded = json.loads(RECORDED.read_text())
    got = station_records(shots, tmp_path / "calibctl.db", jobs)
    assert [u["serial"] for u in got] == list(UNITS)
    for unit, want in zip(got, recorded, strict=True):
        assert unit == want, unit["serial"]
    solved = sum("calibration" in unit for unit in got)
    assert solved == 2 and len(threads) == solved
    assert {name.split("_")[0] for name in threads} == (
        {"MainThread"} if jobs == 1 else {"calibctl-early-numbers"}
    )


@pytest.mark.parametrize("jobs", [1, 2])
def test_a_solve_that_fails_gives_the_same_line_with_its_numbers_started_early(
    shots: Path, tmp_path: Path, jobs: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The error of numbers computed on the early thread is the solve's, as when they are computed inline: the
    unit's error line names it; its session is stored, no calibration."""

    threads: list[str] = []

    def failing(*args: Any) -> Any:
        threads.append(threading.current_thread().name.split("_")[0])
        raise NumericalError("held-out fold 2 (views [2, 7] held out): the solve diverged", hint="recapture")

    monkeypatch.setattr(solve_workflow, "_solve_numbers", failing)
    url = f"sqlite:///{tmp_path / 'c.db'}"
    with Store.open(url) as store:
        store.add_board(measured_board("A17", square_mm=25.0))
    settings = load_settings(db=url, station="line-3", operator="op-ana", env={}, jobs=jobs)
    lines: list[UnitResult] = []
    request = StationRequest("A17", f"{shots}/{{serial}}", spool=tmp_path / "c.spool")
    run_station(settings, request, ["CAM-GOOD"], lines.append)
    (line,) = lines
    assert threads == ["MainThread" if jobs == 1 else "calibctl-early-numbers"]
    assert (line.status, line.message, line.hint) == (
        "error",
        "held-out fold 2 (views [2, 7] held out): the solve diverged",
        "recapture",
    )
    with Store.open(url) as store, pytest.raises(NotFoundError, match="sessions .* but none was solved"):
        store.list_artifacts("CAM-GOOD")


if __name__ == "__main__":  # record: python -m tests.workflows.station.test_station_verdicts_kept OUT.json
    import tempfile

    from calibctl.workflows.synth.synth import run_synth
    from tests.workflows.synth_folders import SEED

    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        run_synth(root / "good", "good", seed=SEED, image_size=(640, 480))
        run_synth(root / "flat", "flat", seed=SEED, image_size=(640, 480))
        folders = unit_folders(root, root / "good", root / "flat")
        Path(sys.argv[1]).write_text(json.dumps(station_records(folders, root / "c.db", 1), indent=1) + "\n")
