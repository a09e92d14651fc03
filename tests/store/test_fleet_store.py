"""The fleet's log in the store: registered robots and assigned versions, chained, checked on write, read
back whole, audited by `db verify`; refused steps write nothing."""

from __future__ import annotations

import pytest
from typer.testing import CliRunner

from calibctl.cli.main import app
from calibctl.errors import AlreadyExistsError, NotFoundError, UnverifiedRecord, UsageError
from calibctl.store.repository import Store
from tests.artifacts.factories import calibration
from tests.store.documents import fleet_event
from tests.store.tamper import patch_stored_bytes

WHO = {"actor": "qa", "station": "st1", "reason": "solved"}


@pytest.fixture
def store_url(db_url: str) -> str:
    """CAM-0001@1 accepted and active, @2 rejected; robot amr-001 carries CAM-0001."""
    with Store.open(db_url) as store:
        store.add_artifact(calibration(), activate=True, **WHO)
        store.add_artifact(calibration(status="rejected"), activate=False, **WHO)
        store.add_fleet_event(fleet_event("register", serials=["CAM-0001"], rigs=["STEREO-1"]))
    return db_url


def test_register_and_assign_are_read_back_in_order_and_verify(store_url: str) -> None:
    with Store.open(store_url) as store:
        assert store.add_fleet_event(fleet_event("assign", serial="CAM-0001", version=1)) == 2
        events = store.fleet_events()
        assert [(e.kind, e.robot) for e in events] == [("register", "amr-001"), ("assign", "amr-001")]
        assert events[1].serial == "CAM-0001" and events[1].version == 1
        audit = store.verify()
    assert audit.problems == [] and audit.heads["fleet"][()][0] == 2


@pytest.mark.parametrize(
    ("event", "error", "message"),
    [
        (
            fleet_event("register", serials=["CAM-0009"]),
            AlreadyExistsError,
            "robot amr-001 is already registered",
        ),
        (
            fleet_event("assign", robot="amr-404", serial="CAM-0001", version=1),
            NotFoundError,
            "amr-404 is not registered",
        ),
        (fleet_event("assign", serial="CAM-0002", version=1), UsageError, "does not carry CAM-0002"),
        (fleet_event("assign", serial="CAM-0001", version=7), NotFoundError, "CAM-0001 has no version 7"),
        (fleet_event("assign", serial="CAM-0001", version=2), UsageError, "CAM-0001@2 is rejected"),
    ],
)
def test_a_refused_step_writes_nothing(store_url: str, event, error, message: str) -> None:
    with Store.open(store_url) as store:
        with pytest.raises(error, match=message):
            store.add_fleet_event(event)
        assert len(store.fleet_events()) == 1
        assert store.verify().problems == []  # the counter row's bump was rolled back with it


def test_a_tampered_fleet_event_is_caught_on_read_and_by_verify(store_url: str) -> None:
    patch_stored_bytes(store_url, "fleet_events", '"reason":"test register"', '"reason":"test rEgister"')
    with Store.open(store_url) as store:
        with pytest.raises(UnverifiedRecord, match=r"fleet event 1 \(amr-001, register\) does not match"):
            store.fleet_events()
        problems = store.verify().problems
    assert any("fleet event 1" in p for p in problems)
    result = CliRunner().invoke(app, ["--db", store_url, "db", "verify"])
    assert result.exit_code == 1 and "fleet event 1" in result.stdout


def test_a_batch_is_all_or_nothing_and_a_stale_one_is_refused(store_url: str) -> None:
    from calibctl.errors import StaleActiveVersionError

    good = fleet_event("assign", serial="CAM-0001", version=1)
    bad = fleet_event("assign", serial="CAM-0001", version=2)  # rejected: refuses the whole batch
    with Store.open(store_url) as store:
        with pytest.raises(UsageError, match="CAM-0001@2 is rejected"):
            store.append_fleet_events([good, bad], after=1)
        assert len(store.fleet_events()) == 1
        with pytest.raises(StaleActiveVersionError, match="the fleet log changed underneath this step"):
            store.append_fleet_events([good], after=0)
        assert store.append_fleet_events([good, good], after=1) == 3
        assert store.verify().problems == []
