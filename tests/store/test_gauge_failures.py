"""``Store.failed_gauges``: a board revision's failed metric gauges, read from its sessions and checks."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from calibctl.artifacts.check import DistanceCheck
from calibctl.store.repository import Store
from tests.artifacts.factories import calibration, measured_board
from tests.store.documents import capture_session, check_event, gauged_session


@pytest.fixture
def store(db_url: str) -> Iterator[Store]:
    with Store.open(db_url) as opened:
        opened.add_board(measured_board("A17"))
        opened.add_board(measured_board("B2"))
        yield opened


def test_only_failed_gauges_of_the_asked_revisions_are_returned(store: Store) -> None:
    store.add_session(capture_session("000000000001"))  # no gauge
    store.add_session(gauged_session("000000000002", 1.002))  # passed
    store.add_session(gauged_session("000000000003", 0.92, serial="CAM-0009"))  # failed, A17@1
    store.add_session(gauged_session("000000000004", 1.08, board_name="B2"))  # failed, B2@1
    found = store.failed_gauges(["A17@1"])
    assert list(found) == ["A17@1"]
    (failure,) = found["A17@1"]
    assert (failure.serial, failure.record, failure.ratio) == ("CAM-0009", "session 000000000003", 0.92)
    assert failure.recovered_m == pytest.approx(0.414) and failure.reference_m == 0.45
    assert set(store.failed_gauges(["A17@1", "B2@1", "A17@2"])) == {"A17@1", "B2@1"}
    assert store.failed_gauges([]) == {}


def test_a_failed_check_side_gauge_counts_for_the_calibrations_board(store: Store) -> None:
    art = store.add_artifact(
        calibration(board=measured_board("B2")), activate=True, actor="qa", station="st1", reason="t"
    )
    distance = DistanceCheck(
        reference_m=0.45,
        reference_sigma_m=0.0005,
        recovered_m=0.414,
        spread=0.0,
        ratio=0.92,
        ratio_limits=(0.99, 1.01),
        passed=False,
    )
    store.add_check(check_event(art.serial, art.version, art.content_sha256, 1))  # passed, no distance
    failed = check_event(art.serial, art.version, art.content_sha256, 2, passed=False)
    store.add_check(failed.model_copy(update={"distance": distance}))
    (failure,) = store.failed_gauges(["B2@1"])["B2@1"]
    assert failure.record == f"check {failed.check_id} of {art.ref}" and failure.ratio == 0.92
    assert store.failed_gauges(["A17@1"]) == {}
