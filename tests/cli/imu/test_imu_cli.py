"""`calibctl imu` end to end on a rendered recording: synth -> solve --rig -> rig show / export -> lint
passes; Kalibr's camchain carries td as timeshift_cam_imu; an edited number in the stored edge is refused
by lint and import; bad input is exit 2 in one line; a degenerate motion is exit 1 and never active."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest
import yaml

from calibctl.store.repository import Store
from tests.artifacts.factories import calibration
from tests.store.rig_documents import RIG
from tests.workflows.imu.imu_data import (
    CAM,
    TD_S,
    WHO,
    cli,
    copy_db,
    copy_recording,
    make_store,
    rendered,
    truth,
)
from tests.workflows.imu.test_imu_workflow import IMU_EDITS, _rewrite


def _yaml_body(text: str) -> dict:
    return yaml.safe_load("\n".join(x for x in text.splitlines() if not x.startswith("#")))


def test_help_names_the_inputs() -> None:
    r = cli("sqlite://", "imu", "solve", "--help")
    assert r.exit_code == 0
    for word in ("imu0/data.csv", "<ns>.csv", "--serial", "--noise", "imu.yaml", "--hold-td-ms", "--rig"):
        assert word in r.output


def test_synths_imu_yaml_reads_as_kalibr_reads_it(recording) -> None:
    noise = yaml.safe_load((recording / "imu.yaml").read_text())  # Kalibr's ConfigReader: plain safe_load
    assert noise["rostopic"] == "/imu0"
    assert all(type(v) is float and v > 0 for k, v in noise.items() if k != "rostopic"), noise


def test_synth_solve_json_is_the_truth_within_its_sigma(recording, tmp_path) -> None:
    url = make_store(tmp_path / "c.db")
    out = tmp_path / "o.json"
    r = cli(
        url,
        "imu",
        "solve",
        str(recording),
        "--serial",
        CAM,
        "--noise",
        str(recording / "imu.yaml"),
        "--json",
        "-o",
        str(out),
    )
    assert r.exit_code == 0, r.output
    doc = json.loads(r.stdout)
    sealed = json.loads(out.read_text())  # -o holds what --json prints, sealed as lidar solve -o's
    assert sealed.pop("kind") == "imu-result" and sealed.pop("content_sha256") and sealed == doc
    linted = cli(url, "lint", str(out))
    assert linted.exit_code == 0 and "(imu-result): pass" in linted.stdout, linted.output
    out.write_text(out.read_text().replace(f'"td_ms": {doc["estimate"]["td_ms"]}', '"td_ms": 0.5'))
    linted = cli(url, "lint", str(out))
    assert linted.exit_code == 1 and "was edited" in linted.output, linted.output
    e = doc["estimate"]
    assert doc["status"] == "accepted" and doc["camera"] == f"{CAM}@1" and "stored" not in doc
    assert abs(e["td_ms"] - TD_S * 1e3) < 5 * e["sigma_td_ms"]
    assert e["timeshift_cam_imu_s"] == pytest.approx(e["td_ms"] / 1e3, abs=1e-6)
    assert np.allclose(np.array(e["T_cam_imu"]) @ np.array(e["matrix"]), np.eye(4), atol=1e-6)
    t = truth(recording)
    assert np.allclose(np.array(e["T_cam_imu"])[:3, :3], np.array(t["T_cam_imu"])[:3, :3], atol=2e-3)
    rows = doc["row_test"]  # a global-shutter render: no ramp over the image rows
    assert not rows["significant"] and rows["message"].endswith("constant across rows, as a time offset is")


def test_the_stored_edge_shows_exports_and_lints_clean(solved, tmp_path) -> None:
    db, doc = solved
    url = copy_db(db, tmp_path)
    (ev,) = doc["imu"]
    td = ev["estimate"]["td_s"]
    shown = cli(url, "rig", "show", RIG)
    assert shown.exit_code == 0 and "(camera-imu)" in shown.stdout
    assert f"imu imu -> {CAM}: accepted, td {td * 1e3:+.3f} ms" in shown.stdout
    history = json.loads(cli(url, "rig", "history", RIG, "--json").stdout)
    assert history["versions"][-1]["imu"] == [{"edge": f"imu:{CAM}", "status": "accepted"}]
    assert cli(url, "rig", "lint", RIG).exit_code == 0
    camchain = _yaml_body(cli(url, "rig", "export", RIG, "--format", "kalibr").stdout)
    T_cam_imu = np.linalg.inv(np.array(ev["estimate"]["T_imu_cam"]))
    assert np.allclose(camchain["cam0"]["T_cam_imu"], T_cam_imu, atol=1e-12)
    assert camchain["cam0"]["timeshift_cam_imu"] == td == camchain["cam1"]["timeshift_cam_imu"]
    imu_yaml = _yaml_body(cli(url, "rig", "export", RIG, "--format", "kalibr-imu").stdout)
    assert imu_yaml["gyroscope_noise_density"] == ev["noise"]["gyro_noise_density"]
    assert imu_yaml["rostopic"] == "/imu"
    tf = _yaml_body(cli(url, "rig", "export", RIG, "--edge", f"imu:{CAM}", "--format", "tf").stdout)
    assert tf["transforms"][0]["header"]["frame_id"] == "imu"
    edge = tmp_path / "edge.json"  # unsealed alone: lint checks its schema and says where the seal is
    assert (
        cli(url, "rig", "export", RIG, "--edge", f"imu:{CAM}", "--format", "json", "-o", str(edge)).exit_code
        == 0
    )
    linted = cli(url, "lint", str(edge))
    assert linted.exit_code == 0 and "(imu-edge-json): pass" in linted.stdout, linted.output
    assert "no content hash of its own" in linted.stdout
    bundle = tmp_path / "bundle"
    assert cli(url, "rig", "export", RIG, "--format", "bundle", "-o", str(bundle)).exit_code == 0
    assert (bundle / "imu.yaml").is_file()
    linted = cli(url, "lint", str(bundle / "manifest.json"))
    assert linted.exit_code == 0, linted.output
    assert "imu.yaml (kalibr-imu): pass" in linted.stdout and "camchain.yaml (kalibr): pass" in linted.stdout


def test_kalibrs_target_yaml_is_the_edges_board_in_kalibrs_types_and_lint_checks_it(
    recording, solved, tmp_path
) -> None:
    db, _ = solved
    url = copy_db(db, tmp_path)
    no_board = cli(url, "rig", "export", RIG, "--format", "kalibr-target")  # solved from corner files alone
    assert (
        no_board.exit_code == 2
        and "without --board" in no_board.output
        and "Traceback" not in no_board.output
    )
    assert cli(url, "board", "add", "G7N", "--cols", "7", "--rows", "6", "--square-mm", "50").exit_code == 0
    args = ["imu", "solve", str(recording), "--serial", CAM, "--board", "G7N", "--rig", RIG, "--json"]
    solved_doc = json.loads(cli(url, *args, "--noise", str(recording / "imu.yaml")).stdout)
    assert solved_doc["stored"]["status"] == "accepted"  # a typed board size is named, not refused
    assert any("G7N@1's size is nominal" in note for note in solved_doc["notes"])
    path = tmp_path / "target.yaml"
    assert cli(url, "rig", "export", RIG, "--format", "kalibr-target", "-o", str(path)).exit_code == 0
    target = _yaml_body(path.read_text())  # the types Kalibr's ConfigReader insists on: ints and floats
    assert target == {"target_type": "checkerboard", "targetCols": 7, "targetRows": 6,
                      "rowSpacingMeters": 0.05, "colSpacingMeters": 0.05}  # fmt: skip
    assert all(type(target[k]) is float for k in ("rowSpacingMeters", "colSpacingMeters"))
    linted = cli(url, "lint", str(path))
    assert linted.exit_code == 0 and "(kalibr-target): pass" in linted.stdout, linted.output
    path.write_text(path.read_text().replace("0.05\n", "0.06\n"))  # a hand-edited square size
    assert cli(url, "lint", str(path)).exit_code == 1


def test_a_kalibr_users_aprilgrid_recording_solves_and_exports_its_target(tmp_path_factory, tmp_path) -> None:
    rec = rendered(tmp_path_factory, "aprilgrid")
    url = make_store(tmp_path / "c.db")
    given = {k: v for k, v in truth(rec)["board"].items() if k != "kind"}  # Kalibr's target.yaml fields
    (tmp_path / "target.yaml").write_text(yaml.safe_dump(given))
    measured = [
        "--uncertainty-mm",
        "0.05",
        "--instrument",
        "calipers",
        "--measured-by",
        "qa",
        "--measured-on",
        "2026-12-01",
    ]
    added = cli(url, "board", "add", "AG", "--from-kalibr", str(tmp_path / "target.yaml"), *measured)
    assert added.exit_code == 0, added.output
    args = ["imu", "solve", str(rec), "--serial", CAM, "--board", "AG", "--noise", str(rec / "imu.yaml")]
    r = cli(url, *args, "--rig", RIG, "--json")
    assert r.exit_code == 0, r.output
    e = json.loads(r.stdout)["estimate"]
    assert abs(e["td_ms"] - TD_S * 1e3) < 5 * e["sigma_td_ms"]
    exported = _yaml_body(cli(url, "rig", "export", RIG, "--format", "kalibr-target").stdout)
    assert exported == given
    no_images = cli(url, "imu", "synth", str(tmp_path / "x"), "--pattern", "aprilgrid")
    assert no_images.exit_code == 2 and "add --images" in no_images.output


@pytest.mark.parametrize(
    ("body", "says"),
    [
        ("target_type: aprilgrid\ntagCols: 6\ntagRows: 6\ntagSize: 0.088\ntagSpacing: 1\n", "tagSpacing = 1"),
        (
            "target_type: checkerboard\ntargetCols: 2\ntargetRows: 6\nrowSpacingMeters: 0.05\n",
            "targetCols = 2",
        ),
        ("target_type: circles\n", "target_type 'circles' is not"),
    ],
    ids=["int tagSpacing", "2 columns", "unknown type"],
)
def test_lint_refuses_a_target_yaml_kalibr_would_refuse(tmp_path, body, says) -> None:
    path = tmp_path / "target.yaml"
    path.write_text(body)
    linted = cli(f"sqlite:///{tmp_path / 'none.db'}", "lint", str(path))
    assert linted.exit_code == 1 and says in linted.output, linted.output


def test_an_edited_number_in_the_stored_edge_is_refused_by_lint_and_import(solved, tmp_path) -> None:
    db, doc = solved
    url = copy_db(db, tmp_path)
    path = tmp_path / "rig.json"
    path.write_text(cli(url, "rig", "export", RIG, "--format", "json").stdout)
    assert cli(url, "lint", str(path)).exit_code == 0
    edited = json.loads(path.read_text())
    edited["imu"][0]["estimate"]["td_s"] += 0.001  # one millisecond later
    path.write_text(json.dumps(edited))
    linted = cli(url, "lint", str(path))
    assert linted.exit_code == 1 and "sha256" in linted.output
    imported = cli(url, "rig", "import", str(path))
    assert imported.exit_code == 1 and "content does not match its sha256" in imported.output


def test_a_gyro_in_deg_per_second_is_exit_2_in_one_line_naming_the_unit(recording, tmp_path) -> None:
    url = make_store(tmp_path / "c.db")
    rec = copy_recording(recording, tmp_path)
    log = rec / "imu0" / "data.csv"
    lines = log.read_text().splitlines()
    rows = [lines[0]]
    for line in lines[1:]:
        c = line.split(",")
        rows.append(",".join([c[0], *(f"{float(v) * 180 / np.pi:.6f}" for v in c[1:4]), *c[4:]]))
    log.write_text("\n".join(rows) + "\n")
    r = cli(url, "imu", "solve", str(rec), "--serial", CAM, "--rig", RIG)
    assert r.exit_code == 2 and len([x for x in r.output.splitlines() if x.startswith("Error:")]) == 1
    assert "the gyro reads deg/s; multiply by pi/180" in r.output and str(log) in r.output
    assert "Traceback" not in r.output
    assert json.loads(cli(url, "rig", "history", RIG, "--json").stdout)["versions"][-1]["version"] == 1


def test_a_corridor_is_exit_1_and_stored_as_a_rejected_version(tmp_path_factory, tmp_path) -> None:
    rec = rendered(tmp_path_factory, "corridor")
    url = make_store(tmp_path / "c.db")
    r = cli(url, "imu", "solve", str(rec), "--serial", CAM, "--rig", RIG)
    assert r.exit_code == 1, r.output
    assert "Result: REJECTED" in r.output and "(rejected, never active; no edge)" in r.output
    assert "excite with turns and reversals" in r.output
    assert "to hold td: imu solve ... --hold-td-ms MS" in r.output  # the other way out, by its flag
    history = json.loads(cli(url, "rig", "history", RIG, "--json").stdout)
    assert history["active_version"] == 1
    assert history["versions"][-1]["imu"] == [{"edge": f"imu:{CAM}", "status": "rejected"}]
    page = tmp_path / "rejected.html"
    assert cli(url, "report", "--rig", f"{RIG}@2", "-o", str(page)).exit_code == 0
    html = page.read_text()
    assert f'data-key="imu_status_imu-{CAM}">rejected' in html and ">FAIL<" in html


def _refused_and_never_active(url: str, r, says: str) -> None:
    assert r.exit_code == 1, r.output
    (result,) = [x for x in r.output.splitlines() if x.startswith("Result: REJECTED")]
    assert says in result, result
    history = json.loads(cli(url, "rig", "history", RIG, "--json").stdout)
    assert history["active_version"] == 1
    assert history["versions"][-1]["imu"] == [{"edge": f"imu:{CAM}", "status": "rejected"}]


def test_a_50_mm_board_registered_at_40_mm_is_exit_1_naming_its_size(tmp_path_factory, tmp_path) -> None:
    rec = rendered(tmp_path_factory, "images")  # board G7: 50 mm squares
    url = make_store(tmp_path / "c.db")
    noise = ("--noise", str(rec / "imu.yaml"))
    r = cli(url, "imu", "solve", str(rec), "--serial", CAM, *noise, "--rig", RIG, "--board", "G7-40")
    _refused_and_never_active(url, r, "the accelerometer measures the board at 1.2")
    assert re.search(r"its square or tag edge (49|50|51)\.\d \+/- \d+\.\d mm, not 40\.0 mm", r.output), (
        r.output
    )


def test_another_lens_intrinsics_are_exit_1_naming_them(recording, tmp_path) -> None:
    url = make_store(tmp_path / "c.db")
    with Store.open(url) as store:  # the render's lens is 800 px; this calibration says 752 (6 % short)
        store.add_artifact(calibration(serial=CAM, fx=752.0), activate=True, **WHO)
    noise = ("--noise", str(recording / "imu.yaml"))
    r = cli(url, "imu", "solve", str(recording), "--serial", CAM, *noise, "--rig", RIG)
    _refused_and_never_active(url, r, "the camera's intrinsics do not fit these images")


def test_a_rolling_shutter_solved_without_line_delay_is_named_with_the_fix(tmp_path) -> None:
    url = make_store(tmp_path / "c.db")
    rec = tmp_path / "rs"
    made = cli(url, "imu", "synth", str(rec), "--serial", CAM, "--duration-s", "3", "--line-delay-us", "30")
    assert made.exit_code == 0, made.output
    r = cli(url, "imu", "solve", str(rec), "--serial", CAM, "--noise", str(rec / "imu.yaml"))
    assert (
        "  row test: rolling shutter suspected: solve with --line-delay; time residual vs image row +"
        in r.output
    )


def test_a_bag_without_rosbags_installed_names_the_bags_extra(monkeypatch, tmp_path) -> None:
    from tests.cli.app.test_extras_cli import _assert_missing_extra, _hide

    _hide(monkeypatch, "rosbags")
    bag = tmp_path / "bag"
    bag.mkdir()
    (bag / "metadata.yaml").write_text("rosbag2_bagfile_information: {}\n")
    url = make_store(tmp_path / "c.db")
    args = ["--board", "G7", "--image-topic", "/cam0/image_raw", "--imu-topic", "/imu0"]
    res = cli(url, "imu", "solve", str(bag), "--serial", CAM, *args)
    _assert_missing_extra(res, "bags", "rosbags", "reading a ROS bag")


def test_the_rig_report_draws_the_imu_edge_from_the_store_byte_identical(solved, tmp_path) -> None:
    db, doc = solved
    url = copy_db(db, tmp_path)
    (ev,) = doc["imu"]
    e, k = ev["estimate"], f"imu-{CAM}"
    page = tmp_path / "rig.html"
    done = cli(url, "report", "--rig", RIG, "-o", str(page))
    assert done.exit_code == 0, done.output
    html = page.read_text()
    assert "<h2>Camera-IMU</h2>" in html and f'data-key="imu_status_{k}">accepted' in html
    for i, axis in enumerate("xyz"):
        assert f'data-key="imu_t_{k}_{axis}">{e["T_imu_cam"][i][3] * 1e3:.2f}<' in html
        assert f'data-key="imu_sigma_r_{k}_{axis}">{e["sigma_rotation_deg"][i]:.4f}<' in html
    assert f'data-key="imu_td_{k}">{e["td_s"] * 1e3:.4f}<' in html
    assert f'data-key="imu_sigma_td_{k}">{e["sigma_td_ms"]:.4f}<' in html
    assert f'data-key="imu_td_crlb_{k}">{e["td_crlb_ms"]:.4f}<' in html
    for gate in ev["gates"]:
        assert f'data-key="imu_gate_{k}_{gate["gate"]}">pass<' in html
    # a global-shutter render: the residuals do not ramp with the row
    assert f'data-key="imu_rolling_shutter_{k}">no<' in html and ev["row_test"]["message"] in html
    assert "gyro (lines) and camera rate (dots)" in html and "time residual over image rows" in html
    again = tmp_path / "again.html"
    assert cli(url, "report", "--rig", RIG, "-o", str(again)).exit_code == 0
    assert again.read_bytes() == page.read_bytes()


def _imu_log(case: str):
    """The workflow test's edit of the IMU log; returns the message it must get."""
    edit, message, _ = IMU_EDITS[case]

    def make(rec) -> str:
        _rewrite(rec / "imu0" / "data.csv", edit)
        return message

    return make


