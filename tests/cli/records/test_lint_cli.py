"""calibctl lint: the seed's chapter 0 file fails for principal point and provenance, in both formats."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from calibctl.cli.main import app
from calibctl.store.repository import Store
from tests.artifacts.factories import measured_board
from tests.workflows.sessions import synthetic_capture

FIXTURES = Path(__file__).resolve().parents[3] / "fixtures"
runner = CliRunner()


def lint(*args: str, db: str | None = None):
    return runner.invoke(app, [*(["--db", db] if db else []), "lint", *args])


@pytest.mark.parametrize("name", ["camera_front.json", "camera_front_ros.yaml"])
def test_chapter0_camera_front_fails_principal_point_and_provenance(name):
    result = lint(str(FIXTURES / name), "--format", "json")
    assert result.exit_code == 1, result.output
    report = json.loads(result.stdout)
    rules = {f["rule"] for f in report["results"][0]["findings"] if f["severity"] == "error"}
    if name.endswith(".json"):  # the artifact records its square size: nominal, an error
        assert {"principal-point", "square-size-provenance"} <= rules
    else:  # a bare camera_info carries no square size: its numbers fail, the gauge is a traceability warning
        assert "principal-point" in rules and "square-size-provenance" not in rules
        traced = next(f for f in report["results"][0]["findings"] if f["rule"] == "traceability")
        assert traced["severity"] == "warning" and "square size's provenance" in traced["message"]
    pp = next(f for f in report["results"][0]["findings"] if f["rule"] == "principal-point")
    assert "(319.62, 240.31)" in pp["message"] and "1280x960" in pp["message"]


def test_github_format_prints_workflow_annotations():
    result = lint(str(FIXTURES / "camera_front.json"), "--format", "github")
    assert result.exit_code == 1
    lines = result.stdout.splitlines()
    assert any(
        line.startswith("::error file=") and "title=calibctl principal-point::" in line for line in lines
    )
    assert lines[-1] == "calibctl lint: 1 of 1 calibration(s) failed"


def test_a_good_solved_calibration_passes(sqlite_url, tmp_path):
    with Store.open(sqlite_url) as store:
        board = store.add_board(measured_board())
        store.add_session(synthetic_capture(board).model_copy(update={"board": board}))
    assert runner.invoke(app, ["--db", sqlite_url, "solve", "--serial", "CAM-0001"]).exit_code == 0
    result = lint("--serial", "CAM-0001", db=sqlite_url)
    assert result.exit_code == 0, result.output
    assert "pass" in result.stdout
    exported = tmp_path / "good.json"
    runner.invoke(app, ["--db", sqlite_url, "export", "CAM-0001", "-o", str(exported)])
    assert lint(str(exported)).exit_code == 0
    # and the same file with one number changed fails the hash rule
    doc = json.loads(exported.read_text())
    doc["dist_coeffs"][0] = -0.25
    exported.write_text(json.dumps(doc))
    tampered = lint(str(exported), "--json")
    assert tampered.exit_code == 1
    assert "content-hash" in {f["rule"] for f in json.loads(tampered.stdout)["results"][0]["findings"]}


def test_sigma_fx_limit_comes_from_the_station_file(sqlite_url, tmp_path):
    with Store.open(sqlite_url) as store:
        board = store.add_board(measured_board())
        store.add_session(synthetic_capture(board).model_copy(update={"board": board}))
    runner.invoke(app, ["--db", sqlite_url, "solve", "--serial", "CAM-0001"])
    station = tmp_path / "station.yaml"
    station.write_text("lint:\n  sigma_fx_max_px: 0.01\n")
    result = runner.invoke(
        app, ["--db", sqlite_url, "--station-config", str(station), "lint", "--serial", "CAM-0001", "--json"]
    )
    assert result.exit_code == 1
    finding = next(f for f in json.loads(result.stdout)["results"][0]["findings"] if f["rule"] == "sigma-fx")
    assert "limit 0.010 px" in finding["message"]


def test_nan_in_a_file_is_a_finite_error(tmp_path):
    path = tmp_path / "nan.yaml"
    path.write_text((FIXTURES / "camera_front_ros.yaml").read_text().replace("800.14", ".nan"))
    result = lint(str(path), "--json")
    assert result.exit_code == 1
    errors = [
        f["rule"] for f in json.loads(result.stdout)["results"][0]["findings"] if f["severity"] == "error"
    ]
    assert errors == ["finite"]


@pytest.mark.parametrize(
    ("content", "suffix", "code", "message"),
    [
        ("a: [1, 2", ".yaml", 2, "malformed YAML"),
        ("just: text\n", ".yaml", 2, "is not a calibration"),
        ("{}", ".json", 2, "is not a calibration"),
    ],
)
def test_unreadable_or_non_calibration_inputs_exit_2(tmp_path, content, suffix, code, message):
    path = tmp_path / f"in{suffix}"
    path.write_text(content)
    result = lint(str(path))
    assert result.exit_code == code and message in result.stderr


def test_missing_file_and_no_input_exit_2(tmp_path):
    result = lint(str(tmp_path / "nope.json"))
    assert result.exit_code == 2 and "no such file" in result.stderr
    result = lint()
    assert result.exit_code == 2 and "nothing to lint" in result.stderr


def test_unknown_format_exits_2():
    result = lint(str(FIXTURES / "camera_front.json"), "--format", "xml")
    assert result.exit_code == 2 and "unknown --format 'xml'" in result.stderr
