"""solve: session in the store -> linted, immutable artifact as the serial's next version."""

from __future__ import annotations

import numpy as np
import pytest

from calibctl.artifacts.session import CaptureSession
from calibctl.config import load_settings
from calibctl.core.capture import camera_split
from calibctl.core.capture.camera_split import CAPTURE_MAX_VIEWS, spread_views
from calibctl.errors import InputError, NotFoundError, UsageError
from calibctl.store.repository import Store
from calibctl.workflows.board.boards import board_spec
from calibctl.workflows.camera import solve as solve_workflow
from tests.artifacts.factories import measured_board, nominal_board
from tests.workflows.sessions import K_TRUE, synthetic_capture


@pytest.fixture
def settings(tmp_path):
    return load_settings(db=f"sqlite:///{tmp_path / 'w.db'}", station="st-test", operator="tester", env={})


def _store_session(settings, session):
    with Store.open(settings.db_url) as store:
        board = store.add_board(session.board)
        session = session.model_copy(update={"board": board})
        store.add_session(session)
    return session


def test_good_session_solves_accepted_active_and_close_to_truth(settings):
    session = _store_session(settings, synthetic_capture(measured_board()))
    out = solve_workflow.solve(settings, solve_workflow.SolveRequest(session_id=session.session_id))
    art = out.artifact
    assert art.status == "accepted" and out.active and art.version == 1
    assert art.lint == []
    sigma_fx = art.stdev.sigma["fx"]
    assert 0 < sigma_fx < 2.0
    assert abs(art.fx - K_TRUE[0, 0]) < 4 * sigma_fx
    assert art.held_out.k_folds == 5 and art.held_out.outer_ring_rms_px is not None
    assert art.content_sha256 == art.computed_sha256()
    assert art.provenance.session_id == session.session_id and art.board.ref == "A17@1"


def test_same_session_solved_twice_gives_identical_numbers(settings):
    session = _store_session(settings, synthetic_capture(measured_board()))
    req = solve_workflow.SolveRequest(session_id=session.session_id)
    a = solve_workflow.solve(settings, req).artifact
    b = solve_workflow.solve(settings, req).artifact
    assert b.version == a.version + 1
    assert a.camera_matrix == b.camera_matrix and a.dist_coeffs == b.dist_coeffs
    assert a.stdev == b.stdev and a.held_out == b.held_out


def test_nominal_board_is_rejected_and_never_active(settings):
    _store_session(settings, synthetic_capture(nominal_board()))
    out = solve_workflow.solve(settings, solve_workflow.SolveRequest(serial="CAM-0001"))
    assert out.artifact.status == "rejected" and not out.active
    assert [f.rule for f in out.artifact.lint] == ["square-size-provenance"]
    with Store.open(settings.db_url) as store:
        assert store.active_version("CAM-0001") is None


def test_no_activate_keeps_the_previous_active_version(settings):
    session = _store_session(settings, synthetic_capture(measured_board()))
    first = solve_workflow.solve(settings, solve_workflow.SolveRequest(session_id=session.session_id))
    second = solve_workflow.solve(
        settings, solve_workflow.SolveRequest(session_id=session.session_id, activate=False)
    )
    assert first.active and not second.active and second.artifact.status == "accepted"
    with Store.open(settings.db_url) as store:
        assert store.active_version("CAM-0001") == 1


def test_auto_model_records_its_trail(settings):
    session = _store_session(settings, synthetic_capture(measured_board()))
    art = solve_workflow.solve(
        settings, solve_workflow.SolveRequest(session_id=session.session_id, model="auto")
    ).artifact
    assert art.model.selection and art.model.selection[0]["model"] == "k1k2"
    assert art.model.name in {"k1k2", "k1k2k3", "k1k2p1p2k3", "rational"}


def test_rejected_session_cannot_be_solved(settings):
    session = _store_session(settings, synthetic_capture(measured_board(), status="rejected"))
    with pytest.raises(UsageError, match=f"session {session.session_id} was rejected at capture"):
        solve_workflow.solve(settings, solve_workflow.SolveRequest(session_id=session.session_id))


def test_unknown_session_and_model_are_refused(settings):
    _store_session(settings, synthetic_capture(measured_board()))
    with pytest.raises(NotFoundError):
        solve_workflow.solve(settings, solve_workflow.SolveRequest(session_id="ffffffffffff"))
    with pytest.raises(UsageError, match="unknown model 'k9'"):
        solve_workflow.solve(settings, solve_workflow.SolveRequest(serial="CAM-0001", model="k9"))


