"""A LiDAR edge in a real rig flow (rendered 75 mm pair): carried through a hand-eye write and a rig re-solve,
dropped (named) once its camera is re-calibrated, replaced (not added) by a second LiDAR solve, compared by
`diff --rig`; and on SQLite and PostgreSQL, sealed, chained and rolled back."""

from __future__ import annotations

import numpy as np
import pytest
import yaml
from typer.testing import CliRunner

from calibctl.artifacts.common import utc_now
from calibctl.artifacts.lidar import LidarEdgeResult, LidarGate, LidarTransform
from calibctl.cli.main import app
from calibctl.config import load_settings
from calibctl.core.extrinsics import se3
from calibctl.store.repository import Store
from calibctl.workflows.compare.rig_diff import diff_rigs
from calibctl.workflows.edges import versions as rig_edges
from calibctl.workflows.handeye import rig_handeye
from calibctl.workflows.handeye.handeye import SynthRequest, run_handeye, run_synth_motions
from calibctl.workflows.lidar import rig_lidar
from calibctl.workflows.rig import rig_export, rig_lint, rigs
from tests.artifacts.factories import calibration
from tests.store.rig_documents import RIG, rig_calibration, rig_definition
from tests.workflows.rig.test_rig_store_flow import WHO, _sources, _truth_artifact, rig2, settings  # noqa: F401


def _lidar(camera: str = "CAM0@1", x_m: float = 0.05) -> LidarEdgeResult:
    """An accepted LiDAR result lidar -> CAM0 as `lidar solve` seals it (T and covariance chosen, not
    solved)."""
    T = se3.transform(se3.rotation_from_rotvec(np.array([0.1, -1.2, 0.3])), [x_m, 0.02, -0.19])
    cov = np.diag([1e-6, 2e-6, 1.5e-6, 1e-6, 4e-6, 9e-6])
    transform = LidarTransform(
        T_lidar_cam=tuple(map(tuple, T.tolist())),
        quaternion_wxyz=tuple(se3.quaternion_from_rotation(T[:3, :3])),
        rpy_rad=(0.0, 0.0, 0.0),
        sigma_translation_mm=(1.0, 2.0, 3.0),
        sigma_rotation_deg=(0.06, 0.08, 0.07),
        covariance=cov.tolist(),
    )
    gate = LidarGate(gate="lidar-observability", passed=True, value=0.2, threshold=0.08, message="spread")
    return LidarEdgeResult(
        parent_frame="lidar",
        child_frame="CAM0",
        status="accepted",
        camera=camera,
        board="L5@1",
        images="images",
        scans="scans",
        box=(1, -2, -1, 4, 2, 1),
        range_offset_applied_mm=0.0,
        transform=transform,
        metrics=None,
        gates=[gate],
        scans_outcomes=[],
        created_at=utc_now(),
    )


@pytest.fixture
def solved(settings, rig2):
    rigs.add_rig(settings, "R1", ["CAM0", "CAM1"], None, [], frames=["flange", "lidar"])
    rigs.capture_rig(settings, "R1", _sources(rig2), "A17")
    rigs.solve_rig_stored(settings, "R1")
    return settings


