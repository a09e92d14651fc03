"""The verdict stages on ``--jobs`` lanes give the numbers and verdicts of the sequential run, to the bit.

Each concurrent stage is run at jobs 1 (the plain loop), 2 and 4 with every remembered answer forgotten in
between, so each run computes its own: the held-out folds (tests/core/intrinsics/test_validation.py), the
one-camera split test and its capture gate, the lens floor's models, --model auto's ladder, and the whole
``calibrate`` (capture gates beside the split test, the solve's folds, split test and floor at once).
"""

from __future__ import annotations

import threading

import numpy as np
import pytest

from calibctl.config import load_settings
from calibctl.core.capture import camera_split
from calibctl.core.intrinsics import model_fit, model_select
from calibctl.core.intrinsics import solve as solve_module
from calibctl.core.intrinsics.recent_answers import RecentAnswers
from calibctl.core.synth.corners import synthesize_session
from calibctl.errors import UsageError
from calibctl.store.repository import Store
from calibctl.workflows.camera import capture as capture_workflow
from calibctl.workflows.camera.capture import CaptureRequest
from calibctl.workflows.camera.verdict_lanes import verdict_lanes
from tests.artifacts.factories import measured_board
from tests.workflows.camera.test_calibrate_reuse import numbers_without
from tests.workflows.synth_folders import rendered

JOBS = (1, 2, 4)
SIZE = (640, 480)
D = np.array([-0.12, 0.05, 0.0, 0.0, 0.0])
VOLATILE = {
    "content_sha256",
    "signature",
    "signed_by",
    "created_at",
    "started_at",
    "finished_at",
    "session_id",
}


def _K(f: float) -> np.ndarray:
    return np.array([[f, 0.0, 321.3], [0.0, f, 238.7], [0.0, 0.0, 1.0]])


@pytest.fixture
def forget(monkeypatch):
    """Forget every remembered answer, so that the next run computes its own."""

    def clear() -> None:
        solve_module.forget_recent_solves()
        camera_split.forget_recent_checks()
        monkeypatch.setattr(model_select, "_RECENT", RecentAnswers(model_select.RECENT_SELECTIONS))

    clear()
    return clear


def _two_cameras() -> tuple[list[np.ndarray], list[np.ndarray]]:
    one = synthesize_session(_K(800.0), D, SIZE, 12, seed=1, noise_px=0.1)
    other = synthesize_session(_K(832.0), D, SIZE, 12, seed=2, noise_px=0.1)
    order = np.random.default_rng(0).permutation(24)
    obj = [*one.object_points_per_view, *other.object_points_per_view]
    img = [*one.image_points_per_view, *other.image_points_per_view]
    return [obj[i] for i in order], [img[i] for i in order]


def _each_jobs(forget, run):
    out = {}
    for jobs in JOBS:
        forget()
        with verdict_lanes(jobs) as lanes:
            out[jobs] = run(lanes)
    return out


def _same_split(a: camera_split.CameraSplit | None, b: camera_split.CameraSplit | None) -> bool:
    assert a is not None and b is not None
    return (
        (a.group_a, a.group_b, a.holdout_rms_px, a.cross_rms_px, a.ratio)
        == (b.group_a, b.group_b, b.holdout_rms_px, b.cross_rms_px, b.ratio)
        and np.array_equal(a.camera_a, b.camera_a)
        and np.array_equal(a.camera_b, b.camera_b)
    )


def test_the_split_test_and_its_gate_are_the_same_at_every_job_count(forget) -> None:
    obj, img = _two_cameras()
    splits = _each_jobs(forget, lambda lanes: camera_split.check_one_camera(obj, img, SIZE, lanes=lanes))
    assert splits[1] is not None and splits[1].suspected  # a real verdict is compared, not an empty one
    assert all(_same_split(splits[1], splits[j]) for j in JOBS)
    names = [f"v{i:02d}" for i in range(len(obj))]
    gates = _each_jobs(forget, lambda lanes: camera_split.one_camera_gate(obj, img, names, SIZE, lanes=lanes))
    assert not gates[1].passed
    assert all(
        (g.passed, g.value, g.reason, g.hint, g.detail)
        == (gates[1].passed, gates[1].value, gates[1].reason, gates[1].hint, gates[1].detail)
        for g in gates.values()
    )


def test_the_lens_floor_and_the_model_ladder_are_the_same_at_every_job_count(forget) -> None:
    ses = synthesize_session(_K(800.0), D, SIZE, 16, seed=4, noise_px=0.3)
    obj, img = ses.object_points_per_view, ses.image_points_per_view
    floors = _each_jobs(forget, lambda lanes: model_fit.lens_floor_px(obj, img, SIZE, lanes=lanes))
    assert floors[1] is not None and len(set(floors.values())) == 1
    picks = _each_jobs(forget, lambda lanes: model_select.select_model(obj, img, SIZE, lanes=lanes))
    first = picks[1]
    for pick in picks.values():
        assert pick.chosen == first.chosen and pick.trail == first.trail
        assert np.array_equal(pick.holdout.fold_camera_matrices, first.holdout.fold_camera_matrices)
        assert pick.holdout.holdout_rms_px == first.holdout.holdout_rms_px


