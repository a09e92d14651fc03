"""history / show / export / import / rollback / solve from the command line: wiring, exit codes, messages."""

from __future__ import annotations

import json
import re
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml
from typer.testing import CliRunner

from calibctl.cli.main import app
from calibctl.store.repository import Store
from tests.artifacts.factories import measured_board
from tests.workflows.sessions import synthetic_capture

SERIAL = "CAM-0001"


@pytest.fixture
def db(sqlite_url: str) -> str:
    """A store with one measured board and one accepted synthetic session."""
    with Store.open(sqlite_url) as store:
        board = store.add_board(measured_board())
        store.add_session(synthetic_capture(board, serial=SERIAL).model_copy(update={"board": board}))
    return sqlite_url


@pytest.fixture
def run(db: str, monkeypatch):
    monkeypatch.setenv("CALIBCTL_OPERATOR", "tech-bo")
    monkeypatch.setenv("CALIBCTL_STATION", "field-van-2")
    runner = CliRunner()
    return lambda *args, url=db: runner.invoke(app, ["--db", url, *args])


def _two_versions(run) -> None:
    for _ in range(2):
        result = run("solve", "--serial", SERIAL)
        assert result.exit_code == 0, result.output


def test_solve_reports_parameters_with_sigma_and_exits_0(run):
    result = run("solve", "--serial", SERIAL)
    assert result.exit_code == 0, result.output
    assert re.search(r"fx = \d+\.\d\d \+/- \d+\.\d\d px", result.stdout), result.stdout
    assert "held-out" in result.stdout and "CAM-0001@1 accepted" in result.stdout


def test_solve_json_is_the_artifact(run):
    result = run("solve", "0123456789ab", "--json")
    assert result.exit_code == 0, result.output
    art = json.loads(result.stdout)
    assert art["serial"] == SERIAL and art["version"] == 1 and art["status"] == "accepted"
    assert art["stdev"]["sigma"]["fx"] > 0


def test_solve_unknown_session_exits_2(run):
    result = run("solve", "ffffffffffff")
    assert result.exit_code == 2
    assert "Error: " in result.stderr and "ffffffffffff" in result.stderr


def test_history_marks_the_active_version_and_lists_events(run):
    _two_versions(run)
    result = run("history", SERIAL, "--json")
    assert result.exit_code == 0, result.output
    hist = json.loads(result.stdout)
    assert hist["active_version"] == 2
    assert [v["version"] for v in hist["versions"]] == [1, 2]
    assert [e["kind"] for e in hist["events"]] == ["activate", "activate"]
    text = run("history", SERIAL)
    row2 = next(line for line in text.stdout.splitlines() if line.lstrip().startswith("2 "))
    assert " * " in row2 and "field-van-2" in row2


def test_rollback_moves_active_version_and_is_logged(run):
    _two_versions(run)
    result = run("rollback", SERIAL, "--to", "1", "--reason", "v2 drifted after the bracket swap")
    assert result.exit_code == 0, result.output
    assert "active version is now v1 (was v2)" in result.stdout
    hist = json.loads(run("history", SERIAL, "--json").stdout)
    assert hist["active_version"] == 1
    last = hist["events"][-1]
    assert (last["kind"], last["actor"], last["station"]) == ("rollback", "tech-bo", "field-van-2")
    assert last["reason"] == "v2 drifted after the bracket swap"


def test_rollback_to_the_active_version_is_a_success_that_writes_nothing(run):
    _two_versions(run)
    for extra in ((), ("--expect-active", "2")):
        result = run("rollback", SERIAL, "--to", "2", "--reason", "make sure", *extra)
        assert result.exit_code == 0, result.output
        assert f"{SERIAL}: v2 is already the active version; nothing written" in result.stdout
    done = run("rollback", SERIAL, "--to", "2", "--reason", "make sure", "--json")
    assert done.exit_code == 0 and json.loads(done.stdout) == {
        "serial": SERIAL,
        "version": 2,
        "already_active": True,
    }
    hist = json.loads(run("history", SERIAL, "--json").stdout)
    assert hist["active_version"] == 2 and [e["kind"] for e in hist["events"]] == ["activate", "activate"]
    # compare-and-set first: a view of v1 is stale even when the target is what is active now
    stale = run("rollback", SERIAL, "--to", "2", "--reason", "r", "--expect-active", "1")
    assert stale.exit_code == 2 and "the active version changed underneath this rollback" in stale.stderr


def test_rollback_to_unknown_version_exits_2_listing_versions(run):
    _two_versions(run)
    result = run("rollback", SERIAL, "--to", "9", "--reason", "x")
    assert result.exit_code == 2
    assert "Error:" in result.stderr and "9" in result.stderr and "1, 2" in result.stderr


def test_unknown_serial_exits_2_listing_known_serials(run):
    _two_versions(run)
    for args in (("history", "NOPE"), ("show", "NOPE"), ("export", "NOPE@1")):
        result = run(*args)
        assert result.exit_code == 2, args
        assert "NOPE" in result.stderr and SERIAL in result.stderr


