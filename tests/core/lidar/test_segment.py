"""The board in a rendered sweep: found in the box, measured, and each failure named with its numbers."""

from __future__ import annotations

import numpy as np
import pytest

from calibctl.core.lidar import render
from calibctl.core.lidar.pcd import PointCloud
from calibctl.core.lidar.segment import StationBox, rings_from_elevation, segment_board

SIZE_TOL_M = 0.03  # acfr: board dimension errors under 30 mm are acceptable


@pytest.fixture(scope="module")
def session() -> render.RenderedSession:
    return render.render_session(4, seed=3)


def test_rendered_boards_are_found_with_their_size(session: render.RenderedSession) -> None:
    for pose in session.poses:
        found = segment_board(pose.cloud, session.box, session.board.backing_m)
        assert found.outcome == "accepted", found.message
        assert abs(found.width_m - 0.61) < SIZE_TOL_M and abs(found.height_m - 0.85) < SIZE_TOL_M
        true_n = pose.T_lidar_board[:3, 2]
        assert abs(abs(found.normal @ true_n) - 1.0) < 1e-3
        true_centre = (
            pose.T_lidar_board[:3, :3] @ session.board.centre_in_pattern() + pose.T_lidar_board[:3, 3]
        )
        assert np.linalg.norm(found.centre_m - true_centre) < 0.03
        assert found.rings >= 7 and len(found.edge_points_m) == len(found.edge_ring) > 0


def test_without_a_ring_field_rings_come_from_elevation(session: render.RenderedSession) -> None:
    cloud = session.poses[0].cloud
    rings = rings_from_elevation(cloud.points_m)
    assert len(np.unique(rings)) == len(np.unique(cloud.ring))
    bare = PointCloud(cloud.points_m)
    assert segment_board(bare, session.box, session.board.backing_m).outcome == "accepted"


def test_no_board_in_the_box_is_no_plane(session: render.RenderedSession) -> None:
    empty = StationBox((-5.0, -5.0, -1.0), (-4.0, -4.0, 1.0))
    found = segment_board(session.poses[0].cloud, empty, session.board.backing_m)
    assert found.outcome == "no_plane" and "0 points inside the station box" in found.message


def test_too_few_rings_and_wrong_size_name_their_numbers(session: render.RenderedSession) -> None:
    cloud = session.poses[0].cloud
    few = segment_board(cloud, session.box, session.board.backing_m, min_rings=17)
    assert few.outcome == "too_few_rings" and "(need 17)" in few.message
    wrong = segment_board(cloud, session.box, (0.40, 0.85))
    assert wrong.outcome == "dimension_mismatch" and "registered 400 x 850 mm" in wrong.message


def test_a_board_a_thousand_times_too_big_is_named_millimetres(session: render.RenderedSession) -> None:
    cloud = session.poses[0].cloud
    found = segment_board(cloud, session.box, (0.00061, 0.00085))
    assert found.outcome == "dimension_mismatch" and "millimetres" in found.message
