"""lint --all reads the fleet in bulk: the same verdicts as one serial at a time, and a tampered record is
a finding for its serial while every other serial is still linted."""

from __future__ import annotations

from calibctl.config import load_settings
from calibctl.store.repository import Store
from calibctl.workflows.lint import lint, run
from tests.artifacts.factories import calibration
from tests.store.tamper import run_underneath

WHO = {"actor": "qa", "station": "st1"}


def _fleet(url: str) -> None:
    with Store.open(url) as store:
        store.add_artifact(calibration(serial="CAM-A"), activate=True, reason="solved", **WHO)
        store.add_artifact(
            calibration(serial="CAM-A", cx=400.0), activate=True, reason="solved", **WHO
        )  # off-centre
        store.add_artifact(calibration(serial="CAM-B"), activate=True, reason="solved", **WHO)
        store.add_artifact(
            calibration(serial="CAM-C", status="rejected"), activate=False, reason="solved", **WHO
        )
        store.rollback("CAM-A", 1, reason="v2 is off-centre", **WHO)


def test_bulk_verdicts_equal_per_serial_verdicts(db_url: str):
    _fleet(db_url)
    settings = load_settings(db=db_url, env={})
    bulk = {r.source: r.as_json() for r in run.lint(settings, [], None, True)}
    one_by_one = {
        r.source: r.as_json() for s in ("CAM-A", "CAM-B", "CAM-C") for r in run.lint(settings, [], s, False)
    }
    assert bulk == one_by_one
    assert sorted(bulk) == ["CAM-A@1", "CAM-B@1", "CAM-C"]
    assert [f["rule"] for f in bulk["CAM-C"]["findings"]] == ["no-active-version"]


def test_a_tampered_active_record_is_a_finding_and_the_rest_is_linted(db_url: str):
    _fleet(db_url)
    run_underneath(db_url, "UPDATE calibration_artifacts SET operator = 'nobody' WHERE serial = 'CAM-B'")
    results = {r.source: r for r in run.lint(load_settings(db=db_url, env={}), [], None, True)}
    assert [f.rule for f in results["CAM-B"].findings] == ["content-hash"]
    assert "CAM-B@1 was changed after it was written" in results["CAM-B"].findings[0].message
    assert not results["CAM-A@1"].failed


def test_the_stored_lint_reads_only_the_fact_fields_and_gives_the_full_dumps_verdicts(monkeypatch):
    """``_lint_stored`` dumps only ``FACT_FIELDS`` (a third of the cost): the findings are the full dump's."""
    import json
    from pathlib import Path

    from calibctl.artifacts.calibration import CalibrationArtifact

    limits = load_settings(env={}).lint
    front = CalibrationArtifact.model_validate(json.loads(Path("fixtures/camera_front.json").read_text()))
    arts = [
        calibration(),
        calibration(cx=400.0),
        calibration(status="rejected"),
        calibration(fx=90.0),
        calibration(image_size=(4000, 3000)),
        front,
        calibration().model_copy(update={"dist_coeffs": [-1.5, 0.0, 0.0, 0.0, 0.0]}),
    ]  # folds over
    fast = [lint.lint_artifact(a, limits).as_json() for a in arts]
    monkeypatch.setattr(lint, "FACT_FIELDS", None)  # include=None: the whole document
    full = [lint.lint_artifact(a, limits).as_json() for a in arts]
    assert fast == full
    failing = {f["rule"] for r in full for f in r["findings"] if f["severity"] == "error"}
    assert {
        "principal-point",
        "status",
        "distortion-foldover",
    } <= failing  # the cases differ in their verdicts
