"""``calibrate`` with the hot path cut stores what it stored before, number for number.

Each case runs the whole workflow (detection, capture gates, solve, validation, lint, store) twice on the same
rendered folder: once the way it ran before (no solve or fisheye focal-guess score remembered, the misfit
floor's lens models always solved) and once as it runs now (the projection gate's solve reused by the solve,
--model auto's fold fits reused, the lens models skipped where no floor can fail the fit, the tilt lens's
fisheye solve reused by the projection gate, each view's focal-guess score computed once per focal length).
The session's gates and every number of
the calibration are equal to the bit; the one number that may differ is the stored floor
(``detector_rms_px``), which is then the lens-free estimate, never below the full floor, with the same
model-misfit verdict.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from calibctl.config import load_settings
from calibctl.core.intrinsics import fisheye_model, model_fit
from calibctl.core.intrinsics import solve as solve_module
from calibctl.core.intrinsics.recent_answers import RecentAnswers
from calibctl.store.repository import Store
from calibctl.workflows.camera import capture as capture_workflow
from calibctl.workflows.camera.capture import CaptureRequest
from tests.artifacts.factories import measured_board
from tests.workflows.synth_folders import fisheye_gauge_folders, rendered

# what differs between any two runs (ids, times, the hash over them), not what the change touches
VOLATILE = {
    "content_sha256",
    "signature",
    "signed_by",
    "created_at",
    "started_at",
    "finished_at",
    "session_id",
    "lint",
    "detector_rms_px",
}


def _calibrate(tmp_path: Path, name: str, folder: Path, model: str) -> capture_workflow.CalibrateResult:
    url = f"sqlite:///{tmp_path / name}.db"
    with Store.open(url) as store:
        store.add_board(measured_board("A17", square_mm=25.0))
    settings = load_settings(db=url, station="st-7", operator="op", env={})
    return capture_workflow.calibrate(
        settings, CaptureRequest("CAM-0042", "A17", str(folder), jobs=1), model=model
    )


def numbers_without(doc: object, volatile: frozenset[str] | set[str]) -> object:
    """A dumped artifact or session without the keys in ``volatile``, at every depth."""
    if isinstance(doc, dict):
        return {k: numbers_without(v, volatile) for k, v in doc.items() if k not in volatile}
    if isinstance(doc, list):
        return [numbers_without(v, volatile) for v in doc]
    return doc


def _numbers(doc: object) -> object:
    return numbers_without(doc, VOLATILE)


@pytest.mark.parametrize(
    ("scene", "model"), [("good", "k1k2"), ("good", "auto"), ("fisheye", "fisheye"), ("fisheye", "auto")]
)
def test_calibrate_stores_the_numbers_and_verdicts_it_stored_before(
    tmp_path, tmp_path_factory, monkeypatch, scene, model
):
    folder = (
        rendered(tmp_path_factory, "good") if scene == "good" else fisheye_gauge_folders(tmp_path_factory)[0]
    )
    solve_module.forget_recent_solves()
    computed: list[str] = []  # the solves each run really computed
    real = solve_module._solve
    monkeypatch.setattr(solve_module, "_solve", lambda *a: computed.append(a[3].name) or real(*a))
    scored: list[float] = []  # the fisheye focal-guess view scores each run really computed
    real_score = fisheye_model._homography_rms_px
    monkeypatch.setattr(fisheye_model, "_homography_rms_px", lambda *a: scored.append(a[2]) or real_score(*a))
    with monkeypatch.context() as before:
        before.setattr(solve_module, "_RECENT", RecentAnswers(0))  # nothing remembered
        before.setattr(solve_module, "_RECENT_FITS", RecentAnswers(0))
        before.setattr(fisheye_model, "_RECENT_SCORES", RecentAnswers(0))
        before.setattr(model_fit, "can_misfit", lambda fit_rms_px: True)  # the lens models always solved
        old = _calibrate(tmp_path, "before", folder, model)
    solves_before, scores_before = len(computed), len(scored)
    fisheye_before = computed.count("fisheye")
    new = _calibrate(tmp_path, "after", folder, model)
    assert len(computed) - solves_before <= solves_before - 3  # the gate's solve again, rational and fisheye
    if (
        scene == "fisheye"
    ):  # the tilt lens is the fisheye solve the gate asks for; most guess scores are asked before
        assert computed[solves_before:].count("fisheye") <= fisheye_before - 2
        assert len(scored) - scores_before < scores_before / 2
    assert old.solve is not None and new.solve is not None
    assert _numbers(new.capture.session.model_dump(mode="json")) == _numbers(
        old.capture.session.model_dump(mode="json")
    )
    a, b = old.solve.artifact, new.solve.artifact
    assert _numbers(b.model_dump(mode="json")) == _numbers(a.model_dump(mode="json"))
    assert (b.status, new.solve.active) == (a.status, old.solve.active) == ("accepted", True)
    assert [(f.rule, f.severity, f.passed) for f in b.lint] == [
        (f.rule, f.severity, f.passed) for f in a.lint
    ]
    assert [f.message for f in b.lint if f.rule != "model-misfit"] == [
        f.message for f in a.lint if f.rule != "model-misfit"
    ]
    assert a.detector_rms_px is not None and b.detector_rms_px is not None
    assert b.rms_px <= model_fit.MISFIT_MIN_PX and b.detector_rms_px >= a.detector_rms_px
