"""`calibctl imu solve --imu-model`: an unknown model is exit 2 in one line; a recording too short to pin
the scale-misalignment model is exit 1, the gate naming the model and the fix, stored never active; the
Kalibr imu.yaml export carries a solved model in Kalibr's own fields, and lint checks them."""

from __future__ import annotations

import json

import numpy as np
import yaml

from calibctl.artifacts.imu import ImuModelEstimate
from calibctl.config import LintThresholds
from calibctl.core.imu import intrinsics
from calibctl.workflows.exports.rig_exports import kalibr_imu
from calibctl.workflows.lint.rig_files import lint_rig_file
from tests.artifacts.test_imu_contract import imu_model_estimate, imu_result
from tests.store.rig_documents import RIG
from tests.workflows.imu.imu_data import CAM, cli, make_store


def test_an_unknown_imu_model_is_exit_2_in_one_line(recording, tmp_path) -> None:
    url = make_store(tmp_path / "c.db")
    r = cli(url, "imu", "solve", str(recording), "--serial", CAM, "--imu-model", "scaled", "--rig", RIG)
    assert r.exit_code == 2 and len([x for x in r.output.splitlines() if x.startswith("Error:")]) == 1
    assert "unknown --imu-model 'scaled'" in r.output and "scale-misalignment" in r.output
    assert "Traceback" not in r.output
    assert json.loads(cli(url, "rig", "history", RIG, "--json").stdout)["versions"][-1]["version"] == 1


def test_a_recording_that_cannot_pin_the_model_is_exit_1_and_never_active(recording, tmp_path) -> None:
    url = make_store(tmp_path / "c.db")
    args = ["--noise", str(recording / "imu.yaml"), "--imu-model", "scale-misalignment", "--rig", RIG]
    r = cli(url, "imu", "solve", str(recording), "--serial", CAM, *args, "-o", str(tmp_path / "o.json"))
    assert r.exit_code == 1, r.output
    assert "Result: REJECTED" in r.output and "IMU model scale-misalignment" in r.output
    assert "  M_gyro: xx " in r.output and "  A_gyro: xx " in r.output  # each state with its sigma
    doc = json.loads((tmp_path / "o.json").read_text())
    (gate,) = [g for g in doc["gates"] if g["gate"] == "imu_model_observability"]
    assert not gate["passed"] and "IMU model scale-misalignment" in gate["message"]
    assert "--imu-model calibrated" in gate["hint"]
    states = doc["estimate"]["imu_intrinsics"]["states"]
    assert doc["estimate"]["imu_model"] == "scale-misalignment" and tuple(states) == intrinsics.NAMES
    history = json.loads(cli(url, "rig", "history", RIG, "--json").stdout)
    assert history["active_version"] == 1
    assert history["versions"][-1]["imu"] == [{"edge": f"imu:{CAM}", "status": "rejected"}]


def test_the_kalibr_imu_yaml_carries_the_model_in_kalibrs_fields() -> None:
    noise = imu_result().noise
    x = np.arange(24) * 1e-4
    M_g, C, A_g, M_a = intrinsics.matrices(x)

    def rows(M: np.ndarray) -> list[list[float]]:
        return [[float(v) for v in row] for row in M]

    model = ImuModelEstimate.model_validate(
        {
            "model": "scale-misalignment",
            "gyro_M": rows(M_g),
            "gyro_C_gyro_i": rows(C),
            "gyro_A": rows(A_g),
            "accel_M": rows(M_a),
            "states": dict(zip(intrinsics.NAMES, x.tolist(), strict=True)),
            "sigmas": dict(zip(intrinsics.NAMES, [1e-3] * 24, strict=True)),
            "prior_sigmas": dict(zip(intrinsics.NAMES, intrinsics.PRIOR_SIGMAS.tolist(), strict=True)),
            "min_information": 500.0,
        }
    )
    plain = yaml.safe_load(kalibr_imu(noise))
    assert "model" not in plain  # Kalibr reads a file without one as its calibrated IMU
    doc = yaml.safe_load(kalibr_imu(noise, "/imu0", model))
    assert {k: doc[k] for k in plain} == plain and doc["model"] == "scale-misalignment"
    assert np.array_equal(doc["gyroscopes"]["M"], M_g) and np.array_equal(doc["accelerometers"]["M"], M_a)
    assert np.array_equal(doc["gyroscopes"]["A"], A_g) and np.array_equal(doc["gyroscopes"]["C_gyro_i"], C)


def test_lint_checks_the_model_in_a_kalibr_imu_yaml(tmp_path) -> None:
    C = intrinsics.matrices(np.r_[np.zeros(6), [0.01, 0.0, 0.0], np.zeros(15)])[1]
    model = imu_model_estimate().model_copy(update={"gyro_C_gyro_i": tuple(map(tuple, C.tolist()))})
    path = tmp_path / "imu.yaml"
    path.write_text(kalibr_imu(imu_result().noise, "/imu0", model))
    (result,) = lint_rig_file(path, LintThresholds())
    assert result.kind == "kalibr-imu" and not [f for f in result.findings if f.severity == "error"]
    doc = yaml.safe_load(path.read_text())
    doc["gyroscopes"]["C_gyro_i"][0][0] = 1.5
    doc["accelerometers"]["M"] = [[1.0, 0.0], [0.0, 1.0]]
    path.write_text(yaml.safe_dump(doc))
    (result,) = lint_rig_file(path, LintThresholds())
    errors = [f.message for f in result.findings if f.severity == "error"]
    assert "gyroscopes.C_gyro_i is not a rotation (R R^T != I or det != 1)" in errors
    assert "accelerometers.M is not a 3x3 matrix of numbers" in errors