def _with(session, view: int, corners_px):
    views = list(session.views)
    views[view] = views[view].model_copy(update={"corners_px": corners_px})
    return session.model_copy(update={"views": views})


def test_an_implausible_corner_is_removed_and_recorded_in_the_artifact(settings):
    session = synthetic_capture(measured_board())
    bad = session.views[3].corners_px.copy()
    bad[10] = (bad[10][0] + 15.0, bad[10][1])
    session = _store_session(settings, _with(session, 3, bad))
    out = solve_workflow.solve(settings, solve_workflow.SolveRequest(session_id=session.session_id))
    art = out.artifact
    assert [(c.view, c.corner_id) for c in art.rejected_corners] == [("view03.png", 10)]
    assert art.rejected_corners[0].residual_px == pytest.approx(15.0, abs=1.0)
    assert out.outlier_corners == []  # nothing flagged is left in the solve
    assert not art.views[3].outlier and not art.views[3].dropped and art.views[3].worst_corner_px < 1.5
    assert art.status == "accepted" and art.content_sha256 == art.computed_sha256()
    with Store.open(settings.db_url) as store:
        assert store.get_artifact(art.serial, art.version).rejected_corners == art.rejected_corners
    assert np.isclose(art.fx, K_TRUE[0, 0], atol=4 * art.stdev.sigma["fx"])


def test_a_noisy_view_is_flagged_and_dropped_only_with_drop_outliers(settings):
    session = synthetic_capture(measured_board())
    rng = np.random.default_rng(9)
    noisy = [(u + rng.normal(0, 1.5), v + rng.normal(0, 1.5)) for u, v in session.views[5].corners_px]
    session = _store_session(settings, _with(session, 5, noisy))
    kept = solve_workflow.solve(settings, solve_workflow.SolveRequest(session_id=session.session_id)).artifact
    assert kept.views[5].outlier and not kept.views[5].dropped
    assert [v.name for v in kept.views if v.outlier] == ["view05.png"]
    dropped = solve_workflow.solve(
        settings, solve_workflow.SolveRequest(session_id=session.session_id, drop_outliers=True)
    ).artifact
    assert dropped.views[5].outlier and dropped.views[5].dropped
    assert dropped.views[5].tvec_m[2] > 0.1  # the pose of the solve that flagged it
    assert dropped.rms_px < kept.rms_px


def test_one_camera_session_records_a_passed_two_camera_check(settings):
    session = _store_session(settings, synthetic_capture(measured_board()))
    art = solve_workflow.solve(settings, solve_workflow.SolveRequest(session_id=session.session_id)).artifact
    check = art.camera_consistency
    assert check is not None and not check.two_cameras_suspected and check.ratio < check.threshold
    assert len(check.group_a) + len(check.group_b) == 18 and art.status == "accepted"


def test_two_cameras_in_one_session_are_a_rejected_blend(settings):
    left = synthetic_capture(measured_board(), n_views=12, seed=1, noise_px=0.1)
    K_other = K_TRUE.copy()
    K_other[0, 0] = K_other[1, 1] = 1.04 * K_TRUE[0, 0]
    right = synthetic_capture(measured_board(), n_views=12, seed=2, noise_px=0.1, camera_matrix=K_other)
    views = [*left.views, *(v.model_copy(update={"name": "right-" + v.name}) for v in right.views)]
    session = _store_session(settings, left.model_copy(update={"views": views}))
    out = solve_workflow.solve(settings, solve_workflow.SolveRequest(session_id=session.session_id))
    art = out.artifact
    assert art.status == "rejected" and not out.active
    check = art.camera_consistency
    assert check is not None and check.two_cameras_suspected
    assert sorted(check.group_b) == sorted(v.name for v in views[12:])
    finding = next(f for f in art.lint if f.rule == "one-camera")
    assert finding.severity == "error" and "two cameras" in finding.message
    assert "its own images" in finding.fix and finding.value == pytest.approx(check.ratio)
    assert art.content_sha256 == art.computed_sha256()


