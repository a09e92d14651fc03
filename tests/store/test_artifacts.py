"""Calibration artifacts, versions, activation and rollback -- on SQLite and on PostgreSQL."""

from __future__ import annotations

from collections.abc import Iterator

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from calibctl.artifacts.calibration import UNSEALED
from calibctl.artifacts.common import SERIAL_PATTERN
from calibctl.errors import AlreadyExistsError, IntegrityError, NotFoundError, UsageError
from calibctl.store.repository import Store
from tests.artifacts.factories import calibration

WHO = {"actor": "qa", "station": "st1"}


@pytest.fixture
def store(db_url: str) -> Iterator[Store]:
    with Store.open(db_url) as opened:
        yield opened


def add(store: Store, serial: str = "CAM-0001", status: str = "accepted", activate: bool | None = None, **kw):
    activate = status == "accepted" if activate is None else activate
    return store.add_artifact(
        calibration(serial=serial, status=status, **kw), activate=activate, reason="solved", **WHO
    )


def test_round_trip_returns_an_equal_sealed_artifact(store: Store):
    draft = calibration(version=1).model_copy(update={"content_sha256": UNSEALED, "version": 7})
    stored = store.add_artifact(draft, activate=True, reason="first solve", **WHO)
    assert stored.version == 1  # the store allocates versions; the draft's 7 is ignored
    assert stored.content_sha256 == stored.computed_sha256() != UNSEALED
    assert store.get_artifact("CAM-0001", 1) == stored
    assert store.get_artifact("CAM-0001") == stored  # the active version
    assert store.list_artifacts("CAM-0001") == [stored]


@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    fx=st.floats(min_value=50.0, max_value=20000.0, allow_nan=False),
    rms_px=st.floats(min_value=0.0, max_value=50.0, allow_nan=False),
    serial=st.from_regex(SERIAL_PATTERN, fullmatch=True).filter(lambda s: len(s) <= 40),
    accepted=st.booleans(),
)
def test_any_artifact_survives_the_store_bit_for_bit(store: Store, fx, rms_px, serial, accepted):
    status = "accepted" if accepted else "rejected"
    art = calibration(serial=serial, status=status, fx=fx).model_copy(update={"rms_px": rms_px}).sealed()
    stored = store.add_artifact(art, activate=accepted, reason="property test", **WHO)
    again = store.get_artifact(serial, stored.version)
    assert again == stored
    assert again.rms_px == rms_px and again.camera_matrix[0][0] == fx  # exact, not approximately


def test_versions_count_up_per_serial(store: Store):
    versions = [
        add(store, "A").version,
        add(store, "B").version,
        add(store, "A").version,
        add(store, "A").version,
    ]
    assert versions == [1, 1, 2, 3]
    assert store.serials() == ["A", "B"]
    assert [a.version for a in store.list_artifacts("A")] == [1, 2, 3]
    assert store.active_version("A") == 3


def test_rejected_artifact_is_stored_but_never_active(store: Store):
    add(store, status="accepted")
    rejected = add(store, status="rejected")
    assert rejected.version == 2 and rejected.status == "rejected"
    assert store.active_version("CAM-0001") == 1
    assert store.get_artifact("CAM-0001", 2) == rejected


def test_activating_a_rejected_artifact_is_refused_and_writes_nothing(store: Store):
    with pytest.raises(UsageError, match="a rejected calibration can never become active"):
        add(store, status="rejected", activate=True)
    assert store.serials() == []


def test_rollback_moves_the_active_version_and_appends_an_event(store: Store):
    for _ in range(3):
        add(store)
    event = store.rollback("CAM-0001", 1, reason="v3 drifts at the corners", actor="tech", station="line3")
    assert (event.version, event.previous_version, event.kind) == (1, 3, "rollback")
    assert (event.actor, event.station, event.reason) == ("tech", "line3", "v3 drifts at the corners")
    assert store.active_version("CAM-0001") == 1
    assert store.get_artifact("CAM-0001").version == 1
    events = store.events("CAM-0001")
    assert [(e.kind, e.version, e.previous_version) for e in events] == [
        ("activate", 1, None),
        ("activate", 2, 1),
        ("activate", 3, 2),
        ("rollback", 1, 3),
    ]
    assert [e.event_id for e in events] == sorted(e.event_id for e in events)