def _stamp_listed_twice(rec) -> str:
    stamps = sorted(p.stem for p in (rec / "cam0").glob("*.csv"))
    listing = ["#timestamp [ns],filename"] + [f"{s},{s}.png" for s in [stamps[0], *stamps[:3]]]
    (rec / "cam0" / "data.csv").write_text("\n".join(listing) + "\n")
    return f"cam0/data.csv: frame stamp {stamps[0]} is listed twice"


def _rows_of_another_stamp(rec) -> str:
    first = sorted((rec / "cam0").glob("*.csv"))[0]
    other = int(first.stem) + 1
    _rewrite(first, lambda lines: [lines[0]] + [f"{other},{x.split(',', 1)[1]}" for x in lines[1:]])
    return f"named {first.stem} but its rows are stamped {other}"


BAD_INPUTS = {
    "IMU stamps not increasing": (_imu_log("stamps not increasing"), ()),
    "accelerometer in g": (_imu_log("accel numbers in g"), ()),
    "logs that do not overlap": (_imu_log("logs that do not overlap"), ()),
    "a camera stamp listed twice": (_stamp_listed_twice, ()),
    "a corner file stamped as another frame": (_rows_of_another_stamp, ()),
    "a camera without an active calibration": (
        lambda rec: "camera CAM-0002 has no active calibration",
        ("--serial", "CAM-0002"),
    ),
    "a board that is not registered": (
        lambda rec: "unknown board 'NOPE'; known: G7, G7-40",
        ("--board", "NOPE"),
    ),
    "corners of another board than the registered one": (
        lambda rec: "m is no corner of board G7-40@1",
        ("--board", "G7-40"),
    ),
}