def _two_camera_session(n_each: int) -> CaptureSession:
    """``n_each`` views of K_TRUE then ``n_each`` of a camera with a focal length 4 % longer (names
    right-*)."""
    left = synthetic_capture(measured_board(), n_views=n_each, seed=1, noise_px=0.1)
    K_other = K_TRUE.copy()
    K_other[0, 0] = K_other[1, 1] = 1.04 * K_TRUE[0, 0]
    right = synthetic_capture(measured_board(), n_views=n_each, seed=2, noise_px=0.1, camera_matrix=K_other)
    return left.model_copy(
        update={
            "views": [*left.views, *(v.model_copy(update={"name": "right-" + v.name}) for v in right.views)]
        }
    )


def test_above_the_capture_cap_the_solve_checks_the_gates_spread_views_and_still_finds_two_cameras(settings):
    """72 views, more than CAPTURE_MAX_VIEWS: the split test runs on the gate's 60 spread views, the groups
    name
    them, and a second camera among them is still found (lint one-camera) while one camera is not flagged."""
    session = _store_session(settings, _two_camera_session(36))
    art = solve_workflow.solve(settings, solve_workflow.SolveRequest(session_id=session.session_id)).artifact
    check = art.camera_consistency
    assert check is not None and check.two_cameras_suspected and art.status == "rejected"
    checked = [session.views[i].name for i in spread_views(72)]
    assert len(checked) == CAPTURE_MAX_VIEWS and sorted(check.group_a + check.group_b) == sorted(checked)
    assert sorted(check.group_b) == sorted(n for n in checked if n.startswith("right-"))
    assert any(f.rule == "one-camera" and f.severity == "error" for f in art.lint)
    one = synthetic_capture(
        measured_board(), serial="CAM-0002", session_id="0123456789cd", n_views=72, seed=5, noise_px=0.1
    )
    _store_session(settings, one)
    clean = solve_workflow.solve(settings, solve_workflow.SolveRequest(session_id=one.session_id)).artifact
    assert clean.camera_consistency is not None and not clean.camera_consistency.two_cameras_suspected
    assert len(clean.camera_consistency.group_a) + len(clean.camera_consistency.group_b) == CAPTURE_MAX_VIEWS
    assert clean.status == "accepted" and not any(f.rule == "one-camera" for f in clean.lint)


def test_the_solve_asks_the_capture_gates_question_so_it_is_answered_once(settings, monkeypatch):
    """calibrate: the capture gate, then the solve of the same corners under k1k2 (72 views): one split
    test."""
    session = _store_session(settings, synthetic_capture(measured_board(), n_views=72, seed=5, noise_px=0.1))
    points = board_spec(session.board).object_points()
    camera_split.forget_recent_checks()
    computed = []
    real = camera_split._check_one_camera
    monkeypatch.setattr(camera_split, "_check_one_camera", lambda *a: computed.append(len(a[0])) or real(*a))
    gate = camera_split.one_camera_gate(
        [points[np.asarray(v.corner_ids)] for v in session.views],
        [np.asarray(v.corners_px, np.float64) for v in session.views],
        [v.name for v in session.views],
        (640, 480),
    )
    art = solve_workflow.solve(settings, solve_workflow.SolveRequest(session_id=session.session_id)).artifact
    assert gate.passed and computed == [CAPTURE_MAX_VIEWS]  # the gate computed it, the solve remembered it
    assert art.camera_consistency is not None and art.camera_consistency.ratio == gate.value


def test_the_stored_covariance_is_the_one_sigma_comes_from(settings):
    session = _store_session(settings, synthetic_capture(measured_board()))
    art = solve_workflow.solve(settings, solve_workflow.SolveRequest(session_id=session.session_id)).artifact
    cov = art.stdev.covariance
    assert cov is not None and cov.parameters == ["fy", "cx", "cy", "k1", "k2"]  # k1k2: fx tied to fy
    matrix = np.asarray(cov.matrix)
    assert np.allclose(matrix, matrix.T) and np.all(np.linalg.eigvalsh(matrix) > 0)
    for i, name in enumerate(cov.parameters):
        assert np.sqrt(matrix[i, i]) == pytest.approx(art.stdev.sigma[name], rel=1e-12)
    assert cov.aspect_ratio * np.sqrt(matrix[0, 0]) == pytest.approx(art.stdev.sigma["fx"], rel=1e-12)
    with Store.open(settings.db_url) as store:
        assert store.get_artifact(art.serial, art.version).stdev.covariance == cov


