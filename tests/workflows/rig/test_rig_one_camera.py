"""A one-camera rig in the library: registered, its version pins the member's active calibration, a hand-eye
edge joins it; no camera at all is still refused."""

from __future__ import annotations

import numpy as np
import pytest
from pydantic import ValidationError

from calibctl.artifacts.rig import RigDefinition
from calibctl.config import Settings, load_settings
from calibctl.errors import UsageError
from calibctl.store.repository import Store
from calibctl.workflows.handeye import rig_handeye
from calibctl.workflows.rig import rig_lint, rigs
from tests.artifacts.factories import calibration
from tests.store.rig_documents import rig_definition
from tests.workflows.handeye.test_rig_handeye import WHO, _result

CAM = "CAM-0001"
MONO = "MONO-1"


@pytest.fixture
def settings(sqlite_url: str) -> Settings:
    s = load_settings(db=sqlite_url, station="st-test", operator="tester", env={})
    with Store.open(s.db_url) as store:
        store.add_artifact(calibration(serial=CAM), activate=True, **WHO)
    rigs.add_rig(s, MONO, [CAM], None, [], ["flange"])
    return s


def test_the_version_of_a_one_camera_rig_pins_its_active_calibration(settings) -> None:
    out = rigs.solve_rig_stored(settings, MONO)
    cal = out.calibration
    with Store.open(settings.db_url) as store:
        art = store.get_artifact(CAM, None)
    (m,) = cal.members
    assert out.active and cal.status == "accepted" and cal.root == CAM
    assert (m.serial, m.version, m.content_sha256) == (CAM, art.version, art.content_sha256)
    assert np.array_equal(m.camera_matrix, art.camera_matrix) and m.dist_coeffs == art.dist_coeffs
    assert (cal.edges, cal.pairs, cal.fit_rms_px) == ([], [], {CAM: art.rms_px})
    assert not rig_lint.lint_rig(settings, MONO).failed


def test_a_hand_eye_edge_joins_a_one_camera_rig(settings, tmp_path) -> None:
    rigs.solve_rig_stored(settings, MONO)
    stored = rig_handeye.store_handeye(settings, MONO, _result(tmp_path, settings, "flange", CAM))
    assert stored.active and stored.calibration.version == 2
    assert [(e.parent, e.child, e.source) for e in stored.calibration.edges] == [("flange", CAM, "hand-eye")]


def test_a_rig_still_needs_a_camera(settings) -> None:
    with pytest.raises(UsageError, match="at least one camera"):
        rigs.add_rig(settings, "EMPTY", [], None, [])
    with pytest.raises(ValidationError, match="at least 1 item"):
        RigDefinition.model_validate({**rig_definition().model_dump(), "cameras": [], "design_baselines": []})