@pytest.fixture(scope="module")
def uncalibrated_other(tmp_path_factory) -> str:
    """The rig store with CAM-0002 a member but never calibrated; every bad input must leave it as it is."""
    return make_store(tmp_path_factory.mktemp("bad-input") / "c.db", other_calibrated=False)


@pytest.mark.parametrize("case", BAD_INPUTS, ids=list(BAD_INPUTS))
def test_bad_input_is_exit_2_in_one_line_and_nothing_is_stored(case, recording, uncalibrated_other, tmp_path):
    edit, extra = BAD_INPUTS[case]
    rec = copy_recording(recording, tmp_path)
    message = edit(rec)
    args = ["--serial", CAM, *extra] if "--serial" not in extra else list(extra)
    r = cli(uncalibrated_other, "imu", "solve", str(rec), *args, "--rig", RIG)
    assert r.exit_code == 2, r.output
    assert [x for x in r.output.splitlines() if x.startswith("Error:")] == [
        next(x for x in r.output.splitlines() if message in x)
    ]
    assert "Traceback" not in r.output
    history = json.loads(cli(uncalibrated_other, "rig", "history", RIG, "--json").stdout)
    assert [v["version"] for v in history["versions"]] == [1]


def test_a_bag_without_the_named_topic_is_exit_2_and_nothing_is_stored(recording, tmp_path) -> None:
    pytest.importorskip("rosbags")
    from tests.workflows.imu.test_imu_bags import _write_bag

    rec = copy_recording(recording, tmp_path)
    (rec / "cam0" / "data.csv").write_text("#timestamp [ns],filename\n")  # the IMU topic alone
    bag = tmp_path / "run"
    _write_bag(rec, bag)
    url = make_store(tmp_path / "c.db")
    topics = ["--image-topic", "/cam0/image_raw", "--imu-topic", "/imu1"]
    r = cli(url, "imu", "solve", str(bag), "--serial", CAM, "--board", "G7", *topics, "--rig", RIG)
    assert r.exit_code == 2, r.output
    (error,) = [x for x in r.output.splitlines() if x.startswith("Error:")]
    assert (
        str(bag) in error
        and "has no topic /imu1 (it has: /cam0/image_raw (sensor_msgs/msg/Image), /imu0" in error
    )
    assert "--imu-topic" in r.output and "Traceback" not in r.output
    assert [
        v["version"] for v in json.loads(cli(url, "rig", "history", RIG, "--json").stdout)["versions"]
    ] == [1]
