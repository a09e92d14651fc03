"""Scans from files, pairing with images, and the acfr set: segmentation against the authors' crops."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from calibctl.core.lidar.segment import StationBox, segment_board
from calibctl.errors import InputError
from calibctl.workflows.lidar.scans import pair, read_scan
from tests.datasets import ACFR, require_acfr

ACFR_BOX = StationBox((1.0, -2.2, -0.8), (3.6, 1.6, 0.6))


def _touch(folder: Path, *names: str) -> None:
    folder.mkdir(exist_ok=True)
    for n in names:
        (folder / n).write_bytes(b"x")


def test_pairing_by_last_number_reports_the_unpaired(tmp_path: Path) -> None:
    _touch(tmp_path / "img", "pose1.png", "pose2.png", "pose9.png")
    _touch(tmp_path / "pcd", "pose1_full.pcd", "pose2_full.pcd", "pose5_full.pcd", "notes.txt")
    p = pair(tmp_path / "img", tmp_path / "pcd", "*_full.pcd")
    assert [k for k, _, _ in p.pairs] == [1, 2]
    why = {path.name: reason for path, reason in p.unpaired}
    assert why == {
        "pose9.png": "no scan with this frame number",
        "pose5_full.pcd": "no image with this frame number",
    }


def test_two_scans_with_one_frame_number_are_an_error(tmp_path: Path) -> None:
    _touch(tmp_path / "img", "pose1.png")
    _touch(tmp_path / "pcd", "pose1_full.pcd", "pose1_target.pcd")
    with pytest.raises(InputError, match="two scans with frame number 1") as err:
        pair(tmp_path / "img", tmp_path / "pcd")
    assert err.value.exit_code == 2 and "pose1_full.pcd" in err.value.message


def test_a_scan_in_millimetres_is_refused_naming_the_unit(tmp_path: Path) -> None:
    path = tmp_path / "scan1.txt"
    rng = np.random.default_rng(0)
    np.savetxt(path, rng.uniform(1000.0, 3000.0, (50, 3)))
    with pytest.raises(InputError, match="millimetres") as err:
        read_scan(path)
    assert "--scan-units mm" in (err.value.hint or "")
    assert read_scan(path, 1e-3).points_m.max() < 3.1


def test_acfr_segmentation_matches_the_authors_crops() -> None:
    """Every acfr sweep, station box only: our board points are the authors' (precision), nearly all of
    theirs are ours (recall; theirs keep points >3 cm off the plane, ours do not)."""
    require_acfr()
    outcomes = {}
    for full in sorted((ACFR / "pcd").glob("*_full.pcd")):
        found = segment_board(read_scan(full), ACFR_BOX, (0.61, 0.85))
        outcomes[full.name] = found.outcome
        theirs = {
            tuple(np.round(p, 4)) for p in read_scan(Path(str(full).replace("_full", "_target"))).points_m
        }
        ours = {tuple(np.round(p, 4)) for p in found.points_m}
        common = len(ours & theirs)
        assert common / len(ours) > 0.99, full.name
        assert common / len(theirs) > 0.85, full.name
    assert len(outcomes) == 20
    assert sum(o == "accepted" for o in outcomes.values()) >= 18


def test_overlay_draws_the_board_points_where_the_camera_sees_the_board() -> None:
    from calibctl.core.lidar import render
    from calibctl.core.lidar.segment import segment_board
    from calibctl.workflows.lidar.camera import Lens
    from calibctl.workflows.lidar.lidar_overlay import overlay_image

    session = render.render_session(1, seed=4)
    pose = session.poses[0]
    lens = Lens(render.K_RENDER, np.zeros(5), render.IMAGE_SIZE, "k1k2", "render")
    blank = np.zeros((render.IMAGE_SIZE[1], render.IMAGE_SIZE[0], 3), np.uint8)
    board = segment_board(pose.cloud, session.box, session.board.backing_m).points_m
    drawn = overlay_image(blank, board, session.T_lidar_cam, lens)
    assert not blank.any()  # the input is left alone
    T_cam_board = pose.camera.T_cam_board if pose.camera is not None else None
    assert T_cam_board is not None
    centre = T_cam_board[:3, :3] @ session.board.centre_in_pattern() + T_cam_board[:3, 3]
    u, v = (centre[:2] / centre[2] * render.K_RENDER[0, 0] + render.K_RENDER[:2, 2]).round().astype(int)
    assert drawn[v - 40 : v + 40, u - 40 : u + 40].any()  # dots around the board's centre in the image
    wrong = session.T_lidar_cam.copy()
    wrong[:3, 3] += [0.0, 3.0, 0.0]  # 3 m off: the dots land elsewhere
    assert not overlay_image(blank, board, wrong, lens)[v - 40 : v + 40, u - 40 : u + 40].any()
