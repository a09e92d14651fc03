"""Import re-derives its verdict and version; rollback is compare-and-set; stores that keep nothing are
refused; stored text is printed escaped."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from calibctl.artifacts.calibration import CalibrationArtifact
from calibctl.artifacts.common import MAX_VERSION
from calibctl.cli.main import app
from calibctl.store.repository import Store
from tests.artifacts.factories import calibration

SERIAL = "CAM-T1"
WHO = {"actor": "qa", "station": "st1", "reason": "solved"}


@pytest.fixture
def run(monkeypatch):
    monkeypatch.setenv("CALIBCTL_OPERATOR", "tech-bo")
    monkeypatch.setenv("CALIBCTL_STATION", "field-van-2")
    runner = CliRunner()
    return lambda url, *args: runner.invoke(app, ["--db", url, *args])


def _write(path: Path, art: CalibrationArtifact) -> Path:
    path.write_text(json.dumps(art.model_dump(mode="json")))
    return path


def _forged(**update) -> CalibrationArtifact:
    """A hand-made document: whatever numbers, "status": "accepted", and a hash recomputed to match."""
    art = calibration(serial=SERIAL, version=7)
    return art.model_copy(update=update).sealed()


def test_forged_accepted_file_that_fails_lint_is_imported_rejected_and_never_activated(
    run, sqlite_url, tmp_path
):
    bad_sigma = calibration(serial=SERIAL).stdev.model_copy(update={"sigma": {"fx": 9.0, "fy": 9.0}})
    path = _write(tmp_path / "forged.json", _forged(stdev=bad_sigma, lint=[]))
    result = run(sqlite_url, "import", str(path))
    assert result.exit_code == 1, result.output
    assert (
        f"imported {SERIAL}@1 (rejected by this store's lint, not active; source {SERIAL}@7 was accepted"
        in result.stdout
    )
    assert "sigma" in result.stdout  # the finding that rejects it is shown
    with Store.open(sqlite_url) as store:
        assert store.active_version(SERIAL) is None and store.events(SERIAL) == []
        (stored,) = store.list_artifacts(SERIAL)
    assert stored.status == "rejected" and stored.version == 1
    assert any(f.severity == "error" for f in stored.lint)
    assert stored.provenance.imported_from is not None and stored.provenance.imported_from.startswith(
        f"{SERIAL}@7 "
    )


def test_forged_file_recording_a_failed_gate_is_rejected(run, sqlite_url, tmp_path):
    from calibctl.artifacts.session import GateResult

    gate = GateResult(gate="tilt", passed=False, value=1, threshold=3)
    result = run(sqlite_url, "import", str(_write(tmp_path / "f.json", _forged(gates=[gate]))))
    assert result.exit_code == 1 and "failed capture gates (tilt)" in result.stdout


def test_import_gets_the_next_version_and_a_second_import_is_the_same_version(run, sqlite_url, tmp_path):
    with Store.open(sqlite_url) as store:
        store.add_artifact(calibration(serial=SERIAL), activate=True, **WHO)
    path = _write(tmp_path / "a.json", _forged())
    first = run(sqlite_url, "import", str(path), "--json")
    assert first.exit_code == 0, first.output
    doc = json.loads(first.stdout)
    assert doc["artifact"]["version"] == 2 and doc["active"] and doc["source"] == f"{SERIAL}@7"
    renamed = tmp_path / "renamed.json"
    renamed.write_bytes(path.read_bytes())
    again = run(sqlite_url, "import", str(renamed))
    assert again.exit_code == 0 and f"already stored as {SERIAL}@2" in again.stdout
    with Store.open(sqlite_url) as store:
        assert [a.version for a in store.list_artifacts(SERIAL)] == [1, 2]
        assert store.verify().problems == []


def test_keep_version_only_when_it_is_the_next_one(run, sqlite_url, tmp_path):
    refused = run(sqlite_url, "import", "--keep-version", str(_write(tmp_path / "a.json", _forged())))
    assert refused.exit_code == 2
    assert (
        f"{SERIAL}@7 cannot keep its version here; this store's next version of {SERIAL} is 1"
        in refused.stderr
    )
    kept = run(sqlite_url, "import", "--keep-version", str(_write(tmp_path / "b.json", _forged(version=1))))
    assert kept.exit_code == 0 and f"imported {SERIAL}@1 " in kept.stdout


def test_a_huge_source_version_does_not_poison_the_serial(run, db_url, tmp_path):
    path = _write(tmp_path / "max.json", _forged(version=MAX_VERSION))
    assert run(db_url, "import", str(path)).exit_code == 0
    with Store.open(db_url) as store:
        assert store.add_artifact(calibration(serial=SERIAL), activate=True, **WHO).version == 2


def test_a_version_beyond_the_store_range_is_refused_with_exit_2(run, sqlite_url, tmp_path):
    doc = _forged().model_dump(mode="json")
    doc["version"] = MAX_VERSION + 1
    path = tmp_path / "over.json"
    path.write_text(json.dumps(doc))
    result = run(sqlite_url, "import", str(path))
    assert result.exit_code == 2 and "version" in result.stderr and "Traceback" not in result.output
    assert run(sqlite_url, "show", f"{SERIAL}@99999999999999999999").exit_code == 2


def test_a_counter_at_the_largest_version_refuses_instead_of_overflowing(db_url):
    with Store.open(db_url) as store:
        store.import_artifact(calibration(serial=SERIAL, version=MAX_VERSION), activate=False, **WHO)
        with pytest.raises(Exception, match=f"has reached version {MAX_VERSION}"):
            store.add_artifact(calibration(serial=SERIAL), activate=False, **WHO)


def _three_versions(url: str) -> None:
    with Store.open(url) as store:
        for fx in (800.0, 801.0, 802.0):
            store.add_artifact(calibration(serial=SERIAL, fx=fx), activate=True, **WHO)


def test_rollback_decided_on_an_old_view_is_refused_naming_the_newer_version(run, db_url):
    _three_versions(db_url)
    result = run(db_url, "rollback", SERIAL, "--to", "1", "--reason", "drift", "--expect-active", "2")
    assert result.exit_code == 2
    assert "active version changed underneath this rollback (it saw v2, it is now v3)" in result.stderr
    with Store.open(db_url) as store:
        assert store.active_version(SERIAL) == 3
        assert [e.kind for e in store.events(SERIAL)] == ["activate"] * 3
    ok = run(db_url, "rollback", SERIAL, "--to", "1", "--reason", "drift", "--expect-active", "3")
    assert ok.exit_code == 0 and "active version is now v1 (was v3)" in ok.stdout


def test_store_rollback_compare_and_set(db_url):
    _three_versions(db_url)
    with Store.open(db_url) as store:
        with pytest.raises(Exception, match="it saw no active version, it is now v3"):
            store.rollback(SERIAL, 1, expected_active=None, **{**WHO, "reason": "r"})
        event = store.rollback(SERIAL, 1, expected_active=3, **{**WHO, "reason": "r"})
    assert (event.version, event.previous_version) == (1, 3)


@pytest.mark.parametrize("url", ["sqlite://", "sqlite:///:memory:", ":memory:", ""])
@pytest.mark.parametrize("command", [["history", SERIAL], ["rollback", SERIAL, "--to", "1", "--reason", "x"]])
def test_stores_that_keep_nothing_are_refused(run, url, command):
    result = run(url, *command)
    assert result.exit_code == 2
    assert ("in-memory database" in result.stderr) or ("--db is empty" in result.stderr)


def test_import_into_an_in_memory_store_is_refused(run, tmp_path):
    result = run("sqlite://", "import", str(_write(tmp_path / "a.json", _forged())))
    assert result.exit_code == 2 and "keep nothing" in result.stderr and "imported" not in result.stdout


def test_control_characters_in_stored_text_are_escaped_when_printed(run, sqlite_url):
    _three_versions(sqlite_url)
    hostile = "ok\x1b[2J\x1b[1;1Hfake line\n  2026-01-01 rollback -> v9\r[bold]x[/bold]\u202e"
    with Store.open(sqlite_url) as store:
        store.rollback(SERIAL, 1, reason=hostile, actor="tech\x07", station="st\x00x")
    result = run(sqlite_url, "history", SERIAL)
    assert result.exit_code == 0, result.output
    out = result.stdout
    assert "\x1b" not in out and "\r" not in out and "\x07" not in out and "\u202e" not in out
    assert "ok\\x1b[2J\\x1b[1;1Hfake line\\x0a  2026-01-01 rollback -> v9\\x0d[bold]x[/bold]\\u202e" in out
    assert "by tech\\x07 at st\\x00x" in out


def test_a_nul_in_a_rollback_reason_or_operator_is_refused_before_the_database(run, db_url):
    _three_versions(db_url)
    result = run(db_url, "rollback", SERIAL, "--to", "1", "--reason", "bad\x00reason")
    assert result.exit_code == 2 and "--reason: the reason holds a NUL character" in result.stderr
    result = CliRunner().invoke(
        app,
        ["--db", db_url, "rollback", SERIAL, "--to", "1", "--reason", "r"],
        env={"CALIBCTL_OPERATOR": "o\x01p"},
    )
    assert (
        result.exit_code == 2
        and "CALIBCTL_OPERATOR): its value holds control character \\x01" in result.stderr
    )
    with Store.open(db_url) as store:
        assert store.active_version(SERIAL) == 3


def test_importing_the_stores_own_export_is_a_no_op_and_never_undoes_a_rollback(run, sqlite_url, tmp_path):
    with Store.open(sqlite_url) as store:
        store.add_artifact(calibration(serial=SERIAL), activate=True, **WHO)
        second = calibration(serial=SERIAL).model_copy(
            update={"camera_matrix": ((801.0, 0.0, 320.0), (0.0, 801.0, 240.0), (0.0, 0.0, 1.0))}
        )
        store.add_artifact(second, activate=True, **WHO)
    out = tmp_path / "v2.json"
    assert run(sqlite_url, "export", f"{SERIAL}@2", "-o", str(out)).exit_code == 0
    assert run(sqlite_url, "rollback", SERIAL, "--to", "1", "--reason", "v2 drifted").exit_code == 0
    with Store.open(sqlite_url) as store:
        events_before = store.events(SERIAL)
    result = run(sqlite_url, "import", str(out))
    assert result.exit_code == 0, result.output
    assert f"already stored as {SERIAL}@2" in result.stdout and "not active" in result.stdout
    with Store.open(sqlite_url) as store:
        assert [a.version for a in store.list_artifacts(SERIAL)] == [1, 2]  # no duplicate version
        assert store.active_version(SERIAL) == 1  # the rollback stands
        assert store.events(SERIAL) == events_before  # nothing written at all
    doc = json.loads(run(sqlite_url, "import", str(out), "--json").stdout)
    assert doc["already_imported"] is True and doc["active"] is False and doc["artifact"]["version"] == 2


@pytest.mark.parametrize(
    ("update", "words"),
    [
        (
            {"camera_matrix": ((805.0, 0.0, 320.0), (0.0, 800.0, 240.0), (0.0, 0.0, 1.0))},
            "fx 805.000 and fy 800.000 differ",
        ),
        ("sigma", "sigma_fx 0.9 and sigma_fy 0.3 differ"),
    ],
)
def test_a_forged_artifact_that_breaks_its_models_tied_focal_is_refused_and_nothing_stored(
    run, sqlite_url, tmp_path, update, words
):
    """fx + 5 px on a model that ties fx to fy, hash re-sealed, unsigned: it imported as accepted and
    active."""
    art = calibration(serial=SERIAL, version=7)
    if update == "sigma":
        update = {"stdev": art.stdev.model_copy(update={"sigma": {**art.stdev.sigma, "fx": 0.9, "fy": 0.3}})}
    path = _write(tmp_path / "forged.json", art.model_copy(update=update).sealed())
    result = run(sqlite_url, "import", str(path))
    assert result.exit_code == 1, result.output
    assert (
        words in result.stderr and "ties fx to fy" in result.stderr and "nothing was stored" in result.stderr
    )
    with Store.open(sqlite_url) as store:
        assert store.serials() == []
