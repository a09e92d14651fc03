"""The hand-eye result document: an accepted edge needs a transform and passed gates; a rejected one has
none."""

from __future__ import annotations

import datetime as dt

import pytest
from pydantic import ValidationError

from calibctl.artifacts.handeye import EdgeGate, EdgeProvenance, HandEyeResult, RigidTransform

UNSEALED = "0" * 64


def _result(**changes) -> HandEyeResult:
    data = {
        "parent_frame": "lidar",
        "child_frame": "camera",
        "status": "accepted",
        "method": "park",
        "transform": RigidTransform(translation_m=(0.3, 0.1, 0.0), rotation_wxyz=(1.0, 0.0, 0.0, 0.0)),
        "uncertainty": None,
        "gates": [EdgeGate(gate="lever-arm", passed=True, value=1.2, threshold=0.5, message="ok")],
        "lever_arm_singular_values": (2.0, 1.5, 1.2),
        "motions": [],
        "provenance": EdgeProvenance(
            calibctl_version="0.1.0",
            opencv_version="5.0.0",
            station="s",
            operator="o",
            created_at=dt.datetime(2026, 11, 23, tzinfo=dt.UTC),
            input_file="m.csv",
            input_sha256="a" * 64,
            input_shape="poses",
        ),
        "content_sha256": UNSEALED,
    }
    data.update(changes)
    return HandEyeResult(**data)


def test_sealed_result_hash_detects_a_change():
    doc = _result().sealed()
    assert doc.content_sha256 == doc.computed_sha256()
    assert doc.model_copy(update={"child_frame": "camera2"}).computed_sha256() != doc.content_sha256
    assert HandEyeResult.model_validate_json(doc.model_dump_json()) == doc


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"transform": None}, "an accepted result needs a transform and every gate passed"),
        (
            {
                "gates": [
                    EdgeGate(
                        gate="lever-arm", passed=False, value=0.03, threshold=0.5, message="unobservable"
                    )
                ]
            },
            "an accepted result needs a transform and every gate passed",
        ),
        ({"status": "rejected"}, "a rejected result carries no transform"),
        ({"child_frame": "lidar"}, "parent_frame and child_frame must differ"),
    ],
)
def test_inconsistent_documents_are_refused(changes, message):
    with pytest.raises(ValidationError, match=message):
        _result(**changes)


def test_a_rotation_must_be_a_unit_quaternion():
    with pytest.raises(ValidationError, match="unit quaternion"):
        RigidTransform(translation_m=(0.0, 0.0, 0.0), rotation_wxyz=(1.0, 0.1, 0.0, 0.0))