def test_a_lidar_edge_survives_a_hand_eye_write_and_a_rig_re_solve(solved, tmp_path):
    ev = _lidar()
    assert rig_lidar.store_lidar(solved, "R1", ev).calibration.version == 2
    csv = tmp_path / "arm.csv"
    run_synth_motions(SynthRequest(csv))
    arm = run_handeye(solved, csv, "flange", "CAM1").result
    with_arm = rig_handeye.store_handeye(solved, "R1", arm).calibration
    assert with_arm.version == 3 and with_arm.lidar == [ev] and with_arm.handeye == [arm]
    again = rigs.solve_rig_stored(solved, "R1").calibration
    assert again.version == 4 and again.status == "accepted" and again.lidar == [ev]
    assert sorted(e.source for e in again.edges) == ["hand-eye", "lidar-board", "rig-solve"]
    assert not rig_lint.lint_rig(solved, "R1").failed
    tf = yaml.safe_load(
        "\n".join(
            x
            for x in rig_export.export(solved, "R1", "tf", None, force=False).splitlines()
            if not x.startswith("#")
        )
    )["transforms"]
    # flange and lidar both hang off the cameras: the tree is rooted at CAM0, the lidar edge met from its
    # child
    pairs = [(t["header"]["frame_id"], t["child_frame_id"]) for t in tf]
    assert ("cam0_optical_frame", "lidar") in pairs and len(pairs) == 3
    # a second LiDAR solve of the same edge replaces it: one edge, one result
    second = _lidar(x_m=0.06)
    fifth = rig_lidar.store_lidar(solved, "R1", second).calibration
    assert fifth.lidar == [second] and [
        e.T_parent_child[0][3] for e in fifth.edges if e.source == "lidar-board"
    ] == [0.06]
    # `calibctl diff --rig` compares the LiDAR edge of two versions like a hand-eye edge
    change = next(c for c in diff_rigs(solved, "R1@4", "R1@5").edges if (c.a, c.b) == ("lidar", "CAM0"))
    assert change.translation_mm == pytest.approx(10.0, abs=1e-6) and change.significant


def test_a_stale_lidar_edge_is_dropped_and_named_by_the_next_write(solved, rig2, tmp_path):
    rig_lidar.store_lidar(solved, "R1", _lidar())
    with Store.open(solved.db_url) as store:
        store.add_artifact(_truth_artifact(rig2, "CAM0"), activate=True, **WHO)  # CAM0@2
        active = store.get_rig_calibration("R1")
        versions = rig_edges.cal_versions(store, active)
    kept = rig_edges.carried_forward(active, versions)
    assert (
        kept.edges == []
        and kept.evidence["lidar"] == []
        and [f.rule for f in kept.dropped] == ["lidar-dropped"]
    )
    assert "lidar -> CAM0 of R1@2 was solved with CAM0@1" in kept.dropped[0].message
    csv = tmp_path / "arm.csv"
    run_synth_motions(SynthRequest(csv))
    nxt = rig_handeye.store_handeye(
        solved, "R1", run_handeye(solved, csv, "flange", "CAM1").result
    ).calibration
    assert nxt.lidar == [] and not [e for e in nxt.edges if e.source == "lidar-board"]
    assert "lidar-dropped" in [f.rule for f in nxt.lint]


def test_a_lidar_edge_is_sealed_chained_and_rolled_back_on_both_backends(db_url):
    """SQLite and PostgreSQL: the version holding the LiDAR result reads back with its RFC 8785 hash intact,
    `db verify` passes over the rig chain, and a rollback takes the edge out of the active tree."""
    s = load_settings(db=db_url, station="st-test", operator="tester", env={})
    with Store.open(s.db_url) as store:
        store.add_rig(rig_definition().model_copy(update={"frames": ["lidar"]}))
        store.add_rig_calibration(rig_calibration(), activate=True, **WHO)
        store.add_artifact(calibration(serial="CAM-0001"), activate=True, **WHO)
    ev = _lidar(camera="CAM-0001@1").model_copy(update={"child_frame": "CAM-0001"})
    stored = rig_lidar.store_lidar(s, RIG, ev)
    assert stored.active and stored.calibration.version == 2
    back = rig_lint.show(s, RIG)
    assert (
        back.lidar == [ev]
        and back.computed_sha256() == back.content_sha256 == stored.calibration.content_sha256
    )
    verify = CliRunner().invoke(app, ["--db", db_url, "db", "verify"])
    assert verify.exit_code == 0, verify.output
    rig_lint.rollback(s, RIG, 1, "lidar edge looked off")
    assert rig_lint.show(s, RIG).lidar == [] and rig_lint.show(s, f"{RIG}@2").lidar == [ev]
