"""A stereo pair of fisheye lenses (equidistant Kannala-Brandt), corner level, seeded: the rig solve
projects through cv2.fisheye, the held-out epipolar and rectified-row errors are measured on rays, and
the exports name the equidistant model. Before, a fisheye member raised IndexError in the covariance (the
real sourishg fisheye pair, `rig solve-folders --model fisheye`)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import yaml

from calibctl.core.board.board_spec import BoardSpec
from calibctl.core.board.views import BoardView
from calibctl.core.extrinsics import se3
from calibctl.core.extrinsics.rig_problem import MemberIntrinsics, RigViews
from calibctl.core.extrinsics.rig_solve import solve_rig
from calibctl.core.extrinsics.rig_validation import validate_rig_holdout
from calibctl.core.intrinsics.fisheye_model import MAX_SOLVE_THETA_RAD
from calibctl.core.intrinsics.solve import FISHEYE_DIST_NAMES
from calibctl.core.synth.fisheye import FisheyeCamera, default_fisheye_distance_m, fisheye_poses
from calibctl.workflows.exports.rig_exports import write_exports

BOARD = BoardSpec.chessboard(9, 6, 0.025)
SIZE = (960, 600)
T_R_L = se3.transform(
    se3.rotation_from_rotvec(np.radians([0.4, -0.3, 0.5])), np.array([-0.060, 0.001, 0.002])
)
NOISE_PX = 0.2
Z_MAX = 3.5  # |estimate - truth| / sigma


def _cameras() -> tuple[FisheyeCamera, FisheyeCamera]:
    left = FisheyeCamera.from_fov(SIZE, 170.0)
    right = FisheyeCamera.from_fov(SIZE, 165.0, dist=(0.01, 0.005, -0.002, 0.0005))
    return left, right


def _sees(camera: FisheyeCamera, obj: np.ndarray, T_cam_board: np.ndarray) -> bool:
    cam = obj @ T_cam_board[:3, :3].T + T_cam_board[:3, 3]
    theta = np.arctan2(np.hypot(cam[:, 0], cam[:, 1]), cam[:, 2])
    return bool(
        theta.max() < MAX_SOLVE_THETA_RAD and camera.inside(camera.project(obj, T_cam_board), 4.0).all()
    )


def _session(seed: int) -> tuple[RigViews, list[MemberIntrinsics]]:
    rng = np.random.default_rng(seed)
    left, right = _cameras()
    obj = BOARD.object_points()
    poses = fisheye_poses(
        left, obj, 40, rng, default_fisheye_distance_m(left, BOARD.square_size_m), (15.0, 45.0), None, 4.0
    )
    ids = np.arange(BOARD.n_corners)
    rows = []
    for T_L_board in poses:
        T_R_board = T_R_L @ T_L_board
        if not _sees(right, obj, T_R_board):
            continue
        rows.append(
            tuple(
                BoardView(
                    f"f{len(rows)}", ids, cam.project(obj, T) + rng.normal(0.0, NOISE_PX, (len(ids), 2))
                )
                for cam, T in ((left, T_L_board), (right, T_R_board))
            )
        )
    views = RigViews(("L", "R"), obj, tuple(f"f{i}" for i in range(len(rows))), tuple(rows))
    members = [
        MemberIntrinsics(
            name, cam.K, cam.dist, SIZE, ("fx", "fy", "cx", "cy"), FISHEYE_DIST_NAMES, None, None, "fisheye"
        )
        for name, cam in (("L", left), ("R", right))
    ]
    return views, members


@pytest.fixture(scope="module")
def session():
    return _session(3)


def test_a_fisheye_pair_solves_to_its_truth_within_its_sigma(session) -> None:
    views, members = session
    assert len(views.frames) >= 15
    sol = solve_rig(views, members)
    assert sol.solver == "calibctl joint LM"  # cv2.stereoCalibrateExtended has no fisheye lens
    T = sol.T_a_b(1, 0)  # T_R_L
    edge = sol.tree.edges[0]
    err_mm = abs(np.linalg.norm(T[:3, 3]) - np.linalg.norm(T_R_L[:3, 3])) * 1e3
    assert err_mm < Z_MAX * edge.sigma_translation_mm
    err_deg = se3.rotation_angle_deg(T[:3, :3] @ T_R_L[:3, :3].T)
    assert err_deg < Z_MAX * edge.sigma_rotation_deg
    assert max(sol.rms_px) < 2 * NOISE_PX


def test_refined_fisheye_intrinsics_keep_their_k1_to_k4_order(session) -> None:
    views, members = session
    start = [replace(m, camera_matrix=m.camera_matrix + np.diag([2.0, 2.0, 0.0])) for m in members]
    sol = solve_rig(views, start, refine_intrinsics=True)
    for got, truth in zip(sol.members, members, strict=True):
        assert got.lens == "fisheye" and len(got.dist_coeffs) == 4
        assert abs(got.camera_matrix[0, 0] - truth.camera_matrix[0, 0]) < 1.0
        np.testing.assert_allclose(got.dist_coeffs, truth.dist_coeffs, atol=0.02)


def test_held_out_epipolar_and_row_errors_are_at_the_corner_noise(session) -> None:
    # On rays times the focal length: a pinhole's ideal pixels would magnify corners 70 deg off-axis 9x.
    views, members = session
    pair = validate_rig_holdout(views, members).pairs[0]
    assert pair.epipolar_rms_px < 2 * NOISE_PX and pair.rectified_rms_px < 2 * NOISE_PX


def test_exports_name_the_equidistant_lens(session, tmp_path) -> None:
    views, members = session
    sol = solve_rig(views, members)
    write_exports(sol, tmp_path)
    chain = yaml.safe_load((tmp_path / "camchain.yaml").read_text())
    assert [chain[c]["distortion_model"] for c in ("cam0", "cam1")] == ["equidistant", "equidistant"]
    assert chain["cam1"]["distortion_coeffs"] == pytest.approx(list(members[1].dist_coeffs))
    info = yaml.safe_load((tmp_path / "R_camera_info.yaml").read_text())
    assert info["distortion_model"] == "equidistant" and info["distortion_coefficients"]["cols"] == 4
    P = np.array(info["projection_matrix"]["data"]).reshape(3, 4)
    assert P[0, 0] > 100 and P[0, 3] / -P[0, 0] == pytest.approx(np.linalg.norm(T_R_L[:3, 3]), rel=0.01)


def test_a_stored_fisheye_calibration_joins_a_rig_as_a_fisheye_member() -> None:
    from calibctl.artifacts.rig import RigMember
    from calibctl.workflows.rig.rigs import member_intrinsics
    from tests.artifacts.factories import calibration

    base = calibration()
    sigma = {"fx": 0.3, "fy": 0.3, "cx": 0.2, "cy": 0.2, "k1": 0.001, "k2": 0.002, "k3": 0.003, "k4": 0.004}
    art = base.model_copy(
        update={
            "dist_coeffs": [0.02, -0.01, 0.005, -0.001],
            "model": base.model.model_copy(update={"name": "fisheye"}),
            "stdev": base.stdev.model_copy(update={"sigma": sigma}),
        }
    )
    m = member_intrinsics(art)
    assert m.lens == "fisheye" and m.aspect is None and m.free_distortion == FISHEYE_DIST_NAMES
    assert m.covariance is not None and np.diag(m.covariance) == pytest.approx([v**2 for v in sigma.values()])
    assert member_intrinsics(base).lens == "pinhole"
    fields = {
        "serial": "CAM-0001",
        "version": 1,
        "content_sha256": "ab" * 32,
        "image_size": (640, 480),
        "camera_matrix": ((800.0, 0.0, 320.0), (0.0, 800.0, 240.0), (0.0, 0.0, 1.0)),
        "dist_coeffs": [0.0] * 4,
        "refined": False,
    }
    assert "lens" not in RigMember(**fields).model_dump(mode="json")  # pinhole documents hash as before
    assert RigMember(**fields, lens="fisheye").model_dump(mode="json")["lens"] == "fisheye"
