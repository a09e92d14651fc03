"""lint --all reads the fleet in bulk: the same verdicts as one serial at a time, and a tampered record is
a finding for its serial while every other serial is still linted."""

from __future__ import annotations

from calibctl.config import load_settings
from calibctl.store.repository import Store
from calibctl.workflows import lint
from tests.artifacts.factories import calibration
from tests.store.tamper import run_underneath

WHO = {"actor": "qa", "station": "st1"}


def _fleet(url: str) -> None:
    with Store.open(url) as store:
        store.add_artifact(calibration(serial="CAM-A"), activate=True, reason="solved", **WHO)
        store.add_artifact(calibration(serial="CAM-A", cx=400.0), activate=True, reason="solved", **WHO)  # off-centre
        store.add_artifact(calibration(serial="CAM-B"), activate=True, reason="solved", **WHO)
        store.add_artifact(calibration(serial="CAM-C", status="rejected"), activate=False, reason="solved", **WHO)
        store.rollback("CAM-A", 1, reason="v2 is off-centre", **WHO)


def test_bulk_verdicts_equal_per_serial_verdicts(db_url: str):
    _fleet(db_url)
    settings = load_settings(db=db_url, env={})
    bulk = {r.source: r.as_json() for r in lint.lint(settings, [], None, True)}
    one_by_one = {r.source: r.as_json() for s in ("CAM-A", "CAM-B", "CAM-C") for r in lint.lint(settings, [], s, False)}
    assert bulk == one_by_one
    assert sorted(bulk) == ["CAM-A@1", "CAM-B@1", "CAM-C"]
    assert [f["rule"] for f in bulk["CAM-C"]["findings"]] == ["no-active-version"]


def test_a_tampered_active_record_is_a_finding_and_the_rest_is_linted(db_url: str):
    _fleet(db_url)
    run_underneath(db_url, "UPDATE calibration_artifacts SET operator = 'nobody' WHERE serial = 'CAM-B'")
    results = {r.source: r for r in lint.lint(load_settings(db=db_url, env={}), [], None, True)}
    assert [f.rule for f in results["CAM-B"].findings] == ["content-hash"]
    assert "CAM-B@1 was changed after it was written" in results["CAM-B"].findings[0].message
    assert not results["CAM-A@1"].failed