def test_show_unknown_version_exits_2(run):
    _two_versions(run)
    result = run("show", f"{SERIAL}@7")
    assert result.exit_code == 2 and "7" in result.stderr


def test_export_ros_is_camera_info_yaml(run, tmp_path: Path):
    _two_versions(run)
    out = tmp_path / "cam.yaml"
    result = run("export", f"{SERIAL}@1", "--format", "ros", "-o", str(out))
    assert result.exit_code == 0, result.output
    info = yaml.safe_load(out.read_text())
    assert info["image_width"] == 640 and info["image_height"] == 480
    assert info["distortion_model"] == "plumb_bob" and len(info["distortion_coefficients"]["data"]) == 5
    art = json.loads(run("show", f"{SERIAL}@1", "--json").stdout)
    assert info["camera_matrix"]["data"] == [v for row in art["camera_matrix"] for v in row]
    assert info["projection_matrix"]["data"][3] == 0.0


def test_export_opencv_is_readable_by_filestorage(run, tmp_path: Path):
    _two_versions(run)
    out = tmp_path / "cam.yml"
    assert run("export", SERIAL, "--format", "opencv", "-o", str(out)).exit_code == 0
    fs = cv2.FileStorage(str(out), cv2.FILE_STORAGE_READ)
    K = fs.getNode("camera_matrix").mat()
    art = json.loads(run("show", SERIAL, "--json").stdout)
    np.testing.assert_array_equal(K, np.array(art["camera_matrix"]))
    assert int(fs.getNode("image_width").real()) == 640
    fs.release()


def test_export_never_overwrites_without_force(run, tmp_path: Path):
    _two_versions(run)
    out = tmp_path / "cam.json"
    out.write_text("keep me")
    result = run("export", SERIAL, "-o", str(out))
    assert result.exit_code == 2 and "exists" in result.stderr and "--force" in result.stderr
    assert out.read_text() == "keep me"
    assert run("export", SERIAL, "-o", str(out), "--force").exit_code == 0
    assert json.loads(out.read_text())["serial"] == SERIAL


def test_export_unknown_format_exits_2(run):
    _two_versions(run)
    result = run("export", SERIAL, "--format", "xml")
    assert result.exit_code == 2 and "unknown export format 'xml'" in result.stderr


def test_import_into_another_store_gets_its_next_version_and_keeps_the_source_as_provenance(
    run, tmp_path: Path
):
    _two_versions(run)
    exported = tmp_path / "cam.json"
    assert run("export", f"{SERIAL}@2", "-o", str(exported)).exit_code == 0
    robot = f"sqlite:///{tmp_path / 'robot.db'}"
    result = run("import", str(exported), url=robot)
    assert result.exit_code == 0, result.output
    assert f"imported {SERIAL}@1 (accepted by this store's lint, active; source {SERIAL}@2" in result.stdout
    shown = json.loads(run("show", SERIAL, "--json", url=robot).stdout)
    source_sha = json.loads(exported.read_text())["content_sha256"]
    assert shown["version"] == 1 and shown["status"] == "accepted"
    assert shown["provenance"]["imported_from"].startswith(f"{SERIAL}@2 sha256 {source_sha}")


def test_import_of_a_tampered_file_exits_1_and_writes_nothing(run, tmp_path: Path):
    _two_versions(run)
    exported = tmp_path / "cam.json"
    run("export", SERIAL, "-o", str(exported))
    doc = json.loads(exported.read_text())
    doc["camera_matrix"][0][0] += 1.0
    exported.write_text(json.dumps(doc))
    robot = f"sqlite:///{tmp_path / 'robot.db'}"
    result = run("import", str(exported), url=robot)
    assert result.exit_code == 1
    assert "does not match its sha256" in result.stderr
    assert run("history", SERIAL, url=robot).exit_code == 2


@pytest.mark.parametrize(
    ("content", "message"),
    [("{not json", "malformed JSON at line 1"), ('{"hello": 1}', "is not a calibration")],
)
def test_import_of_malformed_input_exits_2(run, tmp_path: Path, content, message):
    path = tmp_path / "bad.json"
    path.write_text(content)
    result = run("import", str(path))
    assert result.exit_code == 2 and message in result.stderr


def test_import_schema_violation_names_the_field(run, tmp_path: Path):
    _two_versions(run)
    exported = tmp_path / "cam.json"
    run("export", SERIAL, "-o", str(exported))
    doc = json.loads(exported.read_text())
    doc["held_out"]["k_folds"] = "five"
    exported.write_text(json.dumps(doc))
    result = run("import", str(exported))
    assert result.exit_code == 2 and "held_out.k_folds" in result.stderr


