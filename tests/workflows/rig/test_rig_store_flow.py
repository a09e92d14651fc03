"""The stored rig flow on a rendered 75 mm pair: register, capture, solve, lint (stale member,
design baseline), history, rollback, export; and every refusal with its message."""

from __future__ import annotations

import json

import numpy as np
import pytest

from calibctl.config import load_settings
from calibctl.errors import AlreadyExistsError, InputError, NotFoundError, UsageError
from calibctl.store.repository import Store
from calibctl.workflows.rig import rig_export, rig_lint, rigs
from tests.artifacts.factories import calibration, measured_board
from tests.workflows.rig_folders_data import rendered_rig, true_baseline_mm

WHO = {"actor": "qa", "station": "st1", "reason": "solved"}


@pytest.fixture(scope="module")
def rig2(tmp_path_factory):
    return rendered_rig(tmp_path_factory)


def _truth_artifact(rig2, name, **extra):
    cam = next(c for c in json.loads((rig2 / "rig_truth.json").read_text())["cameras"] if c["name"] == name)
    K = np.array(cam["K"])
    return calibration(
        serial=name, fx=K[0, 0], cx=K[0, 2], cy=K[1, 2], board=measured_board(square_mm=25.0), **extra
    )


def store_members(url, rig2) -> str:
    """``url`` with board A17 and CAM0 / CAM1 of the 2-camera render stored at their true lenses, active."""
    with Store.open(url) as store:
        store.add_board(measured_board(square_mm=25.0))
        for name in ("CAM0", "CAM1"):
            store.add_artifact(_truth_artifact(rig2, name), activate=True, **WHO)
    return url


@pytest.fixture
def settings(tmp_path, rig2):
    s = load_settings(db=f"sqlite:///{tmp_path / 'r.db'}", station="st-test", operator="tester", env={})
    store_members(s.db_url, rig2)
    return s


def _sources(rig2):
    return {"CAM0": str(rig2 / "CAM0"), "CAM1": str(rig2 / "CAM1")}


def test_register_capture_solve_lint(settings, rig2):
    rigs.add_rig(settings, "R1", ["CAM0", "CAM1"], None, ["CAM0:CAM1=75.0+-0.5"])
    cap = rigs.capture_rig(settings, "R1", _sources(rig2), "A17")
    assert cap.passed and len(cap.session.frames) == 8 and cap.session.shared_views == {"CAM0-CAM1": 8}
    out = rigs.solve_rig_stored(settings, "R1")
    cal = out.calibration
    assert cal.status == "accepted" and out.active and cal.version == 1 and cal.lint == []
    edge = cal.edges[0]
    assert (edge.parent, edge.child) == ("CAM0", "CAM1")
    assert abs(edge.translation_mm - true_baseline_mm(rig2)) < 3 * edge.sigma_translation_mm
    assert [(m.serial, m.version) for m in cal.members] == [("CAM0", 1), ("CAM1", 1)]
    assert cal.pairs[0].epipolar_rms_px is not None and cal.pairs[0].epipolar_rms_px < 0.1
    assert not rig_lint.lint_rig(settings, "R1").failed


def test_recalibrating_a_member_makes_rig_lint_fail_until_the_rig_is_re_solved(settings, rig2):
    rigs.add_rig(settings, "R1", ["CAM0", "CAM1"], None, [])
    rigs.capture_rig(settings, "R1", _sources(rig2), "A17")
    rigs.solve_rig_stored(settings, "R1")
    with Store.open(settings.db_url) as store:
        store.add_artifact(_truth_artifact(rig2, "CAM1"), activate=True, **WHO)  # CAM1@2
    stale = rig_lint.lint_rig(settings, "R1")
    assert stale.failed and [f.rule for f in stale.findings] == ["rig-stale-member"]
    assert "solved with CAM1@1, the active one is now CAM1@2" in stale.findings[0].message
    again = rigs.solve_rig_stored(settings, "R1")
    assert again.calibration.version == 2 and not rig_lint.lint_rig(settings, "R1").failed
    cals, active, events = rig_lint.history(settings, "R1")
    assert [c.version for c in cals] == [1, 2] and active == 2
    rig_lint.rollback(settings, "R1", 1, "compare")
    assert rig_lint.lint_rig(settings, "R1").failed  # v1 is stale, and it is active again


def test_a_baseline_off_its_design_is_rejected_and_never_active(settings, rig2):
    rigs.add_rig(settings, "R1", ["CAM0", "CAM1"], None, ["CAM0:CAM1=80+-0.5"])
    rigs.capture_rig(settings, "R1", _sources(rig2), "A17")
    out = rigs.solve_rig_stored(settings, "R1")
    assert out.calibration.status == "rejected" and not out.active
    assert [f.rule for f in out.calibration.lint] == ["baseline-design"]
    with pytest.raises(NotFoundError, match="no active version"):
        rig_lint.show(settings, "R1")


