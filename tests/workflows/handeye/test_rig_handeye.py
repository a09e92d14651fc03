"""Hand-eye edges stored in the rig tree (SQLite and PostgreSQL): accepted -> the rig's next active
version; rejected -> a rejected version with no edge; lint, stale camera, rollback, exports; refusals."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from calibctl.artifacts.handeye import HandEyeResult
from calibctl.config import Settings, load_settings
from calibctl.core.extrinsics import se3
from calibctl.errors import NotFoundError, UsageError
from calibctl.store.repository import Store
from calibctl.workflows.edges import versions as rig_edges
from calibctl.workflows.handeye import rig_handeye
from calibctl.workflows.handeye.handeye import SynthRequest, run_handeye, run_synth_motions
from calibctl.workflows.rig import rig_export, rig_lint
from tests.artifacts.factories import calibration
from tests.store.rig_documents import RIG, rig_calibration, rig_definition
from tests.workflows.urdf_check import loadable_urdf

WHO = {"actor": "qa", "station": "st1", "reason": "test"}
ROOT, OTHER = "CAM-0001", "CAM-0002"
ROOT_FRAME, OTHER_FRAME = "cam_0001_optical_frame", "cam_0002_optical_frame"  # frame_names.default_frame


@pytest.fixture
def settings(db_url: str) -> Settings:
    s = load_settings(db=db_url, station="st-test", operator="tester", env={})
    with Store.open(s.db_url) as store:
        store.add_rig(rig_definition().model_copy(update={"frames": ["flange", "imu", "lidar"]}))
        store.add_rig_calibration(rig_calibration(), activate=True, **WHO)
        store.add_artifact(calibration(serial=ROOT), activate=True, **WHO)
        store.add_artifact(calibration(serial=OTHER), activate=True, **WHO)
    return s


def _result(
    tmp_path: Path, settings: Settings, parent: str, child: str, excitation: str = "3d", seed: int = 0
) -> HandEyeResult:
    csv = tmp_path / f"{parent}-{child}-{excitation}-{seed}.csv"
    run_synth_motions(SynthRequest(csv, excitation=excitation, seed=seed, force=True))
    return run_handeye(settings, csv, parent, child).result


def _tf(text: str) -> dict[tuple[str, str], np.ndarray]:
    out = {}
    for tr in yaml.safe_load("\n".join(line for line in text.splitlines() if not line.startswith("#")))[
        "transforms"
    ]:
        t, q = tr["transform"]["translation"], tr["transform"]["rotation"]
        R = se3.rotation_from_quaternion(np.array([q["w"], q["x"], q["y"], q["z"]]))
        out[(tr["header"]["frame_id"], tr["child_frame_id"])] = se3.transform(R, [t["x"], t["y"], t["z"]])
    return out


def _X(result: HandEyeResult) -> np.ndarray:
    assert result.transform is not None
    R = se3.rotation_from_quaternion(np.array(result.transform.rotation_wxyz))
    return se3.transform(R, list(result.transform.translation_m))


def test_an_accepted_edge_is_the_rigs_next_active_version_and_exports_in_the_tree(settings, tmp_path):
    result = _result(tmp_path, settings, "flange", ROOT)
    stored = rig_handeye.store_handeye(settings, RIG, result)
    cal = stored.calibration
    assert stored.active and cal.version == 2 and cal.status == "accepted"
    edge = next(e for e in cal.edges if e.source == "hand-eye")
    assert (edge.parent, edge.child) == ("flange", ROOT)
    assert np.allclose(np.array(edge.T_parent_child), _X(result), atol=1e-12)
    assert cal.handeye == [result]
    assert (
        result.uncertainty is not None
    )  # the translation block is the result's, untouched by the re-expression
    assert np.allclose(
        np.array(edge.covariance)[3:, 3:], np.array(result.uncertainty.covariance)[3:, 3:], rtol=1e-6
    )
    with Store.open(settings.db_url) as store:
        assert store.active_rig_version(RIG) == 2
    tf = _tf(rig_export.export(settings, RIG, "tf", None, force=False, allow_stale=True))
    # the flange is nobody's child: it roots the tree, as the robot's tf needs (base -> ... -> flange)
    assert set(tf) == {("flange", ROOT_FRAME), (ROOT_FRAME, OTHER_FRAME)}
    assert np.allclose(tf[("flange", ROOT_FRAME)], _X(result), atol=1e-9)
    urdf = rig_export.export(settings, RIG, "urdf", None, force=False, allow_stale=True)
    name, root, joints = loadable_urdf(urdf)
    assert (name, root, set(joints)) == (RIG, "flange", {ROOT_FRAME, OTHER_FRAME})
    assert joints[ROOT_FRAME].find("parent").get("link") == "flange"


def test_an_edge_to_a_non_root_camera_hangs_below_it_inverted(settings, tmp_path):
    result = _result(tmp_path, settings, "imu", OTHER)
    rig_handeye.store_handeye(settings, RIG, result)
    tf = _tf(rig_export.export(settings, RIG, "tf", None, force=False, allow_stale=True))
    assert set(tf) == {(ROOT_FRAME, OTHER_FRAME), (OTHER_FRAME, "imu")}
    assert np.allclose(tf[(OTHER_FRAME, "imu")], se3.invert(_X(result)), atol=1e-9)
    # Kalibr still lists only the cameras, each with T_cam_imu (IMU points into the camera frame)
    chain = yaml.safe_load(rig_export.export(settings, RIG, "kalibr", None, force=False, allow_stale=True))
    assert list(chain) == ["cam0", "cam1"] and all(c["timeshift_cam_imu"] == 0.0 for c in chain.values())
    assert np.allclose(chain["cam1"]["T_cam_imu"], se3.invert(_X(result)), atol=1e-9)
    assert [c["rostopic"] for c in chain.values()] == ["/cam_0001/image_raw", "/cam_0002/image_raw"]


def test_a_rejected_result_is_stored_rejected_never_active_and_carries_no_edge(settings, tmp_path):
    good = _result(tmp_path, settings, "imu", OTHER)
    rig_handeye.store_handeye(settings, RIG, good)
    bad = _result(tmp_path, settings, "imu", OTHER, excitation="corridor")
    assert bad.status == "rejected"
    stored = rig_handeye.store_handeye(settings, RIG, bad)
    assert not stored.active and stored.calibration.status == "rejected" and stored.calibration.version == 3
    assert [e.source for e in stored.calibration.edges] == ["rig-solve"]  # not even the old imu edge
    with Store.open(settings.db_url) as store:
        assert store.active_rig_version(RIG) == 2
    lint = rig_lint.lint_rig(settings, f"{RIG}@3")
    gates = [f for f in lint.findings if f.rule == "handeye-gates"]
    assert lint.failed and any("gate lever-arm failed" in f.message for f in gates)
    with pytest.raises(UsageError, match="rejected: a robot must not load it"):
        rig_export.export(settings, f"{RIG}@3", "tf", None, force=False, allow_stale=True)
    assert "imu" not in rig_export.export(
        settings, f"{RIG}@3", "tf", None, force=False, allow_rejected=True, allow_stale=True
    )
    with pytest.raises(UsageError, match="can never become active"):
        rig_lint.rollback(settings, RIG, 3, "try")


def test_history_and_rollback_move_the_hand_eye_edges_with_the_tree(settings, tmp_path):
    first = _result(tmp_path, settings, "imu", OTHER, seed=1)
    second = _result(tmp_path, settings, "imu", OTHER, seed=2)
    rig_handeye.store_handeye(settings, RIG, first)
    rig_handeye.store_handeye(settings, RIG, second)
    cals, active, _ = rig_lint.history(settings, RIG)
    assert [c.version for c in cals] == [1, 2, 3] and active == 3
    assert [h.content_sha256 for h in cals[2].handeye] == [second.content_sha256]  # replaced, not added
    rig_lint.rollback(settings, RIG, 2, "second run looked off")
    assert rig_lint.show(settings, RIG).handeye == [first]


def test_a_camera_recalibrated_after_a_robot_hand_eye_makes_the_edge_stale(settings, tmp_path):
    generic = _result(tmp_path, settings, "flange", ROOT)
    robot = generic.model_copy(
        update={
            "provenance": generic.provenance.model_copy(
                update={"camera": f"{ROOT}@1", "input_shape": "robot-eye-in-hand"}
            )
        }
    ).sealed()
    rig_handeye.store_handeye(settings, RIG, robot)
    assert not [f for f in rig_lint.lint_rig(settings, RIG).findings if f.rule.startswith("handeye-")]
    with Store.open(settings.db_url) as store:
        store.add_artifact(calibration(serial=ROOT), activate=True, **WHO)
        versions = rig_edges.active_versions(store, [ROOT])
        active = store.get_rig_calibration(RIG)
    stale = [f for f in rig_lint.lint_rig(settings, RIG).findings if f.rule == "handeye-stale-member"]
    assert stale and f"{ROOT}@1" in stale[0].message and f"{ROOT}@2" in stale[0].message
    # a rig re-solve does not carry the stale edge; it names it
    kept = rig_edges.carried_forward(active, versions)
    assert kept.edges == [] and kept.evidence["handeye"] == [] and kept.dropped[0].rule == "handeye-dropped"
    assert rig_edges.carried_forward(active, {ROOT: 1}).evidence["handeye"] == [robot]
    # the next hand-eye on the rig drops the stale edge too (named), instead of being rejected for it
    nxt = rig_handeye.store_handeye(settings, RIG, _result(tmp_path, settings, "imu", OTHER)).calibration
    assert nxt.status == "accepted" and [h.parent_frame for h in nxt.handeye] == ["imu"]
    assert [f.rule for f in nxt.lint] == ["handeye-dropped"] and "flange -> CAM-0001" in nxt.lint[0].message
    # re-running the stale one replaces it: no warning about itself
    fresh = robot.model_copy(
        update={"provenance": robot.provenance.model_copy(update={"camera": f"{ROOT}@2"})}
    )
    again = rig_handeye.store_handeye(settings, RIG, fresh.sealed()).calibration
    assert again.status == "accepted" and again.lint == [] and len(again.handeye) == 2


def test_refusals_name_what_is_wrong(settings, tmp_path):
    rig_handeye.check_target(settings, RIG, "imu", ROOT)  # the valid target passes
    with pytest.raises(NotFoundError, match="unknown rig 'NOPE'"):
        rig_handeye.check_target(settings, "NOPE", "imu", OTHER)
    with pytest.raises(NotFoundError, match="frame 'gps' is not in rig"):
        rig_handeye.check_target(settings, RIG, "gps", OTHER)
    with pytest.raises(UsageError, match="both cameras"):
        rig_handeye.check_target(settings, RIG, ROOT, OTHER)
    with pytest.raises(UsageError, match="does not connect"):
        rig_handeye.check_target(settings, RIG, "imu", "lidar")
    rig_handeye.store_handeye(settings, RIG, _result(tmp_path, settings, "imu", OTHER))
    with pytest.raises(UsageError, match="already has the edge imu -> CAM-0002"):
        rig_handeye.check_target(settings, RIG, OTHER, "imu")
    with pytest.raises(UsageError, match="closes a loop"):
        rig_handeye.check_target(settings, RIG, "imu", ROOT)
    with Store.open(settings.db_url) as store:
        store.add_rig(rig_definition("EMPTY").model_copy(update={"frames": ["imu"]}))
    with pytest.raises(NotFoundError, match="camera CAM-0009 has no active calibration"):
        rig_handeye.check_target(settings, RIG, "imu", OTHER, serial="CAM-0009")
    with pytest.raises(NotFoundError, match="rig EMPTY has no active version"):
        rig_handeye.check_target(settings, "EMPTY", "imu", ROOT)