@pytest.mark.parametrize(
    ("views", "model", "message"), [(4, "rational", "model rational needs at least 5 board views, got 4")]
)
def test_too_few_views_for_the_model_exits_2_and_writes_nothing(sqlite_url, views, model, message):
    with Store.open(sqlite_url) as store:
        board = store.add_board(measured_board())
        session = synthetic_capture(board, serial="FEW-1", n_views=views)
        store.add_session(session.model_copy(update={"board": board}))
    result = CliRunner().invoke(app, ["--db", sqlite_url, "solve", "--serial", "FEW-1", "--model", model])
    assert result.exit_code == 2, result.output
    assert message in result.stderr and "Hint:" in result.stderr
    with Store.open(sqlite_url) as store:
        assert store.serials() == []


def test_show_json_exposes_the_full_covariance(run):
    assert run("solve", "--serial", SERIAL).exit_code == 0
    result = run("show", SERIAL, "--json")
    assert result.exit_code == 0, result.output
    stdev = json.loads(result.stdout)["stdev"]
    names, matrix = stdev["covariance"]["parameters"], stdev["covariance"]["matrix"]
    assert len(matrix) == len(names) and "cx" in names
    assert matrix[names.index("cx")][names.index("cx")] ** 0.5 == pytest.approx(
        stdev["sigma"]["cx"], rel=1e-12
    )


def test_solve_report_writes_the_new_versions_page(run, tmp_path):
    result = run("solve", "--serial", SERIAL, "--report", str(tmp_path / "reports"))
    assert result.exit_code == 0, result.output
    page = tmp_path / "reports" / f"{SERIAL}-v1-report.html"
    assert f"report: {page}" in " ".join(result.stdout.split()) and "CAM-0001@1" in page.read_text(
        encoding="utf-8"
    )


def test_solve_report_onto_a_file_exits_2_before_solving(run, tmp_path):
    not_a_folder = tmp_path / "file.txt"
    not_a_folder.write_text("x", encoding="utf-8")
    result = run("solve", "--serial", SERIAL, "--report", str(not_a_folder))
    assert result.exit_code == 2 and "it is not a folder" in result.stderr
    assert "no calibration is stored for" in run("history", SERIAL).stderr  # nothing was stored


def test_solve_report_onto_an_existing_page_exits_2_before_storing(run, tmp_path):
    """It used to store (and activate) the new version first, then fail writing its page."""
    page = tmp_path / f"{SERIAL}-v1-report.html"
    page.write_text("an older store's page", encoding="utf-8")
    result = run("solve", "--serial", SERIAL, "--report", str(tmp_path))
    assert result.exit_code == 2, result.output
    assert f"{page} already exists" in " ".join(result.stderr.split())
    assert "nothing was stored" in result.stderr
    assert "no calibration is stored for" in run("history", SERIAL).stderr  # nothing was stored
    assert page.read_text(encoding="utf-8") == "an older store's page"


def test_solve_report_onto_a_dangling_symlink_exits_2_before_storing(run, tmp_path):
    """exists() is False for a dangling link: the solve was stored, then its page refused."""
    page = tmp_path / f"{SERIAL}-v1-report.html"
    page.symlink_to(tmp_path / "elsewhere.html")
    result = run("solve", "--serial", SERIAL, "--report", str(tmp_path))
    assert result.exit_code == 2 and "it is a symbolic link, not a regular file" in result.stderr, (
        result.output
    )
    assert "no calibration is stored for" in run("history", SERIAL).stderr
    assert page.is_symlink() and not (tmp_path / "elsewhere.html").exists()


def test_solve_report_stores_nothing_when_another_version_took_the_checked_one(
    run, db, tmp_path, monkeypatch
):
    """The page checked is the one of the version about to be stored: a version stored meanwhile (another
    station) makes the store refuse, rather than store a version whose page was never checked."""
    from calibctl.workflows.camera import solve as solve_workflow

    build = solve_workflow.build_artifact

    def with_an_interloper(session, request, settings, board_gauge=None):
        art, outliers = build(session, request, settings, board_gauge)
        with Store.open(db) as store:
            store.add_artifact(art, activate=False, actor="other", station="other", reason="meanwhile")
        return art, outliers

    monkeypatch.setattr(solve_workflow, "build_artifact", with_an_interloper)
    result = run("solve", "--serial", SERIAL, "--report", str(tmp_path / "reports"))
    assert result.exit_code == 2, result.output
    assert f"{SERIAL}@1 cannot be stored: this store's next version of {SERIAL} is 2" in " ".join(
        result.stderr.split()
    )
    with Store.open(db) as store:
        assert [a.version for a in store.list_artifacts(SERIAL)] == [1]  # the other one's, never activated:
        assert (
            store.active_version(SERIAL) is None
        )  # the solve, which would have activated its own, stored nothing
    assert list((tmp_path / "reports").iterdir()) == []


def test_solve_report_with_rig_exits_2(run, tmp_path):
    result = run("solve", "--rig", "RIG-1", "--report", str(tmp_path))
    assert result.exit_code == 2 and "--report is not available with --rig" in result.stderr
