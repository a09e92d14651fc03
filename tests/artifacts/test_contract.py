"""The artifact contract: validation, hashing and JSON round trips."""

from __future__ import annotations

import json
import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pydantic import ValidationError

from calibctl.artifacts.board import BoardRevision, SquareMeasurement, parse_board_ref
from calibctl.artifacts.calibration import CalibrationArtifact
from calibctl.artifacts.common import SERIAL_PATTERN, parse_document
from calibctl.errors import InputError
from tests.artifacts.factories import calibration, measured_board, nominal_board


def test_sealed_artifact_hash_matches_and_detects_any_change():
    art = calibration()
    assert art.content_sha256 == art.computed_sha256()
    changed = art.model_copy(update={"rms_px": 0.285})
    assert changed.computed_sha256() != art.content_sha256


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_non_finite_numbers_are_refused(bad):
    data = calibration().model_dump(mode="python")
    data["rms_px"] = bad
    with pytest.raises(ValidationError, match="finite"):
        CalibrationArtifact.model_validate(data)


def test_unknown_fields_are_refused_with_their_path():
    data = calibration().model_dump(mode="json")
    data["provenance"]["stattion"] = "typo"
    with pytest.raises(InputError, match=r"provenance\.stattion: Extra inputs are not permitted"):
        parse_document(CalibrationArtifact, data, "cam.json")


def test_many_field_errors_name_the_first_three_and_count_the_rest():
    data = calibration().model_dump(mode="json")
    for typo in ("stattion", "operater", "hostt", "clock", "site"):
        data["provenance"][typo] = "typo"
    with pytest.raises(InputError) as bad:
        parse_document(CalibrationArtifact, data, "cam.json")
    message = bad.value.message
    assert message.startswith("cam.json is not a valid document: provenance.")
    assert message.count("Extra inputs are not permitted") == 3 and message.endswith(" and 2 more")
    assert bad.value.exit_code == 2


def test_camera_matrix_must_be_a_camera_matrix():
    data = calibration().model_dump(mode="json")
    data["camera_matrix"][2] = [0.0, 0.0, 2.0]
    with pytest.raises(ValidationError, match="upper triangular"):
        CalibrationArtifact.model_validate(data)


def test_measured_square_size_requires_full_provenance():
    with pytest.raises(ValidationError, match="needs uncertainty_m, instrument, measured_by, measured_on"):
        SquareMeasurement(status="measured", square_size_m=0.025)
    assert nominal_board().measurement.status == "nominal"


def test_charuco_board_needs_marker_and_dictionary():
    data = measured_board().model_dump(mode="python")
    data["kind"] = "charuco"
    with pytest.raises(ValidationError, match="needs marker_size_m and dictionary"):
        BoardRevision.model_validate(data)
    data.update(marker_size_m=0.018, dictionary="DICT_5X5_100")
    assert BoardRevision.model_validate(data).ref == "A17@1"


def test_naive_timestamps_are_refused():
    data = measured_board().model_dump(mode="python")
    data["created_at"] = data["created_at"].replace(tzinfo=None)
    with pytest.raises(ValidationError, match="timezone"):
        BoardRevision.model_validate(data)


@pytest.mark.parametrize(
    ("ref", "expected"), [("A17", ("A17", None)), ("A17@2", ("A17", 2)), ("board-3.x@10", ("board-3.x", 10))]
)
def test_board_refs_parse(ref, expected):
    assert parse_board_ref(ref) == expected


@pytest.mark.parametrize("ref", ["", "@2", "A17@", "A17@x", "a b"])
def test_bad_board_refs_are_refused(ref):
    with pytest.raises(ValueError, match="not a board reference"):
        parse_board_ref(ref)


finite = st.floats(min_value=-1e6, max_value=1e6, allow_nan=False, allow_infinity=False)


@settings(max_examples=60, deadline=None)
@given(
    fx=st.floats(min_value=50, max_value=5000),
    cx=finite,
    cy=finite,
    rms=st.floats(min_value=0, max_value=50),
    serial=st.from_regex(SERIAL_PATTERN, fullmatch=True).filter(lambda s: len(s) <= 40),
    version=st.integers(min_value=1, max_value=10_000),
)
def test_json_round_trip_is_exact_and_hash_stable(fx, cx, cy, rms, serial, version):
    art = calibration(serial=serial, version=version, fx=fx, cx=cx, cy=cy)
    art = art.model_copy(update={"rms_px": rms}).sealed()
    text = json.dumps(art.model_dump(mode="json"))
    back = parse_document(CalibrationArtifact, json.loads(text), "round-trip")
    assert back == art
    assert back.computed_sha256() == art.content_sha256


@pytest.mark.parametrize("serial", ["", "CAM@2", "has space", "-lead", "tab\tx"])
def test_serials_that_would_be_ambiguous_or_unsafe_are_refused(serial):
    with pytest.raises(ValidationError, match="serial"):
        calibration(serial=serial)


def test_rig_hand_eye_fields_are_absent_while_empty_and_frames_are_checked() -> None:
    """`frames` and `handeye` joined the rig documents later: absent while empty, so older rows hash the
    same."""
    import pydantic

    from tests.store.rig_documents import rig_calibration, rig_definition

    cal = rig_calibration().sealed()
    assert "handeye" not in cal.model_dump(mode="json") and "frames" not in rig_definition().model_dump(
        mode="json"
    )
    assert rig_definition().model_copy(update={"frames": ["imu"]}).model_dump(mode="json")["frames"] == [
        "imu"
    ]
    data = rig_definition().model_dump(mode="json")
    for frames in (["CAM-0001"], ["imu", "imu"]):
        with pytest.raises(pydantic.ValidationError, match="listed twice"):
            type(rig_definition()).model_validate({**data, "frames": frames})
