"""Every export format goes back through `calibctl lint`: clean exports pass, edited ones fail the hash,
files ROS would refuse fail, and every export says whether its version was accepted or rejected."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import pytest
import yaml
from typer.testing import CliRunner

from calibctl.cli.main import app
from calibctl.store.repository import Store
from calibctl.workflows.exports import trace_header
from tests.artifacts.factories import calibration, measured_board
from tests.workflows.sessions import synthetic_capture

FORMATS = ("json", "yaml", "ros", "opencv", "kalibr", "mrcal")
runner = CliRunner()


def cli(*args: str):
    return runner.invoke(app, list(args))


def findings(result) -> list[dict]:
    return json.loads(result.stdout)["results"][0]["findings"]


def errors(result) -> set[str]:
    return {f["rule"] for f in findings(result) if f["severity"] == "error"}


@pytest.fixture
def store_url(sqlite_url: str) -> str:
    """CAM-0001@1 accepted and active; BAD-7@1 rejected (never active)."""
    with Store.open(sqlite_url) as store:
        store.add_artifact(calibration(), activate=True, actor="qa", station="st1", reason="solved")
        store.add_artifact(
            calibration(serial="BAD-7", status="rejected", cx=420.0),
            activate=False,
            actor="qa",
            station="st1",
            reason="solved",
        )
    return sqlite_url


def export(url: str, ref: str, fmt: str, out: Path, *extra: str):
    return cli("--db", url, "export", ref, "--format", fmt, "-o", str(out), *extra)


def test_exports_of_a_solved_calibration_pass_lint_in_every_format(sqlite_url: str, tmp_path: Path):
    with Store.open(sqlite_url) as store:
        board = store.add_board(measured_board())
        store.add_session(synthetic_capture(board).model_copy(update={"board": board}))
    assert cli("--db", sqlite_url, "solve", "--serial", "CAM-0001").exit_code == 0
    paths = []
    for fmt in FORMATS:
        paths.append(
            tmp_path / f"cam.{fmt}.{'json' if fmt == 'json' else 'cameramodel' if fmt == 'mrcal' else 'yaml'}"
        )
        assert export(sqlite_url, "CAM-0001", fmt, paths[-1]).exit_code == 0
    result = cli("lint", *map(str, paths), "--json")
    assert result.exit_code == 0, result.output
    report = json.loads(result.stdout)
    assert [r["kind"] for r in report["results"]] == [
        "calibctl",
        "calibctl",
        "ros",
        "opencv",
        "kalibr",
        "mrcal",
    ]
    assert all(r["errors"] == 0 and r["warnings"] == 0 for r in report["results"]), report


@pytest.mark.parametrize(
    ("fmt", "old", "new"),
    [("ros", "image_height: 480", "image_height: 482"), ("opencv", "image_height: 480", "image_height: 482")],
)
def test_an_edited_ros_or_opencv_export_fails_the_content_hash(store_url, tmp_path, fmt, old, new):
    out = tmp_path / "cam.yaml"
    assert export(store_url, "CAM-0001", fmt, out).exit_code == 0
    assert cli("lint", str(out)).exit_code == 0
    out.write_text(out.read_text().replace(old, new))
    result = cli("lint", str(out), "--json")
    assert result.exit_code == 1
    hashed = next(f for f in findings(result) if f["rule"] == "content-hash")
    assert "changed after `calibctl export` wrote CAM-0001@1" in hashed["message"]


def test_the_file_hash_is_reproducible_with_grep_and_sha256(store_url, tmp_path):
    import hashlib

    out = tmp_path / "cam.yaml"
    export(store_url, "CAM-0001", "ros", out)
    text = out.read_text()
    body = "".join(
        line for line in text.splitlines(keepends=True) if not line.startswith("# calibctl file-sha256 ")
    )
    recorded = next(
        line.split()[-1] for line in text.splitlines() if line.startswith("# calibctl file-sha256 ")
    )
    assert hashlib.sha256(body.encode()).hexdigest() == recorded


def test_ros_export_is_what_ros_reads_with_a_valid_camera_name(store_url, tmp_path):
    out = tmp_path / "cam.yaml"
    assert export(store_url, "CAM-0001", "ros", out).exit_code == 0
    info = yaml.safe_load(out.read_text())
    assert info["camera_name"] == "CAM_0001"
    assert out.read_text().startswith("# calibctl CAM-0001@1 accepted sha256 ")
    named = tmp_path / "named.yaml"
    assert export(store_url, "CAM-0001", "ros", named, "--camera-name", "front_left").exit_code == 0
    assert yaml.safe_load(named.read_text())["camera_name"] == "front_left"
    assert cli("lint", str(named)).exit_code == 0


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (("--format", "ros", "--camera-name", "front-left"), "'front-left' is not a valid ROS camera name"),
        (("--format", "json", "--camera-name", "front"), "--camera-name applies to --format ros only"),
    ],
)
def test_bad_camera_name_exits_2(store_url, args, message):
    result = cli("--db", store_url, "export", "CAM-0001", *args)
    assert result.exit_code == 2 and message in result.stderr


def test_a_kalibr_export_takes_the_topic_given(store_url, tmp_path):
    plain, named = tmp_path / "plain.yaml", tmp_path / "named.yaml"
    assert export(store_url, "CAM-0001", "kalibr", plain).exit_code == 0
    assert yaml.safe_load(plain.read_text())["cam0"]["rostopic"] == "/cam_0001/image_raw"  # the default
    assert export(store_url, "CAM-0001", "kalibr", named, "--topic", "/cam0/image_raw").exit_code == 0
    assert yaml.safe_load(named.read_text())["cam0"]["rostopic"] == "/cam0/image_raw"
    assert cli("lint", str(named)).exit_code == 0


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (
            ("--format", "kalibr", "--topic", "/cam-0/image_raw"),
            "'/cam-0/image_raw' is not a legal ROS topic",
        ),
        (("--format", "ros", "--topic", "/cam0/image_raw"), "--topic applies to --format kalibr only"),
    ],
)
def test_a_bad_topic_exits_2(store_url, args, message):
    result = cli("--db", store_url, "export", "CAM-0001", *args)
    assert result.exit_code == 2 and message in result.stderr


def test_opencv_export_is_readable_by_opencv_and_carries_the_status(store_url, tmp_path):
    out = tmp_path / "cam.yaml"
    assert export(store_url, "CAM-0001", "opencv", out).exit_code == 0
    fs = cv2.FileStorage(str(out), cv2.FILE_STORAGE_READ)
    assert fs.getNode("status").string() == "accepted"
    assert fs.getNode("camera_matrix").mat()[0, 0] == 800.0
    fs.release()
    assert out.read_text().splitlines()[1].startswith("# calibctl CAM-0001@1 accepted sha256 ")


def test_a_rejected_version_is_not_exported_without_allow_rejected(store_url, tmp_path):
    out = tmp_path / "bad.yaml"
    refused = export(store_url, "BAD-7@1", "ros", out)
    assert refused.exit_code == 2
    assert "BAD-7@1 is a rejected calibration" in refused.stderr and "--allow-rejected" in refused.stderr
    assert not out.exists()
    for fmt in FORMATS:
        path = tmp_path / f"bad-{fmt}.yaml"
        assert export(store_url, "BAD-7@1", fmt, path, "--allow-rejected").exit_code == 0
        text = path.read_text()
        assert ('"status": "rejected"' in text) if fmt == "json" else ("rejected" in text), fmt
        result = cli("lint", str(path), "--json")
        assert result.exit_code == 1 and "status" in errors(result), fmt


def test_a_file_without_header_is_linted_on_its_numbers_and_cannot_be_traced(store_url, tmp_path):
    out = tmp_path / "cam.yaml"
    export(store_url, "CAM-0001", "ros", out)
    bare = tmp_path / "bare.yaml"
    bare.write_text("".join(line + "\n" for line in out.read_text().splitlines() if not line.startswith("#")))
    result = cli("lint", str(bare), "--json")
    rules = {f["rule"]: f["severity"] for f in findings(result)}
    assert rules["traceability"] == "warning"
    assert "cannot be traced" in next(f["message"] for f in findings(result) if f["rule"] == "traceability")
    # ROS rewrites camera_info without comments (set_camera_info, the convert tool): what only the solve knew
    # (sigma, held-out outer ring, square size) is named as not checked, never an error whose fix is to
    # re-capture
    traced = next(f for f in findings(result) if f["rule"] == "traceability")
    assert (
        "sigma(fx), the held-out outer ring and the square size's provenance are not checked"
        in traced["message"]
    )
    assert (
        "calibctl lint --serial SERIAL" in traced["fix"]
    )  # the gauge is audited where it is kept: the store
    assert rules == {"traceability": "warning"}  # good numbers: a warning only, the verdict passes
    assert result.exit_code == 0, result.output


def test_a_header_without_file_hash_says_it_cannot_be_checked(store_url, tmp_path):
    out = tmp_path / "cam.yaml"
    export(store_url, "CAM-0001", "ros", out)
    old = "".join(
        line + "\n"
        for line in out.read_text().splitlines()
        if not line.startswith(("# calibctl evidence", "# calibctl file-sha256"))
    )
    out.write_text(old.replace(" accepted sha256 ", " sha256 "))  # the header calibctl 0.1 wrote
    header = trace_header.read(out.read_text())
    assert header is not None and header.intact is None and header.status is None
    traced = next(f for f in findings(cli("lint", str(out), "--json")) if f["rule"] == "traceability")
    assert "records no file-sha256" in traced["message"] and traced["severity"] == "warning"


ROS_OK = {
    "image_width": 640,
    "image_height": 480,
    "camera_name": "front",
    "camera_matrix": {"rows": 3, "cols": 3, "data": [800.0, 0.0, 320.0, 0.0, 800.0, 240.0, 0.0, 0.0, 1.0]},
    "distortion_model": "plumb_bob",
    "distortion_coefficients": {"rows": 1, "cols": 5, "data": [-0.05, 0.01, 0.0, 0.0, 0.0]},
    "rectification_matrix": {"rows": 3, "cols": 3, "data": [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]},
    "projection_matrix": {
        "rows": 3,
        "cols": 4,
        "data": [800.0, 0.0, 320.0, 0.0, 0.0, 800.0, 240.0, 0.0, 0.0, 0.0, 1.0, 0.0],
    },
}


def _ros_file(tmp_path: Path, **changes) -> Path:
    doc = {k: v for k, v in {**ROS_OK, **changes}.items() if v is not None}
    path = tmp_path / "ros.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


@pytest.mark.parametrize(
    ("changes", "rule", "message"),
    [
        ({"projection_matrix": None}, "ros-camera-info", "projection_matrix is missing"),
        ({"rectification_matrix": None}, "ros-camera-info", "rectification_matrix is missing"),
        ({"image_height": None}, "ros-camera-info", "image_height is missing"),
        ({"camera_matrix": None}, "ros-camera-info", "camera_matrix is missing"),
        (
            {"camera_matrix": {"rows": 3, "cols": 3, "data": [800.0, 0.0, 320.0]}},
            "ros-camera-info",
            "camera_matrix says 3x3 but has 3 numbers",
        ),
        (
            {"projection_matrix": {"rows": 3, "cols": 3, "data": [1.0] * 9}},
            "ros-camera-info",
            "projection_matrix is 3x3, ROS reads it as 3x4",
        ),
        ({"distortion_model": "kannala_brandt"}, "ros-distortion-model", "'kannala_brandt' is unknown"),
        ({"distortion_model": "rational_polynomial"}, "ros-distortion-model", "rational_polynomial takes 8"),
    ],
)
def test_a_file_ros_would_refuse_fails_lint(tmp_path, changes, rule, message):
    result = cli("lint", str(_ros_file(tmp_path, **changes)), "--json")
    assert result.exit_code == 1, result.output
    hit = [f for f in findings(result) if f["rule"] == rule and f["severity"] == "error"]
    assert hit and message in hit[0]["message"], findings(result)


def test_missing_model_and_bad_camera_name_are_warnings_like_in_ros(tmp_path):
    result = cli("lint", str(_ros_file(tmp_path, distortion_model=None, camera_name="front-left")), "--json")
    rules = {f["rule"]: f["severity"] for f in findings(result)}
    assert rules["ros-distortion-model"] == "warning" and rules["ros-camera-name"] == "warning"
    assert "ros-camera-info" not in rules


def test_equidistant_is_checked_as_a_fisheye_not_as_radial_tangential(tmp_path):
    import numpy as np

    from calibctl.core.intrinsics.lens_checks import check_distortion_foldover

    K = [300.0, 0.0, 320.0, 0.0, 300.0, 240.0, 0.0, 0.0, 1.0]
    d = [0.0, 0.0, 0.5, 0.5]  # fisheye k3 = k4 = 0.5; read as k1 k2 p1 p2 it is a tangential fold-over
    assert not check_distortion_foldover(np.reshape(K, (3, 3)), np.array(d), (640, 480)).passed
    fisheye = {
        "distortion_model": "equidistant",
        "distortion_coefficients": {"rows": 1, "cols": 4, "data": d},
        "camera_matrix": {"rows": 3, "cols": 3, "data": K},
    }
    result = cli("lint", str(_ros_file(tmp_path, **fisheye)), "--json")
    assert not {"ros-distortion-model", "ros-camera-info", "distortion-foldover"} & errors(result), findings(
        result
    )
    folding = {**fisheye, "distortion_coefficients": {"rows": 1, "cols": 4, "data": [-0.3, 0.0, 0.0, 0.0]}}
    result = cli("lint", str(_ros_file(tmp_path, **folding)), "--json")
    assert "distortion-foldover" in errors(result)
    assert "fisheye theta_d(theta) stops increasing" in next(
        f["message"] for f in findings(result) if f["rule"] == "distortion-foldover"
    )
    five = {**fisheye, "distortion_coefficients": {"rows": 1, "cols": 5, "data": [*d, 0.0]}}
    assert "equidistant takes 4" in next(
        f["message"]
        for f in findings(cli("lint", str(_ros_file(tmp_path, **five)), "--json"))
        if f["rule"] == "ros-distortion-model"
    )


@pytest.mark.parametrize("fmt", ["ros", "opencv"])
def test_import_of_a_ros_or_opencv_export_exits_2_naming_the_format(store_url, tmp_path, fmt):
    out = tmp_path / "cam.yaml"
    export(store_url, "CAM-0001", fmt, out)
    result = cli("--db", f"sqlite:///{tmp_path / 'robot.db'}", "import", str(out))
    assert result.exit_code == 2
    assert ("ROS camera_info export" if fmt == "ros" else "OpenCV FileStorage export") in result.stderr


OPENCV_HEAD = "%YAML:1.0\n---\n"
OPENCV_K = "camera_matrix: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n"


@pytest.mark.parametrize(
    ("body", "message"),
    [
        (OPENCV_K + "   rows: [\n", "OpenCV cannot read this FileStorage file"),
        (OPENCV_K + "   data: [ 500., 0., 320. ]\n", "camera_matrix is not a matrix OpenCV can read"),
        ("image_width: 640\n", "an OpenCV FileStorage file without camera_matrix is not a calibration"),
    ],
)
def test_an_opencv_file_opencv_cannot_read_is_exit_2(tmp_path, body, message):
    path = tmp_path / "cam.yml"
    path.write_text(OPENCV_HEAD + body)
    result = cli("lint", str(path))
    assert result.exit_code == 2 and message in result.stderr and "Traceback" not in result.output


def test_an_opencv_calibration_from_another_tool_is_linted_on_its_numbers(tmp_path):
    path = tmp_path / "cam.yml"
    path.write_text(
        OPENCV_HEAD
        + "notes:\n   by: someone\nviews: [1, 2]\n"
        + OPENCV_K
        + "   data: [ 500., 0., 320., 0., 500., 240., 0., 0., 1. ]\nimage_width: 640\nimage_height: 480\n"
    )
    result = cli("lint", str(path), "--json")
    rules = {f["rule"]: f["severity"] for f in findings(result)}
    assert json.loads(result.stdout)["results"][0]["kind"] == "opencv"
    assert rules["traceability"] == "warning" and "principal-point" not in rules and "finite" not in rules