def test_exports_of_a_stored_rig(settings, rig2, tmp_path):
    import cv2
    import yaml

    rigs.add_rig(settings, "R1", ["CAM0", "CAM1"], None, [])
    rigs.capture_rig(settings, "R1", _sources(rig2), "A17")
    rigs.solve_rig_stored(settings, "R1")
    kalibr = yaml.safe_load(rig_export.export(settings, "R1", "kalibr", None, force=False))
    assert np.allclose(
        np.linalg.norm(np.array(kalibr["cam1"]["T_cn_cnm1"])[:3, 3]) * 1e3, true_baseline_mm(rig2), atol=0.2
    )
    path = tmp_path / "stereo.yaml"
    rig_export.export(settings, "R1@1", "opencv", path, force=False)
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    assert fs.getNode("P2").mat().shape == (3, 4)
    fs.release()
    for fmt in ("tf", "urdf"):
        assert "cam1_optical_frame" in rig_export.export(settings, "R1", fmt, None, force=False)
    assert "CAM1" in rig_export.export(settings, "R1", "json", None, force=False)
    with pytest.raises(UsageError, match="ROS reads only the first YAML document"):
        rig_export.export(settings, "R1", "ros", None, force=False)
    # the stereo FileStorage goes to stdout like every other format, byte for byte what -o wrote
    assert rig_export.export(settings, "R1@1", "opencv", None, force=False) == path.read_text(
        encoding="utf-8"
    )
    with pytest.raises(AlreadyExistsError, match="already exists"):
        rig_export.export(settings, "R1@1", "opencv", path, force=False)


def test_registry_refusals(settings):
    with pytest.raises(NotFoundError, match="unknown camera.*CAM7"):
        rigs.add_rig(settings, "R1", ["CAM0", "CAM7"], None, [])
    with pytest.raises(UsageError, match="camera CAM0 is listed twice"):
        rigs.add_rig(settings, "R1", ["CAM0", "CAM0"], None, [])
    with pytest.raises(UsageError, match="A:B=75.0"):
        rigs.add_rig(settings, "R1", ["CAM0", "CAM1"], None, ["CAM0-CAM1=75"])
    with pytest.raises(UsageError, match="--root CAM5 is not one of the cameras"):
        rigs.add_rig(settings, "R1", ["CAM0", "CAM1"], "CAM5", [])


def test_capture_refusals(settings, rig2):
    rigs.add_rig(settings, "R1", ["CAM0", "CAM1"], None, [])
    with pytest.raises(UsageError, match="no --source for CAM1"):
        rigs.capture_rig(settings, "R1", {"CAM0": str(rig2 / "CAM0")}, "A17")
    with pytest.raises(NotFoundError, match="unknown rig 'R9'"):
        rigs.capture_rig(settings, "R9", _sources(rig2), "A17")
    gated = rigs.capture_rig(settings, "R1", _sources(rig2), "A17", min_shared_views=20)
    assert not gated.passed and "CAM0-CAM1 shares 8 view(s) (needs 20)" in gated.session.gates[0].message
    with pytest.raises(NotFoundError, match="no an accepted rig session"):
        rigs.solve_rig_stored(settings, "R1")


def test_a_member_without_an_active_calibration_is_refused(settings, rig2):
    with Store.open(settings.db_url) as store:
        store.add_artifact(
            _truth_artifact(rig2, "CAM1").model_copy(update={"serial": "CAM9", "status": "rejected"}),
            activate=False,
            **WHO,
        )
    rigs.add_rig(settings, "R1", ["CAM0", "CAM9"], None, [])
    rigs.capture_rig(settings, "R1", {"CAM0": str(rig2 / "CAM0"), "CAM9": str(rig2 / "CAM1")}, "A17")
    with pytest.raises(NotFoundError, match="rig member CAM9 has no active calibration"):
        rigs.solve_rig_stored(settings, "R1")
    # nothing that looks like a rig calibration was stored
    with Store.open(settings.db_url) as store, pytest.raises(NotFoundError, match="has no calibration yet"):
        store.get_rig_calibration("R1")


def test_a_capture_at_another_resolution_than_the_members_calibration_is_refused(settings, rig2):
    with Store.open(settings.db_url) as store:
        store.add_artifact(_truth_artifact(rig2, "CAM1", image_size=(1280, 960)), activate=True, **WHO)
    rigs.add_rig(settings, "R1", ["CAM0", "CAM1"], None, [])
    rigs.capture_rig(settings, "R1", _sources(rig2), "A17")
    with pytest.raises(InputError, match="capture is 640x480 but its calibration CAM1@2 is 1280x960"):
        rigs.solve_rig_stored(settings, "R1")


def test_refine_intrinsics_moves_a_wrong_member_focal_length_back(settings, rig2):
    with Store.open(settings.db_url) as store:  # CAM1@2: focal length 1 % off the renderer's
        good = _truth_artifact(rig2, "CAM1")
        fx = good.camera_matrix[0][0]
        store.add_artifact(
            _truth_artifact(rig2, "CAM1").model_copy(
                update={
                    "camera_matrix": (
                        (fx * 1.01, 0.0, good.camera_matrix[0][2]),
                        (0.0, fx * 1.01, good.camera_matrix[1][2]),
                        (0.0, 0.0, 1.0),
                    )
                }
            ),
            activate=True,
            **WHO,
        )
    rigs.add_rig(settings, "R1", ["CAM0", "CAM1"], None, [])
    rigs.capture_rig(settings, "R1", _sources(rig2), "A17")
    fixed = rigs.solve_rig_stored(settings, "R1").calibration
    refined = rigs.solve_rig_stored(settings, "R1", refine_intrinsics=True).calibration
    cam1 = next(m for m in refined.members if m.serial == "CAM1")
    assert cam1.refined and abs(cam1.camera_matrix[0][0] - fx) < 0.2 * abs(0.01 * fx)
    assert refined.fit_rms_px["CAM1"] < fixed.fit_rms_px["CAM1"]