def _numbers(doc: object) -> object:
    return numbers_without(doc, VOLATILE)


@pytest.mark.parametrize("model", ["k1k2", "auto"])
def test_calibrate_stores_the_same_numbers_and_verdicts_at_every_job_count(
    tmp_path, tmp_path_factory, monkeypatch, forget, model
) -> None:
    folder = rendered(tmp_path_factory, "good")
    threads: set[str] = set()
    real = solve_module._solve
    monkeypatch.setattr(
        solve_module, "_solve", lambda *a: threads.add(threading.current_thread().name) or real(*a)
    )
    runs = {}
    for jobs in JOBS:
        forget()
        url = f"sqlite:///{tmp_path / f'jobs{jobs}'}.db"
        with Store.open(url) as store:
            store.add_board(measured_board("A17", square_mm=25.0))
        settings = load_settings(db=url, station="st-7", operator="op", env={}, jobs=jobs)
        runs[jobs] = capture_workflow.calibrate(
            settings, CaptureRequest("CAM-0042", "A17", str(folder)), model=model
        )
    first = runs[1]
    assert first.solve is not None and first.capture.session.status == "accepted"
    for run in runs.values():
        assert run.solve is not None
        assert _numbers(run.capture.session.model_dump(mode="json")) == _numbers(
            first.capture.session.model_dump(mode="json")
        )
        assert _numbers(run.solve.artifact.model_dump(mode="json")) == _numbers(
            first.solve.artifact.model_dump(mode="json")
        )
        assert (run.solve.artifact.status, run.solve.active) == (
            first.solve.artifact.status,
            first.solve.active,
        )
    assert any(name.startswith("calibctl-verdicts") for name in threads)  # jobs 2 and 4 did solve on the pool


def test_a_failing_capture_gate_stage_leaves_no_solve_running(
    tmp_path, tmp_path_factory, monkeypatch, forget
) -> None:
    """An error in the gates beside the split test reaches the caller after the split test has stopped, and
    nothing is stored (exit 2 path of a bad station region)."""
    folder = rendered(tmp_path_factory, "good")
    url = f"sqlite:///{tmp_path / 'bad'}.db"
    with Store.open(url) as store:
        store.add_board(measured_board("A17", square_mm=25.0))
    settings = load_settings(db=url, station="st-7", operator="op", env={}, jobs=2)
    settings = settings.model_copy(
        update={"gates": settings.gates.model_copy(update={"projection_region": "0,0,99999,5"})}
    )
    with pytest.raises(UsageError, match="projection_region"):
        capture_workflow.calibrate(settings, CaptureRequest("CAM-0042", "A17", str(folder)), model="k1k2")
    assert not [t for t in threading.enumerate() if t.name.startswith("calibctl-verdicts")]
    with Store.open(url) as store:
        assert store.list_sessions("CAM-0042") == []


@pytest.mark.parametrize("jobs", [1, 2])
def test_a_failing_fold_stops_the_solve_with_the_split_test_stopped_and_nothing_stored(
    tmp_path, tmp_path_factory, monkeypatch, forget, jobs
) -> None:
    """The held-out folds fail while the split test runs beside them: the folds' error reaches the caller, at
    every job count the same, after the split test has stopped; no calibration is stored."""
    from calibctl.errors import NotFoundError, NumericalError
    from calibctl.workflows.camera import solve as solve_workflow

    def failing(*args, **kwargs):
        raise NumericalError("held-out fold 0 (views [0, 5] held out): the solve diverged")

    monkeypatch.setattr(solve_workflow, "validate_holdout", failing)
    folder = rendered(tmp_path_factory, "good")
    url = f"sqlite:///{tmp_path / 'fold'}.db"
    with Store.open(url) as store:
        store.add_board(measured_board("A17", square_mm=25.0))
    settings = load_settings(db=url, station="st-7", operator="op", env={}, jobs=jobs)
    with pytest.raises(
        NumericalError, match=r"held-out fold 0 \(views \[0, 5\] held out\): the solve diverged"
    ):
        capture_workflow.calibrate(settings, CaptureRequest("CAM-0042", "A17", str(folder)), model="k1k2")
    assert not [t for t in threading.enumerate() if t.name.startswith("calibctl-verdicts")]
    with Store.open(url) as store, pytest.raises(NotFoundError, match="none was solved"):
        store.list_artifacts("CAM-0042")
