"""Frame matching by file-name number, the rig-connected gate, and the tree's bookkeeping."""

from __future__ import annotations

import numpy as np
import pytest

from calibctl.core.extrinsics.rig_frames import frame_key, match_frames, rig_connected_gate
from calibctl.core.extrinsics.rig_tree import Edge, RigTree, simple_cycles


@pytest.mark.parametrize(
    ("name", "key"),
    [
        ("left01.jpg", 1),
        ("right01.jpg", 1),
        ("left_001772846782141.jpg", 1772846782141),
        ("cam0_frame_0042.png", 42),
        ("IMG_0042_left.png", 42),
        ("left.png", None),
    ],
)
def test_frame_key_is_the_last_number_of_the_stem(name, key):
    assert frame_key(f"/some/dir7/{name}") == key


def test_match_frames_pairs_by_key_and_reports_the_rest():
    m = match_frames(
        {
            "L": ["l/left01.jpg", "l/left02.jpg", "l/left.jpg", "l/left_2.jpg"],
            "R": ["r/right01.jpg", "r/right03.jpg"],
            "C": ["c/c_0002.png"],
        }
    )
    assert [(k, dict(v)) for k, v in m.frames] == [
        (1, {"L": "l/left01.jpg", "R": "r/right01.jpg"}),
        (2, {"L": "l/left02.jpg", "C": "c/c_0002.png"}),
    ]
    assert {(u.camera, u.path, u.reason) for u in m.unmatched} == {
        ("L", "l/left.jpg", "no-frame-key"),
        ("L", "l/left_2.jpg", "duplicate-frame-key"),
        ("R", "r/right03.jpg", "no-partner"),
    }


def test_gate_passes_a_connected_rig_with_enough_views():
    g = rig_connected_gate(["A", "B", "C"], {(0, 1): 9, (0, 2): 0, (1, 2): 6}, min_shared_views=5)
    assert g.passed and g.value == 6


def test_gate_names_the_cheapest_pair_across_the_split():
    g = rig_connected_gate(["A", "B", "C"], {(0, 1): 9, (0, 2): 1, (1, 2): 3}, min_shared_views=5)
    assert not g.passed and g.reason == "rig-not-connected"
    assert "B-C shares 3 view(s) (needs 5)" in g.message
    assert g.hint == "capture at least 2 more frame(s) with the board seen by both B and C"


def test_a_pair_that_never_shares_a_view_is_refused_by_name():
    g = rig_connected_gate(["LEFT", "RIGHT"], {(0, 1): 0})
    assert not g.passed and "LEFT-RIGHT shares 0 view(s)" in g.message


def test_simple_cycles_of_a_complete_graph_of_four():
    edges = {frozenset(p) for p in [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)]}
    cycles = simple_cycles(range(4), edges)
    assert len(cycles) == 7 and len(set(cycles)) == 7  # 4 triangles + 3 four-cycles, each once
    assert simple_cycles(range(3), {frozenset((0, 1)), frozenset((1, 2))}) == []


def _edge(parent, child, x):
    T = np.eye(4)
    T[0, 3] = x
    return Edge(parent, child, T, np.eye(6) * 1e-8)


def test_a_tree_composes_along_its_one_path_and_takes_a_non_camera_edge():
    tree = RigTree("cam0", (_edge("cam0", "cam1", 0.1), _edge("cam1", "flange", 0.05)))
    assert np.allclose(tree.T_root("flange")[:3, 3], [0.15, 0, 0])
    assert np.allclose(tree.T("cam1", "cam0")[:3, 3], [-0.1, 0, 0])
    assert tree.frames == ("cam0", "cam1", "flange")


def test_an_edge_that_does_not_extend_the_tree_is_refused():
    with pytest.raises(ValueError, match="does not extend the tree"):
        RigTree("cam0", (_edge("cam0", "cam1", 0.1), _edge("cam2", "cam1", 0.1)))


@pytest.mark.parametrize("angle", [1e-9, 1e-6, 1e-3, 0.5, 3.0])
def test_rotation_vector_round_trips_down_to_tiny_angles(angle):
    import cv2

    from calibctl.core.extrinsics.rig_tree import rotation_vector

    rvec = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8]) * angle
    assert np.allclose(rotation_vector(cv2.Rodrigues(rvec)[0]), rvec, rtol=1e-6, atol=1e-15)
