"""Rig versions and hand-eye results are hashed over RFC 8785 (JCS) like camera artifacts, checked against an
independent implementation (PyPI rfc8785) on the exported JSON; versions hashed the old way still verify."""

from __future__ import annotations

import hashlib
import json

import rfc8785

from calibctl.artifacts.common import CURRENT_HASH, LEGACY_HASH, canonical_json_bytes
from calibctl.artifacts.handeye import HandEyeResult
from calibctl.artifacts.rig import RigCalibration
from tests.artifacts.test_handeye_contract import _result
from tests.store.rig_documents import rig_calibration


def _independent(doc: dict) -> str:
    """What a robot in any language does: parse the export, drop content_sha256, JCS, sha256."""
    doc = dict(doc)
    doc.pop("content_sha256")
    return hashlib.sha256(rfc8785.dumps(doc)).hexdigest()


def test_a_sealed_rig_version_and_its_hand_eye_result_hash_over_jcs():
    result = _result().sealed()
    cal = rig_calibration().model_copy(update={"handeye": [result]}).sealed()
    assert (cal.content_hash_algorithm, result.content_hash_algorithm) == (CURRENT_HASH, CURRENT_HASH)
    for doc in (json.loads(cal.model_dump_json()), json.loads(result.model_dump_json())):
        assert doc["content_hash_algorithm"] == CURRENT_HASH and _independent(doc) == doc["content_sha256"]
    edited = json.loads(cal.model_dump_json())
    edited["edges"][0]["translation_mm"] += 0.001
    assert _independent(edited) != cal.content_sha256
    assert RigCalibration.model_validate(edited).computed_sha256() != cal.content_sha256


def _legacy(model: RigCalibration | HandEyeResult) -> dict:
    """A document as calibctl wrote it before the algorithm field: Python-JSON form, no field."""
    doc = json.loads(model.model_dump_json())
    doc.pop("content_hash_algorithm", None)
    doc.pop("content_sha256")
    return {**doc, "content_sha256": hashlib.sha256(canonical_json_bytes(doc)).hexdigest()}


def test_versions_hashed_the_old_way_still_verify_and_cannot_be_relabelled():
    old_result = _legacy(_result().sealed())
    loaded = HandEyeResult.model_validate(old_result)
    assert (
        loaded.content_hash_algorithm == LEGACY_HASH
        and loaded.computed_sha256() == old_result["content_sha256"]
    )
    assert "content_hash_algorithm" not in json.loads(
        loaded.model_dump_json()
    )  # its dump, and hash, unchanged
    old_rig = _legacy(rig_calibration().model_copy(update={"handeye": [loaded]}).sealed())
    rig = RigCalibration.model_validate(old_rig)
    assert rig.content_hash_algorithm == LEGACY_HASH and rig.computed_sha256() == old_rig["content_sha256"]
    relabelled = RigCalibration.model_validate({**old_rig, "content_hash_algorithm": CURRENT_HASH})
    assert relabelled.computed_sha256() != old_rig["content_sha256"]