def test_rollback_to_a_rejected_version_is_refused(store: Store):
    add(store)
    add(store, status="rejected")
    with pytest.raises(
        UsageError, match=r"CAM-0001@2 is rejected and can never become active; accepted versions: 1"
    ):
        store.rollback("CAM-0001", 2, reason="try", **WHO)
    assert store.active_version("CAM-0001") == 1
    assert len(store.events("CAM-0001")) == 1


def test_rollback_to_an_unknown_version_lists_the_versions(store: Store):
    add(store)
    add(store)
    with pytest.raises(NotFoundError, match=r"CAM-0001 has no version 5; versions: 1, 2"):
        store.rollback("CAM-0001", 5, reason="x", **WHO)


def test_rollback_to_the_active_version_writes_nothing_and_without_reason_is_refused(store: Store):
    add(store)
    assert store.rollback("CAM-0001", 1, reason="again", **WHO) is None
    assert len(store.events("CAM-0001")) == 1
    with pytest.raises(UsageError, match="needs a reason"):
        store.rollback("CAM-0001", 1, reason="  ", **WHO)


def test_unknown_serial_and_version_name_what_exists(store: Store):
    with pytest.raises(NotFoundError, match="unknown serial 'NOPE'; no calibrations are stored yet"):
        store.get_artifact("NOPE")
    add(store, "CAM-1")
    add(store, "CAM-2")
    with pytest.raises(NotFoundError, match="unknown serial 'NOPE'; known: CAM-1, CAM-2"):
        store.list_artifacts("NOPE")
    with pytest.raises(NotFoundError, match="CAM-1 has no version 9; versions: 1"):
        store.get_artifact("CAM-1", 9)


def test_serial_without_an_active_version_says_so(store: Store):
    add(store, status="rejected")
    with pytest.raises(
        NotFoundError, match=r"CAM-0001 has no active version; versions: 1 \(rejected\)"
    ) as none:
        store.get_artifact("CAM-0001")
    assert store.active_version("CAM-0001") is None
    # no accepted version to roll back to (udacity-camcal, every solve rejected): the hint must not say "roll
    # back"
    assert none.value.hint is not None and "roll back" not in none.value.hint
    assert "recalibrate it (`calibctl calibrate --serial CAM-0001 ...`)" in none.value.hint
    assert none.value.exit_code == 2


def test_import_keeps_the_version_and_is_idempotent(store: Store):
    art = calibration(version=7)
    first = store.import_artifact(art, activate=True, **WHO)
    second = store.import_artifact(art, activate=True, **WHO)
    assert first == second == art
    assert store.active_version("CAM-0001") == 7
    assert len(store.events("CAM-0001")) == 1  # importing the same thing twice changed nothing
    assert add(store).version == 8  # the next solve continues after the imported version


def test_import_of_a_different_artifact_under_an_existing_version_is_refused(store: Store):
    add(store)
    other = calibration(version=1, fx=812.5)
    with pytest.raises(AlreadyExistsError, match="CAM-0001@1 already exists .* with different content"):
        store.import_artifact(other, activate=False, **WHO)


def test_import_of_a_tampered_artifact_is_an_integrity_error(store: Store):
    tampered = calibration(version=3).model_copy(update={"rms_px": 0.1})  # hash no longer matches
    with pytest.raises(IntegrityError, match="CAM-0001@3 does not match its content_sha256") as info:
        store.import_artifact(tampered, activate=True, **WHO)
    assert info.value.exit_code == 1
    assert store.serials() == []


def test_add_artifact_once_stores_one_calibration_per_capture_session(store: Store):
    """The spool's sync: the same session's calibration offered again (a sync run after a kill) is the stored
    one, no new version; another session's gets the next version."""

    def solved_from(session_id: str):
        art = calibration()
        return art.model_copy(
            update={"provenance": art.provenance.model_copy(update={"session_id": session_id})}
        )

    first, new = store.add_artifact_once(solved_from("aaaaaaaaaaaa"), activate=True, reason="synced", **WHO)
    again, new_again = store.add_artifact_once(
        solved_from("aaaaaaaaaaaa"), activate=True, reason="synced", **WHO
    )
    other, new_other = store.add_artifact_once(
        solved_from("bbbbbbbbbbbb"), activate=True, reason="synced", **WHO
    )
    assert (first.version, new, again.version, new_again, other.version, new_other) == (
        1,
        True,
        1,
        False,
        2,
        True,
    )
    assert again == first and [a.version for a in store.list_artifacts("CAM-0001")] == [1, 2]
    assert [e.version for e in store.events("CAM-0001")] == [1, 2]  # nothing activated twice
