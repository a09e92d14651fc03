"""Capture sessions: immutable, found by id or as a serial's latest, with messages listing what exists."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from calibctl.errors import AlreadyExistsError, NotFoundError
from calibctl.store.repository import Store
from tests.store.documents import capture_session


@pytest.fixture
def store(db_url: str) -> Iterator[Store]:
    with Store.open(db_url) as opened:
        yield opened


def test_session_round_trip(store: Store):
    session = capture_session()
    store.add_session(session)
    assert store.get_session(session.session_id) == session
    assert store.list_sessions() == [session]
    assert store.list_sessions("CAM-0001") == [session] and store.list_sessions("OTHER") == []


def test_a_session_id_is_stored_once(store: Store):
    store.add_session(capture_session())
    with pytest.raises(AlreadyExistsError, match="capture session 0123456789ab is already stored"):
        store.add_session(capture_session(serial="CAM-0002"))
    assert store.get_session("0123456789ab").serial == "CAM-0001"


def test_latest_session_is_the_newest_with_the_status(store: Store):
    store.add_session(capture_session("aaaaaaaaaaa1", minutes_after=0))
    store.add_session(capture_session("aaaaaaaaaaa2", minutes_after=10))
    store.add_session(capture_session("aaaaaaaaaaa3", status="rejected", minutes_after=20))
    store.add_session(capture_session("bbbbbbbbbbb1", serial="CAM-0002", minutes_after=30))
    assert store.latest_session("CAM-0001").session_id == "aaaaaaaaaaa2"
    assert store.latest_session("CAM-0001", status=None).session_id == "aaaaaaaaaaa3"
    assert store.latest_session("CAM-0001", status="rejected").session_id == "aaaaaaaaaaa3"
    assert [s.session_id for s in store.list_sessions()] == [
        "aaaaaaaaaaa1",
        "aaaaaaaaaaa2",
        "aaaaaaaaaaa3",
        "bbbbbbbbbbb1",
    ]


def test_missing_sessions_name_what_exists(store: Store):
    with pytest.raises(
        NotFoundError, match="unknown capture session 'ffffffffffff'; no sessions are stored yet"
    ):
        store.get_session("ffffffffffff")
    store.add_session(capture_session("aaaaaaaaaaa1", status="rejected"))
    with pytest.raises(NotFoundError, match=r"unknown capture session 'ffffffffffff'; recent: aaaaaaaaaaa1"):
        store.get_session("ffffffffffff")
    with pytest.raises(
        NotFoundError,
        match=r"no accepted capture session for serial 'CAM-0001'; its sessions: aaaaaaaaaaa1 \(rejected\)",
    ):
        store.latest_session("CAM-0001")
    with pytest.raises(
        NotFoundError, match="no accepted capture session for serial 'CAM-7'; serials with sessions: CAM-0001"
    ):
        store.latest_session("CAM-7")


def test_a_serial_with_sessions_but_no_calibration_is_not_called_unknown(store: Store):
    # Its capture was rejected at the gates, so no calibration was ever stored: the serial is known.
    store.add_session(capture_session("aaaaaaaaaaa1", status="rejected"))
    with pytest.raises(NotFoundError) as info:
        store.get_artifact("CAM-0001")
    assert "unknown serial" not in info.value.message
    assert info.value.message == (
        "no calibration is stored for 'CAM-0001': its capture sessions were rejected at "
        "the gates, so it has no accepted version (aaaaaaaaaaa1 (rejected))"
    )
    assert info.value.hint is not None and "calibctl calibrate --serial CAM-0001" in info.value.hint
    store.add_session(capture_session("aaaaaaaaaaa2", minutes_after=5))  # accepted, never solved
    with pytest.raises(
        NotFoundError,
        match=r"it has capture sessions \(aaaaaaaaaaa1 \(rejected\), aaaaaaaaaaa2 "
        r"\(accepted\)\) but none was solved",
    ) as info:
        store.get_artifact("CAM-0001")
    assert info.value.hint == "solve it: `calibctl solve --serial CAM-0001`"
    with pytest.raises(NotFoundError, match="unknown serial 'CAM-7'"):  # no session either: still unknown
        store.get_artifact("CAM-7")


def test_a_rig_capture_stores_its_members_and_the_rig_session_together_or_not_at_all(store: Store):
    from tests.store.rig_documents import rig_definition, rig_session

    store.add_rig(rig_definition())
    store.add_session(capture_session("0123456789ab", serial="CAM-0001"))
    with pytest.raises(AlreadyExistsError, match="0123456789ab is already stored"):
        store.add_rig_session(
            rig_session(),
            [
                capture_session("aaaaaaaaaaa9", serial="CAM-0002"),
                capture_session("0123456789ab", serial="CAM-0001"),
            ],
        )
    assert [s.session_id for s in store.list_sessions()] == [
        "0123456789ab"
    ]  # the first member rolled back too


def test_latest_session_never_picks_a_rig_members_session(store: Store):
    """A session taken for a rig (named in any rig session, old stores included) is solved only when named."""
    from tests.store.rig_documents import rig_definition, rig_session

    store.add_rig(rig_definition())
    store.add_session(capture_session("aaaaaaaaaaa1", minutes_after=0))
    member = rig_session()  # names 0123456789ab as CAM-0001's session
    store.add_rig_session(member, [capture_session("0123456789ab", minutes_after=10)])
    assert store.latest_session("CAM-0001").session_id == "aaaaaaaaaaa1"
    assert store.get_session("0123456789ab").serial == "CAM-0001"  # named: still there
    with pytest.raises(
        NotFoundError,
        match=r"no accepted capture session for serial 'CAM-0002'.*0123456789aa "
        r"\(accepted, rig member\)",
    ) as info:
        store.add_session(capture_session("0123456789aa", serial="CAM-0002", minutes_after=5))
        store.add_rig_session(
            rig_session("fedcba987600").model_copy(
                update={"camera_sessions": {"CAM-0001": "aaaaaaaaaaa1", "CAM-0002": "0123456789aa"}}
            )
        )
        store.latest_session("CAM-0002")
    assert "name a rig member's session" in (info.value.hint or "")
