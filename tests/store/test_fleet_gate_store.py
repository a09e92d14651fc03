"""The store's side of the rollout gate, on SQLite and PostgreSQL: reports stored in one executemany and read
back by robot, target and time; every active version in one read; a fleet step's rig activations in the same
transaction as its events (a moved rig refuses the whole step)."""

from __future__ import annotations

from datetime import timedelta

import pytest

from calibctl.errors import StaleActiveVersionError
from calibctl.store.fleet import RigActivationStep
from calibctl.store.repository import Store
from tests.artifacts.factories import FIXED_TIME, calibration
from tests.store.documents import fleet_event, health_report
from tests.store.rig_documents import rig_calibration, rig_definition

WHO = {"actor": "qa", "station": "st1", "reason": "solved"}


@pytest.fixture
def store_url(db_url: str) -> str:
    """CAM-0001 @1 (active) and @2; STEREO-1 @1 and @2 (@2 active); robot amr-001 carries both."""
    with Store.open(db_url) as store:
        store.add_artifact(calibration(), activate=True, **WHO)
        store.add_artifact(calibration(), activate=False, **WHO)
        store.add_rig(rig_definition())
        for _ in range(2):
            store.add_rig_calibration(rig_calibration(), activate=True, **WHO)
        store.add_fleet_event(fleet_event("register", serials=["CAM-0001"], rigs=["STEREO-1"]))
    return db_url


def test_gate_reports_by_robot_target_and_time(store_url: str) -> None:
    later = FIXED_TIME + timedelta(days=1)
    reports = [
        health_report("CAM-0001", source_id="early"),
        health_report("CAM-0001", source_id="late").model_copy(update={"time": later}),
        health_report("STEREO-1", source_id="rig", kind="triage", verdict="ok").model_copy(
            update={"time": later}
        ),
        health_report(
            "CAM-0001", source_id="td", kind="timeoffset", td_ms=1.0, sigma_ms=0.1, temperature_c=20.0
        ).model_copy(update={"time": later}),
    ]
    with Store.open(store_url) as store:
        assert store.add_health_reports(reports) == []
        got = store.gate_reports(["amr-001"], ["CAM-0001", "STEREO-1"], later)
        assert [(r.source_id, r.kind, r.verdict) for r in got] == [
            ("late", "check", "pass"),
            ("rig", "triage", "ok"),
        ]
        assert all(len(r.payload_sha256) == 64 for r in got)
        assert store.gate_reports(["amr-002"], ["CAM-0001"], FIXED_TIME) == []
        assert store.fleet_check_rms(later) == {"CAM-0001": (pytest.approx(0.3), 1)}
        assert store.fleet_check_rms()["CAM-0001"][1] == 2
        assert store.active_versions() == ({"CAM-0001": 1}, {"STEREO-1": 2})


def test_rig_steps_commit_with_the_events_or_not_at_all(store_url: str) -> None:
    with Store.open(store_url) as store:
        before = len(store.fleet_events())
        assign = fleet_event("assign", rig="STEREO-1", version=1)
        stale = RigActivationStep("STEREO-1", 1, "rollback", expected_active=1, reason="x")  # it is @2
        with pytest.raises(StaleActiveVersionError, match="rig STEREO-1: the active version changed"):
            store.append_fleet_events([assign], before, [stale])
        assert len(store.fleet_events()) == before and store.active_rig_version("STEREO-1") == 2
        step = RigActivationStep("STEREO-1", 1, "rollback", expected_active=2, reason="fleet step")
        store.append_fleet_events([assign], before, [step])
        assert len(store.fleet_events()) == before + 1 and store.active_rig_version("STEREO-1") == 1
        assert store.rig_events("STEREO-1")[-1].reason == "fleet step"
        assert store.verify().problems == []
