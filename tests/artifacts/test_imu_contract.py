"""The camera-IMU evidence document: its covariance layout is checked, and a rig version without an IMU
edge dumps (and hashes) exactly as before the field existed."""

from __future__ import annotations

import json

import numpy as np
import pytest
from pydantic import ValidationError

from calibctl.artifacts.imu import ImuEdgeResult, ImuEstimate, ImuGate, ImuModelEstimate, ImuNoiseModel
from tests.artifacts.factories import FIXED_TIME
from tests.store.rig_documents import rig_calibration


def imu_estimate(covariance: list[list[float]] | None = None) -> ImuEstimate:
    return ImuEstimate(
        T_imu_cam=tuple(map(tuple, np.eye(4).tolist())),
        quaternion_wxyz=(1.0, 0.0, 0.0, 0.0),
        td_s=0.012,
        td_held=False,
        covariance=covariance if covariance is not None else (np.eye(7) * 1e-6).tolist(),
        sigma_translation_mm=(1.0, 1.0, 1.0),
        sigma_rotation_deg=(0.05, 0.05, 0.05),
        sigma_td_ms=0.1,
        td_crlb_ms=0.05,
        gyro_bias_rad_s=(0.0, 0.0, 0.0),
        accel_bias_m_s2=(0.0, 0.0, 0.0),
        gravity_board_m_s2=(0.0, 9.81, 0.0),
    )


def imu_result(estimate: ImuEstimate | None = None) -> ImuEdgeResult:
    return ImuEdgeResult(
        parent_frame="imu",
        child_frame="CAM-0001",
        status="accepted",
        camera="CAM-0001@1",
        recording="rec",
        estimate=estimate if estimate is not None else imu_estimate(),
        noise=ImuNoiseModel(
            gyro_noise_density=1.7e-4,
            accel_noise_density=2e-3,
            gyro_random_walk=1e-5,
            accel_random_walk=1e-4,
            gravity_m_s2=9.81,
            rate_hz=200.0,
            variance_factors=(1.0, 1.0),
            source="defaults",
        ),
        metrics=None,
        gates=[ImuGate(gate="imu_gaps", passed=True, value=0.0, threshold=5.0, message="no gap")],
        inputs=[],
        created_at=FIXED_TIME,
    )


def test_the_covariance_must_be_seven_by_seven() -> None:
    with pytest.raises(ValidationError, match="covariance must be 7x7"):
        imu_estimate((np.eye(6) * 1e-6).tolist())


def test_the_td_convention_is_fixed_in_the_document() -> None:
    doc = json.loads(imu_result().model_dump_json())
    assert doc["td_convention"].startswith("t_imu = t_cam + td_s")
    doc["td_convention"] = "t_cam = t_imu + td_s"
    with pytest.raises(ValidationError):
        ImuEdgeResult.model_validate(doc)


def test_a_rig_version_without_an_imu_edge_hashes_as_before_and_one_with_it_carries_it() -> None:
    cal = rig_calibration().sealed()
    assert "imu" not in json.loads(cal.model_dump_json())
    with_imu = cal.model_copy(update={"imu": [imu_result()]}).sealed()
    doc = json.loads(with_imu.model_dump_json())
    assert doc["imu"][0]["estimate"]["td_s"] == 0.012
    assert with_imu.content_sha256 != cal.content_sha256
    edited = dict(doc, imu=[dict(doc["imu"][0], estimate=dict(doc["imu"][0]["estimate"], td_s=0.013))])
    assert type(with_imu).model_validate(edited).computed_sha256() != with_imu.content_sha256


def imu_model_estimate() -> ImuModelEstimate:
    eye = tuple(map(tuple, np.eye(3).tolist()))
    zero = tuple(map(tuple, np.zeros((3, 3)).tolist()))
    return ImuModelEstimate(
        model="scale-misalignment",
        gyro_M=eye,
        gyro_C_gyro_i=eye,
        gyro_A=zero,
        accel_M=eye,
        states={"mg_xx": 0.001},
        sigmas={"mg_xx": 0.0005},
        prior_sigmas={"mg_xx": 0.02},
        min_information=250.0,
    )


def test_an_estimate_without_an_imu_model_dumps_as_before_and_one_with_it_round_trips() -> None:
    plain = imu_result()
    assert "imu_model" not in json.loads(plain.model_dump_json())["estimate"]
    with_model = imu_result(imu_estimate().model_copy(update={"imu_model": imu_model_estimate()}))
    doc = json.loads(with_model.model_dump_json())
    assert doc["estimate"]["imu_model"]["model"] == "scale-misalignment"
    assert ImuEdgeResult.model_validate(doc) == with_model
    cal = rig_calibration()
    one, two = (cal.model_copy(update={"imu": [r]}).sealed() for r in (plain, with_model))
    assert one.content_sha256 != two.content_sha256