def test_fisheye_session_solves_exports_equidistant_and_lints_clean(settings, tmp_path):
    from calibctl.workflows.exports import formats
    from calibctl.workflows.lint import run as lint_run
    from calibctl.workflows.lint.lint import lint_files
    from tests.workflows.sessions import fisheye_capture

    session = _store_session(settings, fisheye_capture(measured_board()))
    art = solve_workflow.solve(
        settings, solve_workflow.SolveRequest(session_id=session.session_id, model="fisheye")
    ).artifact
    assert art.status == "accepted" and art.lint == [] and art.model.name == "fisheye"
    assert len(art.dist_coeffs) == 4 and set(art.stdev.sigma) == {
        "fx",
        "fy",
        "cx",
        "cy",
        "k1",
        "k2",
        "k3",
        "k4",
    }
    assert "CALIB_FIX_SKEW" in art.model.flag_names
    for fmt in formats.EXPORT_FORMATS:
        path = tmp_path / f"fe.{fmt}.{'json' if fmt == 'json' else 'yaml'}"
        if fmt == "mrcal":  # mrcal has no Kannala-Brandt model: refused, saying so
            with pytest.raises(InputError, match="mrcal has no Kannala-Brandt"):
                formats.render(art, fmt)
            continue
        path.write_text(formats.render(art, fmt), encoding="utf-8")
        if fmt == "kalibr":  # a one-camera camchain is linted as a rig export file
            [result] = lint_run.lint(settings, [path], None, False)
            assert not result.failed, (fmt, result.findings)
            continue
        loaded = formats.load_calibration(path)
        [result] = lint_files([path], settings.lint)
        assert not result.failed, (fmt, result.findings)
        if fmt == "ros":
            assert loaded.data["distortion_model"] == "equidistant"
            assert loaded.data["distortion_coefficients"]["data"] == art.dist_coeffs
        if fmt == "opencv":
            assert loaded.data["distortion_model"] == "equidistant"
            np.testing.assert_allclose(np.ravel(loaded.data["distortion_coefficients"]), art.dist_coeffs)
    from calibctl.workflows.store_admin.records import read_artifact_file

    assert read_artifact_file(tmp_path / "fe.json.json") == art


def test_k1k2_on_a_fisheye_session_is_rejected_by_model_misfit(settings):
    from tests.workflows.sessions import fisheye_capture

    session = _store_session(settings, fisheye_capture(measured_board(), fov_deg=150.0))
    art = solve_workflow.solve(settings, solve_workflow.SolveRequest(session_id=session.session_id)).artifact
    assert art.status == "rejected" and art.detector_rms_px is not None
    misfit = [f for f in art.lint if f.rule == "model-misfit"]
    assert misfit and "--model fisheye" in (misfit[0].fix or "")


def test_a_good_pinhole_session_records_its_detector_noise_and_passes_model_misfit(settings):
    session = _store_session(settings, synthetic_capture(measured_board()))
    art = solve_workflow.solve(settings, solve_workflow.SolveRequest(session_id=session.session_id)).artifact
    assert art.status == "accepted" and "model-misfit" not in [f.rule for f in art.lint]
    assert 0.5 * art.rms_px < art.detector_rms_px < 2.0 * art.rms_px


def test_auto_on_a_lens_k1k2_cannot_explain_ends_in_fisheye_instead_of_exit_2(settings):
    """`solve --model auto` used to exit 2 ("the solve does not explain the corners") when the k1k2 rung
    failed; a 185 deg circular render of a 12 x 9 board held close fails the k1k2 solve at 10.9 px."""
    from calibctl.artifacts.session import ViewCorners
    from tests.core.intrinsics.test_model_select import _strong_fisheye_session

    s, size = _strong_fisheye_session()
    board = measured_board().model_copy(update={"cols": 12, "rows": 9})
    base = synthetic_capture(measured_board(), session_id="fe185fe185fe", n_views=2)
    views = [
        ViewCorners(
            name=f"fisheye{i:02d}.png",
            corner_ids=list(range(12 * 9)),
            corners_px=[(float(u), float(v)) for u, v in img],
        )
        for i, img in enumerate(s.image_points_per_view)
    ]
    session = _store_session(
        settings, base.model_copy(update={"board": board, "views": views, "image_size": size})
    )
    art = solve_workflow.solve(
        settings, solve_workflow.SolveRequest(session_id=session.session_id, model="auto")
    ).artifact
    trail = {c["model"]: c for c in art.model.selection}
    assert art.model.name == "fisheye" and trail["k1k2"]["reason"].startswith("not solvable: ")
    assert art.rms_px < 0.5 and "model-misfit" not in [f.rule for f in art.lint]
